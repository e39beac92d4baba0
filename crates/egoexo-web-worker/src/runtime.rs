//! The worker's message loop in the browser (wasm32 only). `web/worker.js` makes one
//! [`WorkerApp`] and hands it every message; everything else is here, in Rust:
//!
//! - requests ([`WorkerRequest`]) are read without copying their byte arrays
//!   (`egoexo_protocol::js`) — a message that is not one is answered with a `bad-request`
//!   error — and run one at a time in arrival order;
//!   `cancel` is handled at once (a queued job is dropped, a running reconstruction stops at
//!   its next window);
//! - a reconstruction runs one window per step and gives control back to the event loop
//!   between steps (a `MessageChannel` round trip, well under a millisecond), which is where a
//!   `cancel` is read; nothing here reads a clock itself (stage timings use the glue's, passed in);
//! - the models are fetched from the models URL (`manifest.json`, then the files it lists),
//!   kept in the Cache API keyed by their sha256, checked and loaded by [`SessionWorker`];
//!   a failure with cached files clears them and fetches once more;
//! - shares are packed by [`SessionWorker`] and sealed (or opened) with WebCrypto's AES-GCM
//!   in the layout of `egoexo_share::envelope`, under a key drawn with
//!   `crypto.getRandomValues`; the key goes back to the page for the link and nowhere else;
//! - events ([`WorkerEvent`]) are posted with their byte buffers transferred, not copied;
//! - a Rust panic is reported as a `panic` event (and on the console) before the module dies;
//! - with a pool (the glue's `pool` object: `size` helpers, `start()` to spawn them, `post(i,
//!   message, transfer)`), a reconstruction's chunks are shared with helper workers — the
//!   same module, spawned by the glue for a long session's job or once the first job is
//!   done — and decoded here in order ([`crate::pool`]); a helper's messages come in through `handle_helper`. A helper
//!   answers `pool-job` and `pool-chunk` requests from its coordinator.

use std::cell::{Cell, RefCell};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::rc::Rc;

use egoexo_infer::{ChunkOutputs, InferError};
use egoexo_protocol::JsBytes;
use egoexo_protocol::js::{event_from_js, request_from_js};
use egoexo_protocol::worker::{
    ErrorKind, ErrorStage, ExportFormat, ExportedFile, JobId, JobStage, ModelFileRef, ModelsSummary, PoolSummary,
    ReconstructionSummary, SessionInput, WORKER_PROTOCOL_VERSION, WorkerEvent, WorkerRequest,
};
use js_sys::{Array, Promise, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::{JsFuture, spawn_local};
use web_sys::{Cache, DedicatedWorkerGlobalScope, MessageChannel, RequestCache, RequestInit, Response, Url};

use egoexo_share::envelope;
use egoexo_share::{ShareError, ShareKey};
use web_sys::{AesGcmParams, Crypto, CryptoKey, SubtleCrypto};

use crate::pool::ChunkSchedule;
use crate::worker::{PoolHelperJob, ReconstructionTask, SessionWorker, WorkerClock, WorkerError};

type Request = WorkerRequest<JsBytes>;
type Event = WorkerEvent<JsBytes>;

mod live;
mod video;

/// Lets the event loop run: resolves on the next task (a round trip through `channel`, one
/// waiter per channel at a time).
async fn yield_on(channel: &MessageChannel) {
    let (port1, port2) = (channel.port1(), channel.port2());
    let tick = Promise::new(&mut |resolve, _reject| {
        port2.set_onmessage(Some(&resolve));
        let _ = port1.post_message(&JsValue::UNDEFINED);
    });
    let _ = JsFuture::from(tick).await;
}

/// Sessions of at least this many frames (100 s at 30 fps; over a second of one worker's
/// time) start the pool's helpers for their own reconstruction; shorter ones leave that
/// until the worker is idle.
const POOL_EAGER_FRAMES: usize = 3_000;

/// The Cache API cache holding the model files.
pub const MODEL_CACHE: &str = "egoexo-models";

/// The text of the panic that [`WorkerRequest::PanicForTest`] causes.
pub const TEST_PANIC_MESSAGE: &str = "a panic requested by the test suite";

#[wasm_bindgen]
extern "C" {
    #[wasm_bindgen(js_namespace = console, js_name = error)]
    fn console_error(message: &str);
}

/// The worker: `new WorkerApp(modelsUrl)` once, then `app.handle(event.data)` per message.
#[wasm_bindgen]
#[derive(Debug)]
pub struct WorkerApp {
    runtime: Rc<Runtime>,
}

#[wasm_bindgen]
impl WorkerApp {
    /// Starts the worker: installs the panic reporter, posts `ready`. `models_url` is the
    /// folder holding `manifest.json` (absolute, or relative to the worker script).
    ///
    /// `clock` (optional) returns the time in Unix milliseconds (`performance.timeOrigin +
    /// performance.now()`); the live connection answers the relay's clock pings with it, and
    /// each reconstruction's summary reports its time per stage with it.
    ///
    /// `pool` (optional, the page's worker only) is the glue's pool of helper workers:
    /// `{size, start(), post(i, message, transfer)}`.
    #[wasm_bindgen(constructor)]
    pub fn new(
        models_url: &str,
        clock: Option<js_sys::Function>,
        pool: Option<js_sys::Object>,
    ) -> Result<WorkerApp, JsValue> {
        let scope: DedicatedWorkerGlobalScope = js_sys::global().dyn_into()?;
        let models_url = Url::new_with_base(models_url, &scope.location().href())?.href();
        install_panic_reporter();
        let mut worker = SessionWorker::new();
        if let Some(clock) = clock.clone() {
            // Stage timings of each job (the summary's `timings`): the glue's clock, passed in.
            worker.set_clock(WorkerClock::new(move || {
                clock.call0(&JsValue::UNDEFINED).ok().and_then(|v| v.as_f64()).unwrap_or(f64::NAN)
            }));
        }
        let runtime = Rc::new(Runtime {
            scope,
            models_url,
            worker: RefCell::new(worker),
            queue: RefCell::new(VecDeque::new()),
            running: Cell::new(false),
            current: Cell::new(None),
            cancel_requested: Cell::new(false),
            channel: MessageChannel::new()?,
            live: RefCell::new(None),
            clock,
            pool: pool.map(|p| PoolGlue::from_js(&p)).transpose()?.filter(|p| p.size > 0),
            helpers_started: Cell::new(false),
            dead_helpers: RefCell::new(BTreeSet::new()),
            helper_inbox: RefCell::new(VecDeque::new()),
            wake: RefCell::new(None),
            pool_job: RefCell::new(None),
            progress_scope: RefCell::new(None),
        });
        runtime.post(Event::Ready { protocol: WORKER_PROTOCOL_VERSION });
        Ok(WorkerApp { runtime })
    }

    /// Handles one message from the page (`event.data`).
    pub fn handle(&self, message: JsValue) {
        let runtime = &self.runtime;
        let request: Request = match request_from_js(&message) {
            Ok(request) => request,
            Err(e) => {
                return runtime.post(Event::Error {
                    job: None,
                    stage: ErrorStage::Request,
                    kind: ErrorKind::BadRequest,
                    message: format!("not a request of the worker protocol (version {WORKER_PROTOCOL_VERSION}): {e}"),
                });
            }
        };
        match request {
            WorkerRequest::Cancel { job } => runtime.cancel(job),
            WorkerRequest::PanicForTest => panic!("{TEST_PANIC_MESSAGE}"),
            WorkerRequest::LiveLookahead { frames } => {
                if let Some(connection) = runtime.live.borrow_mut().as_mut() {
                    connection.reconstructor.set_lookahead(frames);
                }
            }
            request => {
                runtime.queue.borrow_mut().push_back(request);
                if !runtime.running.replace(true) {
                    spawn_local(Runtime::run(runtime.clone()));
                }
            }
        }
    }

    /// Handles one message from pool helper `helper` (`event.data`).
    pub fn handle_helper(&self, helper: usize, message: JsValue) {
        let event = event_from_js(&message);
        self.runtime.helper_inbox.borrow_mut().push_back((helper, event.map_err(|e| e.to_string())));
        self.runtime.wake();
    }

    /// Pool helper `helper` failed outside its Rust code (its script did not load, or it
    /// threw): it gets no more work.
    pub fn helper_failed(&self, helper: usize, message: String) {
        self.runtime.helper_inbox.borrow_mut().push_back((helper, Err(message)));
        self.runtime.wake();
    }
}

/// The glue's pool of helper workers (see [`WorkerApp::new`]).
#[derive(Debug)]
struct PoolGlue {
    /// Helpers in the pool (the coordinator not counted).
    size: usize,
    start: js_sys::Function,
    post: js_sys::Function,
}

impl PoolGlue {
    fn from_js(pool: &js_sys::Object) -> Result<Self, JsValue> {
        let get = |name: &str| js_sys::Reflect::get(pool, &JsValue::from_str(name));
        let size = get("size")?.as_f64().unwrap_or(0.0).max(0.0) as usize;
        let function = |name: &str| -> Result<js_sys::Function, JsValue> {
            get(name)?.dyn_into().map_err(|_| JsValue::from_str(&format!("pool.{name} is not a function")))
        };
        Ok(PoolGlue { size, start: function("start")?, post: function("post")? })
    }
}

/// A message from a helper: its event, or why it could not be read or the helper failed.
type HelperMessage = (usize, Result<Event, String>);

#[derive(Debug)]
struct Runtime {
    scope: DedicatedWorkerGlobalScope,
    /// Absolute URL of the models folder.
    models_url: String,
    worker: RefCell<SessionWorker>,
    queue: RefCell<VecDeque<Request>>,
    /// Whether the queue is being worked through.
    running: Cell<bool>,
    /// The job being worked on.
    current: Cell<Option<JobId>>,
    /// A cancel of `current` arrived.
    cancel_requested: Cell<bool>,
    /// Yields to the event loop ([`Runtime::yield_now`]).
    channel: MessageChannel,
    /// The live room being watched.
    live: RefCell<Option<live::LiveConnection>>,
    /// The page glue's clock (Unix ms), for the relay's clock pings.
    clock: Option<js_sys::Function>,
    /// The pool of helper workers, when this is the page's worker and the glue made one.
    pool: Option<PoolGlue>,
    /// Whether the glue has spawned the helpers ([`Runtime::start_helpers`]).
    helpers_started: Cell<bool>,
    /// Helpers that panicked or failed to start: never used again.
    dead_helpers: RefCell<BTreeSet<usize>>,
    /// Helpers' messages not yet read by the running reconstruction.
    helper_inbox: RefCell<VecDeque<HelperMessage>>,
    /// Resolves the promise a pooled reconstruction waits on for a helper's message.
    wake: RefCell<Option<js_sys::Function>>,
    /// As a helper: the coordinator's job held.
    pool_job: RefCell<Option<(JobId, PoolHelperJob)>>,
    /// While a capture's participants are reconstructed in turn: whose job runs.
    progress_scope: RefCell<Option<ProgressScope>>,
}

/// Which participant of how many a reconstruction's progress is about.
#[derive(Clone, Debug)]
struct ProgressScope {
    participant: String,
    index: usize,
    count: usize,
    /// Steps of the participants before this one.
    done_before: usize,
    /// This participant's job's steps, once known.
    last_total: usize,
}

/// Why loading the models failed.
type ModelsFailure = (ErrorKind, String);

impl Runtime {
    fn post(&self, event: Event) {
        let posted = js_message_with_transfer(&event, event.byte_buffers())
            .and_then(|(value, transfer)| self.scope.post_message_with_transfer(&value, &transfer));
        if let Err(e) = posted {
            console_error(&format!("egoexo worker: cannot post an event: {}", js_message(&e)));
        }
    }

    fn fail(&self, job: Option<JobId>, stage: ErrorStage, error: &WorkerError) {
        self.post(Event::Error { job, stage, kind: error.kind(), message: error.to_string() });
    }

    fn cancel(&self, job: JobId) {
        if self.current.get() == Some(job) {
            self.cancel_requested.set(true);
            self.wake();
            return;
        }
        let mut queue = self.queue.borrow_mut();
        let before = queue.len();
        queue.retain(|r| r.job() != Some(job));
        if queue.len() < before {
            drop(queue);
            self.post(Event::Cancelled { job });
        }
    }

    /// Whether job `job` has been asked to stop; if so, says `cancelled`.
    fn stopped(&self, job: JobId) -> bool {
        let stopped = self.cancel_requested.get();
        if stopped {
            self.post(Event::Cancelled { job });
        }
        stopped
    }

    async fn run(self: Rc<Self>) {
        loop {
            let next = self.queue.borrow_mut().pop_front();
            let Some(request) = next else { break };
            self.current.set(request.job());
            self.cancel_requested.set(false);
            self.process(request).await;
            self.current.set(None);
        }
        self.running.set(false);
    }

    /// The glue's clock, Unix milliseconds.
    fn clock_ms(&self) -> Option<f64> {
        self.clock.as_ref()?.call0(&JsValue::UNDEFINED).ok()?.as_f64()
    }

    async fn process(self: &Rc<Self>, request: Request) {
        let job = request.job();
        if !self.worker.borrow().has_models() {
            self.post(Event::Status { text: "loading the models…".into() });
            match self.load_models().await {
                Ok(summary) => self.post(Event::Models { summary }),
                Err((kind, message)) => {
                    return self.post(Event::Error { job, stage: ErrorStage::Models, kind, message });
                }
            }
        }
        match request {
            WorkerRequest::Open { job, input } => self.open(job, input),
            WorkerRequest::Reconstruct { job, overlay } => self.reconstruct(job, overlay).await,
            WorkerRequest::PoolJob { job, session, overlay, chunk_windows } => {
                let made = self.worker.borrow().start_pool_helper(&session.to_vec(), overlay, chunk_windows);
                match made {
                    Ok(helper_job) => {
                        *self.pool_job.borrow_mut() = Some((job, helper_job));
                        self.post(Event::PoolReady { job });
                    }
                    Err(e) => self.fail(Some(job), ErrorStage::Reconstruct, &e),
                }
            }
            WorkerRequest::PoolChunk { job, chunk } => {
                let computed = match &*self.pool_job.borrow() {
                    Some((held, helper_job)) if *held == job => self.worker.borrow().run_pool_chunk(helper_job, chunk),
                    held => Err(crate::pool::PoolError::NoJob {
                        job,
                        held: held.as_ref().map_or("none".into(), |(j, _)| format!("job {j}")),
                    }
                    .into()),
                };
                match computed {
                    Ok(bytes) => self.post(Event::PoolChunkDone { job, chunk, outputs: JsBytes::copy_from(&bytes) }),
                    Err(e) => self.fail(Some(job), ErrorStage::Reconstruct, &e),
                }
            }
            WorkerRequest::Export { job, format } => self.export(job, format),
            WorkerRequest::CreateShare { job, include_recording } => {
                let result = self.create_share(job, include_recording).await;
                if let Err(e) = result {
                    self.fail(Some(job), ErrorStage::Share, &e);
                }
            }
            WorkerRequest::OpenShare { job, sealed, key } => {
                let result = self.open_share(job, &sealed, &key).await;
                if let Err(e) = result {
                    self.fail(Some(job), ErrorStage::Share, &e);
                }
            }
            WorkerRequest::LiveJoin { url, room, secret, lookahead } => live::join(self, &url, room, secret, lookahead),
            WorkerRequest::LiveStop { job, keep, name } => self.live_stop(job, keep, &name),
            WorkerRequest::SaveSession { job } => {
                let saved = self.worker.borrow().save_session();
                self.post_exported(job, saved);
            }
            WorkerRequest::SelectParticipant { job, participant } => {
                let selected = self.worker.borrow_mut().select_participant(&participant);
                match selected {
                    Ok(selected) => {
                        self.post(Event::Imported { job, summary: selected.session });
                        if let Some((summary, scene)) = selected.reconstruction {
                            self.post(Event::Reconstructed { job, scene: JsBytes::copy_from(&scene), summary });
                        }
                    }
                    Err(e) => self.fail(Some(job), ErrorStage::Request, &e),
                }
            }
            WorkerRequest::WarmUp => self.prepare_while_idle().await,
            WorkerRequest::Cancel { .. } | WorkerRequest::PanicForTest | WorkerRequest::LiveLookahead { .. } => {}
        }
    }

    /// Leaves the live room; with `keep`, opens the take as the session.
    fn live_stop(&self, job: JobId, keep: bool, name: &str) {
        let Some(connection) = self.live.borrow_mut().take() else {
            let error = WorkerError::Take(egoexo_session::live::TakeError::NoWearerHead(name.to_string()));
            return self.fail(Some(job), ErrorStage::Import, &error);
        };
        connection.close();
        if !keep {
            return self.post(Event::LiveClosed { code: 1000, reason: "the viewer left".into() });
        }
        let take = connection.reconstructor.summary();
        let reconstructor = connection.reconstructor;
        let kept = self.worker.borrow_mut().keep_take(reconstructor.take(), name);
        match kept {
            Ok(summary) => self.post(Event::LiveKept { job, summary, take }),
            Err(e) => self.fail(Some(job), ErrorStage::Import, &e),
        }
    }

    fn open(&self, job: JobId, input: SessionInput<JsBytes>) {
        let stage = JobStage::Import;
        self.post(Event::Progress { job, stage, label: stage.label().into(), done: 0, total: 1 });
        let result = match input {
            SessionInput::Archive { name, bytes } => self.worker.borrow_mut().import_archive(&name, bytes.to_vec()),
            SessionInput::Files { name, files } => {
                let files = files.into_iter().map(|f| (f.path, f.bytes.to_vec()));
                self.worker.borrow_mut().import_files(&name, files)
            }
        };
        match result {
            Ok(_) if self.stopped(job) => {}
            Ok(summary) => self.post(Event::Imported { job, summary }),
            Err(e) => self.fail(Some(job), ErrorStage::Import, &e),
        }
    }

    async fn reconstruct(&self, job: JobId, overlay: bool) {
        self.reconstruct_job(job, overlay).await;
        // Idle after the first job: the helpers start for the next ones.
        self.start_helpers();
    }

    async fn reconstruct_job(&self, job: JobId, overlay: bool) {
        let begun = self.worker.borrow_mut().begin_group_reconstruction();
        let run = match begun {
            Ok(Some(run)) => run,
            Ok(None) => {
                if let Some(summary) = self.reconstruct_open_session(job, overlay).await {
                    let scene = self.worker.borrow().scene_json();
                    match scene {
                        Ok(scene) => {
                            self.post(Event::Reconstructed { job, scene: JsBytes::copy_from(&scene), summary })
                        }
                        Err(e) => self.fail(Some(job), ErrorStage::Reconstruct, &e),
                    }
                }
                return;
            }
            Err(e) => return self.fail(Some(job), ErrorStage::Reconstruct, &e),
        };
        // A capture of several participants (associated): everyone in turn, each one's
        // detector step and job, then the one shown with everyone drawn.
        let count = run.participants.len();
        let mut done_before = 0;
        for (index, id) in run.participants.iter().enumerate() {
            if self.stopped(job) {
                return;
            }
            if let Err(e) = self.worker.borrow_mut().open_participant_for_reconstruction(id) {
                return self.fail(Some(job), ErrorStage::Reconstruct, &e);
            }
            let scope = ProgressScope { participant: id.clone(), index, count, done_before, last_total: 0 };
            self.progress_scope.replace(Some(scope));
            let done = self.reconstruct_open_session(job, overlay).await;
            done_before += self.progress_scope.take().map_or(0, |s| s.last_total);
            if done.is_none() {
                return;
            }
        }
        let result = self.worker.borrow_mut().finish_group_reconstruction(run);
        match result {
            Ok((summary, scene)) => self.post(Event::Reconstructed { job, scene: JsBytes::copy_from(&scene), summary }),
            Err(e) => self.fail(Some(job), ErrorStage::Reconstruct, &e),
        }
    }

    /// Reconstructs the open session (the detector step first where it needs one); the
    /// summary, or `None` when it failed (reported) or was cancelled.
    async fn reconstruct_open_session(&self, job: JobId, overlay: bool) -> Option<ReconstructionSummary> {
        // Observers with video and no keypoints: the detector step first.
        match self.detect_keypoints(job).await {
            Ok(true) => {}
            Ok(false) => {
                self.stopped(job);
                return None;
            }
            Err(video::DetectFailure::Models(kind, message)) => {
                self.post(Event::Error { job: Some(job), stage: ErrorStage::Models, kind, message });
                return None;
            }
            Err(video::DetectFailure::Worker(e)) => {
                self.fail(Some(job), ErrorStage::Reconstruct, &e);
                return None;
            }
        }
        let frames = self.worker.borrow().aligned_session().map_or(0, |a| a.timeline.frames);
        if frames >= POOL_EAGER_FRAMES {
            self.start_helpers();
        }
        let helpers = self.live_helpers();
        let started = if helpers.is_empty() {
            self.worker.borrow_mut().start_reconstruction(overlay)
        } else {
            self.worker.borrow_mut().start_pooled_reconstruction(overlay, helpers.len() + 1)
        };
        let mut task = match started {
            Ok(task) => task,
            Err(e) => {
                self.fail(Some(job), ErrorStage::Reconstruct, &e);
                return None;
            }
        };
        let computed = if helpers.is_empty() || task.chunk_count() < 2 {
            self.reconstruct_here(job, &mut task).await
        } else {
            self.reconstruct_pooled(job, overlay, &helpers, &mut task).await
        };
        match computed {
            Ok(true) => {}
            Ok(false) => return None,
            Err(e) => {
                self.fail(Some(job), ErrorStage::Reconstruct, &e);
                return None;
            }
        }
        if self.stopped(job) {
            return None;
        }
        let finished = self.worker.borrow_mut().finish_reconstruction(task);
        finished.map_err(|e| self.fail(Some(job), ErrorStage::Reconstruct, &e)).ok()
    }

    /// Every step of `task` here, one window per step; `Ok(false)` when cancelled.
    async fn reconstruct_here(&self, job: JobId, task: &mut ReconstructionTask) -> Result<bool, WorkerError> {
        loop {
            if self.stopped(job) {
                return Ok(false);
            }
            let step = self.worker.borrow().step_reconstruction(task)?;
            match step {
                Some(p) => self.post_progress(job, p),
                None => return Ok(true),
            }
            self.yield_now().await;
        }
    }

    fn post_progress(&self, job: JobId, p: crate::JobProgress) {
        // In a capture of several participants, everyone's steps in one count: those done
        // before this participant, theirs, and an estimate of the rest (as many as theirs
        // each), so `done` only grows.
        let scoped = self.progress_scope.borrow_mut().as_mut().map(|scope| {
            scope.last_total = p.total;
            let left = scope.count - scope.index - 1;
            let label = format!("{} · {} ({} of {})", p.stage.label(), scope.participant, scope.index + 1, scope.count);
            (label, scope.done_before + p.done, scope.done_before + p.total * (1 + left))
        });
        let (label, done, total) = scoped.unwrap_or_else(|| (p.stage.label().into(), p.done, p.total));
        self.post(Event::Progress { job, stage: p.stage, label, done, total });
    }

    /// The helpers that may take work: none without a pool or before they are started.
    fn live_helpers(&self) -> Vec<usize> {
        let Some(pool) = self.pool.as_ref().filter(|_| self.helpers_started.get()) else { return Vec::new() };
        let dead = self.dead_helpers.borrow();
        (0..pool.size).filter(|i| !dead.contains(i)).collect()
    }

    /// Has the glue spawn the pool's helpers (once) and has them load their models (from the
    /// cache, where this worker's are by now) and prepare the networks. Called when a job is
    /// long enough to pay for it ([`POOL_EAGER_FRAMES`]) — they join that job as they become
    /// ready — or once the first job is done, so that the start of the page (the time to the
    /// first skeleton) never shares the two cores with compiling more workers.
    fn start_helpers(&self) {
        let Some(pool) = &self.pool else { return };
        if self.helpers_started.replace(true) {
            return;
        }
        if let Err(e) = pool.start.call0(&JsValue::UNDEFINED) {
            console_error(&format!("egoexo worker: cannot start the pool's helpers: {}", js_message(&e)));
            self.dead_helpers.borrow_mut().extend(0..pool.size);
            return;
        }
        for helper in 0..pool.size {
            self.post_to_helper(helper, &WorkerRequest::WarmUp);
        }
    }

    /// Posts `request` to helper `helper`, its byte buffers transferred.
    fn post_to_helper(&self, helper: usize, request: &Request) {
        let Some(pool) = &self.pool else { return };
        let posted = js_message_with_transfer(request, request.byte_buffers()).and_then(|(value, transfer)| {
            pool.post.call3(&JsValue::UNDEFINED, &JsValue::from(helper as u32), &value, &transfer)
        });
        if let Err(e) = posted {
            console_error(&format!("egoexo worker: cannot post to helper {helper}: {}", js_message(&e)));
            self.helper_inbox.borrow_mut().push_back((helper, Err("a request could not be posted to it".into())));
        }
    }

    /// Wakes a pooled reconstruction waiting for a helper (a message or a cancel arrived).
    fn wake(&self) {
        if let Some(resolve) = self.wake.borrow_mut().take() {
            let _ = resolve.call0(&JsValue::UNDEFINED);
        }
    }

    /// Waits until a helper's message (or a cancel) arrives.
    async fn wait_for_helper(&self) {
        if !self.helper_inbox.borrow().is_empty() || self.cancel_requested.get() {
            return;
        }
        let arrived = Promise::new(&mut |resolve, _reject| {
            *self.wake.borrow_mut() = Some(resolve);
        });
        let _ = JsFuture::from(arrived).await;
    }

    /// Every chunk of `task`, shared with `helpers`: each gets the session and the job's
    /// settings, then one chunk at a time once it says it is ready; this worker computes
    /// chunks too, one window per step, and decodes every chunk in order as it comes in. A
    /// helper that fails gives its chunk back and gets no more; `Ok(false)` when cancelled.
    async fn reconstruct_pooled(
        &self,
        job: JobId,
        overlay: bool,
        helpers: &[usize],
        task: &mut ReconstructionTask,
    ) -> Result<bool, WorkerError> {
        let session = self.worker.borrow().pool_session()?;
        let chunk_windows = task.chunk_size();
        self.helper_inbox.borrow_mut().retain(|(_, message)| message.is_err());
        for &helper in helpers {
            let session = JsBytes::copy_from(&session);
            self.post_to_helper(helper, &WorkerRequest::PoolJob { job, session, overlay, chunk_windows });
        }
        drop(session);
        let mut schedule = ChunkSchedule::new(task.chunk_count());
        let mut ready = BTreeSet::new();
        let mut own: Option<(ChunkOutputs, std::ops::Range<usize>)> = None;
        let mut helper_chunks = 0;
        loop {
            if self.stopped(job) {
                for &helper in helpers {
                    self.post_to_helper(helper, &WorkerRequest::Cancel { job });
                }
                return Ok(false);
            }
            let arrived: Vec<HelperMessage> = self.helper_inbox.borrow_mut().drain(..).collect();
            for (helper, message) in arrived {
                match message {
                    Ok(WorkerEvent::PoolReady { job: j }) if j == job => {
                        ready.insert(helper);
                    }
                    Ok(WorkerEvent::PoolChunkDone { job: j, chunk, outputs }) if j == job => {
                        match ChunkOutputs::from_bytes(&outputs.to_vec()) {
                            Ok(outputs) if outputs.chunk == chunk => {
                                helper_chunks += usize::from(schedule.finished(Some(helper), outputs));
                            }
                            _ => self.helper_lost(&mut schedule, helper, job, "sent outputs that do not decode", false),
                        }
                    }
                    Ok(WorkerEvent::Error { job: j, message, .. }) if j == Some(job) || j.is_none() => {
                        self.helper_lost(&mut schedule, helper, job, &message, false);
                    }
                    Ok(WorkerEvent::Panic { message }) => self.helper_lost(&mut schedule, helper, job, &message, true),
                    Err(message) => self.helper_lost(&mut schedule, helper, job, &message, true),
                    Ok(_) => {}
                }
            }
            for &helper in &ready {
                if self.dead_helpers.borrow().contains(&helper) {
                    continue;
                }
                if let Some(chunk) = schedule.assign(helper) {
                    self.post_to_helper(helper, &WorkerRequest::PoolChunk { job, chunk });
                }
            }
            while let Some(outputs) = schedule.next_to_decode() {
                let progress = self.worker.borrow().add_pool_chunk(task, &outputs)?;
                self.post_progress(job, progress);
            }
            if schedule.is_done() {
                break;
            }
            if own.is_none() {
                own = schedule
                    .take_own()
                    .map(|chunk| (ChunkOutputs::new(chunk, task.method_count()), task.chunk_windows(chunk)));
            }
            match &mut own {
                Some((outputs, windows)) => {
                    if let Some(window) = windows.next() {
                        let computed = self.worker.borrow().run_pool_window(task, window)?;
                        outputs.push_window(computed);
                    }
                    if windows.start >= windows.end
                        && let Some((outputs, _)) = own.take()
                    {
                        schedule.finished(None, outputs);
                    }
                    self.yield_now().await;
                }
                None => self.wait_for_helper().await,
            }
        }
        task.set_pool_summary(PoolSummary {
            workers: helpers.len() + 1,
            chunks: task.chunk_count(),
            chunk_windows,
            helper_chunks,
            failed_helpers: schedule.failed_helpers(),
        });
        Ok(true)
    }

    /// Helper `helper` failed during job `job`: its chunk goes back; after a panic (or when
    /// its messages cannot be read) it is never used again.
    fn helper_lost(&self, schedule: &mut ChunkSchedule, helper: usize, job: JobId, why: &str, dead: bool) {
        console_error(&format!("egoexo worker: helper {helper} failed during job {job}: {why}"));
        schedule.helper_failed(helper);
        if dead {
            self.dead_helpers.borrow_mut().insert(helper);
        }
    }

    fn export(&self, job: JobId, format: ExportFormat) {
        let exported = self.worker.borrow().export(format);
        self.post_exported(job, exported);
    }

    fn post_exported(&self, job: JobId, exported: Result<crate::ExportedFile, WorkerError>) {
        match exported {
            Ok(file) => self.post(Event::Exported {
                job,
                file: ExportedFile {
                    bytes: JsBytes::copy_from(&file.bytes),
                    file_name: file.file_name,
                    mime_type: file.mime_type.into(),
                },
            }),
            Err(e) => self.fail(Some(job), ErrorStage::Export, &e),
        }
    }

    fn crypto(&self) -> Result<(Crypto, SubtleCrypto), WorkerError> {
        let crypto = self.scope.crypto().map_err(|e| ShareError::Random(js_message(&e)))?;
        let subtle = crypto.subtle();
        Ok((crypto, subtle))
    }

    /// Packs what is shown, seals it under a fresh key and posts `share-sealed`.
    async fn create_share(&self, job: JobId, include_recording: bool) -> Result<(), WorkerError> {
        let stage = JobStage::Share;
        self.post(Event::Progress { job, stage, label: stage.label().into(), done: 0, total: 1 });
        let includes_recording = include_recording && self.worker.borrow().can_share_recording();
        let container = self.worker.borrow().pack_share(includes_recording, CREATED_BY)?;
        let (crypto, subtle) = self.crypto()?;
        let mut key = [0u8; 16];
        let mut iv = [0u8; envelope::IV_LEN];
        for buffer in [&mut key[..], &mut iv[..]] {
            crypto.get_random_values_with_u8_array(buffer).map_err(|e| ShareError::Random(js_message(&e)))?;
        }
        let aes = aes_gcm_key(&subtle, &key, "encrypt").await?;
        let params = aes_gcm_params(&iv, &envelope::header());
        let sealed = subtle
            .encrypt_with_object_and_u8_array(&params, &aes, &container)
            .map_err(|e| ShareError::Container(js_message(&e)))?;
        let ciphertext = JsFuture::from(sealed).await.map_err(|e| ShareError::Container(js_message(&e)))?;
        let ciphertext = Uint8Array::new(&ciphertext);
        let prefix = envelope::HEADER_LEN + envelope::IV_LEN;
        let sealed = Uint8Array::new_with_length((prefix + ciphertext.length() as usize) as u32);
        sealed.subarray(0, envelope::HEADER_LEN as u32).copy_from(&envelope::header());
        sealed.subarray(envelope::HEADER_LEN as u32, prefix as u32).copy_from(&iv);
        sealed.set(&ciphertext, prefix as u32);
        if self.stopped(job) {
            return Ok(());
        }
        self.post(Event::ShareSealed {
            job,
            sealed: JsBytes(sealed),
            key: ShareKey::from_bytes(key).encode(),
            includes_recording,
        });
        Ok(())
    }

    /// Opens a sealed share with the key from its link and posts `share-opened`.
    async fn open_share(&self, job: JobId, sealed: &JsBytes, key: &str) -> Result<(), WorkerError> {
        let stage = JobStage::Share;
        self.post(Event::Progress { job, stage, label: stage.label().into(), done: 0, total: 1 });
        let key = ShareKey::decode(key).map_err(ShareError::Link)?;
        let bytes = sealed.to_vec();
        let parts = envelope::parse(&bytes)?;
        let (_, subtle) = self.crypto()?;
        let aes = aes_gcm_key(&subtle, key.as_bytes(), "decrypt").await?;
        let params = aes_gcm_params(&parts.iv, parts.header);
        let opened = subtle
            .decrypt_with_object_and_u8_array(&params, &aes, parts.ciphertext)
            .map_err(|_| ShareError::Decrypt)?;
        let container = JsFuture::from(opened).await.map_err(|_| ShareError::Decrypt)?;
        let opened = self.worker.borrow_mut().open_share(Uint8Array::new(&container).to_vec())?;
        if self.stopped(job) {
            return Ok(());
        }
        let manifest = opened.manifest;
        self.post(Event::ShareOpened {
            job,
            scene: JsBytes::copy_from(&opened.scene_json),
            summary: manifest.summary,
            session: manifest.session,
            includes_recording: manifest.includes_recording,
            created_by: manifest.created_by,
        });
        Ok(())
    }

    /// Parses and optimises the networks one at a time while no request waits (the user is
    /// still choosing a session): yields between networks and stops as soon as one arrives —
    /// whatever is left is prepared when a reconstruction needs it. A malformed network is
    /// left for that reconstruction to report.
    async fn prepare_while_idle(&self) {
        loop {
            self.yield_now().await;
            if !self.queue.borrow().is_empty() {
                return;
            }
            if !matches!(self.worker.borrow().prepare_next_network(), Ok(true)) {
                return;
            }
        }
    }

    /// Lets the event loop run (and so a `cancel` arrive): resolves on the next task.
    async fn yield_now(&self) {
        yield_on(&self.channel).await;
    }

    /// Fetches `manifest.json` and the files it lists (from the cache where it has them) and
    /// loads them; once more without the cache if that fails with cached files.
    async fn load_models(&self) -> Result<ModelsSummary, ModelsFailure> {
        let started = self.clock_ms();
        let manifest_url = resolve_url("manifest.json", &self.models_url)?;
        let manifest = fetch_bytes(&self.scope, &manifest_url, true).await?;
        let listed = SessionWorker::model_files(&manifest).map_err(|e| (e.kind(), e.to_string()))?;
        let cache = open_cache(&self.scope).await;
        let first = self.load_listed(&manifest, &listed, cache.as_ref(), true, started).await;
        match (first, &cache) {
            (Ok(summary), _) => Ok(summary),
            (Err(failure), None) => Err(failure),
            (Err(_), Some(cache)) => {
                // A cached file may be stale or damaged: fetch everything again once.
                for f in &listed {
                    let _ = JsFuture::from(cache.delete_with_str(&self.cache_key(f)?)).await;
                }
                self.load_listed(&manifest, &listed, Some(cache), false, started).await
            }
        }
    }

    /// The cache key of a model file: its URL with its sha256 as the query.
    fn cache_key(&self, file: &ModelFileRef) -> Result<String, ModelsFailure> {
        Ok(format!("{}?sha256={}", resolve_url(&file.file, &self.models_url)?, file.sha256))
    }

    async fn load_listed(
        &self,
        manifest: &[u8],
        listed: &[ModelFileRef],
        cache: Option<&Cache>,
        use_cache: bool,
        started: Option<f64>,
    ) -> Result<ModelsSummary, ModelsFailure> {
        let mut files: BTreeMap<String, Vec<u8>> = BTreeMap::new();
        // Every missing file's request starts before any is awaited, so they download together.
        let mut downloads = Vec::new();
        for f in listed {
            let cached = match cache.filter(|_| use_cache) {
                Some(cache) => cached_bytes(cache, &self.cache_key(f)?).await,
                None => None,
            };
            match cached {
                Some(bytes) => {
                    files.insert(f.file.clone(), bytes);
                }
                None => {
                    let url = resolve_url(&f.file, &self.models_url)?;
                    let response = self.scope.fetch_with_str(&url);
                    downloads.push((f, url, response));
                }
            }
        }
        let cached_files = files.len();
        let mut fetched = Vec::new();
        for (f, url, response) in downloads {
            files.insert(f.file.clone(), response_bytes(response, &url).await?);
            fetched.push(f);
        }
        let read = self.clock_ms();
        let mut summary = self
            .worker
            .borrow_mut()
            .load_models(manifest, |file| {
                files
                    .get(file)
                    .cloned()
                    .ok_or_else(|| InferError::ReadModel { file: file.to_string(), message: "not fetched".into() })
            })
            .map_err(|e| (e.kind(), e.to_string()))?;
        let loaded = self.clock_ms();
        let ms = |from: Option<f64>, to: Option<f64>| Some((to? - from?).max(0.0).round() as u32);
        summary.read_ms = ms(started, read);
        summary.load_ms = ms(read, loaded);
        summary.cached_files = cached_files;
        if let Some(cache) = cache {
            // Cache only what checked out, and forget other versions.
            for f in fetched {
                let body = Uint8Array::from(files[&f.file].as_slice());
                if let Ok(response) = Response::new_with_opt_buffer_source(Some(&body)) {
                    let _ = JsFuture::from(cache.put_with_str(&self.cache_key(f)?, &response)).await;
                }
            }
            // The detector (fetched when a session first needs it) stays too.
            let detector = self.worker.borrow().detector_file();
            let wanted = listed
                .iter()
                .chain(detector.as_ref())
                .map(|f| self.cache_key(f))
                .collect::<Result<BTreeSet<_>, _>>()?;
            if let Ok(keys) = JsFuture::from(cache.keys()).await {
                for request in Array::from(&keys).iter() {
                    let Ok(request) = request.dyn_into::<web_sys::Request>() else { continue };
                    if !wanted.contains(&request.url()) {
                        let _ = JsFuture::from(cache.delete_with_request(&request)).await;
                    }
                }
            }
        }
        Ok(summary)
    }
}

/// What made a share, in its manifest.
const CREATED_BY: &str = concat!("egoexo ", env!("CARGO_PKG_VERSION"), " (page)");

/// A WebCrypto AES-GCM key for `usage` (`encrypt` or `decrypt`).
async fn aes_gcm_key(subtle: &SubtleCrypto, key: &[u8], usage: &str) -> Result<CryptoKey, WorkerError> {
    let usages = Array::of1(&JsValue::from_str(usage));
    let promise = subtle
        .import_key_with_str("raw", &Uint8Array::from(key), "AES-GCM", false, &usages)
        .map_err(|e| ShareError::Container(js_message(&e)))?;
    let key = JsFuture::from(promise).await.map_err(|e| ShareError::Container(js_message(&e)))?;
    key.dyn_into::<CryptoKey>().map_err(|_| ShareError::Container("WebCrypto gave no key".into()).into())
}

/// AES-GCM parameters: the IV, the envelope header as associated data, a 128-bit tag.
fn aes_gcm_params(iv: &[u8], header: &[u8]) -> AesGcmParams {
    let params = AesGcmParams::new("AES-GCM", &Uint8Array::from(iv));
    params.set_additional_data(&Uint8Array::from(header));
    params.set_tag_length((envelope::TAG_LEN * 8) as u8);
    params
}

/// A message as the JS value to post and the transfer list of its byte buffers.
fn js_message_with_transfer<T: serde::Serialize>(
    message: &T,
    buffers: Vec<&JsBytes>,
) -> Result<(JsValue, Array), JsValue> {
    let transfer = Array::new();
    for bytes in buffers {
        transfer.push(&bytes.buffer());
    }
    let serializer = serde_wasm_bindgen::Serializer::json_compatible();
    let value = message.serialize(&serializer).map_err(|e| JsValue::from_str(&format!("cannot serialise it: {e}")))?;
    Ok((value, transfer))
}

/// `relative` resolved against `base`.
fn resolve_url(relative: &str, base: &str) -> Result<String, ModelsFailure> {
    Url::new_with_base(relative, base)
        .map(|u| u.href())
        .map_err(|e| (ErrorKind::ModelsUnavailable, format!("cannot resolve {relative} against {base}: {e:?}")))
}

/// The last two segments of a URL's path (`models/manifest.json`), for messages.
fn short_path(url: &str) -> String {
    let path = Url::new(url).map(|u| u.pathname()).unwrap_or_else(|_| url.to_string());
    let parts: Vec<&str> = path.rsplit('/').take(2).collect();
    parts.into_iter().rev().collect::<Vec<_>>().join("/")
}

fn js_message(e: &JsValue) -> String {
    e.dyn_ref::<js_sys::Error>()
        .map(|e| String::from(e.message()))
        .or_else(|| e.as_string())
        .unwrap_or_else(|| format!("{e:?}"))
}

async fn fetch_bytes(scope: &DedicatedWorkerGlobalScope, url: &str, no_cache: bool) -> Result<Vec<u8>, ModelsFailure> {
    let init = RequestInit::new();
    if no_cache {
        init.set_cache(RequestCache::NoCache);
    }
    response_bytes(scope.fetch_with_str_and_init(url, &init), url).await
}

/// The body of a fetch's response; an HTTP error status or a network failure names the file.
async fn response_bytes(response: Promise, url: &str) -> Result<Vec<u8>, ModelsFailure> {
    let what = short_path(url);
    let unavailable = |detail: String| (ErrorKind::ModelsUnavailable, format!("cannot fetch {what}: {detail}"));
    let response: Response = JsFuture::from(response).await.map_err(|e| unavailable(js_message(&e)))?.unchecked_into();
    if !response.ok() {
        let status = response.status();
        let kind = if status == 404 && what.ends_with("manifest.json") {
            ErrorKind::ModelsMissing
        } else {
            ErrorKind::ModelsUnavailable
        };
        return Err((kind, format!("cannot fetch {what}: HTTP {status} {}", response.status_text())));
    }
    let body = response.array_buffer().map_err(|e| unavailable(js_message(&e)))?;
    let buffer = JsFuture::from(body).await.map_err(|e| unavailable(js_message(&e)))?;
    Ok(Uint8Array::new(&buffer).to_vec())
}

/// The Cache API cache of the models, where the context allows one (not in an insecure
/// context, nor with storage disabled: then every load fetches).
async fn open_cache(scope: &DedicatedWorkerGlobalScope) -> Option<Cache> {
    let caches = scope.caches().ok()?;
    JsFuture::from(caches.open(MODEL_CACHE)).await.ok()?.dyn_into().ok()
}

async fn cached_bytes(cache: &Cache, key: &str) -> Option<Vec<u8>> {
    let hit = JsFuture::from(cache.match_with_str(key)).await.ok()?;
    let response: Response = hit.dyn_into().ok()?;
    let buffer = JsFuture::from(response.array_buffer().ok()?).await.ok()?;
    Some(Uint8Array::new(&buffer).to_vec())
}

/// Reports a Rust panic as a `panic` event and on the console; the module is dead after it
/// (wasm32 aborts), so the page replaces the worker.
fn install_panic_reporter() {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        std::panic::set_hook(Box::new(|info| {
            let message = info.to_string();
            console_error(&format!("egoexo worker panicked: {message}"));
            let event: Event = WorkerEvent::Panic { message };
            if let (Ok(scope), Ok(value)) =
                (js_sys::global().dyn_into::<DedicatedWorkerGlobalScope>(), serde_wasm_bindgen::to_value(&event))
            {
                let _ = scope.post_message(&value);
            }
        }));
    });
}
