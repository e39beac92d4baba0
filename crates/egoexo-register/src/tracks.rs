//! The solver's inputs from a session: the wearer as seen from outside (target track) and
//! each observer camera's frames (view track), on one time axis: seconds after
//! an origin (the wearer's first head sample, [`origin_ns`]): f64 keeps nanoseconds over hours.

use egoexo_core::aligned::{AlignedSession, Timeline};
use egoexo_core::camera::{CameraCalibration, Projection};
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::skeleton::SmplSkeleton;
use egoexo_infer::CoarseBody;
use egoexo_session::align::{DEFAULT_MAX_GAP_NS, resample_trajectory};
use egoexo_session::model::{KeypointTrack, Session, Trajectory};
use egoexo_session::placement::Placement;
use egoexo_solve::registration::{
    PointSigmas, RegistrationError, TargetTrack, ViewFrame, ViewTrack, WearerBody, WearerSample,
};

/// A session's time origin: the wearer's first head sample (nanoseconds, session clock); 0
/// without one.
pub fn origin_ns(session: &Session) -> i64 {
    session.wearer.head.timestamps_ns.first().copied().unwrap_or(0)
}

pub(crate) fn seconds(t_ns: i64, origin_ns: i64) -> f64 {
    (t_ns as i128 - origin_ns as i128) as f64 * 1e-9
}

/// The wearer as seen from outside on `aligned`'s frames: the face from the head device
/// wherever tracked, and the body from `coarse` where EgoNet ran. Times: seconds after
/// `origin_ns`.
pub fn target_track(
    aligned: &AlignedSession,
    coarse: Option<&CoarseBody>,
    origin_ns: i64,
) -> Result<TargetTrack, RegistrationError> {
    let samples: Vec<WearerSample> = (0..aligned.timeline.frames)
        .map(|f| WearerSample {
            time_s: seconds(aligned.timeline.timestamp_ns(f), origin_ns),
            t_world_device: aligned.head.valid[f].then(|| aligned.head.poses[f]),
            joints: coarse.and_then(|c| c.joints.get(f).copied().flatten()),
        })
        .collect();
    let body = WearerBody {
        head_joint_in_device: aligned.head_joint_in_device,
        scale: aligned.skeleton.head_height() / SmplSkeleton::mean_shape().head_height(),
        sigmas: PointSigmas::default(),
    };
    TargetTrack::from_wearer(&samples, &body)
}

/// A camera's frames: at each of `times` (its clock, nanoseconds) the people it saw
/// (`people(i)`) and its pose then, interpolated on its device trajectory `head` (its own
/// world; frames where it was not tracked are dropped). Times: seconds after `origin_ns`.
pub fn view_track(
    head: &Trajectory,
    camera: &CameraCalibration,
    placement: &Placement,
    times: &[i64],
    people: impl Fn(usize) -> Vec<[Option<Keypoint2d>; COCO17_COUNT]>,
    origin_ns: i64,
) -> ViewTrack {
    let poses = resample_trajectory(head, times, DEFAULT_MAX_GAP_NS);
    let frames = times
        .iter()
        .enumerate()
        .filter(|&(i, _)| poses.valid[i])
        .map(|(i, &t)| ViewFrame {
            time_s: seconds(t, origin_ns),
            t_world_camera: poses.poses[i] * camera.t_device_camera,
            people: people(i),
        })
        .collect();
    let pinhole = matches!(camera.projection, Projection::Pinhole(_));
    ViewTrack { camera: *camera, estimate_focal: !placement.focal_known && pinhole, frames }
}

/// Observer `o` of `session`'s view of the wearer.
pub fn observer_view(session: &Session, o: usize, origin_ns: i64) -> ViewTrack {
    let observer = &session.observers[o];
    let empty = KeypointTrack::default();
    let keypoints = observer.keypoints.as_ref().unwrap_or(&empty);
    view_track(
        &observer.head,
        &observer.camera,
        &observer.placement,
        &keypoints.timestamps_ns,
        |i| vec![keypoints.frames[i]],
        origin_ns,
    )
}

/// Per frame of `timeline`: some observer of `observers` has keypoints within a margin of it
/// (`clock_margin_s` for one on its own clock), where the coarse body is worth computing.
pub(crate) fn frames_seen(
    session: &Session,
    timeline: &Timeline,
    observers: &[usize],
    clock_margin_s: f64,
) -> Vec<bool> {
    let views: Vec<(Vec<i64>, bool)> = observers
        .iter()
        .filter_map(|&o| {
            let observer = &session.observers[o];
            let own_clock = observer.placement.clock == egoexo_session::placement::ClockRef::Own;
            Some((observer.keypoints.as_ref()?.timestamps_ns.clone(), own_clock))
        })
        .collect();
    frames_seen_at(timeline, &views, clock_margin_s)
}

/// Per frame of `timeline`: one of `views` (keypoint times, on its own clock or not) has a
/// frame within a margin of it.
pub(crate) fn frames_seen_at(timeline: &Timeline, views: &[(Vec<i64>, bool)], clock_margin_s: f64) -> Vec<bool> {
    let mut seen = vec![false; timeline.frames];
    let fps = f64::from(timeline.fps);
    for (times, own_clock) in views {
        let margin = if *own_clock { clock_margin_s } else { 0.0 };
        for &t in times {
            let at = (t as i128 - timeline.start_ns as i128) as f64 * 1e-9 * fps;
            let (lo, hi) = ((at - margin * fps).floor(), (at + margin * fps).ceil());
            if hi < 0.0 || lo >= timeline.frames as f64 {
                continue;
            }
            let lo = lo.max(0.0) as usize;
            let hi = (hi as usize).min(timeline.frames - 1);
            seen[lo..=hi].iter_mut().for_each(|s| *s = true);
        }
    }
    seen
}
