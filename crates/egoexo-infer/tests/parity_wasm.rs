//! In headless Chromium: tract compiled to wasm32 (+simd128) runs the fixture networks like
//! PyTorch and onnxruntime did (≤ 1e-4), and the whole engine reconstructs a simulated session.
#![cfg(target_arch = "wasm32")]

use egoexo_core::TrackingMode;
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;
use egoexo_infer::{Engine, InferError, Method, ReconstructOptions};
use egoexo_session::align::{AlignOptions, align};
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::{SynthConfig, simulate};
use wasm_bindgen_test::{wasm_bindgen_test, wasm_bindgen_test_configure};

wasm_bindgen_test_configure!(run_in_browser);

const MANIFEST: &[u8] = include_bytes!("fixtures/models/manifest.json");
const REFERENCE_JSON: &[u8] = include_bytes!("fixtures/models/reference.json");
const REFERENCE_BIN: &[u8] = include_bytes!("fixtures/models/reference.bin");

fn file(name: &str) -> Result<Vec<u8>, InferError> {
    Ok(match name {
        "1pt/egonet.onnx" => include_bytes!("fixtures/models/1pt/egonet.onnx").to_vec(),
        "1pt/gate.onnx" => include_bytes!("fixtures/models/1pt/gate.onnx").to_vec(),
        "1pt/fusion.onnx" => include_bytes!("fixtures/models/1pt/fusion.onnx").to_vec(),
        "1pt/fusion_ego_only.onnx" => include_bytes!("fixtures/models/1pt/fusion_ego_only.onnx").to_vec(),
        "3pt/egonet.onnx" => include_bytes!("fixtures/models/3pt/egonet.onnx").to_vec(),
        "3pt/gate.onnx" => include_bytes!("fixtures/models/3pt/gate.onnx").to_vec(),
        "3pt/fusion.onnx" => include_bytes!("fixtures/models/3pt/fusion.onnx").to_vec(),
        "3pt/fusion_ego_only.onnx" => include_bytes!("fixtures/models/3pt/fusion_ego_only.onnx").to_vec(),
        other => return Err(InferError::ReadModel { file: other.into(), message: "not in the fixture".into() }),
    })
}

fn models(tracking: TrackingMode) -> ModelSet {
    let manifest = Manifest::from_json(MANIFEST).unwrap();
    ModelSet::load(manifest.model_set(tracking).unwrap(), file).unwrap()
}

#[wasm_bindgen_test]
fn tract_in_the_browser_matches_pytorch_and_onnxruntime() {
    let index: serde_json::Value = serde_json::from_slice(REFERENCE_JSON).unwrap();
    let data: Vec<f32> = REFERENCE_BIN.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    let array = |key: &str| -> &[f32] {
        let entry = &index["arrays"][key];
        let offset = entry["offset"].as_u64().unwrap() as usize;
        let len: usize = entry["shape"].as_array().unwrap().iter().map(|d| d.as_u64().unwrap() as usize).product();
        &data[offset..offset + len]
    };
    let set = models(TrackingMode::ThreePoint);
    for (name, model, inputs, outputs) in [
        ("egonet", &set.egonet, vec!["ego"], vec!["root_6d", "body_6d"]),
        ("gate", &set.gate, vec!["gate_features"], vec!["gate"]),
        ("fusion", &set.fusion, vec!["ego", "egonet", "exo", "observer_mask"], vec!["root_6d", "body_6d"]),
        ("fusion_ego_only", set.fusion_ego_only.as_ref().unwrap(), vec!["ego", "egonet"], vec!["root_6d", "body_6d"]),
    ] {
        let args: Vec<&[f32]> = inputs.iter().map(|i| array(&format!("{name}/input/{i}"))).collect();
        let got = model.run(&args).unwrap();
        for (out, value) in outputs.iter().zip(&got) {
            for framework in ["torch", "onnxruntime"] {
                let expected = array(&format!("{name}/{framework}/{out}"));
                let diff = value.iter().zip(expected).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(diff <= 1e-4, "{name}.{out}: tract (wasm) vs {framework}: {diff}");
            }
        }
    }
}

#[wasm_bindgen_test]
fn the_engine_reconstructs_a_simulated_session_in_the_browser() {
    let motion = walking_circle(5.0);
    let sim = simulate(&motion, "walk", &SynthConfig { observers: 2, ..SynthConfig::default() }, 3).unwrap();
    let aligned = align(&sim.session, &AlignOptions::default()).unwrap();
    let engine = Engine::new().with_models(models(TrackingMode::ThreePoint));
    let mut windows = 0;
    let r = engine
        .reconstruct(
            &aligned,
            &ReconstructOptions { method: Method::EgoExo, ..ReconstructOptions::default() },
            &mut |_| {
                windows += 1;
                true
            },
        )
        .unwrap();
    assert_eq!(r.motion.len(), aligned.timeline.frames);
    assert!(windows > 0 && r.joints.iter().all(|f| f.iter().all(|p| p.is_finite())));
}
