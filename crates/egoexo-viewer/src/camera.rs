//! The orbit camera of the 3D view: it circles a target point in the world (Y-up, metres).
//!
//! Pointer deltas are CSS pixels; angles are radians. The projection maps view depth to
//! wgpu's `0..1` clip range (right-handed view space, camera looking down −Z).

use glam::camera::rh::{proj::directx, view};
use glam::{Mat4, Quat, Vec2, Vec3, Vec4};

/// Vertical field of view of the view camera, radians.
pub const FOV_Y: f32 = 0.8;
/// Radians of orbit per CSS pixel of pointer drag.
pub const ORBIT_RAD_PER_PX: f32 = 0.006;
/// Closest and farthest orbit distances, metres.
pub const DISTANCE_RANGE: (f32, f32) = (0.25, 400.0);
/// Highest elevation above (or below) the horizon, radians: just short of the poles so the
/// view never flips.
pub const MAX_PITCH: f32 = 1.55;

/// An axis-aligned box in the world, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub min: Vec3,
    pub max: Vec3,
}

impl Bounds {
    /// The box around `points` (non-finite points are skipped); `None` when there are none.
    pub fn around(points: impl IntoIterator<Item = Vec3>) -> Option<Self> {
        points.into_iter().filter(|p| p.is_finite()).fold(None, |b, p| {
            Some(match b {
                None => Self { min: p, max: p },
                Some(Self { min, max }) => Self { min: min.min(p), max: max.max(p) },
            })
        })
    }

    pub fn centre(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Radius of the sphere through the corners, metres.
    pub fn radius(&self) -> f32 {
        0.5 * (self.max - self.min).length()
    }
}

/// Where a frame is drawn from: world → clip (wgpu's `0..1` depth) and the eye in the world,
/// metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewPoint {
    pub view_projection: Mat4,
    pub position: Vec3,
}

impl ViewPoint {
    /// Pixel position (origin top-left, +y down) of world point `p` in a `width × height`
    /// viewport, or `None` behind the eye.
    pub fn project(&self, p: Vec3, width: f32, height: f32) -> Option<Vec2> {
        let clip = self.view_projection * p.extend(1.0);
        if clip.w <= 1e-6 {
            return None;
        }
        let ndc = clip.truncate() / clip.w;
        Some(Vec2::new((ndc.x + 1.0) * 0.5 * width, (1.0 - ndc.y) * 0.5 * height))
    }

    /// The view through an observer's camera: `rotation`, `centre` = `T_world_camera` of its
    /// optical frame (+X right, +Y down, +Z forward), vertical half field of view
    /// `half_fov_y` radians (wider lenses are drawn at [`MAX_OBSERVER_HALF_FOV`]: a perspective
    /// view cannot show a fisheye's whole field), in a viewport of `aspect` = width / height.
    pub fn through_camera(rotation: Quat, centre: Vec3, half_fov_y: f32, aspect: f32) -> Self {
        let aspect = if aspect.is_finite() && aspect > 0.0 { aspect } else { 1.0 };
        let half_fov_y = if half_fov_y.is_finite() { half_fov_y.clamp(0.05, MAX_OBSERVER_HALF_FOV) } else { 0.6 };
        // World → optical, then optical (+Y down, +Z forward) → view (+Y up, looking down −Z).
        let world_to_optical = Mat4::from_rotation_translation(rotation, centre).inverse();
        let optical_to_view = Mat4::from_cols(Vec4::X, -Vec4::Y, -Vec4::Z, Vec4::W);
        let projection = directx::perspective(2.0 * half_fov_y, aspect, 0.05, 200.0);
        Self { view_projection: projection * optical_to_view * world_to_optical, position: centre }
    }
}

/// The widest vertical half field of view an observer's view is drawn with, radians.
pub const MAX_OBSERVER_HALF_FOV: f32 = 1.1;

/// A camera orbiting `target` at `distance`, seen from heading `yaw` (about +Y; 0 looks along
/// −Z from the +Z side) and elevation `pitch` (positive = from above).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbitCamera {
    /// Point looked at, world metres.
    pub target: Vec3,
    /// Radians about world +Y.
    pub yaw: f32,
    /// Radians above the horizon, within ±[`MAX_PITCH`].
    pub pitch: f32,
    /// Metres from the target, within [`DISTANCE_RANGE`].
    pub distance: f32,
}

impl Default for OrbitCamera {
    fn default() -> Self {
        Self { target: Vec3::new(0.0, 1.0, 0.0), yaw: 0.6, pitch: 0.35, distance: 4.5 }
    }
}

impl OrbitCamera {
    /// A camera that shows all of `bounds` from the default heading and elevation.
    pub fn framing(bounds: Bounds, aspect: f32) -> Self {
        let mut camera = Self::default();
        camera.frame(bounds, aspect);
        camera
    }

    /// Re-targets the camera to the centre of `bounds` and backs off just enough (plus a 6 %
    /// margin) for all eight corners to project inside a viewport of `aspect` = width / height;
    /// keeps the heading and elevation.
    pub fn frame(&mut self, bounds: Bounds, aspect: f32) {
        let aspect = if aspect.is_finite() && aspect > 0.0 { aspect } else { 1.0 };
        let tan_y = (FOV_Y * 0.5).tan();
        let tan_x = tan_y * aspect;
        self.target = bounds.centre();
        // Unit vectors of the view: right, up, and back (from the target towards the eye).
        let back = (self.eye() - self.target).normalize_or(Vec3::Z);
        let right = Vec3::Y.cross(back).normalize_or(Vec3::X);
        let up = back.cross(right);
        let mut distance = 0.5f32;
        for corner in 0..8 {
            let c = Vec3::new(
                if corner & 1 == 0 { bounds.min.x } else { bounds.max.x },
                if corner & 2 == 0 { bounds.min.y } else { bounds.max.y },
                if corner & 4 == 0 { bounds.min.z } else { bounds.max.z },
            ) - self.target;
            // A corner at depth `distance - c·back` fits when its offsets fit the half-FOVs.
            let needed = c.dot(back) + (c.dot(right).abs() / tan_x).max(c.dot(up).abs() / tan_y);
            distance = distance.max(needed);
        }
        self.distance = if distance.is_finite() {
            (1.06 * distance).clamp(DISTANCE_RANGE.0, DISTANCE_RANGE.1)
        } else {
            DISTANCE_RANGE.1
        };
    }

    /// Eye position in the world, metres.
    pub fn eye(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        self.target + self.distance * Vec3::new(cp * sy, sp, cp * cy)
    }

    /// Orbits by a pointer drag of `(dx, dy)` CSS pixels: right drags turn the scene right,
    /// down drags tilt the view from above.
    pub fn orbit(&mut self, dx: f32, dy: f32) {
        if !(dx.is_finite() && dy.is_finite()) {
            return;
        }
        self.yaw = (self.yaw - dx * ORBIT_RAD_PER_PX).rem_euclid(std::f32::consts::TAU);
        self.pitch = (self.pitch + dy * ORBIT_RAD_PER_PX).clamp(-MAX_PITCH, MAX_PITCH);
    }

    /// Pans by a drag of `(dx, dy)` CSS pixels in a viewport `viewport_height` CSS pixels tall,
    /// so that the point under the pointer (at the target's depth) follows it.
    pub fn pan(&mut self, dx: f32, dy: f32, viewport_height: f32) {
        if !(dx.is_finite() && dy.is_finite() && viewport_height.is_finite() && viewport_height > 0.0) {
            return;
        }
        let metres_per_px = 2.0 * self.distance * (FOV_Y * 0.5).tan() / viewport_height;
        let forward = (self.target - self.eye()).normalize_or_zero();
        let right = forward.cross(Vec3::Y).normalize_or(Vec3::X);
        let up = right.cross(forward);
        self.target += (-dx * right + dy * up) * metres_per_px;
    }

    /// Zooms by a wheel movement (`deltaY` in CSS pixels; positive = away), exponentially so
    /// that every notch changes the distance by the same ratio.
    pub fn zoom(&mut self, wheel_delta_y: f32) {
        if !wheel_delta_y.is_finite() {
            return;
        }
        let factor = (wheel_delta_y.clamp(-500.0, 500.0) * 0.0015).exp();
        self.distance = (self.distance * factor).clamp(DISTANCE_RANGE.0, DISTANCE_RANGE.1);
    }

    /// World → view transform.
    pub fn view(&self) -> Mat4 {
        view::look_at_mat4(self.eye(), self.target, Vec3::Y)
    }

    /// View → clip transform for a viewport of `aspect` = width / height; near and far planes
    /// follow the orbit distance so that depth precision stays useful at every zoom.
    pub fn projection(&self, aspect: f32) -> Mat4 {
        let aspect = if aspect.is_finite() && aspect > 0.0 { aspect } else { 1.0 };
        let near = (self.distance * 0.01).clamp(0.01, 1.0);
        let far = self.distance * 20.0 + 100.0;
        directx::perspective(FOV_Y, aspect, near, far)
    }

    /// World → clip transform.
    pub fn view_projection(&self, aspect: f32) -> Mat4 {
        self.projection(aspect) * self.view()
    }

    /// This camera as a [`ViewPoint`] for a viewport of `aspect` = width / height.
    pub fn view_point(&self, aspect: f32) -> ViewPoint {
        ViewPoint { view_projection: self.view_projection(aspect), position: self.eye() }
    }

    /// Pixel position (origin top-left, +y down) of world point `p` in a `width × height`
    /// viewport, or `None` behind the camera.
    pub fn project(&self, p: Vec3, width: f32, height: f32) -> Option<Vec2> {
        let clip = self.view_projection(width / height) * p.extend(1.0);
        if clip.w <= 1e-6 {
            return None;
        }
        let ndc = clip.truncate() / clip.w;
        Some(Vec2::new((ndc.x + 1.0) * 0.5 * width, (1.0 - ndc.y) * 0.5 * height))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn the_target_projects_to_the_viewport_centre() {
        let cam = OrbitCamera { target: Vec3::new(1.0, 0.5, -2.0), yaw: 1.2, pitch: 0.4, distance: 3.0 };
        let p = cam.project(cam.target, 640.0, 480.0).unwrap();
        assert!((p - Vec2::new(320.0, 240.0)).length() < 1e-3, "{p}");
        assert!(((cam.eye() - cam.target).length() - 3.0).abs() < 1e-5);
        // Y-up: a point above the target is higher on screen (smaller y).
        let above = cam.project(cam.target + Vec3::Y * 0.3, 640.0, 480.0).unwrap();
        assert!(above.y < 240.0);
        // Behind the eye is not drawn.
        let behind = cam.eye() + (cam.eye() - cam.target);
        assert!(cam.project(behind, 640.0, 480.0).is_none());
    }

    #[test]
    fn depth_is_in_wgpu_clip_range() {
        let cam = OrbitCamera::default();
        let clip = cam.view_projection(1.5) * cam.target.extend(1.0);
        let z = clip.z / clip.w;
        assert!((0.0..1.0).contains(&z), "{z}");
    }

    #[test]
    fn orbit_keeps_distance_and_clamps_pitch() {
        let mut cam = OrbitCamera::default();
        cam.orbit(123.0, 0.0);
        assert!(((cam.eye() - cam.target).length() - cam.distance).abs() < 1e-4);
        cam.orbit(0.0, 1e6);
        assert_eq!(cam.pitch, MAX_PITCH);
        cam.orbit(0.0, -1e6);
        assert_eq!(cam.pitch, -MAX_PITCH);
        let before = cam;
        cam.orbit(f32::NAN, 1.0);
        assert_eq!(cam, before);
    }

    #[test]
    fn pan_moves_the_grabbed_point_with_the_pointer() {
        let mut cam = OrbitCamera::default();
        let (w, h) = (800.0, 600.0);
        let grabbed = cam.target;
        let before = cam.project(grabbed, w, h).unwrap();
        cam.pan(40.0, -25.0, h);
        let after = cam.project(grabbed, w, h).unwrap();
        let moved = after - before;
        assert!((moved - Vec2::new(40.0, -25.0)).length() < 0.5, "{moved}");
    }

    #[test]
    fn zoom_is_multiplicative_and_bounded() {
        let mut cam = OrbitCamera::default();
        let d = cam.distance;
        cam.zoom(100.0);
        let out = cam.distance;
        assert!(out > d);
        cam.zoom(-100.0);
        assert!((cam.distance - d).abs() < 1e-4);
        for _ in 0..1000 {
            cam.zoom(-500.0);
        }
        assert_eq!(cam.distance, DISTANCE_RANGE.0);
        cam.zoom(f32::INFINITY);
        assert_eq!(cam.distance, DISTANCE_RANGE.0);
    }

    #[test]
    fn framing_shows_the_whole_box() {
        let bounds = Bounds::around([Vec3::new(-3.0, 0.0, -1.0), Vec3::new(2.0, 1.8, 4.0), Vec3::NAN]).unwrap();
        for aspect in [0.5f32, 1.0, 2.5] {
            let cam = OrbitCamera::framing(bounds, aspect);
            let (w, h) = (1000.0 * aspect, 1000.0);
            let mut widest = 0.0f32;
            for corner in 0..8 {
                let c = Vec3::new(
                    if corner & 1 == 0 { bounds.min.x } else { bounds.max.x },
                    if corner & 2 == 0 { bounds.min.y } else { bounds.max.y },
                    if corner & 4 == 0 { bounds.min.z } else { bounds.max.z },
                );
                let p = cam.project(c, w, h).unwrap();
                assert!(p.x > 0.0 && p.x < w && p.y > 0.0 && p.y < h, "aspect {aspect}: {c} → {p}");
                widest = widest.max((2.0 * p.x / w - 1.0).abs()).max((2.0 * p.y / h - 1.0).abs());
            }
            // Tight: the box fills the viewport up to the margin in one direction.
            assert!(widest > 0.85, "aspect {aspect}: the box only reaches {widest} of the half-viewport");
        }
        assert!(Bounds::around([Vec3::NAN]).is_none());
    }

    #[test]
    fn an_observer_view_sees_what_its_camera_sees() {
        // A camera at (0, 1.6, 3) looking along −Z (optical +Z → world −Z, +Y down → world −Y).
        let rotation = Quat::from_rotation_x(std::f32::consts::PI);
        let centre = Vec3::new(0.0, 1.6, 3.0);
        let view = ViewPoint::through_camera(rotation, centre, 0.5, 4.0 / 3.0);
        let (w, h) = (640.0, 480.0);
        // Straight ahead: the image centre.
        let ahead = view.project(centre - Vec3::Z * 2.0, w, h).unwrap();
        assert!((ahead - Vec2::new(320.0, 240.0)).length() < 1e-3, "{ahead}");
        // Up in the world is up in the image; +X in the world (the camera's right) is right.
        let up = view.project(centre + Vec3::new(0.0, 0.3, -2.0), w, h).unwrap();
        assert!(up.y < 240.0 && (up.x - 320.0).abs() < 1e-3, "{up}");
        let right = view.project(centre + Vec3::new(0.3, 0.0, -2.0), w, h).unwrap();
        assert!(right.x > 320.0, "{right}");
        // The half field of view reaches the image's top edge.
        let edge = view.project(centre + Vec3::new(0.0, 2.0 * 0.5f32.tan(), -2.0), w, h).unwrap();
        assert!(edge.y.abs() < 0.5, "{edge}");
        // Behind the camera: nothing.
        assert!(view.project(centre + Vec3::Z, w, h).is_none());
        // A fisheye's field is clamped; nonsense is not drawn as nonsense.
        let wide = ViewPoint::through_camera(rotation, centre, 1.5, 1.0);
        let clamped = ViewPoint::through_camera(rotation, centre, MAX_OBSERVER_HALF_FOV, 1.0);
        assert_eq!(wide, clamped);
        assert!(ViewPoint::through_camera(rotation, centre, f32::NAN, f32::NAN).view_projection.is_finite());
        // The orbit camera's view point projects like the camera.
        let cam = OrbitCamera::default();
        let p = Vec3::new(0.3, 1.2, -0.4);
        assert_eq!(cam.view_point(w / h).project(p, w, h), cam.project(p, w, h));
    }
}
