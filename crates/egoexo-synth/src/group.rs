//! Scenes of several people (issue: everyone in the session): 2–3 participants who walk and
//! look at each other, each wearing Aria-like glasses (head tracking, optional wrist devices,
//! an RGB camera), and bystanders who walk through without glasses. Every camera's detector
//! reports everyone it sees — participants and bystanders alike, in no particular order and
//! without identity ([`ViewPeople::Unassigned`]) — with the single-wearer simulator's noise,
//! misses and occlusion model, people occluding each other as cylinders. Which detection is
//! whom is kept aside ([`SimulatedCapture::identities`]) to score association against.
//!
//! World Y-up, metres, seconds; deterministic from the seed.

use egoexo_core::TrackingMode;
use egoexo_core::exo_keypoints::{
    COCO17_COUNT, Keypoint2d, coco17_from_exo, device_from_head_joint, exo_keypoints_from_smpl,
};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::motion::SmplMotion;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE, JointTransforms, SmplJoint, SmplSkeleton};
use egoexo_session::capture::{Capture, Participant, PeopleTrack, View, ViewPeople};
use egoexo_session::model::{Floor, FloorSource, GroundTruth, ObserverOcclusion, SubjectInfo, Trajectory, WristSource};
use serde::{Deserialize, Serialize};

use crate::cameras::{aria_rgb_camera, wide_pinhole_camera};
use crate::config::{CameraChoice, DetectorModel, DeviceNoise};
use crate::detector::{DetectorState, detect};
use crate::devices::add_tracking_noise;
use crate::procedural::{walking_circle_around, walking_line};
use crate::rng::SimRng;
use crate::scene::{Scene, Walker};
use crate::simulate::SynthError;

/// Where the participants look.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GazeBehaviour {
    /// How long attention stays on one person before it moves on, seconds (uniform range).
    pub attention_s: (f32, f32),
    /// Probability that attention goes to the way ahead instead of a person.
    pub look_ahead_probability: f32,
    /// The head turns at most this far from the chest's facing, radians.
    pub max_head_yaw_rad: f32,
    /// The head follows its target with this time constant, seconds.
    pub lag_s: f32,
}

impl Default for GazeBehaviour {
    fn default() -> Self {
        Self {
            attention_s: (1.5, 5.0),
            look_ahead_probability: 0.15,
            max_head_yaw_rad: 75f32.to_radians(),
            lag_s: 0.25,
        }
    }
}

/// A group scene's parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupConfig {
    /// Participants' devices: glasses only (1-point) or glasses + wrist devices (3-point).
    pub tracking: TrackingMode,
    /// People walking through without glasses, seen by the cameras and occluding.
    pub bystanders: usize,
    pub device_noise: DeviceNoise,
    pub camera: CameraChoice,
    pub detector: DetectorModel,
    pub gaze: GazeBehaviour,
    /// A person as an occluder: a cylinder of this radius (metres) up to their head's top.
    pub person_radius_m: f32,
}

impl Default for GroupConfig {
    fn default() -> Self {
        Self {
            tracking: TrackingMode::ThreePoint,
            bystanders: 2,
            device_noise: DeviceNoise::default(),
            camera: CameraChoice::default(),
            detector: DetectorModel::default(),
            gaze: GazeBehaviour::default(),
            person_radius_m: 0.2,
        }
    }
}

/// A simulated capture and what only the simulator knows about it.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedCapture {
    /// Participants `participant-1…`, every camera's people unassigned.
    pub capture: Capture,
    /// Per view (the capture's order), per frame, per detection (as listed): the participant
    /// index it is, or `None` for a bystander.
    pub identities: Vec<Vec<Vec<Option<usize>>>>,
    /// The bystanders' true motions.
    pub bystanders: Vec<SmplMotion>,
}

impl SimulatedCapture {
    /// The capture with every view assigned by the simulator's own identities (a perfect
    /// association): per camera, one keypoint track per other participant, bystanders left out.
    pub fn with_true_identities(&self) -> Capture {
        let mut capture = self.capture.clone();
        let mut views = Vec::new();
        for (view, identities) in self.capture.views.iter().zip(&self.identities) {
            let ViewPeople::Unassigned(people) = &view.people else {
                views.push(view.clone());
                continue;
            };
            for (q, participant) in self.capture.participants.iter().enumerate() {
                if participant.id == view.observer {
                    continue;
                }
                let frames = people
                    .frames
                    .iter()
                    .zip(identities)
                    .map(|(detections, who)| {
                        who.iter().position(|w| *w == Some(q)).map_or([None; COCO17_COUNT], |d| detections[d])
                    })
                    .collect();
                views.push(View {
                    observer: view.observer.clone(),
                    people: ViewPeople::Assigned {
                        target: participant.id.clone(),
                        keypoints: egoexo_session::model::KeypointTrack {
                            timestamps_ns: people.timestamps_ns.clone(),
                            frames,
                        },
                    },
                });
            }
        }
        capture.views = views;
        capture
    }
}

/// Participants for a group walk: `n` people on concentric circles around the origin (radii
/// 1.5, 3, 4.5 m, …) walking the same way at the same angular speed, a little apart, so they
/// stay near each other and can look across at one another; statures 1.50–1.70 m (head
/// height). `seconds` long, 30 fps.
pub fn group_walk(n: usize, seconds: f32) -> Vec<SmplMotion> {
    (0..n)
        .map(|i| {
            let radius = 1.5 * (i + 1) as f32;
            let head_height = 1.5 + 0.1 * (i % 3) as f32;
            walking_circle_around(Vec3::ZERO, radius, 0.25 * radius, 0.35 * i as f32, head_height, seconds)
        })
        .collect()
}

/// Simulates the capture of `motions` (one per participant, same frame rate; the capture is
/// as long as the shortest), the participants looking at each other ([`GazeBehaviour`]: their
/// necks and heads turn, which becomes part of their true motion), with
/// `config.bystanders` people crossing the scene.
pub fn simulate_group(
    motions: &[SmplMotion],
    name: &str,
    config: &GroupConfig,
    seed: u64,
) -> Result<SimulatedCapture, SynthError> {
    let frames = motions.iter().map(SmplMotion::len).min().unwrap_or(0);
    let Some(first) = motions.first().filter(|_| frames > 0) else {
        return Err(SynthError::EmptyMotion { name: name.to_string() });
    };
    let fps = first.fps;
    let mut rng = SimRng::new(seed);
    let truncate = |m: &SmplMotion| {
        let mut m = m.clone();
        m.poses.truncate(frames);
        m
    };
    let mut truth: Vec<SmplMotion> = motions.iter().map(truncate).collect();
    look_at_each_other(&mut truth, &config.gaze, &mut rng.fork(1));
    let fk: Vec<Vec<JointTransforms>> =
        truth.iter().map(|m| m.poses.iter().map(|p| m.skeleton.forward_kinematics(p)).collect()).collect();
    let floor_y = fk
        .iter()
        .flat_map(|frames| frames.iter().flat_map(|f| [7, 8, 10, 11].map(|j| f.positions[j].y)))
        .fold(f32::INFINITY, f32::min)
        - 0.03 * first.skeleton.head_height() / SmplSkeleton::mean_shape().head_height();

    // Bystanders cross the group's area on straight lines at walking speed.
    let centre = fk.iter().map(|f| f[0].positions[SmplJoint::Pelvis.index()]).sum::<Vec3>() / fk.len() as f32;
    let seconds = frames as f32 / fps;
    let mut brng = rng.fork(2);
    let bystanders: Vec<SmplMotion> = (0..config.bystanders)
        .map(|_| {
            let heading = brng.uniform(0.0, std::f32::consts::TAU);
            let speed = brng.uniform(0.9, 1.4);
            let through = centre + Vec3::new(brng.uniform(-2.5, 2.5), 0.0, brng.uniform(-2.5, 2.5));
            let velocity = speed * Vec3::new(heading.sin(), 0.0, heading.cos());
            let start = through - velocity * brng.uniform(0.2, 0.8) * seconds;
            walking_line(start, velocity, brng.uniform(1.45, 1.75), seconds + 1.0 / fps)
        })
        .map(|m| truncate(&m))
        .collect();
    let bystander_fk: Vec<Vec<JointTransforms>> =
        bystanders.iter().map(|m| m.poses.iter().map(|p| m.skeleton.forward_kinematics(p)).collect()).collect();

    // Everyone as an occluder: participants first, then bystanders.
    let people: Vec<(&SmplMotion, &Vec<JointTransforms>)> =
        truth.iter().zip(&fk).chain(bystanders.iter().zip(&bystander_fk)).collect();
    let walkers: Vec<Walker> = people
        .iter()
        .map(|(m, frames)| Walker {
            fps,
            floor: frames
                .iter()
                .map(|f| {
                    let head = f.positions[SmplJoint::Head.index()];
                    Vec3::new(head.x, floor_y, head.z)
                })
                .collect(),
            radius: config.person_radius_m,
            height: m.skeleton.head_height() + 0.12,
        })
        .collect();

    let timestamps: Vec<i64> = (0..frames).map(|i| first.timestamp_ns(i)).collect();
    let mut participants = Vec::new();
    let mut true_heads = Vec::new();
    for (p, (motion, frames_fk)) in truth.iter().zip(&fk).enumerate() {
        let mut prng = rng.fork(100 + p as u64);
        let pose = |f: usize, j: SmplJoint| {
            RigidTransform::new(frames_fk[f].rotations[j.index()], frames_fk[f].positions[j.index()])
        };
        let head_truth: Vec<_> = (0..frames)
            .map(|f| device_from_head_joint(&pose(f, SmplJoint::Head), DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE))
            .collect();
        let head = add_tracking_noise(&head_truth, fps, &config.device_noise, &mut prng);
        let mut wrist = |j: SmplJoint| {
            let truth: Vec<_> = (0..frames).map(|f| pose(f, j)).collect();
            Trajectory {
                timestamps_ns: timestamps.clone(),
                poses: add_tracking_noise(&truth, fps, &config.device_noise, &mut prng),
            }
        };
        let (left_wrist, right_wrist) = match config.tracking {
            TrackingMode::OnePoint => (None, None),
            TrackingMode::ThreePoint => (Some(wrist(SmplJoint::LeftWrist)), Some(wrist(SmplJoint::RightWrist))),
        };
        let sizes = &config.camera.image_sizes;
        let size = *sizes.get(prng.int(0, sizes.len().saturating_sub(1))).ok_or(SynthError::NoImageSizes)?;
        let camera = if prng.chance(config.camera.fisheye_probability) {
            aria_rgb_camera(size)?
        } else {
            wide_pinhole_camera(size)?
        };
        participants.push(Participant {
            id: format!("participant-{}", p + 1),
            reconstruct: true,
            head: Trajectory { timestamps_ns: timestamps.clone(), poses: head },
            left_wrist,
            right_wrist,
            wrist_source: WristSource::Devices,
            head_joint_in_device: DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE,
            camera: Some(camera),
            video: None,
            context_features: None,
            subject: SubjectInfo {
                height_m: None,
                betas: motion.betas.clone(),
                rest_joints: Some(*motion.skeleton.rest_joints()),
            },
            ground_truth: Some(GroundTruth { motion: motion.clone(), occlusion: Vec::new() }),
            placement: egoexo_session::placement::Placement::default(),
        });
        true_heads.push(head_truth);
    }

    // Every camera sees everyone else: one detector state per (camera, person), people listed
    // in a random order per frame.
    let mut views = Vec::new();
    let mut identities = Vec::new();
    let mut labels: Vec<Vec<ObserverOcclusion>> = vec![Vec::new(); participants.len()];
    for (o, observer) in participants.iter().enumerate() {
        let camera = observer.camera.expect("every simulated participant has a camera");
        let mut orng = rng.fork(200 + o as u64);
        // The scene as seen when looking at person `q`: everyone but `q` and the observer.
        let scenes: Vec<Scene> = (0..people.len())
            .map(|q| Scene {
                walkers: walkers
                    .iter()
                    .enumerate()
                    .filter(|&(w, _)| w != q && w != o)
                    .map(|(_, w)| w.clone())
                    .collect(),
                ..Scene::default()
            })
            .collect();
        let mut states = vec![DetectorState::default(); people.len()];
        let mut occluded = vec![Vec::with_capacity(frames); participants.len()];
        let mut track = PeopleTrack { timestamps_ns: timestamps.clone(), frames: Vec::with_capacity(frames) };
        let mut who = Vec::with_capacity(frames);
        for f in 0..frames {
            let t = f as f32 / fps;
            let mut seen: Vec<(Option<usize>, [Option<Keypoint2d>; COCO17_COUNT])> = Vec::new();
            for (q, (motion, frames_fk)) in people.iter().enumerate() {
                if q == o {
                    continue;
                }
                let joints = &frames_fk[f];
                let scale = motion.skeleton.head_height() / SmplSkeleton::mean_shape().head_height();
                let head_joint = RigidTransform::new(
                    joints.rotations[SmplJoint::Head.index()],
                    joints.positions[SmplJoint::Head.index()],
                );
                let exo = exo_keypoints_from_smpl(&joints.positions, head_joint.rotation, scale);
                let points = coco17_from_exo(&exo, &head_joint, scale);
                let detection = detect(
                    &points,
                    &camera,
                    &true_heads[o][f],
                    &scenes[q],
                    t,
                    &config.detector,
                    &mut states[q],
                    &mut orng,
                );
                let participant = (q < participants.len()).then_some(q);
                if let Some(q) = participant {
                    occluded[q].push(detection.occluded);
                }
                if detection.keypoints.iter().any(Option::is_some) {
                    seen.push((participant, detection.keypoints));
                }
            }
            // Shuffle (Fisher–Yates): a detector's output order says nothing about identity.
            for i in (1..seen.len()).rev() {
                seen.swap(i, orng.int(0, i));
            }
            who.push(seen.iter().map(|(q, _)| *q).collect());
            track.frames.push(seen.into_iter().map(|(_, k)| k).collect());
        }
        for (q, masks) in occluded.into_iter().enumerate() {
            if q != o {
                labels[q].push(ObserverOcclusion { observer_id: observer.id.clone(), occluded: masks });
            }
        }
        views.push(View { observer: observer.id.clone(), people: ViewPeople::Unassigned(track) });
        identities.push(who);
    }
    for (participant, labels) in participants.iter_mut().zip(labels) {
        if let Some(gt) = participant.ground_truth.as_mut() {
            gt.occlusion = labels;
        }
    }
    let capture = Capture {
        name: name.to_string(),
        participants,
        views,
        floor: Some(Floor { height_m: floor_y, source: FloorSource::GroundTruth }),
    };
    Ok(SimulatedCapture { capture, identities, bystanders })
}

/// Turns each participant's neck and head towards the others (changing whom every few
/// seconds, sometimes looking ahead instead), within the neck's range and with a lag. The
/// turn is about the world vertical through the neck, split 40/60 between neck and head.
fn look_at_each_other(motions: &mut [SmplMotion], gaze: &GazeBehaviour, rng: &mut SimRng) {
    let heads: Vec<Vec<Vec3>> = motions
        .iter()
        .map(|m| m.poses.iter().map(|p| m.skeleton.forward_kinematics(p).positions[SmplJoint::Head.index()]).collect())
        .collect();
    let n = motions.len();
    for (p, motion) in motions.iter_mut().enumerate() {
        let fps = motion.fps;
        let mut target: Option<usize> = None;
        let mut switch_at = 0.0;
        let mut yaw = 0.0f32;
        let alpha = (1.0 / (gaze.lag_s * fps)).min(1.0);
        for f in 0..motion.poses.len() {
            let t = f as f32 / fps;
            if t >= switch_at {
                switch_at = t + rng.uniform(gaze.attention_s.0, gaze.attention_s.1);
                let others: Vec<usize> = (0..n).filter(|&q| q != p).collect();
                target = if others.is_empty() || rng.chance(gaze.look_ahead_probability) {
                    None
                } else {
                    Some(others[rng.int(0, others.len() - 1)])
                };
            }
            let fk = motion.skeleton.forward_kinematics(&motion.poses[f]);
            let chest = fk.rotations[SmplJoint::Spine3.index()] * Vec3::Z;
            let head_forward = fk.rotations[SmplJoint::Head.index()] * Vec3::Z;
            let wanted = match target {
                Some(q) => {
                    let to = heads[q][f.min(heads[q].len() - 1)] - heads[p][f];
                    let limit = gaze.max_head_yaw_rad;
                    (signed_yaw(head_forward, to) + signed_yaw(chest, head_forward)).clamp(-limit, limit)
                        - signed_yaw(chest, head_forward)
                }
                None => 0.0,
            };
            yaw += alpha * (wanted - yaw);
            let neck = SmplJoint::Neck.index();
            let head = SmplJoint::Head.index();
            let turn = |share: f32| Quat::from_rotation_y(share * yaw);
            // local' = parent_world⁻¹ · R_y(δ) · parent_world · local (a turn about the
            // world vertical); the head's parent has already turned by the neck's share.
            let spine_world = fk.rotations[SmplJoint::Spine3.index()];
            let neck_world = fk.rotations[neck];
            let body = &mut motion.poses[f].body;
            body[neck - 1] = (spine_world.inverse() * turn(0.4) * spine_world * body[neck - 1]).normalize();
            body[head - 1] = (neck_world.inverse() * turn(0.6) * neck_world * body[head - 1]).normalize();
        }
    }
}

/// The angle (radians, about +Y, counter-clockwise seen from above) from `from` to `to`,
/// both projected on the horizontal plane.
fn signed_yaw(from: Vec3, to: Vec3) -> f32 {
    let a = from.x.atan2(from.z);
    let b = to.x.atan2(to.z);
    let d = b - a;
    (d + std::f32::consts::PI).rem_euclid(std::f32::consts::TAU) - std::f32::consts::PI
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_participants_see_each_other_and_the_bystanders_are_in_the_views() {
        let motions = group_walk(2, 10.0);
        let sim = simulate_group(&motions, "pair", &GroupConfig { bystanders: 2, ..Default::default() }, 7).unwrap();
        let capture = &sim.capture;
        capture.validate().unwrap();
        assert_eq!(capture.participants.len(), 2);
        assert_eq!(capture.views.len(), 2);
        let mut bystander_detections = 0;
        for (v, view) in capture.views.iter().enumerate() {
            let ViewPeople::Unassigned(people) = &view.people else { panic!("views start unassigned") };
            assert_eq!(people.frames.len(), 300);
            let other = 1 - v;
            let seen_other = sim.identities[v].iter().filter(|f| f.contains(&Some(other))).count();
            let bystanders = sim.identities[v].iter().map(|f| f.iter().filter(|q| q.is_none()).count()).sum::<usize>();
            assert!(seen_other > 150, "{}: the other participant in {seen_other} of 300 frames", view.observer);
            bystander_detections += bystanders;
            for (frame, who) in people.frames.iter().zip(&sim.identities[v]) {
                assert_eq!(frame.len(), who.len());
                assert!(!who.contains(&Some(v)), "a camera never sees its own wearer");
            }
        }
        assert!(bystander_detections > 0, "the bystanders are seen");
        // The gaze is part of the true motion: the heads turn away from the walking direction.
        let gt = capture.participants[0].ground_truth.as_ref().unwrap();
        assert_ne!(gt.motion.poses[150].body, motions[0].poses[150].body);
        assert_eq!(gt.occlusion.len(), 1, "labelled by the one other camera");
        // The same seed gives the same capture.
        let again = simulate_group(&motions, "pair", &GroupConfig { bystanders: 2, ..Default::default() }, 7).unwrap();
        assert_eq!(again, sim);
    }

    #[test]
    fn each_participant_becomes_a_wearer_watched_by_the_others() {
        let sim = simulate_group(&group_walk(3, 4.0), "three", &GroupConfig::default(), 3).unwrap();
        for p in 0..3 {
            let session = sim.capture.session_for(p).unwrap();
            assert_eq!(session.observers.len(), 2);
            assert!(session.observers.iter().all(|o| o.keypoints.is_none()), "nothing is assigned before association");
            assert_eq!(session.ground_truth.as_ref().unwrap().motion.len(), 120);
        }
    }
}
