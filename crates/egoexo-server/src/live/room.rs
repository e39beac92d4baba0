//! One live room: its secrets, devices and their channels, clocks, the last seconds of every
//! channel, and the viewers it fans frames out to.

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex};

use bytes::{Bytes, BytesMut};
use egoexo_core::camera::CameraCalibration;
use egoexo_core::region::BoundingBox;
use egoexo_protocol::live::{
    ChannelInfo, Close, CloseKind, DataFrame, DeviceHello, DeviceRole, DeviceStatus, HEADER_BYTES, RelayMessage,
    RoomId, Stream, WorldState,
};
use subtle::ConstantTimeEq;

use super::LiveLimits;
use super::clock::{ClockEstimator, ClockSample};
use super::outbox::Outbox;

/// What a join secret lets a client do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Admission {
    /// Publish and watch.
    Device,
    /// Watch only.
    Viewer,
}

/// Most frames held for a device whose clock is not known yet.
const MAX_HELD_FRAMES: usize = 512;
/// A frame stamped this far past the relay's now (beyond the clock's uncertainty) cannot be
/// right: the device's clock moved. Nanoseconds.
const FUTURE_TOLERANCE_NS: i64 = 50_000_000;
/// A frame this late is suspect too (the clock may have stepped back); the relay checks the
/// clock before forwarding it. Nanoseconds.
const PAST_TOLERANCE_NS: i64 = 500_000_000;
/// Latency samples kept per device and status interval.
const MAX_LATENCY_SAMPLES: usize = 1024;

#[derive(Debug)]
struct DeviceState {
    role: DeviceRole,
    client: Option<u32>,
    outbox: Option<Arc<Outbox>>,
    /// Room channel of each stream the device has ever announced.
    channels: BTreeMap<Stream, u16>,
    /// What the current connection announced.
    announced: Vec<Stream>,
    clock: ClockEstimator,
    clock_jumps_before: u32,
    /// Whether frames may be stamped with the clock estimate (false until the first pong,
    /// and after a frame whose stamp cannot be right, until the next pong).
    synced: bool,
    held: VecDeque<(Stream, i64, Bytes)>,
    /// Per stream, the last `(device ns, relay stamp)` forwarded.
    last_stamps: BTreeMap<Stream, (i64, i64)>,
    counts: BTreeMap<Stream, u64>,
    rates_hz: Vec<(Stream, f64)>,
    latencies: Vec<i64>,
    latency_ns: Option<i64>,
    frames: u64,
}

#[derive(Debug)]
struct ViewerState {
    outbox: Arc<Outbox>,
    clock: ClockEstimator,
}

#[derive(Debug, Default)]
struct RoomInner {
    devices: BTreeMap<String, DeviceState>,
    /// Index = room channel.
    channels: Vec<ChannelInfo>,
    /// The last [`LiveLimits::history_ns`] of every channel: `(relay ns, frame)`.
    history: Vec<VecDeque<(i64, Bytes)>>,
    calibrations: BTreeMap<String, CameraCalibration>,
    viewers: BTreeMap<u32, ViewerState>,
    next_client: u32,
    /// When the last client left (`None` while any is connected).
    empty_since_ns: Option<i64>,
    last_status_ns: i64,
    closed: bool,
}

/// What happened to a device's frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameOutcome {
    /// Stamped on the relay clock and sent to the viewers.
    Forwarded,
    /// Held until the device's clock is known; `check_clock`: ping the device now (its
    /// stamp looked wrong).
    Held { check_clock: bool },
}

/// A live room.
#[derive(Debug)]
pub struct Room {
    pub id: RoomId,
    device_secret: String,
    viewer_secret: String,
    /// The device code without its dash (`7KQM4T`).
    pub code: String,
    /// When the room closes, relay clock, nanoseconds; and as RFC 3339.
    pub expires_ns: i64,
    pub expires_at: String,
    limits: Arc<LiveLimits>,
    inner: Mutex<RoomInner>,
}

impl Room {
    pub fn new(
        id: RoomId,
        device_secret: String,
        viewer_secret: String,
        code: String,
        now_ns: i64,
        expires_at: String,
        limits: Arc<LiveLimits>,
    ) -> Self {
        let expires_ns = now_ns.saturating_add(i64::try_from(limits.room_ttl.as_nanos()).unwrap_or(i64::MAX));
        let inner = RoomInner { empty_since_ns: Some(now_ns), last_status_ns: now_ns, ..Default::default() };
        Self { id, device_secret, viewer_secret, code, expires_ns, expires_at, limits, inner: Mutex::new(inner) }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, RoomInner> {
        self.inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// What `secret` admits to (compared in constant time).
    pub fn admission(&self, secret: &str) -> Option<Admission> {
        if bool::from(secret.as_bytes().ct_eq(self.device_secret.as_bytes())) {
            Some(Admission::Device)
        } else if bool::from(secret.as_bytes().ct_eq(self.viewer_secret.as_bytes())) {
            Some(Admission::Viewer)
        } else {
            None
        }
    }

    /// Whether the room has expired, or stood empty for [`LiveLimits::empty_room_ttl`].
    pub fn is_over(&self, now_ns: i64) -> bool {
        let inner = self.lock();
        let empty_ttl = i64::try_from(self.limits.empty_room_ttl.as_nanos()).unwrap_or(i64::MAX);
        inner.closed || now_ns >= self.expires_ns || inner.empty_since_ns.is_some_and(|t| now_ns - t >= empty_ttl)
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        let inner = self.lock();
        inner.viewers.len() + inner.devices.values().filter(|d| d.client.is_some()).count()
    }

    /// Admits a device; a device already connected under the same id is closed (the newer
    /// connection wins: a headset reconnecting after a network change).
    pub fn join_device(&self, hello: &DeviceHello, outbox: Arc<Outbox>, now_ns: i64) -> Result<u32, Close> {
        let mut inner = self.lock();
        if inner.closed {
            return Err(Close::new(CloseKind::RoomClosed, "the room is closed"));
        }
        let mut streams = hello.streams.clone();
        streams.sort();
        streams.dedup();
        if let Some(why) = hello.refused_stream() {
            return Err(Close::new(CloseKind::NotAllowed, why));
        }
        match inner.devices.get(&hello.id) {
            Some(existing) if existing.role != hello.role => {
                return Err(Close::new(
                    CloseKind::NotAllowed,
                    format!("device `{}` is a {:?} in this room", hello.id, existing.role),
                ));
            }
            Some(_) if inner.channels.iter().any(|c| c.device == hello.id && c.target != hello.target) => {
                return Err(Close::new(
                    CloseKind::NotAllowed,
                    format!("device `{}` observes another wearer in this room", hello.id),
                ));
            }
            None if inner.devices.len() >= self.limits.max_devices_per_room => {
                return Err(Close::new(
                    CloseKind::RoomFull,
                    format!("the room holds {} devices, its limit", self.limits.max_devices_per_room),
                ));
            }
            _ => {}
        }
        let known = inner.devices.get(&hello.id).map(|d| d.channels.clone()).unwrap_or_default();
        let new_streams = streams.iter().filter(|s| !known.contains_key(s)).count();
        if inner.channels.len() + new_streams > self.limits.max_channels_per_room {
            return Err(Close::new(
                CloseKind::RoomFull,
                format!("the room holds {} channels, its limit", self.limits.max_channels_per_room),
            ));
        }
        let client = inner.next_client;
        inner.next_client += 1;
        let mut channels = known;
        let mut changed = false;
        for &stream in &streams {
            if let std::collections::btree_map::Entry::Vacant(entry) = channels.entry(stream) {
                let channel = inner.channels.len() as u16;
                inner.channels.push(ChannelInfo::of(channel, hello, stream));
                inner.history.push(VecDeque::new());
                entry.insert(channel);
                changed = true;
            }
        }
        // A device that connects again in another world (a headset told its world is its own
        // now), or mounted or calibrated otherwise, says so on every channel it had.
        for channel in inner.channels.iter_mut().filter(|c| {
            c.device == hello.id && (c.world, c.mount, c.focal_known) != (hello.world, hello.mount, hello.focal_known)
        }) {
            (channel.world, channel.mount, channel.focal_known) = (hello.world, hello.mount, hello.focal_known);
            changed = true;
        }
        let mut previous = inner.devices.remove(&hello.id);
        if let Some(previous) = previous.as_mut() {
            if let Some(outbox) = &previous.outbox {
                outbox.close(Close::new(CloseKind::Replaced, format!("device `{}` connected again", hello.id)));
            }
            // Frames the old connection sent before its clock was checked go out on its last
            // estimate (without one there is no time to give them).
            if previous.clock.offset_ns().is_some() {
                release_held(&mut inner, &self.limits, previous, now_ns);
            }
        }
        let (frames, jumps, last_stamps) = previous
            .map_or((0, 0, BTreeMap::new()), |p| (p.frames, p.clock_jumps_before + p.clock.jumps(), p.last_stamps));
        inner.devices.insert(
            hello.id.clone(),
            DeviceState {
                role: hello.role,
                client: Some(client),
                outbox: Some(outbox),
                channels,
                announced: streams,
                // A reconnecting device may have restarted: its clock is measured afresh.
                clock: ClockEstimator::default(),
                clock_jumps_before: jumps,
                synced: false,
                held: VecDeque::new(),
                last_stamps,
                counts: BTreeMap::new(),
                rates_hz: Vec::new(),
                latencies: Vec::new(),
                latency_ns: None,
                frames,
            },
        );
        inner.empty_since_ns = None;
        if changed {
            Self::broadcast_channels(&inner);
        }
        Ok(client)
    }

    /// Admits a viewer and queues what it needs to start at once: the channels, the
    /// cameras and the last seconds of every channel.
    pub fn join_viewer(&self, outbox: Arc<Outbox>, now_ns: i64) -> Result<u32, Close> {
        let mut inner = self.lock();
        if inner.closed {
            return Err(Close::new(CloseKind::RoomClosed, "the room is closed"));
        }
        if inner.viewers.len() >= self.limits.max_viewers_per_room {
            return Err(Close::new(
                CloseKind::RoomFull,
                format!("the room has {} viewers, its limit", self.limits.max_viewers_per_room),
            ));
        }
        let client = inner.next_client;
        inner.next_client += 1;
        outbox.set_channels(channels_json(&inner.channels));
        for (device, camera) in &inner.calibrations {
            outbox.set_calibration(device, calibration_json(device, camera));
        }
        // History waits longer than live frames before it counts as stale: a viewer on a
        // slow link still gets the seconds it needs to reconstruct at once.
        let deadline = now_ns.saturating_add(self.limits.history_deadline_ns());
        let mut history: Vec<(i64, u16, &Bytes)> = Vec::new();
        for (channel, frames) in inner.history.iter().enumerate() {
            history.extend(frames.iter().map(|(t, bytes)| (*t, channel as u16, bytes)));
        }
        history.sort_by_key(|(t, _, _)| *t);
        for (_, channel, bytes) in history {
            outbox.push_frame(channel, bytes.clone(), deadline, now_ns);
        }
        inner.viewers.insert(client, ViewerState { outbox, clock: ClockEstimator::default() });
        inner.empty_since_ns = None;
        Ok(client)
    }

    /// A client left. A device keeps its channels (it may come back); a viewer is forgotten.
    pub fn leave(&self, client: u32, now_ns: i64) {
        let mut inner = self.lock();
        inner.viewers.remove(&client);
        for device in inner.devices.values_mut() {
            if device.client == Some(client) {
                device.client = None;
                device.outbox = None;
                device.announced.clear();
                device.held.clear();
                device.synced = false;
            }
        }
        let connected = inner.viewers.len() + inner.devices.values().filter(|d| d.client.is_some()).count();
        if connected == 0 {
            inner.empty_since_ns = Some(now_ns);
        }
    }

    /// An observer's camera: kept for viewers who join later, and sent to those watching.
    pub fn set_calibration(&self, device: &str, client: u32, camera: CameraCalibration) -> Result<(), Close> {
        let mut inner = self.lock();
        let state = current_device(&mut inner, device, client)?;
        if state.role != DeviceRole::Observer {
            return Err(Close::new(CloseKind::NotAllowed, "only observers send a camera calibration"));
        }
        check_camera(&camera)?;
        let json = calibration_json(device, &camera);
        for viewer in inner.viewers.values() {
            viewer.outbox.set_calibration(device, json.clone());
        }
        inner.calibrations.insert(device.to_string(), camera);
        Ok(())
    }

    /// Viewer `viewer`'s word on observer `device`'s world, passed to that observer (when it is
    /// one, and connected; otherwise dropped: it may have left).
    pub fn observer_world(&self, device: &str, viewer: u32, state: WorldState, message: String) {
        let inner = self.lock();
        if let Some(DeviceState { role: DeviceRole::Observer, outbox: Some(outbox), .. }) = inner.devices.get(device) {
            outbox.push_message(to_json(&RelayMessage::ObserverWorld { viewer, state, message }));
        }
    }

    /// Viewer `viewer`'s proposal of where observer `device`'s wearer is in its image at relay
    /// time `at_ns`, passed to that observer on its own clock (dropped when it is no observer,
    /// not connected, or has not answered a ping: its clock is not known).
    pub fn wearer_region(&self, device: &str, viewer: u32, region: BoundingBox, at_ns: i64) {
        let inner = self.lock();
        if let Some(DeviceState { role: DeviceRole::Observer, outbox: Some(outbox), clock, .. }) =
            inner.devices.get(device)
            && let Some(offset_ns) = clock.offset_ns()
        {
            // The offset is relay minus device.
            let at_ns = at_ns.saturating_sub(offset_ns);
            outbox.push_message(to_json(&RelayMessage::WearerRegion { viewer, region, at_ns }));
        }
    }

    /// A device's data frame: checked, stamped on the relay clock, kept in the history and
    /// fanned out to the viewers.
    pub fn device_frame(&self, device: &str, client: u32, bytes: &[u8], now_ns: i64) -> Result<FrameOutcome, Close> {
        let frame = DataFrame::decode(bytes).map_err(|e| Close::new(CloseKind::Malformed, format!("frame: {e}")))?;
        let stream = Stream::from_channel(frame.channel).ok_or_else(|| {
            Close::new(
                CloseKind::NotAllowed,
                format!("channel {} is no stream (0 head, 1 left wrist, 2 right wrist, 3 keypoints)", frame.channel),
            )
        })?;
        if frame.payload.op() != stream.op() {
            return Err(Close::new(
                CloseKind::NotAllowed,
                format!("a {:?} frame on the {stream:?} stream", frame.payload.op()),
            ));
        }
        let mut inner = self.lock();
        let limits = self.limits.clone();
        let state = current_device(&mut inner, device, client)?;
        if !state.announced.contains(&stream) {
            return Err(Close::new(
                CloseKind::NotAllowed,
                format!("device `{device}` did not announce the {stream:?} stream in its hello"),
            ));
        }
        state.frames += 1;
        *state.counts.entry(stream).or_default() += 1;
        let bytes = Bytes::copy_from_slice(bytes);
        let hold = |state: &mut DeviceState, check_clock: bool| {
            if state.held.len() >= MAX_HELD_FRAMES {
                return Err(Close::new(
                    CloseKind::TimedOut,
                    "the relay cannot place frames in time: answer every ping with a pong",
                ));
            }
            state.held.push_back((stream, frame.timestamp_ns, bytes.clone()));
            Ok(FrameOutcome::Held { check_clock })
        };
        if !state.synced {
            return hold(state, false);
        }
        let Some(stamp) = state.clock.to_relay(frame.timestamp_ns) else { return hold(state, false) };
        let uncertainty = state.clock.uncertainty_ns().unwrap_or(0);
        if stamp > now_ns + uncertainty + FUTURE_TOLERANCE_NS || stamp < now_ns - PAST_TOLERANCE_NS {
            state.synced = false;
            return hold(state, true);
        }
        if state.latencies.len() < MAX_LATENCY_SAMPLES {
            state.latencies.push(now_ns - stamp);
        }
        let (channel, stamp) = state.place(stream, frame.timestamp_ns, stamp);
        forward(&mut inner, &limits, channel, stamp, &bytes, now_ns);
        Ok(FrameOutcome::Forwarded)
    }

    /// A device's pong: its clock sample; frames held for the clock are released.
    pub fn device_pong(&self, device: &str, client: u32, sample: ClockSample, now_ns: i64) -> Result<(), Close> {
        let mut inner = self.lock();
        let limits = self.limits.clone();
        let state = current_device(&mut inner, device, client)?;
        state.clock.add(sample);
        if state.synced {
            return Ok(());
        }
        state.synced = true;
        let Some(mut state) = inner.devices.remove(device) else { return Ok(()) };
        release_held(&mut inner, &limits, &mut state, now_ns);
        inner.devices.insert(device.to_string(), state);
        Ok(())
    }

    /// A viewer's pong: its clock offset, reported back in its status.
    pub fn viewer_pong(&self, client: u32, sample: ClockSample) {
        if let Some(viewer) = self.lock().viewers.get_mut(&client) {
            viewer.clock.add(sample);
        }
    }

    /// Sends every viewer the room's status (rates and latencies over the time since the
    /// last status).
    pub fn send_status(&self, now_ns: i64) {
        let mut inner = self.lock();
        let interval_s = ((now_ns - inner.last_status_ns) as f64 / 1e9).max(1e-3);
        inner.last_status_ns = now_ns;
        let mut devices = Vec::with_capacity(inner.devices.len());
        for (id, state) in inner.devices.iter_mut() {
            state.rates_hz = state.counts.iter().map(|(s, n)| (*s, *n as f64 / interval_s)).collect();
            state.counts.clear();
            if !state.latencies.is_empty() {
                let middle = state.latencies.len() / 2;
                state.latency_ns = Some(*state.latencies.select_nth_unstable(middle).1);
                state.latencies.clear();
            } else if state.client.is_none() {
                state.latency_ns = None;
            }
            devices.push(DeviceStatus {
                device: id.clone(),
                role: state.role,
                connected: state.client.is_some(),
                rates_hz: state.rates_hz.clone(),
                clock_offset_ns: state.clock.offset_ns(),
                clock_uncertainty_ns: state.clock.uncertainty_ns(),
                clock_jumps: state.clock_jumps_before + state.clock.jumps(),
                latency_ns: state.latency_ns,
                frames: state.frames,
            });
        }
        let viewers = inner.viewers.len();
        for viewer in inner.viewers.values() {
            let status = RelayMessage::Status {
                devices: devices.clone(),
                viewers,
                dropped: viewer.outbox.dropped(),
                relay_ns: now_ns,
                clock_offset_ns: viewer.clock.offset_ns(),
                clock_uncertainty_ns: viewer.clock.uncertainty_ns(),
            };
            viewer.outbox.set_status(to_json(&status));
        }
    }

    /// Frames queued for this room's clients.
    pub fn queued_frames(&self) -> usize {
        self.lock().viewers.values().map(|v| v.outbox.queued_frames()).sum()
    }

    /// Whether any viewer is connected.
    pub fn has_viewers(&self) -> bool {
        !self.lock().viewers.is_empty()
    }

    /// Closes every client with `close`; the room takes no one after.
    pub fn close(&self, close: Close) {
        let mut inner = self.lock();
        inner.closed = true;
        for device in inner.devices.values() {
            if let Some(outbox) = &device.outbox {
                outbox.close(close.clone());
            }
        }
        for viewer in inner.viewers.values() {
            viewer.outbox.close(close.clone());
        }
    }

    fn broadcast_channels(inner: &RoomInner) {
        let json = channels_json(&inner.channels);
        for viewer in inner.viewers.values() {
            viewer.outbox.set_channels(json.clone());
        }
    }
}

impl DeviceState {
    /// The room channel and relay stamp of a frame of `stream`: `stamp`, except that a
    /// stream's frames keep the device's order (a refined clock estimate never reorders them).
    fn place(&mut self, stream: Stream, device_ns: i64, stamp: i64) -> (u16, i64) {
        let stamp = match self.last_stamps.get(&stream) {
            Some(&(last_device, last_stamp)) if device_ns > last_device && stamp <= last_stamp => last_stamp + 1,
            _ => stamp,
        };
        self.last_stamps.insert(stream, (device_ns, stamp));
        (self.channels[&stream], stamp)
    }
}

/// Forwards a device's held frames on its clock estimate (none later than now).
fn release_held(inner: &mut RoomInner, limits: &LiveLimits, state: &mut DeviceState, now_ns: i64) {
    for (stream, device_ns, bytes) in std::mem::take(&mut state.held) {
        let stamp = state.clock.to_relay(device_ns).unwrap_or(now_ns).min(now_ns);
        let (channel, stamp) = state.place(stream, device_ns, stamp);
        forward(inner, limits, channel, stamp, &bytes, now_ns);
    }
}

fn current_device<'a>(inner: &'a mut RoomInner, device: &str, client: u32) -> Result<&'a mut DeviceState, Close> {
    match inner.devices.get_mut(device) {
        Some(state) if state.client == Some(client) => Ok(state),
        _ => Err(Close::new(CloseKind::Replaced, format!("device `{device}` connected again"))),
    }
}

/// Rewrites a device frame for viewers (room channel, relay stamp), keeps it in the channel's
/// history and queues it for every viewer.
fn forward(inner: &mut RoomInner, limits: &LiveLimits, channel: u16, stamp_ns: i64, frame: &[u8], now_ns: i64) {
    let mut bytes = BytesMut::from(frame);
    bytes[2..4].copy_from_slice(&channel.to_le_bytes());
    bytes[4..HEADER_BYTES].copy_from_slice(&stamp_ns.to_le_bytes());
    let bytes = bytes.freeze();
    if let Some(history) = inner.history.get_mut(usize::from(channel)) {
        history.push_back((stamp_ns, bytes.clone()));
        let oldest = stamp_ns - limits.history_ns();
        while history.len() > limits.history_frames || history.front().is_some_and(|(t, _)| *t < oldest) {
            history.pop_front();
        }
    }
    let deadline = now_ns.saturating_add(limits.live_deadline_ns());
    for viewer in inner.viewers.values() {
        viewer.outbox.push_frame(channel, bytes.clone(), deadline, now_ns);
    }
}

/// A camera the relay passes on: a plausible image size and a rigid `T_device_camera`.
fn check_camera(camera: &CameraCalibration) -> Result<(), Close> {
    let size_ok = (1..=16_384).contains(&camera.width) && (1..=16_384).contains(&camera.height);
    let rotation = camera.t_device_camera.rotation;
    let pose_ok = camera.t_device_camera.translation.is_finite()
        && rotation.is_finite()
        && (rotation.length() - 1.0).abs() < 1e-3
        && camera.t_device_camera.translation.length() < 10.0;
    let radius_ok = camera.valid_radius_px.is_none_or(|r| r.is_finite() && r > 0.0);
    if size_ok && pose_ok && radius_ok {
        Ok(())
    } else {
        Err(Close::new(
            CloseKind::Malformed,
            "calibration: expected an image of 1–16384 px a side and a rigid T_device_camera within 10 m",
        ))
    }
}

fn to_json(message: &RelayMessage) -> String {
    serde_json::to_string(message).unwrap_or_else(|_| String::from("{}"))
}

fn channels_json(channels: &[ChannelInfo]) -> String {
    to_json(&RelayMessage::Channels { channels: channels.to_vec() })
}

fn calibration_json(device: &str, camera: &CameraCalibration) -> String {
    to_json(&RelayMessage::Calibration { device: device.to_string(), camera: *camera })
}
