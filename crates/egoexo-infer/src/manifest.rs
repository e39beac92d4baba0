//! `models/manifest.json`: which ONNX files make up each tracking mode's networks, their
//! checksums and tensor shapes, and the feature layouts they were trained with.
//!
//! Loading refuses models trained on a different feature layout than this build computes,
//! so a stale model can never silently receive the wrong inputs.

use egoexo_core::ego_features::{EGO_FEATURE_DIM, EGO_FEATURE_LAYOUT_VERSION, EgoFeatureLayout, TrackingMode};
use egoexo_core::exo_keypoints::COCO17_COUNT;
use egoexo_core::gate_features::{GATE_FEATURE_LAYOUT_VERSION, GateFeatureLayout};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::InferError;
use crate::inputs::{EXO_TOKEN_DIM, EXO_TOKEN_LAYOUT_VERSION};
use crate::windows::WINDOW;

/// Version of the manifest format.
pub const MANIFEST_FORMAT_VERSION: u32 = 1;

/// A tensor's name and shape.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TensorSpec {
    pub name: String,
    pub shape: Vec<usize>,
}

/// One ONNX file.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelFile {
    /// Path relative to the models folder.
    pub file: String,
    /// Lowercase hex sha256 of the file.
    pub sha256: String,
    /// File size in bytes.
    pub bytes: u64,
    pub inputs: Vec<TensorSpec>,
    pub outputs: Vec<TensorSpec>,
}

/// The networks of a model set, by the names benches and tools use (`fusion_ego_only` is
/// optional: sets exported before it existed run the fusion with every observer masked).
pub const NETWORK_NAMES: [&str; 4] = ["egonet", "gate", "fusion", "fusion_ego_only"];

impl ModelSetManifest {
    /// The file of network `name` (one of [`NETWORK_NAMES`]), if the set has it.
    pub fn network(&self, name: &str) -> Option<&ModelFile> {
        match name {
            "egonet" => Some(&self.egonet),
            "gate" => Some(&self.gate),
            "fusion" => Some(&self.fusion),
            "fusion_ego_only" => self.fusion_ego_only.as_ref(),
            _ => None,
        }
    }

    /// The set's network files, in [`NETWORK_NAMES`] order.
    pub fn network_files(&self) -> impl Iterator<Item = &ModelFile> {
        [Some(&self.egonet), Some(&self.gate), Some(&self.fusion), self.fusion_ego_only.as_ref()].into_iter().flatten()
    }
}

impl ModelFile {
    /// The inputs' shapes, in declaration order.
    pub fn input_shapes(&self) -> Vec<Vec<usize>> {
        self.inputs.iter().map(|i| i.shape.clone()).collect()
    }
}

/// The fusion network's per-keypoint exo input ([`crate::inputs::fusion_exo_input`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExoTokenLayout {
    pub version: u32,
    /// Numbers per keypoint.
    pub dim: usize,
}

impl Default for ExoTokenLayout {
    /// Manifests written before the layout was recorded used v1 (ray endpoint and gate).
    fn default() -> Self {
        Self { version: 1, dim: 4 }
    }
}

/// The networks of one tracking mode: the offline ones (read out near the window's centre),
/// or a live variant trained to be read out `lookahead` frames before the window's newest frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelSetManifest {
    pub tracking: TrackingMode,
    /// Live variants: the read-out lookahead L (frames before the window's newest frame) the
    /// networks were trained for. `None`: the offline networks, which every recording uses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lookahead: Option<usize>,
    pub ego_feature_layout: EgoFeatureLayout,
    pub gate_feature_layout: GateFeatureLayout,
    #[serde(default)]
    pub exo_token_layout: ExoTokenLayout,
    /// Observer slots of the fusion network.
    pub max_observers: usize,
    /// Transformer width.
    pub hidden_dim: usize,
    pub egonet: ModelFile,
    pub gate: ModelFile,
    pub fusion: ModelFile,
    /// The fusion with every observer masked as its own graph (inputs `ego`, `egonet`; the
    /// same weights and numbers), which the ego-only method runs instead of the fusion on empty
    /// observer slots. Absent in sets exported before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fusion_ego_only: Option<ModelFile>,
}

/// The whole manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format_version: u32,
    /// Window length T (frames).
    pub window: usize,
    /// Frame rate the models were trained at.
    pub fps: f32,
    pub model_sets: Vec<ModelSetManifest>,
    /// The 2D keypoint detector for observers that bring video instead of keypoints; not one
    /// of [`Manifest::files`] (loaded only when a session needs it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detector: Option<DetectorManifest>,
    /// Free-form provenance: training data, subjects, command, commit, date, timings.
    #[serde(default)]
    pub training: serde_json::Value,
}

/// What is wrong with a `manifest.json`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ManifestError {
    #[error("manifest.json: {0}")]
    Json(String),
    #[error("manifest.json: format_version {found} is not supported (expected {MANIFEST_FORMAT_VERSION})")]
    FormatVersion { found: u32 },
    #[error("manifest.json: window {found} (this build uses {WINDOW})")]
    Window { found: usize },
    #[error("manifest.json: {points}-point live set has lookahead {lookahead}, expected below the window ({WINDOW})")]
    Lookahead { points: u8, lookahead: usize },
    #[error("manifest.json: two {points}-point sets with {}", .lookahead.map_or("no lookahead (offline)".to_string(), |l| format!("lookahead {l}")))]
    DuplicateSet { points: u8, lookahead: Option<usize> },
    #[error(
        "manifest.json: {points}-point models expect ego feature layout v{version} ({dim} numbers per frame), this build computes v{EGO_FEATURE_LAYOUT_VERSION} ({EGO_FEATURE_DIM}){}",
        if *.version < EGO_FEATURE_LAYOUT_VERSION {
            " (older models, trained before the per-frame wrist validity of v2: use the models shipped with this build, or retrain them as training/README.md says)"
        } else {
            " (models newer than this build: update egoexo)"
        }
    )]
    EgoLayout { points: u8, version: u32, dim: usize },
    #[error(
        "manifest.json: {points}-point gate expects gate feature layout v{version}, this build computes v{GATE_FEATURE_LAYOUT_VERSION}"
    )]
    GateLayout { points: u8, version: u32 },
    #[error(
        "manifest.json: {points}-point fusion expects exo token layout v{version} ({dim} numbers per keypoint), this build makes v{EXO_TOKEN_LAYOUT_VERSION} ({EXO_TOKEN_DIM}): retrain or use models made for this build"
    )]
    ExoLayout { points: u8, version: u32, dim: usize },
    #[error("manifest.json: {points}-point set has a mismatched ego layout")]
    EgoLayoutTracking { points: u8 },
    #[error("manifest.json: max_observers {found} out of 1..=16")]
    MaxObservers { found: usize },
    #[error("manifest.json: `{file}` is listed twice with different sha256")]
    ConflictingFile { file: String },
    #[error("manifest.json: detector `{file}`: keypoints `{found}`, expected `coco17`")]
    DetectorKeypoints { file: String, found: String },
    #[error("manifest.json: detector `{file}`: {inputs} inputs and {outputs} outputs, expected one of each")]
    DetectorTensors { file: String, inputs: usize, outputs: usize },
    #[error("manifest.json: detector `{file}`: shapes {input:?} → {output:?}, expected [1, S, S, 3] → [1, 1, 17, 3]")]
    DetectorShapes { file: String, input: Vec<usize>, output: Vec<usize> },
    #[error("manifest.json: no network `{network}` in the {points}-point set: expected one of {expected}")]
    NoNetwork { points: u8, network: String, expected: String },
}

impl Manifest {
    /// Parses and checks a manifest.
    pub fn from_json(bytes: &[u8]) -> Result<Self, InferError> {
        let manifest: Manifest = serde_json::from_slice(bytes).map_err(|e| ManifestError::Json(e.to_string()))?;
        manifest.check()?;
        Ok(manifest)
    }

    fn check(&self) -> Result<(), InferError> {
        if self.format_version != MANIFEST_FORMAT_VERSION {
            return Err(ManifestError::FormatVersion { found: self.format_version }.into());
        }
        if self.window != WINDOW {
            return Err(ManifestError::Window { found: self.window }.into());
        }
        for (i, set) in self.model_sets.iter().enumerate() {
            let mode = set.tracking.points();
            if let Some(lookahead) = set.lookahead
                && lookahead >= WINDOW
            {
                return Err(ManifestError::Lookahead { points: mode, lookahead }.into());
            }
            if self.model_sets[..i].iter().any(|s| s.tracking == set.tracking && s.lookahead == set.lookahead) {
                return Err(ManifestError::DuplicateSet { points: mode, lookahead: set.lookahead }.into());
            }
            if set.ego_feature_layout.version != EGO_FEATURE_LAYOUT_VERSION
                || set.ego_feature_layout.dim != EGO_FEATURE_DIM
            {
                return Err(ManifestError::EgoLayout {
                    points: mode,
                    version: set.ego_feature_layout.version,
                    dim: set.ego_feature_layout.dim,
                }
                .into());
            }
            if set.gate_feature_layout.version != GATE_FEATURE_LAYOUT_VERSION {
                return Err(ManifestError::GateLayout { points: mode, version: set.gate_feature_layout.version }.into());
            }
            let exo = set.exo_token_layout;
            if exo.version != EXO_TOKEN_LAYOUT_VERSION || exo.dim != EXO_TOKEN_DIM {
                return Err(ManifestError::ExoLayout { points: mode, version: exo.version, dim: exo.dim }.into());
            }
            if set.ego_feature_layout.tracking != set.tracking {
                return Err(ManifestError::EgoLayoutTracking { points: mode }.into());
            }
            if set.max_observers == 0 || set.max_observers > 16 {
                return Err(ManifestError::MaxObservers { found: set.max_observers }.into());
            }
        }
        if let Some(detector) = &self.detector {
            detector.input_size()?;
        }
        let files: Vec<&ModelFile> = self.model_sets.iter().flat_map(ModelSetManifest::network_files).collect();
        for (i, file) in files.iter().enumerate() {
            if files[..i].iter().any(|f| f.file == file.file && f.sha256 != file.sha256) {
                return Err(ManifestError::ConflictingFile { file: file.file.clone() }.into());
            }
        }
        Ok(())
    }

    /// The offline model set for a tracking mode, if shipped.
    pub fn model_set(&self, tracking: TrackingMode) -> Option<&ModelSetManifest> {
        self.model_set_for_points(tracking.points())
    }

    /// [`Manifest::model_set`] by tracking points (1 or 3), as a command line or page names it.
    pub fn model_set_for_points(&self, points: u8) -> Option<&ModelSetManifest> {
        self.model_sets.iter().find(|s| s.tracking.points() == points && s.lookahead.is_none())
    }

    /// Every file of every set once (live variants share the offline EgoNet), in set order.
    pub fn files(&self) -> Vec<&ModelFile> {
        let mut files: Vec<&ModelFile> = Vec::new();
        for file in self.model_sets.iter().flat_map(ModelSetManifest::network_files) {
            if !files.iter().any(|f| f.file == file.file) {
                files.push(file);
            }
        }
        files
    }
}

/// Lowercase hex sha256.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

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
        let file = || self.file.file.clone();
        if self.keypoints != "coco17" {
            return Err(ManifestError::DetectorKeypoints { file: file(), found: self.keypoints.clone() }.into());
        }
        let ([input], [output]) = (&self.file.inputs[..], &self.file.outputs[..]) else {
            let (inputs, outputs) = (self.file.inputs.len(), self.file.outputs.len());
            return Err(ManifestError::DetectorTensors { file: file(), inputs, outputs }.into());
        };
        match (&input.shape[..], &output.shape[..]) {
            ([1, h, w, 3], [1, 1, COCO17_COUNT, 3]) if h == w && (32..=1024).contains(h) => Ok(*h as u32),
            (i, o) => Err(ManifestError::DetectorShapes { file: file(), input: i.to_vec(), output: o.to_vec() }.into()),
        }
    }
}
