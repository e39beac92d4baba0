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

/// The world line of sight of one keypoint: from the observer camera's optical centre through
/// the unprojected pixel. Unprojecting is the costly step (Fisheye624 is inverted
/// iteratively), so a keypoint is unprojected once and both the canonical endpoint and the
/// offset are taken from this.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewingRay {
    /// The camera's optical centre, world (metres).
    pub anchor: Vec3,
    /// Unit direction, world.
    pub direction: Vec3,
}

impl ViewingRay {
    /// The ray through `pixel` of `camera` on an observer device at `t_world_observer_device`.
    /// `None` if the pixel does not unproject (outside the valid region) or an input is not
    /// finite.
    pub fn through_pixel(
        pixel: Vec2,
        camera: &CameraCalibration,
        t_world_observer_device: &RigidTransform,
    ) -> Option<Self> {
        if !(pixel.is_finite() && t_world_observer_device.is_finite()) {
            return None;
        }
        let t_world_camera = camera.t_world_camera(t_world_observer_device);
        let direction = t_world_camera.transform_vector(camera.unproject(pixel)?).normalize();
        let anchor = t_world_camera.translation;
        (direction.is_finite() && anchor.is_finite()).then_some(Self { anchor, direction })
    }

    /// Canonical endpoint `r` (wearer head-device frame, metres) for a wearer whose head device
    /// is at `t_world_wearer_head`: the point of the ray at the head's distance from the anchor.
    pub fn canonical_endpoint(&self, t_world_wearer_head: &RigidTransform) -> Option<Vec3> {
        if !t_world_wearer_head.is_finite() {
            return None;
        }
        let wearer_head = t_world_wearer_head.translation;
        let distance = wearer_head.distance(self.anchor);
        let endpoint_world = self.anchor + distance * self.direction;
        let r = t_world_wearer_head.rotation.conjugate() * (endpoint_world - wearer_head);
        r.is_finite().then_some(r)
    }

    /// Offset from an estimate `p` of the keypoint's 3D position (world, metres) to this ray:
    /// `q − p` with `q` the point of the ray closest to `p` (not behind the camera), in the axes
    /// of a frame whose world rotation is `r_world_frame`. Perpendicular to the ray: the part
    /// of the estimate's error the observer sees, free of the depth a detection cannot give.
    pub fn offset_from(&self, estimate_world: Vec3, r_world_frame: Quat) -> Option<Vec3> {
        if !estimate_world.is_finite() {
            return None;
        }
        let depth = (estimate_world - self.anchor).dot(self.direction).max(0.0);
        let offset_world = self.anchor + depth * self.direction - estimate_world;
        let offset = r_world_frame.conjugate() * offset_world;
        offset.is_finite().then_some(offset)
    }
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
    ViewingRay::through_pixel(pixel, camera, t_world_observer_device)?.canonical_endpoint(t_world_wearer_head)
}

/// The 13 keypoints of one observer at one frame, each unprojected once: its canonical ray
/// (as [`canonicalize_keypoints`]) and the offset from `estimates_world[k]` — with EgoNet's
/// coarse keypoints, where each coarse joint must move — in the axes of `r_world_frame`
/// ([`ViewingRay::offset_from`]; zero where the ray is invalid or the estimate is not finite).
pub fn canonicalize_keypoints_with_offsets(
    keypoints: &[Option<Keypoint2d>; EXO_KEYPOINT_COUNT],
    camera: &CameraCalibration,
    t_world_observer_device: &RigidTransform,
    t_world_wearer_head: &RigidTransform,
    estimates_world: &[Vec3; EXO_KEYPOINT_COUNT],
    r_world_frame: Quat,
) -> [(CanonicalRay, Vec3); EXO_KEYPOINT_COUNT] {
    std::array::from_fn(|k| {
        let seen = keypoints[k]
            .and_then(|kp| ViewingRay::through_pixel(kp.pixel, camera, t_world_observer_device))
            .and_then(|ray| Some((ray, ray.canonical_endpoint(t_world_wearer_head)?)));
        let Some((ray, endpoint)) = seen else {
            return (CanonicalRay::MISSING, Vec3::ZERO);
        };
        let offset = ray.offset_from(estimates_world[k], r_world_frame).unwrap_or(Vec3::ZERO);
        (CanonicalRay { endpoint, valid: true }, offset)
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
