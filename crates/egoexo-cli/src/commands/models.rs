//! Loading the trained networks from a models folder (`manifest.json` + ONNX files).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use egoexo_core::TrackingMode;
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;
use egoexo_infer::{InferError, LoadedModels};

/// The models folder to use: the given one, else `./models`, else the repository's `models/`
/// next to this binary's sources.
pub fn models_dir(given: Option<&Path>) -> PathBuf {
    if let Some(dir) = given {
        return dir.to_path_buf();
    }
    let local = PathBuf::from("models");
    if local.join("manifest.json").exists() {
        return local;
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models")
}

/// Reads and checks `manifest.json`.
pub fn read_manifest(dir: &Path) -> Result<Manifest> {
    let path = dir.join("manifest.json");
    let bytes = std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))?;
    Manifest::from_json(&bytes).with_context(|| format!("in {}", path.display()))
}

/// Reads a file of the models folder, for the loaders.
fn read_model_file(dir: &Path, file: &str) -> Result<Vec<u8>, InferError> {
    std::fs::read(dir.join(file))
        .map_err(|e| InferError::ReadModel { file: dir.join(file).display().to_string(), message: e.to_string() })
}

/// Loads the offline model set of one tracking mode (`None` when the manifest has none for it).
pub fn load_model_set(dir: &Path, manifest: &Manifest, tracking: TrackingMode) -> Result<Option<ModelSet>> {
    let Some(set) = manifest.model_set(tracking) else { return Ok(None) };
    let set = ModelSet::load(set, |file| read_model_file(dir, file))
        .with_context(|| format!("loading the {}-point models from {}", tracking.points(), dir.display()))?;
    Ok(Some(set))
}

/// Loads every set of the manifest: the offline networks and the live variants.
pub fn load_all_models(dir: &Path, manifest: &Manifest) -> Result<LoadedModels> {
    LoadedModels::load(manifest, |file| read_model_file(dir, file))
        .with_context(|| format!("loading the models in {}", dir.display()))
}
