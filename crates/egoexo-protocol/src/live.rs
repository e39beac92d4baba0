//! The live protocol between devices, the relay and viewers: WebSocket subprotocol
//! [`LIVE_SUBPROTOCOL`] (`docs/live-protocol.md` is the reader's version, for people who write
//! device bridges).
//!
//! - **Control** travels as JSON text frames: [`ClientMessage`] (hello and join, an observer's
//!   camera calibration, answers to clock pings) and [`RelayMessage`] (welcome, clock pings,
//!   the room's channels, calibrations, status).
//! - **Data** travels as compact binary frames ([`DataFrame`]), Foxglove-style:
//!   `op | flags | channel | timestamp ns | payload`, little-endian. A device numbers its
//!   channels by [`Stream`] and stamps frames with its own clock; the relay maps every device
//!   stream to a room-wide channel, moves the timestamp onto the relay clock (the device's
//!   offset measured by ping/pong) and forwards the frame to viewers.
//!
//! Poses are `T_world_device` in session conventions: a Y-up world in metres, head devices in
//! the CPF frame (+X left, +Y up, +Z forward). Keypoints are COCO-17 pixels in the observer's
//! RGB image with detector scores.

use egoexo_core::camera::CameraCalibration;
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::{Quat, Vec2, Vec3};
use egoexo_core::region::BoundingBox;
use egoexo_core::rigid::RigidTransform;
use serde::{Deserialize, Serialize};

/// The WebSocket subprotocol a client must offer.
pub const LIVE_SUBPROTOCOL: &str = "egoexo-live.1";
/// The protocol's version (in `hello` and `welcome`).
pub const LIVE_PROTOCOL_VERSION: u32 = 1;
/// How much of every channel a viewer joining late receives at once: 96 frames at 30 fps, so
/// it can reconstruct a whole window straight away.
pub const HISTORY_S: f64 = 3.2;
/// Largest message a client may send, bytes.
pub const MAX_MESSAGE_BYTES: usize = 64 << 10;
/// Longest `message` of an [`ClientMessage::ObserverWorld`], characters.
pub const MAX_WORLD_MESSAGE_CHARS: usize = 400;
/// Largest pixel coordinate, either sign, of a [`ClientMessage::WearerRegion`].
pub const MAX_REGION_COORD_PX: f32 = 65_536.0;

/// A room's id: 22 characters of base64url (128 random bits).
pub type RoomId = String;

/// What a device publishes on a stream (its device-local channel number).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stream {
    /// The device's head pose (a wearer's glasses or headset, or an observer's glasses).
    Head,
    /// The wearer's left wrist (a controller grip, a hand-tracked wrist, a wristband).
    LeftWrist,
    /// The wearer's right wrist.
    RightWrist,
    /// An observer's COCO-17 keypoints of the wearer.
    Keypoints,
}

impl Stream {
    pub const ALL: [Stream; 4] = [Stream::Head, Stream::LeftWrist, Stream::RightWrist, Stream::Keypoints];

    /// The device-local channel number.
    pub fn channel(self) -> u16 {
        match self {
            Stream::Head => 0,
            Stream::LeftWrist => 1,
            Stream::RightWrist => 2,
            Stream::Keypoints => 3,
        }
    }

    pub fn from_channel(channel: u16) -> Option<Stream> {
        Stream::ALL.into_iter().find(|s| s.channel() == channel)
    }

    /// Its name on the wire (`head`, `left-wrist`, `right-wrist`, `keypoints`).
    pub fn name(self) -> &'static str {
        match self {
            Stream::Head => "head",
            Stream::LeftWrist => "left-wrist",
            Stream::RightWrist => "right-wrist",
            Stream::Keypoints => "keypoints",
        }
    }

    /// The frame kind the stream carries.
    pub fn op(self) -> FrameOp {
        match self {
            Stream::Keypoints => FrameOp::Keypoints,
            _ => FrameOp::Pose,
        }
    }
}

/// A device's part in the capture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DeviceRole {
    /// The person reconstructed: head, and maybe wrists.
    Wearer,
    /// A person whose camera sees the wearer: head and keypoints.
    Observer,
}

impl DeviceRole {
    /// Its name on the wire (`wearer`, `observer`).
    pub fn name(self) -> &'static str {
        match self {
            DeviceRole::Wearer => "wearer",
            DeviceRole::Observer => "observer",
        }
    }

    /// The streams this role may publish.
    pub fn allows(self, stream: Stream) -> bool {
        match self {
            DeviceRole::Wearer => stream != Stream::Keypoints,
            DeviceRole::Observer => matches!(stream, Stream::Head | Stream::Keypoints),
        }
    }
}

/// Whose world a device's poses are in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DeviceWorld {
    /// The room's one world, shared with every other device that says `shared` (the default:
    /// devices calibrated together, e.g. Aria glasses through Multi-SLAM).
    #[default]
    Shared,
    /// A world of its own (a headset's XR reference space, glasses localised alone): Y-up and
    /// gravity-aligned, in metres, but a yaw and a translation away from everyone else's.
    /// Viewers register such an observer to the wearer from its views before they fuse it
    /// (`docs/registration.md`).
    Own,
}

impl DeviceWorld {
    /// `shared` (the default, left out of the JSON).
    pub fn is_shared(&self) -> bool {
        *self == DeviceWorld::Shared
    }

    /// Its name on the wire (`shared`, `own`).
    pub fn name(self) -> &'static str {
        match self {
            DeviceWorld::Shared => "shared",
            DeviceWorld::Own => "own",
        }
    }
}

/// How a device is carried.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DeviceMount {
    /// On a person (glasses, a headset, a phone in the hand): it streams its head pose.
    #[default]
    Worn,
    /// A static camera that knows nothing of its pose (a phone on a stand, a laptop's webcam):
    /// it publishes keypoints only, no head; viewers place it by registration in 6 DoF (it
    /// knows no gravity either), at one fixed pose in a world of its own (its device frame).
    Fixed,
}

impl DeviceMount {
    /// `worn` (the default, left out of the JSON).
    pub fn is_worn(&self) -> bool {
        *self == DeviceMount::Worn
    }

    /// Its name on the wire (`worn`, `fixed`).
    pub fn name(self) -> &'static str {
        match self {
            DeviceMount::Worn => "worn",
            DeviceMount::Fixed => "fixed",
        }
    }
}

fn is_true(b: &bool) -> bool {
    *b
}

fn yes() -> bool {
    true
}

/// How a client proves it may be in a room.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Join {
    /// The room and its device or viewer secret (from a link).
    Secret { room: RoomId, secret: String },
    /// The short device code a person types on a headset.
    Code { code: String },
}

/// Why what a person typed or pasted is not a way into a room.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum JoinParseError {
    #[error("Type the device code shown where the room was made (like 7KQ-M4T), or open the device link.")]
    Empty,
    #[error(
        "“{0}” is not a device code: a code is six characters, digits 2–9 and letters A–Z without I, L or O (like 7KQ-M4T)."
    )]
    BadCode(String),
    #[error(
        "This link's #live=… part is damaged: it should be #live=<room>.<secret>. Copy the whole device link again."
    )]
    BadLink,
}

impl Join {
    /// A join from what a person typed or pasted: a device code (`7kq m4t` is fine), a link
    /// with `#live=<room>.<secret>`, or a bare `<room>.<secret>`.
    pub fn parse(text: &str) -> Result<Join, JoinParseError> {
        let text = text.trim();
        if text.is_empty() {
            return Err(JoinParseError::Empty);
        }
        if let Some(code) = normalize_code(text) {
            return Ok(Join::Code { code: display_code(&code) });
        }
        // A link, or a room and secret pasted bare (both 22 characters; a code is never that long).
        let bare_link = text.split_once('.').is_some_and(|(room, secret)| room.len() >= 16 && secret.len() >= 16);
        if text.contains('#') || text.contains("live=") || bare_link {
            let link = LiveLink::parse(text).ok_or(JoinParseError::BadLink)?;
            return Ok(Join::Secret { room: link.room, secret: link.secret });
        }
        Err(JoinParseError::BadCode(text.chars().take(24).collect()))
    }
}

/// A device introducing itself.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceHello {
    /// Unique in the room: `wearer`, `observer-1`, … (1–64 of `A–Z a–z 0–9 . _ -`).
    pub id: String,
    pub role: DeviceRole,
    /// What it will publish.
    pub streams: Vec<Stream>,
    /// An observer in a room of several wearers: the wearer (their device id) whose keypoints
    /// it publishes. Absent: the room's only wearer. Only observers name one. (Added within
    /// version 1: a relay that predates it ignores it.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// Whether its poses are in the room's shared world or one of its own. (Added within
    /// version 1: absent means `shared`.)
    #[serde(default, skip_serializing_if = "DeviceWorld::is_shared")]
    pub world: DeviceWorld,
    /// Worn, or a static camera without a pose (publishes no `head`). (Added within version 1:
    /// absent means `worn`.)
    #[serde(default, skip_serializing_if = "DeviceMount::is_worn")]
    pub mount: DeviceMount,
    /// Whether its calibration's focal length is measured (`true`, the default) or a guess (a
    /// browser camera that reports no field of view): registration then estimates it. (Added
    /// within version 1.)
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub focal_known: bool,
}

impl DeviceHello {
    /// A device worn in the room's shared world with a known focal length (the defaults of
    /// every field added within version 1), no target.
    pub fn worn(id: impl Into<String>, role: DeviceRole, streams: Vec<Stream>) -> Self {
        Self {
            id: id.into(),
            role,
            streams,
            target: None,
            world: DeviceWorld::Shared,
            mount: DeviceMount::Worn,
            focal_known: true,
        }
    }

    /// Why the relay refuses this hello's streams, if it does: a role publishing what it may
    /// not, or a static camera publishing a head pose it does not have.
    pub fn refused_stream(&self) -> Option<String> {
        if let Some(stream) = self.streams.iter().find(|s| !self.role.allows(**s)) {
            return Some(format!("a {} may not publish {}", self.role.name(), stream.name()));
        }
        if self.mount == DeviceMount::Fixed && self.streams.contains(&Stream::Head) {
            return Some(
                "a fixed camera (\"mount\": \"fixed\") publishes no head poses; a worn device leaves `mount` out"
                    .into(),
            );
        }
        None
    }
}

/// Client → relay (JSON text frames).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub enum ClientMessage {
    /// The first message: protocol version, the room to join, and for a device, what it is.
    /// Without `device` the client is a viewer.
    Hello { protocol: u32, join: Join, device: Option<DeviceHello> },
    /// An observer's RGB camera (intrinsics, image size, `T_device_camera` in CPF).
    Calibration { camera: CameraCalibration },
    /// The answer to a relay [`RelayMessage::Ping`]: the relay's time echoed, and the device's
    /// clock when it answered.
    Pong { relay_ns: i64, device_ns: i64 },
    /// A viewer's word on an observer in a world of its own: where the viewer's registration
    /// of it stands (`docs/registration.md`, "Live"). The relay passes it to that device as a
    /// [`RelayMessage::ObserverWorld`], so a camera page can say whether its view is used.
    /// Viewers only; `message` at most [`MAX_WORLD_MESSAGE_CHARS`] characters. (Added within
    /// version 1: devices ignore relay messages they do not know.)
    ObserverWorld { device: String, state: WorldState, message: String },
    /// A viewer's proposal of where observer `device`'s wearer is in its image at `at_ns` (relay
    /// clock): the viewer's newest reconstruction of the wearer projected with the observer's
    /// camera at its pose in the wearer's world, registered or shared (paper § Ego-Guided
    /// Wearer Localization). The relay passes it to that device as a
    /// [`RelayMessage::WearerRegion`], so a camera page crops there. Viewers only; `region` in
    /// full-image pixels ([`region_problem`] says what is refused). (Added within version 1.)
    WearerRegion { device: String, region: BoundingBox, at_ns: i64 },
}

/// Why `region` cannot be a [`ClientMessage::WearerRegion`]'s: a coordinate not finite or
/// beyond ±[`MAX_REGION_COORD_PX`], or `min` past `max`.
pub fn region_problem(region: &BoundingBox) -> Option<&'static str> {
    let corners = [region.min, region.max];
    if !corners.iter().all(|c| c.is_finite() && c.abs().max_element() <= MAX_REGION_COORD_PX) {
        return Some("a wearer region's corners must be finite pixels within ±65536");
    }
    (region.min.x > region.max.x || region.min.y > region.max.y).then_some("a wearer region's min is past its max")
}

/// Where a viewer's registration of an observer's world stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WorldState {
    /// Not yet registered (or its world jumped): not fused.
    Registering,
    /// Registered: its rays are fused.
    Registered,
}

/// One channel of the room, as viewers see it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChannelInfo {
    /// The room-wide channel number in frames sent to viewers.
    pub channel: u16,
    pub device: String,
    pub role: DeviceRole,
    pub stream: Stream,
    /// The observer's target wearer ([`DeviceHello::target`]), when it names one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// The device's world ([`DeviceHello::world`]).
    #[serde(default, skip_serializing_if = "DeviceWorld::is_shared")]
    pub world: DeviceWorld,
    /// The device's mount ([`DeviceHello::mount`]).
    #[serde(default, skip_serializing_if = "DeviceMount::is_worn")]
    pub mount: DeviceMount,
    /// Whether the device's focal length is measured ([`DeviceHello::focal_known`]).
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub focal_known: bool,
}

impl ChannelInfo {
    /// Channel `channel`: stream `stream` of the device that said `hello`.
    pub fn of(channel: u16, hello: &DeviceHello, stream: Stream) -> Self {
        Self {
            channel,
            device: hello.id.clone(),
            role: hello.role,
            stream,
            target: hello.target.clone(),
            world: hello.world,
            mount: hello.mount,
            focal_known: hello.focal_known,
        }
    }
}

/// A device, as the relay sees it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeviceStatus {
    pub device: String,
    pub role: DeviceRole,
    pub connected: bool,
    /// Frames per second received over the last status interval, per stream.
    pub rates_hz: Vec<(Stream, f64)>,
    /// Relay clock minus device clock, nanoseconds (from the ping/pong with the smallest
    /// round trip among the recent ones); `None` until the device has answered a ping.
    pub clock_offset_ns: Option<i64>,
    /// Half that round trip: the offset's uncertainty, nanoseconds.
    pub clock_uncertainty_ns: Option<i64>,
    /// Times the device's clock jumped (its offset changed by more than the uncertainty).
    pub clock_jumps: u32,
    /// Median of (arrival at the relay − device timestamp on the relay clock) over the last
    /// status interval: the network's one-way latency, nanoseconds.
    pub latency_ns: Option<i64>,
    /// Frames received in all.
    pub frames: u64,
}

/// Relay → client (JSON text frames).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub enum RelayMessage {
    /// The hello was accepted.
    Welcome { protocol: u32, room: RoomId, client: u32, relay_ns: i64, expires_at: String },
    /// Answer with `pong`: the relay measures the client's clock offset.
    Ping { relay_ns: i64 },
    /// The room's channels (sent to viewers whenever they change).
    Channels { channels: Vec<ChannelInfo> },
    /// A device's camera (sent to viewers).
    Calibration { device: String, camera: CameraCalibration },
    /// The room, once a second (to viewers): its devices, how many viewers, the frames this
    /// viewer missed because it read too slowly, and this viewer's own clock offset.
    Status {
        devices: Vec<DeviceStatus>,
        viewers: usize,
        dropped: u64,
        relay_ns: i64,
        /// Relay clock minus this viewer's clock, nanoseconds (`None` before its first pong).
        clock_offset_ns: Option<i64>,
        clock_uncertainty_ns: Option<i64>,
    },
    /// To an observer: where a viewer's registration of its world stands
    /// ([`ClientMessage::ObserverWorld`]), from viewer `viewer` (a room's viewers each register
    /// on their own; the newest word is the one to show).
    ObserverWorld { viewer: u32, state: WorldState, message: String },
    /// To an observer: viewer `viewer`'s proposal of where its wearer is in its image
    /// ([`ClientMessage::WearerRegion`]), for the moment `at_ns` on **the device's** clock (the
    /// relay maps it with the device's clock offset; a proposal before the device's first pong
    /// is dropped).
    WearerRegion { viewer: u32, region: BoundingBox, at_ns: i64 },
}

/// Why the relay closed a connection: the WebSocket close code, with a sentence as the reason.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CloseKind {
    /// 1001: the server is shutting down.
    GoingAway,
    /// 1007: a message that is not what the protocol says (bad JSON, a malformed frame).
    Malformed,
    /// 1008: a message the client's role may not send (a viewer publishing, a stream not
    /// announced, keypoints from a wearer).
    NotAllowed,
    /// 1009: a message over [`MAX_MESSAGE_BYTES`].
    TooBig,
    /// 4000: a hello for another protocol version, or no hello first.
    BadHello,
    /// 4001: no such room, a wrong secret or code.
    NotAdmitted,
    /// 4002: the room expired or was closed.
    RoomClosed,
    /// 4003: the same device id connected again; the newer connection wins.
    Replaced,
    /// 4004: the room holds as many devices, viewers or channels as it may.
    RoomFull,
    /// 4005: too many messages or join attempts.
    RateLimited,
    /// 4006: no hello, no pong or no reading for too long.
    TimedOut,
}

impl CloseKind {
    pub const ALL: [CloseKind; 11] = [
        CloseKind::GoingAway,
        CloseKind::Malformed,
        CloseKind::NotAllowed,
        CloseKind::TooBig,
        CloseKind::BadHello,
        CloseKind::NotAdmitted,
        CloseKind::RoomClosed,
        CloseKind::Replaced,
        CloseKind::RoomFull,
        CloseKind::RateLimited,
        CloseKind::TimedOut,
    ];

    /// The WebSocket close code.
    pub fn code(self) -> u16 {
        match self {
            CloseKind::GoingAway => 1001,
            CloseKind::Malformed => 1007,
            CloseKind::NotAllowed => 1008,
            CloseKind::TooBig => 1009,
            CloseKind::BadHello => 4000,
            CloseKind::NotAdmitted => 4001,
            CloseKind::RoomClosed => 4002,
            CloseKind::Replaced => 4003,
            CloseKind::RoomFull => 4004,
            CloseKind::RateLimited => 4005,
            CloseKind::TimedOut => 4006,
        }
    }

    pub fn from_code(code: u16) -> Option<CloseKind> {
        CloseKind::ALL.into_iter().find(|k| k.code() == code)
    }

    /// Whether a client should reconnect after it (devices do after network trouble and
    /// shutdowns, never after being refused).
    pub fn may_retry(self) -> bool {
        matches!(self, CloseKind::GoingAway | CloseKind::TimedOut)
    }
}

/// A close: its kind and a sentence for people (at most 123 bytes, WebSocket's limit).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Close {
    pub kind: CloseKind,
    pub reason: String,
}

impl Close {
    /// A close with `reason` cut to 123 bytes on a character boundary.
    pub fn new(kind: CloseKind, reason: impl Into<String>) -> Close {
        let mut reason = reason.into();
        if reason.len() > 123 {
            let mut end = 120;
            while !reason.is_char_boundary(end) {
                end -= 1;
            }
            reason.truncate(end);
            reason.push('…');
        }
        Close { kind, reason }
    }
}

/// Kinds of binary frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameOp {
    /// A pose: valid flag, translation, rotation.
    Pose,
    /// COCO-17 keypoints: pixel and score each.
    Keypoints,
}

impl FrameOp {
    fn byte(self) -> u8 {
        match self {
            FrameOp::Pose => 1,
            FrameOp::Keypoints => 2,
        }
    }
}

/// A frame's content.
// A frame lives for one decode or encode; boxing the keypoints would cost an allocation each.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FramePayload {
    /// `T_world_device`, or `None` when the device lost tracking (sent as invalid).
    Pose(Option<RigidTransform>),
    /// COCO-17 keypoints; `None` for one not detected (score 0).
    Keypoints([Option<Keypoint2d>; COCO17_COUNT]),
}

impl FramePayload {
    pub fn op(&self) -> FrameOp {
        match self {
            FramePayload::Pose(_) => FrameOp::Pose,
            FramePayload::Keypoints(_) => FrameOp::Keypoints,
        }
    }
}

/// A binary data frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DataFrame {
    /// Device → relay: the device-local channel ([`Stream::channel`]); relay → viewer: the
    /// room-wide channel ([`ChannelInfo::channel`]).
    pub channel: u16,
    /// Device → relay: the device's clock; relay → viewer: the relay's clock. Nanoseconds.
    pub timestamp_ns: i64,
    pub payload: FramePayload,
}

/// Bytes of the header: op, flags, channel, timestamp.
pub const HEADER_BYTES: usize = 12;
/// Bytes of a pose payload: valid, 3 × f32 translation, 4 × f32 quaternion (x, y, z, w).
pub const POSE_BYTES: usize = 1 + 7 * 4;
/// Bytes of a keypoints payload: count (17), then 17 × (x, y, score) f32.
pub const KEYPOINTS_BYTES: usize = 1 + COCO17_COUNT * 12;

/// Why a binary frame was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FrameError {
    #[error("a frame has a {HEADER_BYTES}-byte header; got {0} bytes")]
    Short(usize),
    #[error("flags must be 0, got {0}")]
    Flags(u8),
    #[error("unknown frame op {0} (1: pose, 2: keypoints)")]
    UnknownOp(u8),
    #[error("a {op} frame has {expected} payload bytes; got {got}")]
    PayloadLength { op: &'static str, expected: usize, got: usize },
    #[error("a keypoints frame starts with its count, 17; got {0}")]
    KeypointCount(u8),
    #[error("a {0} frame holds a number that is not finite")]
    NotFinite(&'static str),
    #[error("the pose's valid flag must be 0 or 1, got {0}")]
    ValidFlag(u8),
    #[error("the pose's quaternion has length {0}, not 1")]
    NotUnitQuaternion(f32),
    #[error("keypoint {index}'s score must be in [0, 1], got {score}")]
    Score { index: usize, score: f32 },
}

impl DataFrame {
    /// The frame's bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER_BYTES + KEYPOINTS_BYTES);
        out.push(self.payload.op().byte());
        out.push(0);
        out.extend_from_slice(&self.channel.to_le_bytes());
        out.extend_from_slice(&self.timestamp_ns.to_le_bytes());
        match &self.payload {
            FramePayload::Pose(pose) => {
                let p = pose.unwrap_or(RigidTransform::IDENTITY);
                out.push(u8::from(pose.is_some()));
                for v in p.translation.to_array().into_iter().chain(p.rotation.to_array()) {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
            FramePayload::Keypoints(keypoints) => {
                out.push(COCO17_COUNT as u8);
                for k in keypoints {
                    let (x, y, score) = k.map_or((0.0, 0.0, 0.0), |k| (k.pixel.x, k.pixel.y, k.score));
                    for v in [x, y, score] {
                        out.extend_from_slice(&v.to_le_bytes());
                    }
                }
            }
        }
        out
    }

    /// Reads a frame, refusing anything but exactly the layout (lengths, finite numbers, a
    /// unit quaternion within 1e-3, scores in [0, 1]).
    pub fn decode(bytes: &[u8]) -> Result<DataFrame, FrameError> {
        let Some((header, body)) = bytes.split_first_chunk::<HEADER_BYTES>() else {
            return Err(FrameError::Short(bytes.len()));
        };
        let channel = u16::from_le_bytes([header[2], header[3]]);
        let mut ts = [0u8; 8];
        ts.copy_from_slice(&header[4..12]);
        let timestamp_ns = i64::from_le_bytes(ts);
        if header[1] != 0 {
            return Err(FrameError::Flags(header[1]));
        }
        let floats = |b: &[u8]| -> Vec<f32> {
            b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
        };
        let payload = match header[0] {
            1 => {
                if body.len() != POSE_BYTES {
                    return Err(FrameError::PayloadLength { op: "pose", expected: POSE_BYTES, got: body.len() });
                }
                let v = floats(&body[1..]);
                if v.iter().any(|x| !x.is_finite()) {
                    return Err(FrameError::NotFinite("pose"));
                }
                let valid = match body[0] {
                    0 => false,
                    1 => true,
                    other => return Err(FrameError::ValidFlag(other)),
                };
                let rotation = Quat::from_xyzw(v[3], v[4], v[5], v[6]);
                if valid && (rotation.length() - 1.0).abs() > 1e-3 {
                    return Err(FrameError::NotUnitQuaternion(rotation.length()));
                }
                FramePayload::Pose(valid.then(|| RigidTransform {
                    rotation: rotation.normalize(),
                    translation: Vec3::new(v[0], v[1], v[2]),
                }))
            }
            2 => {
                if body.len() != KEYPOINTS_BYTES {
                    return Err(FrameError::PayloadLength {
                        op: "keypoints",
                        expected: KEYPOINTS_BYTES,
                        got: body.len(),
                    });
                }
                if usize::from(body[0]) != COCO17_COUNT {
                    return Err(FrameError::KeypointCount(body[0]));
                }
                let v = floats(&body[1..]);
                if v.iter().any(|x| !x.is_finite()) {
                    return Err(FrameError::NotFinite("keypoints"));
                }
                let mut keypoints = [None; COCO17_COUNT];
                for (k, slot) in keypoints.iter_mut().enumerate() {
                    let (x, y, score) = (v[3 * k], v[3 * k + 1], v[3 * k + 2]);
                    if !(0.0..=1.0).contains(&score) {
                        return Err(FrameError::Score { index: k, score });
                    }
                    *slot = (score > 0.0).then(|| Keypoint2d { pixel: Vec2::new(x, y), score });
                }
                FramePayload::Keypoints(keypoints)
            }
            other => return Err(FrameError::UnknownOp(other)),
        };
        Ok(DataFrame { channel, timestamp_ns, payload })
    }
}

/// Checks a device id: 1–64 characters of `A–Z a–z 0–9 . _ -`.
pub fn valid_device_id(id: &str) -> bool {
    (1..=64).contains(&id.len()) && id.bytes().all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'))
}

/// The characters of device codes: no 0/O, 1/I/L to misread.
pub const CODE_ALPHABET: &[u8] = b"23456789ABCDEFGHJKMNPQRSTUVWXYZ";
/// Characters in a device code (31⁶ ≈ 8.9 × 10⁸ codes).
pub const CODE_LENGTH: usize = 6;

/// A typed code in canonical form (upper case, no dash or spaces), if it could be one.
pub fn normalize_code(code: &str) -> Option<String> {
    let code: String =
        code.chars().filter(|c| !matches!(c, '-' | ' ' | '\u{2010}'..='\u{2015}')).collect::<String>().to_uppercase();
    (code.len() == CODE_LENGTH && code.bytes().all(|b| CODE_ALPHABET.contains(&b))).then_some(code)
}

/// A code as shown: `7KQ-M4T`.
pub fn display_code(code: &str) -> String {
    let half = code.len() / 2;
    format!("{}-{}", &code[..half], &code[half..])
}

/// What `POST /api/live/rooms` answers.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RoomCreated {
    pub room: RoomId,
    /// Lets devices publish (device links carry it).
    pub device_secret: String,
    /// Lets viewers watch, never publish (watch links carry it).
    pub viewer_secret: String,
    /// The device secret as a code a person can type on a headset (`7KQ-M4T`).
    pub device_code: String,
    /// When the room closes, RFC 3339 UTC.
    pub expires_at: String,
}

/// A room and one of its secrets, as page links carry them: `#live=<room>.<secret>` in the
/// address's fragment (never sent to the server). With the viewer secret it is a watch link
/// (`https://host/#live=…`); with the device secret a device link (`https://host/xr.html#live=…`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LiveLink {
    pub room: RoomId,
    pub secret: String,
}

impl LiveLink {
    /// `live=<room>.<secret>`.
    pub fn fragment(&self) -> String {
        format!("live={}.{}", self.room, self.secret)
    }

    /// Finds `live=<room>.<secret>` in a fragment (`#` optional; other `&`-separated
    /// parameters are ignored). Room and secret are base64url, 1–64 characters each.
    pub fn parse_fragment(fragment: &str) -> Option<LiveLink> {
        let fragment = fragment.strip_prefix('#').unwrap_or(fragment);
        Self::parse_value(fragment.split('&').find_map(|part| part.strip_prefix("live="))?)
    }

    /// The value of a `live=` parameter: `<room>.<secret>`.
    pub fn parse_value(value: &str) -> Option<LiveLink> {
        let (room, secret) = value.split_once('.')?;
        let ok = |s: &str| {
            (1..=64).contains(&s.len()) && s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
        };
        (ok(room) && ok(secret)).then(|| LiveLink { room: room.to_string(), secret: secret.to_string() })
    }

    /// The link in a full address (`https://host/#live=…`), or a bare `<room>.<secret>`.
    pub fn parse(text: &str) -> Option<LiveLink> {
        match text.split_once('#') {
            Some((_, fragment)) => Self::parse_fragment(fragment),
            None => Self::parse_value(text),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keypoints() -> [Option<Keypoint2d>; COCO17_COUNT] {
        std::array::from_fn(|k| {
            (k % 5 != 0).then(|| Keypoint2d { pixel: Vec2::new(10.0 * k as f32, 700.5), score: 0.8 })
        })
    }

    #[test]
    fn frames_round_trip_in_their_documented_sizes() {
        let pose = DataFrame {
            channel: 2,
            timestamp_ns: -1_234_567_890_123,
            payload: FramePayload::Pose(Some(RigidTransform {
                rotation: Quat::from_rotation_y(0.3),
                translation: Vec3::new(0.1, 1.6, -2.0),
            })),
        };
        let bytes = pose.encode();
        assert_eq!(bytes.len(), HEADER_BYTES + POSE_BYTES);
        assert_eq!(&bytes[..4], &[1, 0, 2, 0]);
        assert_eq!(DataFrame::decode(&bytes).unwrap(), pose);
        let lost = DataFrame { channel: 0, timestamp_ns: 5, payload: FramePayload::Pose(None) };
        assert_eq!(DataFrame::decode(&lost.encode()).unwrap(), lost);
        let seen = DataFrame { channel: 3, timestamp_ns: 9, payload: FramePayload::Keypoints(keypoints()) };
        let bytes = seen.encode();
        assert_eq!(bytes.len(), HEADER_BYTES + KEYPOINTS_BYTES);
        assert_eq!(DataFrame::decode(&bytes).unwrap(), seen);
    }

    #[test]
    fn malformed_frames_say_what_is_wrong() {
        let good =
            DataFrame { channel: 0, timestamp_ns: 1, payload: FramePayload::Pose(Some(RigidTransform::IDENTITY)) };
        let bytes = good.encode();
        let mut cases: Vec<(Vec<u8>, &str)> = vec![
            (bytes[..5].to_vec(), "header"),
            (bytes[..20].to_vec(), "payload bytes"),
            ([bytes.clone(), vec![0]].concat(), "payload bytes"),
        ];
        let mut op = bytes.clone();
        op[0] = 9;
        cases.push((op, "unknown frame op 9"));
        let mut flags = bytes.clone();
        flags[1] = 1;
        cases.push((flags, "flags"));
        let mut nan = bytes.clone();
        nan[HEADER_BYTES + 1..HEADER_BYTES + 5].copy_from_slice(&f32::NAN.to_le_bytes());
        cases.push((nan, "not finite"));
        let mut long_quat = bytes.clone();
        long_quat[HEADER_BYTES + 25..HEADER_BYTES + 29].copy_from_slice(&2.0f32.to_le_bytes());
        cases.push((long_quat, "length"));
        let mut kp = DataFrame { channel: 3, timestamp_ns: 1, payload: FramePayload::Keypoints(keypoints()) }.encode();
        kp[HEADER_BYTES + 9..HEADER_BYTES + 13].copy_from_slice(&1.5f32.to_le_bytes());
        cases.push((kp, "score"));
        for (bytes, needle) in cases {
            let err = DataFrame::decode(&bytes).unwrap_err().to_string();
            assert!(err.contains(needle), "{needle}: {err}");
        }
    }

    #[test]
    fn names_are_the_wire_names() {
        for stream in Stream::ALL {
            assert_eq!(serde_json::to_value(stream).unwrap(), stream.name());
        }
        for role in [DeviceRole::Wearer, DeviceRole::Observer] {
            assert_eq!(serde_json::to_value(role).unwrap(), role.name());
        }
    }

    #[test]
    fn codes_and_links_become_joins() {
        assert_eq!(Join::parse(" 7kq m4t ").unwrap(), Join::Code { code: "7KQ-M4T".into() });
        let (room, secret) = ("Xq3wZkAbCdEfGhIjKlMnOp", "s3cr3t-s3cr3t_s3cr3t-x");
        let expected = Join::Secret { room: room.into(), secret: secret.into() };
        assert_eq!(Join::parse(&format!("https://h.example/xr.html#live={room}.{secret}")).unwrap(), expected);
        assert_eq!(Join::parse(&format!("{room}.{secret}")).unwrap(), expected);
        assert_eq!(Join::parse("  "), Err(JoinParseError::Empty));
        assert_eq!(Join::parse("7KQ-M40"), Err(JoinParseError::BadCode("7KQ-M40".into())));
        assert_eq!(Join::parse("https://h/xr.html#live=a.b<c"), Err(JoinParseError::BadLink));
    }

    #[test]
    fn links_carry_the_room_and_secret_in_the_fragment() {
        let link = LiveLink { room: "Ab-_9".into(), secret: "s3cr3t".into() };
        assert_eq!(link.fragment(), "live=Ab-_9.s3cr3t");
        assert_eq!(LiveLink::parse("https://h/#t=3&live=Ab-_9.s3cr3t"), Some(link.clone()));
        assert_eq!(LiveLink::parse("Ab-_9.s3cr3t"), Some(link));
        for bad in ["https://h/#live=a", "#live=.x", "#live=a.b<c", "7KQ-M4T", "https://h/?live=a.b"] {
            assert_eq!(LiveLink::parse(bad), None, "{bad}");
        }
    }

    #[test]
    fn device_codes_forgive_case_spaces_and_dashes_but_not_misreadable_characters() {
        assert_eq!(normalize_code("7kq m4t").as_deref(), Some("7KQM4T"));
        assert_eq!(normalize_code("7KQ\u{2013}M4T").as_deref(), Some("7KQM4T"));
        for bad in ["7KQ-M40", "7KQ-M4", "7KQ-M4TT", "", "ÄKQ-M4T"] {
            assert_eq!(normalize_code(bad), None, "{bad}");
        }
        assert_eq!(display_code("7KQM4T"), "7KQ-M4T");
    }

    /// Every JSON example in `docs/live-protocol.md` is a message of the protocol (or the
    /// room API's answer), so the document cannot drift from the types.
    #[test]
    fn the_documented_examples_parse() {
        let doc = include_str!("../../../docs/live-protocol.md");
        let mut examples = 0;
        for block in doc.split("```json").skip(1) {
            let json = block.split("```").next().unwrap();
            let value: serde_json::Value = serde_json::from_str(json).unwrap_or_else(|e| panic!("{e}: {json}"));
            let parsed = if value.get("type").is_none() {
                serde_json::from_value::<RoomCreated>(value.clone()).is_ok()
            } else {
                serde_json::from_value::<ClientMessage>(value.clone()).is_ok()
                    || serde_json::from_value::<RelayMessage>(value.clone()).is_ok()
            };
            assert!(parsed, "not a message of the protocol: {json}");
            examples += 1;
        }
        assert!(examples >= 6, "{examples} examples");
    }

    #[test]
    fn a_wearer_region_is_a_pixel_box_at_a_time_and_nonsense_boxes_are_named() {
        let region = BoundingBox { min: Vec2::new(100.0, 40.5), max: Vec2::new(260.0, 470.0) };
        let message = ClientMessage::WearerRegion { device: "phone".into(), region, at_ns: 1_764_600_000_000_000_000 };
        assert_eq!(
            serde_json::to_value(&message).unwrap(),
            serde_json::json!({"type": "wearer-region", "device": "phone",
                "region": {"min": [100.0, 40.5], "max": [260.0, 470.0]}, "at_ns": 1_764_600_000_000_000_000i64})
        );
        assert_eq!(region_problem(&region), None);
        let flipped = BoundingBox { min: region.max, max: region.min };
        assert_eq!(region_problem(&flipped), Some("a wearer region's min is past its max"));
        for bad in [f32::NAN, f32::INFINITY, 1e6] {
            let b = BoundingBox { max: Vec2::new(bad, 470.0), ..region };
            assert!(region_problem(&b).unwrap().contains("finite"), "{bad}");
        }
    }

    #[test]
    fn control_messages_have_their_wire_shape() {
        let hello = ClientMessage::Hello {
            protocol: LIVE_PROTOCOL_VERSION,
            join: Join::Code { code: "7KQ-M4T".into() },
            device: Some(DeviceHello::worn("wearer", DeviceRole::Wearer, vec![Stream::Head])),
        };
        let json = serde_json::to_value(&hello).unwrap();
        assert_eq!(
            json,
            serde_json::json!({"type": "hello", "protocol": 1, "join": {"code": "7KQ-M4T"},
                "device": {"id": "wearer", "role": "wearer", "streams": ["head"]}})
        );
        assert_eq!(serde_json::from_value::<ClientMessage>(json).unwrap(), hello);
        let viewer: ClientMessage =
            serde_json::from_str(r#"{"type":"hello","protocol":1,"join":{"room":"r","secret":"s"},"device":null}"#)
                .unwrap();
        assert!(matches!(viewer, ClientMessage::Hello { device: None, join: Join::Secret { .. }, .. }));
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"publish"}"#).is_err());
        assert!(DeviceRole::Observer.allows(Stream::Keypoints) && !DeviceRole::Wearer.allows(Stream::Keypoints));
        // A device in a world of its own says so; without the field the world is shared.
        let own: ClientMessage = serde_json::from_str(
            r#"{"type":"hello","protocol":1,"join":{"code":"7KQ-M4T"},"device":{"id":"quest","role":"observer","streams":["head","keypoints"],"world":"own"}}"#,
        )
        .unwrap();
        let ClientMessage::Hello { device: Some(device), .. } = own else { panic!("{own:?}") };
        assert_eq!(device.world, DeviceWorld::Own);
        assert!(serde_json::to_string(&device).unwrap().contains(r#""world":"own""#));
        assert!(
            serde_json::from_str::<DeviceHello>(r#"{"id":"a","role":"wearer","streams":[],"world":"mars"}"#).is_err()
        );
        assert!(valid_device_id("observer-1") && !valid_device_id("<b>") && !valid_device_id(""));
    }

    #[test]
    fn a_fixed_camera_says_so_and_publishes_no_head() {
        let json = r#"{"id":"webcam","role":"observer","streams":["keypoints"],"world":"own","mount":"fixed","focal_known":false}"#;
        let hello: DeviceHello = serde_json::from_str(json).unwrap();
        assert_eq!((hello.mount, hello.focal_known), (DeviceMount::Fixed, false));
        assert_eq!(hello.refused_stream(), None);
        assert_eq!(serde_json::to_string(&hello).unwrap(), json);
        // Absent fields are a worn device with a measured focal length, and are left out.
        let worn = DeviceHello::worn("glasses", DeviceRole::Observer, vec![Stream::Head, Stream::Keypoints]);
        assert_eq!(
            serde_json::from_str::<DeviceHello>(r#"{"id":"glasses","role":"observer","streams":["head","keypoints"]}"#)
                .unwrap(),
            worn
        );
        assert!(!serde_json::to_string(&worn).unwrap().contains("mount"));
        let with_head = DeviceHello { mount: DeviceMount::Fixed, ..worn };
        assert!(with_head.refused_stream().unwrap().contains("no head poses"));
        let wearer_keypoints = DeviceHello::worn("w", DeviceRole::Wearer, vec![Stream::Keypoints]);
        assert!(wearer_keypoints.refused_stream().unwrap().contains("may not publish"));
        assert!(
            serde_json::from_str::<DeviceHello>(r#"{"id":"a","role":"observer","streams":[],"mount":"tripod"}"#)
                .is_err()
        );
    }
}
