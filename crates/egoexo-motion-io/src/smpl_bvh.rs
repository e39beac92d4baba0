//! BVH export of SMPL motion (and reading such a file back).
//!
//! # The file
//! - **Hierarchy**: the 24 SMPL joints with SMPL's names (`pelvis`, `left_hip`, …) and tree.
//!   `OFFSET`s are the skeleton's rest bones (`rest[j] − rest[parent]`, SMPL's body frame) in
//!   [`LengthUnit`]s; the root's `OFFSET` is `0 0 0`. The leaves (head, feet, hands) get an
//!   `End Site` (cosmetic: 10 cm up from the head, 5 cm forward from the feet, 8 cm outward
//!   from the hands, scaled with the skeleton).
//! - **World**: this project's, Y up (as BVH files usually are, and what Blender's importer
//!   assumes by default), metres by default — with Blender's default import scale of 1 the
//!   body comes in at its true size. [`LengthUnit::Centimetres`] writes centimetres instead
//!   (MotionBuilder, Maya).
//! - **Root**: 6 channels, `Xposition Yposition Zposition Yrotation Xrotation Zrotation`. The
//!   position channels are the pelvis joint's world position, `rest[0] + translation`; with
//!   the root `OFFSET` at zero, readers that add the offset and readers that replace it agree.
//!   Heading (Y) is the outermost rotation, so a turning subject never meets gimbal lock.
//! - **Other joints**: 3 rotation channels (degrees), the joint's SMPL local rotation. The
//!   Euler order puts the bone's own (twist) axis in the middle, the axis that rarely nears
//!   90°: `Zrotation Yrotation Xrotation` for the hips, knees, spine, neck and head (bones
//!   along Y), `Zrotation Xrotation Yrotation` for the collars, arms and hands (bones along
//!   X), `Xrotation Zrotation Yrotation` for the ankles and feet (bones along +Z). Elbows and
//!   knees flexing through 90° are then far from gimbal lock. Hands are always 0.
//! - **Frames**: one per motion frame, `Frame Time` = 1/fps. The session clock's start
//!   time is not stored.

use egoexo_core::SmplMotion;
use egoexo_core::euler::{Axis, EulerOrder};
use egoexo_core::glam::{DQuat, DVec3, Quat, Vec3};
use egoexo_core::skeleton::{JOINT_NAMES, NUM_BODY_JOINTS, NUM_JOINTS, PARENTS, SmplPose, SmplSkeleton};
use thiserror::Error;

use crate::bvh::{Bvh, BvhError, BvhJoint, Channel};
use crate::{ExportError, Format, validate};

/// Length unit of the written file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LengthUnit {
    /// Metres (Blender's default import scale).
    #[default]
    Metres,
    /// Centimetres.
    Centimetres,
}

impl LengthUnit {
    /// File units per metre.
    pub fn per_metre(self) -> f64 {
        match self {
            LengthUnit::Metres => 1.0,
            LengthUnit::Centimetres => 100.0,
        }
    }
}

/// Options of [`write_bvh`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BvhOptions {
    pub unit: LengthUnit,
    /// Digits after the decimal point (6 keeps joints within a few µm of the motion's FK).
    pub decimals: usize,
}

impl Default for BvhOptions {
    fn default() -> Self {
        BvhOptions { unit: LengthUnit::Metres, decimals: 6 }
    }
}

/// Order of the root's rotation channels (heading outermost).
pub const ROOT_EULER_ORDER: EulerOrder = EulerOrder::YXZ;

/// The Euler order of SMPL joint `j`'s rotation channels (see the module docs).
pub fn euler_order(j: usize) -> EulerOrder {
    match j {
        0 => ROOT_EULER_ORDER,
        // Collars, shoulders, elbows, wrists, hands: bones along ±X.
        13 | 14 | 16..=23 => EulerOrder::ZXY,
        // Ankles and feet: bones along +Z (forward); flexion (X) outermost.
        7 | 8 | 10 | 11 => EulerOrder::XZY,
        // Spine, neck, head, hips, knees: bones along Y.
        _ => EulerOrder::ZYX,
    }
}

/// End-site offsets of the leaf joints, metres, mean-shape body frame.
fn end_site(j: usize) -> Option<Vec3> {
    match j {
        15 => Some(Vec3::new(0.0, 0.10, 0.0)),
        10 | 11 => Some(Vec3::new(0.0, 0.0, 0.05)),
        22 => Some(Vec3::new(0.08, 0.0, 0.0)),
        23 => Some(Vec3::new(-0.08, 0.0, 0.0)),
        _ => None,
    }
}

/// The SMPL joints in depth-first order (children in SMPL index order), the order a BVH
/// hierarchy lists them: pelvis, left_hip, left_knee, left_ankle, left_foot, right_hip, …
pub fn depth_first_order() -> [usize; NUM_JOINTS] {
    let mut order = [0; NUM_JOINTS];
    let mut stack = vec![0usize];
    let mut n = 0;
    while let Some(j) = stack.pop() {
        order[n] = j;
        n += 1;
        // Push children in reverse so the lowest index is visited first.
        stack.extend((j + 1..NUM_JOINTS).rev().filter(|&c| PARENTS[c] as usize == j));
    }
    order
}

/// The BVH file (hierarchy and channel values) of a motion, in `unit`s. Joints are listed
/// depth-first ([`depth_first_order`]), as BVH nests them.
pub fn smpl_bvh(motion: &SmplMotion, unit: LengthUnit) -> Result<Bvh, ExportError> {
    validate(motion)?;
    if motion.len() > crate::bvh::MAX_FRAMES {
        return Err(ExportError::TooManyFrames {
            format: Format::Bvh,
            frames: motion.len(),
            limit: crate::bvh::MAX_FRAMES,
        });
    }
    let scale = unit.per_metre();
    let to_file = |v: Vec3| v.as_dvec3() * scale;
    let skeleton = &motion.skeleton;
    let body_scale = skeleton.head_height() / SmplSkeleton::mean_shape().head_height();
    let order = depth_first_order();
    let mut position_in_file = [0; NUM_JOINTS];
    for (i, &j) in order.iter().enumerate() {
        position_in_file[j] = i;
    }
    let joints: Vec<BvhJoint> = order
        .iter()
        .map(|&j| {
            let channels = match j {
                0 => [Channel::Xposition, Channel::Yposition, Channel::Zposition]
                    .into_iter()
                    .chain(Channel::rotations(ROOT_EULER_ORDER))
                    .collect(),
                _ => Channel::rotations(euler_order(j)).to_vec(),
            };
            BvhJoint {
                name: JOINT_NAMES[j].to_string(),
                parent: usize::try_from(PARENTS[j]).ok().map(|p| position_in_file[p]),
                offset: to_file(skeleton.bone_offset(j)),
                channels,
                end_site: end_site(j).map(|e| to_file(e * body_scale)),
            }
        })
        .collect();
    let channels_per_frame = 6 + 3 * (NUM_JOINTS - 1);
    let mut values = Vec::with_capacity(motion.len() * channels_per_frame);
    for pose in &motion.poses {
        let pelvis = skeleton.rest_joints()[0] + pose.translation;
        values.extend(to_file(pelvis).to_array());
        for &j in &order {
            let q = pose.local_rotation(j).as_dquat().normalize();
            values.extend(euler_order(j).angles_f64(q).map(f64::to_degrees));
        }
    }
    Bvh::new(joints, 1.0 / f64::from(motion.fps), values)
        .map_err(|e| ExportError::Encode { format: Format::Bvh, message: e.to_string() })
}

/// Writes `motion` as BVH text (see the module docs for the layout and conventions).
pub fn write_bvh(motion: &SmplMotion, options: &BvhOptions) -> Result<Vec<u8>, ExportError> {
    Ok(smpl_bvh(motion, options.unit)?.to_bvh_string(options.decimals).into_bytes())
}

/// Why a BVH file is not an SMPL BVH as [`write_bvh`] writes them.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SmplBvhError {
    #[error(transparent)]
    Bvh(#[from] BvhError),
    #[error("expected the 24 SMPL joints, found {0} joints")]
    JointCount(usize),
    #[error("SMPL joint `{joint}` (parent `{parent}`): found {found}")]
    Topology { joint: &'static str, parent: &'static str, found: String },
    #[error("joint `{joint}` has channels {found}, expected {expected}")]
    Channels { joint: &'static str, found: String, expected: &'static str },
    #[error("the file has no frames")]
    NoFrames,
    #[error("the skeleton read back is invalid: {0}")]
    Skeleton(String),
    #[error("the frame time {0} s does not give a usable frame rate")]
    FrameRate(f64),
}

/// Reads back a BVH written by [`write_bvh`]: any file with exactly the 24 SMPL joints (by
/// name, in any file order) in SMPL's tree, three rotation channels per joint and three
/// position channels on the root, in any order.
///
/// The file does not store the pelvis's rest position (the root `OFFSET` is zero), so the
/// skeleton read back has its pelvis rest joint at the origin and `translation` equals the
/// pelvis's world position; joint positions are those of the file. Betas are not stored
/// (`None`); the start time is 0.
pub fn motion_from_smpl_bvh(bvh: &Bvh, unit: LengthUnit) -> Result<SmplMotion, SmplBvhError> {
    let joints = bvh.joints();
    if joints.len() != NUM_JOINTS {
        return Err(SmplBvhError::JointCount(joints.len()));
    }
    // File index of each SMPL joint.
    let mut in_file = [0usize; NUM_JOINTS];
    for (j, name) in JOINT_NAMES.iter().enumerate() {
        let expected_parent = usize::try_from(PARENTS[j]).ok().map(|p| JOINT_NAMES[p]);
        let topology = |found: String| SmplBvhError::Topology {
            joint: name,
            parent: expected_parent.unwrap_or("none (the root)"),
            found,
        };
        let index = bvh.joint_index(name).ok_or_else(|| topology("no such joint".into()))?;
        let parent = joints[index].parent.map(|p| joints[p].name.as_str());
        if parent != expected_parent {
            return Err(topology(format!("parent {}", parent.unwrap_or("none (the root)"))));
        }
        in_file[j] = index;
        let channels = &joints[index].channels;
        let rotations = channels.iter().filter(|c| c.is_rotation()).count();
        let positions = channels.len() - rotations;
        if rotations != 3 || positions != if j == 0 { 3 } else { 0 } {
            let found = channels.iter().map(|c| c.name()).collect::<Vec<_>>().join(" ");
            let expected = if j == 0 { "3 position + 3 rotation channels" } else { "3 rotation channels" };
            return Err(SmplBvhError::Channels { joint: name, found, expected });
        }
    }
    if bvh.num_frames() == 0 {
        return Err(SmplBvhError::NoFrames);
    }
    let fps = (1.0 / bvh.frame_time_s()) as f32;
    if !(fps.is_finite() && fps > 0.0) {
        return Err(SmplBvhError::FrameRate(bvh.frame_time_s()));
    }
    let to_metres = 1.0 / unit.per_metre();
    let mut rest = [Vec3::ZERO; NUM_JOINTS];
    for j in 1..NUM_JOINTS {
        rest[j] = rest[PARENTS[j] as usize] + (joints[in_file[j]].offset * to_metres).as_vec3();
    }
    let skeleton = SmplSkeleton::from_rest_joints(rest).map_err(|e| SmplBvhError::Skeleton(e.to_string()))?;
    let quat = |q: DQuat| -> Quat { q.normalize().as_quat() };
    let mut poses = Vec::with_capacity(bvh.num_frames());
    for frame in 0..bvh.num_frames() {
        let local = |j: usize| bvh.local_pose(in_file[j], frame).ok_or(SmplBvhError::NoFrames);
        let root = local(0)?;
        let mut body = [Quat::IDENTITY; NUM_BODY_JOINTS];
        for (i, q) in body.iter_mut().enumerate() {
            *q = quat(local(i + 1)?.rotation);
        }
        let pelvis: DVec3 = root.translation * to_metres;
        poses.push(SmplPose { root_orientation: quat(root.rotation), body, translation: pelvis.as_vec3() });
    }
    SmplMotion::new(fps, 0, skeleton, None, poses).map_err(|e| SmplBvhError::Skeleton(e.to_string()))
}

/// The axis SMPL joint `j`'s rotation order puts in the middle (its bone axis).
pub fn twist_axis(j: usize) -> Axis {
    euler_order(j).axes()[1]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_motion;

    fn max_joint_error(a: &SmplMotion, b: &SmplMotion) -> f32 {
        a.joint_positions()
            .iter()
            .zip(b.joint_positions())
            .flat_map(|(pa, pb)| pa.iter().zip(pb).map(|(x, y)| x.distance(y)).collect::<Vec<_>>())
            .fold(0.0, f32::max)
    }

    #[test]
    fn round_trips_through_the_reader_to_the_same_joint_positions() {
        for (unit, skeleton) in [
            (LengthUnit::Metres, SmplSkeleton::mean_shape()),
            (LengthUnit::Centimetres, SmplSkeleton::mean_shape().scaled(1.13)),
        ] {
            let motion = test_motion::motion(40, skeleton, None);
            let bytes = write_bvh(&motion, &BvhOptions { unit, decimals: 6 }).unwrap();
            let bvh = Bvh::parse_bytes(&bytes).unwrap();
            assert_eq!(bvh.num_frames(), 40);
            assert!((bvh.frame_time_s() - 1.0 / 30.0).abs() < 1e-12);
            let back = motion_from_smpl_bvh(&bvh, unit).unwrap();
            let err = max_joint_error(&motion, &back);
            assert!(err < 1e-4, "{unit:?}: max joint error {err} m");

            // The reader's own forward kinematics agrees with the project's.
            let fk = motion.joint_positions();
            for frame in [0, 1, 17, 39] {
                let world = bvh.world_poses(frame).unwrap();
                for j in 0..NUM_JOINTS {
                    let in_file = bvh.joint_index(JOINT_NAMES[j]).unwrap();
                    let p = (world[in_file].translation / unit.per_metre()).as_vec3();
                    assert!(p.distance(fk[frame][j]) < 1e-4, "frame {frame} joint {j}: {p} vs {}", fk[frame][j]);
                }
            }
        }
    }

    #[test]
    fn layout_matches_the_documented_conventions() {
        let motion = test_motion::motion(2, SmplSkeleton::mean_shape(), None);
        let text = String::from_utf8(write_bvh(&motion, &BvhOptions::default()).unwrap()).unwrap();
        assert!(text.starts_with("HIERARCHY\nROOT pelvis\n{\n\tOFFSET 0.000000 0.000000 0.000000\n"));
        assert!(text.contains("CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation"));
        assert!(text.contains("JOINT left_elbow\n\t\t\t\t\t\t{\n\t\t\t\t\t\t\tOFFSET 0.259700 -0.012800 -0.027500\n\t\t\t\t\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation"));
        assert!(text.contains("JOINT left_knee\n\t\t{\n\t\t\tOFFSET 0.034300 -0.375200 -0.004500\n\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation"));
        assert_eq!(text.matches("End Site").count(), 5);
        assert!(text.contains("Frames: 2\nFrame Time: 0.03333333333333333\n"));
        // Frame 0's first values are the pelvis world position, metres.
        let p = motion.skeleton.rest_joints()[0] + motion.poses[0].translation;
        let first_line = text.lines().find(|l| l.starts_with(char::is_numeric) || l.starts_with('-')).unwrap();
        let first: Vec<f64> = first_line.split(' ').take(3).map(|v| v.parse().unwrap()).collect();
        assert!((first[1] - f64::from(p.y)).abs() < 1e-6, "{first:?} vs {p}");
        // The middle (twist) axis is the dominant axis of the bone the joint turns (to its
        // first child; a leaf's own bone).
        let rest = motion.skeleton.rest_joints();
        for j in 1..NUM_JOINTS {
            let bone = match (j + 1..NUM_JOINTS).find(|&c| PARENTS[c] as usize == j) {
                Some(child) => rest[child] - rest[j],
                None => rest[j] - rest[PARENTS[j] as usize],
            };
            let along = bone.abs().to_array()[twist_axis(j).index()];
            assert!(along >= bone.abs().max_element() - 1e-6, "joint {j}: {bone}");
        }
    }

    #[test]
    fn rejects_files_that_are_not_smpl() {
        let motion = test_motion::motion(2, SmplSkeleton::mean_shape(), None);
        let text = String::from_utf8(write_bvh(&motion, &BvhOptions::default()).unwrap()).unwrap();
        let renamed = Bvh::parse(&text.replace("JOINT left_knee", "JOINT knee")).unwrap();
        assert!(matches!(
            motion_from_smpl_bvh(&renamed, LengthUnit::Metres),
            Err(SmplBvhError::Topology { joint: "left_knee", .. })
        ));
        let two_joints = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\nJOINT b\n{\n\
                          OFFSET 0 1 0\n}\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0\n";
        let bvh = Bvh::parse(two_joints).unwrap();
        assert_eq!(motion_from_smpl_bvh(&bvh, LengthUnit::Metres), Err(SmplBvhError::JointCount(2)));
    }
}
