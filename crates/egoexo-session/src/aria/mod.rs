//! Project Aria conventions and the Machine Perception Services (MPS) files the importers
//! read: `closed_loop_trajectory.csv` ([`trajectory`]) and `online_calibration.jsonl`
//! ([`calibration`]).
//!
//! # Conversions (done once, here, at import)
//! - **World.** MPS worlds are gravity-aligned with gravity along −Z (Z up). The session world
//!   is Y up. [`t_session_world_aria_world`] is the rotation of −90° about X:
//!   `(x, y, z)_aria ↦ (x, z, −y)_session` — Aria's up (+Z) becomes +Y, Aria's +Y becomes −Z,
//!   X is kept. It is a proper rotation, so handedness is preserved. A file whose gravity is
//!   not −Z (a Y-up world, or a slightly tilted one) gets [`t_session_world_from_gravity`]:
//!   the same rotation followed by the shortest rotation taking its gravity onto −Y.
//! - **Device frame.** An Aria device pose `T_world_device` refers to the device frame, which
//!   is the left SLAM camera's frame on Aria Gen 1. Head devices in a session use the central
//!   pupil frame (CPF: +X left, +Y up, +Z forward): `T_world_cpf = T_world_device · T_device_cpf`.
//!   `T_device_cpf` comes from the calibration when it carries one, otherwise it is the
//!   nominal CAD value of [`nominal_t_device_cpf`].
//! - **Cameras.** Aria stores `T_device_camera`; sessions store `T_cpf_camera =
//!   T_device_cpf⁻¹ · T_device_camera` (for head devices).
//! - **Time.** MPS `tracking_timestamp_us` is microseconds on the device clock; sessions use
//!   nanoseconds (`× 1000`, overflow-checked). Devices with a [`time_sync`] file are mapped
//!   onto the common clock it names.

pub mod calibration;
pub mod hand_tracking;
pub mod semidense;
pub mod time_sync;
pub mod trajectory;

use egoexo_core::glam::{Mat3, Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::SmplPose;

/// `T_session_aria`: maps points of an Aria (Z-up) world into the session's Y-up world — a
/// rotation of −90° about X, `(x, y, z) ↦ (x, z, −y)`.
pub fn t_session_world_aria_world() -> RigidTransform {
    RigidTransform::from_rotation(Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2))
}

/// `T_session_file`: maps points of a file's world whose gravity is `gravity_world` into the
/// session's Y-up world. It is [`t_session_world_aria_world`] followed by the shortest rotation
/// that takes the (so rotated) gravity onto −Y, so an MPS file (gravity −Z) gets exactly the
/// MPS rotation and a Y-up file (gravity −Y) the identity. `gravity_world` must be non-zero.
pub fn t_session_world_from_gravity(gravity_world: Vec3) -> RigidTransform {
    let aria = t_session_world_aria_world();
    let down = aria.rotation * gravity_world.normalize();
    // `from_rotation_arc` is ill-defined for opposite vectors: gravity along +Y after the
    // MPS rotation (an upside-down world) turns half a turn about X.
    let fix = if down.dot(Vec3::NEG_Y) < -0.999_999 {
        Quat::from_rotation_x(std::f32::consts::PI)
    } else {
        Quat::from_rotation_arc(down, Vec3::NEG_Y)
    };
    RigidTransform::from_rotation((fix * aria.rotation).normalize())
}

/// A device pose in a file's world → the session pose in the Y-up world, with
/// `t_session_file` from [`t_session_world_from_gravity`]: with `Some(T_device_cpf)` the
/// result is `T_world_cpf` (head devices), with `None` the device frame is kept.
pub fn session_pose_from_file(
    t_session_file: &RigidTransform,
    t_file_device: &RigidTransform,
    t_device_cpf: Option<&RigidTransform>,
) -> RigidTransform {
    let t_session_device = *t_session_file * *t_file_device;
    match t_device_cpf {
        Some(t_device_cpf) => t_session_device * *t_device_cpf,
        None => t_session_device,
    }
}

/// Aria Gen 1 frame sizes (`DeviceClassInfo.BuildVersion` in a device calibration).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum AriaFrameSize {
    /// `DVT-S` (the default when the calibration does not say).
    #[default]
    Small,
    /// `DVT-L`.
    Large,
}

impl AriaFrameSize {
    /// From a `BuildVersion` string; `None` for anything else.
    pub fn from_build_version(build: &str) -> Option<Self> {
        match build {
            "DVT-S" => Some(Self::Small),
            "DVT-L" => Some(Self::Large),
            _ => None,
        }
    }
}

/// Nominal `T_device_cpf` of an Aria Gen 1 device whose device frame is the left SLAM camera
/// (every MPS trajectory), from the CAD extrinsics of projectaria_tools
/// (`core/calibration/DeviceCadExtrinsics.cpp`, `constructCadForDvtSmall/Large`: the
/// `camera-slam-left` row gives `T_cpf_slamleft` as a translation and the camera's Y and Z
/// axes in CPF; `getT_Device_Cpf()` is its inverse). Metres.
pub fn nominal_t_device_cpf(size: AriaFrameSize) -> RigidTransform {
    // camera-slam-left: translation, Y axis, Z axis (in CPF).
    let (t, y, z) = match size {
        AriaFrameSize::Small => (
            Vec3::new(0.069051, 0.002372, 0.009254),
            Vec3::new(0.793353, 0.0, -0.608761),
            Vec3::new(0.607927, -0.052336, 0.792266),
        ),
        AriaFrameSize::Large => (
            Vec3::new(0.071351, 0.002372, 0.008454),
            Vec3::new(0.793353, 0.0, -0.608761),
            Vec3::new(0.607927, -0.052336, 0.792266),
        ),
    };
    let y = y.normalize();
    let z = z.normalize();
    let x = y.cross(z).normalize();
    let t_cpf_slamleft = RigidTransform::from_rotation_matrix(Mat3::from_cols(x, y, z), t);
    t_cpf_slamleft.inverse()
}

/// An Aria device pose in its Z-up world → the session pose in the Y-up world: with
/// `Some(T_device_cpf)` the result is `T_world_cpf` (head devices), with `None` the device
/// frame is kept (wrist devices, which have no CPF).
pub fn session_pose_from_aria(t_aria_device: &RigidTransform, t_device_cpf: Option<&RigidTransform>) -> RigidTransform {
    let t_session_device = t_session_world_aria_world() * *t_aria_device;
    match t_device_cpf {
        Some(t_device_cpf) => t_session_device * *t_device_cpf,
        None => t_session_device,
    }
}

/// Inverse of [`session_pose_from_aria`] (used to write Aria-convention fixtures).
pub fn aria_pose_from_session(
    t_session_pose: &RigidTransform,
    t_device_cpf: Option<&RigidTransform>,
) -> RigidTransform {
    let t_session_device = match t_device_cpf {
        Some(t_device_cpf) => *t_session_pose * t_device_cpf.inverse(),
        None => *t_session_pose,
    };
    t_session_world_aria_world().inverse() * t_session_device
}

/// An SMPL pose fitted in an Aria (Z-up) world → the same body in the session's Y-up world.
///
/// SMPL's `transl` is relative to the pelvis rest joint `J0` (pelvis = `J0 + transl`, with the
/// root orientation rotating about the pelvis), so with `R = T_session_aria`:
/// `root' = R · root`, `transl' = R (J0 + transl) − J0`. Body rotations are local and unchanged.
pub fn session_smpl_pose_from_aria(pose: &SmplPose, rest_pelvis: Vec3) -> SmplPose {
    let r = t_session_world_aria_world().rotation;
    SmplPose {
        root_orientation: (r * pose.root_orientation).normalize(),
        body: pose.body,
        translation: r * (rest_pelvis + pose.translation) - rest_pelvis,
    }
}

/// Inverse of [`session_smpl_pose_from_aria`].
pub fn aria_smpl_pose_from_session(pose: &SmplPose, rest_pelvis: Vec3) -> SmplPose {
    let r_inv = t_session_world_aria_world().rotation.conjugate();
    SmplPose {
        root_orientation: (r_inv * pose.root_orientation).normalize(),
        body: pose.body,
        translation: r_inv * (rest_pelvis + pose.translation) - rest_pelvis,
    }
}

/// Microseconds → nanoseconds; `None` on overflow.
pub fn ns_from_us(us: i64) -> Option<i64> {
    us.checked_mul(1000)
}

#[cfg(test)]
mod tests {
    use egoexo_core::skeleton::SmplSkeleton;

    use super::*;

    #[test]
    fn aria_up_becomes_session_up() {
        let r = t_session_world_aria_world();
        assert!(r.transform_vector(Vec3::Z).abs_diff_eq(Vec3::Y, 1e-6));
        assert!(r.transform_vector(Vec3::Y).abs_diff_eq(-Vec3::Z, 1e-6));
        assert!(r.transform_vector(Vec3::X).abs_diff_eq(Vec3::X, 1e-6));
        // Gravity (−Z in Aria) points down (−Y) in the session.
        assert!(r.transform_vector(Vec3::new(0.0, 0.0, -9.81)).abs_diff_eq(Vec3::new(0.0, -9.81, 0.0), 1e-5));
    }

    #[test]
    fn gravity_gives_the_up_axis() {
        let mps = t_session_world_from_gravity(Vec3::new(0.0, 0.0, -9.81));
        assert!(mps.rotation.abs_diff_eq(t_session_world_aria_world().rotation, 1e-6), "MPS worlds as before");
        let y_up = t_session_world_from_gravity(Vec3::new(0.0, -9.81, 0.0));
        assert!(y_up.rotation.abs_diff_eq(Quat::IDENTITY, 1e-6), "a Y-up world is kept: {:?}", y_up.rotation);
        for g in [
            Vec3::new(0.0, 9.81, 0.0),
            Vec3::new(0.0, 0.0, 9.81),
            Vec3::new(-9.81, 0.0, 0.0),
            Vec3::new(0.3, -0.2, -9.7),
            Vec3::new(0.0, 0.0, -0.5),
        ] {
            let r = t_session_world_from_gravity(g);
            let down = r.transform_vector(g.normalize());
            assert!(down.abs_diff_eq(Vec3::NEG_Y, 1e-5), "{g} → {down}");
            assert!((r.rotation_matrix().determinant() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn cad_cpf_is_between_the_eyes_and_slam_left_is_on_the_left() {
        for size in [AriaFrameSize::Small, AriaFrameSize::Large] {
            let t_device_cpf = nominal_t_device_cpf(size);
            // The left SLAM camera sits ~7 cm to the wearer's left (+X in CPF).
            let slam_left_in_cpf = t_device_cpf.inverse().transform_point(Vec3::ZERO);
            assert!(slam_left_in_cpf.x > 0.06 && slam_left_in_cpf.x < 0.08, "{slam_left_in_cpf}");
            assert!(slam_left_in_cpf.y.abs() < 0.01 && slam_left_in_cpf.z.abs() < 0.02);
            // Proper rotation.
            assert!((t_device_cpf.rotation_matrix().determinant() - 1.0).abs() < 1e-5);
        }
    }

    /// Hand-built: upright glasses looking along Aria +X. In CPF, forward is +Z, up +Y and
    /// left +X, so `R_aria_cpf` has columns (left, up, forward) = (+Y, +Z, +X) in Aria axes.
    /// After import the glasses must look along session +X with +Y up and left = −Z.
    #[test]
    fn upright_glasses_stay_upright_after_import() {
        let t_device_cpf = nominal_t_device_cpf(AriaFrameSize::Small);
        let r_aria_cpf = Mat3::from_cols(Vec3::Y, Vec3::Z, Vec3::X);
        let t_aria_cpf = RigidTransform::from_rotation_matrix(r_aria_cpf, Vec3::new(1.0, 2.0, 1.6));
        let t_aria_device = t_aria_cpf * t_device_cpf.inverse();
        let t_session_cpf = session_pose_from_aria(&t_aria_device, Some(&t_device_cpf));
        assert!(t_session_cpf.transform_vector(Vec3::Z).abs_diff_eq(Vec3::X, 1e-5), "forward");
        assert!(t_session_cpf.transform_vector(Vec3::Y).abs_diff_eq(Vec3::Y, 1e-5), "up");
        assert!(t_session_cpf.transform_vector(Vec3::X).abs_diff_eq(-Vec3::Z, 1e-5), "left");
        // Eye height 1.6 m above the Aria floor becomes y = 1.6; Aria y = 2 becomes z = −2.
        assert!(t_session_cpf.translation.abs_diff_eq(Vec3::new(1.0, 1.6, -2.0), 1e-5));
        let back = aria_pose_from_session(&t_session_cpf, Some(&t_device_cpf));
        assert!(back.translation.abs_diff_eq(t_aria_device.translation, 1e-5));
    }

    #[test]
    fn smpl_conversion_keeps_the_pelvis_and_round_trips() {
        let skeleton = SmplSkeleton::mean_shape();
        let j0 = skeleton.rest_joints()[0];
        let pose = SmplPose {
            root_orientation: Quat::from_rotation_x(std::f32::consts::FRAC_PI_2) * Quat::from_rotation_y(0.3),
            body: [Quat::from_rotation_z(0.2); 21],
            translation: Vec3::new(0.5, -1.0, 0.9),
        };
        let converted = session_smpl_pose_from_aria(&pose, j0);
        let r = t_session_world_aria_world();
        let fk_aria = skeleton.forward_kinematics(&pose);
        let fk_session = skeleton.forward_kinematics(&converted);
        for j in 0..24 {
            let expected = r.transform_point(fk_aria.positions[j]);
            assert!(fk_session.positions[j].abs_diff_eq(expected, 1e-5), "joint {j}");
        }
        let back = aria_smpl_pose_from_session(&converted, j0);
        assert!(back.translation.abs_diff_eq(pose.translation, 1e-5));
        assert!(back.root_orientation.abs_diff_eq(pose.root_orientation, 1e-5));
    }
}
