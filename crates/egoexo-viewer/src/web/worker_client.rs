//! `WorkerClient`: the page's end of the page ↔ worker protocol (`egoexo_protocol::worker`,
//! `docs/worker-protocol.md`). It builds every request the page sends, numbers the jobs, and
//! reads every event the worker posts — checking it against the protocol and dropping the
//! events of jobs the page has cancelled or replaced — so `web/main.js` never writes or
//! matches a message by hand.

use egoexo_protocol::JsBytes;
use egoexo_protocol::js::event_from_js;
use egoexo_protocol::worker::{
    DroppedFile, ExportFormat, JobId, SessionInput, WORKER_PROTOCOL_VERSION, WorkerEvent, WorkerRequest,
};
use js_sys::{Array, Object, Uint8Array};
use serde::Serialize;
use wasm_bindgen::prelude::*;
use web_sys::Worker;

type Request = WorkerRequest<JsBytes>;
type Event = WorkerEvent<JsBytes>;

/// Talks to one `worker.js` Web Worker.
#[wasm_bindgen]
#[derive(Debug)]
pub struct WorkerClient {
    worker: Worker,
    /// The last job number handed out.
    last_job: JobId,
    /// The job whose events the page wants.
    current: Option<JobId>,
}

#[wasm_bindgen]
impl WorkerClient {
    /// A client for `worker` (a module worker running `worker.js`).
    #[wasm_bindgen(constructor)]
    pub fn new(worker: Worker) -> WorkerClient {
        WorkerClient { worker, last_job: 0, current: None }
    }

    /// The protocol version this page speaks.
    pub fn protocol_version() -> u32 {
        WORKER_PROTOCOL_VERSION
    }

    /// Asks the worker to load the models now.
    pub fn warm_up(&self) -> Result<(), JsError> {
        self.send(&Request::WarmUp)
    }

    /// Opens a zip archive (`.egoexo`, or a zipped Aria MPS / Nymeria folder); `bytes` is
    /// transferred to the worker. Returns the job number.
    pub fn open_archive(&mut self, name: String, bytes: Uint8Array) -> Result<JobId, JsError> {
        let job = self.next_job();
        self.send(&Request::Open { job, input: SessionInput::Archive { name, bytes: JsBytes(bytes) } })?;
        Ok(job)
    }

    /// Why the page leaves a dropped folder's file unread (`path` relative, `bytes` its size),
    /// or `undefined` to read it ([`egoexo_protocol::worker::dropped_file_not_read`]).
    #[wasm_bindgen(js_name = droppedFileNotRead)]
    pub fn dropped_file_not_read(path: &str, bytes: f64) -> Option<String> {
        let bytes = if bytes.is_finite() && bytes > 0.0 { bytes as u64 } else { 0 };
        egoexo_protocol::worker::dropped_file_not_read(path, bytes)
    }

    /// Opens a dropped folder: `paths[i]` (relative, `/`-separated) holds `contents[i]`; the
    /// contents are transferred to the worker. Returns the job number.
    pub fn open_files(
        &mut self,
        name: String,
        paths: Vec<String>,
        contents: Vec<Uint8Array>,
    ) -> Result<JobId, JsError> {
        if paths.len() != contents.len() {
            return Err(JsError::new(&format!("{} paths but {} file contents", paths.len(), contents.len())));
        }
        let files = paths.into_iter().zip(contents).map(|(path, bytes)| DroppedFile { path, bytes: JsBytes(bytes) });
        let job = self.next_job();
        self.send(&Request::Open { job, input: SessionInput::Files { name, files: files.collect() } })?;
        Ok(job)
    }

    /// Reconstructs the open session (with the ego-only overlay when `overlay`). Returns the
    /// job number.
    pub fn reconstruct(&mut self, overlay: bool) -> Result<JobId, JsError> {
        let job = self.next_job();
        self.send(&Request::Reconstruct { job, overlay })?;
        Ok(job)
    }

    /// Exports the reconstruction as `format` (`npz`, `bvh`, `glb` or `csv`). Returns the job
    /// number.
    pub fn export(&mut self, format: &str) -> Result<JobId, JsError> {
        let format = ExportFormat::from_extension(format)
            .ok_or_else(|| JsError::new(&format!("unknown export format `{format}`: expected npz, bvh, glb or csv")))?;
        let job = self.next_job();
        self.send(&Request::Export { job, format })?;
        Ok(job)
    }

    /// Packs and seals what is shown into a share (with the recording when
    /// `include_recording` and a session is open). Returns the job number; the answer is
    /// `share-sealed` with the bytes to upload and the key for the link.
    pub fn create_share(&mut self, include_recording: bool) -> Result<JobId, JsError> {
        let job = self.next_job();
        self.send(&Request::CreateShare { job, include_recording })?;
        Ok(job)
    }

    /// Opens a sealed share (the bytes from the API) with the key from the link; `sealed` is
    /// transferred to the worker. Returns the job number.
    pub fn open_share(&mut self, sealed: Uint8Array, key: String) -> Result<JobId, JsError> {
        let job = self.next_job();
        self.send(&Request::OpenShare { job, sealed: JsBytes(sealed), key })?;
        Ok(job)
    }

    /// Watches live room `room` through the relay at `url` (`ws(s)://host/live`) with its
    /// viewer `secret`, reading each frame out `lookahead` frames before its window's end.
    pub fn live_join(&self, url: String, room: String, secret: String, lookahead: usize) -> Result<(), JsError> {
        self.send(&Request::LiveJoin { url, room, secret, lookahead })
    }

    /// Changes the live lookahead (frames).
    pub fn live_lookahead(&self, frames: usize) -> Result<(), JsError> {
        self.send(&Request::LiveLookahead { frames })
    }

    /// Leaves the live room; with `keep`, the take becomes the open session named `name`
    /// (answered by `live-kept`). Returns the job number.
    pub fn live_stop(&mut self, keep: bool, name: String) -> Result<JobId, JsError> {
        let job = self.next_job();
        self.send(&Request::LiveStop { job, keep, name })?;
        Ok(job)
    }

    /// Writes the open session as a `.egoexo` file (answered by `exported`). Returns the job
    /// number.
    pub fn save_session(&mut self) -> Result<JobId, JsError> {
        let job = self.next_job();
        self.send(&Request::SaveSession { job })?;
        Ok(job)
    }

    /// Shows participant `id` of the open capture (answered by `reconstructed` when there is a
    /// reconstruction, else `imported`). Returns the job number.
    pub fn select_participant(&mut self, id: String) -> Result<JobId, JsError> {
        let job = self.next_job();
        self.send(&Request::SelectParticipant { job, participant: id })?;
        Ok(job)
    }

    /// Cancels the current job; its events from now on are dropped by [`Self::receive`].
    /// Returns its number, if there was one.
    pub fn cancel(&mut self) -> Result<Option<JobId>, JsError> {
        let Some(job) = self.current.take() else { return Ok(None) };
        self.send(&Request::Cancel { job })?;
        Ok(Some(job))
    }

    /// The job whose events [`Self::receive`] passes on.
    pub fn current_job(&self) -> Option<JobId> {
        self.current
    }

    /// Makes the worker's Rust code panic (tests of the page's crash handling).
    pub fn panic_for_test(&self) -> Result<(), JsError> {
        self.send(&Request::PanicForTest)
    }

    /// Reads a message from the worker (`event.data`): the event as a plain object (see
    /// `docs/worker-protocol.md`), or `null` when it is about a job that is no longer the
    /// current one. Throws on a message that is no event of this protocol, or on a worker
    /// that speaks another version.
    pub fn receive(&mut self, data: JsValue) -> Result<JsValue, JsError> {
        let event: Event = event_from_js(&data)
            .map_err(|e| JsError::new(&format!("the worker sent something that is no event of the protocol: {e}")))?;
        if let WorkerEvent::Ready { protocol } = event
            && protocol != WORKER_PROTOCOL_VERSION
        {
            return Err(JsError::new(&format!(
                "the worker speaks protocol version {protocol}, this page {WORKER_PROTOCOL_VERSION}: reload the page"
            )));
        }
        if event.job().is_some_and(|job| Some(job) != self.current) {
            return Ok(JsValue::NULL);
        }
        to_js(&event)
    }
}

impl WorkerClient {
    fn next_job(&mut self) -> JobId {
        self.last_job = self.last_job.wrapping_add(1).max(1);
        self.current = Some(self.last_job);
        self.last_job
    }

    /// Posts `request`, transferring its byte buffers (each once).
    fn send(&self, request: &Request) -> Result<(), JsError> {
        let transfer = Array::new();
        for bytes in request.byte_buffers() {
            let buffer = bytes.buffer();
            if !transfer.iter().any(|b| Object::is(&b, &buffer)) {
                transfer.push(&buffer);
            }
        }
        let value = to_js(request)?;
        self.worker
            .post_message_with_transfer(&value, &transfer)
            .map_err(|e| JsError::new(&format!("cannot post to the worker: {e:?}")))
    }
}

fn to_js(value: &impl Serialize) -> Result<JsValue, JsError> {
    value
        .serialize(&serde_wasm_bindgen::Serializer::json_compatible())
        .map_err(|e| JsError::new(&format!("cannot build the message: {e}")))
}
