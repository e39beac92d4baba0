//! Live variants in the manifest: chosen by lookahead, sharing the offline EgoNet, each file
//! parsed once; malformed live entries refused.

use std::collections::BTreeMap;

use crate::common::*;
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
    assert_eq!(
        manifest.model_set(TrackingMode::ThreePoint).unwrap().lookahead,
        None,
        "the offline set, not the variant"
    );
    assert_eq!(manifest.files().len(), 8, "the live set's files are the offline ones");

    let dir = fixture_dir();
    let mut reads: BTreeMap<String, usize> = BTreeMap::new();
    let models = LoadedModels::load(&manifest, |file| {
        *reads.entry(file.to_string()).or_default() += 1;
        std::fs::read(dir.join(file)).map_err(|e| InferError::ReadModel { file: file.into(), message: e.to_string() })
    })
    .unwrap();
    assert_eq!(reads.len(), 8);
    assert!(reads.values().all(|&n| n == 1), "{reads:?}");

    let (three, one) = (TrackingMode::ThreePoint, TrackingMode::OnePoint);
    assert!(!models.offline().trained_for_lookahead(three, 0));
    assert!(models.for_lookahead(0).trained_for_lookahead(three, 0));
    // No 1-point variant: the live engine falls back to the offline 1-point networks.
    assert!(models.for_lookahead(0).models(one).is_some_and(|m| m.manifest.lookahead.is_none()));
    // No variant for 4 frames: the offline networks.
    assert!(!models.for_lookahead(4).trained_for_lookahead(three, 4));
    assert!(models.for_lookahead(4).models(three).is_some_and(|m| m.manifest.lookahead.is_none()));
}

#[test]
fn the_engine_for_a_lookahead_runs_the_variants_own_networks_and_shares_egonet() {
    // A 3-point variant whose gate and fusion are other networks (the fixture's 1-point ones
    // take the same tensor shapes), with the offline 3-point EgoNet.
    let mut manifest = manifest_with_live_set(Value::from(0));
    let one_point =
        manifest["model_sets"].as_array().unwrap().iter().find(|s| s["tracking"] == "one_point").unwrap().clone();
    let variant = manifest["model_sets"].as_array_mut().unwrap().last_mut().unwrap();
    variant["gate"] = one_point["gate"].clone();
    variant["fusion"] = one_point["fusion"].clone();
    variant["fusion_ego_only"] = one_point["fusion_ego_only"].clone();
    let manifest = parse(&manifest).unwrap();
    let dir = fixture_dir();
    let models = LoadedModels::load(&manifest, |file| {
        std::fs::read(dir.join(file)).map_err(|e| InferError::ReadModel { file: file.into(), message: e.to_string() })
    })
    .unwrap();
    let aligned = aligned_session(3.2, 1, TrackingMode::ThreePoint, 3);
    let options = egoexo_infer::ReconstructOptions { stride: 96, ..Default::default() };
    let offline_set = models.offline().models(TrackingMode::ThreePoint).unwrap();
    let variant_set = models.for_lookahead(0).models(TrackingMode::ThreePoint).unwrap();
    let runs = || (offline_set.runs(), variant_set.runs());
    let before = runs();
    let offline = models.offline().reconstruct(&aligned, &options, &mut |_| true).unwrap();
    let after_offline = runs();
    let live = models.for_lookahead(0).reconstruct(&aligned, &options, &mut |_| true).unwrap();
    let after_live = runs();
    assert_eq!(offline.joints.len(), live.joints.len());
    let moved = offline.joints.iter().zip(&live.joints).flat_map(|(a, b)| a.iter().zip(b)).map(|(a, b)| a.distance(*b));
    assert!(moved.fold(0.0f32, f32::max) > 1e-3, "the variant's fusion did not change the joints");
    // Each run used its own gate and fusion; both went through the one shared EgoNet.
    let offline_run = (after_offline.0 - before.0, after_offline.1 - before.1);
    let live_run = (after_live.0 - after_offline.0, after_live.1 - after_offline.1);
    assert!(offline_run.0.fusion > 0 && offline_run.1.fusion == 0, "{offline_run:?}");
    assert!(live_run.0.fusion == 0 && live_run.1.fusion > 0, "{live_run:?}");
    assert!(live_run.0.egonet > 0 && live_run.0.egonet == live_run.1.egonet, "one shared EgoNet: {live_run:?}");
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
