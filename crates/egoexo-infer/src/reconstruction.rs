//! What a reconstruction is, below everything that makes one: the methods ([`Method`]), the
//! options ([`ReconstructOptions`]), the progress a job reports ([`Progress`], [`Stage`]) and
//! the result ([`Reconstruction`]: SMPL motion, joints, validity, the gates per observer).
//! Units: metres, seconds; world Y-up.

use std::fmt;

use egoexo_core::ego_features::TrackingMode;
use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_core::foot_contact::FootLift;
use egoexo_core::glam::Vec3;
use egoexo_core::motion::SmplMotion;
use egoexo_core::skeleton::NUM_JOINTS;
use serde::{Deserialize, Serialize};

use crate::passes::ExoMode;
use crate::plan::WindowOptions;
use crate::windows::WINDOW;

/// How to reconstruct.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Baseline: SMPL rest pose hung from the head, facing the head's heading.
    RestPose,
    /// Baseline: per-frame nearest neighbour over training ego features.
    NearestNeighbour,
    /// EgoNet's coarse pose alone (the paper's first stage; what the region proposal and the
    /// detector step project into the observers' images).
    EgoNet,
    /// The fusion network with every observer masked out.
    EgoOnly,
    /// The full method: gated exo rays fused with the ego stream.
    EgoExo,
    /// The fusion network with every valid ray's gate forced to 1 (ablation).
    EgoExoUngated,
}

impl Method {
    /// The name used in tables and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::RestPose => "rest-pose",
            Method::NearestNeighbour => "nearest-neighbour",
            Method::EgoNet => "egonet",
            Method::EgoOnly => "ego-only",
            Method::EgoExo => "ego-exo",
            Method::EgoExoUngated => "ego-exo-ungated",
        }
    }

    /// Whether the method runs the ONNX networks.
    pub fn uses_networks(self) -> bool {
        matches!(self, Method::EgoNet | Method::EgoOnly | Method::EgoExo | Method::EgoExoUngated)
    }

    /// How the method treats the observers' rays (`None` for the baselines and EgoNet alone,
    /// which run no exo pass).
    pub fn exo_mode(self) -> Option<ExoMode> {
        match self {
            Method::RestPose | Method::NearestNeighbour | Method::EgoNet => None,
            Method::EgoOnly => Some(ExoMode::Masked),
            Method::EgoExo => Some(ExoMode::Gated),
            Method::EgoExoUngated => Some(ExoMode::Ungated),
        }
    }

    /// Where the method's coarse pose comes from; methods with the same one can share an
    /// ego pass.
    pub fn coarse_pose(self) -> CoarsePose {
        match self {
            Method::RestPose => CoarsePose::RestPose,
            Method::NearestNeighbour => CoarsePose::NearestNeighbour,
            Method::EgoNet | Method::EgoOnly | Method::EgoExo | Method::EgoExoUngated => CoarsePose::EgoNet,
        }
    }
}

/// The coarse-pose source of a method, without the model or index behind it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CoarsePose {
    RestPose,
    NearestNeighbour,
    EgoNet,
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Options of one reconstruction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReconstructOptions {
    pub method: Method,
    /// Tracking mode; `None` takes what the wearer's devices allow
    /// ([`AlignedSession::tracking_mode`]).
    pub tracking: Option<TrackingMode>,
    /// Frames between window starts (overlapping windows are cross-faded).
    pub stride: usize,
    /// The paper's evaluation protocol: non-overlapping 96-frame segments, no cross-fade.
    pub non_overlapping: bool,
    /// Keep the feet out of the floor when the session knows its floor
    /// ([`AlignedSession::floor_y`]): legs whose feet the networks put through it are folded
    /// onto it ([`egoexo_core::foot_contact::lift_feet_above_floor`]).
    pub floor_contact: bool,
}

impl Default for ReconstructOptions {
    fn default() -> Self {
        Self { method: Method::EgoExo, tracking: None, stride: WINDOW / 2, non_overlapping: false, floor_contact: true }
    }
}

impl ReconstructOptions {
    /// How the timeline is cut into windows.
    pub fn windows(&self) -> WindowOptions {
        WindowOptions { stride: self.stride, non_overlapping: self.non_overlapping }
    }
}

/// Which pass a progress report is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// The ego pass: ego features and the coarse pose (EgoNet or a baseline), per window.
    Ego,
    /// The exo and fusion passes of one method (or, for a baseline, decoding its coarse
    /// pose), per window.
    Fusion(Method),
}

/// A progress report: `done` of `total` windows of a stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Progress {
    pub stage: Stage,
    pub done: usize,
    pub total: usize,
}

/// Gate values of one observer: per frame, per exo keypoint (0 where no valid ray).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObserverGates {
    pub observer_id: String,
    pub gates: Vec<[f32; EXO_KEYPOINT_COUNT]>,
}

/// A reconstruction on the aligned session's timeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reconstruction {
    pub method: Method,
    pub tracking: TrackingMode,
    /// Per-frame SMPL parameters (frames without valid tracking hold the nearest valid pose).
    pub motion: SmplMotion,
    /// World positions of the 24 joints per frame (metres).
    pub joints: Vec<[Vec3; NUM_JOINTS]>,
    /// Frames that were actually reconstructed (wearer tracking valid).
    pub valid: Vec<bool>,
    /// Frames where at least one observer contributed a ray with gate ≥ 0.5.
    pub exo_evidence: Vec<bool>,
    /// Per observer (session order), per frame, per keypoint gate values.
    pub gates: Vec<ObserverGates>,
    /// What the floor constraint did (`None`: not applied — no floor, or turned off).
    #[serde(default)]
    pub feet_lifted: Option<FootLift>,
}

impl Reconstruction {
    /// The reconstruction of frames `range` only (clamped), e.g. the one frame a live view
    /// shows out of its window; the motion's `start_ns` moves with its first frame.
    pub fn frames_slice(&self, range: std::ops::Range<usize>) -> Reconstruction {
        let start = range.start.min(self.joints.len());
        let end = range.end.clamp(start, self.joints.len());
        let slice = |len: usize| start.min(len)..end.min(len);
        let offset_ns = (start as f64 * 1e9 / f64::from(self.motion.fps)).round() as i64;
        Reconstruction {
            method: self.method,
            tracking: self.tracking,
            motion: SmplMotion {
                start_ns: self.motion.start_ns.saturating_add(offset_ns),
                poses: self.motion.poses[slice(self.motion.poses.len())].to_vec(),
                ..self.motion.clone()
            },
            joints: self.joints[start..end].to_vec(),
            feet_lifted: self.feet_lifted,
            valid: self.valid[slice(self.valid.len())].to_vec(),
            exo_evidence: self.exo_evidence[slice(self.exo_evidence.len())].to_vec(),
            gates: self
                .gates
                .iter()
                .map(|g| ObserverGates {
                    observer_id: g.observer_id.clone(),
                    gates: g.gates[slice(g.gates.len())].to_vec(),
                })
                .collect(),
        }
    }
}
