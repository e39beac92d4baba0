//! The core's per-frame pipeline end to end — FK, region proposal, keypoints, canonical rays,
//! ego features, metrics — as the Web Worker will run it. In wasm this binary runs inside a
//! dedicated worker in headless Chromium; natively it is an ordinary test.

mod common;

#[cfg(target_arch = "wasm32")]
wasm_bindgen_test::wasm_bindgen_test_configure!(run_in_dedicated_worker);
#[cfg(target_arch = "wasm32")]
use wasm_bindgen_test::wasm_bindgen_test as test;

use common::*;
use egoexo_core::ego_features::{EgoTrajectories, TrackingMode, ego_features};
use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, Keypoint2d, exo_keypoints_from_smpl};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::metrics::evaluate;
use egoexo_core::rays::canonicalize_keypoints;
use egoexo_core::region::{DEFAULT_REGION_MARGIN, RegionProposal, propose_region};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, SmplJoint, SmplPose, SmplSkeleton};

#[test]
fn one_second_of_walking_through_the_whole_core() {
    let skeleton = SmplSkeleton::mean_shape().scaled_to_head_height(1.55).unwrap();
    let camera = aria_rgb_camera();
    let head_joint_in_device = Vec3::new(0.0, -0.06, -0.09);
    let observer = RigidTransform::cpf_looking_at(Vec3::new(0.0, 1.65, 5.0), Vec3::new(0.0, 1.0, 0.0));
    let fps = 30.0;

    let mut heads = Vec::new();
    let mut truth = Vec::new();
    for i in 0..30 {
        let t = i as f32 / fps;
        let swing = 0.4 * (2.0 * std::f32::consts::PI * t).sin();
        let mut body = [Quat::IDENTITY; NUM_BODY_JOINTS];
        body[SmplJoint::LeftHip.index() - 1] = Quat::from_rotation_x(swing);
        body[SmplJoint::RightHip.index() - 1] = Quat::from_rotation_x(-swing);
        let pose = SmplPose { root_orientation: Quat::IDENTITY, body, translation: Vec3::new(0.0, 0.98, 0.8 * t) };
        let fk = skeleton.forward_kinematics(&pose);
        // The glasses sit in front of and above the head joint.
        let head_device =
            RigidTransform::new(fk.rotations[SmplJoint::Head.index()], fk.positions[SmplJoint::Head.index()])
                * RigidTransform::from_translation(-head_joint_in_device);
        heads.push(head_device);
        truth.push((pose, fk));
    }

    let traj = EgoTrajectories { head: &heads, left_wrist: None, right_wrist: None };
    let features = ego_features(&traj, 0..30, fps, TrackingMode::OnePoint).unwrap();
    assert_eq!(features.frames(), 30);
    assert!(features.features.iter().all(|v| v.is_finite()));

    let mut predicted = Vec::new();
    for (i, (pose, fk)) in truth.iter().enumerate() {
        let RegionProposal::Visible { bbox, .. } =
            propose_region(&fk.positions, &camera, &observer, DEFAULT_REGION_MARGIN)
        else {
            panic!("the wearer walks towards the observer and stays in view (frame {i})")
        };
        let points = exo_keypoints_from_smpl(&fk.positions, fk.rotations[SmplJoint::Head.index()], 1.0);
        let keypoints: [Option<Keypoint2d>; EXO_KEYPOINT_COUNT] =
            points.map(|p| camera.project_world(p, &observer).map(|pixel| Keypoint2d { pixel, score: 0.9 }));
        for kp in keypoints.iter().flatten() {
            assert!(bbox.contains(kp.pixel), "keypoints fall inside the region proposal");
        }
        let rays = canonicalize_keypoints(&keypoints, &camera, &observer, &heads[i]);
        assert!(rays.iter().all(|r| r.valid));
        // The ankles' rays point down from the head, by roughly the body's height.
        let ankle = rays[11].endpoint;
        assert!(ankle.y < -1.0 && ankle.y > -1.8, "{ankle:?}");

        // Root recovery with the true body pose gives back the true joints.
        let translation =
            skeleton.recover_translation(pose.root_orientation, &pose.body, &heads[i], head_joint_in_device);
        predicted.push(skeleton.forward_kinematics(&SmplPose { translation, ..*pose }).positions);
    }
    let gt: Vec<_> = truth.iter().map(|(_, fk)| fk.positions).collect();
    let m = evaluate(&predicted, &gt, fps).unwrap().unwrap();
    assert!(m.mpjpe_cm < 1e-3, "{m:?}");

    // Plain data crosses the worker boundary as JSON.
    let json = serde_json::to_string(&truth[3].0).unwrap();
    let back: SmplPose = serde_json::from_str(&json).unwrap();
    assert_eq!(back, truth[3].0);
}

/// Guards the test configuration itself: in wasm this binary must really run in a worker.
#[cfg(target_arch = "wasm32")]
#[test]
fn runs_inside_a_dedicated_worker() {
    let scope: String = js_sys::global().constructor().name().into();
    assert_eq!(scope, "DedicatedWorkerGlobalScope");
}
