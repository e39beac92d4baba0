//! `egoexo eval`: simulate sessions from chosen subjects, reconstruct them through the engine
//! the app uses (non-overlapping 96-frame segments, the paper's protocol), and score every
//! method with the paper's metrics — on all frames and on the occluded-frames subset.
//!
//! A frame is *occluded* when at least one of its exo keypoints is hidden from at least one
//! observer by furniture or a bystander (the simulator's labels).

use egoexo_core::TrackingMode;
use egoexo_core::ego_features::EGO_FEATURE_DIM;
use egoexo_core::metrics::{MetricsAccumulator, MotionMetrics};
use egoexo_infer::baselines::NearestNeighbourIndex;
use egoexo_infer::inputs::{POSE_DIM, ego_window, window_targets};
use egoexo_infer::windows::{WINDOW, plan_windows, valid_spans};
use egoexo_infer::{Engine, Method, ReconstructOptions};
use egoexo_mocap::MotionLibrary;
use egoexo_session::align::{AlignOptions, AlignedSession, align};
use egoexo_synth::{SynthConfig, simulate};
use serde::{Deserialize, Serialize};

use crate::DatasetError;
use crate::shards::mix;

/// What to evaluate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalOptions {
    pub subjects: Vec<u32>,
    pub observers: usize,
    pub tracking: TrackingMode,
    pub seed: u64,
    pub methods: Vec<Method>,
}

/// One table row: a method and the core's metric row (flattened in JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalRow {
    pub method: Method,
    #[serde(flatten)]
    pub metrics: MotionMetrics,
}

/// The result, in the shape `egoexo eval --json` prints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// 1 or 3.
    pub tracking: u8,
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
}

/// Simulates and aligns clip `clip` for evaluation (deterministic in `seed` and the clip).
pub fn evaluation_session(
    library: &MotionLibrary,
    clip: usize,
    tracking: TrackingMode,
    observers: usize,
    seed: u64,
) -> Result<AlignedSession, DatasetError> {
    let info = library.clips().get(clip).ok_or_else(|| DatasetError::Options(format!("no clip {clip}")))?;
    let motion = library.motion(clip).map_err(|e| DatasetError::Library(e.to_string()))?;
    let config = SynthConfig { tracking, observers, ..SynthConfig::default() };
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
        let aligned = evaluation_session(library, clip, tracking, 0, mix(seed, 0x4E4E, clip as u64))?;
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
    let clips = library.clips_of_subjects(&options.subjects);
    if clips.is_empty() {
        return Err(DatasetError::Options(format!("the library has no clips of subjects {:?}", options.subjects)));
    }
    let mut all: Vec<MetricsAccumulator> = options.methods.iter().map(|_| MetricsAccumulator::new()).collect();
    let mut occluded: Vec<MetricsAccumulator> = options.methods.iter().map(|_| MetricsAccumulator::new()).collect();
    let (mut truth, mut occluded_truth) = (MetricsAccumulator::new(), MetricsAccumulator::new());
    let (mut frames, mut occluded_frames) = (0, 0);
    let protocol = ReconstructOptions {
        method: Method::RestPose,
        tracking: Some(options.tracking),
        stride: WINDOW,
        non_overlapping: true,
    };
    for (done, &clip) in clips.iter().enumerate() {
        let aligned = evaluation_session(library, clip, options.tracking, options.observers, options.seed)?;
        let gt = aligned.ground_truth.as_ref().ok_or(DatasetError::NoGroundTruth)?;
        let gt_joints: Vec<_> = gt.poses.iter().map(|p| aligned.skeleton.forward_kinematics(p).positions).collect();
        let hidden: Vec<bool> = (0..aligned.timeline.frames)
            .map(|f| gt.occluded.iter().any(|o| o.get(f).is_some_and(|m| *m != 0)))
            .collect();
        let segments = plan_windows(&valid_spans(&aligned.head.valid), WINDOW, true);
        frames += segments.iter().map(|s| s.len()).sum::<usize>();
        occluded_frames +=
            segments.iter().map(|s| hidden[s.frames.clone()].iter().filter(|&&h| h).count()).sum::<usize>();
        for segment in &segments {
            let range = segment.frames.clone();
            let (joints, fps) = (&gt_joints[range.clone()], aligned.timeline.fps);
            truth.add_segment(joints, joints, fps, None)?;
            occluded_truth.add_segment(joints, joints, fps, Some(&hidden[range]))?;
        }
        for (m, &method) in options.methods.iter().enumerate() {
            let r = engine
                .reconstruct(&aligned, &ReconstructOptions { method, ..protocol }, &mut |_| true)
                .map_err(|e| DatasetError::Reconstruct { method: method.name(), message: e.to_string() })?;
            for segment in &segments {
                let range = segment.frames.clone();
                all[m].add_segment(&r.joints[range.clone()], &gt_joints[range.clone()], aligned.timeline.fps, None)?;
                occluded[m].add_segment(
                    &r.joints[range.clone()],
                    &gt_joints[range.clone()],
                    aligned.timeline.fps,
                    Some(&hidden[range]),
                )?;
            }
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
        observers: options.observers,
        subjects: options.subjects.clone(),
        clips: clips.len(),
        frames,
        occluded_frames,
        rows: rows(&all),
        occluded_rows: rows(&occluded),
        ground_truth: truth.finish(),
        occluded_ground_truth: occluded_truth.finish(),
    })
}

/// The report as the paper's table (plain text).
pub fn format_table(report: &EvalReport) -> String {
    let mut out = format!(
        "{}-point tracking, {} observer(s), subjects {:?}: {} clips, {} frames ({} occluded)\n",
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
    out
}
