//! The live relay (`egoexo_protocol::live`, `docs/live-protocol.md`): rooms that devices
//! publish head, wrist and keypoint streams into and viewers watch.
//!
//! - `POST /api/live/rooms` creates a room: its id, a device secret (publish), a viewer secret
//!   (watch only) and the device secret as a short code to type on a headset.
//! - `GET /live` upgrades to a WebSocket with the subprotocol
//!   [`LIVE_SUBPROTOCOL`]; the first message is a hello that joins a room.
//!
//! The relay measures every client's clock against its own ([`clock`]), stamps device frames
//! on the relay clock, keeps the last seconds of every channel for viewers who join late, and
//! never lets a slow viewer hold stale frames or grow the server's memory ([`outbox`]). A
//! client that sends something wrong is closed with a reason; nobody else notices.

pub mod clock;
mod connection;
pub mod outbox;
pub mod room;

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::num::NonZeroU32;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::Json;
use axum::extract::ws::WebSocketUpgrade;
use axum::extract::{ConnectInfo, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use egoexo_protocol::live::{Close, CloseKind, LIVE_SUBPROTOCOL, MAX_MESSAGE_BYTES, RoomCreated, RoomId};
use egoexo_protocol::share::{ApiErrorKind, base64url};
use governor::{DefaultKeyedRateLimiter, Quota, RateLimiter};

use crate::api::{Failure, client_ip, rfc3339};
use clock::RelayClock;
use room::Room;

/// The relay's limits (all per room or per client, so one client cannot exhaust them for
/// others).
#[derive(Clone, Debug)]
pub struct LiveLimits {
    /// Rooms open at once on this server.
    pub max_rooms: usize,
    /// Rooms one client (IP address) may create a minute.
    pub rooms_per_minute: u32,
    /// How long a room lives.
    pub room_ttl: Duration,
    /// How long a room with nobody connected lives.
    pub empty_room_ttl: Duration,
    pub max_devices_per_room: usize,
    pub max_viewers_per_room: usize,
    /// Streams in a room (a wearer with wrists is 3, an observer 2).
    pub max_channels_per_room: usize,
    /// Messages a second one connection may send (a headset at 90 Hz sends ~270).
    pub messages_per_second: u32,
    /// Join attempts by code, or with a wrong secret, one client may make a minute.
    pub join_attempts_per_minute: u32,
    /// How much of every channel a viewer joining late receives.
    pub history: Duration,
    /// Most frames kept per channel for late viewers, and queued per channel for a viewer.
    pub history_frames: usize,
    /// How long a live frame may wait for a slow viewer before a newer one replaces it.
    pub live_deadline: Duration,
    /// The same for the history a viewer receives when it joins.
    pub history_deadline: Duration,
    /// How long a client has to send its hello.
    pub hello_timeout: Duration,
    /// How often clients are pinged for their clock (the first pings come faster).
    pub ping_interval: Duration,
    /// How long a device may leave pings unanswered.
    pub pong_timeout: Duration,
    /// How often viewers get the room's status.
    pub status_interval: Duration,
    /// How long a client's socket may accept nothing before it is closed.
    pub stalled_send: Duration,
}

impl Default for LiveLimits {
    /// 256 rooms (10 new a minute per client) living 12 h, or 30 min empty; 16 devices, 16
    /// viewers and 64 channels a room; 1000 messages/s a connection; 10 join attempts a
    /// minute; 3.2 s (≤ 384 frames) of history; live frames stale after 250 ms, history
    /// after 5 s; hello within 5 s; pings every second, answered within 10 s; status every
    /// second; a socket stalled 30 s is closed.
    fn default() -> Self {
        Self {
            max_rooms: 256,
            rooms_per_minute: 10,
            room_ttl: Duration::from_secs(12 * 3600),
            empty_room_ttl: Duration::from_secs(30 * 60),
            max_devices_per_room: 16,
            max_viewers_per_room: 16,
            max_channels_per_room: 64,
            messages_per_second: 1000,
            join_attempts_per_minute: 10,
            history: Duration::from_secs_f64(egoexo_protocol::live::HISTORY_S),
            history_frames: 384,
            live_deadline: Duration::from_millis(250),
            history_deadline: Duration::from_secs(5),
            hello_timeout: Duration::from_secs(5),
            ping_interval: Duration::from_secs(1),
            pong_timeout: Duration::from_secs(10),
            status_interval: Duration::from_secs(1),
            stalled_send: Duration::from_secs(30),
        }
    }
}

fn nanos(d: Duration) -> i64 {
    i64::try_from(d.as_nanos()).unwrap_or(i64::MAX)
}

impl LiveLimits {
    pub fn history_ns(&self) -> i64 {
        nanos(self.history)
    }

    pub fn live_deadline_ns(&self) -> i64 {
        nanos(self.live_deadline)
    }

    pub fn history_deadline_ns(&self) -> i64 {
        nanos(self.history_deadline)
    }
}

// Device codes are part of the protocol (the WebXR page checks what a person typed).
pub use egoexo_protocol::live::{CODE_ALPHABET, CODE_LENGTH, display_code, normalize_code};

#[derive(Debug, Default)]
struct Rooms {
    by_id: HashMap<RoomId, Arc<Room>>,
    by_code: HashMap<String, RoomId>,
}

/// The relay's state.
#[derive(Debug)]
pub struct LiveState {
    pub limits: Arc<LiveLimits>,
    pub clock: RelayClock,
    rooms: Mutex<Rooms>,
    room_rate: DefaultKeyedRateLimiter<IpAddr>,
    join_rate: DefaultKeyedRateLimiter<IpAddr>,
    trust_forwarded_for: bool,
}

impl LiveState {
    pub fn new(limits: LiveLimits, trust_forwarded_for: bool) -> Self {
        let per_minute = |n: u32| Quota::per_minute(NonZeroU32::new(n.max(1)).unwrap_or(NonZeroU32::MIN));
        Self {
            room_rate: RateLimiter::keyed(per_minute(limits.rooms_per_minute)),
            join_rate: RateLimiter::keyed(per_minute(limits.join_attempts_per_minute)),
            limits: Arc::new(limits),
            clock: RelayClock::new(),
            rooms: Mutex::new(Rooms::default()),
            trust_forwarded_for,
        }
    }

    fn rooms(&self) -> std::sync::MutexGuard<'_, Rooms> {
        self.rooms.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Creates a room.
    pub fn create_room(&self) -> Result<(Arc<Room>, RoomCreated), Failure> {
        let mut rooms = self.rooms();
        if rooms.by_id.len() >= self.limits.max_rooms {
            return Err(Failure(
                ApiErrorKind::RateLimited,
                format!("this server holds {} live rooms, its limit; try again later", self.limits.max_rooms),
            ));
        }
        let (id, device_secret, viewer_secret) = (random_token()?, random_token()?, random_token()?);
        let code = loop {
            let code = random_code()?;
            if !rooms.by_code.contains_key(&code) {
                break code;
            }
        };
        let now_ns = self.clock.now_ns();
        let expires_unix_s = u64::try_from(now_ns / 1_000_000_000).unwrap_or(0) + self.limits.room_ttl.as_secs();
        let expires_at = rfc3339(expires_unix_s);
        let room = Arc::new(Room::new(
            id.clone(),
            device_secret.clone(),
            viewer_secret.clone(),
            code.clone(),
            now_ns,
            expires_at.clone(),
            self.limits.clone(),
        ));
        rooms.by_code.insert(code.clone(), id.clone());
        rooms.by_id.insert(id.clone(), room.clone());
        let created =
            RoomCreated { room: id, device_secret, viewer_secret, device_code: display_code(&code), expires_at };
        Ok((room, created))
    }

    /// The room a secret opens, and what it admits to; failures count against `ip`'s join
    /// attempts.
    pub fn join_by_secret(&self, room: &str, secret: &str, ip: IpAddr) -> Result<(Arc<Room>, room::Admission), Close> {
        let found = self.rooms().by_id.get(room).cloned();
        let admitted = found.as_ref().and_then(|r| Some((r.clone(), r.admission(secret)?)));
        match admitted {
            Some(joined) => Ok(joined),
            None => {
                self.count_failed_join(ip)?;
                Err(Close::new(
                    CloseKind::NotAdmitted,
                    if found.is_some() { "wrong secret for this room" } else { "no such room (it may have expired)" },
                ))
            }
        }
    }

    /// The room a device code opens (codes admit devices). Every attempt counts against
    /// `ip`'s join attempts: codes are short.
    pub fn join_by_code(&self, code: &str, ip: IpAddr) -> Result<Arc<Room>, Close> {
        self.count_failed_join(ip)?;
        let room = normalize_code(code).and_then(|code| {
            let rooms = self.rooms();
            rooms.by_id.get(rooms.by_code.get(&code)?).cloned()
        });
        room.ok_or_else(|| {
            Close::new(CloseKind::NotAdmitted, "no room has this code (6 characters like 7KQ-M4T; rooms expire)")
        })
    }

    fn count_failed_join(&self, ip: IpAddr) -> Result<(), Close> {
        self.join_rate.check_key(&ip).map_err(|_| {
            Close::new(
                CloseKind::RateLimited,
                format!("more than {} join attempts a minute from this address", self.limits.join_attempts_per_minute),
            )
        })
    }

    /// Rooms open now.
    pub fn room_count(&self) -> usize {
        self.rooms().by_id.len()
    }

    /// Frames queued for viewers in all rooms: the memory slow viewers cost, bounded by
    /// viewers × channels × [`LiveLimits::history_frames`].
    pub fn queued_frames(&self) -> usize {
        let rooms: Vec<Arc<Room>> = self.rooms().by_id.values().cloned().collect();
        rooms.iter().map(|r| r.queued_frames()).sum()
    }

    /// One tick: rooms that are over are closed and forgotten; the others send their status.
    pub fn tick(&self) {
        let now_ns = self.clock.now_ns();
        let rooms: Vec<Arc<Room>> = self.rooms().by_id.values().cloned().collect();
        let mut over = Vec::new();
        for room in rooms {
            if room.is_over(now_ns) {
                room.close(Close::new(CloseKind::RoomClosed, "the room expired"));
                over.push(room);
            } else if room.has_viewers() {
                room.send_status(now_ns);
            }
        }
        if !over.is_empty() {
            let mut rooms = self.rooms();
            for room in over {
                rooms.by_id.remove(&room.id);
                rooms.by_code.remove(&room.code);
            }
        }
    }

    /// Ticks every [`LiveLimits::status_interval`]; also forgets idle rate-limit entries.
    pub async fn run(self: Arc<Self>) {
        let mut ticks = tokio::time::interval(self.limits.status_interval);
        ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut n: u64 = 0;
        loop {
            ticks.tick().await;
            self.tick();
            n += 1;
            if n.is_multiple_of(60) {
                self.room_rate.retain_recent();
                self.join_rate.retain_recent();
            }
        }
    }

    /// Closes every room (the server is stopping).
    pub fn close_all(&self) {
        for room in self.rooms().by_id.values() {
            room.close(Close::new(CloseKind::GoingAway, "the server is restarting; reconnect shortly"));
        }
    }
}

fn random_bytes<const N: usize>() -> Result<[u8; N], Failure> {
    let mut bytes = [0; N];
    getrandom::fill(&mut bytes).map_err(|e| Failure(ApiErrorKind::Storage, format!("no random numbers: {e}")))?;
    Ok(bytes)
}

fn random_token() -> Result<String, Failure> {
    Ok(base64url(&random_bytes::<16>()?))
}

/// Six characters of [`CODE_ALPHABET`], uniformly (bytes ≥ 248 are redrawn).
fn random_code() -> Result<String, Failure> {
    let limit = (256 / CODE_ALPHABET.len() * CODE_ALPHABET.len()) as u8;
    let mut code = String::with_capacity(CODE_LENGTH);
    while code.len() < CODE_LENGTH {
        for b in random_bytes::<16>()? {
            if b < limit && code.len() < CODE_LENGTH {
                code.push(char::from(CODE_ALPHABET[usize::from(b) % CODE_ALPHABET.len()]));
            }
        }
    }
    Ok(code)
}

/// `POST /api/live/rooms`: a new room (201 with [`RoomCreated`]).
pub async fn create_room(
    State(state): State<Arc<LiveState>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
) -> Result<Response, Failure> {
    let ip = client_ip(state.trust_forwarded_for, peer, &headers);
    if state.room_rate.check_key(&ip).is_err() {
        return Err(Failure(
            ApiErrorKind::RateLimited,
            format!("more than {} live rooms a minute from {ip}; try again in a minute", state.limits.rooms_per_minute),
        ));
    }
    let (_, created) = state.create_room()?;
    Ok((StatusCode::CREATED, [(header::CACHE_CONTROL, "no-store")], Json(created)).into_response())
}

/// `GET /live`: the WebSocket, with the subprotocol [`LIVE_SUBPROTOCOL`].
pub async fn live_socket(
    State(state): State<Arc<LiveState>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
    upgrade: WebSocketUpgrade,
) -> Response {
    let upgrade = upgrade.protocols([LIVE_SUBPROTOCOL]);
    if upgrade.selected_protocol().is_none() {
        return Failure(
            ApiErrorKind::BadRequest,
            format!("offer the WebSocket subprotocol `{LIVE_SUBPROTOCOL}` (docs/live-protocol.md)"),
        )
        .into_response();
    }
    let ip = client_ip(state.trust_forwarded_for, peer, &headers);
    // Messages a little over the protocol's limit reach the handler, which closes the client
    // with a reason; far larger ones end the connection in the WebSocket layer.
    upgrade
        .max_message_size(MAX_MESSAGE_BYTES * 4)
        .max_frame_size(MAX_MESSAGE_BYTES * 4)
        .max_write_buffer_size(4 << 20)
        .on_upgrade(move |socket| connection::serve(state, socket, ip))
}
