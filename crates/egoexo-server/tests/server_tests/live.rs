//! The live relay end to end on loopback, with real WebSocket clients (tokio-tungstenite):
//! rooms and their secrets, clocks, late viewers, back-pressure, and hostile clients closed
//! with a reason while the others carry on.
#![cfg(not(target_arch = "wasm32"))]

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use egoexo_core::camera::{CameraCalibration, Pinhole, Projection};
use egoexo_core::exo_keypoints::Keypoint2d;
use egoexo_core::glam::{Quat, Vec2, Vec3};
use egoexo_core::region::BoundingBox;
use egoexo_core::rigid::RigidTransform;
use egoexo_protocol::live::{
    ChannelInfo, ClientMessage, CloseKind, DataFrame, DeviceHello, DeviceMount, DeviceRole, DeviceStatus, DeviceWorld,
    FramePayload, Join, LIVE_PROTOCOL_VERSION, LIVE_SUBPROTOCOL, MAX_MESSAGE_BYTES, MAX_WORLD_MESSAGE_CHARS,
    RelayMessage, RoomCreated, Stream, WorldState,
};
use egoexo_server::{ApiLimits, LiveLimits, LiveState, Server, ServerOptions};
use futures::{SinkExt, StreamExt};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::tungstenite::{Bytes, Message};
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

type Socket = WebSocketStream<MaybeTlsStream<TcpStream>>;

const MS: i64 = 1_000_000;

/// A relay on a free loopback port (in this test's runtime), stopped when dropped.
struct Relay {
    addr: SocketAddr,
    live: Arc<LiveState>,
    _dist: tempfile::TempDir,
    _store: tempfile::TempDir,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl Drop for Relay {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
    }
}

async fn relay(live_limits: LiveLimits) -> Relay {
    let dist = tempfile::tempdir().unwrap();
    std::fs::write(dist.path().join("index.html"), "<!doctype html><title>egoexo</title>").unwrap();
    let store = tempfile::tempdir().unwrap();
    let options = ServerOptions {
        dist: dist.path().to_path_buf(),
        store: store.path().display().to_string(),
        listen: "127.0.0.1:0".parse().unwrap(),
        limits: ApiLimits::default(),
        live_limits,
        cors_origins: Vec::new(),
        sweep_interval: Duration::from_secs(3600),
    };
    let server = Server::bind(&options).await.unwrap();
    let (addr, live) = (server.local_addr, server.live());
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(server.run(async move {
        let _ = stopped.await;
    }));
    Relay { addr, live, _dist: dist, _store: store, stop: Some(stop) }
}

/// Fast ticks so tests see statuses and expiries quickly.
fn test_limits() -> LiveLimits {
    LiveLimits { status_interval: Duration::from_millis(200), ..LiveLimits::default() }
}

async fn create_room(addr: SocketAddr) -> RoomCreated {
    let url = format!("http://{addr}/api/live/rooms");
    tokio::task::spawn_blocking(move || {
        let mut response = ureq::post(&url).send_empty().expect("room created");
        assert_eq!(response.status(), 201);
        serde_json::from_slice(&response.body_mut().read_to_vec().unwrap()).unwrap()
    })
    .await
    .unwrap()
}

async fn socket(addr: SocketAddr) -> Socket {
    let mut request = format!("ws://{addr}/live").into_client_request().unwrap();
    request.headers_mut().insert("Sec-WebSocket-Protocol", HeaderValue::from_static(LIVE_SUBPROTOCOL));
    let (socket, response) = tokio_tungstenite::connect_async(request).await.expect("the relay takes the socket");
    assert_eq!(response.headers().get("sec-websocket-protocol").unwrap(), LIVE_SUBPROTOCOL);
    socket
}

fn now_ns() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).unwrap().as_nanos() as i64
}

fn json(message: &ClientMessage) -> Message {
    Message::Text(serde_json::to_string(message).unwrap().into())
}

/// What a client heard.
#[derive(Debug)]
enum Heard {
    Message(RelayMessage),
    Frame(DataFrame),
    Closed(Option<(u16, String)>),
}

/// A client that answers pings with its own clock (`clock_offset_ns` from the system's) and
/// reports what it hears. `read` false: it reads nothing until told (a stuck viewer).
struct Client {
    to_relay: mpsc::UnboundedSender<Message>,
    heard: mpsc::UnboundedReceiver<Heard>,
    clock_offset_ns: Arc<std::sync::atomic::AtomicI64>,
    resume: Option<tokio::sync::oneshot::Sender<()>>,
}

impl Client {
    async fn connect(addr: SocketAddr, hello: ClientMessage, clock_offset_ns: i64, read: bool) -> Client {
        let socket = socket(addr).await;
        Self::start(socket, hello, clock_offset_ns, read).await
    }

    async fn start(socket: Socket, hello: ClientMessage, clock_offset_ns: i64, read: bool) -> Client {
        let (mut sink, mut source) = socket.split();
        sink.send(json(&hello)).await.unwrap();
        let (to_relay, mut outgoing) = mpsc::unbounded_channel::<Message>();
        tokio::spawn(async move {
            while let Some(message) = outgoing.recv().await {
                if sink.send(message).await.is_err() {
                    break;
                }
            }
        });
        let (tell, heard) = mpsc::unbounded_channel();
        let offset = Arc::new(std::sync::atomic::AtomicI64::new(clock_offset_ns));
        let (resume, resumed) = tokio::sync::oneshot::channel::<()>();
        let pong = to_relay.clone();
        let clock = offset.clone();
        tokio::spawn(async move {
            if !read {
                let _ = resumed.await;
            }
            while let Some(message) = source.next().await {
                let heard = match message {
                    Ok(Message::Text(text)) => {
                        let message: RelayMessage = serde_json::from_str(&text).unwrap();
                        if let RelayMessage::Ping { relay_ns } = message {
                            let device_ns = now_ns() + clock.load(std::sync::atomic::Ordering::SeqCst);
                            let _ = pong.send(json(&ClientMessage::Pong { relay_ns, device_ns }));
                        }
                        Heard::Message(message)
                    }
                    Ok(Message::Binary(bytes)) => Heard::Frame(DataFrame::decode(&bytes).unwrap()),
                    Ok(Message::Close(frame)) => {
                        Heard::Closed(frame.map(|f: CloseFrame| (u16::from(f.code), f.reason.to_string())))
                    }
                    Ok(_) => continue,
                    Err(_) => Heard::Closed(None),
                };
                let closed = matches!(heard, Heard::Closed(_));
                if tell.send(heard).is_err() || closed {
                    break;
                }
            }
            let _ = tell.send(Heard::Closed(None));
        });
        Client { to_relay, heard, clock_offset_ns: offset, resume: Some(resume) }
    }

    fn device_clock_ns(&self) -> i64 {
        now_ns() + self.clock_offset_ns.load(std::sync::atomic::Ordering::SeqCst)
    }

    fn send_frame(&self, stream: Stream, payload: FramePayload) {
        let frame = DataFrame { channel: stream.channel(), timestamp_ns: self.device_clock_ns(), payload };
        self.send(Message::Binary(Bytes::from(frame.encode())));
    }

    fn send(&self, message: Message) {
        let _ = self.to_relay.send(message);
    }

    /// The next thing heard within `timeout`.
    async fn next(&mut self, timeout: Duration) -> Option<Heard> {
        tokio::time::timeout(timeout, self.heard.recv()).await.ok().flatten()
    }

    /// Waits for the welcome, skipping everything else.
    async fn welcome(&mut self) {
        loop {
            match self.next(Duration::from_secs(5)).await {
                Some(Heard::Message(RelayMessage::Welcome { protocol, .. })) => {
                    assert_eq!(protocol, LIVE_PROTOCOL_VERSION);
                    return;
                }
                Some(Heard::Closed(close)) => panic!("closed instead of welcomed: {close:?}"),
                Some(_) => {}
                None => panic!("no welcome"),
            }
        }
    }

    /// Waits for the close, returning its code and reason.
    async fn closed(&mut self) -> (u16, String) {
        loop {
            match self.next(Duration::from_secs(10)).await {
                Some(Heard::Closed(Some(close))) => return close,
                Some(Heard::Closed(None)) => panic!("closed without a reason"),
                Some(_) => {}
                None => panic!("not closed"),
            }
        }
    }

    /// Everything heard for `period`.
    async fn listen(&mut self, period: Duration) -> Vec<Heard> {
        let end = tokio::time::Instant::now() + period;
        let mut out = Vec::new();
        while let Ok(Some(heard)) = tokio::time::timeout_at(end, self.heard.recv()).await {
            out.push(heard);
        }
        out
    }

    /// Everything heard until `done` holds for it (or `limit` passes: the test's assertions
    /// then say what is missing), then for `settle` more, so that anything that should not
    /// come has had its chance to. A loaded machine delays; it does not fail the test.
    async fn listen_until(&mut self, limit: Duration, settle: Duration, done: impl Fn(&[Heard]) -> bool) -> Vec<Heard> {
        let end = tokio::time::Instant::now() + limit;
        let mut out = Vec::new();
        while !done(&out) {
            match tokio::time::timeout_at(end, self.heard.recv()).await {
                Ok(Some(heard)) => out.push(heard),
                _ => return out,
            }
        }
        out.extend(self.listen(settle).await);
        out
    }
}

fn device_hello(join: Join, id: &str, role: DeviceRole, streams: &[Stream]) -> ClientMessage {
    ClientMessage::Hello {
        protocol: LIVE_PROTOCOL_VERSION,
        join,
        device: Some(DeviceHello::worn(id, role, streams.to_vec())),
    }
}

fn viewer_hello(room: &RoomCreated) -> ClientMessage {
    ClientMessage::Hello {
        protocol: LIVE_PROTOCOL_VERSION,
        join: Join::Secret { room: room.room.clone(), secret: room.viewer_secret.clone() },
        device: None,
    }
}

/// A wearer with only a head stream, joined with the device secret and welcomed.
async fn head_wearer(addr: SocketAddr, room: &RoomCreated) -> Client {
    let hello = device_hello(device_join(room), "wearer", DeviceRole::Wearer, &[Stream::Head]);
    let mut wearer = Client::connect(addr, hello, 0, true).await;
    wearer.welcome().await;
    wearer
}

/// A viewer joined with the watch secret and welcomed.
async fn welcomed_viewer(addr: SocketAddr, room: &RoomCreated) -> Client {
    let mut viewer = Client::connect(addr, viewer_hello(room), 0, true).await;
    viewer.welcome().await;
    viewer
}

fn device_join(room: &RoomCreated) -> Join {
    Join::Secret { room: room.room.clone(), secret: room.device_secret.clone() }
}

fn pose(x: f32) -> FramePayload {
    FramePayload::Pose(Some(RigidTransform { rotation: Quat::from_rotation_y(x), translation: Vec3::new(x, 1.6, 0.0) }))
}

/// Poses equal up to the decoder's quaternion normalisation.
fn assert_close(got: &FramePayload, want: &FramePayload) {
    let (FramePayload::Pose(Some(got)), FramePayload::Pose(Some(want))) = (got, want) else { panic!("{got:?}") };
    assert!(got.translation.abs_diff_eq(want.translation, 1e-6) && got.rotation.abs_diff_eq(want.rotation, 1e-6));
}

fn keypoints() -> FramePayload {
    FramePayload::Keypoints(std::array::from_fn(|k| {
        (k != 3).then(|| Keypoint2d { pixel: Vec2::new(100.0 + k as f32, 200.0), score: 0.9 })
    }))
}

fn camera() -> CameraCalibration {
    CameraCalibration::new(
        Projection::Pinhole(Pinhole::new(600.0, 600.0, 703.5, 703.5).unwrap()),
        1408,
        1408,
        RigidTransform::IDENTITY,
    )
    .unwrap()
}

/// How long a test waits for what it expects on a loaded machine (CI's, with a build
/// beside it), and how long it then listens for anything unexpected.
const LOADED: Duration = Duration::from_secs(10);
const SETTLE: Duration = Duration::from_millis(300);

fn frames(heard: &[Heard]) -> Vec<DataFrame> {
    heard.iter().filter_map(|h| if let Heard::Frame(f) = h { Some(*f) } else { None }).collect()
}

fn last_channels(heard: &[Heard]) -> Vec<ChannelInfo> {
    heard
        .iter()
        .rev()
        .find_map(|h| match h {
            Heard::Message(RelayMessage::Channels { channels }) => Some(channels.clone()),
            _ => None,
        })
        .unwrap_or_default()
}

fn last_status(heard: &[Heard]) -> Option<(Vec<DeviceStatus>, u64, Option<i64>)> {
    heard.iter().rev().find_map(|h| match h {
        Heard::Message(RelayMessage::Status { devices, dropped, clock_offset_ns, .. }) => {
            Some((devices.clone(), *dropped, *clock_offset_ns))
        }
        _ => None,
    })
}

/// Sends `n` frames at `hz` on `stream`, with poses numbered from `start`.
async fn stream_poses(device: &Client, stream: Stream, n: usize, hz: f64, start: usize) {
    let mut ticks = tokio::time::interval(Duration::from_secs_f64(1.0 / hz));
    for i in 0..n {
        ticks.tick().await;
        device.send_frame(stream, pose((start + i) as f32 * 0.01));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn devices_stream_to_viewers_on_the_relay_clock() {
    let relay = relay(test_limits()).await;
    let room = create_room(relay.addr).await;
    assert_eq!(room.device_code.len(), 7);
    // The wearer's clock runs 1000 s ahead of the relay's, the observer's 250 s behind.
    let mut wearer = Client::connect(
        relay.addr,
        device_hello(
            Join::Code { code: room.device_code.to_lowercase() },
            "wearer",
            DeviceRole::Wearer,
            &[Stream::Head, Stream::LeftWrist],
        ),
        1_000_000 * MS,
        true,
    )
    .await;
    wearer.welcome().await;
    let mut observer = Client::connect(
        relay.addr,
        device_hello(device_join(&room), "observer-1", DeviceRole::Observer, &[Stream::Head, Stream::Keypoints]),
        -250_000 * MS,
        true,
    )
    .await;
    observer.welcome().await;
    observer.send(json(&ClientMessage::Calibration { camera: camera() }));
    let mut viewer = welcomed_viewer(relay.addr, &room).await;
    // 60 head poses at 60 Hz, wrists at 30 Hz, keypoints at 30 Hz.
    let (w, o) = (&wearer, &observer);
    tokio::join!(stream_poses(w, Stream::Head, 60, 60.0, 0), stream_poses(w, Stream::LeftWrist, 30, 30.0, 0), async {
        let mut ticks = tokio::time::interval(Duration::from_millis(33));
        for _ in 0..30 {
            ticks.tick().await;
            o.send_frame(Stream::Keypoints, keypoints());
            o.send_frame(Stream::Head, pose(0.5));
        }
    });
    let heard = viewer.listen(Duration::from_millis(700)).await;
    let channels = last_channels(&heard);
    let channel_of = |device: &str, stream: Stream| {
        channels.iter().find(|c| c.device == device && c.stream == stream).map(|c| c.channel).unwrap()
    };
    let frames = frames(&heard);
    let count = |channel: u16| frames.iter().filter(|f| f.channel == channel).count();
    // Nothing is lost when nobody is overloaded.
    assert_eq!(count(channel_of("wearer", Stream::Head)), 60);
    assert_eq!(count(channel_of("wearer", Stream::LeftWrist)), 30);
    assert_eq!(count(channel_of("observer-1", Stream::Keypoints)), 30);
    assert_eq!(count(channel_of("observer-1", Stream::Head)), 30);
    // Every stamp is on the relay clock: within loopback latency of now, whatever the device
    // clocks say.
    let now = now_ns();
    for frame in &frames {
        let age = now - frame.timestamp_ns;
        assert!((0..2_000 * MS).contains(&age), "a frame stamped {age} ns before now");
    }
    // Head poses arrive in order, each with its payload.
    let heads: Vec<_> = frames.iter().filter(|f| f.channel == channel_of("wearer", Stream::Head)).collect();
    assert!(heads.windows(2).all(|w| w[0].timestamp_ns <= w[1].timestamp_ns));
    assert_close(&heads[59].payload, &pose(59.0 * 0.01));
    assert!(heard.iter().any(|h| matches!(h, Heard::Message(RelayMessage::Calibration { device, camera: c })
        if device == "observer-1" && *c == camera())));
    let (devices, dropped, viewer_offset) = last_status(&heard).expect("a status");
    assert_eq!(dropped, 0);
    assert!(viewer_offset.unwrap().abs() < 50 * MS, "the viewer's own offset: {viewer_offset:?}");
    let wearer_status = devices.iter().find(|d| d.device == "wearer").unwrap();
    let offset = wearer_status.clock_offset_ns.unwrap();
    assert!((offset + 1_000_000 * MS).abs() < 20 * MS, "wearer offset {offset}");
    assert!(wearer_status.clock_uncertainty_ns.unwrap() < 20 * MS);
    assert!(wearer_status.latency_ns.unwrap() < 100 * MS);
    let observer_status = devices.iter().find(|d| d.device == "observer-1").unwrap();
    assert!((observer_status.clock_offset_ns.unwrap() - 250_000 * MS).abs() < 20 * MS);
    assert!(observer_status.connected && observer_status.frames == 60);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_viewer_joining_late_gets_the_last_seconds_at_once() {
    let relay = relay(LiveLimits { history: Duration::from_millis(600), ..test_limits() }).await;
    let room = create_room(relay.addr).await;
    let wearer = head_wearer(relay.addr, &room).await;
    // 1.5 s of head poses at 50 Hz; the room keeps the last 0.6 s.
    stream_poses(&wearer, Stream::Head, 75, 50.0, 0).await;
    let mut viewer = Client::connect(relay.addr, viewer_hello(&room), 0, true).await;
    let heard = viewer.listen(Duration::from_millis(300)).await;
    assert!(matches!(heard.first(), Some(Heard::Message(RelayMessage::Welcome { .. }))));
    let frames = frames(&heard);
    let span = frames.last().unwrap().timestamp_ns - frames[0].timestamp_ns;
    assert!((25..=32).contains(&frames.len()), "{} frames of history", frames.len());
    // The room trims by relay stamps, which map device time through the running clock-offset
    // estimate; the estimate may move between the oldest frame kept and the newest (a CI run
    // on a loaded machine saw 620 ms), so the span is the window plus that movement.
    assert!(span <= 650 * MS, "history spans {span} ns");
    // The newest pose came along.
    assert_close(&frames.last().unwrap().payload, &pose(74.0 * 0.01));
    assert_eq!(last_channels(&heard).len(), 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_clients_are_closed_with_a_reason_and_the_others_carry_on() {
    let relay = relay(LiveLimits { join_attempts_per_minute: 5, ..test_limits() }).await;
    let room = create_room(relay.addr).await;
    let wearer = head_wearer(relay.addr, &room).await;
    let mut viewer = welcomed_viewer(relay.addr, &room).await;

    let code = |kind: CloseKind| kind.code();
    // A watch link cannot publish.
    let mut intruder = Client::connect(
        relay.addr,
        device_hello(
            Join::Secret { room: room.room.clone(), secret: room.viewer_secret.clone() },
            "observer-9",
            DeviceRole::Observer,
            &[Stream::Keypoints],
        ),
        0,
        true,
    )
    .await;
    let (c, reason) = intruder.closed().await;
    assert_eq!(c, code(CloseKind::NotAllowed), "{reason}");
    assert!(reason.contains("watch link"), "{reason}");
    // A viewer that publishes.
    let mut publishing_viewer = Client::connect(relay.addr, viewer_hello(&room), 0, true).await;
    publishing_viewer.welcome().await;
    publishing_viewer.send_frame(Stream::Head, pose(0.0));
    let (c, reason) = publishing_viewer.closed().await;
    assert_eq!(c, code(CloseKind::NotAllowed), "{reason}");
    // A malformed frame, then one the role may not send, then one over the size limit.
    let cases: Vec<(&str, Message, CloseKind, &str)> = vec![
        ("bad-frame", Message::Binary(Bytes::from(vec![1, 0, 0, 0, 9])), CloseKind::Malformed, "header"),
        (
            "wrong-stream",
            Message::Binary(Bytes::from(
                DataFrame { channel: Stream::LeftWrist.channel(), timestamp_ns: now_ns(), payload: pose(0.0) }.encode(),
            )),
            CloseKind::NotAllowed,
            "did not announce",
        ),
        ("big", Message::Binary(Bytes::from(vec![0; MAX_MESSAGE_BYTES + 1])), CloseKind::TooBig, "over"),
        ("bad-json", Message::Text("{\"type\":\"pong\",\"relay_ns\":\"x\"}".into()), CloseKind::Malformed, "message"),
        ("second-hello", json(&viewer_hello(&room)), CloseKind::NotAllowed, "once"),
    ];
    for (id, message, kind, needle) in cases {
        let mut bad = Client::connect(
            relay.addr,
            device_hello(device_join(&room), id, DeviceRole::Observer, &[Stream::Head]),
            0,
            true,
        )
        .await;
        bad.welcome().await;
        bad.send(message);
        let (c, reason) = bad.closed().await;
        assert_eq!(c, code(kind), "{id}: {reason}");
        assert!(reason.contains(needle), "{id}: {reason}");
    }
    // Several wearers share a room (a capture of several participants): a second one is in.
    let mut second = Client::connect(
        relay.addr,
        device_hello(device_join(&room), "wearer-2", DeviceRole::Wearer, &[Stream::Head]),
        0,
        true,
    )
    .await;
    second.welcome().await;
    drop(second);
    // Only an observer names the wearer it sees, and never itself.
    for (id, role, target) in
        [("wearer-3", DeviceRole::Wearer, "wearer"), ("observer-9", DeviceRole::Observer, "observer-9")]
    {
        let hello = ClientMessage::Hello {
            protocol: LIVE_PROTOCOL_VERSION,
            join: device_join(&room),
            device: Some(DeviceHello {
                target: Some(target.into()),
                ..DeviceHello::worn(id, role, vec![Stream::Head])
            }),
        };
        let (c, reason) = Client::connect(relay.addr, hello, 0, true).await.closed().await;
        assert_eq!(c, code(CloseKind::BadHello), "{id}: {reason}");
        assert!(reason.contains("target"), "{id}: {reason}");
    }
    // No hello, a hello for another version, an unknown room, wrong codes until rate-limited.
    let mut silent =
        Client::start(socket(relay.addr).await, ClientMessage::Pong { relay_ns: 0, device_ns: 0 }, 0, true).await;
    assert_eq!(silent.closed().await.0, code(CloseKind::BadHello));
    let old = ClientMessage::Hello { protocol: 0, join: device_join(&room), device: None };
    assert_eq!(Client::connect(relay.addr, old, 0, true).await.closed().await.0, code(CloseKind::BadHello));
    let nowhere = ClientMessage::Hello {
        protocol: LIVE_PROTOCOL_VERSION,
        join: Join::Secret { room: "AAAAAAAAAAAAAAAAAAAAAA".into(), secret: "x".into() },
        device: None,
    };
    assert_eq!(Client::connect(relay.addr, nowhere, 0, true).await.closed().await.0, code(CloseKind::NotAdmitted));
    let mut kinds = Vec::new();
    for _ in 0..6 {
        let guess = device_hello(Join::Code { code: "222-222".into() }, "x", DeviceRole::Wearer, &[Stream::Head]);
        kinds.push(CloseKind::from_code(Client::connect(relay.addr, guess, 0, true).await.closed().await.0).unwrap());
    }
    // One failed join above (the unknown room) and these six: the fifth attempt is the last.
    assert_eq!(kinds[..4], [CloseKind::NotAdmitted; 4]);
    assert_eq!(kinds[4..], [CloseKind::RateLimited; 2]);

    // Through all of it the wearer kept streaming to the viewer.
    stream_poses(&wearer, Stream::Head, 20, 100.0, 0).await;
    let heard = viewer.listen_until(LOADED, SETTLE, |h| frames(h).len() >= 20).await;
    assert_eq!(frames(&heard).len(), 20);
    assert!(!heard.iter().any(|h| matches!(h, Heard::Closed(_))));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_clock_jump_is_caught_before_frames_are_misplaced() {
    let relay = relay(test_limits()).await;
    let room = create_room(relay.addr).await;
    let wearer = head_wearer(relay.addr, &room).await;
    let mut viewer = welcomed_viewer(relay.addr, &room).await;
    stream_poses(&wearer, Stream::Head, 20, 50.0, 0).await;
    // The device's clock is set 30 s forward, then 45 s back.
    wearer.clock_offset_ns.store(30_000 * MS, std::sync::atomic::Ordering::SeqCst);
    stream_poses(&wearer, Stream::Head, 20, 50.0, 20).await;
    wearer.clock_offset_ns.store(-15_000 * MS, std::sync::atomic::Ordering::SeqCst);
    stream_poses(&wearer, Stream::Head, 20, 50.0, 40).await;
    let heard = viewer.listen_until(LOADED, SETTLE, |h| frames(h).len() >= 60).await;
    let frames = frames(&heard);
    assert_eq!(frames.len(), 60, "every frame arrives");
    let now = now_ns();
    for frame in &frames {
        let age = now - frame.timestamp_ns;
        assert!((0..3_000 * MS).contains(&age), "a frame stamped {age} ns before now");
    }
    let (devices, _, _) = last_status(&heard).unwrap();
    assert_eq!(devices[0].clock_jumps, 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_viewer_that_stops_reading_costs_bounded_memory_and_is_told_its_drops() {
    let per_channel = 64;
    let relay =
        relay(LiveLimits { history_frames: per_channel, messages_per_second: 1_000_000, ..test_limits() }).await;
    let room = create_room(relay.addr).await;
    let mut observer = Client::connect(
        relay.addr,
        device_hello(device_join(&room), "observer-1", DeviceRole::Observer, &[Stream::Keypoints]),
        0,
        true,
    )
    .await;
    observer.welcome().await;
    // A viewer with a tiny receive buffer that reads nothing, and a healthy one.
    let tcp = tokio::net::TcpSocket::new_v4().unwrap();
    tcp.set_recv_buffer_size(4096).unwrap();
    let stream = tcp.connect(relay.addr).await.unwrap();
    let mut request = format!("ws://{}/live", relay.addr).into_client_request().unwrap();
    request.headers_mut().insert("Sec-WebSocket-Protocol", HeaderValue::from_static(LIVE_SUBPROTOCOL));
    let (stuck_socket, _) = tokio_tungstenite::client_async(request, MaybeTlsStream::Plain(stream)).await.unwrap();
    let mut stuck = Client::start(stuck_socket, viewer_hello(&room), 0, false).await;
    let mut healthy = Client::connect(relay.addr, viewer_hello(&room), 0, true).await;
    healthy.welcome().await;
    // 40 000 keypoint frames (8.7 MB) as fast as the socket takes them.
    let sent = 40_000;
    let mut peak_queued = 0;
    for i in 0..sent {
        observer.send_frame(Stream::Keypoints, keypoints());
        if i % 1000 == 0 {
            tokio::time::sleep(Duration::from_millis(5)).await;
            peak_queued = peak_queued.max(relay.live.queued_frames());
        }
    }
    let mut received = 0;
    let mut last = None;
    let mut quiet_since = tokio::time::Instant::now();
    while let Some(heard) = healthy.next(Duration::from_secs(2)).await {
        if let Heard::Frame(frame) = heard {
            received += 1;
            last = Some(frame);
            quiet_since = tokio::time::Instant::now();
        } else if quiet_since.elapsed() > Duration::from_secs(2) {
            break;
        }
        peak_queued = peak_queued.max(relay.live.queued_frames());
        if received == sent {
            break;
        }
    }
    // Two viewers and one channel: never more than 2 × 64 frames queued, whatever was sent.
    assert!(peak_queued <= 2 * per_channel, "{peak_queued} frames queued");
    assert!(received > 0 && last.is_some());
    // The stuck viewer reads again: it sees the newest frames and how many it missed.
    stuck.resume.take().unwrap().send(()).unwrap();
    let heard = stuck.listen(Duration::from_secs(2)).await;
    let (_, dropped, _) = last_status(&heard).expect("a status");
    let got = frames(&heard).len() as u64;
    assert!(dropped > 0, "drops are counted");
    // Every frame sent reached the viewer or was counted as dropped.
    assert_eq!(got + dropped, sent as u64, "{got} received + {dropped} dropped");
    println!("stuck viewer: {got} frames received, {dropped} dropped; peak queue {peak_queued} frames");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_device_that_reconnects_keeps_its_channels_and_the_old_socket_is_closed() {
    let relay = relay(test_limits()).await;
    let room = create_room(relay.addr).await;
    let hello =
        device_hello(device_join(&room), "observer-1", DeviceRole::Observer, &[Stream::Head, Stream::Keypoints]);
    let mut first = Client::connect(relay.addr, hello.clone(), 0, true).await;
    first.welcome().await;
    let mut viewer = welcomed_viewer(relay.addr, &room).await;
    // The first connection's frame reaches the viewer before the device reconnects: the relay
    // holds a device's frames until it knows the device's clock, and drops what a replaced
    // connection still holds (a fixed sleep for the clock was too short on a loaded machine).
    first.send_frame(Stream::Head, pose(0.1));
    let mut heard = viewer.listen_until(LOADED, Duration::ZERO, |h| !frames(h).is_empty()).await;
    let mut second = Client::connect(relay.addr, hello.clone(), 0, true).await;
    second.welcome().await;
    let (c, _) = first.closed().await;
    assert_eq!(c, CloseKind::Replaced.code());
    second.send_frame(Stream::Head, pose(0.2));
    heard.extend(viewer.listen_until(LOADED, SETTLE, |h| !frames(h).is_empty()).await);
    let frames = frames(&heard);
    assert_eq!(frames.len(), 2);
    assert_eq!(frames[0].channel, frames[1].channel);
    let lists = heard.iter().filter(|h| matches!(h, Heard::Message(RelayMessage::Channels { .. }))).count();
    assert_eq!(lists, 1, "the list the viewer got on joining, and no other: it did not change");
    assert_eq!(last_channels(&heard).len(), 2);
    assert!(last_channels(&heard).iter().all(|c| c.world == DeviceWorld::Shared));
    // Back in a world of its own (a headset told so): the same channels, each saying it.
    let ClientMessage::Hello { protocol, join, device: Some(mut device) } = hello else { unreachable!() };
    device.world = DeviceWorld::Own;
    let own = ClientMessage::Hello { protocol, join, device: Some(device) };
    let mut third = Client::connect(relay.addr, own, 0, true).await;
    third.welcome().await;
    let heard = viewer.listen_until(LOADED, SETTLE, |h| !last_channels(h).is_empty()).await;
    let channels = last_channels(&heard);
    assert_eq!(channels.len(), 2);
    assert!(channels.iter().all(|c| c.world == DeviceWorld::Own), "{channels:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rooms_expire_and_their_clients_are_told() {
    let relay = relay(LiveLimits { room_ttl: Duration::from_millis(800), ..test_limits() }).await;
    let room = create_room(relay.addr).await;
    let mut viewer = welcomed_viewer(relay.addr, &room).await;
    let (c, reason) = viewer.closed().await;
    assert_eq!((c, reason.as_str()), (CloseKind::RoomClosed.code(), "the room expired"));
    assert_eq!(relay.live.room_count(), 0);
    let again = Client::connect(relay.addr, viewer_hello(&room), 0, true).await.closed().await;
    assert_eq!(again.0, CloseKind::NotAdmitted.code());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_socket_needs_the_subprotocol() {
    let relay = relay(test_limits()).await;
    let request = format!("ws://{}/live", relay.addr).into_client_request().unwrap();
    let err = tokio_tungstenite::connect_async(request).await.unwrap_err();
    let tokio_tungstenite::tungstenite::Error::Http(response) = err else { panic!("{err}") };
    assert_eq!(response.status(), 400);
    let body = String::from_utf8_lossy(response.body().as_deref().unwrap_or_default()).to_string();
    assert!(body.contains(LIVE_SUBPROTOCOL), "{body}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fixed_camera_publishes_keypoints_only_and_viewers_see_its_mount() {
    let relay = relay(test_limits()).await;
    let room = create_room(relay.addr).await;
    let code = |kind: CloseKind| kind.code();
    // A fixed camera announcing a head pose it cannot have.
    let fixed_with_head = ClientMessage::Hello {
        protocol: LIVE_PROTOCOL_VERSION,
        join: device_join(&room),
        device: Some(DeviceHello {
            mount: DeviceMount::Fixed,
            ..DeviceHello::worn("webcam", DeviceRole::Observer, vec![Stream::Head, Stream::Keypoints])
        }),
    };
    let (c, reason) = Client::connect(relay.addr, fixed_with_head, 0, true).await.closed().await;
    assert_eq!(c, code(CloseKind::NotAllowed), "{reason}");
    assert!(reason.contains("fixed camera"), "{reason}");
    // Keypoints only: admitted, and its channel says what it is.
    let mut viewer = welcomed_viewer(relay.addr, &room).await;
    let webcam = ClientMessage::Hello {
        protocol: LIVE_PROTOCOL_VERSION,
        join: device_join(&room),
        device: Some(DeviceHello {
            world: DeviceWorld::Own,
            mount: DeviceMount::Fixed,
            focal_known: false,
            ..DeviceHello::worn("webcam", DeviceRole::Observer, vec![Stream::Keypoints])
        }),
    };
    let mut camera = Client::connect(relay.addr, webcam, 0, true).await;
    camera.welcome().await;
    let heard = viewer.listen_until(Duration::from_secs(10), Duration::ZERO, |h| !last_channels(h).is_empty()).await;
    let channels = last_channels(&heard);
    assert_eq!(channels.len(), 1, "{channels:?}");
    let channel = &channels[0];
    assert_eq!((channel.stream, channel.mount, channel.focal_known), (Stream::Keypoints, DeviceMount::Fixed, false));
    assert_eq!(channel.world, DeviceWorld::Own);
}

/// The words on a viewer's word about an observer's world this client heard.
fn world_words(heard: &[Heard]) -> Vec<(u32, WorldState, String)> {
    heard
        .iter()
        .filter_map(|h| match h {
            Heard::Message(RelayMessage::ObserverWorld { viewer, state, message }) => {
                Some((*viewer, *state, message.clone()))
            }
            _ => None,
        })
        .collect()
}

#[tokio::test]
async fn a_viewers_word_on_an_observers_world_reaches_that_observer_only() {
    let relay = relay(test_limits()).await;
    let room = create_room(relay.addr).await;
    let mut viewer = welcomed_viewer(relay.addr, &room).await;
    let mut wearer = head_wearer(relay.addr, &room).await;
    let tripod = device_hello(device_join(&room), "tripod", DeviceRole::Observer, &[Stream::Keypoints]);
    let mut camera = Client::connect(relay.addr, tripod, 0, true).await;
    camera.welcome().await;
    let word = |device: &str, state: WorldState, message: &str| {
        json(&ClientMessage::ObserverWorld { device: device.into(), state, message: message.into() })
    };
    // One for the camera, one naming the wearer (not an observer), one naming nobody.
    viewer.send(word("wearer", WorldState::Registered, "not an observer"));
    viewer.send(word("nobody", WorldState::Registered, "no such device"));
    viewer.send(word("tripod", WorldState::Registering, "registering — 3 s of views"));
    viewer.send(word("tripod", WorldState::Registered, "registered after 4.2 s of views"));
    let heard =
        camera.listen_until(Duration::from_secs(10), Duration::from_millis(300), |h| world_words(h).len() >= 2).await;
    let words: Vec<(WorldState, String)> = world_words(&heard).into_iter().map(|(_, s, m)| (s, m)).collect();
    assert_eq!(
        words,
        [
            (WorldState::Registering, "registering — 3 s of views".to_string()),
            (WorldState::Registered, "registered after 4.2 s of views".to_string()),
        ]
    );
    assert!(world_words(&wearer.listen(Duration::from_millis(300)).await).is_empty(), "the wearer heard a word");
    // Only viewers say it, and briefly: a device that does is closed, as is a viewer whose
    // message is over the limit (the others carry on).
    camera.send(word("tripod", WorldState::Registered, "I say so myself"));
    let (code, reason) = camera.closed().await;
    assert_eq!(code, CloseKind::NotAllowed.code(), "{reason}");
    let long = "x".repeat(MAX_WORLD_MESSAGE_CHARS + 1);
    viewer.send(word("tripod", WorldState::Registering, &long));
    let (code, reason) = viewer.closed().await;
    assert_eq!(code, CloseKind::Malformed.code(), "{reason}");
    assert!(reason.contains("observer-world"), "{reason}");
    wearer.send_frame(Stream::Head, pose(0.0));
    assert!(!matches!(wearer.next(Duration::from_millis(300)).await, Some(Heard::Closed(_))));
}

/// The wearer regions a client heard: (viewer, region, time on its clock).
fn regions_heard(heard: &[Heard]) -> Vec<(u32, BoundingBox, i64)> {
    heard
        .iter()
        .filter_map(|h| match h {
            Heard::Message(RelayMessage::WearerRegion { viewer, region, at_ns }) => Some((*viewer, *region, *at_ns)),
            _ => None,
        })
        .collect()
}

#[tokio::test]
async fn a_viewers_wearer_region_reaches_that_observer_on_its_own_clock() {
    let relay = relay(test_limits()).await;
    let room = create_room(relay.addr).await;
    let mut viewer = welcomed_viewer(relay.addr, &room).await;
    let mut wearer = head_wearer(relay.addr, &room).await;
    // A camera whose clock runs 5 s ahead of the relay's.
    const AHEAD_NS: i64 = 5_000_000_000;
    let tripod = device_hello(device_join(&room), "tripod", DeviceRole::Observer, &[Stream::Keypoints]);
    let mut camera = Client::connect(relay.addr, tripod, AHEAD_NS, true).await;
    camera.welcome().await;
    // Its clock is known once it has answered a ping (the relay pings on joining).
    camera
        .listen_until(Duration::from_secs(10), Duration::from_millis(200), |h| {
            h.iter().any(|h| matches!(h, Heard::Message(RelayMessage::Ping { .. })))
        })
        .await;
    let region = BoundingBox { min: Vec2::new(120.0, 30.0), max: Vec2::new(300.0, 470.0) };
    let at_ns = now_ns();
    let propose =
        |device: &str, region: BoundingBox| json(&ClientMessage::WearerRegion { device: device.into(), region, at_ns });
    // One for the wearer (not an observer) and one for nobody are dropped.
    viewer.send(propose("wearer", region));
    viewer.send(propose("nobody", region));
    viewer.send(propose("tripod", region));
    let heard = camera
        .listen_until(Duration::from_secs(10), Duration::from_millis(300), |h| !regions_heard(h).is_empty())
        .await;
    let regions = regions_heard(&heard);
    assert_eq!(regions.len(), 1, "{regions:?}");
    let (_, got, device_ns) = regions[0];
    assert_eq!(got, region);
    // On the camera's clock, to within the loopback round trip of the clock estimate.
    let off_ms = (device_ns - (at_ns + AHEAD_NS)) as f64 / 1e6;
    assert!(off_ms.abs() < 50.0, "the region's time is {off_ms} ms off the camera's clock");
    assert!(regions_heard(&wearer.listen(Duration::from_millis(300)).await).is_empty(), "the wearer heard a region");
    // Only viewers propose, and only boxes: a device that does is closed, as is a viewer
    // proposing a box that is not one (the others carry on).
    camera.send(propose("tripod", region));
    let (code, reason) = camera.closed().await;
    assert_eq!(code, CloseKind::NotAllowed.code(), "{reason}");
    viewer.send(propose("tripod", BoundingBox { min: region.max, max: region.min }));
    let (code, reason) = viewer.closed().await;
    assert_eq!(code, CloseKind::Malformed.code(), "{reason}");
    assert!(reason.contains("wearer region"), "{reason}");
    wearer.send_frame(Stream::Head, pose(0.0));
    assert!(!matches!(wearer.next(Duration::from_millis(300)).await, Some(Heard::Closed(_))));
}
