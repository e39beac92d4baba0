//! The in-memory session model: what every importer produces, what `.egoexo` stores, what the
//! simulator writes and what reconstruction reads (after [`crate::align`](mod@crate::align)).
//!
//! Conventions: timestamps are nanoseconds on the session's one clock; poses are
//! `T_world_device` in a Y-up world (metres); device frames are CPF (+X left, +Y up,
//! +Z forward); cameras are OpenCV/Aria optical frames (see `egoexo_core::camera`).
//! Importers convert from their source conventions (Aria: Z-up world, device = left SLAM
//! camera, microseconds) into these before anything else sees the data.

use egoexo_core::camera::CameraCalibration;
use egoexo_core::ego_features::TrackingMode;
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::Vec3;
use egoexo_core::motion::SmplMotion;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE, NUM_JOINTS, SkeletonError, SmplSkeleton};
use serde::{Deserialize, Serialize};

pub use crate::placement::Placement;

/// A recording: one wearer, zero or more observers, subject info, optional ground truth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Session {
    /// Human-readable name (folder or file stem, or the simulator's clip id).
    pub name: String,
    pub wearer: Wearer,
    pub observers: Vec<Observer>,
    pub subject: SubjectInfo,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_truth: Option<GroundTruth>,
    /// The floor's height and how it was found ([`crate::floor`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub floor: Option<Floor>,
}

/// A device trajectory: strictly increasing timestamps with one `T_world_device` each.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Trajectory {
    pub timestamps_ns: Vec<i64>,
    pub poses: Vec<RigidTransform>,
}

impl Trajectory {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.timestamps_ns.len()
    }

    /// No samples.
    pub fn is_empty(&self) -> bool {
        self.timestamps_ns.is_empty()
    }

    /// `(first, last)` timestamp, if any.
    pub fn time_range_ns(&self) -> Option<(i64, i64)> {
        Some((*self.timestamps_ns.first()?, *self.timestamps_ns.last()?))
    }
}

/// The person whose motion is reconstructed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Wearer {
    /// Glasses (CPF frame).
    pub head: Trajectory,
    /// Left wrist (3-point tracking): `T_world_wrist` where it was tracked. A wrist device
    /// reports it throughout; hand tracking only while the hand is seen, so its samples come
    /// and go (untracked samples are left out; see [`WristSource`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub left_wrist: Option<Trajectory>,
    /// Right wrist, as the left.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub right_wrist: Option<Trajectory>,
    /// Where the wrist trajectories come from.
    #[serde(default, skip_serializing_if = "WristSource::is_devices")]
    pub wrist_source: WristSource,
    /// SMPL head joint in the head-device frame, metres (root recovery's offset).
    #[serde(default = "default_head_joint_in_device")]
    pub head_joint_in_device: Vec3,
}

/// Where a wearer's wrist poses come from. Wrist poses are SMPL wrist-joint frames (at the
/// rest pose the left hand points along +X, the right along −X, palms −Y), whatever the
/// source.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum WristSource {
    /// Wrist devices (wristbands, controllers, the simulator): measured poses.
    #[default]
    Devices,
    /// MPS hand tracking of the wearer's glasses: wrists only while the hands are seen.
    HandTracking {
        /// The file read (as named in import messages).
        file: String,
        form: HandTrackingForm,
        orientation: WristOrientation,
    },
}

impl WristSource {
    /// Wrist devices (the default, not written to files).
    pub fn is_devices(&self) -> bool {
        matches!(self, WristSource::Devices)
    }

    /// How the orientation the networks receive was obtained.
    pub fn orientation(&self) -> WristOrientation {
        match self {
            WristSource::Devices => WristOrientation::Device,
            WristSource::HandTracking { orientation, .. } => *orientation,
        }
    }

    /// In words.
    pub fn describe(&self) -> String {
        match self {
            WristSource::Devices => "wrist devices".into(),
            WristSource::HandTracking { form, orientation, .. } => {
                format!("{}; orientation {}", form.describe(), orientation.describe())
            }
        }
    }
}

fn default_head_joint_in_device() -> Vec3 {
    DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE
}

impl Wearer {
    /// The tracking mode the wearer's devices allow ([`TrackingMode::for_devices`]).
    pub fn tracking_mode(&self) -> TrackingMode {
        TrackingMode::for_devices(self.left_wrist.is_some(), self.right_wrist.is_some())
    }
}

/// A person whose glasses' RGB camera sees the wearer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Observer {
    /// Unique within the session (`"observer-1"`, an Aria serial, …).
    pub id: String,
    /// Glasses (CPF frame).
    pub head: Trajectory,
    /// The RGB camera: intrinsics, image size and `T_device_camera` (device = CPF).
    pub camera: CameraCalibration,
    /// 2D detections of the wearer in this observer's images.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keypoints: Option<KeypointTrack>,
    /// An exo video to run a detector on later (in the browser).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<VideoRef>,
    /// Optional per-frame image context features (the paper's DINOv3 CLS token).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context_features: Option<ContextFeatureTrack>,
    /// Its world, clock and mount against the session's, and any registration
    /// ([`crate::placement`]); the default: a worn device in the session's world and clock.
    #[serde(default, skip_serializing_if = "Placement::is_default")]
    pub placement: Placement,
}

/// Per-frame COCO-17 detections (pixels in the observer's RGB image, scores in [0, 1]).
/// A `None` keypoint was not detected.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct KeypointTrack {
    pub timestamps_ns: Vec<i64>,
    pub frames: Vec<[Option<Keypoint2d>; COCO17_COUNT]>,
}

/// A video file of an observer's RGB stream.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VideoRef {
    /// Path relative to the session root.
    pub path: String,
    /// Session-clock timestamp of the video's first frame, nanoseconds.
    pub start_ns: i64,
    /// Session-clock time of every frame in presentation order, nanoseconds, when the
    /// recording gave them (Aria exports: each frame's capture time); empty: the first frame at
    /// `start_ns` and the rest at the MP4's own presentation times after it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub frame_times_ns: Vec<i64>,
}

/// Per-frame context feature vectors, row-major `len × dim`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ContextFeatureTrack {
    pub timestamps_ns: Vec<i64>,
    pub dim: usize,
    pub values: Vec<f32>,
}

/// What is known of the wearer's body.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SubjectInfo {
    /// Stature (soles to top of head), metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_m: Option<f32>,
    /// SMPL shape coefficients, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub betas: Option<Vec<f32>>,
    /// Rest joints regressed from an SMPL model for `betas` (metres, SMPL body frame). Without
    /// them, the mean shape scaled to `height_m` is used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rest_joints: Option<[Vec3; NUM_JOINTS]>,
}

impl SubjectInfo {
    /// The skeleton to reconstruct with: explicit rest joints, else the mean shape scaled to
    /// the stature, else the mean shape.
    pub fn skeleton(&self) -> Result<SmplSkeleton, SkeletonError> {
        match (&self.rest_joints, self.height_m) {
            (Some(joints), _) => SmplSkeleton::from_rest_joints(*joints),
            (None, Some(h)) => SmplSkeleton::mean_shape_for_stature(h),
            (None, None) => Ok(SmplSkeleton::mean_shape()),
        }
    }
}

/// Reference motion for evaluation and overlays.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    /// The wearer's true SMPL motion.
    pub motion: SmplMotion,
    /// Which exo keypoints were occluded, per observer (simulated sessions label this).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub occlusion: Vec<ObserverOcclusion>,
}

/// Occlusion labels of one observer on the ground-truth motion's frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObserverOcclusion {
    pub observer_id: String,
    /// One mask per ground-truth frame: bit `k` set = exo keypoint `k` (network order, see
    /// `egoexo_core::exo_keypoints::ExoKeypoint`) was occluded in this observer's view.
    pub occluded: Vec<u16>,
}

/// Where the floor is.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Floor {
    /// Height of the floor plane, metres (session world Y).
    pub height_m: f32,
    pub source: FloorSource,
}

/// How the floor height was found.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FloorSource {
    /// MPS semidense points: `points` well-constrained points in the floor's band.
    SemidensePoints { file: String, points: u64 },
    /// The standing head height minus the glasses' height above the soles for `stature_m`
    /// (`stature_known`: from the subject info, else the mean shape's).
    StandingHead { standing_head_m: f32, stature_m: f32, stature_known: bool },
    /// The ground-truth body's feet (simulated sessions, datasets with fitted bodies).
    GroundTruth,
}

impl FloorSource {
    /// In words, for `inspect` and the page.
    pub fn describe(&self) -> String {
        match self {
            FloorSource::SemidensePoints { file, points } => {
                format!("semidense points ({points} well-constrained points at the floor, {file})")
            }
            FloorSource::StandingHead { standing_head_m, stature_m, stature_known } => format!(
                "standing head height {standing_head_m:.2} m minus the glasses' height for a {stature_m:.2} m {}",
                if *stature_known { "stature" } else { "mean-shape stature (no stature given)" }
            ),
            FloorSource::GroundTruth => "the ground-truth body's feet".into(),
        }
    }
}

/// Which published form a hand tracking file has.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HandTrackingForm {
    /// `wrist_and_palm_poses.csv` without normals.
    WristAndPalmV1,
    /// `wrist_and_palm_poses.csv` with wrist and palm normals.
    WristAndPalmV2,
    /// `hand_tracking_results.csv`: landmarks and `T_device_wrist`.
    HandTrackingResults,
}

impl HandTrackingForm {
    /// A human-readable name.
    pub fn describe(self) -> &'static str {
        match self {
            HandTrackingForm::WristAndPalmV1 => "MPS wrist_and_palm_poses.csv v1 (positions)",
            HandTrackingForm::WristAndPalmV2 => "MPS wrist_and_palm_poses.csv v2 (positions and normals)",
            HandTrackingForm::HandTrackingResults => "MPS hand_tracking_results.csv (T_device_wrist)",
        }
    }
}

/// How a wrist's orientation was obtained.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WristOrientation {
    /// Measured by a wrist device.
    Device,
    /// Hand direction and MPS's wrist pose (−Y of `T_device_wrist` as the palm normal).
    FromWristPose,
    /// Hand direction and the file's wrist (or palm) normal.
    FromNormals,
    /// Hand direction measured; the palm is assumed to face the floor.
    PalmDownAssumed,
}

impl WristOrientation {
    /// What the networks receive, in words.
    pub fn describe(self) -> &'static str {
        match self {
            WristOrientation::Device => "measured by the wrist devices",
            WristOrientation::FromWristPose => "from the hand direction and MPS's wrist pose",
            WristOrientation::FromNormals => "from the hand direction and the wrist normal",
            WristOrientation::PalmDownAssumed => {
                "hand direction measured, palm assumed to face the floor (the file has no normals)"
            }
        }
    }
}
