#![cfg(not(target_arch = "wasm32"))]
//! The engine's passes and jobs: methods share one ego pass (EgoNet runs once per window),
//! a job can be stepped and finished only when done, and feeding windows one at a time
//! through the passes gives the batch reconstruction, frame by frame as they become final.

use crate::common::*;
use egoexo_core::TrackingMode;
use egoexo_infer::decode::{MotionAssembler, assemble_reconstruction};
use egoexo_infer::passes::{CoarsePoseSource, ExoMode, ego_pass, exo_pass, fusion_pass};
use egoexo_infer::plan::{ReconstructionPlan, resolve_tracking};
use egoexo_infer::windows::WindowError;
use egoexo_infer::{Engine, InferError, Method, NetworkRuns, ReconstructOptions, Stage, StageTimer, TimedStage};

fn engine() -> Engine {
    Engine::new()
        .with_models(fixture_models(TrackingMode::ThreePoint))
        .with_models(fixture_models(TrackingMode::OnePoint))
}

#[test]
fn ego_exo_and_the_ego_only_overlay_share_one_ego_pass() {
    let aligned = aligned_session(9.0, 2, TrackingMode::ThreePoint, 11);
    let engine = engine();
    let options = ReconstructOptions::default();
    let before = engine.network_runs();
    let mut stages = Vec::new();
    let both = engine
        .reconstruct_each(&aligned, &options, &[Method::EgoExo, Method::EgoOnly], &mut |p| {
            stages.push(p.stage);
            true
        })
        .unwrap();
    let runs = engine.network_runs() - before;
    let windows = stages.iter().filter(|s| **s == Stage::Ego).count();
    assert!(windows >= 4, "{windows} windows");
    // EgoNet once per window; the gate only for ego-exo; the fusion once per window for
    // ego-exo, its every-observer-masked graph once per window for the overlay.
    let w = windows as u64;
    assert_eq!(runs, NetworkRuns { egonet: w, gate: w, fusion: w, fusion_ego_only: w });
    let mut order = stages.clone();
    order.dedup();
    assert_eq!(order, [Stage::Ego, Stage::Fusion(Method::EgoExo), Stage::Fusion(Method::EgoOnly)]);

    // The same numbers as two separate reconstructions (which run EgoNet twice).
    for (shared, method) in both.iter().zip([Method::EgoExo, Method::EgoOnly]) {
        let alone = engine.reconstruct(&aligned, &ReconstructOptions { method, ..options }, &mut |_| true).unwrap();
        assert_eq!(shared, &alone, "{method}");
    }
    let separately = engine.network_runs() - before - runs;
    assert_eq!(separately.egonet, 2 * windows as u64);
}

/// The ego-only method runs the fusion's every-observer-masked graph when the set ships it;
/// it reconstructs what the fusion on empty observer slots does (a set without the graph).
#[test]
fn the_ego_only_graph_reconstructs_what_the_fusion_does_with_every_observer_masked() {
    let aligned = aligned_session(9.0, 2, TrackingMode::ThreePoint, 12);
    let options = ReconstructOptions { method: Method::EgoOnly, ..ReconstructOptions::default() };
    let with_graph = engine();
    let mut without = fixture_models(TrackingMode::ThreePoint);
    assert!(without.fusion_ego_only.is_some(), "the fixture set ships fusion_ego_only");
    without.fusion_ego_only = None;
    let without_graph = Engine::new().with_models(without);

    let before = (with_graph.network_runs(), without_graph.network_runs());
    let a = with_graph.reconstruct(&aligned, &options, &mut |_| true).unwrap();
    let b = without_graph.reconstruct(&aligned, &options, &mut |_| true).unwrap();
    let (runs_a, runs_b) = (with_graph.network_runs() - before.0, without_graph.network_runs() - before.1);
    assert!(runs_a.fusion_ego_only > 0 && runs_a.fusion == 0 && runs_a.gate == 0, "{runs_a:?}");
    assert!(runs_b.fusion_ego_only == 0 && runs_b.fusion == runs_a.fusion_ego_only, "{runs_b:?}");

    assert_eq!(a.joints.len(), b.joints.len());
    let mut max_diff = 0.0f32;
    for (fa, fb) in a.joints.iter().zip(&b.joints) {
        for (ja, jb) in fa.iter().zip(fb) {
            max_diff = max_diff.max((*ja - *jb).abs().max_element());
        }
    }
    assert!(max_diff < 1e-4, "joints differ by {max_diff} m");
    // ...while the observers, when used, move the joints (so the comparison can fail).
    let ego_exo = with_graph.reconstruct(&aligned, &ReconstructOptions::default(), &mut |_| true).unwrap();
    let moved = ego_exo.joints.iter().zip(&a.joints).map(|(e, o)| (e[20] - o[20]).length()).fold(0.0, f32::max);
    assert!(moved > 1e-3, "ego-exo and ego-only agree to {moved} m");
}

#[test]
fn a_timed_job_times_every_engine_stage_per_window_and_gives_the_untimed_result() {
    let aligned = aligned_session(9.0, 2, TrackingMode::ThreePoint, 11);
    let engine = engine();
    let options = ReconstructOptions::default();
    let methods = [Method::EgoExo, Method::EgoOnly];
    // A clock that advances 1 ms per reading: each timed stage call takes exactly 1 ms.
    let mut now = 0.0;
    let mut clock = move || {
        now += 1.0;
        now
    };
    let mut job = engine.start(&aligned, &options, &methods).unwrap();
    let windows = job.plan().windows.len() as u32;
    while job.step_timed(&engine, &aligned, &mut clock).unwrap().is_some() {}
    let (timed, timings) = job.finish_timed(&aligned, &mut clock).unwrap();
    let calls = |stage| timings.stages.iter().find(|s| s.stage == stage).map(|s| s.calls);
    // Ego features and EgoNet once per window (shared); rays and the gate only for ego-exo
    // (ego-only runs the fusion's every-observer-masked graph); fusion and decode once per
    // window and method.
    assert_eq!(calls(TimedStage::EgoFeatures), Some(windows));
    assert_eq!(calls(TimedStage::EgoNet), Some(windows));
    assert_eq!(calls(TimedStage::ExoFeatures), Some(windows));
    assert_eq!(calls(TimedStage::Gate), Some(windows));
    assert_eq!(calls(TimedStage::Fusion), Some(2 * windows));
    assert_eq!(calls(TimedStage::Decode), Some(2 * windows));
    assert_eq!(calls(TimedStage::Import), None);
    assert_eq!(timings.ms(TimedStage::Fusion), f64::from(2 * windows));
    assert_eq!(timings.ms(TimedStage::Decode), f64::from(2 * windows + 1), "the final decode adds time, not a call");
    assert_eq!(timed, engine.reconstruct_each(&aligned, &options, &methods, &mut |_| true).unwrap());
}

#[cfg(feature = "parallel")]
#[test]
fn a_job_run_in_parallel_gives_the_sequential_result_chunk_by_chunk() {
    let aligned = aligned_session(9.0, 2, TrackingMode::ThreePoint, 11);
    let engine = engine();
    let options = ReconstructOptions::default();
    let methods = [Method::EgoExo, Method::EgoOnly];
    let sequential = engine.reconstruct_each(&aligned, &options, &methods, &mut |_| true).unwrap();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
    let mut job = engine.start(&aligned, &options, &methods).unwrap();
    let windows = job.plan().windows.len();
    assert!(windows >= 4, "{windows} windows");
    let mut reports = Vec::new();
    pool.install(|| {
        job.run_in_parallel(&engine, &aligned, 3, &mut |p| {
            reports.push(p.done);
            true
        })
    })
    .unwrap();
    assert!(job.is_done());
    assert_eq!(reports.last(), Some(&windows));
    assert_eq!(reports.len(), windows.div_ceil(3));
    assert_eq!(job.finish(&aligned).unwrap(), sequential);
    // A job already stepped does not restart in parallel; a cancel stops it.
    let mut job = engine.start(&aligned, &options, &methods).unwrap();
    job.step(&engine, &aligned).unwrap();
    assert!(job.run_in_parallel(&engine, &aligned, 3, &mut |_| true).is_err());
    let mut job = engine.start(&aligned, &options, &methods).unwrap();
    assert!(matches!(job.run_in_parallel(&engine, &aligned, 3, &mut |_| false), Err(InferError::Cancelled)));
    assert_eq!(engine.reconstruct_each_in_parallel(&aligned, &options, &methods, &mut |_| true).unwrap(), sequential);
}

/// Steps run chunk by chunk: a chunk's ego passes, then each method over the chunk; at most a
/// chunk's ego outputs are held, and the result is the same whatever the chunk.
#[test]
fn a_job_steps_chunk_by_chunk_holding_only_a_chunks_ego_passes() {
    let aligned = aligned_session(9.0, 2, TrackingMode::ThreePoint, 11);
    let engine = engine();
    let options = ReconstructOptions::default();
    let methods = [Method::EgoExo, Method::EgoOnly];
    let whole = engine.reconstruct_each(&aligned, &options, &methods, &mut |_| true).unwrap();
    let mut job = engine.start(&aligned, &options, &methods).unwrap();
    let windows = job.plan().windows.len();
    assert!(windows >= 5, "{windows} windows");
    job.set_chunk(2).unwrap();
    let (mut stages, mut held) = (Vec::new(), 0);
    while let Some(p) = job.step(&engine, &aligned).unwrap() {
        stages.push((p.stage, p.done));
        held = held.max(job.held_ego_passes());
        assert!(p.done <= p.total && p.total == windows);
    }
    assert_eq!(held, 2, "at most a chunk's ego passes are held");
    assert_eq!(job.held_ego_passes(), 0);
    assert_eq!(stages.len(), job.total_steps());
    assert_eq!(job.done_steps(), job.total_steps());
    // The first chunk: ego passes of windows 1 and 2, ego-exo over them, then ego-only.
    let (ego, exo, only) = (Stage::Ego, Stage::Fusion(Method::EgoExo), Stage::Fusion(Method::EgoOnly));
    assert_eq!(stages[..7], [(ego, 1), (ego, 2), (exo, 1), (exo, 2), (only, 1), (only, 2), (ego, 3)]);
    // Each stage's windows are done in order.
    for stage in [ego, exo, only] {
        let done: Vec<usize> = stages.iter().filter(|(s, _)| *s == stage).map(|(_, d)| *d).collect();
        assert_eq!(done, (1..=windows).collect::<Vec<_>>(), "{stage:?}");
    }
    assert_eq!(job.finish(&aligned).unwrap(), whole);
    // The chunk is set before the first step only.
    let mut job = engine.start(&aligned, &options, &methods).unwrap();
    job.step(&engine, &aligned).unwrap();
    assert!(job.set_chunk(4).is_err());
}

/// A pool of workers: another job made from the same session and options computes chunks in
/// any order (through bytes, as between workers); the first job decodes them in chunk order
/// and gets the sequential result. Outputs that do not fit are refused without harm.
#[test]
fn chunks_computed_elsewhere_in_any_order_decode_to_the_sequential_result() {
    let aligned = aligned_session(9.0, 2, TrackingMode::ThreePoint, 11);
    let engine = engine();
    let options = ReconstructOptions::default();
    let methods = [Method::EgoExo, Method::EgoOnly];
    let sequential = engine.reconstruct_each(&aligned, &options, &methods, &mut |_| true).unwrap();
    let mut coordinator = engine.start(&aligned, &options, &methods).unwrap();
    let mut helper = engine.start(&aligned, &options, &methods).unwrap();
    for job in [&mut coordinator, &mut helper] {
        job.set_chunk(2).unwrap();
    }
    let chunks = coordinator.chunk_count();
    let windows = coordinator.plan().windows.len();
    assert!(chunks >= 3, "{chunks} chunks");
    assert_eq!(coordinator.chunk_windows(chunks - 1).end, windows);
    assert!(coordinator.chunk_windows(chunks).is_empty());
    // The helper computes the chunks last to first; the coordinator runs chunk 0 window by
    // window itself.
    let mut arrived: Vec<Vec<u8>> =
        (1..chunks).rev().map(|c| helper.run_chunk(&engine, &aligned, c).unwrap().to_bytes().unwrap()).collect();
    assert_eq!(helper.done_steps(), 0, "running chunks leaves a job as it was");
    let own: Vec<Vec<_>> = coordinator
        .chunk_windows(0)
        .map(|w| coordinator.run_window(&engine, &aligned, w, &mut StageTimer::off()).unwrap())
        .collect();
    let mut first = egoexo_infer::ChunkOutputs::new(0, methods.len());
    for window in own {
        first.push_window(window);
    }
    // Out of order: refused, nothing decoded.
    let last = egoexo_infer::ChunkOutputs::from_bytes(&arrived[0]).unwrap();
    assert!(matches!(coordinator.add_chunk(&last), Err(InferError::Chunk { .. })));
    // Another chunk's windows under this chunk's number: refused.
    let mut mislabelled = last.clone();
    mislabelled.chunk = 0;
    assert!(matches!(coordinator.add_chunk(&mislabelled), Err(InferError::Chunk { .. })));
    // Bytes that are not outputs: a clear error.
    let err = egoexo_infer::ChunkOutputs::from_bytes(&arrived[0][..10]).unwrap_err();
    assert!(err.to_string().contains("not a chunk's window outputs"), "{err}");
    assert_eq!(coordinator.next_chunk(), Some(0));
    let p = coordinator.add_chunk(&first).unwrap();
    assert_eq!((p.done, p.total), (2, windows));
    while let Some(bytes) = arrived.pop() {
        let outputs = egoexo_infer::ChunkOutputs::from_bytes(&bytes).unwrap();
        assert_eq!(coordinator.next_chunk(), Some(outputs.chunk));
        coordinator.add_chunk(&outputs).unwrap();
    }
    assert_eq!(coordinator.next_chunk(), None);
    assert!(coordinator.is_done());
    assert_eq!(coordinator.finish(&aligned).unwrap(), sequential);
}

#[test]
fn methods_with_different_coarse_poses_cannot_share_a_job() {
    let aligned = aligned_session(3.0, 1, TrackingMode::OnePoint, 12);
    let err =
        engine().start(&aligned, &ReconstructOptions::default(), &[Method::EgoExo, Method::RestPose]).unwrap_err();
    assert!(matches!(err, InferError::CoarseSourcesDiffer { first: Method::EgoExo, other: Method::RestPose }), "{err}");
    assert!(err.to_string().contains("ego-exo and rest-pose"), "{err}");
    assert!(matches!(engine().start(&aligned, &ReconstructOptions::default(), &[]), Err(InferError::NoMethod)));
}

#[test]
fn a_job_steps_window_by_window_and_finishes_only_when_done() {
    let aligned = aligned_session(6.0, 1, TrackingMode::ThreePoint, 13);
    let engine = engine();
    let mut job = engine.start(&aligned, &ReconstructOptions::default(), &[Method::EgoExo]).unwrap();
    let total = job.total_steps();
    assert_eq!(total, 2 * job.plan().windows.len());
    job.step(&engine, &aligned).unwrap().unwrap();
    assert_eq!(job.done_steps(), 1);
    let unfinished = job.clone().finish(&aligned).unwrap_err();
    assert!(matches!(unfinished, InferError::Window(WindowError::Unfinished { done: 1, .. })), "{unfinished}");
    assert!(unfinished.to_string().contains("1 of"), "{unfinished}");
    // Another session's timeline is refused rather than indexed.
    let other = aligned_session(2.0, 1, TrackingMode::ThreePoint, 14);
    assert!(matches!(job.step(&engine, &other), Err(InferError::Window(WindowError::SessionMismatch { .. }))));
    let mut steps = 1;
    while job.step(&engine, &aligned).unwrap().is_some() {
        steps += 1;
    }
    assert_eq!(steps, total);
    assert!(job.step(&engine, &aligned).unwrap().is_none(), "a finished job stays finished");
    assert_eq!(job.finish(&aligned).unwrap().len(), 1);
}

/// What a live caller does: windows through the passes one at a time, each window's frames
/// taken as soon as the next window starts after them.
#[test]
fn windows_one_at_a_time_give_the_batch_reconstruction_frame_by_frame() {
    let aligned = aligned_session(8.0, 2, TrackingMode::ThreePoint, 15);
    let engine = engine();
    let options = ReconstructOptions::default();
    let batch = engine.reconstruct(&aligned, &options, &mut |_| true).unwrap();

    let tracking = resolve_tracking(&aligned, None).unwrap();
    let models = engine.models(tracking).unwrap();
    let plan = ReconstructionPlan::new(&aligned, tracking, &options.windows(), models.manifest.max_observers).unwrap();
    let mut assembler = MotionAssembler::new(aligned.observers.len(), plan.crossfade_ramp);
    let mut frames = Vec::new();
    let mut released = Vec::new();
    for (i, window) in plan.windows.iter().enumerate() {
        let ego =
            ego_pass(&aligned, window, tracking, CoarsePoseSource::EgoNet(&models.egonet), &mut StageTimer::off())
                .unwrap();
        let exo = exo_pass(&aligned, models, &ego, &plan.observers, ExoMode::Gated, &mut StageTimer::off()).unwrap();
        assembler.add(&fusion_pass(models, &ego, &exo, &mut StageTimer::off()).unwrap()).unwrap();
        let final_before = plan.windows.get(i + 1).map_or(aligned.timeline.frames, |next| next.frames.start);
        let out = assembler.take_frames(&aligned, final_before);
        released.push(out.len());
        frames.extend(out);
    }
    assert!(released.iter().all(|&n| n > 0 && n < aligned.timeline.frames), "frames came out per window: {released:?}");
    // A window that starts before frames already given out is refused.
    let late =
        ego_pass(&aligned, &plan.windows[0], tracking, CoarsePoseSource::RestPose, &mut StageTimer::off()).unwrap();
    assert!(assembler.add(&egoexo_infer::passes::WindowOutput::from_coarse(&late)).is_err());

    let streamed = assemble_reconstruction(Method::EgoExo, tracking, &aligned, frames, aligned.floor_y).unwrap();
    assert_eq!(streamed, batch);
}

#[test]
fn a_root_output_collapsing_mid_turn_decodes_on_the_turn() {
    use egoexo_core::glam::Quat;
    use egoexo_core::rotation::{Rot6d, angle_between};
    use egoexo_infer::inputs::POSE_DIM;
    use egoexo_infer::passes::WindowOutput;

    let aligned = aligned_session(4.0, 1, TrackingMode::OnePoint, 5);
    let options = ReconstructOptions { stride: egoexo_infer::windows::WINDOW, ..ReconstructOptions::default() };
    let plan = ReconstructionPlan::new(&aligned, TrackingMode::OnePoint, &options.windows(), 1).unwrap();
    let window = &plan.windows[0];
    let ego =
        ego_pass(&aligned, window, TrackingMode::OnePoint, CoarsePoseSource::RestPose, &mut StageTimer::off()).unwrap();
    let mut output = WindowOutput::from_coarse(&ego);
    output.r_world_window = Quat::IDENTITY;
    // The wearer turns 6° a frame; over frames 40..=43 the network hesitates: its first
    // column shrinks to a tenth, pointing the wrong way round.
    let turn = |t: usize| Quat::from_rotation_y((6.0 * t as f32).to_radians());
    for t in 0..window.len() {
        let mut root = Rot6d::from_quat(turn(t)).0;
        if (40..=43).contains(&t) {
            let wrong = Rot6d::from_quat(Quat::from_rotation_y((6.0 * t as f32 + 180.0).to_radians())).0;
            root[0..3].iter_mut().zip(&wrong[0..3]).for_each(|(r, w)| *r = 0.1 * w);
        }
        output.poses[t * POSE_DIM..t * POSE_DIM + 6].copy_from_slice(&root);
    }
    let mut assembler = MotionAssembler::new(aligned.observers.len(), plan.crossfade_ramp);
    assembler.add(&output).unwrap();
    let frames = assembler.take_frames(&aligned, window.frames.end);
    for t in 36..48 {
        let root = frames[window.frames.start + t].pose.unwrap().root_orientation;
        let off = angle_between(root, turn(t)).to_degrees();
        assert!(off < 0.1, "frame {t}: {off:.2}° off the wearer's turn");
    }
}
