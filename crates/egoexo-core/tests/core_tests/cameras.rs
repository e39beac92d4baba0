//! Pinhole and Aria Fisheye624 projection: hand-checked values, project∘unproject identity
//! inside the valid region, rescaling.

#[cfg(target_arch = "wasm32")]
use wasm_bindgen_test::wasm_bindgen_test as test;

use crate::common::*;
use egoexo_core::camera::{CameraError, Fisheye624, Projection};
use egoexo_core::glam::{Vec2, Vec3};
use egoexo_core::rigid::RigidTransform;
use proptest::prelude::*;

fn aria() -> Fisheye624 {
    Fisheye624::new(ARIA_RGB_1408).unwrap()
}

/// A fisheye with only the listed parameters set beyond `f = 500, c = (600, 400)`.
fn fisheye_with(extra: &[(usize, f32)]) -> Fisheye624 {
    let mut p = [0.0; 15];
    p[0] = 500.0;
    p[1] = 600.0;
    p[2] = 400.0;
    for &(i, v) in extra {
        p[i] = v;
    }
    Fisheye624::new(p).unwrap()
}

#[test]
fn fisheye_radial_term_matches_hand_computation() {
    // Point at 30° off-axis along +X: θ = π/6, θ_d = θ (1 + k0 θ²), u = cu + f θ_d.
    let k0 = 0.1f32;
    let cam = fisheye_with(&[(3, k0)]);
    let theta = std::f32::consts::FRAC_PI_6;
    let p = Vec3::new(theta.tan(), 0.0, 1.0);
    let px = cam.project(p).unwrap();
    let expected = 600.0 + 500.0 * theta * (1.0 + k0 * theta * theta);
    assert!((px.x - expected).abs() < 1e-3, "{px:?} vs {expected}");
    assert!((px.y - 400.0).abs() < 1e-4);
}

#[test]
fn fisheye_tangential_and_thin_prism_match_hand_computation() {
    // Along +Y with θ = 0.4: x_r = (0, θ). Tangential: u_y = y + 3 p1 y², u_x = p0 y².
    // Thin prism: u_x += s0 y² + s1 y⁴, u_y += s2 y² + s3 y⁴.
    let (p0, p1, s0, s1, s2, s3) = (0.01f32, -0.02, 0.003, 0.004, -0.005, 0.006);
    let cam = fisheye_with(&[(9, p0), (10, p1), (11, s0), (12, s1), (13, s2), (14, s3)]);
    let theta = 0.4f32;
    let px = cam.project(Vec3::new(0.0, theta.tan(), 1.0)).unwrap();
    let y = theta;
    let ux = p0 * y * y + s0 * y * y + s1 * y.powi(4);
    let uy = y + 3.0 * p1 * y * y + s2 * y * y + s3 * y.powi(4);
    assert!((px - Vec2::new(600.0 + 500.0 * ux, 400.0 + 500.0 * uy)).length() < 1e-3, "{px:?}");
}

#[test]
fn aria_rgb_field_of_view_is_realistic() {
    let cam = aria();
    // Aria's RGB camera sees about 110° diagonally; the monotonic range must cover that.
    assert!(cam.max_field_angle() > 55f32.to_radians(), "{}", cam.max_field_angle());
    // The optical axis lands on the principal point.
    assert!(cam.project(Vec3::Z).unwrap().abs_diff_eq(cam.principal_point(), 1e-4));
    // Behind the camera does not project.
    assert_eq!(cam.project(Vec3::new(0.1, 0.0, -1.0)), None);
    // A point 89° off-axis is beyond the valid field angle.
    assert_eq!(cam.project(Vec3::new(1.0, 0.0, 0.01)), None);
}

#[test]
fn pixels_outside_the_valid_radius_do_not_unproject() {
    let cam = aria_rgb_camera().with_valid_radius(600.0);
    let c = cam.projection.principal_point();
    assert!(cam.unproject(c + Vec2::new(590.0, 0.0)).is_some());
    assert!(cam.unproject(c + Vec2::new(0.0, -610.0)).is_none());
    assert!(!cam.is_valid_pixel(c + Vec2::new(500.0, 500.0)));
    assert!(cam.is_valid_pixel(c + Vec2::new(300.0, 300.0)));
    assert!(!cam.is_valid_pixel(Vec2::new(-1.0, 10.0)));
}

/// Pixels within the Aria RGB image circle (radius 700 px around the principal point).
fn aria_pixel() -> impl Strategy<Value = Vec2> {
    (0.0f32..1.0, 0.0f32..std::f32::consts::TAU).prop_map(|(s, phi)| {
        let c = Vec2::new(ARIA_RGB_1408[1], ARIA_RGB_1408[2]);
        c + 700.0 * s.sqrt() * Vec2::new(phi.cos(), phi.sin())
    })
}

proptest! {
    #[test]
    fn fisheye_project_of_unproject_is_identity(px in aria_pixel()) {
        let cam = aria();
        let ray = cam.unproject(px).expect("inside the image circle");
        prop_assert!((ray.length() - 1.0).abs() < 1e-5);
        let back = cam.project(ray * 3.7).expect("projects back");
        prop_assert!(back.distance(px) < 1e-2, "{px:?} -> {ray:?} -> {back:?}");
    }

    #[test]
    fn fisheye_unproject_of_project_is_identity(
        theta in 0.0f32..1.0, phi in 0.0f32..std::f32::consts::TAU, depth in 0.2f32..20.0,
    ) {
        let cam = aria();
        let dir = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
        let px = cam.project(dir * depth).expect("inside the field of view");
        let ray = cam.unproject(px).expect("unprojects");
        prop_assert!((ray - dir).length() < 2e-5, "{dir:?} -> {px:?} -> {ray:?}");
    }

    #[test]
    fn pinhole_round_trips(px in (0.0f32..639.0, 0.0f32..479.0)) {
        let cam = pinhole_camera();
        let px = Vec2::new(px.0, px.1);
        let ray = cam.unproject(px).unwrap();
        prop_assert!(cam.project(ray * 2.0).unwrap().distance(px) < 1e-3);
    }

    #[test]
    fn rescaled_camera_maps_pixel_centres(theta in 0.0f32..0.9, phi in 0.0f32..std::f32::consts::TAU) {
        // Downscaling 1408 → 704 halves (pixel + 0.5): u' = (u + 0.5) / 2 − 0.5.
        let full = aria_rgb_camera();
        let half = full.scaled_to(704, 704).unwrap();
        let dir = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
        let u = full.project(dir).unwrap();
        let u_half = half.project(dir).unwrap();
        prop_assert!(u_half.distance((u + 0.5) * 0.5 - 0.5) < 1e-3);
    }

    #[test]
    fn world_projection_uses_device_and_camera_extrinsics(t_world_device in rigid(10.0), px in aria_pixel(), depth in 0.5f32..10.0) {
        let cam = aria_rgb_camera();
        let t_world_camera = t_world_device * cam.t_device_camera;
        let ray = cam.unproject(px).unwrap();
        let p_world = t_world_camera.transform_point(ray * depth);
        let back = cam.project_world(p_world, &t_world_device).unwrap();
        prop_assert!(back.distance(px) < 2e-2, "{px:?} vs {back:?}");
    }
}

#[test]
fn fisheye_refuses_non_uniform_rescale() {
    let cam = aria_rgb_camera();
    assert!(matches!(cam.scaled_to(704, 600), Err(CameraError::NonUniformScale { .. })));
    let pinhole = pinhole_camera().scaled_to(320, 120).unwrap();
    let Projection::Pinhole(k) = pinhole.projection else { panic!("still pinhole") };
    assert!((k.fx - 200.0).abs() < 1e-4 && (k.fy - 102.5).abs() < 1e-4);
    assert!((k.cx - 159.5).abs() < 1e-4 && (k.cy - 59.5).abs() < 1e-4);
    let _ = RigidTransform::IDENTITY;
}
