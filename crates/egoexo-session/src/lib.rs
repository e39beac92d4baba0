//! Sessions in, motion out.
//!
//! - [`model`] — the in-memory session (wearer, observers, keypoints, subject, ground truth).
//! - [`import`] — recognises an input and imports it: [`format`] (`.egoexo`), Nymeria, Aria
//!   MPS (one device or the multi-device layout); [`import::import_session`] is the entry.
//! - [`format`] — the native `.egoexo` format: reader and writer (`docs/session-format.md`).
//! - [`aria`] — Aria conventions and MPS files (`closed_loop_trajectory.csv`,
//!   `online_calibration.jsonl`, `time_sync.csv`).
//! - [`keypoints`] — exo keypoint files: JSON lines (read/write) and COCO JSON (read).
//! - [`npz`] — checked `.npz` reading and writing.
//! - [`vfs`] — [`vfs::FileTree`]: in-memory files, zip archives, and (native) folders.
//! - [`validate`] — the session invariants; [`error`] — errors naming file, line/field and
//!   what was expected.
//! - [`align`] — every stream resampled onto one timeline.
//! - [`bvh`] — a general BVH (Biovision hierarchy) reader and writer.
//! - [`export`] — motion exporters: AMASS-style npz, BVH, glTF binary, joint-position CSV.
//!
//! Everything works on in-memory bytes so the browser's worker can use it; path helpers are
//! native-only.

pub mod align;
pub mod aria;
pub mod bvh;
pub mod error;
pub mod export;
pub mod format;
pub mod import;
mod json;
pub mod keypoints;
pub mod model;
pub mod npz;
pub mod validate;
pub mod vfs;

pub use align::{AlignError, AlignOptions, AlignedSession, align};
pub use error::{ImportError, ImportErrorKind, ImportWarning, Location};
pub use import::{ImportOptions, Imported, SourceKind, import_session};
pub use model::Session;
pub use vfs::{FileTree, Limits};
