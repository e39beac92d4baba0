//! The engine's passes over one window, with the types between them:
//!
//! ```text
//! WindowPlan ─ego_pass─► EgoPassOutput ─exo_pass─► ExoPassOutput ─fusion_pass─► WindowOutput
//!             (features,   (window frame,  (rays, gate features,   (window-frame 6D poses,
//!              coarse pose)  coarse 6D)      gate values)             gates per slot)
//! ```
//!
//! [`observer_fusion_pass`] is the exo and fusion passes of one method; for the ego-only
//! method it runs [`fusion_ego_only_pass`] instead when the model set ships that graph (the
//! fusion with every observer masked, without building empty observer slots).
//!
//! Each pass reads the aligned session only at the window's frames (and one frame of history
//! for the ego features), so a caller may feed windows one at a time as they complete — the
//! batch [`crate::ReconstructionJob`] and, later, a live stream use the same passes. The ego
//! pass depends only on the wearer and the coarse-pose source, so several methods (ego-exo
//! and the ego-only overlay) share one ego pass. The training shards call the same
//! functions of [`crate::inputs`] these passes are made of.

use egoexo_core::aligned::AlignedSession;
use egoexo_core::ego_features::TrackingMode;
use egoexo_core::glam::Quat;
use egoexo_core::skeleton::NUM_BODY_JOINTS;

use crate::InferError;
use crate::baselines::{NearestNeighbourIndex, rest_pose_window};
use crate::inputs::{EgoWindow, ExoWindow, POSE_DIM, ego_window, exo_index, exo_window, fusion_exo_input, world_poses};
use crate::models::{ModelSet, OnnxModel};
use crate::timing::{StageTimer, TimedStage};
use crate::windows::{WINDOW, WindowPlan};

/// Where a window's coarse pose comes from.
#[derive(Clone, Copy, Debug)]
pub enum CoarsePoseSource<'a> {
    /// SMPL's rest pose facing the head's heading (baseline).
    RestPose,
    /// The nearest training frame's pose (baseline).
    NearestNeighbour(&'a NearestNeighbourIndex),
    /// EgoNet.
    EgoNet(&'a OnnxModel),
}

/// The ego pass of one window: the wearer's features and the coarse pose.
#[derive(Clone, Debug)]
pub struct EgoPassOutput {
    /// Ego features, head poses and the window frame.
    pub window: EgoWindow,
    /// `WINDOW × POSE_DIM` coarse pose, root orientation in the window frame.
    pub coarse: Vec<f32>,
}

/// Ego pass: the window's ego features ([`ego_window`]), then its coarse pose.
pub fn ego_pass(
    aligned: &AlignedSession,
    plan: &WindowPlan,
    tracking: TrackingMode,
    source: CoarsePoseSource<'_>,
    timer: &mut StageTimer<'_>,
) -> Result<EgoPassOutput, InferError> {
    let window = timer.time(TimedStage::EgoFeatures, || ego_window(aligned, plan, tracking))?;
    let coarse = match source {
        CoarsePoseSource::RestPose => rest_pose_window(&window),
        CoarsePoseSource::NearestNeighbour(index) => index.window_poses(&window),
        CoarsePoseSource::EgoNet(egonet) => timer.time(TimedStage::EgoNet, || coarse_pose_with(egonet, &window))?,
    };
    Ok(EgoPassOutput { window, coarse })
}

/// EgoNet's coarse pose for one window: `WINDOW × POSE_DIM`, root orientation in the window
/// frame.
pub fn coarse_pose_with(egonet: &OnnxModel, window: &EgoWindow) -> Result<Vec<f32>, InferError> {
    let out = egonet.run(&[&window.ego])?;
    concat_pose(egonet.name(), &out)
}

/// `[root 6D (T×6), body 6D (T×126)]` outputs → `T × POSE_DIM`.
fn concat_pose(model: &str, out: &[Vec<f32>]) -> Result<Vec<f32>, InferError> {
    let (Some(root), Some(body)) = (out.first(), out.get(1)) else {
        return Err(InferError::Model { model: model.to_string(), message: "expected root and body outputs".into() });
    };
    if root.len() != WINDOW * 6 || body.len() != WINDOW * 6 * NUM_BODY_JOINTS {
        return Err(InferError::Model {
            model: model.to_string(),
            message: format!("output sizes {} and {}", root.len(), body.len()),
        });
    }
    let mut pose = Vec::with_capacity(WINDOW * POSE_DIM);
    for t in 0..WINDOW {
        pose.extend_from_slice(&root[t * 6..(t + 1) * 6]);
        pose.extend_from_slice(&body[t * 6 * NUM_BODY_JOINTS..(t + 1) * 6 * NUM_BODY_JOINTS]);
    }
    Ok(pose)
}

/// How the exo pass weighs the observers' rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExoMode {
    /// No observer: every slot empty (the ego-only method).
    Masked,
    /// Every valid ray with gate 1 (the ungated ablation).
    Ungated,
    /// The gate network's values.
    Gated,
}

/// The exo pass of one window: rays, gate features and the gate values.
#[derive(Clone, Debug)]
pub struct ExoPassOutput {
    pub exo: ExoWindow,
    /// `[T, N, K]` gate values, zero where no valid ray.
    pub gate: Vec<f32>,
    pub mode: ExoMode,
}

impl ExoPassOutput {
    /// The gate values of the slots that hold an observer, for reporting; `None` when the
    /// observers are masked.
    pub fn window_gates(&self) -> Option<WindowGates> {
        (self.mode != ExoMode::Masked).then(|| WindowGates {
            slots: self.exo.slots,
            slot_observer: self.exo.slot_observer.clone(),
            values: self.gate.clone(),
        })
    }
}

/// Exo pass: project EgoNet's coarse joints into every slotted observer's image for the
/// regions, lift the keypoints to canonical rays and offsets, compute the gate features
/// ([`exo_window`]), then gate: the gate network (`Gated`), 1 per valid ray (`Ungated`), or
/// nothing (`Masked`, every slot empty).
pub fn exo_pass(
    aligned: &AlignedSession,
    models: &ModelSet,
    ego: &EgoPassOutput,
    observers: &[usize],
    mode: ExoMode,
    timer: &mut StageTimer<'_>,
) -> Result<ExoPassOutput, InferError> {
    let slots = models.manifest.max_observers;
    let slotted: &[usize] = if mode == ExoMode::Masked { &[] } else { observers };
    let exo = timer.time(TimedStage::ExoFeatures, || {
        if slotted.is_empty() {
            exo_window(aligned, &ego.window, &[], &[], slots)
        } else {
            let coarse_world = world_poses(&ego.window, &ego.coarse, &aligned.skeleton, aligned.head_joint_in_device);
            exo_window(aligned, &ego.window, &coarse_world, slotted, slots)
        }
    });
    let gate: Vec<f32> = match mode {
        ExoMode::Gated => timer
            .time(TimedStage::Gate, || models.gate.run(&[&exo.gate_features]))?
            .into_iter()
            .next()
            .unwrap_or_default(),
        ExoMode::Ungated | ExoMode::Masked => exo.ray_valid.clone(),
    };
    if gate.len() != exo.ray_valid.len() {
        return Err(InferError::Model {
            model: models.gate.name().to_string(),
            message: format!("gate output has {} values, expected {}", gate.len(), exo.ray_valid.len()),
        });
    }
    let gate = gate.iter().zip(&exo.ray_valid).map(|(g, v)| g * v).collect();
    Ok(ExoPassOutput { exo, gate, mode })
}

/// Gate values of one window, per slot: `[T, N, K]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WindowGates {
    pub slots: usize,
    /// Which session observer fills each slot.
    pub slot_observer: Vec<Option<usize>>,
    pub values: Vec<f32>,
}

impl WindowGates {
    /// Gate of keypoint `k` seen from `slot` at window frame `t`.
    pub fn get(&self, t: usize, slot: usize, k: usize) -> f32 {
        self.values.get(exo_index(self.slots, t, slot, k)).copied().unwrap_or(0.0)
    }
}

/// One window's result, what decoding needs.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WindowOutput {
    pub plan: WindowPlan,
    /// Rotation of the window frame in the world (`T_world_window`'s).
    pub r_world_window: Quat,
    /// `WINDOW × POSE_DIM`, root orientation in the window frame.
    pub poses: Vec<f32>,
    /// Gate values per slot; `None` for methods without observers.
    pub gates: Option<WindowGates>,
}

impl WindowOutput {
    /// A window whose poses are its coarse pose (the baselines).
    pub fn from_coarse(ego: &EgoPassOutput) -> Self {
        WindowOutput {
            plan: ego.window.plan.clone(),
            r_world_window: ego.window.t_world_window.rotation,
            poses: ego.coarse.clone(),
            gates: None,
        }
    }

    /// A window whose poses are a fusion graph's outputs (`root_6d`, `body_6d`) of `model`.
    fn from_fusion(
        ego: &EgoPassOutput,
        model: &OnnxModel,
        outputs: &[Vec<f32>],
        gates: Option<WindowGates>,
    ) -> Result<Self, InferError> {
        Ok(WindowOutput {
            plan: ego.window.plan.clone(),
            r_world_window: ego.window.t_world_window.rotation,
            poses: concat_pose(model.name(), outputs)?,
            gates,
        })
    }
}

/// The ego-only fusion pass: the fusion network with every observer masked, as its own graph
/// (`fusion_ego_only`: the same weights; a masked observer's attention weight is exactly 0
/// in float32, so the same numbers up to rounding) — what [`fusion_pass`] computes on
/// [`exo_pass`]`(.., ExoMode::Masked, ..)`, without the empty observer slots. `None` when the
/// set does not ship the graph.
pub fn fusion_ego_only_pass(
    models: &ModelSet,
    ego: &EgoPassOutput,
    timer: &mut StageTimer<'_>,
) -> Option<Result<WindowOutput, InferError>> {
    let model = models.fusion_ego_only.as_ref()?;
    let output = timer.time(TimedStage::Fusion, || model.run(&[&ego.window.ego, &ego.coarse]));
    Some(output.and_then(|out| WindowOutput::from_fusion(ego, model, &out, None)))
}

/// One method's passes after the shared ego pass: [`exo_pass`] then [`fusion_pass`], or, for
/// [`ExoMode::Masked`] with a set that ships it, [`fusion_ego_only_pass`].
pub fn observer_fusion_pass(
    aligned: &AlignedSession,
    models: &ModelSet,
    ego: &EgoPassOutput,
    observers: &[usize],
    mode: ExoMode,
    timer: &mut StageTimer<'_>,
) -> Result<WindowOutput, InferError> {
    if mode == ExoMode::Masked
        && let Some(output) = fusion_ego_only_pass(models, ego, timer)
    {
        return output;
    }
    let exo = exo_pass(aligned, models, ego, observers, mode, timer)?;
    fusion_pass(models, ego, &exo, timer)
}

/// Fusion pass: the spatial–temporal transformer over the ego stream, the coarse pose and
/// the gated exo tokens of every slot.
pub fn fusion_pass(
    models: &ModelSet,
    ego: &EgoPassOutput,
    exo: &ExoPassOutput,
    timer: &mut StageTimer<'_>,
) -> Result<WindowOutput, InferError> {
    let out = timer.time(TimedStage::Fusion, || {
        let exo_input = fusion_exo_input(&exo.exo, &exo.gate);
        models.fusion.run(&[&ego.window.ego, &ego.coarse, &exo_input, &exo.exo.observer_mask])
    })?;
    WindowOutput::from_fusion(ego, &models.fusion, &out, exo.window_gates())
}
