//! CMU motion in BVH form, the other common way the CMU database circulates (the community
//! conversions, e.g. `cmuconvert`, name joints `Hips`, `LeftUpLeg`, `Spine1`, …).
//!
//! The file is read by the project's one BVH reader ([`egoexo_motion_io::bvh`]). Each BVH joint
//! of such a conversion sits where the ASF bone of the same role starts, so the joints are
//! matched to ASF bone names by the naming the file's joints reveal ([`CmuBvhNaming`]:
//! cgspeed's MotionBuilder, 3dsMax and DAZ releases, or the ASF names themselves) and the
//! rest of the import is the ASF/AMC one: the same joint map, retarget, corrupt-frame
//! trimming and resampling. Two quirks of the cgspeed releases are undone first: leading
//! reference-pose rows ([`leading_reference_rows`]) are left out, and a collapsed thorax is
//! restored ([`restore_collapsed_thorax`]); both checked against the AMC of the same trial. Interpolation between frames slerps each joint's
//! local rotation and lerps its translation.
//!
//! Frames and units: BVH joint frames are taken as aligned with the world in the rest pose
//! (all channels zero), Y up — true of the CMU conversions. Lengths are in whatever unit the
//! file uses; unless given, it is inferred from the rest skeleton's standing head height
//! ([`infer_metres_per_unit`]). The capture rate comes from `CMU_data.csv`, not from the
//! file's `Frame Time` (conversions wrote 120 fps even for the 60 Hz subjects).

use egoexo_core::glam::{DQuat, DVec3, Quat};
use egoexo_motion_io::bvh::{Bvh, BvhError, BvhPose};

use crate::catalog::CatalogEntry;
use crate::import::{ImportError, ImportOptions, TrialImport, TrialSource, clips_from_source};
use crate::kinematics::CmuBoneTransforms;
use crate::retarget::{CmuJointMap, Retargeter, standing_head_height};

/// ASF bone name → joint name in cgspeed's "MotionBuilder-friendly" CMU conversions (and
/// `cmuconvert`'s). The joint is placed where the bone starts.
pub const CMU_BVH_JOINTS: [(&str, &str); 31] = [
    ("root", "Hips"),
    ("lhipjoint", "LHipJoint"),
    ("lfemur", "LeftUpLeg"),
    ("ltibia", "LeftLeg"),
    ("lfoot", "LeftFoot"),
    ("ltoes", "LeftToeBase"),
    ("rhipjoint", "RHipJoint"),
    ("rfemur", "RightUpLeg"),
    ("rtibia", "RightLeg"),
    ("rfoot", "RightFoot"),
    ("rtoes", "RightToeBase"),
    ("lowerback", "LowerBack"),
    ("upperback", "Spine"),
    ("thorax", "Spine1"),
    ("lowerneck", "Neck"),
    ("upperneck", "Neck1"),
    ("head", "Head"),
    ("lclavicle", "LeftShoulder"),
    ("lhumerus", "LeftArm"),
    ("lradius", "LeftForeArm"),
    ("lwrist", "LeftHand"),
    ("lhand", "LeftFingerBase"),
    ("lfingers", "LeftHandIndex1"),
    ("lthumb", "LThumb"),
    ("rclavicle", "RightShoulder"),
    ("rhumerus", "RightArm"),
    ("rradius", "RightForeArm"),
    ("rwrist", "RightHand"),
    ("rhand", "RightFingerBase"),
    ("rfingers", "RightHandIndex1"),
    ("rthumb", "RThumb"),
];

/// ASF bone name → joint name in cgspeed's "3dsMax-friendly" release (same skeleton as the
/// MotionBuilder one, other names; its `LHipJoint`/`RHipJoint` have zero offsets, their
/// children carry the hip vector).
pub const CGSPEED_MAX_JOINTS: [(&str, &str); 31] = [
    ("root", "Hips"),
    ("lhipjoint", "LHipJoint"),
    ("lfemur", "LeftHip"),
    ("ltibia", "LeftKnee"),
    ("lfoot", "LeftAnkle"),
    ("ltoes", "LeftToe"),
    ("rhipjoint", "RHipJoint"),
    ("rfemur", "RightHip"),
    ("rtibia", "RightKnee"),
    ("rfoot", "RightAnkle"),
    ("rtoes", "RightToe"),
    ("lowerback", "lowerback"),
    ("upperback", "Chest"),
    ("thorax", "Chest2"),
    ("lowerneck", "lowerneck"),
    ("upperneck", "Neck"),
    ("head", "Head"),
    ("lclavicle", "LeftCollar"),
    ("lhumerus", "LeftShoulder"),
    ("lradius", "LeftElbow"),
    ("lwrist", "LeftWrist"),
    ("lhand", "lhand"),
    ("lfingers", "LFingers"),
    ("lthumb", "LThumb"),
    ("rclavicle", "RightCollar"),
    ("rhumerus", "RightShoulder"),
    ("rradius", "RightElbow"),
    ("rwrist", "RightWrist"),
    ("rhand", "rhand"),
    ("rfingers", "RFingers"),
    ("rthumb", "RThumb"),
];

/// ASF bone name → joint name in cgspeed's "DAZ-friendly" release: one standard DAZ figure
/// (43 joints, root `hip`), not the subject's skeleton. It has no toe joint and one neck
/// joint: the toes are the foot's end site (`"lFoot end"`, see [`END_SITE_SUFFIX`]) and both
/// CMU neck bones start at `neck`; the CMU hand bone (wrist → knuckles) starts at the middle
/// finger's first joint.
pub const CGSPEED_DAZ_JOINTS: [(&str, &str); 27] = [
    ("root", "hip"),
    ("lhipjoint", "lButtock"),
    ("lfemur", "lThigh"),
    ("ltibia", "lShin"),
    ("lfoot", "lFoot"),
    ("ltoes", "lFoot end"),
    ("rhipjoint", "rButtock"),
    ("rfemur", "rThigh"),
    ("rtibia", "rShin"),
    ("rfoot", "rFoot"),
    ("rtoes", "rFoot end"),
    ("upperback", "abdomen"),
    ("thorax", "chest"),
    ("lowerneck", "neck"),
    ("upperneck", "neck"),
    ("head", "head"),
    ("lclavicle", "lCollar"),
    ("lhumerus", "lShldr"),
    ("lradius", "lForeArm"),
    ("lwrist", "lHand"),
    ("lhand", "lMid1"),
    ("rclavicle", "rCollar"),
    ("rhumerus", "rShldr"),
    ("rradius", "rForeArm"),
    ("rwrist", "rHand"),
    ("rhand", "rMid1"),
    ("lthumb", "lThumb1"),
];

/// A joint's end site is addressed as `"{joint name}{END_SITE_SUFFIX}"`; its bone index
/// follows every joint's (see [`joint_for_bone`]).
pub const END_SITE_SUFFIX: &str = " end";

/// Which family of CMU BVH conversion a file is, by its joint names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CmuBvhNaming {
    /// cgspeed "MotionBuilder-friendly" (root `Hips`, `LeftUpLeg`, `Spine1`, …), per-subject
    /// bone lengths; also `cmuconvert`.
    CgspeedMotionBuilder,
    /// cgspeed "3dsMax-friendly" (root `Hips`, `LeftHip`, `Chest2`, …), per-subject bone
    /// lengths.
    Cgspeed3dsMax,
    /// cgspeed "DAZ-friendly" (root `hip`, `lThigh`, `abdomen`, …): one standard figure.
    CgspeedDaz,
    /// The ASF bone names themselves.
    AsfNames,
}

impl CmuBvhNaming {
    /// Every naming, in the order [`CmuBvhNaming::detect`] tries them.
    pub const ALL: [CmuBvhNaming; 4] = [
        CmuBvhNaming::CgspeedMotionBuilder,
        CmuBvhNaming::Cgspeed3dsMax,
        CmuBvhNaming::CgspeedDaz,
        CmuBvhNaming::AsfNames,
    ];

    /// ASF bone → BVH joint names (empty for [`CmuBvhNaming::AsfNames`]).
    pub fn table(self) -> &'static [(&'static str, &'static str)] {
        match self {
            CmuBvhNaming::CgspeedMotionBuilder => &CMU_BVH_JOINTS,
            CmuBvhNaming::Cgspeed3dsMax => &CGSPEED_MAX_JOINTS,
            CmuBvhNaming::CgspeedDaz => &CGSPEED_DAZ_JOINTS,
            CmuBvhNaming::AsfNames => &[],
        }
    }

    /// How the data source is named in libraries and reports
    /// ([`crate::library::ClipInfo::source_format`]).
    pub fn source_format(self) -> &'static str {
        match self {
            CmuBvhNaming::CgspeedMotionBuilder => "BVH (cgspeed MotionBuilder)",
            CmuBvhNaming::Cgspeed3dsMax => "BVH (cgspeed 3dsMax)",
            CmuBvhNaming::CgspeedDaz => "BVH (cgspeed DAZ, standard figure)",
            CmuBvhNaming::AsfNames => "BVH (ASF joint names)",
        }
    }

    /// The bone index (see [`joint_for_bone`]) playing ASF bone `bone` under this naming.
    pub fn bone_index(self, bvh: &Bvh, bone: &str) -> Option<usize> {
        let name = match self {
            CmuBvhNaming::AsfNames => bone,
            _ => self.table().iter().find(|(asf, _)| *asf == bone).map(|(_, b)| *b)?,
        };
        joint_for_bone(bvh, name)
    }

    /// The first naming under which every bone the CMU→SMPL mapping needs is present.
    pub fn detect(bvh: &Bvh) -> Option<CmuBvhNaming> {
        Self::ALL.into_iter().find(|naming| CmuJointMap::new(|bone| naming.bone_index(bvh, bone)).is_ok())
    }
}

/// Bone index of the BVH joint named `name` (ASCII case-insensitive, surrounding spaces
/// ignored), or — for `"{joint}{END_SITE_SUFFIX}"` — of that joint's end site: end sites
/// are numbered after all joints, in joint order.
pub fn joint_for_bone(bvh: &Bvh, name: &str) -> Option<usize> {
    let find = |name: &str| bvh.joints().iter().position(|j| j.name.trim().eq_ignore_ascii_case(name));
    if let Some(j) = find(name) {
        return Some(j);
    }
    let joint = find(name.strip_suffix(END_SITE_SUFFIX)?)?;
    bvh.joints()[joint].end_site?;
    let before = bvh.joints()[..joint].iter().filter(|j| j.end_site.is_some()).count();
    Some(bvh.joints().len() + before)
}

/// How many leading rows hold a reference pose rather than motion: rows whose rotation
/// channels are all whole numbers of degrees (hand-set poses; captured motion has
/// fractions), before the first row that is not. cgspeed's MotionBuilder release prepends a
/// T-pose to every trial (07_12 also a zero row after it). 0 when no row has fractions.
pub fn leading_reference_rows(bvh: &Bvh) -> usize {
    let rotations_whole = |frame: usize| {
        bvh.joints().iter().enumerate().all(|(j, joint)| {
            let values = bvh.joint_values(j, frame).unwrap_or(&[]);
            joint.channels.iter().zip(values).all(|(c, v)| !c.is_rotation() || (v - v.round()).abs() < 1e-6)
        })
    };
    (0..bvh.num_frames()).position(|f| !rotations_whole(f)).unwrap_or_default()
}

/// Units a BVH file may plausibly use, metres per unit.
pub const CANDIDATE_UNITS: [(&str, f64); 5] = [
    ("metres", 1.0),
    ("centimetres", 0.01),
    ("millimetres", 0.001),
    ("inches", 0.0254),
    ("CMU units (1/0.45 inch)", 0.0254 / 0.45),
];

/// cgspeed's MotionBuilder and 3dsMax releases drop the CMU thorax bone's length: the neck
/// and both collars start where the thorax starts (`Spine1`/`Chest2` with zero offsets), so
/// the head sits ~11 cm low on the hips and the subject comes out ~8 % short. CMU subjects'
/// thorax is as long as their upper back (ratio 1.00–1.04 over the 16 ASFs in
/// `shared/data`) and points straight up in the rest pose (within 8°), so the lost length is
/// restored as the thorax joint's own offset length along its +Y. Returns the length
/// restored (file units) when the file had the collapse, `None` otherwise.
pub fn restore_collapsed_thorax(bvh: Bvh, naming: CmuBvhNaming) -> Result<(Bvh, Option<f64>), BvhError> {
    let (Some(thorax), Some(neck)) = (naming.bone_index(&bvh, "thorax"), naming.bone_index(&bvh, "lowerneck")) else {
        return Ok((bvh, None));
    };
    let joints = bvh.joints();
    let collapsed = neck < joints.len() && joints[neck].parent == Some(thorax) && joints[neck].offset.length() < 1e-9;
    if !collapsed {
        return Ok((bvh, None));
    }
    let length = joints[thorax].offset.length();
    if length <= 0.0 {
        return Ok((bvh, None));
    }
    let (mut joints, frame_time_s, values) = bvh.into_parts();
    for joint in joints.iter_mut().filter(|j| j.parent == Some(thorax) && j.offset.length() < 1e-9) {
        joint.offset = DVec3::new(0.0, length, 0.0);
    }
    Ok((Bvh::new(joints, frame_time_s, values)?, Some(length)))
}

/// World transforms of the rest pose (every rotation the identity), file units, indexed as
/// [`joint_for_bone`] numbers bones (joints, then end sites).
fn rest_transforms(bvh: &Bvh) -> CmuBoneTransforms {
    let mut out = CmuBoneTransforms::default();
    let mut world: Vec<DVec3> = Vec::with_capacity(bvh.joints().len());
    for joint in bvh.joints() {
        let p = joint.parent.and_then(|p| world.get(p).copied()).unwrap_or(DVec3::ZERO) + joint.offset;
        world.push(p);
    }
    let end_sites: Vec<DVec3> =
        bvh.joints().iter().zip(&world).filter_map(|(joint, p)| joint.end_site.map(|e| *p + e)).collect();
    world.extend(end_sites);
    out.starts = world.iter().map(|p| p.as_vec3()).collect();
    out.ends = out.starts.clone();
    out.rotations = vec![Quat::IDENTITY; world.len()];
    out
}

/// Metres per file unit for a skeleton whose standing head height is `head_height` file
/// units: the candidate unit that makes it a human 1.0–2.2 m, nearest 1.5 m.
pub fn infer_metres_per_unit(head_height: f64) -> Option<(&'static str, f64)> {
    CANDIDATE_UNITS
        .iter()
        .map(|&(name, unit)| (name, unit, head_height * unit))
        .filter(|&(_, _, h)| (1.0..=2.2).contains(&h))
        .min_by(|a, b| (a.2 / 1.5).ln().abs().total_cmp(&(b.2 / 1.5).ln().abs()))
        .map(|(name, unit, _)| (name, unit))
}

/// Imports one CMU trial stored as BVH (`file` names it in errors; `entry` gives its
/// description and true capture rate). [`ImportOptions::bvh_metres_per_unit`] overrides the
/// inferred length unit.
pub fn import_bvh_trial(
    text: &str,
    file: &str,
    subject: u32,
    trial: u32,
    entry: &CatalogEntry,
    options: &ImportOptions,
) -> Result<TrialImport, ImportError> {
    let bvh_error = |source| ImportError::Bvh { file: file.to_owned(), source };
    let bvh = Bvh::parse(text).map_err(bvh_error)?;
    let retarget_error = |source| ImportError::Retarget { file: file.to_owned(), source };
    // A file of no known naming fails on the first missing bone under the CMU names.
    let naming = CmuBvhNaming::detect(&bvh).unwrap_or(CmuBvhNaming::CgspeedMotionBuilder);
    let (bvh, restored_thorax) = restore_collapsed_thorax(bvh, naming).map_err(bvh_error)?;
    let lookup = |bone: &str| naming.bone_index(&bvh, bone);
    let rest_units = rest_transforms(&bvh);
    let unit = match options.bvh_metres_per_unit {
        Some(u) if u.is_finite() && u > 0.0 => u,
        Some(u) => return Err(ImportError::BvhUnit { file: file.to_owned(), detail: format!("{u} metres per unit") }),
        None => {
            let map = CmuJointMap::new(lookup).map_err(retarget_error)?;
            let h = f64::from(standing_head_height(&map.positions(&rest_units)));
            infer_metres_per_unit(h).map(|(_, u)| u).ok_or_else(|| ImportError::BvhUnit {
                file: file.to_owned(),
                detail: format!("a standing head height of {h:.3} file units fits no unit (m, cm, mm, in, CMU)"),
            })?
        }
    };
    let mut rest = rest_units;
    for p in rest.starts.iter_mut().chain(rest.ends.iter_mut()) {
        *p = (p.as_dvec3() * unit).as_vec3();
    }
    let retargeter = Retargeter::from_rest(lookup, &rest).map_err(retarget_error)?;

    let joints = bvh.joints();
    // Skip a prepended reference pose: it is not motion, and the jump out of it would be
    // trimmed as a glitch anyway.
    let first_frame = leading_reference_rows(&bvh);
    let frames = bvh.num_frames() - first_frame;
    let mut local_a: Vec<BvhPose> = Vec::with_capacity(joints.len());
    let mut local_b: Vec<BvhPose> = Vec::with_capacity(joints.len());
    let mut world: Vec<(DVec3, DQuat)> = Vec::with_capacity(joints.len());
    let source =
        TrialSource { subject, trial, file, entry, format: naming.source_format(), first_source_frame: first_frame };
    let mut import = clips_from_source(&retargeter, &source, options, frames, |i, alpha, out| {
        let i = i + first_frame;
        local_a.clear();
        local_b.clear();
        world.clear();
        let identity = BvhPose { translation: DVec3::ZERO, rotation: DQuat::IDENTITY };
        for j in 0..joints.len() {
            local_a.push(bvh.local_pose(j, i).unwrap_or(identity));
            if alpha > 0.0 {
                local_b.push(bvh.local_pose(j, i + 1).unwrap_or(identity));
            }
        }
        out.starts.clear();
        out.rotations.clear();
        for (j, joint) in joints.iter().enumerate() {
            let local = if alpha > 0.0 {
                let (a, b) = (local_a[j], local_b[j]);
                let b_rot = if a.rotation.dot(b.rotation) < 0.0 { -b.rotation } else { b.rotation };
                BvhPose {
                    translation: a.translation.lerp(b.translation, f64::from(alpha)),
                    rotation: a.rotation.slerp(b_rot, f64::from(alpha)).normalize(),
                }
            } else {
                local_a[j]
            };
            let pose = match joint.parent.and_then(|p| world.get(p)) {
                None => (local.translation, local.rotation),
                Some(&(pt, pr)) => (pt + pr * local.translation, (pr * local.rotation).normalize()),
            };
            world.push(pose);
            out.starts.push((pose.0 * unit).as_vec3());
            out.rotations.push(pose.1.as_quat());
        }
        // End sites, after every joint (the numbering of `joint_for_bone`).
        for (joint, &(p, r)) in joints.iter().zip(&world) {
            if let Some(end) = joint.end_site {
                out.starts.push(((p + r * end) * unit).as_vec3());
                out.rotations.push(r.as_quat());
            }
        }
        out.ends.clone_from(&out.starts);
    })?;
    import.reference_rows_skipped = first_frame;
    import.restored_thorax_m = restored_thorax.map(|l| (l * unit) as f32);
    Ok(import)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_are_inferred_from_a_human_head_height() {
        assert_eq!(infer_metres_per_unit(1.55).unwrap().0, "metres");
        assert_eq!(infer_metres_per_unit(155.0).unwrap().0, "centimetres");
        assert_eq!(infer_metres_per_unit(1550.0).unwrap().0, "millimetres");
        assert_eq!(infer_metres_per_unit(60.0).unwrap().0, "inches");
        assert_eq!(infer_metres_per_unit(26.6).unwrap().0, "CMU units (1/0.45 inch)");
        assert_eq!(infer_metres_per_unit(0.1), None);
        assert_eq!(infer_metres_per_unit(f64::NAN), None);
    }
}
