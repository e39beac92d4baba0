//! Simulated ego-exo sessions from real motion.
//!
//! No public dataset pairs ego and exo streams, so egoexo makes its own: CMU motion retargeted
//! to SMPL (see `egoexo-mocap`) drives a wearer whose glasses (and wrist devices) are tracked
//! with realistic SLAM noise, watched by observers whose Aria RGB cameras yield 2D keypoint
//! detections — noisy, truncated, missed, and fooled by furniture and bystanders. Everything
//! is deterministic from a seed (ChaCha8), natively and in wasm.
//!
//! - [`config`] — parameters with realistic defaults.
//! - [`devices`] — wearer devices from the body; tracking noise (jitter + drift).
//! - [`observers`] — observer placement, walking, head tracking with saccades and look-aways.
//! - [`scene`] — occluders: furniture boxes and walking bystanders.
//! - [`detector`] — the 2D keypoint detector model.
//! - [`cameras`] — Aria RGB (Fisheye624) and pinhole presets.
//! - [`simulate`] — a full `Session` with ground truth and occlusion labels.
//! - [`group`] — a `Capture` of 2–3 participants who look at each other, with bystanders;
//!   every camera's people without identity (for association).
//! - [`procedural`] — a procedural walking motion for tests and examples.
//! - [`video`] — observer video frames of the wearer's body, for the detector step's tests.

pub mod cameras;
pub mod config;
pub mod detector;
pub mod devices;
pub mod group;
pub mod observers;
pub mod procedural;
pub mod rng;
pub mod scene;
pub mod simulate;
pub mod video;
pub mod worlds;

pub use config::SynthConfig;
pub use simulate::{ObserverReport, SimulatedSession, SynthError, simulate};
