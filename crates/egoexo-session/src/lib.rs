//! Sessions in: recognise a recording, import it into the one session model, check it, and
//! align its streams on one timeline. (Motion files out — BVH, AMASS npz, glb, CSV — are
//! `egoexo-motion-io`'s.)
//!
//! - [`model`] — the in-memory session (wearer, observers, keypoints, subject, ground truth).
//! - [`capture`] — several participants in one recording: each one's devices and body, what
//!   each camera saw (assigned or not yet); [`capture::Capture::session_for`] makes one
//!   participant's session.
//! - [`import`] — recognises an input and imports it: [`format`](mod@format) (`.egoexo`), Nymeria, Aria
//!   MPS (one device or the multi-device layout); [`import::import_session`] is the entry.
//! - [`format`](mod@format) — the native `.egoexo` format: reader and writer (`docs/session-format.md`).
//! - [`aria`] — Aria conventions and MPS files (`closed_loop_trajectory.csv`,
//!   `online_calibration.jsonl`, `time_sync.csv`, hand tracking, semidense points).
//! - [`floor`] — the floor's height: from semidense points, or from the standing head.
//! - [`placement`] — an observer's world, clock and mount against the session's, and what
//!   registration found.
//! - [`live`] — a live take: frames received from the relay gathered into a session.
//! - [`keypoints`] — exo keypoint files: JSON lines (read/write) and COCO JSON (read).
//! - [`npz`] — checked `.npz` reading (writing is `egoexo_motion_io::npz`).
//! - [`vfs`] — [`vfs::FileTree`]: in-memory files, zip archives, and (native) folders.
//! - [`validate`] — the session invariants; [`error`] — errors naming file, line/field and
//!   what was expected.
//! - [`align`](mod@align) — every stream resampled onto one timeline: an
//!   `egoexo_core::aligned::AlignedSession`, the engine's input.
//!
//! Everything works on in-memory bytes so the browser's worker can use it; path helpers are
//! native-only.

pub mod align;
pub mod aria;
pub mod capture;
pub mod error;
pub mod floor;
pub mod format;
pub mod import;
mod json;
pub mod keypoints;
pub mod live;
pub mod model;
pub mod npz;
pub mod placement;
pub mod validate;
pub mod vfs;
pub mod video;

pub use align::{AlignError, AlignOptions, align};
pub use error::{ImportError, ImportErrorKind, ImportWarning, Location};
pub use import::{ImportOptions, Imported, SourceKind, import_session};
pub use model::Session;
pub use vfs::{FileTree, Limits};
