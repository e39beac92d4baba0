//! The viewer's scene ([`egoexo_scene::SceneData`]) from an aligned session and its
//! reconstruction(s): joints, devices, observer cameras and their gated rays in the world.

use egoexo_core::aligned::{AlignedSession, AlignedTrajectory};
use egoexo_core::camera::CameraCalibration;
use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_core::foot_contact::{FOOT_JOINT_ABOVE_SOLE_M, FOOT_JOINTS};
use egoexo_core::glam::{Vec2, Vec3};
use egoexo_core::metrics::{ALL_JOINTS, LOWER_BODY_JOINTS, frame_position_error_cm};
use egoexo_core::rays::canonicalize_keypoints;
use egoexo_core::region::{DEFAULT_REGION_MARGIN, RegionProposal, propose_region};
use egoexo_core::skeleton::NUM_JOINTS;
use egoexo_infer::Reconstruction;
use egoexo_scene::{DeviceTrack, ErrorTimeline, ObserverScene, ObserverTimeline, SceneData, TimelineData};

fn flat_joints(joints: &[[Vec3; NUM_JOINTS]]) -> Vec<f32> {
    joints.iter().flat_map(|f| f.iter().flat_map(|p| p.to_array())).collect()
}

fn device(name: &str, t: &AlignedTrajectory) -> DeviceTrack {
    DeviceTrack {
        name: name.to_string(),
        positions: t.poses.iter().flat_map(|p| p.translation.to_array()).collect(),
        valid: t.valid.clone(),
    }
}

/// Half fields of view (radians, horizontal and vertical) of a camera, measured by
/// unprojecting the middles of the image edges.
pub fn half_fov(camera: &CameraCalibration) -> [f32; 2] {
    let c = camera.projection.principal_point();
    let angle = |px: Vec2| camera.projection.unproject(px).map_or(0.8, |d| d.z.clamp(-1.0, 1.0).acos());
    let (w, h) = (camera.width as f32, camera.height as f32);
    [
        0.5 * (angle(Vec2::new(-0.5, c.y)) + angle(Vec2::new(w - 0.5, c.y))),
        0.5 * (angle(Vec2::new(c.x, -0.5)) + angle(Vec2::new(c.x, h - 0.5))),
    ]
}

/// Builds the scene; `ego_only` adds the comparison overlay.
pub fn build_scene(aligned: &AlignedSession, recon: &Reconstruction, ego_only: Option<&Reconstruction>) -> SceneData {
    let frames = aligned.timeline.frames.min(recon.joints.len());
    let mut scene = SceneData::new(&aligned.name, aligned.timeline.fps, frames, recon.method.name());
    scene.start_s = aligned.timeline.start_ns as f64 * 1e-9;
    scene.joints = flat_joints(&recon.joints[..frames]);
    scene.valid = recon.valid[..frames].to_vec();
    scene.exo_evidence = recon.exo_evidence[..frames].to_vec();
    scene.ego_only_joints = ego_only.filter(|e| e.joints.len() >= frames).map(|e| flat_joints(&e.joints[..frames]));
    scene.ground_truth_joints = aligned.ground_truth.as_ref().filter(|gt| gt.poses.len() >= frames).map(|gt| {
        let joints: Vec<_> =
            gt.poses[..frames].iter().map(|p| aligned.skeleton.forward_kinematics(p).positions).collect();
        flat_joints(&joints)
    });
    scene.devices.push(device("head", &aligned.head));
    if let Some(l) = &aligned.left_wrist {
        scene.devices.push(device("left_wrist", l));
    }
    if let Some(r) = &aligned.right_wrist {
        scene.devices.push(device("right_wrist", r));
    }
    for d in &mut scene.devices {
        d.positions.truncate(3 * frames);
        d.valid.truncate(frames);
    }
    for (o, observer) in aligned.observers.iter().enumerate() {
        let mut camera_poses = Vec::with_capacity(7 * frames);
        let mut rays = vec![0.0f32; 4 * EXO_KEYPOINT_COUNT * frames];
        for f in 0..frames {
            let pose = &observer.head.poses[f];
            let t_world_camera = observer.camera.t_world_camera(pose);
            camera_poses.extend_from_slice(&t_world_camera.rotation.to_array());
            camera_poses.extend_from_slice(&t_world_camera.translation.to_array());
            if !observer.head.valid[f] {
                continue;
            }
            let head = &aligned.head.poses[f];
            let canonical = canonicalize_keypoints(&observer.keypoints[f], &observer.camera, pose, head);
            for (k, ray) in canonical.iter().enumerate() {
                if !ray.valid {
                    continue;
                }
                let i = 4 * (f * EXO_KEYPOINT_COUNT + k);
                rays[i..i + 3].copy_from_slice(&head.transform_point(ray.endpoint).to_array());
                rays[i + 3] = recon.gates.get(o).and_then(|g| g.gates.get(f)).map_or(0.0, |g| g[k]);
            }
        }
        scene.observers.push(ObserverScene {
            id: observer.id.clone(),
            camera_poses,
            valid: observer.head.valid[..frames].to_vec(),
            half_fov: half_fov(&observer.camera),
            image_size: [observer.camera.width, observer.camera.height],
            rays,
        });
    }
    scene.floor_y = aligned.floor_y.unwrap_or_else(|| floor_y(&recon.joints[..frames], &recon.valid));
    scene.timeline = Some(timeline(aligned, recon, ego_only, &scene));
    scene
}

/// The timeline plots' series ([`TimelineData`]) for `scene`, built from the same session and
/// reconstructions: per observer, the reconstruction's joints inside its image (the core's
/// region proposal), its 2D keypoints, occlusion labels and the mean gate of its rays; with
/// ground truth, the per-frame MPJPE and L-PE (the core's metric terms).
pub fn timeline(
    aligned: &AlignedSession,
    recon: &Reconstruction,
    ego_only: Option<&Reconstruction>,
    scene: &SceneData,
) -> TimelineData {
    let frames = scene.frames;
    let observers = aligned
        .observers
        .iter()
        .zip(&scene.observers)
        .enumerate()
        .map(|(o, (observer, drawn))| {
            let joints_in_view = (0..frames)
                .map(|f| {
                    if !(observer.head.valid[f] && recon.valid[f]) {
                        return 0;
                    }
                    let pose = &observer.head.poses[f];
                    match propose_region(&recon.joints[f], &observer.camera, pose, DEFAULT_REGION_MARGIN) {
                        RegionProposal::Visible { joints_in_image, .. } => joints_in_image.min(NUM_JOINTS) as u8,
                        RegionProposal::NotVisible(_) => 0,
                    }
                })
                .collect();
            let keypoints = observer.keypoints[..frames].iter().map(|k| k.iter().flatten().count() as u8).collect();
            let occluded = aligned
                .ground_truth
                .as_ref()
                .and_then(|gt| gt.occluded.get(o))
                .filter(|labels| labels.iter().any(|&m| m != 0))
                .map(|labels| (0..frames).map(|f| labels.get(f).map_or(0, |m| m.count_ones() as u8)).collect());
            let gate_mean = (0..frames)
                .map(|f| {
                    let gates: Vec<f32> =
                        (0..EXO_KEYPOINT_COUNT).filter_map(|k| drawn.ray(f, k)).map(|(_, gate)| gate).collect();
                    if gates.is_empty() { -1.0 } else { gates.iter().sum::<f32>() / gates.len() as f32 }
                })
                .collect();
            ObserverTimeline { id: observer.id.clone(), joints_in_view, keypoints, occluded, gate_mean }
        })
        .collect();
    let errors = aligned.ground_truth.as_ref().filter(|gt| gt.poses.len() >= frames).map(|gt| {
        let truth: Vec<_> =
            gt.poses[..frames].iter().map(|p| aligned.skeleton.forward_kinematics(p).positions).collect();
        let series = |r: &Reconstruction, joints: &[usize]| -> Vec<f32> {
            (0..frames)
                .map(|f| {
                    let scored = r.valid.get(f).copied().unwrap_or(false) && gt.valid[f] && f < r.joints.len();
                    let e = if scored { frame_position_error_cm(&r.joints[f], &truth[f], joints) } else { -1.0 };
                    if e.is_finite() { e as f32 } else { -1.0 }
                })
                .collect()
        };
        ErrorTimeline {
            mpjpe_cm: series(recon, &ALL_JOINTS),
            lower_cm: series(recon, &LOWER_BODY_JOINTS),
            ego_only_mpjpe_cm: ego_only.map(|e| series(e, &ALL_JOINTS)),
            ego_only_lower_cm: ego_only.map(|e| series(e, &LOWER_BODY_JOINTS)),
        }
    });
    TimelineData { observers, errors }
}

/// The floor's height when the session does not say: under the lowest sole over the tracked
/// frames (the lowest ankle or foot joint less [`FOOT_JOINT_ABOVE_SOLE_M`]); 0 without any.
pub fn floor_y(joints: &[[Vec3; NUM_JOINTS]], valid: &[bool]) -> f32 {
    let y = joints
        .iter()
        .zip(valid)
        .filter(|(_, v)| **v)
        .flat_map(|(j, _)| FOOT_JOINTS.map(|k| j[k].y))
        .fold(f32::INFINITY, f32::min);
    if y.is_finite() { y - FOOT_JOINT_ABOVE_SOLE_M } else { 0.0 }
}
