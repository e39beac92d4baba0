//! The worker's live connection (wasm32 only): a WebSocket to the relay as a viewer
//! (`docs/live-protocol.md`), whose frames feed a [`LiveReconstructor`]. Pings are answered
//! with the clock the page's glue handed to [`WorkerApp`](super::WorkerApp) (this module never
//! reads a clock itself). Frames are reconstructed on their own loop, one live frame at a
//! time with a yield to the event loop between, so socket messages keep arriving while the
//! engine runs and the frame shown is always the newest that can be.

use std::cell::Cell;
use std::rc::{Rc, Weak};

use egoexo_protocol::JsBytes;
use egoexo_protocol::live::{ClientMessage, DataFrame, Join, LIVE_PROTOCOL_VERSION, LIVE_SUBPROTOCOL, RelayMessage};
use egoexo_protocol::worker::{ErrorKind, ErrorStage, LiveFrameInfo, WorkerEvent};
use js_sys::{ArrayBuffer, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::spawn_local;
use web_sys::{BinaryType, CloseEvent, MessageChannel, MessageEvent, WebSocket};

use super::{Event, Runtime, yield_on};
use crate::live::{LiveReconstructor, ObserverRegion, RegionReports, WorldReports};

#[wasm_bindgen]
extern "C" {
    #[wasm_bindgen(js_namespace = console, js_name = warn)]
    fn console_warn(message: &str);
}

/// An open live connection.
pub(super) struct LiveConnection {
    socket: WebSocket,
    pub(super) reconstructor: LiveReconstructor,
    /// What this viewer told each observer about its registration.
    world_reports: WorldReports,
    /// When this viewer last told each observer where it sees the wearer.
    region_reports: RegionReports,
    /// Whether the reconstruction loop is running.
    reconstructing: Cell<bool>,
    /// Yields of the reconstruction loop (its own channel: the job loop has another).
    channel: MessageChannel,
    _on_open: Closure<dyn FnMut()>,
    _on_message: Closure<dyn FnMut(MessageEvent)>,
    _on_close: Closure<dyn FnMut(CloseEvent)>,
}

impl std::fmt::Debug for LiveConnection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveConnection").field("url", &self.socket.url()).finish()
    }
}

impl LiveConnection {
    /// Closes the socket (the relay sees a normal close) and stops its callbacks.
    pub(super) fn close(&self) {
        self.socket.set_onclose(None);
        self.socket.set_onmessage(None);
        self.socket.set_onopen(None);
        let _ = self.socket.close_with_code_and_reason(1000, "the viewer left");
    }
}

/// Connects to the relay at `url` as a viewer of `room` and keeps the connection in
/// `runtime.live` (closing one already there).
pub(super) fn join(runtime: &Rc<Runtime>, url: &str, room: String, secret: String, lookahead: usize) {
    if let Some(old) = runtime.live.borrow_mut().take() {
        old.close();
    }
    let fail = |message: String| {
        runtime.post(Event::Error { job: None, stage: ErrorStage::Request, kind: ErrorKind::BadRequest, message })
    };
    let socket = match WebSocket::new_with_str(url, LIVE_SUBPROTOCOL) {
        Ok(socket) => socket,
        Err(e) => return fail(format!("cannot connect to the relay at {url}: {}", super::js_message(&e))),
    };
    socket.set_binary_type(BinaryType::Arraybuffer);
    let weak = Rc::downgrade(runtime);
    let hello =
        ClientMessage::Hello { protocol: LIVE_PROTOCOL_VERSION, join: Join::Secret { room, secret }, device: None };
    let on_open = {
        let socket = socket.clone();
        Closure::<dyn FnMut()>::new(move || {
            let _ = socket.send_with_str(&serde_json::to_string(&hello).unwrap_or_default());
        })
    };
    let on_message = {
        let weak = weak.clone();
        Closure::<dyn FnMut(MessageEvent)>::new(move |event: MessageEvent| on_message(&weak, event))
    };
    let on_close = Closure::<dyn FnMut(CloseEvent)>::new(move |event: CloseEvent| {
        if let Some(runtime) = weak.upgrade() {
            runtime.post(Event::LiveClosed { code: event.code(), reason: event.reason() });
        }
    });
    socket.set_onopen(Some(on_open.as_ref().unchecked_ref()));
    socket.set_onmessage(Some(on_message.as_ref().unchecked_ref()));
    socket.set_onclose(Some(on_close.as_ref().unchecked_ref()));
    let channel = match MessageChannel::new() {
        Ok(channel) => channel,
        Err(e) => return fail(super::js_message(&e)),
    };
    let fps = runtime.worker.borrow().live_fps();
    *runtime.live.borrow_mut() = Some(LiveConnection {
        socket,
        reconstructor: LiveReconstructor::new(fps, lookahead),
        world_reports: WorldReports::default(),
        region_reports: RegionReports::default(),
        reconstructing: Cell::new(false),
        channel,
        _on_open: on_open,
        _on_message: on_message,
        _on_close: on_close,
    });
}

fn on_message(runtime: &Weak<Runtime>, event: MessageEvent) {
    let Some(runtime) = runtime.upgrade() else { return };
    let data = event.data();
    if let Some(buffer) = data.dyn_ref::<ArrayBuffer>() {
        let bytes = Uint8Array::new(buffer).to_vec();
        let frame = match DataFrame::decode(&bytes) {
            Ok(frame) => frame,
            // The relay checked it; a frame that does not decode is from a relay of another version.
            Err(e) => return console_warn(&format!("egoexo worker: a live frame from the relay: {e}")),
        };
        let start = {
            let mut live = runtime.live.borrow_mut();
            let Some(connection) = live.as_mut() else { return };
            connection.reconstructor.add_frame(&frame);
            !connection.reconstructing.replace(true)
        };
        if start {
            spawn_local(reconstruct_loop(runtime.clone()));
        }
        return;
    }
    let Some(text) = data.as_string() else { return };
    let message: RelayMessage = match serde_json::from_str(&text) {
        Ok(message) => message,
        Err(e) => return console_warn(&format!("egoexo worker: a live message from the relay: {e}")),
    };
    let event = {
        let mut live = runtime.live.borrow_mut();
        let Some(connection) = live.as_mut() else { return };
        match &message {
            RelayMessage::Ping { relay_ns } => {
                let device_ns = runtime.clock_ms().map_or(0, |ms| (ms * 1e6) as i64);
                let pong = ClientMessage::Pong { relay_ns: *relay_ns, device_ns };
                let _ = connection.socket.send_with_str(&serde_json::to_string(&pong).unwrap_or_default());
                None
            }
            RelayMessage::Welcome { room, expires_at, .. } => {
                Some(Event::LiveJoined { room: room.to_string(), expires_at: expires_at.clone() })
            }
            RelayMessage::Status { devices, dropped, clock_offset_ns, clock_uncertainty_ns, .. } => {
                Some(Event::LiveStatus {
                    devices: devices.clone(),
                    dropped: *dropped,
                    clock_offset_ns: *clock_offset_ns,
                    clock_uncertainty_ns: *clock_uncertainty_ns,
                    take: connection.reconstructor.summary(),
                })
            }
            _ => {
                connection.reconstructor.handle_relay_message(&message);
                None
            }
        }
    };
    if let Some(event) = event {
        runtime.post(event);
    }
}

/// Shows the newest showable frame until there is none, yielding between frames.
async fn reconstruct_loop(runtime: Rc<Runtime>) {
    loop {
        // Let the frames that arrived meanwhile in first.
        let channel = match runtime.live.borrow().as_ref() {
            Some(connection) => connection.channel.clone(),
            None => return,
        };
        yield_on(&channel).await;
        let result = {
            let mut live = runtime.live.borrow_mut();
            let Some(connection) = live.as_mut() else { return };
            let lookahead = connection.reconstructor.lookahead();
            let started = runtime.clock_ms();
            let frame = runtime.worker.borrow().live_frame(&mut connection.reconstructor);
            let compute_ms = started.zip(runtime.clock_ms()).map(|(a, b)| b - a);
            frame.map(|f| f.map(|f| (f, lookahead, compute_ms)))
        };
        match result {
            Ok(Some((frame, lookahead, compute_ms))) => {
                let info = LiveFrameInfo { compute_ms, posted_ms: runtime.clock_ms(), ..frame.info(lookahead) };
                report_worlds(&runtime, &info);
                report_regions(&runtime, &frame.wearer_regions);
                runtime.post(WorkerEvent::LiveFrame { scene: JsBytes::copy_from(&frame.scene_json), frame: info });
            }
            Ok(None) => break,
            Err(e) => {
                // That frame is passed over (the reconstructor moved on); newer ones follow.
                console_warn(&format!("egoexo worker: live frame: {e}"));
            }
        }
    }
    if let Some(connection) = runtime.live.borrow().as_ref() {
        connection.reconstructing.set(false);
    }
}

/// Tells the observers in worlds of their own where this viewer's registration of them stands
/// (through the relay; [`WorldReports`] says when).
fn report_worlds(runtime: &Runtime, info: &LiveFrameInfo) {
    let Some(now_ms) = runtime.clock_ms() else { return };
    let mut live = runtime.live.borrow_mut();
    let Some(connection) = live.as_mut() else { return };
    for report in connection.world_reports.due(&info.observer_worlds, now_ms) {
        if let Ok(text) = serde_json::to_string(&report) {
            let _ = connection.socket.send_with_str(&text);
        }
    }
}

/// Tells each observer placed in a wearer's world where this viewer sees the wearer in its
/// image (through the relay, which maps the time onto the observer's clock; [`RegionReports`]
/// says when), so a camera page crops there.
fn report_regions(runtime: &Runtime, regions: &[ObserverRegion]) {
    let Some(now_ms) = runtime.clock_ms() else { return };
    let mut live = runtime.live.borrow_mut();
    let Some(connection) = live.as_mut() else { return };
    for report in connection.region_reports.due(regions, now_ms) {
        if let Ok(text) = serde_json::to_string(&report) {
            let _ = connection.socket.send_with_str(&text);
        }
    }
}
