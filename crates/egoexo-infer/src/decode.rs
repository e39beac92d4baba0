//! Decoding window outputs into the motion: a window's collapsed root outputs (a 6D column
//! near the origin, where the network hesitates in a fast turn) interpolated between their
//! confident neighbours ([`interpolate_collapsed_6d`]), overlapping windows cross-faded in 6D,
//! root orientations rotated from each window's frame into the world, and each frame's root
//! translation recovered from the head by forward kinematics (`p_root = p_head − FK_head(θ)`).
//!
//! [`MotionAssembler`] takes windows in timeline order and gives frames out as soon as no
//! later window can change them ([`MotionAssembler::take_frames`]); a batch reconstruction
//! takes them all at the end and [`assemble_reconstruction`] fills untracked frames.

use std::collections::VecDeque;

use egoexo_core::aligned::AlignedSession;
use egoexo_core::ego_features::TrackingMode;
use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_core::foot_contact::lift_feet_above_floor;
use egoexo_core::glam::Mat3;
use egoexo_core::motion::SmplMotion;
use egoexo_core::rotation::{COLLAPSED_6D_STRENGTH, Rot6d, interpolate_collapsed_6d};
use egoexo_core::skeleton::SmplPose;

use crate::InferError;
use crate::inputs::{POSE_DIM, decode_pose};
use crate::passes::WindowOutput;
use crate::reconstruction::{Method, ObserverGates, Reconstruction};
use crate::windows::WindowError;
use crate::windows::crossfade_weight;

/// A window-frame 6D row whose root block cannot be read (never produced by the networks).
const IDENTITY_6D: [f32; 6] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// One timeline frame, decoded.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedFrame {
    /// Timeline frame index.
    pub frame: usize,
    /// The pose, world frame; `None` where no window covered the frame (wearer untracked).
    pub pose: Option<SmplPose>,
    /// Per session observer, per exo keypoint: the cross-faded gate (0 where no valid ray).
    pub gates: Vec<[f32; EXO_KEYPOINT_COUNT]>,
    /// At least one observer contributed a ray with gate ≥ 0.5.
    pub exo_evidence: bool,
}

#[derive(Clone, Debug)]
struct Accumulator {
    weight: f32,
    /// Root orientation already in the world; body rotations local.
    pose: Vec<f32>,
    gates: Vec<f32>,
    evidence: bool,
}

impl Accumulator {
    fn new(observers: usize) -> Self {
        Self {
            weight: 0.0,
            pose: vec![0.0; POSE_DIM],
            gates: vec![0.0; observers * EXO_KEYPOINT_COUNT],
            evidence: false,
        }
    }
}

/// Cross-fades window outputs into frames. Windows must arrive in timeline order of their
/// first frame (as the planner makes them).
#[derive(Clone, Debug)]
pub struct MotionAssembler {
    /// Session observers (gates are reported for each).
    observers: usize,
    crossfade_ramp: usize,
    /// Timeline frame of `pending[0]`.
    first: usize,
    pending: VecDeque<Accumulator>,
}

impl MotionAssembler {
    /// An assembler for a session with `observers` observers, cross-fading overlaps over
    /// `crossfade_ramp` frames.
    pub fn new(observers: usize, crossfade_ramp: usize) -> Self {
        Self { observers, crossfade_ramp, first: 0, pending: VecDeque::new() }
    }

    /// The first frame not yet taken.
    pub fn next_frame(&self) -> usize {
        self.first
    }

    /// Adds one window. A window starting before the first frame not yet taken is an error
    /// (its frames were already given out).
    pub fn add(&mut self, window: &WindowOutput) -> Result<(), InferError> {
        let plan = &window.plan;
        if plan.frames.start < self.first || window.poses.len() < plan.len() * POSE_DIM {
            return Err(WindowError::OutOfOrder {
                frames: plan.frames.clone(),
                given_out: self.first,
                pose_values: window.poses.len(),
            }
            .into());
        }
        let end = plan.frames.end - self.first;
        while self.pending.len() < end {
            self.pending.push_back(Accumulator::new(self.observers));
        }
        let r_world_window = Mat3::from_quat(window.r_world_window);
        // The window's root orientations (window frame), collapsed outputs interpolated
        // between their confident neighbours before anything is blended.
        let mut roots: Vec<Rot6d> = (0..plan.len())
            .map(|t| Rot6d(window.poses[t * POSE_DIM..t * POSE_DIM + 6].try_into().unwrap_or(IDENTITY_6D)))
            .collect();
        interpolate_collapsed_6d(&mut roots, COLLAPSED_6D_STRENGTH);
        for (t, root) in roots.iter().enumerate() {
            let w = crossfade_weight(
                t,
                plan.len(),
                self.crossfade_ramp,
                plan.frames.start == plan.span.start,
                plan.frames.end == plan.span.end,
            );
            let row = &window.poses[t * POSE_DIM..(t + 1) * POSE_DIM];
            let a = &mut self.pending[plan.frames.start + t - self.first];
            // Root orientation: rotate the window-frame 6D columns into the world first.
            let root_world = Rot6d::from_mat3(r_world_window * root.to_mat3()).0;
            for (c, v) in root_world.iter().enumerate() {
                a.pose[c] += w * v;
            }
            for (c, v) in row[6..].iter().enumerate() {
                a.pose[6 + c] += w * v;
            }
            if let Some(gates) = &window.gates {
                for (slot, observer) in gates.slot_observer.iter().enumerate() {
                    let Some(o) = *observer else { continue };
                    if o >= self.observers {
                        continue;
                    }
                    for k in 0..EXO_KEYPOINT_COUNT {
                        let value = gates.get(t, slot, k);
                        a.gates[o * EXO_KEYPOINT_COUNT + k] += w * value;
                        a.evidence |= value >= 0.5;
                    }
                }
            }
            a.weight += w;
        }
        Ok(())
    }

    /// Decodes and gives out every frame before `before`: final once every window covering
    /// them has been added, i.e. `before` is at most the next window's first frame (or the
    /// timeline's length after the last window). Frames no window covered come out with no
    /// pose.
    pub fn take_frames(&mut self, aligned: &AlignedSession, before: usize) -> Vec<DecodedFrame> {
        let before = before.min(aligned.timeline.frames);
        let mut out = Vec::with_capacity(before.saturating_sub(self.first));
        while self.first < before {
            let a = self.pending.pop_front().unwrap_or_else(|| Accumulator::new(self.observers));
            out.push(decode_frame(aligned, self.first, &a, self.observers));
            self.first += 1;
        }
        out
    }
}

fn decode_frame(aligned: &AlignedSession, frame: usize, a: &Accumulator, observers: usize) -> DecodedFrame {
    let pose = (a.weight > 0.0).then(|| {
        let row: Vec<f32> = a.pose.iter().map(|v| v / a.weight).collect();
        let (root_orientation, body) = decode_pose(&row);
        let translation = aligned.skeleton.recover_translation(
            root_orientation,
            &body,
            &aligned.head.poses[frame],
            aligned.head_joint_in_device,
        );
        SmplPose { root_orientation, body, translation }
    });
    let gates = (0..observers)
        .map(|o| {
            std::array::from_fn(|k| if a.weight > 0.0 { a.gates[o * EXO_KEYPOINT_COUNT + k] / a.weight } else { 0.0 })
        })
        .collect();
    DecodedFrame { frame, pose, gates, exo_evidence: a.evidence }
}

/// The reconstruction from every frame of the timeline, in order: frames without a pose take
/// the nearest reconstructed frame's pose (and stay marked invalid), joints by forward
/// kinematics.
pub fn assemble_reconstruction(
    method: Method,
    tracking: TrackingMode,
    aligned: &AlignedSession,
    frames: Vec<DecodedFrame>,
    floor_y: Option<f32>,
) -> Result<Reconstruction, InferError> {
    if frames.len() != aligned.timeline.frames || frames.iter().enumerate().any(|(i, f)| f.frame != i) {
        return Err(WindowError::Incomplete { decoded: frames.len(), timeline: aligned.timeline.frames }.into());
    }
    let valid: Vec<bool> = frames.iter().map(|f| f.pose.is_some()).collect();
    let mut poses: Vec<Option<SmplPose>> = frames.iter().map(|f| f.pose).collect();
    fill_gaps(&mut poses);
    let mut poses: Vec<SmplPose> = poses.into_iter().map(Option::unwrap_or_default).collect();
    let skeleton = aligned.skeleton.clone();
    let feet_lifted = floor_y.map(|y| lift_feet_above_floor(&skeleton, &mut poses, y));
    let joints = poses.iter().map(|p| skeleton.forward_kinematics(p).positions).collect();
    let gates = aligned
        .observers
        .iter()
        .enumerate()
        .map(|(o, observer)| ObserverGates {
            observer_id: observer.id.clone(),
            gates: frames.iter().map(|f| f.gates.get(o).copied().unwrap_or([0.0; EXO_KEYPOINT_COUNT])).collect(),
        })
        .collect();
    let motion = SmplMotion::new(aligned.timeline.fps, aligned.timeline.start_ns, skeleton, None, poses)
        .map_err(WindowError::Motion)?;
    Ok(Reconstruction {
        method,
        tracking,
        motion,
        joints,
        valid,
        exo_evidence: frames.iter().map(|f| f.exo_evidence).collect(),
        gates,
        feet_lifted,
    })
}

/// Frames without a reconstruction take the nearest reconstructed frame's pose.
fn fill_gaps(poses: &mut [Option<SmplPose>]) {
    let mut last = None;
    for p in poses.iter_mut() {
        match p {
            Some(v) => last = Some(*v),
            None => *p = last,
        }
    }
    let mut next = None;
    for p in poses.iter_mut().rev() {
        match p {
            Some(v) => next = Some(*v),
            None => *p = next,
        }
    }
}
