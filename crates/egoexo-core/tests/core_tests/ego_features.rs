//! The ego feature vector: layout, invariances, velocities, 1-point mode, bad input.

#[cfg(target_arch = "wasm32")]
use wasm_bindgen_test::wasm_bindgen_test as test;

use crate::common::*;
use egoexo_core::ego_features::{
    EGO_FEATURE_DIM, EGO_FEATURE_LAYOUT_VERSION, EgoFeatureLayout as L, EgoTrajectories, FeatureError, TrackingMode,
    WristTrack, ego_features, heading_yaw,
};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::rotation::Rot6d;
use proptest::prelude::*;

const FPS: f32 = 30.0;

/// A wandering head with wrists swinging beside it, `n` frames.
fn trajectories(n: usize, seed: f32) -> [Vec<RigidTransform>; 3] {
    let head: Vec<_> = (0..n)
        .map(|i| {
            let t = i as f32 / FPS;
            let yaw = 0.3 * (t + seed).sin() + seed;
            let rot = Quat::from_rotation_y(yaw) * Quat::from_rotation_x(0.2 * (2.0 * t).sin());
            RigidTransform::new(rot, Vec3::new(1.2 * t + seed, 1.6 + 0.03 * (9.0 * t).sin(), 0.4 * t.sin()))
        })
        .collect();
    let wrist = |side: f32| -> Vec<RigidTransform> {
        head.iter()
            .enumerate()
            .map(|(i, h)| {
                let swing = 0.3 * (6.0 * i as f32 / FPS + side).sin();
                let local = Vec3::new(0.25 * side, -0.55, swing);
                RigidTransform::new(h.rotation * Quat::from_rotation_x(swing), h.transform_point(local))
            })
            .collect()
    };
    let (left, right) = (wrist(1.0), wrist(-1.0));
    [head, left, right]
}

fn three_point(t: &[Vec<RigidTransform>; 3]) -> EgoTrajectories<'_> {
    EgoTrajectories {
        head: &t[0],
        left_wrist: Some(WristTrack::always(&t[1])),
        right_wrist: Some(WristTrack::always(&t[2])),
    }
}

#[test]
fn layout_is_the_papers_sixty_numbers_and_two_wrist_validity_slots() {
    assert_eq!(EGO_FEATURE_DIM, 62);
    assert_eq!(EGO_FEATURE_LAYOUT_VERSION, 2);
    assert_eq!(L::HEAD.len() + L::LEFT_WRIST.len() + L::RIGHT_WRIST.len(), 54);
    assert_eq!(L::DISPLACEMENT, 54..60);
    assert_eq!((L::LEFT_WRIST_VALID, L::RIGHT_WRIST_VALID), (60, 61));
    let one = L::new(TrackingMode::OnePoint);
    assert!(!one.wrists_present && one.version == EGO_FEATURE_LAYOUT_VERSION);
    assert!(L::new(TrackingMode::ThreePoint).wrists_present);
}

#[test]
fn first_frame_head_sits_at_the_window_origin_facing_forward() {
    let t = trajectories(40, 0.7);
    let f = ego_features(&three_point(&t), 10..40, FPS, TrackingMode::ThreePoint).unwrap();
    assert_eq!(f.frames(), 30);
    let row = f.row(0);
    assert_eq!(&row[12..15], &[0.0, 0.0, 0.0]);
    // The heading is removed: the first orientation has zero yaw in the window frame.
    let r0 = Rot6d(row[0..6].try_into().unwrap()).to_quat();
    assert!(heading_yaw(r0).abs() < 1e-5);
    // The window frame maps back to the world pose.
    assert!(f.t_world_window.translation.abs_diff_eq(t[0][10].translation, 1e-6));
}

#[test]
fn one_point_mode_zeroes_the_wrist_slots() {
    let t = trajectories(20, 0.1);
    let one = EgoTrajectories { head: &t[0], left_wrist: None, right_wrist: None };
    let f1 = ego_features(&one, 0..20, FPS, TrackingMode::OnePoint).unwrap();
    let f3 = ego_features(&three_point(&t), 0..20, FPS, TrackingMode::ThreePoint).unwrap();
    assert!(!f1.layout.wrists_present);
    for i in 0..20 {
        assert!(f1.row(i)[18..54].iter().all(|&v| v == 0.0));
        assert_eq!(f1.row(i)[60..62], [0.0, 0.0]);
        assert!(f3.row(i)[18..54].iter().any(|&v| v != 0.0));
        assert_eq!(f3.row(i)[60..62], [1.0, 1.0]);
        assert_eq!(f1.row(i)[0..18], f3.row(i)[0..18]);
        assert_eq!(f1.row(i)[54..60], f3.row(i)[54..60]);
    }
    // Wrists given but 1-point requested: still zero (the model decides, not the data).
    let f = ego_features(&three_point(&t), 0..20, FPS, TrackingMode::OnePoint).unwrap();
    assert_eq!(f.features, f1.features);
}

#[test]
fn constant_velocity_walk_has_that_velocity_and_displacement() {
    // Walking along world −X at 1.5 m/s while facing −X: in the window frame that is forward
    // (+Z) at 1.5 m/s, and the displacement encoding grows linearly.
    let facing = Quat::from_rotation_y(-std::f32::consts::FRAC_PI_2);
    let head: Vec<_> =
        (0..31).map(|i| RigidTransform::new(facing, Vec3::new(-1.5 * i as f32 / FPS, 1.7, 0.0))).collect();
    let traj = EgoTrajectories { head: &head, left_wrist: None, right_wrist: None };
    let f = ego_features(&traj, 0..31, FPS, TrackingMode::OnePoint).unwrap();
    assert_eq!(&f.row(0)[15..18], &[0.0, 0.0, 0.0], "no velocity at the first frame of a sequence");
    for i in 1..31 {
        let row = f.row(i);
        let v = Vec3::from_slice(&row[15..18]);
        assert!(v.abs_diff_eq(Vec3::new(0.0, 0.0, 1.5), 1e-4), "{v:?}");
        let d = 1.5 * i as f32 / FPS;
        let expected = [0.0, d, 0.0, d, d, 0.0];
        for (a, b) in row[54..60].iter().zip(expected) {
            assert!((a - b).abs() < 1e-4, "{:?} vs {expected:?}", &row[54..60]);
        }
        // Orientation: identity in the window frame; no rotation between frames.
        assert!(Rot6d(row[0..6].try_into().unwrap()).to_mat3().abs_diff_eq(egoexo_core::glam::Mat3::IDENTITY, 1e-5));
        assert!(Rot6d(row[6..12].try_into().unwrap()).to_mat3().abs_diff_eq(egoexo_core::glam::Mat3::IDENTITY, 1e-5));
    }
}

#[test]
fn a_window_inside_a_sequence_uses_the_previous_frame_for_velocity() {
    let t = trajectories(50, 0.3);
    let whole = ego_features(&three_point(&t), 0..50, FPS, TrackingMode::ThreePoint).unwrap();
    let window = ego_features(&three_point(&t), 20..50, FPS, TrackingMode::ThreePoint).unwrap();
    // Velocities and frame-to-frame rotations are window-independent up to the heading
    // rotation; their norms must agree.
    for i in 0..30 {
        let v_whole = Vec3::from_slice(&whole.row(20 + i)[15..18]).length();
        let v_window = Vec3::from_slice(&window.row(i)[15..18]).length();
        assert!((v_whole - v_window).abs() < 1e-4);
        assert!(v_window > 0.0);
        assert_eq!(whole.row(20 + i)[6..12], window.row(i)[6..12]);
    }
}

proptest! {
    #[test]
    fn features_ignore_where_the_wearer_stands_and_faces(seed in 0.0f32..6.0, yaw in -3.1f32..3.1, shift in point(50.0)) {
        let t = trajectories(40, seed);
        let g = RigidTransform::new(Quat::from_rotation_y(yaw), shift);
        let moved: [Vec<RigidTransform>; 3] = t.clone().map(|traj| traj.into_iter().map(|p| g * p).collect());
        let a = ego_features(&three_point(&t), 5..40, FPS, TrackingMode::ThreePoint).unwrap();
        let b = ego_features(&three_point(&moved), 5..40, FPS, TrackingMode::ThreePoint).unwrap();
        for (x, y) in a.features.iter().zip(&b.features) {
            prop_assert!((x - y).abs() < 2e-3 * (1.0 + x.abs()), "{x} vs {y}");
        }
    }

    #[test]
    fn wrist_positions_are_relative_to_the_head(seed in 0.0f32..6.0) {
        let t = trajectories(10, seed);
        let f = ego_features(&three_point(&t), 0..10, FPS, TrackingMode::ThreePoint).unwrap();
        let r_window_world = f.t_world_window.rotation.conjugate();
        for i in 0..10 {
            let expected = r_window_world * (t[1][i].translation - t[0][i].translation);
            prop_assert!(Vec3::from_slice(&f.row(i)[18 + 12..18 + 15]).abs_diff_eq(expected, 1e-5));
        }
    }
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let t = trajectories(10, 0.0);
    let one = EgoTrajectories { head: &t[0], left_wrist: None, right_wrist: None };
    // 3-point with no wrist at all: both read as never tracked.
    let none = ego_features(&one, 0..10, FPS, TrackingMode::ThreePoint).unwrap();
    assert!((0..10).all(|i| none.row(i)[18..54].iter().all(|&v| v == 0.0) && none.row(i)[60..62] == [0.0, 0.0]));
    assert!(matches!(ego_features(&one, 5..5, FPS, TrackingMode::OnePoint), Err(FeatureError::EmptyWindow { .. })));
    assert!(matches!(
        ego_features(&one, 0..11, FPS, TrackingMode::OnePoint),
        Err(FeatureError::WindowOutOfRange { .. })
    ));
    assert!(matches!(ego_features(&one, 0..10, 0.0, TrackingMode::OnePoint), Err(FeatureError::InvalidFps(_))));
    let short = &t[1][..9];
    let mismatched = EgoTrajectories {
        head: &t[0],
        left_wrist: Some(WristTrack::always(short)),
        right_wrist: Some(WristTrack::always(&t[2])),
    };
    assert!(matches!(
        ego_features(&mismatched, 0..10, FPS, TrackingMode::ThreePoint),
        Err(FeatureError::LengthMismatch { device: "left wrist", got: 9, expected: 10 })
    ));
    let valid = vec![true; 9];
    let bad_validity = EgoTrajectories {
        head: &t[0],
        left_wrist: Some(WristTrack { poses: &t[1], valid: Some(&valid) }),
        right_wrist: None,
    };
    assert!(matches!(
        ego_features(&bad_validity, 0..10, FPS, TrackingMode::ThreePoint),
        Err(FeatureError::ValidityLengthMismatch { device: "left wrist", got: 9, expected: 10 })
    ));
    // A non-finite pose on a frame where the wrist is not tracked is never read.
    let mut hidden_nan = t[1].clone();
    hidden_nan[3].translation.x = f32::NAN;
    let mut seen = vec![true; 10];
    seen[3] = false;
    let ok = EgoTrajectories {
        head: &t[0],
        left_wrist: Some(WristTrack { poses: &hidden_nan, valid: Some(&seen) }),
        right_wrist: None,
    };
    assert!(ego_features(&ok, 0..10, FPS, TrackingMode::ThreePoint).is_ok());
    let mut broken = t[0].clone();
    broken[4].translation.y = f32::NAN;
    let nan = EgoTrajectories { head: &broken, left_wrist: None, right_wrist: None };
    assert!(matches!(
        ego_features(&nan, 0..10, FPS, TrackingMode::OnePoint),
        Err(FeatureError::NonFinitePose { device: "head", frame: 4 })
    ));
}

/// Wrists that come and go (hand tracking): a frame where a wrist is not tracked has its
/// block zero and its validity slot 0; the frame it comes back starts like a sequence
/// (identity step, zero velocity); tracked frames equal the always-tracked features.
#[test]
fn untracked_wrist_frames_are_zero_and_flagged() {
    let t = trajectories(30, 0.4);
    let mut valid = vec![true; 30];
    for v in &mut valid[10..15] {
        *v = false;
    }
    let partial = EgoTrajectories {
        head: &t[0],
        left_wrist: Some(WristTrack { poses: &t[1], valid: Some(&valid) }),
        right_wrist: Some(WristTrack::always(&t[2])),
    };
    let f = ego_features(&partial, 0..30, FPS, TrackingMode::ThreePoint).unwrap();
    let full = ego_features(&three_point(&t), 0..30, FPS, TrackingMode::ThreePoint).unwrap();
    for i in 0..30 {
        let row = f.row(i);
        assert_eq!(row[36..54], full.row(i)[36..54], "the right wrist is unaffected");
        assert_eq!(row[61], 1.0);
        if (10..15).contains(&i) {
            assert!(row[18..36].iter().all(|&v| v == 0.0), "frame {i}");
            assert_eq!(row[60], 0.0);
        } else if i == 15 {
            assert_eq!(row[60], 1.0);
            assert_eq!(row[18..24], full.row(i)[18..24], "orientation as tracked");
            assert_eq!(row[24..30], Rot6d::from_quat(Quat::IDENTITY).0, "identity step after the gap");
            assert_eq!(row[33..36], [0.0, 0.0, 0.0], "zero velocity after the gap");
        } else {
            assert_eq!(row[18..36], full.row(i)[18..36], "frame {i}");
            assert_eq!(row[60], 1.0);
        }
    }
}

#[test]
fn heading_is_defined_looking_straight_down() {
    // Facing +X (yaw +90°), then pitched down 90°: the heading is still +90°.
    let q = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2) * Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
    assert!((q * Vec3::Z).y < -0.99, "looking down");
    assert!((heading_yaw(q) - std::f32::consts::FRAC_PI_2).abs() < 1e-4);
}
