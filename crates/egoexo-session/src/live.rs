//! A live take: the frames a viewer receives from the relay (`egoexo_protocol::live`),
//! gathered by device and stream into an ordinary [`Session`] — for the streaming
//! reconstruction (a window of the last seconds) and for "Stop and keep" (the whole take).
//!
//! Timestamps are the relay's clock (nanoseconds), so every device is on one clock already.
//! A pose a device sent as invalid (tracking lost) is left out, so alignment sees a gap and
//! marks those frames invalid; a stale pose is never repeated. Frames that arrive twice (the
//! history a viewer gets again when it reconnects) are kept once.
//!
//! A room may hold several wearers (a capture of several participants): each is a session of
//! its own ([`LiveTake::to_session_of`]) with the observers that name them as their target
//! (an observer naming none belongs to the room's only wearer), and the whole take is a
//! [`Capture`] ([`LiveTake::to_capture`]). The frame grid runs from the first head pose of
//! the wearer who streamed theirs first.

use std::collections::BTreeMap;
use std::ops::RangeInclusive;

use egoexo_core::camera::CameraCalibration;
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::rigid::RigidTransform;
use egoexo_protocol::live::{
    ChannelInfo, DataFrame, DeviceHello, DeviceMount, DeviceRole, DeviceWorld, FramePayload, Stream, valid_device_id,
};

use crate::capture::{Capture, CaptureError, Participant, View, ViewPeople};
use crate::model::{KeypointTrack, Observer, Session, SubjectInfo, Trajectory, Wearer, WristSource};
use crate::placement::{Mount, Placement, WorldRef};
use crate::validate::validate_session;
use crate::{ImportError, ImportWarning};

type Keypoints = [Option<Keypoint2d>; COCO17_COUNT];

/// What became of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameAdded {
    Added,
    /// The same stream already has a frame at this time.
    Duplicate,
    /// The channel is not (yet) in the room's channel list.
    UnknownChannel,
    /// A pose frame on a keypoints channel or the reverse.
    WrongKind,
}

/// Counts of what a take received.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TakeStats {
    /// Frames kept.
    pub frames: u64,
    /// Of those, poses sent as invalid (tracking lost).
    pub lost_tracking: u64,
    pub duplicates: u64,
    pub unknown_channel: u64,
    pub wrong_kind: u64,
}

/// Why a take is not a session (yet).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TakeError {
    #[error("no valid head pose from a wearer device in {0}; a take needs the wearer's head")]
    NoWearerHead(String),
    #[error("the take is not a valid session: {0}")]
    Invalid(#[from] ImportError),
    #[error("no wearer `{0}` in the take")]
    NoSuchWearer(String),
    #[error("the take is not a valid capture: {0}")]
    Capture(#[from] CaptureError),
    #[error("`{0}` is not a live device id (1–64 of A–Z a–z 0–9 . _ -)")]
    DeviceId(String),
}

/// One device of a capture as it streams into a live room ([`capture_devices`]).
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureDevice {
    pub hello: DeviceHello,
    /// An observer's camera (sent as its calibration).
    pub camera: Option<CameraCalibration>,
    /// Its pose streams.
    pub poses: Vec<(Stream, Trajectory)>,
    /// An observer's keypoints (of its target).
    pub keypoints: Option<KeypointTrack>,
}

/// A capture's devices as they stream into a live room (what [`LiveTake::to_capture`] reads
/// back): every participant to reconstruct a wearer under their id (`head`, and the wrists
/// they have); every camera's keypoints of a participant an observer `<camera>-sees-<target>`
/// that names its target (the camera's head, calibration and those keypoints). A capture of
/// one participant to reconstruct keeps the observers' own ids and names no target (a room
/// of one wearer). Views of people without identity are left out: a live observer streams one
/// person's keypoints.
pub fn capture_devices(capture: &Capture) -> Result<Vec<CaptureDevice>, TakeError> {
    let one_wearer = capture.reconstructed().count() == 1;
    let mut devices = Vec::new();
    for p in capture.participants.iter().filter(|p| p.reconstruct) {
        let mut poses = vec![(Stream::Head, p.head.clone())];
        poses.extend(p.left_wrist.clone().map(|w| (Stream::LeftWrist, w)));
        poses.extend(p.right_wrist.clone().map(|w| (Stream::RightWrist, w)));
        devices.push(CaptureDevice {
            hello: DeviceHello {
                world: device_world(&p.placement),
                ..DeviceHello::worn(&p.id, DeviceRole::Wearer, poses.iter().map(|(s, _)| *s).collect())
            },
            camera: None,
            poses,
            keypoints: None,
        });
    }
    // A room of one wearer: cameras that see nobody yet still stream their pose (as a
    // recording's observers without keypoints do).
    for p in capture.participants.iter().filter(|p| one_wearer && !p.reconstruct) {
        let (Some(calibration), false) = (p.camera, capture.views.iter().any(|v| v.observer == p.id)) else { continue };
        if p.placement.mount == Mount::Fixed {
            continue; // a static camera that sees nobody streams nothing
        }
        devices.push(CaptureDevice {
            hello: DeviceHello {
                world: device_world(&p.placement),
                ..DeviceHello::worn(&p.id, DeviceRole::Observer, vec![Stream::Head])
            },
            camera: Some(calibration),
            poses: vec![(Stream::Head, p.head.clone())],
            keypoints: None,
        });
    }
    for view in &capture.views {
        let ViewPeople::Assigned { target, keypoints } = &view.people else { continue };
        let Some(camera) = capture.participants.iter().find(|p| p.id == view.observer) else { continue };
        let Some(calibration) = camera.camera else { continue };
        let (id, target) = if one_wearer {
            (view.observer.clone(), None)
        } else {
            (format!("{}-sees-{target}", view.observer), Some(target.clone()))
        };
        // A static camera streams its keypoints only: viewers place it by registration.
        let fixed = camera.placement.mount == Mount::Fixed;
        let (streams, poses) = if fixed {
            (vec![Stream::Keypoints], Vec::new())
        } else {
            (vec![Stream::Head, Stream::Keypoints], vec![(Stream::Head, camera.head.clone())])
        };
        devices.push(CaptureDevice {
            hello: DeviceHello {
                target,
                world: if fixed { DeviceWorld::Own } else { device_world(&camera.placement) },
                mount: if fixed { DeviceMount::Fixed } else { DeviceMount::Worn },
                focal_known: camera.placement.focal_known || !fixed,
                ..DeviceHello::worn(id, DeviceRole::Observer, streams)
            },
            camera: Some(calibration),
            poses,
            keypoints: Some(keypoints.clone()),
        });
    }
    if let Some(bad) = devices.iter().find(|d| !valid_device_id(&d.hello.id)) {
        return Err(TakeError::DeviceId(bad.hello.id.clone()));
    }
    Ok(devices)
}

/// The live world of a participant placed by `placement`: a live device is on the relay's
/// clock and always has a pose stream, so only the world can be its own.
fn device_world(placement: &Placement) -> DeviceWorld {
    match placement.world {
        WorldRef::Shared => DeviceWorld::Shared,
        WorldRef::Own => DeviceWorld::Own,
    }
}

/// An observer's placement in a live session: its world is the wearer's only when both said
/// they share the room's world; else its own (gravity-aligned, on the relay's clock), to be
/// registered before it is fused.
fn live_placement(observer: DeviceWorld, wearer: DeviceWorld) -> Placement {
    match (observer, wearer) {
        (DeviceWorld::Shared, DeviceWorld::Shared) => Placement::default(),
        _ => Placement { world: WorldRef::Own, ..Placement::default() },
    }
}

/// A static camera's trajectory in a live take: its one pose, the identity (its world is its
/// own device frame, placed by registration), at every time it has keypoints and at the
/// wearer's first and last head pose (what alignment interpolates over). Empty when it has no
/// keypoints: it contributes nothing.
fn fixed_camera_trajectory(keypoint_times: impl Iterator<Item = i64>, wearer_head: &Trajectory) -> Trajectory {
    let mut times: std::collections::BTreeSet<i64> = keypoint_times.collect();
    if times.is_empty() {
        return Trajectory::default();
    }
    times.extend(wearer_head.time_range_ns().map(|(a, b)| [a, b]).into_iter().flatten());
    let timestamps_ns: Vec<i64> = times.into_iter().collect();
    let poses = vec![RigidTransform::IDENTITY; timestamps_ns.len()];
    Trajectory { timestamps_ns, poses }
}

/// One device's streams.
#[derive(Debug)]
struct DeviceTake {
    role: Option<DeviceRole>,
    /// An observer's target wearer, when it names one.
    target: Option<String>,
    /// Its world, as its hello said.
    world: DeviceWorld,
    /// Worn, or a static camera without a pose, as its hello said.
    mount: DeviceMount,
    /// Whether its focal length is measured, as its hello said.
    focal_known: bool,
    poses: BTreeMap<Stream, BTreeMap<i64, Option<RigidTransform>>>,
    keypoints: BTreeMap<i64, Keypoints>,
    camera: Option<CameraCalibration>,
}

impl Default for DeviceTake {
    fn default() -> Self {
        Self {
            role: None,
            target: None,
            world: DeviceWorld::Shared,
            mount: DeviceMount::Worn,
            focal_known: true,
            poses: BTreeMap::new(),
            keypoints: BTreeMap::new(),
            camera: None,
        }
    }
}

/// A take being recorded.
#[derive(Debug, Default)]
pub struct LiveTake {
    channels: BTreeMap<u16, ChannelInfo>,
    devices: BTreeMap<String, DeviceTake>,
    stats: TakeStats,
    /// The wearer whose head pose arrived first: the take's frame grid is theirs, so a wearer
    /// joining later never moves it.
    first_wearer: Option<String>,
}

impl LiveTake {
    pub fn new() -> Self {
        Self::default()
    }

    /// The room's channel list (the relay's `channels` message): later frames are filed by it.
    pub fn set_channels(&mut self, channels: &[ChannelInfo]) {
        for channel in channels {
            self.channels.insert(channel.channel, channel.clone());
            let device = self.devices.entry(channel.device.clone()).or_default();
            device.role = Some(channel.role);
            device.target.clone_from(&channel.target);
            device.world = channel.world;
            device.mount = channel.mount;
            device.focal_known = channel.focal_known;
        }
    }

    /// An observer's camera (the relay's `calibration` message).
    pub fn set_camera(&mut self, device: &str, camera: CameraCalibration) {
        self.devices.entry(device.to_string()).or_default().camera = Some(camera);
    }

    /// Files a frame from the relay (room channel, relay clock).
    pub fn add_frame(&mut self, frame: &DataFrame) -> FrameAdded {
        let Some(info) = self.channels.get(&frame.channel) else {
            self.stats.unknown_channel += 1;
            return FrameAdded::UnknownChannel;
        };
        if info.role == DeviceRole::Wearer && info.stream == Stream::Head && self.first_wearer.is_none() {
            self.first_wearer = Some(info.device.clone());
        }
        let device = self.devices.entry(info.device.clone()).or_default();
        let fresh = match (&frame.payload, info.stream) {
            (FramePayload::Keypoints(points), Stream::Keypoints) => {
                device.keypoints.insert(frame.timestamp_ns, *points).is_none()
            }
            (FramePayload::Pose(pose), stream) if stream != Stream::Keypoints => {
                let fresh = device.poses.entry(stream).or_default().insert(frame.timestamp_ns, *pose).is_none();
                if fresh && pose.is_none() {
                    self.stats.lost_tracking += 1;
                }
                fresh
            }
            _ => {
                self.stats.wrong_kind += 1;
                return FrameAdded::WrongKind;
            }
        };
        if fresh {
            self.stats.frames += 1;
            FrameAdded::Added
        } else {
            self.stats.duplicates += 1;
            FrameAdded::Duplicate
        }
    }

    pub fn stats(&self) -> TakeStats {
        self.stats
    }

    /// Whether a device of the take said its world is its own, or is a static camera without
    /// a pose (one of its own too).
    pub fn has_own_worlds(&self) -> bool {
        self.devices.values().any(|d| d.world == DeviceWorld::Own || d.mount == DeviceMount::Fixed)
    }

    /// The wearers whose head has streamed: the first to stream it (whose head is the take's
    /// frame grid), then the others by device id.
    pub fn wearers(&self) -> Vec<String> {
        let mut wearers: Vec<String> = self
            .devices
            .iter()
            .filter(|(_, d)| {
                d.role == Some(DeviceRole::Wearer) && d.poses.get(&Stream::Head).is_some_and(|h| !h.is_empty())
            })
            .map(|(id, _)| id.clone())
            .collect();
        if let Some(first) = wearers.iter().position(|w| Some(w) == self.first_wearer.as_ref()) {
            let first = wearers.remove(first);
            wearers.insert(0, first);
        }
        wearers
    }

    fn wearer_stream(&self, wearer: &str, stream: Stream) -> Option<&BTreeMap<i64, Option<RigidTransform>>> {
        self.devices.get(wearer).filter(|d| d.role == Some(DeviceRole::Wearer)).and_then(|d| d.poses.get(&stream))
    }

    /// First and last time of the (first) wearer's head stream (relay clock, ns).
    pub fn head_range_ns(&self) -> Option<(i64, i64)> {
        let head = self.wearer_stream(self.wearers().first()?, Stream::Head)?;
        Some((*head.keys().next()?, *head.keys().next_back()?))
    }

    /// Frames kept per device and stream (wire names: `wearer` → `head` → 1234).
    pub fn frame_counts(&self) -> BTreeMap<String, BTreeMap<String, u64>> {
        let mut out: BTreeMap<String, BTreeMap<String, u64>> = BTreeMap::new();
        for (id, device) in &self.devices {
            let counts = out.entry(id.clone()).or_default();
            counts.extend(device.poses.iter().map(|(s, p)| (s.name().to_string(), p.len() as u64)));
            if !device.keypoints.is_empty() {
                counts.insert(Stream::Keypoints.name().to_string(), device.keypoints.len() as u64);
            }
        }
        out.retain(|_, counts| !counts.is_empty());
        out
    }

    /// The take (or the part of it within `range`, relay ns) as a session named `name`:
    /// the wearer's head and wrists, and every observer with a camera and a head trajectory
    /// (an observer without a camera yet cannot place its keypoints and is left out, with a
    /// warning). The session is validated; its warnings come back with it.
    pub fn to_session(
        &self,
        name: &str,
        range: Option<RangeInclusive<i64>>,
    ) -> Result<(Session, Vec<ImportWarning>), TakeError> {
        match self.wearers().first() {
            Some(wearer) => self.to_session_of(wearer, name, range),
            None => Err(TakeError::NoWearerHead(name.to_string())),
        }
    }

    /// Wearer `wearer`'s part of the take as a session: their head and wrists, and the
    /// observers that see them (those naming them as their target; in a room of one wearer,
    /// also those naming nobody).
    pub fn to_session_of(
        &self,
        wearer: &str,
        name: &str,
        range: Option<RangeInclusive<i64>>,
    ) -> Result<(Session, Vec<ImportWarning>), TakeError> {
        if self.devices.get(wearer).is_none_or(|d| d.role != Some(DeviceRole::Wearer)) {
            return Err(TakeError::NoSuchWearer(wearer.to_string()));
        }
        let range = range.unwrap_or(i64::MIN..=i64::MAX);
        let trajectory = |poses: &BTreeMap<i64, Option<RigidTransform>>| trajectory_in(poses, &range);
        let head = self.wearer_stream(wearer, Stream::Head).map(trajectory).unwrap_or_default();
        if head.is_empty() {
            return Err(TakeError::NoWearerHead(name.to_string()));
        }
        // A wrist needs two samples to be interpolated at all.
        let wrist = |stream| self.wearer_stream(wearer, stream).map(trajectory).filter(|t| t.len() >= 2);
        let several = self.wearers().len() > 1;
        let wearer_world = self.devices.get(wearer).map_or(DeviceWorld::Shared, |d| d.world);
        let mut warnings = Vec::new();
        let mut observers = Vec::new();
        for (id, device) in self.devices.iter().filter(|(_, d)| d.role == Some(DeviceRole::Observer)) {
            match &device.target {
                Some(target) if target != wearer => continue,
                None if several => {
                    warnings.push(ImportWarning {
                        file: format!("observers/{id}"),
                        message: "names no target wearer in a room of several; left out".into(),
                    });
                    continue;
                }
                _ => {}
            }
            let fixed = device.mount == DeviceMount::Fixed;
            let head = if fixed {
                fixed_camera_trajectory(device.keypoints.range(range.clone()).map(|(t, _)| *t), &head)
            } else {
                device.poses.get(&Stream::Head).map(trajectory).unwrap_or_default()
            };
            let Some(camera) = device.camera else {
                warnings.push(ImportWarning {
                    file: format!("observers/{id}"),
                    message: "no camera calibration received; left out".into(),
                });
                continue;
            };
            if head.is_empty() {
                continue;
            }
            let mut keypoints = KeypointTrack::default();
            for (&ts, frame) in device.keypoints.range(range.clone()) {
                keypoints.timestamps_ns.push(ts);
                keypoints.frames.push(*frame);
            }
            observers.push(Observer {
                id: id.clone(),
                head,
                camera,
                keypoints: (!keypoints.frames.is_empty()).then_some(keypoints),
                video: None,
                context_features: None,
                placement: if fixed {
                    Placement::fixed_unposed(device.focal_known)
                } else {
                    live_placement(device.world, wearer_world)
                },
            });
        }
        let session = Session {
            name: name.to_string(),
            wearer: Wearer {
                head,
                left_wrist: wrist(Stream::LeftWrist),
                right_wrist: wrist(Stream::RightWrist),
                wrist_source: WristSource::Devices,
                head_joint_in_device: egoexo_core::skeleton::DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE,
            },
            observers,
            subject: SubjectInfo::default(),
            ground_truth: None,
            floor: None,
        };
        warnings.extend(validate_session(&session)?);
        Ok((session, warnings))
    }

    /// The whole take as a capture named `name`: every wearer a participant to reconstruct
    /// and every observer of theirs (the observers [`LiveTake::to_session_of`] gives them) a
    /// participant seen only through their camera, whose keypoints are a view of that wearer.
    pub fn to_capture(&self, name: &str) -> Result<(Capture, Vec<ImportWarning>), TakeError> {
        let wearers = self.wearers();
        if wearers.is_empty() {
            return Err(TakeError::NoWearerHead(name.to_string()));
        }
        let mut warnings: Vec<ImportWarning> = Vec::new();
        let mut participants = Vec::new();
        let mut views = Vec::new();
        let mut observers = Vec::new();
        for id in &wearers {
            let (session, found) = self.to_session_of(id, name, None)?;
            for w in found {
                if !warnings.contains(&w) {
                    warnings.push(w);
                }
            }
            let head_joint = session.wearer.head_joint_in_device;
            let mut participant = Participant::wearing(id, &session.wearer, SubjectInfo::default(), None);
            if self.devices.get(id).is_some_and(|d| d.world == DeviceWorld::Own) {
                participant.placement = Placement { world: WorldRef::Own, ..Placement::default() };
            }
            participants.push(participant);
            for o in session.observers {
                if let Some(keypoints) = &o.keypoints {
                    views.push(View {
                        observer: o.id.clone(),
                        people: ViewPeople::Assigned { target: id.clone(), keypoints: keypoints.clone() },
                    });
                }
                observers.push(Participant::observing(&o, head_joint));
            }
        }
        participants.extend(observers);
        let capture = Capture { name: name.to_string(), participants, views, floor: None };
        capture.validate()?;
        Ok((capture, warnings))
    }
}

/// The valid poses of `poses` within `range` as a trajectory.
fn trajectory_in(poses: &BTreeMap<i64, Option<RigidTransform>>, range: &RangeInclusive<i64>) -> Trajectory {
    let mut t = Trajectory::default();
    for (&ts, pose) in poses.range(range.clone()) {
        if let Some(pose) = pose {
            t.timestamps_ns.push(ts);
            t.poses.push(*pose);
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use egoexo_core::camera::{Pinhole, Projection};
    use egoexo_core::glam::{Quat, Vec2, Vec3};

    const MS: i64 = 1_000_000;

    fn channels() -> Vec<ChannelInfo> {
        let c = |channel, device: &str, role, stream| {
            ChannelInfo::of(channel, &DeviceHello::worn(device, role, vec![]), stream)
        };
        vec![
            c(0, "wearer", DeviceRole::Wearer, Stream::Head),
            c(1, "wearer", DeviceRole::Wearer, Stream::LeftWrist),
            c(2, "observer-1", DeviceRole::Observer, Stream::Head),
            c(3, "observer-1", DeviceRole::Observer, Stream::Keypoints),
        ]
    }

    fn pose(ts: i64, channel: u16, valid: bool) -> DataFrame {
        let p =
            RigidTransform { rotation: Quat::from_rotation_y(0.1), translation: Vec3::new(0.0, 1.6, ts as f32 / 1e9) };
        DataFrame { channel, timestamp_ns: ts, payload: FramePayload::Pose(valid.then_some(p)) }
    }

    fn camera() -> CameraCalibration {
        CameraCalibration::new(
            Projection::Pinhole(Pinhole::new(500.0, 500.0, 320.0, 240.0).unwrap()),
            640,
            480,
            RigidTransform::IDENTITY,
        )
        .unwrap()
    }

    #[test]
    fn frames_become_a_session_on_the_relay_clock() {
        let mut take = LiveTake::new();
        // A frame before the channel list cannot be filed.
        assert_eq!(take.add_frame(&pose(0, 0, true)), FrameAdded::UnknownChannel);
        take.set_channels(&channels());
        for i in 0..90 {
            let ts = i * 11 * MS;
            // Tracking lost for frames 40..45.
            assert_eq!(take.add_frame(&pose(ts, 0, !(40..45).contains(&i))), FrameAdded::Added);
            if i % 3 == 0 {
                take.add_frame(&pose(ts, 1, true));
                take.add_frame(&pose(ts + MS, 2, true));
                let points = [Some(Keypoint2d { pixel: Vec2::new(300.0, 200.0), score: 0.9 }); COCO17_COUNT];
                take.add_frame(&DataFrame {
                    channel: 3,
                    timestamp_ns: ts + 2 * MS,
                    payload: FramePayload::Keypoints(points),
                });
            }
        }
        // History received again after a reconnect: kept once.
        assert_eq!(take.add_frame(&pose(0, 0, true)), FrameAdded::Duplicate);
        assert_eq!(take.add_frame(&pose(5, 3, true)), FrameAdded::WrongKind);
        // Without a camera the observer is left out, with a warning.
        let (session, warnings) = take.to_session("take", None).unwrap();
        assert!(session.observers.is_empty() && warnings.iter().any(|w| w.to_string().contains("no camera")));
        take.set_camera("observer-1", camera());
        let (session, _) = take.to_session("take", None).unwrap();
        assert_eq!(session.wearer.head.len(), 85);
        assert_eq!(session.wearer.left_wrist.as_ref().unwrap().len(), 30);
        assert!(session.wearer.right_wrist.is_none());
        assert_eq!(session.observers[0].keypoints.as_ref().unwrap().frames.len(), 30);
        let stats = take.stats();
        assert_eq!((stats.frames, stats.lost_tracking, stats.duplicates), (90 + 3 * 30, 5, 1));
        // A window of the take.
        let (window, _) = take.to_session("window", Some(500 * MS..=800 * MS)).unwrap();
        assert!(window.wearer.head.timestamps_ns.iter().all(|t| (500 * MS..=800 * MS).contains(t)));
        assert_eq!(take.head_range_ns(), Some((0, 89 * 11 * MS)));
        let counts = take.frame_counts();
        assert_eq!(counts["wearer"], BTreeMap::from([("head".into(), 90), ("left-wrist".into(), 30)]));
        assert_eq!(counts["observer-1"], BTreeMap::from([("head".into(), 30), ("keypoints".into(), 30)]));
    }

    #[test]
    fn a_fixed_camera_is_one_unknown_pose_in_a_world_of_its_own_over_its_keypoints() {
        let webcam = DeviceHello {
            mount: DeviceMount::Fixed,
            focal_known: false,
            ..DeviceHello::worn("webcam", DeviceRole::Observer, vec![Stream::Keypoints])
        };
        let mut take = LiveTake::new();
        take.set_channels(&[
            ChannelInfo::of(0, &DeviceHello::worn("wearer", DeviceRole::Wearer, vec![]), Stream::Head),
            ChannelInfo::of(1, &webcam, Stream::Keypoints),
        ]);
        take.set_camera("webcam", camera());
        for i in 0..60 {
            take.add_frame(&pose(i * 33 * MS, 0, true));
        }
        // No keypoints yet: nothing to contribute, left out.
        assert!(take.to_session("take", None).unwrap().0.observers.is_empty());
        assert!(take.has_own_worlds());
        let points = [Some(Keypoint2d { pixel: Vec2::new(300.0, 200.0), score: 0.9 }); COCO17_COUNT];
        for i in 10..40 {
            take.add_frame(&DataFrame {
                channel: 1,
                timestamp_ns: i * 33 * MS + 5 * MS,
                payload: FramePayload::Keypoints(points),
            });
        }
        let (session, _) = take.to_session("take", None).unwrap();
        let observer = &session.observers[0];
        assert_eq!(observer.placement, Placement::fixed_unposed(false));
        // The identity at every keypoint time and at the head's ends.
        assert_eq!(observer.head.len(), 30 + 2);
        assert!(observer.head.poses.iter().all(|p| *p == RigidTransform::IDENTITY));
        assert_eq!(observer.head.time_range_ns(), Some((0, 59 * 33 * MS)));
        // A window holds the keypoints inside it, and the window's head ends.
        let (window, _) = take.to_session("window", Some(500 * MS..=800 * MS)).unwrap();
        let head = &window.observers[0].head;
        assert!(head.timestamps_ns.iter().all(|t| (500 * MS..=800 * MS).contains(t)), "{head:?}");
        assert_eq!(window.observers[0].keypoints.as_ref().unwrap().frames.len(), head.len() - 2);
    }

    #[test]
    fn a_room_of_two_wearers_is_a_session_each_and_one_capture() {
        let c = |channel, device: &str, role, stream, target: Option<&str>| {
            let hello = DeviceHello { target: target.map(Into::into), ..DeviceHello::worn(device, role, vec![]) };
            ChannelInfo::of(channel, &hello, stream)
        };
        let mut take = LiveTake::new();
        take.set_channels(&[
            c(0, "bob", DeviceRole::Wearer, Stream::Head, None),
            c(1, "alice", DeviceRole::Wearer, Stream::Head, None),
            c(2, "bob-sees-alice", DeviceRole::Observer, Stream::Head, Some("alice")),
            c(3, "bob-sees-alice", DeviceRole::Observer, Stream::Keypoints, Some("alice")),
            c(4, "alice-sees-bob", DeviceRole::Observer, Stream::Head, Some("bob")),
            c(5, "stray", DeviceRole::Observer, Stream::Head, None),
        ]);
        for device in ["bob-sees-alice", "alice-sees-bob", "stray"] {
            take.set_camera(device, camera());
        }
        let points = [Some(Keypoint2d { pixel: Vec2::new(300.0, 200.0), score: 0.9 }); COCO17_COUNT];
        for i in 0..30 {
            let ts = i * 33 * MS;
            for channel in [0, 1, 2, 4, 5] {
                take.add_frame(&pose(ts + i64::from(channel) * MS, channel, true));
            }
            take.add_frame(&DataFrame { channel: 3, timestamp_ns: ts, payload: FramePayload::Keypoints(points) });
        }
        // Bob's head came first: the grid is his, whoever joins later.
        assert_eq!(take.wearers(), ["bob", "alice"]);
        assert_eq!(take.head_range_ns(), Some((0, 29 * 33 * MS)));
        let (alice, warnings) = take.to_session_of("alice", "take", None).unwrap();
        assert_eq!(alice.observers.iter().map(|o| o.id.as_str()).collect::<Vec<_>>(), ["bob-sees-alice"]);
        assert_eq!(alice.observers[0].keypoints.as_ref().unwrap().frames.len(), 30);
        assert!(
            warnings.iter().any(|w| w.file == "observers/stray" && w.message.contains("no target")),
            "{warnings:?}"
        );
        let (bob, _) = take.to_session_of("bob", "take", None).unwrap();
        assert_eq!(bob.observers.iter().map(|o| o.id.as_str()).collect::<Vec<_>>(), ["alice-sees-bob"]);
        assert!(bob.observers[0].keypoints.is_none());
        assert_eq!(take.to_session("take", None).unwrap().0.wearer.head, bob.wearer.head);
        assert!(matches!(take.to_session_of("stray", "t", None), Err(TakeError::NoSuchWearer(_))));

        let (capture, _) = take.to_capture("take").unwrap();
        let ids: Vec<_> = capture.participants.iter().map(|p| (p.id.as_str(), p.reconstruct)).collect();
        assert_eq!(ids, [("bob", true), ("alice", true), ("alice-sees-bob", false), ("bob-sees-alice", false)]);
        assert_eq!(capture.views.len(), 1, "only bob's camera sent keypoints (of alice)");
        // Reconstructing alice from the capture: the same session as from the take.
        let from_capture = capture.session_for(1).unwrap();
        assert_eq!(from_capture.wearer.head, alice.wearer.head);
        assert_eq!(from_capture.observers.iter().find(|o| o.keypoints.is_some()).unwrap().id, "bob-sees-alice");
    }

    #[test]
    fn a_take_needs_the_wearer_head() {
        let mut take = LiveTake::new();
        take.set_channels(&channels());
        take.add_frame(&pose(0, 2, true));
        assert!(matches!(take.to_session("t", None), Err(TakeError::NoWearerHead(_))));
    }
}
