//! The egoexo reconstruction engine: an [`AlignedSession`](egoexo_core::aligned::AlignedSession)
//! in, SMPL motion out, in named passes.
//!
//! Modules bottom up, each importing only modules listed before it (no circle: checked by
//! `cargo xtask test`, `xtask/src/modules.rs`): `windows`, `timing`, `plan`, `inputs`,
//! `manifest`, `models`, `detector`, `baselines`, `passes`, `reconstruction`, `decode`,
//! `engine`, `job`, `coarse`, `cost`.
//!
//! - [`reconstruction`] — what a reconstruction is: [`Method`], [`ReconstructOptions`],
//!   [`Progress`], and the [`Reconstruction`] it returns.
//! - [`engine`] — [`Engine`] (the loaded networks and baselines) and [`LoadedModels`];
//!   [`job`] runs it ([`Engine::reconstruct`]).
//! - [`plan`] — the tracking mode (decided once, [`plan::resolve_tracking`]), tracked spans,
//!   windows and observer slots of a reconstruction.
//! - [`passes`] — one window at a time: the ego pass (ego features → EgoNet's coarse pose),
//!   the exo pass (regions → canonical rays → gate features → gate) and the fusion pass, with
//!   the types between them.
//! - [`decode`] — window outputs cross-faded into frames, rotated into the world, root
//!   translation from the head by FK; frames out as soon as they are final.
//! - [`job`] — [`ReconstructionJob`]: the passes as a resumable computation, one window per
//!   step, several methods sharing one ego pass.
//! - [`windows`] — valid spans, 96-frame windows, cross-fade weights.
//! - [`inputs`] — the networks' input tensors (shared with the training shards): ego
//!   features, coarse poses, rays, gate features, masks, targets.
//! - [`models`] — ONNX models loaded from bytes and run by tract; [`manifest`] —
//!   `models/manifest.json` (the detector's entry included).
//! - [`baselines`] — rest pose and nearest neighbour.
//! - [`coarse`] — EgoNet's coarse body on a few chosen windows (for steps before the
//!   reconstruction, such as registering observers).
//! - [`timing`] — time per stage, with a clock the caller passes in; [`cost`] — FLOPs per
//!   network run and a plain matrix-product probe of the same shapes.
//!
//! Nothing here does I/O (models arrive as bytes), spawns threads or reads the clock, so the
//! same engine runs in the browser's Web Worker.

pub mod baselines;
pub mod coarse;
pub mod cost;
pub mod decode;
pub mod detector;
pub mod engine;
pub mod inputs;
pub mod job;
pub mod manifest;
pub mod models;
pub mod passes;
pub mod plan;
pub mod reconstruction;
pub mod timing;
pub mod windows;

pub use coarse::CoarseBody;
pub use detector::{CropKeypoint, DetectorManifest, KeypointDetector};
pub use engine::{Engine, LoadedModels};
pub use job::{ChunkOutputs, ReconstructionJob};
pub use models::NetworkRuns;
pub use reconstruction::{Method, ObserverGates, Progress, ReconstructOptions, Reconstruction, Stage};
pub use timing::{Clock, StageTimer, StageTimings, TimedStage};

use thiserror::Error;

/// Errors from the engine.
#[derive(Debug, Error)]
pub enum InferError {
    #[error(transparent)]
    Manifest(#[from] crate::manifest::ManifestError),
    #[error("model `{model}`: {message}")]
    Model { model: String, message: String },
    #[error("model file `{file}` does not match the manifest: sha256 {actual}, expected {expected}")]
    Checksum { file: String, expected: String, actual: String },
    #[error("cannot read model file `{file}`: {message}")]
    ReadModel { file: String, message: String },
    #[error("no {points}-point models are loaded")]
    NoModels { points: u8 },
    #[error("no nearest-neighbour index for {points}-point tracking")]
    NoNearestNeighbourIndex { points: u8 },
    #[error("3-point tracking needs a wrist trajectory (devices or hand tracking), and this session has none")]
    MissingWrists,
    #[error("the wearer's head is never tracked on the timeline: nothing to reconstruct")]
    NoValidFrames,
    #[error("window: {0}")]
    Window(#[from] crate::windows::WindowError),
    #[error("ego features: {0}")]
    Features(#[from] egoexo_core::ego_features::FeatureError),
    #[error("methods: no method to run")]
    NoMethod,
    #[error("methods: {first} and {other} take their coarse poses from different sources and cannot share an ego pass")]
    CoarseSourcesDiffer { first: crate::reconstruction::Method, other: crate::reconstruction::Method },
    #[error("cancelled")]
    Cancelled,
    /// A chunk's outputs computed elsewhere (another worker) that do not fit the job, or
    /// whose bytes do not decode.
    #[error("window chunk {chunk}: {message}")]
    Chunk { chunk: usize, message: String },
    /// Bytes handed over as a chunk's outputs that do not decode as any.
    #[error("{bytes} bytes are not a chunk's window outputs: {message}")]
    ChunkBytes { bytes: usize, message: String },
}
