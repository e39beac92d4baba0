//! Finding or installing the tools the browser tests need: the wasm32 target,
//! wasm-bindgen-cli at exactly the Cargo.lock version, Chromium and chromedriver.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

use crate::cmd;

/// Paths of the tools a browser test run uses.
#[derive(Debug, Clone)]
pub struct BrowserTestTools {
    pub wasm_bindgen_test_runner: PathBuf,
    pub chromium: PathBuf,
    pub chromedriver: PathBuf,
}

/// Ensures every tool is present (installing what it can) and returns their paths.
pub fn ensure_browser_test_tools(root: &Path) -> Result<BrowserTestTools> {
    let wasm_bindgen_test_runner = ensure_wasm_test_runner(root)?;
    let (chromium, chromedriver) = ensure_chromium()?;
    Ok(BrowserTestTools { wasm_bindgen_test_runner, chromium, chromedriver })
}

/// The wasm32 target and the `wasm-bindgen-test-runner` matching Cargo.lock (built from
/// crates.io when missing: CPU-bound, several minutes); its path.
pub fn ensure_wasm_test_runner(root: &Path) -> Result<PathBuf> {
    ensure_wasm_target()?;
    ensure_wasm_bindgen_cli(root)
}

const WASM_TARGET: &str = "wasm32-unknown-unknown";

/// The wasm target and the `wasm-bindgen` CLI matching Cargo.lock (installed with the test
/// runner, next to it).
pub fn ensure_wasm_bindgen(root: &Path) -> Result<PathBuf> {
    ensure_wasm_target()?;
    Ok(ensure_wasm_bindgen_cli(root)?.with_file_name("wasm-bindgen"))
}

fn ensure_wasm_target() -> Result<()> {
    let installed = cmd::output(Command::new("rustup").args(["target", "list", "--installed"]))
        .context("rustup is needed to add the wasm32 target")?;
    if !installed.lines().any(|l| l.trim() == WASM_TARGET) {
        cmd::run(Command::new("rustup").args(["target", "add", WASM_TARGET]))?;
    }
    Ok(())
}

/// The `wasm-bindgen` version pinned in Cargo.lock.
pub fn locked_wasm_bindgen_version(root: &Path) -> Result<String> {
    let lock = std::fs::read_to_string(root.join("Cargo.lock")).context("reading Cargo.lock")?;
    let mut lines = lock.lines();
    while let Some(line) = lines.next() {
        if line.trim() == "name = \"wasm-bindgen\"" {
            let version = lines.next().unwrap_or_default().trim();
            if let Some(v) = version.strip_prefix("version = \"").and_then(|v| v.strip_suffix('"')) {
                return Ok(v.to_string());
            }
        }
    }
    bail!("Cargo.lock has no wasm-bindgen package")
}

/// `wasm-bindgen-test-runner` matching Cargo.lock: from PATH if its version matches, else the
/// workspace's own build of it (package `xtask-wasm-bindgen`, in `target/debug`; `cargo test
/// --workspace` builds it with the rest), built now if missing or stale.
fn ensure_wasm_bindgen_cli(root: &Path) -> Result<PathBuf> {
    let version = locked_wasm_bindgen_version(root)?;
    let wanted = format!("wasm-bindgen {version}");
    if cmd::output(Command::new("wasm-bindgen").arg("--version")).as_deref() == Some(wanted.as_str())
        && let Some(path) = find_on_path("wasm-bindgen-test-runner")
    {
        return Ok(path);
    }
    let bin = root.join("target").join("debug");
    let runner = bin.join("wasm-bindgen-test-runner");
    let cli = bin.join("wasm-bindgen");
    let built =
        || runner.exists() && cmd::output(Command::new(&cli).arg("--version")).as_deref() == Some(wanted.as_str());
    if built() {
        return Ok(runner);
    }
    eprintln!("building wasm-bindgen-cli {version} (package xtask-wasm-bindgen; several minutes, once)");
    cmd::run(Command::new("cargo").args(["build", "--quiet", "--package", "xtask-wasm-bindgen", "--bins"]))?;
    if !built() {
        bail!("{} is not `{wanted}` after building package xtask-wasm-bindgen", cli.display());
    }
    Ok(runner)
}

pub fn ensure_chromium() -> Result<(PathBuf, PathBuf)> {
    let find = || (find_on_path("chromium").or_else(|| find_on_path("chromium-browser")), find_on_path("chromedriver"));
    if let (Some(chromium), Some(driver)) = find() {
        return Ok((chromium, driver));
    }
    // Without Debian's recommended packages (udev, upower, a printer dialog and what they pull
    // in: 131 packages on a fresh machine): a headless Chromium needs none of them, only a font.
    let install =
        "apt-get update && apt-get install -y --no-install-recommends chromium chromium-driver fonts-liberation";
    if !is_root() {
        bail!(
            "Chromium and chromedriver are needed for the browser tests; install them with:\n    sudo sh -c '{install}'"
        );
    }
    eprintln!("installing Debian chromium + chromium-driver");
    cmd::run(Command::new("sh").args(["-c", &format!("DEBIAN_FRONTEND=noninteractive {install}")]))?;
    match find() {
        (Some(chromium), Some(driver)) => Ok((chromium, driver)),
        _ => bail!("chromium/chromedriver still missing after `{install}`"),
    }
}

fn is_root() -> bool {
    cmd::output(Command::new("id").arg("-u")).as_deref() == Some("0")
}

/// First executable named `name` on PATH.
pub fn find_on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).map(|dir| dir.join(name)).find(|p| p.is_file())
}

/// Paths of the Python venv and the Node packages the native tests use.
#[derive(Debug, Clone)]
pub struct NativeTestTools {
    /// The venv's interpreter (`target/py/bin/python`), with `tests/requirements.txt`.
    pub python: PathBuf,
    /// `tests/node_modules`, installed from `tests/package-lock.json`.
    pub node_modules: PathBuf,
}

/// Ensures the Python venv and the Node packages are installed and current.
pub fn ensure_native_test_tools(root: &Path) -> Result<NativeTestTools> {
    let python = ensure_python_venv(root)?;
    let node_modules = ensure_node_packages(root)?;
    Ok(NativeTestTools { python, node_modules })
}

/// The uv (PyPI) that installs `tests/requirements.txt` into the tests' venv. Pinned; bump
/// deliberately.
const UV_VERSION: &str = "0.13.10";

/// The tests' venv interpreter, `target/py/bin/python` (it may not exist yet).
pub fn venv_python(root: &Path) -> PathBuf {
    root.join("target").join("py").join("bin").join("python")
}

/// `target/py`, a venv with the pinned `tests/requirements.txt`; reinstalled when that file
/// changes (a copy of what was installed is kept in the venv).
fn ensure_python_venv(root: &Path) -> Result<PathBuf> {
    let venv = root.join("target").join("py");
    let python = venv_python(root);
    let requirements = root.join("tests").join("requirements.txt");
    let wanted =
        std::fs::read_to_string(&requirements).with_context(|| format!("reading {}", requirements.display()))?;
    let stamp = venv.join("egoexo-requirements.txt");
    if python.exists() && std::fs::read_to_string(&stamp).ok().as_deref() == Some(wanted.as_str()) {
        return Ok(python);
    }
    if !python.exists() {
        let make_venv = || cmd::run(Command::new("python3").args(["-m", "venv"]).arg(&venv));
        if make_venv().is_err() {
            // Debian's python3 needs python3-venv for `-m venv`.
            apt_install("python3 python3-venv", "the Python test environment")?;
            let _ = std::fs::remove_dir_all(&venv);
            make_venv()?;
        }
    }
    // The packages through uv (from PyPI, into the venv by pip): it installs the same pinned
    // wheels as pip, and like `pip --no-compile` leaves byte-compiling to the imports. On a
    // fresh machine (empty caches, ~4 GB of wheels, torch's CUDA libraries among them), one
    // after the other: pip 117 s of wall clock and 106 s of CPU, uv 30 s and 37 s (pip
    // installing uv included) — CPU the native test build beside it gets back
    // (docs/performance.md).
    cmd::run(
        Command::new(&python)
            .args(["-m", "pip", "install", "--disable-pip-version-check", "-q"])
            .arg(format!("uv=={UV_VERSION}")),
    )?;
    cmd::run(
        Command::new(&python)
            .args(["-m", "uv", "pip", "install", "-q", "--python"])
            .arg(&python)
            .arg("-r")
            .arg(&requirements),
    )?;
    std::fs::write(&stamp, wanted)?;
    Ok(python)
}

/// `tests/node_modules` from `tests/package-lock.json` (`npm ci`); reinstalled when the lock
/// file changes.
pub fn ensure_node_packages(root: &Path) -> Result<PathBuf> {
    let dir = root.join("tests");
    let node_modules = dir.join("node_modules");
    let lock = std::fs::read_to_string(dir.join("package-lock.json")).context("reading tests/package-lock.json")?;
    let stamp = node_modules.join(".egoexo-package-lock.json");
    if std::fs::read_to_string(&stamp).ok().as_deref() == Some(lock.as_str()) {
        return Ok(node_modules);
    }
    if find_on_path("npm").is_none() || find_on_path("node").is_none() {
        apt_install("nodejs npm", "the Node test packages")?;
    }
    cmd::run(Command::new("npm").args(["ci", "--no-audit", "--no-fund"]).current_dir(&dir))?;
    std::fs::write(&stamp, lock)?;
    Ok(node_modules)
}

/// Installs Debian packages when running as root; otherwise says what to run.
fn apt_install(packages: &str, purpose: &str) -> Result<()> {
    let install = format!("apt-get update && apt-get install -y {packages}");
    if !is_root() {
        bail!("{purpose} needs Debian packages; install them with:\n    sudo sh -c '{install}'");
    }
    eprintln!("installing Debian {packages} for {purpose}");
    cmd::run(Command::new("sh").args(["-c", &format!("DEBIAN_FRONTEND=noninteractive {install}")]))
}
