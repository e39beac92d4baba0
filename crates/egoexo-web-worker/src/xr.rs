//! The WebXR page's side of the live protocol (`web/xr.html`, `docs/live-protocol.md`): a
//! headset streaming as a wearer. The page reads the XR poses and the clock and owns the
//! socket; everything that is geometry or protocol is here, so no JS re-implements it:
//!
//! - [`pose_frame`] — an XR pose → the session pose ([`egoexo_core::xr::session_pose`]) → a
//!   binary data frame of the device's stream;
//! - [`parse_join`] / [`fragment_join`] — what the person typed (a device code) or the
//!   address carried (`#live=<room>.<secret>`) → a [`Join`]; [`hello`] — the first message;
//! - [`answer`] — the pong to a relay ping (the relay's time echoed to the nanosecond, which
//!   a JS number cannot hold);
//! - [`close_may_retry`] — whether a close is worth reconnecting after.
//!
//! Nothing here reads a clock: the page passes every time in. In the browser the functions
//! are exported through wasm-bindgen (`xr_pose_frame`, `XrJoin`, …; errors are JS `Error`s).

use egoexo_core::xr::{Hand, XrPose, XrPoseError, XrSpace, session_pose};
use egoexo_protocol::live::{
    ClientMessage, CloseKind, DataFrame, DeviceHello, DeviceRole, DeviceWorld, FramePayload, Join, JoinParseError,
    LIVE_PROTOCOL_VERSION, LiveLink, RelayMessage, Stream, valid_device_id,
};

/// The XR space a pose comes from, and so the stream it goes to.
#[cfg_attr(target_arch = "wasm32", wasm_bindgen::prelude::wasm_bindgen)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum XrSource {
    /// The viewer pose → `head`.
    Viewer = 0,
    /// The left controller's grip space → `left-wrist`.
    LeftGrip = 1,
    /// The right controller's grip space → `right-wrist`.
    RightGrip = 2,
    /// The left hand's tracked `wrist` joint → `left-wrist`.
    LeftHandWrist = 3,
    /// The right hand's tracked `wrist` joint → `right-wrist`.
    RightHandWrist = 4,
}

impl XrSource {
    pub fn space(self) -> XrSpace {
        match self {
            XrSource::Viewer => XrSpace::Viewer,
            XrSource::LeftGrip => XrSpace::Grip(Hand::Left),
            XrSource::RightGrip => XrSpace::Grip(Hand::Right),
            XrSource::LeftHandWrist => XrSpace::HandWrist(Hand::Left),
            XrSource::RightHandWrist => XrSpace::HandWrist(Hand::Right),
        }
    }

    pub fn stream(self) -> Stream {
        match self.space() {
            XrSpace::Viewer => Stream::Head,
            XrSpace::Grip(Hand::Left) | XrSpace::HandWrist(Hand::Left) => Stream::LeftWrist,
            XrSpace::Grip(Hand::Right) | XrSpace::HandWrist(Hand::Right) => Stream::RightWrist,
        }
    }
}

/// The streams the page announces: the head and both wrists (a wrist without a pose is sent
/// as not valid).
pub const XR_STREAMS: [Stream; 3] = [Stream::Head, Stream::LeftWrist, Stream::RightWrist];

/// What the page did wrong, in words for the person holding the headset.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum XrError {
    #[error(transparent)]
    Join(#[from] JoinParseError),
    #[error("“{0}” cannot be a device id: use 1–64 letters, digits, '.', '_' or '-'.")]
    BadDeviceId(String),
    #[error("a {what} needs {expected} numbers, got {got}")]
    Length { what: &'static str, expected: usize, got: usize },
    #[error("the timestamp must be a finite number of nanoseconds, got {0}")]
    Timestamp(f64),
    #[error(transparent)]
    Pose(#[from] XrPoseError),
    #[error("the relay sent a message that is not one of the protocol: {0}")]
    RelayMessage(String),
    #[error("could not write a protocol message: {0}")]
    Json(String),
}

fn to_json(message: &ClientMessage) -> Result<String, XrError> {
    serde_json::to_string(message).map_err(|e| XrError::Json(e.to_string()))
}

fn xr_pose(position: &[f32], orientation: &[f32]) -> Result<XrPose, XrError> {
    let position: [f32; 3] =
        position.try_into().map_err(|_| XrError::Length { what: "position", expected: 3, got: position.len() })?;
    let orientation: [f32; 4] = orientation.try_into().map_err(|_| XrError::Length {
        what: "orientation (quaternion x, y, z, w)",
        expected: 4,
        got: orientation.len(),
    })?;
    Ok(XrPose { position, orientation })
}

/// `T_world_device` in session conventions of an XR pose (`XRRigidTransform.position` x, y, z
/// and `.orientation` x, y, z, w): translation x, y, z (metres) then rotation x, y, z, w.
pub fn session_pose_array(source: XrSource, position: &[f32], orientation: &[f32]) -> Result<[f32; 7], XrError> {
    let t = session_pose(source.space(), &xr_pose(position, orientation)?)?;
    let mut out = [0.0; 7];
    out[..3].copy_from_slice(&t.translation.to_array());
    out[3..].copy_from_slice(&t.rotation.to_array());
    Ok(out)
}

/// Nanoseconds held in a JS number as an `i64` (rounded; a JS number holds epoch nanoseconds
/// to a fraction of a microsecond).
fn nanoseconds(ns: f64) -> Result<i64, XrError> {
    crate::page_time_ns(ns).ok_or(XrError::Timestamp(ns))
}

/// The data frame of one pose: the session pose of `source` on its stream's device-local
/// channel, stamped `device_timestamp_ns` (the page's clock, the one its pongs carry). With
/// `valid` false the pose is "tracking lost" and `position` / `orientation` are not read.
pub fn pose_frame(
    source: XrSource,
    device_timestamp_ns: f64,
    position: &[f32],
    orientation: &[f32],
    valid: bool,
) -> Result<Vec<u8>, XrError> {
    let timestamp_ns = nanoseconds(device_timestamp_ns)?;
    let pose = if valid { Some(session_pose(source.space(), &xr_pose(position, orientation)?)?) } else { None };
    Ok(DataFrame { channel: source.stream().channel(), timestamp_ns, payload: FramePayload::Pose(pose) }.encode())
}

/// A join from what a person typed ([`Join::parse`]).
pub fn parse_join(text: &str) -> Result<Join, XrError> {
    Ok(Join::parse(text)?)
}

/// The join in the page's address fragment (`location.hash`): `None` without `live=`, an
/// error when it is there but damaged.
pub fn fragment_join(fragment: &str) -> Result<Option<Join>, XrError> {
    if !fragment.contains("live=") {
        return Ok(None);
    }
    let link = LiveLink::parse_fragment(fragment).ok_or(JoinParseError::BadLink)?;
    Ok(Some(Join::Secret { room: link.room, secret: link.secret }))
}

/// How the page names a join (never showing a secret): `code 7KQ-M4T` or `room Xq3wZk…`.
pub fn join_label(join: &Join) -> String {
    match join {
        Join::Code { code } => format!("code {code}"),
        Join::Secret { room, .. } => format!("room {}…", room.chars().take(6).collect::<String>()),
    }
}

/// The hello of a wearer `device_id` publishing [`XR_STREAMS`], as JSON.
pub fn hello(join: &Join, device_id: &str) -> Result<String, XrError> {
    let id = device_id.trim();
    if !valid_device_id(id) {
        return Err(XrError::BadDeviceId(id.chars().take(70).collect()));
    }
    let message = ClientMessage::Hello {
        protocol: LIVE_PROTOCOL_VERSION,
        join: join.clone(),
        device: Some(DeviceHello {
            // A headset's XR reference space is its own: Y-up, floor-level, but a yaw and a
            // translation away from any other device's (`docs/registration.md`).
            world: DeviceWorld::Own,
            ..DeviceHello::worn(id, DeviceRole::Wearer, XR_STREAMS.to_vec())
        }),
    };
    to_json(&message)
}

/// The answer to a relay text message: a pong (JSON) to a ping, carrying `device_ns`, the
/// page's clock now (the clock its frames are stamped with); `None` for anything else
/// (messages of a later protocol revision included).
pub fn answer(relay_text: &str, device_ns: f64) -> Result<Option<String>, XrError> {
    match serde_json::from_str::<RelayMessage>(relay_text) {
        Ok(RelayMessage::Ping { relay_ns }) => {
            let pong = ClientMessage::Pong { relay_ns, device_ns: nanoseconds(device_ns)? };
            to_json(&pong).map(Some)
        }
        Ok(_) => Ok(None),
        Err(e) => {
            let typed = serde_json::from_str::<serde_json::Value>(relay_text)
                .is_ok_and(|v| v.get("type").is_some_and(|t| t.is_string()));
            if typed { Ok(None) } else { Err(XrError::RelayMessage(e.to_string())) }
        }
    }
}

/// Whether to reconnect after the relay (or the network) closed the socket with `code`: the
/// relay's codes say (`CloseKind::may_retry`: shutdowns and time-outs); a connection lost
/// without a close (1005, 1006) or a server error (1011–1014) is retried too.
pub fn close_may_retry(code: u16) -> bool {
    match CloseKind::from_code(code) {
        Some(kind) => kind.may_retry(),
        None => matches!(code, 1005 | 1006 | 1011..=1014),
    }
}

#[cfg(target_arch = "wasm32")]
mod bindings {
    use egoexo_protocol::live::Join;
    use wasm_bindgen::prelude::*;

    use super::{XrError, XrSource};

    fn js(e: XrError) -> JsError {
        JsError::new(&e.to_string())
    }

    /// The binary data frame of one XR pose (see `pose_frame`); a JS `Error` for bad numbers.
    #[wasm_bindgen]
    pub fn xr_pose_frame(
        source: XrSource,
        device_timestamp_ns: f64,
        position: &[f32],
        orientation: &[f32],
        valid: bool,
    ) -> Result<Vec<u8>, JsError> {
        super::pose_frame(source, device_timestamp_ns, position, orientation, valid).map_err(js)
    }

    /// The session pose of an XR pose: `Float32Array` [tx, ty, tz, qx, qy, qz, qw].
    #[wasm_bindgen]
    pub fn xr_session_pose(source: XrSource, position: &[f32], orientation: &[f32]) -> Result<Vec<f32>, JsError> {
        super::session_pose_array(source, position, orientation).map(|a| a.to_vec()).map_err(js)
    }

    /// The pong to a relay ping, or `undefined` for any other message.
    #[wasm_bindgen]
    pub fn xr_answer(relay_text: &str, device_ns: f64) -> Result<Option<String>, JsError> {
        super::answer(relay_text, device_ns).map_err(js)
    }

    /// Whether to reconnect after a close with this code.
    #[wasm_bindgen]
    pub fn xr_close_may_retry(code: u16) -> bool {
        super::close_may_retry(code)
    }

    /// How the page joins a room: by a typed device code or a device link.
    #[wasm_bindgen]
    #[derive(Debug)]
    pub struct XrJoin {
        join: Join,
    }

    #[wasm_bindgen]
    impl XrJoin {
        /// From what a person typed (a code, or a pasted link); an `Error` that says what a
        /// code looks like otherwise.
        pub fn parse(text: &str) -> Result<XrJoin, JsError> {
            super::parse_join(text).map(|join| XrJoin { join }).map_err(js)
        }

        /// From the address's fragment: `undefined` without `#live=`, an `Error` when damaged.
        #[wasm_bindgen(js_name = fromFragment)]
        pub fn from_fragment(fragment: &str) -> Result<Option<XrJoin>, JsError> {
            super::fragment_join(fragment).map(|join| join.map(|join| XrJoin { join })).map_err(js)
        }

        /// `code 7KQ-M4T` or `room Xq3wZk…` (never the secret).
        #[wasm_bindgen(getter)]
        pub fn label(&self) -> String {
            super::join_label(&self.join)
        }

        /// The hello (JSON) of the wearer `device_id`; an `Error` for an invalid id.
        pub fn hello(&self, device_id: &str) -> Result<String, JsError> {
            super::hello(&self.join, device_id).map_err(js)
        }

        /// The hello (JSON) of the static camera `device_id` watching `target` (empty: the
        /// room's only wearer) for the observer page; an `Error` for an invalid id.
        #[wasm_bindgen(js_name = observerHello)]
        pub fn observer_hello(&self, device_id: &str, target: &str, focal_known: bool) -> Result<String, JsError> {
            crate::observe::observer_hello(&self.join, device_id, Some(target), focal_known)
                .map_err(|e| JsError::new(&e.to_string()))
        }
    }
}

#[cfg(test)]
mod tests {
    use egoexo_core::glam::{Quat, Vec3};

    use super::*;

    #[test]
    fn a_pose_frame_holds_the_session_pose_on_the_stream_channel() {
        let ts = 1_764_600_000_123_456_000.0;
        let bytes = pose_frame(XrSource::Viewer, ts, &[0.1, 1.6, -0.3], &[0.0, 0.0, 0.0, 1.0], true).unwrap();
        let frame = DataFrame::decode(&bytes).unwrap();
        assert_eq!(frame.channel, 0);
        assert_eq!(frame.timestamp_ns, 1_764_600_000_123_456_000);
        let FramePayload::Pose(Some(pose)) = frame.payload else { panic!("{frame:?}") };
        assert!(pose.translation.abs_diff_eq(Vec3::new(0.1, 1.6, -0.3), 1e-6));
        assert!(pose.rotation.dot(Quat::from_rotation_y(std::f32::consts::PI)).abs() > 1.0 - 1e-6);

        let right = pose_frame(XrSource::RightHandWrist, 5.4, &[0.0; 3], &[0.0, 0.0, 0.0, 1.0], true).unwrap();
        let frame = DataFrame::decode(&right).unwrap();
        assert_eq!((frame.channel, frame.timestamp_ns), (2, 5));
        let array = session_pose_array(XrSource::LeftGrip, &[0.0, 1.0, 0.0], &[0.0, 0.0, 0.0, 1.0]).unwrap();
        assert!((Quat::from_slice(&array[3..]).length() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn lost_tracking_is_an_invalid_pose_and_needs_no_numbers() {
        let bytes = pose_frame(XrSource::LeftGrip, 7.0, &[], &[], false).unwrap();
        let frame = DataFrame::decode(&bytes).unwrap();
        assert_eq!(frame.channel, 1);
        assert_eq!(frame.payload, FramePayload::Pose(None));
    }

    #[test]
    fn bad_numbers_are_errors_that_say_so() {
        let cases = [
            pose_frame(XrSource::Viewer, f64::NAN, &[0.0; 3], &[0.0, 0.0, 0.0, 1.0], true),
            pose_frame(XrSource::Viewer, 1e19, &[0.0; 3], &[0.0, 0.0, 0.0, 1.0], true),
            pose_frame(XrSource::Viewer, 0.0, &[0.0; 2], &[0.0, 0.0, 0.0, 1.0], true),
            pose_frame(XrSource::Viewer, 0.0, &[0.0; 3], &[0.0; 3], true),
            pose_frame(XrSource::Viewer, 0.0, &[0.0; 3], &[0.0; 4], true),
            pose_frame(XrSource::Viewer, 0.0, &[f32::INFINITY, 0.0, 0.0], &[0.0, 0.0, 0.0, 1.0], true),
        ];
        let needles = ["timestamp", "timestamp", "position needs 3", "needs 4", "not a rotation", "not finite"];
        for (case, needle) in cases.into_iter().zip(needles) {
            let err = case.unwrap_err().to_string();
            assert!(err.contains(needle), "{needle}: {err}");
        }
    }

    #[test]
    fn codes_and_links_become_joins() {
        assert_eq!(parse_join(" 7kq m4t ").unwrap(), Join::Code { code: "7KQ-M4T".into() });
        let room = "Xq3wZkAbCdEfGhIjKlMnOp";
        let secret = "s3cr3t-s3cr3t_s3cr3t-x";
        let expected = Join::Secret { room: room.into(), secret: secret.into() };
        assert_eq!(parse_join(&format!("https://h.example/xr.html#live={room}.{secret}")).unwrap(), expected);
        assert_eq!(parse_join(&format!("{room}.{secret}")).unwrap(), expected);
        assert_eq!(fragment_join(&format!("#live={room}.{secret}")).unwrap(), Some(expected.clone()));
        assert_eq!(fragment_join("").unwrap(), None);
        assert_eq!(fragment_join("#t=3").unwrap(), None);
        assert_eq!(join_label(&expected), "room Xq3wZk…");
        assert_eq!(join_label(&Join::Code { code: "7KQ-M4T".into() }), "code 7KQ-M4T");

        assert!(parse_join("  ").unwrap_err().to_string().contains("Type the device code"));
        let err = parse_join("7KQ-M40").unwrap_err().to_string();
        assert!(err.contains("“7KQ-M40” is not a device code") && err.contains("without I, L or O"), "{err}");
        assert_eq!(fragment_join("#live=abc").unwrap_err(), XrError::Join(JoinParseError::BadLink));
        assert_eq!(parse_join("https://h/xr.html#live=a.b<c").unwrap_err(), XrError::Join(JoinParseError::BadLink));
    }

    #[test]
    fn the_hello_is_a_wearer_with_head_and_wrists_in_a_world_of_its_own() {
        let json = hello(&Join::Code { code: "7KQ-M4T".into() }, " quest ").unwrap();
        assert_eq!(
            serde_json::from_str::<serde_json::Value>(&json).unwrap(),
            serde_json::json!({"type": "hello", "protocol": 1, "join": {"code": "7KQ-M4T"},
                "device": {"id": "quest", "role": "wearer", "streams": ["head", "left-wrist", "right-wrist"],
                    "world": "own"}})
        );
        for bad in ["", "my quest", "<b>", &"x".repeat(65)] {
            let err = hello(&Join::Code { code: "7KQ-M4T".into() }, bad).unwrap_err().to_string();
            assert!(err.contains("cannot be a device id"), "{err}");
        }
    }

    #[test]
    fn pings_are_answered_with_the_relay_time_exact() {
        // 1764600000123456789 is not a JS number; the pong must echo it digit for digit.
        let pong = answer(r#"{"type":"ping","relay_ns":1764600000123456789}"#, 81_234_567_890.4).unwrap().unwrap();
        assert_eq!(pong, r#"{"type":"pong","relay_ns":1764600000123456789,"device_ns":81234567890}"#);
        let welcome = r#"{"type":"welcome","protocol":1,"room":"r","client":3,"relay_ns":1,"expires_at":"x"}"#;
        assert_eq!(answer(welcome, 0.0).unwrap(), None);
        assert_eq!(answer(r#"{"type":"from-the-future","x":1}"#, 0.0).unwrap(), None);
        assert!(answer("not json", 0.0).unwrap_err().to_string().contains("not one of the protocol"));
    }

    #[test]
    fn only_shutdowns_time_outs_and_lost_connections_are_retried() {
        for code in [1001, 4006, 1006, 1005, 1011] {
            assert!(close_may_retry(code), "{code}");
        }
        for code in [1000, 1007, 1008, 1009, 4000, 4001, 4002, 4003, 4004, 4005] {
            assert!(!close_may_retry(code), "{code}");
        }
    }
}
