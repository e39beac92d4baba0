//! Every simulator effect, measured on simulated sessions.

mod common;

use common::*;
use egoexo_core::TrackingMode;
use egoexo_core::exo_keypoints::coco17_from_exo;
use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, ExoKeypoint, exo_keypoints_from_smpl};
use egoexo_core::glam::Vec3;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::rotation::angle_between;
use egoexo_core::skeleton::SmplJoint;
use egoexo_synth::config::{DeviceNoise, SynthConfig};
use egoexo_synth::{SimulatedSession, simulate};

fn clean_config() -> SynthConfig {
    SynthConfig { wearer_noise: DeviceNoise::none(), observer_noise: DeviceNoise::none(), ..SynthConfig::default() }
}

fn median(mut v: Vec<f32>) -> f32 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// The true pixel of every exo keypoint for observer `o` at frame `f`.
fn true_pixels(sim: &SimulatedSession, o: usize, f: usize) -> [Option<egoexo_core::glam::Vec2>; EXO_KEYPOINT_COUNT] {
    let gt = &sim.session.ground_truth.as_ref().unwrap().motion;
    let fk = gt.skeleton.forward_kinematics(&gt.poses[f]);
    let exo = exo_keypoints_from_smpl(
        &fk.positions,
        fk.rotations[SmplJoint::Head.index()],
        gt.skeleton.head_height() / 1.4963,
    );
    let camera = &sim.session.observers[o].camera;
    exo.map(|p| camera.project_world(p, &sim.true_observer_heads[o][f]))
}

#[test]
fn same_seed_same_session_other_seed_other_session() {
    let motion = walking_circle(6.0);
    let config = SynthConfig { observers: 2, ..SynthConfig::default() };
    let a = simulate(&motion, "clip", &config, 7).unwrap();
    let b = simulate(&motion, "clip", &config, 7).unwrap();
    let c = simulate(&motion, "clip", &config, 8).unwrap();
    assert_eq!(a, b);
    assert_ne!(a.session.wearer.head.poses, c.session.wearer.head.poses);
    assert_ne!(a.session.observers[0].keypoints, c.session.observers[0].keypoints);
}

#[test]
fn glasses_sit_at_the_head_joint_offset_and_wrists_on_the_wrist_joints() {
    let motion = walking_circle(3.0);
    let sim = simulate(&motion, "clip", &clean_config(), 1).unwrap();
    let wearer = &sim.session.wearer;
    for (f, pose) in motion.poses.iter().enumerate() {
        let fk = motion.skeleton.forward_kinematics(pose);
        let glasses = &wearer.head.poses[f];
        // Root recovery from the glasses with the true body pose gives back the true pelvis.
        let t = motion.skeleton.recover_translation(
            pose.root_orientation,
            &pose.body,
            glasses,
            wearer.head_joint_in_device,
        );
        assert!(t.abs_diff_eq(pose.translation, 1e-4), "frame {f}");
        // The glasses are in front of (+Z) and above (+Y) the head joint, in the head's frame.
        let offset = glasses.rotation.conjugate() * (glasses.translation - fk.positions[SmplJoint::Head.index()]);
        assert!(offset.z > 0.05 && offset.y > 0.03, "{offset:?}");
        let left = &wearer.left_wrist.as_ref().unwrap().poses[f];
        assert!(left.translation.abs_diff_eq(fk.positions[SmplJoint::LeftWrist.index()], 1e-5));
    }
    let one_point = SynthConfig { tracking: TrackingMode::OnePoint, ..clean_config() };
    let sim1 = simulate(&motion, "clip", &one_point, 1).unwrap();
    assert!(sim1.session.wearer.left_wrist.is_none() && sim1.session.wearer.right_wrist.is_none());
}

#[test]
fn device_noise_is_millimetre_jitter_sub_degree_rotation_and_slow_drift() {
    let motion = walking_circle(20.0);
    let clean = simulate(&motion, "clip", &clean_config(), 3).unwrap();
    let mut jitter_only = clean_config();
    jitter_only.wearer_noise =
        DeviceNoise { position_drift_m_per_sqrt_s: 0.0, yaw_drift_rad_per_sqrt_s: 0.0, ..DeviceNoise::default() };
    let noisy = simulate(&motion, "clip", &jitter_only, 3).unwrap();
    let pairs = || clean.session.wearer.head.poses.iter().zip(&noisy.session.wearer.head.poses);
    let position_errors: Vec<f32> = pairs().map(|(a, b)| a.translation.distance(b.translation)).collect();
    let angle_errors: Vec<f32> = pairs().map(|(a, b)| angle_between(a.rotation, b.rotation).to_degrees()).collect();
    // |N(0, σ²I₃)| has median ≈ 1.54 σ: σ = 2 mm → ≈ 3 mm.
    let p = median(position_errors);
    assert!((0.002..0.0045).contains(&p), "median position jitter {p} m");
    let a = median(angle_errors);
    assert!(a > 0.05 && a < 1.0, "median orientation jitter {a}°");

    // Drift: a random walk, so the error late in a long recording exceeds the early error.
    let mut drift_only = clean_config();
    drift_only.wearer_noise =
        DeviceNoise { position_jitter_m: 0.0, orientation_jitter_rad: 0.0, ..DeviceNoise::default() };
    let (mut early, mut late) = (0.0, 0.0);
    for seed in 0..20 {
        let sim = simulate(&motion, "clip", &drift_only, seed).unwrap();
        let err = |f: usize| {
            sim.session.wearer.head.poses[f].translation.distance(clean.session.wearer.head.poses[f].translation)
        };
        early += err(15);
        late += err(motion.len() - 1);
    }
    assert!(late > 3.0 * early, "drift grows: early {early}, late {late}");
    assert!(late / 20.0 < 0.05, "but stays centimetre-level over 20 s: {}", late / 20.0);
}

#[test]
fn observers_start_1_5_to_8_m_away_and_stand_or_walk() {
    let motion = walking_circle(10.0);
    let (mut standing, mut walking) = (0, 0);
    for seed in 0..30 {
        let sim = simulate(&motion, "clip", &clean_config(), seed).unwrap();
        let report = &sim.observers[0];
        let head = &sim.true_observer_heads[0];
        let wearer0 = sim.session.wearer.head.poses[0].translation;
        let d0 = Vec3::new(head[0].translation.x - wearer0.x, 0.0, head[0].translation.z - wearer0.z).length();
        assert!((1.4..8.3).contains(&d0), "initial distance {d0}");
        let travelled = head[0].translation.distance(head[head.len() - 1].translation);
        if report.walking {
            walking += 1;
            assert!(travelled > 0.5, "a walking observer follows the wearer ({travelled} m)");
        } else {
            standing += 1;
            assert!(travelled < 0.15, "a standing observer stays put ({travelled} m)");
        }
        for (f, h) in head.iter().enumerate() {
            let w = sim.session.wearer.head.poses[f].translation;
            assert!(
                Vec3::new(h.translation.x - w.x, 0.0, h.translation.z - w.z).length() > 1.2,
                "personal space at frame {f}"
            );
        }
    }
    assert!(standing >= 5 && walking >= 5, "both behaviours occur: {standing} standing, {walking} walking");
}

#[test]
fn look_aways_take_the_wearer_out_of_view_for_half_to_five_seconds() {
    let motion = walking_circle(60.0);
    let (mut away, mut total, mut away_detected, mut toward_detected, mut toward) =
        (0usize, 0usize, 0usize, 0usize, 0usize);
    let mut spans = Vec::new();
    for seed in 0..6 {
        let mut config = clean_config();
        config.occlusion.furniture_probability = 0.0;
        config.occlusion.max_bystanders = 0;
        let sim = simulate(&motion, "clip", &config, seed).unwrap();
        let track = sim.session.observers[0].keypoints.as_ref().unwrap();
        let flags: Vec<bool> = (0..motion.len())
            .map(|f| {
                // Looking away ⇔ the true gaze is far from the wearer.
                let head = &sim.true_observer_heads[0][f];
                let to_wearer = (sim.session.wearer.head.poses[f].translation - head.translation).normalize();
                head.transform_vector(Vec3::Z).angle_between(to_wearer) > 60f32.to_radians()
            })
            .collect();
        let mut run = 0;
        for (f, &a) in flags.iter().enumerate() {
            let detected = track.frames[f].iter().any(Option::is_some);
            total += 1;
            if a {
                away += 1;
                away_detected += usize::from(detected);
                run += 1;
            } else {
                toward += 1;
                toward_detected += usize::from(detected);
                if run > 0 {
                    spans.push(run as f32 / FPS);
                }
                run = 0;
            }
        }
    }
    let away_fraction = away as f32 / total as f32;
    // Expected ≈ mean span / (mean interval + mean span) = 2.75 / 14.75 ≈ 0.19.
    assert!((0.05..0.4).contains(&away_fraction), "fraction of frames looking away {away_fraction}");
    assert!((away_detected as f32) < 0.05 * away as f32, "looking away, the wearer is out of the image");
    assert!(toward_detected as f32 > 0.8 * toward as f32, "looking at them, the wearer is mostly detected");
    assert!(!spans.is_empty());
    // Spans measured by gaze angle include the head turning away and back (~0.3 s).
    for s in &spans {
        assert!((0.2..6.0).contains(s), "look-away span {s} s");
    }
}

#[test]
fn saccades_keep_the_gaze_near_but_not_on_the_wearer() {
    let motion = walking_circle(30.0);
    let sim = simulate(&motion, "clip", &clean_config(), 11).unwrap();
    let offsets: Vec<f32> = (0..motion.len())
        .filter_map(|f| {
            let head = &sim.true_observer_heads[0][f];
            let chest = motion.skeleton.forward_kinematics(&motion.poses[f]).positions[SmplJoint::Spine3.index()];
            let a = head.transform_vector(Vec3::Z).angle_between((chest - head.translation).normalize()).to_degrees();
            (a < 40.0).then_some(a)
        })
        .collect();
    let m = median(offsets);
    assert!(m > 1.0 && m < 15.0, "median gaze offset from the wearer {m}°");
}

#[test]
fn cameras_are_mostly_aria_fisheye_at_1408_or_2880() {
    let motion = walking_circle(1.0);
    let (mut fisheye, mut sizes) = (0, std::collections::BTreeSet::new());
    for seed in 0..40 {
        let sim = simulate(&motion, "clip", &clean_config(), seed).unwrap();
        fisheye += usize::from(sim.observers[0].fisheye);
        sizes.insert(sim.session.observers[0].camera.width);
    }
    assert!((22..=38).contains(&fisheye), "{fisheye}/40 fisheye");
    assert_eq!(sizes.into_iter().collect::<Vec<_>>(), vec![1408, 2880]);
}

#[test]
fn keypoint_noise_grows_with_distance_and_scores_are_high_when_visible() {
    let motion = walking_circle(30.0);
    let mut config = clean_config();
    config.occlusion.furniture_probability = 0.0;
    config.occlusion.max_bystanders = 0;
    config.camera.image_sizes = vec![1408];
    let (mut near, mut far, mut scores, mut detected, mut visible) = (vec![], vec![], vec![], 0usize, 0usize);
    for seed in 0..8 {
        let sim = simulate(&motion, "clip", &config, seed).unwrap();
        let track = sim.session.observers[0].keypoints.as_ref().unwrap();
        for f in 0..motion.len() {
            let truth = true_pixels(&sim, 0, f);
            let camera = &sim.session.observers[0].camera;
            let frame_has_detection = track.frames[f].iter().any(Option::is_some);
            let distance =
                sim.true_observer_heads[0][f].translation.distance(sim.session.wearer.head.poses[f].translation);
            for k in ExoKeypoint::ALL {
                let Some(true_px) = truth[k.index()].filter(|p| camera.is_valid_pixel(*p)) else {
                    // Truncated: never reported.
                    assert!(track.frames[f][k.coco17_index()].is_none(), "a keypoint outside the image was reported");
                    continue;
                };
                if !frame_has_detection {
                    continue;
                }
                visible += 1;
                if let Some(kp) = track.frames[f][k.coco17_index()] {
                    detected += 1;
                    scores.push(kp.score);
                    let err = kp.pixel.distance(true_px);
                    if distance < 3.0 {
                        near.push(err);
                    } else if distance > 5.5 {
                        far.push(err);
                    }
                }
            }
        }
    }
    let (n, f) = (median(near), median(far));
    assert!(f > 1.3 * n, "pixel error grows with distance: near {n} px, far {f} px");
    assert!(n > 1.0 && f < 10.0, "pixel-level noise: near {n}, far {f}");
    let s = median(scores);
    assert!((0.8..0.9).contains(&s), "visible keypoint median score {s}");
    let miss = 1.0 - detected as f32 / visible as f32;
    assert!((0.01..0.06).contains(&miss), "missed keypoint rate {miss}");
}

#[test]
fn furniture_occludes_and_fools_the_detector_with_confident_wrong_keypoints() {
    let motion = walking_circle(20.0);
    let mut config = clean_config();
    config.occlusion.furniture_probability = 1.0;
    config.occlusion.max_bystanders = 0;
    let (mut confident_scores, mut low_scores, mut confident_errors, mut clean_errors) =
        (vec![], vec![], vec![], vec![]);
    let (mut occluded, mut labelled_frames) = (0usize, 0usize);
    for seed in 0..10 {
        let sim = simulate(&motion, "clip", &config, seed).unwrap();
        assert_eq!(sim.scene.furniture.len(), 1);
        let gt = sim.session.ground_truth.as_ref().unwrap();
        let masks = &gt.occlusion[0].occluded;
        assert_eq!(masks.len(), motion.len());
        let track = sim.session.observers[0].keypoints.as_ref().unwrap();
        for f in 0..motion.len() {
            labelled_frames += usize::from(masks[f] != 0);
            let truth = true_pixels(&sim, 0, f);
            for k in ExoKeypoint::ALL {
                let (Some(kp), Some(true_px)) = (track.frames[f][k.coco17_index()], truth[k.index()]) else { continue };
                let err = kp.pixel.distance(true_px);
                if masks[f] & (1 << k.index()) != 0 {
                    occluded += 1;
                    if kp.score >= 0.6 {
                        confident_scores.push(kp.score);
                        confident_errors.push(err);
                    } else {
                        low_scores.push(kp.score);
                    }
                } else {
                    clean_errors.push(err);
                }
            }
        }
    }
    assert!(
        labelled_frames > 0 && occluded > 50,
        "furniture occludes: {occluded} keypoints in {labelled_frames} frames"
    );
    let confident_share = confident_scores.len() as f32 / occluded as f32;
    assert!(
        (0.45..0.75).contains(&confident_share),
        "share of occluded keypoints reported confidently {confident_share}"
    );
    assert!(low_scores.iter().all(|&s| s <= 0.35));
    assert!(median(confident_scores) > 0.7, "confidently wrong keypoints score like visible ones");
    assert!(median(confident_errors) > 4.0 * median(clean_errors), "…but sit far from the truth");
}

#[test]
fn an_occlusion_episode_fools_the_detector_the_same_way_on_every_frame() {
    // A real detector behind the same occluder repeats its mistake; mistakes drawn afresh each
    // frame would average out over time and teach the networks to ignore them.
    let motion = walking_circle(20.0);
    let mut config = clean_config();
    config.occlusion.furniture_probability = 1.0;
    config.occlusion.max_bystanders = 0;
    let (mut kind_kept, mut kind_changed) = (0usize, 0usize);
    let (mut wrong_offsets, mut offset_steps) = (vec![], vec![]);
    for seed in 0..10 {
        let sim = simulate(&motion, "clip", &config, seed).unwrap();
        let masks = &sim.session.ground_truth.as_ref().unwrap().occlusion[0].occluded;
        let track = sim.session.observers[0].keypoints.as_ref().unwrap();
        let mut previous: [Option<(bool, egoexo_core::glam::Vec2)>; EXO_KEYPOINT_COUNT] = [None; EXO_KEYPOINT_COUNT];
        for f in 0..motion.len() {
            let truth = true_pixels(&sim, 0, f);
            for k in ExoKeypoint::ALL {
                let now = match (track.frames[f][k.coco17_index()], truth[k.index()]) {
                    (Some(kp), Some(true_px)) if masks[f] & (1 << k.index()) != 0 => {
                        Some((kp.score >= 0.6, kp.pixel - true_px))
                    }
                    _ => None,
                };
                if let (Some((was_confident, before)), Some((confident, offset))) = (previous[k.index()], now) {
                    if was_confident == confident {
                        kind_kept += 1;
                    } else {
                        kind_changed += 1;
                    }
                    if confident && was_confident {
                        wrong_offsets.push(offset.length());
                        offset_steps.push((offset - before).length());
                    }
                }
                previous[k.index()] = now;
            }
        }
    }
    assert!(kind_kept > 50, "{kind_kept} consecutive occluded detections");
    assert_eq!(kind_changed, 0, "an episode is confidently wrong or low-score throughout");
    let (offset, step) = (median(wrong_offsets), median(offset_steps));
    assert!(
        step < 0.3 * offset,
        "a confidently wrong keypoint stays where it was: {offset} px off the joint, moving {step} px per frame"
    );
}

#[test]
fn bystanders_walk_between_observer_and_wearer() {
    let motion = walking_circle(20.0);
    let mut config = clean_config();
    config.occlusion.furniture_probability = 0.0;
    config.occlusion.max_bystanders = 2;
    let mut occluded = 0;
    let mut bystanders = 0;
    for seed in 0..10 {
        let sim = simulate(&motion, "clip", &config, seed).unwrap();
        bystanders += sim.scene.bystanders.len();
        occluded += sim.observers[0].occluded_keypoints;
        assert!(sim.scene.furniture.is_empty());
    }
    assert!(bystanders > 5, "{bystanders} bystanders in 10 sessions");
    assert!(occluded > 0, "bystanders occlude some keypoints");
}

#[test]
fn several_observers_get_distinct_ids_cameras_and_views() {
    let motion = walking_circle(4.0);
    let sim = simulate(&motion, "clip", &SynthConfig { observers: 3, ..clean_config() }, 5).unwrap();
    let ids: Vec<_> = sim.session.observers.iter().map(|o| o.id.as_str()).collect();
    assert_eq!(ids, ["observer-1", "observer-2", "observer-3"]);
    assert_eq!(sim.session.ground_truth.as_ref().unwrap().occlusion.len(), 3);
    assert_ne!(sim.true_observer_heads[0][0].translation, sim.true_observer_heads[1][0].translation);
    let _ = (RigidTransform::IDENTITY, coco17_from_exo);
}

/// Hand tracking from the glasses: a wrist is reported only where it was inside the view
/// cone, at its true place within the detection noise, on a subset of the head's
/// timestamps; a wrist held in front of the face is seen almost always, a wrist hanging at
/// the side almost never.
#[test]
fn hand_tracking_reports_wrists_only_inside_the_glasses_view() {
    use egoexo_core::glam::Quat;
    use egoexo_session::model::WristSource;
    use egoexo_synth::config::{HandTrackingModel, WristTracking};
    use egoexo_synth::devices::simulate_hand_tracking;
    use egoexo_synth::rng::SimRng;

    let model = HandTrackingModel::default();
    let fps = 30.0;
    let glasses = vec![RigidTransform::from_translation(Vec3::new(0.0, 1.6, 0.0)); 300];
    // CPF: +Z forward, +Y up, +X left. In front and below the eyes: in view.
    let front = vec![RigidTransform::new(Quat::IDENTITY, Vec3::new(0.05, 1.3, 0.35)); 300];
    // Hanging at the side, beside the hip: out of view.
    let side = vec![RigidTransform::new(Quat::IDENTITY, Vec3::new(0.25, 0.85, 0.0)); 300];
    let mut rng = SimRng::new(3);
    let seen_front = simulate_hand_tracking(&glasses, &glasses, &front, fps, &model, &mut rng);
    let seen_side = simulate_hand_tracking(&glasses, &glasses, &side, fps, &model, &mut rng);
    let front_fraction = seen_front.frames.len() as f32 / 300.0;
    assert!((0.85..1.0).contains(&front_fraction), "in front: seen on {front_fraction} of frames (dropouts only)");
    assert!(seen_side.frames.is_empty(), "at the side: seen on {} frames", seen_side.frames.len());
    for (pose, c) in seen_front.poses.iter().zip(&seen_front.confidence) {
        assert!(pose.translation.distance(front[0].translation) < 0.05);
        assert!((model.min_confidence..=1.0).contains(c));
    }

    // In a simulated session: the wrists are a subset of the head's frames, marked as hand
    // tracking; a walking wearer's swinging hands are seen only part of the time (the
    // procedural walker's hands hang at the edge of Aria's view; a wider cone sees them swing
    // forward).
    let motion = walking_circle(8.0);
    let wide = HandTrackingModel { view_half_angle_rad: 75f32.to_radians(), ..model };
    let config = SynthConfig { wrists: WristTracking::HandTracking(wide), ..SynthConfig::default() };
    let sim = simulate(&motion, "clip", &config, 5).unwrap();
    let wearer = &sim.session.wearer;
    assert!(matches!(wearer.wrist_source, WristSource::HandTracking { .. }));
    let head_times = &wearer.head.timestamps_ns;
    assert!(wearer.left_wrist.is_some() || wearer.right_wrist.is_some(), "a hand is seen at some point");
    for wrist in [&wearer.left_wrist, &wearer.right_wrist].into_iter().flatten() {
        assert!(wrist.timestamps_ns.iter().all(|t| head_times.binary_search(t).is_ok()));
        assert!(wrist.timestamps_ns.len() < head_times.len(), "a walking wearer's wrist is not always in view");
    }
    let devices = simulate(&motion, "clip", &SynthConfig::default(), 5).unwrap();
    assert_eq!(devices.session.wearer.left_wrist.as_ref().unwrap().timestamps_ns.len(), head_times.len());
}
