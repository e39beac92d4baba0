//! WebXR poses → session conventions, over arbitrary poses: unit quaternions out, and what is
//! in front of the viewer is in front of the CPF.

#[cfg(target_arch = "wasm32")]
use wasm_bindgen_test::wasm_bindgen_test as test;

use crate::common::*;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::xr::{Hand, XrPose, XrSpace, session_pose, t_xr_space_device};
use proptest::prelude::*;

const SPACES: [XrSpace; 5] = [
    XrSpace::Viewer,
    XrSpace::Grip(Hand::Left),
    XrSpace::Grip(Hand::Right),
    XrSpace::HandWrist(Hand::Left),
    XrSpace::HandWrist(Hand::Right),
];

proptest! {
    #[test]
    fn session_poses_are_unit_and_finite(q in any_rotation(), p in point(5.0), space in 0usize..5, scale in 0.5f32..2.0) {
        let pose = XrPose { position: p.to_array(), orientation: (q * scale).to_array() };
        let t = session_pose(SPACES[space], &pose).unwrap();
        prop_assert!(t.is_finite());
        prop_assert!((t.rotation.length() - 1.0).abs() < 1e-5, "{t:?}");
    }

    #[test]
    fn what_is_in_front_of_the_viewer_is_in_front_of_the_cpf(q in any_rotation(), p in point(5.0), d in 0.1f32..10.0,
                                                              side in -1.0f32..1.0, up in -1.0f32..1.0) {
        let pose = XrPose { position: p.to_array(), orientation: q.to_array() };
        let t_world_cpf = session_pose(XrSpace::Viewer, &pose).unwrap();
        // A point d metres ahead (XR view space −Z), off to the right and up a little.
        let in_view = Vec3::new(side, up, -d);
        let world = q * in_view + p;
        let in_cpf = t_world_cpf.inverse().transform_point(world);
        prop_assert!(in_cpf.abs_diff_eq(Vec3::new(-side, up, d), 1e-3 * (1.0 + p.length() + d)), "{in_cpf}");
        // The head is where the viewer is.
        prop_assert!(t_world_cpf.translation.abs_diff_eq(p, 1e-6));
    }

    #[test]
    fn the_conversion_is_a_fixed_offset_in_the_xr_space(q in any_rotation(), p in point(5.0), space in 0usize..5) {
        // Composing two XR poses composes the session poses: the offset does not depend on
        // where the device is (no world-dependent fix-ups).
        let space = SPACES[space];
        let t = session_pose(space, &XrPose { position: p.to_array(), orientation: q.to_array() }).unwrap();
        let offset = t_xr_space_device(space);
        prop_assert!(t.translation.abs_diff_eq(q * offset.translation + p, 1e-4));
        prop_assert!((t.rotation.dot(q * offset.rotation).abs() - 1.0).abs() < 1e-5);
    }
}

#[test]
fn the_identity_viewer_is_a_cpf_facing_minus_z() {
    let t = session_pose(XrSpace::Viewer, &XrPose { position: [0.1, 1.6, -0.3], orientation: [0.0, 0.0, 0.0, 1.0] })
        .unwrap();
    assert!(t.rotation.dot(Quat::from_rotation_y(std::f32::consts::PI)).abs() > 1.0 - 1e-6);
    assert!(t.transform_vector(Vec3::Z).abs_diff_eq(-Vec3::Z, 1e-6));
}
