//! `cargo xtask`: the project's build and test automation (the cargo xtask pattern).
//!
//! - `cargo xtask test` — installs what is missing (wasm target, wasm-bindgen-cli at the
//!   Cargo.lock version, Chromium + chromedriver, the Python venv `target/py` from
//!   `tests/requirements.txt`, `tests/node_modules` from `tests/package-lock.json`), runs the
//!   native tests of the workspace (with `EGOEXO_PYTHON` and `EGOEXO_NODE_MODULES` set),
//!   then the browser tests (wasm-bindgen-test in headless Chromium), builds the web app and
//!   runs its end-to-end tests (Playwright) and bench page, and prints the counts.
//! - `cargo xtask serve` — builds the web app into `dist/` (both wasm modules, wasm-bindgen,
//!   wasm-opt, `web/` + `public/` + the models) and serves it on http://127.0.0.1:8080/.
//! - `cargo xtask dist` — only builds `dist/`; `cargo xtask bench-web` — runs the bench page.

mod cmd;
mod e2e;
#[cfg(test)]
mod layers;
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
    /// Skip wasm-opt even when it is available.
    #[arg(long)]
    no_wasm_opt: bool,
}

impl AppArgs {
    /// Builds dist/ and prints the module sizes.
    fn build(&self, root: &Path) -> Result<()> {
        let models = web::models_dir(root, self.models.as_deref())?;
        if !self.no_wasm_opt {
            // npm `binaryen` (a current wasm-opt) comes with the test packages.
            if tools::find_on_path("npm").is_some() {
                tools::ensure_node_packages(root)?;
            }
        }
        let opt = if self.no_wasm_opt { web::WasmOpt::Off } else { web::WasmOpt::IfAvailable };
        let sizes = web::build_dist(root, &models, opt)?;
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
        Command::Serve { app, port } => {
            app.build(&root)?;
            let store = root.join("target").join("shares");
            let running = serve::spawn(&root, &root.join("dist"), &store, &format!("127.0.0.1:{port}"))?;
            println!("egoexo is at {} (shares in {}; Ctrl-C to stop)", running.url, store.display());
            running.wait()
        }
        Command::Dist { app } => app.build(&root),
        Command::BenchWeb { app, runs } => {
            app.build(&root)?;
            let chromium = tools::ensure_browser_test_tools(&root)?.chromium;
            let run = e2e::BrowserRun { chromium, out: root.join("target").join("e2e") };
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
            Ok(())
        }
    }
}

/// The repository root (the parent of this crate's directory).
fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask lives in the workspace").to_path_buf()
}
