//! Time alignment: every stream of a [`Session`](crate::model::Session) resampled onto one
//! fixed-rate timeline — what reconstruction, the simulator's shards and the viewer consume.
//!
//! Conventions as in [`crate::model`]. Frame `i` of a [`Timeline`] is at
//! `start_ns + round(i · 1e9 / fps)`.

use egoexo_core::camera::CameraCalibration;
use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, Keypoint2d};
use egoexo_core::glam::Vec3;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{SmplPose, SmplSkeleton};
use serde::{Deserialize, Serialize};

/// Default output rate, frames per second (the networks are trained at this rate).
pub const DEFAULT_FPS: f32 = 30.0;

/// A fixed-rate timeline on the session clock.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Timeline {
    /// Timestamp of frame 0, nanoseconds.
    pub start_ns: i64,
    /// Frames per second.
    pub fps: f32,
    /// Number of frames.
    pub frames: usize,
}

impl Timeline {
    /// Timestamp of frame `i`, nanoseconds.
    pub fn timestamp_ns(&self, i: usize) -> i64 {
        self.start_ns + (i as f64 * 1e9 / f64::from(self.fps)).round() as i64
    }
}

/// A trajectory on the timeline. Frames not covered by the source (outside its time range,
/// or inside a gap longer than the bridging limit) are invalid and hold the identity pose —
/// consumers must check `valid`; nothing is invented.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AlignedTrajectory {
    pub poses: Vec<RigidTransform>,
    pub valid: Vec<bool>,
}

/// One observer on the timeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlignedObserver {
    pub id: String,
    pub camera: CameraCalibration,
    pub head: AlignedTrajectory,
    /// The K = 13 exo keypoints per frame (mapped from COCO-17); `None` = no detection within
    /// tolerance of the frame time, or that keypoint not detected.
    pub keypoints: Vec<[Option<Keypoint2d>; EXO_KEYPOINT_COUNT]>,
    /// Context feature vector per frame, when the session has them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context_features: Option<Vec<Option<Vec<f32>>>>,
}

/// Ground truth on the timeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlignedGroundTruth {
    pub poses: Vec<SmplPose>,
    pub valid: Vec<bool>,
    /// Per observer (same order as `AlignedSession::observers`), per frame: occlusion bitmask
    /// of the 13 exo keypoints (0 when unlabelled).
    pub occluded: Vec<Vec<u16>>,
}

/// How much of the timeline a stream covers.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreamCoverage {
    /// `"wearer/head"`, `"observer-1/keypoints"`, …
    pub stream: String,
    pub valid_frames: usize,
    pub frames: usize,
}

/// A session resampled onto one timeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlignedSession {
    pub name: String,
    pub timeline: Timeline,
    pub head: AlignedTrajectory,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub left_wrist: Option<AlignedTrajectory>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub right_wrist: Option<AlignedTrajectory>,
    pub observers: Vec<AlignedObserver>,
    /// The wearer's skeleton (from the subject info).
    pub skeleton: SmplSkeleton,
    /// SMPL head joint in the head-device frame, metres.
    pub head_joint_in_device: Vec3,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_truth: Option<AlignedGroundTruth>,
    pub coverage: Vec<StreamCoverage>,
}
