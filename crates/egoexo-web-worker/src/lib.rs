//! The browser's Web Worker side of egoexo (the only wasm module with tract in it).
//!
//! - [`worker`] — [`SessionWorker`]: load the models (sha256-checked), import a session
//!   (`.egoexo`, a zip, or a dropped folder of an Aria MPS / Nymeria layout), reconstruct it
//!   step by step (ego-exo plus the ego-only overlay, one shared ego pass), build the
//!   viewer's scene, export the motion (AMASS npz, BVH, glb, CSV). Plain Rust; the native
//!   tests drive it directly.
//! - [`detection`] — the detector step: observers' video frames, cropped to the region
//!   EgoNet's coarse pose proposes, through the keypoint detector into the session (the
//!   runtime decodes with WebCodecs).
//! - [`scene`] — the viewer's [`egoexo_scene::SceneData`] from the aligned session and its
//!   reconstructions.
//! - `runtime` (wasm32 only) — `WorkerApp`, the message loop: requests and events of the
//!   page ↔ worker protocol (`egoexo_protocol::worker`, `docs/worker-protocol.md`), model
//!   fetching with the Cache API, cooperative cancel between windows, panic reporting.
//!
//! - [`pool`] — a pool of workers sharing one reconstruction: the session handed to helpers,
//!   chunk sizes, and [`pool::ChunkSchedule`] (who computes which chunk; decoding in order).
//! - [`coordinator`] — the pool's roles as state machines the runtime and the native tests
//!   both drive: [`coordinator::PoolCoordinator`] (one pooled job) and
//!   [`coordinator::PoolHelper`] (a helper's answers).
//! - [`bench`] — the bench page's network probe (`NetworkBench` in JS): one network on
//!   deterministic inputs, its FLOPs and a matrix-product probe, timed by the page.
//! - [`live`] — [`live::LiveReconstructor`]: a take streaming in from the live relay,
//!   reconstructed window by window at a chosen lookahead, one frame to draw at a time.
//! - [`xr`] — the WebXR page's (`web/xr.html`) poses, frames and messages of the live
//!   protocol (exported to JS as `xr_pose_frame`, `XrJoin`, …).
//! - [`observe`] — the observer page's (`web/observe.html`) hello and calibration of a static
//!   camera, and [`observe::LiveDetector`]: each camera frame's crop, the detector, the
//!   keypoints frame (exported to JS as `LiveDetector`, `observeCalibration`, …).
//!
//! `web/worker.js` only creates the `WorkerApp` and hands it the page's messages. Nothing
//! here reads the clock or spawns threads; timing belongs to the page.

pub mod bench;
pub mod coordinator;
pub mod detection;
pub mod live;
pub mod observe;
pub mod pool;
#[cfg(target_arch = "wasm32")]
mod runtime;

/// A page's time in nanoseconds since the epoch, as JS gives it (an f64), as an integer:
/// `None` when it is not finite or does not fit an i64 (2^63 is exactly representable; anything
/// at or beyond it does not fit). The device pages' (WebXR, observer) one conversion.
pub(crate) fn page_time_ns(ns: f64) -> Option<i64> {
    (ns.is_finite() && ns.abs() < 9_223_372_036_854_775_808.0).then(|| ns.round() as i64)
}
pub mod scene;
pub mod worker;
pub mod xr;

#[cfg(target_arch = "wasm32")]
pub use runtime::{MODEL_CACHE, TEST_PANIC_MESSAGE, WorkerApp};
pub use worker::{
    ExportedFile, JobProgress, PoolHelperJob, ReconstructionTask, SelectedParticipant, SessionWorker, WorkerClock,
    WorkerError,
};
