//! The per-frame egocentric feature vector `x_t^ego` (paper § Ego-Guided Wearer Localization),
//! layout version [`EGO_FEATURE_LAYOUT_VERSION`].
//!
//! Units: metres, metres per second, radians. Input poses are `T_world_device` of head-device
//! frames in the CPF convention (+X left, +Y up, +Z forward) in a Y-up world.
//!
//! # The window frame
//! Features are computed per window (the networks see 96-frame windows). The *window frame*
//! `W` has its origin at the head device's position at the window's first frame and is
//! rotated about world +Y by that frame's heading (see [`heading_yaw`]); its Y axis is world
//! up. Every position, orientation and velocity below is expressed in `W`, which removes the
//! wearer's absolute position and facing direction (the networks' root-orientation output is
//! in `W` too; `T_world_window` maps it back). Heading canonicalisation is this project's
//! choice on top of the paper's normalisation: the training set is small, and a model should
//! not have to learn that walking north and walking east are the same motion.
//!
//! # Layout v2 (62 numbers per frame)
//! | slots | content |
//! |---|---|
//! | 0..18 | head block |
//! | 18..36 | left-wrist block (zero where the left wrist is not tracked, and in 1-point mode) |
//! | 36..54 | right-wrist block (likewise) |
//! | 54..60 | horizontal displacement encoding |
//! | 60, 61 | left, right wrist tracked at this frame (1 or 0; 0 in 1-point mode) |
//!
//! Each 18-number device block: `0..6` orientation `R_W_device` as [`Rot6d`]; `6..12`
//! frame-to-frame rotation `R_{t−1}ᵀ R_t` as 6D (identity at a sequence's first frame);
//! `12..15` position; `15..18` linear velocity (backward difference × fps, m/s; zero at a
//! sequence's first frame). The head position is relative to the window's first frame; wrist
//! positions are relative to the head at the same frame (both in `W` axes). A wrist tracked
//! at `t` but not at `t − 1` (it just came into the glasses' view) starts like a sequence:
//! identity rotation step, zero velocity.
//!
//! v1 (60 numbers) had no validity slots: a 3-point model read both wrists on every frame,
//! so a session whose wrists come and go (hand tracking) had to fall back to 1-point. Models
//! trained on v1 are refused by the manifest check.
//!
//! The displacement encoding (the paper's 6-D XY-plane displacement; our horizontal plane is
//! XZ): with `d = (dx, dy, dz)` the head position in `W`: `[dx, dz, dx_h, dz_h, √(dx²+dz²), dy]`
//! where `(dx_h, dz_h)` is the same horizontal displacement seen from the current heading.

use std::ops::Range;

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::rigid::RigidTransform;
use crate::rotation::Rot6d;

/// Version of the feature layout documented above; recorded in the models' manifest.
pub const EGO_FEATURE_LAYOUT_VERSION: u32 = 2;
/// Numbers per frame.
pub const EGO_FEATURE_DIM: usize = 62;
/// Numbers per device block.
pub const DEVICE_BLOCK_DIM: usize = 18;

/// Which wearer devices are tracked.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackingMode {
    /// Head only (glasses).
    OnePoint,
    /// Head and both wrists.
    ThreePoint,
}

impl TrackingMode {
    /// The mode a wearer's devices allow: 3-point when a wrist is tracked (ego feature layout
    /// v2 marks a missing or untracked wrist per frame), else 1-point.
    /// The one place this rule is written; sessions, the engine, the CLI and the worker ask
    /// here.
    pub fn for_devices(left_wrist: bool, right_wrist: bool) -> TrackingMode {
        if left_wrist || right_wrist { TrackingMode::ThreePoint } else { TrackingMode::OnePoint }
    }

    /// The paper's name for the mode: 1 or 3 points.
    pub fn points(self) -> u8 {
        match self {
            TrackingMode::OnePoint => 1,
            TrackingMode::ThreePoint => 3,
        }
    }
}

/// The feature layout a model was trained with (serialised into the models' manifest).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct EgoFeatureLayout {
    pub version: u32,
    pub dim: usize,
    pub tracking: TrackingMode,
    /// False in 1-point mode: the wrist slots are zero.
    pub wrists_present: bool,
}

impl EgoFeatureLayout {
    /// Head block slots.
    pub const HEAD: Range<usize> = 0..18;
    /// Left-wrist block slots.
    pub const LEFT_WRIST: Range<usize> = 18..36;
    /// Right-wrist block slots.
    pub const RIGHT_WRIST: Range<usize> = 36..54;
    /// Displacement encoding slots.
    pub const DISPLACEMENT: Range<usize> = 54..60;
    /// Left wrist tracked (1) or not (0).
    pub const LEFT_WRIST_VALID: usize = 60;
    /// Right wrist tracked (1) or not (0).
    pub const RIGHT_WRIST_VALID: usize = 61;
    /// Within a block: orientation (6D).
    pub const BLOCK_ORIENTATION: Range<usize> = 0..6;
    /// Within a block: frame-to-frame rotation (6D).
    pub const BLOCK_ANGULAR_VELOCITY: Range<usize> = 6..12;
    /// Within a block: position.
    pub const BLOCK_POSITION: Range<usize> = 12..15;
    /// Within a block: linear velocity.
    pub const BLOCK_VELOCITY: Range<usize> = 15..18;

    /// The current layout for a tracking mode.
    pub fn new(tracking: TrackingMode) -> Self {
        Self {
            version: EGO_FEATURE_LAYOUT_VERSION,
            dim: EGO_FEATURE_DIM,
            tracking,
            wrists_present: tracking == TrackingMode::ThreePoint,
        }
    }
}

/// Errors computing features.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FeatureError {
    #[error("empty window {start}..{end}")]
    EmptyWindow { start: usize, end: usize },
    #[error("window {start}..{end} exceeds the {len}-frame trajectory")]
    WindowOutOfRange { start: usize, end: usize, len: usize },
    #[error("{device} validity has {got} frames but the head has {expected}")]
    ValidityLengthMismatch { device: &'static str, got: usize, expected: usize },
    #[error("{device} trajectory has {got} frames but the head has {expected}")]
    LengthMismatch { device: &'static str, got: usize, expected: usize },
    #[error("{device} pose at frame {frame} is not finite")]
    NonFinitePose { device: &'static str, frame: usize },
    #[error("frame rate must be positive and finite, got {0}")]
    InvalidFps(f32),
}

/// The wearer's device trajectories on one timeline (`T_world_device` per frame).
#[derive(Clone, Copy, Debug)]
pub struct EgoTrajectories<'a> {
    pub head: &'a [RigidTransform],
    pub left_wrist: Option<WristTrack<'a>>,
    pub right_wrist: Option<WristTrack<'a>>,
}

/// One wrist on the head's timeline: `T_world_wrist` per frame and whether it was tracked
/// there (`None`: every frame). Poses of untracked frames are never read.
#[derive(Clone, Copy, Debug)]
pub struct WristTrack<'a> {
    pub poses: &'a [RigidTransform],
    pub valid: Option<&'a [bool]>,
}

impl<'a> WristTrack<'a> {
    /// A wrist tracked on every frame (wrist devices).
    pub fn always(poses: &'a [RigidTransform]) -> Self {
        Self { poses, valid: None }
    }

    fn tracked(&self, frame: usize) -> bool {
        self.valid.is_none_or(|v| v.get(frame).copied().unwrap_or(false))
    }
}

/// Features for one window.
#[derive(Clone, Debug, PartialEq)]
pub struct EgoWindowFeatures {
    /// Maps window-frame points into the world.
    pub t_world_window: RigidTransform,
    pub layout: EgoFeatureLayout,
    /// `frames × EGO_FEATURE_DIM`, row-major.
    pub features: Vec<f32>,
}

impl EgoWindowFeatures {
    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.features.len() / EGO_FEATURE_DIM
    }

    /// The feature row of frame `i` (window-relative).
    pub fn row(&self, i: usize) -> &[f32] {
        &self.features[i * EGO_FEATURE_DIM..(i + 1) * EGO_FEATURE_DIM]
    }
}

/// Heading of a head device: the yaw (radians, about world +Y, 0 = facing world +Z,
/// positive towards +X) of its forward axis. Stays defined when looking straight up or down:
/// the horizontal direction is `f_h − f_y · u_h` with `f`, `u` the device's forward (+Z) and
/// up (+Y) axes, which equals the forward direction for any pitch in (−90°, 90°).
pub fn heading_yaw(rotation: Quat) -> f32 {
    let forward = rotation * Vec3::Z;
    let up = rotation * Vec3::Y;
    let h = forward - forward.y * up;
    if h.x.abs() + h.z.abs() < 1e-9 {
        return 0.0;
    }
    h.x.atan2(h.z)
}

/// `T_world_window` for a window whose first head pose is `t_world_head`.
pub fn window_frame(t_world_head: &RigidTransform) -> RigidTransform {
    RigidTransform::new(Quat::from_rotation_y(heading_yaw(t_world_head.rotation)), t_world_head.translation)
}

fn check_trajectory(
    device: &'static str,
    poses: &[RigidTransform],
    valid: Option<&[bool]>,
    expected: usize,
    window: &Range<usize>,
) -> Result<(), FeatureError> {
    if poses.len() != expected {
        return Err(FeatureError::LengthMismatch { device, got: poses.len(), expected });
    }
    if let Some(valid) = valid
        && valid.len() != expected
    {
        return Err(FeatureError::ValidityLengthMismatch { device, got: valid.len(), expected });
    }
    let from = window.start.saturating_sub(1);
    let tracked = |i: usize| valid.is_none_or(|v| v[i]);
    if let Some(frame) = (from..window.end).find(|&i| tracked(i) && !poses[i].is_finite()) {
        return Err(FeatureError::NonFinitePose { device, frame });
    }
    Ok(())
}

fn write_rot6d(out: &mut [f32], r: Quat) {
    out.copy_from_slice(&Rot6d::from_quat(r).0);
}

/// Computes the ego features for frames `window` of the trajectories at `fps`.
///
/// Frames before the window (when the window does not start the sequence) are used for the
/// first frame's velocities, so a window cut out of a long sequence sees the same velocities
/// as the sequence does.
pub fn ego_features(
    trajectories: &EgoTrajectories<'_>,
    window: Range<usize>,
    fps: f32,
    tracking: TrackingMode,
) -> Result<EgoWindowFeatures, FeatureError> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(FeatureError::InvalidFps(fps));
    }
    if window.is_empty() {
        return Err(FeatureError::EmptyWindow { start: window.start, end: window.end });
    }
    let n = trajectories.head.len();
    if window.end > n {
        return Err(FeatureError::WindowOutOfRange { start: window.start, end: window.end, len: n });
    }
    check_trajectory("head", trajectories.head, None, n, &window)?;
    // In 3-point mode a missing wrist is a wrist never tracked; 1-point reads no wrist.
    let wrists: [Option<WristTrack<'_>>; 2] = match tracking {
        TrackingMode::OnePoint => [None, None],
        TrackingMode::ThreePoint => [trajectories.left_wrist, trajectories.right_wrist],
    };
    for (wrist, device) in wrists.iter().zip(["left wrist", "right wrist"]) {
        if let Some(w) = wrist {
            check_trajectory(device, w.poses, w.valid, n, &window)?;
        }
    }

    let head = trajectories.head;
    let t_world_window = window_frame(&head[window.start]);
    let r_window_world = t_world_window.rotation.conjugate();
    let window_yaw = heading_yaw(t_world_window.rotation);
    let origin = t_world_window.translation;

    let mut features = vec![0.0f32; window.len() * EGO_FEATURE_DIM];
    for (row, t) in features.chunks_exact_mut(EGO_FEATURE_DIM).zip(window.clone()) {
        let prev = t.checked_sub(1);
        // Head block.
        let head_pos = r_window_world * (head[t].translation - origin);
        let head_vel = prev.map_or(Vec3::ZERO, |p| r_window_world * (head[t].translation - head[p].translation) * fps);
        write_block(
            &mut row[EgoFeatureLayout::HEAD],
            &head[t],
            prev.map(|p| &head[p]),
            r_window_world,
            head_pos,
            head_vel,
        );
        // Wrist blocks where tracked: positions relative to the head at the same frame.
        let slots = [
            (EgoFeatureLayout::LEFT_WRIST, EgoFeatureLayout::LEFT_WRIST_VALID),
            (EgoFeatureLayout::RIGHT_WRIST, EgoFeatureLayout::RIGHT_WRIST_VALID),
        ];
        for (wrist, (range, valid_slot)) in wrists.iter().zip(slots) {
            let Some(wrist) = wrist.filter(|w| w.tracked(t)) else { continue };
            let poses = wrist.poses;
            let prev = prev.filter(|&p| wrist.tracked(p));
            let rel = |i: usize| poses[i].translation - head[i].translation;
            let pos = r_window_world * rel(t);
            let vel = prev.map_or(Vec3::ZERO, |p| r_window_world * (rel(t) - rel(p)) * fps);
            write_block(&mut row[range], &poses[t], prev.map(|p| &poses[p]), r_window_world, pos, vel);
            row[valid_slot] = 1.0;
        }
        // Horizontal displacement encoding.
        let delta_yaw = heading_yaw(head[t].rotation) - window_yaw;
        let seen_from_heading = Quat::from_rotation_y(-delta_yaw) * head_pos;
        row[EgoFeatureLayout::DISPLACEMENT].copy_from_slice(&[
            head_pos.x,
            head_pos.z,
            seen_from_heading.x,
            seen_from_heading.z,
            (head_pos.x * head_pos.x + head_pos.z * head_pos.z).sqrt(),
            head_pos.y,
        ]);
    }
    Ok(EgoWindowFeatures { t_world_window, layout: EgoFeatureLayout::new(tracking), features })
}

fn write_block(
    out: &mut [f32],
    pose: &RigidTransform,
    previous: Option<&RigidTransform>,
    r_window_world: Quat,
    position: Vec3,
    velocity: Vec3,
) {
    write_rot6d(&mut out[EgoFeatureLayout::BLOCK_ORIENTATION], r_window_world * pose.rotation);
    let step = previous.map_or(Quat::IDENTITY, |p| p.rotation.conjugate() * pose.rotation);
    write_rot6d(&mut out[EgoFeatureLayout::BLOCK_ANGULAR_VELOCITY], step);
    out[EgoFeatureLayout::BLOCK_POSITION].copy_from_slice(&position.to_array());
    out[EgoFeatureLayout::BLOCK_VELOCITY].copy_from_slice(&velocity.to_array());
}
