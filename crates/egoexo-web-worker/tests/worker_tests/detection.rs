//! The worker's detector step natively, with the shipped models: a simulated walk whose two
//! observers bring only video (rendered, H.264) is imported as a `.egoexo` file; the worker
//! plans each frame's crop from EgoNet, and OpenH264 stands in for the browser's WebCodecs
//! decoder — frames handed in by sample index, as the browser's runtime does. The keypoints
//! land in the session, the reconstruction uses the observers, and a saved session carries
//! its videos and the found keypoints. The browser's path (WebCodecs, the canvas crop) is
//! `tests/e2e/detect.test.mjs`.
#![cfg(not(target_arch = "wasm32"))]

use egoexo_core::crop::resample_rgb;
use egoexo_detect::native::{decode_frames, encode_mp4};
use egoexo_session::format::write_egoexo_zip_with;
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::video::{Appearance, render_observer_videos};
use egoexo_synth::{SynthConfig, simulate};
use egoexo_test_support::workspace_root;
use egoexo_web_worker::{SessionWorker, WorkerError};

/// A 5 s walk whose two 320 px observers have video and no keypoints, as a `.egoexo` zip.
fn walk_with_video() -> Vec<u8> {
    let motion = walking_circle(5.0);
    let mut config = SynthConfig { observers: 2, ..SynthConfig::default() };
    config.camera.image_sizes = vec![320];
    let mut sim = simulate(&motion, "walk-video", &config, 5).unwrap();
    let videos = render_observer_videos(&mut sim, &motion, &Appearance::default(), |frames, w, h, fps| {
        encode_mp4(frames, w, h, fps, 3_000_000)
    })
    .unwrap();
    assert!(sim.session.observers.iter().all(|o| o.keypoints.is_none() && o.video.is_some()));
    write_egoexo_zip_with(&sim.session, videos).unwrap()
}

fn shipped_models(worker: &mut SessionWorker) {
    let models = workspace_root().join("models");
    let manifest = std::fs::read(models.join("manifest.json")).unwrap();
    worker
        .load_models(&manifest, |file| {
            std::fs::read(models.join(file))
                .map_err(|e| egoexo_infer::InferError::ReadModel { file: file.into(), message: e.to_string() })
        })
        .unwrap();
    let detector = worker.detector_file().expect("models/manifest.json ships a detector");
    worker.load_detector(&std::fs::read(models.join(&detector.file)).unwrap()).unwrap();
}

#[test]
fn observers_with_only_video_get_keypoints_and_contribute() {
    let mut worker = SessionWorker::new();
    shipped_models(&mut worker);
    let summary = worker.import_archive("walk-video.egoexo", walk_with_video()).unwrap();
    assert!(summary.observers.iter().all(|o| o.needs_detection && o.keypoint_frames == 0), "{summary:?}");
    assert_eq!(worker.observers_needing_detection(), ["observer-1", "observer-2"]);

    let mut task = worker.start_detection().unwrap().expect("two observers need the step");
    let size = task.input_size();
    for o in 0..task.observers().len() {
        let (track, mp4, frames) = {
            let job = &task.observers()[o];
            (job.track().clone(), job.mp4().to_vec(), job.plan.frames.clone())
        };
        let decoded = decode_frames(&track, &mp4, |i, rgb| {
            // The decoder's frame i (presentation order) is sample `frames[i].sample`.
            let sample = frames[i].sample;
            let crop = task.observers()[o]
                .window(sample)
                .map(|window| resample_rgb(rgb, track.width, track.height, &window, size).unwrap());
            task.detect_crop(o, sample, crop.as_deref(), Some(i as f64 * 10.0)).unwrap();
            true
        })
        .unwrap();
        assert_eq!(decoded, frames.len());
    }
    let found = worker.finish_detection(task).unwrap();
    assert_eq!(found.len(), 2);
    for d in &found {
        assert_eq!(d.frames, 150, "{d:?}");
        assert!(d.detected >= 100, "the wearer is in view most of the walk: {d:?}");
        assert!(d.ms.is_some());
    }
    let after = worker.session_summary().unwrap();
    assert!(after.observers.iter().all(|o| !o.needs_detection && o.keypoint_frames > 50), "{after:?}");
    assert!(worker.start_detection().unwrap().is_none(), "the keypoints are kept: no second step");

    let result = worker.reconstruct(false, &mut |_| true).unwrap();
    assert_eq!(result.detection, found);
    assert!(result.exo_evidence_frames > 30, "{result:?}");
    assert!(result.observer_ray_frames.values().all(|&n| n > 30), "{result:?}");

    // Saved, the session carries its videos and keypoints: it opens without the step.
    let saved = worker.save_session().unwrap();
    let mut again = SessionWorker::new();
    shipped_models(&mut again);
    let reopened = again.import_archive(&saved.file_name, saved.bytes).unwrap();
    assert!(reopened.observers.iter().all(|o| o.video.is_some() && !o.needs_detection), "{reopened:?}");
}

#[test]
fn without_a_detector_the_step_says_which_observer_needs_one() {
    let mut worker = SessionWorker::new();
    let models = workspace_root().join("models");
    let mut manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(models.join("manifest.json")).unwrap()).unwrap();
    manifest.as_object_mut().unwrap().remove("detector");
    worker
        .load_models(&serde_json::to_vec(&manifest).unwrap(), |file| {
            std::fs::read(models.join(file))
                .map_err(|e| egoexo_infer::InferError::ReadModel { file: file.into(), message: e.to_string() })
        })
        .unwrap();
    assert!(worker.detector_file().is_none());
    worker.import_archive("walk-video.egoexo", walk_with_video()).unwrap();
    let error = worker.start_detection().unwrap_err();
    assert!(matches!(error, WorkerError::Detection(_)), "{error:?}");
    assert!(error.to_string().contains("observer `observer-1` has video and no keypoints"), "{error}");
}

#[test]
fn a_damaged_detector_is_refused_by_its_checksum() {
    let models = workspace_root().join("models");
    let mut worker = SessionWorker::new();
    worker
        .load_models(&std::fs::read(models.join("manifest.json")).unwrap(), |file| {
            std::fs::read(models.join(file))
                .map_err(|e| egoexo_infer::InferError::ReadModel { file: file.into(), message: e.to_string() })
        })
        .unwrap();
    let error = worker.load_detector(b"not a model").unwrap_err();
    assert!(error.to_string().contains("sha256"), "{error}");
    assert!(!worker.has_detector());
}
