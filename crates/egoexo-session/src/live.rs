//! A live take: the frames a viewer receives from the relay (`egoexo_protocol::live`),
//! gathered by device and stream into an ordinary [`Session`] — for the streaming
//! reconstruction (a window of the last seconds) and for "Stop and keep" (the whole take).
//!
//! Timestamps are the relay's clock (nanoseconds), so every device is on one clock already.
//! A pose a device sent as invalid (tracking lost) is left out, so alignment sees a gap and
//! marks those frames invalid; a stale pose is never repeated. Frames that arrive twice (the
//! history a viewer gets again when it reconnects) are kept once.

use std::collections::BTreeMap;
use std::ops::RangeInclusive;

use egoexo_core::camera::CameraCalibration;
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::rigid::RigidTransform;
use egoexo_protocol::live::{ChannelInfo, DataFrame, DeviceRole, FramePayload, Stream};

use crate::model::{KeypointTrack, Observer, Session, SubjectInfo, Trajectory, Wearer, WristSource};
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
}

/// One device's streams.
#[derive(Debug, Default)]
struct DeviceTake {
    role: Option<DeviceRole>,
    poses: BTreeMap<Stream, BTreeMap<i64, Option<RigidTransform>>>,
    keypoints: BTreeMap<i64, Keypoints>,
    camera: Option<CameraCalibration>,
}

/// A take being recorded.
#[derive(Debug, Default)]
pub struct LiveTake {
    channels: BTreeMap<u16, ChannelInfo>,
    devices: BTreeMap<String, DeviceTake>,
    stats: TakeStats,
}

impl LiveTake {
    pub fn new() -> Self {
        Self::default()
    }

    /// The room's channel list (the relay's `channels` message): later frames are filed by it.
    pub fn set_channels(&mut self, channels: &[ChannelInfo]) {
        for channel in channels {
            self.channels.insert(channel.channel, channel.clone());
            self.devices.entry(channel.device.clone()).or_default().role = Some(channel.role);
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

    fn wearer_stream(&self, stream: Stream) -> Option<&BTreeMap<i64, Option<RigidTransform>>> {
        self.devices.values().filter(|d| d.role == Some(DeviceRole::Wearer)).find_map(|d| d.poses.get(&stream))
    }

    /// First and last time of the wearer's head stream (relay clock, ns).
    pub fn head_range_ns(&self) -> Option<(i64, i64)> {
        let head = self.wearer_stream(Stream::Head)?;
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
        let range = range.unwrap_or(i64::MIN..=i64::MAX);
        let trajectory = |poses: &BTreeMap<i64, Option<RigidTransform>>| {
            let mut t = Trajectory::default();
            for (&ts, pose) in poses.range(range.clone()) {
                if let Some(pose) = pose {
                    t.timestamps_ns.push(ts);
                    t.poses.push(*pose);
                }
            }
            t
        };
        let head = self.wearer_stream(Stream::Head).map(trajectory).unwrap_or_default();
        if head.is_empty() {
            return Err(TakeError::NoWearerHead(name.to_string()));
        }
        // A wrist needs two samples to be interpolated at all.
        let wrist = |stream| self.wearer_stream(stream).map(trajectory).filter(|t| t.len() >= 2);
        let mut warnings = Vec::new();
        let mut observers = Vec::new();
        for (id, device) in self.devices.iter().filter(|(_, d)| d.role == Some(DeviceRole::Observer)) {
            let head = device.poses.get(&Stream::Head).map(trajectory).unwrap_or_default();
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use egoexo_core::camera::{Pinhole, Projection};
    use egoexo_core::glam::{Quat, Vec2, Vec3};

    const MS: i64 = 1_000_000;

    fn channels() -> Vec<ChannelInfo> {
        let c = |channel, device: &str, role, stream| ChannelInfo { channel, device: device.into(), role, stream };
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
    fn a_take_needs_the_wearer_head() {
        let mut take = LiveTake::new();
        take.set_channels(&channels());
        take.add_frame(&pose(0, 2, true));
        assert!(matches!(take.to_session("t", None), Err(TakeError::NoWearerHead(_))));
    }
}
