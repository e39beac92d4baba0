//! Canonical exo rays: the invariances of the paper's Fig. 3 and the ray geometry.

#[cfg(target_arch = "wasm32")]
use wasm_bindgen_test::wasm_bindgen_test as test;

use crate::common::*;
use egoexo_core::camera::CameraCalibration;
use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, Keypoint2d};
use egoexo_core::glam::{Quat, Vec2, Vec3};
use egoexo_core::rays::{
    CanonicalRay, ViewingRay, canonicalize_keypoints, canonicalize_keypoints_with_offsets, canonicalize_ray,
};
use egoexo_core::rigid::RigidTransform;
use proptest::prelude::*;

/// A wearer, an observer looking roughly at them from 1.5–8 m, and body points near the
/// wearer's head.
#[derive(Debug, Clone)]
struct Scene {
    wearer_head: RigidTransform,
    observer: RigidTransform,
    body: Vec<Vec3>,
}

fn scene() -> impl Strategy<Value = Scene> {
    (
        point(5.0),
        any_rotation(),
        1.5f32..8.0,
        0.0f32..std::f32::consts::TAU,
        -0.3f32..0.3,
        small_rotation(0.15),
        prop::collection::vec(point(0.6), 1..12),
    )
        .prop_map(|(wearer_pos, wearer_rot, distance, azimuth, dh, look_jitter, offsets)| {
            let wearer_pos = wearer_pos + Vec3::Y * 1.6;
            let observer_pos = wearer_pos + Vec3::new(distance * azimuth.sin(), dh, distance * azimuth.cos());
            let looking = RigidTransform::cpf_looking_at(observer_pos, wearer_pos - Vec3::Y * 0.5);
            let observer = RigidTransform::new(looking.rotation * look_jitter, observer_pos);
            let body = offsets.into_iter().map(|o| wearer_pos + o - Vec3::Y * 0.6).collect();
            Scene { wearer_head: RigidTransform::new(wearer_rot, wearer_pos), observer, body }
        })
}

/// Pixels of the body points that project into the valid image region.
fn project_all(camera: &CameraCalibration, observer: &RigidTransform, points: &[Vec3]) -> Vec<Option<Vec2>> {
    points.iter().map(|&p| camera.project_world(p, observer).filter(|px| camera.is_valid_pixel(*px))).collect()
}

fn endpoints(
    camera: &CameraCalibration,
    observer: &RigidTransform,
    wearer: &RigidTransform,
    pixels: &[Option<Vec2>],
) -> Vec<Option<Vec3>> {
    pixels.iter().map(|px| px.and_then(|px| canonicalize_ray(px, camera, observer, wearer))).collect()
}

proptest! {
    #[test]
    fn rotating_the_observer_head_leaves_endpoints_unchanged(s in scene(), turn in small_rotation(0.25)) {
        // Exact when the head turns about the camera's optical centre: here the camera sits at
        // the device origin (rotation-only extrinsic, Aria intrinsics).
        let camera = aria_rgb_camera_at_device_origin();
        let turned = RigidTransform::new(s.observer.rotation * turn, s.observer.translation);
        let before = endpoints(&camera, &s.observer, &s.wearer_head, &project_all(&camera, &s.observer, &s.body));
        let after = endpoints(&camera, &turned, &s.wearer_head, &project_all(&camera, &turned, &s.body));
        let mut compared = 0;
        for (b, a) in before.iter().zip(&after) {
            if let (Some(b), Some(a)) = (b, a) {
                compared += 1;
                prop_assert!(b.abs_diff_eq(*a, 2e-3), "{b:?} vs {a:?}");
            }
        }
        // Rejects (and so fails, if it happened often) scenes where nothing was visible.
        prop_assume!(compared > 0);
    }

    #[test]
    fn rotating_the_observer_head_with_an_offset_camera_changes_endpoints_by_about_the_camera_shift(
        s in scene(), turn in small_rotation(0.25),
    ) {
        // On real glasses the camera sits a few centimetres from the head-device origin, so a
        // head turn also moves the anchor; endpoints then move by about that much, no more.
        let camera = aria_rgb_camera();
        let turned = RigidTransform::new(s.observer.rotation * turn, s.observer.translation);
        let shift = camera.t_world_camera(&s.observer).translation.distance(camera.t_world_camera(&turned).translation);
        let before = endpoints(&camera, &s.observer, &s.wearer_head, &project_all(&camera, &s.observer, &s.body));
        let after = endpoints(&camera, &turned, &s.wearer_head, &project_all(&camera, &turned, &s.body));
        let mut compared = 0;
        for (b, a) in before.iter().zip(&after) {
            if let (Some(b), Some(a)) = (b, a) {
                compared += 1;
                prop_assert!(b.distance(*a) <= 2.0 * shift + 2e-3, "{b:?} vs {a:?} (camera moved {shift} m)");
            }
        }
        // Rejects (and so fails, if it happened often) scenes where nothing was visible.
        prop_assume!(compared > 0);
    }

    #[test]
    fn moving_the_whole_scene_rigidly_leaves_endpoints_unchanged(s in scene(), g in rigid(20.0)) {
        let camera = aria_rgb_camera();
        let pixels = project_all(&camera, &s.observer, &s.body);
        let before = endpoints(&camera, &s.observer, &s.wearer_head, &pixels);
        let moved_body: Vec<Vec3> = s.body.iter().map(|&p| g.transform_point(p)).collect();
        let moved_observer = g * s.observer;
        let moved_wearer = g * s.wearer_head;
        let moved_pixels = project_all(&camera, &moved_observer, &moved_body);
        let after = endpoints(&camera, &moved_observer, &moved_wearer, &moved_pixels);
        let mut compared = 0;
        for (b, a) in before.iter().zip(&after) {
            if let (Some(b), Some(a)) = (b, a) {
                compared += 1;
                prop_assert!(b.abs_diff_eq(*a, 2e-3), "{b:?} vs {a:?}");
            }
        }
        // Rejects (and so fails, if it happened often) scenes where nothing was visible.
        prop_assume!(compared > 0);
    }

    #[test]
    fn the_wearer_head_projects_to_the_canonical_origin(s in scene()) {
        let camera = aria_rgb_camera();
        let head = s.wearer_head.translation;
        let px = camera.project_world(head, &s.observer).filter(|px| camera.is_valid_pixel(*px));
        prop_assume!(px.is_some());
        let r = canonicalize_ray(px.unwrap(), &camera, &s.observer, &s.wearer_head).unwrap();
        prop_assert!(r.length() < 1e-3, "{r:?}");
    }

    #[test]
    fn endpoint_lies_on_the_viewing_ray_at_the_head_distance(s in scene()) {
        let camera = aria_rgb_camera();
        let centre = camera.t_world_camera(&s.observer).translation;
        let distance = s.wearer_head.translation.distance(centre);
        let pixels = project_all(&camera, &s.observer, &s.body);
        prop_assume!(pixels.iter().any(Option::is_some));
        for (&p, px) in s.body.iter().zip(pixels) {
            let Some(px) = px else { continue };
            let r = canonicalize_ray(px, &camera, &s.observer, &s.wearer_head).unwrap();
            let e_world = s.wearer_head.transform_point(r);
            prop_assert!((e_world.distance(centre) - distance).abs() < 2e-3);
            prop_assert!((e_world - centre).normalize().abs_diff_eq((p - centre).normalize(), 1e-4));
        }
    }

    #[test]
    fn an_estimate_off_the_ray_is_pulled_back_perpendicular_to_it(
        s in scene(), shift in point(0.4), along in -0.5f32..0.5, frame in any_rotation(),
    ) {
        // Each body point is seen; its estimate is off by `shift`. The offset must undo the part
        // of `shift` across the viewing ray and ignore the part along it (depth is unseen).
        let camera = aria_rgb_camera();
        let centre = camera.t_world_camera(&s.observer).translation;
        let pixels = project_all(&camera, &s.observer, &s.body);
        prop_assume!(pixels.iter().any(Option::is_some));
        for (&p, px) in s.body.iter().zip(pixels) {
            let Some(px) = px else { continue };
            let view = (p - centre).normalize();
            let across = shift - shift.dot(view) * view;
            let estimate = p + across + along * view;
            let ray = ViewingRay::through_pixel(px, &camera, &s.observer).unwrap();
            let offset = ray.offset_from(estimate, frame).unwrap();
            let offset_world = frame * offset;
            prop_assert!(offset_world.abs_diff_eq(-across, 3e-3), "{offset_world:?} vs {:?}", -across);
            prop_assert!(offset_world.dot(view).abs() < 1e-3);
        }
    }
}

#[test]
fn estimates_of_missing_keypoints_give_zero_offsets() {
    let camera = aria_rgb_camera().with_valid_radius(650.0);
    let observer = RigidTransform::cpf_looking_at(Vec3::new(0.0, 1.6, 4.0), Vec3::new(0.0, 1.6, 0.0));
    let mut keypoints: [Option<Keypoint2d>; EXO_KEYPOINT_COUNT] = [None; EXO_KEYPOINT_COUNT];
    let seen = Vec3::new(0.1, 1.2, 0.0);
    keypoints[0] = Some(Keypoint2d { pixel: camera.project_world(seen, &observer).unwrap(), score: 0.9 });
    keypoints[1] = Some(Keypoint2d { pixel: Vec2::new(5.0, 5.0), score: 0.9 }); // outside the image circle
    let mut estimates = [Vec3::new(0.0, 1.0, 0.0); EXO_KEYPOINT_COUNT];
    estimates[0] = seen + Vec3::X * 0.2;
    let wearer = RigidTransform::from_translation(Vec3::new(0.0, 1.6, 0.0));
    let both = canonicalize_keypoints_with_offsets(&keypoints, &camera, &observer, &wearer, &estimates, Quat::IDENTITY);
    // The rays are exactly `canonicalize_keypoints`'s; the offsets come from the same unprojection.
    assert_eq!(both.map(|(r, _)| r), canonicalize_keypoints(&keypoints, &camera, &observer, &wearer));
    let offsets = both.map(|(_, o)| o);
    let view = (seen - camera.t_world_camera(&observer).translation).normalize();
    let across = Vec3::X * 0.2 - 0.2 * view.x * view;
    assert!(offsets[0].abs_diff_eq(-across, 1e-3), "{:?} vs {:?}", offsets[0], -across);
    assert!(offsets[1..].iter().all(|o| *o == Vec3::ZERO));
}

#[test]
fn endpoint_is_expressed_in_the_wearer_head_frame() {
    // Wearer turned +90° about +Y (now facing world +X); observer 4 m in front of them on
    // world +X, looking back.
    let camera = pinhole_camera();
    let wearer = RigidTransform::new(Quat::from_rotation_y(std::f32::consts::FRAC_PI_2), Vec3::new(0.0, 1.6, 0.0));
    let observer = RigidTransform::cpf_looking_at(Vec3::new(4.0, 1.6, 0.0), Vec3::new(0.0, 1.6, 0.0));
    // A point at head height, 0.3 m to the wearer's left (+X of the head frame → world −Z).
    let p = Vec3::new(0.0, 1.6, -0.3);
    let px = camera.project_world(p, &observer).unwrap();
    let r = canonicalize_ray(px, &camera, &observer, &wearer).unwrap();
    // On the viewing ray at depth 4 m (the head distance) rather than 4.011 m: +0.3 m along
    // head +X (left) and 1.1 cm towards the observer, who stands in front (head +Z).
    assert!(r.abs_diff_eq(Vec3::new(0.299, 0.0, 0.011), 1e-3), "{r:?}");
}

#[test]
fn missing_and_unprojectable_keypoints_give_zero_invalid_rays() {
    let camera = aria_rgb_camera().with_valid_radius(650.0);
    let wearer = RigidTransform::from_translation(Vec3::new(0.0, 1.6, 0.0));
    let observer = RigidTransform::cpf_looking_at(Vec3::new(0.0, 1.6, 4.0), Vec3::new(0.0, 1.6, 0.0));
    let mut keypoints: [Option<Keypoint2d>; EXO_KEYPOINT_COUNT] = [None; EXO_KEYPOINT_COUNT];
    keypoints[0] = Some(Keypoint2d { pixel: Vec2::new(704.0, 704.0), score: 0.9 });
    keypoints[1] = Some(Keypoint2d { pixel: Vec2::new(5.0, 5.0), score: 0.9 }); // outside the image circle
    keypoints[2] = Some(Keypoint2d { pixel: Vec2::new(f32::NAN, 3.0), score: 0.9 });
    let rays = canonicalize_keypoints(&keypoints, &camera, &observer, &wearer);
    assert!(rays[0].valid && rays[0].endpoint != Vec3::ZERO);
    for ray in &rays[1..] {
        assert_eq!(*ray, CanonicalRay::MISSING);
    }
}
