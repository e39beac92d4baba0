//! A small synthetic scene for tests, the bench and demos: a wearer standing in SMPL's mean-shape
//! rest pose (arms out) walking slowly forward (+Z, towards the observer), an ego-only overlay and a ground-truth ghost
//! slightly offset, head and wrist devices, and one observer 3 m in front looking at the wearer
//! with rays to the 13 exo keypoints whose gates rise from 0 (nose) to 1 (right ankle).

use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, ExoKeypoint, NOSE_IN_HEAD_JOINT};
use egoexo_core::skeleton::{MEAN_SHAPE_REST_JOINTS, NUM_JOINTS, SmplJoint};
use egoexo_scene::{DeviceTrack, ObserverScene, SceneData};
use glam::{Mat3, Quat, Vec3};

/// Frame rate of the example, frames per second.
pub const EXAMPLE_FPS: f32 = 30.0;
/// Where the example's observer camera is, world metres.
pub const EXAMPLE_OBSERVER_POSITION: Vec3 = Vec3::new(0.4, 1.6, 3.0);
/// Height the mean-shape rest joints are lifted by so that the soles touch `y = 0`, metres.
const LIFT_Y: f32 = 1.16;
/// Wearer drift along +Z (the way it faces), metres per second.
const DRIFT_M_PER_S: f32 = 0.2;

/// World joints of the example wearer at `frame`, metres.
pub fn example_joints(frame: usize) -> [Vec3; NUM_JOINTS] {
    let shift = Vec3::new(0.0, LIFT_Y, DRIFT_M_PER_S * frame as f32 / EXAMPLE_FPS);
    MEAN_SHAPE_REST_JOINTS.map(|j| Vec3::from(j) + shift)
}

/// `T_world_camera` rotation of an optical frame (+X right, +Y down, +Z forward) at `eye`
/// looking at `target` with world +Y up in the image.
fn look_at_optical(eye: Vec3, target: Vec3) -> Quat {
    let z = (target - eye).normalize();
    let x = z.cross(Vec3::Y).normalize(); // right: forward × up
    let y = z.cross(x); // down
    Quat::from_mat3(&Mat3::from_cols(x, y, z))
}

/// The example scene with `frames` frames (see the module docs); every frame is valid.
pub fn example_scene(frames: usize) -> SceneData {
    let mut scene = SceneData::new("example", EXAMPLE_FPS, frames, "ego-exo");
    let all: Vec<[Vec3; NUM_JOINTS]> = (0..frames).map(example_joints).collect();
    let flat = |offset: Vec3| -> Vec<f32> {
        all.iter().flat_map(|f| f.iter().flat_map(move |p| (*p + offset).to_array())).collect()
    };
    scene.joints = flat(Vec3::ZERO);
    scene.valid = vec![true; frames];
    scene.exo_evidence = vec![true; frames];
    scene.ego_only_joints = Some(flat(Vec3::new(0.0, 0.0, 0.08)));
    scene.ground_truth_joints = Some(flat(Vec3::new(0.03, 0.0, -0.04)));
    let device = |name: &str, joint: SmplJoint, offset: Vec3| DeviceTrack {
        name: name.to_string(),
        positions: all.iter().flat_map(|f| (f[joint.index()] + offset).to_array()).collect(),
        valid: vec![true; frames],
    };
    scene.devices = vec![
        device("head", SmplJoint::Head, Vec3::new(0.0, 0.09, 0.09)),
        device("left_wrist", SmplJoint::LeftWrist, Vec3::ZERO),
        device("right_wrist", SmplJoint::RightWrist, Vec3::ZERO),
    ];
    let rotation = look_at_optical(EXAMPLE_OBSERVER_POSITION, Vec3::new(0.0, 1.0, 0.0));
    let mut camera_poses = Vec::with_capacity(7 * frames);
    let mut rays = Vec::with_capacity(4 * EXO_KEYPOINT_COUNT * frames);
    for joints in &all {
        camera_poses.extend_from_slice(&rotation.to_array());
        camera_poses.extend_from_slice(&EXAMPLE_OBSERVER_POSITION.to_array());
        for (k, keypoint) in ExoKeypoint::ALL.iter().enumerate() {
            let mut end = joints[keypoint.smpl_joint().index()];
            if *keypoint == ExoKeypoint::Nose {
                end += NOSE_IN_HEAD_JOINT;
            }
            rays.extend_from_slice(&end.to_array());
            rays.push(k as f32 / (EXO_KEYPOINT_COUNT - 1) as f32);
        }
    }
    scene.observers = vec![ObserverScene {
        id: "observer-1".to_string(),
        camera_poses,
        valid: vec![true; frames],
        half_fov: [0.9, 0.75],
        image_size: [640, 480],
        rays,
    }];
    // The floor under the soles: the lowest foot joint less its height above the sole.
    use egoexo_core::foot_contact::{FOOT_JOINT_ABOVE_SOLE_M, FOOT_JOINTS};
    scene.floor_y =
        all.iter().flat_map(|f| FOOT_JOINTS.map(|j| f[j].y)).fold(f32::INFINITY, f32::min) - FOOT_JOINT_ABOVE_SOLE_M;
    if !scene.floor_y.is_finite() {
        scene.floor_y = 0.0;
    }
    scene
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn the_observer_looks_at_the_wearer() {
        let scene = example_scene(3);
        scene.check().unwrap();
        let (q, t) = crate::scene::observer_pose(&scene.observers[0], 0).unwrap();
        let pelvis = example_joints(0)[0];
        let in_camera = q.inverse() * (pelvis - t);
        assert!(in_camera.z > 2.0, "wearer is in front: {in_camera}");
        let head = q.inverse() * (example_joints(0)[15] - t);
        assert!(head.y < in_camera.y, "+Y is down in the optical frame");
        assert!(scene.floor_y.abs() < 0.03, "{}", scene.floor_y);
    }
}
