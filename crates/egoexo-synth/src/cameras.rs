//! Observer camera presets: Project Aria's RGB camera (Fisheye624) and a pinhole of similar
//! field of view, mounted on a CPF head device.

use egoexo_core::camera::{CameraCalibration, CameraError, Pinhole, Projection};

/// Aria's RGB camera at `size × size` pixels (1408 or 2880 on the device): the core's preset.
pub use egoexo_core::camera::aria_rgb::camera as aria_rgb_camera;
use egoexo_core::camera::aria_rgb::t_device_camera as aria_rgb_t_device_camera;

/// An ideal pinhole with a 100° horizontal field of view at `size × size` pixels, mounted
/// like the Aria RGB camera.
pub fn wide_pinhole_camera(size: u32) -> Result<CameraCalibration, CameraError> {
    let s = size as f32;
    let f = 0.5 * s / (50f32.to_radians()).tan();
    let c = 0.5 * s - 0.5;
    CameraCalibration::new(Projection::Pinhole(Pinhole::new(f, f, c, c)?), size, size, aria_rgb_t_device_camera())
}
