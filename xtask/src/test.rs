//! `cargo xtask test`: native tests, then the browser tests in headless Chromium.

use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result};

use crate::cmd::{self, TestCounts};
use crate::tools;

/// Crates whose tests also run compiled to wasm32 in headless Chromium.
const WASM_TEST_CRATES: &[&str] = &["egoexo-core", "egoexo-viewer"];

/// Single test targets (crate, test) that run compiled to wasm32 in headless Chromium, for
/// crates whose other tests need native I/O.
const WASM_TEST_TARGETS: &[(&str, &str)] = &[("egoexo-session", "export_wasm"), ("egoexo-session", "import_wasm")];

/// Chromium flags for a closed network and a root user (see shared/notes/toolchain.md);
/// wasm-bindgen-test-runner adds `headless` and `no-sandbox` itself.
const CHROMIUM_ARGS: &[&str] = &[
    "disable-background-networking",
    "disable-component-update",
    "disable-sync",
    "no-first-run",
    "disable-quic",
    "disable-default-apps",
    "disable-extensions",
    // WebGPU through SwiftShader: the viewer's tests render with it off-screen and check that
    // it is refused for a canvas (headless Chromium cannot present it).
    "enable-unsafe-webgpu",
    "enable-unsafe-swiftshader",
];

pub fn run(root: &Path, native: bool, wasm: bool) -> Result<()> {
    // Install first, so a missing tool fails fast rather than after the native tests.
    let browser = if wasm { Some(tools::ensure_browser_test_tools(root)?) } else { None };
    let native_tools = if native { Some(tools::ensure_native_test_tools(root)?) } else { None };

    let native_counts = match &native_tools {
        // The exporter tests read their files back with numpy, bvhio and gltf-validator.
        Some(t) => Some(cmd::run_tests(
            Command::new("cargo")
                .args(["test", "--workspace"])
                .env("EGOEXO_PYTHON", &t.python)
                .env("EGOEXO_NODE_MODULES", &t.node_modules),
        )?),
        None => None,
    };

    let wasm_counts = match &browser {
        Some(t) => {
            let webdriver_json = write_webdriver_json(root, &t.chromium)?;
            let mut total = TestCounts::default();
            let crates = WASM_TEST_CRATES.iter().map(|krate| vec!["--package", krate]);
            let targets = WASM_TEST_TARGETS.iter().map(|(krate, test)| vec!["--package", krate, "--test", test]);
            for selection in crates.chain(targets) {
                let counts = cmd::run_tests(
                    Command::new("cargo")
                        .arg("test")
                        .args(&selection)
                        .args(["--target", "wasm32-unknown-unknown"])
                        .env("CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_RUNNER", &t.wasm_bindgen_test_runner)
                        .env("CHROMEDRIVER", &t.chromedriver)
                        .env("WASM_BINDGEN_TEST_WEBDRIVER_JSON", &webdriver_json)
                        .env("WASM_BINDGEN_TEST_TIMEOUT", "300"),
                )?;
                total.passed += counts.passed;
                total.failed += counts.failed;
                total.ignored += counts.ignored;
            }
            Some(total)
        }
        None => None,
    };

    println!();
    println!("== egoexo test summary ==");
    if let Some(c) = native_counts {
        println!("native tests:                    {} passed, {} failed, {} ignored", c.passed, c.failed, c.ignored);
    }
    if let Some(c) = wasm_counts {
        println!("wasm tests (headless Chromium):  {} passed, {} failed, {} ignored", c.passed, c.failed, c.ignored);
    }
    Ok(())
}

/// The WebDriver capabilities file: Debian's Chromium binary and the flags it needs here.
fn write_webdriver_json(root: &Path, chromium: &Path) -> Result<std::path::PathBuf> {
    let dir = root.join("target").join("xtask");
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("webdriver.json");
    let caps = serde_json::json!({
        "goog:chromeOptions": { "binary": chromium, "args": CHROMIUM_ARGS }
    });
    std::fs::write(&path, serde_json::to_string_pretty(&caps)?)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}
