#![cfg(not(target_arch = "wasm32"))]
//! The engine end to end on simulated sessions, for every method, with the (untrained)
//! fixture networks: the invariants a reconstruction must keep whatever the weights.

use crate::common::*;
use egoexo_core::TrackingMode;
use egoexo_core::aligned::AlignedSession;
use egoexo_core::ego_features::EGO_FEATURE_DIM;
use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_core::glam::Vec3;
use egoexo_core::skeleton::SmplJoint;
use egoexo_infer::baselines::NearestNeighbourIndex;
use egoexo_infer::inputs::{ego_window, window_targets};
use egoexo_infer::windows::{WINDOW, plan_windows, valid_spans};
use egoexo_infer::{Engine, InferError, Method, Progress, ReconstructOptions, Stage};

fn engine() -> Engine {
    Engine::new()
        .with_models(fixture_models(TrackingMode::ThreePoint))
        .with_models(fixture_models(TrackingMode::OnePoint))
}

fn nearest_index(tracking: TrackingMode) -> NearestNeighbourIndex {
    let training = aligned_session(12.0, 1, TrackingMode::ThreePoint, 99);
    let plans = plan_windows(&valid_spans(&training.head.valid), WINDOW, true);
    let (mut features, mut poses) = (Vec::new(), Vec::new());
    for plan in &plans {
        let window = ego_window(&training, plan, tracking).unwrap();
        let targets = window_targets(&training, &window).unwrap();
        features.extend_from_slice(&window.ego[..plan.len() * EGO_FEATURE_DIM]);
        poses.extend_from_slice(&targets[..plan.len() * 132]);
    }
    NearestNeighbourIndex::build(&features, &poses).unwrap()
}

fn run(engine: &Engine, aligned: &AlignedSession, method: Method) -> egoexo_infer::Reconstruction {
    let options = ReconstructOptions { method, ..ReconstructOptions::default() };
    engine.reconstruct(aligned, &options, &mut |_| true).unwrap()
}

#[test]
fn every_method_hangs_the_body_from_the_tracked_head() {
    let aligned = aligned_session(7.0, 2, TrackingMode::ThreePoint, 1);
    let engine = engine().with_nearest_neighbour(TrackingMode::ThreePoint, nearest_index(TrackingMode::ThreePoint));
    for method in [
        Method::RestPose,
        Method::NearestNeighbour,
        Method::EgoNet,
        Method::EgoOnly,
        Method::EgoExo,
        Method::EgoExoUngated,
    ] {
        let r = run(&engine, &aligned, method);
        assert_eq!(r.motion.len(), aligned.timeline.frames, "{method}");
        assert_eq!(r.tracking, TrackingMode::ThreePoint);
        assert!(r.valid.iter().all(|&v| v), "{method}: every frame is tracked");
        for (f, joints) in r.joints.iter().enumerate() {
            assert!(joints.iter().all(|p| p.is_finite()), "{method} frame {f}");
            // Root recovery: the FK head joint sits exactly at the head device + offset.
            let head = aligned.head.poses[f].transform_point(aligned.head_joint_in_device);
            assert!(joints[SmplJoint::Head.index()].abs_diff_eq(head, 1e-4), "{method} frame {f}");
        }
        assert_eq!(r.gates.len(), 2);
    }
}

/// EgoNet alone is the coarse pose the other network methods start from: it runs EgoNet once
/// per window and nothing else, uses no exo evidence, and differs from the fused result.
#[test]
fn egonet_alone_is_the_coarse_pose_without_the_fusion() {
    let aligned = aligned_session(5.0, 2, TrackingMode::ThreePoint, 3);
    let engine = engine();
    let before = engine.network_runs();
    let coarse = run(&engine, &aligned, Method::EgoNet);
    let runs = engine.network_runs() - before;
    assert!(runs.egonet > 0 && runs.gate == 0 && runs.fusion == 0 && runs.fusion_ego_only == 0, "{runs:?}");
    assert!(!coarse.exo_evidence.iter().any(|&e| e));
    let fused = run(&engine, &aligned, Method::EgoOnly);
    let moved =
        coarse.joints.iter().zip(&fused.joints).any(|(a, b)| a.iter().zip(b).any(|(p, q)| p.distance(*q) > 1e-3));
    assert!(moved, "the fusion refines EgoNet's pose");
}

#[test]
fn gates_follow_the_method() {
    let aligned = aligned_session(5.0, 2, TrackingMode::ThreePoint, 2);
    let engine = engine();
    let ego_only = run(&engine, &aligned, Method::EgoOnly);
    assert!(ego_only.gates.iter().all(|g| g.gates.iter().all(|f| f.iter().all(|&v| v == 0.0))));
    assert!(!ego_only.exo_evidence.iter().any(|&e| e), "ego-only uses no exo evidence");

    let ungated = run(&engine, &aligned, Method::EgoExoUngated);
    let gated = run(&engine, &aligned, Method::EgoExo);
    let mut any_evidence = false;
    for (f, keypoints) in aligned.observers[0].keypoints.iter().enumerate() {
        for k in 0..EXO_KEYPOINT_COUNT {
            let g = ungated.gates[0].gates[f][k];
            // Ungated: 1 exactly where a valid ray exists, else 0 (cross-fades average 1s to 1).
            assert!(g.abs() < 1e-5 || (g - 1.0).abs() < 1e-5, "frame {f} k {k}: {g}");
            if keypoints[k].is_none() {
                assert_eq!(g, 0.0);
            }
            let gated_value = gated.gates[0].gates[f][k];
            assert!((0.0..=1.0).contains(&gated_value));
            if keypoints[k].is_none() {
                assert_eq!(gated_value, 0.0, "no keypoint, no gate");
            }
        }
        any_evidence |= ungated.exo_evidence[f];
    }
    assert!(any_evidence, "the observers see the wearer some of the time");
    // The networks' outputs differ once exo evidence is fused.
    assert_ne!(ego_only.motion.poses, ungated.motion.poses);
}

#[test]
fn any_length_works_including_shorter_than_a_window() {
    let engine = engine();
    for seconds in [1.0, 3.2, 3.3, 11.0] {
        let aligned = aligned_session(seconds, 1, TrackingMode::OnePoint, 3);
        let r = run(&engine, &aligned, Method::EgoExo);
        assert_eq!(r.motion.len(), aligned.timeline.frames, "{seconds} s");
        assert_eq!(r.tracking, TrackingMode::OnePoint);
    }
}

#[test]
fn progress_counts_windows_and_cancel_stops() {
    let aligned = aligned_session(10.0, 1, TrackingMode::ThreePoint, 4);
    let engine = engine();
    let mut reports: Vec<Progress> = Vec::new();
    engine
        .reconstruct(&aligned, &ReconstructOptions::default(), &mut |p| {
            reports.push(p);
            true
        })
        .unwrap();
    let total = reports[0].total;
    // 300 frames with stride 48: windows at 0, 48, …, 192 and one ending at 300.
    assert_eq!(total, 6);
    assert_eq!(reports.iter().filter(|p| p.stage == Stage::Ego).count(), total);
    assert_eq!(reports.iter().filter(|p| p.stage == Stage::Fusion(Method::EgoExo)).count(), total);
    assert_eq!(reports.last().unwrap().done, total);

    let mut calls = 0;
    let err = engine
        .reconstruct(&aligned, &ReconstructOptions::default(), &mut |_| {
            calls += 1;
            calls < 3
        })
        .unwrap_err();
    assert!(matches!(err, InferError::Cancelled));
    assert_eq!(calls, 3);
}

#[test]
fn non_overlapping_segments_match_the_papers_protocol() {
    let aligned = aligned_session(7.0, 1, TrackingMode::ThreePoint, 5);
    let engine = engine();
    let options = ReconstructOptions {
        method: Method::EgoExo,
        stride: WINDOW,
        non_overlapping: true,
        tracking: None,
        floor_contact: true,
    };
    let mut ego_windows = 0;
    let r = engine
        .reconstruct(&aligned, &options, &mut |p| {
            ego_windows += usize::from(p.stage == Stage::Ego);
            true
        })
        .unwrap();
    assert_eq!(ego_windows, 3, "210 frames = 96 + 96 + 18");
    assert_eq!(r.motion.len(), 210);
}

#[test]
fn tracking_mode_errors_are_clear() {
    let one_point = aligned_session(2.0, 1, TrackingMode::OnePoint, 6);
    let options = ReconstructOptions { tracking: Some(TrackingMode::ThreePoint), ..ReconstructOptions::default() };
    assert!(matches!(engine().reconstruct(&one_point, &options, &mut |_| true), Err(InferError::MissingWrists)));
    let no_models = Engine::new();
    let err = no_models.reconstruct(&one_point, &ReconstructOptions::default(), &mut |_| true).unwrap_err();
    assert!(err.to_string().contains("no 1-point models"), "{err}");
    // A 3-point session can be reconstructed with the 1-point models.
    let three = aligned_session(2.0, 1, TrackingMode::ThreePoint, 6);
    let forced = ReconstructOptions { tracking: Some(TrackingMode::OnePoint), ..ReconstructOptions::default() };
    assert_eq!(engine().reconstruct(&three, &forced, &mut |_| true).unwrap().tracking, TrackingMode::OnePoint);
}

#[test]
fn rest_pose_baseline_stands_upright_facing_the_head() {
    let aligned = aligned_session(3.0, 1, TrackingMode::OnePoint, 7);
    let r = run(&engine(), &aligned, Method::RestPose);
    for (f, joints) in r.joints.iter().enumerate() {
        let up = joints[SmplJoint::Head.index()] - joints[SmplJoint::Pelvis.index()];
        assert!(up.normalize().dot(Vec3::Y) > 0.99, "frame {f}");
        let body_forward = r.motion.poses[f].root_orientation * Vec3::Z;
        let head_forward = aligned.head.poses[f].transform_vector(Vec3::Z);
        let flat = |v: Vec3| Vec3::new(v.x, 0.0, v.z).normalize();
        assert!(flat(body_forward).dot(flat(head_forward)) > 0.999, "frame {f}");
    }
}

/// Hand-tracking wrists that come and go: the session's default is the 3-point model, every
/// frame the head tracks is reconstructed (not only those with wrists), and the ego features
/// flag exactly the frames where each wrist is tracked.
#[test]
fn wrists_that_come_and_go_reconstruct_every_head_frame_in_3_point() {
    use egoexo_infer::inputs::ego_window;
    use egoexo_infer::windows::{WINDOW, plan_windows, valid_spans};
    use egoexo_session::{AlignOptions, align};
    use egoexo_synth::config::{HandTrackingModel, WristTracking};
    use egoexo_synth::procedural::walking_circle;
    use egoexo_synth::{SynthConfig, simulate};

    // The procedural walker's hands hang at its sides, at the edge of Aria's view: a wider
    // view cone sees them as they swing forward, part of the time.
    let wide = HandTrackingModel { view_half_angle_rad: 75f32.to_radians(), ..HandTrackingModel::default() };
    let config = SynthConfig { observers: 1, wrists: WristTracking::HandTracking(wide), ..SynthConfig::default() };
    let sim = simulate(&walking_circle(8.0), "walk", &config, 11).unwrap();
    let aligned = align(&sim.session, &AlignOptions::default()).unwrap();
    let coverage = aligned.wrist_coverage();
    assert!(coverage.iter().flatten().any(|&c| c > 0.05 && c < 0.98), "{coverage:?}");
    let choice = aligned.tracking_choice();
    assert_eq!(choice.mode, TrackingMode::ThreePoint);
    assert!(choice.reason.is_some());

    let recon = run(&engine(), &aligned, Method::EgoExo);
    assert_eq!(recon.tracking, TrackingMode::ThreePoint);
    assert!(recon.valid.iter().all(|&v| v), "every head frame is reconstructed");

    let plan = &plan_windows(&valid_spans(&aligned.head.valid), WINDOW, true)[0];
    let window = ego_window(&aligned, plan, TrackingMode::ThreePoint).unwrap();
    for t in 0..plan.len() {
        let row = &window.ego[t * EGO_FEATURE_DIM..(t + 1) * EGO_FEATURE_DIM];
        let frame = plan.frames.start + t;
        for (wrist, slot) in [(&aligned.left_wrist, 60), (&aligned.right_wrist, 61)] {
            let tracked = wrist.as_ref().is_some_and(|w| w.valid[frame]);
            assert_eq!(row[slot], f32::from(u8::from(tracked)), "frame {frame} slot {slot}");
        }
    }
}
