//! The shipped networks against this machine's limit, natively, one thread: per network of
//! a tracking mode, FLOPs per window (from the ONNX graph), median ms per window, achieved
//! GFLOP/s, and the GFLOP/s of a plain matrix product of the network's dominant shape through
//! the same engine (the attainable); `cargo xtask bench-web` prints it beside the browser's.
//!
//! `cargo run --release -p egoexo-infer --example bench_networks -- MODELS_DIR [POINTS] [RUNS]`

use std::time::Instant;

use egoexo_infer::cost::{MatmulProbe, bench_inputs, network_cost};
use egoexo_infer::manifest::{Manifest, NETWORK_NAMES};
use egoexo_infer::models::OnnxModel;
use egoexo_infer::timing::median;

/// Median ms of `f` over `runs` calls after two warm-up calls.
fn median_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    f();
    let times: Vec<f64> = (0..runs)
        .map(|_| {
            let started = Instant::now();
            f();
            started.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    median(&times)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = std::path::Path::new(args.first().ok_or("usage: bench_networks MODELS_DIR [POINTS] [RUNS]")?);
    let points: u8 = args.get(1).map_or(Ok(3), |p| p.parse())?;
    let runs: usize = args.get(2).map_or(Ok(30), |r| r.parse())?;
    let manifest = Manifest::from_json(&std::fs::read(dir.join("manifest.json"))?)?;
    let set = manifest.model_set_for_points(points).ok_or_else(|| format!("no offline {points}-point model set"))?;
    println!(
        "{:<15} {:>9} {:>9} {:>9} {:>22} {:>10} {:>9}",
        "network", "MFLOP", "ms", "GFLOP/s", "dominant product", "attainable", "achieved"
    );
    let mut rows = Vec::new();
    // Sets exported before `fusion_ego_only` existed have the other three.
    for (name, file) in NETWORK_NAMES.iter().filter_map(|&name| Some((name, set.network(name)?))) {
        let bytes = std::fs::read(dir.join(&file.file))?;
        let shapes: Vec<Vec<usize>> = file.inputs.iter().map(|i| i.shape.clone()).collect();
        let cost = network_cost(&file.file, &bytes, &shapes)?;
        let model = OnnxModel::load(&file.file, &bytes, &shapes)?;
        let inputs = bench_inputs(&file.inputs);
        let refs: Vec<&[f32]> = inputs.iter().map(Vec::as_slice).collect();
        let ms = median_ms(runs, || drop(model.run(&refs).expect("the network runs")));
        let achieved = cost.flops as f64 / (ms * 1e6);
        let dominant = cost.dominant_matmul().ok_or("no matrix product")?;
        let probe = MatmulProbe::new(dominant)?;
        let probe_ms = median_ms(runs * 4, || {
            let _ = probe.run().expect("the probe runs");
        });
        let attainable = dominant.flops() as f64 / (probe_ms * 1e6);
        let shape = format!("{}x({}x{})·({}x{})", dominant.batch, dominant.m, dominant.k, dominant.k, dominant.n);
        println!(
            "{name:<15} {:>9.2} {ms:>9.3} {achieved:>9.2} {shape:>22} {attainable:>10.2} {:>8.0}%",
            cost.flops as f64 / 1e6,
            100.0 * achieved / attainable
        );
        rows.push(serde_json::json!({
            "network": name, "flops": cost.flops, "matmul_flops": cost.matmul_flops, "ms": ms,
            "gflops": achieved, "dominant": [dominant.batch, dominant.m, dominant.k, dominant.n],
            "attainable_gflops": attainable,
        }));
    }
    println!("BENCH_NETWORKS {}", serde_json::json!({ "points": points, "runs": runs, "networks": rows }));
    Ok(())
}
