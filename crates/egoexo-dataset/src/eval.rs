//! `egoexo eval`: simulate sessions from chosen subjects, reconstruct them through the engine
//! the app uses (non-overlapping 96-frame segments, the paper's protocol), and score every
//! method with the paper's metrics — on all frames and on the occluded-frames subset.
//!
//! A frame is *occluded* when at least one of its exo keypoints is hidden from at least one
//! observer by furniture or a bystander (the simulator's labels).
//!
//! Differences of a tenth of a centimetre decide whether the observers or the gate help, so
//! the report also compares the networks' rows clip by clip ([`PairedComparison`]): the mean
//! difference and a 95 % bootstrap interval over clips, which says whether a difference is
//! larger than what the choice of clips alone would produce.

use egoexo_core::TrackingMode;
use egoexo_core::aligned::AlignedSession;
use egoexo_core::ego_features::EGO_FEATURE_DIM;
use egoexo_core::foot_contact::{FOOT_JOINTS, FootContactAccumulator, FootContactMetrics, sole_offset_m};
use egoexo_core::metrics::{MetricsAccumulator, MotionMetrics};
use egoexo_infer::baselines::NearestNeighbourIndex;
use egoexo_infer::inputs::{POSE_DIM, ego_window, window_targets};
use egoexo_infer::windows::{WINDOW, plan_windows, valid_spans};
use egoexo_infer::{Engine, LoadedModels, Method, ReconstructOptions};
use egoexo_mocap::MotionLibrary;
use egoexo_session::align::{AlignOptions, align};
use egoexo_synth::rng::SimRng;
use egoexo_synth::{SynthConfig, simulate};
use serde::{Deserialize, Serialize};

use crate::DatasetError;
use crate::shards::{WristKind, mix};

/// What to evaluate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalOptions {
    pub subjects: Vec<u32>,
    pub observers: usize,
    pub tracking: TrackingMode,
    /// How 3-point wrists are simulated (devices, or hand tracking that comes and goes).
    #[serde(default)]
    pub wrists: WristKind,
    /// Only clips whose head drops at least this far below the subject's standing head
    /// height (crouching, kneeling, sitting, lying), metres ([`head_drop_m`]).
    #[serde(default)]
    pub min_head_drop_m: Option<f32>,
    /// Apply the floor constraint to every method (the engine's default; off to measure the
    /// networks alone).
    #[serde(default = "yes")]
    pub floor_contact: bool,
    pub seed: u64,
    pub methods: Vec<Method>,
}

fn yes() -> bool {
    true
}

/// One table row: a method and the core's metric row (flattened in JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalRow {
    pub method: Method,
    #[serde(flatten)]
    pub metrics: MotionMetrics,
}

/// A method's feet against the floor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FootRow {
    pub method: Method,
    #[serde(flatten)]
    pub metrics: FootContactMetrics,
}

/// The result, in the shape `egoexo eval --json` prints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// 1 or 3.
    pub tracking: u8,
    /// How the 3-point wrists were simulated.
    #[serde(default)]
    pub wrists: WristKind,
    /// Mean fraction of the frames on which each wrist was tracked (left, right); 1 for wrist
    /// devices, 0 in 1-point mode.
    #[serde(default)]
    pub wrist_coverage: [f32; 2],
    /// Whether the floor constraint was applied.
    #[serde(default = "yes")]
    pub floor_contact: bool,
    /// Clips reconstructed with the 1-point model because no wrist was ever tracked (hand
    /// tracking only).
    #[serde(default)]
    pub one_point_clips: usize,
    pub observers: usize,
    pub subjects: Vec<u32>,
    pub clips: usize,
    pub frames: usize,
    pub occluded_frames: usize,
    pub rows: Vec<EvalRow>,
    pub occluded_rows: Vec<EvalRow>,
    /// The true motion scored against itself on the same frames (all, occluded): its jitter is
    /// the smoothness a faithful reconstruction should have — jitter far below it means
    /// over-smoothed motion, above it shaky motion. `None` when no segment has 4 frames.
    pub ground_truth: Option<MotionMetrics>,
    pub occluded_ground_truth: Option<MotionMetrics>,
    /// Feet against the simulated floor per method ([`egoexo_core::foot_contact`]): how far
    /// they go through it and how much they slide while standing on it.
    #[serde(default)]
    pub feet: Vec<FootRow>,
    /// The true motion's feet on the same frames (its skating is the foot's own roll).
    #[serde(default)]
    pub ground_truth_feet: Option<FootContactMetrics>,
    /// Clip-paired comparisons between the networks' rows ([`COMPARED_METHODS`]), on all and
    /// on occluded frames; empty without networks.
    #[serde(default)]
    pub paired: Vec<PairedComparison>,
}

/// The pairs `(method, baseline)` the report compares clip by clip when both were evaluated:
/// the observers' effect and the gate's.
pub const COMPARED_METHODS: [(Method, Method); 2] =
    [(Method::EgoExo, Method::EgoOnly), (Method::EgoExo, Method::EgoExoUngated)];

/// Bootstrap resamples of the clips behind each [`Interval`].
pub const BOOTSTRAP_RESAMPLES: usize = 2000;

/// `method` minus `baseline` on the same frames of the same clips (negative: `method` has the
/// lower error).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairedComparison {
    pub method: Method,
    pub baseline: Method,
    /// `false`: all frames; `true`: the occluded frames.
    pub occluded: bool,
    /// Clips with at least one such frame.
    pub clips: usize,
    /// Difference of MPJPE, cm.
    pub mpjpe_cm: Interval,
    /// Difference of lower-body position error, cm.
    pub lower_cm: Interval,
}

/// A frame-weighted mean over clips with its 95 % percentile-bootstrap interval (clips
/// resampled with replacement).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    pub mean: f64,
    pub low: f64,
    pub high: f64,
}

/// The frame-weighted mean of per-clip `values` (`weights`: each clip's frame count) and its
/// 95 % percentile-bootstrap interval from `resamples` draws of the clips with replacement.
/// `None` when the weights sum to zero or the lengths differ.
pub fn bootstrap_weighted_mean(
    weights: &[f64],
    values: &[f64],
    resamples: usize,
    rng: &mut SimRng,
) -> Option<Interval> {
    let weighted_mean = |picks: &mut dyn Iterator<Item = usize>| {
        let (mut sum, mut weight) = (0.0, 0.0);
        for i in picks {
            sum += weights[i] * values[i];
            weight += weights[i];
        }
        (weight > 0.0).then(|| sum / weight)
    };
    if weights.len() != values.len() || weights.is_empty() {
        return None;
    }
    let n = weights.len();
    let mean = weighted_mean(&mut (0..n))?;
    let mut draws: Vec<f64> =
        (0..resamples).filter_map(|_| weighted_mean(&mut (0..n).map(|_| rng.int(0, n - 1)))).collect();
    if draws.is_empty() {
        return Some(Interval { mean, low: mean, high: mean });
    }
    draws.sort_by(f64::total_cmp);
    let at = |q: f64| draws[((q * (draws.len() - 1) as f64).round() as usize).min(draws.len() - 1)];
    Some(Interval { mean, low: at(0.025), high: at(0.975) })
}

/// Each evaluated method's metrics per clip (all frames, occluded frames; `None` where the
/// clip has no such frame).
type ClipMetrics = Vec<[Option<MotionMetrics>; 2]>;

fn paired_comparisons(methods: &[Method], per_clip: &[ClipMetrics], seed: u64) -> Vec<PairedComparison> {
    let mut out = Vec::new();
    for (method, baseline) in COMPARED_METHODS {
        let (Some(a), Some(b)) =
            (methods.iter().position(|&m| m == method), methods.iter().position(|&m| m == baseline))
        else {
            continue;
        };
        for (subset, occluded) in [(0, false), (1, true)] {
            let (mut weights, mut mpjpe, mut lower) = (Vec::new(), Vec::new(), Vec::new());
            for (ma, mb) in per_clip[a].iter().zip(&per_clip[b]) {
                if let (Some(ma), Some(mb)) = (&ma[subset], &mb[subset]) {
                    weights.push(ma.frames as f64);
                    mpjpe.push(ma.mpjpe_cm - mb.mpjpe_cm);
                    lower.push(ma.lower_cm - mb.lower_cm);
                }
            }
            // The same resampled clips for both metrics.
            let stream = mix(seed, 0xB007, (a * 8 + b * 2 + subset) as u64);
            let (Some(mpjpe_cm), Some(lower_cm)) = (
                bootstrap_weighted_mean(&weights, &mpjpe, BOOTSTRAP_RESAMPLES, &mut SimRng::new(stream)),
                bootstrap_weighted_mean(&weights, &lower, BOOTSTRAP_RESAMPLES, &mut SimRng::new(stream)),
            ) else {
                continue;
            };
            out.push(PairedComparison { method, baseline, occluded, clips: weights.len(), mpjpe_cm, lower_cm });
        }
    }
    out
}

/// How far the head joint drops below the skeleton's standing head height over a motion,
/// metres: the standing height minus the lowest height of the head above the clip's floor
/// (its lowest foot joint over the whole clip), so a crouch counts and a jump does not.
pub fn head_drop_m(motion: &egoexo_core::motion::SmplMotion) -> f32 {
    let fk: Vec<_> = motion.poses.iter().map(|p| motion.skeleton.forward_kinematics(p).positions).collect();
    let floor = fk.iter().flat_map(|p| FOOT_JOINTS.map(|j| p[j].y)).fold(f32::INFINITY, f32::min);
    let head = egoexo_core::skeleton::SmplJoint::Head.index();
    let lowest_head = fk.iter().map(|p| p[head].y).fold(f32::INFINITY, f32::min);
    motion.skeleton.head_height() - (lowest_head - floor)
}

/// Simulates and aligns clip `clip` for evaluation (deterministic in `seed` and the clip).
pub fn evaluation_session(
    library: &MotionLibrary,
    clip: usize,
    tracking: TrackingMode,
    wrists: WristKind,
    observers: usize,
    seed: u64,
) -> Result<AlignedSession, DatasetError> {
    let info = library.clips().get(clip).ok_or_else(|| DatasetError::Options(format!("no clip {clip}")))?;
    let motion = library.motion(clip).map_err(|e| DatasetError::Library(e.to_string()))?;
    let config =
        SynthConfig { tracking, wrists: wrists.for_simulation(clip as u64), observers, ..SynthConfig::default() };
    let sim = simulate(&motion, &info.label(), &config, mix(seed, clip as u64, 0xE7A1))
        .map_err(|e| DatasetError::Simulate(e.to_string()))?;
    align(&sim.session, &AlignOptions { fps: library.fps(), ..AlignOptions::default() })
        .map_err(|e| DatasetError::Simulate(e.to_string()))
}

/// The nearest-neighbour baseline's index over `subjects` (one simulation per clip, every
/// `subsample`-th frame).
pub fn nearest_neighbour_index(
    library: &MotionLibrary,
    subjects: &[u32],
    tracking: TrackingMode,
    seed: u64,
    subsample: usize,
) -> Result<NearestNeighbourIndex, DatasetError> {
    let (mut features, mut poses) = (Vec::new(), Vec::new());
    for clip in library.clips_of_subjects(subjects) {
        let aligned =
            evaluation_session(library, clip, tracking, WristKind::Devices, 0, mix(seed, 0x4E4E, clip as u64))?;
        for plan in plan_windows(&valid_spans(&aligned.head.valid), WINDOW, true) {
            let window = ego_window(&aligned, &plan, tracking).map_err(|e| DatasetError::Simulate(e.to_string()))?;
            let Some(targets) = window_targets(&aligned, &window) else { continue };
            for t in (0..plan.len()).step_by(subsample.max(1)) {
                features.extend_from_slice(&window.ego[t * EGO_FEATURE_DIM..(t + 1) * EGO_FEATURE_DIM]);
                poses.extend_from_slice(&targets[t * POSE_DIM..(t + 1) * POSE_DIM]);
            }
        }
    }
    NearestNeighbourIndex::build(&features, &poses).ok_or_else(|| {
        DatasetError::Options(format!("no training frames for the nearest-neighbour index (subjects {subjects:?})"))
    })
}

/// Runs the evaluation. `progress(done, total)` counts clips.
pub fn evaluate(
    library: &MotionLibrary,
    engine: &Engine,
    options: &EvalOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<EvalReport, DatasetError> {
    let mut clips = library.clips_of_subjects(&options.subjects);
    if clips.is_empty() {
        return Err(DatasetError::Options(format!("the library has no clips of subjects {:?}", options.subjects)));
    }
    if let Some(drop) = options.min_head_drop_m {
        let mut kept = Vec::new();
        for clip in clips {
            let motion = library.motion(clip).map_err(|e| DatasetError::Library(e.to_string()))?;
            if head_drop_m(&motion) >= drop {
                kept.push(clip);
            }
        }
        if kept.is_empty() {
            return Err(DatasetError::Options(format!(
                "no clip of subjects {:?} lowers the head by {drop} m or more",
                options.subjects
            )));
        }
        clips = kept;
    }
    let mut all: Vec<MetricsAccumulator> = options.methods.iter().map(|_| MetricsAccumulator::new()).collect();
    let mut occluded: Vec<MetricsAccumulator> = options.methods.iter().map(|_| MetricsAccumulator::new()).collect();
    let mut feet: Vec<FootContactAccumulator> = options.methods.iter().map(|_| FootContactAccumulator::new()).collect();
    let mut truth_feet = FootContactAccumulator::new();
    let (mut truth, mut occluded_truth) = (MetricsAccumulator::new(), MetricsAccumulator::new());
    let mut per_clip: Vec<ClipMetrics> = options.methods.iter().map(|_| Vec::with_capacity(clips.len())).collect();
    let (mut frames, mut occluded_frames) = (0, 0);
    // Hand-tracking wrists: each session's own choice (3-point when a hand was ever seen,
    // else 1-point), as a real recording gets.
    let session_tracking = match options.wrists {
        WristKind::Devices => Some(options.tracking),
        WristKind::HandTracking | WristKind::Mixed => None,
    };
    let protocol = ReconstructOptions {
        method: Method::RestPose,
        tracking: session_tracking,
        stride: WINDOW,
        non_overlapping: true,
        floor_contact: options.floor_contact,
    };
    // Frame-weighted wrist coverage over the clips' timelines.
    let (mut wrist_frames, mut timeline_frames, mut one_point_clips) = ([0.0f64; 2], 0.0f64, 0usize);
    for (done, &clip) in clips.iter().enumerate() {
        let aligned =
            evaluation_session(library, clip, options.tracking, options.wrists, options.observers, options.seed)?;
        for (sum, coverage) in wrist_frames.iter_mut().zip(aligned.wrist_coverage()) {
            *sum += f64::from(coverage.unwrap_or(0.0)) * aligned.timeline.frames as f64;
        }
        timeline_frames += aligned.timeline.frames as f64;
        one_point_clips += usize::from(session_tracking.is_none() && aligned.tracking_mode() == TrackingMode::OnePoint);
        let gt = aligned.ground_truth.as_ref().ok_or(DatasetError::NoGroundTruth)?;
        let gt_joints: Vec<_> = gt.poses.iter().map(|p| aligned.skeleton.forward_kinematics(p).positions).collect();
        let hidden: Vec<bool> = (0..aligned.timeline.frames)
            .map(|f| gt.occluded.iter().any(|o| o.get(f).is_some_and(|m| *m != 0)))
            .collect();
        let segments = plan_windows(&valid_spans(&aligned.head.valid), WINDOW, true);
        frames += segments.iter().map(|s| s.len()).sum::<usize>();
        occluded_frames +=
            segments.iter().map(|s| hidden[s.frames.clone()].iter().filter(|&&h| h).count()).sum::<usize>();
        // The simulator's floor; soles sit below the foot joints in proportion to the body.
        let floor_y =
            aligned.floor_y.ok_or_else(|| DatasetError::Options("a simulated session without a floor".into()))?;
        let sole_offset = sole_offset_m(&aligned.skeleton);
        for segment in &segments {
            let range = segment.frames.clone();
            let (joints, fps) = (&gt_joints[range.clone()], aligned.timeline.fps);
            truth.add_segment(joints, joints, fps, None)?;
            occluded_truth.add_segment(joints, joints, fps, Some(&hidden[range]))?;
            truth_feet.add_segment(joints, joints, fps, floor_y, sole_offset);
        }
        // Methods sharing a coarse pose share one ego pass (EgoNet once per window).
        let reconstructions =
            engine.reconstruct_each(&aligned, &protocol, &options.methods, &mut |_| true).map_err(|e| {
                DatasetError::Reconstruct { method: method_names(&options.methods), message: e.to_string() }
            })?;
        for (m, r) in reconstructions.iter().enumerate() {
            let (mut clip_all, mut clip_occluded) = (MetricsAccumulator::new(), MetricsAccumulator::new());
            for segment in &segments {
                let range = segment.frames.clone();
                let (pred, truth, fps) = (&r.joints[range.clone()], &gt_joints[range.clone()], aligned.timeline.fps);
                for acc in [&mut all[m], &mut clip_all] {
                    acc.add_segment(pred, truth, fps, None)?;
                }
                for acc in [&mut occluded[m], &mut clip_occluded] {
                    acc.add_segment(pred, truth, fps, Some(&hidden[range.clone()]))?;
                }
                feet[m].add_segment(pred, truth, fps, floor_y, sole_offset);
            }
            per_clip[m].push([clip_all.finish(), clip_occluded.finish()]);
        }
        progress(done + 1, clips.len());
    }
    let rows = |accs: &[MetricsAccumulator]| -> Vec<EvalRow> {
        options
            .methods
            .iter()
            .zip(accs)
            .filter_map(|(&method, acc)| acc.finish().map(|metrics| EvalRow { method, metrics }))
            .collect()
    };
    Ok(EvalReport {
        tracking: options.tracking.points(),
        wrists: options.wrists,
        floor_contact: options.floor_contact,
        one_point_clips,
        wrist_coverage: wrist_frames.map(|f| if timeline_frames > 0.0 { (f / timeline_frames) as f32 } else { 0.0 }),
        observers: options.observers,
        subjects: options.subjects.clone(),
        clips: clips.len(),
        frames,
        occluded_frames,
        rows: rows(&all),
        occluded_rows: rows(&occluded),
        ground_truth: truth.finish(),
        occluded_ground_truth: occluded_truth.finish(),
        feet: options
            .methods
            .iter()
            .zip(&feet)
            .filter_map(|(&method, acc)| acc.finish().map(|metrics| FootRow { method, metrics }))
            .collect(),
        ground_truth_feet: truth_feet.finish(),
        paired: paired_comparisons(&options.methods, &per_clip, options.seed),
    })
}

/// `rest-pose, ego-exo, …`.
fn method_names(methods: &[Method]) -> String {
    methods.iter().map(|m| m.name()).collect::<Vec<_>>().join(", ")
}

/// The report as the paper's table (plain text).
pub fn format_table(report: &EvalReport) -> String {
    let wrists = match report.wrists {
        WristKind::Devices => String::new(),
        kind => format!(
            " ({}: left wrist tracked on {:.0}%, right on {:.0}% of frames; {} clip(s) without any wrist reconstructed 1-point)",
            kind.describe(),
            report.wrist_coverage[0] * 100.0,
            report.wrist_coverage[1] * 100.0,
            report.one_point_clips
        ),
    };
    let mut out = format!(
        "{}-point tracking{wrists}, {} observer(s), subjects {:?}: {} clips, {} frames ({} occluded)\n",
        report.tracking, report.observers, report.subjects, report.clips, report.frames, report.occluded_frames
    );
    let sections = [
        ("all frames", &report.rows, &report.ground_truth),
        ("occluded frames", &report.occluded_rows, &report.occluded_ground_truth),
    ];
    for (title, rows, truth) in sections {
        out.push_str(&format!("\n{title}\n"));
        out.push_str(&format!(
            "{:<20} {:>8} {:>8} {:>8} {:>11} {:>8}\n",
            "method", "MPJPE", "U-PE", "L-PE", "MPJVE", "Jitter"
        ));
        out.push_str(&format!("{:<20} {:>8} {:>8} {:>8} {:>11} {:>8}\n", "", "cm", "cm", "cm", "cm/s", "1e2m/s3"));
        for r in rows.iter() {
            let m = &r.metrics;
            out.push_str(&format!(
                "{:<20} {:>8.2} {:>8.2} {:>8.2} {:>11.2} {:>8.2}\n",
                r.method.name(),
                m.mpjpe_cm,
                m.upper_cm,
                m.lower_cm,
                m.mpjve_cm_s,
                m.jitter
            ));
        }
        if let Some(truth) = truth {
            let dash = "-";
            out.push_str(&format!(
                "{:<20} {dash:>8} {dash:>8} {dash:>8} {dash:>11} {:>8.2}\n",
                "(ground truth)", truth.jitter
            ));
        }
    }
    if !report.feet.is_empty() {
        out.push_str("\nfeet and floor (all frames)\n");
        out.push_str(&format!(
            "{:<20} {:>12} {:>12} {:>10}\n{:<20} {:>12} {:>12} {:>10}\n",
            "method", "penetration", "worst", "skating", "", "cm (mean)", "cm", "cm/s"
        ));
        let truth = report.ground_truth_feet.map(|m| ("(ground truth)", m));
        for (name, m) in report.feet.iter().map(|r| (r.method.name(), r.metrics)).chain(truth) {
            let skating = m.skating_cm_s.map_or("-".to_owned(), |s| format!("{s:.2}"));
            out.push_str(&format!(
                "{name:<20} {:>12.2} {:>12.2} {skating:>10}\n",
                m.penetration_mean_cm, m.penetration_worst_cm
            ));
        }
    }
    if !report.paired.is_empty() {
        out.push_str("\npaired by clip: mean difference [95 % bootstrap interval over clips], cm\n");
        for p in &report.paired {
            let cell = |i: &Interval| format!("{:+.2} [{:+.2}, {:+.2}]", i.mean, i.low, i.high);
            out.push_str(&format!(
                "{:<34} {:<16} MPJPE {:<22} L-PE {}\n",
                format!("{} - {}", p.method.name(), p.baseline.name()),
                if p.occluded { "occluded frames" } else { "all frames" },
                cell(&p.mpjpe_cm),
                cell(&p.lower_cm),
            ));
        }
    }
    out
}

/// The lookaheads `egoexo eval --live` reports (frames).
pub const LIVE_LOOKAHEADS: [usize; 4] = [0, 4, 8, 16];

/// One row of the live table: a method read out `lookahead` frames before its window's end,
/// scored against the ground truth, and its distance from the offline reconstruction of the
/// same frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LiveEvalRow {
    pub method: Method,
    pub lookahead: usize,
    /// Read out by the live variant trained for this lookahead (else by the offline networks).
    #[serde(default)]
    pub trained_for_lookahead: bool,
    #[serde(flatten)]
    pub metrics: MotionMetrics,
    /// MPJPE between the live and the offline joints, cm.
    pub vs_offline_cm: f64,
    /// MPJPE over the offline result's MPJPE (1.10 = 10 % worse).
    pub mpjpe_ratio: f64,
}

/// What `egoexo eval --live` prints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LiveEvalReport {
    pub tracking: u8,
    pub observers: usize,
    pub subjects: Vec<u32>,
    pub clips: usize,
    /// Frames scored (every tracked frame with `max(lookaheads)` frames after it).
    pub frames: usize,
    /// The offline reconstruction (overlapping windows, cross-faded: what the page shows after
    /// "Stop and keep") on the same frames.
    pub offline: Vec<EvalRow>,
    pub rows: Vec<LiveEvalRow>,
}

/// The live reconstruction's accuracy: every frame `f` read out of the 96-frame window ending
/// at `f + L` (as the page's worker does), for every method of `options` and every `L` of
/// `lookaheads`, by the offline networks and, where `models` has one, by the live variant
/// trained for `L`; one window per end frame and networks serves every lookahead.
/// `progress(done, total)` counts clips.
pub fn evaluate_live(
    library: &MotionLibrary,
    models: &LoadedModels,
    options: &EvalOptions,
    lookaheads: &[usize],
    progress: &mut dyn FnMut(usize, usize),
) -> Result<LiveEvalReport, DatasetError> {
    let clips = library.clips_of_subjects(&options.subjects);
    if clips.is_empty() {
        return Err(DatasetError::Options(format!("no clips of subjects {:?}", options.subjects)));
    }
    let max_lookahead = lookaheads.iter().copied().max().unwrap_or(0);
    if max_lookahead >= WINDOW {
        return Err(DatasetError::Options(format!("a lookahead must be below {WINDOW} frames")));
    }
    let methods = &options.methods;
    let fail = |e: egoexo_infer::InferError| DatasetError::Reconstruct {
        method: method_names(methods),
        message: e.to_string(),
    };
    let engine = models.offline();
    // Columns: (lookahead, the engine that reads it out, whether that is a live variant).
    let mut columns: Vec<(usize, &Engine, bool)> = lookaheads.iter().map(|&l| (l, engine, false)).collect();
    for &lookahead in lookaheads {
        let live = models.for_lookahead(lookahead);
        if live.trained_for_lookahead(options.tracking, lookahead) {
            columns.push((lookahead, live, true));
        }
    }
    let mut offline_acc: Vec<MetricsAccumulator> = methods.iter().map(|_| MetricsAccumulator::new()).collect();
    let cell = || -> Vec<Vec<MetricsAccumulator>> {
        methods.iter().map(|_| columns.iter().map(|_| MetricsAccumulator::new()).collect()).collect()
    };
    let (mut live_acc, mut vs_offline_acc) = (cell(), cell());
    let mut frames = 0;
    let offline_options = ReconstructOptions { tracking: Some(options.tracking), ..ReconstructOptions::default() };
    let window_options =
        ReconstructOptions { tracking: Some(options.tracking), stride: WINDOW, ..ReconstructOptions::default() };
    for (done, &clip) in clips.iter().enumerate() {
        let aligned =
            evaluation_session(library, clip, options.tracking, options.wrists, options.observers, options.seed)?;
        let gt = aligned.ground_truth.as_ref().ok_or(DatasetError::NoGroundTruth)?;
        let gt_joints: Vec<_> = gt.poses.iter().map(|p| aligned.skeleton.forward_kinematics(p).positions).collect();
        let offline = engine.reconstruct_each(&aligned, &offline_options, methods, &mut |_| true).map_err(fail)?;
        let tracked: Vec<bool> = (0..aligned.timeline.frames).map(|f| aligned.wearer_tracked(f)).collect();
        for span in valid_spans(&tracked) {
            if span.len() <= max_lookahead {
                continue;
            }
            let scored = span.start..span.end - max_lookahead;
            // live[method][column][frame - scored.start]
            let mut live: Vec<Vec<Vec<[egoexo_core::glam::Vec3; egoexo_core::skeleton::NUM_JOINTS]>>> =
                vec![vec![Vec::with_capacity(scored.len()); columns.len()]; methods.len()];
            for end in span.clone() {
                let start = (end + 1).saturating_sub(WINDOW).max(span.start);
                let window = aligned.frames_slice(start..end + 1);
                let offline_results =
                    engine.reconstruct_each(&window, &window_options, methods, &mut |_| true).map_err(fail)?;
                for (c, &(lookahead, column_engine, trained)) in columns.iter().enumerate() {
                    let Some(frame) = end.checked_sub(lookahead) else { continue };
                    if frame < start || !scored.contains(&frame) {
                        continue;
                    }
                    let live_results;
                    let results = if trained {
                        live_results = column_engine
                            .reconstruct_each(&window, &window_options, methods, &mut |_| true)
                            .map_err(fail)?;
                        &live_results
                    } else {
                        &offline_results
                    };
                    for (m, result) in results.iter().enumerate() {
                        live[m][c].push(result.joints[frame - start]);
                    }
                }
            }
            frames += scored.len();
            let truth = &gt_joints[scored.clone()];
            let fps = aligned.timeline.fps;
            for (m, result) in offline.iter().enumerate() {
                let offline_joints = &result.joints[scored.clone()];
                offline_acc[m].add_segment(offline_joints, truth, fps, None)?;
                for c in 0..columns.len() {
                    live_acc[m][c].add_segment(&live[m][c], truth, fps, None)?;
                    vs_offline_acc[m][c].add_segment(&live[m][c], offline_joints, fps, None)?;
                }
            }
        }
        progress(done + 1, clips.len());
    }
    let mut offline_rows = Vec::new();
    let mut rows = Vec::new();
    for (m, &method) in methods.iter().enumerate() {
        let Some(offline) = offline_acc[m].finish() else { continue };
        for (c, &(lookahead, _, trained_for_lookahead)) in columns.iter().enumerate() {
            let (Some(metrics), Some(vs)) = (live_acc[m][c].finish(), vs_offline_acc[m][c].finish()) else { continue };
            let mpjpe_ratio = metrics.mpjpe_cm / offline.mpjpe_cm;
            rows.push(LiveEvalRow {
                method,
                lookahead,
                trained_for_lookahead,
                metrics,
                vs_offline_cm: vs.mpjpe_cm,
                mpjpe_ratio,
            });
        }
        offline_rows.push(EvalRow { method, metrics: offline });
    }
    Ok(LiveEvalReport {
        tracking: options.tracking.points(),
        observers: options.observers,
        subjects: options.subjects.clone(),
        clips: clips.len(),
        frames,
        offline: offline_rows,
        rows,
    })
}

/// The live table (markdown): offline and each lookahead per method; `L (live)` rows are read
/// out by the variant trained for `L`.
pub fn format_live_table(report: &LiveEvalReport) -> String {
    let mut out = format!(
        "**live, {}-point tracking, {} observer(s), subjects {:?}: {} clips, {} frames**\n\n",
        report.tracking, report.observers, report.subjects, report.clips, report.frames
    );
    out.push_str("| method | lookahead | latency ≥ | MPJPE | L-PE | Jitter | vs offline | MPJPE / offline |\n");
    out.push_str("|---|---|---|---|---|---|---|---|\n");
    for offline in &report.offline {
        let m = &offline.metrics;
        out.push_str(&format!(
            "| {} | offline | – | {:.2} | {:.2} | {:.2} | – | 1.00 |\n",
            offline.method, m.mpjpe_cm, m.lower_cm, m.jitter
        ));
        let mut rows: Vec<&LiveEvalRow> = report.rows.iter().filter(|r| r.method == offline.method).collect();
        rows.sort_by_key(|r| (r.lookahead, r.trained_for_lookahead));
        for row in rows {
            let m = &row.metrics;
            out.push_str(&format!(
                "| {} | {}{} | {:.0} ms | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |\n",
                row.method,
                row.lookahead,
                if row.trained_for_lookahead { " (live)" } else { "" },
                row.lookahead as f64 * 1000.0 / 30.0,
                m.mpjpe_cm,
                m.lower_cm,
                m.jitter,
                row.vs_offline_cm,
                row.mpjpe_ratio
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn interval(weights: &[f64], values: &[f64], seed: u64) -> Option<Interval> {
        bootstrap_weighted_mean(weights, values, BOOTSTRAP_RESAMPLES, &mut SimRng::new(seed))
    }

    #[test]
    fn the_mean_is_weighted_by_frames() {
        let i = interval(&[1.0, 3.0], &[0.0, 4.0], 1).unwrap();
        assert!((i.mean - 3.0).abs() < 1e-12, "{i:?}");
        assert!(i.low <= i.mean && i.mean <= i.high && i.low >= 0.0 && i.high <= 4.0, "{i:?}");
    }

    #[test]
    fn equal_differences_leave_no_uncertainty() {
        let i = interval(&[10.0, 50.0, 96.0], &[-0.25; 3], 1).unwrap();
        assert!((i.mean + 0.25).abs() < 1e-12 && (i.low + 0.25).abs() < 1e-12 && (i.high + 0.25).abs() < 1e-12);
    }

    #[test]
    fn the_interval_separates_a_consistent_difference_from_noise() {
        // 40 clips: a consistent gain of about 1 cm, and differences of either sign.
        let weights = vec![96.0; 40];
        let consistent: Vec<f64> = (0..40).map(|i| -1.0 + 0.05 * f64::from(i % 7) - 0.15).collect();
        let noise: Vec<f64> = (0..40).map(|i| if i % 2 == 0 { 0.5 } else { -0.5 } + 0.01 * f64::from(i % 3)).collect();
        let gain = interval(&weights, &consistent, 3).unwrap();
        assert!(gain.high < 0.0, "{gain:?}");
        let tie = interval(&weights, &noise, 3).unwrap();
        assert!(tie.low < 0.0 && tie.high > 0.0, "{tie:?}");
        // Wider spread, wider interval; the same seed, the same interval.
        assert!(tie.high - tie.low > gain.high - gain.low);
        assert_eq!(Some(tie), interval(&weights, &noise, 3));
    }

    #[test]
    fn nothing_to_average_is_none() {
        assert_eq!(interval(&[], &[], 1), None);
        assert_eq!(interval(&[1.0], &[1.0, 2.0], 1), None);
        assert_eq!(interval(&[0.0, 0.0], &[1.0, 2.0], 1), None);
    }
}
