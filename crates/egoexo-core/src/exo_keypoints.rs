//! The paper's K = 13 exocentric keypoints and their one mapping from COCO-17 (what 2D pose
//! detectors write) and onto the SMPL skeleton (what the simulator projects).
//!
//! The 13 are COCO-17 without the eyes and ears: the nose plus shoulders, elbows, wrists,
//! hips, knees and ankles. Image coordinates are pixels (centre of the top-left pixel at 0, 0).

use glam::{Quat, Vec2, Vec3};
use serde::{Deserialize, Serialize};

use crate::rigid::RigidTransform;
use crate::skeleton::SmplJoint;

/// Number of exocentric keypoints per observer and frame (the paper's K).
pub const EXO_KEYPOINT_COUNT: usize = 13;

/// Number of COCO-17 keypoints.
pub const COCO17_COUNT: usize = 17;

/// COCO-17 keypoint names in their standard order.
pub const COCO17_NAMES: [&str; COCO17_COUNT] = [
    "nose",
    "left_eye",
    "right_eye",
    "left_ear",
    "right_ear",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
];

/// The 13 exocentric keypoints, in network order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum ExoKeypoint {
    Nose = 0,
    LeftShoulder,
    RightShoulder,
    LeftElbow,
    RightElbow,
    LeftWrist,
    RightWrist,
    LeftHip,
    RightHip,
    LeftKnee,
    RightKnee,
    LeftAnkle,
    RightAnkle,
}

impl ExoKeypoint {
    /// All 13 in network order.
    pub const ALL: [ExoKeypoint; EXO_KEYPOINT_COUNT] = [
        ExoKeypoint::Nose,
        ExoKeypoint::LeftShoulder,
        ExoKeypoint::RightShoulder,
        ExoKeypoint::LeftElbow,
        ExoKeypoint::RightElbow,
        ExoKeypoint::LeftWrist,
        ExoKeypoint::RightWrist,
        ExoKeypoint::LeftHip,
        ExoKeypoint::RightHip,
        ExoKeypoint::LeftKnee,
        ExoKeypoint::RightKnee,
        ExoKeypoint::LeftAnkle,
        ExoKeypoint::RightAnkle,
    ];

    /// Index in network order.
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Index of this keypoint in COCO-17 order.
    pub const fn coco17_index(self) -> usize {
        match self {
            ExoKeypoint::Nose => 0,
            other => other as usize + 4,
        }
    }

    /// COCO name (`"left_knee"`, …).
    pub fn name(self) -> &'static str {
        COCO17_NAMES[self.coco17_index()]
    }

    /// The SMPL joint this keypoint is placed at (the nose is offset from the head joint,
    /// see [`NOSE_IN_HEAD_JOINT`]).
    pub const fn smpl_joint(self) -> SmplJoint {
        match self {
            ExoKeypoint::Nose => SmplJoint::Head,
            ExoKeypoint::LeftShoulder => SmplJoint::LeftShoulder,
            ExoKeypoint::RightShoulder => SmplJoint::RightShoulder,
            ExoKeypoint::LeftElbow => SmplJoint::LeftElbow,
            ExoKeypoint::RightElbow => SmplJoint::RightElbow,
            ExoKeypoint::LeftWrist => SmplJoint::LeftWrist,
            ExoKeypoint::RightWrist => SmplJoint::RightWrist,
            ExoKeypoint::LeftHip => SmplJoint::LeftHip,
            ExoKeypoint::RightHip => SmplJoint::RightHip,
            ExoKeypoint::LeftKnee => SmplJoint::LeftKnee,
            ExoKeypoint::RightKnee => SmplJoint::RightKnee,
            ExoKeypoint::LeftAnkle => SmplJoint::LeftAnkle,
            ExoKeypoint::RightAnkle => SmplJoint::RightAnkle,
        }
    }
}

/// Nose tip in the SMPL head joint's frame for the mean shape (metres; the head frame is the
/// body frame in the rest pose: Y up, facing +Z). Scaled with the skeleton.
pub const NOSE_IN_HEAD_JOINT: Vec3 = Vec3::new(0.0, -0.01, 0.11);

/// The COCO-17 skeleton's bones (pairs of keypoint indices) as drawn over a detection: face,
/// arms, torso, legs.
pub const COCO17_BONES: [(u8, u8); 16] = [
    (0, 1),
    (0, 2),
    (1, 3),
    (2, 4),
    (5, 7),
    (7, 9),
    (6, 8),
    (8, 10),
    (5, 6),
    (5, 11),
    (6, 12),
    (11, 12),
    (11, 13),
    (13, 15),
    (12, 14),
    (14, 16),
];

/// COCO-17's left–right mirror: keypoint `k`'s counterpart on the other side (the nose maps
/// to itself).
pub const COCO17_MIRROR: [usize; COCO17_COUNT] = [0, 2, 1, 4, 3, 6, 5, 8, 7, 10, 9, 12, 11, 14, 13, 16, 15];

/// One detected 2D keypoint: pixel position and detector score in `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Keypoint2d {
    pub pixel: Vec2,
    pub score: f32,
}

/// Picks the 13 exocentric keypoints out of a COCO-17 detection (the only place this
/// mapping is done).
pub fn exo_from_coco17<T: Copy>(coco: &[T; COCO17_COUNT]) -> [T; EXO_KEYPOINT_COUNT] {
    ExoKeypoint::ALL.map(|k| coco[k.coco17_index()])
}

/// World positions of the 13 exocentric keypoints on a posed SMPL body, given the 24 joint
/// positions and the head joint's world rotation; `skeleton_scale` scales the nose offset
/// (1 for the mean shape).
pub fn exo_keypoints_from_smpl(
    positions: &[Vec3; 24],
    head_rotation: Quat,
    skeleton_scale: f32,
) -> [Vec3; EXO_KEYPOINT_COUNT] {
    ExoKeypoint::ALL.map(|k| match k {
        ExoKeypoint::Nose => positions[SmplJoint::Head.index()] + head_rotation * (NOSE_IN_HEAD_JOINT * skeleton_scale),
        other => positions[other.smpl_joint().index()],
    })
}

/// Eyes and ears in the SMPL head joint's frame (mean shape, metres; Y up, facing +Z, left +X),
/// by COCO-17 index. Scaled with the skeleton.
pub const FACE_POINTS_IN_HEAD_JOINT: [(usize, Vec3); 4] = [
    (1, Vec3::new(0.032, 0.035, 0.085)),  // left eye
    (2, Vec3::new(-0.032, 0.035, 0.085)), // right eye
    (3, Vec3::new(0.075, 0.01, 0.0)),     // left ear
    (4, Vec3::new(-0.075, 0.01, 0.0)),    // right ear
];

/// The 17 COCO keypoints' world positions from the 13 exo keypoints and the head joint's world
/// pose `T_world_headjoint` (eyes and ears at [`FACE_POINTS_IN_HEAD_JOINT`] × `scale`).
pub fn coco17_from_exo(
    exo_points: &[Vec3; EXO_KEYPOINT_COUNT],
    head_joint: &RigidTransform,
    scale: f32,
) -> [Vec3; COCO17_COUNT] {
    let mut points = [Vec3::ZERO; COCO17_COUNT];
    for k in ExoKeypoint::ALL {
        points[k.coco17_index()] = exo_points[k.index()];
    }
    for (index, offset) in FACE_POINTS_IN_HEAD_JOINT {
        points[index] = head_joint.transform_point(offset * scale);
    }
    points
}

/// The head joint's world pose `T_world_headjoint` of glasses tracked at `T_world_device`
/// whose frame (CPF: +X left, +Y up, +Z forward, the head joint's own axes) holds the head
/// joint at `head_joint_in_device` (metres).
pub fn head_joint_from_device(t_world_device: &RigidTransform, head_joint_in_device: Vec3) -> RigidTransform {
    *t_world_device * RigidTransform::from_translation(head_joint_in_device)
}

/// The glasses' `T_world_device` for a head joint at `T_world_headjoint` (the inverse of
/// [`head_joint_from_device`]).
pub fn device_from_head_joint(t_world_head_joint: &RigidTransform, head_joint_in_device: Vec3) -> RigidTransform {
    *t_world_head_joint * RigidTransform::from_translation(-head_joint_in_device)
}

/// The five face keypoints (COCO-17 nose, eyes, ears: indices 0–4) in the world that a head
/// device at `T_world_device` fixes by itself: exact up to the wearer's face, with no body
/// pose needed. `scale` is the skeleton's size against the mean shape.
pub fn face_points_from_device(t_world_device: &RigidTransform, head_joint_in_device: Vec3, scale: f32) -> [Vec3; 5] {
    let head = head_joint_from_device(t_world_device, head_joint_in_device);
    let mut points = [head.transform_point(NOSE_IN_HEAD_JOINT * scale); 5];
    for (index, offset) in FACE_POINTS_IN_HEAD_JOINT {
        points[index] = head.transform_point(offset * scale);
    }
    points
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn coco_mapping_skips_eyes_and_ears() {
        let names: Vec<_> = ExoKeypoint::ALL.iter().map(|k| k.name()).collect();
        assert_eq!(names[0], "nose");
        assert_eq!(names[1], "left_shoulder");
        assert_eq!(names[12], "right_ankle");
        assert!(!names.iter().any(|n| n.contains("eye") || n.contains("ear")));
        let picked = exo_from_coco17(&std::array::from_fn::<usize, 17, _>(|i| i));
        assert_eq!(picked, [0, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16]);
    }

    #[test]
    fn names_match_smpl_joint_names() {
        for k in ExoKeypoint::ALL.iter().skip(1) {
            assert_eq!(k.name(), crate::skeleton::JOINT_NAMES[k.smpl_joint().index()]);
        }
    }
}
