//! Metric definitions checked on tiny hand-computed sequences.

#[cfg(target_arch = "wasm32")]
use wasm_bindgen_test::wasm_bindgen_test as test;

use egoexo_core::glam::Vec3;
use egoexo_core::metrics::{
    JointPositions, LOWER_BODY_JOINTS, MetricsAccumulator, MetricsError, UPPER_BODY_JOINTS, evaluate,
};

const FPS: f32 = 30.0;

fn still(frames: usize) -> Vec<JointPositions> {
    vec![[Vec3::ZERO; 24]; frames]
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-6 * (1.0 + b.abs())
}

#[test]
fn a_constant_3_4_5_offset_is_5_cm_everywhere_and_no_velocity_error() {
    let gt = still(3);
    let pred: Vec<_> = gt.iter().map(|f| f.map(|p| p + Vec3::new(0.03, 0.04, 0.0))).collect();
    let m = evaluate(&pred, &gt, FPS).unwrap().unwrap();
    assert!(close(m.mpjpe_cm, 5.0) && close(m.upper_cm, 5.0) && close(m.lower_cm, 5.0), "{m:?}");
    assert!(close(m.mpjve_cm_s, 0.0));
    assert!(m.jitter.is_nan(), "3 frames have no third difference");
    assert_eq!(m.frames, 3);
}

#[test]
fn upper_and_lower_errors_use_their_joint_sets() {
    // Upper joints off by 2 cm, lower joints by 10 cm, pelvis exact:
    // MPJPE = (15·2 + 8·10 + 0) / 24 = 110/24 cm.
    let gt = still(2);
    let pred: Vec<_> = gt
        .iter()
        .map(|f| {
            let mut f = *f;
            UPPER_BODY_JOINTS.iter().for_each(|&j| f[j].x += 0.02);
            LOWER_BODY_JOINTS.iter().for_each(|&j| f[j].z -= 0.10);
            f
        })
        .collect();
    let m = evaluate(&pred, &gt, FPS).unwrap().unwrap();
    assert!(close(m.upper_cm, 2.0) && close(m.lower_cm, 10.0), "{m:?}");
    assert!(close(m.mpjpe_cm, 110.0 / 24.0), "{m:?}");
}

#[test]
fn velocity_error_of_a_drift_is_its_speed() {
    // Prediction drifts 1 cm per frame at 30 fps = 30 cm/s while the truth stands still.
    let gt = still(5);
    let pred: Vec<_> = (0..5).map(|t| [Vec3::new(0.01 * t as f32, 0.0, 0.0); 24]).collect();
    let m = evaluate(&pred, &gt, FPS).unwrap().unwrap();
    assert!(close(m.mpjve_cm_s, 30.0), "{m:?}");
    assert!(close(m.mpjpe_cm, 2.0), "mean of 0,1,2,3,4 cm");
    assert!(m.jitter.abs() < 1e-9, "constant velocity has no jerk: {}", m.jitter);
}

#[test]
fn jitter_of_a_cubic_is_six_metres_per_second_cubed() {
    // x(t) = t³ (t in seconds) has jerk 6 m/s³ everywhere: 0.06 in units of 10² m/s³.
    let pred: Vec<_> = (0..6).map(|i| [Vec3::new((i as f32 / FPS).powi(3), 0.0, 0.0); 24]).collect();
    let m = evaluate(&pred, &pred, FPS).unwrap().unwrap();
    assert!((m.jitter - 0.06).abs() < 1e-5, "{}", m.jitter);
    assert!(close(m.mpjpe_cm, 0.0) && close(m.mpjve_cm_s, 0.0));
}

#[test]
fn segments_average_over_terms_and_never_difference_across_a_boundary() {
    let mut acc = MetricsAccumulator::new();
    // Segment A: 2 frames, 1 cm error. Segment B: 1 frame, 4 cm error, far away.
    let a_gt = still(2);
    let a_pred: Vec<_> = a_gt.iter().map(|f| f.map(|p| p + Vec3::X * 0.01)).collect();
    let b_gt = vec![[Vec3::splat(100.0); 24]];
    let b_pred = vec![[Vec3::splat(100.0) + Vec3::Y * 0.04; 24]];
    acc.add_segment(&a_pred, &a_gt, FPS, None).unwrap();
    acc.add_segment(&b_pred, &b_gt, FPS, None).unwrap();
    let m = acc.finish().unwrap();
    // f32 positions near 100 m carry ~4 µm of rounding.
    assert!((m.mpjpe_cm - 2.0).abs() < 1e-3, "(1 + 1 + 4) / 3: {m:?}");
    assert!(close(m.mpjve_cm_s, 0.0), "the jump between segments is not a velocity");
    assert_eq!(m.frames, 3);
}

#[test]
fn frame_selection_keeps_only_terms_inside_it() {
    let gt = still(4);
    let pred: Vec<_> = (0..4).map(|t| [Vec3::new(0.01 * t as f32, 0.0, 0.0); 24]).collect();
    let mut acc = MetricsAccumulator::new();
    acc.add_segment(&pred, &gt, FPS, Some(&[false, false, true, true])).unwrap();
    let m = acc.finish().unwrap();
    assert!(close(m.mpjpe_cm, 2.5), "frames 2 and 3: {m:?}");
    assert!(close(m.mpjve_cm_s, 30.0), "only the 2→3 velocity");
    let mut none = MetricsAccumulator::new();
    none.add_segment(&pred, &gt, FPS, Some(&[false; 4])).unwrap();
    assert!(none.finish().is_none());
}

#[test]
fn bad_input_is_an_error() {
    let mut acc = MetricsAccumulator::new();
    assert_eq!(acc.add_segment(&still(2), &still(3), FPS, None), Err(MetricsError::LengthMismatch { pred: 2, gt: 3 }));
    assert!(matches!(acc.add_segment(&still(2), &still(2), f32::NAN, None), Err(MetricsError::InvalidFps(_))));
    assert!(matches!(
        acc.add_segment(&still(2), &still(2), FPS, Some(&[true])),
        Err(MetricsError::SelectionLength { .. })
    ));
    let mut bad = still(2);
    bad[1][7].y = f32::INFINITY;
    assert_eq!(
        acc.add_segment(&bad, &still(2), FPS, None),
        Err(MetricsError::NonFinite { which: "predicted", frame: 1, joint: 7 })
    );
    assert!(acc.finish().is_none(), "failed segments add nothing");
}
