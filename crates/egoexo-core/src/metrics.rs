//! Motion metrics in the paper's units (§ Experimental Protocol):
//!
//! - **MPJPE** (cm): mean Euclidean distance between predicted and true world joint positions
//!   over all 24 SMPL joints and all frames.
//! - **U-PE** / **L-PE** (cm): the same over [`UPPER_BODY_JOINTS`] / [`LOWER_BODY_JOINTS`].
//! - **MPJVE** (cm/s): mean norm of the difference of joint velocities, velocities being
//!   forward differences `(p[t+1] − p[t]) · fps`.
//! - **Jitter** (10² m/s³): mean norm of the predicted positions' third finite difference
//!   `(p[t+3] − 3p[t+2] + 3p[t+1] − p[t]) · fps³`, divided by 100.
//!
//! Inputs are world positions in metres (24 joints per frame). Segments are scored
//! independently — no difference crosses a segment boundary — and averaged over every
//! joint-frame term they contribute, as the paper's non-overlapping-segment protocol does.
//! An optional frame selection (e.g. "occluded frames") keeps position terms of selected
//! frames and difference terms whose frames are all selected.

use glam::Vec3;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::skeleton::NUM_JOINTS;

/// Joints of the upper-body error (spine, neck, head and arms), fixed as in
/// `shared/smpl/README.md`.
pub const UPPER_BODY_JOINTS: [usize; 15] = [3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23];
/// Joints of the lower-body error (hips, knees, ankles, feet).
pub const LOWER_BODY_JOINTS: [usize; 8] = [1, 2, 4, 5, 7, 8, 10, 11];

/// One frame's 24 world joint positions, metres.
pub type JointPositions = [Vec3; NUM_JOINTS];

/// The paper's metric row.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MotionMetrics {
    pub mpjpe_cm: f64,
    pub upper_cm: f64,
    pub lower_cm: f64,
    pub mpjve_cm_s: f64,
    /// 10² m/s³.
    pub jitter: f64,
    /// Frames that contributed position terms.
    pub frames: usize,
}

/// Errors scoring motion.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MetricsError {
    #[error("prediction has {pred} frames but ground truth has {gt}")]
    LengthMismatch { pred: usize, gt: usize },
    #[error("frame selection has {got} entries for {expected} frames")]
    SelectionLength { got: usize, expected: usize },
    #[error("frame rate must be positive and finite, got {0}")]
    InvalidFps(f32),
    #[error("{which} joint {joint} at frame {frame} is not finite")]
    NonFinite { which: &'static str, frame: usize, joint: usize },
}

#[derive(Clone, Copy, Debug, Default)]
struct Mean {
    sum: f64,
    count: u64,
}

impl Mean {
    fn add(&mut self, v: f64) {
        self.sum += v;
        self.count += 1;
    }
    fn value(&self) -> f64 {
        if self.count == 0 { f64::NAN } else { self.sum / self.count as f64 }
    }
}

/// Accumulates metrics over many segments.
#[derive(Clone, Debug, Default)]
pub struct MetricsAccumulator {
    all: Mean,
    upper: Mean,
    lower: Mean,
    velocity: Mean,
    jitter: Mean,
    frames: usize,
}

/// One frame's mean position error over `joints`, cm: the per-frame term of MPJPE (all 24
/// joints), U-PE ([`UPPER_BODY_JOINTS`]) or L-PE ([`LOWER_BODY_JOINTS`]). NaN for no joints.
pub fn frame_position_error_cm(pred: &JointPositions, truth: &JointPositions, joints: &[usize]) -> f64 {
    let sum: f64 = joints.iter().map(|&j| dist(pred[j], truth[j])).sum();
    100.0 * sum / joints.len() as f64
}

/// All 24 joints, for [`frame_position_error_cm`].
pub const ALL_JOINTS: [usize; NUM_JOINTS] = {
    let mut all = [0; NUM_JOINTS];
    let mut j = 0;
    while j < NUM_JOINTS {
        all[j] = j;
        j += 1;
    }
    all
};

fn dist(a: Vec3, b: Vec3) -> f64 {
    a.as_dvec3().distance(b.as_dvec3())
}

fn check_finite(which: &'static str, frames: &[JointPositions]) -> Result<(), MetricsError> {
    for (frame, joints) in frames.iter().enumerate() {
        if let Some(joint) = joints.iter().position(|p| !p.is_finite()) {
            return Err(MetricsError::NonFinite { which, frame, joint });
        }
    }
    Ok(())
}

impl MetricsAccumulator {
    /// An empty accumulator.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one segment scored independently. `selected[t]` restricts the terms to selected
    /// frames (`None` = every frame).
    pub fn add_segment(
        &mut self,
        pred: &[JointPositions],
        gt: &[JointPositions],
        fps: f32,
        selected: Option<&[bool]>,
    ) -> Result<(), MetricsError> {
        if pred.len() != gt.len() {
            return Err(MetricsError::LengthMismatch { pred: pred.len(), gt: gt.len() });
        }
        if !(fps.is_finite() && fps > 0.0) {
            return Err(MetricsError::InvalidFps(fps));
        }
        if let Some(s) = selected
            && s.len() != pred.len()
        {
            return Err(MetricsError::SelectionLength { got: s.len(), expected: pred.len() });
        }
        check_finite("predicted", pred)?;
        check_finite("ground-truth", gt)?;
        let is_selected = |range: std::ops::Range<usize>| selected.is_none_or(|s| s[range].iter().all(|&b| b));
        let fps = f64::from(fps);

        for t in 0..pred.len() {
            if !is_selected(t..t + 1) {
                continue;
            }
            self.frames += 1;
            for j in 0..NUM_JOINTS {
                self.all.add(dist(pred[t][j], gt[t][j]));
            }
            for &j in &UPPER_BODY_JOINTS {
                self.upper.add(dist(pred[t][j], gt[t][j]));
            }
            for &j in &LOWER_BODY_JOINTS {
                self.lower.add(dist(pred[t][j], gt[t][j]));
            }
        }
        for t in 0..pred.len().saturating_sub(1) {
            if !is_selected(t..t + 2) {
                continue;
            }
            for j in 0..NUM_JOINTS {
                let v_pred = (pred[t + 1][j] - pred[t][j]).as_dvec3() * fps;
                let v_gt = (gt[t + 1][j] - gt[t][j]).as_dvec3() * fps;
                self.velocity.add(v_pred.distance(v_gt));
            }
        }
        for t in 0..pred.len().saturating_sub(3) {
            if !is_selected(t..t + 4) {
                continue;
            }
            for j in 0..NUM_JOINTS {
                let p = |k: usize| pred[t + k][j].as_dvec3();
                let jerk = (p(3) - 3.0 * p(2) + 3.0 * p(1) - p(0)) * fps * fps * fps;
                self.jitter.add(jerk.length());
            }
        }
        Ok(())
    }

    /// The metrics so far; `None` before any frame was added. A metric with no terms (e.g.
    /// jitter over segments shorter than 4 frames) is NaN.
    pub fn finish(&self) -> Option<MotionMetrics> {
        (self.frames > 0).then(|| MotionMetrics {
            mpjpe_cm: self.all.value() * 100.0,
            upper_cm: self.upper.value() * 100.0,
            lower_cm: self.lower.value() * 100.0,
            mpjve_cm_s: self.velocity.value() * 100.0,
            jitter: self.jitter.value() / 100.0,
            frames: self.frames,
        })
    }
}

/// Scores one sequence as a single segment.
pub fn evaluate(
    pred: &[JointPositions],
    gt: &[JointPositions],
    fps: f32,
) -> Result<Option<MotionMetrics>, MetricsError> {
    let mut acc = MetricsAccumulator::new();
    acc.add_segment(pred, gt, fps, None)?;
    Ok(acc.finish())
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn joint_sets_partition_all_but_the_pelvis() {
        let mut seen = [false; NUM_JOINTS];
        for &j in UPPER_BODY_JOINTS.iter().chain(LOWER_BODY_JOINTS.iter()) {
            assert!(!seen[j], "joint {j} in both sets");
            seen[j] = true;
        }
        assert_eq!(seen.iter().filter(|&&s| !s).count(), 1);
        assert!(!seen[0]);
    }

    #[test]
    fn per_frame_errors_average_to_the_metrics() {
        let frames = 7;
        let truth: Vec<JointPositions> =
            (0..frames).map(|t| std::array::from_fn(|j| Vec3::new(j as f32 * 0.1, t as f32 * 0.05, 0.0))).collect();
        let pred: Vec<JointPositions> = truth
            .iter()
            .enumerate()
            .map(|(t, f)| std::array::from_fn(|j| f[j] + Vec3::new(0.01 * (t + j % 3) as f32, 0.0, 0.02)))
            .collect();
        let m = evaluate(&pred, &truth, 30.0).unwrap().unwrap();
        let mean = |joints: &[usize]| {
            (0..frames).map(|t| frame_position_error_cm(&pred[t], &truth[t], joints)).sum::<f64>() / frames as f64
        };
        assert!((mean(&ALL_JOINTS) - m.mpjpe_cm).abs() < 1e-9);
        assert!((mean(&LOWER_BODY_JOINTS) - m.lower_cm).abs() < 1e-9);
        assert!((mean(&UPPER_BODY_JOINTS) - m.upper_cm).abs() < 1e-9);
        assert!(frame_position_error_cm(&pred[0], &truth[0], &[]).is_nan());
    }
}
