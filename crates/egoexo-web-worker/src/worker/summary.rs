//! The summaries the page shows of an open session: its devices, wrists, observers and
//! their worlds, floor and warnings.

use super::*;

pub(super) fn projection_name(projection: &Projection) -> &'static str {
    match projection {
        Projection::Pinhole(_) => "pinhole",
        Projection::Fisheye624(_) => "fisheye624",
    }
}

pub(super) fn session_summary(
    imported: &Imported,
    aligned: &AlignedSession,
    videos: &BTreeMap<String, Arc<[u8]>>,
) -> SessionSummary {
    let session = &imported.session;
    let mut devices = vec!["head".to_string()];
    devices.extend(session.wearer.left_wrist.as_ref().map(|_| "left_wrist".to_string()));
    devices.extend(session.wearer.right_wrist.as_ref().map(|_| "right_wrist".to_string()));
    let observers = session
        .observers
        .iter()
        .zip(&aligned.observers)
        .map(|(o, a)| ObserverSummary {
            id: o.id.clone(),
            camera: format!("{} {}×{}", projection_name(&o.camera.projection), o.camera.width, o.camera.height),
            keypoint_frames: a.keypoints.iter().filter(|f| f.iter().any(Option::is_some)).count(),
            video: o.video.as_ref().map(|v| v.path.clone()),
            needs_detection: o.keypoints.is_none() && o.video.as_ref().is_some_and(|v| videos.contains_key(&v.path)),
            world: o.placement.describe(),
            fused: o.placement.fusable(),
        })
        .collect();
    let mut warnings: Vec<String> = imported.warnings.iter().map(ToString::to_string).collect();
    for o in &session.observers {
        if let Some(video) = o.video.as_ref().filter(|v| o.keypoints.is_none() && !videos.contains_key(&v.path)) {
            warnings.push(format!(
                "observer `{}` names the video `{}`, which is not in the session: it cannot contribute rays",
                o.id, video.path
            ));
        } else if o.keypoints.is_none() && o.video.is_none() {
            warnings.push(format!("observer `{}` has no 2D keypoints: it is shown but cannot contribute rays", o.id));
        }
    }
    let timeline = &aligned.timeline;
    let choice = aligned.tracking_choice();
    SessionSummary {
        name: aligned.name.clone(),
        source: imported.source.describe().to_string(),
        frames: timeline.frames,
        fps: timeline.fps,
        duration_s: timeline.frames as f32 / timeline.fps,
        devices,
        tracking_points: choice.mode.points(),
        tracking_reason: choice.reason,
        wrists: wrist_summaries(session, aligned),
        floor: egoexo_session::floor::floor_or_estimate(session)
            .map(|f| FloorSummary { height_m: f.height_m, source: f.source.describe() }),
        observers,
        ground_truth: aligned.ground_truth.is_some(),
        warnings,
        participants: Vec::new(),
        participant: None,
    }
}

/// Per wrist: source and coverage of the timeline (what `egoexo inspect` prints too).
pub(super) fn wrist_summaries(session: &egoexo_session::Session, aligned: &AlignedSession) -> Vec<WristSummary> {
    [("left", &aligned.left_wrist), ("right", &aligned.right_wrist)]
        .into_iter()
        .filter_map(|(side, w)| {
            let coverage = w.as_ref()?.coverage();
            Some(WristSummary {
                side: side.into(),
                source: session.wearer.wrist_source.describe(),
                tracked_percent: coverage.tracked_fraction * 100.0,
                longest_gap_s: coverage.longest_gap_frames as f32 / aligned.timeline.fps,
            })
        })
        .collect()
}
