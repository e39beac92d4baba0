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
//! - a Rust panic is reported as a `panic` event (and on the console) before the module dies.

use std::cell::{Cell, RefCell};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::rc::Rc;

use egoexo_infer::InferError;
use egoexo_protocol::JsBytes;
use egoexo_protocol::js::request_from_js;
use egoexo_protocol::worker::{
    ErrorKind, ErrorStage, ExportFormat, ExportedFile, JobId, JobStage, ModelFileRef, ModelsSummary, SessionInput,
    WORKER_PROTOCOL_VERSION, WorkerEvent, WorkerRequest,
};
use js_sys::{Array, Promise, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::{JsFuture, spawn_local};
use web_sys::{Cache, DedicatedWorkerGlobalScope, MessageChannel, RequestCache, RequestInit, Response, Url};

use egoexo_share::envelope;
use egoexo_share::{ShareError, ShareKey};
use web_sys::{AesGcmParams, Crypto, CryptoKey, SubtleCrypto};

use crate::worker::{SessionWorker, WorkerClock, WorkerError};

type Request = WorkerRequest<JsBytes>;
type Event = WorkerEvent<JsBytes>;

mod live;

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
    #[wasm_bindgen(constructor)]
    pub fn new(models_url: &str, clock: Option<js_sys::Function>) -> Result<WorkerApp, JsValue> {
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
}

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
}

/// Why loading the models failed.
type ModelsFailure = (ErrorKind, String);

impl Runtime {
    fn post(&self, event: Event) {
        let transfer = Array::new();
        for bytes in event.byte_buffers() {
            transfer.push(&bytes.buffer());
        }
        let serializer = serde_wasm_bindgen::Serializer::json_compatible();
        match serde::Serialize::serialize(&event, &serializer) {
            Ok(value) => {
                if let Err(e) = self.scope.post_message_with_transfer(&value, &transfer) {
                    console_error(&format!("egoexo worker: cannot post an event: {e:?}"));
                }
            }
            Err(e) => console_error(&format!("egoexo worker: cannot serialise an event: {e}")),
        }
    }

    fn fail(&self, job: Option<JobId>, stage: ErrorStage, error: &WorkerError) {
        self.post(Event::Error { job, stage, kind: error.kind(), message: error.to_string() });
    }

    fn cancel(&self, job: JobId) {
        if self.current.get() == Some(job) {
            self.cancel_requested.set(true);
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
        let started = self.worker.borrow_mut().start_reconstruction(overlay);
        let mut task = match started {
            Ok(task) => task,
            Err(e) => return self.fail(Some(job), ErrorStage::Reconstruct, &e),
        };
        loop {
            if self.stopped(job) {
                return;
            }
            let step = self.worker.borrow().step_reconstruction(&mut task);
            match step {
                Ok(Some(p)) => self.post(Event::Progress {
                    job,
                    stage: p.stage,
                    label: p.stage.label().into(),
                    done: p.done,
                    total: p.total,
                }),
                Ok(None) => break,
                Err(e) => return self.fail(Some(job), ErrorStage::Reconstruct, &e),
            }
            self.yield_now().await;
        }
        if self.stopped(job) {
            return;
        }
        let finished = self.worker.borrow_mut().finish_reconstruction(task);
        let result = finished.and_then(|summary| Ok((summary, self.worker.borrow().scene_json()?)));
        match result {
            Ok((summary, scene)) => self.post(Event::Reconstructed { job, scene: JsBytes::copy_from(&scene), summary }),
            Err(e) => self.fail(Some(job), ErrorStage::Reconstruct, &e),
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
            let wanted = listed.iter().map(|f| self.cache_key(f)).collect::<Result<BTreeSet<_>, _>>()?;
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
    e.dyn_ref::<js_sys::Error>().map(|e| String::from(e.message())).unwrap_or_else(|| format!("{e:?}"))
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
