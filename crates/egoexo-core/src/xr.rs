//! WebXR poses in session conventions: what a headset's browser streams as a wearer.
//!
//! # Frames
//! - **World.** The XR reference space the page tracks in (`local-floor`, else `local`):
//!   right-handed, +Y up, metres — already a session world. It is used as it is (no
//!   rotation, no translation); with `local` the origin is the head at the session's start
//!   rather than on the floor, which is fine (the core assumes no floor height).
//! - **Head.** The XR viewer space (+X right, +Y up, −Z forward, between the eyes) becomes
//!   CPF (+X left, +Y up, +Z forward, between the eyes): a half turn about +Y, no offset.
//! - **Wrists.** A wrist device's frame is the SMPL wrist joint's frame, as the simulated
//!   wrists (`egoexo-synth`) and the networks use it: at the wrist, with the axes of the SMPL
//!   body in the rest pose (arms out sideways, palms down): +X the subject's left, +Y up
//!   (out of the back of the hand), +Z forward (the thumb's side). So a hand in the T-pose
//!   has the identity rotation, and either hand's fingers point along the arm, outwards.
//!   - From the hand-tracking `wrist` joint (origin at the wrist, −Z along the hand towards
//!     the fingers, +Y out of the back of the hand): a quarter turn about +Y, +90° for the
//!     left hand, −90° for the right; no offset.
//!   - From a controller's grip space (origin at the centre of the fist, −Z along the
//!     handle towards the thumb, +X out of the back of the right hand and −X out of the back
//!     of the left, +Y up the arm): a half turn, and the wrist [`WRIST_IN_GRIP_M`] from the
//!     fist. The offset is an adult hand's, approximate to a centimetre or two.
//!
//! Inputs are `XRRigidTransform`s as the page reads them: `position` (x, y, z metres) and
//! `orientation` (a quaternion x, y, z, w), `T_reference_space` of the XR space.

use glam::{Mat3, Quat, Vec3};
use thiserror::Error;

use crate::rigid::RigidTransform;

/// Left or right (the wearer's).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Hand {
    Left,
    Right,
}

/// The XR space a pose is of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum XrSpace {
    /// The viewer (`XRViewerPose.transform`): the head.
    Viewer,
    /// A controller's `gripSpace`.
    Grip(Hand),
    /// The hand-tracking `wrist` joint (`XRHand.get("wrist")`).
    HandWrist(Hand),
}

/// An `XRRigidTransform`: `T_reference_space`, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct XrPose {
    /// x, y, z, metres.
    pub position: [f32; 3],
    /// x, y, z, w; normalised here (the browser's is unit already).
    pub orientation: [f32; 4],
}

/// Why an XR pose was refused.
#[derive(Clone, Copy, Debug, PartialEq, Error)]
pub enum XrPoseError {
    #[error("the XR pose's position is not finite: {0:?}")]
    NotFinitePosition([f32; 3]),
    #[error("the XR pose's orientation is not a rotation (quaternion {0:?})")]
    NotARotation([f32; 4]),
}

/// The wrist joint in a controller's grip space (metres): up the arm from the centre of the
/// fist, and towards the back of the hand (+X for the right hand, −X for the left).
pub const WRIST_IN_GRIP_M: [f32; 3] = [0.03, 0.08, 0.0];

/// `T_xrspace_device`: the session device frame of a pose of `space`, in that XR space.
pub fn t_xr_space_device(space: XrSpace) -> RigidTransform {
    // Each matrix's columns are the device frame's axes (X, Y, Z) in the XR space's axes.
    match space {
        XrSpace::Viewer => {
            RigidTransform::from_rotation_matrix(Mat3::from_cols(-Vec3::X, Vec3::Y, -Vec3::Z), Vec3::ZERO)
        }
        XrSpace::HandWrist(Hand::Left) => {
            RigidTransform::from_rotation_matrix(Mat3::from_cols(-Vec3::Z, Vec3::Y, Vec3::X), Vec3::ZERO)
        }
        XrSpace::HandWrist(Hand::Right) => {
            RigidTransform::from_rotation_matrix(Mat3::from_cols(Vec3::Z, Vec3::Y, -Vec3::X), Vec3::ZERO)
        }
        XrSpace::Grip(hand) => {
            // The back of the hand (device +Y) is +X of a right grip and −X of a left one;
            // the arm runs along grip +Y, outwards (device ∓X); the thumb along grip −Z.
            let back = if hand == Hand::Right { Vec3::X } else { -Vec3::X };
            let [across, up_arm, along] = WRIST_IN_GRIP_M;
            RigidTransform::from_rotation_matrix(
                Mat3::from_cols(if hand == Hand::Right { Vec3::Y } else { -Vec3::Y }, back, -Vec3::Z),
                across * back + up_arm * Vec3::Y + along * Vec3::Z,
            )
        }
    }
}

/// `T_world_device` in session conventions from an XR pose of `space` in the reference
/// space (module docs: frames). The result's rotation is a unit quaternion.
pub fn session_pose(space: XrSpace, pose: &XrPose) -> Result<RigidTransform, XrPoseError> {
    let position = Vec3::from_array(pose.position);
    if !position.is_finite() {
        return Err(XrPoseError::NotFinitePosition(pose.position));
    }
    let q = Quat::from_array(pose.orientation);
    let length = q.length();
    if !(length.is_finite() && length > 1e-3) {
        return Err(XrPoseError::NotARotation(pose.orientation));
    }
    let t_world_xr = RigidTransform { rotation: q / length, translation: position };
    let t = t_world_xr * t_xr_space_device(space);
    Ok(RigidTransform::new(t.rotation, t.translation))
}

#[cfg(test)]
mod tests {
    use std::f32::consts::{FRAC_PI_2, PI};

    use super::*;

    fn pose(position: [f32; 3], rotation: Quat) -> XrPose {
        XrPose { position, orientation: rotation.to_array() }
    }

    fn same_rotation(a: Quat, b: Quat) -> bool {
        a.dot(b).abs() > 1.0 - 1e-6
    }

    #[test]
    fn a_viewer_looking_down_minus_z_is_a_cpf_turned_half_about_y() {
        let t = session_pose(XrSpace::Viewer, &pose([0.1, 1.6, -0.3], Quat::IDENTITY)).unwrap();
        assert!(same_rotation(t.rotation, Quat::from_rotation_y(PI)), "{t:?}");
        assert_eq!(t.translation, Vec3::new(0.1, 1.6, -0.3));
        // CPF forward (+Z) is XR forward (−Z), CPF left (+X) is XR left (−X).
        assert!(t.transform_vector(Vec3::Z).abs_diff_eq(-Vec3::Z, 1e-6));
        assert!(t.transform_vector(Vec3::X).abs_diff_eq(-Vec3::X, 1e-6));
        assert!(t.transform_vector(Vec3::Y).abs_diff_eq(Vec3::Y, 1e-6));
    }

    #[test]
    fn a_viewer_turned_left_looks_down_minus_x() {
        let t = session_pose(XrSpace::Viewer, &pose([0.0, 1.7, 0.0], Quat::from_rotation_y(FRAC_PI_2))).unwrap();
        assert!(t.transform_vector(Vec3::Z).abs_diff_eq(-Vec3::X, 1e-6), "forward {t:?}");
        assert!(t.transform_vector(Vec3::X).abs_diff_eq(Vec3::Z, 1e-6), "left {t:?}");
        assert!(same_rotation(t.rotation, Quat::from_rotation_y(-FRAC_PI_2)));
    }

    /// Hands held out sideways, palms down (the SMPL rest pose): the wrist frames have the
    /// identity rotation, as the SMPL wrist joints do.
    #[test]
    fn hands_in_the_t_pose_have_the_smpl_rest_wrist_frame() {
        // Hand joints: −Z towards the fingers (outwards: +X left, −X right), +Y the back of
        // the hand (up); X = Y × Z.
        let left_joint = Quat::from_mat3(&Mat3::from_cols(Vec3::Z, Vec3::Y, -Vec3::X));
        let right_joint = Quat::from_mat3(&Mat3::from_cols(-Vec3::Z, Vec3::Y, Vec3::X));
        for (space, q) in [(XrSpace::HandWrist(Hand::Left), left_joint), (XrSpace::HandWrist(Hand::Right), right_joint)]
        {
            let t = session_pose(space, &pose([0.7, 1.4, 0.0], q)).unwrap();
            assert!(same_rotation(t.rotation, Quat::IDENTITY), "{space:?}: {t:?}");
            assert_eq!(t.translation, Vec3::new(0.7, 1.4, 0.0));
        }
        // Grips, fists closed around a rod running front to back, thumbs forward: −Z forward,
        // +X the back of the right hand (up) / −X the back of the left hand; Y = Z × X.
        let right_grip = Quat::from_mat3(&Mat3::from_cols(Vec3::Y, Vec3::X, -Vec3::Z));
        let left_grip = Quat::from_mat3(&Mat3::from_cols(-Vec3::Y, -Vec3::X, -Vec3::Z));
        for (hand, q, outwards) in [(Hand::Right, right_grip, -Vec3::X), (Hand::Left, left_grip, Vec3::X)] {
            let fist = Vec3::new(0.0, 1.4, 0.2) + 0.8 * outwards;
            let t = session_pose(XrSpace::Grip(hand), &pose(fist.to_array(), q)).unwrap();
            assert!(same_rotation(t.rotation, Quat::IDENTITY), "{hand:?}: {t:?}");
            // The wrist is nearer the body than the fist, and above it (the back of the hand).
            let expected = fist - WRIST_IN_GRIP_M[1] * outwards + WRIST_IN_GRIP_M[0] * Vec3::Y;
            assert!(t.translation.abs_diff_eq(expected, 1e-6), "{hand:?}: {t:?}, expected {expected}");
        }
    }

    #[test]
    fn a_grip_pose_carries_the_wrist_offset_along() {
        // A right controller held out in front, pointing forward, turned 90° left.
        let q = Quat::from_rotation_y(FRAC_PI_2);
        let t = session_pose(XrSpace::Grip(Hand::Right), &pose([0.2, 1.2, -0.4], q)).unwrap();
        let offset = q * Vec3::from_array(WRIST_IN_GRIP_M);
        assert!(t.translation.abs_diff_eq(Vec3::new(0.2, 1.2, -0.4) + offset, 1e-6));
        let expected = q * Quat::from_mat3(&Mat3::from_cols(Vec3::Y, Vec3::X, -Vec3::Z));
        assert!(same_rotation(t.rotation, expected));
    }

    #[test]
    fn orientations_are_normalised_and_bad_numbers_refused() {
        let t =
            session_pose(XrSpace::Viewer, &XrPose { position: [0.0; 3], orientation: [0.0, 0.0, 0.0, 2.0] }).unwrap();
        assert!(same_rotation(t.rotation, Quat::from_rotation_y(PI)));
        assert!((t.rotation.length() - 1.0).abs() < 1e-6);
        let nan = XrPose { position: [f32::NAN, 0.0, 0.0], orientation: [0.0, 0.0, 0.0, 1.0] };
        assert!(matches!(session_pose(XrSpace::Viewer, &nan), Err(XrPoseError::NotFinitePosition(_))));
        for orientation in [[0.0; 4], [f32::INFINITY, 0.0, 0.0, 1.0], [f32::NAN; 4]] {
            let bad = XrPose { position: [0.0; 3], orientation };
            let err = session_pose(XrSpace::Grip(Hand::Left), &bad).unwrap_err();
            assert!(err.to_string().contains("not a rotation"), "{err}");
        }
    }

    #[test]
    fn every_offset_is_a_proper_rotation() {
        for space in [
            XrSpace::Viewer,
            XrSpace::Grip(Hand::Left),
            XrSpace::Grip(Hand::Right),
            XrSpace::HandWrist(Hand::Left),
            XrSpace::HandWrist(Hand::Right),
        ] {
            let m = t_xr_space_device(space).rotation_matrix();
            assert!((m.determinant() - 1.0).abs() < 1e-6, "{space:?}");
            assert!((m * m.transpose()).abs_diff_eq(Mat3::IDENTITY, 1e-6), "{space:?}");
        }
    }
}
