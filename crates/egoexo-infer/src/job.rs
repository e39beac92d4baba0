//! A reconstruction as a resumable computation: one window of one pass per
//! [`ReconstructionJob::step`].
//!
//! The job holds only its own state (the plan, the ego pass's outputs, one
//! [`MotionAssembler`] per method); the engine and the aligned session are passed in at every
//! step, so a caller can give control back between steps — the browser's worker yields to its
//! event loop there, so that a cancel request is read while a long session runs. Several
//! methods that share a coarse-pose source (ego-exo and the ego-only overlay) share one ego
//! pass: EgoNet runs once per window per job.
//!
//! Steps, in order, chunk by chunk of [`WINDOW_CHUNK`] windows: the ego pass over the chunk's
//! windows, then for each method its exo and fusion passes over them (for a baseline, its
//! coarse pose decoded). Only a chunk's ego outputs are held at once, so an hour-long session
//! (~2,300 windows) never holds every window's features and coarse pose; a session of up to a
//! chunk runs pass by pass.
//!
//! A chunk is also the unit a pool of workers shares out: [`ReconstructionJob::run_chunk`]
//! computes a chunk's window outputs without touching the job (in another worker that made
//! the same job from the same session and options), [`ChunkOutputs`] travel as bytes, and
//! [`ReconstructionJob::add_chunk`] decodes them in chunk order — the same functions and the
//! same order of decoding as [`ReconstructionJob::step`], so the same result.

use std::ops::Range;

use egoexo_core::aligned::AlignedSession;
use egoexo_core::ego_features::TrackingMode;
use serde::{Deserialize, Serialize};

use crate::InferError;
use crate::decode::{MotionAssembler, assemble_reconstruction};
use crate::engine::Engine;
use crate::inputs::POSE_DIM;
use crate::models::NetworkRuns;
use crate::passes::{EgoPassOutput, WindowOutput, ego_pass, observer_fusion_pass};
use crate::plan::{ReconstructionPlan, resolve_tracking};
use crate::reconstruction::{CoarsePose, Method, Progress, ReconstructOptions, Reconstruction, Stage};
use crate::timing::{Clock, StageTimer, StageTimings, TimedStage};
use crate::windows::WindowError;

/// Windows per chunk of a job (sequential steps and [`ReconstructionJob::run_in_parallel`]):
/// enough to keep a few cores busy, few enough that a chunk's outputs stay small (an
/// hour-long session has ~2,300 windows; a chunk is ~100 s of a session at the default
/// stride).
pub const WINDOW_CHUNK: usize = 64;

/// One chunk's window outputs, one list per method of the job (in the job's order): what
/// [`ReconstructionJob::run_chunk`] computes — here or in another worker holding the same
/// job — and [`ReconstructionJob::add_chunk`] decodes, chunk after chunk.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChunkOutputs {
    /// Index of the chunk: its windows are [`ReconstructionJob::chunk_windows`]`(chunk)`.
    pub chunk: usize,
    /// Per method, the chunk's windows in order.
    pub methods: Vec<Vec<WindowOutput>>,
    /// The network runs that computed it, as the worker that did counted them (zero unless
    /// that worker says: [`ReconstructionJob::run_chunk`] leaves the counting to its caller).
    pub runs: NetworkRuns,
}

impl ChunkOutputs {
    /// An empty chunk `chunk` of a job of `methods` methods, to fill window by window.
    pub fn new(chunk: usize, methods: usize) -> Self {
        ChunkOutputs { chunk, methods: vec![Vec::new(); methods], runs: NetworkRuns::default() }
    }

    /// Appends one window's outputs, one per method ([`ReconstructionJob::run_window`]).
    pub fn push_window(&mut self, outputs: Vec<WindowOutput>) {
        for (list, output) in self.methods.iter_mut().zip(outputs) {
            list.push(output);
        }
    }

    /// The outputs as bytes (postcard), to hand to another worker.
    pub fn to_bytes(&self) -> Result<Vec<u8>, InferError> {
        postcard::to_allocvec(self).map_err(|e| InferError::Chunk { chunk: self.chunk, message: e.to_string() })
    }

    /// Outputs from [`Self::to_bytes`]'s bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, InferError> {
        postcard::from_bytes(bytes).map_err(|e| InferError::ChunkBytes { bytes: bytes.len(), message: e.to_string() })
    }
}

/// One reconstruction of one session with one or more methods (see the module docs).
#[derive(Clone, Debug)]
pub struct ReconstructionJob {
    plan: ReconstructionPlan,
    methods: Vec<Method>,
    coarse: CoarsePose,
    /// The ego pass's output per window of the current chunk.
    ego: Vec<EgoPassOutput>,
    /// One per method.
    assemblers: Vec<MotionAssembler>,
    /// Windows per chunk.
    chunk: usize,
    /// First window of the current chunk.
    chunk_start: usize,
    /// 0: the ego pass; `1 + m`: method `m`'s passes (within the current chunk).
    pass: usize,
    /// Next window of the current pass, counted from the chunk's start.
    window: usize,
    /// Steps run.
    steps: usize,
    /// The floor the feet are kept above, when the options ask and the session knows it.
    floor_y: Option<f32>,
    /// Time per stage of the steps run with a clock ([`Self::step_timed`]).
    timings: StageTimings,
}

impl ReconstructionJob {
    /// Plans the job: resolves the tracking mode, checks that every method's models (or
    /// index) are loaded and that the methods share a coarse-pose source.
    pub fn new(
        engine: &Engine,
        aligned: &AlignedSession,
        options: &ReconstructOptions,
        methods: &[Method],
    ) -> Result<Self, InferError> {
        let Some(first) = methods.first() else {
            return Err(InferError::NoMethod);
        };
        let coarse = first.coarse_pose();
        if let Some(other) = methods.iter().find(|m| m.coarse_pose() != coarse) {
            return Err(InferError::CoarseSourcesDiffer { first: *first, other: *other });
        }
        let tracking = resolve_tracking(aligned, options.tracking)?;
        engine.coarse_pose_source(coarse, tracking)?;
        let networks = methods.iter().any(|m| m.exo_mode().is_some());
        let slots = if networks { engine.require_models(tracking)?.manifest.max_observers } else { 0 };
        let plan = ReconstructionPlan::new(aligned, tracking, &options.windows(), slots)?;
        let assemblers =
            methods.iter().map(|_| MotionAssembler::new(aligned.observers.len(), plan.crossfade_ramp)).collect();
        Ok(Self {
            ego: Vec::with_capacity(WINDOW_CHUNK.min(plan.windows.len())),
            plan,
            methods: methods.to_vec(),
            coarse,
            assemblers,
            chunk: WINDOW_CHUNK,
            chunk_start: 0,
            pass: 0,
            window: 0,
            steps: 0,
            floor_y: aligned.floor_y.filter(|y| options.floor_contact && y.is_finite()),
            timings: StageTimings::default(),
        })
    }

    /// The plan.
    pub fn plan(&self) -> &ReconstructionPlan {
        &self.plan
    }

    /// The methods, in the order of their passes and results.
    pub fn methods(&self) -> &[Method] {
        &self.methods
    }

    /// Steps in the whole job: windows × (1 + methods).
    pub fn total_steps(&self) -> usize {
        self.plan.windows.len() * (1 + self.methods.len())
    }

    /// Steps done so far.
    pub fn done_steps(&self) -> usize {
        self.steps
    }

    /// Sets the windows per chunk (≥ 1; [`WINDOW_CHUNK`] by default) of a job that has not
    /// started; the result does not depend on it, only the order of the steps and the memory
    /// held do.
    pub fn set_chunk(&mut self, windows: usize) -> Result<(), InferError> {
        if self.steps != 0 {
            return Err(WindowError::ChunkAfterStart.into());
        }
        self.chunk = windows.max(1);
        Ok(())
    }

    /// Ego-pass outputs held now (at most a chunk's).
    pub fn held_ego_passes(&self) -> usize {
        self.ego.len()
    }

    /// Chunks in the job (at the chunk size of [`Self::set_chunk`]).
    pub fn chunk_count(&self) -> usize {
        self.plan.windows.len().div_ceil(self.chunk)
    }

    /// Window indices of chunk `chunk` (empty past the last).
    pub fn chunk_windows(&self, chunk: usize) -> Range<usize> {
        let windows = self.plan.windows.len();
        let start = chunk.saturating_mul(self.chunk).min(windows);
        start..(start + self.chunk).min(windows)
    }

    /// The chunk [`Self::add_chunk`] takes next; `None` when every chunk is in, or while a
    /// chunk is half stepped through with [`Self::step`].
    pub fn next_chunk(&self) -> Option<usize> {
        let at_boundary = self.pass == 0 && self.window == 0 && self.chunk_start.is_multiple_of(self.chunk);
        (at_boundary && self.chunk_start < self.plan.windows.len()).then_some(self.chunk_start / self.chunk)
    }

    /// Every method's output for window `window` of the plan (its ego pass run once), without
    /// changing the job: what a chunk is made of.
    pub fn run_window(
        &self,
        engine: &Engine,
        aligned: &AlignedSession,
        window: usize,
        timer: &mut StageTimer<'_>,
    ) -> Result<Vec<WindowOutput>, InferError> {
        self.plan.check_session(aligned)?;
        let plan =
            self.plan.windows.get(window).ok_or_else(|| {
                InferError::from(WindowError::NoSuchWindow { window, windows: self.plan.windows.len() })
            })?;
        let tracking = self.plan.tracking;
        let source = engine.coarse_pose_source(self.coarse, tracking)?;
        let ego = ego_pass(aligned, plan, tracking, source, timer)?;
        self.methods
            .iter()
            .map(|&method| method_window(engine, aligned, tracking, &self.plan.observers, method, &ego, timer))
            .collect()
    }

    /// [`Self::run_window`], timing its stages with `clock` into [`Self::timings`].
    pub fn run_window_timed(
        &mut self,
        engine: &Engine,
        aligned: &AlignedSession,
        window: usize,
        clock: &mut dyn Clock,
    ) -> Result<Vec<WindowOutput>, InferError> {
        let mut timer = StageTimer::new(clock);
        let outputs = self.run_window(engine, aligned, window, &mut timer);
        self.timings.merge(&timer.timings);
        outputs
    }

    /// Chunk `chunk`'s window outputs, every method, without changing the job.
    pub fn run_chunk(
        &self,
        engine: &Engine,
        aligned: &AlignedSession,
        chunk: usize,
    ) -> Result<ChunkOutputs, InferError> {
        let windows = self.chunk_windows(chunk);
        if windows.is_empty() {
            return Err(InferError::Chunk { chunk, message: format!("the job has {} chunks", self.chunk_count()) });
        }
        let mut outputs = ChunkOutputs::new(chunk, self.methods.len());
        for window in windows {
            outputs.push_window(self.run_window(engine, aligned, window, &mut StageTimer::off())?);
        }
        Ok(outputs)
    }

    /// Decodes chunk [`Self::next_chunk`]'s outputs (computed by [`Self::run_chunk`] here or
    /// in another worker): every step of the chunk counts as run. Outputs for another chunk,
    /// another method list or other windows than the plan's are refused, and the job is left
    /// as it was.
    pub fn add_chunk(&mut self, outputs: &ChunkOutputs) -> Result<Progress, InferError> {
        let chunk = outputs.chunk;
        let refuse = |message: String| Err(InferError::Chunk { chunk, message });
        match self.next_chunk() {
            Some(next) if next == chunk => {}
            Some(next) => return refuse(format!("chunk {next} is the next to decode")),
            None => return refuse("the job takes no chunk now".into()),
        }
        let windows = self.chunk_windows(chunk);
        if outputs.methods.len() != self.methods.len() {
            return refuse(format!("{} methods' outputs for a job of {}", outputs.methods.len(), self.methods.len()));
        }
        for list in &outputs.methods {
            let planned = &self.plan.windows[windows.clone()];
            if list.len() != planned.len()
                || list.iter().zip(planned).any(|(o, w)| o.plan != *w || o.poses.len() < w.len() * POSE_DIM)
            {
                return refuse(format!("outputs are not for windows {windows:?} of this job's plan"));
            }
        }
        for (list, assembler) in outputs.methods.iter().zip(&mut self.assemblers) {
            for output in list {
                assembler.add(output)?;
            }
        }
        self.chunk_start = windows.end;
        self.steps += windows.len() * (1 + self.methods.len());
        // A chunk ran every pass: its progress names the first method's (the result's) fusion.
        let stage = self.methods.first().map_or(Stage::Ego, |&m| Stage::Fusion(m));
        Ok(Progress { stage, done: windows.end, total: self.plan.windows.len() })
    }

    /// Runs the next step (one window of one pass of the current chunk); `None` when every
    /// step has run. `engine` and
    /// `aligned` must be the ones the job was started with.
    pub fn step(&mut self, engine: &Engine, aligned: &AlignedSession) -> Result<Option<Progress>, InferError> {
        self.step_with(engine, aligned, &mut StageTimer::off())
    }

    /// [`Self::step`], timing its stages with `clock` into [`Self::timings`].
    pub fn step_timed(
        &mut self,
        engine: &Engine,
        aligned: &AlignedSession,
        clock: &mut dyn Clock,
    ) -> Result<Option<Progress>, InferError> {
        let mut timer = StageTimer::new(clock);
        let step = self.step_with(engine, aligned, &mut timer);
        self.timings.merge(&timer.timings);
        step
    }

    /// The time per engine stage of the steps run with [`Self::step_timed`] (and the decode
    /// of [`Self::finish_timed`]).
    pub fn timings(&self) -> &StageTimings {
        &self.timings
    }

    fn step_with(
        &mut self,
        engine: &Engine,
        aligned: &AlignedSession,
        timer: &mut StageTimer<'_>,
    ) -> Result<Option<Progress>, InferError> {
        let windows = self.plan.windows.len();
        if self.chunk_start >= windows {
            return Ok(None);
        }
        self.plan.check_session(aligned)?;
        let chunk_len = self.chunk.min(windows - self.chunk_start);
        let i = self.chunk_start + self.window;
        let tracking = self.plan.tracking;
        let stage = if self.pass == 0 {
            let source = engine.coarse_pose_source(self.coarse, tracking)?;
            self.ego.push(ego_pass(aligned, &self.plan.windows[i], tracking, source, timer)?);
            Stage::Ego
        } else {
            let method = self.methods[self.pass - 1];
            let ego = &self.ego[self.window];
            let output = method_window(engine, aligned, tracking, &self.plan.observers, method, ego, timer)?;
            let assembler = &mut self.assemblers[self.pass - 1];
            timer.time(TimedStage::Decode, || assembler.add(&output))?;
            Stage::Fusion(method)
        };
        self.steps += 1;
        self.window += 1;
        if self.window == chunk_len {
            self.window = 0;
            self.pass += 1;
            if self.pass > self.methods.len() {
                // Every pass of the chunk ran: its ego outputs are done with.
                self.pass = 0;
                self.chunk_start += chunk_len;
                self.ego.clear();
            }
        }
        // The stage's windows run in order, chunk after chunk: windows 0..=i are done.
        Ok(Some(Progress { stage, done: i + 1, total: windows }))
    }

    /// Runs every step of a job that has not started, its windows spread over the current
    /// rayon pool: chunks of `chunk` windows ([`WINDOW_CHUNK`] in the engine), each chunk's
    /// ego passes in parallel,
    /// then each method's exo and fusion passes in parallel, decoded in window order — the same
    /// functions and order of decoding as [`Self::step`], so the same result; at most a
    /// chunk's window outputs are held at once. `progress` is called after every chunk;
    /// returning `false` cancels.
    #[cfg(feature = "parallel")]
    pub fn run_in_parallel(
        &mut self,
        engine: &Engine,
        aligned: &AlignedSession,
        chunk: usize,
        progress: &mut dyn FnMut(Progress) -> bool,
    ) -> Result<(), InferError> {
        use rayon::prelude::*;

        if self.done_steps() != 0 {
            return Err(WindowError::ParallelAfterStart.into());
        }
        self.plan.check_session(aligned)?;
        let tracking = self.plan.tracking;
        let source = engine.coarse_pose_source(self.coarse, tracking)?;
        let windows = self.plan.windows.len();
        let mut done = 0;
        for chunk in self.plan.windows.chunks(chunk.max(1)) {
            let ego: Vec<EgoPassOutput> = chunk
                .par_iter()
                .map(|w| ego_pass(aligned, w, tracking, source, &mut StageTimer::off()))
                .collect::<Result<_, _>>()?;
            for (method, assembler) in self.methods.iter().zip(&mut self.assemblers) {
                let outputs: Vec<WindowOutput> = ego
                    .par_iter()
                    .map(|ego| {
                        let observers = &self.plan.observers;
                        method_window(engine, aligned, tracking, observers, *method, ego, &mut StageTimer::off())
                    })
                    .collect::<Result<_, _>>()?;
                for output in &outputs {
                    assembler.add(output)?;
                }
            }
            done += chunk.len();
            let stage = self.methods.last().map_or(Stage::Ego, |&m| Stage::Fusion(m));
            if !progress(Progress { stage, done, total: windows }) {
                return Err(InferError::Cancelled);
            }
        }
        // Every pass has run: the state `step` leaves at the end.
        self.chunk_start = windows;
        self.pass = 0;
        self.window = 0;
        self.steps = self.total_steps();
        self.ego = Vec::new();
        Ok(())
    }

    /// Whether every step has run.
    pub fn is_done(&self) -> bool {
        self.done_steps() >= self.total_steps()
    }

    /// The reconstructions, one per method in order. Fails unless every step has run.
    pub fn finish(self, aligned: &AlignedSession) -> Result<Vec<Reconstruction>, InferError> {
        self.finish_with(aligned, &mut StageTimer::off())
    }

    /// [`Self::finish`], timing the final decode with `clock`; also returns every stage's
    /// time over the job (the steps run with [`Self::step_timed`], and this decode).
    pub fn finish_timed(
        self,
        aligned: &AlignedSession,
        clock: &mut dyn Clock,
    ) -> Result<(Vec<Reconstruction>, StageTimings), InferError> {
        let mut timings = self.timings.clone();
        let mut timer = StageTimer::new(clock);
        let out = self.finish_with(aligned, &mut timer)?;
        // The final decode counts as part of the decode stage, not as another call.
        for s in &timer.timings.stages {
            timings.add_time(s.stage, s.ms, 0);
        }
        Ok((out, timings))
    }

    fn finish_with(
        self,
        aligned: &AlignedSession,
        timer: &mut StageTimer<'_>,
    ) -> Result<Vec<Reconstruction>, InferError> {
        if !self.is_done() {
            return Err(WindowError::Unfinished { done: self.done_steps(), total: self.total_steps() }.into());
        }
        self.plan.check_session(aligned)?;
        let tracking = self.plan.tracking;
        let floor_y = self.floor_y;
        timer.time(TimedStage::Decode, || {
            self.methods
                .iter()
                .zip(self.assemblers)
                .map(|(&method, mut assembler)| {
                    let frames = assembler.take_frames(aligned, aligned.timeline.frames);
                    assemble_reconstruction(method, tracking, aligned, frames, floor_y)
                })
                .collect()
        })
    }
}

/// One method's window after the shared ego pass: a baseline's coarse pose as it is, or the
/// network methods' exo and fusion passes ([`observer_fusion_pass`]).
fn method_window(
    engine: &Engine,
    aligned: &AlignedSession,
    tracking: TrackingMode,
    observers: &[usize],
    method: Method,
    ego: &EgoPassOutput,
    timer: &mut StageTimer<'_>,
) -> Result<WindowOutput, InferError> {
    match method.exo_mode() {
        None => Ok(WindowOutput::from_coarse(ego)),
        Some(mode) => observer_fusion_pass(aligned, engine.require_models(tracking)?, ego, observers, mode, timer),
    }
}

/// Running the engine: a job per group of methods sharing a coarse-pose source.
impl Engine {
    /// Starts a reconstruction of `aligned` with every method of `methods`, sharing one ego
    /// pass (so the methods must share a coarse-pose source). `options.method` is ignored;
    /// step the job with [`ReconstructionJob::step`].
    pub fn start(
        &self,
        aligned: &AlignedSession,
        options: &ReconstructOptions,
        methods: &[Method],
    ) -> Result<ReconstructionJob, InferError> {
        ReconstructionJob::new(self, aligned, options, methods)
    }

    /// Reconstructs the wearer's motion. `progress` is called after every window of every
    /// pass; returning `false` cancels (the result is then [`InferError::Cancelled`]).
    pub fn reconstruct(
        &self,
        aligned: &AlignedSession,
        options: &ReconstructOptions,
        progress: &mut dyn FnMut(Progress) -> bool,
    ) -> Result<Reconstruction, InferError> {
        let mut all = self.reconstruct_each(aligned, options, &[options.method], progress)?;
        all.pop().ok_or(WindowError::NoResult.into())
    }

    /// Reconstructs with every method of `methods`, results in that order. Methods that share
    /// a coarse-pose source share one job and so one ego pass (ego-exo, its ungated ablation
    /// and the ego-only overlay run EgoNet once per window between them); the jobs run in
    /// the order of their first method.
    pub fn reconstruct_each(
        &self,
        aligned: &AlignedSession,
        options: &ReconstructOptions,
        methods: &[Method],
        progress: &mut dyn FnMut(Progress) -> bool,
    ) -> Result<Vec<Reconstruction>, InferError> {
        self.run_jobs(aligned, options, methods, &mut |engine, job| {
            while let Some(p) = job.step(engine, aligned)? {
                if !progress(p) {
                    return Err(InferError::Cancelled);
                }
            }
            Ok(())
        })
    }

    /// [`Engine::reconstruct_each`] with each job's windows spread over the current rayon
    /// pool ([`ReconstructionJob::run_in_parallel`]); the same results.
    #[cfg(feature = "parallel")]
    pub fn reconstruct_each_in_parallel(
        &self,
        aligned: &AlignedSession,
        options: &ReconstructOptions,
        methods: &[Method],
        progress: &mut dyn FnMut(Progress) -> bool,
    ) -> Result<Vec<Reconstruction>, InferError> {
        self.run_jobs(aligned, options, methods, &mut |engine, job| {
            job.run_in_parallel(engine, aligned, crate::job::WINDOW_CHUNK, progress)
        })
    }

    /// One job per group of methods sharing a coarse-pose source (groups in the order of
    /// their first method), each run to the end by `run`; results in the order of `methods`.
    fn run_jobs(
        &self,
        aligned: &AlignedSession,
        options: &ReconstructOptions,
        methods: &[Method],
        run: &mut dyn FnMut(&Engine, &mut ReconstructionJob) -> Result<(), InferError>,
    ) -> Result<Vec<Reconstruction>, InferError> {
        let mut results: Vec<Option<Reconstruction>> = vec![None; methods.len()];
        for members in coarse_pose_groups(methods) {
            let group: Vec<Method> = members.iter().map(|&i| methods[i]).collect();
            let mut job = self.start(aligned, options, &group)?;
            run(self, &mut job)?;
            for (i, r) in members.into_iter().zip(job.finish(aligned)?) {
                results[i] = Some(r);
            }
        }
        results.into_iter().map(|r| r.ok_or(InferError::NoMethod)).collect()
    }
}

/// Indices of `methods` grouped by coarse-pose source (one job each), groups in the order of
/// their first method.
fn coarse_pose_groups(methods: &[Method]) -> Vec<Vec<usize>> {
    let mut groups: Vec<(CoarsePose, Vec<usize>)> = Vec::new();
    for (i, method) in methods.iter().enumerate() {
        match groups.iter_mut().find(|(coarse, _)| *coarse == method.coarse_pose()) {
            Some((_, members)) => members.push(i),
            None => groups.push((method.coarse_pose(), vec![i])),
        }
    }
    groups.into_iter().map(|(_, members)| members).collect()
}
