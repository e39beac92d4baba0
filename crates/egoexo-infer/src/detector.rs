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
use crate::manifest::sha256_hex;
use crate::models::OnnxModel;

pub use crate::manifest::DetectorManifest;

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
