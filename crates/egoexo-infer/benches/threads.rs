//! Scaling over cores, natively: a simulated 60 s session (3-point, 2 observers) through the
//! app's whole job (ego-exo + the ego-only overlay, one shared ego pass) with its windows on
//! rayon pools of 1, 2, … threads (up to the machine's cores), against the sequential job
//! (`Engine::reconstruct_each`) as the in-run reference. Run with
//! `cargo bench -p egoexo-infer --features parallel --bench threads`; throughput in frames.

mod common;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use egoexo_core::TrackingMode;
use egoexo_infer::{Engine, Method, ReconstructOptions};
use egoexo_session::align::{AlignOptions, align};
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::{SynthConfig, simulate};

fn engine() -> Engine {
    Engine::new().with_models(common::three_point_models())
}

fn threads(c: &mut Criterion) {
    let engine = engine();
    let config = SynthConfig { observers: 2, tracking: TrackingMode::ThreePoint, ..SynthConfig::default() };
    let sim = simulate(&walking_circle(60.0), "bench", &config, 1).expect("simulates");
    let aligned = align(&sim.session, &AlignOptions::default()).expect("aligns");
    let options = ReconstructOptions::default();
    let job = [Method::EgoExo, Method::EgoOnly];
    let mut group = c.benchmark_group("threads");
    group.sample_size(10);
    group.throughput(Throughput::Elements(aligned.timeline.frames as u64));
    group.bench_function("sequential", |b| {
        b.iter(|| engine.reconstruct_each(&aligned, &options, &job, &mut |_| true).expect("reconstructs"))
    });
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut counts: Vec<usize> = (0..).map(|i| 1 << i).take_while(|&n| n < cores).collect();
    counts.push(cores);
    for n in counts {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().expect("a rayon pool");
        group.bench_with_input(BenchmarkId::new("parallel", format!("{n}-threads")), &n, |b, _| {
            b.iter(|| {
                pool.install(|| {
                    engine.reconstruct_each_in_parallel(&aligned, &options, &job, &mut |_| true).expect("reconstructs")
                })
            })
        });
    }
    group.finish();
}

criterion_group!(benches, threads);
criterion_main!(benches);
