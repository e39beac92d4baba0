//! Region proposals from projected joints.

#[cfg(target_arch = "wasm32")]
use wasm_bindgen_test::wasm_bindgen_test as test;

use crate::common::*;
use egoexo_core::glam::{Quat, Vec2, Vec3};
use egoexo_core::region::{BoundingBox, DEFAULT_REGION_MARGIN, NotVisibleReason, RegionProposal, propose_region};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{SmplPose, SmplSkeleton};

/// The mean-shape body standing with its feet on y = 0 at `position`.
fn standing_body(position: Vec3) -> Vec<Vec3> {
    let skeleton = SmplSkeleton::mean_shape();
    let lift = -skeleton.rest_joints().iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
    let pose = SmplPose { translation: position + Vec3::Y * lift, ..SmplPose::rest() };
    skeleton.forward_kinematics(&pose).positions.to_vec()
}

#[test]
fn a_wearer_in_front_gets_a_box_around_every_joint() {
    for camera in [aria_rgb_camera(), pinhole_camera()] {
        let body = standing_body(Vec3::ZERO);
        let observer = RigidTransform::cpf_looking_at(Vec3::new(0.0, 1.6, 5.0), Vec3::new(0.0, 1.0, 0.0));
        let proposal = propose_region(&body, &camera, &observer, DEFAULT_REGION_MARGIN);
        let RegionProposal::Visible { bbox, joints_in_image } = proposal else { panic!("{proposal:?}") };
        assert_eq!(joints_in_image, body.len());
        let tight = BoundingBox::around(body.iter().map(|&p| camera.project_world(p, &observer).unwrap())).unwrap();
        assert!(bbox.contains(tight.min) && bbox.contains(tight.max));
        // The margin grows the box by 15 % of the longer side on each side (nothing clipped).
        let pad = tight.size().max_element() * DEFAULT_REGION_MARGIN;
        assert!(bbox.min.abs_diff_eq(tight.min - pad, 1e-2) && bbox.max.abs_diff_eq(tight.max + pad, 1e-2), "{bbox:?}");
        // Image +Y points down: the head is above the feet, the wearer's left hand (facing the
        // observer) on the image's right.
        let px = |j: usize| camera.project_world(body[j], &observer).unwrap();
        assert!(px(15).y < px(10).y - 100.0);
        assert!(px(22).x > px(23).x + 100.0);
    }
}

#[test]
fn a_wearer_behind_the_observer_is_not_visible() {
    let body = standing_body(Vec3::ZERO);
    let observer = RigidTransform::cpf_looking_at(Vec3::new(0.0, 1.6, 5.0), Vec3::new(0.0, 1.6, 10.0));
    let proposal = propose_region(&body, &aria_rgb_camera(), &observer, DEFAULT_REGION_MARGIN);
    assert_eq!(proposal, RegionProposal::NotVisible(NotVisibleReason::BehindCamera));
}

#[test]
fn a_wearer_beside_the_field_of_view_is_out_of_frame() {
    let body = standing_body(Vec3::ZERO);
    // Looking 80° away from the wearer: in front of the camera plane, but outside the image.
    let eye = Vec3::new(0.0, 1.6, 5.0);
    let away = Quat::from_rotation_y(80f32.to_radians()) * (Vec3::new(0.0, 1.6, 0.0) - eye);
    let observer = RigidTransform::cpf_looking_at(eye, eye + away);
    for camera in [aria_rgb_camera(), pinhole_camera()] {
        let proposal = propose_region(&body, &camera, &observer, DEFAULT_REGION_MARGIN);
        assert_eq!(proposal, RegionProposal::NotVisible(NotVisibleReason::OutOfFrame), "{camera:?}");
    }
}

#[test]
fn a_partly_visible_wearer_gets_a_clipped_box() {
    // Close and looking at the head: the feet fall below the pinhole image.
    let camera = pinhole_camera();
    let body = standing_body(Vec3::ZERO);
    let observer = RigidTransform::cpf_looking_at(Vec3::new(0.0, 1.7, 1.2), Vec3::new(0.0, 1.6, 0.0));
    let RegionProposal::Visible { bbox, joints_in_image } =
        propose_region(&body, &camera, &observer, DEFAULT_REGION_MARGIN)
    else {
        panic!("partly visible")
    };
    assert!(joints_in_image > 0 && joints_in_image < body.len(), "{joints_in_image}");
    assert_eq!(bbox.max.y, 479.5, "clipped at the bottom edge");
    assert!(bbox.min.cmpge(Vec2::splat(-0.5)).all());
}
