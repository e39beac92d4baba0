//! SMPL forward kinematics and root recovery from the head device.

#[cfg(target_arch = "wasm32")]
use wasm_bindgen_test::wasm_bindgen_test as test;

use crate::common::*;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{
    JOINT_NAMES, MIRRORED_JOINT, NUM_BODY_JOINTS, NUM_JOINTS, PARENTS, SmplJoint, SmplPose, SmplSkeleton,
};
use proptest::prelude::*;

fn body_pose() -> impl Strategy<Value = [Quat; NUM_BODY_JOINTS]> {
    prop::collection::vec(small_rotation(1.2), NUM_BODY_JOINTS).prop_map(|v| std::array::from_fn(|i| v[i]))
}

fn pose() -> impl Strategy<Value = SmplPose> {
    (any_rotation(), body_pose(), point(5.0)).prop_map(|(root_orientation, body, translation)| SmplPose {
        root_orientation,
        body,
        translation,
    })
}

#[test]
fn rest_pose_gives_rest_joints() {
    let skeleton = SmplSkeleton::mean_shape();
    let fk = skeleton.forward_kinematics(&SmplPose::rest());
    for j in 0..NUM_JOINTS {
        assert!(fk.positions[j].abs_diff_eq(skeleton.rest_joints()[j], 1e-6), "{}", JOINT_NAMES[j]);
        assert_eq!(fk.rotations[j], Quat::IDENTITY);
    }
}

#[test]
fn translation_moves_the_pelvis_from_its_rest_position() {
    let skeleton = SmplSkeleton::mean_shape();
    let t = Vec3::new(1.0, 0.9, -2.0);
    let fk = skeleton.forward_kinematics(&SmplPose { translation: t, ..SmplPose::rest() });
    assert!(fk.positions[0].abs_diff_eq(skeleton.rest_joints()[0] + t, 1e-6));
}

#[test]
fn rest_skeleton_is_upright_facing_z_with_left_on_plus_x() {
    let s = SmplSkeleton::mean_shape();
    let j = |joint: SmplJoint| s.rest_joints()[joint.index()];
    assert!(j(SmplJoint::Head).y > j(SmplJoint::Pelvis).y + 0.5);
    assert!(j(SmplJoint::LeftWrist).x > 0.5 && j(SmplJoint::RightWrist).x < -0.5);
    assert!(j(SmplJoint::LeftFoot).z > j(SmplJoint::LeftAnkle).z, "toes point forward (+Z)");
}

#[test]
fn bending_the_left_elbow_moves_only_its_descendants() {
    let skeleton = SmplSkeleton::mean_shape();
    let mut pose = SmplPose::rest();
    pose.body[SmplJoint::LeftElbow.index() - 1] = Quat::from_rotation_y(-std::f32::consts::FRAC_PI_2);
    let fk = skeleton.forward_kinematics(&pose);
    let rest = skeleton.rest_joints();
    for j in 0..NUM_JOINTS {
        let moved = !fk.positions[j].abs_diff_eq(rest[j], 1e-6);
        let descendant = [20, 22].contains(&j);
        assert_eq!(moved, descendant, "{}", JOINT_NAMES[j]);
    }
    // −90° about +Y turns the forearm (pointing about +X) to point about +Z (forward).
    let forearm = (fk.positions[20] - fk.positions[18]).normalize();
    assert!(forearm.z > 0.99, "{forearm:?}");
}

#[test]
fn scaling_to_head_height() {
    let s = SmplSkeleton::mean_shape().scaled_to_head_height(1.3).unwrap();
    assert!((s.head_height() - 1.3).abs() < 1e-5);
    assert!(SmplSkeleton::mean_shape().scaled_to_head_height(f32::NAN).is_err());
    assert!(SmplSkeleton::mean_shape().scaled_to_head_height(-1.0).is_err());
    let tall = SmplSkeleton::mean_shape_for_stature(1.87).unwrap();
    assert!(tall.head_height() > SmplSkeleton::mean_shape().head_height());
}

proptest! {
    #[test]
    fn fk_preserves_bone_lengths(pose in pose()) {
        let skeleton = SmplSkeleton::mean_shape();
        let fk = skeleton.forward_kinematics(&pose);
        for j in 1..NUM_JOINTS {
            let parent = PARENTS[j] as usize;
            let len = fk.positions[j].distance(fk.positions[parent]);
            prop_assert!((len - skeleton.bone_offset(j).length()).abs() < 1e-5);
        }
    }

    #[test]
    fn fk_is_equivariant_under_root_motion(pose in pose(), extra in rigid(3.0)) {
        // Rotating the root orientation by R about the pelvis and moving the pelvis rotates
        // and moves every joint the same way.
        let skeleton = SmplSkeleton::mean_shape();
        let fk = skeleton.forward_kinematics(&pose);
        let pelvis = fk.positions[0];
        let moved_pelvis = extra.transform_point(pelvis);
        let moved = SmplPose {
            root_orientation: extra.rotation * pose.root_orientation,
            translation: moved_pelvis - skeleton.rest_joints()[0],
            ..pose
        };
        let fk2 = skeleton.forward_kinematics(&moved);
        for j in 0..NUM_JOINTS {
            let expected = moved_pelvis + extra.rotation * (fk.positions[j] - pelvis);
            prop_assert!(fk2.positions[j].abs_diff_eq(expected, 1e-4));
        }
    }

    #[test]
    fn mirrored_pose_is_the_reflected_body_with_sides_swapped(pose in pose(), scale in 0.8f32..1.2) {
        let skeleton = SmplSkeleton::mean_shape().scaled(scale);
        let fk = skeleton.forward_kinematics(&pose);
        let mirrored = skeleton.mirrored().forward_kinematics(&pose.mirrored());
        for j in 0..NUM_JOINTS {
            let p = fk.positions[MIRRORED_JOINT[j]];
            prop_assert!(mirrored.positions[j].abs_diff_eq(Vec3::new(-p.x, p.y, p.z), 1e-4), "{}", JOINT_NAMES[j]);
        }
        // Mirroring twice gives back the pose.
        let twice = pose.mirrored().mirrored();
        prop_assert!(same_rotation(twice.root_orientation, pose.root_orientation, 1e-5));
        prop_assert!(twice.translation.abs_diff_eq(pose.translation, 1e-6));
    }

    #[test]
    fn root_recovery_puts_the_fk_head_on_the_given_head(
        root in any_rotation(), body in body_pose(), device in rigid(10.0), offset in point(0.15),
    ) {
        let skeleton = SmplSkeleton::mean_shape().scaled(1.07);
        let translation = skeleton.recover_translation(root, &body, &device, offset);
        let fk = skeleton.forward_kinematics(&SmplPose { root_orientation: root, body, translation });
        let head = fk.positions[SmplJoint::Head.index()];
        let expected = device.transform_point(offset);
        prop_assert!(head.abs_diff_eq(expected, 1e-5), "{head:?} vs {expected:?}");
    }
}

#[test]
fn root_recovery_with_zero_offset_hangs_the_body_below_the_device() {
    let skeleton = SmplSkeleton::mean_shape();
    let device = RigidTransform::from_translation(Vec3::new(0.0, 1.6, 0.0));
    let t = skeleton.recover_translation(Quat::IDENTITY, &[Quat::IDENTITY; NUM_BODY_JOINTS], &device, Vec3::ZERO);
    let fk = skeleton.forward_kinematics(&SmplPose { translation: t, ..SmplPose::rest() });
    // Head at 1.6 m, so the lowest foot joint is 1.6 − 1.496 m above y = 0.
    let lowest = fk.positions.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
    assert!((lowest - (1.6 - skeleton.head_height())).abs() < 1e-5);
}
