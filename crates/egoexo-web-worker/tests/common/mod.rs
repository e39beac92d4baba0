//! Shared by the native and the browser tests: the fixture session, the fixture networks'
//! files, and the recorded native reconstruction (`tests/fixtures/expected_reconstruction.json`).
#![allow(dead_code)]

use serde::{Deserialize, Serialize};

/// A short simulated session (CMU 105_36, two observers, 3-point tracking, ground truth),
/// made with `egoexo synth --subjects 105 --observers 2 --tracking 3` (seed 7).
pub const SESSION: &[u8] = include_bytes!("../fixtures/105_36.egoexo");
pub const SESSION_NAME: &str = "105_36.egoexo";

macro_rules! model_file {
    ($path:literal) => {
        ($path, include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/../egoexo-infer/tests/fixtures/models/", $path)))
    };
}

/// The untrained fixture networks of `egoexo-infer` (same format as the shipped `models/`).
pub const MANIFEST: &[u8] =
    include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/../egoexo-infer/tests/fixtures/models/manifest.json"));
pub const MODEL_FILES: [(&str, &[u8]); 8] = [
    model_file!("1pt/egonet.onnx"),
    model_file!("1pt/gate.onnx"),
    model_file!("1pt/fusion.onnx"),
    model_file!("1pt/fusion_ego_only.onnx"),
    model_file!("3pt/egonet.onnx"),
    model_file!("3pt/gate.onnx"),
    model_file!("3pt/fusion.onnx"),
    model_file!("3pt/fusion_ego_only.onnx"),
];

pub fn model_file(name: &str) -> Option<&'static [u8]> {
    MODEL_FILES.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
}

/// The recorded reconstruction: joints of every `STRIDE`-th frame (and the last), metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Expected {
    pub session: String,
    pub frames: usize,
    pub valid_frames: usize,
    pub sample_frames: Vec<usize>,
    /// Per sampled frame, 24 joints `[x, y, z]` of the ego-exo reconstruction.
    pub ego_exo: Vec<Vec<[f32; 3]>>,
    /// The same for the ego-only overlay.
    pub ego_only: Vec<Vec<[f32; 3]>>,
}

pub const EXPECTED_JSON: &str = include_str!("../fixtures/expected_reconstruction.json");
pub const STRIDE: usize = 7;

/// Largest native-vs-wasm difference accepted: float kernels differ (SIMD widths, FMA), the
/// answer must not (a wrong input or stage moves joints by centimetres).
pub const TOLERANCE_M: f32 = 1e-4;

pub fn sample_frames(frames: usize) -> Vec<usize> {
    let mut s: Vec<usize> = (0..frames).step_by(STRIDE).collect();
    if frames > 0 && s.last() != Some(&(frames - 1)) {
        s.push(frames - 1);
    }
    s
}

/// Picks the sampled frames out of flat `frames × 24 × 3` joints.
pub fn sample(flat: &[f32], frames: &[usize]) -> Vec<Vec<[f32; 3]>> {
    frames.iter().map(|&f| (0..24).map(|j| std::array::from_fn(|c| flat[(f * 24 + j) * 3 + c])).collect()).collect()
}

/// The largest joint distance between two samplings, with where it is.
pub fn max_difference(a: &[Vec<[f32; 3]>], b: &[Vec<[f32; 3]>]) -> (f32, usize, usize) {
    let mut worst = (0.0f32, 0, 0);
    for (i, (fa, fb)) in a.iter().zip(b).enumerate() {
        for (j, (pa, pb)) in fa.iter().zip(fb).enumerate() {
            let d = ((pa[0] - pb[0]).powi(2) + (pa[1] - pb[1]).powi(2) + (pa[2] - pb[2]).powi(2)).sqrt();
            if d > worst.0 || d.is_nan() {
                worst = (d, i, j);
            }
        }
    }
    worst
}
