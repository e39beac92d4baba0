//! The detector step end to end on video whose true 2D joints are known: a simulated walk
//! whose observers film the wearer's rendered body (`egoexo_synth::video`), encoded with
//! OpenH264, demuxed, decoded, cropped to EgoNet's regions, run through the shipped detector
//! and mapped back to full-image pixels — against the projections of the true joints; then the
//! reconstruction with the detected keypoints against ego-only. Prints the figures the model
//! card quotes (`cargo test -p egoexo-detect --features openh264 --test video -- --nocapture`).

use egoexo_core::TrackingMode;
use egoexo_core::crop::resample_rgb;
use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, ExoKeypoint, exo_keypoints_from_smpl};
use egoexo_core::metrics::MetricsAccumulator;
use egoexo_core::region::BoundingBox;
use egoexo_core::skeleton::SmplSkeleton;
use egoexo_detect::native::{decode_frames, encode_mp4};
use egoexo_detect::{ObserverDetections, observers_needing_detection, plan_observer};
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;
use egoexo_infer::{Engine, KeypointDetector, Method, ReconstructOptions};
use egoexo_session::{AlignOptions, align};
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::video::{Appearance, render_observer_videos};
use egoexo_synth::{SynthConfig, simulate};
use egoexo_test_support::workspace_root;

#[test]
fn detected_keypoints_land_on_the_true_joints_and_the_observers_help() {
    let models = workspace_root().join("models");
    let manifest = Manifest::from_json(&std::fs::read(models.join("manifest.json")).unwrap()).unwrap();
    let detector_manifest = manifest.detector.clone().expect("models/manifest.json ships a detector");
    let detector =
        KeypointDetector::load(&detector_manifest, &std::fs::read(models.join(&detector_manifest.file.file)).unwrap())
            .unwrap();
    let set = ModelSet::load(manifest.model_set(TrackingMode::ThreePoint).unwrap(), |f| {
        std::fs::read(models.join(f))
            .map_err(|e| egoexo_infer::InferError::ReadModel { file: f.to_string(), message: e.to_string() })
    })
    .unwrap();
    let engine = Engine::new().with_models(set);

    // 12 s of walking, two observers with 512 px cameras (fisheye or pinhole, as drawn).
    let motion = walking_circle(12.0);
    let mut config = SynthConfig { observers: 2, ..SynthConfig::default() };
    config.camera.image_sizes = vec![512];
    let mut sim = simulate(&motion, "walk", &config, 11).unwrap();
    let with_simulated_keypoints = sim.session.clone();
    let videos = render_observer_videos(&mut sim, &motion, &Appearance::default(), |frames, w, h, fps| {
        encode_mp4(frames, w, h, fps, 6_000_000)
    })
    .unwrap();
    let mut session = sim.session.clone();
    assert_eq!(observers_needing_detection(&session), [0, 1]);

    let aligned = align(&session, &AlignOptions::default()).unwrap();
    let egonet = ReconstructOptions { method: Method::EgoNet, ..ReconstructOptions::default() };
    let coarse = engine.reconstruct(&aligned, &egonet, &mut |_| true).unwrap();
    let scale = motion.skeleton.head_height() / SmplSkeleton::mean_shape().head_height();
    let size = detector.input_size();
    println!(
        "observer | frames | with region | left–right exchanged | PCK@0.1 | PCK@0.2 | median error (% of box) | mean score"
    );
    for o in 0..2 {
        let mp4 = &videos[&format!("observers/observer-{}/rgb.mp4", o + 1)];
        let plan = plan_observer(&session, &aligned, &coarse, o, mp4).unwrap();
        assert_eq!(plan.frames.len(), motion.len());
        let mut detections = ObserverDetections::new(&plan);
        let n = decode_frames(&plan.track, mp4, |i, rgb| {
            if let Some(window) = plan.frames[i].window {
                let crop = resample_rgb(rgb, plan.track.width, plan.track.height, &window, size).unwrap();
                detections.record(i, &detector.detect(&crop).unwrap()).unwrap();
            }
            true
        })
        .unwrap();
        assert_eq!(n, motion.len());
        let mirrored = detections.mirrored_frames();
        let track = detections.into_track();
        // Against the true joints projected with the true camera pose, in units of the true
        // box's diagonal (PCK's usual normalisation is the box or torso size).
        let camera = &session.observers[o].camera;
        let (mut errors, mut scores, mut with_region) = (Vec::new(), Vec::new(), 0);
        for (f, frame) in track.frames.iter().enumerate() {
            if frame.iter().all(Option::is_none) {
                continue;
            }
            with_region += 1;
            let fk = motion.skeleton.forward_kinematics(&motion.poses[f]);
            let head = &sim.true_observer_heads[o][f];
            let truth = exo_keypoints_from_smpl(&fk.positions, fk.rotations[15], scale)
                .map(|p| camera.project_world(p, head).filter(|px| camera.is_valid_pixel(*px)));
            let visible: Vec<_> = truth.iter().flatten().copied().collect();
            let Some(diag) = BoundingBox::around(visible.iter().copied()).map(|b| b.diagonal()) else { continue };
            if visible.len() < EXO_KEYPOINT_COUNT || diag < 20.0 {
                continue;
            }
            for k in ExoKeypoint::ALL {
                if let (Some(t), Some(d)) = (truth[k.index()], frame[k.coco17_index()]) {
                    errors.push(d.pixel.distance(t) / diag);
                    scores.push(d.score);
                }
            }
        }
        errors.sort_by(f32::total_cmp);
        let pck = |r: f32| errors.iter().filter(|&&e| e <= r).count() as f32 / errors.len().max(1) as f32;
        let median = errors.get(errors.len() / 2).copied().unwrap_or(f32::NAN);
        let mean_score = scores.iter().sum::<f32>() / scores.len().max(1) as f32;
        println!(
            "{} | {} | {} | {} | {:.3} | {:.3} | {:.1} | {:.2}",
            plan.observer_id,
            plan.frames.len(),
            with_region,
            mirrored,
            pck(0.1),
            pck(0.2),
            100.0 * median,
            mean_score
        );
        assert!(with_region as f32 > 0.5 * plan.frames.len() as f32, "the wearer is in view most of the time");
        assert!(pck(0.2) > 0.9, "PCK@0.2 {:.3}: the detector does not find the rendered body", pck(0.2));
        session.observers[o].keypoints = Some(track);
    }

    // Reconstruction with the detected keypoints, against ego-only and against the simulator's
    // own keypoints.
    let mpjpe = |s: &egoexo_session::Session, method: Method| {
        let aligned = align(s, &AlignOptions::default()).unwrap();
        let r = engine
            .reconstruct(&aligned, &ReconstructOptions { method, ..ReconstructOptions::default() }, &mut |_| true)
            .unwrap();
        let gt = aligned.ground_truth.as_ref().unwrap();
        let mut acc = MetricsAccumulator::new();
        let want: Vec<_> = gt.poses.iter().map(|p| aligned.skeleton.forward_kinematics(p).positions).collect();
        acc.add_segment(&r.joints, &want, aligned.timeline.fps, Some(&gt.valid)).unwrap();
        acc.finish().unwrap().mpjpe_cm
    };
    let ego_only = mpjpe(&session, Method::EgoOnly);
    let detected = mpjpe(&session, Method::EgoExo);
    let simulated = mpjpe(&with_simulated_keypoints, Method::EgoExo);
    println!(
        "MPJPE (cm): ego-only {ego_only:.2} | ego-exo, detected keypoints {detected:.2} | ego-exo, simulated keypoints {simulated:.2}"
    );
    assert!(detected < ego_only, "detected keypoints make it worse: {detected:.2} vs ego-only {ego_only:.2}");
}
