//! The networks' inputs for one window, computed from an aligned session with the core's
//! geometry — the one place they are assembled, used alike by reconstruction and by the
//! training shards (`egoexo synth --shards`).
//!
//! Tensor layouts (batch 1, `T` = [`WINDOW`], `N` = observer slots, `K` = 13, row-major):
//! - `ego` `[1, T, 62]` — [`egoexo_core::ego_features`] layout v2, window frame.
//! - `egonet` `[1, T, 132]` — EgoNet's coarse pose in the window frame: root orientation 6D
//!   then the 21 body rotations 6D ([`POSE_DIM`]).
//! - `gate_features` `[1, T, N, K, F]` — [`egoexo_core::gate_features`] layout v2.
//! - `rays` `[1, T, N, K, 3]` — canonical ray endpoints in the wearer's head frame (metres),
//!   zero when invalid; `ray_valid` `[1, T, N, K]`.
//! - `ray_offsets` `[1, T, N, K, 3]` — from each of EgoNet's coarse keypoints to its detection's
//!   viewing ray, perpendicular to the ray, in window-frame axes (metres), zero when invalid
//!   ([`egoexo_core::rays::ViewingRay::offset_from`]).
//! - `exo` `[1, T, N, K, 7]` — the fusion network's exo input, exo token layout
//!   [`EXO_TOKEN_LAYOUT_VERSION`]: the ray endpoint, the ray offset, then the gate
//!   ([`fusion_exo_input`]); the fusion graph does the gate-weighted temporal low-pass, the
//!   scaling by the (low-passed) gate and, for models trained with `--exo-fade`, derives each
//!   observer's presence from it.
//! - `observer_mask` `[1, T, N]` — 1 where the slot holds an observer whose head is tracked and
//!   at least one ray is valid at that frame.
//!
//! Padded frames (after a short span's last frame) repeat the last real frame's wearer poses
//! and carry no exo evidence; `frame_mask` marks the real ones.

use egoexo_core::aligned::AlignedSession;
use egoexo_core::camera::CameraCalibration;
use egoexo_core::ego_features::{EGO_FEATURE_DIM, EgoTrajectories, TrackingMode, WristTrack, ego_features};
use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, exo_keypoints_from_smpl};
use egoexo_core::gate_features::{GATE_FEATURE_DIM, detection_jumps, gate_features};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rays::canonicalize_keypoints_with_offsets;
use egoexo_core::region::{DEFAULT_REGION_MARGIN, propose_region};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::rotation::Rot6d;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, NUM_JOINTS, SmplJoint, SmplPose, SmplSkeleton};

use crate::InferError;
use crate::windows::WindowError;
use crate::windows::{WINDOW, WindowPlan};

/// Numbers per frame of a pose in 6D: root orientation (6) + 21 body rotations (126).
pub const POSE_DIM: usize = 6 + 6 * NUM_BODY_JOINTS;

/// The wearer's side of one window.
#[derive(Clone, Debug)]
pub struct EgoWindow {
    pub plan: WindowPlan,
    /// Maps window-frame points to the world.
    pub t_world_window: RigidTransform,
    /// `WINDOW × EGO_FEATURE_DIM`.
    pub ego: Vec<f32>,
    /// Head-device poses of the `WINDOW` frames (padded by repetition), `T_world_device`.
    pub head: Vec<RigidTransform>,
    /// 1 for real frames, 0 for padding (`WINDOW`).
    pub frame_mask: Vec<f32>,
}

fn padded<T: Copy>(frames: &[T], len: usize) -> Vec<T> {
    (0..len).map(|i| frames[i.min(frames.len() - 1)]).collect()
}

/// Ego features of one window. In 3-point mode each wrist reaches the features only on the
/// frames where it is tracked (ego feature layout v2's validity slots); a wrist the session
/// lacks is never tracked. (Asking for 3-point on a session without any wrist is refused
/// earlier, by [`crate::plan::resolve_tracking`]; a simulated hand-tracking session whose
/// hands were never in view is still a valid 3-point input.)
pub fn ego_window(
    aligned: &AlignedSession,
    plan: &WindowPlan,
    tracking: TrackingMode,
) -> Result<EgoWindow, InferError> {
    if plan.frames.is_empty() || plan.frames.len() > WINDOW || plan.frames.end > aligned.head.poses.len() {
        return Err(WindowError::OffTimeline { frames: plan.frames.clone(), timeline: aligned.head.poses.len() }.into());
    }
    // One frame of history from inside the span, so the first frame's velocities are real.
    let history = usize::from(plan.frames.start > plan.span.start);
    let from = plan.frames.start - history;
    let slice =
        |poses: &[RigidTransform]| -> Vec<RigidTransform> { padded(&poses[from..plan.frames.end], WINDOW + history) };
    let head = slice(&aligned.head.poses);
    // Padding frames repeat the last real frame, validity included.
    let wrist = |w: &Option<egoexo_core::aligned::AlignedTrajectory>| {
        w.as_ref().map(|w| (slice(&w.poses), padded(&w.valid[from..plan.frames.end], WINDOW + history)))
    };
    let (left, right) = match tracking {
        TrackingMode::OnePoint => (None, None),
        TrackingMode::ThreePoint => (wrist(&aligned.left_wrist), wrist(&aligned.right_wrist)),
    };
    fn track(w: &Option<(Vec<RigidTransform>, Vec<bool>)>) -> Option<WristTrack<'_>> {
        w.as_ref().map(|(poses, valid)| WristTrack { poses, valid: Some(valid) })
    }
    let trajectories = EgoTrajectories { head: &head, left_wrist: track(&left), right_wrist: track(&right) };
    let features = ego_features(&trajectories, history..history + WINDOW, aligned.timeline.fps, tracking)?;
    let frame_mask = (0..WINDOW).map(|i| f32::from(u8::from(i < plan.frames.len()))).collect();
    Ok(EgoWindow {
        plan: plan.clone(),
        t_world_window: features.t_world_window,
        ego: features.features,
        head: head[history..].to_vec(),
        frame_mask,
    })
}

/// Decodes a `WINDOW × POSE_DIM` window-frame pose tensor into world SMPL poses, recovering
/// each frame's root translation from the head device (`p_root = p_head − FK_head(θ)`).
pub fn world_poses(
    window: &EgoWindow,
    poses_6d: &[f32],
    skeleton: &SmplSkeleton,
    head_joint_in_device: Vec3,
) -> Vec<SmplPose> {
    poses_6d
        .chunks_exact(POSE_DIM)
        .zip(&window.head)
        .map(|(row, head)| {
            let (root_window, body) = decode_pose(row);
            let root_orientation = window.t_world_window.rotation * root_window;
            let translation = skeleton.recover_translation(root_orientation, &body, head, head_joint_in_device);
            SmplPose { root_orientation, body, translation }
        })
        .collect()
}

/// One frame's `POSE_DIM` numbers → (root orientation, body rotations).
pub fn decode_pose(row: &[f32]) -> (Quat, [Quat; NUM_BODY_JOINTS]) {
    let rot = |i: usize| {
        let mut six = [0.0; 6];
        six.copy_from_slice(&row[6 * i..6 * i + 6]);
        Rot6d(six).to_quat()
    };
    (rot(0), std::array::from_fn(|j| rot(j + 1)))
}

/// One frame's pose → `POSE_DIM` numbers (root orientation given in the frame to encode in).
pub fn encode_pose(root: Quat, body: &[Quat; NUM_BODY_JOINTS], out: &mut [f32]) {
    out[0..6].copy_from_slice(&Rot6d::from_quat(root).0);
    for (j, q) in body.iter().enumerate() {
        out[6 + 6 * j..12 + 6 * j].copy_from_slice(&Rot6d::from_quat(*q).0);
    }
}

/// The exo side of one window for `slots` observer slots.
#[derive(Clone, Debug)]
pub struct ExoWindow {
    pub slots: usize,
    /// Which session observer fills each slot.
    pub slot_observer: Vec<Option<usize>>,
    /// `[T, N, K, 3]`, wearer head frame.
    pub rays: Vec<f32>,
    /// `[T, N, K, 3]`, window-frame axes.
    pub ray_offsets: Vec<f32>,
    /// `[T, N, K]`.
    pub ray_valid: Vec<f32>,
    /// `[T, N, K, F]`.
    pub gate_features: Vec<f32>,
    /// `[T, N]`.
    pub observer_mask: Vec<f32>,
}

impl ExoWindow {
    /// Index of `(t, slot, k)` in `[T, N, K]` arrays ([`exo_index`]).
    pub fn index(&self, t: usize, slot: usize, k: usize) -> usize {
        exo_index(self.slots, t, slot, k)
    }
}

/// Index of window frame `t`, observer slot `slot`, keypoint `k` in a row-major `[T, N, K]`
/// array with `slots` = N (multiply by the trailing dimension for `[T, N, K, D]`).
pub fn exo_index(slots: usize, t: usize, slot: usize, k: usize) -> usize {
    (t * slots + slot) * EXO_KEYPOINT_COUNT + k
}

/// Rays, validity, gate features and observer masks of one window, given the coarse world
/// poses (EgoNet's, decoded with [`world_poses`]) for its `WINDOW` frames. Observers beyond
/// `slots` are ignored; `observers` lists the session observers to place in the slots.
pub fn exo_window(
    aligned: &AlignedSession,
    window: &EgoWindow,
    coarse: &[SmplPose],
    observers: &[usize],
    slots: usize,
) -> ExoWindow {
    let skeleton = &aligned.skeleton;
    let scale = skeleton.head_height() / SmplSkeleton::mean_shape().head_height();
    let mut exo = ExoWindow {
        slots,
        slot_observer: (0..slots).map(|s| observers.get(s).copied()).collect(),
        rays: vec![0.0; WINDOW * slots * EXO_KEYPOINT_COUNT * 3],
        ray_offsets: vec![0.0; WINDOW * slots * EXO_KEYPOINT_COUNT * 3],
        ray_valid: vec![0.0; WINDOW * slots * EXO_KEYPOINT_COUNT],
        gate_features: vec![0.0; WINDOW * slots * EXO_KEYPOINT_COUNT * GATE_FEATURE_DIM],
        observer_mask: vec![0.0; WINDOW * slots],
    };
    let coarse_fk: Vec<_> = coarse.iter().map(|p| skeleton.forward_kinematics(p)).collect();
    for (slot, observer_index) in exo.slot_observer.clone().into_iter().enumerate() {
        let Some(observer) = observer_index.and_then(|o| aligned.observers.get(o)) else { continue };
        // Per frame: detections, EgoNet's predicted pixels, region, rays (None: head not tracked).
        let frames: Vec<_> = (0..window.plan.len())
            .map(|t| {
                let frame = window.plan.frames.start + t;
                if !observer.head.valid.get(frame).copied().unwrap_or(false) {
                    return None;
                }
                let observer_pose = &observer.head.poses[frame];
                let fk = &coarse_fk[t];
                let region =
                    propose_region(&fk.positions[..NUM_JOINTS], &observer.camera, observer_pose, DEFAULT_REGION_MARGIN);
                let predicted_points =
                    exo_keypoints_from_smpl(&fk.positions, fk.rotations[SmplJoint::Head.index()], scale);
                let predicted = predicted_points.map(|p| project(&observer.camera, observer_pose, p));
                let detected = &observer.keypoints[frame];
                let rays_and_offsets = canonicalize_keypoints_with_offsets(
                    detected,
                    &observer.camera,
                    observer_pose,
                    &window.head[t],
                    &predicted_points,
                    window.t_world_window.rotation,
                );
                Some((detected, predicted, region, rays_and_offsets))
            })
            .collect();
        let diagonals: Vec<Option<f32>> = frames
            .iter()
            .map(|f| f.as_ref().and_then(|(_, _, region, _)| region.bbox()).map(|b| b.diagonal()))
            .collect();
        let jumps: Vec<Vec<f32>> = (0..EXO_KEYPOINT_COUNT)
            .map(|k| {
                let pixels: Vec<_> = frames
                    .iter()
                    .map(|f| f.as_ref().and_then(|(detected, ..)| detected[k]).map(|kp| kp.pixel))
                    .collect();
                detection_jumps(&pixels, &diagonals)
            })
            .collect();
        for (t, frame) in frames.iter().enumerate() {
            let Some((detected, predicted, region, rays_and_offsets)) = frame else { continue };
            let valid = rays_and_offsets.map(|(r, _)| r.valid);
            let jumps_now = std::array::from_fn(|k| jumps[k][t]);
            let features = gate_features(detected, &valid, predicted, &observer.camera, region, &jumps_now);
            for k in 0..EXO_KEYPOINT_COUNT {
                let i = exo.index(t, slot, k);
                let (ray, offset) = rays_and_offsets[k];
                exo.rays[3 * i..3 * i + 3].copy_from_slice(&ray.endpoint.to_array());
                exo.ray_offsets[3 * i..3 * i + 3].copy_from_slice(&offset.to_array());
                exo.ray_valid[i] = f32::from(u8::from(valid[k]));
                exo.gate_features[GATE_FEATURE_DIM * i..GATE_FEATURE_DIM * (i + 1)].copy_from_slice(&features[k]);
            }
            exo.observer_mask[t * slots + slot] = f32::from(u8::from(valid.iter().any(|&v| v)));
        }
    }
    exo
}

fn project(camera: &CameraCalibration, t_world_device: &RigidTransform, p: Vec3) -> Option<egoexo_core::glam::Vec2> {
    camera.project_world(p, t_world_device)
}

/// Version of the exo token layout (the fusion network's `exo` input per keypoint). v1: the
/// gated ray endpoint and the gate (4 numbers, the paper's); v2: the gated ray endpoint, the
/// gated ray offset and the gate (7 numbers); v3: as v2, each keypoint's endpoints and offsets
/// low-passed over its detections in the window before the gate; v4: the raw ray endpoint, the
/// raw ray offset and the gate (7 numbers) — the fusion graph itself low-passes each track
/// weighted by the gate and then scales it by the gate, so a gated-out detection also leaves
/// its neighbours' averages.
pub const EXO_TOKEN_LAYOUT_VERSION: u32 = 4;

/// Numbers per keypoint in the exo input, layout [`EXO_TOKEN_LAYOUT_VERSION`].
pub const EXO_TOKEN_DIM: usize = 7;

/// `[T, N, K, 7]` fusion input (exo token layout v4): each keypoint's ray endpoint and ray
/// offset, then its gate value; all zero where the ray is invalid. The fusion graph weights,
/// low-passes and scales the rays by the gate; `gate` forced to 1 is the ungated ablation.
pub fn fusion_exo_input(exo: &ExoWindow, gate: &[f32]) -> Vec<f32> {
    let mut out = vec![0.0; WINDOW * exo.slots * EXO_KEYPOINT_COUNT * EXO_TOKEN_DIM];
    for i in 0..WINDOW * exo.slots * EXO_KEYPOINT_COUNT {
        let valid = exo.ray_valid[i];
        let token = &mut out[EXO_TOKEN_DIM * i..EXO_TOKEN_DIM * (i + 1)];
        for c in 0..3 {
            token[c] = valid * exo.rays[3 * i + c];
            token[3 + c] = valid * exo.ray_offsets[3 * i + c];
        }
        token[6] = valid * gate[i];
    }
    out
}

/// Ego features dimension re-exported for shape checks.
pub const EGO_DIM: usize = EGO_FEATURE_DIM;

/// The ground-truth pose of one window as the networks' targets: `WINDOW × POSE_DIM`, root
/// orientation in the window frame. Padded frames repeat the last real frame. `None` if the
/// ground truth is missing or invalid at a real frame of the window.
pub fn window_targets(aligned: &AlignedSession, window: &EgoWindow) -> Option<Vec<f32>> {
    let gt = aligned.ground_truth.as_ref()?;
    let frames = window.plan.frames.clone();
    if !frames.clone().all(|f| gt.valid.get(f).copied().unwrap_or(false)) {
        return None;
    }
    let r_window_world = window.t_world_window.rotation.conjugate();
    let mut out = vec![0.0; WINDOW * POSE_DIM];
    for t in 0..WINDOW {
        let pose = &gt.poses[frames.start + t.min(frames.len() - 1)];
        encode_pose(r_window_world * pose.root_orientation, &pose.body, &mut out[t * POSE_DIM..(t + 1) * POSE_DIM]);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fusion_exo_input_writes_the_endpoint_the_offset_then_the_gate_and_zeroes_invalid_rays() {
        // The layout `train.py` builds (training/tests/test_model_shapes.py checks that side).
        let slots = 1;
        let n = WINDOW * slots * EXO_KEYPOINT_COUNT;
        let (valid, invalid) = (3 * EXO_KEYPOINT_COUNT + 4, 3 * EXO_KEYPOINT_COUNT + 5);
        let exo = ExoWindow {
            slots,
            slot_observer: vec![Some(0)],
            rays: (0..3 * n).map(|v| v as f32).collect(),
            ray_offsets: (0..3 * n).map(|v| -(v as f32)).collect(),
            ray_valid: (0..n).map(|i| f32::from(u8::from(i != invalid))).collect(),
            gate_features: vec![0.0; n * GATE_FEATURE_DIM],
            observer_mask: vec![1.0; WINDOW * slots],
        };
        let gate = vec![0.5; n];
        let out = fusion_exo_input(&exo, &gate);
        assert_eq!(out.len(), n * EXO_TOKEN_DIM);
        assert_eq!((exo.index(3, 0, 4), exo.index(3, 0, 5)), (valid, invalid));
        assert_eq!(
            &out[EXO_TOKEN_DIM * valid..EXO_TOKEN_DIM * (valid + 1)],
            &[
                exo.rays[3 * valid],
                exo.rays[3 * valid + 1],
                exo.rays[3 * valid + 2],
                exo.ray_offsets[3 * valid],
                exo.ray_offsets[3 * valid + 1],
                exo.ray_offsets[3 * valid + 2],
                0.5,
            ]
        );
        assert!(out[EXO_TOKEN_DIM * invalid..EXO_TOKEN_DIM * (invalid + 1)].iter().all(|&v| v == 0.0));
    }
}
