//! The detector step natively: for every observer of a session that has video and no
//! keypoints, EgoNet's coarse pose gives each frame's region, OpenH264 decodes the frames,
//! the crop goes through the shipped detector (tract) and the keypoints land in the session.
//! `egoexo keypoints` runs it alone; `egoexo reconstruct` runs it first when needed.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_core::crop::resample_rgb;
use egoexo_detect::native::decode_frames;
use egoexo_detect::{ObserverDetections, observers_needing_detection, plan_observer};
use egoexo_infer::manifest::Manifest;
use egoexo_infer::plan::resolve_tracking;
use egoexo_infer::{Engine, KeypointDetector, Method, ReconstructOptions};
use egoexo_session::align::{AlignOptions, align};
use egoexo_session::import::{Imported, detect_source};
use egoexo_session::vfs::{FileTree, Limits};
use indicatif::{ProgressBar, ProgressStyle};

use super::models::{load_model_set, read_manifest};

/// The detector `manifest` (read from `models`) names, loaded.
pub fn load_detector(models: &Path, manifest: &Manifest) -> Result<KeypointDetector> {
    let detector_manifest = manifest.detector.clone().with_context(|| {
        format!("{} has no detector: observers with video need one to find the wearer's keypoints", models.display())
    })?;
    let detector_path = models.join(&detector_manifest.file.file);
    let bytes = std::fs::read(&detector_path).with_context(|| format!("cannot read {}", detector_path.display()))?;
    Ok(KeypointDetector::load(&detector_manifest, &bytes)?)
}

/// What the detector step did for one observer.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ObserverDetectionReport {
    pub observer: String,
    pub video: String,
    /// Video frames, frames with a region (so a detection), seconds spent (decode + crop + model).
    pub frames: usize,
    pub detected: usize,
    pub seconds: f64,
}

impl ObserverDetectionReport {
    /// Detections per second (decoding included).
    pub fn per_second(&self) -> f64 {
        self.detected as f64 / self.seconds.max(1e-9)
    }
}

/// Runs the detector step on `imported` (read from `path`) for the observers that need it
/// (only those named in `only`, when given), with the networks in `models`. Returns what was
/// done per observer; the session's keypoint tracks are filled in.
pub fn detect_missing_keypoints(
    path: &Path,
    imported: &mut Imported,
    models: &Path,
    tracking: Option<TrackingMode>,
    only: &[String],
) -> Result<Vec<ObserverDetectionReport>> {
    let session = &imported.session;
    let mut todo = observers_needing_detection(session);
    if !only.is_empty() {
        for id in only {
            let Some(o) = session.observers.iter().position(|o| &o.id == id) else {
                let known: Vec<_> = session.observers.iter().map(|o| o.id.as_str()).collect();
                bail!("--observer {id}: the session's observers are {known:?}");
            };
            if session.observers[o].video.is_none() {
                bail!("--observer {id}: this observer has no video to detect keypoints in");
            }
        }
        todo = (0..session.observers.len()).filter(|&o| only.contains(&session.observers[o].id)).collect();
    }
    if todo.is_empty() {
        return Ok(Vec::new());
    }
    let manifest = read_manifest(models)?;
    let detector = load_detector(models, &manifest)?;

    // EgoNet's coarse pose on the session's timeline: where the regions come from.
    let aligned = align(session, &AlignOptions::default())?;
    let tracking = resolve_tracking(&aligned, tracking)?;
    let set = load_model_set(models, &manifest, tracking)?
        .with_context(|| format!("{} has no {}-point models", models.display(), tracking.points()))?;
    let engine = Engine::new().with_models(set);
    let options =
        ReconstructOptions { method: Method::EgoNet, tracking: Some(tracking), ..ReconstructOptions::default() };
    let coarse = engine.reconstruct(&aligned, &options, &mut |_| true)?;

    let tree = FileTree::open(path, Limits::default())?;
    let (_, root) = detect_source(&tree)?;
    let size = detector.input_size();
    let mut reports = Vec::new();
    for o in todo {
        let started = Instant::now();
        let observer = &imported.session.observers[o];
        let video = observer.video.as_ref().context("checked above")?;
        let mp4 = root.read(&video.path)?;
        let plan = plan_observer(&imported.session, &aligned, &coarse, o, &mp4)?;
        let bar = ProgressBar::new(plan.frames.len() as u64).with_style(
            ProgressStyle::with_template("{msg} {bar:40} {pos}/{len} frames [{elapsed_precise}]")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_message(format!("detecting ({})", plan.observer_id));
        let mut detections = ObserverDetections::new(&plan);
        let mut failure = None;
        let decoded = decode_frames(&plan.track, &mp4, |i, rgb| {
            bar.set_position(i as u64 + 1);
            let Some(window) = plan.frames.get(i).and_then(|f| f.window) else { return true };
            let result = resample_rgb(rgb, plan.track.width, plan.track.height, &window, size)
                .context("the decoded frame does not match the video's size")
                .and_then(|crop| Ok(detector.detect(&crop)?))
                .and_then(|keypoints| Ok(detections.record(i, &keypoints)?));
            match result {
                Ok(()) => true,
                Err(e) => {
                    failure = Some(e);
                    false
                }
            }
        })
        .with_context(|| format!("decoding {}", root.display_path(&video.path)))?;
        bar.finish_and_clear();
        if let Some(e) = failure {
            return Err(e.context(format!("detecting in {}", root.display_path(&video.path))));
        }
        if decoded != plan.frames.len() {
            bail!("{}: {decoded} frames decoded of {}", root.display_path(&video.path), plan.frames.len());
        }
        let report = ObserverDetectionReport {
            observer: plan.observer_id.clone(),
            video: video.path.clone(),
            frames: plan.frames.len(),
            detected: detections.detected_frames(),
            seconds: started.elapsed().as_secs_f64(),
        };
        imported.session.observers[o].keypoints = Some(detections.into_track());
        reports.push(report);
    }
    Ok(reports)
}

/// One line per observer: frames, detections, detections per second.
pub fn print_reports(reports: &[ObserverDetectionReport]) {
    for r in reports {
        eprintln!(
            "detected keypoints for observer `{}` ({}): {} of {} frames had the wearer's region, {:.1} detections/s",
            r.observer,
            r.video,
            r.detected,
            r.frames,
            r.per_second()
        );
    }
}
