//! The engine per stage, natively, one thread: on a simulated 20 s session with 3 observers
//! (3-point tracking) and the shipped models, every window through ego features, EgoNet, exo
//! features (regions, rays, gate features), the gate, fusion, and the decode of all windows
//! into motion — the stages of `egoexo reconstruct --timings`. Run with
//! `cargo bench -p egoexo-infer --bench stages`; throughput is in windows.

mod common;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use egoexo_core::TrackingMode;
use egoexo_core::aligned::AlignedSession;
use egoexo_infer::decode::{MotionAssembler, assemble_reconstruction};
use egoexo_infer::inputs::ego_window;
use egoexo_infer::models::ModelSet;
use egoexo_infer::passes::{CoarsePoseSource, ExoMode, coarse_pose_with, ego_pass, exo_pass, fusion_pass};
use egoexo_infer::plan::ReconstructionPlan;
use egoexo_infer::{Method, ReconstructOptions, StageTimer};
use egoexo_session::align::{AlignOptions, align};
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::{SynthConfig, simulate};

fn models() -> ModelSet {
    common::three_point_models()
}

fn session() -> AlignedSession {
    let config = SynthConfig { observers: 3, tracking: TrackingMode::ThreePoint, ..SynthConfig::default() };
    let sim = simulate(&walking_circle(20.0), "bench", &config, 1).expect("simulates");
    align(&sim.session, &AlignOptions::default()).expect("aligns")
}

fn stages(c: &mut Criterion) {
    let models = models();
    let aligned = session();
    let tracking = TrackingMode::ThreePoint;
    let options = ReconstructOptions::default();
    let plan =
        ReconstructionPlan::new(&aligned, tracking, &options.windows(), models.manifest.max_observers).expect("plans");
    let off = || StageTimer::off();
    let source = CoarsePoseSource::EgoNet(&models.egonet);
    let ego: Vec<_> =
        plan.windows.iter().map(|w| ego_pass(&aligned, w, tracking, source, &mut off()).expect("ego pass")).collect();
    let exo: Vec<_> = ego
        .iter()
        .map(|e| exo_pass(&aligned, &models, e, &plan.observers, ExoMode::Gated, &mut off()).expect("exo pass"))
        .collect();
    let outputs: Vec<_> =
        ego.iter().zip(&exo).map(|(e, x)| fusion_pass(&models, e, x, &mut off()).expect("fusion")).collect();

    let mut group = c.benchmark_group("stages");
    group.sample_size(10);
    group.throughput(Throughput::Elements(plan.windows.len() as u64));
    group.bench_function("ego-features", |b| {
        b.iter(|| plan.windows.iter().map(|w| ego_window(&aligned, w, tracking).expect("features")).collect::<Vec<_>>())
    });
    group.bench_function("egonet", |b| {
        b.iter(|| ego.iter().map(|e| coarse_pose_with(&models.egonet, &e.window).expect("egonet")).collect::<Vec<_>>())
    });
    // The ungated exo pass is the exo features alone (no gate network).
    group.bench_function("exo-features", |b| {
        b.iter(|| {
            ego.iter()
                .map(|e| exo_pass(&aligned, &models, e, &plan.observers, ExoMode::Ungated, &mut off()).expect("exo"))
                .collect::<Vec<_>>()
        })
    });
    group.bench_function("gate", |b| {
        b.iter(|| exo.iter().map(|x| models.gate.run(&[&x.exo.gate_features]).expect("gate")).collect::<Vec<_>>())
    });
    group.bench_function("fusion", |b| {
        b.iter(|| {
            ego.iter()
                .zip(&exo)
                .map(|(e, x)| fusion_pass(&models, e, x, &mut off()).expect("fusion"))
                .collect::<Vec<_>>()
        })
    });
    group.bench_function("decode", |b| {
        b.iter(|| {
            let mut assembler = MotionAssembler::new(aligned.observers.len(), plan.crossfade_ramp);
            for output in &outputs {
                assembler.add(output).expect("decodes");
            }
            let frames = assembler.take_frames(&aligned, aligned.timeline.frames);
            assemble_reconstruction(Method::EgoExo, tracking, &aligned, frames, None).expect("assembles")
        })
    });
    group.finish();
}

criterion_group!(benches, stages);
criterion_main!(benches);
