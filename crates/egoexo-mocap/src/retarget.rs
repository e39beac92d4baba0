//! Retargeting CMU skeleton motion onto the SMPL mean-shape skeleton.
//!
//! Frames and units: metres, the capture's world frame (CMU: Y up, floor near `y = 0`).
//! The CMU rest pose faces +Z with the subject's left on +X — the same as SMPL's rest pose —
//! so no facing rotation is applied: a retargeted pose's root orientation maps SMPL's body
//! frame into the capture world, and the body faces wherever the subject faced in the
//! studio (`root_orientation · +Z`).
//!
//! Method, per frame:
//! 1. CMU forward kinematics gives bone starts; the 24 SMPL joint *targets* are the mapped
//!    positions of [`CMU_TO_SMPL`] (the mapping of `shared/data/cmu/README.md`).
//! 2. The SMPL skeleton is the mean shape scaled uniformly so its head height matches the
//!    subject's standing head height measured on the ASF ([`standing_head_height`]).
//! 3. Initial fit down the kinematic chain, pelvis on the CMU root: a joint with one child
//!    gets the CMU segment's world rotation (its twist), swung by the smallest rotation that
//!    points the SMPL bone from the joint's *fitted* position at the child's target; the
//!    pelvis and spine3 (three children each) get the least-squares rotation (Horn's
//!    quaternion method) of their child bones onto the targets; the feet and head (no
//!    child) take their CMU segment's rotation. CMU's rest legs splay about 20° while
//!    SMPL's hang straight, so rest directions are aligned once per skeleton and Euler
//!    angles are never copied.
//! 4. Refinement ([`REFINE_ITERATIONS`] rounds): the translation moves by the mean residual
//!    over all joints, then each body joint's rotation takes a damped Gauss–Newton step
//!    that moves its whole subtree onto the targets. The mean shape's proportions differ
//!    from a CMU subject's (its torso is longer, its thighs and forearms shorter), so no pose
//!    puts every joint on its target; this spreads the mismatch over the body instead of
//!    piling it on the limb ends. Measured on the shared subset: mean error 3.0 cm with the
//!    pelvis pinned to the CMU root and the initial fit only, 2.6 cm after refinement. The
//!    pelvis orientation (pelvis–hips–spine frame) and the head and feet orientations (the
//!    CMU segments') are not changed by refinement, so the head-mounted device follows the
//!    subject's real head.
//!
//! The retarget error of a frame is the distance between each target and the fitted SMPL
//! joint (forward kinematics of the output pose), over all 24 joints.

use egoexo_core::glam::{Mat3, Quat, Vec3};
use egoexo_core::skeleton::{JOINT_NAMES, NUM_BODY_JOINTS, NUM_JOINTS, PARENTS, SkeletonError, SmplPose, SmplSkeleton};
use thiserror::Error;

use crate::kinematics::{CmuBoneTransforms, CmuSkeleton};

/// Each SMPL joint as a weighted blend of CMU bone *starts* (where a bone begins: the end
/// of its parent). `root` is the root's position.
pub const CMU_TO_SMPL: [&[(&str, f32)]; NUM_JOINTS] = [
    &[("root", 1.0)],                           // pelvis
    &[("lfemur", 1.0)],                         // left_hip
    &[("rfemur", 1.0)],                         // right_hip
    &[("upperback", 1.0)],                      // spine1
    &[("ltibia", 1.0)],                         // left_knee
    &[("rtibia", 1.0)],                         // right_knee
    &[("thorax", 1.0)],                         // spine2
    &[("lfoot", 1.0)],                          // left_ankle
    &[("rfoot", 1.0)],                          // right_ankle
    &[("thorax", 0.6), ("lowerneck", 0.4)],     // spine3
    &[("ltoes", 1.0)],                          // left_foot
    &[("rtoes", 1.0)],                          // right_foot
    &[("upperneck", 1.0)],                      // neck
    &[("lclavicle", 0.65), ("lhumerus", 0.35)], // left_collar
    &[("rclavicle", 0.65), ("rhumerus", 0.35)], // right_collar
    &[("head", 1.0)],                           // head
    &[("lhumerus", 1.0)],                       // left_shoulder
    &[("rhumerus", 1.0)],                       // right_shoulder
    &[("lradius", 1.0)],                        // left_elbow
    &[("rradius", 1.0)],                        // right_elbow
    &[("lwrist", 1.0)],                         // left_wrist
    &[("rwrist", 1.0)],                         // right_wrist
    &[("lhand", 1.0)],                          // left_hand
    &[("rhand", 1.0)],                          // right_hand
];

/// The CMU segment whose world rotation gives each SMPL joint's twist (the segment that
/// spans the SMPL bone from the joint to its child, or the joint's own segment for the
/// feet and head; for the pelvis and spine3, fitted from positions, the fallback when the
/// positions are degenerate). `None`: identity (hands).
const TWIST_SEGMENT: [Option<&str>; NUM_JOINTS] = [
    Some("root"),
    Some("lfemur"),
    Some("rfemur"),
    Some("upperback"),
    Some("ltibia"),
    Some("rtibia"),
    Some("thorax"),
    Some("lfoot"),
    Some("rfoot"),
    Some("thorax"),
    Some("ltoes"),
    Some("rtoes"),
    Some("upperneck"),
    Some("lclavicle"),
    Some("rclavicle"),
    Some("head"),
    Some("lhumerus"),
    Some("rhumerus"),
    Some("lradius"),
    Some("rradius"),
    Some("lwrist"),
    Some("rwrist"),
    None,
    None,
];

/// How a joint's global rotation is found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Fit {
    /// Least squares over these three children.
    ThreeChildren([usize; 3]),
    /// Twist from the CMU segment, swung to aim at this child.
    Aim(usize),
    /// The CMU segment's rotation (no child to aim at).
    Segment,
    /// Same as the parent (SMPL hands: not part of the 21 body rotations).
    Parent,
}

const FIT: [Fit; NUM_JOINTS] = [
    Fit::ThreeChildren([1, 2, 3]),
    Fit::Aim(4),
    Fit::Aim(5),
    Fit::Aim(6),
    Fit::Aim(7),
    Fit::Aim(8),
    Fit::Aim(9),
    Fit::Aim(10),
    Fit::Aim(11),
    Fit::ThreeChildren([12, 13, 14]),
    Fit::Segment,
    Fit::Segment,
    Fit::Aim(15),
    Fit::Aim(16),
    Fit::Aim(17),
    Fit::Segment,
    Fit::Aim(18),
    Fit::Aim(19),
    Fit::Aim(20),
    Fit::Aim(21),
    Fit::Aim(22),
    Fit::Aim(23),
    Fit::Parent,
    Fit::Parent,
];

/// Errors setting up a retarget.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RetargetError {
    #[error("the skeleton has no bone `{bone}`, which the CMU→SMPL mapping needs for `{joint}`")]
    MissingBone { bone: &'static str, joint: &'static str },
    #[error("the subject's standing head height is not usable: {0}")]
    HeadHeight(#[from] SkeletonError),
}

/// Mapped SMPL joint positions (metres) from CMU bone transforms.
#[derive(Clone, Debug, PartialEq)]
pub struct CmuJointMap {
    terms: [Vec<(usize, f32)>; NUM_JOINTS],
}

impl CmuJointMap {
    /// Resolves [`CMU_TO_SMPL`] with `bone_index`, which finds a CMU (ASF) bone by name in
    /// the source's bone transforms.
    pub fn new(bone_index: impl Fn(&str) -> Option<usize>) -> Result<Self, RetargetError> {
        let mut terms: [Vec<(usize, f32)>; NUM_JOINTS] = Default::default();
        for (j, sources) in CMU_TO_SMPL.iter().enumerate() {
            for &(bone, weight) in *sources {
                let index = bone_index(bone).ok_or(RetargetError::MissingBone { bone, joint: JOINT_NAMES[j] })?;
                terms[j].push((index, weight));
            }
        }
        Ok(Self { terms })
    }

    /// The map for an ASF skeleton.
    pub fn for_skeleton(skeleton: &CmuSkeleton) -> Result<Self, RetargetError> {
        Self::new(|name| skeleton.bone_index(name))
    }

    /// The 24 mapped positions, metres, world frame.
    pub fn positions(&self, fk: &CmuBoneTransforms) -> [Vec3; NUM_JOINTS] {
        std::array::from_fn(|j| {
            self.terms[j].iter().map(|&(b, w)| fk.starts.get(b).copied().unwrap_or(Vec3::NAN) * w).sum()
        })
    }
}

/// The subject's standing head height, metres, from the mapped joints of the rest pose: the
/// head joint above the lowest ankle/foot joint once each leg is swung about its hip to hang
/// straight down (CMU's rest legs splay about 20°; SMPL's hang straight). Directly
/// comparable to [`SmplSkeleton::head_height`].
pub fn standing_head_height(rest_targets: &[Vec3; NUM_JOINTS]) -> f32 {
    let mut lowest = f32::INFINITY;
    for (hip, knee, ankle, foot) in [(1, 4, 7, 10), (2, 5, 8, 11)] {
        let p = rest_targets;
        let swing = match (p[knee] - p[hip]).try_normalize() {
            Some(thigh) => Quat::from_rotation_arc(thigh, Vec3::NEG_Y),
            None => Quat::IDENTITY,
        };
        for j in [ankle, foot] {
            lowest = lowest.min((p[hip] + swing * (p[j] - p[hip])).y);
        }
    }
    rest_targets[15].y - lowest
}

/// Retargets frames of one CMU subject onto the scaled SMPL mean skeleton.
#[derive(Clone, Debug)]
pub struct Retargeter {
    map: CmuJointMap,
    twist_segment: [Option<usize>; NUM_JOINTS],
    smpl: SmplSkeleton,
    /// Per joint: rotation taking the SMPL rest bone direction (to the aimed child) onto the
    /// CMU rest direction of the same bone, so `W_segment · rest_alignment` is a twist
    /// candidate in SMPL terms.
    rest_alignment: [Quat; NUM_JOINTS],
    head_height: f32,
    scale: f32,
    /// Per SMPL joint, every joint below it.
    descendants: [Vec<usize>; NUM_JOINTS],
}

/// One retargeted frame.
#[derive(Clone, Debug, PartialEq)]
pub struct RetargetedFrame {
    /// The SMPL pose (world frame, metres).
    pub pose: SmplPose,
    /// Mapped CMU joint positions, metres.
    pub targets: [Vec3; NUM_JOINTS],
    /// Distance from each target to the fitted SMPL joint, metres.
    pub errors: [f32; NUM_JOINTS],
}

impl Retargeter {
    /// Sets up retargeting for a subject's ASF skeleton.
    pub fn new(skeleton: &CmuSkeleton) -> Result<Self, RetargetError> {
        let rest = skeleton.forward_kinematics(&skeleton.rest_pose());
        Self::from_rest(|name| skeleton.bone_index(name), &rest)
    }

    /// Sets up retargeting for any source that provides CMU (ASF-named) bones: `bone_index`
    /// finds a bone by its ASF name in the source's [`CmuBoneTransforms`], and `rest` is the
    /// source's rest pose (every rotation the identity; Y up). Frames passed to
    /// [`Retargeter::retarget`] must then give bone starts in metres and rotations as
    /// `W_b` = rest → current, in the same indexing.
    pub fn from_rest(
        bone_index: impl Fn(&str) -> Option<usize>,
        rest: &CmuBoneTransforms,
    ) -> Result<Self, RetargetError> {
        let map = CmuJointMap::new(&bone_index)?;
        let mut twist_segment = [None; NUM_JOINTS];
        for (j, seg) in TWIST_SEGMENT.iter().enumerate() {
            if let Some(bone) = seg {
                let index = bone_index(bone).ok_or(RetargetError::MissingBone { bone, joint: JOINT_NAMES[j] })?;
                twist_segment[j] = Some(index);
            }
        }
        let rest_targets = map.positions(rest);
        let head_height = standing_head_height(&rest_targets);
        let mean = SmplSkeleton::mean_shape();
        // Validates the height; the skeleton is then built from the stored scale exactly as
        // a library loader rebuilds it (`mean_shape().scaled(scale)`).
        mean.scaled_to_head_height(head_height)?;
        let scale = head_height / mean.head_height();
        let smpl = mean.scaled(scale);

        // The source's rest facing about the vertical: SMPL's left (+X) onto the source's
        // left-hip direction. The identity for CMU's ASF (its rest pose faces +Z too).
        let left = rest_targets[1] - rest_targets[2];
        let facing = match Vec3::new(left.x, 0.0, left.z).try_normalize() {
            Some(l) => Quat::from_rotation_arc(Vec3::X, l),
            None => Quat::IDENTITY,
        };
        let rest = smpl.rest_joints();
        let mut rest_alignment = [facing; NUM_JOINTS];
        for j in 0..NUM_JOINTS {
            if let Fit::Aim(c) = FIT[j] {
                let smpl_dir = (facing * (rest[c] - rest[j])).normalize_or_zero();
                let cmu_dir = (rest_targets[c] - rest_targets[j]).normalize_or_zero();
                if smpl_dir != Vec3::ZERO && cmu_dir != Vec3::ZERO {
                    rest_alignment[j] = Quat::from_rotation_arc(smpl_dir, cmu_dir) * facing;
                }
            }
        }
        let descendants = std::array::from_fn(|j| {
            (j + 1..NUM_JOINTS)
                .filter(|&d| {
                    let mut a = PARENTS[d];
                    while a >= 0 && a as usize > j {
                        a = PARENTS[a as usize];
                    }
                    a == j as i8
                })
                .collect()
        });
        Ok(Self { map, twist_segment, smpl, rest_alignment, head_height, scale, descendants })
    }

    /// The scaled SMPL skeleton the poses drive.
    pub fn smpl_skeleton(&self) -> &SmplSkeleton {
        &self.smpl
    }

    /// The subject's standing head height, metres ([`standing_head_height`]).
    pub fn head_height(&self) -> f32 {
        self.head_height
    }

    /// Uniform scale applied to the SMPL mean shape.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// The joint map in use.
    pub fn joint_map(&self) -> &CmuJointMap {
        &self.map
    }

    /// Retargets one frame of CMU bone transforms.
    pub fn retarget(&self, fk: &CmuBoneTransforms) -> RetargetedFrame {
        let targets = self.map.positions(fk);
        let mut pelvis = targets[0];
        let mut global = self.fit_rotations(fk, &targets, pelvis);
        for _ in 0..REFINE_ITERATIONS {
            let fitted = self.positions_from_globals(&global, pelvis);
            let shift: Vec3 = (0..NUM_JOINTS).map(|j| targets[j] - fitted[j]).sum::<Vec3>() / NUM_JOINTS as f32;
            pelvis += shift;
            self.refine(&mut global, pelvis, &targets);
        }
        let pose = self.pose_from_globals(&global, pelvis);
        let fitted = self.smpl.forward_kinematics(&pose).positions;
        let errors = std::array::from_fn(|j| fitted[j].distance(targets[j]));
        RetargetedFrame { pose, targets, errors }
    }

    /// SMPL joint positions for global rotations and a pelvis position.
    fn positions_from_globals(&self, global: &[Quat; NUM_JOINTS], pelvis: Vec3) -> [Vec3; NUM_JOINTS] {
        let rest = self.smpl.rest_joints();
        let mut p = [Vec3::ZERO; NUM_JOINTS];
        p[0] = pelvis;
        for j in 1..NUM_JOINTS {
            let parent = PARENTS[j] as usize;
            p[j] = p[parent] + global[parent] * (rest[j] - rest[parent]);
        }
        p
    }

    /// One sweep from the spine to the limb ends: each body joint's rotation is corrected by
    /// a Gauss–Newton step of the rotation (about the joint) that best moves all its
    /// descendants onto their targets, which spreads bone-length mismatches along a chain
    /// instead of piling them on its end. Damping towards no correction keeps the CMU twist
    /// where the descendants do not determine it (a straight limb). The feet and head keep
    /// their CMU segment orientation.
    fn refine(&self, global: &mut [Quat; NUM_JOINTS], pelvis: Vec3, targets: &[Vec3; NUM_JOINTS]) {
        let mut p = self.positions_from_globals(global, pelvis);
        for j in 1..=NUM_BODY_JOINTS {
            let descendants = &self.descendants[j];
            if descendants.is_empty() || FIT[j] == Fit::Segment {
                continue;
            }
            // Minimise Σ |ω × a + a − b|² + μ|ω|² over the small rotation ω:
            // (Σ (|a|² I − a aᵀ) + μ I) ω = Σ a × b.
            let mut h = Mat3::from_diagonal(Vec3::splat(REFINE_DAMPING_M2));
            let mut g = Vec3::ZERO;
            for &d in descendants {
                let a = p[d] - p[j];
                let b = targets[d] - p[j];
                h += Mat3::from_diagonal(Vec3::splat(a.length_squared())) - outer(a, a);
                g += a.cross(b);
            }
            let omega = h.inverse() * g;
            if !omega.is_finite() {
                continue;
            }
            let delta = Quat::from_scaled_axis(omega);
            for d in std::iter::once(j).chain(descendants.iter().copied()) {
                if FIT[d] != Fit::Segment {
                    global[d] = (delta * global[d]).normalize();
                }
            }
            for &d in descendants {
                p[d] = p[j] + delta * (p[d] - p[j]);
            }
        }
    }

    fn pose_from_globals(&self, global: &[Quat; NUM_JOINTS], pelvis: Vec3) -> SmplPose {
        let mut body = [Quat::IDENTITY; NUM_BODY_JOINTS];
        for (k, slot) in body.iter_mut().enumerate() {
            let j = k + 1;
            *slot = canonical(global[PARENTS[j] as usize].conjugate() * global[j]);
        }
        SmplPose { root_orientation: canonical(global[0]), body, translation: pelvis - self.smpl.rest_joints()[0] }
    }

    /// Global joint rotations fitted down the chain with the pelvis at `pelvis`.
    fn fit_rotations(&self, fk: &CmuBoneTransforms, targets: &[Vec3; NUM_JOINTS], pelvis: Vec3) -> [Quat; NUM_JOINTS] {
        let rest = self.smpl.rest_joints();
        let mut global = [Quat::IDENTITY; NUM_JOINTS];
        let mut position = [Vec3::ZERO; NUM_JOINTS];
        position[0] = pelvis;
        for j in 0..NUM_JOINTS {
            if j > 0 {
                let parent = PARENTS[j] as usize;
                position[j] = position[parent] + global[parent] * (rest[j] - rest[parent]);
            }
            let segment = self.twist_segment[j].map(|b| fk.rotations[b]);
            global[j] = match FIT[j] {
                Fit::ThreeChildren(children) => {
                    let pairs = children.map(|c| (rest[c] - rest[j], targets[c] - position[j]));
                    best_rotation(&pairs).or(segment.map(|w| w * self.rest_alignment[j])).unwrap_or(Quat::IDENTITY)
                }
                Fit::Aim(c) => {
                    let candidate = (segment.unwrap_or(Quat::IDENTITY) * self.rest_alignment[j]).normalize();
                    let bone = candidate * (rest[c] - rest[j]);
                    let wanted = targets[c] - position[j];
                    match (bone.try_normalize(), wanted.try_normalize()) {
                        (Some(from), Some(to)) => (Quat::from_rotation_arc(from, to) * candidate).normalize(),
                        _ => candidate,
                    }
                }
                Fit::Segment => segment.unwrap_or(Quat::IDENTITY) * self.rest_alignment[j],
                Fit::Parent => global[PARENTS[j] as usize],
            };
        }
        global
    }
}

/// Rounds of moving the pelvis by the mean residual and refining the chains.
pub const REFINE_ITERATIONS: usize = 20;

/// Damping of a refinement step, m² (a 5 cm lever on each axis).
const REFINE_DAMPING_M2: f32 = 0.0025;

fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}

fn canonical(q: Quat) -> Quat {
    let q = q.normalize();
    if q.w < 0.0 { -q } else { q }
}

/// The rotation `R` minimising `Σ |R·a − b|²` over pairs `(a, b)` (Horn 1987, quaternion
/// form, in f64). `None` when the pairs do not determine a rotation (fewer than two
/// independent directions).
pub fn best_rotation(pairs: &[(Vec3, Vec3)]) -> Option<Quat> {
    let mut s = [[0.0f64; 3]; 3];
    for (a, b) in pairs {
        let (a, b) = (a.as_dvec3(), b.as_dvec3());
        for r in 0..3 {
            for c in 0..3 {
                s[r][c] += a[r] * b[c];
            }
        }
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let n = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (values, vectors) = symmetric_eigen4(n);
    let mut order = [0, 1, 2, 3];
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    let (top, second) = (values[order[0]], values[order[1]]);
    let scale = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if !(scale.is_finite() && scale > 0.0) || top - second <= 1e-9 * scale {
        return None;
    }
    let v = vectors[order[0]];
    let q = Quat::from_xyzw(v[1] as f32, v[2] as f32, v[3] as f32, v[0] as f32);
    q.is_finite().then(|| canonical(q))
}

/// Eigen-decomposition of a symmetric 4×4 matrix by cyclic Jacobi rotations: eigenvalues
/// and the matching unit eigenvectors.
fn symmetric_eigen4(mut a: [[f64; 4]; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let mut v = [[0.0f64; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..50 {
        let off: f64 = (0..4).flat_map(|p| ((p + 1)..4).map(move |q| (p, q))).map(|(p, q)| a[p][q] * a[p][q]).sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..4 {
            for q in (p + 1)..4 {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                // signum(0.0) = 1: the rotation by 45° when the diagonal entries are equal.
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..4 {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..4 {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let values = [a[0][0], a[1][1], a[2][2], a[3][3]];
    // Column k of `v` is the eigenvector of values[k].
    let vectors = std::array::from_fn(|k| std::array::from_fn(|r| v[r][k]));
    (values, vectors)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn best_rotation_recovers_a_known_rotation() {
        let r = Quat::from_euler(egoexo_core::glam::EulerRot::YXZ, 1.0, -0.4, 2.5);
        let pairs: Vec<(Vec3, Vec3)> =
            [Vec3::new(0.1, -0.1, 0.02), Vec3::new(-0.1, -0.1, 0.0), Vec3::new(0.0, 0.12, -0.01)]
                .map(|a| (a, r * a))
                .to_vec();
        let q = best_rotation(&pairs).unwrap();
        assert!(q.angle_between(r) < 1e-4, "{}", q.angle_between(r));
    }

    #[test]
    fn best_rotation_rejects_a_single_direction() {
        assert_eq!(best_rotation(&[(Vec3::X, Vec3::Y), (Vec3::X * 2.0, Vec3::Y * 2.0)]), None);
        assert_eq!(best_rotation(&[]), None);
    }
}
