//! CMU motion in BVH form, the other common way the CMU database circulates (the community
//! conversions, e.g. `cmuconvert`, name joints `Hips`, `LeftUpLeg`, `Spine1`, …).
//!
//! The file is read by the project's one BVH reader ([`egoexo_motion_io::bvh`]). Each BVH joint
//! of such a conversion sits where the ASF bone of the same role starts, so the joints are
//! matched to ASF bone names ([`CMU_BVH_JOINTS`]; a file may also use the ASF names
//! themselves) and the rest of the import is the ASF/AMC one: the same joint map, retarget,
//! corrupt-frame trimming and resampling. Interpolation between frames slerps each joint's
//! local rotation and lerps its translation.
//!
//! Frames and units: BVH joint frames are taken as aligned with the world in the rest pose
//! (all channels zero), Y up — true of the CMU conversions. Lengths are in whatever unit the
//! file uses; unless given, it is inferred from the rest skeleton's standing head height
//! ([`infer_metres_per_unit`]). The capture rate comes from `CMU_data.csv`, not from the
//! file's `Frame Time` (conversions wrote 120 fps even for the 60 Hz subjects).

use egoexo_core::glam::{DQuat, DVec3, Quat};
use egoexo_motion_io::bvh::{Bvh, BvhPose};

use crate::catalog::CatalogEntry;
use crate::import::{ImportError, ImportOptions, TrialImport, TrialSource, clips_from_source};
use crate::kinematics::CmuBoneTransforms;
use crate::retarget::{CmuJointMap, Retargeter, standing_head_height};

/// ASF bone name → joint name in the CMU BVH conversions. The joint is placed where the bone
/// starts.
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

/// Units a BVH file may plausibly use, metres per unit.
pub const CANDIDATE_UNITS: [(&str, f64); 5] = [
    ("metres", 1.0),
    ("centimetres", 0.01),
    ("millimetres", 0.001),
    ("inches", 0.0254),
    ("CMU units (1/0.45 inch)", 0.0254 / 0.45),
];

/// The BVH joint playing ASF bone `bone`: by its CMU-BVH name, else by the ASF name itself
/// (ASCII case-insensitive).
pub fn joint_for_bone(bvh: &Bvh, bone: &str) -> Option<usize> {
    let bvh_name = CMU_BVH_JOINTS.iter().find(|(asf, _)| *asf == bone).map(|(_, b)| *b);
    let find = |name: &str| bvh.joints().iter().position(|j| j.name.trim().eq_ignore_ascii_case(name));
    bvh_name.and_then(find).or_else(|| find(bone))
}

/// World transforms of the rest pose (every rotation the identity), file units.
fn rest_transforms(bvh: &Bvh) -> CmuBoneTransforms {
    let mut out = CmuBoneTransforms::default();
    let mut world: Vec<DVec3> = Vec::with_capacity(bvh.joints().len());
    for joint in bvh.joints() {
        let p = joint.parent.and_then(|p| world.get(p).copied()).unwrap_or(DVec3::ZERO) + joint.offset;
        world.push(p);
    }
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
    let bvh = Bvh::parse(text).map_err(|source| ImportError::Bvh { file: file.to_owned(), source })?;
    let retarget_error = |source| ImportError::Retarget { file: file.to_owned(), source };
    let lookup = |bone: &str| joint_for_bone(&bvh, bone);
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
    let frames = bvh.num_frames();
    let mut local_a: Vec<BvhPose> = Vec::with_capacity(joints.len());
    let mut local_b: Vec<BvhPose> = Vec::with_capacity(joints.len());
    let mut world: Vec<(DVec3, DQuat)> = Vec::with_capacity(joints.len());
    let source = TrialSource { subject, trial, file, entry };
    clips_from_source(&retargeter, &source, options, frames, |i, alpha, out| {
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
        out.ends.clone_from(&out.starts);
    })
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
