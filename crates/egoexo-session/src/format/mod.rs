//! The native session format, `.egoexo`: a zip archive (or the same files as a plain folder)
//! with a versioned `session.json` manifest and data files. Specified, with a JSON Schema and
//! an example, in `docs/session-format.md`.
//!
//! ```text
//! session.json                                  manifest (format "egoexo-session"; version 2 for one wearer, 1 is read)
//! wearer/head/closed_loop_trajectory.csv        trajectories: the Aria MPS CSV layout
//! wearer/left_wrist/closed_loop_trajectory.csv  (optional)
//! wearer/right_wrist/closed_loop_trajectory.csv (optional)
//! observers/<id>/closed_loop_trajectory.csv    a worn observer (a static camera has `pose`, or
//!                                               none and a `placement`, in the manifest)
//! observers/<id>/keypoints.jsonl                (optional) JSON-lines keypoints
//! observers/<id>/context_features.npz           (optional) timestamps_ns (N,), values (N, D)
//! ground_truth.npz                              (optional) SMPL motion + occlusion labels
//! ```
//! A capture of several participants ([`crate::capture::Capture`]) is manifest version 3:
//! `participants/<id>/…` and `views/<observer>/…` instead of `wearer/` and `observers/`
//! ([`write_capture_files`], [`read_capture`]; every version reads as a capture).
//!
//! Modules: this one reads the manifest's header and dispatches on its version; `manifest`
//! holds one typed struct per version (their fields are the manifest's keys, in one place:
//! the writer fills and serialises them, the reader deserialises them and warns about any
//! other key); `session` reads and writes versions 1–2 (one wearer), `capture` version 3;
//! `read` and `write` hold the entries every version shares (trajectories, cameras,
//! placements, videos, context features, ground truth).
//!
//! Everything is in session conventions: Y-up world, metres, CPF head-device frames,
//! nanoseconds on one clock. The manifest names every data file, so the layout above is what
//! the writer produces, not something the reader assumes.
//!
//! `ground_truth.npz` arrays: `fps` (1,) f32; `start_ns` (1,) i64; `rest_joints` (24, 3) f32,
//! metres, SMPL body frame; `betas` (B,) f32 (optional); `root_orientation_xyzw` (N, 4) f32;
//! `body_rotations_xyzw` (N, 21, 4) f32 (joints 1..=21, local to their parents);
//! `translation` (N, 3) f32 (SMPL `transl`: pelvis = rest pelvis + translation); `occluded`
//! (O, N) u16 (optional; bit k = exo keypoint k occluded, rows in the order of the manifest's
//! `ground_truth.occlusion_observers`). Quaternions are stored, not axis-angle, so a
//! write → read round trip is exact.

use serde_json::Value;
use thiserror::Error;

use crate::capture::{Capture, CaptureError, ViewPeople};
use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::json::JsonCtx;
use crate::model::Session;
use crate::vfs::FileTree;

mod capture;
mod manifest;
mod read;
mod session;
mod write;

#[cfg(not(target_arch = "wasm32"))]
pub use capture::save_capture;
pub use capture::{MAX_PARTICIPANTS, write_capture_files, write_capture_zip};
pub use session::{
    STATIC_CAMERA_FILE, read_static_camera, write_egoexo_files, write_egoexo_zip, write_egoexo_zip_with,
};
#[cfg(not(target_arch = "wasm32"))]
pub use session::{save_egoexo, save_egoexo_with};

/// The manifest's file name.
pub const MANIFEST_FILE: &str = "session.json";
/// The manifest's `format` value.
pub const FORMAT_NAME: &str = "egoexo-session";
/// The manifest version this build writes for a one-wearer session. Version 2 added the
/// optional `floor` and `wearer.wrist_source` fields; version 1 files (without them) are read
/// too.
pub const FORMAT_VERSION: u32 = 2;
/// The manifest version of a capture of several participants ([`Capture`]): `participants`
/// and `views` instead of `wearer` and `observers`. Every older version reads as a capture
/// too ([`read_capture`]).
pub const CAPTURE_FORMAT_VERSION: u32 = 3;
/// The oldest manifest version this build reads.
pub const MIN_FORMAT_VERSION: u32 = 1;
/// Largest accepted angle between a session trajectory's gravity and −Y, degrees (session
/// worlds are Y-up by definition).
pub const MAX_SESSION_GRAVITY_TILT_DEG: f32 = 1.0;

/// Why a session could not be written.
#[derive(Debug, Error)]
pub enum WriteError {
    /// The session fails validation.
    #[error("the session is invalid: {0}")]
    Invalid(#[from] ImportError),
    /// The capture's participants and views do not fit together.
    #[error("the capture is invalid: {0}")]
    InvalidCapture(#[from] CaptureError),
    /// Building an archive failed.
    #[error("could not build {what}: {message}")]
    Encode { what: String, message: String },
    /// Writing to disk failed (native only).
    #[error("could not write {path}: {source}")]
    Io { path: String, source: std::io::Error },
}

/// The manifest of a `.egoexo` rooted at `root`, parsed, with its checked version.
fn read_manifest_header(root: &FileTree) -> Result<(String, Value, u64), ImportError> {
    let manifest_file = root.display_path(MANIFEST_FILE);
    let ctx = JsonCtx::file(&manifest_file);
    let text = root.read_text(MANIFEST_FILE)?;
    if text.trim().is_empty() {
        return Err(ImportError::new(
            &manifest_file,
            Location::File,
            ImportErrorKind::Empty { expected: "the session manifest (JSON)".into() },
        ));
    }
    let doc = ctx.parse(&text)?;
    let format = ctx.field(&doc, "", "format")?;
    if format.as_str() != Some(FORMAT_NAME) {
        return Err(ctx.invalid("format", format!("\"{FORMAT_NAME}\""), format));
    }
    let version = ctx.field(&doc, "", "version")?;
    let unsupported = |got: String| {
        ctx.error(
            "version",
            ImportErrorKind::UnsupportedVersion { got, oldest: MIN_FORMAT_VERSION, newest: CAPTURE_FORMAT_VERSION },
        )
    };
    let version = match version.as_u64() {
        Some(v) if (u64::from(MIN_FORMAT_VERSION)..=u64::from(CAPTURE_FORMAT_VERSION)).contains(&v) => v,
        Some(v) => return Err(unsupported(v.to_string())),
        None => return Err(unsupported(crate::json::describe(version))),
    };
    let conventions = ctx.field(&doc, "", "conventions")?;
    let expected = manifest::Conventions::session();
    if serde_json::from_value::<manifest::Conventions>(conventions.clone()).ok().as_ref() != Some(&expected) {
        return Err(ctx.invalid("conventions", expected.to_string(), conventions));
    }
    Ok((manifest_file, doc, version))
}

/// Reads a `.egoexo` session (zip or folder) rooted at `root`. A capture of several
/// participants (version 3) reads as a session when it has exactly one participant to
/// reconstruct and every view is assigned; otherwise [`read_capture`] reads it.
pub fn read_egoexo(root: &FileTree) -> Result<(Session, Vec<ImportWarning>), ImportError> {
    let (manifest_file, doc, version) = read_manifest_header(root)?;
    if version >= u64::from(CAPTURE_FORMAT_VERSION) {
        let (capture, warnings) = capture::read_capture_manifest(root, &manifest_file, &doc)?;
        return Ok((single_session(&manifest_file, &capture)?, warnings));
    }
    session::read_session_manifest(root, &manifest_file, &doc)
}

/// The manifest version of the `.egoexo` rooted at `root` (checked to be one this build reads).
pub fn manifest_version(root: &FileTree) -> Result<u64, ImportError> {
    Ok(read_manifest_header(root)?.2)
}

/// The one session a capture stands for: its only participant to reconstruct, with every
/// view assigned.
pub fn single_session(file: &str, capture: &Capture) -> Result<Session, ImportError> {
    let reconstructed: Vec<usize> = capture.reconstructed().collect();
    let [participant] = reconstructed[..] else {
        return Err(ImportError::invalid(
            file,
            Location::Field("participants".into()),
            "exactly one participant to reconstruct for a one-wearer session (a capture of several is reconstructed participant by participant)",
            format!("{} participants to reconstruct", reconstructed.len()),
        ));
    };
    if let Some(index) = capture.views.iter().position(|v| matches!(v.people, ViewPeople::Unassigned(_))) {
        return Err(ImportError::invalid(
            file,
            Location::Field(format!("views[{index}]")),
            "keypoints assigned to a participant (people without identity need association first)",
            "people without identity",
        ));
    }
    capture.session_for(participant).map_err(|e| {
        ImportError::invalid(file, Location::Field("participants".into()), "a valid capture", e.to_string())
    })
}

/// Reads a `.egoexo` (zip or folder) rooted at `root` as a capture: version 3 as written,
/// older versions as their one wearer plus observers ([`Capture::from_session`]).
pub fn read_capture(root: &FileTree) -> Result<(Capture, Vec<ImportWarning>), ImportError> {
    let (manifest_file, doc, version) = read_manifest_header(root)?;
    if version >= u64::from(CAPTURE_FORMAT_VERSION) {
        return capture::read_capture_manifest(root, &manifest_file, &doc);
    }
    let (session, warnings) = session::read_session_manifest(root, &manifest_file, &doc)?;
    Ok((Capture::from_session(&session), warnings))
}
