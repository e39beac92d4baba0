//! Fixtures and proptest strategies shared by the core's integration tests (native and wasm).
#![allow(dead_code)]

use egoexo_core::camera::{CameraCalibration, Fisheye624, Pinhole, Projection};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use proptest::prelude::*;

/// Project Aria RGB camera intrinsics at 1408×1408 (the core's preset).
pub use egoexo_core::camera::aria_rgb::PARAMS_1408 as ARIA_RGB_1408;
pub use egoexo_core::camera::aria_rgb::t_device_camera as aria_rgb_t_device_camera;

/// Aria RGB at 1408² with a CPF-consistent extrinsic.
pub fn aria_rgb_camera() -> CameraCalibration {
    CameraCalibration::new(
        Projection::Fisheye624(Fisheye624::new(ARIA_RGB_1408).unwrap()),
        1408,
        1408,
        aria_rgb_t_device_camera(),
    )
    .unwrap()
}

/// Aria RGB intrinsics with the camera at the device origin (rotation-only extrinsic).
pub fn aria_rgb_camera_at_device_origin() -> CameraCalibration {
    let mut cam = aria_rgb_camera();
    cam.t_device_camera.translation = Vec3::ZERO;
    cam
}

/// A pinhole camera (640×480) facing forward on a CPF device.
pub fn pinhole_camera() -> CameraCalibration {
    CameraCalibration::new(
        Projection::Pinhole(Pinhole::new(400.0, 410.0, 319.5, 239.5).unwrap()),
        640,
        480,
        RigidTransform::from_rotation(Quat::from_rotation_z(std::f32::consts::PI)),
    )
    .unwrap()
}

/// A uniformly spread unit quaternion.
pub fn any_rotation() -> impl Strategy<Value = Quat> {
    (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0)
        .prop_filter("not near zero", |(x, y, z, w)| x * x + y * y + z * z + w * w > 0.05)
        .prop_map(|(x, y, z, w)| Quat::from_xyzw(x, y, z, w).normalize())
}

/// A rotation by at most `max_angle` radians.
pub fn small_rotation(max_angle: f32) -> impl Strategy<Value = Quat> {
    (any_rotation(), 0.0f32..1.0).prop_map(move |(q, s)| {
        let (axis, _) = q.to_axis_angle();
        Quat::from_axis_angle(axis, s * max_angle)
    })
}

/// A point in a box of half-size `r` metres.
pub fn point(r: f32) -> impl Strategy<Value = Vec3> {
    (-r..r, -r..r, -r..r).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// A rigid transform with translation within `r` metres.
pub fn rigid(r: f32) -> impl Strategy<Value = RigidTransform> {
    (any_rotation(), point(r)).prop_map(|(q, t)| RigidTransform::new(q, t))
}

/// Rotations agree up to the quaternion sign.
pub fn same_rotation(a: Quat, b: Quat, tol: f32) -> bool {
    egoexo_core::rotation::angle_between(a, b) < tol
}
