//! What the worker reports to the page: plain serde data (crosses to JS as plain objects).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// One file a models manifest lists.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelFileRef {
    /// Path relative to the models folder.
    pub file: String,
    /// Lowercase hex sha256 the file must have.
    pub sha256: String,
    pub bytes: u64,
}

/// The networks of one tracking mode.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelSetSummary {
    pub tracking_points: u8,
    pub max_observers: usize,
    pub hidden_dim: usize,
}

/// The loaded models.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelsSummary {
    pub model_sets: Vec<ModelSetSummary>,
    /// Total size of the ONNX files.
    pub bytes: u64,
}

/// One observer of an imported session.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ObserverSummary {
    pub id: String,
    /// Projection model and image size, e.g. `fisheye624 1408×1408`.
    pub camera: String,
    /// Timeline frames with at least one 2D keypoint.
    pub keypoint_frames: usize,
}

/// An imported session, on the models' timeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionSummary {
    pub name: String,
    /// What the input was recognised as (`.egoexo session`, `Nymeria sequence`, …).
    pub source: String,
    /// Frames of the aligned timeline.
    pub frames: usize,
    pub fps: f32,
    pub duration_s: f32,
    /// Wearer devices: `head`, and `left_wrist` / `right_wrist` when tracked.
    pub devices: Vec<String>,
    /// 1 (glasses) or 3 (glasses + wrists).
    pub tracking_points: u8,
    pub observers: Vec<ObserverSummary>,
    /// Whether the session carries ground-truth motion.
    pub ground_truth: bool,
    /// What the import noticed (each `file: message`).
    pub warnings: Vec<String>,
}

/// Errors against ground truth, where the session has it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Accuracy {
    /// Frames scored (reconstructed and with ground truth).
    pub frames: usize,
    pub ego_exo_mpjpe_cm: f64,
    pub ego_only_mpjpe_cm: Option<f64>,
}

/// A finished reconstruction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReconstructionSummary {
    pub method: String,
    pub tracking_points: u8,
    pub frames: usize,
    /// Frames with valid wearer tracking (the rest hold the nearest valid pose).
    pub valid_frames: usize,
    /// Frames where an observer ray had gate ≥ 0.5.
    pub exo_evidence_frames: usize,
    /// Per observer: frames where it contributed at least one ray.
    pub observer_ray_frames: BTreeMap<String, usize>,
    pub accuracy: Option<Accuracy>,
}

/// Which part of a reconstruction job a progress report is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum JobStage {
    /// Ego features and EgoNet's coarse pose, per window.
    EgoPass,
    /// Regions, rays, gates and fusion, per window.
    Fusion,
    /// The ego-only reconstruction for the comparison overlay.
    EgoOnlyOverlay,
}

impl JobStage {
    /// What the progress bar says.
    pub fn label(self) -> &'static str {
        match self {
            JobStage::EgoPass => "ego pass",
            JobStage::Fusion => "exo fusion",
            JobStage::EgoOnlyOverlay => "ego-only overlay",
        }
    }
}

/// Progress of a whole job: `done` of `total` window steps over every pass and stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct JobProgress {
    pub stage: JobStage,
    pub done: usize,
    pub total: usize,
}
