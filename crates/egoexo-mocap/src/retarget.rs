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
//! 3. The torso keeps SMPL's own shape and follows the CMU torso's rotations: pelvis,
//!    spine1–3, neck, collars, head and feet start from their CMU segment's rotation since
//!    the rest pose (`W`; spine2 and spine3 both from `thorax`). So a neutral CMU posture
//!    starts as a neutral SMPL posture even though the two skeletons place their joints
//!    differently (SMPL's neck joint sits ~5 cm behind its head joint, its spine is
//!    curved, CMU's is straight). The head and feet keep exactly the CMU rotation (a
//!    head-mounted device follows the subject's real head).
//! 4. The limbs (hips, knees, ankles, shoulders, elbows, wrists) are fitted to bone
//!    directions: twist from the CMU segment, swung by the smallest rotation that aims the
//!    SMPL bone from the joint's *fitted* position at the child's target (wrists: along the
//!    CMU wrist → hand direction). CMU's rest legs splay about 20° while SMPL's hang
//!    straight, so rest directions are aligned once per skeleton and Euler angles are never
//!    copied.
//! 5. [`REFINE_ROUNDS`] rounds of
//!    - a Gauss–Newton step of the translation and the seven torso rotations (pelvis,
//!      spine1–3, neck, collars) towards the targets, with a penalty on each joint's *bend*
//!      away from the CMU segments (its local rotation's deviation; for the pelvis its
//!      orientation; the head's bend, since its global rotation is fixed, holds the neck)
//!      that stiffens past 15°: the torso may lean a few degrees to absorb the skeletons'
//!      different proportions, never fold;
//!    - [`LIMB_SWEEPS_PER_ROUND`] sweeps of a damped Gauss–Newton step per limb joint that
//!      moves its limb below it onto the targets, spreading a limb's length mismatch over
//!      its joints, each after moving the translation by the mean residual.
//!
//! Design note, measured on the shared subset (mean / p95 joint error over 159 trials):
//! - fitting every joint to positions freely reaches 2.6 cm but bends SMPL's spine and
//!   neck to make up for the skeletons' different proportions (a neutral CMU T-pose came
//!   out with the neck bent ~80°);
//! - copying the torso rotations exactly (pelvis and spine3 from their child bones):
//!   3.05 / 5.45 cm;
//! - the penalised torso fit: 2.79 / 5.25 cm; with the collar targets at SMPL's collar
//!   proportion (see [`CMU_TO_SMPL`]) 2.71 / 5.15 cm (the collar mapping alone, with the
//!   copied torso: 2.97 cm); with the wrists along the CMU bone direction (step 4)
//!   2.72 / 5.15 cm. Bends from the CMU segments: mean 1–3° (pelvis, spine,
//!   neck), 4° (head), 11° (collars); largest in any frame 10° (spine), 7° (neck), 12°
//!   (head), 14° (pelvis), 24° (collars); in the neutral T-pose at most 6° (collars 14°).
//!   Half the penalty gives 2.66 cm for bends about 1.6 times as large.
//!
//! The remaining error is the skeletons' proportions (SMPL scaled to the head height has
//! ~6 cm shorter legs and a ~6 cm longer torso than CMU's subjects; its hips sit ~4 cm
//! further back): pelvis, hips, neck and head keep ~4.5 cm.
//!
//! The retarget error of a frame is the distance between each target and the fitted SMPL
//! joint (forward kinematics of the output pose), over all 24 joints.

use egoexo_core::glam::{DMat3, DVec3, Mat3, Quat, Vec3};
use egoexo_core::skeleton::{JOINT_NAMES, NUM_BODY_JOINTS, NUM_JOINTS, PARENTS, SkeletonError, SmplPose, SmplSkeleton};
use egoexo_solve::dense::{outer_d, skew, solve_spd};
use thiserror::Error;

use crate::kinematics::{CmuBoneTransforms, CmuSkeleton};

/// Each SMPL joint as a weighted blend of CMU bone *starts* (where a bone begins: the end
/// of its parent). `root` is the root's position.
///
/// The mapping of `shared/data/cmu/README.md`, except that the collars sit 45% (not "about
/// 35%") of the way from the clavicle's start (the neck base) to the shoulder: that is
/// where SMPL's mean-shape collar joints sit between its spine and its shoulders (45–47%),
/// and it brings the collar error from about 3.4 to 2.5 cm.
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
    &[("lclavicle", 0.55), ("lhumerus", 0.45)], // left_collar
    &[("rclavicle", 0.55), ("rhumerus", 0.45)], // right_collar
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

/// The CMU segment whose world rotation each SMPL joint starts from (for a limb joint its
/// twist: the segment that spans the SMPL bone from the joint to its child; the joint's
/// own segment for the torso, feet and head). `None`: identity (hands).
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
    /// Torso joints (pelvis, spine, neck, collars): the CMU segment's rotation since its
    /// rest pose, then a small penalised correction towards the targets ([`TorsoPenalty`]).
    Torso,
    /// Limb joints: twist from the CMU segment, swung to aim the bone at this child's
    /// target from the joint's fitted position; refined afterwards.
    Aim(usize),
    /// Wrists: twist from the CMU segment, swung onto the CMU bone's direction (joint
    /// target → this child's target); not refined itself, only carried along by the
    /// refinement of the joints above. The hand target is too close to the wrist for its
    /// position to steer the wrist: aimed from the fitted wrist, a subject with a short CMU
    /// forearm (05) had its wrists bent 40–67° in the T-pose.
    Direction(usize),
    /// Exactly the CMU segment's rotation since its rest pose (head, feet).
    Segment,
    /// Same as the parent (SMPL hands: not part of the 21 body rotations).
    Parent,
}

const FIT: [Fit; NUM_JOINTS] = [
    Fit::Torso,         // pelvis
    Fit::Aim(4),        // left_hip
    Fit::Aim(5),        // right_hip
    Fit::Torso,         // spine1
    Fit::Aim(7),        // left_knee
    Fit::Aim(8),        // right_knee
    Fit::Torso,         // spine2
    Fit::Aim(10),       // left_ankle
    Fit::Aim(11),       // right_ankle
    Fit::Torso,         // spine3
    Fit::Segment,       // left_foot
    Fit::Segment,       // right_foot
    Fit::Torso,         // neck
    Fit::Torso,         // left_collar
    Fit::Torso,         // right_collar
    Fit::Segment,       // head
    Fit::Aim(18),       // left_shoulder
    Fit::Aim(19),       // right_shoulder
    Fit::Aim(20),       // left_elbow
    Fit::Aim(21),       // right_elbow
    Fit::Direction(22), // left_wrist
    Fit::Direction(23), // right_wrist
    Fit::Parent,        // left_hand
    Fit::Parent,        // right_hand
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
    /// Per joint, the rotation that turns a CMU segment rotation `W` (rest → now) into an
    /// SMPL global rotation candidate `W · rest_alignment`: the rest facing for every joint,
    /// and for limb joints also the swing from SMPL's rest bone direction onto CMU's (CMU's
    /// rest legs splay about 20°).
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
            if let Fit::Aim(c) | Fit::Direction(c) = FIT[j] {
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
        let copied = global;
        for _ in 0..REFINE_ROUNDS {
            self.fit_torso(&mut global, &copied, &mut pelvis, &targets);
            for sweep in 0..LIMB_SWEEPS_PER_ROUND {
                if sweep > 0 {
                    let fitted = self.positions_from_globals(&global, pelvis);
                    let shift: Vec3 = (0..NUM_JOINTS).map(|j| targets[j] - fitted[j]).sum::<Vec3>() / NUM_JOINTS as f32;
                    pelvis += shift;
                }
                self.refine(&mut global, pelvis, &targets);
            }
        }
        let pose = self.pose_from_globals(&global, pelvis);
        let fitted = self.smpl.forward_kinematics(&pose).positions;
        let errors = std::array::from_fn(|j| fitted[j].distance(targets[j]));
        RetargetedFrame { pose, targets, errors }
    }

    /// SMPL joint positions for global rotations and a pelvis position.
    fn positions_from_globals(&self, global: &[Quat; NUM_JOINTS], pelvis: Vec3) -> [Vec3; NUM_JOINTS] {
        positions_from_globals(self.smpl.rest_joints(), global, pelvis)
    }

    /// One Gauss–Newton step of the translation and the torso joints' rotations towards the
    /// targets ([`torso_step`]). `copied` holds the CMU-copied global rotations.
    fn fit_torso(
        &self,
        global: &mut [Quat; NUM_JOINTS],
        copied: &[Quat; NUM_JOINTS],
        pelvis: &mut Vec3,
        targets: &[Vec3; NUM_JOINTS],
    ) {
        let p = self.positions_from_globals(global, *pelvis);
        let deviation = TORSO_JOINTS.map(|j| canonical(global[j] * copied[j].conjugate()).to_scaled_axis());
        let Some((shift, rotations)) = torso_step(&p, targets, &deviation, &TORSO_PENALTY) else { return };
        *pelvis += shift;
        for (slot, &j) in TORSO_JOINTS.iter().enumerate() {
            global[j] = (Quat::from_scaled_axis(rotations[slot]) * global[j]).normalize();
        }
    }

    /// One sweep down the limbs: each limb joint's rotation is corrected by a Gauss–Newton
    /// step of the rotation (about the joint) that best moves the rest of its limb onto the
    /// targets, which spreads a limb's length mismatch over its joints instead of piling it
    /// on the hand or foot. Damping towards no correction keeps the CMU twist where the limb
    /// does not determine it (a straight limb). Torso joints are not touched (see
    /// `fit_torso`).
    fn refine(&self, global: &mut [Quat; NUM_JOINTS], pelvis: Vec3, targets: &[Vec3; NUM_JOINTS]) {
        let mut p = self.positions_from_globals(global, pelvis);
        for j in 1..=NUM_BODY_JOINTS {
            let descendants = &self.descendants[j];
            if descendants.is_empty() || !matches!(FIT[j], Fit::Aim(_)) {
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
                fit @ (Fit::Aim(c) | Fit::Direction(c)) => {
                    let candidate = (segment.unwrap_or(Quat::IDENTITY) * self.rest_alignment[j]).normalize();
                    let bone = candidate * (rest[c] - rest[j]);
                    let from = if matches!(fit, Fit::Aim(_)) { position[j] } else { targets[j] };
                    let wanted = targets[c] - from;
                    match (bone.try_normalize(), wanted.try_normalize()) {
                        (Some(from), Some(to)) => (Quat::from_rotation_arc(from, to) * candidate).normalize(),
                        _ => candidate,
                    }
                }
                Fit::Torso | Fit::Segment => segment.unwrap_or(Quat::IDENTITY) * self.rest_alignment[j],
                Fit::Parent => global[PARENTS[j] as usize],
            };
        }
        global
    }
}

/// Rounds of the refinement: a torso fit (with the translation), then
/// [`LIMB_SWEEPS_PER_ROUND`] limb sweeps.
pub const REFINE_ROUNDS: usize = 6;

/// Limb sweeps per refinement round, each but the first after moving the translation by
/// the mean residual (the limbs converge more slowly than the torso fit).
pub const LIMB_SWEEPS_PER_ROUND: usize = 4;

/// Damping of a refinement step, m² (a 5 cm lever on each axis).
const REFINE_DAMPING_M2: f32 = 0.0025;

/// One Gauss–Newton step of the translation and the torso joints' rotations ([`TORSO_JOINTS`])
/// that moves SMPL joints at `p` towards `targets` (metres, world frame), penalising how far
/// each torso joint bends away from the CMU segments. `deviation` is each torso joint's
/// current global deviation from its CMU-copied rotation (world-frame rotation vector,
/// rad). Returns the translation step (m) and each torso joint's rotation step (world-frame
/// rotation vector, rad, applied as `exp(δ) · R`), or `None` when the system is singular.
///
/// Linearised, a small world-frame rotation `δ_j` of torso joint `j` turns only its own
/// bones (the limbs keep their global rotations and move along; the limb refinement re-aims
/// them), so a joint `k` moves by `Δt + Σ δ_j × b_j` over the torso joints `j` above it,
/// `b_j` being the bone from `j` towards `k`. Every joint of a limb shares the Jacobian of
/// the limb's first joint, so the normal equations are summed per attachment.
fn torso_step(
    p: &[Vec3; NUM_JOINTS],
    targets: &[Vec3; NUM_JOINTS],
    deviation: &[Vec3; TORSO_JOINTS.len()],
    penalty: &TorsoPenalty,
) -> Option<(Vec3, [Vec3; TORSO_JOINTS.len()])> {
    let mut residual = [DVec3::ZERO; NUM_JOINTS];
    for k in 0..NUM_JOINTS {
        residual[ATTACHMENT[k]] += (targets[k] - p[k]).as_dvec3();
    }
    let mut h = [[0.0f64; TORSO_UNKNOWNS]; TORSO_UNKNOWNS];
    let mut g = [0.0f64; TORSO_UNKNOWNS];
    let add = |h: &mut [[f64; TORSO_UNKNOWNS]; TORSO_UNKNOWNS], row: usize, col: usize, m: DMat3| {
        for c in 0..3 {
            let column = m.col(c);
            for r in 0..3 {
                h[row + r][col + c] += column[r];
            }
        }
    };
    for &(a, count) in ATTACHMENTS.iter() {
        let n = count as f64;
        let r = residual[a];
        // The torso joints above `a` (unknown offset, bone towards `a`).
        let mut chain = [(0usize, DVec3::ZERO); TORSO_JOINTS.len()];
        let mut len = 0;
        let (mut c, mut up) = (a, PARENTS[a]);
        while up >= 0 {
            let j = up as usize;
            if let Some(slot) = TORSO_SLOT[j] {
                chain[len] = (3 + 3 * slot, (p[c] - p[j]).as_dvec3());
                len += 1;
            }
            c = j;
            up = PARENTS[j];
        }
        let chain = &chain[..len];
        add(&mut h, 0, 0, DMat3::from_diagonal(DVec3::splat(n)));
        for d in 0..3 {
            g[d] += r[d];
        }
        for (i, &(oi, bi)) in chain.iter().enumerate() {
            // ∂p/∂δ_i = −[b_i]×.
            let cross = skew(bi) * n;
            add(&mut h, 0, oi, -cross);
            add(&mut h, oi, 0, cross);
            let gi = bi.cross(r);
            for d in 0..3 {
                g[oi + d] += gi[d];
            }
            for &(oj, bj) in &chain[i..] {
                // (−[b_i]×)ᵀ(−[b_j]×) = (b_i·b_j) I − b_j b_iᵀ.
                let m = (DMat3::from_diagonal(DVec3::splat(bi.dot(bj))) - outer_d(bj, bi)) * n;
                add(&mut h, oi, oj, m);
                if oi != oj {
                    add(&mut h, oj, oi, m.transpose());
                }
            }
        }
    }
    // Penalised bends: the deviation of each torso joint's local rotation from the CMU
    // segments', to first order e_j − e_parent with e the global deviation; the pelvis
    // bends against the world (its orientation), and the head, whose global rotation is
    // the CMU head's, bends by −e_neck.
    let deviation = deviation.map(|e| e.as_dvec3());
    let mut bend_terms = [(0usize, None::<usize>, 0.0f64); TORSO_JOINTS.len() + 1];
    for (slot, &j) in TORSO_JOINTS.iter().enumerate() {
        let parent = if j == 0 { None } else { TORSO_SLOT[PARENTS[j] as usize] };
        bend_terms[slot] = (slot, parent, penalty.lambda[slot]);
    }
    bend_terms[TORSO_JOINTS.len()] = (NECK_SLOT, None, penalty.head);
    for &(slot, parent, lambda) in &bend_terms {
        let bend = deviation[slot] - parent.map_or(DVec3::ZERO, |ps| deviation[ps]);
        let lambda = lambda * (1.0 + (bend.length() / penalty.soft_limit).powi(2));
        let a = 3 + 3 * slot;
        for d in 0..3 {
            h[a + d][a + d] += lambda;
            g[a + d] -= lambda * bend[d];
            if let Some(ps) = parent {
                let b = 3 + 3 * ps;
                h[b + d][b + d] += lambda;
                h[a + d][b + d] -= lambda;
                h[b + d][a + d] -= lambda;
                g[b + d] += lambda * bend[d];
            }
        }
    }
    let x = solve_spd(h, g)?;
    let shift = DVec3::new(x[0], x[1], x[2]).as_vec3();
    let rotations = std::array::from_fn(|slot| {
        let o = 3 + 3 * slot;
        DVec3::new(x[o], x[o + 1], x[o + 2]).as_vec3()
    });
    Some((shift, rotations))
}

/// Joint positions (metres) of a skeleton with rest joints `rest` for global joint rotations
/// (rest → now) and a pelvis position.
fn positions_from_globals(rest: &[Vec3; NUM_JOINTS], global: &[Quat; NUM_JOINTS], pelvis: Vec3) -> [Vec3; NUM_JOINTS] {
    let mut p = [Vec3::ZERO; NUM_JOINTS];
    p[0] = pelvis;
    for j in 1..NUM_JOINTS {
        let parent = PARENTS[j] as usize;
        p[j] = p[parent] + global[parent] * (rest[j] - rest[parent]);
    }
    p
}

/// Torso joints whose rotations the torso fit corrects: pelvis, spine1–3, neck, collars.
const TORSO_JOINTS: [usize; 7] = [0, 3, 6, 9, 12, 13, 14];
const TORSO_SLOT: [Option<usize>; NUM_JOINTS] = {
    let mut slots = [None; NUM_JOINTS];
    let mut i = 0;
    while i < TORSO_JOINTS.len() {
        slots[TORSO_JOINTS[i]] = Some(i);
        i += 1;
    }
    slots
};
/// The neck's place in [`TORSO_JOINTS`].
const NECK_SLOT: usize = 4;
const _: () = assert!(TORSO_JOINTS[NECK_SLOT] == 12);
const TORSO_UNKNOWNS: usize = 3 + 3 * TORSO_JOINTS.len();

/// Per SMPL joint, the joint whose Jacobian it shares in the torso fit: itself for the
/// pelvis and the joints whose parent is a torso joint, else its parent's.
const ATTACHMENT: [usize; NUM_JOINTS] = {
    let mut a = [0; NUM_JOINTS];
    let mut j = 1;
    while j < NUM_JOINTS {
        let parent = PARENTS[j] as usize;
        a[j] = if TORSO_SLOT[parent].is_some() { j } else { a[parent] };
        j += 1;
    }
    a
};
/// The distinct attachments and how many joints each carries.
const ATTACHMENTS: [(usize, u32); 12] = {
    let mut out = [(0, 0); 12];
    let mut n = 0;
    let mut j = 0;
    while j < NUM_JOINTS {
        if ATTACHMENT[j] == j {
            let mut count = 0;
            let mut k = 0;
            while k < NUM_JOINTS {
                if ATTACHMENT[k] == j {
                    count += 1;
                }
                k += 1;
            }
            out[n] = (j, count);
            n += 1;
        }
        j += 1;
    }
    assert!(n == 12);
    out
};

/// How strongly the torso fit holds each torso joint to the CMU segments: the squared bend
/// `θ²` (rad²) is weighed against the sum of squared joint errors (m²) by
/// `λ (1 + (θ / soft_limit)²)`, the weight re-evaluated each round; `λ = 0.01` makes a
/// 0.1 rad (5.7°) bend cost as much as a 1 cm error.
struct TorsoPenalty {
    /// Per torso joint ([`TORSO_JOINTS`] order), m²/rad².
    lambda: [f64; TORSO_JOINTS.len()],
    /// The head's bend against the neck (the head's global rotation is the CMU head's, so
    /// this holds the neck's global rotation to CMU's).
    head: f64,
    /// Bend beyond which the penalty stiffens quickly, rad.
    soft_limit: f64,
}

/// Chosen on the shared CMU subset (see the module's design note): the spine and pelvis
/// stiff, the neck and head less so, the collars (shoulder girdle, which moves freely in
/// life) softest.
const TORSO_PENALTY: TorsoPenalty = TorsoPenalty {
    //       pelvis spine1 spine2 spine3 neck  l_collar r_collar
    lambda: [0.04, 0.04, 0.04, 0.04, 0.02, 0.005, 0.005],
    head: 0.02,
    soft_limit: 15.0 * std::f64::consts::PI / 180.0,
};

fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}

fn canonical(q: Quat) -> Quat {
    let q = q.normalize();
    if q.w < 0.0 { -q } else { q }
}

#[cfg(test)]
mod tests {
    use super::*;
    use egoexo_core::glam::EulerRot;

    /// SMPL mean-shape joint positions for global rotations and a pelvis position.
    fn positions(global: &[Quat; NUM_JOINTS], pelvis: Vec3) -> [Vec3; NUM_JOINTS] {
        positions_from_globals(SmplSkeleton::mean_shape().rest_joints(), global, pelvis)
    }

    /// A posture with every joint turned somewhat (deterministic).
    fn posture() -> [Quat; NUM_JOINTS] {
        std::array::from_fn(|j| {
            let a = j as f32;
            Quat::from_euler(EulerRot::YXZ, 0.3 * (a * 1.3).sin(), 0.4 * (a * 0.7).cos(), 0.2 * (a * 2.1).sin())
        })
    }

    const FREE: TorsoPenalty =
        TorsoPenalty { lambda: [1e-9; TORSO_JOINTS.len()], head: 1e-9, soft_limit: std::f64::consts::PI };

    #[test]
    fn the_torso_table_matches_the_fit_table() {
        for j in 0..NUM_JOINTS {
            assert_eq!(FIT[j] == Fit::Torso, TORSO_SLOT[j].is_some(), "joint {j}");
        }
        // Every joint shares the Jacobian of exactly one attachment.
        assert_eq!(ATTACHMENTS.iter().map(|&(_, n)| n).sum::<u32>(), NUM_JOINTS as u32);
        assert_eq!(ATTACHMENT[22], 16);
        assert_eq!(ATTACHMENT[10], 1);
        assert_eq!(ATTACHMENT[15], 15);
    }

    #[test]
    fn a_torso_step_recovers_a_small_torso_motion() {
        // Targets: the same posture with each torso joint turned a little more and the body
        // moved; the limbs keep their global rotations. One unpenalised step recovers it
        // (to second order).
        let global = posture();
        let pelvis = Vec3::new(0.3, 0.9, -0.2);
        let turns: [Vec3; TORSO_JOINTS.len()] =
            std::array::from_fn(|i| Vec3::new(0.02 * (i as f32 - 3.0), 0.015, -0.01 * i as f32));
        let shift = Vec3::new(0.01, -0.02, 0.015);
        let mut moved = global;
        for (slot, &j) in TORSO_JOINTS.iter().enumerate() {
            moved[j] = Quat::from_scaled_axis(turns[slot]) * global[j];
        }
        let p = positions(&global, pelvis);
        let targets = positions(&moved, pelvis + shift);
        let (t, r) = torso_step(&p, &targets, &[Vec3::ZERO; TORSO_JOINTS.len()], &FREE).unwrap();
        assert!(t.distance(shift) < 1e-3, "{t} vs {shift}");
        // The pelvis (three bones) is fully determined; a one-bone joint only up to a turn
        // about its bone, so check where the step puts the joints.
        assert!(r[0].distance(turns[0]) < 4e-3, "{} vs {}", r[0], turns[0]);
        let mut stepped = global;
        for (slot, &j) in TORSO_JOINTS.iter().enumerate() {
            stepped[j] = Quat::from_scaled_axis(r[slot]) * global[j];
        }
        let after = positions(&stepped, pelvis + t);
        let before = (0..NUM_JOINTS).map(|k| p[k].distance(targets[k])).fold(0.0, f32::max);
        let left = (0..NUM_JOINTS).map(|k| after[k].distance(targets[k])).fold(0.0, f32::max);
        assert!(before > 0.02 && left < 1e-3, "{before} m before, {left} m after");
    }

    #[test]
    fn the_penalty_pulls_the_torso_back_to_the_cmu_segments() {
        // Joints exactly on their targets, but the spine3 and neck bent away from the CMU
        // segments: the step turns them back, and the more so the stiffer the penalty.
        let global = posture();
        let p = positions(&global, Vec3::ZERO);
        let mut deviation = [Vec3::ZERO; TORSO_JOINTS.len()];
        deviation[3] = Vec3::new(0.2, 0.0, 0.0);
        deviation[NECK_SLOT] = Vec3::new(0.2, 0.0, 0.0);
        let (_, soft) = torso_step(&p, &p, &deviation, &TORSO_PENALTY).unwrap();
        let stiff = TorsoPenalty { lambda: TORSO_PENALTY.lambda.map(|l| l * 100.0), head: 100.0, ..TORSO_PENALTY };
        let (_, hard) = torso_step(&p, &p, &deviation, &stiff).unwrap();
        for slot in [3, NECK_SLOT] {
            assert!(soft[slot].x < 0.0 && hard[slot].x < soft[slot].x, "{} {}", soft[slot], hard[slot]);
            assert!((hard[slot].x + 0.2).abs() < 0.02, "stiff: back to the segments, {}", hard[slot]);
        }
        // Nothing to do: no step.
        let (t, r) = torso_step(&p, &p, &[Vec3::ZERO; TORSO_JOINTS.len()], &TORSO_PENALTY).unwrap();
        assert!(t.length() < 1e-6 && r.iter().all(|v| v.length() < 1e-6));
    }
}
