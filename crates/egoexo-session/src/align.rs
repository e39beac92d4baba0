//! Time alignment: every stream of a [`Session`] resampled onto one fixed-rate timeline, an
//! [`AlignedSession`] (defined in `egoexo_core::aligned`, the engine's input type) — what
//! reconstruction, the simulator's shards and the viewer consume.
//!
//! Conventions as in [`crate::model`]. Frame `i` of a [`Timeline`] is at
//! `start_ns + round(i · 1e9 / fps)`.

use egoexo_core::aligned::{
    AlignedGroundTruth, AlignedObserver, AlignedSession, AlignedTrajectory, StreamCoverage, Timeline,
};
use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, Keypoint2d, exo_from_coco17};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::SmplPose;

use crate::model::{Session, Trajectory};

/// Default output rate, frames per second (the networks are trained at this rate).
pub const DEFAULT_FPS: f32 = 30.0;

/// Alignment choices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlignOptions {
    /// Output rate, frames per second.
    pub fps: f32,
    /// Longest gap between two trajectory samples that interpolation bridges, nanoseconds.
    /// Frames inside a longer gap are invalid.
    pub max_gap_ns: i64,
    /// Largest time difference between a frame and the keypoint detection (or context
    /// feature) assigned to it, nanoseconds; `None` = half a frame period.
    pub keypoint_tolerance_ns: Option<i64>,
    /// Most frames a timeline may have (a guard against absurd time ranges).
    pub max_frames: usize,
}

impl Default for AlignOptions {
    /// 30 fps; gaps up to 100 ms bridged; keypoints within half a frame; at most 10 million
    /// frames (~93 hours at 30 fps).
    fn default() -> Self {
        Self { fps: DEFAULT_FPS, max_gap_ns: DEFAULT_MAX_GAP_NS, keypoint_tolerance_ns: None, max_frames: 10_000_000 }
    }
}

/// Default bridging limit: 100 ms (three frames at 30 fps).
pub const DEFAULT_MAX_GAP_NS: i64 = 100_000_000;

/// The bridging limit of a wrist trajectory: `max_gap_ns`, or 1.5 of its median sample
/// interval when that is longer. MPS hand tracking runs at the SLAM cameras' rate, 10 Hz in
/// many recordings (samples 100.002 ms apart): consecutive tracked samples are bridged, a
/// missed sample (a gap of two intervals) is not.
pub fn wrist_max_gap_ns(trajectory: &Trajectory, max_gap_ns: i64) -> i64 {
    let mut intervals: Vec<i64> = trajectory.timestamps_ns.windows(2).map(|w| w[1] - w[0]).collect();
    if intervals.is_empty() {
        return max_gap_ns;
    }
    let mid = intervals.len() / 2;
    let (_, median, _) = intervals.select_nth_unstable(mid);
    max_gap_ns.max(median.saturating_mul(3) / 2)
}

/// Why a session could not be aligned.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum AlignError {
    #[error("frame rate must be in (0, 1000] fps, got {0}")]
    InvalidFps(f32),
    #[error("the bridging limit must be positive, got {0} ns")]
    InvalidGap(i64),
    #[error("the keypoint tolerance must be positive, got {0} ns")]
    InvalidTolerance(i64),
    #[error("the wearer's head trajectory is empty; it defines the timeline")]
    EmptyHead,
    #[error(
        "the head trajectory spans {span_s:.1} s, which at {fps} fps is {frames} frames, over the limit of {limit}"
    )]
    TooManyFrames { span_s: f64, fps: f32, frames: u128, limit: usize },
    #[error("the session is invalid: {0}")]
    Invalid(#[from] crate::error::ImportError),
}

/// Resamples every stream of a session onto one timeline spanning the wearer's head
/// trajectory (frame 0 at its first sample, the last frame at or before its last sample).
///
/// Trajectories: slerp + lerp ([`RigidTransform::interpolate`]) between the two samples around
/// a frame when they are at most [`AlignOptions::max_gap_ns`] apart; frames outside a
/// trajectory's range or inside a longer gap are invalid (identity pose). Keypoints: the
/// detection nearest to the frame time within the tolerance, mapped to the K = 13 with
/// `exo_from_coco17`; none otherwise (detections are never interpolated). Context features:
/// likewise. Ground truth: per-joint slerp and translation lerp between its two frames
/// around the time (its frames are regular, so every time inside its range is valid);
/// occlusion masks from the nearest ground-truth frame (ties: the earlier). The session is
/// validated first.
pub fn align(session: &Session, options: &AlignOptions) -> Result<AlignedSession, AlignError> {
    if !(options.fps.is_finite() && options.fps > 0.0 && options.fps <= 1000.0) {
        return Err(AlignError::InvalidFps(options.fps));
    }
    if options.max_gap_ns <= 0 {
        return Err(AlignError::InvalidGap(options.max_gap_ns));
    }
    let frame_ns = 1e9 / f64::from(options.fps);
    let tolerance = options.keypoint_tolerance_ns.unwrap_or((frame_ns / 2.0).round() as i64);
    if tolerance <= 0 {
        return Err(AlignError::InvalidTolerance(tolerance));
    }
    let (first, last) = session.wearer.head.time_range_ns().ok_or(AlignError::EmptyHead)?;
    crate::validate::validate_session(session)?;
    let span = (last as i128 - first as i128) as f64;
    // Frame i lies at `first + round(i · frame_ns)`; keep every frame not after `last`.
    let frames = ((span + 0.5) / frame_ns).floor() as u128 + 1;
    if frames > options.max_frames as u128 {
        return Err(AlignError::TooManyFrames {
            span_s: span / 1e9,
            fps: options.fps,
            frames,
            limit: options.max_frames,
        });
    }
    let timeline = Timeline { start_ns: first, fps: options.fps, frames: frames as usize };
    align_on_timeline(session, timeline, options)
}

/// [`align`] onto a given timeline instead of one spanning the head trajectory: the live
/// reconstruction resamples each window of a take on one fixed 30 fps grid, so a frame keeps
/// its time from window to window. Frames the head does not cover are invalid.
pub fn align_on_timeline(
    session: &Session,
    timeline: Timeline,
    options: &AlignOptions,
) -> Result<AlignedSession, AlignError> {
    if !(timeline.fps.is_finite() && timeline.fps > 0.0 && timeline.fps <= 1000.0) {
        return Err(AlignError::InvalidFps(timeline.fps));
    }
    if timeline.frames > options.max_frames {
        return Err(AlignError::TooManyFrames {
            span_s: timeline.frames as f64 / f64::from(timeline.fps),
            fps: timeline.fps,
            frames: timeline.frames as u128,
            limit: options.max_frames,
        });
    }
    if session.wearer.head.is_empty() {
        return Err(AlignError::EmptyHead);
    }
    crate::validate::validate_session(session)?;
    let frame_ns = 1e9 / f64::from(timeline.fps);
    let tolerance = options.keypoint_tolerance_ns.unwrap_or((frame_ns / 2.0).round() as i64);
    let times: Vec<i64> = (0..timeline.frames).map(|i| timeline.timestamp_ns(i)).collect();

    let mut coverage = Vec::new();
    let mut cover = |stream: String, valid: usize| {
        coverage.push(StreamCoverage { stream, valid_frames: valid, frames: timeline.frames })
    };

    let head = resample_trajectory(&session.wearer.head, &times, options.max_gap_ns);
    cover("wearer/head".into(), count(&head.valid));
    let wrist = |t: &Trajectory| resample_trajectory(t, &times, wrist_max_gap_ns(t, options.max_gap_ns));
    let left_wrist = session.wearer.left_wrist.as_ref().map(wrist);
    let right_wrist = session.wearer.right_wrist.as_ref().map(wrist);
    if let Some(w) = &left_wrist {
        cover("wearer/left_wrist".into(), count(&w.valid));
    }
    if let Some(w) = &right_wrist {
        cover("wearer/right_wrist".into(), count(&w.valid));
    }

    let mut observers = Vec::with_capacity(session.observers.len());
    for observer in &session.observers {
        // An observer not known to share the wearer's world and clock (`placement`) keeps its
        // slot (indices follow the session's) but brings nothing: no tracked frame, no
        // keypoint, no feature — its rays would be drawn from the wrong place.
        let fused = observer.placement.fusable();
        let mut head = resample_trajectory(&observer.head, &times, options.max_gap_ns);
        if !fused {
            head.valid.fill(false);
        }
        cover(format!("{}/head", observer.id), count(&head.valid));
        let keypoints: Vec<[Option<Keypoint2d>; EXO_KEYPOINT_COUNT]> = match &observer.keypoints {
            Some(track) if fused => times
                .iter()
                .map(|&t| match nearest(&track.timestamps_ns, t, tolerance) {
                    Some(i) => track.frames.get(i).map_or([None; EXO_KEYPOINT_COUNT], exo_from_coco17),
                    None => [None; EXO_KEYPOINT_COUNT],
                })
                .collect(),
            _ => vec![[None; EXO_KEYPOINT_COUNT]; timeline.frames],
        };
        if observer.keypoints.is_some() {
            cover(
                format!("{}/keypoints", observer.id),
                keypoints.iter().filter(|f| f.iter().any(Option::is_some)).count(),
            );
        }
        let context_features = observer.context_features.as_ref().filter(|_| fused).map(|track| {
            times
                .iter()
                .map(|&t| {
                    let i = nearest(&track.timestamps_ns, t, tolerance)?;
                    track.values.get(i * track.dim..(i + 1) * track.dim).map(<[f32]>::to_vec)
                })
                .collect::<Vec<_>>()
        });
        if let Some(f) = &context_features {
            cover(format!("{}/context_features", observer.id), f.iter().filter(|v| v.is_some()).count());
        }
        observers.push(AlignedObserver {
            id: observer.id.clone(),
            camera: observer.camera,
            head,
            keypoints,
            context_features,
        });
    }

    let ground_truth = session.ground_truth.as_ref().map(|gt| {
        let motion = &gt.motion;
        let mut poses = Vec::with_capacity(timeline.frames);
        let mut valid = Vec::with_capacity(timeline.frames);
        let mut nearest_frame = Vec::with_capacity(timeline.frames);
        let n = motion.len();
        for &t in &times {
            let x = (t as i128 - motion.start_ns as i128) as f64 * f64::from(motion.fps) / 1e9;
            if n == 0 || x < -1e-6 || x > (n - 1) as f64 + 1e-6 {
                poses.push(SmplPose::rest());
                valid.push(false);
                nearest_frame.push(None);
                continue;
            }
            let x = x.clamp(0.0, (n - 1) as f64);
            let i = (x.floor() as usize).min(n - 1);
            let j = (i + 1).min(n - 1);
            let alpha = (x - i as f64) as f32;
            poses.push(motion.poses[i].interpolate(&motion.poses[j], alpha));
            valid.push(true);
            nearest_frame.push(Some(if alpha <= 0.5 { i } else { j }));
        }
        let occluded = session
            .observers
            .iter()
            .map(|o| match gt.occlusion.iter().find(|occ| occ.observer_id == o.id) {
                Some(occ) => {
                    nearest_frame.iter().map(|f| f.and_then(|f| occ.occluded.get(f).copied()).unwrap_or(0)).collect()
                }
                None => vec![0; timeline.frames],
            })
            .collect();
        AlignedGroundTruth { poses, valid, occluded }
    });
    if let Some(gt) = &ground_truth {
        cover("ground_truth".into(), count(&gt.valid));
    }

    let skeleton = session.subject.skeleton().map_err(|e| {
        crate::error::ImportError::invalid(
            &session.name,
            crate::error::Location::Field("subject".into()),
            "a valid skeleton",
            e.to_string(),
        )
    })?;
    Ok(AlignedSession {
        name: session.name.clone(),
        timeline,
        head,
        left_wrist,
        right_wrist,
        observers,
        skeleton,
        head_joint_in_device: session.wearer.head_joint_in_device,
        ground_truth,
        coverage,
        floor_y: crate::floor::floor_or_estimate(session).map(|f| f.height_m),
    })
}

fn count(valid: &[bool]) -> usize {
    valid.iter().filter(|&&v| v).count()
}

/// Index of the timestamp nearest to `t` within `tolerance` (ties: the earlier one).
fn nearest(timestamps: &[i64], t: i64, tolerance: i64) -> Option<usize> {
    let i = timestamps.partition_point(|&x| x < t);
    let before = i.checked_sub(1).map(|j| (j, t.abs_diff(timestamps[j])));
    let after = timestamps.get(i).map(|&x| (i, x.abs_diff(t)));
    let best = match (before, after) {
        (Some(b), Some(a)) => Some(if a.1 < b.1 { a } else { b }),
        (b, a) => b.or(a),
    }?;
    (best.1 <= tolerance as u64).then_some(best.0)
}

/// Samples a trajectory at `times` (sorted): interpolation between the bracketing samples when
/// they are at most `max_gap_ns` apart, an exact sample when a time coincides with one. (Also
/// how `egoexo live replay` puts a recorded trajectory at a headset's rate.)
pub fn resample_trajectory(trajectory: &Trajectory, times: &[i64], max_gap_ns: i64) -> AlignedTrajectory {
    let ts = &trajectory.timestamps_ns;
    let mut poses = Vec::with_capacity(times.len());
    let mut valid = Vec::with_capacity(times.len());
    let mut i = 0;
    for &t in times {
        // First sample at or after t.
        while i < ts.len() && ts[i] < t {
            i += 1;
        }
        let sample = match (i.checked_sub(1), ts.get(i)) {
            (_, Some(&exact)) if exact == t => trajectory.poses.get(i).copied(),
            (Some(b), Some(&after)) if i128::from(after) - i128::from(ts[b]) <= i128::from(max_gap_ns) => {
                let alpha = ((i128::from(t) - i128::from(ts[b])) as f64
                    / (i128::from(after) - i128::from(ts[b])) as f64) as f32;
                match (trajectory.poses.get(b), trajectory.poses.get(i)) {
                    (Some(p0), Some(p1)) => Some(p0.interpolate(p1, alpha)),
                    _ => None,
                }
            }
            _ => None,
        };
        valid.push(sample.is_some());
        poses.push(sample.unwrap_or(RigidTransform::IDENTITY));
    }
    AlignedTrajectory { poses, valid }
}

#[cfg(test)]
mod tests {
    use egoexo_core::camera::{CameraCalibration, Pinhole, Projection};
    use egoexo_core::exo_keypoints::COCO17_COUNT;
    use egoexo_core::glam::{Quat, Vec2, Vec3};
    use egoexo_core::motion::SmplMotion;

    use super::*;
    use crate::model::{GroundTruth, KeypointTrack, Observer, ObserverOcclusion, SubjectInfo, Wearer};

    const MS: i64 = 1_000_000;

    fn trajectory(times_ms: &[i64]) -> Trajectory {
        Trajectory {
            timestamps_ns: times_ms.iter().map(|t| t * MS).collect(),
            poses: times_ms
                .iter()
                .map(|&t| {
                    RigidTransform::new(Quat::from_rotation_y(t as f32 * 1e-3), Vec3::new(t as f32 * 1e-3, 1.6, 0.0))
                })
                .collect(),
        }
    }

    fn session(head: Trajectory) -> Session {
        Session {
            name: "t".into(),
            wearer: Wearer {
                head,
                left_wrist: None,
                right_wrist: None,
                wrist_source: Default::default(),
                head_joint_in_device: Vec3::new(0.0, -0.06, -0.09),
            },
            observers: Vec::new(),
            subject: SubjectInfo::default(),
            ground_truth: None,
            floor: None,
        }
    }

    fn observer(id: &str, head: Trajectory, keypoint_times_ms: &[i64]) -> Observer {
        let kp = |t: i64| Some(Keypoint2d { pixel: Vec2::new(t as f32, 0.0), score: 0.9 });
        Observer {
            id: id.into(),
            head,
            camera: CameraCalibration::new(
                Projection::Pinhole(Pinhole::new(500.0, 500.0, 320.0, 240.0).unwrap()),
                640,
                480,
                RigidTransform::IDENTITY,
            )
            .unwrap(),
            keypoints: Some(KeypointTrack {
                timestamps_ns: keypoint_times_ms.iter().map(|t| t * MS).collect(),
                frames: keypoint_times_ms
                    .iter()
                    .map(|&t| std::array::from_fn::<_, COCO17_COUNT, _>(|_| kp(t)))
                    .collect(),
            }),
            video: None,
            context_features: None,
            placement: crate::placement::Placement::default(),
        }
    }

    #[test]
    fn an_observer_in_its_own_world_brings_nothing_until_registered() {
        use crate::placement::{ClockRef, Placement, RegistrationRecord, WorldRef};
        use egoexo_solve::registration::{Registration, RegistrationStatus};
        let times: Vec<i64> = (0..=1000).step_by(10).collect();
        let mut s = session(trajectory(&times));
        for id in ["shared", "own", "own-clock", "registered", "inconsistent"] {
            s.observers.push(observer(id, trajectory(&times), &[100, 500, 900]));
        }
        s.observers[1].placement.world = WorldRef::Own;
        s.observers[2].placement.clock = ClockRef::Own;
        let record = |status| RegistrationRecord {
            result: Registration { status, ..Registration::as_given(90, 80, 3.0, 2.7, None, String::new()) },
            applied: true,
        };
        s.observers[3].placement =
            Placement { registration: Some(record(RegistrationStatus::Registered)), ..Placement::default() };
        s.observers[4].placement =
            Placement { registration: Some(record(RegistrationStatus::Inconsistent)), ..Placement::default() };
        let a = align(&s, &AlignOptions::default()).unwrap();
        let brings = |o: usize| {
            a.observers[o].head.valid.iter().any(|&v| v)
                && a.observers[o].keypoints.iter().flatten().any(Option::is_some)
        };
        assert_eq!((0..5).map(brings).collect::<Vec<_>>(), [true, false, false, true, false]);
        assert_eq!(a.observers.len(), 5, "indices follow the session's");
    }

    #[test]
    fn a_stream_sampled_at_the_timeline_rate_keeps_every_frame() {
        // 86 samples at 30 fps with nanosecond-rounded times (the last at 2 833 333 333 ns):
        // 86 frames, although 2.833333333 s × 30 is a hair under 85.
        let timeline = Timeline { start_ns: 0, fps: 30.0, frames: 86 };
        let times: Vec<i64> = (0..86).map(|i| timeline.timestamp_ns(i)).collect();
        let head = Trajectory { timestamps_ns: times.clone(), poses: vec![RigidTransform::IDENTITY; 86] };
        let a = align(&session(head), &AlignOptions::default()).unwrap();
        assert_eq!(a.timeline.frames, 86);
        assert!(a.head.valid.iter().all(|&v| v));
    }

    #[test]
    fn short_gaps_are_bridged_and_long_gaps_are_invalid() {
        // 10 fps timeline over 0..=1000 ms; samples every 20 ms except an 80 ms gap
        // (bridged) and a 300 ms gap (not).
        let mut times: Vec<i64> = (0..=200).step_by(20).collect();
        times.extend((280..=400).step_by(20));
        times.extend((700..=1000).step_by(20));
        let s = session(trajectory(&times));
        let a = align(&s, &AlignOptions { fps: 10.0, ..AlignOptions::default() }).unwrap();
        assert_eq!(a.timeline.frames, 11);
        let valid: Vec<bool> = a.head.valid.clone();
        assert_eq!(valid, [true, true, true, true, true, false, false, true, true, true, true]);
        // 250 ms is inside the bridged gap: interpolated between 200 and 280 ms.
        let expected = s.wearer.head.poses[10].interpolate(&s.wearer.head.poses[11], 50.0 / 80.0);
        let mid = a.head.poses[2];
        assert_eq!(a.timeline.timestamp_ns(2), 200 * MS);
        assert!(mid.translation.abs_diff_eq(s.wearer.head.poses[10].translation, 1e-6));
        let a2 = align(&s, &AlignOptions { fps: 4.0, ..AlignOptions::default() }).unwrap();
        assert_eq!(a2.timeline.timestamp_ns(1), 250 * MS);
        assert!(a2.head.valid[1]);
        assert!(a2.head.poses[1].translation.abs_diff_eq(expected.translation, 1e-6));
        // Invalid frames hold the identity, never an invented pose.
        assert_eq!(a.head.poses[5], RigidTransform::IDENTITY);
        let cov = &a.coverage[0];
        assert_eq!((cov.stream.as_str(), cov.valid_frames, cov.frames), ("wearer/head", 9, 11));
    }

    #[test]
    fn observer_outside_its_range_and_keypoint_tolerance() {
        let mut s = session(trajectory(&(0..=1000).step_by(10).collect::<Vec<_>>()));
        // Observer tracked from 300 ms; keypoints 10 ms and 20 ms away from frame times.
        s.observers.push(observer("o", trajectory(&(300..=1000).step_by(10).collect::<Vec<_>>()), &[410, 620, 900]));
        let a = align(&s, &AlignOptions { fps: 10.0, ..AlignOptions::default() }).unwrap();
        let o = &a.observers[0];
        assert_eq!(o.head.valid.iter().filter(|v| **v).count(), 8);
        assert!(!o.head.valid[2] && o.head.valid[3]);
        // Tolerance = half a frame = 50 ms: all three detections are assigned…
        assert!(o.keypoints[4][0].is_some() && o.keypoints[6][0].is_some() && o.keypoints[9][0].is_some());
        assert_eq!(o.keypoints[4][0].unwrap().pixel.x, 410.0, "mapped with exo_from_coco17 (nose first)");
        // …and with a 15 ms tolerance only the one 10 ms away.
        let tight =
            align(&s, &AlignOptions { fps: 10.0, keypoint_tolerance_ns: Some(15 * MS), ..AlignOptions::default() })
                .unwrap();
        let hits: Vec<usize> = (0..11).filter(|&i| tight.observers[0].keypoints[i][0].is_some()).collect();
        assert_eq!(hits, [4, 9]);
        let cov = tight.coverage.iter().find(|c| c.stream == "o/keypoints").unwrap();
        assert_eq!(cov.valid_frames, 2);
    }

    #[test]
    fn ground_truth_is_interpolated_and_occlusion_follows_observer_order() {
        let mut s = session(trajectory(&(0..=1000).step_by(10).collect::<Vec<_>>()));
        s.observers.push(observer("b", trajectory(&[0, 1000]), &[0]));
        s.observers.push(observer("a", trajectory(&[0, 1000]), &[0]));
        let poses: Vec<SmplPose> = (0..5)
            .map(|i| SmplPose { root_orientation: Quat::from_rotation_y(0.1 * i as f32), ..SmplPose::rest() })
            .collect();
        let motion =
            SmplMotion::new(5.0, 200 * MS, egoexo_core::skeleton::SmplSkeleton::mean_shape(), None, poses).unwrap();
        s.ground_truth = Some(GroundTruth {
            motion,
            occlusion: vec![ObserverOcclusion { observer_id: "a".into(), occluded: vec![1, 2, 3, 4, 5] }],
        });
        let a = align(&s, &AlignOptions { fps: 10.0, ..AlignOptions::default() }).unwrap();
        let gt = a.ground_truth.unwrap();
        // Motion frames at 200, 400, …, 1000 ms.
        assert_eq!(gt.valid, [false, false, true, true, true, true, true, true, true, true, true]);
        let angle = egoexo_core::rotation::angle_between(gt.poses[3].root_orientation, Quat::from_rotation_y(0.05));
        assert!(angle < 1e-5, "300 ms is halfway between frames 0 and 1: {angle}");
        assert_eq!(gt.occluded[0], vec![0; 11], "observer b has no labels");
        assert_eq!(gt.occluded[1][2..].to_vec(), vec![1, 1, 2, 2, 3, 3, 4, 4, 5]);
    }

    #[test]
    fn bad_options_and_absurd_ranges_are_errors() {
        let s = session(trajectory(&[0, 10]));
        assert_eq!(align(&s, &AlignOptions { fps: 0.0, ..AlignOptions::default() }), Err(AlignError::InvalidFps(0.0)));
        assert!(matches!(
            align(&s, &AlignOptions { max_gap_ns: 0, ..AlignOptions::default() }),
            Err(AlignError::InvalidGap(0))
        ));
        // A century-long head trajectory is refused before anything is allocated.
        let long = session(Trajectory {
            timestamps_ns: vec![0, 3_155_760_000_000_000_000],
            poses: vec![RigidTransform::IDENTITY; 2],
        });
        let err = align(&long, &AlignOptions::default()).unwrap_err();
        assert!(matches!(err, AlignError::TooManyFrames { .. }), "{err}");
        assert!(err.to_string().contains("over the limit of 10000000"));
        let empty = session(Trajectory::default());
        assert_eq!(align(&empty, &AlignOptions::default()), Err(AlignError::EmptyHead));
    }

    #[test]
    fn extreme_timestamps_do_not_overflow() {
        let mut s = session(trajectory(&[0, 1000]));
        let head =
            Trajectory { timestamps_ns: vec![i64::MIN + 1, 0, i64::MAX - 1], poses: vec![RigidTransform::IDENTITY; 3] };
        s.observers.push(observer("o", head, &[0]));
        let a = align(&s, &AlignOptions::default()).unwrap();
        // Only frame 0 coincides with a sample; the rest lie in gaps of ~292 years.
        let valid: Vec<usize> = (0..a.timeline.frames).filter(|&i| a.observers[0].head.valid[i]).collect();
        assert_eq!(valid, [0]);
        let far = Timeline { start_ns: i64::MAX - 5, fps: 1.0, frames: 3 };
        assert_eq!(far.timestamp_ns(2), i64::MAX);
    }

    #[test]
    fn nearest_respects_ties_and_tolerance() {
        let ts = [0, 10, 20];
        assert_eq!(nearest(&ts, 5, 5), Some(0));
        assert_eq!(nearest(&ts, 16, 5), Some(2));
        assert_eq!(nearest(&ts, 26, 5), None);
        assert_eq!(nearest(&[], 0, 5), None);
    }
}
