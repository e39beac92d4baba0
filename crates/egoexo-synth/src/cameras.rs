//! Observer camera presets: Project Aria's RGB camera (Fisheye624) and a pinhole of similar
//! field of view, mounted on a CPF head device.

use egoexo_core::camera::{CameraCalibration, CameraError, Fisheye624, Pinhole, Projection};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;

/// A real Aria RGB factory calibration at 1408×1408 (`[f, cu, cv, k0..k5, p0, p1, s0..s3]`).
pub const ARIA_RGB_1408_PARAMS: [f32; 15] = [
    610.941,
    715.115,
    716.715,
    0.406036,
    -0.489948,
    0.174565,
    1.13298,
    -1.70164,
    0.651156,
    0.000621147,
    1.9322e-05,
    -1.48553e-05,
    0.000260123,
    -0.000658211,
    3.7614e-05,
];

/// Radius of Aria RGB's image circle at 1408 px (pixels from the principal point).
pub const ARIA_RGB_1408_VALID_RADIUS: f32 = 700.0;

/// The RGB camera on the glasses' left temple, looking forward and slightly down:
/// `T_device_camera` for a CPF device (an OpenCV camera is the CPF frame turned 180° about Z).
pub fn aria_rgb_t_device_camera() -> RigidTransform {
    RigidTransform::new(
        Quat::from_rotation_z(std::f32::consts::PI) * Quat::from_rotation_x(-0.2),
        Vec3::new(0.05, 0.012, 0.006),
    )
}

/// Aria's RGB camera at `size × size` pixels (1408 or 2880 on the device).
pub fn aria_rgb_camera(size: u32) -> Result<CameraCalibration, CameraError> {
    let base = CameraCalibration::new(
        Projection::Fisheye624(Fisheye624::new(ARIA_RGB_1408_PARAMS)?),
        1408,
        1408,
        aria_rgb_t_device_camera(),
    )?
    .with_valid_radius(ARIA_RGB_1408_VALID_RADIUS);
    if size == 1408 { Ok(base) } else { base.scaled_to(size, size) }
}

/// An ideal pinhole with a 100° horizontal field of view at `size × size` pixels, mounted
/// like the Aria RGB camera.
pub fn wide_pinhole_camera(size: u32) -> Result<CameraCalibration, CameraError> {
    let s = size as f32;
    let f = 0.5 * s / (50f32.to_radians()).tan();
    let c = 0.5 * s - 0.5;
    CameraCalibration::new(Projection::Pinhole(Pinhole::new(f, f, c, c)?), size, size, aria_rgb_t_device_camera())
}
