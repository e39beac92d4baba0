//! The SMPL 24-joint skeleton, forward kinematics, and root recovery from a head device.
//!
//! Frames and units: metres; SMPL's body frame in the rest pose is Y up, facing +Z, the
//! subject's left is +X. A pose is SMPL's parameterisation: a root (pelvis) orientation in
//! the world, 21 body-joint rotations local to their parent (joints 1..=21), and SMPL's
//! `transl`. The two hand joints (22, 23) keep the identity rotation.
//!
//! Translation convention (SMPL and AMASS `trans`): the pelvis joint's world position is
//! `rest_joints[0] + translation`; the root orientation rotates about the pelvis joint.

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::rigid::RigidTransform;

/// Number of SMPL joints (body + the two hands).
pub const NUM_JOINTS: usize = 24;
/// Number of body joints whose local rotations the networks predict (joints 1..=21).
pub const NUM_BODY_JOINTS: usize = 21;

/// Parent of each joint (`-1` for the pelvis root).
pub const PARENTS: [i8; NUM_JOINTS] =
    [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21];

/// Joint names in SMPL order.
pub const JOINT_NAMES: [&str; NUM_JOINTS] = [
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hand",
    "right_hand",
];

/// Named SMPL joints (discriminant = index).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum SmplJoint {
    Pelvis = 0,
    LeftHip,
    RightHip,
    Spine1,
    LeftKnee,
    RightKnee,
    Spine2,
    LeftAnkle,
    RightAnkle,
    Spine3,
    LeftFoot,
    RightFoot,
    Neck,
    LeftCollar,
    RightCollar,
    Head,
    LeftShoulder,
    RightShoulder,
    LeftElbow,
    RightElbow,
    LeftWrist,
    RightWrist,
    LeftHand,
    RightHand,
}

impl SmplJoint {
    /// Index into the 24-joint arrays.
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// Mean-shape (neutral, betas = 0) rest joints, metres, SMPL's body frame
/// (from `shared/smpl/README.md`).
pub const MEAN_SHAPE_REST_JOINTS: [[f32; 3]; NUM_JOINTS] = [
    [-0.0018, -0.2233, 0.0282],
    [0.0677, -0.3147, 0.0214],
    [-0.0695, -0.3139, 0.0239],
    [-0.0043, -0.1144, 0.0015],
    [0.1020, -0.6899, 0.0169],
    [-0.1078, -0.6964, 0.0150],
    [0.0012, 0.0208, 0.0026],
    [0.0884, -1.0879, -0.0268],
    [-0.0920, -1.0948, -0.0273],
    [0.0026, 0.0737, 0.0280],
    [0.1148, -1.1437, 0.0925],
    [-0.1174, -1.1430, 0.0961],
    [-0.0002, 0.2876, -0.0148],
    [0.0815, 0.1955, -0.0060],
    [-0.0791, 0.1926, -0.0106],
    [0.0050, 0.3526, 0.0365],
    [0.1724, 0.2260, -0.0149],
    [-0.1752, 0.2251, -0.0197],
    [0.4321, 0.2132, -0.0424],
    [-0.4289, 0.2118, -0.0411],
    [0.6813, 0.2222, -0.0435],
    [-0.6842, 0.2196, -0.0467],
    [0.7653, 0.2140, -0.0585],
    [-0.7688, 0.2134, -0.0570],
];

/// Approximate standing height (soles to top of head) of the SMPL neutral mean-shape body,
/// metres. Only used to turn a subject's stature into a uniform scale factor when no SMPL
/// shape is known; the ratio of stature to [`SmplSkeleton::head_height`] is what matters.
pub const MEAN_SHAPE_STATURE_M: f32 = 1.70;

/// The joint that mirrors each joint left↔right (itself for the spine, neck, head and pelvis).
pub const MIRRORED_JOINT: [usize; NUM_JOINTS] =
    [0, 2, 1, 3, 5, 4, 6, 8, 7, 9, 11, 10, 12, 14, 13, 15, 17, 16, 19, 18, 21, 20, 23, 22];

/// The rotation `M R M` for the reflection `M = diag(−1, 1, 1)` (the world mirrored across
/// its YZ plane): quaternion `(x, y, z, w) ↦ (x, −y, −z, w)`.
pub fn mirror_rotation(q: Quat) -> Quat {
    Quat::from_xyzw(q.x, -q.y, -q.z, q.w)
}

/// Default position of the SMPL head joint in the head-device (CPF) frame, metres, for the mean
/// shape: glasses sit about 9 cm in front of and 6 cm above the head joint (the head joint is
/// near the top of the neck, between the ears). Used when a session does not calibrate it;
/// the simulator places glasses with the same offset.
pub const DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE: Vec3 = Vec3::new(0.0, -0.06, -0.09);

/// Errors building a skeleton.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SkeletonError {
    #[error("rest joint {joint} (`{name}`) is not finite: {value:?}")]
    NonFiniteJoint { joint: usize, name: &'static str, value: [f32; 3] },
    #[error("bone from `{parent}` to `{child}` has zero length")]
    ZeroLengthBone { parent: &'static str, child: &'static str },
    #[error("target height must be a positive finite number of metres, got {0}")]
    InvalidHeight(f32),
}

/// A skeleton: the 24 rest-pose joint positions (metres, body frame), with SMPL's topology.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SmplSkeleton {
    rest_joints: [Vec3; NUM_JOINTS],
}

impl Default for SmplSkeleton {
    fn default() -> Self {
        Self::mean_shape()
    }
}

/// Global (world) joint transforms after forward kinematics.
#[derive(Clone, Debug, PartialEq)]
pub struct JointTransforms {
    /// World positions of the 24 joints, metres.
    pub positions: [Vec3; NUM_JOINTS],
    /// World orientations of the 24 joints (`R_world_joint`).
    pub rotations: [Quat; NUM_JOINTS],
}

/// SMPL pose parameters for one frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SmplPose {
    /// Pelvis orientation in the world (`R_world_pelvis`).
    pub root_orientation: Quat,
    /// Local rotations of joints 1..=21, each relative to its parent.
    pub body: [Quat; NUM_BODY_JOINTS],
    /// SMPL `transl`, metres: pelvis world position = `rest_joints[0] + translation`.
    pub translation: Vec3,
}

impl Default for SmplPose {
    fn default() -> Self {
        Self::rest()
    }
}

impl SmplPose {
    /// The rest (T-) pose at the origin.
    pub fn rest() -> Self {
        Self { root_orientation: Quat::IDENTITY, body: [Quat::IDENTITY; NUM_BODY_JOINTS], translation: Vec3::ZERO }
    }

    /// Local rotation of joint `j` (0 = root orientation; 22, 23 = identity).
    pub fn local_rotation(&self, j: usize) -> Quat {
        match j {
            0 => self.root_orientation,
            1..=NUM_BODY_JOINTS => self.body[j - 1],
            _ => Quat::IDENTITY,
        }
    }

    /// Every number is finite.
    pub fn is_finite(&self) -> bool {
        self.root_orientation.is_finite() && self.translation.is_finite() && self.body.iter().all(|q| q.is_finite())
    }

    /// The pose mirrored across the world's YZ plane (`x ↦ −x`), left and right swapped: on
    /// the [mirrored skeleton](SmplSkeleton::mirrored) its joint `j` lands where this pose's
    /// joint [`MIRRORED_JOINT`]`[j]` lands, reflected. A data augmentation for training.
    pub fn mirrored(&self) -> Self {
        Self {
            root_orientation: mirror_rotation(self.root_orientation),
            body: std::array::from_fn(|i| mirror_rotation(self.body[MIRRORED_JOINT[i + 1] - 1])),
            translation: Vec3::new(-self.translation.x, self.translation.y, self.translation.z),
        }
    }

    /// Interpolates from `self` (`alpha = 0`) to `other` (`alpha = 1`): every rotation (root and
    /// the 21 local ones) by slerp along the shortest arc, the translation linearly. Used to
    /// resample motions between frames.
    pub fn interpolate(&self, other: &Self, alpha: f32) -> Self {
        let mut body = self.body;
        for (q, q_other) in body.iter_mut().zip(&other.body) {
            *q = q.slerp(*q_other, alpha).normalize();
        }
        Self {
            root_orientation: self.root_orientation.slerp(other.root_orientation, alpha).normalize(),
            body,
            translation: self.translation.lerp(other.translation, alpha),
        }
    }
}

impl SmplSkeleton {
    /// The neutral mean-shape skeleton (about 1.50 m from lowest foot joint to head joint).
    pub fn mean_shape() -> Self {
        Self { rest_joints: MEAN_SHAPE_REST_JOINTS.map(Vec3::from_array) }
    }

    /// A skeleton from arbitrary rest joints (e.g. regressed from an SMPL model file for
    /// given betas). Rejects non-finite joints and zero-length bones.
    pub fn from_rest_joints(rest_joints: [Vec3; NUM_JOINTS]) -> Result<Self, SkeletonError> {
        for (joint, p) in rest_joints.iter().enumerate() {
            if !p.is_finite() {
                return Err(SkeletonError::NonFiniteJoint { joint, name: JOINT_NAMES[joint], value: p.to_array() });
            }
        }
        for (child, &parent) in PARENTS.iter().enumerate().skip(1) {
            if rest_joints[child].distance(rest_joints[parent as usize]) < 1e-6 {
                return Err(SkeletonError::ZeroLengthBone {
                    parent: JOINT_NAMES[parent as usize],
                    child: JOINT_NAMES[child],
                });
            }
        }
        Ok(Self { rest_joints })
    }

    /// The skeleton mirrored across its YZ plane with left and right swapped (for a
    /// symmetric body, itself).
    pub fn mirrored(&self) -> Self {
        Self {
            rest_joints: std::array::from_fn(|j| {
                let p = self.rest_joints[MIRRORED_JOINT[j]];
                Vec3::new(-p.x, p.y, p.z)
            }),
        }
    }

    /// Rest joint positions (metres, body frame).
    pub fn rest_joints(&self) -> &[Vec3; NUM_JOINTS] {
        &self.rest_joints
    }

    /// Vector from the parent joint to joint `j` in the rest pose (zero for the root).
    pub fn bone_offset(&self, j: usize) -> Vec3 {
        match PARENTS[j] {
            -1 => Vec3::ZERO,
            parent => self.rest_joints[j] - self.rest_joints[parent as usize],
        }
    }

    /// Rest-pose height of the head joint above the lowest ankle/foot joint, metres.
    pub fn head_height(&self) -> f32 {
        let lowest = [7, 8, 10, 11].iter().map(|&j| self.rest_joints[j].y).fold(f32::INFINITY, f32::min);
        self.rest_joints[SmplJoint::Head.index()].y - lowest
    }

    /// Every joint scaled about the origin by `factor`.
    pub fn scaled(&self, factor: f32) -> Self {
        Self { rest_joints: self.rest_joints.map(|p| p * factor) }
    }

    /// Scaled uniformly so that [`SmplSkeleton::head_height`] equals `head_height_m`.
    pub fn scaled_to_head_height(&self, head_height_m: f32) -> Result<Self, SkeletonError> {
        if !(head_height_m.is_finite() && head_height_m > 0.0) {
            return Err(SkeletonError::InvalidHeight(head_height_m));
        }
        Ok(self.scaled(head_height_m / self.head_height()))
    }

    /// The mean-shape skeleton scaled uniformly to a subject's stature (soles to top of head,
    /// metres), using [`MEAN_SHAPE_STATURE_M`] for the mean shape's stature.
    pub fn mean_shape_for_stature(stature_m: f32) -> Result<Self, SkeletonError> {
        if !(stature_m.is_finite() && stature_m > 0.0) {
            return Err(SkeletonError::InvalidHeight(stature_m));
        }
        Ok(Self::mean_shape().scaled(stature_m / MEAN_SHAPE_STATURE_M))
    }

    /// Forward kinematics: world joint positions and orientations for a pose.
    ///
    /// `R_j = R_parent · local_j`, `p_j = p_parent + R_parent · (rest_j − rest_parent)`,
    /// with `p_0 = rest_0 + translation` and `R_0 = root_orientation`.
    pub fn forward_kinematics(&self, pose: &SmplPose) -> JointTransforms {
        let mut positions = [Vec3::ZERO; NUM_JOINTS];
        let mut rotations = [Quat::IDENTITY; NUM_JOINTS];
        positions[0] = self.rest_joints[0] + pose.translation;
        rotations[0] = pose.root_orientation.normalize();
        for j in 1..NUM_JOINTS {
            let parent = PARENTS[j] as usize;
            rotations[j] = (rotations[parent] * pose.local_rotation(j)).normalize();
            positions[j] = positions[parent] + rotations[parent] * self.bone_offset(j);
        }
        JointTransforms { positions, rotations }
    }

    /// `FK_head(θ)`: the head joint's position relative to the pelvis joint, in world axes,
    /// for a pose's root orientation and body rotations (translation ignored).
    pub fn head_offset_from_pelvis(&self, root_orientation: Quat, body: &[Quat; NUM_BODY_JOINTS]) -> Vec3 {
        let pose = SmplPose { root_orientation, body: *body, translation: Vec3::ZERO };
        let fk = self.forward_kinematics(&pose);
        fk.positions[SmplJoint::Head.index()] - fk.positions[0]
    }

    /// Root recovery from the head device (paper § Temporal modeling and decoding):
    /// `p_root = p_head − FK_head(θ)`, returned as SMPL `transl`.
    ///
    /// `t_world_head_device` is the tracked head-device pose; `head_joint_in_device` is the
    /// SMPL head joint's position in the head-device frame (metres) — the fixed offset
    /// between the glasses and the head joint.
    pub fn recover_translation(
        &self,
        root_orientation: Quat,
        body: &[Quat; NUM_BODY_JOINTS],
        t_world_head_device: &RigidTransform,
        head_joint_in_device: Vec3,
    ) -> Vec3 {
        let p_head = t_world_head_device.transform_point(head_joint_in_device);
        let p_root = p_head - self.head_offset_from_pelvis(root_orientation, body);
        p_root - self.rest_joints[0]
    }
}

/// The body's tapered capsules for the SMPL mean shape ([`MEAN_SHAPE_REST_JOINTS`], 1.70 m), for drawing a body (the viewer) or
/// rendering one into simulated observer video (`egoexo-synth`):
/// per bone, indexed by its child joint, the radius at the parent's end and at the child's end,
/// metres (index 0, the pelvis, has no bone). Scaled per subject (the viewer's `subject_scale`).
pub const MEAN_SHAPE_BONE_RADII: [(f32, f32); NUM_JOINTS] = [
    (0.0, 0.0),     // pelvis (root)
    (0.085, 0.075), // pelvis → left hip
    (0.085, 0.075), // pelvis → right hip
    (0.105, 0.1),   // pelvis → spine1
    (0.075, 0.05),  // left thigh
    (0.075, 0.05),  // right thigh
    (0.1, 0.105),   // spine1 → spine2
    (0.05, 0.038),  // left shin
    (0.05, 0.038),  // right shin
    (0.105, 0.11),  // spine2 → spine3
    (0.038, 0.03),  // left foot (its joint is 3 cm above the sole)
    (0.038, 0.03),  // right foot
    (0.065, 0.05),  // spine3 → neck
    (0.07, 0.055),  // spine3 → left collar
    (0.07, 0.055),  // spine3 → right collar
    (0.05, 0.05),   // neck → head joint (the skull is a sphere above it)
    (0.055, 0.05),  // left collar → shoulder
    (0.055, 0.05),  // right collar → shoulder
    (0.05, 0.04),   // left upper arm
    (0.05, 0.04),   // right upper arm
    (0.04, 0.03),   // left forearm
    (0.04, 0.03),   // right forearm
    (0.032, 0.03),  // left hand
    (0.032, 0.03),  // right hand
];
/// The skull of the mean shape: a sphere of this radius, metres, centred this far beyond the
/// head joint along the neck → head direction.
pub const MEAN_SHAPE_SKULL: (f32, f32) = (0.1, 0.085);

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn parents_precede_children() {
        for (j, &p) in PARENTS.iter().enumerate().skip(1) {
            assert!((p as usize) < j);
        }
    }

    #[test]
    fn mean_shape_head_height_is_about_one_and_a_half_metres() {
        let h = SmplSkeleton::mean_shape().head_height();
        assert!((h - 1.50).abs() < 0.01, "{h}");
    }

    #[test]
    fn pose_interpolation_endpoints_midpoint_and_short_arc() {
        let a = SmplPose { root_orientation: Quat::from_rotation_y(0.2), ..SmplPose::rest() };
        let mut b =
            SmplPose { root_orientation: -Quat::from_rotation_y(0.6), translation: Vec3::X, ..SmplPose::rest() };
        b.body[3] = Quat::from_rotation_z(1.0);
        let mid = a.interpolate(&b, 0.5);
        assert!(crate::rotation::angle_between(mid.root_orientation, Quat::from_rotation_y(0.4)) < 1e-5);
        assert!(crate::rotation::angle_between(mid.body[3], Quat::from_rotation_z(0.5)) < 1e-5);
        assert!(mid.translation.abs_diff_eq(Vec3::new(0.5, 0.0, 0.0), 1e-6));
        assert!(crate::rotation::angle_between(a.interpolate(&b, 0.0).root_orientation, a.root_orientation) < 1e-6);
        assert!(crate::rotation::angle_between(a.interpolate(&b, 1.0).body[3], b.body[3]) < 1e-6);
    }

    #[test]
    fn rejects_degenerate_rest_joints() {
        let mut joints = SmplSkeleton::mean_shape().rest_joints;
        joints[4] = joints[1];
        assert!(matches!(
            SmplSkeleton::from_rest_joints(joints),
            Err(SkeletonError::ZeroLengthBone { child: "left_knee", .. })
        ));
        joints[4] = Vec3::NAN;
        assert!(matches!(SmplSkeleton::from_rest_joints(joints), Err(SkeletonError::NonFiniteJoint { joint: 4, .. })));
    }
}
