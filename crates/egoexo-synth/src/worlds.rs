//! Observers in worlds of their own: what two Aria glasses through MPS one by one, a Quest
//! and a phone in their own XR spaces, or devices without a shared clock look like. A
//! simulated session's observers share the wearer's world; [`perturb_observer_worlds`] moves
//! each into a random world of its own (a yaw, a horizontal translation, a floor offset, and
//! maybe a clock offset) and returns the truth, for registration's tests and evaluation.

use egoexo_core::ego_features::heading_yaw;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_session::capture::{Capture, ViewPeople};
use egoexo_session::model::{Session, Trajectory};
use egoexo_session::placement::{ClockRef, Placement, WorldRef};
use serde::{Deserialize, Serialize};

use crate::rng::SimRng;

/// How far worlds are moved.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorldPerturbation {
    /// Yaw uniform in ±this, degrees.
    pub max_yaw_deg: f32,
    /// Horizontal translation uniform in a disc of this radius, metres.
    pub max_translation_m: f32,
    /// Vertical offset uniform in ±this, metres (`local-floor` spaces that disagree on the floor).
    pub max_floor_offset_m: f32,
    /// Clock offset uniform in ±this, seconds (0: the clocks stay shared).
    pub max_clock_offset_s: f32,
}

impl Default for WorldPerturbation {
    /// Any yaw, up to 10 m away, ±0.3 m of floor, clocks shared.
    fn default() -> Self {
        Self { max_yaw_deg: 180.0, max_translation_m: 10.0, max_floor_offset_m: 0.3, max_clock_offset_s: 0.0 }
    }
}

/// The truth of one moved world.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorldTruth {
    /// The observer (participant) moved.
    pub id: String,
    /// `T_session_observerworld`: maps its new world back into the session's.
    pub t_session_world: RigidTransform,
    /// `t_session = t_observer + clock_offset_s`.
    pub clock_offset_s: f64,
}

impl WorldTruth {
    /// The yaw of `t_session_world`, degrees (a positive yaw turns +X towards −Z; for a
    /// rotation with tilt, its heading: `egoexo_core::ego_features::heading_yaw`).
    pub fn yaw_deg(&self) -> f64 {
        f64::from(heading_yaw(self.t_session_world.rotation).to_degrees())
    }
}

fn draw(rng: &mut SimRng, p: &WorldPerturbation) -> (RigidTransform, f64) {
    let yaw = rng.uniform(-p.max_yaw_deg, p.max_yaw_deg).to_radians();
    let radius = p.max_translation_m * rng.uniform(0.0, 1.0).sqrt();
    let angle = rng.uniform(0.0, std::f32::consts::TAU);
    let up = if p.max_floor_offset_m > 0.0 { rng.uniform(-p.max_floor_offset_m, p.max_floor_offset_m) } else { 0.0 };
    let clock = if p.max_clock_offset_s > 0.0 { rng.uniform(-p.max_clock_offset_s, p.max_clock_offset_s) } else { 0.0 };
    let t = RigidTransform {
        rotation: Quat::from_rotation_y(yaw),
        translation: Vec3::new(radius * angle.cos(), up, radius * angle.sin()),
    };
    (t, f64::from(clock))
}

/// Moves `trajectory` from the session's world and clock into the world `t_session_world`
/// maps from, on a clock `offset_ns` behind.
fn move_out(trajectory: &mut Trajectory, t_session_world: &RigidTransform, offset_ns: i64) {
    let t_world_session = t_session_world.inverse();
    for pose in &mut trajectory.poses {
        *pose = t_world_session * *pose;
    }
    for t in &mut trajectory.timestamps_ns {
        *t -= offset_ns;
    }
}

/// Moves every observer of `session` into a random world (and clock) of its own, marks its
/// placement so, and returns the truth per observer (session order).
pub fn perturb_observer_worlds(session: &mut Session, perturbation: &WorldPerturbation, seed: u64) -> Vec<WorldTruth> {
    let mut rng = SimRng::new(seed ^ 0x0030_17d5);
    let mut truth = Vec::new();
    for observer in &mut session.observers {
        let (t, clock_offset_s) = draw(&mut rng, perturbation);
        let offset_ns = (clock_offset_s * 1e9).round() as i64;
        move_out(&mut observer.head, &t, offset_ns);
        if let Some(k) = &mut observer.keypoints {
            k.timestamps_ns.iter_mut().for_each(|x| *x -= offset_ns);
        }
        if let Some(v) = &mut observer.video {
            v.start_ns -= offset_ns;
            v.frame_times_ns.iter_mut().for_each(|x| *x -= offset_ns);
        }
        if let Some(f) = &mut observer.context_features {
            f.timestamps_ns.iter_mut().for_each(|x| *x -= offset_ns);
        }
        observer.placement.world = WorldRef::Own;
        if offset_ns != 0 {
            observer.placement.clock = ClockRef::Own;
        }
        truth.push(WorldTruth { id: observer.id.clone(), t_session_world: t, clock_offset_s });
    }
    truth
}

/// Moves every participant of `capture` but the first into a random world (and clock) of its
/// own, with their devices, camera streams and the views their cameras made; returns the truth
/// per moved participant (`T_firstworld_participantworld`).
pub fn perturb_capture_worlds(capture: &mut Capture, perturbation: &WorldPerturbation, seed: u64) -> Vec<WorldTruth> {
    let mut rng = SimRng::new(seed ^ 0x0030_17d6);
    let mut truth = Vec::new();
    for p in capture.participants.iter_mut().skip(1) {
        let (t, clock_offset_s) = draw(&mut rng, perturbation);
        let offset_ns = (clock_offset_s * 1e9).round() as i64;
        move_out(&mut p.head, &t, offset_ns);
        for wrist in [&mut p.left_wrist, &mut p.right_wrist].into_iter().flatten() {
            move_out(wrist, &t, offset_ns);
        }
        if let Some(v) = &mut p.video {
            v.start_ns -= offset_ns;
            v.frame_times_ns.iter_mut().for_each(|x| *x -= offset_ns);
        }
        for view in capture.views.iter_mut().filter(|v| v.observer == p.id) {
            let times = match &mut view.people {
                ViewPeople::Assigned { keypoints, .. } => &mut keypoints.timestamps_ns,
                ViewPeople::Unassigned(people) => &mut people.timestamps_ns,
            };
            times.iter_mut().for_each(|x| *x -= offset_ns);
        }
        p.placement.world = WorldRef::Own;
        if offset_ns != 0 {
            p.placement.clock = ClockRef::Own;
        }
        truth.push(WorldTruth { id: p.id.clone(), t_session_world: t, clock_offset_s });
    }
    truth
}

/// Makes every observer of `session` (simulated as static cameras:
/// `ObserverBehaviour::static_camera`) a static camera that knows nothing of its pose: its
/// poses become the identity (its own world is its device frame), its placement
/// [`Placement::fixed_unposed`] with the focal length known or not; returns the truth per
/// observer (`T_session_observerworld` = its true pose).
pub fn unpose_static_cameras(session: &mut Session, focal_known: bool) -> Vec<WorldTruth> {
    let mut truth = Vec::new();
    for observer in &mut session.observers {
        let pose = observer.head.poses.first().copied().unwrap_or(RigidTransform::IDENTITY);
        observer.head.poses.fill(RigidTransform::IDENTITY);
        observer.placement = Placement::fixed_unposed(focal_known);
        truth.push(WorldTruth { id: observer.id.clone(), t_session_world: pose, clock_offset_s: 0.0 });
    }
    truth
}
