//! Registering an observer's world to the wearer's from what its camera sees.
//!
//! Ego-exo fusion lifts an observer's keypoints to rays with the observer's pose, so the
//! observer's world must be the wearer's. Devices that were not mapped together (two Aria
//! glasses through MPS one by one, a Quest and a phone in their own XR spaces, a static camera
//! with no pose) are not. The wearer's own head track, and the coarse body the ego signals
//! give, are seen by the observer's camera: the transform `T_wearer_observerworld` that makes
//! the projected body match the 2D keypoints over time is found here (and, where the devices
//! share no clock, the offset between their clocks; for a pinhole camera of unknown focal
//! length, that too).
//!
//! Method ([`register`]): keypoints become bearings; RANSAC over frames on left–right-free
//! keypoint groups gives a start per clock-offset and focal candidate ([`ransac`]); the best
//! starts are refined by robust (Cauchy) Levenberg–Marquardt on every keypoint, with the
//! person and left–right labelling that fit best per frame ([`problem`]); the covariance is
//! the larger of the model-based and the cluster-robust (one-second clusters) estimates; and
//! a verdict ([`RegistrationStatus`]) says whether to trust it. [`graph`] registers several
//! worlds that see each other jointly.
//!
//! `p_target = R · p_observer + t`: with 4 DoF `R = R_y(yaw)`, right-handed about +Y (a
//! positive yaw turns +X towards −Z). Clocks: `t_target = t_observer + clock_offset_s`.

pub mod graph;
pub(crate) mod problem;
pub(crate) mod ransac;
pub mod track;
pub(crate) mod view;

use egoexo_core::rigid::RigidTransform;
use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use problem::{Dof, NodeSpec, NodeState};
pub use track::{PointAt, PointSigmas, TargetPoint, TargetTrack, WearerBody, WearerSample};
pub use view::{ViewFrame, ViewTrack};

use crate::geometry::{M3, V3, heading, rigid_transform};
use crate::lsq::{LmOptions, levenberg_marquardt};
use crate::robust::RobustLoss;
use problem::{Edge, Problem};
use view::PreparedView;

/// Inputs the solver cannot use.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum RegistrationError {
    #[error("{what}: {times} times and {items} samples; expected one time per sample")]
    Lengths { what: &'static str, times: usize, items: usize },
    #[error("{what}: time at index {index} is not after the one before; expected strictly increasing times")]
    TimesNotIncreasing { what: &'static str, index: usize },
    #[error("{what} at index {index} is not finite (or its σ is not positive)")]
    NotFinite { what: &'static str, index: usize },
    #[error("the focal length of a fisheye camera cannot be estimated; give its calibration")]
    FocalOfFisheye,
    #[error("a registration graph needs its anchor among its {nodes} worlds; got {anchor}")]
    BadAnchor { anchor: usize, nodes: usize },
    #[error("edge {edge} names world {node}, and there are {nodes}")]
    BadEdge { edge: usize, node: usize, nodes: usize },
}

/// The verdict on an observer's world.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RegistrationStatus {
    /// A transform that explains the views, with an uncertainty inside the limits.
    Registered,
    /// Too little to go on: too few seconds of views, or a configuration that leaves the
    /// transform undetermined (a wearer who never moves or turns, seen from one place).
    NotEnoughMotion,
    /// No transform explains the views (the camera sees someone else, or the wearer's
    /// tracking and the views disagree).
    Inconsistent,
    /// The world the recording gave is kept: its views agree with it (or were not checked).
    AsGiven,
}

impl RegistrationStatus {
    /// The status as written in files and JSON (`"registered"`, `"not-enough-motion"`, …).
    pub fn name(self) -> &'static str {
        match self {
            RegistrationStatus::Registered => "registered",
            RegistrationStatus::NotEnoughMotion => "not-enough-motion",
            RegistrationStatus::Inconsistent => "inconsistent",
            RegistrationStatus::AsGiven => "as-given",
        }
    }

    /// Whether an observer with this verdict may be fused.
    pub fn fusable(self) -> bool {
        matches!(self, RegistrationStatus::Registered | RegistrationStatus::AsGiven)
    }
}

impl std::fmt::Display for RegistrationStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// When a registration is trusted.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct VerdictLimits {
    /// Seconds of views (frames with the target's keypoints) below which nothing is solved.
    pub min_view_s: f64,
    /// Fraction of those frames the transform must explain.
    pub min_inlier_fraction: f64,
    /// 1σ limits of a registered transform.
    pub max_sigma_yaw_deg: f64,
    pub max_sigma_rotation_deg: f64,
    pub max_sigma_translation_m: f64,
    pub max_sigma_clock_s: f64,
    /// A given world agrees with its views when this fraction of frames fit it.
    pub agree_inlier_fraction: f64,
}

impl Default for VerdictLimits {
    fn default() -> Self {
        Self {
            min_view_s: 2.0,
            min_inlier_fraction: 0.5,
            max_sigma_yaw_deg: 2.0,
            max_sigma_rotation_deg: 3.0,
            max_sigma_translation_m: 0.12,
            max_sigma_clock_s: 0.05,
            agree_inlier_fraction: 0.6,
        }
    }
}

/// How to register.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegisterOptions {
    pub dof: Dof,
    /// The observer's clock is searched this far (seconds) either side of the target's; 0:
    /// the clocks are shared.
    pub clock_search_s: f64,
    /// Keypoints scored below this are not used.
    pub min_score: f32,
    /// The detector's pixel noise (1σ) at 1408 px of image width.
    pub pixel_noise_px: f64,
    pub loss: RobustLoss,
    /// A frame fits when its keypoints' median whitened error is below this.
    pub inlier_threshold: f64,
    /// At most this many frames (evenly spread) enter the fit.
    pub max_frames: usize,
    pub ransac_iterations: usize,
    pub seed: u64,
    pub limits: VerdictLimits,
    /// Added in quadrature to the reported 1σ.
    #[serde(default)]
    pub systematic: SystematicSigma,
}

/// The part of a registration's uncertainty the views cannot show: the devices' own tracking
/// drift over the seconds of views, and the coarse body's bias. Measured on simulated sessions
/// (`egoexo eval --perturb-worlds`: without it the errors ran at 2–3.5× the reported σ).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SystematicSigma {
    pub rotation_deg: f64,
    pub translation_m: f64,
}

impl Default for SystematicSigma {
    fn default() -> Self {
        Self { rotation_deg: 0.15, translation_m: 0.02 }
    }
}

impl Default for RegisterOptions {
    fn default() -> Self {
        Self {
            dof: Dof::Four,
            clock_search_s: 0.0,
            min_score: 0.3,
            pixel_noise_px: 3.0,
            loss: RobustLoss::Cauchy { scale: 2.5 },
            inlier_threshold: 3.0,
            max_frames: 1800,
            ransac_iterations: 256,
            seed: 0x5eed_e90e,
            limits: VerdictLimits::default(),
            systematic: SystematicSigma::default(),
        }
    }
}

/// A registration: the transform that maps the observer's world into the target's, its
/// uncertainty, and the verdict.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Registration {
    pub status: RegistrationStatus,
    pub dof: Dof,
    /// `T_target_observerworld`.
    pub transform: RigidTransform,
    /// The transform's heading (degrees; the whole rotation with 4 DoF).
    pub yaw_deg: f64,
    /// `t_target = t_observer + clock_offset_s`.
    pub clock_offset_s: f64,
    /// The camera's focal length found (pixels), when it was estimated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focal_px: Option<f64>,
    /// 1σ of the yaw (degrees), of the whole rotation (degrees), of the translation (metres:
    /// the root of the covariance's trace), of the clock offset (seconds) and focal (pixels);
    /// `None` where the views do not determine them (or nothing was solved).
    pub sigma_yaw_deg: Option<f64>,
    pub sigma_rotation_deg: Option<f64>,
    pub sigma_translation_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_clock_offset_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_focal_px: Option<f64>,
    /// Frames with the target's keypoints that entered the fit, and of those the ones the
    /// transform explains.
    pub frames: usize,
    pub inlier_frames: usize,
    /// Seconds of views, and of views the transform explains.
    pub view_s: f64,
    pub inlier_view_s: f64,
    /// Median angle (degrees) between seen and predicted keypoints on the explained frames.
    pub median_residual_deg: Option<f64>,
    /// Why, in words.
    pub reason: String,
}

impl Registration {
    /// The transform as a yaw (degrees) and translation, and so on, for a world kept as given.
    pub fn as_given(
        frames: usize,
        inlier_frames: usize,
        view_s: f64,
        inlier_view_s: f64,
        median: Option<f64>,
        reason: String,
    ) -> Self {
        Self {
            status: RegistrationStatus::AsGiven,
            dof: Dof::Four,
            transform: RigidTransform::IDENTITY,
            yaw_deg: 0.0,
            clock_offset_s: 0.0,
            focal_px: None,
            sigma_yaw_deg: None,
            sigma_rotation_deg: None,
            sigma_translation_m: None,
            sigma_clock_offset_s: None,
            sigma_focal_px: None,
            frames,
            inlier_frames,
            view_s,
            inlier_view_s,
            median_residual_deg: median,
            reason,
        }
    }

    fn unsolved(status: RegistrationStatus, dof: Dof, frames: usize, view_s: f64, reason: String) -> Self {
        Self { status, dof, ..Self::as_given(frames, 0, view_s, 0.0, None, reason) }
    }

    /// The translation, metres.
    pub fn translation_m(&self) -> [f64; 3] {
        let t = self.transform.translation;
        [f64::from(t.x), f64::from(t.y), f64::from(t.z)]
    }
}

/// How well a given world explains the views.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Agreement {
    pub frames: usize,
    pub inlier_frames: usize,
    pub view_s: f64,
    pub inlier_view_s: f64,
    pub median_residual_deg: Option<f64>,
    /// Enough of the frames fit the given world (the residual test).
    pub fits: bool,
    /// The fit started from the given world stays within its uncertainty of it (or within 1°
    /// and 5 cm).
    pub within_uncertainty: bool,
    /// Both: the views agree with the given world.
    pub agrees: bool,
    /// There were too few seconds of views to tell.
    pub undetermined: bool,
}

/// Checks whether `given` (`T_target_observerworld`, clocks as given) explains the views:
/// enough frames fit it, and the robust fit started from it stays within its own uncertainty
/// of it (a χ² test at 99.9 %, with a floor of 5 cm and 1°, the accuracy registration itself
/// reaches on simulated views with a body of its own estimate — below it no registration is
/// worth its own noise). Cheap: no search, a few iterations from the given world.
pub fn check_agreement(
    track: &TargetTrack,
    view: &ViewTrack,
    given: &RigidTransform,
    options: &RegisterOptions,
) -> Result<Agreement, RegistrationError> {
    let prepared = PreparedView::new(view, options.min_score, options.pixel_noise_px, options.max_frames)?;
    let spec = NodeSpec { dof: options.dof, fixed: false, clock: false, focal: false };
    let anchor = NodeSpec { dof: options.dof, fixed: true, clock: false, focal: false };
    let problem =
        Problem::new(vec![anchor, spec], vec![Edge { observer: 1, target: 0, view: &prepared, track }], options.loss);
    let iso = crate::geometry::isometry(given);
    let given_state = NodeState {
        rotation: iso.rotation.to_rotation_matrix().into_inner(),
        translation: iso.translation.vector,
        ..NodeState::identity()
    };
    let state = vec![NodeState::identity(), given_state];
    let stats = problem.statistics(&state, 0, options.inlier_threshold);
    let frames = prepared.frames.len();
    let view_s = prepared.seconds(0..frames);
    let inlier_view_s = prepared.seconds(stats.inlier_frames.iter().copied());
    let undetermined = view_s < options.limits.min_view_s;
    let fraction = stats.inlier_frames.len() as f64 / stats.usable_frames.max(1) as f64;
    let fits = !undetermined && fraction >= options.limits.agree_inlier_fraction;
    let mut within_uncertainty = false;
    if fits {
        let report = levenberg_marquardt(&problem, state, &LmOptions { max_iterations: 12, ..LmOptions::default() });
        let fitted = &report.state[1];
        let rotation = fitted.rotation * given_state.rotation.transpose();
        let translation = fitted.translation - given_state.translation;
        let omega = nalgebra::Rotation3::from_matrix_unchecked(rotation).scaled_axis();
        let delta: Vec<f64> = match options.dof {
            Dof::Four => vec![omega.y, translation.x, translation.y, translation.z],
            Dof::Six => vec![omega.x, omega.y, omega.z, translation.x, translation.y, translation.z],
        };
        let within_floor = omega.norm() <= 1f64.to_radians() && translation.norm() <= 0.05;
        let chi2 = report.normal.covariance().and_then(|c| c.try_inverse()).map(|inv| {
            let d = nalgebra::DVector::from_vec(delta);
            (d.transpose() * inv * &d)[0]
        });
        // χ² quantiles at 99.9 % for 4 and 6 degrees of freedom.
        let limit = match options.dof {
            Dof::Four => 18.47,
            Dof::Six => 22.46,
        };
        within_uncertainty = within_floor || chi2.is_none_or(|c| c <= limit);
    }
    Ok(Agreement {
        frames,
        inlier_frames: stats.inlier_frames.len(),
        view_s,
        inlier_view_s,
        median_residual_deg: stats.median_angle_rad.is_finite().then(|| stats.median_angle_rad.to_degrees()),
        fits,
        within_uncertainty,
        agrees: fits && within_uncertainty,
        undetermined,
    })
}

/// The candidate starts: clock offsets and focal scales to try.
fn candidates(options: &RegisterOptions, view: &PreparedView) -> (Vec<f64>, Vec<f64>) {
    let clocks = if options.clock_search_s > 0.0 {
        let step = if view.focal_estimated.is_some() { 0.2 } else { 0.1 };
        let n = (options.clock_search_s / step).round() as i64;
        (-n..=n).map(|i| i as f64 * step).collect()
    } else {
        vec![0.0]
    };
    let focals = match view.focal_estimated {
        // Horizontal fields of view from 35° to 120°, as log focal scales against the guess.
        Some((fx, _)) => [35.0f64, 45.0, 55.0, 65.0, 75.0, 90.0, 105.0, 120.0]
            .iter()
            .map(|fov| ((0.5 * view.image_width / (fov.to_radians() * 0.5).tan()) / fx).ln())
            .collect(),
        None => vec![0.0],
    };
    (clocks, focals)
}

/// Below this, the points of the target seen over the view span too little (the second
/// principal extent, metres) to fix a rotation.
const MIN_SEEN_EXTENT_M: f64 = 0.1;

/// The second principal extent (1σ, metres) of the target's points at the times of the
/// view's frames (at the middle of a clock search), for the keypoints the view saw.
fn seen_extent_m(track: &TargetTrack, view: &PreparedView, _clock_search_s: f64) -> f64 {
    let mut points = Vec::new();
    for frame in &view.frames {
        let Some(at) = track.sample(frame.time_s) else { continue };
        for person in &frame.people {
            points.extend(person.observations.iter().filter_map(|o| at[o.k].map(|p| p.position)));
        }
    }
    if points.len() < 3 {
        // Nothing at shared times (a clock far off): let the search decide.
        return f64::INFINITY;
    }
    let n = points.len() as f64;
    let mean = points.iter().sum::<V3>() / n;
    let covariance = points.iter().map(|p| (p - mean) * (p - mean).transpose()).sum::<M3>() / n;
    let mut eigen: Vec<f64> = covariance.symmetric_eigenvalues().iter().copied().collect();
    eigen.sort_by(f64::total_cmp);
    eigen[1].max(0.0).sqrt()
}

/// Registers the observer whose camera made `view` to the target whose body is `track`.
pub fn register(
    track: &TargetTrack,
    view: &ViewTrack,
    options: &RegisterOptions,
) -> Result<Registration, RegistrationError> {
    let prepared = PreparedView::new(view, options.min_score, options.pixel_noise_px, options.max_frames)?;
    Ok(register_prepared(track, &prepared, options))
}

/// The pairwise solve on a prepared view.
pub(crate) fn register_prepared(track: &TargetTrack, view: &PreparedView, options: &RegisterOptions) -> Registration {
    let dof = options.dof;
    let frames = view.frames.len();
    let view_s = view.seconds(0..frames);
    if view_s < options.limits.min_view_s {
        return Registration::unsolved(
            RegistrationStatus::NotEnoughMotion,
            dof,
            frames,
            view_s,
            format!(
                "the camera sees the target for {view_s:.1} s; at least {:.1} s are needed",
                options.limits.min_view_s
            ),
        );
    }
    let extent = seen_extent_m(track, view, options.clock_search_s);
    if extent < MIN_SEEN_EXTENT_M {
        return Registration::unsolved(
            RegistrationStatus::NotEnoughMotion,
            dof,
            frames,
            view_s,
            format!(
                "the target's points in view span {:.0} cm across: a body that neither moves nor turns (and no body pose \
                 to go with the head) does not fix a transform",
                100.0 * extent
            ),
        );
    }
    let (clocks, focals) = candidates(options, view);
    let combos = clocks.len() * focals.len();
    let iterations = if combos > 1 { (options.ransac_iterations / 4).max(48) } else { options.ransac_iterations };
    let mut starts = Vec::new();
    for (ci, &clock) in clocks.iter().enumerate() {
        for (fi, &log_focal) in focals.iter().enumerate() {
            let frames = ransac::correspondences(view, track, clock, log_focal);
            let seed = ransac::derive_seed(options.seed, (ci * 97 + fi) as u64);
            if let Some(scored) = ransac::ransac(&frames, dof, iterations, options.inlier_threshold, seed) {
                starts.push((scored, clock, log_focal));
            }
        }
    }
    starts.sort_by(|a, b| a.0.cost.total_cmp(&b.0.cost));
    if starts.is_empty() {
        return Registration::unsolved(
            RegistrationStatus::NotEnoughMotion,
            dof,
            frames,
            view_s,
            "no frame holds enough of the target's keypoints with its body at that time to start from".into(),
        );
    }
    // The best few distinct starts, each refined.
    let mut chosen: Vec<(ransac::Scored, f64, f64)> = Vec::new();
    for s in starts {
        let distinct = chosen.iter().all(|c| {
            (c.1 - s.1).abs() > 0.25
                || (c.2 - s.2).abs() > 0.05
                || crate::geometry::rotation_angle(&(c.0.hypothesis.rotation.transpose() * s.0.hypothesis.rotation))
                    > 0.2
                || (c.0.hypothesis.translation - s.0.hypothesis.translation).norm() > 0.5
        });
        if distinct {
            chosen.push(s);
        }
        if chosen.len() == 3 {
            break;
        }
    }
    let observer =
        NodeSpec { dof, fixed: false, clock: options.clock_search_s > 0.0, focal: view.focal_estimated.is_some() };
    let anchor = NodeSpec { dof, fixed: true, clock: false, focal: false };
    let problem =
        Problem::new(vec![anchor, observer], vec![Edge { observer: 1, target: 0, view, track }], options.loss);
    let mut refined: Vec<(crate::lsq::LmReport<Vec<NodeState>>, f64)> = chosen
        .iter()
        .map(|(scored, clock, log_focal)| {
            let start = vec![
                NodeState::identity(),
                NodeState {
                    rotation: scored.hypothesis.rotation,
                    translation: scored.hypothesis.translation,
                    clock_s: *clock,
                    log_focal: *log_focal,
                },
            ];
            let report = levenberg_marquardt(&problem, start, &LmOptions::default());
            let clock_ok = report.state[1].clock_s.abs() <= options.clock_search_s + 0.25;
            (report, if clock_ok { 0.0 } else { f64::INFINITY })
        })
        .collect();
    refined.sort_by(|a, b| (a.0.cost + a.1).total_cmp(&(b.0.cost + b.1)));
    let (best, _) = refined.remove(0);
    let state = &best.state[1];

    // Another start that ends elsewhere, almost as well: the views do not tell them apart.
    let ambiguous = refined.iter().any(|(r, penalty)| {
        let other = &r.state[1];
        penalty.is_finite()
            && r.cost <= best.cost * 1.05 + 1.0
            && (crate::geometry::rotation_angle(&(other.rotation.transpose() * state.rotation)) > 10f64.to_radians()
                || (other.translation - state.translation).norm() > 0.5
                || (other.clock_s - state.clock_s).abs() > 0.25)
    });

    let stats = problem.statistics(&best.state, 0, options.inlier_threshold);
    let inlier_view_s = view.seconds(stats.inlier_frames.iter().copied());
    let covariance = best.normal.covariance();
    let sigma = |i: usize| covariance.as_ref().map(|c| c[(i, i)].max(0.0).sqrt());
    let rot_dims = dof.rotation_dims();
    let (sigma_yaw_deg, sigma_rotation_deg) = match dof {
        Dof::Four => (sigma(0).map(f64::to_degrees), sigma(0).map(f64::to_degrees)),
        Dof::Six => (
            sigma(1).map(f64::to_degrees),
            covariance.as_ref().map(|c| (c[(0, 0)] + c[(1, 1)] + c[(2, 2)]).max(0.0).sqrt().to_degrees()),
        ),
    };
    let sigma_translation_m = covariance.as_ref().map(|c| {
        (c[(rot_dims, rot_dims)] + c[(rot_dims + 1, rot_dims + 1)] + c[(rot_dims + 2, rot_dims + 2)]).max(0.0).sqrt()
    });
    // What the views cannot show (the devices' own drift, the coarse body's bias), in quadrature.
    let floor = options.systematic;
    let with_floor = |s: Option<f64>, f: f64| s.map(|s| s.hypot(f));
    let sigma_yaw_deg = with_floor(sigma_yaw_deg, floor.rotation_deg);
    let sigma_rotation_deg = with_floor(sigma_rotation_deg, floor.rotation_deg);
    let sigma_translation_m = with_floor(sigma_translation_m, floor.translation_m);
    let mut next = rot_dims + 3;
    let sigma_clock_offset_s = observer.clock.then(|| sigma(next)).flatten();
    next += usize::from(observer.clock);
    let focal_px = view.focal_estimated.map(|(fx, _)| fx * state.log_focal.exp());
    let sigma_focal_px = focal_px.and_then(|f| sigma(next).map(|s| f * s));

    let inlier_fraction = stats.inlier_frames.len() as f64 / stats.usable_frames.max(1) as f64;
    let limits = &options.limits;
    let too_uncertain = |value: Option<f64>, limit: f64| value.is_none_or(|v| v.is_nan() || v > limit);
    let uncertain = too_uncertain(sigma_yaw_deg, limits.max_sigma_yaw_deg)
        || too_uncertain(
            sigma_rotation_deg,
            if dof == Dof::Four { limits.max_sigma_yaw_deg } else { limits.max_sigma_rotation_deg },
        )
        || too_uncertain(sigma_translation_m, limits.max_sigma_translation_m)
        || (observer.clock && too_uncertain(sigma_clock_offset_s, limits.max_sigma_clock_s));
    let (status, reason) = if uncertain {
        (
            RegistrationStatus::NotEnoughMotion,
            format!(
                "the views leave the transform uncertain (1σ yaw {}, translation {}); the wearer must move or turn more in view",
                sigma_yaw_deg.map_or("undetermined".into(), |s| format!("{s:.1}°")),
                sigma_translation_m.map_or("undetermined".into(), |s| format!("{:.0} cm", 100.0 * s)),
            ),
        )
    } else if inlier_fraction < limits.min_inlier_fraction || inlier_view_s < limits.min_view_s {
        (
            RegistrationStatus::Inconsistent,
            format!(
                "the best transform explains {} of {} frames with comparable points ({:.0} %, {:.1} s); no transform explains the views",
                stats.inlier_frames.len(),
                stats.usable_frames,
                100.0 * inlier_fraction,
                inlier_view_s
            ),
        )
    } else if ambiguous {
        (
            RegistrationStatus::NotEnoughMotion,
            "two different transforms explain the views about equally: the motion seen does not tell them apart".into(),
        )
    } else {
        (
            RegistrationStatus::Registered,
            format!(
                "{} of {} frames ({:.1} s) explained, median residual {:.2}°",
                stats.inlier_frames.len(),
                frames,
                inlier_view_s,
                stats.median_angle_rad.to_degrees()
            ),
        )
    };
    Registration {
        status,
        dof,
        transform: rigid_transform(&state.rotation, &state.translation),
        yaw_deg: heading(&state.rotation).to_degrees(),
        clock_offset_s: state.clock_s,
        focal_px,
        sigma_yaw_deg,
        sigma_rotation_deg,
        sigma_translation_m,
        sigma_clock_offset_s,
        sigma_focal_px,
        frames,
        inlier_frames: stats.inlier_frames.len(),
        view_s,
        inlier_view_s,
        median_residual_deg: stats.median_angle_rad.is_finite().then(|| stats.median_angle_rad.to_degrees()),
        reason,
    }
}

/// `M3`/`V3` of a registration's transform (f64).
pub fn transform_parts(r: &Registration) -> (M3, V3) {
    let iso = crate::geometry::isometry(&r.transform);
    (iso.rotation.to_rotation_matrix().into_inner(), iso.translation.vector)
}
