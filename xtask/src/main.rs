//! `cargo xtask`: the project's build and test automation (the cargo xtask pattern).
//!
//! - `cargo xtask test` — installs what is missing (wasm target, wasm-bindgen-cli at the
//!   Cargo.lock version, Chromium + chromedriver, the Python venv `target/py` from
//!   `tests/requirements.txt`, `tests/node_modules` from `tests/package-lock.json`), runs the
//!   native tests of the workspace (with `EGOEXO_PYTHON` and `EGOEXO_NODE_MODULES` set),
//!   then the browser tests (wasm-bindgen-test in headless Chromium), builds the web app and
//!   runs its end-to-end tests (Playwright) and bench page, and prints the counts.
//! - `cargo xtask serve` — builds the web app into `dist/` (both wasm modules with the shipped
//!   profile `wasm-dist`, wasm-bindgen, `web/` + `public/` + the models) and serves it on
//!   http://127.0.0.1:8080/.
//! - `cargo xtask dist` — only builds `dist/`; `cargo xtask bench-web` — runs the bench page.

mod cmd;
// The docs name only flags `cargo xtask` has (a test).
#[cfg(test)]
mod docs_flags;
mod e2e;
#[cfg(test)]
mod layers;
// The module-circle check runs as a test (`cargo test -p xtask`, part of `cargo xtask test`).
#[cfg(test)]
mod modules;
mod serve;
mod test;
mod tools;
mod web;

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "cargo xtask", about = "egoexo build and test automation")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run every test: native, then wasm in headless Chromium. Installs missing tools first.
    Test {
        /// Skip the browser (wasm) tests.
        #[arg(long)]
        native_only: bool,
        /// Skip the native tests.
        #[arg(long)]
        wasm_only: bool,
    },
    /// Install (if missing) the tools the tests need, and print where they are.
    Setup,
    /// Build the web app into dist/ and serve it with `egoexo serve` on 127.0.0.1 (default
    /// port 8080), shares in target/shares.
    Serve {
        #[command(flatten)]
        app: AppArgs,
        #[arg(long, default_value_t = 8080)]
        port: u16,
        /// The address to listen on: 127.0.0.1 (this machine only) unless a device elsewhere
        /// must reach it — `0.0.0.0` or the machine's LAN address lets anyone on the network
        /// open the page, make rooms and upload shares (docs/hosting.md).
        #[arg(long, default_value = "127.0.0.1")]
        host: std::net::IpAddr,
    },
    /// Build the web app into dist/ only.
    Dist {
        #[command(flatten)]
        app: AppArgs,
    },
    /// Build the web app and run its bench page in headless Chromium (median frames/s).
    BenchWeb {
        #[command(flatten)]
        app: AppArgs,
        /// Timed reconstructions (after one warm-up).
        #[arg(long, default_value_t = 5)]
        runs: u32,
    },
}

/// How to build the web app.
#[derive(clap::Args)]
struct AppArgs {
    /// Models folder (manifest.json + ONNX files); default: EGOEXO_MODELS, else models/.
    #[arg(long)]
    models: Option<PathBuf>,
    /// Run wasm-opt (npm `binaryen`) on the modules: smaller raw, larger gzipped on the LTO
    /// build (docs/performance.md), so off by default.
    #[arg(long)]
    wasm_opt: bool,
    /// The tests' build of the modules (profile wasm-release: no LTO, function names kept):
    /// much quicker to rebuild after a change, a few per cent faster, 40 % larger.
    #[arg(long)]
    test_build: bool,
}

impl AppArgs {
    /// Builds dist/ and prints the module sizes.
    fn build(&self, root: &Path) -> Result<()> {
        let models = web::models_dir(root, self.models.as_deref())?;
        if self.wasm_opt {
            // npm `binaryen` (a current wasm-opt) comes with the test packages.
            if tools::find_on_path("npm").is_some() {
                tools::ensure_node_packages(root)?;
            }
        }
        let opt = if self.wasm_opt { web::WasmOpt::IfAvailable } else { web::WasmOpt::Off };
        let build = if self.test_build { web::WasmBuild::Tests } else { web::WasmBuild::Shipped };
        let sizes = web::build_dist(root, &models, build, opt)?;
        println!("dist/ assembled (models from {}):", models.display());
        web::print_sizes(&sizes);
        Ok(())
    }
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    let root = workspace_root();
    std::env::set_current_dir(&root)?;
    match cli.command {
        Command::Test { native_only, wasm_only } => test::run(&root, !wasm_only, !native_only),
        Command::Setup => {
            let t = tools::ensure_browser_test_tools(&root)?;
            println!("wasm-bindgen-test-runner: {}", t.wasm_bindgen_test_runner.display());
            println!("chromium: {}", t.chromium.display());
            println!("chromedriver: {}", t.chromedriver.display());
            let n = tools::ensure_native_test_tools(&root)?;
            println!("python (venv, EGOEXO_PYTHON): {}", n.python.display());
            println!("node_modules (EGOEXO_NODE_MODULES): {}", n.node_modules.display());
            Ok(())
        }
        Command::Serve { app, port, host } => {
            if let Some(warning) = serve::exposure_warning(host) {
                eprintln!("warning: {warning}");
            }
            app.build(&root)?;
            let store = root.join("target").join("shares");
            let egoexo = serve::build_server(&root)?;
            let listen = std::net::SocketAddr::new(host, port).to_string();
            let running = serve::spawn(&egoexo, &root.join("dist"), &store, &listen)?;
            println!("egoexo is at {} (shares in {}; Ctrl-C to stop)", running.url, store.display());
            running.wait()
        }
        Command::Dist { app } => app.build(&root),
        Command::BenchWeb { app, runs } => {
            app.build(&root)?;
            let chromium = tools::ensure_browser_test_tools(&root)?.chromium;
            let egoexo = serve::build_server(&root)?;
            let run = e2e::BrowserRun { chromium, egoexo, out: root.join("target").join("e2e") };
            let web = e2e::run_bench(&root, &run, runs)?;
            let models = web::models_dir(&root, app.models.as_deref())?;
            let native = e2e::run_native_reference(&root, &models, runs)?;
            println!("bench: {} frames, medians of {} runs (after one warm-up)", web.frames, web.runs);
            for (what, w, n) in [
                ("ego-exo", web.median_fps, native.median_fps),
                ("whole app job", web.median_app_fps, native.median_app_fps),
            ] {
                println!(
                    "  {what:<14} browser worker {w:>8.0} frames/s, native {n:>8.0} frames/s, browser/native {:.2}",
                    w / n
                );
            }
            print_pool_line(&web);
            print_stage_table(&web.stages, &native.stages);
            let points = web.networks.as_ref().and_then(|n| n["points"].as_u64()).unwrap_or(3) as u8;
            let native_networks = e2e::run_native_networks(&models, points, 30)?;
            print_network_table(web.networks.as_ref(), &native_networks);
            let observe = e2e::run_observe_bench(&root, &run, OBSERVE_BENCH_SECONDS)?;
            print_observe_bench(&observe);
            Ok(())
        }
    }
}

/// Seconds of once-a-second readings of the observer page's detection rate per detector count.
const OBSERVE_BENCH_SECONDS: u32 = 10;

/// The observer page's detection rate, one detector and two side by side (`OBSERVEBENCH`).
fn print_observe_bench(observe: &serde_json::Value) {
    println!("observer page alone (a film as its camera), detection rate over {} s:", observe["seconds"]);
    for row in observe["rows"].as_array().into_iter().flatten() {
        let goal = observe["goal_fps"].as_f64().unwrap_or(15.0);
        let fps = row["median_fps"].as_f64().unwrap_or(f64::NAN);
        println!(
            "  {} detector(s): median {fps:.0} frames/s (lowest {}, highest {}), {} ms a detection — goal ≥ {goal:.0}/s {}",
            row["detectors"],
            row["min_fps"],
            row["max_fps"],
            row["median_ms"],
            if fps >= goal { "met" } else { "missed" },
        );
    }
}

/// The bench page's pool line (the whole job shared by N workers against one, same run) and
/// its 3D view line (frame time with bodies and with stick figures).
fn print_pool_line(web: &e2e::BenchResult) {
    if let Some((workers, fps, speedup, share)) = web.pool {
        println!(
            "  whole app job, a pool of {workers} workers: {fps:>8.0} frames/s, {speedup:.2}× one worker \
             (helpers computed {:.0} % of the chunks)",
            share * 100.0
        );
    }
    if let Some((backend, width, height, body, stick)) = &web.render {
        println!(
            "  3D view ({backend}, {width}×{height}): {body:.2} ms a frame with bodies, {stick:.2} ms with stick \
             figures ({:.2}×)",
            body / stick
        );
    }
}

/// The per-stage table of the whole job: median ms in the browser's worker and natively.
fn print_stage_table(web: &[(String, f64)], native: &[(String, f64)]) {
    const ORDER: [&str; 10] =
        ["import", "align", "ego-features", "egonet", "exo-features", "gate", "fusion", "decode", "scene", "export"];
    let mut names: Vec<&str> =
        ORDER.iter().copied().filter(|n| web.iter().chain(native).any(|(s, _)| s == n)).collect();
    names.extend(web.iter().chain(native).map(|(s, _)| s.as_str()).filter(|s| !ORDER.contains(s)));
    names.dedup();
    if names.is_empty() {
        return;
    }
    let get = |list: &[(String, f64)], name: &str| list.iter().find(|(s, _)| s == name).map(|(_, ms)| *ms);
    let total = |list: &[(String, f64)]| list.iter().map(|(_, ms)| ms).sum::<f64>();
    println!("per stage (median ms: fresh open, whole job, npz export):");
    println!("  {:<14} {:>10} {:>10} {:>8} {:>7}", "stage", "browser", "native", "ratio", "share");
    let web_total = total(web);
    for name in names {
        let (w, n) = (get(web, name), get(native, name));
        let cell = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        let ratio = match (w, n) {
            (Some(w), Some(n)) if n > 0.0 => format!("{:.2}", w / n),
            _ => "-".into(),
        };
        let share = w.map_or("-".into(), |w| format!("{:.1}%", 100.0 * w / web_total.max(f64::MIN_POSITIVE)));
        println!("  {name:<14} {:>10} {:>10} {ratio:>8} {share:>7}", cell(w), cell(n));
    }
    println!("  {:<14} {:>10.2} {:>10.2}", "total", web_total, total(native));
}

/// The engines side by side per network: tract in the browser against onnxruntime-web (same
/// worker, inputs, one thread), and achieved against attainable GFLOP/s, browser and native.
pub(crate) fn print_network_table(web: Option<&serde_json::Value>, native: &serde_json::Value) {
    let num = |v: &serde_json::Value, k: &str| v[k].as_f64();
    let cell = |v: Option<f64>, d: usize| v.map_or("-".to_string(), |v| format!("{v:.d$}"));
    println!(
        "networks per 96-frame window (median ms; GFLOP/s achieved / attainable by a plain product of the dominant shape):"
    );
    println!(
        "  {:<15} {:>8} {:>9} {:>7} {:>9} {:>13} {:>13} {:>8} {:>8} {:>15}",
        "network",
        "MFLOP",
        "tract-web",
        "ort-web",
        "tract/ort",
        "max |diff|",
        "load tract/ort",
        "native",
        "ort GF/s",
        "GF/s web|native"
    );
    let empty = Vec::new();
    let web_rows = web.and_then(|w| w["networks"].as_array()).unwrap_or(&empty);
    let native_rows = native["networks"].as_array().unwrap_or(&empty);
    let null = serde_json::Value::Null;
    for name in ["egonet", "gate", "fusion", "fusion_ego_only"] {
        let w = web_rows.iter().find(|r| r["network"].as_str() == Some(name));
        let n = native_rows.iter().find(|r| r["network"].as_str() == Some(name)).unwrap_or(&null);
        if w.is_none() && n.is_null() {
            continue;
        }
        let get = |k: &str| w.and_then(|w| num(w, k));
        let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) if b > 0.0 => Some(100.0 * a / b),
            _ => None,
        };
        let web_share = ratio(get("tract_gflops"), get("attainable_gflops"));
        let native_share = ratio(num(n, "gflops"), num(n, "attainable_gflops"));
        println!(
            "  {name:<15} {:>8} {:>9} {:>7} {:>9} {:>13} {:>13} {:>8} {:>8} {:>15}",
            cell(num(n, "flops").or_else(|| get("flops")).map(|f| f / 1e6), 2),
            cell(get("tract_ms"), 3),
            cell(get("ort_ms"), 3),
            cell(get("ratio"), 2),
            get("max_abs_diff").map_or("-".into(), |d| format!("{d:.1e}")),
            format!("{}/{}", cell(get("tract_load_ms"), 0), cell(get("ort_load_ms"), 0)),
            cell(num(n, "ms"), 3),
            cell(get("ort_gflops"), 1),
            format!(
                "{}/{} {}%|{}/{} {}%",
                cell(get("tract_gflops"), 1),
                cell(get("attainable_gflops"), 1),
                cell(web_share, 0),
                cell(num(n, "gflops"), 1),
                cell(num(n, "attainable_gflops"), 1),
                cell(native_share, 0)
            ),
        );
    }
    if let Some(missing) = web.and_then(|w| w["ort_missing"].as_str()) {
        println!("  (onnxruntime-web was not available in the page: {missing})");
    }
}

/// The repository root (the parent of this crate's directory).
fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask lives in the workspace").to_path_buf()
}
