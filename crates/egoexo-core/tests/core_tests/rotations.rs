//! Round trips between 6D, matrices, quaternions and axis-angle; rigid transform algebra.

#[cfg(target_arch = "wasm32")]
use wasm_bindgen_test::wasm_bindgen_test as test;

use crate::common::*;
use egoexo_core::glam::{Mat3, Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::rotation::{
    Rot6d, angle_between, axis_angle_from_quat, quat_from_axis_angle, quat_from_rotation_matrix,
};
use proptest::prelude::*;

/// Columns 172° apart: one Gram–Schmidt pass cancels and leaves the decoded columns 2e-5
/// from orthogonal, so decoding the output again moved it (a CI proptest case, kept here
/// because proptest does not read regression files next to integration tests).
#[test]
fn gram_schmidt_of_nearly_opposite_columns_is_orthonormal_and_idempotent() {
    let m = Rot6d([8.536994, -1.7020134, -8.678864, -7.6027865, 1.5620908, 7.6577654]).to_mat3();
    assert!(m.x_axis.dot(m.y_axis).abs() < 1e-6, "b1·b2 = {}", m.x_axis.dot(m.y_axis));
    assert!((m.transpose() * m).abs_diff_eq(Mat3::IDENTITY, 1e-6));
    assert!(Rot6d::from_mat3(m).to_mat3().abs_diff_eq(m, 1e-6));
}

proptest! {
    #[test]
    fn six_d_matrix_round_trip(q in any_rotation()) {
        let m = Mat3::from_quat(q);
        let back = Rot6d::from_mat3(m).to_mat3();
        prop_assert!(back.abs_diff_eq(m, 1e-5), "{m:?} -> {back:?}");
    }

    #[test]
    fn six_d_quaternion_round_trip(q in any_rotation()) {
        let back = Rot6d::from_quat(q).to_quat();
        prop_assert!(same_rotation(q, back, 1e-3), "{q:?} -> {back:?}");
        prop_assert!(back.w >= 0.0);
    }

    #[test]
    fn matrix_quaternion_round_trip(q in any_rotation()) {
        let back = quat_from_rotation_matrix(Mat3::from_quat(q));
        prop_assert!(same_rotation(q, back, 1e-3));
        prop_assert!(Mat3::from_quat(back).abs_diff_eq(Mat3::from_quat(q), 1e-5));
    }

    #[test]
    fn axis_angle_round_trip(axis in point(1.0).prop_filter("nonzero", |v| v.length() > 1e-3), angle in 0.0f32..3.1) {
        let v = axis.normalize() * angle;
        let back = axis_angle_from_quat(quat_from_axis_angle(v));
        prop_assert!(back.abs_diff_eq(v, 2e-5), "{v:?} -> {back:?}");
    }

    #[test]
    fn axis_angle_of_tiny_rotations_is_accurate(v in point(1e-5)) {
        let back = axis_angle_from_quat(quat_from_axis_angle(v));
        prop_assert!((back - v).length() <= 1e-3 * v.length() + 1e-12, "{v:?} -> {back:?}");
    }

    #[test]
    fn axis_angle_matches_matrix(axis in point(1.0).prop_filter("nonzero", |v| v.length() > 1e-3), angle in 0.0f32..3.1) {
        // The rotation vector rotates by its length about its direction (right-hand rule).
        let v = axis.normalize() * angle;
        let expected = Mat3::from_axis_angle(axis.normalize(), angle);
        prop_assert!(Mat3::from_quat(quat_from_axis_angle(v)).abs_diff_eq(expected, 1e-5));
    }

    #[test]
    fn gram_schmidt_decodes_any_six_numbers_to_a_rotation(raw in prop::array::uniform6(-10.0f32..10.0)) {
        let m = Rot6d(raw).to_mat3();
        prop_assert!((m.determinant() - 1.0).abs() < 1e-4);
        prop_assert!((m.transpose() * m).abs_diff_eq(Mat3::IDENTITY, 1e-4));
        // Decoding is a projection: encoding the result and decoding again changes nothing.
        prop_assert!(Rot6d::from_mat3(m).to_mat3().abs_diff_eq(m, 1e-5));
        // The first column keeps the first input column's direction.
        let a1 = Vec3::new(raw[0], raw[1], raw[2]);
        if a1.length() > 1e-3 {
            prop_assert!(m.x_axis.abs_diff_eq(a1.normalize(), 1e-5));
        }
    }

    #[test]
    fn six_d_stores_the_first_two_columns(q in any_rotation()) {
        let m = Mat3::from_quat(q);
        let r = Rot6d::from_quat(q).0;
        prop_assert!(Vec3::new(r[0], r[1], r[2]).abs_diff_eq(m.x_axis, 1e-6));
        prop_assert!(Vec3::new(r[3], r[4], r[5]).abs_diff_eq(m.y_axis, 1e-6));
    }

    #[test]
    fn composition_matches_sequential_application(a in rigid(5.0), b in rigid(5.0), p in point(3.0)) {
        let direct = (a * b).transform_point(p);
        let sequential = a.transform_point(b.transform_point(p));
        prop_assert!(direct.abs_diff_eq(sequential, 1e-4));
    }

    #[test]
    fn composition_is_associative(a in rigid(5.0), b in rigid(5.0), c in rigid(5.0), p in point(3.0)) {
        prop_assert!(((a * b) * c).transform_point(p).abs_diff_eq((a * (b * c)).transform_point(p), 1e-4));
    }

    #[test]
    fn inverse_undoes(a in rigid(5.0), p in point(3.0)) {
        prop_assert!(a.inverse().transform_point(a.transform_point(p)).abs_diff_eq(p, 1e-4));
        prop_assert!((a * a.inverse()).transform_point(p).abs_diff_eq(p, 1e-4));
    }

    #[test]
    fn interpolation_hits_endpoints_and_is_geodesic(a in rigid(5.0), b in rigid(5.0), alpha in 0.0f32..1.0) {
        let start = a.interpolate(&b, 0.0);
        let end = a.interpolate(&b, 1.0);
        prop_assert!(same_rotation(start.rotation, a.rotation, 1e-3) && start.translation.abs_diff_eq(a.translation, 1e-5));
        prop_assert!(same_rotation(end.rotation, b.rotation, 1e-3) && end.translation.abs_diff_eq(b.translation, 1e-5));
        let mid = a.interpolate(&b, alpha);
        let total = angle_between(a.rotation, b.rotation);
        // Slerp moves at constant angular speed along the shortest arc.
        prop_assert!((angle_between(a.rotation, mid.rotation) - alpha * total).abs() < 2e-3);
        prop_assert!((angle_between(mid.rotation, b.rotation) - (1.0 - alpha) * total).abs() < 2e-3);
        prop_assert!(mid.translation.abs_diff_eq(a.translation.lerp(b.translation, alpha), 1e-4));
    }
}

#[test]
fn quarter_turn_about_y_maps_z_to_x() {
    // Right-handed: +90° about +Y takes +Z to +X.
    let q = quat_from_axis_angle(Vec3::Y * std::f32::consts::FRAC_PI_2);
    assert!((q * Vec3::Z).abs_diff_eq(Vec3::X, 1e-6));
    let t = RigidTransform::new(q, Vec3::new(0.0, 1.0, 0.0));
    assert!(t.transform_point(Vec3::Z).abs_diff_eq(Vec3::new(1.0, 1.0, 0.0), 1e-6));
    assert!(t.transform_vector(Vec3::Z).abs_diff_eq(Vec3::X, 1e-6));
    assert!(t.inverse().transform_point(Vec3::new(1.0, 1.0, 0.0)).abs_diff_eq(Vec3::Z, 1e-6));
    let _ = Quat::IDENTITY;
}
