#![cfg(not(target_arch = "wasm32"))]
//! Registration of simulated sessions and captures whose observers were moved into worlds
//! (and clocks) of their own, with the shipped models' coarse body: the worlds land on the
//! truth, shared worlds that agree are kept, a world claimed shared but wrong is registered,
//! `off` leaves own worlds out, an observer that sees someone else is never fused, and a
//! capture's participants land in the anchor's world.

use egoexo_core::TrackingMode;
use egoexo_core::glam::Vec3;
use egoexo_core::rigid::RigidTransform;
use egoexo_infer::Engine;
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;
use egoexo_register::capture::register_capture;
use egoexo_register::{Outcome, RegisterMode, RegisterSettings, register_session};
use egoexo_session::Session;
use egoexo_session::align::{AlignOptions, align};
use egoexo_session::placement::{RegistrationStatus, WorldRef};
use egoexo_synth::group::{GroupConfig, group_walk, simulate_group};
use egoexo_synth::procedural::{walking_circle, wandering};
use egoexo_synth::worlds::{
    WorldPerturbation, WorldTruth, perturb_capture_worlds, perturb_observer_worlds, unpose_static_cameras,
};
use egoexo_synth::{SynthConfig, simulate};

/// The shipped 1-point networks (the coarse body a static camera's registration needs).
pub(crate) fn engine() -> Engine {
    let dir = egoexo_test_support::workspace_root().join("models");
    let manifest = Manifest::from_json(&std::fs::read(dir.join("manifest.json")).unwrap()).unwrap();
    let set = ModelSet::load(manifest.model_set(TrackingMode::OnePoint).unwrap(), |file| {
        std::fs::read(dir.join(file))
            .map_err(|e| egoexo_infer::InferError::ReadModel { file: file.into(), message: e.to_string() })
    })
    .unwrap();
    Engine::new().with_models(set)
}

fn session(seconds: f32, observers: usize, seed: u64) -> Session {
    let config = SynthConfig { observers, tracking: TrackingMode::OnePoint, ..SynthConfig::default() };
    simulate(&walking_circle(seconds), "walk", &config, seed).unwrap().session
}

fn settings(mode: RegisterMode) -> RegisterSettings {
    RegisterSettings { mode, ..RegisterSettings::default() }
}

/// Rotation error (degrees) of a registration against the truth, and its translation error
/// where it matters: at `scene` (session world, metres; the wearer's mean head position),
/// mapped from the observer's world by both.
/// A registration's error against the truth: its rotation (degrees) and how far (metres) it
/// puts `scene` (in the session's world) from where the truth does.
pub(crate) fn error(found: &RigidTransform, truth: &WorldTruth, scene: Vec3) -> (f32, f32) {
    let yaw = found.rotation.angle_between(truth.t_session_world.rotation).to_degrees();
    let own = truth.t_session_world.inverse().transform_point(scene);
    (yaw, found.transform_point(own).distance(scene))
}

/// The middle of the wearer's path.
pub(crate) fn scene_centre(s: &Session) -> Vec3 {
    let poses = &s.wearer.head.poses;
    poses.iter().map(|p| p.translation).sum::<Vec3>() / poses.len() as f32
}

#[test]
fn observers_in_worlds_of_their_own_are_registered_onto_the_truth() {
    let original = session(20.0, 2, 7);
    let mut moved = original.clone();
    let truth = perturb_observer_worlds(&mut moved, &WorldPerturbation::default(), 3);
    let engine = engine();
    let report =
        register_session(Some(&engine), TrackingMode::OnePoint, &mut moved, &settings(RegisterMode::Auto)).unwrap();
    for ((r, truth), (before, after)) in
        report.observers.iter().zip(&truth).zip(original.observers.iter().zip(&moved.observers))
    {
        assert_eq!(r.outcome, Outcome::Registered, "{}", r.message);
        let found = r.registration.as_ref().unwrap();
        let (yaw, translation) = error(&found.transform, truth, scene_centre(&original));
        eprintln!(
            "{}: {yaw:.2}° {:.1} cm at the scene, {:.1} cm at the origin",
            r.id,
            translation * 100.0,
            found.transform.translation.distance(truth.t_session_world.translation) * 100.0
        );
        assert!(yaw < 1.0 && translation < 0.05, "{}: {yaw}° {translation} m off ({})", r.id, r.message);
        // Applied: the poses are back in the wearer's world, the placement says so.
        assert!(after.placement.fusable() && after.placement.registration.as_ref().unwrap().applied);
        let worst = before
            .head
            .poses
            .iter()
            .zip(&after.head.poses)
            .map(|(a, b)| a.translation.distance(b.translation))
            .fold(0.0, f32::max);
        assert!(worst < 0.1, "{}: the observer's head is up to {worst} m from where it was", r.id);
    }
    // Aligned, the observers bring their views again; registering again keeps them.
    let aligned = align(&moved, &AlignOptions::default()).unwrap();
    assert!(aligned.observers.iter().all(|o| o.head.valid.iter().any(|&v| v)));
    let again =
        register_session(Some(&engine), TrackingMode::OnePoint, &mut moved, &settings(RegisterMode::Auto)).unwrap();
    assert!(again.observers.iter().all(|r| r.outcome == Outcome::Kept && r.message.contains("registered before")));
}

#[test]
fn shared_worlds_that_agree_are_kept_and_a_wrong_one_is_registered() {
    let mut s = session(15.0, 2, 11);
    let original = s.clone();
    // The second observer claims the wearer's world but is 3 m and 40° off.
    let truth = {
        let mut one = Session { observers: vec![s.observers[1].clone()], ..s.clone() };
        let p = WorldPerturbation { max_yaw_deg: 40.0, max_translation_m: 3.0, ..WorldPerturbation::default() };
        let truth = perturb_observer_worlds(&mut one, &p, 5).remove(0);
        s.observers[1] = one.observers.remove(0);
        s.observers[1].placement.world = WorldRef::Shared;
        truth
    };
    let report =
        register_session(Some(&engine()), TrackingMode::OnePoint, &mut s, &settings(RegisterMode::Auto)).unwrap();
    let kept = &report.observers[0];
    assert_eq!(kept.outcome, Outcome::Kept, "{}", kept.message);
    assert_eq!(kept.registration.as_ref().unwrap().status, RegistrationStatus::AsGiven);
    assert_eq!(s.observers[0].head, original.observers[0].head, "a kept world is not moved");
    let fixed = &report.observers[1];
    assert_eq!(fixed.outcome, Outcome::Registered, "{}", fixed.message);
    assert!(fixed.message.contains("does not explain its views"), "{}", fixed.message);
    let (yaw, translation) = error(&fixed.registration.as_ref().unwrap().transform, &truth, scene_centre(&original));
    assert!(yaw < 1.0 && translation < 0.05, "{yaw}° {translation} m");
}

#[test]
fn off_leaves_own_worlds_out_and_force_registers_shared_ones() {
    let mut s = session(12.0, 2, 13);
    perturb_observer_worlds(
        &mut Session { observers: vec![s.observers[0].clone()], ..s.clone() },
        &WorldPerturbation::default(),
        1,
    );
    s.observers[0].placement.world = WorldRef::Own;
    let mut off = s.clone();
    let report = register_session(None, TrackingMode::OnePoint, &mut off, &settings(RegisterMode::Off)).unwrap();
    assert_eq!(report.observers[0].outcome, Outcome::LeftOut);
    assert!(report.observers[0].message.contains("registration is off"), "{}", report.observers[0].message);
    assert_eq!(report.observers[1].outcome, Outcome::Kept);
    let aligned = align(&off, &AlignOptions::default()).unwrap();
    assert!(!aligned.observers[0].head.valid.iter().any(|&v| v), "left out of the fusion");
    // `force` registers every observer, the shared one too (face points only: no engine).
    let report = register_session(None, TrackingMode::OnePoint, &mut s, &settings(RegisterMode::Force)).unwrap();
    for r in &report.observers {
        assert!(r.registration.is_some() && r.message.starts_with("registration forced"), "{}", r.message);
    }
}

#[test]
fn an_own_clock_is_found() {
    // A wandering walk: on a circle at constant speed a clock offset is a rotation of the world.
    let config = SynthConfig { observers: 1, tracking: TrackingMode::OnePoint, ..SynthConfig::default() };
    let mut s = simulate(&wandering(20.0), "wander", &config, 17).unwrap().session;
    let p = WorldPerturbation { max_clock_offset_s: 1.5, ..WorldPerturbation::default() };
    let truth = perturb_observer_worlds(&mut s, &p, 9).remove(0);
    let report =
        register_session(Some(&engine()), TrackingMode::OnePoint, &mut s, &settings(RegisterMode::Auto)).unwrap();
    let r = &report.observers[0];
    assert_eq!(r.outcome, Outcome::Registered, "{}", r.message);
    let found = r.registration.as_ref().unwrap();
    assert!(
        (found.clock_offset_s - truth.clock_offset_s).abs() < 0.05,
        "{} vs {}",
        found.clock_offset_s,
        truth.clock_offset_s
    );
}

#[test]
fn an_observer_that_sees_someone_else_is_never_fused() {
    let mut s = session(15.0, 1, 19);
    // Its keypoints are of another walk entirely (another seed, another circle phase).
    let other = session(15.0, 1, 23);
    s.observers[0].keypoints = other.observers[0].keypoints.clone();
    s.observers[0].placement.world = WorldRef::Own;
    let report =
        register_session(Some(&engine()), TrackingMode::OnePoint, &mut s, &settings(RegisterMode::Auto)).unwrap();
    let r = &report.observers[0];
    assert_eq!(r.outcome, Outcome::LeftOut, "{}", r.message);
    assert!(!s.observers[0].placement.fusable());
}

#[test]
fn a_capture_lands_in_the_anchors_world() {
    let config = GroupConfig { tracking: TrackingMode::OnePoint, bystanders: 0, ..GroupConfig::default() };
    let sim = simulate_group(&group_walk(3, 20.0), "group", &config, 29).unwrap();
    let mut capture = sim.with_true_identities();
    let truth = perturb_capture_worlds(&mut capture, &WorldPerturbation::default(), 31);
    let report =
        register_capture(Some(&engine()), Some(TrackingMode::OnePoint), &mut capture, 0, &settings(RegisterMode::Auto))
            .unwrap();
    assert_eq!(report.anchor, "participant-1");
    assert!(!report.pairs.is_empty());
    for (r, truth) in report.participants.iter().zip(&truth) {
        assert_eq!(r.id, truth.id);
        assert_eq!(r.outcome, Outcome::Registered, "{}", r.message);
        let (yaw, translation) = error(&r.registration.as_ref().unwrap().transform, truth, Vec3::new(0.0, 1.0, 0.0));
        assert!(yaw < 1.0 && translation < 0.05, "{}: {yaw}° {translation} m", r.id);
    }
    assert!(capture.participants.iter().all(|p| p.placement.fusable()));
}

#[test]
fn a_clock_offset_on_a_circle_walked_at_constant_speed_is_never_confidently_wrong() {
    // There a clock offset and a rotation of the world about the circle's centre look alike.
    let mut s = session(20.0, 1, 0);
    let p = WorldPerturbation { max_clock_offset_s: 1.5, ..WorldPerturbation::default() };
    let truth = perturb_observer_worlds(&mut s, &p, 9).remove(0);
    let report =
        register_session(Some(&engine()), TrackingMode::OnePoint, &mut s, &settings(RegisterMode::Auto)).unwrap();
    let r = &report.observers[0];
    let found = r.registration.as_ref().unwrap();
    let right = (found.clock_offset_s - truth.clock_offset_s).abs() < 0.05;
    assert!(r.outcome == Outcome::LeftOut || right, "{}", r.message);
    if r.outcome == Outcome::LeftOut {
        assert_eq!(found.status, RegistrationStatus::NotEnoughMotion, "{}", r.message);
    }
}

#[test]
fn a_static_camera_without_pose_is_placed_in_the_wearers_world() {
    // Two tripods aimed at the middle of the wearer's wandering path, knowing nothing of their
    // pose: registered in 6 DoF, each lands where it stands.
    let mut config = SynthConfig { observers: 2, tracking: TrackingMode::OnePoint, ..SynthConfig::default() };
    config.observer.static_camera = true;
    config.observer_noise = egoexo_synth::config::DeviceNoise::none();
    let original = simulate(&wandering(20.0), "tripods", &config, 31).unwrap().session;
    assert!(original.observers.iter().all(|o| o.head.poses.windows(2).all(|w| w[0] == w[1])), "tripods do not move");
    let mut s = original.clone();
    let truth = unpose_static_cameras(&mut s, true);
    assert!(s.observers.iter().all(|o| !o.placement.fusable()));
    let report =
        register_session(Some(&engine()), TrackingMode::OnePoint, &mut s, &settings(RegisterMode::Auto)).unwrap();
    for (r, t) in report.observers.iter().zip(&truth) {
        let found = r.registration.as_ref().unwrap();
        assert_eq!(r.outcome, Outcome::Registered, "{}: {}", r.id, r.message);
        assert_eq!(found.dof, egoexo_solve::registration::Dof::Six);
        let (deg, m) = error(&found.transform, t, scene_centre(&original));
        assert!(deg < 2.0 && m < 0.05, "{}: {deg}°, {m} m", r.id);
    }
    assert!(s.observers.iter().all(|o| o.placement.fusable()));
}
