//! [`SessionWorker`]: the worker's state and operations in plain Rust — load the models,
//! import a session, reconstruct it step by step (ego-exo plus the ego-only overlay, sharing
//! one ego pass), build the viewer's scene, export the motion, pack it into a share container
//! and open one. The browser's message loop ([`crate::WorkerApp`], wasm32 only), the CLI's
//! `egoexo share` and the native tests drive the same code; everything that can fail returns
//! [`WorkerError`], whose [`WorkerError::kind`] is what the page sees.

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

mod group;

pub use group::{GroupReconstruction, SelectedParticipant};

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

/// A share opened by [`SessionWorker::open_share`].
#[derive(Clone, Debug, PartialEq)]
pub struct OpenedShare {
    pub manifest: ShareManifest,
    /// The viewer's scene (JSON).
    pub scene_json: Vec<u8>,
}

/// A file made by [`SessionWorker::export`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExportedFile {
    pub bytes: Vec<u8>,
    /// `<session>-<method>.<extension>`.
    pub file_name: String,
    pub mime_type: &'static str,
}

/// Progress of a whole reconstruction: `done` of `total` window steps over every pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct JobProgress {
    pub stage: JobStage,
    pub done: usize,
    pub total: usize,
}

/// A reconstruction under way ([`SessionWorker::start_reconstruction`]): the engine's job
/// with ego-exo (and the ego-only overlay) sharing one ego pass.
#[derive(Debug)]
pub struct ReconstructionTask {
    job: ReconstructionJob,
    runs_before: NetworkRuns,
    /// The network runs of the chunks pool helpers computed.
    helper_runs: NetworkRuns,
    /// How a pool shared the job, for the summary.
    pool: Option<protocol::PoolSummary>,
}

impl ReconstructionTask {
    /// Chunks of the job (see [`crate::pool`]).
    pub fn chunk_count(&self) -> usize {
        self.job.chunk_count()
    }

    /// Window indices of chunk `chunk`.
    pub fn chunk_windows(&self, chunk: usize) -> std::ops::Range<usize> {
        self.job.chunk_windows(chunk)
    }

    /// Windows per chunk.
    pub fn chunk_size(&self) -> usize {
        self.job.chunk_windows(0).len()
    }

    /// Sets the windows per chunk (≥ 1) before the first step: the result does not depend
    /// on it.
    pub fn set_chunk_size(&mut self, windows: usize) -> Result<(), WorkerError> {
        Ok(self.job.set_chunk(windows)?)
    }

    /// Says in the summary how a pool shared the job.
    pub fn set_pool_summary(&mut self, pool: protocol::PoolSummary) {
        self.pool = Some(pool);
    }

    /// Methods of the job (outputs per window).
    pub fn method_count(&self) -> usize {
        self.job.methods().len()
    }
}

/// A pool helper's copy of a coordinator's job ([`SessionWorker::start_pool_helper`]): the
/// same aligned session, methods and chunks, computed chunk by chunk on request.
#[derive(Debug)]
pub struct PoolHelperJob {
    job: ReconstructionJob,
    aligned: AlignedSession,
}

impl PoolHelperJob {
    /// Chunks of the job.
    pub fn chunk_count(&self) -> usize {
        self.job.chunk_count()
    }
}

/// The methods of a job: ego-exo, and the ego-only overlay when asked for.
fn job_methods(ego_only_overlay: bool) -> &'static [Method] {
    if ego_only_overlay { &[Method::EgoExo, Method::EgoOnly] } else { &[Method::EgoExo] }
}

/// The protocol's stage of an engine stage.
fn job_stage(stage: Stage) -> JobStage {
    match stage {
        Stage::Ego => JobStage::EgoPass,
        Stage::Fusion(Method::EgoOnly) => JobStage::EgoOnlyOverlay,
        Stage::Fusion(_) => JobStage::ExoFusion,
    }
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
/// **Modes.** One session open (a recording of one wearer), or a capture of several
/// participants (`group` set): then `session` and `results` are always the *shown*
/// participant's, and the others' results wait in the group. Every method below works on the
/// shown one unless it names a participant.
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
    session: Option<OpenSession>,
    results: Option<Results>,
    /// A capture of several participants: everyone's results; `session` and `results` are
    /// the shown participant's.
    group: Option<group::Group>,
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
        self.session = None;
        self.results = None;
        self.group = None;
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
        self.session = None;
        self.results = None;
        self.group = None;
        let fps = self.fps();
        self.timed(&mut timings, TimedStage::Register, || self.register_observers(&mut imported))?;
        let aligned = self.timed(&mut timings, TimedStage::Align, || align_for(&imported, fps))?;
        let videos = BTreeMap::new();
        let summary = session_summary(&imported, &aligned, &videos);
        self.session =
            Some(OpenSession { imported, aligned, summary: summary.clone(), timings, videos, detection: Vec::new() });
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
        self.session.as_ref().map(|s| &s.aligned)
    }

    /// The frame rate the models were trained at (the default timeline rate without models).
    fn fps(&self) -> f32 {
        self.manifest.as_ref().map_or(DEFAULT_FPS, |m| m.fps)
    }

    /// Observers of the open session whose keypoints the detector step finds first (video
    /// and no keypoints), by id.
    pub fn observers_needing_detection(&self) -> Vec<String> {
        let Some(open) = &self.session else { return Vec::new() };
        observers_needing_detection(&open.imported.session)
            .into_iter()
            .map(|o| open.imported.session.observers[o].id.clone())
            .collect()
    }

    /// The detector's file in the models folder, when the manifest has one.
    pub fn detector_file(&self) -> Option<ModelFileRef> {
        let file = &self.manifest.as_ref()?.detector.as_ref()?.file;
        Some(ModelFileRef { file: file.file.clone(), sha256: file.sha256.clone(), bytes: file.bytes })
    }

    /// Whether the detector is loaded.
    pub fn has_detector(&self) -> bool {
        self.detector.is_some()
    }

    /// Loads the detector from its file's bytes (sha256-checked against the manifest).
    pub fn load_detector(&mut self, bytes: &[u8]) -> Result<(), WorkerError> {
        let manifest = self.manifest.as_ref().ok_or(WorkerError::NoModels)?;
        let observer = self.observers_needing_detection().into_iter().next().unwrap_or_default();
        let entry = manifest.detector.as_ref().ok_or(crate::detection::DetectionError::NoDetector(observer))?;
        self.detector = Some(Arc::new(KeypointDetector::load(entry, bytes).map_err(WorkerError::Infer)?));
        Ok(())
    }

    /// Starts the detector step for the open session ([`Self::observers_needing_detection`];
    /// `None` when there are none): EgoNet's coarse pose over the session (one pass) plans
    /// every video frame's crop window. Hand each decoded frame's crop to
    /// [`DetectionTask::detect_crop`], then call [`Self::finish_detection`].
    pub fn start_detection(&mut self) -> Result<Option<DetectionTask>, WorkerError> {
        let Some(first) = self.observers_needing_detection().into_iter().next() else { return Ok(None) };
        let detector = match &self.detector {
            Some(detector) => detector.clone(),
            None if self.detector_file().is_none() => {
                return Err(crate::detection::DetectionError::NoDetector(first).into());
            }
            None => return Err(WorkerError::NoDetectorLoaded),
        };
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let fps = self.fps();
        let open = self.session.as_mut().ok_or(WorkerError::NoSession)?;
        if open.aligned.timeline.fps != fps {
            open.aligned = align_for(&open.imported, fps)?;
        }
        let options = ReconstructOptions { method: Method::EgoNet, ..ReconstructOptions::default() };
        let coarse = engine.reconstruct(&open.aligned, &options, &mut |_| true)?;
        let session = &open.imported.session;
        let mut observers = Vec::new();
        for o in observers_needing_detection(session) {
            let observer = &session.observers[o];
            let path = observer.video.as_ref().map(|v| v.path.clone()).unwrap_or_default();
            let mp4 = open.videos.get(&path).cloned().ok_or_else(|| {
                crate::detection::DetectionError::MissingVideo { observer: observer.id.clone(), path: path.clone() }
            })?;
            let plan = plan_observer(session, &open.aligned, &coarse, o, &mp4)
                .map_err(crate::detection::DetectionError::from)?;
            observers.push(ObserverDetectionJob::new(plan, mp4));
        }
        Ok(Some(DetectionTask { detector, observers }))
    }

    /// Puts the keypoints `task` found into the open session (which is aligned again; later
    /// jobs skip the step) and returns what was done per observer.
    pub fn finish_detection(&mut self, task: DetectionTask) -> Result<Vec<protocol::DetectionSummary>, WorkerError> {
        let fps = self.fps();
        let open = self.session.as_mut().ok_or(WorkerError::NoSession)?;
        let mut summaries = Vec::new();
        let mut found = Vec::new();
        for (o, track, summary) in task.finish() {
            let observer = open.imported.session.observers.get_mut(o).ok_or(WorkerError::NoSession)?;
            found.push((observer.id.clone(), track.clone()));
            observer.keypoints = Some(track);
            summaries.push(summary);
        }
        open.aligned = align_for(&open.imported, fps)?;
        open.detection = summaries.clone();
        let summary = session_summary(&open.imported, &open.aligned, &open.videos);
        // In a capture, the found keypoints are the capture's too (saved, shared, reopened).
        for (id, track) in found {
            self.keep_detected_keypoints(&id, track);
        }
        let summary = self.with_group(summary);
        self.session.as_mut().ok_or(WorkerError::NoSession)?.summary = summary;
        Ok(summaries)
    }

    /// The open session's summary as it is now (after a detector step it counts the found
    /// keypoints).
    pub fn session_summary(&self) -> Option<SessionSummary> {
        self.session.as_ref().map(|open| open.summary.clone())
    }

    /// Starts reconstructing the open session with the full method and, if
    /// `ego_only_overlay`, ego-only for the comparison overlay (one shared ego pass). The
    /// previous results are dropped. Step it with [`SessionWorker::step_reconstruction`].
    pub fn start_reconstruction(&mut self, ego_only_overlay: bool) -> Result<ReconstructionTask, WorkerError> {
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let fps = self.fps();
        let open = self.session.as_mut().ok_or(WorkerError::NoSession)?;
        if open.aligned.timeline.fps != fps {
            open.aligned = align_for(&open.imported, fps)?;
            open.timings = StageTimings::default();
        }
        self.results = None;
        let job = start_job(engine, &open.aligned, ego_only_overlay)?;
        Ok(ReconstructionTask {
            job,
            runs_before: engine.network_runs(),
            helper_runs: NetworkRuns::default(),
            pool: None,
        })
    }

    /// [`Self::start_reconstruction`] for a pool of `workers` workers (this one and
    /// `workers − 1` helpers): chunks of [`crate::pool::pool_chunk_windows`] windows, which
    /// the helpers compute from [`Self::pool_session`] and this worker decodes in order with
    /// [`Self::add_pool_chunk`].
    pub fn start_pooled_reconstruction(
        &mut self,
        ego_only_overlay: bool,
        workers: usize,
    ) -> Result<ReconstructionTask, WorkerError> {
        let mut task = self.start_reconstruction(ego_only_overlay)?;
        let windows = task.job.plan().windows.len();
        task.job.set_chunk(crate::pool::pool_chunk_windows(windows, workers))?;
        Ok(task)
    }

    /// The open session as the pool's helpers receive it ([`crate::pool::encode_pool_session`]).
    pub fn pool_session(&self) -> Result<Vec<u8>, WorkerError> {
        let open = self.session.as_ref().ok_or(WorkerError::NoSession)?;
        Ok(crate::pool::encode_pool_session(&open.aligned)?)
    }

    /// Every method's output for window `window` of `task` (the coordinator's own share of a
    /// pooled job, one window per step), timed into the task's stage timings with a clock.
    pub fn run_pool_window(
        &self,
        task: &mut ReconstructionTask,
        window: usize,
    ) -> Result<Vec<egoexo_infer::passes::WindowOutput>, WorkerError> {
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let open = self.session.as_ref().ok_or(WorkerError::NoSession)?;
        Ok(if self.clock.is_set() {
            let mut now = self.clock.now_fn();
            task.job.run_window_timed(engine, &open.aligned, window, &mut now)?
        } else {
            task.job.run_window(engine, &open.aligned, window, &mut StageTimer::off())?
        })
    }

    /// Decodes the next chunk of a pooled `task` (computed here or by a helper; a helper's
    /// network runs count in the summary).
    pub fn add_pool_chunk(
        &self,
        task: &mut ReconstructionTask,
        outputs: &ChunkOutputs,
    ) -> Result<JobProgress, WorkerError> {
        let Progress { stage, .. } = task.job.add_chunk(outputs)?;
        task.helper_runs = task.helper_runs + outputs.runs;
        Ok(JobProgress { stage: job_stage(stage), done: task.job.done_steps(), total: task.job.total_steps() })
    }

    /// A helper's copy of a coordinator's pooled job: the session from
    /// [`Self::pool_session`]'s bytes, the same methods and `chunk_windows` windows per chunk.
    pub fn start_pool_helper(
        &self,
        session: &[u8],
        ego_only_overlay: bool,
        chunk_windows: usize,
    ) -> Result<PoolHelperJob, WorkerError> {
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let aligned = crate::pool::decode_pool_session(session)?;
        let mut job = start_job(engine, &aligned, ego_only_overlay)?;
        job.set_chunk(chunk_windows)?;
        Ok(PoolHelperJob { job, aligned })
    }

    /// Chunk `chunk` of a helper's job, as the bytes the coordinator decodes.
    pub fn run_pool_chunk(&self, helper: &PoolHelperJob, chunk: usize) -> Result<Vec<u8>, WorkerError> {
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let before = engine.network_runs();
        let mut outputs = helper.job.run_chunk(engine, &helper.aligned, chunk)?;
        outputs.runs = engine.network_runs() - before;
        Ok(outputs.to_bytes()?)
    }

    /// Runs the next window of `task`; `None` when every pass is done.
    pub fn step_reconstruction(&self, task: &mut ReconstructionTask) -> Result<Option<JobProgress>, WorkerError> {
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let open = self.session.as_ref().ok_or(WorkerError::NoSession)?;
        let progress = if self.clock.is_set() {
            let mut now = self.clock.now_fn();
            task.job.step_timed(engine, &open.aligned, &mut now)?
        } else {
            task.job.step(engine, &open.aligned)?
        };
        let Some(progress) = progress else { return Ok(None) };
        let stage = job_stage(progress.stage);
        Ok(Some(JobProgress { stage, done: task.job.done_steps(), total: task.job.total_steps() }))
    }

    /// Finishes `task` (every step must have run) and keeps its results for the scene and
    /// the exports.
    pub fn finish_reconstruction(&mut self, task: ReconstructionTask) -> Result<ReconstructionSummary, WorkerError> {
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let open = self.session.as_ref().ok_or(WorkerError::NoSession)?;
        let windows = task.job.plan().windows.len();
        let runs = (engine.network_runs() - task.runs_before) + task.helper_runs;
        let (reconstructions, mut timings) = if self.clock.is_set() {
            let mut now = self.clock.now_fn();
            task.job.finish_timed(&open.aligned, &mut now)?
        } else {
            (task.job.finish(&open.aligned)?, StageTimings::default())
        };
        let mut reconstructions = reconstructions.into_iter();
        let ego_exo = reconstructions.next().ok_or(WorkerError::NoReconstruction)?;
        let ego_only = reconstructions.next();
        let mut summary = reconstruction_summary(&open.aligned, &ego_exo, ego_only.as_ref(), windows, runs);
        summary.pool = task.pool;
        summary.detection = open.detection.clone();
        let participant = self.group.as_ref().map(|g| g.scene_participant(g.selected));
        let scene_json = self.timed(&mut timings, TimedStage::Scene, || {
            let mut scene = crate::scene::build_scene(&open.aligned, &ego_exo, ego_only.as_ref());
            scene.participant = participant.clone();
            scene.check().map_err(WorkerError::Scene)?;
            serde_json::to_vec(&scene).map_err(|e| WorkerError::Scene(e.to_string()))
        })?;
        summary.participant = participant.map(|p| p.id);
        timings.merge(&open.timings);
        summary.timings = timings
            .stages
            .iter()
            .map(|s| protocol::StageTiming { stage: s.stage.name().to_string(), ms: s.ms, calls: s.calls })
            .collect();
        self.results = Some(Results {
            name: open.aligned.name.clone(),
            method: ego_exo.method.name().to_string(),
            motion: ego_exo.motion.clone(),
            scene_json,
            summary: summary.clone(),
            session: open.summary.clone(),
            made_here: Some((ego_exo, ego_only)),
        });
        self.store_participant_results();
        Ok(summary)
    }

    /// Reconstructs the open session in one go ([`SessionWorker::start_reconstruction`], every
    /// step, [`SessionWorker::finish_reconstruction`]). `progress` is called after every
    /// window of every pass; returning `false` cancels ([`InferError::Cancelled`]) and keeps no
    /// result.
    /// A capture of several participants: everyone in turn (after the association), the
    /// shown participant's summary returned (with everyone's rows).
    pub fn reconstruct(
        &mut self,
        ego_only_overlay: bool,
        progress: &mut dyn FnMut(JobProgress) -> bool,
    ) -> Result<ReconstructionSummary, WorkerError> {
        let Some(run) = self.begin_group_reconstruction()? else {
            return self.reconstruct_open_session(ego_only_overlay, progress);
        };
        for id in &run.participants {
            self.open_participant_for_reconstruction(id)?;
            self.reconstruct_open_session(ego_only_overlay, progress)?;
        }
        Ok(self.finish_group_reconstruction(run)?.0)
    }

    fn reconstruct_open_session(
        &mut self,
        ego_only_overlay: bool,
        progress: &mut dyn FnMut(JobProgress) -> bool,
    ) -> Result<ReconstructionSummary, WorkerError> {
        let mut task = self.start_reconstruction(ego_only_overlay)?;
        while let Some(p) = self.step_reconstruction(&mut task)? {
            if !progress(p) {
                return Err(InferError::Cancelled.into());
            }
        }
        self.finish_reconstruction(task)
    }

    /// The models' frame rate, for a [`LiveReconstructor`](crate::live::LiveReconstructor).
    pub fn live_fps(&self) -> f32 {
        self.fps()
    }

    /// Reconstructs the newest frame of a live take that can be shown, if any.
    pub fn live_frame(
        &self,
        live: &mut crate::live::LiveReconstructor,
    ) -> Result<Option<crate::live::LiveFrame>, WorkerError> {
        let models = self.models.as_ref().ok_or(WorkerError::NoModels)?;
        Ok(live.reconstruct_next(models.for_lookahead(live.lookahead()))?)
    }

    /// "Stop and keep": the take becomes the open session (replacing any), ready for the
    /// offline reconstruction, exports, sharing and [`SessionWorker::save_session`].
    pub fn keep_take(
        &mut self,
        take: &egoexo_session::live::LiveTake,
        name: &str,
    ) -> Result<SessionSummary, WorkerError> {
        if take.wearers().len() > 1 {
            // Several wearers: the take is a capture of them all, opened like a dropped one.
            let (capture, warnings) = take.to_capture(name)?;
            let imported = egoexo_session::import::ImportedCapture {
                capture,
                source: egoexo_session::SourceKind::Egoexo,
                warnings,
            };
            return self.open_capture(None, imported, StageTimings::default());
        }
        let (session, warnings) = take.to_session(name, None)?;
        self.open_imported(Imported { session, source: egoexo_session::SourceKind::Egoexo, warnings })
    }

    /// The open session as a `.egoexo` file.
    pub fn save_session(&self) -> Result<ExportedFile, WorkerError> {
        let open = self.session.as_ref().ok_or(WorkerError::NoSession)?;
        // A capture of several participants is saved whole (version 3), with every keypoint
        // the detector step found.
        if let Some((name, bytes)) = self.capture_zip(true) {
            return Ok(ExportedFile {
                bytes: bytes.map_err(|e| WorkerError::SaveSession(e.to_string()))?,
                file_name: format!("{}.egoexo", file_name(&name)),
                mime_type: "application/zip",
            });
        }
        // The observers' videos go with it: a saved session opens again as it was.
        let videos = open.videos.iter().map(|(path, bytes)| (path.clone(), bytes.to_vec())).collect();
        let bytes = write_egoexo_zip_with(&open.imported.session, videos)
            .map_err(|e| WorkerError::SaveSession(e.to_string()))?;
        let name = file_name(&open.imported.session.name);
        Ok(ExportedFile { bytes, file_name: format!("{name}.egoexo"), mime_type: "application/zip" })
    }

    /// The last reconstruction made here (the full method), if any.
    pub fn reconstruction(&self) -> Option<&Reconstruction> {
        self.results.as_ref().and_then(|r| r.made_here.as_ref()).map(|(ego_exo, _)| ego_exo)
    }

    /// The ego-only reconstruction of the overlay, if any.
    pub fn ego_only_reconstruction(&self) -> Option<&Reconstruction> {
        self.results.as_ref().and_then(|r| r.made_here.as_ref()).and_then(|(_, ego_only)| ego_only.as_ref())
    }

    /// The summary of the last reconstruction.
    pub fn reconstruction_summary(&self) -> Option<&ReconstructionSummary> {
        self.results.as_ref().map(|r| &r.summary)
    }

    /// The viewer's scene of what is shown ([`egoexo_scene::SceneData`]) as JSON.
    pub fn scene_json(&self) -> Result<Vec<u8>, WorkerError> {
        Ok(self.results.as_ref().ok_or(WorkerError::NoReconstruction)?.scene_json.clone())
    }

    /// Writes the shown motion (the full method) in `format`.
    pub fn export(&self, format: ExportFormat) -> Result<ExportedFile, WorkerError> {
        let results = self.results.as_ref().ok_or(WorkerError::NoReconstruction)?;
        let format = motion_format(format);
        let bytes = egoexo_motion_io::write(format, &results.motion)?;
        Ok(ExportedFile {
            bytes,
            file_name: format!("{}-{}.{}", file_name(&results.name), results.method, format.extension()),
            mime_type: format.mime_type(),
        })
    }

    /// What is shown, as a share container (`egoexo_share::container`; not yet sealed),
    /// with the recording as a `.egoexo` session when `include_recording` and the session is
    /// open here. `created_by` names the app (`egoexo 0.1.0 (page)`).
    pub fn pack_share(&self, include_recording: bool, created_by: &str) -> Result<Vec<u8>, WorkerError> {
        let results = self.results.as_ref().ok_or(WorkerError::NoReconstruction)?;
        // The recording: a capture of several participants whole, else the open session.
        let session_egoexo = match (&self.session, include_recording) {
            (Some(open), true) => Some(
                match self.capture_zip(false) {
                    Some((_, bytes)) => bytes,
                    None => write_egoexo_zip(&open.imported.session),
                }
                .map_err(|e| WorkerError::ShareRecording(e.to_string()))?,
            ),
            _ => None,
        };
        let contents = ShareContents {
            manifest: ShareManifest::new(&results.name, created_by, results.summary.clone(), results.session.clone()),
            scene_json: results.scene_json.clone(),
            motion: results.motion.clone(),
            session_egoexo,
            participants: self.shared_participants(),
        };
        Ok(egoexo_share::pack(&contents)?)
    }

    /// Whether a share made now could include the recording (a session is open here).
    pub fn can_share_recording(&self) -> bool {
        self.session.is_some()
    }

    /// Opens a share container (already opened from its envelope): shows its scene and motion
    /// (exports work), and when it includes the recording, opens that session so it can be
    /// reconstructed again.
    pub fn open_share(&mut self, container: Vec<u8>) -> Result<OpenedShare, WorkerError> {
        let contents = egoexo_share::unpack(container)?;
        self.results = None;
        self.session = None;
        self.group = None;
        if let Some(recording) = contents.session_egoexo {
            let name = format!("{}.egoexo", contents.manifest.name);
            self.import(&FileTree::from_zip(name, recording, Limits::default())?)?;
        }
        let manifest = contents.manifest;
        self.results = Some(Results {
            name: manifest.name.clone(),
            method: manifest.summary.method.clone(),
            motion: contents.motion,
            scene_json: contents.scene_json.clone(),
            summary: manifest.summary.clone(),
            session: manifest.session.clone(),
            made_here: None,
        });
        self.open_shared_participants(contents.participants, manifest.summary.participant.as_deref())?;
        Ok(OpenedShare { manifest, scene_json: contents.scene_json })
    }
}

/// The motion file format of a protocol export format.
pub fn motion_format(format: ExportFormat) -> Format {
    match format {
        ExportFormat::Npz => Format::Npz,
        ExportFormat::Bvh => Format::Bvh,
        ExportFormat::Glb => Format::Glb,
        ExportFormat::Csv => Format::Csv,
    }
}

/// The worker's job on `aligned` (the same for the page's worker and a pool's helpers), its
/// tracking mode's networks parsed and optimised now rather than inside the first window's
/// stage timings.
fn start_job(
    engine: &Engine,
    aligned: &AlignedSession,
    ego_only_overlay: bool,
) -> Result<ReconstructionJob, WorkerError> {
    let job = engine.start(aligned, &ReconstructOptions::default(), job_methods(ego_only_overlay))?;
    if let Some(set) = engine.models(job.plan().tracking) {
        set.prepare()?;
    }
    Ok(job)
}

fn align_for(imported: &Imported, fps: f32) -> Result<AlignedSession, WorkerError> {
    align(&imported.session, &AlignOptions { fps, ..AlignOptions::default() })
        .map_err(|source| WorkerError::Align { session: imported.session.name.clone(), source })
}

fn projection_name(projection: &Projection) -> &'static str {
    match projection {
        Projection::Pinhole(_) => "pinhole",
        Projection::Fisheye624(_) => "fisheye624",
    }
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

fn session_summary(
    imported: &Imported,
    aligned: &AlignedSession,
    videos: &BTreeMap<String, Arc<[u8]>>,
) -> SessionSummary {
    let session = &imported.session;
    let mut devices = vec!["head".to_string()];
    devices.extend(session.wearer.left_wrist.as_ref().map(|_| "left_wrist".to_string()));
    devices.extend(session.wearer.right_wrist.as_ref().map(|_| "right_wrist".to_string()));
    let observers = session
        .observers
        .iter()
        .zip(&aligned.observers)
        .map(|(o, a)| ObserverSummary {
            id: o.id.clone(),
            camera: format!("{} {}×{}", projection_name(&o.camera.projection), o.camera.width, o.camera.height),
            keypoint_frames: a.keypoints.iter().filter(|f| f.iter().any(Option::is_some)).count(),
            video: o.video.as_ref().map(|v| v.path.clone()),
            needs_detection: o.keypoints.is_none() && o.video.as_ref().is_some_and(|v| videos.contains_key(&v.path)),
            world: o.placement.describe(),
            fused: o.placement.fusable(),
        })
        .collect();
    let mut warnings: Vec<String> = imported.warnings.iter().map(ToString::to_string).collect();
    for o in &session.observers {
        if let Some(video) = o.video.as_ref().filter(|v| o.keypoints.is_none() && !videos.contains_key(&v.path)) {
            warnings.push(format!(
                "observer `{}` names the video `{}`, which is not in the session: it cannot contribute rays",
                o.id, video.path
            ));
        } else if o.keypoints.is_none() && o.video.is_none() {
            warnings.push(format!("observer `{}` has no 2D keypoints: it is shown but cannot contribute rays", o.id));
        }
    }
    let timeline = &aligned.timeline;
    let choice = aligned.tracking_choice();
    SessionSummary {
        name: aligned.name.clone(),
        source: imported.source.describe().to_string(),
        frames: timeline.frames,
        fps: timeline.fps,
        duration_s: timeline.frames as f32 / timeline.fps,
        devices,
        tracking_points: choice.mode.points(),
        tracking_reason: choice.reason,
        wrists: wrist_summaries(session, aligned),
        floor: egoexo_session::floor::floor_or_estimate(session)
            .map(|f| FloorSummary { height_m: f.height_m, source: f.source.describe() }),
        observers,
        ground_truth: aligned.ground_truth.is_some(),
        warnings,
        participants: Vec::new(),
        participant: None,
    }
}

/// Per wrist: source and coverage of the timeline (what `egoexo inspect` prints too).
fn wrist_summaries(session: &egoexo_session::Session, aligned: &AlignedSession) -> Vec<WristSummary> {
    [("left", &aligned.left_wrist), ("right", &aligned.right_wrist)]
        .into_iter()
        .filter_map(|(side, w)| {
            let coverage = w.as_ref()?.coverage();
            Some(WristSummary {
                side: side.into(),
                source: session.wearer.wrist_source.describe(),
                tracked_percent: coverage.tracked_fraction * 100.0,
                longest_gap_s: coverage.longest_gap_frames as f32 / aligned.timeline.fps,
            })
        })
        .collect()
}

fn reconstruction_summary(
    aligned: &AlignedSession,
    ego_exo: &Reconstruction,
    ego_only: Option<&Reconstruction>,
    windows: usize,
    runs: NetworkRuns,
) -> ReconstructionSummary {
    let accuracy = aligned.ground_truth.as_ref().and_then(|gt| {
        let mpjpe = |r: &Reconstruction| aligned.ground_truth_mpjpe_cm(&r.joints, &r.valid);
        let frames = gt.valid.iter().zip(&ego_exo.valid).filter(|(g, v)| **g && **v).count();
        Some(Accuracy { frames, ego_exo_mpjpe_cm: mpjpe(ego_exo)?, ego_only_mpjpe_cm: ego_only.and_then(mpjpe) })
    });
    let mut observers_used: BTreeMap<&str, usize> = BTreeMap::new();
    for g in &ego_exo.gates {
        let used = g.gates.iter().filter(|f| f.iter().any(|&v| v > 0.0)).count();
        observers_used.insert(&g.observer_id, used);
    }
    ReconstructionSummary {
        method: ego_exo.method.name().to_string(),
        tracking_points: ego_exo.tracking.points(),
        frames: ego_exo.joints.len(),
        valid_frames: ego_exo.valid.iter().filter(|&&v| v).count(),
        windows,
        network_runs: protocol::NetworkRuns {
            egonet: runs.egonet,
            gate: runs.gate,
            fusion: runs.fusion,
            fusion_ego_only: runs.fusion_ego_only,
        },
        exo_evidence_frames: ego_exo.exo_evidence.iter().filter(|&&v| v).count(),
        observer_ray_frames: observers_used.into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
        accuracy,
        timings: Vec::new(),
        pool: None,
        detection: Vec::new(),
        participant: None,
        participants: Vec::new(),
        association: Vec::new(),
    }
}

/// `name` as a file name: letters, digits, `-`, `_` and `.` kept, anything else `_`.
fn file_name(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') { c } else { '_' }).collect()
}
