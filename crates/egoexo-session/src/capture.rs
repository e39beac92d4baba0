//! Everyone in one recording: a [`Capture`] holds every participant — each with their own head
//! (and maybe wrist) tracking, maybe an RGB camera that sees the others, and what is known of
//! their body — and what each camera saw of the people in front of it, either already
//! assigned to a participant or as unidentified people per frame (which
//! [`egoexo_core::association`] assigns).
//!
//! The reconstruction itself stays single-wearer: [`Capture::session_for`] makes the
//! [`Session`] of one participant, whose observers are the other participants with a camera,
//! each bringing the keypoints assigned to that participant. A one-wearer [`Session`] (every
//! file before the multi-participant format) is a capture whose first participant is the
//! wearer and whose observers are participants that are not reconstructed
//! ([`Capture::from_session`]; [`Capture::session_for`] gives the same session back).
//!
//! Conventions as [`crate::model`]: session-clock nanoseconds, `T_world_device` poses in a
//! Y-up world (metres), CPF device frames, image pixels with the top-left pixel's centre at
//! (0, 0).

use egoexo_core::camera::CameraCalibration;
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::Vec3;
use egoexo_core::rigid::RigidTransform;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::model::{
    ContextFeatureTrack, Floor, GroundTruth, KeypointTrack, Observer, Session, SubjectInfo, Trajectory, VideoRef,
    Wearer, WristSource,
};
use crate::placement::{ClockRef, Mount, Placement, WorldRef};

/// The participant id a one-wearer session's wearer gets in a capture.
pub const WEARER_ID: &str = "wearer";

/// A recording of several people, each wearing glasses (or just being tracked).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Capture {
    /// Human-readable name.
    pub name: String,
    pub participants: Vec<Participant>,
    /// What each camera saw of the people in front of it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub views: Vec<View>,
    /// The floor all participants stand on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub floor: Option<Floor>,
}

/// One person of a capture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Participant {
    /// Unique within the capture (`"wearer"`, `"observer-1"`, an Aria serial, a name).
    pub id: String,
    /// Whether this participant's motion is reconstructed. A one-wearer session's observers
    /// are not: nobody's camera was pointed at them, and their devices were only there to
    /// see the wearer.
    pub reconstruct: bool,
    /// Glasses (CPF frame), `T_world_device`.
    pub head: Trajectory,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub left_wrist: Option<Trajectory>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub right_wrist: Option<Trajectory>,
    #[serde(default, skip_serializing_if = "WristSource::is_devices")]
    pub wrist_source: WristSource,
    /// SMPL head joint in the head-device frame, metres.
    pub head_joint_in_device: Vec3,
    /// The glasses' RGB camera, when its images (keypoints or video) are part of the capture.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraCalibration>,
    /// The RGB camera's video, for the detector step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<VideoRef>,
    /// Per-frame image context features of the RGB camera.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context_features: Option<ContextFeatureTrack>,
    pub subject: SubjectInfo,
    /// This participant's true motion (simulated captures).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_truth: Option<GroundTruth>,
    /// Their devices' world and clock against the capture's (the first participant's, or the
    /// registration anchor's), and any registration ([`crate::placement`]).
    #[serde(default, skip_serializing_if = "Placement::is_default")]
    pub placement: Placement,
}

/// What one participant's camera saw.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct View {
    /// The participant whose camera it is.
    pub observer: String,
    pub people: ViewPeople,
}

/// The people in one camera's images.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ViewPeople {
    /// One participant's keypoints (a one-wearer session's observers, or after association).
    Assigned { target: String, keypoints: KeypointTrack },
    /// Everyone the detector found, without identity: participants and bystanders alike.
    Unassigned(PeopleTrack),
}

/// Per-frame detections of any number of people, COCO-17 each (pixels in the camera's image,
/// scores in `[0, 1]`; a `None` keypoint was not detected).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PeopleTrack {
    pub timestamps_ns: Vec<i64>,
    pub frames: Vec<Vec<[Option<Keypoint2d>; COCO17_COUNT]>>,
}

/// Why a capture cannot give what was asked.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum CaptureError {
    #[error("the capture has no participant `{0}`")]
    NoSuchParticipant(String),
    #[error("participant `{0}` is not reconstructed (an observer only)")]
    NotReconstructed(String),
    #[error("participants {index} and {other} are both called `{id}`; expected unique ids")]
    DuplicateId { id: String, index: usize, other: usize },
    #[error("view {index} names observer `{observer}`, which is no participant with a camera")]
    ViewWithoutCamera { index: usize, observer: String },
    #[error(
        "view {index} ({observer}) assigns keypoints to `{target}`, which is no participant (or the observer itself)"
    )]
    BadTarget { index: usize, observer: String, target: String },
    #[error("view {index} ({observer}): {what} has {times} timestamps and {frames} frames; expected one per frame")]
    Lengths { index: usize, observer: String, what: &'static str, times: usize, frames: usize },
    #[error("participant `{observer}` has two views of `{target}` (views {index} and {other})")]
    DuplicateView { observer: String, target: String, index: usize, other: usize },
}

impl Participant {
    /// A participant to reconstruct from `wearer`'s devices, with their body (`subject`,
    /// `ground_truth`); no camera.
    pub fn wearing(id: &str, wearer: &Wearer, subject: SubjectInfo, ground_truth: Option<GroundTruth>) -> Self {
        Participant {
            id: id.to_owned(),
            reconstruct: true,
            head: wearer.head.clone(),
            left_wrist: wearer.left_wrist.clone(),
            right_wrist: wearer.right_wrist.clone(),
            wrist_source: wearer.wrist_source.clone(),
            head_joint_in_device: wearer.head_joint_in_device,
            camera: None,
            video: None,
            context_features: None,
            subject,
            ground_truth,
            placement: Placement::default(),
        }
    }

    /// A participant seen only through `observer`'s camera (not reconstructed): its head,
    /// camera, video and context features. `head_joint_in_device` is the capture's head
    /// device mounting (unused while they are not reconstructed).
    pub fn observing(observer: &Observer, head_joint_in_device: Vec3) -> Self {
        Participant {
            id: observer.id.clone(),
            reconstruct: false,
            head: observer.head.clone(),
            left_wrist: None,
            right_wrist: None,
            wrist_source: WristSource::Devices,
            head_joint_in_device,
            camera: Some(observer.camera),
            video: observer.video.clone(),
            context_features: observer.context_features.clone(),
            subject: SubjectInfo::default(),
            ground_truth: None,
            placement: observer.placement.clone(),
        }
    }
}

impl Capture {
    /// The one-wearer session as a capture: the wearer is participant [`WEARER_ID`] (index 0,
    /// reconstructed), every observer a participant that is not, and each observer's keypoints
    /// a view assigned to the wearer.
    pub fn from_session(session: &Session) -> Self {
        let wearer = &session.wearer;
        let mut participants =
            vec![Participant::wearing(WEARER_ID, wearer, session.subject.clone(), session.ground_truth.clone())];
        let mut views = Vec::new();
        for o in &session.observers {
            participants.push(Participant::observing(o, wearer.head_joint_in_device));
            if let Some(keypoints) = &o.keypoints {
                views.push(View {
                    observer: o.id.clone(),
                    people: ViewPeople::Assigned { target: WEARER_ID.to_owned(), keypoints: keypoints.clone() },
                });
            }
        }
        Self { name: session.name.clone(), participants, views, floor: session.floor.clone() }
    }

    /// Whether the capture is one session: one participant to reconstruct, every view
    /// assigned (what every file before version 3 is).
    pub fn is_one_session(&self) -> bool {
        self.reconstructed().count() == 1 && self.views.iter().all(|v| matches!(v.people, ViewPeople::Assigned { .. }))
    }

    /// The index of participant `id`.
    pub fn index_of(&self, id: &str) -> Result<usize, CaptureError> {
        self.participants.iter().position(|p| p.id == id).ok_or_else(|| CaptureError::NoSuchParticipant(id.into()))
    }

    /// The participants that are reconstructed, by index.
    pub fn reconstructed(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.participants.len()).filter(|&p| self.participants[p].reconstruct)
    }

    /// The keypoints view `observer` has of `target`, if assigned.
    pub fn assigned_keypoints(&self, observer: &str, target: &str) -> Option<&KeypointTrack> {
        self.views.iter().find_map(|v| match &v.people {
            ViewPeople::Assigned { target: t, keypoints } if v.observer == observer && t == target => Some(keypoints),
            _ => None,
        })
    }

    /// Checks ids, views and track lengths.
    pub fn validate(&self) -> Result<(), CaptureError> {
        for (index, p) in self.participants.iter().enumerate() {
            if let Some(other) = self.participants[..index].iter().position(|q| q.id == p.id) {
                return Err(CaptureError::DuplicateId { id: p.id.clone(), index: other, other: index });
            }
        }
        for (index, view) in self.views.iter().enumerate() {
            let observer = view.observer.clone();
            if !self.participants.iter().any(|p| p.id == view.observer && p.camera.is_some()) {
                return Err(CaptureError::ViewWithoutCamera { index, observer });
            }
            let (what, times, frames) = match &view.people {
                ViewPeople::Assigned { target, keypoints } => {
                    if target == &view.observer || !self.participants.iter().any(|p| &p.id == target) {
                        return Err(CaptureError::BadTarget { index, observer, target: target.clone() });
                    }
                    if let Some(other) = self.views[..index].iter().position(|v| {
                        v.observer == view.observer
                            && matches!(&v.people, ViewPeople::Assigned { target: t, .. } if t == target)
                    }) {
                        return Err(CaptureError::DuplicateView {
                            observer,
                            target: target.clone(),
                            index: other,
                            other: index,
                        });
                    }
                    ("keypoints", keypoints.timestamps_ns.len(), keypoints.frames.len())
                }
                ViewPeople::Unassigned(people) => ("people", people.timestamps_ns.len(), people.frames.len()),
            };
            if times != frames {
                return Err(CaptureError::Lengths { index, observer, what, times, frames });
            }
        }
        Ok(())
    }

    /// The one-wearer session that reconstructs participant `index`: their devices and body as
    /// the wearer; every other participant with a camera as an observer (capture order),
    /// bringing the keypoints assigned to this participant (none when there are none yet: a
    /// view without identity must be associated first, [`egoexo_core::association`]).
    pub fn session_for(&self, index: usize) -> Result<Session, CaptureError> {
        let p = self.participants.get(index).ok_or_else(|| CaptureError::NoSuchParticipant(format!("#{index}")))?;
        if !p.reconstruct {
            return Err(CaptureError::NotReconstructed(p.id.clone()));
        }
        let observers = self
            .participants
            .iter()
            .enumerate()
            .filter(|&(o, _)| o != index)
            .filter_map(|(_, o)| {
                let camera = o.camera?;
                Some(Observer {
                    id: o.id.clone(),
                    head: o.head.clone(),
                    camera,
                    keypoints: self.assigned_keypoints(&o.id, &p.id).cloned(),
                    video: o.video.clone(),
                    context_features: o.context_features.clone(),
                    placement: placement_seen_from(&p.placement, &o.placement),
                })
            })
            .collect();
        // A one-wearer session keeps its name; a participant of several gets theirs added.
        let several = self.reconstructed().count() > 1 || p.id != WEARER_ID;
        Ok(Session {
            name: if several { format!("{} · {}", self.name, p.id) } else { self.name.clone() },
            wearer: Wearer {
                head: p.head.clone(),
                left_wrist: p.left_wrist.clone(),
                right_wrist: p.right_wrist.clone(),
                wrist_source: p.wrist_source.clone(),
                head_joint_in_device: p.head_joint_in_device,
            },
            observers,
            subject: p.subject.clone(),
            ground_truth: p.ground_truth.clone(),
            floor: self.floor.clone(),
        })
    }
}

/// An observer's placement in the session of a wearer: both placements are against the
/// capture's world. When the wearer's world is the capture's, the observer's placement as it
/// is; when it is the wearer's own, the observer's world (and clock) is another: a
/// registration into the capture's world says nothing of the wearer's own.
fn placement_seen_from(wearer: &Placement, observer: &Placement) -> Placement {
    if wearer.world == WorldRef::Shared && wearer.clock == ClockRef::Shared {
        return observer.clone();
    }
    let mut seen = observer.clone();
    if wearer.world == WorldRef::Own {
        seen.world = WorldRef::Own;
        seen.registration = None;
    }
    if wearer.clock == ClockRef::Own {
        seen.clock = ClockRef::Own;
    }
    seen
}

/// Spans every static camera's one pose over the recording: its trajectory becomes that pose
/// at the first and the last time of the wearer's head and the camera's keypoints (what
/// alignment interpolates over). Readers call it once the whole session is read.
pub fn spread_fixed_poses(session: &mut Session) {
    let head = session.wearer.head.time_range_ns();
    for observer in session.observers.iter_mut().filter(|o| o.placement.mount == Mount::Fixed) {
        let keypoints =
            observer.keypoints.as_ref().and_then(|k| Some((*k.timestamps_ns.first()?, *k.timestamps_ns.last()?)));
        spread(&mut observer.head, [head, keypoints]);
    }
}

/// [`spread_fixed_poses`] for a capture: over every worn device's trajectory and every view.
pub fn spread_fixed_poses_in_capture(capture: &mut Capture) {
    let mut ranges: Vec<Option<(i64, i64)>> = capture
        .participants
        .iter()
        .filter(|p| p.placement.mount == Mount::Worn)
        .map(|p| p.head.time_range_ns())
        .collect();
    for view in &capture.views {
        let times = match &view.people {
            ViewPeople::Assigned { keypoints, .. } => &keypoints.timestamps_ns,
            ViewPeople::Unassigned(people) => &people.timestamps_ns,
        };
        ranges.push(times.first().zip(times.last()).map(|(a, b)| (*a, *b)));
    }
    for p in capture.participants.iter_mut().filter(|p| p.placement.mount == Mount::Fixed) {
        spread(&mut p.head, ranges.iter().copied());
    }
}

fn spread(trajectory: &mut Trajectory, ranges: impl IntoIterator<Item = Option<(i64, i64)>>) {
    let pose = trajectory.poses.first().copied().unwrap_or(RigidTransform::IDENTITY);
    let (start, end) = ranges.into_iter().flatten().fold((i64::MAX, i64::MIN), |(a, b), (s, e)| (a.min(s), b.max(e)));
    let (start, end) = if start > end { (0, 1) } else { (start, end.max(start.saturating_add(1))) };
    *trajectory = Trajectory { timestamps_ns: vec![start, end], poses: vec![pose; 2] };
}

#[cfg(test)]
mod tests {
    use egoexo_core::camera::{Pinhole, Projection};
    use egoexo_core::glam::Vec2;
    use egoexo_core::rigid::RigidTransform;

    use super::*;

    fn trajectory(x: f32) -> Trajectory {
        Trajectory {
            timestamps_ns: vec![0, 33_333_333],
            poses: vec![RigidTransform::from_translation(Vec3::new(x, 1.6, 0.0)); 2],
        }
    }

    fn camera() -> CameraCalibration {
        let projection = Projection::Pinhole(Pinhole::new(300.0, 300.0, 320.0, 240.0).unwrap());
        CameraCalibration::new(projection, 640, 480, RigidTransform::IDENTITY).unwrap()
    }

    fn keypoints(x: f32) -> KeypointTrack {
        let k = Keypoint2d { pixel: Vec2::new(x, 100.0), score: 0.9 };
        KeypointTrack { timestamps_ns: vec![0, 33_333_333], frames: vec![[Some(k); COCO17_COUNT]; 2] }
    }

    fn session() -> Session {
        Session {
            name: "walk".into(),
            wearer: Wearer {
                head: trajectory(0.0),
                left_wrist: None,
                right_wrist: None,
                wrist_source: WristSource::Devices,
                head_joint_in_device: Vec3::new(0.0, -0.1, -0.1),
            },
            observers: ["observer-1", "observer-2"]
                .iter()
                .enumerate()
                .map(|(i, id)| Observer {
                    id: (*id).into(),
                    head: trajectory(2.0 + i as f32),
                    camera: camera(),
                    keypoints: (i == 0).then(|| keypoints(10.0)),
                    video: None,
                    context_features: None,
                    placement: Placement::default(),
                })
                .collect(),
            subject: SubjectInfo { height_m: Some(1.8), ..Default::default() },
            ground_truth: None,
            floor: None,
        }
    }

    #[test]
    fn a_one_wearer_session_round_trips_through_a_capture() {
        let session = session();
        let capture = Capture::from_session(&session);
        capture.validate().unwrap();
        assert_eq!(capture.participants.len(), 3);
        assert_eq!(capture.reconstructed().collect::<Vec<_>>(), [0]);
        assert_eq!(capture.views.len(), 1, "observer-2 brought no keypoints");
        assert_eq!(capture.session_for(0).unwrap(), session);
        assert_eq!(capture.session_for(1), Err(CaptureError::NotReconstructed("observer-1".into())));
    }

    #[test]
    fn each_participant_is_the_wearer_of_their_own_session_and_the_others_observe() {
        let mut capture = Capture::from_session(&session());
        for p in &mut capture.participants {
            p.reconstruct = true;
            p.camera = Some(camera());
        }
        // observer-2 saw observer-1; the wearer's camera saw observer-2.
        capture.views.push(View {
            observer: "observer-2".into(),
            people: ViewPeople::Assigned { target: "observer-1".into(), keypoints: keypoints(20.0) },
        });
        capture.views.push(View {
            observer: WEARER_ID.into(),
            people: ViewPeople::Assigned { target: "observer-2".into(), keypoints: keypoints(30.0) },
        });
        capture.validate().unwrap();
        let first = capture.session_for(1).unwrap();
        assert_eq!(first.name, "walk · observer-1");
        assert_eq!(first.wearer.head, trajectory(2.0));
        let ids: Vec<_> = first.observers.iter().map(|o| o.id.as_str()).collect();
        assert_eq!(ids, [WEARER_ID, "observer-2"]);
        assert_eq!(first.observers[0].keypoints, None, "the wearer's camera never saw observer-1");
        assert_eq!(first.observers[1].keypoints, Some(keypoints(20.0)));
        let second = capture.session_for(2).unwrap();
        assert_eq!(second.observers[0].keypoints, Some(keypoints(30.0)));
        assert_eq!(second.observers[1].id, "observer-1");
    }

    #[test]
    fn inconsistent_captures_are_refused_with_the_reason() {
        let base = Capture::from_session(&session());
        let mut twice = base.clone();
        twice.participants[2].id = "observer-1".into();
        assert!(matches!(twice.validate(), Err(CaptureError::DuplicateId { index: 1, other: 2, .. })));
        let mut blind = base.clone();
        blind.views[0].observer = WEARER_ID.into();
        assert!(matches!(blind.validate(), Err(CaptureError::ViewWithoutCamera { .. })));
        let mut nobody = base.clone();
        nobody.views[0].people = ViewPeople::Assigned { target: "nobody".into(), keypoints: keypoints(1.0) };
        assert!(nobody.validate().unwrap_err().to_string().contains("`nobody`"));
        let mut short = base.clone();
        short.views.push(View {
            observer: "observer-2".into(),
            people: ViewPeople::Unassigned(PeopleTrack { timestamps_ns: vec![0], frames: vec![] }),
        });
        assert!(matches!(short.validate(), Err(CaptureError::Lengths { index: 1, times: 1, frames: 0, .. })));
        let mut again = base;
        again.views.push(again.views[0].clone());
        assert!(matches!(again.validate(), Err(CaptureError::DuplicateView { index: 0, other: 1, .. })));
    }
}
