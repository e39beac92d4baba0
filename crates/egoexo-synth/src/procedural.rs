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
    walking_circle_around(Vec3::ZERO, 3.0, 1.1, 0.0, 1.55, seconds)
}

/// `seconds` of walking around a circle of `radius` (metres) about `centre` (its y ignored:
/// feet on y = 0) at `speed` (m/s along the circle; negative: clockwise seen from above), starting at
/// angle `phase` (0: at `centre + radius · +Z`), for a person whose head is `head_height` m
/// above the soles. Legs and arms swing at 0.9 Hz whatever the speed.
pub fn walking_circle_around(
    centre: Vec3,
    radius: f32,
    speed: f32,
    phase: f32,
    head_height: f32,
    seconds: f32,
) -> SmplMotion {
    let frames = (seconds * FPS) as usize;
    let turn = if speed < 0.0 { -std::f32::consts::FRAC_PI_2 } else { std::f32::consts::FRAC_PI_2 };
    walking(head_height, frames, |t| {
        let angle = phase + t * speed / radius;
        let position = Vec3::new(centre.x + radius * angle.sin(), 0.0, centre.z + radius * angle.cos());
        // Facing the direction of travel (tangent of the circle).
        (position, angle + turn)
    })
}

/// `seconds` of walking a straight line from `start` (feet on y = 0) at `velocity` (m/s,
/// horizontal), for a person whose head is `head_height` m above the soles.
pub fn walking_line(start: Vec3, velocity: Vec3, head_height: f32, seconds: f32) -> SmplMotion {
    let frames = (seconds * FPS) as usize;
    let yaw = velocity.x.atan2(velocity.z);
    walking(head_height, frames, |t| {
        (Vec3::new(start.x, 0.0, start.z) + Vec3::new(velocity.x, 0.0, velocity.z) * t, yaw)
    })
}

/// `seconds` of wandering a Lissajous figure (3 m × 2 m, periods about 21 s and 13 s): speed
/// and curvature keep changing, so no shift in time looks like a move in space — unlike a
/// circle or a line walked at constant speed, where a clock offset and a rotation (or a
/// translation) of the world cannot be told apart. Head 1.6 m above the soles.
pub fn wandering(seconds: f32) -> SmplMotion {
    let frames = (seconds * FPS) as usize;
    let (wx, wz) = (0.3f32, 0.48f32);
    walking(1.6, frames, |t| {
        let position = Vec3::new(3.0 * (wx * t).sin(), 0.0, 2.0 * (wz * t + 0.7).sin());
        let velocity = Vec3::new(3.0 * wx * (wx * t).cos(), 0.0, 2.0 * wz * (wz * t + 0.7).cos());
        (position, velocity.x.atan2(velocity.z))
    })
}

/// A walking gait along `path(t) → (floor position, facing yaw about +Y)`.
fn walking(head_height: f32, frames: usize, path: impl Fn(f32) -> (Vec3, f32)) -> SmplMotion {
    let skeleton = SmplSkeleton::mean_shape().scaled_to_head_height(head_height).expect("procedural motion is valid");
    let lift = -skeleton.rest_joints().iter().map(|p| p.y).fold(f32::INFINITY, f32::min) - skeleton.rest_joints()[0].y;
    let poses = (0..frames)
        .map(|i| {
            let t = i as f32 / FPS;
            let swing = 0.45 * (2.0 * std::f32::consts::PI * 0.9 * t).sin();
            let mut body = [Quat::IDENTITY; NUM_BODY_JOINTS];
            let set = |body: &mut [Quat; NUM_BODY_JOINTS], j: SmplJoint, q: Quat| body[j.index() - 1] = q;
            set(&mut body, SmplJoint::LeftHip, Quat::from_rotation_x(-swing));
            set(&mut body, SmplJoint::RightHip, Quat::from_rotation_x(swing));
            set(&mut body, SmplJoint::LeftKnee, Quat::from_rotation_x(0.6 * swing.max(0.0)));
            set(&mut body, SmplJoint::RightKnee, Quat::from_rotation_x(0.6 * (-swing).max(0.0)));
            set(&mut body, SmplJoint::LeftShoulder, Quat::from_rotation_z(-1.2) * Quat::from_rotation_y(0.5 * swing));
            set(&mut body, SmplJoint::RightShoulder, Quat::from_rotation_z(1.2) * Quat::from_rotation_y(0.5 * swing));
            let (position, yaw) = path(t);
            SmplPose { root_orientation: Quat::from_rotation_y(yaw), body, translation: position + Vec3::Y * lift }
        })
        .collect();
    SmplMotion::new(FPS, 1_000_000_000, skeleton, None, poses).expect("procedural motion is valid")
}
