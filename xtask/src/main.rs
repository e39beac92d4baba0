//! `cargo xtask`: the project's build and test automation (the cargo xtask pattern).
//!
//! - `cargo xtask test` — installs what is missing (wasm target, wasm-bindgen-cli at the
//!   Cargo.lock version, Chromium + chromedriver, the Python venv `target/py` from
//!   `tests/requirements.txt`, `tests/node_modules` from `tests/package-lock.json`), runs the
//!   native tests of the workspace (with `EGOEXO_PYTHON` and `EGOEXO_NODE_MODULES` set),
//!   then the browser tests (wasm-bindgen-test in headless Chromium), and prints the counts.

mod cmd;
mod test;
mod tools;

use std::path::PathBuf;

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
    }
}

/// The repository root (the parent of this crate's directory).
fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask lives in the workspace").to_path_buf()
}
