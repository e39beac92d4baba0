#![cfg(not(target_arch = "wasm32"))]
//! tract runs the exported networks like PyTorch and onnxruntime did: the fixture stores
//! seeded inputs with both frameworks' outputs (written by `egoexo_train.export`).

use crate::common::*;
use egoexo_core::TrackingMode;
use egoexo_infer::models::{Loading, OnnxModel};
use egoexo_infer::{InferError, LoadedModels};

struct Reference {
    index: serde_json::Value,
    data: Vec<f32>,
}

impl Reference {
    fn load() -> Self {
        let dir = fixture_dir();
        let index: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("reference.json")).unwrap()).unwrap();
        let bytes = std::fs::read(dir.join("reference.bin")).unwrap();
        let data = bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        Self { index, data }
    }

    fn array(&self, key: &str) -> &[f32] {
        let entry = &self.index["arrays"][key];
        let offset = entry["offset"].as_u64().unwrap_or_else(|| panic!("no array {key}")) as usize;
        let len: usize = entry["shape"].as_array().unwrap().iter().map(|d| d.as_u64().unwrap() as usize).product();
        &self.data[offset..offset + len]
    }
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

#[test]
fn tract_matches_pytorch_and_onnxruntime_within_1e_4() {
    let reference = Reference::load();
    assert_eq!(reference.index["tracking"], "three_point");
    let models = fixture_models(TrackingMode::ThreePoint);
    for (name, model, inputs, outputs) in [
        ("egonet", &models.egonet, vec!["ego"], vec!["root_6d", "body_6d"]),
        ("gate", &models.gate, vec!["gate_features"], vec!["gate"]),
        ("fusion", &models.fusion, vec!["ego", "egonet", "exo", "observer_mask"], vec!["root_6d", "body_6d"]),
        (
            "fusion_ego_only",
            models.fusion_ego_only.as_ref().unwrap(),
            vec!["ego", "egonet"],
            vec!["root_6d", "body_6d"],
        ),
    ] {
        let args: Vec<&[f32]> = inputs.iter().map(|i| reference.array(&format!("{name}/input/{i}"))).collect();
        let got = model.run(&args).unwrap();
        assert_eq!(got.len(), outputs.len());
        for (out, value) in outputs.iter().zip(&got) {
            for framework in ["torch", "onnxruntime"] {
                let expected = reference.array(&format!("{name}/{framework}/{out}"));
                let diff = max_abs_diff(value, expected);
                assert!(diff <= 1e-4, "{name}.{out}: tract vs {framework} max abs diff {diff}");
            }
        }
    }
}

/// A deferred model is parsed and optimised on its first run, to the same outputs; a malformed
/// file fails then, naming the model; loading a whole manifest deferred prepares nothing.
#[test]
fn a_deferred_model_is_made_on_first_use_with_the_same_outputs() {
    let reference = Reference::load();
    let manifest = fixture_manifest();
    let file = &manifest.model_set(TrackingMode::ThreePoint).unwrap().egonet;
    let bytes = std::fs::read(fixture_dir().join(&file.file)).unwrap();
    let eager = OnnxModel::load(&file.file, &bytes, &file.input_shapes()).unwrap();
    let deferred = OnnxModel::load_deferred(&file.file, bytes.clone(), &file.input_shapes());
    assert!(eager.is_ready() && !deferred.is_ready());
    let input = reference.array("egonet/input/ego");
    assert_eq!(deferred.run(&[input]).unwrap(), eager.run(&[input]).unwrap());
    assert!(deferred.is_ready());

    let broken = OnnxModel::load_deferred("3pt/broken.onnx", bytes[..bytes.len() / 2].to_vec(), &file.input_shapes());
    let err = broken.prepare().unwrap_err().to_string();
    assert!(err.contains("3pt/broken.onnx"), "{err}");
    assert!(broken.run(&[input]).unwrap_err().to_string().contains("3pt/broken.onnx"), "the failure stays");

    let dir = fixture_dir();
    let read = |f: &str| {
        std::fs::read(dir.join(f)).map_err(|e| InferError::ReadModel { file: f.into(), message: e.to_string() })
    };
    let loaded = LoadedModels::load_with(&manifest, read, Loading::Deferred).unwrap();
    let (one, three) = (TrackingMode::OnePoint, TrackingMode::ThreePoint);
    assert!(!loaded.offline().models(one).unwrap().is_ready());
    let set = loaded.offline().models(three).unwrap();
    assert!(!set.is_ready());
    set.prepare().unwrap();
    assert!(set.is_ready() && !loaded.offline().models(one).unwrap().is_ready());
}

#[test]
fn a_tampered_model_file_is_refused() {
    let manifest = fixture_manifest();
    let set = manifest.model_set(TrackingMode::OnePoint).unwrap();
    let dir = fixture_dir();
    let err = egoexo_infer::models::ModelSet::load(set, |file| {
        let mut bytes = std::fs::read(dir.join(file)).unwrap();
        if file.ends_with("gate.onnx") {
            bytes[100] ^= 1;
        }
        Ok(bytes)
    })
    .unwrap_err();
    assert!(err.to_string().contains("gate.onnx") && err.to_string().contains("sha256"), "{err}");
}

#[test]
fn a_manifest_from_another_feature_layout_is_refused() {
    let text = std::fs::read_to_string(fixture_dir().join("manifest.json")).unwrap();
    let with_layout = |version: u32, dim: usize| {
        let mut manifest: serde_json::Value = serde_json::from_str(&text).unwrap();
        for set in manifest["model_sets"].as_array_mut().unwrap() {
            set["ego_feature_layout"]["version"] = version.into();
            set["ego_feature_layout"]["dim"] = dim.into();
        }
        egoexo_infer::manifest::Manifest::from_json(manifest.to_string().as_bytes()).unwrap_err().to_string()
    };
    // Models from before per-frame wrist validity (layout v1, 60 numbers).
    let old = with_layout(1, 60);
    assert!(old.contains("expect ego feature layout v1 (60 numbers per frame), this build computes v2 (62)"), "{old}");
    assert!(old.contains("trained before the per-frame wrist validity") && old.contains("retrain"), "{old}");
    let newer = with_layout(99, 62);
    assert!(newer.contains("layout v99") && newer.contains("update egoexo"), "{newer}");
}

#[test]
fn a_manifest_for_the_old_exo_token_layout_is_refused() {
    // Manifests from before the ray offsets carry no exo token layout: they mean v1 (4 numbers).
    let text = std::fs::read_to_string(fixture_dir().join("manifest.json")).unwrap();
    let mut manifest: serde_json::Value = serde_json::from_str(&text).unwrap();
    for set in manifest["model_sets"].as_array_mut().unwrap() {
        set.as_object_mut().unwrap().remove("exo_token_layout");
    }
    let err = egoexo_infer::manifest::Manifest::from_json(manifest.to_string().as_bytes()).unwrap_err();
    assert!(err.to_string().contains("exo token layout v1 (4 numbers per keypoint)"), "{err}");
}
