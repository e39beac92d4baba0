//! [`SessionWorker`]: the worker's state and operations in plain Rust — load the models,
//! import a session, reconstruct it step by step (ego-exo plus the ego-only overlay, sharing
//! one ego pass), build the viewer's scene, export the motion, pack it into a share container
//! and open one. The browser's message loop ([`crate::WorkerApp`], wasm32 only), the CLI's
//! `egoexo share` and the native tests drive the same code; everything that can fail returns
//! [`WorkerError`], whose [`WorkerError::kind`] is what the page sees.
//!
//! This file holds the worker's state, the models and opening a session; the rest by
//! concern: `detect` (the detector step), `reconstruct` (jobs, stepped or pooled), `results`
//! (scene, exports, shares, saving, a kept live take), `summary` (what the page shows of a
//! session), `group` (a capture of several participants).

use std::collections::BTreeMap;
use std::rc::Rc;
use std::sync::Arc;

use egoexo_core::aligned::AlignedSession;
use egoexo_core::camera::Projection;
use egoexo_core::{SmplMotion, TrackingMode};
use egoexo_detect::{observers_needing_detection, plan_observer};
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::{Loading, ModelSet};
use egoexo_infer::{
    ChunkOutputs, Engine, InferError, KeypointDetector, LoadedModels, Method, NetworkRuns, Progress,
    ReconstructOptions, Reconstruction, ReconstructionJob, Stage, StageTimer, StageTimings, TimedStage,
};
use egoexo_motion_io::{ExportError, Format};
use egoexo_protocol::worker::{
    self as protocol, Accuracy, ErrorKind, ExportFormat, FloorSummary, JobStage, ModelFileRef, ModelSetSummary,
    ModelsSummary, ObserverSummary, ReconstructionSummary, SessionSummary, WristSummary,
};
use egoexo_register::{RegisterSettings, register_session};
use egoexo_session::align::DEFAULT_FPS;
use egoexo_session::format::{write_egoexo_zip, write_egoexo_zip_with};
use egoexo_session::import::{detect_source, import_capture};
use egoexo_session::{
    AlignError, AlignOptions, FileTree, ImportError, ImportOptions, ImportWarning, Imported, Limits, align,
};
use egoexo_share::{ShareContents, ShareError, ShareManifest};
use thiserror::Error;

use crate::detection::{DetectionTask, ObserverDetectionJob};

mod detect;
mod group;
mod reconstruct;
mod results;
mod summary;

pub use group::{GroupReconstruction, SelectedParticipant};
pub use reconstruct::{JobProgress, PoolHelperJob, ReconstructionTask};
pub use results::{ExportedFile, OpenedShare, motion_format};
use summary::{projection_name, session_summary};

/// Everything that can go wrong in the worker. Library errors keep their exact messages
/// (the importers' name the file, line/field and what was expected).
#[derive(Debug, Error)]
pub enum WorkerError {
    #[error(transparent)]
    Import(#[from] ImportError),
    #[error("{session}: {source}")]
    Align { session: String, source: AlignError },
    #[error(transparent)]
    Infer(#[from] InferError),
    #[error(transparent)]
    Export(#[from] ExportError),
    #[error("the models are not loaded yet")]
    NoModels,
    #[error("no session is open: import one first")]
    NoSession,
    #[error("nothing is reconstructed yet: reconstruct the session first")]
    NoReconstruction,
    #[error("cannot build the scene: {0}")]
    Scene(String),
    #[error(transparent)]
    Share(#[from] ShareError),
    #[error("cannot write the recording into the share: {0}")]
    ShareRecording(String),
    #[error(transparent)]
    Live(#[from] crate::live::LiveError),
    #[error("the take cannot be kept: {0}")]
    Take(#[from] egoexo_session::live::TakeError),
    #[error("cannot write the session: {0}")]
    SaveSession(String),
    #[error("the detector is not loaded yet")]
    NoDetectorLoaded,
    #[error("the network bench has not been analysed: analyse it before running its probe")]
    BenchNotAnalysed,
    #[error(transparent)]
    Pool(#[from] crate::pool::PoolError),
    #[error(transparent)]
    Detection(#[from] crate::detection::DetectionError),
    #[error(transparent)]
    Capture(#[from] egoexo_session::capture::CaptureError),
    #[error("registering the observers: {0}")]
    Registration(#[from] egoexo_register::RegisterError),
    #[error("the open capture has no participant `{0}`")]
    NoSuchParticipant(String),
    #[error("participant `{0}` is not reconstructed (the capture has them only as an observer)")]
    NotReconstructed(String),
}

impl WorkerError {
    /// The protocol's kind of this error.
    pub fn kind(&self) -> ErrorKind {
        match self {
            WorkerError::NoModels => ErrorKind::ModelsMissing,
            WorkerError::Import(_) | WorkerError::Align { .. } => ErrorKind::Import,
            // The kind comes from the engine's error, wherever it arose: a manifest or model
            // file the engine refuses is the models' fault, anything else the reconstruction's.
            WorkerError::Infer(
                InferError::Manifest(_)
                | InferError::Model { .. }
                | InferError::Checksum { .. }
                | InferError::ReadModel { .. },
            ) => ErrorKind::ModelsInvalid,
            WorkerError::Infer(_) | WorkerError::Scene(_) => ErrorKind::Reconstruct,
            WorkerError::Export(_) => ErrorKind::Export,
            WorkerError::NoSession => ErrorKind::NoSession,
            WorkerError::NoReconstruction => ErrorKind::NoReconstruction,
            WorkerError::Share(_) => ErrorKind::ShareInvalid,
            WorkerError::ShareRecording(_) | WorkerError::SaveSession(_) => ErrorKind::Export,
            WorkerError::Live(_) => ErrorKind::Reconstruct,
            WorkerError::Take(_) | WorkerError::Capture(_) | WorkerError::Registration(_) => ErrorKind::Import,
            WorkerError::NoSuchParticipant(_) | WorkerError::NotReconstructed(_) | WorkerError::BenchNotAnalysed => {
                ErrorKind::BadRequest
            }
            WorkerError::Pool(_) | WorkerError::Detection(_) | WorkerError::NoDetectorLoaded => ErrorKind::Reconstruct,
        }
    }

    /// Whether this is the engine's answer to a cancel.
    pub fn is_cancelled(&self) -> bool {
        matches!(self, WorkerError::Infer(InferError::Cancelled))
    }
}

/// An imported session, aligned on the timeline the models run at.
#[derive(Debug)]
struct OpenSession {
    imported: Imported,
    aligned: AlignedSession,
    summary: SessionSummary,
    /// Import and align of this session (with the worker's clock).
    timings: StageTimings,
    /// The observers' videos (path in the session → bytes), kept for the detector step and
    /// for saving the session.
    videos: BTreeMap<String, Arc<[u8]>>,
    /// What the detector step did (for the next reconstruction's summary).
    detection: Vec<protocol::DetectionSummary>,
}

/// What the worker has open ([`SessionWorker`]'s modes); opening anything replaces it whole.
#[derive(Debug, Default)]
enum Opened {
    #[default]
    Nothing,
    /// One wearer: a recording, a kept live take, or a share of one.
    Wearer(Shown),
    /// A capture of several participants, or a share of one: everyone's results wait in the
    /// group; `Shown` is the shown participant's session and results.
    Capture(Box<group::Group>, Shown),
}

/// The shown wearer's session and results. A share opened without its recording has
/// results and no session; a session not yet reconstructed has no results.
#[derive(Debug, Default)]
struct Shown {
    session: Option<OpenSession>,
    results: Option<Results>,
}

impl Opened {
    /// One wearer's `session` newly opened (no results yet).
    fn wearer(session: OpenSession) -> Self {
        Opened::Wearer(Shown { session: Some(session), results: None })
    }

    fn shown(&self) -> Option<&Shown> {
        match self {
            Opened::Nothing => None,
            Opened::Wearer(shown) | Opened::Capture(_, shown) => Some(shown),
        }
    }

    fn shown_mut(&mut self) -> Option<&mut Shown> {
        match self {
            Opened::Nothing => None,
            Opened::Wearer(shown) | Opened::Capture(_, shown) => Some(shown),
        }
    }

    /// The shown wearer's session, if one is open.
    fn session(&self) -> Option<&OpenSession> {
        self.shown()?.session.as_ref()
    }

    fn session_mut(&mut self) -> Option<&mut OpenSession> {
        self.shown_mut()?.session.as_mut()
    }

    /// What is shown, if anything is reconstructed or opened from a share.
    fn results(&self) -> Option<&Results> {
        self.shown()?.results.as_ref()
    }

    /// The capture of several participants, if one is open.
    fn group(&self) -> Option<&group::Group> {
        match self {
            Opened::Capture(group, _) => Some(group),
            _ => None,
        }
    }

    fn group_mut(&mut self) -> Option<&mut group::Group> {
        match self {
            Opened::Capture(group, _) => Some(group),
            _ => None,
        }
    }
}

/// What is shown: a reconstruction made here, or one opened from a share.
#[derive(Clone, Debug)]
struct Results {
    /// The session's name (export file names).
    name: String,
    /// The method of `motion`.
    method: String,
    /// The motion the exports write (the full method).
    motion: SmplMotion,
    /// The viewer's scene, as JSON.
    scene_json: Vec<u8>,
    summary: ReconstructionSummary,
    /// The session it was made from.
    session: SessionSummary,
    /// The reconstructions themselves, when made here (an opened share has only the motion).
    made_here: Option<(Reconstruction, Option<Reconstruction>)>,
}

/// A clock in milliseconds (any origin) handed to the worker by its host: the page glue's
/// `performance.now()` in the browser, `Instant` natively. The worker never reads one itself.
#[derive(Clone, Default)]
pub struct WorkerClock(Option<Rc<dyn Fn() -> f64>>);

impl WorkerClock {
    pub fn new(now_ms: impl Fn() -> f64 + 'static) -> Self {
        WorkerClock(Some(Rc::new(now_ms)))
    }

    /// The clock as a [`egoexo_infer::Clock`] (reading 0 without one).
    fn now_fn(&self) -> impl FnMut() -> f64 + '_ {
        move || self.0.as_ref().map_or(0.0, |now| now())
    }

    fn is_set(&self) -> bool {
        self.0.is_some()
    }
}

impl std::fmt::Debug for WorkerClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.is_set() { "WorkerClock(set)" } else { "WorkerClock(none)" })
    }
}

/// The worker: models, the open session and its reconstructions.
///
/// **Modes** (`Opened`): nothing open; one wearer (a recording, a kept take or a share of
/// one); or a capture of several participants, whose group holds everyone's results while
/// the *shown* participant's session and results are the ones every method below works on,
/// unless it names a participant. In either mode a share opened without its recording has
/// results and no session.
///
/// **Call order.**
/// 1. `load_models` (and `load_detector` once a session needs it: `observers_needing_detection`).
/// 2. Open: `import_archive` / `open_imported` (observers are registered here, `auto`), or
///    `open_share`, or "Stop and keep" of a live take.
/// 3. Reconstruct — one wearer: `reconstruct` (or a job stepped by the page's runtime; a pool
///    runs its chunks with `run_pool_chunk`). A capture: `begin_group_reconstruction`, then for
///    each participant it returns `open_participant_for_reconstruction` and the same job, then
///    `finish_group_reconstruction` (which shows again who was shown); `select_participant`
///    switches who is shown afterwards.
/// 4. Use the results: `export`, `pack_share`, the scene.
///
/// Opening anything drops the previous session, results and group; a call out of order is a
/// typed error (`NoModels`, `NoSession`, `NoReconstruction`), never a panic.
#[derive(Debug, Default)]
pub struct SessionWorker {
    models: Option<LoadedModels>,
    /// The keypoint detector, loaded when a session first needs it.
    detector: Option<Arc<KeypointDetector>>,
    manifest: Option<Manifest>,
    /// The open session or capture and what is shown of it.
    opened: Opened,
    /// Times each stage of a job when set ([`ReconstructionSummary::timings`]).
    clock: WorkerClock,
}

impl SessionWorker {
    pub fn new() -> Self {
        Self::default()
    }

    /// Times every stage of the jobs from now on with `clock` (reported in
    /// [`ReconstructionSummary::timings`]).
    pub fn set_clock(&mut self, clock: WorkerClock) {
        self.clock = clock;
    }

    /// Runs `f` as `stage`, timed when the worker has a clock.
    fn timed<T>(&self, timings: &mut StageTimings, stage: TimedStage, f: impl FnOnce() -> T) -> T {
        if !self.clock.is_set() {
            return f();
        }
        let mut now = self.clock.now_fn();
        let mut timer = StageTimer::new(&mut now);
        let out = timer.time(stage, f);
        timings.merge(&timer.timings);
        out
    }

    /// The files a manifest lists (paths relative to the models folder), for the caller to
    /// fetch before [`SessionWorker::load_models`].
    pub fn model_files(manifest_json: &[u8]) -> Result<Vec<ModelFileRef>, WorkerError> {
        let manifest = Manifest::from_json(manifest_json).map_err(WorkerError::Infer)?;
        Ok(manifest
            .files()
            .into_iter()
            .map(|f| ModelFileRef { file: f.file.clone(), sha256: f.sha256.clone(), bytes: f.bytes })
            .collect())
    }

    /// Loads every model set of the manifest (the offline networks and any live variants),
    /// reading each file once through `read` (path relative to the models folder → bytes);
    /// each file's sha256 is checked against the manifest. The networks are parsed and
    /// optimised when a reconstruction (or live frame) first needs their tracking mode.
    pub fn load_models(
        &mut self,
        manifest_json: &[u8],
        read: impl FnMut(&str) -> Result<Vec<u8>, InferError>,
    ) -> Result<ModelsSummary, WorkerError> {
        let manifest = Manifest::from_json(manifest_json).map_err(WorkerError::Infer)?;
        // Checked now, parsed and optimised per tracking mode when a reconstruction first
        // needs it: a session pays only for its own mode's networks.
        let models = LoadedModels::load_with(&manifest, read, Loading::Deferred).map_err(WorkerError::Infer)?;
        let sets = manifest
            .model_sets
            .iter()
            .map(|set| ModelSetSummary {
                tracking_points: set.tracking.points(),
                max_observers: set.max_observers,
                hidden_dim: set.hidden_dim,
                lookahead: set.lookahead,
            })
            .collect();
        let bytes = manifest.files().iter().map(|f| f.bytes).sum();
        self.models = Some(models);
        self.manifest = Some(manifest);
        Ok(ModelsSummary { model_sets: sets, bytes, read_ms: None, load_ms: None, cached_files: 0 })
    }

    /// The tracking modes (points) whose offline networks are parsed and optimised: none
    /// after [`Self::load_models`], a mode's once a reconstruction needed it.
    pub fn prepared_tracking_points(&self) -> Vec<u8> {
        let Some(models) = &self.models else { return Vec::new() };
        [TrackingMode::OnePoint, TrackingMode::ThreePoint]
            .into_iter()
            .filter(|&mode| models.offline().models(mode).is_some_and(|set| set.is_ready()))
            .map(TrackingMode::points)
            .collect()
    }

    /// Parses and optimises one network not yet prepared, the offline 3-point set's first,
    /// then the 1-point set's (live variants when first used); `Ok(false)` when none is left.
    pub fn prepare_next_network(&self) -> Result<bool, WorkerError> {
        let Some(models) = &self.models else { return Ok(false) };
        let next = [TrackingMode::ThreePoint, TrackingMode::OnePoint]
            .into_iter()
            .filter_map(|mode| models.offline().models(mode))
            .find_map(ModelSet::next_unprepared);
        match next {
            Some(network) => network.prepare().map(|()| true).map_err(WorkerError::Infer),
            None => Ok(false),
        }
    }

    /// Whether models are loaded.
    pub fn has_models(&self) -> bool {
        self.models.is_some()
    }

    /// How often each network has run since the models were loaded.
    pub fn network_runs(&self) -> NetworkRuns {
        self.models.as_ref().map(LoadedModels::network_runs).unwrap_or_default()
    }

    /// Imports a zip archive (`.egoexo` or a zipped Aria MPS / Nymeria folder) from its bytes.
    pub fn import_archive(&mut self, name: &str, bytes: Vec<u8>) -> Result<SessionSummary, WorkerError> {
        let tree = FileTree::from_zip(name, Arc::<[u8]>::from(bytes), Limits::default())?;
        self.import(&tree)
    }

    /// Imports a dropped folder: `(relative path, bytes)` per file, paths `/`-separated.
    pub fn import_files(
        &mut self,
        name: &str,
        files: impl IntoIterator<Item = (String, Vec<u8>)>,
    ) -> Result<SessionSummary, WorkerError> {
        let tree = FileTree::from_files(name, files, Limits::default())?;
        self.import(&tree)
    }

    /// Imports any supported input and aligns it; replaces the open session.
    /// A capture of several participants opens with the first one to reconstruct shown
    /// ([`SessionSummary::participants`]).
    pub fn import(&mut self, tree: &FileTree) -> Result<SessionSummary, WorkerError> {
        self.opened = Opened::Nothing;
        let mut timings = StageTimings::default();
        let imported =
            self.timed(&mut timings, TimedStage::Import, || import_capture(tree, &ImportOptions::default()))?;
        self.open_capture(Some(tree), imported, timings)
    }

    /// Opens a session imported elsewhere (the CLI imports with its own options); replaces
    /// the open session.
    pub fn open_imported(&mut self, imported: Imported) -> Result<SessionSummary, WorkerError> {
        self.open_imported_timed(imported, StageTimings::default())
    }

    fn open_imported_timed(
        &mut self,
        mut imported: Imported,
        mut timings: StageTimings,
    ) -> Result<SessionSummary, WorkerError> {
        self.opened = Opened::Nothing;
        let fps = self.fps();
        self.timed(&mut timings, TimedStage::Register, || self.register_observers(&mut imported))?;
        let aligned = self.timed(&mut timings, TimedStage::Align, || align_for(&imported, fps))?;
        let videos = BTreeMap::new();
        let summary = session_summary(&imported, &aligned, &videos);
        self.opened = Opened::wearer(OpenSession {
            imported,
            aligned,
            summary: summary.clone(),
            timings,
            videos,
            detection: Vec::new(),
        });
        Ok(summary)
    }

    /// Registers the observers of `imported` whose worlds are their own or disagree with
    /// their views (`egoexo_register`, mode `auto`: docs/registration.md), with EgoNet's
    /// coarse body when models are loaded (the face alone otherwise); what it did becomes the
    /// session's warnings.
    fn register_observers(&self, imported: &mut Imported) -> Result<(), WorkerError> {
        if imported.session.observers.is_empty() {
            return Ok(());
        }
        let engine = self.models.as_ref().map(|m| m.offline());
        let tracking = imported.session.wearer.tracking_mode();
        let tracking =
            if engine.is_some_and(|e| e.models(tracking).is_none()) { TrackingMode::OnePoint } else { tracking };
        let report = register_session(engine, tracking, &mut imported.session, &RegisterSettings::default())?;
        for o in report.warnings() {
            imported.warnings.push(ImportWarning { file: o.id.clone(), message: o.message.clone() });
        }
        Ok(())
    }

    /// The open session on the models' timeline, if any.
    pub fn aligned_session(&self) -> Option<&AlignedSession> {
        self.opened.session().map(|s| &s.aligned)
    }

    /// The frame rate the models were trained at (the default timeline rate without models).
    fn fps(&self) -> f32 {
        self.manifest.as_ref().map_or(DEFAULT_FPS, |m| m.fps)
    }

    /// The open session's summary as it is now (after a detector step it counts the found
    /// keypoints).
    pub fn session_summary(&self) -> Option<SessionSummary> {
        self.opened.session().map(|open| open.summary.clone())
    }
}

fn align_for(imported: &Imported, fps: f32) -> Result<AlignedSession, WorkerError> {
    align(&imported.session, &AlignOptions { fps, ..AlignOptions::default() })
        .map_err(|source| WorkerError::Align { session: imported.session.name.clone(), source })
}

/// The bytes of every video the session's observers name, read from `tree` (the session's
/// own folder inside it).
fn session_videos(tree: &FileTree, imported: &Imported) -> Result<BTreeMap<String, Arc<[u8]>>, WorkerError> {
    let mut videos = BTreeMap::new();
    if imported.session.observers.iter().all(|o| o.video.is_none()) {
        return Ok(videos);
    }
    let (_, root) = detect_source(tree)?;
    for observer in &imported.session.observers {
        let Some(video) = &observer.video else { continue };
        if root.contains(&video.path) {
            videos.insert(video.path.clone(), Arc::from(root.read(&video.path)?));
        }
    }
    Ok(videos)
}

/// `name` as a file name: letters, digits, `-`, `_` and `.` kept, anything else `_`.
fn file_name(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') { c } else { '_' }).collect()
}
