//! Exocentric ray canonicalisation (paper § Exocentric Ray-based Pose Canonicalization).
//!
//! A 2D keypoint seen by an observer is lifted to a unit ray `d̂` in the world using the
//! observer camera's calibration and pose, scaled by the observer–wearer head distance,
//! anchored at the observer, and expressed in the wearer's head-device frame:
//!
//! `r = R_wearer_head⁻¹ (p_obs + ‖p_wearer_head − p_obs‖ · d̂ − p_wearer_head)`
//!
//! Frames: world is Y up; `r` is in the wearer's head-device frame (metres). The anchor
//! `p_obs` is the observer camera's optical centre — the point every ray passes through —
//! which sits a few millimetres from the observer's head-device origin on Aria glasses.
//! Because the ray passes through the anchor, a keypoint that is the projection of the
//! wearer's head-device origin maps exactly to `r = 0`.

use glam::{Quat, Vec2, Vec3};
use serde::{Deserialize, Serialize};

use crate::camera::CameraCalibration;
use crate::exo_keypoints::{EXO_KEYPOINT_COUNT, Keypoint2d};
use crate::rigid::RigidTransform;

/// A canonical ray endpoint with its validity flag. Invalid rays carry a zero endpoint.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CanonicalRay {
    /// Endpoint in the wearer's head-device frame, metres (zero when invalid).
    pub endpoint: Vec3,
    /// The keypoint existed and unprojected inside the camera's valid region.
    pub valid: bool,
}

impl CanonicalRay {
    /// The ray of a missing keypoint: zero endpoint, not valid.
    pub const MISSING: CanonicalRay = CanonicalRay { endpoint: Vec3::ZERO, valid: false };
}

/// Canonical endpoint `r` for a keypoint at `pixel` seen by `camera` on an observer device at
/// `t_world_observer_device`, for a wearer whose head device is at `t_world_wearer_head`.
/// `None` if the pixel does not unproject (outside the valid region) or any input is not
/// finite.
pub fn canonicalize_ray(
    pixel: Vec2,
    camera: &CameraCalibration,
    t_world_observer_device: &RigidTransform,
    t_world_wearer_head: &RigidTransform,
) -> Option<Vec3> {
    if !(pixel.is_finite() && t_world_observer_device.is_finite() && t_world_wearer_head.is_finite()) {
        return None;
    }
    let t_world_camera = camera.t_world_camera(t_world_observer_device);
    let direction_world = t_world_camera.transform_vector(camera.unproject(pixel)?).normalize();
    let anchor = t_world_camera.translation;
    let wearer_head = t_world_wearer_head.translation;
    let distance = wearer_head.distance(anchor);
    let endpoint_world = anchor + distance * direction_world;
    let r = t_world_wearer_head.rotation.conjugate() * (endpoint_world - wearer_head);
    r.is_finite().then_some(r)
}

/// Offset from an estimate of a keypoint's 3D position to the keypoint's viewing ray: `q − p`,
/// where `p` is the estimate (world, metres) and `q` the point of the ray through `pixel`
/// closest to it (not behind the camera), expressed in the axes of a frame whose world
/// rotation is `r_world_frame`. The offset is perpendicular to the ray: it is the part of the
/// estimate's error that the observer sees, free of the depth the detection cannot give. With
/// EgoNet's coarse joints as estimates it tells the fusion network where each coarse joint
/// must move. `None` under the same conditions as [`canonicalize_ray`].
pub fn ray_offset_from_estimate(
    pixel: Vec2,
    camera: &CameraCalibration,
    t_world_observer_device: &RigidTransform,
    estimate_world: Vec3,
    r_world_frame: Quat,
) -> Option<Vec3> {
    if !(pixel.is_finite() && t_world_observer_device.is_finite() && estimate_world.is_finite()) {
        return None;
    }
    let t_world_camera = camera.t_world_camera(t_world_observer_device);
    let direction_world = t_world_camera.transform_vector(camera.unproject(pixel)?).normalize();
    let anchor = t_world_camera.translation;
    let depth = (estimate_world - anchor).dot(direction_world).max(0.0);
    let offset_world = anchor + depth * direction_world - estimate_world;
    let offset = r_world_frame.conjugate() * offset_world;
    offset.is_finite().then_some(offset)
}

/// [`ray_offset_from_estimate`] for the 13 keypoints of one observer at one frame, with the
/// 13 estimates in world coordinates; zero where the keypoint is missing, does not unproject or
/// its estimate is not finite.
pub fn ray_offsets_from_estimates(
    keypoints: &[Option<Keypoint2d>; EXO_KEYPOINT_COUNT],
    camera: &CameraCalibration,
    t_world_observer_device: &RigidTransform,
    estimates_world: &[Vec3; EXO_KEYPOINT_COUNT],
    r_world_frame: Quat,
) -> [Vec3; EXO_KEYPOINT_COUNT] {
    std::array::from_fn(|k| {
        keypoints[k]
            .and_then(|kp| {
                ray_offset_from_estimate(kp.pixel, camera, t_world_observer_device, estimates_world[k], r_world_frame)
            })
            .unwrap_or(Vec3::ZERO)
    })
}

/// The 13 canonical rays of one observer at one frame. `None` keypoints (not detected) and
/// keypoints that fail to unproject give [`CanonicalRay::MISSING`].
pub fn canonicalize_keypoints(
    keypoints: &[Option<Keypoint2d>; EXO_KEYPOINT_COUNT],
    camera: &CameraCalibration,
    t_world_observer_device: &RigidTransform,
    t_world_wearer_head: &RigidTransform,
) -> [CanonicalRay; EXO_KEYPOINT_COUNT] {
    keypoints.map(|kp| {
        kp.and_then(|kp| canonicalize_ray(kp.pixel, camera, t_world_observer_device, t_world_wearer_head))
            .map_or(CanonicalRay::MISSING, |endpoint| CanonicalRay { endpoint, valid: true })
    })
}
