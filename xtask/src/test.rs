//! `cargo xtask test`: native tests, then the browser tests in headless Chromium.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result};

use crate::cmd::{self, TestCounts};
use crate::{e2e, serve, tools, web};

/// The tests that run compiled to wasm32 in headless Chromium, with the web app's profile
/// ([`web::WASM_PROFILE`]). They build in **one** `cargo test --no-run`, so every dependency
/// compiles once, with one feature set: four selections built in turn resolved four feature
/// sets and compiled ~240 s of CPU again (syn, web-sys, egoexo-protocol, …; docs/performance.md).
/// That build makes the app's two modules too, which `dist/` is then assembled from
/// ([`web::WasmBuild::BuiltByWasmTests`]).
const WASM_TESTS: &[WasmTests] = &[
    WasmTests::Crate("egoexo-viewer"),
    WasmTests::Crate("egoexo-core"),
    WasmTests::Crate("egoexo-video"),
    WasmTests::Target("egoexo-web-worker", "worker_wasm"),
    WasmTests::Target("egoexo-infer", "parity_wasm"),
    WasmTests::Target("egoexo-motion-io", "export_wasm"),
    WasmTests::Target("egoexo-session", "import_wasm"),
];

/// One entry of [`WASM_TESTS`].
#[derive(Clone, Copy, Debug)]
enum WasmTests {
    /// Every test of the crate: its unit tests and each `tests/*.rs`.
    Crate(&'static str),
    /// One integration test (crate, test) of a crate whose other tests need native I/O. (The
    /// one build selects unit tests with `--lib` for every crate, so these crates' unit tests
    /// are compiled for wasm32 too, but not run.)
    Target(&'static str, &'static str),
}

impl WasmTests {
    fn package(self) -> &'static str {
        match self {
            Self::Crate(package) | Self::Target(package, _) => package,
        }
    }
}

/// Timed reconstructions of the bench page during `cargo xtask test` (a figure, not a check).
const TEST_BENCH_RUNS: u32 = 3;
/// Seconds of the live bench at each lookahead during `cargo xtask test`.
const TEST_LIVE_BENCH_SECONDS: u32 = 6;
/// The short version of the relay load benchmark (the long one: `egoexo live load
/// --duration-s 600`).
const TEST_RELAY_LOAD_SECONDS: u32 = 10;

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

/// Wall-clock time of each phase of a test run, printed in the summary (CI budgets them).
#[derive(Debug, Default)]
struct Phases(Vec<(String, f64)>);

impl Phases {
    /// Runs `f`, recording how long it took under `name`.
    fn time<T>(&mut self, name: impl Into<String>, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let name = name.into();
        let started = Instant::now();
        let result = f();
        let seconds = started.elapsed().as_secs_f64();
        eprintln!("[xtask] {name}: {seconds:.0} s");
        self.0.push((name, seconds));
        result
    }

    fn print(&self) {
        let total: f64 = self.0.iter().map(|(_, s)| s).sum();
        for (name, seconds) in &self.0 {
            println!("  {name:<58} {:>7.0} s", seconds);
        }
        println!("  {:<58} {:>7.0} s", "total", total);
    }
}

/// Free disk a clean `cargo xtask test` needs, in GiB (target/ plus the torch venv, measured
/// on a clean clone: 9.3 GB, of which the venv is 5.6 GB; with headroom).
const DISK_NEEDED_GIB: f64 = 12.0;

/// Free space, in GiB, on the file system holding `path` (from POSIX `df -Pk`), or `None` where
/// `df` is missing or prints something else.
fn free_disk_gib(path: &Path) -> Option<f64> {
    parse_df_available_gib(&cmd::output(Command::new("df").arg("-Pk").arg(path))?)
}

/// The "Available" column (KiB) of `df -Pk`'s one data line, in GiB.
fn parse_df_available_gib(df_output: &str) -> Option<f64> {
    let line = df_output.lines().nth(1)?;
    let available_kib: f64 = line.split_whitespace().nth(3)?.parse().ok()?;
    Some(available_kib / (1024.0 * 1024.0))
}

/// Says up front when the disk is too small for a clean run: otherwise the first sign is the
/// linker dying with a bus error half an hour in.
fn warn_if_disk_low(root: &Path) {
    if let Some(free) = free_disk_gib(root)
        && free < DISK_NEEDED_GIB
    {
        eprintln!(
            "[xtask] warning: {free:.1} GiB free on the disk holding {}; a clean test run needs about \
                 {DISK_NEEDED_GIB:.0} GiB (target/ and the training venv). A linker 'Bus error' or \
                 'No space left on device' below means the disk filled up.",
            root.display()
        );
    }
}

pub fn run(root: &Path, native: bool, wasm: bool) -> Result<()> {
    warn_if_disk_low(root);
    let mut phases = Phases::default();
    // The downloads (pip's wheels, npm's packages, Debian's Chromium: network and disk) run
    // beside the CPU-bound work (building the native tests and wasm-bindgen-test-runner), so
    // a fresh machine waits for whichever is longer instead of both. A missing tool still
    // fails before any test runs.
    let (browser, native_tools) =
        phases.time("tools (downloads) beside the builds of the test runner and native tests", || {
            std::thread::scope(|scope| {
                let downloads = scope.spawn(|| -> Result<_> {
                    // The Node packages are needed by the exporter tests and by the app's browser tests.
                    let native_tools = if native || wasm { Some(tools::ensure_native_test_tools(root)?) } else { None };
                    let chromium = if wasm { Some(tools::ensure_chromium()?) } else { None };
                    Ok((native_tools, chromium))
                });
                // The native build includes wasm-bindgen-test-runner (package
                // `xtask-wasm-bindgen`), so the runner is found after it, not built alone.
                let built = if native {
                    cmd::run(Command::new("cargo").args(["test", "--workspace", "--no-run", "--quiet"]))
                } else {
                    Ok(())
                };
                let runner = if wasm && built.is_ok() { Some(tools::ensure_wasm_test_runner(root)) } else { None };
                let (native_tools, chromium) =
                    downloads.join().map_err(|_| anyhow::anyhow!("the tool downloads panicked"))??;
                built?;
                let browser = match (runner.transpose()?, chromium) {
                    (Some(wasm_bindgen_test_runner), Some((chromium, chromedriver))) => {
                        Some(tools::BrowserTestTools { wasm_bindgen_test_runner, chromium, chromedriver })
                    }
                    _ => None,
                };
                Ok((browser, native_tools))
            })
        })?;

    let wasm_selection = match wasm {
        true => Some(WasmSelection::new(root, WASM_TESTS)?),
        false => None,
    };
    let wasm_env = match &browser {
        Some(t) => Some(WasmTestEnv { tools: t.clone(), webdriver_json: write_webdriver_json(root, &t.chromium)? }),
        None => None,
    };

    // The wasm test builds and `dist/` compile while the native tests run: a test binary with
    // one long test leaves a core idle, and the wasm builds lock another profile's folder. The
    // browsers start only once the native tests are done.
    let (native_counts, built_app) =
        phases.time("native tests, with the wasm test builds and dist/ beside them", || {
            std::thread::scope(|scope| {
                let wasm_build = wasm_env.as_ref().zip(wasm_selection.as_ref()).map(|(_, selection)| {
                    scope.spawn(move || -> Result<(Vec<WasmTestBinary>, Vec<web::ModuleSize>)> {
                        let binaries = selection.build(root)?;
                        // The modules that build made (profile wasm-release); the shipped LTO
                        // build would compile everything again.
                        let models = web::models_dir(root, None)?;
                        let sizes =
                            web::build_dist(root, &models, web::WasmBuild::BuiltByWasmTests, web::WasmOpt::Off)?;
                        Ok((binaries, sizes))
                    })
                });
                let native_counts = match (&native_tools, native) {
                    // The exporter tests read their files back with numpy, bvhio and gltf-validator.
                    (Some(t), true) => Some(cmd::run_tests(
                        Command::new("cargo")
                            .args(["test", "--workspace"])
                            .env("EGOEXO_PYTHON", &t.python)
                            .env("EGOEXO_NODE_MODULES", &t.node_modules),
                    )),
                    _ => None,
                };
                let built_app = wasm_build
                    .map(|handle| handle.join().map_err(|_| anyhow::anyhow!("the wasm builds panicked"))?)
                    .transpose();
                Ok((native_counts.transpose()?, built_app?))
            })
        })?;

    let wasm_counts = match (&wasm_env, built_app) {
        (Some(env), Some((binaries, sizes))) => {
            let name = format!("wasm tests ({} binaries in headless Chromium)", binaries.len());
            let total = phases.time(name, || {
                let mut total = TestCounts::default();
                for binary in &binaries {
                    let counts = cmd::run_tests(&mut env.run_test(binary))?;
                    total.passed += counts.passed;
                    total.failed += counts.failed;
                    total.ignored += counts.ignored;
                }
                Ok(total)
            })?;
            // The `egoexo` the native build made; `cargo build -p egoexo-cli` would resolve
            // other features for its dependencies and compile much of the workspace again.
            let built_by_native_tests = root.join("target").join("debug").join("egoexo");
            let egoexo = if native && built_by_native_tests.is_file() {
                built_by_native_tests
            } else {
                serve::build_server(root)?
            };
            let app = run_web_app(root, &env.tools, egoexo, sizes, &mut phases)?;
            Some((total, app))
        }
        _ => None,
    };

    println!();
    println!("== egoexo test summary ==");
    if let Some(c) = native_counts {
        println!("native tests:                    {} passed, {} failed, {} ignored", c.passed, c.failed, c.ignored);
    }
    if let Some((c, app)) = wasm_counts {
        println!("wasm tests (headless Chromium):  {} passed, {} failed, {} ignored", c.passed, c.failed, c.ignored);
        let e = app.e2e;
        println!("app end to end (Playwright):     {} passed, {} failed, {} ignored", e.passed, e.failed, e.ignored);
        let b = &app.bench;
        println!(
            "bench page ({} frames, median of {}): {:.0} frames/s ego-exo, {:.0} frames/s whole app job",
            b.frames, b.runs, b.median_fps, b.median_app_fps
        );
        crate::print_pool_line(b);
        if b.networks.is_some() {
            crate::print_network_table(b.networks.as_ref(), &serde_json::Value::Null);
        }
        println!(
            "live in the browser (glass-to-skeleton latency; the part up to the worker's post; worker ms per frame):"
        );
        for row in app.live["rows"].as_array().into_iter().flatten() {
            let n = |k: &str| row[k].as_f64().map_or("–".to_string(), |v| format!("{v:.0}"));
            println!(
                "  lookahead {:>2}: p50 {} ms, p95 {} ms (goal ≤ {} ms: {}); posted p50 {} / p95 {} ms; worker {} ms/frame, {} frames",
                row["lookahead"],
                n("latency_p50_ms"),
                n("latency_p95_ms"),
                n("goal_p95_ms"),
                if row["meets_goal"].as_bool() == Some(true) { "met" } else { "missed" },
                n("posted_p50_ms"),
                n("posted_p95_ms"),
                n("worker_ms_per_frame"),
                row["frames"],
            );
        }
        if let Some(hour) = &app.hour {
            println!(
                "hour-long session in the browser ({} frames): imported and reconstructed in {:.1} s ({:.0} frames/s) by {} workers; Chromium peak {:.0} MB in one process, {:.0} MB summed",
                hour["frames"],
                hour["reconstruct_s"].as_f64().unwrap_or(f64::NAN),
                hour["fps"].as_f64().unwrap_or(f64::NAN),
                hour["pool"]["workers"].as_u64().unwrap_or(1),
                hour["peak_process_mb"].as_f64().unwrap_or(f64::NAN),
                hour["sum_of_peaks_mb"].as_f64().unwrap_or(f64::NAN),
            );
        }
        if let Some(first) = &app.first_skeleton {
            let ms = |run: &str, mark: &str| first[run][mark].as_f64().map_or("–".to_string(), |v| format!("{v:.0}"));
            println!(
                "time to first skeleton (page load → sample drawn): cold {} ms, warm {} ms (goal warm ≤ {} ms); models ready {} / {} ms (read {} / {}, check + load {} / {})",
                ms("cold_ms", "first-skeleton"),
                ms("warm_ms", "first-skeleton"),
                first["goal_warm_first_skeleton_ms"],
                ms("cold_ms", "models-ready"),
                ms("warm_ms", "models-ready"),
                ms("cold_ms", "models-read"),
                ms("warm_ms", "models-read"),
                ms("cold_ms", "models-load"),
                ms("warm_ms", "models-load"),
            );
        }
        let r = &app.relay;
        println!(
            "relay load: {} streams × {} Hz, {} viewers: {} of {} frames received, {} lost, {} dropped; latency p50 {:.2} / p95 {:.2} / p99 {:.2} ms; relay CPU {:.1} %, peak {:.1} MiB",
            r["device_streams"],
            r["hz"],
            r["viewers"],
            r["frames_received"],
            r["frames_expected"],
            r["frames_lost"],
            r["dropped_by_relay"],
            r["latency_ms"]["p50"].as_f64().unwrap_or(f64::NAN),
            r["latency_ms"]["p95"].as_f64().unwrap_or(f64::NAN),
            r["latency_ms"]["p99"].as_f64().unwrap_or(f64::NAN),
            r["relay"]["cpu_percent"].as_f64().unwrap_or(f64::NAN),
            r["relay"]["rss_peak_mib"].as_f64().unwrap_or(f64::NAN),
        );
        web::print_sizes(&app.sizes);
    }
    println!("phases (wall clock):");
    phases.print();
    Ok(())
}

/// The `cargo test` arguments that build [`WASM_TESTS`] in one invocation, and which of the
/// binaries it makes to run.
struct WasmSelection {
    tests: &'static [WasmTests],
    /// `--package …`, `--lib`, `--test …`.
    args: Vec<String>,
}

/// A wasm test binary to run: its crate's folder (the working directory, as cargo would set
/// it) and the file.
#[derive(Debug)]
struct WasmTestBinary {
    crate_dir: std::path::PathBuf,
    path: std::path::PathBuf,
}

impl WasmSelection {
    /// The arguments for `tests`. Every `--test NAME` selects that test in each selected crate,
    /// so a name two of these crates use would build a native-only test for wasm32: refused.
    fn new(root: &Path, tests: &'static [WasmTests]) -> Result<Self> {
        let mut packages: Vec<&str> = Vec::new();
        for t in tests {
            if !packages.contains(&t.package()) {
                packages.push(t.package());
            }
        }
        let mut tests_of: Vec<(&str, Vec<String>)> = Vec::new();
        for package in &packages {
            tests_of.push((*package, integration_tests(&root.join("crates").join(package))?));
        }
        let of = |package: &str| tests_of.iter().find(|(p, _)| *p == package).map(|(_, t)| t.clone());
        let mut names: Vec<String> = Vec::new();
        for t in tests {
            match *t {
                WasmTests::Crate(package) => names.extend(of(package).unwrap_or_default()),
                WasmTests::Target(_, test) => names.push(test.to_string()),
            }
        }
        for name in &names {
            let owners: Vec<&str> = tests_of.iter().filter(|(_, t)| t.contains(name)).map(|(p, _)| *p).collect();
            if owners.len() > 1 {
                anyhow::bail!(
                    "the wasm tests select `--test {name}`, which {owners:?} all have: rename one (one \
                     `cargo test` builds every wasm test, and `--test` applies to each crate)"
                );
            }
        }
        let mut args: Vec<String> = packages.iter().flat_map(|p| ["--package".to_string(), p.to_string()]).collect();
        args.push("--lib".into());
        args.extend(names.into_iter().flat_map(|n| ["--test".to_string(), n]));
        Ok(Self { tests, args })
    }

    /// Builds every wasm test (`--no-run`) and returns the binaries to run, in
    /// [`WASM_TESTS`]' order.
    fn build(&self, root: &Path) -> Result<Vec<WasmTestBinary>> {
        let mut c = Command::new("cargo");
        c.arg("test")
            .args(["--profile", web::WASM_PROFILE, "--target", web::WASM_TARGET, "--no-run"])
            .arg("--message-format=json-render-diagnostics")
            .args(&self.args);
        let messages = cmd::json_lines(&mut c)?;
        // The app's modules, which `dist/` is assembled from: built as the libraries of the
        // worker's and the viewer's integration tests.
        for (package, lib) in web::MODULES {
            let wanted = web::module_built_by_tests(root, lib);
            let made = messages.iter().any(|m| {
                m["reason"] == "compiler-artifact"
                    && m["profile"]["test"] == false
                    && m["target"]["name"] == *lib
                    && m["filenames"].as_array().is_some_and(|f| f.iter().any(|f| f.as_str() == wanted.to_str()))
            });
            if !made {
                anyhow::bail!("the wasm test build did not report {} ({package})", wanted.display());
            }
        }
        let built = test_executables(&messages);
        let mut binaries = Vec::new();
        for t in self.tests {
            let crate_dir = root.join("crates").join(t.package());
            let manifest = crate_dir.join("Cargo.toml");
            let found = built.iter().filter(|b| b.manifest == manifest).filter(|b| match *t {
                WasmTests::Crate(_) => true,
                WasmTests::Target(_, test) => b.kind == "test" && b.name == test,
            });
            let before = binaries.len();
            binaries.extend(found.map(|b| WasmTestBinary { crate_dir: crate_dir.clone(), path: b.path.clone() }));
            if binaries.len() == before {
                anyhow::bail!("the wasm test build made no test binary for {t:?}");
            }
        }
        Ok(binaries)
    }
}

/// The integration tests of the crate at `dir`, as cargo finds them: the stems of its
/// `tests/*.rs` and the names of its `tests/*/main.rs`.
fn integration_tests(dir: &Path) -> Result<Vec<String>> {
    let tests = dir.join("tests");
    let mut names = Vec::new();
    if tests.is_dir() {
        for entry in std::fs::read_dir(&tests).with_context(|| format!("listing {}", tests.display()))? {
            let path = entry?.path();
            let name = if path.extension().is_some_and(|e| e == "rs") && path.is_file() {
                path.file_stem()
            } else if path.join("main.rs").is_file() {
                path.file_name()
            } else {
                None
            };
            names.extend(name.map(|s| s.to_string_lossy().into_owned()));
        }
    }
    names.sort();
    Ok(names)
}

/// A test executable cargo reported building.
#[derive(Debug, PartialEq)]
struct BuiltTest {
    /// The crate's `Cargo.toml`.
    manifest: std::path::PathBuf,
    /// `lib` (unit tests) or `test`.
    kind: String,
    name: String,
    path: std::path::PathBuf,
}

/// The test executables among cargo's `--message-format=json` messages.
fn test_executables(messages: &[serde_json::Value]) -> Vec<BuiltTest> {
    messages
        .iter()
        .filter(|m| m["reason"] == "compiler-artifact" && m["profile"]["test"] == true)
        .filter_map(|m| {
            let kinds = m["target"]["kind"].as_array()?;
            let kind = if kinds.iter().any(|k| k == "test") { "test" } else { "lib" };
            Some(BuiltTest {
                manifest: m["manifest_path"].as_str()?.into(),
                kind: kind.into(),
                name: m["target"]["name"].as_str()?.into(),
                path: m["executable"].as_str()?.into(),
            })
        })
        .collect()
}

/// What the web app's browser run produced.
struct WebAppRun {
    sizes: Vec<web::ModuleSize>,
    e2e: TestCounts,
    bench: e2e::BenchResult,
    /// `tests/e2e/live-bench.mjs`'s result.
    live: serde_json::Value,
    /// `egoexo live load`'s report.
    relay: serde_json::Value,
    /// The e2e suite's time to first skeleton (`target/e2e/first-skeleton.json`), cold and warm.
    first_skeleton: Option<serde_json::Value>,
    /// The hour-long browser test's measurements (`target/e2e/hour.json`).
    hour: Option<serde_json::Value>,
}

/// Runs the Playwright suite and the bench page against `dist/` (built beside the native
/// tests, with the models from `models/` or `EGOEXO_MODELS`; `sizes` are its modules').
fn run_web_app(
    root: &Path,
    t: &tools::BrowserTestTools,
    egoexo: std::path::PathBuf,
    sizes: Vec<web::ModuleSize>,
    phases: &mut Phases,
) -> Result<WebAppRun> {
    let run = e2e::BrowserRun { chromium: t.chromium.clone(), egoexo, out: root.join("target").join("e2e") };
    let e2e = phases.time("web app: end to end (Playwright)", || e2e::run_suite(root, &run))?;
    let bench = phases.time("web app: bench page", || e2e::run_bench(root, &run, TEST_BENCH_RUNS))?;
    let live = phases.time("web app: live bench", || e2e::run_live_bench(root, &run, TEST_LIVE_BENCH_SECONDS))?;
    let relay = phases
        .time("relay load (50 streams × 30 Hz)", || e2e::run_relay_load(&run.egoexo, 50, TEST_RELAY_LOAD_SECONDS))?;
    let first_skeleton =
        std::fs::read(run.out.join("first-skeleton.json")).ok().and_then(|bytes| serde_json::from_slice(&bytes).ok());
    let hour = std::fs::read(run.out.join("hour.json")).ok().and_then(|bytes| serde_json::from_slice(&bytes).ok());
    Ok(WebAppRun { sizes, e2e, bench, live, relay, first_skeleton, hour })
}

/// What a wasm `cargo test` needs: the runner, the browser and its capabilities file.
struct WasmTestEnv {
    tools: tools::BrowserTestTools,
    webdriver_json: std::path::PathBuf,
}

impl WasmTestEnv {
    /// Runs one built wasm test binary in headless Chromium, from its crate's folder as
    /// `cargo test` would.
    fn run_test(&self, binary: &WasmTestBinary) -> Command {
        let mut c = Command::new(&self.tools.wasm_bindgen_test_runner);
        c.arg(&binary.path)
            .current_dir(&binary.crate_dir)
            .env("CHROMEDRIVER", &self.tools.chromedriver)
            .env("WASM_BINDGEN_TEST_WEBDRIVER_JSON", &self.webdriver_json)
            .env("WASM_BINDGEN_TEST_TIMEOUT", "300");
        c
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wasm_tests_build_in_one_selection_without_a_shared_test_name() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
        let selection = WasmSelection::new(root, WASM_TESTS).unwrap();
        let args = selection.args.join(" ");
        assert!(args.starts_with("--package egoexo-viewer --package egoexo-core --package egoexo-video"), "{args}");
        assert!(args.contains(" --lib "), "{args}");
        // egoexo-core's tests: its one-binary suite (`tests/core_tests/main.rs`) and the one
        // that runs in a dedicated worker.
        for test in
            ["browser", "core_tests", "pipeline_in_worker", "worker_wasm", "parity_wasm", "export_wasm", "import_wasm"]
        {
            assert!(args.contains(&format!("--test {test}")), "{test} missing from {args}");
        }
    }

    #[test]
    fn a_test_name_two_selected_crates_share_is_refused() {
        // `--test live` would build both crates' `live` tests, whatever the entry meant; a
        // folder test (`tests/live/main.rs`) has its folder's name.
        let root = std::env::temp_dir().join(format!("xtask-wasm-selection-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(root.join("crates/a/tests")).unwrap();
        std::fs::create_dir_all(root.join("crates/b/tests/live")).unwrap();
        std::fs::write(root.join("crates/a/tests/live.rs"), "").unwrap();
        std::fs::write(root.join("crates/a/tests/other.rs"), "").unwrap();
        std::fs::write(root.join("crates/b/tests/live/main.rs"), "").unwrap();
        const WHOLE_CRATE: &[WasmTests] = &[WasmTests::Crate("a"), WasmTests::Target("b", "other")];
        const CLASH: &[WasmTests] = &[WasmTests::Target("a", "live"), WasmTests::Target("b", "live")];
        let whole = WasmSelection::new(&root, WHOLE_CRATE).err().map(|e| e.to_string());
        let clash = WasmSelection::new(&root, CLASH).err().map(|e| e.to_string());
        let _ = std::fs::remove_dir_all(&root);
        let whole = whole.expect("crate a's `live` clashes with crate b's folder test");
        assert!(whole.contains("`--test live`"), "{whole}");
        let clash = clash.expect("a shared test name is refused");
        assert!(clash.contains("`--test live`"), "{clash}");
    }

    /// The `{ opt-level = 0 }` entries of the `[profile.<profile>.package]` table.
    fn unoptimised_crates(cargo_toml: &str, profile: &str) -> Vec<String> {
        let header = format!("[profile.{profile}.package]");
        let table = cargo_toml.split(&header).nth(1).expect("the profile's package table");
        let table = table.split("\n[").next().unwrap();
        table.lines().filter_map(|l| l.strip_suffix(" = { opt-level = 0 }")).map(str::to_string).collect()
    }

    #[test]
    fn the_compile_time_crates_are_unoptimised_in_both_profiles() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
        let cargo_toml = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
        let lock = std::fs::read_to_string(root.join("Cargo.lock")).unwrap();
        let dev = unoptimised_crates(&cargo_toml, "dev");
        assert!(dev.len() >= 10 && dev.contains(&"syn".to_string()), "{dev:?}");
        assert_eq!(dev, unoptimised_crates(&cargo_toml, web::WASM_PROFILE), "the dev and wasm lists differ");
        for name in &dev {
            assert!(lock.contains(&format!("name = \"{name}\"\n")), "{name} is not in Cargo.lock");
        }
    }

    #[test]
    fn finds_the_test_executables_among_cargo_messages() {
        let lines = [
            r#"{"reason":"compiler-artifact","manifest_path":"/w/crates/a/Cargo.toml","target":{"kind":["cdylib","rlib"],"name":"a"},"profile":{"test":true},"executable":"/t/deps/a-1.wasm"}"#,
            r#"{"reason":"compiler-artifact","manifest_path":"/w/crates/a/Cargo.toml","target":{"kind":["cdylib","rlib"],"name":"a"},"profile":{"test":false},"executable":null}"#,
            r#"{"reason":"compiler-artifact","manifest_path":"/w/crates/b/Cargo.toml","target":{"kind":["test"],"name":"b_wasm"},"profile":{"test":true},"executable":"/t/deps/b_wasm-2.wasm"}"#,
            r#"{"reason":"build-finished","success":true}"#,
        ];
        let messages: Vec<serde_json::Value> = lines.iter().map(|l| serde_json::from_str(l).unwrap()).collect();
        let built = test_executables(&messages);
        assert_eq!(
            built,
            vec![
                BuiltTest {
                    manifest: "/w/crates/a/Cargo.toml".into(),
                    kind: "lib".into(),
                    name: "a".into(),
                    path: "/t/deps/a-1.wasm".into()
                },
                BuiltTest {
                    manifest: "/w/crates/b/Cargo.toml".into(),
                    kind: "test".into(),
                    name: "b_wasm".into(),
                    path: "/t/deps/b_wasm-2.wasm".into()
                },
            ]
        );
    }

    #[test]
    fn reads_the_available_column_of_posix_df() {
        let out = "Filesystem     1024-blocks      Used Available Capacity Mounted on\n\
                   /dev/vda         264191980  42991756  53477376      45% /";
        let gib = parse_df_available_gib(out).unwrap();
        assert!((gib - 53_477_376.0 / 1_048_576.0).abs() < 1e-9, "{gib}");
        assert_eq!(parse_df_available_gib("df: /nowhere: No such file or directory"), None);
    }
}
