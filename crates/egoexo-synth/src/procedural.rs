//! A procedural wearer motion for tests, examples and benchmarks: walking a circle with
//! swinging legs and arms, feet on y = 0. Not a substitute for real motion (see
//! `egoexo-mocap`), but deterministic and available everywhere.

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::motion::SmplMotion;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, SmplJoint, SmplPose, SmplSkeleton};

/// Frame rate of the procedural motions.
pub const FPS: f32 = 30.0;

/// `seconds` of walking around a circle of radius 3 m at about 1.1 m/s.
pub fn walking_circle(seconds: f32) -> SmplMotion {
    let skeleton = SmplSkeleton::mean_shape().scaled_to_head_height(1.55).expect("procedural motion is valid");
    let lift = -skeleton.rest_joints().iter().map(|p| p.y).fold(f32::INFINITY, f32::min) - skeleton.rest_joints()[0].y;
    let frames = (seconds * FPS) as usize;
    let poses = (0..frames)
        .map(|i| {
            let t = i as f32 / FPS;
            let angle = t * 1.1 / 3.0;
            let swing = 0.45 * (2.0 * std::f32::consts::PI * 0.9 * t).sin();
            let mut body = [Quat::IDENTITY; NUM_BODY_JOINTS];
            let set = |body: &mut [Quat; NUM_BODY_JOINTS], j: SmplJoint, q: Quat| body[j.index() - 1] = q;
            set(&mut body, SmplJoint::LeftHip, Quat::from_rotation_x(-swing));
            set(&mut body, SmplJoint::RightHip, Quat::from_rotation_x(swing));
            set(&mut body, SmplJoint::LeftKnee, Quat::from_rotation_x(0.6 * swing.max(0.0)));
            set(&mut body, SmplJoint::RightKnee, Quat::from_rotation_x(0.6 * (-swing).max(0.0)));
            set(&mut body, SmplJoint::LeftShoulder, Quat::from_rotation_z(-1.2) * Quat::from_rotation_y(0.5 * swing));
            set(&mut body, SmplJoint::RightShoulder, Quat::from_rotation_z(1.2) * Quat::from_rotation_y(0.5 * swing));
            // Facing the direction of travel (tangent of the circle).
            let position = Vec3::new(3.0 * angle.sin(), 0.0, 3.0 * angle.cos());
            let facing = Quat::from_rotation_y(angle + std::f32::consts::FRAC_PI_2);
            SmplPose { root_orientation: facing, body, translation: position + Vec3::Y * lift }
        })
        .collect();
    SmplMotion::new(FPS, 1_000_000_000, skeleton, None, poses).expect("procedural motion is valid")
}
