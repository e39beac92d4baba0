//! Registering a session's observers to the wearer's world before the reconstruction
//! (`docs/registration.md`).
//!
//! Ego-exo fusion lifts each observer's keypoints to rays with the observer's pose, so an
//! observer must be in the wearer's world and on the wearer's clock. An observer's
//! [`Placement`](egoexo_session::placement::Placement) says whether it is (as given) or not
//! (its own world, its own clock, a static camera without pose). This crate, between the
//! importers and the engine:
//!
//! 1. builds what the wearer looks like from outside over time — the face from the head
//!    trajectory, and, for an observer the face alone does not settle (one that sees the
//!    wearer's back), the body from EgoNet's coarse pose on the windows the observers see
//!    ([`Engine::coarse_body`]) — and what each observer's camera saw (its keypoints at its
//!    camera poses, in its own world);
//! 2. per [`RegisterMode`]: checks a world given as shared against its views
//!    ([`check_agreement`]), registers the ones that disagree or are their own
//!    ([`egoexo_solve::registration::register`]);
//! 3. applies a registration to the session (poses into the wearer's world, times onto the
//!    wearer's clock, the focal length found) and records every verdict in the observer's
//!    placement. An observer that cannot be registered stays out of the fusion (alignment gives
//!    it no frame) and the report says so.
//!
//! Captures of several people: [`capture`] registers every participant's world into one
//! (the anchor's) through whoever sees whom, jointly.

pub mod capture;
pub mod live;
mod tracks;

use egoexo_core::camera::{CameraCalibration, Pinhole, Projection};
use egoexo_core::ego_features::TrackingMode;
use egoexo_core::rigid::RigidTransform;
use egoexo_infer::{Engine, InferError};
use egoexo_session::align::{AlignError, AlignOptions, align};
use egoexo_session::model::{ContextFeatureTrack, Observer, Session, Trajectory, VideoRef};
use egoexo_session::placement::{ClockRef, Placement, RegistrationRecord, WorldRef, describe_registration};
use egoexo_solve::registration::{
    Agreement, Dof, RegisterOptions, Registration, RegistrationError, RegistrationStatus, TargetTrack, check_agreement,
    register,
};
use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use tracks::{observer_view, origin_ns, target_track, view_track};

/// What to do with the observers' worlds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RegisterMode {
    /// Keep worlds given as shared when their views agree; register those that disagree and
    /// those in their own world (the default of the CLI, the worker and the server).
    #[default]
    Auto,
    /// Keep every world as given; an observer in its own world is left out.
    Off,
    /// Register every observer with keypoints, whatever its placement says.
    Force,
}

impl RegisterMode {
    /// `"auto"`, `"off"`, `"force"`.
    pub fn name(self) -> &'static str {
        match self {
            RegisterMode::Auto => "auto",
            RegisterMode::Off => "off",
            RegisterMode::Force => "force",
        }
    }
}

impl std::str::FromStr for RegisterMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(RegisterMode::Auto),
            "off" => Ok(RegisterMode::Off),
            "force" => Ok(RegisterMode::Force),
            other => Err(format!("`{other}`: expected auto, off or force")),
        }
    }
}

/// How to register.
#[derive(Clone, Debug, PartialEq)]
pub struct RegisterSettings {
    pub mode: RegisterMode,
    /// The solver's options; the degrees of freedom, clock search and focal estimation are set
    /// per observer from its placement.
    pub options: RegisterOptions,
    /// How far (seconds) an observer on its own clock is searched either side of the wearer's.
    pub own_clock_search_s: f64,
    /// EgoNet runs on at most this many windows (96 frames each) for the coarse body: those
    /// the observers see most.
    pub coarse_windows: usize,
}

impl Default for RegisterSettings {
    fn default() -> Self {
        Self {
            mode: RegisterMode::Auto,
            options: RegisterOptions::default(),
            own_clock_search_s: 2.0,
            coarse_windows: 16,
        }
    }
}

/// What became of one observer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// Its world was given as shared and is kept (its views agree, or were too few to tell,
    /// or were not checked).
    Kept,
    /// Registered now: its poses (and clock, focal) were moved into the session's.
    Registered,
    /// Not fused: its world is its own and could not be (or was not) registered, or its given
    /// world contradicts its views and no registration explains them.
    LeftOut,
}

/// One observer's registration step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObserverReport {
    pub id: String,
    pub outcome: Outcome,
    /// The check or solve made now (`None`: nothing was checked).
    pub registration: Option<Registration>,
    /// In words: what was done and why.
    pub message: String,
}

/// The registration step of a session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionRegistration {
    pub mode: RegisterMode,
    pub observers: Vec<ObserverReport>,
    /// Windows EgoNet ran on for the coarse body (0 when the face points settled every
    /// observer, or without models).
    pub coarse_windows: usize,
}

impl SessionRegistration {
    /// The observers left out and the worlds that were moved: worth a warning.
    pub fn warnings(&self) -> impl Iterator<Item = &ObserverReport> {
        self.observers.iter().filter(|o| o.outcome != Outcome::Kept)
    }
}

/// Why registration could not run.
#[derive(Debug, Error)]
pub enum RegisterError {
    #[error("cannot align the session for registration: {0}")]
    Align(#[from] AlignError),
    #[error("EgoNet's coarse body for registration: {0}")]
    Infer(#[from] InferError),
    #[error("{0}")]
    Capture(#[from] egoexo_session::capture::CaptureError),
    #[error("observer `{observer}`: {source}")]
    Solve { observer: String, source: RegistrationError },
    #[error("observer `{observer}`: the estimated focal length {focal_px:.1} px is not a valid camera")]
    Focal { observer: String, focal_px: f64 },
}

/// Registers `session`'s observers to its wearer per `settings` (see the crate docs), in
/// place: registered observers' poses, times and cameras are moved into the wearer's world
/// and clock, and every verdict is recorded in the observer's placement. `engine` (with the
/// models for `tracking`) gives the coarse body; without it only the face points the head
/// trajectory gives are used.
pub fn register_session(
    engine: Option<&Engine>,
    tracking: TrackingMode,
    session: &mut Session,
    settings: &RegisterSettings,
) -> Result<SessionRegistration, RegisterError> {
    let mut report = SessionRegistration { mode: settings.mode, observers: Vec::new(), coarse_windows: 0 };
    let todo: Vec<usize> = (0..session.observers.len())
        .filter(|&o| {
            let observer = &session.observers[o];
            let has_views = observer.keypoints.as_ref().is_some_and(|k| !k.frames.is_empty());
            has_views && settings.mode != RegisterMode::Off && !already_settled(observer, settings.mode)
        })
        .collect();
    // The face from the head trajectory first (free, and exact up to the face); EgoNet's body
    // only for an observer the face alone cannot settle (one that sees the wearer's back).
    let prepared = if todo.is_empty() {
        None
    } else {
        let aligned = align(session, &AlignOptions::default())?;
        let face = target_track(&aligned, None, origin_ns(session))
            .map_err(|source| RegisterError::Solve { observer: "(wearer)".into(), source })?;
        Some((aligned, face))
    };
    let mut body: Option<TargetTrack> = None;
    for o in 0..session.observers.len() {
        let observer = &session.observers[o];
        let id = observer.id.clone();
        let Some((aligned, face)) = prepared.as_ref().filter(|_| todo.contains(&o)) else {
            report.observers.push(untouched(observer, settings.mode));
            continue;
        };
        let solve_error = |source| RegisterError::Solve { observer: id.clone(), source };
        let mut body_track = |report: &mut SessionRegistration| -> Result<Option<TargetTrack>, RegisterError> {
            let Some(engine) = engine else { return Ok(None) };
            if body.is_none() {
                let wanted = tracks::frames_seen(session, &aligned.timeline, &todo, settings.own_clock_search_s);
                let coarse = engine.coarse_body(aligned, tracking, settings.coarse_windows, &|f| wanted[f])?;
                report.coarse_windows = coarse.windows;
                body = Some(
                    target_track(aligned, Some(&coarse), origin_ns(session))
                        .map_err(|source| RegisterError::Solve { observer: "(wearer)".into(), source })?,
                );
            }
            Ok(body.clone())
        };
        let placement = &observer.placement;
        let view = observer_view(session, o, origin_ns(session));
        let options = RegisterOptions {
            dof: if placement.gravity { Dof::Four } else { Dof::Six },
            clock_search_s: if placement.clock == ClockRef::Own { settings.own_clock_search_s } else { 0.0 },
            ..settings.options.clone()
        };
        let given_shared =
            placement.world == WorldRef::Shared && placement.clock == ClockRef::Shared && !view.estimate_focal;
        let mut why = "its world is its own";
        let mut fits_given = None;
        if settings.mode == RegisterMode::Auto && given_shared {
            let mut agreement =
                check_agreement(face, &view, &RigidTransform::IDENTITY, &options).map_err(solve_error)?;
            if !agreement.agrees
                && !agreement.undetermined
                && let Some(body) = body_track(&mut report)?
            {
                agreement = check_agreement(&body, &view, &RigidTransform::IDENTITY, &options).map_err(solve_error)?;
            }
            if agreement.agrees || agreement.undetermined {
                let reason = if agreement.agrees {
                    format!(
                        "the given world explains {} of {} frames over {:.1} s",
                        agreement.inlier_frames, agreement.frames, agreement.view_s
                    )
                } else {
                    format!("{:.1} s of views are too few to check the given world; kept as given", agreement.view_s)
                };
                report.observers.push(keep_as_given(&mut session.observers[o], &agreement, reason));
                continue;
            }
            if agreement.fits {
                fits_given = Some(agreement);
                why = "its given world fits its views only loosely";
            } else {
                why = "its given world does not explain its views";
            }
        } else if settings.mode == RegisterMode::Force {
            why = "registration forced";
        }
        let mut result = register(face, &view, &options).map_err(solve_error)?;
        if result.status != RegistrationStatus::Registered
            && let Some(body) = body_track(&mut report)?
        {
            result = register(&body, &view, &options).map_err(solve_error)?;
        }
        if result.status != RegistrationStatus::Registered
            && let Some(agreement) = fits_given
        {
            // The views fit the given world; no better one is found: keep it.
            let reason = format!(
                "the given world explains {} of {} frames over {:.1} s; registration found nothing surer ({}: {}); kept as given",
                agreement.inlier_frames, agreement.frames, agreement.view_s, result.status, result.reason
            );
            report.observers.push(keep_as_given(&mut session.observers[o], &agreement, reason));
            continue;
        }
        let observer = &mut session.observers[o];
        let outcome = if result.status == RegistrationStatus::Registered {
            apply_registration(observer, &result)?;
            Outcome::Registered
        } else {
            // Recorded, not applied: the verdict keeps it out of the fusion.
            observer.placement.registration = Some(RegistrationRecord { result: result.clone(), applied: false });
            Outcome::LeftOut
        };
        let message = match outcome {
            Outcome::Registered => format!("{why}: {}", describe_registration(&result, true)),
            _ => format!("{why}; not fused: {} — {}", result.status, result.reason),
        };
        report.observers.push(ObserverReport { id, outcome, registration: Some(result), message });
    }
    Ok(report)
}

/// Keeps `observer`'s given world, which `agreement` found to explain its views: the verdict
/// `as-given` is recorded (not applied: nothing moves) and reported with `reason`.
fn keep_as_given(observer: &mut Observer, agreement: &Agreement, reason: String) -> ObserverReport {
    let result = Registration::as_given(
        agreement.frames,
        agreement.inlier_frames,
        agreement.view_s,
        agreement.inlier_view_s,
        agreement.median_residual_deg,
        reason.clone(),
    );
    observer.placement.registration = Some(RegistrationRecord { result: result.clone(), applied: false });
    ObserverReport { id: observer.id.clone(), outcome: Outcome::Kept, registration: Some(result), message: reason }
}

/// An observer a mode leaves alone: already registered (`auto`), or anything (`off`).
fn already_settled(observer: &Observer, mode: RegisterMode) -> bool {
    mode == RegisterMode::Auto
        && observer
            .placement
            .registration
            .as_ref()
            .is_some_and(|r| r.applied || r.result.status == RegistrationStatus::AsGiven)
        && observer.placement.world == WorldRef::Shared
        && observer.placement.clock == ClockRef::Shared
}

/// The report of an observer nothing was done to.
fn untouched(observer: &Observer, mode: RegisterMode) -> ObserverReport {
    let placement = &observer.placement;
    let has_views = observer.keypoints.as_ref().is_some_and(|k| !k.frames.is_empty());
    let (outcome, message) = if placement.fusable() {
        let why = if already_settled(observer, mode) {
            "registered before".to_owned()
        } else if mode == RegisterMode::Off {
            "registration off".to_owned()
        } else if !has_views {
            "no keypoints to check it against".to_owned()
        } else {
            "kept".to_owned()
        };
        (Outcome::Kept, format!("as given ({why}): {}", placement.describe()))
    } else {
        let why = if mode == RegisterMode::Off {
            "registration is off"
        } else if !has_views {
            "it has no keypoints to register it with"
        } else {
            "its registration failed before"
        };
        (Outcome::LeftOut, format!("not fused: {} and {why}", placement.describe()))
    };
    ObserverReport { id: observer.id.clone(), outcome, registration: None, message }
}

/// Moves `observer` into the wearer's world and clock by `result` (`T_session_observerworld`,
/// `t_session = t_observer + clock_offset_s`, the focal length found) and records it.
pub fn apply_registration(observer: &mut Observer, result: &Registration) -> Result<(), RegisterError> {
    let offset_ns = clock_offset_ns(result);
    move_trajectory(&mut observer.head, &result.transform, offset_ns);
    if let Some(k) = &mut observer.keypoints {
        shift_times(&mut k.timestamps_ns, offset_ns);
    }
    shift_streams(&mut observer.video, &mut observer.context_features, offset_ns);
    observer.camera = camera_with_focal(&observer.camera, result, &observer.id)?;
    observer.placement = registered_placement(&observer.placement, result);
    Ok(())
}

/// The clock offset, nanoseconds.
pub(crate) fn clock_offset_ns(result: &Registration) -> i64 {
    (result.clock_offset_s * 1e9).round() as i64
}

/// Poses mapped by `t` (into the session's world), times shifted by `offset_ns`.
pub(crate) fn move_trajectory(trajectory: &mut Trajectory, t: &RigidTransform, offset_ns: i64) {
    for pose in &mut trajectory.poses {
        *pose = *t * *pose;
    }
    shift_times(&mut trajectory.timestamps_ns, offset_ns);
}

pub(crate) fn shift_times(times: &mut [i64], offset_ns: i64) {
    if offset_ns != 0 {
        times.iter_mut().for_each(|x| *x = x.saturating_add(offset_ns));
    }
}

/// A camera's video and context features onto the session's clock.
pub(crate) fn shift_streams(video: &mut Option<VideoRef>, features: &mut Option<ContextFeatureTrack>, offset_ns: i64) {
    if let Some(v) = video {
        v.start_ns = v.start_ns.saturating_add(offset_ns);
        shift_times(&mut v.frame_times_ns, offset_ns);
    }
    if let Some(f) = features {
        shift_times(&mut f.timestamps_ns, offset_ns);
    }
}

/// The camera with the focal length `result` found (a pinhole's `fx`; `fy` scaled alike).
pub(crate) fn camera_with_focal(
    camera: &CameraCalibration,
    result: &Registration,
    who: &str,
) -> Result<CameraCalibration, RegisterError> {
    let (Some(focal_px), Projection::Pinhole(p)) = (result.focal_px, camera.projection) else { return Ok(*camera) };
    let scale = (focal_px / f64::from(p.fx)) as f32;
    let scaled = Pinhole::new(p.fx * scale, p.fy * scale, p.cx, p.cy)
        .map_err(|_| RegisterError::Focal { observer: who.to_owned(), focal_px })?;
    Ok(CameraCalibration { projection: Projection::Pinhole(scaled), ..*camera })
}

/// The placement after `result` was applied: the session's world and clock, recorded.
pub(crate) fn registered_placement(before: &Placement, result: &Registration) -> Placement {
    Placement {
        world: WorldRef::Shared,
        clock: ClockRef::Shared,
        gravity: true,
        focal_known: true,
        mount: before.mount,
        registration: Some(RegistrationRecord { result: result.clone(), applied: true }),
    }
}
