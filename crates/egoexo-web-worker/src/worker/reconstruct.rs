//! Reconstructing the open session: a [`ReconstructionTask`] stepped window by window (or
//! shared with a pool: [`PoolHelperJob`], chunks), finished into the results the page shows.

use super::*;

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
pub(super) fn job_methods(ego_only_overlay: bool) -> &'static [Method] {
    if ego_only_overlay { &[Method::EgoExo, Method::EgoOnly] } else { &[Method::EgoExo] }
}

/// The protocol's stage of an engine stage.
pub(super) fn job_stage(stage: Stage) -> JobStage {
    match stage {
        Stage::Ego => JobStage::EgoPass,
        Stage::Fusion(Method::EgoOnly) => JobStage::EgoOnlyOverlay,
        Stage::Fusion(_) => JobStage::ExoFusion,
    }
}

/// The worker's job on `aligned` (the same for the page's worker and a pool's helpers), its
/// tracking mode's networks parsed and optimised now rather than inside the first window's
/// stage timings.
pub(super) fn start_job(
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

pub(super) fn reconstruction_summary(
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

impl SessionWorker {
    /// Starts reconstructing the open session with the full method and, if
    /// `ego_only_overlay`, ego-only for the comparison overlay (one shared ego pass). The
    /// previous results are dropped. Step it with [`SessionWorker::step_reconstruction`].
    pub fn start_reconstruction(&mut self, ego_only_overlay: bool) -> Result<ReconstructionTask, WorkerError> {
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let fps = self.fps();
        let Some(Shown { session: Some(open), results }) = self.opened.shown_mut() else {
            return Err(WorkerError::NoSession);
        };
        if open.aligned.timeline.fps != fps {
            open.aligned = align_for(&open.imported, fps)?;
            open.timings = StageTimings::default();
        }
        *results = None;
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
        let open = self.opened.session().ok_or(WorkerError::NoSession)?;
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
        let open = self.opened.session().ok_or(WorkerError::NoSession)?;
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
        let open = self.opened.session().ok_or(WorkerError::NoSession)?;
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
        let open = self.opened.session().ok_or(WorkerError::NoSession)?;
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
        let participant = self.opened.group().map(|g| g.scene_participant(g.selected));
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
        let shown = Results {
            name: open.aligned.name.clone(),
            method: ego_exo.method.name().to_string(),
            motion: ego_exo.motion.clone(),
            scene_json,
            summary: summary.clone(),
            session: open.summary.clone(),
            made_here: Some((ego_exo, ego_only)),
        };
        self.opened.shown_mut().ok_or(WorkerError::NoSession)?.results = Some(shown);
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
}
