//! What the benches share: the networks they time.

use std::path::Path;

use egoexo_core::TrackingMode;
use egoexo_infer::InferError;
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;

/// The shipped 3-point networks (`models/`), or the untrained fixture networks when
/// `models/` has no manifest (said on stderr).
pub fn three_point_models() -> ModelSet {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut dir = root.join("models");
    if !dir.join("manifest.json").exists() {
        eprintln!("models/ has no manifest.json: benchmarking the untrained fixture networks instead");
        dir = root.join("crates/egoexo-infer/tests/fixtures/models");
    }
    let manifest =
        Manifest::from_json(&std::fs::read(dir.join("manifest.json")).expect("manifest")).expect("valid manifest");
    ModelSet::load(manifest.model_set(TrackingMode::ThreePoint).expect("3-point models"), |f| {
        std::fs::read(dir.join(f)).map_err(|e| InferError::ReadModel { file: f.into(), message: e.to_string() })
    })
    .expect("models load")
}
