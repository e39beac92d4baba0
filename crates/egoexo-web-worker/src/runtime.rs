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
//! - in parts a reader can name: this file is the event loop (requests, cancel, the job
//!   order, posting events, the panic hook); `models.rs` fetches the models through the Cache
//!   API; `sharing.rs` seals and opens shares with WebCrypto; `pool.rs` runs a pooled job with
//!   the helper workers (its logic is [`crate::coordinator`], which the native tests drive
//!   too); `video.rs` decodes observers' video with WebCodecs for the detector step;
//!   `live.rs` is the live relay's socket;
//! - events ([`WorkerEvent`]) are posted with their byte buffers transferred, not copied;
//! - a Rust panic is reported as a `panic` event (and on the console) before the module dies;
//! - with a pool (the glue's `pool` object: `size` helpers, `start()` to spawn them, `post(i,
//!   message, transfer)`), a reconstruction's chunks are shared with helper workers — the
//!   same module, spawned by the glue for a long session's job or once the first job is done
//!   — whose messages come in through `handle_helper`; a helper answers `pool-job` and
//!   `pool-chunk` requests with [`crate::coordinator::PoolHelper`].

use std::cell::{Cell, RefCell};
use std::collections::{BTreeSet, VecDeque};
use std::rc::Rc;

use egoexo_protocol::JsBytes;
use egoexo_protocol::js::{event_from_js, request_from_js};
use egoexo_protocol::worker::{
    ErrorKind, ErrorStage, ExportFormat, ExportedFile, JobId, JobStage, ReconstructionSummary, SessionInput,
    WORKER_PROTOCOL_VERSION, WorkerEvent, WorkerRequest,
};
use js_sys::{Array, Promise};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::{JsFuture, spawn_local};
use web_sys::{DedicatedWorkerGlobalScope, MessageChannel, Url};

use crate::coordinator::PoolHelper;
use crate::worker::{ReconstructionTask, SessionWorker, WorkerClock, WorkerError};

type Request = WorkerRequest<JsBytes>;
type Event = WorkerEvent<JsBytes>;

mod live;
mod models;
mod pool;
mod sharing;
mod video;

pub use models::MODEL_CACHE;
use pool::PoolGlue;

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
            pool_helper: RefCell::new(PoolHelper::default()),
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

/// A message from a helper: its event, or why it could not be read or the helper failed.
type HelperMessage = crate::coordinator::HelperMessage<JsBytes>;

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
    pool_helper: RefCell<PoolHelper>,
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
            request @ (WorkerRequest::PoolJob { .. } | WorkerRequest::PoolChunk { .. }) => {
                let answer = self.pool_helper.borrow_mut().answer(&self.worker.borrow(), &request);
                if let Some(event) = answer {
                    self.post(event);
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

fn js_message(e: &JsValue) -> String {
    e.dyn_ref::<js_sys::Error>()
        .map(|e| String::from(e.message()))
        .or_else(|| e.as_string())
        .unwrap_or_else(|| format!("{e:?}"))
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
