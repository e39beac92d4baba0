//! An hour-long session natively: a simulated hour of walking (108,000 frames at 30 fps, two
//! observers, 3-point) reconstructed as the app's whole job (ego-exo + the ego-only overlay,
//! one shared ego pass) with the shipped models, one after another and with the windows on
//! every core; prints frames per second and the process's peak resident memory after each
//! phase (Linux `VmHWM`).
//!
//! `cargo run --release -p egoexo-infer --features parallel --example hour_session -- MODELS_DIR [SECONDS]`

use std::time::Instant;

use egoexo_core::TrackingMode;
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;
use egoexo_infer::{Engine, InferError, Method, ReconstructOptions};
use egoexo_session::align::{AlignOptions, align};
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::{SynthConfig, simulate};

/// Peak resident memory of this process so far, MB (0 where `/proc` has no answer).
fn peak_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).map(str::to_owned))
        .and_then(|l| l.split_whitespace().nth(1).and_then(|kb| kb.parse::<f64>().ok()))
        .map_or(0.0, |kb| kb / 1024.0)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = std::path::Path::new(args.first().ok_or("usage: hour_session MODELS_DIR [SECONDS]")?);
    let seconds: f32 = args.get(1).map_or(Ok(3600.0), |s| s.parse())?;
    let manifest = Manifest::from_json(&std::fs::read(dir.join("manifest.json"))?)?;
    let set = ModelSet::load(manifest.model_set(TrackingMode::ThreePoint).ok_or("no 3-point models")?, |f| {
        std::fs::read(dir.join(f)).map_err(|e| InferError::ReadModel { file: f.into(), message: e.to_string() })
    })?;
    let engine = Engine::new().with_models(set);
    println!("models loaded: peak {:.0} MB", peak_mb());

    let started = Instant::now();
    let config = SynthConfig { observers: 2, tracking: TrackingMode::ThreePoint, ..SynthConfig::default() };
    let sim = simulate(&walking_circle(seconds), "hour", &config, 1)?;
    let aligned = align(&sim.session, &AlignOptions::default())?;
    drop(sim);
    let frames = aligned.timeline.frames;
    println!(
        "simulated and aligned {frames} frames ({:.0} s of session) in {:.1} s: peak {:.0} MB",
        frames as f64 / 30.0,
        started.elapsed().as_secs_f64(),
        peak_mb()
    );

    let options = ReconstructOptions::default();
    let job = [Method::EgoExo, Method::EgoOnly];
    let started = Instant::now();
    let results = engine.reconstruct_each(&aligned, &options, &job, &mut |_| true)?;
    let sequential = started.elapsed().as_secs_f64();
    println!(
        "whole job, one thread: {:.1} s, {:.0} frames/s; peak {:.0} MB",
        sequential,
        frames as f64 / sequential,
        peak_mb()
    );
    drop(results);
    let started = Instant::now();
    let results = engine.reconstruct_each_in_parallel(&aligned, &options, &job, &mut |_| true)?;
    let parallel = started.elapsed().as_secs_f64();
    println!(
        "whole job, {} threads: {:.1} s, {:.0} frames/s ({:.2}x); peak {:.0} MB",
        rayon::current_num_threads(),
        parallel,
        frames as f64 / parallel,
        sequential / parallel,
        peak_mb()
    );
    println!("{} reconstructions of {} frames", results.len(), results[0].motion.len());
    Ok(())
}
