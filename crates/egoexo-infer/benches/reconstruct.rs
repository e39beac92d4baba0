//! Reconstruction throughput, native: frames per second of the engine on simulated 20 s
//! sessions with 1 and 3 observers (3-point tracking), with the shipped models (`models/`),
//! against ego-only on the same session as the in-run reference; and the app's whole job
//! (ego-exo plus the ego-only overlay) as one job sharing the ego pass against two separate
//! reconstructions (EgoNet twice). Run with `cargo bench -p egoexo-infer`; criterion reports
//! medians, and the throughput lines give frames per second.

mod common;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use egoexo_core::aligned::AlignedSession;
use egoexo_infer::{Engine, Method, ReconstructOptions};
use egoexo_session::align::{AlignOptions, align};
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::{SynthConfig, simulate};

fn engine() -> Engine {
    Engine::new().with_models(common::three_point_models())
}

fn session(observers: usize) -> AlignedSession {
    let sim = simulate(&walking_circle(20.0), "bench", &SynthConfig { observers, ..SynthConfig::default() }, 1)
        .expect("simulates");
    align(&sim.session, &AlignOptions::default()).expect("aligns")
}

fn reconstruct(c: &mut Criterion) {
    let engine = engine();
    let mut group = c.benchmark_group("reconstruct");
    group.sample_size(10);
    for observers in [1, 3] {
        let aligned = session(observers);
        group.throughput(Throughput::Elements(aligned.timeline.frames as u64));
        for method in [Method::EgoOnly, Method::EgoExo] {
            let options = ReconstructOptions { method, ..ReconstructOptions::default() };
            group.bench_with_input(
                BenchmarkId::new(method.name(), format!("{observers}-observer")),
                &aligned,
                |b, aligned| b.iter(|| engine.reconstruct(aligned, &options, &mut |_| true).expect("reconstructs")),
            );
        }
        let options = ReconstructOptions::default();
        let app_job = [Method::EgoExo, Method::EgoOnly];
        group.bench_with_input(
            BenchmarkId::new("app-job-shared-ego-pass", format!("{observers}-observer")),
            &aligned,
            |b, aligned| {
                b.iter(|| engine.reconstruct_each(aligned, &options, &app_job, &mut |_| true).expect("reconstructs"))
            },
        );
        group.bench_with_input(
            BenchmarkId::new("app-job-two-reconstructions", format!("{observers}-observer")),
            &aligned,
            |b, aligned| {
                b.iter(|| {
                    app_job.map(|method| {
                        let options = ReconstructOptions { method, ..options };
                        engine.reconstruct(aligned, &options, &mut |_| true).expect("reconstructs")
                    })
                })
            },
        );
    }
    group.finish();
}

criterion_group!(benches, reconstruct);
criterion_main!(benches);
