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

use serde::{Deserialize, Serialize};

use crate::metrics::JointPositions;

/// The ankle and foot joints (SMPL order).
pub const FOOT_JOINTS: [usize; 4] = [7, 8, 10, 11];
/// Height of the ankle/foot joints above the soles for the mean shape, metres.
pub const FOOT_JOINT_ABOVE_SOLE_M: f32 = 0.03;
/// A sole closer than this to the floor can be in contact, metres.
pub const CONTACT_HEIGHT_M: f32 = 0.05;
/// A foot joint slower than this (horizontally) can be in contact, m/s.
pub const STANCE_SPEED_M_S: f32 = 0.25;

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
