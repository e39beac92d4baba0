//! `egoexo inspect <session>`: devices, time ranges, rates, observers, keypoint coverage, and
//! every problem found. Invalid input is an error (exit code 1, message on stderr).

use std::fmt::Write as _;

use anyhow::{Context, Result};
use egoexo_core::aligned::AlignedSession;
use egoexo_core::camera::Projection;
use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_session::align::{AlignOptions, align};
use egoexo_session::capture::ViewPeople;
use egoexo_session::import::{Imported, ImportedCapture};
use egoexo_session::model::{Session, Trajectory};
use serde_json::json;

use super::session_input::SessionInput;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub input: SessionInput,
    /// Frame rate of the timeline coverage is reported on.
    #[arg(long, default_value_t = egoexo_session::align::DEFAULT_FPS)]
    pub fps: f32,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> Result<()> {
    if let Some(capture) = args.input.import_several()? {
        return inspect_capture(&args, capture);
    }
    let imported = args.input.import()?;
    let aligned = align(&imported.session, &AlignOptions { fps: args.fps, ..AlignOptions::default() })
        .with_context(|| format!("cannot align {}", args.input.session.display()))?;
    let problems = problems(&imported, &aligned);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary_json(&imported, &aligned, &problems))?);
    } else {
        print!("{}", summary_text(&args, &imported, &aligned, &problems));
    }
    Ok(())
}

/// A capture of several participants: who is in it, what each camera saw, then each
/// participant to reconstruct as the session they are reconstructed from.
fn inspect_capture(args: &Args, imported: ImportedCapture) -> Result<()> {
    let capture = &imported.capture;
    let mut sessions = Vec::new();
    for p in capture.reconstructed() {
        let session = Imported {
            session: capture.session_for(p)?,
            source: imported.source,
            warnings: if sessions.is_empty() { imported.warnings.clone() } else { Vec::new() },
        };
        let aligned = align(&session.session, &AlignOptions { fps: args.fps, ..AlignOptions::default() })
            .with_context(|| format!("cannot align participant `{}`", capture.participants[p].id))?;
        let problems = problems(&session, &aligned);
        sessions.push((session, aligned, problems));
    }
    let views: Vec<_> = capture
        .views
        .iter()
        .map(|v| match &v.people {
            ViewPeople::Assigned { target, keypoints } => {
                json!({"observer": v.observer, "target": target, "frames": keypoints.frames.len()})
            }
            ViewPeople::Unassigned(people) => json!({
                "observer": v.observer,
                "frames": people.frames.len(),
                "people": people.frames.iter().map(Vec::len).sum::<usize>(),
            }),
        })
        .collect();
    if args.json {
        let participants: Vec<_> = capture
            .participants
            .iter()
            .map(|p| json!({"id": p.id, "reconstruct": p.reconstruct, "camera": p.camera.is_some(), "video": p.video.is_some()}))
            .collect();
        let sessions: Vec<_> = sessions.iter().map(|(i, a, pr)| summary_json(i, a, pr)).collect();
        let out = json!({"capture": capture.name, "participants": participants, "views": views, "sessions": sessions});
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let mut out = String::new();
    let _ = writeln!(out, "capture {} ({} participants)", capture.name, capture.participants.len());
    for p in &capture.participants {
        let _ = writeln!(
            out,
            "  participant {}: {}{}{}; world: {}",
            p.id,
            if p.reconstruct { "reconstructed" } else { "observes only" },
            if p.camera.is_some() { ", RGB camera" } else { "" },
            if p.video.is_some() { " with video" } else { "" },
            p.placement.describe(),
        );
    }
    for v in &capture.views {
        let _ = match &v.people {
            ViewPeople::Assigned { target, keypoints } => {
                writeln!(out, "  view {} → {}: {} frames of keypoints", v.observer, target, keypoints.frames.len())
            }
            ViewPeople::Unassigned(people) => writeln!(
                out,
                "  view {}: {} people without identity over {} frames (associated with the participants' EgoNet poses at reconstruction)",
                v.observer,
                people.frames.iter().map(Vec::len).sum::<usize>(),
                people.frames.len()
            ),
        };
    }
    print!("{out}");
    for (session, aligned, problems) in &sessions {
        println!();
        print!("{}", summary_text(args, session, aligned, problems));
    }
    Ok(())
}

/// Median sample rate, Hz (`None` with fewer than two samples).
fn rate_hz(timestamps: &[i64]) -> Option<f64> {
    let mut intervals: Vec<i128> = timestamps.windows(2).map(|w| i128::from(w[1]) - i128::from(w[0])).collect();
    if intervals.is_empty() {
        return None;
    }
    intervals.sort_unstable();
    Some(1e9 / intervals[intervals.len() / 2] as f64)
}

/// `a − b` in seconds (no overflow for any two timestamps).
fn seconds(a: i64, b: i64) -> f64 {
    (i128::from(a) - i128::from(b)) as f64 / 1e9
}

/// One line about a stream of timestamps, times relative to `origin`.
fn stream_line(count: usize, what: &str, timestamps: &[i64], origin: i64) -> String {
    let (Some(&first), Some(&last)) = (timestamps.first(), timestamps.last()) else {
        return format!("no {what}");
    };
    let rate = rate_hz(timestamps).map_or("—".to_owned(), |r| format!("{r:.1} Hz"));
    format!(
        "{count} {what}, {:.3} s, {rate}, {:+.3} s .. {:+.3} s",
        seconds(last, first),
        seconds(first, origin),
        seconds(last, origin)
    )
}

fn trajectory_line(t: &Trajectory, origin: i64) -> String {
    stream_line(t.len(), "poses", &t.timestamps_ns, origin)
}

fn camera_line(camera: &egoexo_core::camera::CameraCalibration) -> String {
    let model = match camera.projection {
        Projection::Pinhole(_) => "pinhole",
        Projection::Fisheye624(_) => "fisheye624",
    };
    let radius = camera.valid_radius_px.map_or(String::new(), |r| format!(", valid radius {r:.0} px"));
    format!("{model} {}×{}{radius}", camera.width, camera.height)
}

/// One wrist's coverage of the timeline.
struct WristCoverage {
    side: &'static str,
    percent: f64,
    longest_gap_s: f64,
}

fn wrist_coverage(aligned: &AlignedSession) -> Vec<WristCoverage> {
    [("left", &aligned.left_wrist), ("right", &aligned.right_wrist)]
        .into_iter()
        .filter_map(|(side, w)| {
            let coverage = w.as_ref()?.coverage();
            Some(WristCoverage {
                side,
                percent: 100.0 * f64::from(coverage.tracked_fraction),
                longest_gap_s: coverage.longest_gap_frames as f64 / f64::from(aligned.timeline.fps),
            })
        })
        .collect()
}

fn floor_line(session: &Session) -> String {
    match (&session.floor, egoexo_session::floor::floor_or_estimate(session)) {
        (Some(f), _) => format!("{:.3} m, from {}", f.height_m + 0.0, f.source.describe()),
        (None, Some(f)) => {
            format!("{:.3} m, from {} (estimated: the file stores none)", f.height_m + 0.0, f.source.describe())
        }
        (None, None) => "unknown".into(),
    }
}

fn subject_line(session: &Session) -> String {
    let s = &session.subject;
    let mut parts = Vec::new();
    if let Some(h) = s.height_m {
        parts.push(format!("stature {h:.2} m"));
    }
    if let Some(b) = &s.betas {
        parts.push(format!("{} SMPL betas", b.len()));
    }
    if s.rest_joints.is_some() {
        parts.push("rest joints given".into());
    }
    if parts.is_empty() { "mean SMPL shape (no stature or betas given)".into() } else { parts.join(", ") }
}

/// Import warnings plus what alignment reveals: gaps, partial coverage, missing keypoints.
fn problems(imported: &Imported, aligned: &AlignedSession) -> Vec<String> {
    let mut out: Vec<String> = imported.warnings.iter().map(ToString::to_string).collect();
    let session = &imported.session;
    if session.observers.is_empty() {
        out.push("no observers: only the wearer's own tracking is available".into());
    }
    for o in &session.observers {
        if o.keypoints.is_none() && o.video.is_none() {
            out.push(format!("observer `{}` has neither keypoints nor a video", o.id));
        }
    }
    for c in &aligned.coverage {
        if c.valid_frames < c.frames {
            let what = if c.stream.ends_with("/keypoints") { "has detections on" } else { "covers" };
            out.push(format!(
                "{} {what} {} of {} frames ({:.1}%) at {} fps",
                c.stream,
                c.valid_frames,
                c.frames,
                100.0 * c.valid_frames as f64 / c.frames.max(1) as f64,
                aligned.timeline.fps
            ));
        }
    }
    out
}

fn summary_text(args: &Args, imported: &Imported, aligned: &AlignedSession, problems: &[String]) -> String {
    let s = &imported.session;
    let origin = s.wearer.head.timestamps_ns.first().copied().unwrap_or_default();
    let mut out = String::new();
    let _ = writeln!(out, "{} — {} ({})", s.name, imported.source.describe(), args.input.session.display());
    let _ = writeln!(out, "time 0 = {origin} ns on the session clock; times below are relative to it\n");
    let _ = writeln!(out, "Wearer");
    let _ = writeln!(out, "  {:<12} {}", "head", trajectory_line(&s.wearer.head, origin));
    for (name, wrist) in [("left_wrist", &s.wearer.left_wrist), ("right_wrist", &s.wearer.right_wrist)] {
        if let Some(w) = wrist {
            let _ = writeln!(out, "  {name:<12} {}", trajectory_line(w, origin));
        }
    }
    for c in wrist_coverage(aligned) {
        let _ = writeln!(
            out,
            "  {:<12} {} wrist tracked on {:.1}% of frames, longest gap {:.2} s",
            "", c.side, c.percent, c.longest_gap_s
        );
    }
    if s.wearer.left_wrist.is_some() || s.wearer.right_wrist.is_some() {
        let _ = writeln!(out, "  {:<12} {}", "wrists from", s.wearer.wrist_source.describe());
    }
    let choice = aligned.tracking_choice();
    let _ = writeln!(
        out,
        "  {:<12} {}-point{}",
        "tracking",
        choice.mode.points(),
        choice.reason.as_ref().map_or(String::new(), |r| format!(" ({r})"))
    );
    let _ = writeln!(out, "  {:<12} {}", "subject", subject_line(s));
    let _ = writeln!(out, "  {:<12} {}", "floor", floor_line(s));
    let _ = writeln!(out, "\nObservers ({})", s.observers.len());
    for o in &s.observers {
        let _ = writeln!(out, "  {:<12} {}", o.id, trajectory_line(&o.head, origin));
        let _ = writeln!(out, "  {:<12} camera {}", "", camera_line(&o.camera));
        let fused = if o.placement.fusable() { "fused" } else { "NOT fused" };
        let _ = writeln!(out, "  {:<12} world: {} ({fused})", "", o.placement.describe());
        match &o.keypoints {
            Some(kp) => {
                let detected: usize = kp.frames.iter().map(|f| f.iter().filter(|k| k.is_some()).count()).sum();
                let _ = writeln!(
                    out,
                    "  {:<12} keypoints: {}; {:.1} of 17 detected per frame",
                    "",
                    stream_line(kp.frames.len(), "frames", &kp.timestamps_ns, origin),
                    detected as f64 / kp.frames.len().max(1) as f64
                );
            }
            None => {
                let _ = writeln!(out, "  {:<12} keypoints: none", "");
            }
        }
        if let Some(v) = &o.video {
            let _ = writeln!(out, "  {:<12} video {} from {:+.3} s", "", v.path, seconds(v.start_ns, origin));
        }
        if let Some(f) = &o.context_features {
            let _ = writeln!(out, "  {:<12} context features: {} × {}", "", f.timestamps_ns.len(), f.dim);
        }
    }
    match &s.ground_truth {
        Some(gt) => {
            let m = &gt.motion;
            let last = m.timestamp_ns(m.len().saturating_sub(1));
            let _ = writeln!(
                out,
                "\nGround truth: {} SMPL frames at {:.2} fps, {:+.3} s .. {:+.3} s; {}",
                m.len(),
                m.fps,
                seconds(m.start_ns, origin),
                seconds(last, origin),
                if gt.occlusion.is_empty() {
                    "no occlusion labels".to_owned()
                } else {
                    let ids: Vec<&str> = gt.occlusion.iter().map(|o| o.observer_id.as_str()).collect();
                    format!("occlusion labels for {}", ids.join(", "))
                }
            );
        }
        None => {
            let _ = writeln!(out, "\nGround truth: none");
        }
    }
    let _ =
        writeln!(out, "\nCoverage on a {} fps timeline ({} frames):", aligned.timeline.fps, aligned.timeline.frames);
    for c in &aligned.coverage {
        let _ = writeln!(
            out,
            "  {:<28} {:>7} / {:<7} {:>6.1}%",
            c.stream,
            c.valid_frames,
            c.frames,
            100.0 * c.valid_frames as f64 / c.frames.max(1) as f64
        );
    }
    for o in &aligned.observers {
        let mut per_keypoint = [0usize; EXO_KEYPOINT_COUNT];
        for frame in &o.keypoints {
            for (k, kp) in frame.iter().enumerate() {
                per_keypoint[k] += usize::from(kp.is_some());
            }
        }
        if per_keypoint.iter().any(|&n| n > 0) {
            let least = per_keypoint.iter().min().copied().unwrap_or_default();
            let _ = writeln!(
                out,
                "  {:<28} {:>7} / {:<7} {:>6.1}%  (the least-seen of the K = 13)",
                format!("{}/keypoints, each", o.id),
                least,
                aligned.timeline.frames,
                100.0 * least as f64 / aligned.timeline.frames.max(1) as f64
            );
        }
    }
    let _ = writeln!(out, "\nProblems ({}):", problems.len());
    if problems.is_empty() {
        let _ = writeln!(out, "  none");
    }
    for p in problems {
        let _ = writeln!(out, "  - {p}");
    }
    out
}

fn summary_json(imported: &Imported, aligned: &AlignedSession, problems: &[String]) -> serde_json::Value {
    let s = &imported.session;
    let stream = |t: &[i64]| {
        json!({
            "samples": t.len(),
            "first_ns": t.first(),
            "last_ns": t.last(),
            "rate_hz": rate_hz(t),
        })
    };
    json!({
        "name": s.name,
        "source": imported.source.describe(),
        "wearer": {
            "head": stream(&s.wearer.head.timestamps_ns),
            "left_wrist": s.wearer.left_wrist.as_ref().map(|w| stream(&w.timestamps_ns)),
            "right_wrist": s.wearer.right_wrist.as_ref().map(|w| stream(&w.timestamps_ns)),
        },
        "wrists": wrist_coverage(aligned).iter().map(|c| json!({
            "side": c.side, "tracked_percent": c.percent, "longest_gap_s": c.longest_gap_s,
        })).collect::<Vec<_>>(),
        "wrist_source": s.wearer.wrist_source,
        "tracking": {"points": aligned.tracking_choice().mode.points(), "reason": aligned.tracking_choice().reason},
        "floor": egoexo_session::floor::floor_or_estimate(s).map(|f| json!({"height_m": f.height_m, "source": f.source.describe(), "stored": s.floor.is_some()})),
        "subject": subject_line(s),
        "observers": s.observers.iter().map(|o| json!({
            "id": o.id,
            "head": stream(&o.head.timestamps_ns),
            "camera": camera_line(&o.camera),
            "keypoints": o.keypoints.as_ref().map(|k| stream(&k.timestamps_ns)),
            "placement": o.placement,
            "fused": o.placement.fusable(),
        })).collect::<Vec<_>>(),
        "ground_truth_frames": s.ground_truth.as_ref().map(|g| g.motion.len()),
        "timeline": {"fps": aligned.timeline.fps, "frames": aligned.timeline.frames, "start_ns": aligned.timeline.start_ns},
        "coverage": aligned.coverage.iter().map(|c| json!({
            "stream": c.stream, "valid_frames": c.valid_frames, "frames": c.frames,
        })).collect::<Vec<_>>(),
        "problems": problems,
    })
}
