//! Wearer devices from the ground-truth body, and the tracking error every SLAM'd device
//! carries.
//!
//! Frames: the glasses use the CPF convention (+X left, +Y up, +Z forward), which is the SMPL
//! head joint's own frame in the rest pose — so the glasses pose is the head joint pose
//! shifted by a fixed offset. Wrist devices use the SMPL wrist joint frames. World Y-up, metres.

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;

use crate::config::DeviceNoise;
use crate::rng::SimRng;

/// `T_world_device` of glasses whose frame has the head joint at `head_joint_in_device`
/// (metres), given the head joint's world pose `T_world_headjoint`.
pub fn glasses_pose(t_world_head_joint: &RigidTransform, head_joint_in_device: Vec3) -> RigidTransform {
    *t_world_head_joint * RigidTransform::from_translation(-head_joint_in_device)
}

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
