//! Training data and evaluation on simulated sessions.
//!
//! - [`shards`] — the networks' exact inputs and targets for PyTorch (`egoexo synth --shards`).
//! - [`eval`] — the paper's metric tables through the reconstruction engine (`egoexo eval`).
//! - [`group`] — captures of several participants: association error and per-participant
//!   MPJPE on simulated group scenes (`egoexo eval-group`).
//!
//! Both start from the CMU motion library (`egoexo-mocap`), simulate wearers and observers
//! (`egoexo-synth`), align (`egoexo-session`) and compute every feature with the engine's own
//! code (`egoexo-infer`), so training, evaluation and the app see identical inputs.

pub mod eval;
pub mod group;
pub mod registration;
pub mod shards;
mod table;

use thiserror::Error;

/// Errors making shards or evaluating.
#[derive(Debug, Error)]
pub enum DatasetError {
    #[error("{0}")]
    Options(String),
    #[error("motion library: {0}")]
    Library(String),
    #[error("simulation: {0}")]
    Simulate(String),
    #[error("the fusion stage needs a trained EgoNet (--models)")]
    NeedEgoNet,
    #[error("simulated session has no ground truth")]
    NoGroundTruth,
    #[error("{method}: {message}")]
    Reconstruct { method: String, message: String },
    #[error("metrics: {0}")]
    Metrics(#[from] egoexo_core::metrics::MetricsError),
    #[error("writing shards: {0}")]
    Write(String),
}
