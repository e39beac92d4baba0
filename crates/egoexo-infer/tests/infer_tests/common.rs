//! Shared fixtures: the untrained fixture networks and simulated, aligned sessions.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use egoexo_core::TrackingMode;
use egoexo_core::aligned::AlignedSession;
use egoexo_infer::InferError;
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;
use egoexo_session::align::{AlignOptions, align};
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::{SynthConfig, simulate};

/// The fixture models folder (small untrained networks exported by
/// `training/egoexo_train/export.py --random-init`).
pub fn fixture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/models")
}

pub fn fixture_manifest() -> Manifest {
    Manifest::from_json(&std::fs::read(fixture_dir().join("manifest.json")).unwrap()).unwrap()
}

pub fn fixture_models(tracking: TrackingMode) -> ModelSet {
    let manifest = fixture_manifest();
    let dir = fixture_dir();
    ModelSet::load(manifest.model_set(tracking).unwrap(), |file| {
        std::fs::read(dir.join(file)).map_err(|e| InferError::ReadModel { file: file.into(), message: e.to_string() })
    })
    .unwrap()
}

/// A simulated session of `seconds` of walking, aligned at 30 fps.
pub fn aligned_session(seconds: f32, observers: usize, tracking: TrackingMode, seed: u64) -> AlignedSession {
    let motion = walking_circle(seconds);
    let config = SynthConfig { observers, tracking, ..SynthConfig::default() };
    let sim = simulate(&motion, "walk", &config, seed).unwrap();
    align(&sim.session, &AlignOptions::default()).unwrap()
}
