//! The browser's Web Worker side of egoexo (the only wasm module with tract in it).
//!
//! - [`worker`] — [`SessionWorker`]: load the models (sha256-checked), import a session
//!   (`.egoexo`, a zip, or a dropped folder of an Aria MPS / Nymeria layout), reconstruct it
//!   (ego-exo plus the ego-only overlay) with progress and cancel, build the viewer's scene,
//!   export the motion (AMASS npz, BVH, glb, CSV).
//! - [`summary`] — the plain data reported to the page.
//! - `bindings` (wasm32 only) — the JS API: `WorkerApp`, `ExportedFile`,
//!   `install_panic_reporter`; errors become JS `Error`s with the Rust message verbatim.
//!
//! `web/worker.js` drives it; `web/main.js` never touches this module. Nothing here reads
//! the clock or spawns threads; timing belongs to the page.

#[cfg(target_arch = "wasm32")]
mod bindings;
pub mod summary;
pub mod worker;

#[cfg(target_arch = "wasm32")]
pub use bindings::{ExportedFileJs, WorkerApp, install_panic_reporter, panic_for_test};
pub use worker::{ExportedFile, SessionWorker, WorkerError};
