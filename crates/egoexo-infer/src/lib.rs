//! The egoexo reconstruction engine.
//!
//! - [`windows`] — valid spans, 96-frame windows, cross-fade weights.
//! - [`inputs`] — the networks' input tensors from an aligned session (shared with the
//!   training shards): ego features, coarse poses, rays, gate features, masks, targets.
//! - [`models`] — ONNX models loaded from bytes and run by tract.
//! - [`manifest`] — `models/manifest.json`.
//! - [`baselines`] — rest pose and nearest neighbour.
//! - [`pipeline`] — [`Engine::reconstruct`]: aligned session → [`Reconstruction`].
//! - [`scene`] — the viewer's [`egoexo_scene::SceneData`] from a reconstruction.
//!
//! Nothing here does I/O (models arrive as bytes), spawns threads or reads the clock, so the
//! same engine runs in the browser's Web Worker.

pub mod baselines;
pub mod inputs;
pub mod manifest;
pub mod models;
pub mod pipeline;
pub mod scene;
pub mod windows;

pub use pipeline::{Engine, Method, ObserverGates, Progress, ReconstructOptions, Reconstruction, Stage};

use thiserror::Error;

/// Errors from the engine.
#[derive(Debug, Error)]
pub enum InferError {
    #[error("{0}")]
    Manifest(String),
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
    #[error("3-point tracking needs both wrist trajectories, and this session lacks them")]
    MissingWrists,
    #[error("the wearer's head is never tracked on the timeline: nothing to reconstruct")]
    NoValidFrames,
    #[error("window: {0}")]
    Window(String),
    #[error("ego features: {0}")]
    Features(#[from] egoexo_core::ego_features::FeatureError),
    #[error("cancelled")]
    Cancelled,
}
