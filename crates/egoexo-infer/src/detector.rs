//! The 2D keypoint detector of the detector step (paper § Ego-Guided Wearer Localization: a
//! top-down pose model on the region EgoNet's pose projects to): a square RGB crop in, the
//! 17 COCO keypoints with their confidences out, in the crop's normalised coordinates
//! ([`egoexo_core::crop::CropWindow`] maps them to the full image).
//!
//! The shipped model is MoveNet single-pose (Google, Apache-2.0) converted to ONNX once by
//! `training/egoexo_train/export_movenet.py`; `models/manifest.json`'s `detector` entry names
//! the file, its sha256, its input size and its output layout. Run by tract, like every
//! network here.

use egoexo_core::exo_keypoints::COCO17_COUNT;
use egoexo_core::glam::Vec2;
use serde::{Deserialize, Serialize};

use crate::InferError;
use crate::manifest::{ModelFile, sha256_hex};
use crate::models::OnnxModel;

/// The `detector` entry of the manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectorManifest {
    /// Which model (`movenet-lightning`, `movenet-thunder`).
    pub model: String,
    /// The keypoint set of its output; only `coco17` is read.
    pub keypoints: String,
    /// Where the weights come from and under which licence.
    pub licence: String,
    pub source: String,
    /// The ONNX file: input `[1, S, S, 3]` RGB in 0..=255 (float32), output `[1, 1, 17, 3]` as
    /// (y, x, score), y and x in [0, 1] of the input square.
    pub file: ModelFile,
}

impl DetectorManifest {
    /// The model's square input side S, pixels; checks the file's declared shapes.
    pub fn input_size(&self) -> Result<u32, InferError> {
        let bad = |what: String| InferError::Manifest(format!("manifest.json: detector `{}`: {what}", self.file.file));
        if self.keypoints != "coco17" {
            return Err(bad(format!("keypoints `{}`, expected `coco17`", self.keypoints)));
        }
        let [input] = &self.file.inputs[..] else { return Err(bad("expected one input".into())) };
        let [output] = &self.file.outputs[..] else { return Err(bad("expected one output".into())) };
        match (&input.shape[..], &output.shape[..]) {
            ([1, h, w, 3], [1, 1, COCO17_COUNT, 3]) if h == w && (32..=1024).contains(h) => Ok(*h as u32),
            (i, o) => Err(bad(format!("shapes {i:?} → {o:?}, expected [1, S, S, 3] → [1, 1, 17, 3]"))),
        }
    }
}

/// One keypoint of a detection: where in the crop (normalised, x right, y down, `[0, 1]`
/// across the window) and the model's confidence in `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CropKeypoint {
    pub at: Vec2,
    pub score: f32,
}

/// The detector, loaded and optimised once.
#[derive(Clone, Debug)]
pub struct KeypointDetector {
    model: OnnxModel,
    input_size: u32,
    manifest: DetectorManifest,
}

impl KeypointDetector {
    /// Loads the file `bytes` of `manifest`'s detector, checking its sha256.
    pub fn load(manifest: &DetectorManifest, bytes: &[u8]) -> Result<Self, InferError> {
        let input_size = manifest.input_size()?;
        let actual = sha256_hex(bytes);
        if actual != manifest.file.sha256 {
            return Err(InferError::Checksum {
                file: manifest.file.file.clone(),
                expected: manifest.file.sha256.clone(),
                actual,
            });
        }
        let model = OnnxModel::load(&manifest.model, bytes, &manifest.file.input_shapes())?;
        Ok(Self { model, input_size, manifest: manifest.clone() })
    }

    /// The square input side, pixels.
    pub fn input_size(&self) -> u32 {
        self.input_size
    }

    /// What was loaded.
    pub fn manifest(&self) -> &DetectorManifest {
        &self.manifest
    }

    /// Detections run so far.
    pub fn runs(&self) -> u64 {
        self.model.runs()
    }

    /// Runs the model on `crop`, `input_size²` RGB pixels (3 bytes each, rows top to bottom).
    pub fn detect(&self, crop: &[u8]) -> Result<[CropKeypoint; COCO17_COUNT], InferError> {
        let side = self.input_size as usize;
        if crop.len() != side * side * 3 {
            return Err(InferError::Model {
                model: self.manifest.model.clone(),
                message: format!("a crop of {} bytes, expected {side}×{side}×3", crop.len()),
            });
        }
        let input: Vec<f32> = crop.iter().map(|&v| f32::from(v)).collect();
        let out = self.model.run(&[&input])?.into_iter().next().unwrap_or_default();
        if out.len() != COCO17_COUNT * 3 {
            return Err(InferError::Model {
                model: self.manifest.model.clone(),
                message: format!("{} output numbers, expected 17 × 3", out.len()),
            });
        }
        Ok(std::array::from_fn(|k| {
            let (y, x, score) = (out[3 * k], out[3 * k + 1], out[3 * k + 2]);
            let finite = x.is_finite() && y.is_finite() && score.is_finite();
            CropKeypoint {
                at: if finite { Vec2::new(x, y) } else { Vec2::ZERO },
                score: if finite { score.clamp(0.0, 1.0) } else { 0.0 },
            }
        }))
    }
}
