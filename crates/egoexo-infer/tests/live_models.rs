//! Live variants in the manifest: chosen by lookahead, sharing the offline EgoNet, each file
//! parsed once; malformed live entries refused.

mod common;

use std::collections::BTreeMap;

use common::*;
use egoexo_core::TrackingMode;
use egoexo_infer::manifest::Manifest;
use egoexo_infer::{InferError, LoadedModels};
use serde_json::Value;

/// The fixture manifest with a 3-point live set for `lookahead` that shares the offline
/// 3-point files (the fixture has no other networks).
fn manifest_with_live_set(lookahead: Value) -> Value {
    let text = std::fs::read_to_string(fixture_dir().join("manifest.json")).unwrap();
    let mut manifest: Value = serde_json::from_str(&text).unwrap();
    let sets = manifest["model_sets"].as_array_mut().unwrap();
    let mut live = sets.iter().find(|s| s["tracking"] == "three_point").unwrap().clone();
    live["lookahead"] = lookahead;
    sets.push(live);
    manifest
}

fn parse(manifest: &Value) -> Result<Manifest, InferError> {
    Manifest::from_json(manifest.to_string().as_bytes())
}

#[test]
fn live_sets_are_chosen_by_lookahead_and_files_are_read_once() {
    let manifest = parse(&manifest_with_live_set(Value::from(0))).unwrap();
    assert_eq!(manifest.model_set(TrackingMode::ThreePoint).unwrap().lookahead, None, "offline set first");
    assert_eq!(manifest.live_model_set(TrackingMode::ThreePoint, 0).unwrap().lookahead, Some(0));
    assert!(manifest.live_model_set(TrackingMode::OnePoint, 0).is_none());
    assert_eq!(manifest.files().len(), 6, "the live set's files are the offline ones");

    let dir = fixture_dir();
    let mut reads: BTreeMap<String, usize> = BTreeMap::new();
    let models = LoadedModels::load(&manifest, |file| {
        *reads.entry(file.to_string()).or_default() += 1;
        std::fs::read(dir.join(file)).map_err(|e| InferError::ReadModel { file: file.into(), message: e.to_string() })
    })
    .unwrap();
    assert_eq!(reads.len(), 6);
    assert!(reads.values().all(|&n| n == 1), "{reads:?}");

    assert_eq!(models.live_lookaheads(), vec![0]);
    let lookahead_of = |engine: &egoexo_infer::Engine, tracking| engine.models(tracking).unwrap().manifest.lookahead;
    assert_eq!(lookahead_of(models.offline(), TrackingMode::ThreePoint), None);
    assert_eq!(lookahead_of(models.for_lookahead(0), TrackingMode::ThreePoint), Some(0));
    // No 1-point variant: the live engine falls back to the offline 1-point networks.
    assert_eq!(lookahead_of(models.for_lookahead(0), TrackingMode::OnePoint), None);
    // No variant for 4 frames: the offline networks.
    assert_eq!(lookahead_of(models.for_lookahead(4), TrackingMode::ThreePoint), None);
}

#[test]
fn a_live_set_and_its_offline_set_reconstruct_alike_from_the_same_files() {
    let manifest = parse(&manifest_with_live_set(Value::from(0))).unwrap();
    let dir = fixture_dir();
    let models = LoadedModels::load(&manifest, |file| {
        std::fs::read(dir.join(file)).map_err(|e| InferError::ReadModel { file: file.into(), message: e.to_string() })
    })
    .unwrap();
    let aligned = aligned_session(3.2, 1, TrackingMode::ThreePoint, 3);
    let options = egoexo_infer::ReconstructOptions { stride: 96, ..Default::default() };
    let offline = models.offline().reconstruct(&aligned, &options, &mut |_| true).unwrap();
    let live = models.for_lookahead(0).reconstruct(&aligned, &options, &mut |_| true).unwrap();
    assert_eq!(offline.joints, live.joints);
}

#[test]
fn malformed_live_entries_are_refused() {
    let err = parse(&manifest_with_live_set(Value::Null)).unwrap_err();
    assert!(err.to_string().contains("two 3-point sets with no lookahead (offline)"), "{err}");

    let mut twice = manifest_with_live_set(Value::from(4));
    let live = twice["model_sets"].as_array().unwrap().last().unwrap().clone();
    twice["model_sets"].as_array_mut().unwrap().push(live);
    let err = parse(&twice).unwrap_err();
    assert!(err.to_string().contains("two 3-point sets with lookahead 4"), "{err}");

    let err = parse(&manifest_with_live_set(Value::from(96))).unwrap_err();
    assert!(err.to_string().contains("lookahead 96, expected below the window (96)"), "{err}");

    let mut other_bytes = manifest_with_live_set(Value::from(0));
    let live = other_bytes["model_sets"].as_array_mut().unwrap().last_mut().unwrap();
    live["fusion"]["sha256"] = Value::from("00".repeat(32));
    let err = parse(&other_bytes).unwrap_err();
    assert!(err.to_string().contains("3pt/fusion.onnx` is listed twice with different sha256"), "{err}");
}
