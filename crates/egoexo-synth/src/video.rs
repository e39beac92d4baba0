//! Simulated observer video: the wearer's body drawn into an observer's RGB image, so that the
//! detector step (a real 2D pose model) can be tested end to end on frames whose true 2D
//! joints are known.
//!
//! The body is the viewer's: per SMPL bone a tapered capsule of the mean shape's radii
//! ([`egoexo_core::skeleton::MEAN_SHAPE_BONE_RADII`], scaled to the subject) and a skull,
//! dressed (skin, a short-sleeved shirt, trousers, shoes, hair, eyes) and lit from above, in
//! front of a room (a tiled floor at the session's floor height, walls). It is drawn by
//! splatting points sampled on the surfaces through the camera model itself
//! ([`CameraCalibration::project`]) with a depth buffer, so a fisheye image is exactly as
//! distorted as the camera says. Occluders of the simulated scene (furniture, bystanders) are
//! not drawn.
//!
//! Units: metres, world Y up; pixels with the centre of the top-left pixel at (0, 0).

use egoexo_core::camera::{CameraCalibration, Projection};
use egoexo_core::glam::{Quat, Vec2, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{JointTransforms, MEAN_SHAPE_BONE_RADII, MEAN_SHAPE_SKULL, NUM_JOINTS, PARENTS, SmplJoint};

/// Spacing of the points sampled on the body's surfaces, metres.
const SURFACE_SPACING_M: f32 = 0.01;

/// Colours of the body and the room (sRGB bytes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Appearance {
    pub skin: [u8; 3],
    pub hair: [u8; 3],
    pub shirt: [u8; 3],
    pub trousers: [u8; 3],
    pub shoes: [u8; 3],
    pub wall: [u8; 3],
    pub floor: [[u8; 3]; 2],
}

impl Default for Appearance {
    fn default() -> Self {
        Self {
            skin: [214, 170, 140],
            hair: [52, 36, 28],
            shirt: [178, 48, 44],
            trousers: [44, 58, 96],
            shoes: [30, 30, 32],
            wall: [196, 192, 182],
            floor: [[150, 128, 104], [128, 108, 88]],
        }
    }
}

/// The per-pixel viewing directions of one camera (camera frame), computed once and reused
/// for every frame of its video; `None` outside the valid image.
#[derive(Clone, Debug)]
pub struct CameraRays {
    camera: CameraCalibration,
    directions: Vec<Option<Vec3>>,
}

impl CameraRays {
    pub fn new(camera: &CameraCalibration) -> Self {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let directions = (0..w * h)
            .map(|i| {
                let pixel = Vec2::new((i % w) as f32, (i / w) as f32);
                camera.is_valid_pixel(pixel).then(|| camera.unproject(pixel)).flatten().map(|d| d.normalize())
            })
            .collect();
        Self { camera: *camera, directions }
    }
}

/// One surface point: where, its outward normal, its colour.
struct SurfacePoint {
    at: Vec3,
    normal: Vec3,
    colour: [u8; 3],
}

/// The dressed body's surface points for one posed frame (`fk`), the skeleton `scale` times
/// the mean shape's size.
fn body_surface(fk: &JointTransforms, scale: f32, look: &Appearance) -> Vec<SurfacePoint> {
    let mut points = Vec::with_capacity(20_000);
    let s = SURFACE_SPACING_M;
    for child in 1..NUM_JOINTS {
        let parent = PARENTS[child] as usize;
        let (a, b) = (fk.positions[parent], fk.positions[child]);
        let (ra, rb) = MEAN_SHAPE_BONE_RADII[child];
        let (ra, rb) = (ra * scale, rb * scale);
        let colour = bone_colour(child, look);
        let axis = b - a;
        let length = axis.length();
        if length < 1e-4 {
            continue;
        }
        let dir = axis / length;
        let (u, v) = dir.any_orthonormal_pair();
        let steps = (length / s).ceil().max(1.0) as usize;
        for i in 0..=steps {
            let t = i as f32 / steps as f32;
            let r = ra + (rb - ra) * t;
            let around = ((std::f32::consts::TAU * r / s).ceil() as usize).max(6);
            for k in 0..around {
                let angle = std::f32::consts::TAU * k as f32 / around as f32;
                let normal = u * angle.cos() + v * angle.sin();
                points.push(SurfacePoint { at: a + axis * t + normal * r, normal, colour });
            }
        }
        // Round ends: a sphere of the end's radius at each joint.
        for (centre, r) in [(a, ra), (b, rb)] {
            sphere(centre, r, |_| colour, &mut points);
        }
    }
    // The skull: a sphere beyond the head joint along the neck → head direction, with hair on
    // top and at the back, and two eyes.
    let head = fk.positions[SmplJoint::Head.index()];
    let neck = fk.positions[SmplJoint::Neck.index()];
    let up_dir = (head - neck).normalize_or(Vec3::Y);
    let (radius, offset) = MEAN_SHAPE_SKULL;
    let rotation: Quat = fk.rotations[SmplJoint::Head.index()];
    let (up, forward, left) = (rotation * Vec3::Y, rotation * Vec3::Z, rotation * Vec3::X);
    let eyes = [0.34f32, -0.34].map(|x| (left * x + up * 0.12 + forward * 0.93).normalize());
    sphere(
        head + up_dir * offset * scale,
        radius * scale,
        |n| {
            if eyes.iter().any(|e| n.dot(*e) > 0.992) {
                [25, 20, 18]
            } else if n.dot(up) > 0.45 || n.dot(forward) < -0.25 {
                look.hair
            } else {
                look.skin
            }
        },
        &mut points,
    );
    points
}

/// Points on a sphere (a Fibonacci lattice at about the surface spacing), coloured by normal.
fn sphere(centre: Vec3, r: f32, colour: impl Fn(Vec3) -> [u8; 3], points: &mut Vec<SurfacePoint>) {
    let n = ((4.0 * std::f32::consts::PI * r * r) / (SURFACE_SPACING_M * SURFACE_SPACING_M)).ceil().max(12.0) as usize;
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    for i in 0..n {
        let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
        let ring = (1.0 - y * y).max(0.0).sqrt();
        let theta = golden * i as f32;
        let normal = Vec3::new(ring * theta.cos(), y, ring * theta.sin());
        points.push(SurfacePoint { at: centre + normal * r, normal, colour: colour(normal) });
    }
}

/// What the bone ending at joint `child` wears.
fn bone_colour(child: usize, look: &Appearance) -> [u8; 3] {
    match child {
        1 | 2 | 4 | 5 | 7 | 8 => look.trousers,
        10 | 11 => look.shoes,
        12 | 15 | 20 | 21 | 22 | 23 => look.skin,
        _ => look.shirt,
    }
}

/// Renders one frame: the body posed by `fk` (skeleton `scale` × the mean shape) seen by
/// `rays`' camera on a device at `t_world_device`, the floor at height `floor_y`. Returns
/// `width × height × 3` RGB bytes, rows top to bottom.
pub fn render_frame(
    fk: &JointTransforms,
    scale: f32,
    rays: &CameraRays,
    t_world_device: &RigidTransform,
    floor_y: f32,
    look: &Appearance,
) -> Vec<u8> {
    let camera = &rays.camera;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let t_world_camera = camera.t_world_camera(t_world_device);
    let mut rgb = vec![0u8; w * h * 3];
    // The room: walls, and a floor of 0.6 m tiles.
    let eye = t_world_camera.translation;
    for (i, dir) in rays.directions.iter().enumerate() {
        let Some(dir) = dir else { continue };
        let d = t_world_camera.rotation * *dir;
        let colour = if d.y < -1e-3 && eye.y > floor_y {
            let hit = eye + d * ((floor_y - eye.y) / d.y);
            let tile = ((hit.x / 0.6).floor() as i64 + (hit.z / 0.6).floor() as i64).rem_euclid(2) as usize;
            let fade = (1.0 - ((hit - eye).length() / 40.0)).clamp(0.6, 1.0);
            look.floor[tile].map(|c| (f32::from(c) * fade) as u8)
        } else {
            let shade = 0.85 + 0.15 * d.y.clamp(0.0, 1.0);
            look.wall.map(|c| (f32::from(c) * shade) as u8)
        };
        rgb[i * 3..i * 3 + 3].copy_from_slice(&colour);
    }
    // The body, nearest point wins.
    let t_camera_world = t_world_camera.inverse();
    let light = Vec3::new(0.3, 1.0, 0.4).normalize();
    let focal = match &camera.projection {
        Projection::Pinhole(k) => 0.5 * (k.fx + k.fy),
        Projection::Fisheye624(f) => f.focal(),
    };
    let mut depth = vec![f32::INFINITY; w * h];
    for p in body_surface(fk, scale, look) {
        if p.normal.dot(eye - p.at) <= 0.0 {
            continue; // faces away
        }
        let in_camera = t_camera_world.transform_point(p.at);
        if in_camera.z <= 0.05 {
            continue;
        }
        let Some(pixel) = camera.project(in_camera) else { continue };
        if !camera.is_valid_pixel(pixel) {
            continue;
        }
        let lit = 0.45 + 0.55 * p.normal.dot(light).max(0.0);
        let colour = p.colour.map(|c| (f32::from(c) * lit).min(255.0) as u8);
        let reach = (0.75 * SURFACE_SPACING_M * focal / in_camera.z).max(0.5);
        let (x0, x1) =
            ((pixel.x - reach).round().max(0.0) as usize, (pixel.x + reach).round().min(w as f32 - 1.0) as usize);
        let (y0, y1) =
            ((pixel.y - reach).round().max(0.0) as usize, (pixel.y + reach).round().min(h as f32 - 1.0) as usize);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let i = y * w + x;
                if in_camera.z < depth[i] && rays.directions[i].is_some() {
                    depth[i] = in_camera.z;
                    rgb[i * 3..i * 3 + 3].copy_from_slice(&colour);
                }
            }
        }
    }
    rgb
}

/// Renders every observer's video of `sim` — the wearer's `motion` (its ground truth) seen
/// from the observer's true head poses, one frame per motion frame — and hands each to
/// `encode(frames, width, height, fps)`, which returns the video file's bytes (natively,
/// `egoexo_detect::native::encode_mp4`). The observers' simulated keypoints are replaced by the
/// video (`observers/<id>/rgb.mp4`, first frame at the motion's start); returns the files by
/// their session paths.
pub fn render_observer_videos<E>(
    sim: &mut crate::SimulatedSession,
    motion: &egoexo_core::SmplMotion,
    look: &Appearance,
    mut encode: impl FnMut(&mut dyn Iterator<Item = Vec<u8>>, u32, u32, f64) -> Result<Vec<u8>, E>,
) -> Result<std::collections::BTreeMap<String, Vec<u8>>, E> {
    let scale = motion.skeleton.head_height() / egoexo_core::SmplSkeleton::mean_shape().head_height();
    let floor_y = sim.session.floor.as_ref().map_or(0.0, |f| f.height_m);
    let mut files = std::collections::BTreeMap::new();
    for (o, observer) in sim.session.observers.iter_mut().enumerate() {
        let rays = CameraRays::new(&observer.camera);
        let heads = &sim.true_observer_heads[o];
        let mut frames = motion.poses.iter().zip(heads).map(|(pose, head)| {
            render_frame(&motion.skeleton.forward_kinematics(pose), scale, &rays, head, floor_y, look)
        });
        let (w, h) = (observer.camera.width, observer.camera.height);
        let bytes = encode(&mut frames, w, h, f64::from(motion.fps))?;
        let path = format!("observers/{}/rgb.mp4", observer.id);
        observer.keypoints = None;
        observer.video = Some(egoexo_session::model::VideoRef {
            path: path.clone(),
            start_ns: motion.start_ns,
            frame_times_ns: Vec::new(),
        });
        files.insert(path, bytes);
    }
    Ok(files)
}
