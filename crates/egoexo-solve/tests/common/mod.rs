//! Synthetic scenes for the solver's tests: a wearer walking a loop (a rigid-ish body of
//! COCO-17 points carried by the head), an observer camera following them, keypoints projected
//! with noise and the failures a detector makes, and the observer's world moved by a known
//! transform.

#![allow(dead_code)]

use egoexo_core::camera::{CameraCalibration, Pinhole, Projection, aria_rgb};
use egoexo_core::exo_keypoints::{COCO17_COUNT, COCO17_MIRROR, Keypoint2d, face_points_from_device};
use egoexo_core::glam::{Quat, Vec2, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE;
use egoexo_solve::registration::{TargetPoint, TargetTrack, ViewFrame, ViewTrack};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Body points (COCO 5..17) in the walker's heading frame (+X left, +Y up, +Z forward),
/// relative to the head device.
const BODY: [(usize, [f32; 3]); 12] = [
    (5, [0.18, -0.30, -0.10]),
    (6, [-0.18, -0.30, -0.10]),
    (7, [0.22, -0.58, -0.10]),
    (8, [-0.22, -0.58, -0.10]),
    (9, [0.22, -0.84, -0.04]),
    (10, [-0.22, -0.84, -0.04]),
    (11, [0.10, -0.80, -0.10]),
    (12, [-0.10, -0.80, -0.10]),
    (13, [0.10, -1.22, -0.06]),
    (14, [-0.10, -1.22, -0.06]),
    (15, [0.10, -1.62, -0.10]),
    (16, [-0.10, -1.62, -0.10]),
];

#[derive(Clone, Debug)]
pub struct Scene {
    pub fps: f64,
    pub seconds: f64,
    /// The wearer walks a circle of this radius (0: stands still).
    pub walk_radius: f64,
    /// Radians per second around the circle (negative: the other way).
    pub angular_speed: f64,
    /// The wearer turns the head by this much (radians) back and forth.
    pub head_sway: f64,
    /// Observer: distance from the circle's centre, and whether it walks.
    pub observer_distance: f64,
    pub observer_walks: bool,
    /// The camera: fisheye (Aria RGB at 1408) or a pinhole of this focal length.
    pub fisheye: bool,
    pub pinhole_focal: f32,
    /// The observer's world is `X⁻¹ ·` the wearer's: `X = T_wearer_observerworld`.
    pub transform: RigidTransform,
    /// The observer's clock runs this much behind: `t_wearer = t_observer + offset`.
    pub clock_offset_s: f64,
    /// A static camera with no pose: its frames' poses are the identity.
    pub static_unposed: bool,
    pub pixel_noise: f32,
    /// Probability per frame of a left–right swap, of another person instead of the wearer,
    /// and per keypoint of a confidently wrong place (per 1 s episode).
    pub swap_probability: f64,
    pub other_person_probability: f64,
    pub wrong_keypoint_probability: f64,
    /// The body model's error (slowly varying offset per point, metres), as a coarse pose's.
    pub body_error_m: f32,
    /// Give the solver body points at all (else the face only).
    pub with_body: bool,
    /// The camera follows and sees someone else (a bystander walking a circle of this radius
    /// at this angular speed, with this head sway, this many seconds out of phase), never the
    /// wearer.
    pub bystander: Option<(f64, f64, f64, f64)>,
    pub seed: u64,
}

impl Default for Scene {
    fn default() -> Self {
        Self {
            fps: 30.0,
            seconds: 10.0,
            walk_radius: 1.5,
            angular_speed: 0.5,
            head_sway: 0.4,
            observer_distance: 4.0,
            observer_walks: false,
            fisheye: true,
            pinhole_focal: 600.0,
            transform: RigidTransform::IDENTITY,
            clock_offset_s: 0.0,
            static_unposed: false,
            pixel_noise: 2.0,
            swap_probability: 0.0,
            other_person_probability: 0.0,
            wrong_keypoint_probability: 0.0,
            body_error_m: 0.0,
            with_body: true,
            bystander: None,
            seed: 1,
        }
    }
}

pub struct Built {
    pub track: TargetTrack,
    pub view: ViewTrack,
    /// The camera's true pose in the wearer's world, per frame.
    pub true_cameras: Vec<RigidTransform>,
}

fn head_pose(s: &Scene, t: f64) -> RigidTransform {
    let angle = s.angular_speed * t;
    let (sin, cos) = angle.sin_cos();
    let position =
        Vec3::new((s.walk_radius * cos) as f32, 1.6 + 0.02 * (6.0 * t).sin() as f32, (s.walk_radius * sin) as f32);
    // Walking direction (tangent) as the heading; the head sways about it.
    let heading = if s.walk_radius > 0.0 {
        (-sin * s.angular_speed.signum()).atan2(cos * s.angular_speed.signum()) as f32
    } else {
        0.0
    };
    let yaw = heading + (s.head_sway * (0.7 * t).sin()) as f32;
    let pitch = (0.15 * (0.9 * t).sin()) as f32;
    RigidTransform::new(Quat::from_rotation_y(yaw) * Quat::from_rotation_x(pitch), position)
}

pub fn body_points(_: &Scene, t: f64, head: &RigidTransform) -> [Vec3; COCO17_COUNT] {
    let mut points = [Vec3::ZERO; COCO17_COUNT];
    let face = face_points_from_device(head, DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE, 1.0);
    points[..5].copy_from_slice(&face);
    let (_, yaw, _) = head.rotation.to_euler(egoexo_core::glam::EulerRot::YXZ);
    let heading = RigidTransform::new(Quat::from_rotation_y(yaw), head.translation);
    let swing = (0.25 * (4.0 * t).sin()) as f32;
    for (k, offset) in BODY {
        let mut o = Vec3::from(offset);
        if k >= 13 {
            o.z += if k % 2 == 1 { swing } else { -swing } * (o.y.abs() - 0.8);
        }
        points[k] = heading.transform_point(o);
    }
    points
}

pub fn camera(s: &Scene) -> CameraCalibration {
    if s.fisheye {
        aria_rgb::camera(1408).unwrap()
    } else {
        CameraCalibration::new(
            Projection::Pinhole(Pinhole::new(s.pinhole_focal, s.pinhole_focal, 703.5, 703.5).unwrap()),
            1408,
            1408,
            RigidTransform::IDENTITY,
        )
        .unwrap()
    }
}

/// An optical-frame camera at `eye` looking at `target` (+Z forward, +Y down).
fn look_at(eye: Vec3, target: Vec3) -> RigidTransform {
    let z = (target - eye).normalize();
    let x = Vec3::Y.cross(z).normalize() * -1.0; // right
    let y = z.cross(x);
    RigidTransform::from_rotation_matrix(egoexo_core::glam::Mat3::from_cols(x, y, z), eye)
}

pub fn build(s: &Scene) -> Built {
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    let camera = camera(s);
    let frames = (s.seconds * s.fps) as usize;
    let mut body_error = [Vec3::ZERO; COCO17_COUNT];
    let mut times = Vec::new();
    let mut points = Vec::new();
    // The wearer's track covers the view with a margin for clock offsets.
    let margin = 3.0;
    let track_frames = ((s.seconds + 2.0 * margin) * s.fps) as usize;
    for i in 0..track_frames {
        let t = i as f64 / s.fps - margin;
        let head = head_pose(s, t);
        let p = body_points(s, t, &head);
        if i % 15 == 0 {
            for e in &mut body_error {
                *e = Vec3::new(rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.5)
                    * (2.0 * s.body_error_m);
            }
        }
        let mut frame = [None; COCO17_COUNT];
        for k in 0..COCO17_COUNT {
            if k < 5 {
                frame[k] = Some(TargetPoint { position: v(p[k]), sigma_m: 0.025 });
            } else if s.with_body {
                frame[k] = Some(TargetPoint { position: v(p[k] + body_error[k]), sigma_m: 0.08 });
            }
        }
        times.push(t);
        points.push(frame);
    }
    let track = TargetTrack::new(times, points).unwrap();

    let x_inv = s.transform.inverse();
    let mut view_frames = Vec::new();
    let mut true_cameras = Vec::new();
    let mut wrong: [Option<(Vec3, usize)>; COCO17_COUNT] = [None; COCO17_COUNT];
    let observer_start = Vec3::new(s.observer_distance as f32, 1.65, 0.3);
    let static_pose = look_at(observer_start, Vec3::new(0.0, 1.0, 0.0));
    for i in 0..frames {
        // Camera time (observer clock) and the wearer's time.
        let t_obs = i as f64 / s.fps;
        let t = t_obs + s.clock_offset_s;
        let mut p = match s.bystander {
            None => body_points(s, t, &head_pose(s, t)),
            Some((radius, speed, sway, phase)) => {
                let them = Scene { walk_radius: radius, angular_speed: speed, head_sway: sway, ..s.clone() };
                body_points(&them, t + phase, &head_pose(&them, t + phase))
            }
        };
        let chest = (p[5] + p[6]) * 0.5;
        let true_camera = if s.static_unposed {
            static_pose
        } else {
            let eye = if s.observer_walks {
                let a = 0.2 * t as f32;
                Vec3::new(s.observer_distance as f32 * a.cos(), 1.65, s.observer_distance as f32 * a.sin())
            } else {
                observer_start
            };
            let jitter = Vec3::new(0.2 * (1.3 * t as f32).sin(), 0.1 * (2.1 * t as f32).cos(), 0.0);
            look_at(eye, chest + jitter)
        };
        if rng.random_bool(s.other_person_probability) {
            // Someone else: the same body shifted 1.5 m aside.
            for q in &mut p {
                *q += Vec3::new(1.2, 0.0, -0.9);
            }
        }
        let swap = rng.random_bool(s.swap_probability);
        let mut keypoints = [None; COCO17_COUNT];
        for k in 0..COCO17_COUNT {
            if let Some((_, left)) = wrong[k] {
                if left == 0 {
                    wrong[k] = None;
                } else {
                    wrong[k] = wrong[k].map(|(d, l)| (d, l - 1));
                }
            } else if rng.random_bool(s.wrong_keypoint_probability / s.fps) {
                let d = Vec3::new(rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.8, rng.random::<f32>() - 0.5)
                    .normalize()
                    * 0.35;
                wrong[k] = Some((d, s.fps as usize));
            }
            let point = p[k] + wrong[k].map_or(Vec3::ZERO, |(d, _)| d);
            let q = true_camera.inverse().transform_point(point);
            let Some(pixel) = camera.project(q) else { continue };
            if !camera.is_valid_pixel(pixel) {
                continue;
            }
            let noise = Vec2::new(normal(&mut rng), normal(&mut rng)) * s.pixel_noise;
            let k_out = if swap { COCO17_MIRROR[k] } else { k };
            keypoints[k_out] = Some(Keypoint2d { pixel: pixel + noise, score: 0.9 });
        }
        let pose = if s.static_unposed { RigidTransform::IDENTITY } else { x_inv * true_camera };
        view_frames.push(ViewFrame { time_s: t_obs, t_world_camera: pose, people: vec![keypoints] });
        true_cameras.push(true_camera);
    }
    Built { track, view: ViewTrack { camera, estimate_focal: false, frames: view_frames }, true_cameras }
}

fn normal(rng: &mut ChaCha8Rng) -> f32 {
    // Box–Muller.
    let u1: f32 = rng.random::<f32>().max(1e-7);
    let u2: f32 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

pub fn v(p: Vec3) -> nalgebra::Vector3<f64> {
    nalgebra::Vector3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z))
}

/// Yaw (degrees) and translation error (metres) between two transforms.
pub fn errors(found: &RigidTransform, truth: &RigidTransform) -> (f64, f64) {
    let (a, b) = (egoexo_solve::geometry::isometry(found), egoexo_solve::geometry::isometry(truth));
    let angle = a.rotation.angle_to(&b.rotation).to_degrees();
    (angle, (a.translation.vector - b.translation.vector).norm())
}

pub fn yaw_transform(yaw_deg: f32, t: [f32; 3]) -> RigidTransform {
    RigidTransform::new(Quat::from_rotation_y(yaw_deg.to_radians()), Vec3::from(t))
}
