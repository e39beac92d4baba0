//! From a [`SceneData`] to what the GPU draws: validation on arrival, the static lines (floor
//! grid, whole device trajectories) built once, and the per-frame instances (skeletons,
//! device trails, observer frustums, gated rays).
//!
//! Nothing here computes geometry beyond placing primitives: every position in the scene is
//! already in the world (Y-up, metres). Non-finite positions are never drawn.

use bytemuck::{Pod, Zeroable};
use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, ExoKeypoint};
use egoexo_core::skeleton::{MEAN_SHAPE_REST_JOINTS, NUM_JOINTS, PARENTS, SmplJoint};
use egoexo_scene::{ObserverScene, SceneData};
use glam::{Quat, Vec3};
use thiserror::Error;

use crate::camera::Bounds;
use crate::colors::{self, BodySide, Rgba};
use crate::mesh::{self, LineVertex};

/// The most frames a scene may have (about 46 h at 30 fps); bounds the array-size arithmetic.
pub const MAX_FRAMES: usize = 5_000_000;

/// The highest frame rate a scene may declare, frames per second.
pub const MAX_FPS: f32 = 1000.0;

/// Joint sphere radius of the reconstructed skeleton, metres.
pub const JOINT_RADIUS: f32 = 0.028;
/// Head joint sphere radius, metres.
pub const HEAD_RADIUS: f32 = 0.075;
/// Bone cylinder radius, metres.
pub const BONE_RADIUS: f32 = 0.018;
/// Device trail seconds shown before and after the current frame.
pub const TRAIL_S: (f32, f32) = (2.0, 1.0);
/// Radius of an observer ray's cylinder, metres.
pub const RAY_RADIUS: f32 = 0.007;
/// Depth at which the observer frustum is drawn, metres.
pub const FRUSTUM_DEPTH: f32 = 0.3;
/// Largest half field of view drawn (fisheye cameras exceed 90°), radians.
pub const MAX_DRAWN_HALF_FOV: f32 = 1.2;

/// Why a scene was refused.
#[derive(Debug, Error)]
pub enum SceneError {
    #[error("scene JSON is not a SceneData: {0}")]
    Json(#[from] serde_json::Error),
    #[error("scene has {0} frames; the viewer accepts at most {MAX_FRAMES}")]
    TooManyFrames(usize),
    #[error("scene is inconsistent: {0}")]
    Inconsistent(String),
}

/// Parses `serde_json` bytes of a [`SceneData`] and validates it ([`validate_scene`]).
pub fn parse_scene(json: &[u8]) -> Result<SceneData, SceneError> {
    let scene: SceneData = serde_json::from_slice(json)?;
    validate_scene(&scene)?;
    Ok(scene)
}

/// [`SceneData::check`] (array lengths, format version) plus what the viewer relies on: a
/// positive finite rate, a tree of parents (each before its child), finite half-FOVs.
pub fn validate_scene(scene: &SceneData) -> Result<(), SceneError> {
    if scene.frames > MAX_FRAMES {
        return Err(SceneError::TooManyFrames(scene.frames));
    }
    let mut problems: Vec<String> = scene.check().err().into_iter().collect();
    if !(scene.fps.is_finite() && scene.fps > 0.0 && scene.fps <= MAX_FPS) {
        problems.push(format!("fps is {}, expected a rate in (0, {MAX_FPS}] frames per second", scene.fps));
    }
    for (child, &parent) in scene.parents.iter().enumerate() {
        if parent != -1 && !(parent >= 0 && (parent as usize) < child) {
            problems.push(format!("parents[{child}] = {parent}, expected -1 or a joint index below {child}"));
        }
    }
    for o in &scene.observers {
        if !o.half_fov.iter().all(|a| a.is_finite() && *a > 0.0) {
            problems.push(format!("observer {} half_fov {:?}, expected positive radians", o.id, o.half_fov));
        }
    }
    if !scene.floor_y.is_finite() {
        problems.push(format!("floor_y is {}, expected a finite height", scene.floor_y));
    }
    if problems.is_empty() { Ok(()) } else { Err(SceneError::Inconsistent(problems.join("; "))) }
}

/// One instanced solid: a sphere at `a` (then `b == a`) of `radius`, or a (tapered) cylinder
/// from `a` (of `radius`) to `b` (of `radius_b`), world metres; display-encoded colour.
/// Layout shared with the shaders (48 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct SolidInstance {
    pub a: [f32; 3],
    pub radius: f32,
    pub b: [f32; 3],
    /// A cylinder's radius at `b`, metres (a sphere's equals `radius`).
    pub radius_b: f32,
    pub colour: Rgba,
}

/// Everything drawn for one frame besides the static lines, split by pass: opaque solids
/// write depth; the floor's contact shadows (flat cylinders) blend over the floor; translucent
/// solids (alpha < 1) are blended over them, nearest surface only (a depth pre-pass), so a
/// translucent body shows one layer, not its overlapping capsules.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameDrawList {
    pub spheres: Vec<SolidInstance>,
    pub cylinders: Vec<SolidInstance>,
    pub shadows: Vec<SolidInstance>,
    pub translucent_spheres: Vec<SolidInstance>,
    pub translucent_cylinders: Vec<SolidInstance>,
}

impl FrameDrawList {
    fn sphere(&mut self, centre: Vec3, radius: f32, colour: Rgba) {
        if !centre.is_finite() {
            return;
        }
        let instance = SolidInstance { a: centre.to_array(), radius, b: centre.to_array(), radius_b: radius, colour };
        if colour[3] < 1.0 { self.translucent_spheres.push(instance) } else { self.spheres.push(instance) }
    }

    fn cylinder(&mut self, a: Vec3, b: Vec3, radius: f32, colour: Rgba) {
        self.cone(a, b, radius, radius, colour);
    }

    /// A cylinder from `a` (radius `radius_a`) to `b` (radius `radius_b`).
    fn cone(&mut self, a: Vec3, b: Vec3, radius_a: f32, radius_b: f32, colour: Rgba) {
        if !(a.is_finite() && b.is_finite()) || a.distance_squared(b) < 1e-12 {
            return;
        }
        let instance = SolidInstance { a: a.to_array(), radius: radius_a, b: b.to_array(), radius_b, colour };
        if colour[3] < 1.0 { self.translucent_cylinders.push(instance) } else { self.cylinders.push(instance) }
    }

    /// A tapered capsule: the cone from `a` to `b` closed by a sphere at each end.
    fn capsule(&mut self, a: Vec3, b: Vec3, radius_a: f32, radius_b: f32, colour: Rgba) {
        self.cone(a, b, radius_a, radius_b, colour);
        self.sphere(a, radius_a, colour);
        self.sphere(b, radius_b, colour);
    }

    /// Number of instances over all passes.
    pub fn len(&self) -> usize {
        self.spheres.len()
            + self.cylinders.len()
            + self.shadows.len()
            + self.translucent_spheres.len()
            + self.translucent_cylinders.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every instance with its kind, for inspection.
    pub fn all(&self) -> impl Iterator<Item = &SolidInstance> {
        self.spheres
            .iter()
            .chain(&self.cylinders)
            .chain(&self.shadows)
            .chain(&self.translucent_spheres)
            .chain(&self.translucent_cylinders)
    }
}

/// Which optional layers are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayerToggles {
    /// The ego-only reconstruction overlay (when the scene has one).
    pub ego_only: bool,
    /// The ground-truth ghost (when the scene has one).
    pub ground_truth: bool,
    /// Observer rays.
    pub rays: bool,
    /// Bodies of capsules (`false`: stick figures of thin joints and bones).
    pub body: bool,
    /// The observer whose camera the view looks through, if any: its own frustum and rays are
    /// not drawn (they would fill its view); its keypoints are, in front of everything.
    pub through_observer: Option<usize>,
}

impl Default for LayerToggles {
    fn default() -> Self {
        Self { ego_only: false, ground_truth: true, rays: true, body: true, through_observer: None }
    }
}

/// How one skeleton is drawn.
#[derive(Clone, Copy, Debug)]
struct SkeletonStyle {
    /// Scale of the joint/bone radii.
    thickness: f32,
    /// `None` = side colours; `Some` = one colour for the whole skeleton.
    colour: Option<Rgba>,
    dimmed: bool,
}

impl SkeletonStyle {
    /// Joint `joint`'s colour (a bone takes its child's: pelvis → left_hip is a left bone).
    fn joint_colour(&self, joint: usize) -> Rgba {
        let c = self.colour.unwrap_or_else(|| BodySide::of_joint(joint).colour());
        if self.dimmed { colors::dimmed(c) } else { c }
    }
}

/// The bones of the tree `parents` as `(parent, child)` joint indices (the root has none;
/// indices outside the 24 joints are skipped).
fn bones(parents: &[i8]) -> impl Iterator<Item = (usize, usize)> + '_ {
    parents
        .iter()
        .enumerate()
        .take(NUM_JOINTS)
        .filter_map(|(child, &parent)| usize::try_from(parent).ok().filter(|&p| p < NUM_JOINTS).map(|p| (p, child)))
}

/// The joints of frame `frame` in a flat `frames × 24 × 3` array, or `None` when the frame holds
/// no pose at all (all zeros, as producers write for "nothing here").
fn frame_joints(joints: &[f32], frame: usize) -> Option<[Vec3; NUM_JOINTS]> {
    let flat = joints.get(frame * NUM_JOINTS * 3..(frame + 1) * NUM_JOINTS * 3)?;
    if flat.iter().all(|&v| v == 0.0) {
        return None;
    }
    Some(std::array::from_fn(|j| Vec3::new(flat[3 * j], flat[3 * j + 1], flat[3 * j + 2])))
}

pub use egoexo_core::skeleton::{MEAN_SHAPE_BONE_RADII, MEAN_SHAPE_SKULL};

/// The subject's size relative to the SMPL mean shape: the summed length of its 23 bones over
/// the mean shape's, the median over up to 64 frames spread over the session that hold a
/// pose; 1 when none does. Bone lengths are the subject's (rest) shape, whatever the pose.
pub fn subject_scale(joints: &[f32], frames: usize) -> f32 {
    let mean_length = skeleton_length(&MEAN_SHAPE_REST_JOINTS.map(Vec3::from_array));
    let stride = frames.div_ceil(64).max(1);
    let mut ratios: Vec<f32> = (0..frames)
        .step_by(stride)
        .filter_map(|f| frame_joints(joints, f))
        .map(|j| skeleton_length(&j) / mean_length)
        .filter(|r| r.is_finite() && *r > 0.2 && *r < 5.0)
        .collect();
    if ratios.is_empty() {
        return 1.0;
    }
    ratios.sort_by(f32::total_cmp);
    ratios[ratios.len() / 2]
}

fn skeleton_length(joints: &[Vec3; NUM_JOINTS]) -> f32 {
    bones(&PARENTS).map(|(parent, child)| joints[child].distance(joints[parent])).sum()
}

/// A body of tapered capsules per SMPL bone ([`MEAN_SHAPE_BONE_RADII`] × `scale`) and a skull.
fn push_body(list: &mut FrameDrawList, joints: &[Vec3; NUM_JOINTS], parents: &[i8], scale: f32, style: SkeletonStyle) {
    let colour = |joint: usize| style.joint_colour(joint);
    for (parent, child) in bones(parents) {
        let (ra, rb) = MEAN_SHAPE_BONE_RADII[child];
        list.capsule(joints[parent], joints[child], ra * scale, rb * scale, colour(child));
    }
    let head = SmplJoint::Head.index();
    let up = (joints[head] - joints[SmplJoint::Neck.index()]).normalize_or(Vec3::Y);
    let (radius, offset) = MEAN_SHAPE_SKULL;
    list.sphere(joints[head] + up * offset * scale, radius * scale, colour(head));
}

/// Soft contact shadows on the floor at `floor_y` under the feet and the pelvis: concentric
/// dark discs that fade as the joint rises (gone 0.5 m above the floor for a foot, 1.5 m for
/// the pelvis).
fn push_contact_shadows(list: &mut FrameDrawList, joints: &[Vec3; NUM_JOINTS], scale: f32, floor_y: f32) {
    let spots = [(7, 0.09, 0.5), (8, 0.09, 0.5), (10, 0.08, 0.5), (11, 0.08, 0.5), (0, 0.28, 1.5)];
    for (joint, radius, fade_m) in spots {
        let p = joints[joint];
        let height = p.y - floor_y;
        let strength = (1.0 - height / fade_m).clamp(0.0, 1.0);
        if !p.is_finite() || strength <= 0.0 {
            continue;
        }
        let (a, b) = (Vec3::new(p.x, floor_y + 0.002, p.z), Vec3::new(p.x, floor_y + 0.0025, p.z));
        for (size, alpha) in [(1.0, 0.12), (0.7, 0.14), (0.4, 0.16)] {
            let r = radius * scale * size * (0.6 + 0.4 * strength);
            let colour = colors::with_alpha(colors::SHADOW, alpha * strength);
            list.shadows.push(SolidInstance { a: a.to_array(), radius: r, b: b.to_array(), radius_b: r, colour });
        }
    }
}

fn push_skeleton(list: &mut FrameDrawList, joints: &[Vec3; NUM_JOINTS], parents: &[i8], style: SkeletonStyle) {
    let colour = |joint: usize| style.joint_colour(joint);
    for (j, &p) in joints.iter().enumerate() {
        let radius = if j == egoexo_core::skeleton::SmplJoint::Head.index() { HEAD_RADIUS } else { JOINT_RADIUS };
        list.sphere(p, radius * style.thickness, colour(j));
    }
    for (parent, child) in bones(parents) {
        list.cylinder(joints[parent], joints[child], BONE_RADIUS * style.thickness, colour(child));
    }
}

/// `T_world_camera` of observer `o` at `frame` (optical frame: +X right, +Y down, +Z forward),
/// or `None` when the observer is not tracked then or its pose is not a rotation.
pub fn observer_pose(o: &ObserverScene, frame: usize) -> Option<(Quat, Vec3)> {
    if !o.valid.get(frame).copied().unwrap_or(false) {
        return None;
    }
    let v = o.camera_poses.get(7 * frame..7 * frame + 7)?;
    let q = Quat::from_xyzw(v[0], v[1], v[2], v[3]);
    let t = Vec3::new(v[4], v[5], v[6]);
    let norm = q.length();
    if !(q.is_finite() && t.is_finite()) || (norm - 1.0).abs() > 0.01 {
        return None;
    }
    Some((q / norm, t))
}

/// Distance from an observer's camera at which its keypoints are drawn in its own view, metres
/// (in front of the wearer, at the pixels where the keypoints were seen).
pub const KEYPOINT_MARKER_DEPTH: f32 = 0.25;
/// Angular radius of a keypoint marker in its observer's view, radians (a dot of a few pixels
/// however far the wearer stands).
pub const KEYPOINT_MARKER_ANGLE: f32 = 0.012;

fn push_observer(list: &mut FrameDrawList, o: &ObserverScene, index: usize, frame: usize, layers: LayerToggles) {
    let Some((rotation, centre)) = observer_pose(o, frame) else { return };
    if layers.through_observer == Some(index) {
        push_keypoint_markers(list, o, frame, centre);
        return;
    }
    let show_rays = layers.rays;
    let colour = colors::OBSERVERS[index % colors::OBSERVERS.len()];
    let [hx, hy] = o.half_fov.map(|a| a.clamp(0.05, MAX_DRAWN_HALF_FOV).tan() * FRUSTUM_DEPTH);
    let d = FRUSTUM_DEPTH;
    let to_world = |x: f32, y: f32, z: f32| centre + rotation * Vec3::new(x, y, z);
    // Image corners: top-left, top-right, bottom-right, bottom-left (+Y is down in the image).
    let corners = [to_world(-hx, -hy, d), to_world(hx, -hy, d), to_world(hx, hy, d), to_world(-hx, hy, d)];
    const EDGE: f32 = 0.005;
    list.sphere(centre, 0.035, colour);
    for i in 0..4 {
        list.cylinder(centre, corners[i], EDGE, colour);
        list.cylinder(corners[i], corners[(i + 1) % 4], EDGE, colour);
    }
    // The image's "up": a small triangle over the top edge.
    let apex = to_world(0.0, -1.6 * hy, d);
    let (left, right) = (to_world(-0.5 * hx, -hy, d), to_world(0.5 * hx, -hy, d));
    list.cylinder(left, apex, EDGE, colour);
    list.cylinder(apex, right, EDGE, colour);
    if !show_rays {
        return;
    }
    for k in 0..EXO_KEYPOINT_COUNT {
        let Some((end, gate)) = o.ray(frame, k) else { continue };
        let end = Vec3::from_array(end);
        let c = colors::gate_colour(gate);
        list.cylinder(centre, end, RAY_RADIUS, c);
        let radius = if ExoKeypoint::ALL[k] == ExoKeypoint::Nose { 0.02 } else { 0.016 };
        list.sphere(end, radius, c);
    }
}

/// What the viewer derives once per scene to draw any of its frames: the bodies' sizes, the
/// floor's extent and whether the wearer walks about.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneGeometry {
    /// [`subject_scale`] of the reconstruction (and of the ego-only overlay).
    pub body_scale: f32,
    /// [`subject_scale`] of the ground truth.
    pub ground_truth_scale: f32,
    /// [`subject_scale`] of each of the capture's other participants (`scene.others`).
    pub others_scale: Vec<f32>,
    /// Centre of the floor disc (world, at `floor_y`) and its radius, metres.
    pub floor_centre: Vec3,
    pub floor_radius: f32,
    /// The wearer's pelvis covers more than [`MOVING_WEARER_M`] horizontally over the session:
    /// the view follows it by default.
    pub moving_wearer: bool,
}

/// One entry of the page's participant legend ([`participant_legend`]).
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct LegendEntry {
    pub id: String,
    /// CSS colour of their body (the shown participant: their palette colour, for the legend).
    pub colour: String,
    /// Whether this is the participant shown (side colours, the facts and plots are theirs).
    pub shown: bool,
}

/// A capture's participants as the viewer draws them: the shown one first, then the others;
/// empty for a scene of one wearer.
pub fn participant_legend(scene: &SceneData) -> Vec<LegendEntry> {
    let Some(shown) = &scene.participant else { return Vec::new() };
    let entry = |p: &egoexo_scene::SceneParticipant, shown: bool| LegendEntry {
        id: p.id.clone(),
        colour: colors::css(colors::participant_colour(p.colour)),
        shown,
    };
    std::iter::once(entry(shown, true)).chain(scene.others.iter().map(|o| entry(&o.participant, false))).collect()
}

/// Horizontal extent (the diagonal of the box the pelvis covers) beyond which a wearer counts
/// as moving about, metres.
pub const MOVING_WEARER_M: f32 = 1.5;

impl SceneGeometry {
    pub fn of(scene: &SceneData) -> Self {
        let (floor_centre, floor_radius) = match scene_bounds(scene) {
            Some(b) => {
                let half = 0.5 * (b.max - b.min);
                let c = b.centre();
                (Vec3::new(c.x, scene.floor_y, c.z), (half.x.max(half.z) + 1.0).max(3.0))
            }
            None => (Vec3::new(0.0, scene.floor_y, 0.0), 3.0),
        };
        let stride = scene.frames.div_ceil(2000).max(1);
        let pelvis = (0..scene.frames).step_by(stride).filter_map(|f| frame_joints(&scene.joints, f)).map(|j| j[0]);
        let moving_wearer = Bounds::around(pelvis).is_some_and(|b| {
            let extent = b.max - b.min;
            extent.x.hypot(extent.z) > MOVING_WEARER_M
        });
        Self {
            body_scale: subject_scale(&scene.joints, scene.frames),
            ground_truth_scale: scene.ground_truth_joints.as_deref().map_or(1.0, |j| subject_scale(j, scene.frames)),
            others_scale: scene.others.iter().map(|o| subject_scale(&o.joints, scene.frames)).collect(),
            floor_centre,
            floor_radius,
            moving_wearer,
        }
    }
}

/// The point a following view keeps centred at `frame`: the reconstruction's pelvis, else the
/// head device; `None` when neither is known then.
pub fn follow_anchor(scene: &SceneData, frame: usize) -> Option<Vec3> {
    let frame = frame.min(scene.frames.checked_sub(1)?);
    if let Some(joints) = frame_joints(&scene.joints, frame)
        && joints[0].is_finite()
    {
        return Some(joints[0]);
    }
    let head = scene.devices.iter().find(|d| d.name == "head")?;
    if !head.valid.get(frame).copied().unwrap_or(false) {
        return None;
    }
    let p = head.positions.get(3 * frame..3 * frame + 3)?;
    Some(Vec3::new(p[0], p[1], p[2])).filter(|p| p.is_finite())
}

/// The keypoints of observer `o` at `frame` seen from its own camera at `centre`: a sphere on
/// each ray [`KEYPOINT_MARKER_DEPTH`] from the camera (so it covers the keypoint's pixel
/// whatever stands behind it), [`KEYPOINT_MARKER_ANGLE`] across, gate-coloured.
fn push_keypoint_markers(list: &mut FrameDrawList, o: &ObserverScene, frame: usize, centre: Vec3) {
    for k in 0..EXO_KEYPOINT_COUNT {
        let Some((end, gate)) = o.ray(frame, k) else { continue };
        let end = Vec3::from_array(end);
        let distance = end.distance(centre);
        if !(distance.is_finite() && distance > KEYPOINT_MARKER_DEPTH) {
            continue;
        }
        let marker = centre + (end - centre) * (KEYPOINT_MARKER_DEPTH / distance);
        list.sphere(marker, KEYPOINT_MARKER_DEPTH * KEYPOINT_MARKER_ANGLE, colors::gate_colour(gate));
    }
}

/// The instances of frame `frame` (clamped to the scene): the floor and the wearer's contact
/// shadows, the reconstruction (a body of capsules or a stick figure; dimmed where the frame
/// was not reconstructed), the optional ego-only overlay and ground-truth ghost, device
/// positions with a trail of [`TRAIL_S`], and each tracked observer's frustum and rays.
/// `geometry` is [`SceneGeometry::of`] this scene.
pub fn build_frame(scene: &SceneData, geometry: &SceneGeometry, frame: usize, layers: LayerToggles) -> FrameDrawList {
    let mut list = FrameDrawList::default();
    if scene.frames == 0 {
        return list;
    }
    let frame = frame.min(scene.frames - 1);
    let valid = scene.valid.get(frame).copied().unwrap_or(false);
    // The floor: an opaque disc just under the grid lines.
    let floor = geometry.floor_centre;
    list.cylinder(floor - Vec3::Y * 0.004, floor - Vec3::Y * 0.003, geometry.floor_radius, colors::FLOOR);
    let draw = |list: &mut FrameDrawList, joints: &[Vec3; NUM_JOINTS], scale: f32, style: SkeletonStyle| {
        if layers.body {
            push_body(list, joints, &scene.parents, scale, style);
        } else {
            push_skeleton(list, joints, &scene.parents, style);
        }
    };
    if let Some(joints) = frame_joints(&scene.joints, frame) {
        let style = SkeletonStyle { thickness: 1.0, colour: None, dimmed: !valid };
        draw(&mut list, &joints, geometry.body_scale, style);
        push_contact_shadows(&mut list, &joints, geometry.body_scale, scene.floor_y);
    }
    // The capture's other participants: one colour each, the same body scale as theirs.
    for (o, other) in scene.others.iter().enumerate() {
        if let Some(joints) = frame_joints(&other.joints, frame) {
            let valid = other.valid.get(frame).copied().unwrap_or(false);
            let colour = colors::participant_colour(other.participant.colour);
            let style = SkeletonStyle { thickness: 1.0, colour: Some(colour), dimmed: !valid };
            let scale = geometry.others_scale.get(o).copied().unwrap_or(1.0);
            draw(&mut list, &joints, scale, style);
            push_contact_shadows(&mut list, &joints, scale, scene.floor_y);
        }
    }
    if layers.ego_only
        && let Some(joints) = scene.ego_only_joints.as_deref().and_then(|j| frame_joints(j, frame))
    {
        let style = SkeletonStyle { thickness: 0.8, colour: Some(colors::EGO_ONLY), dimmed: !valid };
        draw(&mut list, &joints, geometry.body_scale, style);
    }
    if layers.ground_truth
        && let Some(joints) = scene.ground_truth_joints.as_deref().and_then(|j| frame_joints(j, frame))
    {
        let style = SkeletonStyle { thickness: 1.25, colour: Some(colors::GROUND_TRUTH), dimmed: false };
        draw(&mut list, &joints, geometry.ground_truth_scale, style);
    }

    let fps = scene.fps.max(1e-3);
    let back = (TRAIL_S.0 * fps).ceil() as usize;
    let ahead = (TRAIL_S.1 * fps).ceil() as usize;
    for device in &scene.devices {
        let colour = colors::device_colour(&device.name);
        let at = |f: usize| -> Option<Vec3> {
            if !device.valid.get(f).copied().unwrap_or(false) {
                return None;
            }
            let p = device.positions.get(3 * f..3 * f + 3)?;
            Some(Vec3::new(p[0], p[1], p[2])).filter(|p| p.is_finite())
        };
        if let Some(p) = at(frame) {
            list.sphere(p, if device.name == "head" { 0.03 } else { 0.022 }, colour);
        }
        let first = frame.saturating_sub(back);
        let last = frame.saturating_add(ahead).min(scene.frames - 1);
        for f in first..last {
            if let (Some(a), Some(b)) = (at(f), at(f + 1)) {
                let c = if f < frame { colour } else { colors::with_alpha(colour, 0.35) };
                list.cylinder(a, b, 0.006, c);
            }
        }
    }

    for (index, observer) in scene.observers.iter().enumerate() {
        push_observer(&mut list, observer, index, frame, layers);
    }
    list
}

/// The box around everything the session shows: every reconstructed joint (sampled to at most
/// ~2000 frames), every tracked observer position, and the floor under them. Sizes the grid.
pub fn scene_bounds(scene: &SceneData) -> Option<Bounds> {
    let stride = scene.frames.div_ceil(2000).max(1);
    let frames = (0..scene.frames).step_by(stride);
    let joints = frames.clone().filter_map(|f| frame_joints(&scene.joints, f)).flatten();
    let others = scene.others.iter().flat_map(|o| frames.clone().filter_map(|f| frame_joints(&o.joints, f)).flatten());
    let observers =
        scene.observers.iter().flat_map(|o| frames.clone().filter_map(move |f| observer_pose(o, f).map(|(_, t)| t)));
    with_floor(Bounds::around(joints.chain(others).chain(observers))?, scene.floor_y)
}

/// The box the default view frames at `frame`: the wearer over the whole session (sampled to
/// at most ~2000 frames), the observers tracked at `frame` (moving observers' whole paths would
/// shrink the wearer to a speck), and the floor under them.
pub fn view_bounds(scene: &SceneData, frame: usize) -> Option<Bounds> {
    let stride = scene.frames.div_ceil(2000).max(1);
    let joints = (0..scene.frames).step_by(stride).filter_map(|f| frame_joints(&scene.joints, f)).flatten();
    let others = scene.others.iter().filter_map(|o| frame_joints(&o.joints, frame)).flatten();
    let observers = scene.observers.iter().filter_map(|o| observer_pose(o, frame).map(|(_, t)| t));
    with_floor(Bounds::around(joints.chain(others).chain(observers))?, scene.floor_y)
}

/// The box a following view frames at `frame`: the wearer's body now with room to move
/// ([`FOLLOW_MARGIN_M`] around it), the observers tracked now, and the floor under them.
pub fn follow_bounds(scene: &SceneData, frame: usize) -> Option<Bounds> {
    let frame = frame.min(scene.frames.checked_sub(1)?);
    let anchor = follow_anchor(scene, frame)?;
    let body = frame_joints(&scene.joints, frame).map(|j| j.to_vec()).unwrap_or_else(|| vec![anchor]);
    let margin = Vec3::new(FOLLOW_MARGIN_M, 0.0, FOLLOW_MARGIN_M);
    let around = Bounds::around(body)?;
    let observers = scene.observers.iter().filter_map(|o| observer_pose(o, frame).map(|(_, t)| t));
    let corners = [around.min - margin, around.max + margin];
    with_floor(Bounds::around(corners.into_iter().chain(observers))?, scene.floor_y)
}

/// Room left around the wearer by a following view, metres.
pub const FOLLOW_MARGIN_M: f32 = 0.75;

fn with_floor(bounds: Bounds, floor_y: f32) -> Option<Bounds> {
    let floor = Vec3::new(bounds.min.x, floor_y, bounds.min.z);
    Bounds::around([bounds.min, bounds.max, floor])
}

/// Lines drawn under everything for the whole session: the floor grid at `floor_y` around the
/// scene (1 m beyond everything it shows), and the head device's full path (faint; broken where
/// tracking is invalid). Wrists get trails only: their whole paths tangle around the body.
pub fn static_lines(scene: &SceneData) -> Vec<LineVertex> {
    let (centre, half) = match scene_bounds(scene) {
        Some(b) => {
            let half_size = 0.5 * (b.max - b.min);
            (b.centre(), (half_size.x.max(half_size.z) + 1.0).max(3.0))
        }
        None => (Vec3::ZERO, 3.0),
    };
    let mut lines = mesh::floor_grid(centre.x, centre.z, scene.floor_y, half, 0.5);
    // Long sessions: at most ~20000 segments.
    let stride = scene.frames.div_ceil(20_000).max(1);
    for device in scene.devices.iter().filter(|d| d.name == "head") {
        let colour = colors::with_alpha(colors::device_colour(&device.name), 0.35);
        let at = |f: usize| -> Option<[f32; 3]> {
            if !device.valid.get(f).copied().unwrap_or(false) {
                return None;
            }
            let p = device.positions.get(3 * f..3 * f + 3)?;
            p.iter().all(|v| v.is_finite()).then(|| [p[0], p[1], p[2]])
        };
        let samples: Vec<usize> = (0..scene.frames).step_by(stride).collect();
        for pair in samples.windows(2) {
            if let (Some(a), Some(b)) = (at(pair[0]), at(pair[1])) {
                lines.push(LineVertex { position: a, colour });
                lines.push(LineVertex { position: b, colour });
            }
        }
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::example::example_scene;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    const ALL_LAYERS: LayerToggles =
        LayerToggles { ego_only: true, ground_truth: true, rays: true, body: false, through_observer: None };
    const STICK_ONLY: LayerToggles =
        LayerToggles { ego_only: false, ground_truth: false, rays: false, body: false, through_observer: None };

    fn build_frame(scene: &SceneData, frame: usize, layers: LayerToggles) -> FrameDrawList {
        super::build_frame(scene, &SceneGeometry::of(scene), frame, layers)
    }

    #[test]
    fn the_example_scene_is_valid_and_survives_json() {
        let scene = example_scene(30);
        validate_scene(&scene).unwrap();
        let json = serde_json::to_vec(&scene).unwrap();
        assert_eq!(parse_scene(&json).unwrap(), scene);
    }

    #[test]
    fn bad_scenes_get_messages_naming_the_field() {
        let err = |bytes: &[u8]| parse_scene(bytes).unwrap_err().to_string();
        assert!(err(b"{").contains("scene JSON is not a SceneData"), "{}", err(b"{"));
        assert!(err(b"{\"format_version\": 1}").contains("missing field"));
        let mut scene = example_scene(4);
        scene.joints.truncate(10);
        scene.fps = 0.0;
        scene.parents[3] = 7;
        let msg = err(&serde_json::to_vec(&scene).unwrap());
        assert!(msg.contains("joints has 10 values, expected 288"), "{msg}");
        assert!(msg.contains("fps is 0"), "{msg}");
        assert!(msg.contains("parents[3] = 7"), "{msg}");
        let mut fast = example_scene(2);
        fast.fps = 1e30;
        assert!(validate_scene(&fast).unwrap_err().to_string().contains("fps is 1000000000000000000000000000000"));
        // Drawing never overflows, even for scenes that skip validation.
        assert!(!build_frame(&fast, 1, ALL_LAYERS).is_empty());
        let mut huge = example_scene(1);
        huge.frames = usize::MAX;
        assert!(matches!(validate_scene(&huge), Err(SceneError::TooManyFrames(_))));
        let mut fov = example_scene(2);
        fov.observers[0].half_fov = [f32::NAN, 0.5];
        assert!(validate_scene(&fov).unwrap_err().to_string().contains("half_fov"));
    }

    #[test]
    fn a_valid_frame_draws_a_side_coloured_opaque_skeleton() {
        let scene = example_scene(10);
        let list = build_frame(&scene, 3, STICK_ONLY);
        let count = |c: Rgba| list.spheres.iter().filter(|s| s.colour == c).count();
        // 24 joints: 9 left, 9 right, 6 centre.
        assert_eq!((count(colors::LEFT), count(colors::RIGHT), count(colors::CENTRE)), (9, 9, 6));
        let bones = |c: Rgba| list.cylinders.iter().filter(|s| s.colour == c).count();
        assert_eq!(bones(colors::LEFT) + bones(colors::RIGHT) + bones(colors::CENTRE), 23);
        assert_eq!(bones(colors::LEFT), 9);
        // The left wrist's sphere sits on the left wrist joint.
        let left_wrist = Vec3::from_slice(&scene.joints[(3 * 24 + 20) * 3..]);
        assert!(list.spheres.iter().any(|s| Vec3::from(s.a) == left_wrist && s.colour == colors::LEFT));
        assert!(list.all().all(|s| s.a.iter().chain(&s.b).all(|v| v.is_finite())));
    }

    #[test]
    fn other_participants_are_drawn_in_their_colour_beside_the_wearer() {
        let mut scene = example_scene(10);
        scene.participant = Some(egoexo_scene::SceneParticipant { id: "alice".into(), colour: 0 });
        let mut bob = example_scene(10);
        bob.participant = Some(egoexo_scene::SceneParticipant { id: "bob".into(), colour: 1 });
        bob.joints.chunks_mut(3).for_each(|p| p[0] += 2.0); // two metres to the side
        bob.valid[4] = false;
        let scene = scene.with_others([&bob]);
        validate_scene(&scene).unwrap();
        let bob_colour = colors::participant_colour(1);
        let list = build_frame(&scene, 3, STICK_ONLY);
        let bob_joints: Vec<_> = list.spheres.iter().filter(|s| s.colour == bob_colour).collect();
        assert_eq!(bob_joints.len(), 24);
        let wrist = Vec3::from_slice(&scene.others[0].joints[(3 * 24 + 20) * 3..]);
        assert!(bob_joints.iter().any(|s| Vec3::from(s.a) == wrist));
        assert_eq!(list.spheres.iter().filter(|s| s.colour == colors::LEFT).count(), 9, "the wearer as before");
        // Not reconstructed at that frame: dimmed, like the wearer's invalid frames.
        let list = build_frame(&scene, 4, STICK_ONLY);
        assert!(!list.spheres.iter().any(|s| s.colour == bob_colour));
        assert!(list.translucent_spheres.iter().any(|s| s.colour == colors::dimmed(bob_colour)));
        // The view frames both of them.
        let bounds = scene_bounds(&scene).unwrap();
        assert!(bounds.max.x >= wrist.x);
        let legend = participant_legend(&scene);
        assert_eq!(
            legend.iter().map(|e| (e.id.as_str(), e.shown)).collect::<Vec<_>>(),
            [("alice", true), ("bob", false)]
        );
        assert_eq!(legend[1].colour, colors::css(bob_colour));
        assert!(participant_legend(&example_scene(2)).is_empty());
    }

    #[test]
    fn invalid_frames_are_dimmed_and_empty_frames_hidden() {
        let mut scene = example_scene(10);
        scene.valid[5] = false;
        let layers = STICK_ONLY;
        let list = build_frame(&scene, 5, layers);
        let skeleton: Vec<_> = list.translucent_spheres.iter().filter(|s| s.radius >= JOINT_RADIUS).collect();
        assert_eq!(skeleton.len(), 24);
        assert!(skeleton.iter().all(|s| s.colour[3] < 0.5));
        assert!(!list.spheres.iter().any(|s| s.colour == colors::LEFT));
        // All-zero joints mean "no pose": nothing is drawn for the skeleton.
        scene.joints[5 * 72..6 * 72].fill(0.0);
        let list = build_frame(&scene, 5, layers);
        assert!(!list.all().any(|s| s.radius == JOINT_RADIUS || s.radius == BONE_RADIUS));
        // A non-finite joint hides that joint and its bones only.
        let mut scene = example_scene(3);
        scene.joints[(24 + 20) * 3] = f32::NAN; // frame 1, left wrist
        let list = build_frame(&scene, 1, layers);
        assert_eq!(list.spheres.iter().filter(|s| s.radius == JOINT_RADIUS || s.radius == HEAD_RADIUS).count(), 23);
        assert_eq!(list.cylinders.iter().filter(|s| s.radius == BONE_RADIUS).count(), 21);
    }

    #[test]
    fn layers_toggle_the_overlay_ghost_and_rays() {
        let scene = example_scene(6);
        let none = build_frame(&scene, 2, STICK_ONLY);
        let all = build_frame(&scene, 2, ALL_LAYERS);
        let with = |c: Rgba| all.all().filter(|s| s.colour == c).count();
        assert_eq!(with(colors::EGO_ONLY), 24 + 23);
        assert_eq!(with(colors::GROUND_TRUTH), 24 + 23);
        assert!(none.all().all(|s| s.colour != colors::EGO_ONLY && s.colour != colors::GROUND_TRUTH));
        // Rays: one cylinder + endpoint per keypoint with a ray, gate-coloured.
        let gates: Vec<f32> = (0..13).map(|k| scene.observers[0].rays[4 * (2 * 13 + k) + 3]).collect();
        for g in gates {
            assert!(all.all().any(|s| s.colour == colors::gate_colour(g)), "gate {g}");
        }
        assert_eq!(all.len() - none.len(), 2 * (24 + 23) + 2 * 13);
        // The ghost and overlay are translucent.
        assert!(all.spheres.iter().all(|s| s.colour[3] == 1.0));
    }

    #[test]
    fn rays_start_at_the_observer_and_end_at_their_endpoints() {
        let scene = example_scene(4);
        let list = build_frame(&scene, 1, ALL_LAYERS);
        let (_, centre) = observer_pose(&scene.observers[0], 1).unwrap();
        let ray = &scene.observers[0].rays[4 * 13..4 * 13 + 4];
        assert!(list.cylinders.iter().any(|c| Vec3::from(c.a) == centre
            && Vec3::from(c.b) == Vec3::new(ray[0], ray[1], ray[2])
            && c.colour == colors::gate_colour(ray[3])));
    }

    #[test]
    fn untracked_observers_and_missing_rays_are_not_drawn() {
        let mut scene = example_scene(4);
        let baseline = build_frame(&scene, 1, ALL_LAYERS).len();
        // A keypoint without a ray (zero endpoint, gate 0) draws nothing.
        scene.observers[0].rays[4 * 13..4 * 13 + 4].fill(0.0);
        assert_eq!(build_frame(&scene, 1, ALL_LAYERS).len(), baseline - 2);
        scene.observers[0].valid[1] = false;
        let list = build_frame(&scene, 1, ALL_LAYERS);
        assert!(list.all().all(|s| !colors::OBSERVERS.contains(&s.colour)));
        // A pose that is not a rotation is skipped rather than drawn distorted.
        let mut scene = example_scene(4);
        scene.observers[0].camera_poses[7..11].copy_from_slice(&[0.0, 0.0, 0.0, 3.0]);
        assert!(observer_pose(&scene.observers[0], 1).is_none());
    }

    #[test]
    fn the_frustum_opens_along_the_camera_z_axis() {
        let scene = example_scene(2);
        let (q, c) = observer_pose(&scene.observers[0], 0).unwrap();
        let forward = q * Vec3::Z;
        let list = build_frame(&scene, 0, LayerToggles { rays: false, ..ALL_LAYERS });
        let edges: Vec<_> = list.cylinders.iter().filter(|s| s.colour == colors::OBSERVERS[0]).collect();
        assert_eq!(edges.len(), 10);
        for e in edges.iter().filter(|e| Vec3::from(e.a) == c) {
            let depth = (Vec3::from(e.b) - c).dot(forward);
            assert!((depth - FRUSTUM_DEPTH).abs() < 1e-4, "{depth}");
        }
    }

    #[test]
    fn device_trails_follow_the_current_frame() {
        let scene = example_scene(200);
        let list = build_frame(&scene, 100, LayerToggles { body: false, ..LayerToggles::default() });
        let head = colors::HEAD_DEVICE;
        let past = list.cylinders.iter().filter(|s| s.colour == head).count();
        let future = list.translucent_cylinders.iter().filter(|s| s.colour == colors::with_alpha(head, 0.35)).count();
        let fps = scene.fps;
        assert_eq!(past, (TRAIL_S.0 * fps) as usize);
        assert_eq!(future, (TRAIL_S.1 * fps) as usize);
        // Invalid samples break the trail.
        let mut broken = scene.clone();
        broken.devices[0].valid[95] = false;
        let list = build_frame(&broken, 100, LayerToggles { body: false, ..LayerToggles::default() });
        assert_eq!(list.cylinders.iter().filter(|s| s.colour == head).count(), past - 2);
    }

    #[test]
    fn the_view_frames_the_wearer_and_the_observers_where_they_are_now() {
        let mut scene = example_scene(20);
        // The observer walks 10 m away along +X over the session.
        for f in 0..20 {
            scene.observers[0].camera_poses[7 * f + 4] += f as f32 * 0.5;
        }
        let now = view_bounds(&scene, 0).unwrap();
        let all = scene_bounds(&scene).unwrap();
        assert!(all.max.x > 9.0, "the grid covers the observer's whole walk");
        assert!(now.max.x < 1.0, "the view frames where the observer is at frame 0: {now:?}");
        let later = view_bounds(&scene, 19).unwrap();
        assert!(later.max.x > 9.0);
        // The wearer's whole session is always in view.
        let wearer = crate::example::example_joints(19);
        assert!(wearer.iter().all(|p| p.cmpge(now.min).all() && p.cmple(now.max).all()));
        assert!(now.min.y <= scene.floor_y);
    }

    #[test]
    fn static_lines_lie_on_the_floor_and_trace_devices() {
        let scene = example_scene(50);
        let lines = static_lines(&scene);
        let floor = lines.iter().filter(|v| v.position[1] == scene.floor_y).count();
        assert!(floor > 40);
        // The head's whole path: one segment per pair of frames.
        assert_eq!(lines.len() - floor, 2 * 49);
        assert!(
            lines.iter().filter(|v| v.position[1] != scene.floor_y).all(|v| v.colour[..3] == colors::HEAD_DEVICE[..3])
        );
        let bounds = scene_bounds(&scene).unwrap();
        assert!(bounds.min.y <= scene.floor_y && bounds.max.y > 1.5);
        let empty = SceneData::new("e", 30.0, 0, "ego-exo");
        assert!(build_frame(&empty, 0, ALL_LAYERS).is_empty());
        assert!(scene_bounds(&empty).is_none());
        assert!(view_bounds(&empty, 0).is_none());
        assert!(!static_lines(&empty).is_empty());
    }

    #[test]
    fn the_body_is_capsules_sized_from_the_subjects_bones() {
        let scene = example_scene(10);
        let geometry = SceneGeometry::of(&scene);
        // The example wearer is the mean shape itself.
        assert!((geometry.body_scale - 1.0).abs() < 1e-4, "{}", geometry.body_scale);
        let layers = LayerToggles { body: true, ..STICK_ONLY };
        let list = super::build_frame(&scene, &geometry, 3, layers);
        // 23 tapered cones, a sphere at each end, and the skull (besides the floor disc and
        // the devices' balls and trails).
        let body = [colors::LEFT, colors::RIGHT, colors::CENTRE];
        let cones: Vec<_> = list.cylinders.iter().filter(|c| body.contains(&c.colour) && c.radius > 0.02).collect();
        assert_eq!(cones.len(), 23);
        assert_eq!(list.spheres.iter().filter(|c| body.contains(&c.colour) && c.radius > 0.02).count(), 2 * 23 + 1);
        let knee = Vec3::from_slice(&scene.joints[(3 * 24 + 4) * 3..]);
        let thigh = cones.iter().find(|c| Vec3::from(c.b) == knee).expect("the left thigh");
        assert!((thigh.radius - MEAN_SHAPE_BONE_RADII[4].0).abs() < 1e-4);
        assert!((thigh.radius_b - MEAN_SHAPE_BONE_RADII[4].1).abs() < 1e-4);
        assert_eq!(thigh.colour, colors::LEFT);
        // The skull's top is about the mean shape's stature above its soles.
        let body_spheres = || list.spheres.iter().filter(|c| body.contains(&c.colour) && c.radius > 0.02);
        let top = body_spheres().map(|s| s.a[1] + s.radius).fold(f32::MIN, f32::max);
        let soles = body_spheres().map(|s| s.a[1] - s.radius).fold(f32::MAX, f32::min);
        assert!((top - soles - 1.70).abs() < 0.06, "{top} - {soles}");
        // The floor sits under the feet: the lowest sole touches it.
        assert!((soles - scene.floor_y).abs() < 0.01, "soles {soles}, floor {}", scene.floor_y);

        // A subject 10 % larger in every bone gets 10 % thicker capsules.
        let mut big = scene.clone();
        big.joints.iter_mut().for_each(|v| *v *= 1.1);
        let big_geometry = SceneGeometry::of(&big);
        assert!((big_geometry.body_scale - 1.1).abs() < 1e-3, "{}", big_geometry.body_scale);
        let big_list = super::build_frame(&big, &big_geometry, 3, layers);
        let big_knee = Vec3::from_slice(&big.joints[(3 * 24 + 4) * 3..]);
        let big_thigh = big_list.cylinders.iter().find(|c| Vec3::from(c.b) == big_knee).unwrap();
        assert!((big_thigh.radius - 1.1 * thigh.radius).abs() < 1e-4);
        // No pose anywhere: the mean shape's size.
        assert_eq!(subject_scale(&[0.0; 72], 1), 1.0);
    }

    #[test]
    fn the_ghost_and_overlay_are_translucent_bodies_and_shadows_fade_with_height() {
        let scene = example_scene(10);
        let geometry = SceneGeometry::of(&scene);
        let layers =
            LayerToggles { ego_only: true, ground_truth: true, rays: false, body: true, through_observer: None };
        let list = super::build_frame(&scene, &geometry, 2, layers);
        let count = |c: Rgba| list.all().filter(|s| s.colour == c).count();
        assert_eq!(count(colors::EGO_ONLY), 3 * 23 + 1);
        assert_eq!(count(colors::GROUND_TRUTH), 3 * 23 + 1);
        assert!(list.translucent_spheres.iter().all(|s| s.colour[3] < 1.0));
        // Standing on the floor: shadows under both feet and the pelvis.
        assert_eq!(list.shadows.len(), 5 * 3);
        assert!(list.shadows.iter().all(|s| (s.a[1] - scene.floor_y) < 0.01 && s.colour[3] > 0.0));
        // Lifted 0.3 m: fainter; lifted 2 m: none.
        let shadow_alpha = |lift: f32| {
            let mut lifted = scene.clone();
            lifted.joints.chunks_mut(3).for_each(|p| p[1] += lift);
            super::build_frame(&lifted, &geometry, 2, layers).shadows.iter().map(|s| s.colour[3]).sum::<f32>()
        };
        let (ground, low, high) = (shadow_alpha(0.0), shadow_alpha(0.3), shadow_alpha(2.0));
        assert!(ground > low && low > 0.0 && high == 0.0, "{ground} {low} {high}");
    }

    #[test]
    fn the_view_follows_a_walking_wearer() {
        let standing = example_scene(30);
        assert!(!SceneGeometry::of(&standing).moving_wearer, "20 cm of drift is not walking about");
        let walking = example_scene(300); // 2 m along +Z over 10 s
        assert!(SceneGeometry::of(&walking).moving_wearer);
        let anchor = follow_anchor(&walking, 150).unwrap();
        assert_eq!(anchor, crate::example::example_joints(150)[0]);
        // Without a pose the head device anchors; past the end, the last frame.
        let mut no_pose = walking.clone();
        no_pose.joints[150 * 72..151 * 72].fill(0.0);
        let head = &no_pose.devices[0].positions[3 * 150..3 * 151];
        assert_eq!(follow_anchor(&no_pose, 150).unwrap(), Vec3::from_slice(head));
        assert_eq!(follow_anchor(&walking, 10_000), follow_anchor(&walking, 299));
        assert!(follow_anchor(&SceneData::new("e", 30.0, 0, "ego-exo"), 0).is_none());
    }

    #[test]
    fn through_an_observer_its_keypoints_are_drawn_in_front_and_its_frustum_not() {
        let scene = example_scene(4);
        let through = LayerToggles { through_observer: Some(0), ..ALL_LAYERS };
        let list = build_frame(&scene, 1, through);
        assert!(list.all().all(|s| s.colour != colors::OBSERVERS[0]), "no frustum");
        let (q, centre) = observer_pose(&scene.observers[0], 1).unwrap();
        let markers: Vec<_> = list.spheres.iter().filter(|s| Vec3::from(s.a).distance(centre) < 0.3).collect();
        assert_eq!(markers.len(), 13);
        let view = crate::camera::ViewPoint::through_camera(q, centre, 0.75, 640.0 / 480.0);
        // The observer looks at the wearer: the pelvis is near the middle of its view.
        let pelvis = view.project(crate::example::example_joints(1)[0], 640.0, 480.0).unwrap();
        assert!((pelvis - glam::Vec2::new(320.0, 240.0)).length() < 120.0, "{pelvis}");
        for (k, marker) in markers.iter().enumerate() {
            let ray = &scene.observers[0].rays[4 * (13 + k)..4 * (13 + k) + 4];
            assert_eq!(marker.colour, colors::gate_colour(ray[3]));
            // Each marker covers the pixel where its keypoint projects.
            let at = view.project(Vec3::from(marker.a), 640.0, 480.0).unwrap();
            let keypoint = view.project(Vec3::new(ray[0], ray[1], ray[2]), 640.0, 480.0).unwrap();
            assert!(at.distance(keypoint) < 0.01, "{at} vs {keypoint}");
        }
        // No cylinder starts at the camera (its rays would fill its own view).
        assert!(list.all().all(|s| Vec3::from(s.a) != centre));
    }
}
