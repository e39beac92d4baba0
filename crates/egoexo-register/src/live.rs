//! Registering observers while they stream (a live room, `docs/registration.md`, "Live").
//!
//! A live observer in a world of its own (its hello said `"world": "own"`: a headset's XR
//! space, glasses localised alone) is registered to its wearer from the last seconds of its
//! views, again and again until a solution holds, then fused. [`RollingRegistration`] keeps one
//! estimate per observer:
//!
//! - **registering** — not fused; the wearer is reconstructed from the ego signals. Once
//!   [`RollingSettings::min_views_s`] of views are in, every [`RollingSettings::interval_s`]
//!   the solver runs on the last [`RollingSettings::window_s`]; a solution is taken when a
//!   later solve is `registered` too and agrees with it within their uncertainty (one lucky
//!   solve is not trusted; a solve that finds too little motion in between does not refute
//!   it, one that finds the views inconsistent does).
//! - **registered** — fused: every window's observer poses are mapped into the wearer's world.
//!   Every [`RollingSettings::check_interval_s`] it is solved again on the newest views: the
//!   same world (within the uncertainty) refines the estimate; another one drops it — back to
//!   registering — only if the estimate no longer explains the views since the last check.
//!
//! A device whose world jumps (a headset that re-centres, glasses that relocalise) shows it as
//! a step in its pose stream no head can make ([`world_jumps`]). From the step on, its poses
//! are in a new world: the estimate is dropped, the observer registers again from the views
//! after the step, and [`RollingRegistration::apply`] never fuses poses after a step it has not
//! registered — even between two updates. A step in the wearer's head (the world everyone is
//! registered into) does the same to every observer of theirs.
//!
//! Pure and clock-free: times are the relay's (nanoseconds), given by the caller.

use std::collections::BTreeMap;

use egoexo_core::ego_features::TrackingMode;
use egoexo_infer::Engine;
use egoexo_session::model::{KeypointTrack, Observer, Session, Trajectory};
use egoexo_session::placement::{Placement, WorldRef};
use egoexo_solve::registration::{Dof, Registration, RegistrationStatus};
use serde::{Deserialize, Serialize};

use crate::{RegisterMode, RegisterSettings, apply_registration, register_session};

/// How the rolling registration runs.
#[derive(Clone, Debug, PartialEq)]
pub struct RollingSettings {
    /// The solver's settings (mode auto; EgoNet's coarse body on a couple of windows at most).
    pub register: RegisterSettings,
    /// Seconds between two solves for an observer still registering.
    pub interval_s: f64,
    /// Seconds of views a solve reads (the newest).
    pub window_s: f64,
    /// Seconds of views before the first solve.
    pub min_views_s: f64,
    /// Seconds between two checks of a registered observer.
    pub check_interval_s: f64,
    /// A step between consecutive poses (at most [`RollingSettings::jump_max_gap_s`] apart)
    /// larger than this translation (metres) plus `jump_speed_m_s` × the gap is a world jump.
    pub jump_translation_m: f64,
    pub jump_speed_m_s: f64,
    /// … or larger than this rotation (degrees) plus `jump_turn_deg_s` × the gap.
    pub jump_rotation_deg: f64,
    pub jump_turn_deg_s: f64,
    /// Poses further apart than this (seconds) are a gap, not a step.
    pub jump_max_gap_s: f64,
}

impl Default for RollingSettings {
    fn default() -> Self {
        Self {
            register: RegisterSettings { coarse_windows: 2, ..RegisterSettings::default() },
            interval_s: 1.0,
            window_s: 20.0,
            min_views_s: 3.0,
            check_interval_s: 5.0,
            // A head moves at most a few metres and turns at most ~700°/s; a re-centred world
            // moves the pose by its whole offset in one sample.
            jump_translation_m: 0.2,
            jump_speed_m_s: 4.0,
            jump_rotation_deg: 25.0,
            jump_turn_deg_s: 900.0,
            jump_max_gap_s: 0.5,
        }
    }
}

/// Where an observer's world stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RollingState {
    /// Not yet registered (or its world jumped): not fused.
    Registering,
    /// Registered: fused, its poses mapped into the wearer's world.
    Registered,
}

/// One observer's rolling estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RollingObserver {
    pub state: RollingState,
    /// The registration fused (state registered).
    pub registration: Option<Registration>,
    /// The newest solve, when it was `registered` but not yet confirmed by the next.
    pub candidate: Option<Registration>,
    /// Seconds of views (frames with keypoints) in its current world so far.
    pub views_s: f64,
    /// Where its current world begins (relay ns): the last world jump, or its first pose.
    pub world_since_ns: i64,
    /// Its first view in the current world (relay ns).
    pub first_view_ns: Option<i64>,
    /// When it was registered (relay ns).
    pub registered_ns: Option<i64>,
    /// World jumps seen.
    pub jumps: u32,
    /// In words: where it stands and why.
    pub message: String,
    last_solve_ns: Option<i64>,
    last_check_ns: Option<i64>,
}

impl RollingObserver {
    fn new(world_since_ns: i64) -> Self {
        Self {
            state: RollingState::Registering,
            registration: None,
            candidate: None,
            views_s: 0.0,
            world_since_ns,
            first_view_ns: None,
            registered_ns: None,
            jumps: 0,
            message: "registering — no views yet".into(),
            last_solve_ns: None,
            last_check_ns: None,
        }
    }

    /// Seconds from its first view in the current world to its registration.
    pub fn registered_after_s(&self) -> Option<f64> {
        Some((self.registered_ns? - self.first_view_ns?) as f64 / 1e9)
    }

    /// Back to registering from `since_ns` (a world jump, or a check that failed).
    fn restart(&mut self, since_ns: i64, why: String) {
        self.state = RollingState::Registering;
        self.registration = None;
        self.candidate = None;
        self.views_s = 0.0;
        self.world_since_ns = since_ns;
        self.first_view_ns = None;
        self.registered_ns = None;
        self.last_solve_ns = None;
        self.last_check_ns = None;
        self.message = why;
    }
}

/// The rolling registration of a room's observers in worlds of their own.
#[derive(Clone, Debug, Default)]
pub struct RollingRegistration {
    settings: RollingSettings,
    observers: BTreeMap<String, RollingObserver>,
}

impl RollingRegistration {
    pub fn new(settings: RollingSettings) -> Self {
        Self { settings, observers: BTreeMap::new() }
    }

    pub fn settings(&self) -> &RollingSettings {
        &self.settings
    }

    /// Every observer in a world of its own seen so far, by id.
    pub fn observers(&self) -> &BTreeMap<String, RollingObserver> {
        &self.observers
    }

    /// Updates the estimates of `recent`'s observers in worlds of their own (`recent`: the
    /// newest [`RollingSettings::window_s`] of one wearer's part of the take, relay clock, as
    /// `LiveTake::to_session_of` gives it; `now_ns`: the newest head pose's time). Solves only
    /// when one is due, so it may be called every frame. A solve that fails leaves the
    /// observer registering and says why in its message.
    pub fn update(&mut self, engine: Option<&Engine>, recent: &Session, now_ns: i64) {
        let tracking = tracking_for(engine, recent);
        let wearer_jumps = world_jumps(&recent.wearer.head, &self.settings);
        for (index, observer) in recent.observers.iter().enumerate() {
            if observer.placement.world != WorldRef::Own {
                continue;
            }
            let Some(first_pose) = observer.head.timestamps_ns.first().copied() else { continue };
            let settings = &self.settings;
            let entry = self.observers.entry(observer.id.clone()).or_insert_with(|| RollingObserver::new(first_pose));
            // The newest step in its own poses, or in the wearer's (whose world is the one it
            // is registered into).
            let own = world_jumps(&observer.head, settings).into_iter().rev().find(|&t| t > entry.world_since_ns);
            let wearer = wearer_jumps.iter().rev().copied().find(|&t| t > entry.world_since_ns);
            if let Some(jump) = own.max(wearer) {
                let jumps = entry.jumps + 1;
                let was = if entry.state == RollingState::Registered { "registered; " } else { "" };
                let whose = if own >= wearer { "its world" } else { "the wearer's world" };
                entry.restart(
                    jump,
                    format!("{was}{whose} jumped (a re-centred or relocalised device): registering again"),
                );
                entry.jumps = jumps;
            }
            let since = entry.world_since_ns;
            let (views_s, first_view) = views_since(observer, since);
            if entry.first_view_ns.is_none() {
                entry.first_view_ns = first_view;
            }
            match entry.state {
                RollingState::Registering => {
                    // Views accumulate over the take even when the window holds fewer.
                    entry.views_s = entry.views_s.max(views_s);
                    let due = entry.last_solve_ns.is_none_or(|t| (now_ns - t) as f64 / 1e9 >= settings.interval_s);
                    if views_s < settings.min_views_s || !due {
                        if entry.candidate.is_none() && entry.last_solve_ns.is_none() && entry.jumps == 0 {
                            entry.message = format!("registering — {:.0} s of views", entry.views_s);
                        }
                        continue;
                    }
                    entry.last_solve_ns = Some(now_ns);
                    let solved = solve(engine, tracking, recent, index, since, None, &settings.register);
                    match solved {
                        Ok(Some(found)) if found.status == RegistrationStatus::Registered => {
                            let confirmed = entry.candidate.as_ref().is_some_and(|c| consistent(c, &found));
                            if confirmed {
                                entry.message =
                                    format!("registered after {:.1} s of views: {}", entry.views_s, estimate(&found));
                                entry.state = RollingState::Registered;
                                entry.registration = Some(found);
                                entry.candidate = None;
                                entry.registered_ns = Some(now_ns);
                                entry.last_check_ns = Some(now_ns);
                            } else {
                                entry.message =
                                    format!("registering — {:.0} s of views, a solution to confirm", entry.views_s);
                                entry.candidate = Some(found);
                            }
                        }
                        Ok(found) => {
                            // Too little motion in this window says nothing against a
                            // candidate; views no transform explains do.
                            if found.as_ref().is_some_and(|r| r.status == RegistrationStatus::Inconsistent) {
                                entry.candidate = None;
                            }
                            entry.message = match found {
                                Some(r) => format!(
                                    "registering — {:.0} s of views ({}: {})",
                                    entry.views_s, r.status, r.reason
                                ),
                                None => format!("registering — {:.0} s of views", entry.views_s),
                            };
                        }
                        Err(e) => {
                            entry.candidate = None;
                            entry.message =
                                format!("registering — {:.0} s of views (the solve failed: {e})", entry.views_s);
                        }
                    }
                }
                RollingState::Registered => {
                    entry.views_s = entry.views_s.max(views_s);
                    let due =
                        entry.last_check_ns.is_none_or(|t| (now_ns - t) as f64 / 1e9 >= settings.check_interval_s);
                    let Some(current) = entry.registration.clone().filter(|_| due) else { continue };
                    let check_since = entry.last_check_ns.unwrap_or(since).max(since);
                    entry.last_check_ns = Some(now_ns);
                    // A fresh solve on the newest views: the same world, better known, refines
                    // the estimate; another world (a drift, a small re-centre no step showed)
                    // is believed only if the estimate no longer explains the views.
                    let fresh = solve(engine, tracking, recent, index, since, None, &settings.register);
                    let Ok(Some(found)) = fresh else { continue };
                    if found.status != RegistrationStatus::Registered {
                        continue;
                    }
                    if consistent(&current, &found) {
                        entry.message =
                            format!("registered over {:.0} s of views: {}", entry.views_s, estimate(&found));
                        entry.registration = Some(found);
                        continue;
                    }
                    let checked =
                        solve(engine, tracking, recent, index, check_since, Some(&current), &settings.register);
                    if let Ok(Some(check)) = checked
                        && check.status != RegistrationStatus::AsGiven
                    {
                        let jumps = entry.jumps;
                        entry.restart(
                            check_since,
                            format!("registered, but its newest views disagree ({}): registering again", check.status),
                        );
                        entry.jumps = jumps;
                    }
                }
            }
        }
    }

    /// Moves `session`'s registered observers into the wearer's world (poses since their
    /// world began, up to any newer jump); observers in worlds of their own that are not
    /// registered — or whose poses are all in a world not registered — stay in their own
    /// world, and alignment keeps them out of the fusion.
    pub fn apply(&self, session: &mut Session) -> Result<(), crate::RegisterError> {
        let wearer_jumps = world_jumps(&session.wearer.head, &self.settings);
        for observer in &mut session.observers {
            if observer.placement.world != WorldRef::Own {
                continue;
            }
            let Some(estimate) = self.observers.get(&observer.id) else { continue };
            let Some(registration) =
                estimate.registration.as_ref().filter(|_| estimate.state == RollingState::Registered)
            else {
                continue;
            };
            // Only the poses and views of the registered world: from its start to the next
            // jump (one the next update has not seen yet).
            let start = estimate.world_since_ns;
            let end = world_jumps(&observer.head, &self.settings)
                .into_iter()
                .chain(wearer_jumps.iter().copied())
                .filter(|&t| t > start)
                .min()
                .unwrap_or(i64::MAX);
            keep_between(observer, start, end);
            if observer.head.is_empty() {
                continue;
            }
            apply_registration(observer, registration)?;
        }
        Ok(())
    }
}

/// The tracking mode whose networks give the coarse body.
fn tracking_for(engine: Option<&Engine>, session: &Session) -> TrackingMode {
    let tracking = session.wearer.tracking_mode();
    if engine.is_some_and(|e| e.models(tracking).is_none()) { TrackingMode::OnePoint } else { tracking }
}

/// Registers observer `index` of `recent` from its views since `since_ns`; with `current`,
/// checks that registration instead (the observer moved by it, its world then given as the
/// wearer's). `Ok(None)`: nothing to solve with.
fn solve(
    engine: Option<&Engine>,
    tracking: TrackingMode,
    recent: &Session,
    index: usize,
    since_ns: i64,
    current: Option<&Registration>,
    settings: &RegisterSettings,
) -> Result<Option<Registration>, crate::RegisterError> {
    let mut observer = recent.observers[index].clone();
    keep_between(&mut observer, since_ns, i64::MAX);
    if observer.head.len() < 2 || observer.keypoints.as_ref().is_none_or(|k| k.frames.is_empty()) {
        return Ok(None);
    }
    if let Some(current) = current {
        apply_registration(&mut observer, current)?;
        // Checked as a world given as shared: auto keeps it if the views agree.
        observer.placement = Placement { registration: None, ..observer.placement.clone() };
    }
    // The wearer and this one observer (a ground truth would name the others).
    let mut one = Session {
        name: recent.name.clone(),
        wearer: recent.wearer.clone(),
        observers: vec![observer],
        subject: recent.subject.clone(),
        ground_truth: None,
        floor: recent.floor.clone(),
    };
    let settings = RegisterSettings { mode: RegisterMode::Auto, ..settings.clone() };
    let report = register_session(engine, tracking, &mut one, &settings)?;
    // A kept world reports as-given; a registered or left-out one the solve's result.
    Ok(report.observers.into_iter().next().and_then(|o| o.registration))
}

/// Two solutions agree: their yaw and translation differ by at most three of their combined
/// σ (with a floor of 1° and 5 cm: the coarse body's bias moves solves of overlapping windows by more than their σ).
fn consistent(a: &Registration, b: &Registration) -> bool {
    let combined = |x: Option<f64>, y: Option<f64>| (x.unwrap_or(0.0).powi(2) + y.unwrap_or(0.0).powi(2)).sqrt();
    let mut yaw = (a.yaw_deg - b.yaw_deg).rem_euclid(360.0);
    if yaw > 180.0 {
        yaw = 360.0 - yaw;
    }
    let moved = a.transform.translation.distance(b.transform.translation) as f64;
    // In 6 DoF (a static camera that knows no gravity) the whole rotation must agree, not
    // only the yaw.
    let turned = a.transform.rotation.angle_between(b.transform.rotation).to_degrees() as f64;
    let rotation_agrees = a.dof == Dof::Four && b.dof == Dof::Four
        || turned <= 3.0 * combined(a.sigma_rotation_deg, b.sigma_rotation_deg) + 1.0;
    yaw <= 3.0 * combined(a.sigma_yaw_deg, b.sigma_yaw_deg) + 1.0
        && rotation_agrees
        && moved <= 3.0 * combined(a.sigma_translation_m, b.sigma_translation_m) + 0.05
}

/// A registration in words: yaw and translation with their 1σ.
fn estimate(r: &Registration) -> String {
    let [x, y, z] = r.translation_m();
    format!(
        "yaw {:.1}° ± {:.1}°, translation ({x:.2}, {y:.2}, {z:.2}) m ± {:.1} cm",
        r.yaw_deg,
        r.sigma_yaw_deg.unwrap_or(f64::NAN),
        r.sigma_translation_m.unwrap_or(f64::NAN) * 100.0
    )
}

/// Seconds of views of `observer` since `since_ns` (frames with a detected keypoint, each
/// counting the time to the next one, up to 0.2 s), and the first of them.
fn views_since(observer: &Observer, since_ns: i64) -> (f64, Option<i64>) {
    let Some(k) = &observer.keypoints else { return (0.0, None) };
    let seen: Vec<i64> = k
        .timestamps_ns
        .iter()
        .zip(&k.frames)
        .filter(|(t, f)| **t >= since_ns && f.iter().any(Option::is_some))
        .map(|(t, _)| *t)
        .collect();
    let seconds = seen.windows(2).map(|w| ((w[1] - w[0]) as f64 / 1e9).min(0.2)).sum();
    (seconds, seen.first().copied())
}

/// Keeps `observer`'s poses and views within `[start, end)` (relay ns).
fn keep_between(observer: &mut Observer, start: i64, end: i64) {
    let inside = |t: &i64| *t >= start && *t < end;
    let head = std::mem::take(&mut observer.head);
    (observer.head.timestamps_ns, observer.head.poses) =
        head.timestamps_ns.into_iter().zip(head.poses).filter(|(t, _)| inside(t)).unzip();
    if let Some(k) = observer.keypoints.take() {
        let (timestamps_ns, frames) = k.timestamps_ns.into_iter().zip(k.frames).filter(|(t, _)| inside(t)).unzip();
        observer.keypoints = Some(KeypointTrack { timestamps_ns, frames });
    }
}

/// Times (ns) of the first pose after each world jump in `trajectory`: a step between
/// consecutive poses at most [`RollingSettings::jump_max_gap_s`] apart that no head makes
/// (translation or rotation beyond the settings' bounds for the time between them).
pub fn world_jumps(trajectory: &Trajectory, settings: &RollingSettings) -> Vec<i64> {
    let mut jumps = Vec::new();
    for i in 1..trajectory.len() {
        let dt = (trajectory.timestamps_ns[i] - trajectory.timestamps_ns[i - 1]) as f64 / 1e9;
        if !(0.0..=settings.jump_max_gap_s).contains(&dt) {
            continue;
        }
        let (a, b) = (&trajectory.poses[i - 1], &trajectory.poses[i]);
        let moved = f64::from(a.translation.distance(b.translation));
        let turned = f64::from(a.rotation.angle_between(b.rotation)).to_degrees();
        if moved > settings.jump_translation_m + settings.jump_speed_m_s * dt
            || turned > settings.jump_rotation_deg + settings.jump_turn_deg_s * dt
        {
            jumps.push(trajectory.timestamps_ns[i]);
        }
    }
    jumps
}
