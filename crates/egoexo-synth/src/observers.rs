//! Observers: where they stand or walk, and where their heads point.
//!
//! An observer starts 1.5–8 m from the wearer (configurable), stands still (with a little sway)
//! or walks to keep a slowly varying distance and bearing to the wearer. Their head follows a
//! point on the wearer's chest with a smooth-pursuit lag and small saccades, and now and then
//! looks away for 0.5–5 s so the wearer leaves the image. World Y-up, metres, seconds; head
//! poses are `T_world_device` of CPF glasses.

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;

use crate::config::ObserverBehaviour;
use crate::rng::SimRng;

/// An observer's true motion.
#[derive(Clone, Debug, PartialEq)]
pub struct ObserverTrack {
    /// True `T_world_device` of the observer's glasses, per frame.
    pub head: Vec<RigidTransform>,
    /// Frames in which the observer deliberately looks away from the wearer.
    pub looking_away: Vec<bool>,
    /// Whether the observer walks (else stands).
    pub walking: bool,
}

fn horizontal(v: Vec3) -> Vec3 {
    Vec3::new(v.x, 0.0, v.z)
}

/// Simulates one observer watching a wearer whose chest is at `wearer_chest[i]` (world) at
/// frame `i`, on a floor at height `floor_y`.
pub fn simulate_observer(
    wearer_chest: &[Vec3],
    floor_y: f32,
    fps: f32,
    behaviour: &ObserverBehaviour,
    rng: &mut SimRng,
) -> ObserverTrack {
    let n = wearer_chest.len();
    let dt = 1.0 / fps;
    let walking = rng.chance(behaviour.walking_probability);
    let eye_height = rng.uniform(behaviour.eye_height_m.0, behaviour.eye_height_m.1);
    let (min_d, max_d) = (behaviour.min_distance_m, behaviour.max_distance_m.max(behaviour.min_distance_m));

    // Position: distance and bearing to the wearer, slowly varying when walking.
    let start = wearer_chest.first().copied().unwrap_or(Vec3::ZERO);
    let mut distance = rng.uniform(min_d, max_d);
    let mut bearing = rng.uniform(0.0, std::f32::consts::TAU);
    let mut position = horizontal(start) + distance * Vec3::new(bearing.sin(), 0.0, bearing.cos());
    let sway_phase = rng.uniform(0.0, std::f32::consts::TAU);
    let anchor = position;
    if behaviour.static_camera {
        // A tripod: one pose, aimed at the middle of the wearer's path.
        let middle = wearer_chest.iter().copied().sum::<Vec3>() / n.max(1) as f32;
        let eye = Vec3::new(anchor.x, floor_y + eye_height, anchor.z);
        let pose = RigidTransform::cpf_looking_at(eye, middle);
        return ObserverTrack { head: vec![pose; n], looking_away: vec![false; n], walking: false };
    }

    // Gaze state.
    let mut gaze = Vec3::ZERO; // current look direction (unit), set on the first frame
    let mut saccade = Quat::IDENTITY;
    let mut next_saccade = rng.exponential(behaviour.saccade_interval_s);
    let mut next_look_away = rng.exponential(behaviour.look_away_interval_s);
    let mut look_away_until = f32::NEG_INFINITY;
    let mut look_away_direction = Vec3::Z;

    let mut head = Vec::with_capacity(n);
    let mut looking_away = Vec::with_capacity(n);
    for (i, &chest) in wearer_chest.iter().enumerate() {
        let t = i as f32 * dt;
        if walking {
            // Ornstein–Uhlenbeck wander of the preferred distance and bearing.
            distance += (0.5 * (min_d + max_d) - distance) * dt / 8.0 + rng.normal(0.0, 0.35 * dt.sqrt());
            distance = distance.clamp(min_d, max_d);
            bearing += rng.normal(0.0, 0.25 * dt.sqrt());
            let target = horizontal(chest) + distance * Vec3::new(bearing.sin(), 0.0, bearing.cos());
            let step = (target - position) * (dt / 1.0).min(1.0);
            let max_step = 1.6 * dt;
            position += if step.length() > max_step { step.normalize() * max_step } else { step };
        } else {
            position = anchor + 0.03 * Vec3::new((0.7 * t + sway_phase).sin(), 0.0, (0.5 * t).cos());
        }
        // Never closer than the minimum distance (people keep personal space).
        let away = horizontal(position - chest);
        if away.length() < min_d {
            position = horizontal(chest) + away.normalize_or(Vec3::Z) * min_d;
        }
        let eye = Vec3::new(position.x, floor_y + eye_height + 0.01 * (1.8 * t).sin(), position.z);

        // Gaze target.
        let to_wearer = (chest - eye).normalize_or(Vec3::Z);
        if t >= next_look_away {
            look_away_until = t + rng.uniform(behaviour.look_away_duration_s.0, behaviour.look_away_duration_s.1);
            let side = if rng.chance(0.5) { 1.0 } else { -1.0 };
            let yaw = side * rng.uniform(75f32.to_radians(), 170f32.to_radians());
            let pitch = rng.uniform(-0.3, 0.2);
            look_away_direction = (Quat::from_rotation_y(yaw) * horizontal(to_wearer).normalize_or(Vec3::Z)
                + Vec3::Y * pitch)
                .normalize();
            next_look_away = look_away_until + rng.exponential(behaviour.look_away_interval_s);
        }
        let away_now = t < look_away_until;
        if t >= next_saccade {
            let amplitude = rng.uniform(behaviour.saccade_amplitude_rad.0, behaviour.saccade_amplitude_rad.1);
            saccade = Quat::from_axis_angle(rng.unit_vec3(), amplitude);
            next_saccade = t + rng.exponential(behaviour.saccade_interval_s);
        }
        let target = if away_now { look_away_direction } else { (saccade * to_wearer).normalize() };
        gaze = if i == 0 {
            target
        } else {
            // Smooth pursuit: first-order lag towards the target direction (faster when
            // turning away or back, as heads do for large shifts).
            let lag = if away_now { 0.12 } else { behaviour.tracking_lag_s.max(1e-3) };
            let alpha = 1.0 - (-dt / lag).exp();
            gaze.lerp(target, alpha).normalize_or(target)
        };
        head.push(RigidTransform::cpf_looking_at(eye, eye + gaze));
        looking_away.push(away_now);
    }
    ObserverTrack { head, looking_away, walking }
}
