//! Honest baselines that need no trained network, run through the same windowing and root
//! recovery as the networks:
//!
//! - **rest pose**: SMPL's rest pose hung from the head device, turned to the head's heading.
//! - **nearest neighbour**: for each frame, the pose of the training frame whose ego feature
//!   vector is closest (standardised Euclidean distance), expressed in the window frame.

use egoexo_core::ego_features::{EGO_FEATURE_DIM, heading_yaw};
use egoexo_core::glam::Quat;
use egoexo_core::skeleton::NUM_BODY_JOINTS;
use serde::{Deserialize, Serialize};

use crate::inputs::{EgoWindow, POSE_DIM, encode_pose};
use crate::windows::WINDOW;

/// The rest-pose baseline's window-frame poses: identity body, root turned to the head's
/// heading relative to the window.
pub fn rest_pose_window(window: &EgoWindow) -> Vec<f32> {
    let r_window_world = window.t_world_window.rotation.conjugate();
    let mut out = vec![0.0; WINDOW * POSE_DIM];
    for (t, head) in window.head.iter().enumerate() {
        let yaw = heading_yaw(r_window_world * head.rotation);
        encode_pose(
            Quat::from_rotation_y(yaw),
            &[Quat::IDENTITY; NUM_BODY_JOINTS],
            &mut out[t * POSE_DIM..(t + 1) * POSE_DIM],
        );
    }
    out
}

/// Training frames for the nearest-neighbour baseline: ego feature rows and their poses.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct NearestNeighbourIndex {
    /// `n × EGO_FEATURE_DIM`, standardised.
    features: Vec<f32>,
    /// `n × POSE_DIM`, window frame.
    poses: Vec<f32>,
    mean: Vec<f32>,
    inv_std: Vec<f32>,
}

impl NearestNeighbourIndex {
    /// Builds an index from raw feature rows and their poses (same number of rows).
    pub fn build(features: &[f32], poses: &[f32]) -> Option<Self> {
        let n = features.len() / EGO_FEATURE_DIM;
        if n == 0 || features.len() != n * EGO_FEATURE_DIM || poses.len() != n * POSE_DIM {
            return None;
        }
        let mut mean = vec![0.0f64; EGO_FEATURE_DIM];
        let mut var = vec![0.0f64; EGO_FEATURE_DIM];
        for row in features.chunks_exact(EGO_FEATURE_DIM) {
            for (m, &v) in mean.iter_mut().zip(row) {
                *m += f64::from(v) / n as f64;
            }
        }
        for row in features.chunks_exact(EGO_FEATURE_DIM) {
            for ((s, &v), m) in var.iter_mut().zip(row).zip(&mean) {
                *s += (f64::from(v) - m).powi(2) / n as f64;
            }
        }
        // Constant dimensions (e.g. zeroed wrist slots) get unit scale rather than infinity.
        let inv_std: Vec<f32> = var.iter().map(|v| if *v > 1e-10 { (1.0 / v.sqrt()) as f32 } else { 1.0 }).collect();
        let mean: Vec<f32> = mean.iter().map(|m| *m as f32).collect();
        let standardised = features
            .chunks_exact(EGO_FEATURE_DIM)
            .flat_map(|row| row.iter().zip(&mean).zip(&inv_std).map(|((v, m), s)| (v - m) * s).collect::<Vec<_>>())
            .collect();
        Some(Self { features: standardised, poses: poses.to_vec(), mean, inv_std })
    }

    /// Number of indexed frames.
    pub fn len(&self) -> usize {
        self.features.len() / EGO_FEATURE_DIM
    }

    /// Nothing indexed.
    pub fn is_empty(&self) -> bool {
        self.features.is_empty()
    }

    /// The pose row of the nearest indexed frame to one raw feature row.
    pub fn nearest(&self, row: &[f32]) -> &[f32] {
        let query: Vec<f32> = row.iter().zip(&self.mean).zip(&self.inv_std).map(|((v, m), s)| (v - m) * s).collect();
        let mut best = (f32::INFINITY, 0);
        for (i, candidate) in self.features.chunks_exact(EGO_FEATURE_DIM).enumerate() {
            let mut d = 0.0;
            for (a, b) in candidate.iter().zip(&query) {
                d += (a - b) * (a - b);
                if d >= best.0 {
                    break;
                }
            }
            if d < best.0 {
                best = (d, i);
            }
        }
        &self.poses[best.1 * POSE_DIM..(best.1 + 1) * POSE_DIM]
    }

    /// The nearest-neighbour poses of one window.
    pub fn window_poses(&self, window: &EgoWindow) -> Vec<f32> {
        window.ego.chunks_exact(EGO_FEATURE_DIM).flat_map(|row| self.nearest(row).to_vec()).collect()
    }
}
