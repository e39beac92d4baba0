//! The reconstruction engine: an aligned session in, SMPL motion out.
//!
//! align → valid spans → windows → ego features → EgoNet (coarse pose) → per observer: region
//! proposal, keypoints, canonical rays, gate features → gate → fusion → window-frame poses →
//! world → cross-fade overlapping windows → root translation from the head by FK.
//!
//! The same engine runs the networks (`ego-only`, `ego-exo`, `ego-exo-ungated`) and the
//! baselines (`rest-pose`, `nearest-neighbour`), natively and in the browser's worker. Units:
//! metres, seconds; world Y-up.

use std::collections::BTreeMap;
use std::fmt;

use egoexo_core::ego_features::TrackingMode;
use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_core::glam::Vec3;
use egoexo_core::motion::SmplMotion;
use egoexo_core::rotation::Rot6d;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, NUM_JOINTS, SmplPose};
use egoexo_session::align::AlignedSession;
use serde::{Deserialize, Serialize};

use crate::InferError;
use crate::baselines::{NearestNeighbourIndex, rest_pose_window};
use crate::inputs::{EgoWindow, POSE_DIM, ego_window, exo_window, fusion_exo_input, world_poses};
use crate::models::{ModelSet, OnnxModel};
use crate::windows::{WINDOW, crossfade_weight, plan_windows, valid_spans};

/// How to reconstruct.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Baseline: SMPL rest pose hung from the head, facing the head's heading.
    RestPose,
    /// Baseline: per-frame nearest neighbour over training ego features.
    NearestNeighbour,
    /// The fusion network with every observer masked out.
    EgoOnly,
    /// The full method: gated exo rays fused with the ego stream.
    EgoExo,
    /// The fusion network with every valid ray's gate forced to 1 (ablation).
    EgoExoUngated,
}

impl Method {
    /// The name used in tables and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::RestPose => "rest-pose",
            Method::NearestNeighbour => "nearest-neighbour",
            Method::EgoOnly => "ego-only",
            Method::EgoExo => "ego-exo",
            Method::EgoExoUngated => "ego-exo-ungated",
        }
    }

    /// Whether the method runs the ONNX networks.
    pub fn uses_networks(self) -> bool {
        matches!(self, Method::EgoOnly | Method::EgoExo | Method::EgoExoUngated)
    }

    fn uses_exo(self) -> bool {
        matches!(self, Method::EgoExo | Method::EgoExoUngated)
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Options of one reconstruction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReconstructOptions {
    pub method: Method,
    /// Tracking mode; `None` picks 3-point when the session has both wrists.
    pub tracking: Option<TrackingMode>,
    /// Frames between window starts (overlapping windows are cross-faded).
    pub stride: usize,
    /// The paper's evaluation protocol: non-overlapping 96-frame segments, no cross-fade.
    pub non_overlapping: bool,
}

impl Default for ReconstructOptions {
    fn default() -> Self {
        Self { method: Method::EgoExo, tracking: None, stride: WINDOW / 2, non_overlapping: false }
    }
}

/// Which part of the work a progress report is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Ego features and the coarse pose (EgoNet or a baseline), per window.
    Ego,
    /// Regions, rays, gate and fusion, per window.
    Fusion,
}

/// A progress report: `done` of `total` windows of a stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Progress {
    pub stage: Stage,
    pub done: usize,
    pub total: usize,
}

/// Gate values of one observer: per frame, per exo keypoint (0 where no valid ray).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObserverGates {
    pub observer_id: String,
    pub gates: Vec<[f32; EXO_KEYPOINT_COUNT]>,
}

/// A reconstruction on the aligned session's timeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reconstruction {
    pub method: Method,
    pub tracking: TrackingMode,
    /// Per-frame SMPL parameters (frames without valid tracking hold the nearest valid pose).
    pub motion: SmplMotion,
    /// World positions of the 24 joints per frame (metres).
    pub joints: Vec<[Vec3; NUM_JOINTS]>,
    /// Frames that were actually reconstructed (wearer tracking valid).
    pub valid: Vec<bool>,
    /// Frames where at least one observer contributed a ray with gate ≥ 0.5.
    pub exo_evidence: Vec<bool>,
    /// Per observer (session order), per frame, per keypoint gate values.
    pub gates: Vec<ObserverGates>,
}

/// The engine: the trained networks (per tracking mode) and the baselines' data.
#[derive(Clone, Debug, Default)]
pub struct Engine {
    models: BTreeMap<u8, ModelSet>,
    nearest: BTreeMap<u8, NearestNeighbourIndex>,
}

#[derive(Clone)]
struct Accumulator {
    weight: f32,
    pose: Vec<f32>,
    gates: Vec<f32>,
    evidence: bool,
}

impl Engine {
    /// An engine without networks (baselines only until models are added).
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the networks of one tracking mode.
    pub fn with_models(mut self, models: ModelSet) -> Self {
        self.models.insert(models.manifest.tracking.points(), models);
        self
    }

    /// Adds a nearest-neighbour index for one tracking mode.
    pub fn with_nearest_neighbour(mut self, tracking: TrackingMode, index: NearestNeighbourIndex) -> Self {
        self.nearest.insert(tracking.points(), index);
        self
    }

    /// The loaded networks of a tracking mode.
    pub fn models(&self, tracking: TrackingMode) -> Option<&ModelSet> {
        self.models.get(&tracking.points())
    }

    /// Reconstructs the wearer's motion. `progress` is called after every window; returning
    /// `false` cancels (the result is then [`InferError::Cancelled`]).
    pub fn reconstruct(
        &self,
        aligned: &AlignedSession,
        options: &ReconstructOptions,
        progress: &mut dyn FnMut(Progress) -> bool,
    ) -> Result<Reconstruction, InferError> {
        let has_wrists = aligned.left_wrist.is_some() && aligned.right_wrist.is_some();
        let tracking =
            options.tracking.unwrap_or(if has_wrists { TrackingMode::ThreePoint } else { TrackingMode::OnePoint });
        if tracking == TrackingMode::ThreePoint && !has_wrists {
            return Err(InferError::MissingWrists);
        }
        let models = if options.method.uses_networks() {
            Some(self.models(tracking).ok_or(InferError::NoModels { points: tracking.points() })?)
        } else {
            None
        };
        let nearest = if options.method == Method::NearestNeighbour {
            Some(
                self.nearest
                    .get(&tracking.points())
                    .ok_or(InferError::NoNearestNeighbourIndex { points: tracking.points() })?,
            )
        } else {
            None
        };

        let frames = aligned.timeline.frames;
        let valid: Vec<bool> = (0..frames)
            .map(|f| {
                let head = aligned.head.valid.get(f).copied().unwrap_or(false);
                let wrist_ok = |w: &Option<egoexo_session::align::AlignedTrajectory>| {
                    w.as_ref().is_some_and(|w| w.valid.get(f).copied().unwrap_or(false))
                };
                head && (tracking == TrackingMode::OnePoint
                    || (wrist_ok(&aligned.left_wrist) && wrist_ok(&aligned.right_wrist)))
            })
            .collect();
        if !valid.iter().any(|&v| v) {
            return Err(InferError::NoValidFrames);
        }
        let spans = valid_spans(&valid);
        let plans = plan_windows(&spans, options.stride, options.non_overlapping);
        let slots = models.map_or(0, |m| m.manifest.max_observers);
        let observers: Vec<usize> = observer_order(aligned).into_iter().take(slots).collect();

        // Ego pass: features and coarse poses of every window.
        let mut windows: Vec<(EgoWindow, Vec<f32>)> = Vec::with_capacity(plans.len());
        for (i, plan) in plans.iter().enumerate() {
            let window = ego_window(aligned, plan, tracking)?;
            let coarse = match options.method {
                Method::RestPose => rest_pose_window(&window),
                Method::NearestNeighbour => nearest
                    .ok_or(InferError::NoNearestNeighbourIndex { points: tracking.points() })?
                    .window_poses(&window),
                _ => coarse_pose(models.ok_or(InferError::NoModels { points: tracking.points() })?, &window)?,
            };
            windows.push((window, coarse));
            if !progress(Progress { stage: Stage::Ego, done: i + 1, total: plans.len() }) {
                return Err(InferError::Cancelled);
            }
        }

        // Fusion pass, accumulated with cross-fade weights.
        let ramp = if options.non_overlapping { 1 } else { WINDOW.saturating_sub(options.stride).max(1) };
        let n_obs = aligned.observers.len();
        let mut acc = vec![
            Accumulator {
                weight: 0.0,
                pose: vec![0.0; POSE_DIM],
                gates: vec![0.0; n_obs * EXO_KEYPOINT_COUNT],
                evidence: false
            };
            frames
        ];
        let total = windows.len();
        for (i, (window, coarse)) in windows.iter().enumerate() {
            let (poses, gates) = match models {
                Some(m) => run_fusion(aligned, m, window, coarse, &observers, options.method)?,
                None => (coarse.clone(), None),
            };
            let r_world_window = window.t_world_window.rotation;
            let plan = &window.plan;
            for t in 0..plan.len() {
                let frame = plan.frames.start + t;
                let w = crossfade_weight(
                    t,
                    plan.len(),
                    ramp,
                    plan.frames.start == plan.span.start,
                    plan.frames.end == plan.span.end,
                );
                let row = &poses[t * POSE_DIM..(t + 1) * POSE_DIM];
                let a = &mut acc[frame];
                // Root orientation: rotate the window-frame 6D columns into the world first.
                let root = Rot6d(row[0..6].try_into().unwrap_or([1.0, 0.0, 0.0, 0.0, 1.0, 0.0])).to_mat3();
                let root_world = Rot6d::from_mat3(egoexo_core::glam::Mat3::from_quat(r_world_window) * root).0;
                for (c, v) in root_world.iter().enumerate() {
                    a.pose[c] += w * v;
                }
                for (c, v) in row[6..].iter().enumerate() {
                    a.pose[6 + c] += w * v;
                }
                if let Some(g) = &gates {
                    for (slot, obs) in observers.iter().enumerate() {
                        for k in 0..EXO_KEYPOINT_COUNT {
                            let value = g[(t * observers.len() + slot) * EXO_KEYPOINT_COUNT + k];
                            a.gates[obs * EXO_KEYPOINT_COUNT + k] += w * value;
                            a.evidence |= value >= 0.5;
                        }
                    }
                }
                a.weight += w;
            }
            if !progress(Progress { stage: Stage::Fusion, done: i + 1, total }) {
                return Err(InferError::Cancelled);
            }
        }

        // Decode, recover the root from the head, fill untracked frames.
        let skeleton = aligned.skeleton.clone();
        let mut poses: Vec<Option<SmplPose>> = acc
            .iter()
            .enumerate()
            .map(|(f, a)| {
                (a.weight > 0.0).then(|| {
                    let row: Vec<f32> = a.pose.iter().map(|v| v / a.weight).collect();
                    let (root_orientation, body) = crate::inputs::decode_pose(&row);
                    let translation = skeleton.recover_translation(
                        root_orientation,
                        &body,
                        &aligned.head.poses[f],
                        aligned.head_joint_in_device,
                    );
                    SmplPose { root_orientation, body, translation }
                })
            })
            .collect();
        fill_gaps(&mut poses);
        let poses: Vec<SmplPose> = poses.into_iter().map(|p| p.unwrap_or_default()).collect();
        let joints = poses.iter().map(|p| skeleton.forward_kinematics(p).positions).collect();
        let gates = aligned
            .observers
            .iter()
            .enumerate()
            .map(|(o, obs)| ObserverGates {
                observer_id: obs.id.clone(),
                gates: acc
                    .iter()
                    .map(|a| {
                        std::array::from_fn(|k| {
                            if a.weight > 0.0 { a.gates[o * EXO_KEYPOINT_COUNT + k] / a.weight } else { 0.0 }
                        })
                    })
                    .collect(),
            })
            .collect();
        let motion = SmplMotion::new(aligned.timeline.fps, aligned.timeline.start_ns, skeleton, None, poses)
            .map_err(|e| InferError::Window(e.to_string()))?;
        Ok(Reconstruction {
            method: options.method,
            tracking,
            motion,
            joints,
            exo_evidence: acc.iter().map(|a| a.evidence).collect(),
            valid: acc.iter().map(|a| a.weight > 0.0).collect(),
            gates,
        })
    }
}

/// Observers in the order they take the networks' slots: most frames with keypoints first
/// (ties keep session order).
pub fn observer_order(aligned: &AlignedSession) -> Vec<usize> {
    let mut order: Vec<(usize, usize)> = aligned
        .observers
        .iter()
        .enumerate()
        .map(|(i, o)| (i, o.keypoints.iter().filter(|f| f.iter().any(Option::is_some)).count()))
        .collect();
    order.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    order.into_iter().map(|(i, _)| i).collect()
}

/// EgoNet's coarse pose for one window: `WINDOW × POSE_DIM`, root orientation in the window
/// frame.
pub fn coarse_pose(models: &ModelSet, window: &EgoWindow) -> Result<Vec<f32>, InferError> {
    coarse_pose_with(&models.egonet, window)
}

/// [`coarse_pose`] with a given EgoNet model (e.g. one not yet in a model set).
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

/// Runs gate and fusion for one window; returns the window-frame poses and, for exo methods,
/// the `[T, N, K]` gate values (0 for invalid rays).
fn run_fusion(
    aligned: &AlignedSession,
    models: &ModelSet,
    window: &EgoWindow,
    coarse: &[f32],
    observers: &[usize],
    method: Method,
) -> Result<(Vec<f32>, Option<Vec<f32>>), InferError> {
    let slots = models.manifest.max_observers;
    let coarse_world = world_poses(window, coarse, &aligned.skeleton, aligned.head_joint_in_device);
    let exo = exo_window(aligned, window, &coarse_world, if method.uses_exo() { observers } else { &[] }, slots);
    let gate: Vec<f32> = match method {
        Method::EgoExo => models.gate.run(&[&exo.gate_features])?.into_iter().next().unwrap_or_default(),
        _ => exo.ray_valid.clone(),
    };
    if gate.len() != exo.ray_valid.len() {
        return Err(InferError::Model {
            model: models.gate.name().to_string(),
            message: format!("gate output has {} values", gate.len()),
        });
    }
    let gate: Vec<f32> = gate.iter().zip(&exo.ray_valid).map(|(g, v)| g * v).collect();
    let exo_input = fusion_exo_input(&exo, &gate);
    let out = models.fusion.run(&[&window.ego, coarse, &exo_input, &exo.observer_mask])?;
    let poses = concat_pose(models.fusion.name(), &out)?;
    // Report gates per used slot only.
    let used = observers.len().min(slots);
    let mut reported = vec![0.0; WINDOW * used * EXO_KEYPOINT_COUNT];
    for t in 0..WINDOW {
        for s in 0..used {
            for k in 0..EXO_KEYPOINT_COUNT {
                reported[(t * used + s) * EXO_KEYPOINT_COUNT + k] = gate[exo.index(t, s, k)];
            }
        }
    }
    Ok((poses, method.uses_exo().then_some(reported)))
}

/// Frames without a reconstruction take the nearest reconstructed frame's pose.
fn fill_gaps(poses: &mut [Option<SmplPose>]) {
    let mut last = None;
    for p in poses.iter_mut() {
        match p {
            Some(v) => last = Some(*v),
            None => *p = last,
        }
    }
    let mut next = None;
    for p in poses.iter_mut().rev() {
        match p {
            Some(v) => next = Some(*v),
            None => *p = next,
        }
    }
}
