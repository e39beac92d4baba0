//! The pool's two roles as plain state machines, driven by the wasm message loop
//! (`runtime/pool.rs`, which only posts and waits) and by the native tests alike — one copy of
//! the logic (`docs/worker-protocol.md`, "The worker pool"):
//!
//! - [`PoolCoordinator`] — the page's worker during one pooled job: it hands each helper the
//!   session (`pool-job`), gives ready helpers one chunk at a time (`pool-chunk`), computes
//!   chunks itself one window per turn, and decodes every chunk in chunk order as it comes in
//!   ([`ChunkSchedule`]). A helper that fails gives its chunk back and gets no more.
//! - [`PoolHelper`] — a helper: holds the coordinator's job and answers its requests.
//!
//! A turn never blocks: [`PoolCoordinator::turn`] says whether to yield to the event loop
//! (it computed a window), wait for a helper's message (nothing to compute) or stop (done).

use std::collections::BTreeSet;
use std::ops::Range;

use egoexo_infer::ChunkOutputs;
use egoexo_protocol::ByteBuf;
use egoexo_protocol::worker::{ErrorStage, JobId, PoolSummary, WorkerEvent, WorkerRequest};

use crate::pool::{ChunkSchedule, PoolError};
use crate::worker::{JobProgress, PoolHelperJob, ReconstructionTask, SessionWorker, WorkerError};

/// The byte arrays of the pool's messages: the JS `Uint8Array` in the browser
/// (`egoexo_protocol::JsBytes`), [`ByteBuf`] where the native tests drive the pool.
pub trait PoolBytes: Sized {
    /// A new array holding a copy of `bytes`.
    fn copy_from(bytes: &[u8]) -> Self;
    /// The bytes, copied.
    fn to_vec(&self) -> Vec<u8>;
}

#[cfg(target_arch = "wasm32")]
impl PoolBytes for egoexo_protocol::JsBytes {
    fn copy_from(bytes: &[u8]) -> Self {
        egoexo_protocol::JsBytes::copy_from(bytes)
    }
    fn to_vec(&self) -> Vec<u8> {
        egoexo_protocol::JsBytes::to_vec(self)
    }
}

impl PoolBytes for ByteBuf {
    fn copy_from(bytes: &[u8]) -> Self {
        ByteBuf::from(bytes)
    }
    fn to_vec(&self) -> Vec<u8> {
        self.clone().into_vec()
    }
}

/// Requests to post, each to helper `.0`.
pub type HelperRequests<B> = Vec<(usize, WorkerRequest<B>)>;

/// What arrived from helper `.0`: its event, or why none could be read (a broken message, a
/// request that could not be posted to it, its worker failing).
pub type HelperMessage<B> = (usize, Result<WorkerEvent<B>, String>);

/// A helper the coordinator stopped using during a job.
#[derive(Debug, Clone, PartialEq)]
pub struct HelperLost {
    pub helper: usize,
    /// Its error, or why its messages could not be used.
    pub why: String,
    /// It panicked or cannot be reached: use it for no later job either.
    pub dead: bool,
}

/// What the loop does after a turn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NextTurn {
    /// Every chunk is decoded: [`PoolCoordinator::summary`], then finish the job.
    Done,
    /// A window was computed here: let the event loop run (a cancel may be waiting), then turn
    /// again.
    Yield,
    /// Nothing to compute here: turn again when a helper's message (or a cancel) arrives.
    WaitForHelpers,
}

/// What one turn asks of the loop.
#[derive(Debug)]
pub struct Turn<B> {
    /// Requests to post, to helper `.0`.
    pub to_helpers: HelperRequests<B>,
    /// The job's progress after each chunk decoded this turn.
    pub progress: Vec<JobProgress>,
    /// Helpers given up this turn.
    pub lost: Vec<HelperLost>,
    pub next: NextTurn,
}

/// The coordinator's side of one pooled job.
#[derive(Debug)]
pub struct PoolCoordinator {
    job: JobId,
    helpers: Vec<usize>,
    chunk_windows: usize,
    schedule: ChunkSchedule,
    /// Helpers that hold the job (said `pool-ready`).
    ready: BTreeSet<usize>,
    /// The chunk computed here: its outputs so far and the windows left.
    own: Option<(ChunkOutputs, Range<usize>)>,
    helper_chunks: usize,
}

impl PoolCoordinator {
    /// Starts job `job` of `task` (made by [`SessionWorker::start_pooled_reconstruction`])
    /// with `helpers`; returns the `pool-job` request to post to each.
    pub fn start<B: PoolBytes>(
        worker: &SessionWorker,
        task: &ReconstructionTask,
        job: JobId,
        overlay: bool,
        helpers: &[usize],
    ) -> Result<(Self, HelperRequests<B>), WorkerError> {
        let session = worker.pool_session()?;
        let chunk_windows = task.chunk_size();
        let requests = helpers
            .iter()
            .map(|&helper| {
                let session = B::copy_from(&session);
                (helper, WorkerRequest::PoolJob { job, session, overlay, chunk_windows })
            })
            .collect();
        let coordinator = PoolCoordinator {
            job,
            helpers: helpers.to_vec(),
            chunk_windows,
            schedule: ChunkSchedule::new(task.chunk_count()),
            ready: BTreeSet::new(),
            own: None,
            helper_chunks: 0,
        };
        Ok((coordinator, requests))
    }

    /// One turn: reads what `arrived` from the helpers, gives each ready idle helper a chunk,
    /// decodes the chunks whose turn it is, and computes one window of a chunk here.
    pub fn turn<B: PoolBytes>(
        &mut self,
        worker: &SessionWorker,
        task: &mut ReconstructionTask,
        arrived: Vec<HelperMessage<B>>,
    ) -> Result<Turn<B>, WorkerError> {
        let mut turn = Turn { to_helpers: Vec::new(), progress: Vec::new(), lost: Vec::new(), next: NextTurn::Yield };
        for (helper, message) in arrived {
            self.read_helper_message(helper, message, &mut turn.lost);
        }
        for &helper in &self.ready {
            if let Some(chunk) = self.schedule.assign(helper) {
                turn.to_helpers.push((helper, WorkerRequest::PoolChunk { job: self.job, chunk }));
            }
        }
        while let Some(outputs) = self.schedule.next_to_decode() {
            turn.progress.push(worker.add_pool_chunk(task, &outputs)?);
        }
        if self.schedule.is_done() {
            turn.next = NextTurn::Done;
            return Ok(turn);
        }
        if self.own.is_none() {
            self.own = self
                .schedule
                .take_own()
                .map(|chunk| (ChunkOutputs::new(chunk, task.method_count()), task.chunk_windows(chunk)));
        }
        turn.next = match &mut self.own {
            Some((outputs, windows)) => {
                if let Some(window) = windows.next() {
                    outputs.push_window(worker.run_pool_window(task, window)?);
                }
                if windows.start >= windows.end
                    && let Some((outputs, _)) = self.own.take()
                {
                    self.schedule.finished(None, outputs);
                }
                NextTurn::Yield
            }
            None => NextTurn::WaitForHelpers,
        };
        Ok(turn)
    }

    fn read_helper_message<B: PoolBytes>(
        &mut self,
        helper: usize,
        message: Result<WorkerEvent<B>, String>,
        lost: &mut Vec<HelperLost>,
    ) {
        let job = self.job;
        let mut lose = |schedule: &mut ChunkSchedule, why: String, dead: bool| {
            schedule.helper_failed(helper);
            lost.push(HelperLost { helper, why, dead });
        };
        match message {
            Ok(WorkerEvent::PoolReady { job: j }) if j == job => {
                self.ready.insert(helper);
            }
            Ok(WorkerEvent::PoolChunkDone { job: j, chunk, outputs }) if j == job => {
                match ChunkOutputs::from_bytes(&outputs.to_vec()) {
                    Ok(outputs) if outputs.chunk == chunk => {
                        self.helper_chunks += usize::from(self.schedule.finished(Some(helper), outputs));
                    }
                    _ => lose(&mut self.schedule, "sent outputs that do not decode".into(), false),
                }
            }
            Ok(WorkerEvent::Error { job: j, message, .. }) if j == Some(job) || j.is_none() => {
                lose(&mut self.schedule, message, false);
            }
            Ok(WorkerEvent::Panic { message }) | Err(message) => lose(&mut self.schedule, message, true),
            // Another job's late answer, or an event that is no answer (e.g. its models).
            Ok(_) => {}
        }
    }

    /// The `cancel` to post to every helper when the job is cancelled.
    pub fn cancel_requests<B>(&self) -> HelperRequests<B> {
        self.helpers.iter().map(|&helper| (helper, WorkerRequest::Cancel { job: self.job })).collect()
    }

    /// How the job was shared, for its summary.
    pub fn summary(&self, task: &ReconstructionTask) -> PoolSummary {
        PoolSummary {
            workers: self.helpers.len() + 1,
            chunks: task.chunk_count(),
            chunk_windows: self.chunk_windows,
            helper_chunks: self.helper_chunks,
            failed_helpers: self.schedule.failed_helpers(),
        }
    }
}

/// A helper's side of the pool: the coordinator's job it holds.
#[derive(Debug, Default)]
pub struct PoolHelper {
    held: Option<(JobId, PoolHelperJob)>,
}

impl PoolHelper {
    /// The answer to the coordinator's `pool-job` (`pool-ready`) or `pool-chunk`
    /// (`pool-chunk-done` with the chunk's outputs), or its error; `None` for any other request.
    pub fn answer<B: PoolBytes>(
        &mut self,
        worker: &SessionWorker,
        request: &WorkerRequest<B>,
    ) -> Option<WorkerEvent<B>> {
        let (job, answered) = match request {
            WorkerRequest::PoolJob { job, session, overlay, chunk_windows } => {
                let made = worker.start_pool_helper(&session.to_vec(), *overlay, *chunk_windows);
                (
                    *job,
                    made.map(|helper_job| self.held = Some((*job, helper_job)))
                        .map(|()| WorkerEvent::PoolReady { job: *job }),
                )
            }
            WorkerRequest::PoolChunk { job, chunk } => {
                let computed = match &self.held {
                    Some((held, helper_job)) if held == job => worker.run_pool_chunk(helper_job, *chunk),
                    held => Err(PoolError::NoJob {
                        job: *job,
                        held: held.as_ref().map_or("none".into(), |(j, _)| format!("job {j}")),
                    }
                    .into()),
                };
                let done = |bytes: Vec<u8>| WorkerEvent::PoolChunkDone {
                    job: *job,
                    chunk: *chunk,
                    outputs: B::copy_from(&bytes),
                };
                (*job, computed.map(done))
            }
            _ => return None,
        };
        Some(answered.unwrap_or_else(|e| WorkerEvent::Error {
            job: Some(job),
            stage: ErrorStage::Reconstruct,
            kind: e.kind(),
            message: e.to_string(),
        }))
    }
}
