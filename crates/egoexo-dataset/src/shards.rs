//! Training shards: the networks' exact inputs and targets, computed by the same Rust code the
//! engine runs (`egoexo_infer::inputs`), written as `.npz` files PyTorch reads with numpy.
//!
//! Two stages, as the paper trains:
//! - **ego** — for EgoNet: `ego [W,T,62]`, `target [W,T,132]`, `frame_mask [W,T]`,
//!   `rest_joints [W,24,3]`, and `subject`, `clip`, `start` `[W]` (int32).
//! - **fusion** — everything of the ego stage plus, from a trained EgoNet run by tract:
//!   `egonet [W,T,132]`, `rays [W,T,N,K,3]` (wearer head frame), `ray_offsets [W,T,N,K,3]`
//!   (window frame, [`egoexo_infer::inputs`]), `ray_valid [W,T,N,K]`,
//!   `gate_features [W,T,N,K,F]`, `observer_mask [W,T,N]`, and the simulator's labels
//!   `occluded [W,T,N,K]` (1 = the keypoint was hidden by furniture or a bystander) and
//!   `ray_error [W,T,N,K]` (metres: how far the detection's viewing ray passes from the true
//!   keypoint, 0 where there is no valid ray) — labels for training and diagnostics only.
//!
//! Poses are 6D (first two matrix columns) with the root orientation in the window frame;
//! positions in metres. `index.json` lists the shards and records the layouts, options and
//! the EgoNet checksum used. The writer returns bytes; the caller stores them.

use egoexo_core::TrackingMode;
use egoexo_core::aligned::AlignedSession;
use egoexo_core::ego_features::EGO_FEATURE_DIM;
use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_core::gate_features::{GATE_FEATURE_DIM, GATE_FEATURE_LAYOUT_VERSION};
use egoexo_core::glam::Vec3;
use egoexo_core::skeleton::NUM_JOINTS;
use egoexo_infer::inputs::{POSE_DIM, ego_window, exo_window, window_targets, world_poses};
use egoexo_infer::models::OnnxModel;
use egoexo_infer::passes::coarse_pose_with;
use egoexo_infer::plan::observer_order;
use egoexo_infer::windows::{WINDOW, plan_windows, valid_spans};
use egoexo_mocap::MotionLibrary;
use egoexo_motion_io::npz::{NpzWriteError, NpzWriter};
use egoexo_session::align::{AlignOptions, align};
use egoexo_synth::config::{HandTrackingModel, WristTracking};
use egoexo_synth::{SynthConfig, simulate};
use serde::{Deserialize, Serialize};

use crate::DatasetError;

/// Version of the shard format. v2 added `ray_offsets`; v3 low-passed `rays` and
/// `ray_offsets` over each keypoint's detections (exo token layout v3); v4 stores them raw
/// again, per frame (exo token layout v4: the fusion graph does the gate-weighted low-pass),
/// and adds the `ray_error` labels; v5 carries ego feature layout v2 (62 numbers: wrist
/// validity) and may mix wrist devices with hand tracking (`options.wrists`).
pub const SHARD_FORMAT_VERSION: u32 = 5;

/// Which networks the shards train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShardStage {
    Ego,
    Fusion,
}

/// How a simulated 3-point wearer's wrists are tracked.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WristKind {
    /// Wrist devices on every frame.
    #[default]
    Devices,
    /// The glasses' hand tracking: wrists only while in view (Aria MPS).
    HandTracking,
    /// Both, alternately (by clip, mirror and simulation number): training data for a model
    /// that takes either.
    Mixed,
}

impl WristKind {
    /// The simulator's setting for the simulation numbered `index` (`Mixed` alternates on
    /// its parity).
    pub fn for_simulation(self, index: u64) -> WristTracking {
        match self {
            WristKind::Devices => WristTracking::Devices,
            WristKind::HandTracking => WristTracking::HandTracking(HandTrackingModel::default()),
            WristKind::Mixed if index % 2 == 1 => WristTracking::HandTracking(HandTrackingModel::default()),
            WristKind::Mixed => WristTracking::Devices,
        }
    }

    /// In words, for table titles.
    pub fn describe(self) -> &'static str {
        match self {
            WristKind::Devices => "wrist devices",
            WristKind::HandTracking => "hand-tracking wrists",
            WristKind::Mixed => "wrist devices and hand tracking",
        }
    }
}

/// How to make shards.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShardOptions {
    pub tracking: TrackingMode,
    /// How 3-point wrists are simulated.
    #[serde(default)]
    pub wrists: WristKind,
    /// Observer slots `N` of the fusion network.
    pub max_observers: usize,
    /// Observers simulated per session, uniform in this inclusive range (each session draws).
    pub observers: (usize, usize),
    /// Independent simulations of every clip (different devices noise, observers, scenes).
    pub simulations_per_clip: usize,
    /// Frames between consecutive training windows.
    pub stride: usize,
    pub seed: u64,
    /// Windows per `.npz` file.
    pub windows_per_shard: usize,
    /// Also simulate every clip mirrored left↔right (doubles the motions).
    pub mirror: bool,
}

impl Default for ShardOptions {
    fn default() -> Self {
        Self {
            tracking: TrackingMode::ThreePoint,
            wrists: WristKind::Devices,
            max_observers: 3,
            observers: (1, 3),
            simulations_per_clip: 3,
            stride: 24,
            seed: 7,
            windows_per_shard: 512,
            mirror: true,
        }
    }
}

/// One shard file in the index.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShardEntry {
    pub file: String,
    pub windows: usize,
}

/// `index.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShardIndex {
    pub format_version: u32,
    pub stage: ShardStage,
    pub window: usize,
    pub fps: f32,
    pub pose_dim: usize,
    pub ego_feature_layout_version: u32,
    pub gate_feature_layout_version: u32,
    pub gate_feature_dim: usize,
    pub keypoints: usize,
    pub options: ShardOptions,
    pub subjects: Vec<u32>,
    pub clips: Vec<String>,
    /// sha256 of the EgoNet that produced the fusion stage's coarse poses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub egonet_sha256: Option<String>,
    pub shards: Vec<ShardEntry>,
    pub windows: usize,
    pub frames_simulated: usize,
}

#[derive(Default)]
struct Buffer {
    windows: usize,
    ego: Vec<f32>,
    target: Vec<f32>,
    frame_mask: Vec<f32>,
    rest_joints: Vec<f32>,
    subject: Vec<i32>,
    clip: Vec<i32>,
    start: Vec<i32>,
    egonet: Vec<f32>,
    rays: Vec<f32>,
    ray_offsets: Vec<f32>,
    ray_valid: Vec<f32>,
    gate_features: Vec<f32>,
    observer_mask: Vec<f32>,
    occluded: Vec<f32>,
    ray_error: Vec<f32>,
}

impl Buffer {
    fn finish(&mut self, stage: ShardStage, slots: usize) -> Result<Vec<u8>, DatasetError> {
        let w = self.windows as u64;
        let t = WINDOW as u64;
        let n = slots as u64;
        let k = EXO_KEYPOINT_COUNT as u64;
        let mut npz = NpzWriter::new();
        let io = |e: NpzWriteError| DatasetError::Write(e.to_string());
        npz.add("ego", &[w, t, EGO_FEATURE_DIM as u64], &self.ego).map_err(io)?;
        npz.add("target", &[w, t, POSE_DIM as u64], &self.target).map_err(io)?;
        npz.add("frame_mask", &[w, t], &self.frame_mask).map_err(io)?;
        npz.add("rest_joints", &[w, NUM_JOINTS as u64, 3], &self.rest_joints).map_err(io)?;
        npz.add("subject", &[w], &self.subject).map_err(io)?;
        npz.add("clip", &[w], &self.clip).map_err(io)?;
        npz.add("start", &[w], &self.start).map_err(io)?;
        if stage == ShardStage::Fusion {
            npz.add("egonet", &[w, t, POSE_DIM as u64], &self.egonet).map_err(io)?;
            npz.add("rays", &[w, t, n, k, 3], &self.rays).map_err(io)?;
            npz.add("ray_offsets", &[w, t, n, k, 3], &self.ray_offsets).map_err(io)?;
            npz.add("ray_valid", &[w, t, n, k], &self.ray_valid).map_err(io)?;
            npz.add("gate_features", &[w, t, n, k, GATE_FEATURE_DIM as u64], &self.gate_features).map_err(io)?;
            npz.add("observer_mask", &[w, t, n], &self.observer_mask).map_err(io)?;
            npz.add("occluded", &[w, t, n, k], &self.occluded).map_err(io)?;
            npz.add("ray_error", &[w, t, n, k], &self.ray_error).map_err(io)?;
        }
        let bytes = npz.finish().map_err(io)?;
        *self = Buffer::default();
        Ok(bytes)
    }
}

/// Receives each file the shard writer produces (name, bytes).
pub type ShardStore<'a> = dyn FnMut(&str, Vec<u8>) -> Result<(), DatasetError> + 'a;

/// A trained EgoNet for the fusion stage: the model and its file's sha256 (recorded in the
/// index so training can check which EgoNet made its inputs).
#[derive(Clone, Copy, Debug)]
pub struct EgoNetForShards<'a> {
    pub model: &'a OnnxModel,
    pub sha256: &'a str,
}

/// Writes shards for `clips` of `library`. `egonet` is required for the fusion stage.
/// `store(name, bytes)` receives each shard file and finally `index.json`; `progress(done,
/// total)` counts clips.
pub fn write_shards(
    library: &MotionLibrary,
    clips: &[usize],
    stage: ShardStage,
    options: &ShardOptions,
    egonet: Option<EgoNetForShards<'_>>,
    store: &mut ShardStore<'_>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ShardIndex, DatasetError> {
    let models = match stage {
        ShardStage::Ego => None,
        ShardStage::Fusion => Some(egonet.ok_or(DatasetError::NeedEgoNet)?),
    };
    if options.max_observers == 0
        || options.observers.0 > options.observers.1
        || options.observers.1 > options.max_observers
    {
        return Err(DatasetError::Options(format!(
            "observers {:?} must lie within 0..={} slots",
            options.observers, options.max_observers
        )));
    }
    let slots = options.max_observers;
    let mut index = ShardIndex {
        format_version: SHARD_FORMAT_VERSION,
        stage,
        window: WINDOW,
        fps: library.fps(),
        pose_dim: POSE_DIM,
        ego_feature_layout_version: egoexo_core::ego_features::EGO_FEATURE_LAYOUT_VERSION,
        gate_feature_layout_version: GATE_FEATURE_LAYOUT_VERSION,
        gate_feature_dim: GATE_FEATURE_DIM,
        keypoints: EXO_KEYPOINT_COUNT,
        options: options.clone(),
        subjects: Vec::new(),
        clips: Vec::new(),
        egonet_sha256: models.map(|m| m.sha256.to_string()),
        shards: Vec::new(),
        windows: 0,
        frames_simulated: 0,
    };
    let mut buffer = Buffer::default();
    let mut flush = |buffer: &mut Buffer, index: &mut ShardIndex| -> Result<(), DatasetError> {
        if buffer.windows == 0 {
            return Ok(());
        }
        let name = format!("shard-{:04}.npz", index.shards.len());
        let windows = buffer.windows;
        store(&name, buffer.finish(stage, slots)?)?;
        index.shards.push(ShardEntry { file: name, windows });
        index.windows += windows;
        Ok(())
    };

    for (done, &clip) in clips.iter().enumerate() {
        let info =
            library.clips().get(clip).ok_or_else(|| DatasetError::Options(format!("no clip {clip} in the library")))?;
        if !index.subjects.contains(&info.subject) {
            index.subjects.push(info.subject);
        }
        index.clips.push(info.label());
        let motion = library.motion(clip).map_err(|e| DatasetError::Library(e.to_string()))?;
        let variants: Vec<_> = if options.mirror { vec![motion.clone(), motion.mirrored()] } else { vec![motion] };
        for (v, motion) in variants.iter().enumerate() {
            for s in 0..options.simulations_per_clip {
                let seed = mix(options.seed, clip as u64, (v * 1000 + s) as u64);
                let observers = options.observers.0 + (seed as usize % (options.observers.1 - options.observers.0 + 1));
                let config = SynthConfig {
                    tracking: options.tracking,
                    wrists: options.wrists.for_simulation(clip as u64 + (v * 1000 + s) as u64),
                    observers,
                    ..SynthConfig::default()
                };
                let sim = simulate(motion, &info.label(), &config, seed)
                    .map_err(|e| DatasetError::Simulate(e.to_string()))?;
                let aligned = align(&sim.session, &AlignOptions { fps: library.fps(), ..AlignOptions::default() })
                    .map_err(|e| DatasetError::Simulate(e.to_string()))?;
                index.frames_simulated += aligned.timeline.frames;
                add_windows(&aligned, info.subject, clip, options, models, slots, &mut buffer)?;
                if buffer.windows >= options.windows_per_shard {
                    flush(&mut buffer, &mut index)?;
                }
            }
        }
        progress(done + 1, clips.len());
    }
    flush(&mut buffer, &mut index)?;
    index.subjects.sort_unstable();
    let json = serde_json::to_vec_pretty(&index).map_err(|e| DatasetError::Write(e.to_string()))?;
    store("index.json", json)?;
    Ok(index)
}

fn add_windows(
    aligned: &AlignedSession,
    subject: u32,
    clip: usize,
    options: &ShardOptions,
    models: Option<EgoNetForShards<'_>>,
    slots: usize,
    buffer: &mut Buffer,
) -> Result<(), DatasetError> {
    let spans = valid_spans(&aligned.head.valid);
    let plans = plan_windows(&spans, options.stride, false);
    let observers = observer_order(aligned);
    let gt = aligned.ground_truth.as_ref().ok_or(DatasetError::NoGroundTruth)?;
    for plan in &plans {
        let window = ego_window(aligned, plan, options.tracking).map_err(|e| DatasetError::Simulate(e.to_string()))?;
        let Some(target) = window_targets(aligned, &window) else { continue };
        buffer.ego.extend_from_slice(&window.ego);
        buffer.target.extend_from_slice(&target);
        buffer.frame_mask.extend_from_slice(&window.frame_mask);
        buffer.rest_joints.extend(aligned.skeleton.rest_joints().iter().flat_map(|p| p.to_array()));
        buffer.subject.push(subject as i32);
        buffer.clip.push(clip as i32);
        buffer.start.push(plan.frames.start as i32);
        if let Some(models) = models {
            let coarse = coarse_pose_with(models.model, &window).map_err(|e| DatasetError::Simulate(e.to_string()))?;
            let coarse_world = world_poses(&window, &coarse, &aligned.skeleton, aligned.head_joint_in_device);
            let exo = exo_window(aligned, &window, &coarse_world, &observers, slots);
            buffer.egonet.extend_from_slice(&coarse);
            buffer.rays.extend_from_slice(&exo.rays);
            buffer.ray_offsets.extend_from_slice(&exo.ray_offsets);
            buffer.ray_valid.extend_from_slice(&exo.ray_valid);
            buffer.gate_features.extend_from_slice(&exo.gate_features);
            buffer.observer_mask.extend_from_slice(&exo.observer_mask);
            let mut occluded = vec![0.0f32; WINDOW * slots * EXO_KEYPOINT_COUNT];
            for t in 0..plan.len() {
                for (slot, observer) in exo.slot_observer.iter().enumerate() {
                    let Some(o) = observer else { continue };
                    let mask = gt.occluded.get(*o).and_then(|m| m.get(plan.frames.start + t)).copied().unwrap_or(0);
                    for k in 0..EXO_KEYPOINT_COUNT {
                        occluded[exo.index(t, slot, k)] = f32::from(u8::from(mask & (1 << k) != 0));
                    }
                }
            }
            buffer.occluded.extend_from_slice(&occluded);
            // The same rays' offsets from the true pose's keypoints instead of EgoNet's: their
            // lengths are the rays' distances from the true keypoints.
            let truth_world = world_poses(&window, &target, &aligned.skeleton, aligned.head_joint_in_device);
            let truth = exo_window(aligned, &window, &truth_world, &observers, slots);
            buffer.ray_error.extend(
                truth
                    .ray_offsets
                    .chunks_exact(3)
                    .zip(&truth.ray_valid)
                    .map(|(offset, valid)| if *valid > 0.0 { Vec3::from_slice(offset).length() } else { 0.0 }),
            );
        }
        buffer.windows += 1;
    }
    Ok(())
}

/// A seed from a base seed and two indices (SplitMix64 finaliser), so every simulation's
/// randomness depends only on its own identity.
pub fn mix(seed: u64, a: u64, b: u64) -> u64 {
    let mut z = seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
