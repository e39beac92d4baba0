//! Putting it together: a full [`Session`] (with ground truth) from an SMPL motion clip.

use egoexo_core::TrackingMode;
use egoexo_core::exo_keypoints::{coco17_from_exo, device_from_head_joint, exo_keypoints_from_smpl};
use egoexo_core::glam::Vec3;
use egoexo_core::motion::SmplMotion;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE, SmplJoint, SmplSkeleton};
use egoexo_session::model::{
    Floor, FloorSource, GroundTruth, HandTrackingForm, KeypointTrack, Observer, ObserverOcclusion, Session,
    SubjectInfo, Trajectory, Wearer, WristOrientation, WristSource,
};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::cameras::{aria_rgb_camera, wide_pinhole_camera};
use crate::config::SynthConfig;
use crate::config::WristTracking;
use crate::detector::{DetectorState, detect};
use crate::devices::{add_tracking_noise, simulate_hand_tracking};
use crate::observers::simulate_observer;
use crate::rng::SimRng;
use crate::scene::{Bystander, Furniture, Scene};

/// The file name a simulated hand-tracking wrist source reports.
pub const SIMULATED_HAND_TRACKING: &str = "simulated hand tracking";

/// Errors simulating a session.
#[derive(Debug, Error)]
pub enum SynthError {
    #[error("motion `{name}` has no frames")]
    EmptyMotion { name: String },
    #[error("camera: {0}")]
    Camera(#[from] egoexo_core::camera::CameraError),
    #[error("the camera choice lists no image sizes")]
    NoImageSizes,
}

/// What the simulator did, per observer (for reports and tests).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObserverReport {
    pub id: String,
    pub walking: bool,
    pub fisheye: bool,
    pub image_size: u32,
    pub frames: usize,
    /// Frames in which the observer looked away on purpose.
    pub frames_looking_away: usize,
    /// Frames with at least the detector's minimum of keypoints inside the image.
    pub frames_in_view: usize,
    /// Frames with at least one detected keypoint.
    pub frames_detected: usize,
    /// Exo keypoint-frames occluded by the scene (while in view).
    pub occluded_keypoints: usize,
    /// Of those, reported confidently at a wrong place.
    pub confidently_wrong_keypoints: usize,
    /// Mean distance from the observer's eye to the wearer's head (m).
    pub mean_distance_m: f32,
}

/// A simulated session and its report.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedSession {
    pub session: Session,
    pub observers: Vec<ObserverReport>,
    /// Furniture and bystanders used (for overlays and tests).
    pub scene: Scene,
    /// True (noise-free) observer head poses, per observer, per frame.
    pub true_observer_heads: Vec<Vec<RigidTransform>>,
}

/// Simulates a session around `motion` (the wearer's ground truth), deterministically from
/// `seed`.
pub fn simulate(
    motion: &SmplMotion,
    name: &str,
    config: &SynthConfig,
    seed: u64,
) -> Result<SimulatedSession, SynthError> {
    if motion.is_empty() {
        return Err(SynthError::EmptyMotion { name: name.to_string() });
    }
    let mut rng = SimRng::new(seed);
    let skeleton = &motion.skeleton;
    let scale = skeleton.head_height() / SmplSkeleton::mean_shape().head_height();
    let fps = motion.fps;
    let timestamps: Vec<i64> = (0..motion.len()).map(|i| motion.timestamp_ns(i)).collect();
    let fk: Vec<_> = motion.poses.iter().map(|p| skeleton.forward_kinematics(p)).collect();
    let joint_pose =
        |f: usize, j: SmplJoint| RigidTransform::new(fk[f].rotations[j.index()], fk[f].positions[j.index()]);
    let floor_y =
        fk.iter().flat_map(|f| [7, 8, 10, 11].map(|j| f.positions[j].y)).fold(f32::INFINITY, f32::min) - 0.03 * scale;

    // Wearer devices.
    let head_joint_in_device = DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE;
    let true_head: Vec<_> =
        (0..fk.len()).map(|f| device_from_head_joint(&joint_pose(f, SmplJoint::Head), head_joint_in_device)).collect();
    let mut wearer_rng = rng.fork(1);
    let head = add_tracking_noise(&true_head, fps, &config.wearer_noise, &mut wearer_rng);
    let mut wrist_source = WristSource::Devices;
    let (left_wrist, right_wrist) = match config.tracking {
        TrackingMode::OnePoint => (None, None),
        TrackingMode::ThreePoint => {
            let mut side = |j: SmplJoint| {
                let truth: Vec<_> = (0..fk.len()).map(|f| joint_pose(f, j)).collect();
                match &config.wrists {
                    WristTracking::Devices => Trajectory {
                        timestamps_ns: timestamps.clone(),
                        poses: add_tracking_noise(&truth, fps, &config.wearer_noise, &mut wearer_rng),
                    },
                    WristTracking::HandTracking(model) => {
                        let seen = simulate_hand_tracking(&head, &true_head, &truth, fps, model, &mut wearer_rng);
                        Trajectory {
                            timestamps_ns: seen.frames.iter().map(|&f| timestamps[f]).collect(),
                            poses: seen.poses,
                        }
                    }
                }
            };
            let wrists = (side(SmplJoint::LeftWrist), side(SmplJoint::RightWrist));
            if let WristTracking::HandTracking(_) = &config.wrists {
                wrist_source = WristSource::HandTracking {
                    file: SIMULATED_HAND_TRACKING.to_owned(),
                    form: HandTrackingForm::HandTrackingResults,
                    orientation: WristOrientation::FromWristPose,
                };
            }
            // A hand never seen leaves no trajectory, as in a real recording.
            let kept = |t: Trajectory| (!t.timestamps_ns.is_empty()).then_some(t);
            (kept(wrists.0), kept(wrists.1))
        }
    };
    let wearer = Wearer {
        head: Trajectory { timestamps_ns: timestamps.clone(), poses: head },
        left_wrist,
        right_wrist,
        wrist_source,
        head_joint_in_device,
    };

    // Observers' motion first: the scene's occluders are placed between them and the wearer.
    let chest: Vec<Vec3> = fk.iter().map(|f| f.positions[SmplJoint::Spine3.index()]).collect();
    let tracks: Vec<_> = (0..config.observers)
        .map(|o| simulate_observer(&chest, floor_y, fps, &config.observer, &mut rng.fork(100 + o as u64)))
        .collect();
    let scene = build_scene(
        &tracks.iter().map(|t| t.head[0].translation).collect::<Vec<_>>(),
        &chest,
        floor_y,
        fps,
        config,
        &mut rng.fork(2),
    );

    let mut observers = Vec::new();
    let mut reports = Vec::new();
    let mut occlusion = Vec::new();
    for (o, track) in tracks.iter().enumerate() {
        let mut orng = rng.fork(200 + o as u64);
        let id = format!("observer-{}", o + 1);
        let sizes = &config.camera.image_sizes;
        let size = *sizes.get(orng.int(0, sizes.len().saturating_sub(1))).ok_or(SynthError::NoImageSizes)?;
        let fisheye = orng.chance(config.camera.fisheye_probability);
        let camera = if fisheye { aria_rgb_camera(size)? } else { wide_pinhole_camera(size)? };

        let mut frames = Vec::with_capacity(fk.len());
        let mut masks = Vec::with_capacity(fk.len());
        let mut report = ObserverReport {
            id: id.clone(),
            walking: track.walking,
            fisheye,
            image_size: size,
            frames: fk.len(),
            frames_looking_away: track.looking_away.iter().filter(|&&a| a).count(),
            frames_in_view: 0,
            frames_detected: 0,
            occluded_keypoints: 0,
            confidently_wrong_keypoints: 0,
            mean_distance_m: 0.0,
        };
        let mut detector = DetectorState::default();
        for (f, joints) in fk.iter().enumerate() {
            let head_rot = joints.rotations[SmplJoint::Head.index()];
            let exo = exo_keypoints_from_smpl(&joints.positions, head_rot, scale);
            let points = coco17_from_exo(&exo, &joint_pose(f, SmplJoint::Head), scale);
            let t = f as f32 / fps;
            let det = detect(&points, &camera, &track.head[f], &scene, t, &config.detector, &mut detector, &mut orng);
            report.frames_in_view += usize::from(det.in_view >= config.detector.min_keypoints_in_view);
            report.frames_detected += usize::from(det.keypoints.iter().any(Option::is_some));
            report.occluded_keypoints += det.occluded.count_ones() as usize;
            report.confidently_wrong_keypoints += det.confidently_wrong.count_ones() as usize;
            report.mean_distance_m += track.head[f].translation.distance(true_head[f].translation) / fk.len() as f32;
            frames.push(det.keypoints);
            masks.push(det.occluded);
        }
        let noisy_head = add_tracking_noise(&track.head, fps, &config.observer_noise, &mut orng);
        observers.push(Observer {
            id: id.clone(),
            head: Trajectory { timestamps_ns: timestamps.clone(), poses: noisy_head },
            camera,
            keypoints: Some(KeypointTrack { timestamps_ns: timestamps.clone(), frames }),
            video: None,
            context_features: None,
            placement: egoexo_session::placement::Placement::default(),
        });
        occlusion.push(ObserverOcclusion { observer_id: id, occluded: masks });
        reports.push(report);
    }

    let session = Session {
        name: name.to_string(),
        wearer,
        observers,
        subject: SubjectInfo {
            height_m: None,
            betas: motion.betas.clone(),
            rest_joints: Some(*skeleton.rest_joints()),
        },
        ground_truth: Some(GroundTruth { motion: motion.clone(), occlusion }),
        // The simulator's own floor (its observers walk on it): the feet's lowest joints
        // minus their height above the soles.
        floor: Some(Floor { height_m: floor_y, source: FloorSource::GroundTruth }),
    };
    Ok(SimulatedSession {
        session,
        observers: reports,
        scene,
        true_observer_heads: tracks.into_iter().map(|t| t.head).collect(),
    })
}

/// Furniture between each observer's start and the wearer's start (with the configured
/// probability), and bystanders crossing observers' lines of sight at random times.
fn build_scene(
    observer_starts: &[Vec3],
    chest: &[Vec3],
    floor_y: f32,
    fps: f32,
    config: &SynthConfig,
    rng: &mut SimRng,
) -> Scene {
    let occ = &config.occlusion;
    let wearer_start = chest[0];
    let duration = chest.len() as f32 / fps;
    let mut scene = Scene::default();
    for &eye in observer_starts {
        let line = Vec3::new(wearer_start.x - eye.x, 0.0, wearer_start.z - eye.z);
        if rng.chance(occ.furniture_probability) && line.length() > 1.0 {
            let along = rng.uniform(0.4, 0.8);
            let height = rng.uniform(occ.furniture_height_m.0, occ.furniture_height_m.1);
            let centre = Vec3::new(eye.x, floor_y, eye.z) + line * along + Vec3::Y * (0.5 * height);
            // Keep the wearer outside the box: at most 0.45 of the remaining distance deep.
            let max_depth = (line.length() * (1.0 - along) * 0.9).max(0.2);
            let depth = rng.uniform(occ.furniture_depth_m.0, occ.furniture_depth_m.1).min(max_depth);
            let yaw = line.x.atan2(line.z) + rng.normal(0.0, 0.2);
            scene.furniture.push(Furniture {
                center: centre,
                half_extents: Vec3::new(
                    0.5 * rng.uniform(occ.furniture_width_m.0, occ.furniture_width_m.1),
                    0.5 * height,
                    0.5 * depth,
                ),
                yaw,
            });
        }
    }
    let bystanders = rng.int(0, occ.max_bystanders);
    for _ in 0..bystanders {
        let Some(&eye) = observer_starts.get(rng.int(0, observer_starts.len().saturating_sub(1))) else { break };
        let cross_time = rng.uniform(0.0, duration);
        let cross_frame = ((cross_time * fps) as usize).min(chest.len() - 1);
        let target = chest[cross_frame];
        let line = Vec3::new(target.x - eye.x, 0.0, target.z - eye.z);
        let point = Vec3::new(eye.x, floor_y, eye.z) + line * rng.uniform(0.3, 0.7);
        let across = Vec3::Y.cross(line).normalize_or(Vec3::X) * if rng.chance(0.5) { 1.0 } else { -1.0 };
        let velocity = across * rng.uniform(0.8, 1.5);
        scene.bystanders.push(Bystander {
            start: point - velocity * cross_time,
            velocity,
            radius: occ.bystander_radius_m,
            height: rng.uniform(occ.bystander_height_m.0, occ.bystander_height_m.1),
        });
    }
    scene
}
