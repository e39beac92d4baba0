//! Where a shipped network's time goes in tract, op by op, natively, one thread: the
//! optimised plan run `RUNS` times with every node timed, summed per op kind, with each
//! kind's FLOPs (tract's cost model) and GFLOP/s — the arithmetic (products) against the
//! rest (layout changes, elementwise ops, normalisation, softmax).
//!
//! With `TOP` > 0 it also lists the `TOP` slowest nodes (name, op, output shape).
//!
//! `cargo run --release -p egoexo-infer --example profile_network -- MODELS_DIR [POINTS] [NETWORK] [RUNS] [TOP]`

use std::collections::BTreeMap;
use std::io::Cursor;
use std::time::Instant;

use egoexo_infer::cost::bench_inputs;
use egoexo_infer::manifest::Manifest;
use tract_onnx::prelude::*;
use tract_onnx::tract_core::ops::Cost;
use tract_onnx::tract_core::plan::{SimpleState, eval};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = std::path::Path::new(args.first().ok_or("usage: profile_network MODELS_DIR [POINTS] [NETWORK] [RUNS]")?);
    let points: u8 = args.get(1).map_or(Ok(3), |p| p.parse())?;
    let network = args.get(2).map_or("fusion", String::as_str);
    let runs: usize = args.get(3).map_or(Ok(50), |r| r.parse())?;
    let top: usize = args.get(4).map_or(Ok(0), |t| t.parse())?;
    let manifest = Manifest::from_json(&std::fs::read(dir.join("manifest.json"))?)?;
    let set = manifest.model_set_for_points(points).ok_or_else(|| format!("no offline {points}-point model set"))?;
    let file = set.network(network).ok_or_else(|| {
        format!("no network `{network}`: expected one of {}", egoexo_infer::manifest::NETWORK_NAMES.join(", "))
    })?;
    let bytes = std::fs::read(dir.join(&file.file))?;
    let mut model = tract_onnx::onnx().model_for_read(&mut Cursor::new(&bytes))?;
    for (i, shape) in file.input_shapes().iter().enumerate() {
        model = model.with_input_fact(i, f32::fact(shape).into())?;
    }
    let optimised = model.into_optimized()?;
    // FLOPs per node of the optimised graph.
    let mut node_flops = vec![0u64; optimised.nodes().len()];
    for node in optimised.nodes() {
        let facts = optimised.node_input_facts(node.id)?;
        for (cost, n) in node.op.cost(&facts).unwrap_or_default() {
            let n = n.to_i64().unwrap_or(0).max(0) as u64;
            node_flops[node.id] += match cost {
                Cost::FMA(_) => 2 * n,
                Cost::Div(_) => n,
                _ => 0,
            };
        }
    }
    let kinds: Vec<String> = optimised.nodes().iter().map(|n| n.op.name().to_string()).collect();
    let described: Vec<String> = optimised
        .nodes()
        .iter()
        .map(|n| {
            let shape = n.outputs.first().map(|o| format!("{:?}", o.fact.shape)).unwrap_or_default();
            format!("{} {} -> {shape}", n.name, n.op.name())
        })
        .collect();
    let plan = optimised.into_runnable()?;
    let inputs: TVec<TValue> = bench_inputs(&file.inputs)
        .into_iter()
        .zip(file.input_shapes())
        .map(|(data, shape)| Ok(Tensor::from_shape(&shape, &data)?.into()))
        .collect::<TractResult<_>>()?;
    let mut state = SimpleState::new(&plan)?;
    let mut seconds = vec![0f64; kinds.len()];
    let mut total = 0f64;
    for run in 0..runs + 2 {
        let started = Instant::now();
        let mut per_node = vec![0f64; kinds.len()];
        state.run_plan_with_eval(inputs.clone(), |ctx, op_state, node, input| {
            let t = Instant::now();
            let out = eval(ctx, op_state, node, input);
            per_node[node.id] += t.elapsed().as_secs_f64();
            out
        })?;
        // Two warm-up runs.
        if run >= 2 {
            total += started.elapsed().as_secs_f64();
            for (s, p) in seconds.iter_mut().zip(per_node) {
                *s += p;
            }
        }
    }
    let mut by_kind: BTreeMap<&str, (usize, f64, u64)> = BTreeMap::new();
    for (id, kind) in kinds.iter().enumerate() {
        let e = by_kind.entry(kind).or_default();
        e.0 += 1;
        e.1 += seconds[id] / runs as f64;
        e.2 += node_flops[id];
    }
    let mut rows: Vec<_> = by_kind.into_iter().collect();
    rows.sort_by(|a, b| b.1.1.total_cmp(&a.1.1));
    let per_run = total / runs as f64;
    println!("{} ({points}-point {network}), {runs} runs: {:.3} ms per run", file.file, per_run * 1e3);
    println!("{:<28} {:>6} {:>9} {:>7} {:>9} {:>8}", "op", "nodes", "ms", "share", "MFLOP", "GFLOP/s");
    for (kind, (nodes, s, flops)) in rows {
        println!(
            "{kind:<28} {nodes:>6} {:>9.3} {:>6.1}% {:>9.2} {:>8}",
            s * 1e3,
            100.0 * s / per_run,
            flops as f64 / 1e6,
            if flops > 0 { format!("{:.1}", flops as f64 / s / 1e9) } else { "-".into() }
        );
    }
    if top > 0 {
        let mut nodes: Vec<usize> = (0..kinds.len()).collect();
        nodes.sort_by(|&a, &b| seconds[b].total_cmp(&seconds[a]));
        println!("slowest nodes:");
        for id in nodes.into_iter().take(top) {
            println!("  {:>7.3} ms  {}", seconds[id] / runs as f64 * 1e3, described[id]);
        }
    }
    Ok(())
}
