//! A sequence of SMPL poses on a fixed-rate timeline: what reconstruction produces, what the
//! exporters write, and what ground truth looks like.
//!
//! Units: metres, seconds; timestamps in nanoseconds on the session's one clock. Frames:
//! Y-up world, SMPL conventions of [`crate::skeleton`].

use glam::Vec3;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::skeleton::{NUM_JOINTS, SmplPose, SmplSkeleton};

/// Errors validating a motion.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MotionError {
    #[error("frame rate must be positive and finite, got {0}")]
    InvalidFps(f32),
    #[error("pose at frame {0} is not finite")]
    NonFinitePose(usize),
    #[error("betas has {got} values; SMPL uses up to 300 and at least 1")]
    InvalidBetas { got: usize },
}

/// SMPL motion at a fixed frame rate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SmplMotion {
    /// Frames per second.
    pub fps: f32,
    /// Timestamp of frame 0, nanoseconds on the session clock.
    pub start_ns: i64,
    /// The skeleton the poses drive (rest joints, metres).
    pub skeleton: SmplSkeleton,
    /// SMPL shape coefficients when known (the skeleton was regressed from them); `None` when
    /// the skeleton is the scaled mean shape.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub betas: Option<Vec<f32>>,
    /// One pose per frame.
    pub poses: Vec<SmplPose>,
}

impl SmplMotion {
    /// Validates and builds a motion.
    pub fn new(
        fps: f32,
        start_ns: i64,
        skeleton: SmplSkeleton,
        betas: Option<Vec<f32>>,
        poses: Vec<SmplPose>,
    ) -> Result<Self, MotionError> {
        if !(fps.is_finite() && fps > 0.0) {
            return Err(MotionError::InvalidFps(fps));
        }
        if let Some(frame) = poses.iter().position(|p| !p.is_finite()) {
            return Err(MotionError::NonFinitePose(frame));
        }
        if let Some(b) = &betas
            && (b.is_empty() || b.len() > 300)
        {
            return Err(MotionError::InvalidBetas { got: b.len() });
        }
        Ok(Self { fps, start_ns, skeleton, betas, poses })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// No frames.
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// Timestamp of frame `i`, nanoseconds.
    pub fn timestamp_ns(&self, i: usize) -> i64 {
        self.start_ns + (i as f64 * 1e9 / f64::from(self.fps)).round() as i64
    }

    /// The motion mirrored left↔right across the world's YZ plane (see [`SmplPose::mirrored`]).
    pub fn mirrored(&self) -> Self {
        Self {
            fps: self.fps,
            start_ns: self.start_ns,
            skeleton: self.skeleton.mirrored(),
            betas: self.betas.clone(),
            poses: self.poses.iter().map(SmplPose::mirrored).collect(),
        }
    }

    /// World positions of the 24 joints of every frame (forward kinematics).
    pub fn joint_positions(&self) -> Vec<[Vec3; NUM_JOINTS]> {
        self.poses.iter().map(|p| self.skeleton.forward_kinematics(p).positions).collect()
    }
}
