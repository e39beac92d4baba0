//! Association over a whole capture: every camera's unidentified people
//! ([`ViewPeople::Unassigned`]) become keypoint tracks of the participants they are
//! ([`ViewPeople::Assigned`]), frame by frame, by matching each detection against every
//! participant's EgoNet joints projected into that camera ([`associate`]). Detections that
//! match nobody (bystanders) are counted and dropped.
//!
//! The caller runs EgoNet on each reconstructed participant's own session
//! ([`Capture::session_for`], aligned) and hands the results in as [`CoarseParticipant`]s; the
//! observer's pose comes from that same aligned session, so everything is on one clock and in
//! one world.

use std::collections::BTreeMap;

use egoexo_core::aligned::{AlignedObserver, AlignedSession};
use egoexo_core::association::{AssociationOptions, associate};
use egoexo_core::exo_keypoints::{COCO17_COUNT, ExoKeypoint, Keypoint2d};
use egoexo_core::glam::Vec2;
use egoexo_core::skeleton::NUM_JOINTS;
use egoexo_infer::Reconstruction;
use egoexo_session::capture::{Capture, View, ViewPeople};
use egoexo_session::model::KeypointTrack;
use serde::{Deserialize, Serialize};

/// One participant's coarse pose: their index in the capture, their aligned session (from
/// [`Capture::session_for`]) and EgoNet's reconstruction on its timeline.
#[derive(Clone, Copy, Debug)]
pub struct CoarseParticipant<'a> {
    pub participant: usize,
    pub aligned: &'a AlignedSession,
    pub coarse: &'a Reconstruction,
}

/// How far outside an observer image's valid region (a fraction of the image width) a
/// participant's projected joint still counts for association: a body at the edge of the view
/// is detected by what is inside while a slightly wrong coarse pose or observer pose puts most
/// of its projection just outside.
pub const ASSOCIATION_MARGIN: f32 = 0.15;

/// The COCO-17 keypoints a coarse pose puts in an observer's image at aligned frame `frame`
/// (the head joint stands in for no COCO point, so the nose stays `None`; keypoints further
/// than `margin_px` outside the image's valid region are `None`); `None` when the wearer or
/// the observer is not tracked at that frame.
pub fn project_coarse(
    coarse: &Reconstruction,
    observer: &AlignedObserver,
    frame: usize,
    margin_px: f32,
) -> Option<[Option<Vec2>; COCO17_COUNT]> {
    let tracked = coarse.valid.get(frame).copied().unwrap_or(false)
        && observer.head.valid.get(frame).copied().unwrap_or(false)
        && coarse.joints.get(frame).is_some();
    if !tracked {
        return None;
    }
    let (camera, pose) = (&observer.camera, &observer.head.poses[frame]);
    let joints: &[_; NUM_JOINTS] = &coarse.joints[frame];
    let mut expected = [None; COCO17_COUNT];
    for k in ExoKeypoint::ALL.into_iter().skip(1) {
        expected[k.coco17_index()] = camera
            .project_world(joints[k.smpl_joint().index()], pose)
            .filter(|px| camera.is_near_valid_pixel(*px, margin_px));
    }
    Some(expected)
}

/// The aligned frame nearest session time `time_ns`, if on the timeline.
pub fn nearest_frame(aligned: &AlignedSession, time_ns: i64) -> Option<usize> {
    let timeline = &aligned.timeline;
    let position = ((time_ns - timeline.start_ns) as f64 * f64::from(timeline.fps) / 1e9).round();
    (position >= 0.0 && (position as usize) < timeline.frames).then_some(position as usize)
}

/// What association did with one camera's unidentified people.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ViewAssociation {
    /// The participant whose camera it is.
    pub observer: String,
    pub frames: usize,
    /// People detected over all frames.
    pub detections: usize,
    /// Detections assigned, per participant id.
    pub assigned: BTreeMap<String, usize>,
    /// Detections that matched no participant (bystanders, or a participant far from their
    /// coarse pose).
    pub unassigned: usize,
    /// Per frame, per detection (as listed): the participant index it was assigned to.
    #[serde(skip)]
    pub assignment: Vec<Vec<Option<usize>>>,
}

/// Replaces every unassigned view of `capture` by one assigned view per participant that
/// `coarse` covers and the camera has no keypoints of yet (a participant none of whose frames
/// matched gets a track of frames without keypoints); returns what each unassigned view's
/// association did, in view order.
pub fn associate_views(
    capture: &mut Capture,
    coarse: &[CoarseParticipant<'_>],
    options: &AssociationOptions,
) -> Vec<ViewAssociation> {
    let mut reports = Vec::new();
    let mut views = Vec::with_capacity(capture.views.len());
    // (observer, target) pairs the capture already has keypoints for: kept as they are.
    let assigned: Vec<(String, String)> = capture
        .views
        .iter()
        .filter_map(|v| match &v.people {
            ViewPeople::Assigned { target, .. } => Some((v.observer.clone(), target.clone())),
            ViewPeople::Unassigned(_) => None,
        })
        .collect();
    for view in std::mem::take(&mut capture.views) {
        let ViewPeople::Unassigned(people) = &view.people else {
            views.push(view);
            continue;
        };
        // The participants this camera can see: everyone with a coarse pose whose session has
        // this camera as an observer (not its owner) and that it has no keypoints of yet.
        let targets: Vec<(&CoarseParticipant<'_>, &AlignedObserver)> = coarse
            .iter()
            .filter(|c| {
                let id = capture.participants.get(c.participant).map(|p| p.id.as_str());
                !assigned.iter().any(|(o, t)| *o == view.observer && Some(t.as_str()) == id)
            })
            .filter_map(|c| Some((c, c.aligned.observers.iter().find(|o| o.id == view.observer)?)))
            .collect();
        let mut tracks: Vec<Vec<[Option<Keypoint2d>; COCO17_COUNT]>> =
            vec![vec![[None; COCO17_COUNT]; people.frames.len()]; targets.len()];
        let mut report =
            ViewAssociation { observer: view.observer.clone(), frames: people.frames.len(), ..Default::default() };
        for (f, (&time_ns, detections)) in people.timestamps_ns.iter().zip(&people.frames).enumerate() {
            let expected: Vec<_> = targets
                .iter()
                .map(|(c, observer)| {
                    let margin = ASSOCIATION_MARGIN * observer.camera.width as f32;
                    nearest_frame(c.aligned, time_ns).and_then(|a| project_coarse(c.coarse, observer, a, margin))
                })
                .collect();
            let assignment = associate(&expected, detections, options);
            for (d, assigned) in assignment.iter().enumerate() {
                report.detections += 1;
                match assigned {
                    Some(t) => {
                        tracks[*t][f] = detections[d];
                        *report
                            .assigned
                            .entry(capture.participants[targets[*t].0.participant].id.clone())
                            .or_default() += 1;
                    }
                    None => report.unassigned += 1,
                }
            }
            report.assignment.push(assignment.iter().map(|a| a.map(|t| targets[t].0.participant)).collect());
        }
        for ((c, _), frames) in targets.iter().zip(tracks) {
            views.push(View {
                observer: view.observer.clone(),
                people: ViewPeople::Assigned {
                    target: capture.participants[c.participant].id.clone(),
                    keypoints: KeypointTrack { timestamps_ns: people.timestamps_ns.clone(), frames },
                },
            });
        }
        reports.push(report);
    }
    capture.views = views;
    reports
}
