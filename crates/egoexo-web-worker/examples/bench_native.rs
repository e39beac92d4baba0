//! The bench page's reference, natively: the same session, models and jobs as `web/bench.js`
//! (one warm-up, then per run the ego-exo reconstruction alone and the app's whole job:
//! ego-exo + ego-only overlay + scene JSON), timed here with the clock. `cargo xtask bench-web`
//! runs it next to the page and prints the ratio.
//!
//! `cargo run --release -p egoexo-web-worker --example bench_native -- MODELS_DIR SESSION [RUNS]`

use std::time::Instant;

use egoexo_infer::InferError;
use egoexo_web_worker::SessionWorker;

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    let m = xs.len() / 2;
    if xs.len() % 2 == 1 { xs[m] } else { 0.5 * (xs[m - 1] + xs[m]) }
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
    let summary = worker.import_archive(session, std::fs::read(session)?)?;
    let mut time = |overlay: bool| -> Result<f64, Box<dyn std::error::Error>> {
        let started = Instant::now();
        worker.reconstruct(overlay, &mut |_| true)?;
        if overlay {
            worker.scene_json()?;
        }
        Ok(started.elapsed().as_secs_f64())
    };
    time(false)?;
    let (mut ego_exo, mut app) = (Vec::new(), Vec::new());
    for _ in 0..runs.max(1) {
        ego_exo.push(time(false)?);
        app.push(time(true)?);
    }
    let frames = summary.frames as f64;
    println!(
        "BENCH_NATIVE {{\"frames\":{},\"runs\":{},\"median_fps\":{},\"median_app_fps\":{}}}",
        summary.frames,
        runs.max(1),
        frames / median(ego_exo),
        frames / median(app)
    );
    Ok(())
}
