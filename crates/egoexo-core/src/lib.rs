//! The pure-Rust core of egoexo: every transform the training data, the CLI, the Web Worker
//! and the tests share.
//!
//! # Invariants
//! - No I/O, no threads, no clock: every function is a pure computation on values it is
//!   given, so the same code runs natively and in `wasm32-unknown-unknown`.
//! - Geometry exists once, here. Python (training) and JS (the page) never re-implement it.
//! - Bad numeric input (NaN, mismatched lengths, degenerate rotations) gives an `Err` or a
//!   documented, finite fallback — never a panic.
//!
//! # Conventions (all modules)
//! - Units: metres, seconds, radians; pixels for image coordinates.
//! - World frame: right-handed, **Y up** (gravity along −Y). Floor height is not assumed.
//! - `T_a_b` (written `t_a_b` in code) is a [`RigidTransform`] that maps points expressed in
//!   frame `b` into frame `a`: `p_a = T_a_b · p_b`. Composition chains frames:
//!   `T_a_c = T_a_b * T_b_c`.
//! - Rotation matrices act on column vectors (`v' = R v`); quaternions are unit `glam::Quat`.
//! - Cameras use the OpenCV/Aria optical frame: +X right, +Y down, +Z forward. Pixel
//!   coordinates put the centre of the top-left pixel at (0, 0).
//! - The head-device frame (a wearer's or observer's glasses, after import) is the Aria
//!   "central pupil frame" convention: +X left, +Y up, +Z forward out of the face.
//! - The SMPL body frame: Y up, the body faces +Z, the subject's left is +X.
//!
//! Floating point: the public API is `f32` (what the networks consume); numerically delicate
//! iterations (fisheye unprojection, metric accumulation) run in `f64` internally.

pub mod aligned;
pub mod association;
pub mod camera;
pub mod crop;
pub mod ego_features;
pub mod euler;
pub mod exo_keypoints;
pub mod foot_contact;
pub mod gate_features;
pub mod metrics;
pub mod motion;
pub mod rays;
pub mod region;
pub mod rigid;
pub mod rotation;
pub mod skeleton;
pub mod xr;

pub use aligned::{AlignedSession, Timeline};
pub use camera::{CameraCalibration, CameraError, Fisheye624, Pinhole, Projection};
pub use crop::CropWindow;
pub use ego_features::{EgoFeatureLayout, EgoTrajectories, TrackingMode, WristTrack};
pub use euler::{Axis, EulerOrder};
pub use exo_keypoints::{EXO_KEYPOINT_COUNT, ExoKeypoint, Keypoint2d};
pub use metrics::{MetricsAccumulator, MotionMetrics};
pub use motion::SmplMotion;
pub use rays::{CanonicalRay, canonicalize_ray};
pub use region::{BoundingBox, NotVisibleReason, RegionProposal, propose_region};
pub use rigid::RigidTransform;
pub use rotation::Rot6d;
pub use skeleton::{JointTransforms, SmplJoint, SmplPose, SmplSkeleton};

#[cfg(all(test, target_arch = "wasm32"))]
wasm_bindgen_test::wasm_bindgen_test_configure!(run_in_browser);

/// Re-exported so downstream crates use the exact same vector types.
pub use glam;
