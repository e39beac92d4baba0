//! `egoexo eval --perturb-worlds`: registration scored on simulated sessions whose observers
//! were moved into worlds of their own (`egoexo_synth::worlds`: any yaw, up to 10 m, ±0.3 m
//! of floor).
//!
//! (a) **Registration error** by seconds of mutual visibility (each observer keeps only its
//! first `T` seconds of frames that see the wearer) and by detector condition: the rotation
//! error (degrees) and the translation error *at the scene* — where the wearer's head was on
//! average while the observer saw them, mapped from the observer's world by the found and the
//! true transform (the origin of a world up to 10 m away says nothing about the rays) — medians over the observers with
//! that much view, the fraction registered, and the fraction registered *wrongly* (more than
//! 5° or 30 cm off: the failure that must not happen).
//!
//! (b) **MPJPE** of ego-exo with the true worlds, the registered ones, and the moved worlds
//! taken as shared (what egoexo did before registration), with ego-only for reference.

use egoexo_core::TrackingMode;
use egoexo_core::ego_features::heading_yaw;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::metrics::MetricsAccumulator;
use egoexo_core::motion::SmplMotion;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::SmplPose;
use egoexo_infer::windows::{WINDOW, plan_windows, valid_spans};
use egoexo_infer::{Engine, Method, ReconstructOptions};
use egoexo_mocap::MotionLibrary;
use egoexo_register::{RegisterSettings, register_session};
use egoexo_session::Session;
use egoexo_session::align::{AlignOptions, align};
use egoexo_session::placement::{RegistrationStatus, WorldRef};
use egoexo_synth::config::DeviceNoise;
use egoexo_synth::config::{DetectorModel, OcclusionConfig};
use egoexo_synth::worlds::{WorldPerturbation, WorldTruth, perturb_observer_worlds, unpose_static_cameras};
use egoexo_synth::{SynthConfig, simulate};
use serde::{Deserialize, Serialize};

use crate::DatasetError;
use crate::shards::mix;

/// Seconds of mutual visibility the table is made for.
pub const VISIBILITY_S: [f64; 4] = [2.0, 5.0, 10.0, 30.0];

/// A registration "registered" this far off the truth is wrong.
pub const WRONG_DEG: f64 = 5.0;
pub const WRONG_M: f64 = 0.3;

/// How the simulated detector behaves in one row group.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DetectorCondition {
    /// No furniture or bystanders, a third of the pixel noise, no confidently wrong keypoints.
    Clean,
    /// The simulator's detector and occlusion as configured for training and evaluation.
    Simulator,
    /// Twice the pixel noise, three times the misses, more furniture and bystanders, most
    /// occlusion episodes confidently wrong.
    Harsh,
}

impl DetectorCondition {
    pub const ALL: [DetectorCondition; 3] =
        [DetectorCondition::Clean, DetectorCondition::Simulator, DetectorCondition::Harsh];

    pub fn name(self) -> &'static str {
        match self {
            DetectorCondition::Clean => "clean",
            DetectorCondition::Simulator => "simulator",
            DetectorCondition::Harsh => "harsh",
        }
    }

    fn apply(self, config: &mut SynthConfig) {
        let (detector, occlusion) = (&mut config.detector, &mut config.occlusion);
        match self {
            DetectorCondition::Clean => {
                *detector = DetectorModel {
                    pixel_noise_base_px: detector.pixel_noise_base_px / 3.0,
                    pixel_noise_per_metre_px: detector.pixel_noise_per_metre_px / 3.0,
                    occluded_confident_probability: 0.0,
                    ..detector.clone()
                };
                *occlusion = OcclusionConfig { furniture_probability: 0.0, max_bystanders: 0, ..occlusion.clone() };
            }
            DetectorCondition::Simulator => {}
            DetectorCondition::Harsh => {
                *detector = DetectorModel {
                    pixel_noise_base_px: detector.pixel_noise_base_px * 2.0,
                    pixel_noise_per_metre_px: detector.pixel_noise_per_metre_px * 2.0,
                    keypoint_miss_probability: (detector.keypoint_miss_probability * 3.0).min(0.5),
                    frame_miss_probability: (detector.frame_miss_probability * 3.0).min(0.5),
                    occluded_confident_probability: 0.9,
                    ..detector.clone()
                };
                *occlusion = OcclusionConfig { furniture_probability: 0.9, max_bystanders: 4, ..occlusion.clone() };
            }
        }
    }
}

/// What to evaluate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegistrationEvalOptions {
    pub subjects: Vec<u32>,
    pub observers: usize,
    pub tracking: TrackingMode,
    pub seed: u64,
    pub visibility_s: Vec<f64>,
    pub conditions: Vec<DetectorCondition>,
    /// Also reconstruct (ego-only, ego-exo with true / registered / moved-as-shared worlds).
    pub mpjpe: bool,
    /// The observers are static cameras that know nothing of their pose
    /// (`ObserverBehaviour::static_camera`, `unpose_static_cameras`; focal length known):
    /// registered in 6 DoF instead of moved by a yaw and a translation.
    #[serde(default)]
    pub static_cameras: bool,
}

/// One row of table (a).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegistrationRow {
    pub condition: DetectorCondition,
    pub visibility_s: f64,
    /// Observers with at least that many seconds of views.
    pub observers: usize,
    pub registered_fraction: f64,
    /// Registered more than [`WRONG_DEG`] or [`WRONG_M`] off.
    pub wrong_fraction: f64,
    /// Medians over the registered observers (`None`: none registered).
    pub median_rotation_deg: Option<f64>,
    pub median_translation_cm: Option<f64>,
    pub p90_rotation_deg: Option<f64>,
    pub p90_translation_cm: Option<f64>,
    /// Median of the reported 1σ yaw over the registered, and of |error| / σ (1 means the
    /// reported uncertainty is honest on average).
    pub median_sigma_yaw_deg: Option<f64>,
    pub median_error_over_sigma: Option<f64>,
}

/// Table (b): MPJPE (cm) per way of treating the observers' worlds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorldMpjpe {
    pub sessions: usize,
    pub frames: usize,
    pub ego_only_cm: f64,
    pub true_worlds_cm: f64,
    pub registered_cm: f64,
    /// The moved worlds fused as if they were the wearer's (no registration, no check).
    pub moved_as_shared_cm: f64,
}

/// The whole report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegistrationReport {
    pub subjects: Vec<u32>,
    pub clips: usize,
    /// Sessions the clips were chained into ([`chain_clips`]).
    pub sessions: usize,
    pub seconds: f64,
    pub tracking: u8,
    /// The observers were static cameras without pose (6 DoF).
    #[serde(default)]
    pub static_cameras: bool,
    pub rows: Vec<RegistrationRow>,
    pub mpjpe: Option<WorldMpjpe>,
    /// With the MPJPE table: milliseconds of registering a session with all its views, and of
    /// its ego-exo reconstruction (alignment and scoring included), medians.
    pub median_register_ms: Option<f64>,
    pub median_reconstruct_ms: Option<f64>,
}

/// The held-out subjects' clips are a few seconds each (the library cuts trials at corrupt
/// frames); seconds of visibility up to 30 need longer sessions: each subject's clips, in
/// library order, chained into walks of at least `min_seconds` (the last may be shorter).
/// Each clip is turned and moved so that it starts where and facing as the one before ended
/// (the body's pose jumps between clips; the wearer does not teleport).
pub fn chain_clips(
    library: &MotionLibrary,
    clips: &[usize],
    min_seconds: f32,
) -> Result<Vec<(String, SmplMotion)>, DatasetError> {
    let mut chains: Vec<(String, SmplMotion)> = Vec::new();
    let mut current: Option<(String, SmplMotion)> = None;
    for &clip in clips {
        let info = &library.clips()[clip];
        let motion = library.motion(clip).map_err(|e| DatasetError::Library(e.to_string()))?;
        let starts_new = current.as_ref().is_none_or(|(label, m)| {
            !label.starts_with(&format!("{:02}_", info.subject)) || m.poses.len() as f32 / m.fps >= min_seconds
        });
        if starts_new {
            if let Some(done) = current.take() {
                chains.push(done);
            }
            current = Some((info.label(), motion));
            continue;
        }
        let Some((label, chain)) = current.as_mut() else { continue };
        let (Some(last), Some(first)) = (chain.poses.last().copied(), motion.poses.first().copied()) else { continue };
        let turn = Quat::from_rotation_y(heading_yaw(last.root_orientation) - heading_yaw(first.root_orientation));
        let offset = last.translation - turn * first.translation;
        chain.poses.extend(motion.poses.iter().map(|p| SmplPose {
            root_orientation: turn * p.root_orientation,
            translation: Vec3::new(offset.x, 0.0, offset.z) + turn * p.translation,
            ..*p
        }));
        label.push('+');
        label.push_str(&info.label());
    }
    chains.extend(current);
    Ok(chains)
}

/// One observer's registration against the truth: verdict, rotation error (°), translation
/// error at the scene (m), reported 1σ yaw (°).
type Outcome = (RegistrationStatus, f64, f64, Option<f64>);

/// Keeps the first `seconds` of frames in which each observer sees the wearer (frames with
/// any keypoint); `None` for an observer with less than that.
fn limit_views(session: &mut Session, seconds: f64, fps: f64) -> Vec<bool> {
    let keep = (seconds * fps).round() as usize;
    session
        .observers
        .iter_mut()
        .map(|o| {
            let Some(k) = &mut o.keypoints else { return false };
            let seen: Vec<usize> =
                (0..k.frames.len()).filter(|&i| k.frames[i].iter().filter(|p| p.is_some()).count() >= 3).collect();
            if seen.len() < keep {
                return false;
            }
            let last = seen[keep - 1];
            k.timestamps_ns.truncate(last + 1);
            k.frames.truncate(last + 1);
            true
        })
        .collect()
}

/// Where the wearer's head was on average (session world) while `observer` saw them: the
/// place the registration is about, and where its error matters to the rays.
fn wearer_seen_at(session: &Session, observer: &egoexo_session::model::Observer) -> Vec3 {
    let head = &session.wearer.head;
    let range = observer.keypoints.as_ref().and_then(|k| Some((*k.timestamps_ns.first()?, *k.timestamps_ns.last()?)));
    let (sum, n) = head
        .timestamps_ns
        .iter()
        .zip(&head.poses)
        .filter(|(t, _)| range.is_none_or(|(a, b)| (a..=b).contains(*t)))
        .fold((Vec3::ZERO, 0usize), |(s, n), (_, p)| (s + p.translation, n + 1));
    sum / n.max(1) as f32
}

/// Rotation error (degrees) and translation error at `scene` (metres) of a found
/// `T_session_observerworld` against the truth.
pub fn registration_error(found: &RigidTransform, truth: &WorldTruth, scene: Vec3) -> (f64, f64) {
    let rotation = f64::from(found.rotation.angle_between(truth.t_session_world.rotation).to_degrees());
    let own = truth.t_session_world.inverse().transform_point(scene);
    (rotation, f64::from(found.transform_point(own).distance(scene)))
}

fn percentile(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let i = ((values.len() - 1) as f64 * q).round() as usize;
    Some(values[i])
}

/// MPJPE (cm) of `method` on `session` over non-overlapping windows, with the frames scored.
fn mpjpe(
    engine: &Engine,
    session: &Session,
    method: Method,
    tracking: TrackingMode,
) -> Result<(f64, usize), DatasetError> {
    let aligned = align(session, &AlignOptions::default()).map_err(|e| DatasetError::Simulate(e.to_string()))?;
    let options = ReconstructOptions {
        method,
        tracking: Some(tracking),
        stride: WINDOW,
        non_overlapping: true,
        floor_contact: true,
    };
    let recon = engine
        .reconstruct(&aligned, &options, &mut |_| true)
        .map_err(|e| DatasetError::Reconstruct { method: method.to_string(), message: e.to_string() })?;
    let gt = aligned.ground_truth.as_ref().ok_or(DatasetError::NoGroundTruth)?;
    let truth: Vec<_> = gt.poses.iter().map(|p| aligned.skeleton.forward_kinematics(p).positions).collect();
    let mut acc = MetricsAccumulator::new();
    for segment in plan_windows(&valid_spans(&aligned.head.valid), WINDOW, true) {
        let range = segment.frames.clone();
        acc.add_segment(&recon.joints[range.clone()], &truth[range], aligned.timeline.fps, None)
            .map_err(|e| DatasetError::Options(e.to_string()))?;
    }
    let m = acc.finish().ok_or_else(|| DatasetError::Options("no frame to score".into()))?;
    Ok((m.mpjpe_cm, m.frames))
}

/// Runs the evaluation. `clock()` gives milliseconds (the caller's), for the timings;
/// `progress(done, total)` counts sessions.
pub fn evaluate_registration(
    library: &MotionLibrary,
    engine: &Engine,
    options: &RegistrationEvalOptions,
    clock: &mut dyn FnMut() -> f64,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<RegistrationReport, DatasetError> {
    let clips = library.clips_of_subjects(&options.subjects);
    if clips.is_empty() {
        return Err(DatasetError::Options(format!("the library has no clips of subjects {:?}", options.subjects)));
    }
    let fps = f64::from(library.fps());
    let longest = options.visibility_s.iter().copied().fold(0.0, f64::max);
    let chains = chain_clips(library, &clips, (longest * 1.3) as f32)?;
    let settings = RegisterSettings::default();
    // Per (condition, visibility): errors and verdicts.
    let groups = options.conditions.len() * options.visibility_s.len();
    let mut outcomes: Vec<Vec<Outcome>> = vec![Vec::new(); groups];
    let (mut register_ms, mut reconstruct_ms) = (Vec::new(), Vec::new());
    let mut sums = [0.0f64; 4];
    let mut scored_frames = 0usize;
    let total = chains.len() * options.conditions.len();
    let mut done = 0;
    for (chain, (label, motion)) in chains.iter().enumerate() {
        for (c, &condition) in options.conditions.iter().enumerate() {
            let mut config =
                SynthConfig { tracking: options.tracking, observers: options.observers, ..SynthConfig::default() };
            condition.apply(&mut config);
            if options.static_cameras {
                // A tripod's pose is exact: the truth is where it stands.
                config.observer.static_camera = true;
                config.observer_noise = DeviceNoise::none();
            }
            let seed = mix(options.seed, chain as u64, 0x5e61);
            let original =
                simulate(motion, label, &config, seed).map_err(|e| DatasetError::Simulate(e.to_string()))?.session;
            let mut moved = original.clone();
            let truth = if options.static_cameras {
                unpose_static_cameras(&mut moved, true)
            } else {
                perturb_observer_worlds(&mut moved, &WorldPerturbation::default(), seed)
            };
            for (v, &seconds) in options.visibility_s.iter().enumerate() {
                let mut limited = moved.clone();
                let kept = limit_views(&mut limited, seconds, fps);
                let report = register_session(Some(engine), options.tracking, &mut limited, &settings)
                    .map_err(|e| DatasetError::Reconstruct { method: "registration".into(), message: e.to_string() })?;
                for (o, ((r, t), kept)) in report.observers.iter().zip(&truth).zip(&kept).enumerate() {
                    let Some(found) = r.registration.as_ref().filter(|_| *kept) else { continue };
                    let scene = wearer_seen_at(&original, &limited.observers[o]);
                    let (rot, trans) = registration_error(&found.transform, t, scene);
                    outcomes[c * options.visibility_s.len() + v].push((found.status, rot, trans, found.sigma_yaw_deg));
                }
            }
            if options.mpjpe && condition == DetectorCondition::Simulator {
                let mut registered = moved.clone();
                let started = clock();
                register_session(Some(engine), options.tracking, &mut registered, &settings)
                    .map_err(|e| DatasetError::Reconstruct { method: "registration".into(), message: e.to_string() })?;
                register_ms.push(clock() - started);
                let mut as_shared = moved.clone();
                for o in &mut as_shared.observers {
                    o.placement.world = WorldRef::Shared;
                }
                let (ego, frames) = mpjpe(engine, &original, Method::EgoOnly, options.tracking)?;
                let started = clock();
                let (true_worlds, _) = mpjpe(engine, &original, Method::EgoExo, options.tracking)?;
                reconstruct_ms.push(clock() - started);
                let (reg, _) = mpjpe(engine, &registered, Method::EgoExo, options.tracking)?;
                let (naive, _) = mpjpe(engine, &as_shared, Method::EgoExo, options.tracking)?;
                for (sum, value) in sums.iter_mut().zip([ego, true_worlds, reg, naive]) {
                    *sum += value * frames as f64;
                }
                scored_frames += frames;
            }
            done += 1;
            progress(done, total);
        }
    }
    let mut rows = Vec::new();
    for (c, &condition) in options.conditions.iter().enumerate() {
        for (v, &visibility_s) in options.visibility_s.iter().enumerate() {
            let group = &outcomes[c * options.visibility_s.len() + v];
            let registered: Vec<_> = group.iter().filter(|o| o.0 == RegistrationStatus::Registered).collect();
            let n = group.len().max(1) as f64;
            let mut rot: Vec<f64> = registered.iter().map(|o| o.1).collect();
            let mut trans: Vec<f64> = registered.iter().map(|o| o.2 * 100.0).collect();
            let mut sigma: Vec<f64> = registered.iter().filter_map(|o| o.3).collect();
            let mut ratio: Vec<f64> =
                registered.iter().filter_map(|o| o.3.filter(|s| *s > 0.0).map(|s| o.1 / s)).collect();
            rows.push(RegistrationRow {
                condition,
                visibility_s,
                observers: group.len(),
                registered_fraction: registered.len() as f64 / n,
                wrong_fraction: registered.iter().filter(|o| o.1 > WRONG_DEG || o.2 > WRONG_M).count() as f64 / n,
                median_rotation_deg: percentile(&mut rot, 0.5),
                median_translation_cm: percentile(&mut trans, 0.5),
                p90_rotation_deg: percentile(&mut rot, 0.9),
                p90_translation_cm: percentile(&mut trans, 0.9),
                median_sigma_yaw_deg: percentile(&mut sigma, 0.5),
                median_error_over_sigma: percentile(&mut ratio, 0.5),
            });
        }
    }
    let weighted = |i: usize| if scored_frames > 0 { sums[i] / scored_frames as f64 } else { f64::NAN };
    Ok(RegistrationReport {
        subjects: options.subjects.clone(),
        clips: clips.len(),
        sessions: chains.len(),
        seconds: chains.iter().map(|(_, m)| m.poses.len() as f64 / f64::from(m.fps)).sum(),
        tracking: options.tracking.points(),
        static_cameras: options.static_cameras,
        rows,
        mpjpe: (options.mpjpe && scored_frames > 0).then(|| WorldMpjpe {
            sessions: chains.len(),
            frames: scored_frames,
            ego_only_cm: weighted(0),
            true_worlds_cm: weighted(1),
            registered_cm: weighted(2),
            moved_as_shared_cm: weighted(3),
        }),
        median_register_ms: percentile(&mut register_ms, 0.5),
        median_reconstruct_ms: percentile(&mut reconstruct_ms, 0.5),
    })
}

/// The report as the model card's tables.
pub fn format_registration_table(report: &RegistrationReport) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let what = if report.static_cameras {
        "static cameras without pose (6 DoF: their pose in the wearer's world; focal length known)"
    } else {
        "observers moved into worlds of their own (any yaw, ≤ 10 m, ±0.3 m floor)"
    };
    let _ = writeln!(
        out,
        "Registration of {what}: {} clips of subjects {:?} chained into {} sessions ({:.0} s), {}-point",
        report.clips, report.subjects, report.sessions, report.seconds, report.tracking
    );
    let _ = writeln!(
        out,
        "\n| detector | views (s) | observers | registered | wrong | rotation median / p90 (°) | translation at the scene median / p90 (cm) | σ yaw median (°) | error/σ median |"
    );
    let _ = writeln!(out, "|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let f = |v: Option<f64>, digits: usize| v.map_or("–".to_owned(), |v| format!("{v:.digits$}"));
    for r in &report.rows {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {:.0} % | {:.1} % | {} / {} | {} / {} | {} | {} |",
            r.condition.name(),
            r.visibility_s,
            r.observers,
            100.0 * r.registered_fraction,
            100.0 * r.wrong_fraction,
            f(r.median_rotation_deg, 2),
            f(r.p90_rotation_deg, 2),
            f(r.median_translation_cm, 1),
            f(r.p90_translation_cm, 1),
            f(r.median_sigma_yaw_deg, 2),
            f(r.median_error_over_sigma, 1),
        );
    }
    if let Some(m) = &report.mpjpe {
        let _ =
            writeln!(out, "\nMPJPE (cm), {} sessions, {} frames, simulator detector, all views:", m.sessions, m.frames);
        let _ = writeln!(out, "\n| observers' worlds | MPJPE (cm) |\n|---|---:|");
        let _ = writeln!(out, "| ego-only (no observers) | {:.2} |", m.ego_only_cm);
        let _ = writeln!(out, "| ego-exo, true worlds | {:.2} |", m.true_worlds_cm);
        let _ = writeln!(
            out,
            "| ego-exo, registered | {:.2} ({:+.1} % against the true worlds) |",
            m.registered_cm,
            100.0 * (m.registered_cm / m.true_worlds_cm - 1.0)
        );
        let _ = writeln!(out, "| ego-exo, moved worlds fused as given | {:.2} |", m.moved_as_shared_cm);
    }
    if let (Some(register), Some(reconstruct)) = (report.median_register_ms, report.median_reconstruct_ms) {
        let _ = writeln!(
            out,
            "\nPer session (medians): registration {register:.0} ms, ego-exo reconstruction {reconstruct:.0} ms ({:.1} % added).",
            100.0 * register / reconstruct
        );
    }
    out
}
