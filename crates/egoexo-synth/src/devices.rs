//! Wearer devices from the ground-truth body, and the tracking error every SLAM'd device
//! carries.
//!
//! Frames: the glasses use the CPF convention (+X left, +Y up, +Z forward), which is the SMPL
//! head joint's own frame in the rest pose — so the glasses pose is the head joint pose
//! shifted by a fixed offset. Wrist devices use the SMPL wrist joint frames. World Y-up, metres.

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;

use crate::config::{DeviceNoise, HandTrackingModel};
use crate::rng::SimRng;

/// Adds tracking error to a true trajectory sampled at `fps`: white position/orientation
/// jitter plus slowly drifting position and heading (random walks).
pub fn add_tracking_noise(
    truth: &[RigidTransform],
    fps: f32,
    noise: &DeviceNoise,
    rng: &mut SimRng,
) -> Vec<RigidTransform> {
    let dt_sqrt = (1.0 / fps).sqrt();
    let mut drift_position = Vec3::ZERO;
    let mut drift_yaw = 0.0f32;
    truth
        .iter()
        .map(|pose| {
            drift_position += rng.normal_vec3(noise.position_drift_m_per_sqrt_s * dt_sqrt);
            drift_yaw += rng.normal(0.0, noise.yaw_drift_rad_per_sqrt_s * dt_sqrt);
            let jitter_axis = rng.unit_vec3();
            let jitter_angle = rng.normal(0.0, noise.orientation_jitter_rad);
            let rotation =
                Quat::from_rotation_y(drift_yaw) * Quat::from_axis_angle(jitter_axis, jitter_angle) * pose.rotation;
            let translation = pose.translation + drift_position + rng.normal_vec3(noise.position_jitter_m);
            RigidTransform::new(rotation, translation)
        })
        .collect()
}

/// What the glasses' hand tracking reports for one wrist: the frames (indices into the
/// inputs) where the wrist was seen, and `T_world_wrist` there.
#[derive(Clone, Debug, PartialEq)]
pub struct HandTrackingSamples {
    pub frames: Vec<usize>,
    pub poses: Vec<RigidTransform>,
    /// Confidence of each reported sample, in `[min_confidence, 1]`.
    pub confidence: Vec<f32>,
}

/// Simulates hand tracking of one wrist from the glasses: `glasses` are the *measured*
/// `T_world_device` (so the wrist inherits the head's tracking error, as MPS's
/// `T_world_device · T_device_wrist` does), `truth` the true glasses and wrist poses per
/// frame at `fps`. A wrist is seen while it lies inside the view cone and distance range
/// (measured on the true poses), is not in a dropout, and its confidence reaches the
/// threshold.
pub fn simulate_hand_tracking(
    glasses: &[RigidTransform],
    true_glasses: &[RigidTransform],
    true_wrist: &[RigidTransform],
    fps: f32,
    model: &HandTrackingModel,
    rng: &mut SimRng,
) -> HandTrackingSamples {
    let axis = Quat::from_rotation_x(model.view_axis_pitch_down_rad) * Vec3::Z;
    let mut out = HandTrackingSamples { frames: Vec::new(), poses: Vec::new(), confidence: Vec::new() };
    let mut dropout_left = 0usize;
    for f in 0..true_wrist.len().min(glasses.len()).min(true_glasses.len()) {
        // Spontaneous dropouts (motion blur, the other hand in front, a missed detection).
        if dropout_left == 0 && rng.chance(1.0 / (model.dropout_interval_s * fps).max(1.0)) {
            let (lo, hi) = model.dropout_duration_s;
            dropout_left = (rng.uniform(lo, hi) * fps).round().max(1.0) as usize;
        }
        let dropped = dropout_left > 0;
        dropout_left = dropout_left.saturating_sub(1);
        // The wrist in the glasses' frame (CPF: +Z forward, +Y up).
        let local = true_glasses[f].inverse().transform_point(true_wrist[f].translation);
        let distance = local.length();
        if dropped || !(model.distance_m.0..=model.distance_m.1).contains(&distance) {
            continue;
        }
        let angle = (local / distance).dot(axis).clamp(-1.0, 1.0).acos();
        if angle >= model.view_half_angle_rad {
            continue;
        }
        let confidence = (1.0 - (angle / model.view_half_angle_rad).powi(4) + rng.normal(0.0, model.confidence_noise))
            .clamp(0.0, 1.0);
        if confidence < model.min_confidence {
            continue;
        }
        // Measured: the wrist relative to the true glasses, carried by the measured glasses,
        // plus detection noise.
        let t_device_wrist = true_glasses[f].inverse() * true_wrist[f];
        let jitter = Quat::from_axis_angle(rng.unit_vec3(), rng.normal(0.0, model.orientation_noise_rad));
        let noisy = RigidTransform::new(
            jitter * t_device_wrist.rotation,
            t_device_wrist.translation + rng.normal_vec3(model.position_noise_m),
        );
        out.frames.push(f);
        out.poses.push(glasses[f] * noisy);
        out.confidence.push(confidence);
    }
    out
}
