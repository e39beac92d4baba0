//! The page ↔ Web Worker protocol, version [`WORKER_PROTOCOL_VERSION`]
//! (`docs/worker-protocol.md` is the reader's version of this module).
//!
//! The page sends [`WorkerRequest`]s; the worker answers with [`WorkerEvent`]s. Both are JS
//! objects tagged by `type` (kebab-case), built and read by Rust on both ends: the page's
//! `WorkerClient` (egoexo-viewer) makes the requests, the worker's `WorkerApp`
//! (egoexo-web-worker) reads them and posts the events. The JS glue only moves them.
//!
//! Jobs: `open`, `reconstruct` and `export` carry a [`JobId`] chosen by the page; every event
//! about a job carries it back, so the page can drop the events of a job it cancelled or
//! replaced. The worker runs requests one at a time in arrival order; `cancel` is read
//! between the windows of a reconstruction, which then ends with `cancelled` instead of a
//! result (the worker and its loaded models stay).

use serde::{Deserialize, Serialize};

mod summary;

pub use summary::*;

/// The protocol's version; the worker says it in [`WorkerEvent::Ready`], and the page refuses
/// a worker that speaks another.
pub const WORKER_PROTOCOL_VERSION: u32 = 6;

/// A job's number, chosen by the page (unique per worker).
pub type JobId = u32;

/// Page → worker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(
    tag = "type",
    rename_all = "kebab-case",
    bound(serialize = "B: Serialize", deserialize = "B: Deserialize<'de>")
)]
pub enum WorkerRequest<B> {
    /// Load the models now (otherwise the first job does), while the user picks a session.
    WarmUp,
    /// Import a session (replacing the open one) and align it on the models' timeline.
    /// Answered by `imported` or `error`.
    Open { job: JobId, input: SessionInput<B> },
    /// Reconstruct the open session (ego-exo, and with `overlay` the ego-only comparison).
    /// Answered by `progress` events, then `reconstructed`, `cancelled` or `error`.
    Reconstruct { job: JobId, overlay: bool },
    /// Write the last reconstruction as a motion file. Answered by `exported` or `error`.
    Export { job: JobId, format: ExportFormat },
    /// Pack what is shown into a share container (with the recording when
    /// `include_recording` and a session is open) and seal it under a fresh random key.
    /// Answered by `share-sealed` or `error`.
    CreateShare { job: JobId, include_recording: bool },
    /// Open a sealed share with the key from its link: show it, and open its recording if it
    /// has one. Answered by `share-opened` or `error` (kind `share-invalid` for a wrong key or
    /// an altered share).
    OpenShare { job: JobId, sealed: B, key: String },
    /// Stop job `job`: a queued job never starts, a running reconstruction stops at its next
    /// window; either answers `cancelled`. A finished job is not affected.
    Cancel { job: JobId },
    /// Watch a live room (`docs/live-protocol.md`): connect to the relay at `url`
    /// (`ws(s)://host/live`) with the room's viewer secret and reconstruct what streams in,
    /// reading each frame out `lookahead` frames before its window's end. Replaces a live
    /// connection already open. Answered by `live-joined`, then `live-status` every second
    /// and `live-frame`s; `live-closed` when the connection ends.
    LiveJoin { url: String, room: String, secret: String, lookahead: usize },
    /// Change the live lookahead (frames, 0–95).
    LiveLookahead { frames: usize },
    /// Leave the live room; with `keep`, the take becomes the open session (named `name`)
    /// as if imported: answered by `live-kept` (or `error`).
    LiveStop { job: JobId, keep: bool, name: String },
    /// Write the open session as a `.egoexo` file. Answered by `exported` or `error`.
    SaveSession { job: JobId },
    /// Show participant `participant` (an id of the open capture's `participants`): their
    /// facts, plots and exports, the others drawn with them. Answered by `imported` (their
    /// session's summary) and then, when there is a reconstruction, `reconstructed` (their
    /// part of it; nothing is computed again), or by `error`.
    SelectParticipant { job: JobId, participant: String },
    /// Panic inside the worker's Rust code (tests of the page's crash handling).
    PanicForTest,
    /// Pool coordinator → helper (a nested worker of the page's worker; "The worker pool"
    /// in the docs): make job `job` — the aligned session `session` (MessagePack, from the
    /// coordinator), ego-exo and with `overlay` the ego-only overlay, `chunk_windows`
    /// windows per chunk — replacing any pool job held. Answered by `pool-ready` or `error`.
    PoolJob { job: JobId, session: B, overlay: bool, chunk_windows: usize },
    /// Pool coordinator → helper: compute chunk `chunk` of pool job `job`. Answered by
    /// `pool-chunk-done` or `error`; `cancel` drops it while queued.
    PoolChunk { job: JobId, chunk: usize },
}

impl<B> WorkerRequest<B> {
    /// The job the request starts, if it starts one.
    pub fn job(&self) -> Option<JobId> {
        match self {
            WorkerRequest::Open { job, .. }
            | WorkerRequest::Reconstruct { job, .. }
            | WorkerRequest::Export { job, .. }
            | WorkerRequest::CreateShare { job, .. }
            | WorkerRequest::OpenShare { job, .. }
            | WorkerRequest::LiveStop { job, .. }
            | WorkerRequest::SaveSession { job }
            | WorkerRequest::SelectParticipant { job, .. }
            | WorkerRequest::PoolJob { job, .. }
            | WorkerRequest::PoolChunk { job, .. } => Some(*job),
            WorkerRequest::WarmUp
            | WorkerRequest::Cancel { .. }
            | WorkerRequest::PanicForTest
            | WorkerRequest::LiveJoin { .. }
            | WorkerRequest::LiveLookahead { .. } => None,
        }
    }

    /// The byte buffers in the request (to transfer rather than copy when posting it).
    pub fn byte_buffers(&self) -> Vec<&B> {
        match self {
            WorkerRequest::Open { input: SessionInput::Archive { bytes, .. }, .. } => vec![bytes],
            WorkerRequest::Open { input: SessionInput::Files { files, .. }, .. } => {
                files.iter().map(|f| &f.bytes).collect()
            }
            WorkerRequest::OpenShare { sealed, .. } => vec![sealed],
            WorkerRequest::PoolJob { session, .. } => vec![session],
            _ => Vec::new(),
        }
    }

    /// The same request with every byte buffer converted by `f`, in
    /// [`WorkerRequest::byte_buffers`] order.
    pub fn try_map_bytes<C, E>(self, mut f: impl FnMut(B) -> Result<C, E>) -> Result<WorkerRequest<C>, E> {
        Ok(match self {
            WorkerRequest::WarmUp => WorkerRequest::WarmUp,
            WorkerRequest::Open { job, input: SessionInput::Archive { name, bytes } } => {
                WorkerRequest::Open { job, input: SessionInput::Archive { name, bytes: f(bytes)? } }
            }
            WorkerRequest::Open { job, input: SessionInput::Files { name, files } } => {
                let files = files
                    .into_iter()
                    .map(|file| Ok(DroppedFile { path: file.path, bytes: f(file.bytes)? }))
                    .collect::<Result<_, E>>()?;
                WorkerRequest::Open { job, input: SessionInput::Files { name, files } }
            }
            WorkerRequest::Reconstruct { job, overlay } => WorkerRequest::Reconstruct { job, overlay },
            WorkerRequest::Export { job, format } => WorkerRequest::Export { job, format },
            WorkerRequest::CreateShare { job, include_recording } => {
                WorkerRequest::CreateShare { job, include_recording }
            }
            WorkerRequest::OpenShare { job, sealed, key } => WorkerRequest::OpenShare { job, sealed: f(sealed)?, key },
            WorkerRequest::Cancel { job } => WorkerRequest::Cancel { job },
            WorkerRequest::PanicForTest => WorkerRequest::PanicForTest,
            WorkerRequest::LiveJoin { url, room, secret, lookahead } => {
                WorkerRequest::LiveJoin { url, room, secret, lookahead }
            }
            WorkerRequest::LiveLookahead { frames } => WorkerRequest::LiveLookahead { frames },
            WorkerRequest::LiveStop { job, keep, name } => WorkerRequest::LiveStop { job, keep, name },
            WorkerRequest::SaveSession { job } => WorkerRequest::SaveSession { job },
            WorkerRequest::SelectParticipant { job, participant } => {
                WorkerRequest::SelectParticipant { job, participant }
            }
            WorkerRequest::PoolJob { job, session, overlay, chunk_windows } => {
                WorkerRequest::PoolJob { job, session: f(session)?, overlay, chunk_windows }
            }
            WorkerRequest::PoolChunk { job, chunk } => WorkerRequest::PoolChunk { job, chunk },
        })
    }
}

/// What the user gave: one file, or a dropped folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(
    tag = "kind",
    rename_all = "kebab-case",
    bound(serialize = "B: Serialize", deserialize = "B: Deserialize<'de>")
)]
pub enum SessionInput<B> {
    /// A zip archive: `.egoexo`, or a zipped Aria MPS / Nymeria folder.
    Archive { name: String, bytes: B },
    /// A folder: every file with its `/`-separated path below the folder's parent.
    Files { name: String, files: Vec<DroppedFile<B>> },
}

/// One file of a dropped folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound(serialize = "B: Serialize", deserialize = "B: Deserialize<'de>"))]
pub struct DroppedFile<B> {
    pub path: String,
    pub bytes: B,
}

/// Largest file the page reads from a dropped folder, bytes: the importers' largest file
/// (`egoexo_session::vfs::Limits::default().max_file_bytes`; a test there keeps the two equal).
pub const MAX_DROPPED_FILE_BYTES: u64 = 1 << 30;

/// Why the page leaves a file of a dropped folder unread (`path` as in [`DroppedFile`],
/// `bytes` its size), or `None` to read it: a raw Aria recording (`.vrs`), which no layout
/// reads — egoexo imports the MPS output beside it, and the RGB video exported from it —
/// and anything over [`MAX_DROPPED_FILE_BYTES`]. A folder is read into memory before it is
/// imported, so a multi-gigabyte recording beside the MPS output would otherwise be read whole.
pub fn dropped_file_not_read(path: &str, bytes: u64) -> Option<String> {
    let name = path.rsplit('/').next().unwrap_or(path);
    let gib = |b: u64| b as f64 / f64::from(1u32 << 30);
    if name.to_ascii_lowercase().ends_with(".vrs") {
        Some(format!(
            "not read ({:.1} GiB): a raw Aria recording (VRS), which no layout reads — egoexo imports the MPS output \
             beside it, and the RGB video exported from it (docs/session-format.md)",
            gib(bytes)
        ))
    } else if bytes > MAX_DROPPED_FILE_BYTES {
        Some(format!(
            "not read: {:.1} GiB, over the {:.0} GiB a file of a session may be",
            gib(bytes),
            gib(MAX_DROPPED_FILE_BYTES)
        ))
    } else {
        None
    }
}

/// A motion file format the worker exports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExportFormat {
    /// AMASS-style SMPL parameters (`.npz`).
    Npz,
    /// Biovision hierarchy (`.bvh`).
    Bvh,
    /// glTF binary (`.glb`).
    Glb,
    /// Joint positions (`.csv`).
    Csv,
}

impl ExportFormat {
    pub const ALL: [ExportFormat; 4] = [ExportFormat::Npz, ExportFormat::Bvh, ExportFormat::Glb, ExportFormat::Csv];

    /// The file extension (also the wire name).
    pub fn extension(self) -> &'static str {
        match self {
            ExportFormat::Npz => "npz",
            ExportFormat::Bvh => "bvh",
            ExportFormat::Glb => "glb",
            ExportFormat::Csv => "csv",
        }
    }

    /// The format of an extension (`"glb"`), ASCII case ignored.
    pub fn from_extension(extension: &str) -> Option<ExportFormat> {
        ExportFormat::ALL.into_iter().find(|f| f.extension().eq_ignore_ascii_case(extension))
    }
}

/// Worker → page.
// An event is made once and converted to a JS object at once: the summaries' size in the
// largest variants costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(
    tag = "type",
    rename_all = "kebab-case",
    bound(serialize = "B: Serialize", deserialize = "B: Deserialize<'de>")
)]
pub enum WorkerEvent<B> {
    /// The worker runs and speaks protocol `protocol`; sent once, first.
    Ready { protocol: u32 },
    /// What the worker is doing outside a job (e.g. "loading the models…").
    Status { text: String },
    /// The models are loaded.
    Models { summary: ModelsSummary },
    /// `done` of `total` steps of job `job`; `label` is what a progress bar says.
    Progress { job: JobId, stage: JobStage, label: String, done: usize, total: usize },
    /// The session of job `job` is open.
    Imported { job: JobId, summary: SessionSummary },
    /// The reconstruction of job `job`: the viewer's scene (`SceneData` as JSON bytes, for
    /// `Viewer.set_scene_json`) and its summary.
    Reconstructed { job: JobId, scene: B, summary: ReconstructionSummary },
    /// The file of export job `job`.
    Exported { job: JobId, file: ExportedFile<B> },
    /// The sealed share of job `job`, to upload, and its key (base64url) for the link's
    /// fragment — it must never be sent to the server.
    ShareSealed { job: JobId, sealed: B, key: String, includes_recording: bool },
    /// The share of job `job` is open and shown: its scene, summaries, and whether its
    /// recording came with it (then `reconstruct` runs again).
    ShareOpened {
        job: JobId,
        scene: B,
        summary: ReconstructionSummary,
        session: SessionSummary,
        includes_recording: bool,
        created_by: String,
    },
    /// Job `job` was cancelled; nothing of it is kept.
    Cancelled { job: JobId },
    /// The relay admitted the worker to live room `room` as a viewer.
    LiveJoined { room: String, expires_at: String },
    /// The live room, once a second: its devices as the relay sees them, the frames the
    /// relay dropped for this viewer, the worker's clock offset to the relay (relay − worker,
    /// ns, `None` until measured), and what the take holds.
    LiveStatus {
        devices: Vec<crate::live::DeviceStatus>,
        dropped: u64,
        clock_offset_ns: Option<i64>,
        clock_uncertainty_ns: Option<i64>,
        take: LiveTakeSummary,
    },
    /// One live frame to draw: its one-frame scene (for `Viewer.set_live_scene_json`) and
    /// when it happened on the relay clock (Unix ms; latency = now on the relay clock − this).
    LiveFrame { scene: B, frame: LiveFrameInfo },
    /// The live connection ended (`code`, `reason` as the relay gave them; 1000 when the
    /// page left).
    LiveClosed { code: u16, reason: String },
    /// The take of job `job` is the open session now.
    LiveKept { job: JobId, summary: SessionSummary, take: LiveTakeSummary },
    /// A job (or, with `job` null, the model loading of a warm-up) failed.
    Error {
        job: Option<JobId>,
        /// What was being done.
        stage: ErrorStage,
        /// What went wrong, for the page to react to.
        kind: ErrorKind,
        /// The Rust error's message, word for word (an importer's names the file, the
        /// line/field and what was expected).
        message: String,
    },
    /// The worker's Rust code panicked: the module is dead and the worker must be replaced.
    Panic { message: String },
    /// Pool helper → coordinator: pool job `job` is made; it takes `pool-chunk` requests.
    PoolReady { job: JobId },
    /// Pool helper → coordinator: chunk `chunk` of pool job `job`, its window outputs
    /// (`egoexo_infer::ChunkOutputs` as postcard bytes).
    PoolChunkDone { job: JobId, chunk: usize, outputs: B },
}

impl<B> WorkerEvent<B> {
    /// The job the event is about, if any.
    pub fn job(&self) -> Option<JobId> {
        match self {
            WorkerEvent::Progress { job, .. }
            | WorkerEvent::Imported { job, .. }
            | WorkerEvent::Reconstructed { job, .. }
            | WorkerEvent::Exported { job, .. }
            | WorkerEvent::ShareSealed { job, .. }
            | WorkerEvent::ShareOpened { job, .. }
            | WorkerEvent::Cancelled { job }
            | WorkerEvent::LiveKept { job, .. }
            | WorkerEvent::PoolReady { job }
            | WorkerEvent::PoolChunkDone { job, .. } => Some(*job),
            WorkerEvent::Error { job, .. } => *job,
            WorkerEvent::LiveJoined { .. }
            | WorkerEvent::LiveStatus { .. }
            | WorkerEvent::LiveFrame { .. }
            | WorkerEvent::LiveClosed { .. } => None,
            WorkerEvent::Ready { .. }
            | WorkerEvent::Status { .. }
            | WorkerEvent::Models { .. }
            | WorkerEvent::Panic { .. } => None,
        }
    }

    /// The byte buffers in the event (to transfer rather than copy when posting it).
    pub fn byte_buffers(&self) -> Vec<&B> {
        match self {
            WorkerEvent::Reconstructed { scene, .. } => vec![scene],
            WorkerEvent::Exported { file, .. } => vec![&file.bytes],
            WorkerEvent::ShareSealed { sealed, .. } => vec![sealed],
            WorkerEvent::ShareOpened { scene, .. } => vec![scene],
            WorkerEvent::LiveFrame { scene, .. } => vec![scene],
            WorkerEvent::PoolChunkDone { outputs, .. } => vec![outputs],
            _ => Vec::new(),
        }
    }

    /// The same event with every byte buffer converted by `f`, in
    /// [`WorkerEvent::byte_buffers`] order.
    pub fn try_map_bytes<C, E>(self, mut f: impl FnMut(B) -> Result<C, E>) -> Result<WorkerEvent<C>, E> {
        Ok(match self {
            WorkerEvent::Reconstructed { job, scene, summary } => {
                WorkerEvent::Reconstructed { job, scene: f(scene)?, summary }
            }
            WorkerEvent::Exported { job, file } => WorkerEvent::Exported {
                job,
                file: ExportedFile { bytes: f(file.bytes)?, file_name: file.file_name, mime_type: file.mime_type },
            },
            WorkerEvent::ShareSealed { job, sealed, key, includes_recording } => {
                WorkerEvent::ShareSealed { job, sealed: f(sealed)?, key, includes_recording }
            }
            WorkerEvent::ShareOpened { job, scene, summary, session, includes_recording, created_by } => {
                WorkerEvent::ShareOpened { job, scene: f(scene)?, summary, session, includes_recording, created_by }
            }
            WorkerEvent::Ready { protocol } => WorkerEvent::Ready { protocol },
            WorkerEvent::Status { text } => WorkerEvent::Status { text },
            WorkerEvent::Models { summary } => WorkerEvent::Models { summary },
            WorkerEvent::Progress { job, stage, label, done, total } => {
                WorkerEvent::Progress { job, stage, label, done, total }
            }
            WorkerEvent::Imported { job, summary } => WorkerEvent::Imported { job, summary },
            WorkerEvent::Cancelled { job } => WorkerEvent::Cancelled { job },
            WorkerEvent::Error { job, stage, kind, message } => WorkerEvent::Error { job, stage, kind, message },
            WorkerEvent::Panic { message } => WorkerEvent::Panic { message },
            WorkerEvent::LiveJoined { room, expires_at } => WorkerEvent::LiveJoined { room, expires_at },
            WorkerEvent::LiveStatus { devices, dropped, clock_offset_ns, clock_uncertainty_ns, take } => {
                WorkerEvent::LiveStatus { devices, dropped, clock_offset_ns, clock_uncertainty_ns, take }
            }
            WorkerEvent::LiveFrame { scene, frame } => WorkerEvent::LiveFrame { scene: f(scene)?, frame },
            WorkerEvent::LiveClosed { code, reason } => WorkerEvent::LiveClosed { code, reason },
            WorkerEvent::LiveKept { job, summary, take } => WorkerEvent::LiveKept { job, summary, take },
            WorkerEvent::PoolReady { job } => WorkerEvent::PoolReady { job },
            WorkerEvent::PoolChunkDone { job, chunk, outputs } => {
                WorkerEvent::PoolChunkDone { job, chunk, outputs: f(outputs)? }
            }
        })
    }
}

/// A file made by an export.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound(serialize = "B: Serialize", deserialize = "B: Deserialize<'de>"))]
pub struct ExportedFile<B> {
    pub bytes: B,
    /// `<session>-<method>.<extension>`.
    pub file_name: String,
    /// The media type, for the download.
    pub mime_type: String,
}

/// Which part of a job a progress report is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum JobStage {
    /// Reading and aligning the session.
    Import,
    /// The detector step, before the ego pass when observers have video and no keypoints:
    /// per video frame, decoded, cropped to the wearer's region and run through the detector.
    Detection,
    /// Ego features and EgoNet's coarse pose, per window (shared by ego-exo and the overlay).
    EgoPass,
    /// Regions, rays, gates and fusion of ego-exo, per window.
    ExoFusion,
    /// The fusion of the ego-only comparison overlay, per window.
    EgoOnlyOverlay,
    /// Packing and sealing, or opening, a share.
    Share,
}

impl JobStage {
    /// What the progress bar says.
    pub fn label(self) -> &'static str {
        match self {
            JobStage::Import => "importing the session",
            JobStage::Detection => "detecting keypoints in the observers' video",
            JobStage::EgoPass => "ego pass",
            JobStage::ExoFusion => "exo fusion",
            JobStage::EgoOnlyOverlay => "ego-only overlay",
            JobStage::Share => "preparing the share",
        }
    }
}

/// What the failing request was doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ErrorStage {
    /// Fetching, checking and loading the models.
    Models,
    /// Importing a session.
    Import,
    /// Reconstructing.
    Reconstruct,
    /// Exporting.
    Export,
    /// Making or opening a share.
    Share,
    /// Reading the request itself.
    Request,
}

/// What went wrong, as the page tells it apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ErrorKind {
    /// `models/manifest.json` does not exist (HTTP 404): this copy of the app has no models.
    ModelsMissing,
    /// A model file could not be fetched (network, HTTP status).
    ModelsUnavailable,
    /// The manifest or a model file is malformed, of another layout, or fails its sha256.
    ModelsInvalid,
    /// The input is not a session egoexo can read (the message names file, line/field and
    /// what was expected).
    Import,
    /// Reconstruction failed (e.g. the wearer is never tracked).
    Reconstruct,
    /// The motion could not be written.
    Export,
    /// A request needs a session and none is open.
    NoSession,
    /// A request needs a reconstruction and there is none.
    NoReconstruction,
    /// A share cannot be opened: the link's key is wrong, the share was altered, or it is not
    /// a share of a version this page reads.
    ShareInvalid,
    /// The message is not a request of this protocol version.
    BadRequest,
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_dropped_folder_leaves_raw_recordings_and_oversized_files_unread() {
        use super::{MAX_DROPPED_FILE_BYTES, dropped_file_not_read};
        assert_eq!(dropped_file_not_read("take/wearer/closed_loop_trajectory.csv", 5 << 20), None);
        assert_eq!(dropped_file_not_read("take/observers/o1/rgb.mp4", MAX_DROPPED_FILE_BYTES), None);
        let vrs = dropped_file_not_read("take/wearer/recording.VRS", 3 << 30).unwrap();
        assert!(vrs.starts_with("not read (3.0 GiB): a raw Aria recording"), "{vrs}");
        // Even a small one: nothing reads it.
        assert!(dropped_file_not_read("take/a.vrs", 10).is_some());
        let big = dropped_file_not_read("take/wearer/semidense_points.csv.gz", MAX_DROPPED_FILE_BYTES + 1).unwrap();
        assert!(big.contains("over the 1 GiB"), "{big}");
    }

    use serde_json::json;

    use super::*;
    use crate::ByteBuf;

    type Request = WorkerRequest<ByteBuf>;
    type Event = WorkerEvent<ByteBuf>;

    #[test]
    fn requests_have_the_documented_shape() {
        let open: Request = serde_json::from_value(
            json!({"type": "open", "job": 3, "input": {"kind": "archive", "name": "a.egoexo", "bytes": [80, 75]}}),
        )
        .unwrap();
        assert_eq!(
            open,
            WorkerRequest::Open {
                job: 3,
                input: SessionInput::Archive { name: "a.egoexo".into(), bytes: ByteBuf::from(vec![80, 75]) }
            }
        );
        assert_eq!(open.job(), Some(3));
        assert_eq!(open.byte_buffers().len(), 1);
        let folder: Request = serde_json::from_value(json!({"type": "open", "job": 4, "input": {
            "kind": "files", "name": "walk", "files": [{"path": "walk/a.csv", "bytes": [1]}, {"path": "walk/b", "bytes": []}]
        }}))
        .unwrap();
        assert_eq!(folder.byte_buffers().len(), 2);
        for (value, expected) in [
            (json!({"type": "warm-up"}), WorkerRequest::WarmUp),
            (json!({"type": "panic-for-test"}), WorkerRequest::PanicForTest),
            (
                json!({"type": "reconstruct", "job": 5, "overlay": true}),
                WorkerRequest::Reconstruct { job: 5, overlay: true },
            ),
            (
                json!({"type": "export", "job": 6, "format": "glb"}),
                WorkerRequest::Export { job: 6, format: ExportFormat::Glb },
            ),
            (json!({"type": "cancel", "job": 5}), WorkerRequest::Cancel { job: 5 }),
        ] {
            let request: Request = serde_json::from_value(value.clone()).unwrap();
            assert_eq!(request, expected);
            assert_eq!(serde_json::to_value(&request).unwrap(), value);
        }
    }

    #[test]
    fn malformed_requests_are_refused_with_what_is_wrong() {
        for (value, needle) in [
            (json!({"type": "reconstruct"}), "job"),
            (json!({"type": "export", "job": 1, "format": "fbx"}), "fbx"),
            (json!({"type": "explode"}), "explode"),
            (json!({"job": 1}), "type"),
            (json!({"type": "open", "job": 1, "input": {"kind": "archive", "name": "x"}}), "bytes"),
        ] {
            let err = serde_json::from_value::<Request>(value.clone()).unwrap_err().to_string();
            assert!(err.contains(needle), "{value}: {err}");
        }
    }

    #[test]
    fn events_have_the_documented_shape() {
        let error: Event = WorkerEvent::Error {
            job: None,
            stage: ErrorStage::Models,
            kind: ErrorKind::ModelsMissing,
            message: "cannot fetch models/manifest.json: HTTP 404 Not Found".into(),
        };
        assert_eq!(
            serde_json::to_value(&error).unwrap(),
            json!({"type": "error", "job": null, "stage": "models", "kind": "models-missing",
                   "message": "cannot fetch models/manifest.json: HTTP 404 Not Found"})
        );
        let progress: Event = WorkerEvent::Progress {
            job: 2,
            stage: JobStage::EgoOnlyOverlay,
            label: JobStage::EgoOnlyOverlay.label().into(),
            done: 3,
            total: 9,
        };
        assert_eq!(
            serde_json::to_value(&progress).unwrap(),
            json!({"type": "progress", "job": 2, "stage": "ego-only-overlay", "label": "ego-only overlay", "done": 3, "total": 9})
        );
        let exported: Event = WorkerEvent::Exported {
            job: 7,
            file: ExportedFile {
                bytes: ByteBuf::from(vec![1, 2]),
                file_name: "a-ego-exo.bvh".into(),
                mime_type: "text/plain".into(),
            },
        };
        assert_eq!(exported.job(), Some(7));
        assert_eq!(exported.byte_buffers(), [&ByteBuf::from(vec![1, 2])]);
        let back: Event = serde_json::from_value(serde_json::to_value(&exported).unwrap()).unwrap();
        assert_eq!(back, exported);
        assert_eq!(
            serde_json::to_value(WorkerEvent::<ByteBuf>::Ready { protocol: WORKER_PROTOCOL_VERSION }).unwrap()["type"],
            "ready"
        );
    }

    #[test]
    fn export_formats_are_their_extensions() {
        for f in ExportFormat::ALL {
            assert_eq!(serde_json::to_value(f).unwrap(), json!(f.extension()));
            assert_eq!(ExportFormat::from_extension(&f.extension().to_uppercase()), Some(f));
        }
        assert_eq!(ExportFormat::from_extension("fbx"), None);
    }
}
