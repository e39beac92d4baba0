//! A session resampled onto one fixed-rate timeline: the reconstruction engine's input.
//!
//! [`AlignedSession`] is plain data. `egoexo_session::align` builds it from a recorded
//! session (every stream resampled onto one timeline); the engine, the training shards and the
//! viewer's scene read it; a live capture can fill it frame by frame. Frame `i` of a
//! [`Timeline`] is at `start_ns + round(i · 1e9 / fps)`.
//!
//! Conventions as in the crate docs: poses are `T_world_device` in the Y-up world (metres),
//! head devices in the CPF frame, cameras in the OpenCV/Aria optical frame.

use serde::{Deserialize, Serialize};

use crate::camera::CameraCalibration;
use crate::ego_features::TrackingMode;
use crate::exo_keypoints::{EXO_KEYPOINT_COUNT, Keypoint2d};
use crate::glam::Vec3;
use crate::metrics::MetricsAccumulator;
use crate::rigid::RigidTransform;
use crate::skeleton::{NUM_JOINTS, SmplPose, SmplSkeleton};

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
    /// Timestamp of frame `i`, nanoseconds (saturating at the ends of `i64`).
    pub fn timestamp_ns(&self, i: usize) -> i64 {
        let offset = (i as f64 * 1e9 / f64::from(self.fps)).round() as i64;
        self.start_ns.saturating_add(offset)
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

impl AlignedTrajectory {
    /// How much of the timeline it covers: the tracked fraction of frames and the longest run
    /// of untracked frames.
    pub fn coverage(&self) -> TrackCoverage {
        TrackCoverage {
            tracked_fraction: self.valid.iter().filter(|&&v| v).count() as f32 / self.valid.len().max(1) as f32,
            longest_gap_frames: longest_gap_frames(&self.valid),
        }
    }
}

/// What [`AlignedTrajectory::coverage`] reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackCoverage {
    /// Tracked frames / timeline frames, in [0, 1].
    pub tracked_fraction: f32,
    /// The longest run of untracked frames.
    pub longest_gap_frames: usize,
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

/// Least fraction of the head's tracked frames on which both wrists must be tracked for
/// [`AlignedSession::tracking_choice`] to call them complete (wrist devices); below it the
/// choice carries a note that the wrists come and go.
pub const THREE_POINT_MIN_WRIST_COVERAGE: f32 = 0.98;

/// The default tracking mode of a session, with a note when its wrists are only partly there.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TrackingChoice {
    pub mode: TrackingMode,
    /// Set when wrists exist but are tracked on only part of the frames (or only one
    /// exists): what the 3-point model will do with them.
    pub reason: Option<String>,
}

/// The longest run of `false` in `valid`, in frames.
pub fn longest_gap_frames(valid: &[bool]) -> usize {
    let (mut longest, mut run) = (0, 0);
    for &v in valid {
        run = if v { 0 } else { run + 1 };
        longest = longest.max(run);
    }
    longest
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
    /// The floor's height (world Y, metres), when the session knows it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub floor_y: Option<f32>,
}

impl AlignedSession {
    /// The session on frames `range` of its timeline only (clamped to it): what a live
    /// reconstruction sees of a window. Coverage is not carried over (it describes the whole
    /// session).
    pub fn frames_slice(&self, range: std::ops::Range<usize>) -> AlignedSession {
        let start = range.start.min(self.timeline.frames);
        let end = range.end.clamp(start, self.timeline.frames);
        let trajectory = |t: &AlignedTrajectory| AlignedTrajectory {
            poses: t.poses[start..end].to_vec(),
            valid: t.valid[start..end].to_vec(),
        };
        AlignedSession {
            name: self.name.clone(),
            timeline: Timeline {
                start_ns: self.timeline.timestamp_ns(start),
                fps: self.timeline.fps,
                frames: end - start,
            },
            head: trajectory(&self.head),
            left_wrist: self.left_wrist.as_ref().map(trajectory),
            right_wrist: self.right_wrist.as_ref().map(trajectory),
            observers: self
                .observers
                .iter()
                .map(|o| AlignedObserver {
                    id: o.id.clone(),
                    camera: o.camera,
                    head: trajectory(&o.head),
                    keypoints: o.keypoints[start..end].to_vec(),
                    context_features: o.context_features.as_ref().map(|c| c[start..end].to_vec()),
                })
                .collect(),
            skeleton: self.skeleton.clone(),
            head_joint_in_device: self.head_joint_in_device,
            ground_truth: self.ground_truth.as_ref().map(|gt| AlignedGroundTruth {
                poses: gt.poses[start..end].to_vec(),
                valid: gt.valid[start..end].to_vec(),
                occluded: gt
                    .occluded
                    .iter()
                    .map(|o| o.get(start..end).map_or_else(|| vec![0; end - start], <[u16]>::to_vec))
                    .collect(),
            }),
            coverage: Vec::new(),
            floor_y: self.floor_y,
        }
    }

    /// The tracking mode to reconstruct with by default ([`AlignedSession::tracking_choice`]).
    pub fn tracking_mode(&self) -> TrackingMode {
        self.tracking_choice().mode
    }

    /// Whether either wrist trajectory exists (3-point tracking can be asked for: a wrist
    /// that is missing, or untracked on a frame, reaches the network as not tracked).
    pub fn has_wrists(&self) -> bool {
        self.left_wrist.is_some() || self.right_wrist.is_some()
    }

    /// Per wrist (left, right): the fraction of the head's tracked frames on which it is
    /// tracked too; `None` for a wrist the session does not have.
    pub fn wrist_coverage(&self) -> [Option<f32>; 2] {
        let head: Vec<usize> = (0..self.head.valid.len()).filter(|&f| self.head.valid[f]).collect();
        [&self.left_wrist, &self.right_wrist].map(|w| {
            w.as_ref().map(|w| {
                let both = head.iter().filter(|&&f| w.valid.get(f).copied().unwrap_or(false)).count();
                both as f32 / head.len().max(1) as f32
            })
        })
    }

    /// The tracking mode to reconstruct with by default: 3-point whenever the session has a
    /// wrist (ego feature layout v2 tells the network, frame by frame, which wrists are
    /// tracked, so hand-tracking wrists that come and go are used where they exist), else
    /// 1-point. The note says how much of the time the wrists are there when that is not
    /// (nearly) always.
    pub fn tracking_choice(&self) -> TrackingChoice {
        let [left, right] = self.wrist_coverage();
        let percent = |c: f32| format!("{:.0}%", c * 100.0);
        let reason = match (left, right) {
            (Some(l), Some(r)) if l >= THREE_POINT_MIN_WRIST_COVERAGE && r >= THREE_POINT_MIN_WRIST_COVERAGE => None,
            (Some(l), Some(r)) => Some(format!(
                "the wrists are tracked on {} (left) and {} (right) of the head's frames: the 3-point model uses them where they are and the head alone elsewhere",
                percent(l),
                percent(r)
            )),
            (Some(c), None) | (None, Some(c)) => Some(format!(
                "only the {} wrist is tracked ({} of the head's frames): the 3-point model reads the other as never tracked",
                if left.is_some() { "left" } else { "right" },
                percent(c)
            )),
            (None, None) => return TrackingChoice { mode: TrackingMode::OnePoint, reason: None },
        };
        TrackingChoice { mode: TrackingMode::ThreePoint, reason }
    }

    /// Whether the wearer is reconstructable at `frame`: the head is tracked. (Wrists, in
    /// 3-point mode, may come and go: their per-frame validity reaches the network.)
    pub fn wearer_tracked(&self, frame: usize) -> bool {
        self.head.valid.get(frame).copied().unwrap_or(false)
    }

    /// MPJPE (cm) of per-frame world joints (metres, on this timeline) against the ground
    /// truth, over the frames where both the truth and `valid` hold; `None` without ground
    /// truth or without such frames.
    pub fn ground_truth_mpjpe_cm(&self, joints: &[[Vec3; NUM_JOINTS]], valid: &[bool]) -> Option<f64> {
        let gt = self.ground_truth.as_ref()?;
        let frames = joints.len().min(gt.poses.len()).min(valid.len()).min(gt.valid.len());
        let truth: Vec<_> = gt.poses[..frames].iter().map(|p| self.skeleton.forward_kinematics(p).positions).collect();
        let selected: Vec<bool> = (0..frames).map(|f| valid[f] && gt.valid[f]).collect();
        let mut metrics = MetricsAccumulator::new();
        metrics.add_segment(&joints[..frames], &truth, self.timeline.fps, Some(&selected)).ok()?;
        metrics.finish().map(|m| m.mpjpe_cm)
    }
}
