//! Every manifest object's keys, in one place: the reader warns about any other key
//! ("unknown field … ignored"), and the writer writes no other (the round-trip tests read
//! every written manifest back without a warning). `docs/session-format.md`'s schema lists the
//! same keys.

/// A one-wearer session's manifest (versions 1–2).
pub(super) const SESSION: &[&str] = &[
    "format",
    "version",
    "name",
    "created_by",
    "conventions",
    "subject",
    "wearer",
    "observers",
    "ground_truth",
    "floor",
];
/// A capture's manifest (version 3).
pub(super) const CAPTURE: &[&str] =
    &["format", "version", "name", "created_by", "conventions", "participants", "views", "floor"];
/// `subject` (and a participant's `subject`).
pub(super) const SUBJECT: &[&str] = &["height_m", "betas", "rest_joints"];
/// `wearer` (versions 1–2).
pub(super) const WEARER: &[&str] = &["head", "left_wrist", "right_wrist", "head_joint_in_device", "wrist_source"];
/// `observers[i]` (versions 1–2).
pub(super) const OBSERVER: &[&str] =
    &["id", "trajectory", "pose", "placement", "camera", "keypoints", "video", "context_features"];
/// `participants[i]` (version 3).
pub(super) const PARTICIPANT: &[&str] = &[
    "id",
    "reconstruct",
    "head",
    "left_wrist",
    "right_wrist",
    "wrist_source",
    "head_joint_in_device",
    "camera",
    "video",
    "context_features",
    "subject",
    "ground_truth",
    "pose",
    "placement",
];
/// `views[i]` (version 3).
pub(super) const VIEW: &[&str] = &["observer", "target", "keypoints", "people"];
/// A camera (`observers[i].camera`, `participants[i].camera`).
pub(super) const CAMERA: &[&str] = &["model", "params", "width", "height", "t_device_camera", "valid_radius_px"];
/// `ground_truth` (and a participant's).
pub(super) const GROUND_TRUTH: &[&str] = &["motion", "occlusion_observers"];
/// A static camera's file in the multi-device folder layout (`static_camera.json`).
pub(super) const STATIC_CAMERA: &[&str] = &["camera", "pose", "placement"];
