//! One WebSocket client: its hello, then a reader (messages in, pings out) and a writer (the
//! client's [`Outbox`] out).

use std::collections::VecDeque;
use std::net::IpAddr;
use std::num::NonZeroU32;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message, WebSocket};
use egoexo_protocol::live::{
    ClientMessage, Close, CloseKind, DeviceHello, DeviceRole, Join, LIVE_PROTOCOL_VERSION, LIVE_SUBPROTOCOL,
    MAX_MESSAGE_BYTES, MAX_WORLD_MESSAGE_CHARS, RelayMessage, region_problem, valid_device_id,
};
use futures::stream::{SplitSink, SplitStream};
use futures::{SinkExt, StreamExt};
use governor::{Quota, RateLimiter};
use tokio::sync::watch;
use tokio::time::Instant;

use super::LiveState;
use super::clock::ClockSample;
use super::outbox::{Outbox, Outgoing};
use super::room::{Admission, FrameOutcome, Room};

/// Pings at a connection's start, 100 ms apart, so its clock is known at once.
const FAST_PINGS: u32 = 4;
const FAST_PING_INTERVAL: Duration = Duration::from_millis(100);
/// Soonest a clock check follows the previous ping.
const MIN_PING_GAP: Duration = Duration::from_millis(100);
/// Pings remembered for their pongs.
const OUTSTANDING_PINGS: usize = 16;
/// Frames or messages sent in one go.
const BATCH: usize = 64;

type Sink = SplitSink<WebSocket, Message>;
type Source = SplitStream<WebSocket>;

fn close_message(close: Close) -> Message {
    Message::Close(Some(CloseFrame { code: close.kind.code(), reason: close.reason.into() }))
}

fn relay_json(message: &RelayMessage) -> String {
    serde_json::to_string(message).unwrap_or_else(|_| String::from("{}"))
}

/// Serves one client until it leaves or is closed.
pub(super) async fn serve(state: Arc<LiveState>, socket: WebSocket, ip: IpAddr) {
    let (mut sink, mut source) = socket.split();
    let joined = match tokio::time::timeout(state.limits.hello_timeout, read_hello(&mut source)).await {
        Err(_) => Err(Close::new(
            CloseKind::TimedOut,
            format!("no hello within {} s", state.limits.hello_timeout.as_secs_f32()),
        )),
        Ok(Err(close)) => Err(close),
        Ok(Ok(None)) => return,
        Ok(Ok(Some((join, device)))) => join_room(&state, &join, device, ip),
    };
    let (room, device) = match joined {
        Ok(joined) => joined,
        Err(close) => {
            let _ = tokio::time::timeout(Duration::from_secs(2), sink.send(close_message(close))).await;
            return;
        }
    };
    let outbox = Arc::new(Outbox::new(state.limits.history_frames));
    let now_ns = state.clock.now_ns();
    let client = match &device {
        Some(hello) => room.join_device(hello, outbox.clone(), now_ns),
        None => room.join_viewer(outbox.clone(), now_ns),
    };
    let client = match client {
        Ok(client) => client,
        Err(close) => {
            let _ = tokio::time::timeout(Duration::from_secs(2), sink.send(close_message(close))).await;
            return;
        }
    };
    outbox.push_message(relay_json(&RelayMessage::Welcome {
        protocol: LIVE_PROTOCOL_VERSION,
        room: room.id.clone(),
        client,
        relay_ns: now_ns,
        expires_at: room.expires_at.clone(),
    }));
    let (done_tx, done_rx) = watch::channel(false);
    let writer = tokio::spawn(write_loop(state.clone(), outbox.clone(), sink, done_tx));
    let reader = Reader {
        state: state.clone(),
        room: room.clone(),
        client,
        device: device.map(|d| d.id),
        outbox: outbox.clone(),
        outstanding: VecDeque::new(),
    };
    if let Some(close) = reader.run(source, done_rx).await {
        outbox.close(close);
    } else {
        outbox.close(Close::new(CloseKind::GoingAway, "bye"));
    }
    room.leave(client, state.clock.now_ns());
    if tokio::time::timeout(Duration::from_secs(5), writer).await.is_err() {
        // The writer is stuck on a socket that takes nothing; dropping it ends the connection.
    }
}

/// The first message: `Ok(None)` if the client left before saying anything.
async fn read_hello(source: &mut Source) -> Result<Option<(Join, Option<DeviceHello>)>, Close> {
    loop {
        let Some(message) = source.next().await else { return Ok(None) };
        let text = match message {
            Ok(Message::Text(text)) => text,
            Ok(Message::Ping(_) | Message::Pong(_)) => continue,
            Ok(Message::Close(_)) | Err(_) => return Ok(None),
            Ok(Message::Binary(_)) => {
                return Err(Close::new(CloseKind::BadHello, "the first message must be a hello (JSON text)"));
            }
        };
        if text.len() > MAX_MESSAGE_BYTES {
            return Err(Close::new(CloseKind::TooBig, format!("a message over {MAX_MESSAGE_BYTES} bytes")));
        }
        return match serde_json::from_str::<ClientMessage>(&text) {
            Ok(ClientMessage::Hello { protocol, join, device }) => {
                if protocol != LIVE_PROTOCOL_VERSION {
                    return Err(Close::new(
                        CloseKind::BadHello,
                        format!(
                            "this relay speaks {LIVE_SUBPROTOCOL}, protocol {LIVE_PROTOCOL_VERSION}; got {protocol}"
                        ),
                    ));
                }
                Ok(Some((join, device)))
            }
            Ok(_) => Err(Close::new(CloseKind::BadHello, "the first message must be a hello")),
            Err(e) => Err(Close::new(CloseKind::BadHello, format!("hello: {e}"))),
        };
    }
}

/// Finds the room and checks that the client may take the part it asks for.
fn join_room(
    state: &LiveState,
    join: &Join,
    device: Option<DeviceHello>,
    ip: IpAddr,
) -> Result<(Arc<Room>, Option<DeviceHello>), Close> {
    let (room, admission) = match join {
        Join::Secret { room, secret } => state.join_by_secret(room, secret, ip)?,
        Join::Code { code } => (state.join_by_code(code, ip)?, Admission::Device),
    };
    if let Some(hello) = &device {
        if admission != Admission::Device {
            return Err(Close::new(
                CloseKind::NotAllowed,
                "a watch link cannot publish: devices join with the device link or code",
            ));
        }
        if !valid_device_id(&hello.id) {
            return Err(Close::new(CloseKind::BadHello, "a device id is 1–64 of A–Z a–z 0–9 . _ -"));
        }
        if hello.streams.is_empty() {
            return Err(Close::new(CloseKind::BadHello, "a device announces at least one stream"));
        }
        if let Some(target) = &hello.target {
            if hello.role != DeviceRole::Observer {
                return Err(Close::new(CloseKind::BadHello, "only an observer names a target wearer"));
            }
            if !valid_device_id(target) || *target == hello.id {
                return Err(Close::new(
                    CloseKind::BadHello,
                    "an observer's target is another device's id (1–64 of A–Z a–z 0–9 . _ -)",
                ));
            }
        }
    }
    Ok((room, device))
}

struct Reader {
    state: Arc<LiveState>,
    room: Arc<Room>,
    client: u32,
    /// The device's id; `None` for a viewer.
    device: Option<String>,
    outbox: Arc<Outbox>,
    /// Relay times of pings not yet answered.
    outstanding: VecDeque<i64>,
}

impl Reader {
    /// Reads until the client leaves (`None`) or must be closed.
    async fn run(mut self, mut source: Source, mut done: watch::Receiver<bool>) -> Option<Close> {
        let limits = self.state.limits.clone();
        let per_second = NonZeroU32::new(limits.messages_per_second.max(1)).unwrap_or(NonZeroU32::MIN);
        let rate = RateLimiter::direct(Quota::per_second(per_second));
        let mut pings_sent = 0u32;
        let mut next_ping = Instant::now();
        let mut last_ping = Instant::now() - MIN_PING_GAP;
        let mut last_pong = Instant::now();
        loop {
            tokio::select! {
                message = source.next() => {
                    let message = match message {
                        None | Some(Ok(Message::Close(_))) => return None,
                        Some(Ok(message)) => message,
                        Some(Err(e)) => {
                            let text = e.to_string();
                            return text.contains("Space limit exceeded").then(|| {
                                Close::new(CloseKind::TooBig, format!("a message over {MAX_MESSAGE_BYTES} bytes"))
                            });
                        }
                    };
                    if rate.check().is_err() {
                        return Some(Close::new(
                            CloseKind::RateLimited,
                            format!("more than {} messages a second", limits.messages_per_second),
                        ));
                    }
                    match self.handle(message) {
                        Ok(Handled::Nothing) => {}
                        Ok(Handled::Pong) => last_pong = Instant::now(),
                        Ok(Handled::CheckClock) => {
                            next_ping = next_ping.min(last_ping + MIN_PING_GAP);
                        }
                        Err(close) => return Some(close),
                    }
                }
                _ = tokio::time::sleep_until(next_ping) => {
                    let relay_ns = self.state.clock.now_ns();
                    self.outbox.push_message(relay_json(&RelayMessage::Ping { relay_ns }));
                    if self.outstanding.len() >= OUTSTANDING_PINGS {
                        self.outstanding.pop_front();
                    }
                    self.outstanding.push_back(relay_ns);
                    pings_sent += 1;
                    last_ping = Instant::now();
                    let gap = if pings_sent < FAST_PINGS { FAST_PING_INTERVAL } else { limits.ping_interval };
                    next_ping = last_ping + gap;
                    if self.device.is_some() && last_pong.elapsed() > limits.pong_timeout {
                        return Some(Close::new(
                            CloseKind::TimedOut,
                            format!("no pong for {} s: answer every ping", limits.pong_timeout.as_secs_f32()),
                        ));
                    }
                }
                _ = done.changed() => return None,
            }
        }
    }

    fn handle(&mut self, message: Message) -> Result<Handled, Close> {
        let too_big = || Close::new(CloseKind::TooBig, format!("a message over {MAX_MESSAGE_BYTES} bytes"));
        match message {
            Message::Text(text) => {
                if text.len() > MAX_MESSAGE_BYTES {
                    return Err(too_big());
                }
                let message = serde_json::from_str::<ClientMessage>(&text)
                    .map_err(|e| Close::new(CloseKind::Malformed, format!("message: {e}")))?;
                match message {
                    ClientMessage::Hello { .. } => Err(Close::new(CloseKind::NotAllowed, "hello comes once")),
                    ClientMessage::Calibration { camera } => {
                        let Some(device) = &self.device else {
                            return Err(Close::new(CloseKind::NotAllowed, "viewers only watch"));
                        };
                        self.room.set_calibration(device, self.client, camera)?;
                        Ok(Handled::Nothing)
                    }
                    ClientMessage::Pong { relay_ns, device_ns } => {
                        let now_ns = self.state.clock.now_ns();
                        // Only pongs to this connection's pings count (a forged relay time
                        // could otherwise set any offset).
                        let Some(at) = self.outstanding.iter().position(|&t| t == relay_ns) else {
                            return Ok(Handled::Nothing);
                        };
                        self.outstanding.drain(..=at);
                        let Some(sample) = ClockSample::from_exchange(relay_ns, device_ns, now_ns) else {
                            return Ok(Handled::Pong);
                        };
                        match &self.device {
                            Some(device) => self.room.device_pong(device, self.client, sample, now_ns)?,
                            None => self.room.viewer_pong(self.client, sample),
                        }
                        Ok(Handled::Pong)
                    }
                    ClientMessage::ObserverWorld { device, state, message } => {
                        if self.device.is_some() {
                            return Err(Close::new(CloseKind::NotAllowed, "only viewers report an observer's world"));
                        }
                        if message.chars().count() > MAX_WORLD_MESSAGE_CHARS {
                            return Err(Close::new(
                                CloseKind::Malformed,
                                format!("an observer-world message over {MAX_WORLD_MESSAGE_CHARS} characters"),
                            ));
                        }
                        self.room.observer_world(&device, self.client, state, message);
                        Ok(Handled::Nothing)
                    }
                    ClientMessage::WearerRegion { device, region, at_ns } => {
                        if self.device.is_some() {
                            return Err(Close::new(CloseKind::NotAllowed, "only viewers propose a wearer's region"));
                        }
                        if let Some(problem) = region_problem(&region) {
                            return Err(Close::new(CloseKind::Malformed, problem));
                        }
                        self.room.wearer_region(&device, self.client, region, at_ns);
                        Ok(Handled::Nothing)
                    }
                }
            }
            Message::Binary(bytes) => {
                if bytes.len() > MAX_MESSAGE_BYTES {
                    return Err(too_big());
                }
                let Some(device) = &self.device else {
                    return Err(Close::new(CloseKind::NotAllowed, "viewers only watch; frames come from devices"));
                };
                match self.room.device_frame(device, self.client, &bytes, self.state.clock.now_ns())? {
                    FrameOutcome::Held { check_clock: true } => Ok(Handled::CheckClock),
                    _ => Ok(Handled::Nothing),
                }
            }
            Message::Ping(_) | Message::Pong(_) | Message::Close(_) => Ok(Handled::Nothing),
        }
    }
}

enum Handled {
    Nothing,
    Pong,
    CheckClock,
}

/// Sends the outbox until a close goes out or the socket fails or stalls; then tells the
/// reader through `done`.
async fn write_loop(state: Arc<LiveState>, outbox: Arc<Outbox>, mut sink: Sink, done: watch::Sender<bool>) {
    let stalled = state.limits.stalled_send;
    loop {
        let batch = outbox.take(BATCH, state.clock.now_ns());
        if batch.is_empty() {
            outbox.wait().await;
            continue;
        }
        let mut close = None;
        let send = async {
            for item in batch {
                match item {
                    Outgoing::Text(text) => sink.feed(Message::Text(text.into())).await?,
                    Outgoing::Binary(bytes) => sink.feed(Message::Binary(bytes)).await?,
                    Outgoing::Close(c) => {
                        close = Some(c);
                        break;
                    }
                }
            }
            sink.flush().await
        };
        match tokio::time::timeout(stalled, send).await {
            Ok(Ok(())) => {}
            Ok(Err(_)) => break,
            Err(_) => {
                close = Some(Close::new(
                    CloseKind::TimedOut,
                    format!("the client read nothing for {} s", stalled.as_secs_f32()),
                ));
            }
        }
        if let Some(close) = close {
            let _ = tokio::time::timeout(Duration::from_secs(2), sink.send(close_message(close))).await;
            break;
        }
    }
    let _ = tokio::time::timeout(Duration::from_secs(1), sink.close()).await;
    let _ = done.send(true);
}
