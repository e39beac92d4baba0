//! The bench page's reference, natively: the same session, models and jobs as `web/bench.js`
//! (one warm-up, then per run the ego-exo reconstruction alone and the app's whole job:
//! ego-exo + ego-only overlay + scene JSON), timed here with the clock. `cargo xtask bench-web`
//! runs it next to the page and prints the ratio.
//!
//! Per stage, the worker's own timings of a fresh open (import, align) and the whole job, as
//! the page reports them, plus an npz export.
//!
//! `cargo run --release -p egoexo-web-worker --example bench_native -- MODELS_DIR SESSION [RUNS]`

use std::collections::BTreeMap;
use std::time::Instant;

use egoexo_infer::InferError;
use egoexo_protocol::worker::ExportFormat;
use egoexo_web_worker::{SessionWorker, WorkerClock};

fn median(xs: Vec<f64>) -> f64 {
    egoexo_infer::timing::median(&xs)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(models), Some(session)) = (args.first(), args.get(1)) else {
        return Err("usage: bench_native MODELS_DIR SESSION [RUNS]".into());
    };
    let runs: usize = args.get(2).map_or(Ok(5), |r| r.parse())?;
    let dir = std::path::Path::new(models);
    let manifest = std::fs::read(dir.join("manifest.json"))?;
    let mut worker = SessionWorker::new();
    worker.load_models(&manifest, |file| {
        std::fs::read(dir.join(file)).map_err(|e| InferError::ReadModel { file: file.into(), message: e.to_string() })
    })?;
    let origin = Instant::now();
    worker.set_clock(WorkerClock::new(move || origin.elapsed().as_secs_f64() * 1e3));
    let archive = std::fs::read(session)?;
    let summary = worker.import_archive(session, archive.clone())?;
    let time = |worker: &mut SessionWorker, overlay: bool| -> Result<f64, Box<dyn std::error::Error>> {
        let started = Instant::now();
        worker.reconstruct(overlay, &mut |_| true)?;
        if overlay {
            worker.scene_json()?;
        }
        Ok(started.elapsed().as_secs_f64())
    };
    time(&mut worker, false)?;
    let (mut ego_exo, mut app) = (Vec::new(), Vec::new());
    let mut stage_runs: Vec<BTreeMap<String, f64>> = Vec::new();
    for _ in 0..runs.max(1) {
        ego_exo.push(time(&mut worker, false)?);
        worker.import_archive(session, archive.clone())?;
        app.push(time(&mut worker, true)?);
        let mut stages: BTreeMap<String, f64> = BTreeMap::new();
        for t in worker.reconstruction_summary().map(|s| s.timings.clone()).unwrap_or_default() {
            stages.insert(t.stage, t.ms);
        }
        let started = Instant::now();
        worker.export(ExportFormat::Npz)?;
        stages.insert("export".into(), started.elapsed().as_secs_f64() * 1e3);
        stage_runs.push(stages);
    }
    let names: Vec<String> = stage_runs
        .iter()
        .flat_map(|r| r.keys().cloned())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let stages: Vec<serde_json::Value> = names
        .iter()
        .map(|name| {
            let ms = median(stage_runs.iter().map(|r| r.get(name).copied().unwrap_or(0.0)).collect());
            serde_json::json!({ "stage": name, "ms": ms })
        })
        .collect();
    let frames = summary.frames as f64;
    let result = serde_json::json!({
        "frames": summary.frames,
        "runs": runs.max(1),
        "median_fps": frames / median(ego_exo),
        "median_app_fps": frames / median(app),
        "stages": stages,
    });
    println!("BENCH_NATIVE {result}");
    Ok(())
}
