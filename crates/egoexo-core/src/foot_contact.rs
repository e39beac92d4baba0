//! Feet against the floor: how far a motion's feet go through the floor, and how much they
//! slide while they stand on it.
//!
//! - **Penetration** (cm): per frame, how far the lowest sole is below the floor (0 when it is
//!   on or above it); the mean over frames and the worst frame. A sole is an ankle or foot
//!   joint (SMPL 7, 8, 10, 11) minus the joints' height above the soles
//!   ([`FOOT_JOINT_ABOVE_SOLE_M`] scaled with the body).
//! - **Skating** (cm/s): the mean horizontal speed of the foot joints on the frame pairs where
//!   the *reference* motion (the ground truth) stands on that foot: its sole within
//!   [`CONTACT_HEIGHT_M`] of the floor and its horizontal speed under [`STANCE_SPEED_M_S`] on
//!   both frames. A foot that stands should not slide; the reference scored against itself
//!   gives the floor of the metric (a real foot rolls a little).
//!
//! Positions are world positions in metres, Y up; the floor is a height on Y.
//!
//! [`lift_feet_above_floor`] is the reconstruction's floor constraint: a foot that goes
//! through the floor is raised onto it by folding its leg (two-bone IK at hip and knee), the
//! pelvis, upper body and head staying where the networks and the head device put them. A
//! wearer who lowers the head (crouching, kneeling, sitting) while the networks keep the legs
//! straight thus bends the knees instead of sinking through the floor.

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::metrics::JointPositions;
use crate::skeleton::{SmplPose, SmplSkeleton};

/// The ankle and foot joints (SMPL order).
pub const FOOT_JOINTS: [usize; 4] = [7, 8, 10, 11];
/// Height of the ankle/foot joints above the soles for the mean shape, metres.
pub const FOOT_JOINT_ABOVE_SOLE_M: f32 = 0.03;
/// A sole closer than this to the floor can be in contact, metres.
pub const CONTACT_HEIGHT_M: f32 = 0.05;
/// A foot joint slower than this (horizontally) can be in contact, m/s.
pub const STANCE_SPEED_M_S: f32 = 0.25;

/// The legs as SMPL joints: (hip, knee, ankle, foot), left then right.
pub const LEGS: [(usize, usize, usize, usize); 2] = [(1, 4, 7, 10), (2, 5, 8, 11)];

/// Height of the foot joints above the soles for `skeleton`: [`FOOT_JOINT_ABOVE_SOLE_M`] scaled
/// with the body, metres.
pub fn sole_offset_m(skeleton: &SmplSkeleton) -> f32 {
    FOOT_JOINT_ABOVE_SOLE_M * skeleton.head_height() / SmplSkeleton::mean_shape().head_height()
}

/// What [`lift_feet_above_floor`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FootLift {
    /// Frames where a leg was folded.
    pub frames: usize,
    /// The largest lift, metres.
    pub max_lift_m: f32,
}

/// Folds each leg whose ankle or foot joint is below `floor_y` + the soles' offset, so that
/// joint sits on the floor: two-bone IK moves the knee and ankle (the ankle straight up by
/// the penetration), bending the knee in the plane it already bends in (forward when the leg
/// is straight); each foot keeps its world orientation; the pelvis and everything above it
/// are untouched. A leg already folded as far as it goes stays partly below. Poses are
/// changed in place; `floor_y` is a world height (Y up), metres.
pub fn lift_feet_above_floor(skeleton: &SmplSkeleton, poses: &mut [SmplPose], floor_y: f32) -> FootLift {
    let sole = sole_offset_m(skeleton);
    let mut report = FootLift::default();
    for pose in poses.iter_mut() {
        let fk = skeleton.forward_kinematics(pose);
        let (p, r) = (&fk.positions, &fk.rotations);
        let mut changed = false;
        for (hip, knee, ankle, foot) in LEGS {
            let lift = floor_y + sole - p[ankle].y.min(p[foot].y);
            if lift.is_nan() || lift <= 1e-4 {
                continue;
            }
            let (h, k, a) = (p[hip], p[knee], p[ankle]);
            let (thigh, shin) = ((k - h).length(), (a - k).length());
            if thigh < 1e-6 || shin < 1e-6 {
                continue;
            }
            let to_target = a + Vec3::Y * lift - h;
            let Some(direction) = to_target.try_normalize() else { continue };
            let reach = to_target.length().clamp((thigh - shin).abs() + 1e-4, thigh + shin - 1e-4);
            // The knee's offset from the hip→ankle line: keep its side, or bend forward.
            let sideways = (k - h) - direction * (k - h).dot(direction);
            let forward = r[0] * Vec3::Z;
            let bend = sideways
                .try_normalize()
                .filter(|_| sideways.length() > 0.01 * thigh)
                .or_else(|| (forward - direction * forward.dot(direction)).try_normalize())
                .unwrap_or(Vec3::Z);
            let along = (thigh * thigh - shin * shin + reach * reach) / (2.0 * reach);
            let across = (thigh * thigh - along * along).max(0.0).sqrt();
            let new_knee = h + direction * along + bend * across;
            let new_ankle = h + direction * reach;
            // Global rotations: the hip swung onto the new thigh, the knee onto the new shin.
            let hip_swing = Quat::from_rotation_arc((k - h) / thigh, (new_knee - h) / thigh);
            let hip_rotation = (hip_swing * r[hip]).normalize();
            let knee_carried = hip_swing * r[knee];
            let shin_carried = (hip_swing * (a - k)) / shin;
            let Some(new_shin) = (new_ankle - new_knee).try_normalize() else { continue };
            let knee_rotation = (Quat::from_rotation_arc(shin_carried, new_shin) * knee_carried).normalize();
            pose.body[hip - 1] = (r[0].conjugate() * hip_rotation).normalize();
            pose.body[knee - 1] = (hip_rotation.conjugate() * knee_rotation).normalize();
            pose.body[ankle - 1] = (knee_rotation.conjugate() * r[ankle]).normalize();
            report.max_lift_m = report.max_lift_m.max(lift);
            changed = true;
        }
        report.frames += usize::from(changed);
    }
    report
}

/// Feet against the floor over some frames.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FootContactMetrics {
    /// Mean over frames of the lowest sole's depth below the floor, cm.
    pub penetration_mean_cm: f64,
    /// The deepest frame, cm.
    pub penetration_worst_cm: f64,
    /// Mean horizontal speed of foot joints while the reference stands on them, cm/s; `None`
    /// when the reference never does.
    pub skating_cm_s: Option<f64>,
    /// Frames scored.
    pub frames: usize,
    /// Joint-frame pairs in contact (the skating terms).
    pub contact_pairs: usize,
}

/// Accumulates [`FootContactMetrics`] over segments.
#[derive(Clone, Debug, Default)]
pub struct FootContactAccumulator {
    depth_sum: f64,
    worst: f64,
    frames: usize,
    speed_sum: f64,
    pairs: usize,
}

impl FootContactAccumulator {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one segment: `joints` per frame at `fps`, with `reference` (the same frames of the
    /// true motion, or `joints` itself) telling when a foot stands; the floor at `floor_y`,
    /// soles `sole_offset_m` below the foot joints. Differences never cross segments.
    pub fn add_segment(
        &mut self,
        joints: &[JointPositions],
        reference: &[JointPositions],
        fps: f32,
        floor_y: f32,
        sole_offset_m: f32,
    ) {
        let sole = |p: glam::Vec3| p.y - sole_offset_m - floor_y;
        for frame in joints {
            let lowest = FOOT_JOINTS.iter().map(|&j| f64::from(sole(frame[j]))).fold(f64::INFINITY, f64::min);
            if !lowest.is_finite() {
                continue;
            }
            let depth = (-lowest).max(0.0);
            self.depth_sum += depth;
            self.worst = self.worst.max(depth);
            self.frames += 1;
        }
        let horizontal = |a: glam::Vec3, b: glam::Vec3| glam::Vec2::new(b.x - a.x, b.z - a.z).length() * fps;
        let frames = joints.len().min(reference.len());
        for t in 0..frames.saturating_sub(1) {
            for &j in &FOOT_JOINTS {
                let (r0, r1) = (reference[t][j], reference[t + 1][j]);
                let stands =
                    sole(r0) < CONTACT_HEIGHT_M && sole(r1) < CONTACT_HEIGHT_M && horizontal(r0, r1) < STANCE_SPEED_M_S;
                let speed = f64::from(horizontal(joints[t][j], joints[t + 1][j]));
                if stands && speed.is_finite() {
                    self.speed_sum += speed;
                    self.pairs += 1;
                }
            }
        }
    }

    /// The metrics so far; `None` before any frame.
    pub fn finish(&self) -> Option<FootContactMetrics> {
        (self.frames > 0).then(|| FootContactMetrics {
            penetration_mean_cm: self.depth_sum / self.frames as f64 * 100.0,
            penetration_worst_cm: self.worst * 100.0,
            skating_cm_s: (self.pairs > 0).then(|| self.speed_sum / self.pairs as f64 * 100.0),
            frames: self.frames,
            contact_pairs: self.pairs,
        })
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    /// A standing body whose head has dropped by `drop` metres, legs still straight: the
    /// lift folds the legs so the soles meet the floor, the head and upper body stay, the
    /// knees bend forward and the feet keep their orientation.
    #[test]
    fn a_sunken_standing_body_folds_its_legs_onto_the_floor() {
        let skeleton = SmplSkeleton::mean_shape();
        let sole = sole_offset_m(&skeleton);
        let rest = SmplPose::rest();
        let fk = skeleton.forward_kinematics(&rest);
        let standing_floor = FOOT_JOINTS.iter().map(|&j| fk.positions[j].y).fold(f32::INFINITY, f32::min) - sole;
        for drop in [0.0f32, 0.1, 0.45] {
            let mut poses = vec![SmplPose { translation: rest.translation - Vec3::Y * drop, ..rest }];
            let before = skeleton.forward_kinematics(&poses[0]);
            let report = lift_feet_above_floor(&skeleton, &mut poses, standing_floor);
            let after = skeleton.forward_kinematics(&poses[0]);
            if drop == 0.0 {
                assert_eq!(report.frames, 0);
                assert_eq!(poses[0], SmplPose { translation: rest.translation, ..rest });
                continue;
            }
            assert_eq!(report.frames, 1);
            assert!((report.max_lift_m - drop).abs() < 1e-3, "{report:?}");
            let lowest = FOOT_JOINTS.iter().map(|&j| after.positions[j].y).fold(f32::INFINITY, f32::min) - sole;
            assert!((lowest - standing_floor).abs() < 2e-3, "drop {drop}: soles at {lowest}, floor {standing_floor}");
            for j in [0, 3, 6, 9, 12, 15, 16, 17, 20, 21] {
                assert!(after.positions[j].abs_diff_eq(before.positions[j], 1e-5), "joint {j} moved");
            }
            for (hip, knee, ankle, foot) in LEGS {
                // The knees come forward (+Z is the rest body's front), the feet stay level.
                assert!(after.positions[knee].z > before.positions[knee].z + 0.02, "drop {drop}: knee {knee}");
                assert!(after.rotations[ankle].angle_between(before.rotations[ankle]) < 1e-3);
                assert!(after.rotations[foot].angle_between(before.rotations[foot]) < 1e-3);
                // Bones keep their lengths (it is a rotation-only change).
                let len =
                    |t: &crate::skeleton::JointTransforms, a: usize, b: usize| t.positions[a].distance(t.positions[b]);
                assert!((len(&after, hip, knee) - len(&before, hip, knee)).abs() < 1e-4);
                assert!((len(&after, knee, ankle) - len(&before, knee, ankle)).abs() < 1e-4);
            }
        }
    }

    /// Feet at height `y` (joints), moving along X at `vx` m/s.
    fn feet(frames: usize, y: impl Fn(usize) -> f32, vx: f32, fps: f32) -> Vec<JointPositions> {
        (0..frames)
            .map(|t| {
                let mut joints = [Vec3::new(0.0, 1.0, 0.0); 24];
                for &j in &FOOT_JOINTS {
                    joints[j] = Vec3::new(vx * t as f32 / fps, y(t), 0.1 * j as f32);
                }
                joints
            })
            .collect()
    }

    #[test]
    fn feet_through_the_floor_are_measured_in_cm() {
        let mut acc = FootContactAccumulator::new();
        // Soles 10 cm below the floor on half the frames, on it otherwise.
        let joints = feet(10, |t| if t < 5 { -0.07 } else { 0.03 }, 0.0, 30.0);
        acc.add_segment(&joints, &joints, 30.0, 0.0, 0.03);
        let m = acc.finish().unwrap();
        assert!((m.penetration_mean_cm - 5.0).abs() < 1e-4, "{m:?}");
        assert!((m.penetration_worst_cm - 10.0).abs() < 1e-4);
        assert_eq!(m.skating_cm_s, Some(0.0), "standing still");
    }

    #[test]
    fn a_foot_that_slides_while_the_truth_stands_skates() {
        let standing = feet(31, |_| 0.04, 0.0, 30.0);
        let sliding = feet(31, |_| 0.04, 0.5, 30.0);
        let mut acc = FootContactAccumulator::new();
        acc.add_segment(&sliding, &standing, 30.0, 0.0, 0.03);
        let m = acc.finish().unwrap();
        assert!((m.skating_cm_s.unwrap() - 50.0).abs() < 1e-3, "{m:?}");
        assert_eq!(m.contact_pairs, 30 * 4);
        // A truth that walks (feet moving) or swings (feet high) stands on nothing.
        for reference in [sliding.clone(), feet(31, |_| 0.3, 0.0, 30.0)] {
            let mut acc = FootContactAccumulator::new();
            acc.add_segment(&sliding, &reference, 30.0, 0.0, 0.03);
            assert_eq!(acc.finish().unwrap().skating_cm_s, None);
        }
        // The floor's height counts: on a floor 0.3 m lower the same feet are in the air.
        let mut higher = FootContactAccumulator::new();
        higher.add_segment(&sliding, &standing, 30.0, -0.3, 0.03);
        assert_eq!(higher.finish().unwrap().contact_pairs, 0);
    }
}
