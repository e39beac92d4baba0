//! The app in a real browser: the Playwright suite (`tests/e2e/*.test.mjs`, Node's test runner,
//! `playwright-core` driving Debian's Chromium) and the bench page (`tests/e2e/bench.mjs`),
//! both against `dist/` served by the real server, `egoexo serve` ([`crate::serve`]), with
//! shares in a fresh folder under `target/e2e`.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

use crate::cmd::{self, TestCounts};
use crate::{serve, tools};

/// What the browser scripts need to know.
#[derive(Clone, Debug)]
pub struct BrowserRun {
    pub chromium: PathBuf,
    /// The `egoexo` binary: it serves the app and the tests run its commands.
    pub egoexo: PathBuf,
    /// Screenshots and reports go here (`target/e2e`).
    pub out: PathBuf,
}

impl BrowserRun {
    fn node(&self, root: &Path, url: &str) -> Command {
        let mut c = Command::new("node");
        c.current_dir(root)
            .env("EGOEXO_E2E_URL", url)
            .env("EGOEXO_CHROMIUM", &self.chromium)
            .env("EGOEXO_E2E_OUT", &self.out)
            // The CLI tests (`egoexo share` → the page) use the binary the server runs from.
            .env("EGOEXO_BIN", &self.egoexo);
        // The video export's check decodes the MP4 with PyAV from the tests' venv.
        let python = tools::venv_python(root);
        if python.is_file() {
            c.env("EGOEXO_PYTHON", python);
        }
        c
    }

    /// `egoexo serve` on `dist/` with an empty share store, `shares-{lane}`.
    fn serve(&self, root: &Path, lane: usize) -> Result<serve::Running> {
        let store = self.out.join(format!("shares-{lane}"));
        if store.exists() {
            std::fs::remove_dir_all(&store).with_context(|| format!("clearing {}", store.display()))?;
        }
        serve::spawn(&self.egoexo, &root.join("dist"), &store, "127.0.0.1:0")
    }
}

/// The browser test files that run one after the other once the rest are done, with no other
/// browser beside them: those that measure (time to first skeleton; the hour-long session's
/// rate and memory), so that their figures are comparable from run to run, and those that
/// stream in real time — the live room's and the observer page's. Beside another browser file
/// on this 2-core machine (the bad-input file's pool of workers) the live page showed its 20th
/// frame 7–19 s into a 20 s replay and a late viewer had not drawn by its end, so the checks
/// that need the stream ran after it. Chromium's file camera plays its film slower than real
/// time when starved of CPU (measured beside `live.test.mjs`: 0.1 s behind after 20 s) while
/// the wearer's replay keeps time, and the views it stamps no longer match the wearer (a real
/// camera is a device of its own; in CI a second browser made it miss registration).
pub const RUN_ALONE: &[&str] = &["hour.test.mjs", "live.test.mjs", "observe.test.mjs", "startup.test.mjs"];

/// How many of the other test files run at once. Each lane has its own server (its own share
/// store and per-client rate limits: every test connects from 127.0.0.1) and runs its files one
/// at a time, taking the next from a queue shared by the lanes. Two on this 2-core machine: one
/// file at a time kept ~1.6 cores busy (the live tests stream in real time, the pages wait on
/// their workers); two keep both busy (docs/performance.md has the suite's times).
const LANES: usize = 2;

/// Serves `dist/` and runs every `tests/e2e/*.test.mjs`: the files not in [`RUN_ALONE`] in
/// [`LANES`] lanes, then those, alone. Each file's report is printed whole when it ends.
pub fn run_suite(root: &Path, run: &BrowserRun) -> Result<TestCounts> {
    std::fs::create_dir_all(&run.out)?;
    let (alone, shared) = test_files(&root.join("tests").join("e2e"))?;
    let reports = run.out.join("reports");
    if reports.exists() {
        std::fs::remove_dir_all(&reports).with_context(|| format!("clearing {}", reports.display()))?;
    }
    std::fs::create_dir_all(&reports)?;
    let servers = (0..LANES).map(|lane| run.serve(root, lane)).collect::<Result<Vec<_>>>()?;
    eprintln!(
        "$ node --test: {} files in {LANES} lanes (app at {}), then {} alone",
        shared.len(),
        servers.iter().map(|s| s.url.as_str()).collect::<Vec<_>>().join(", "),
        alone.len()
    );
    let queue = std::sync::Mutex::new(std::collections::VecDeque::from(shared));
    let print = std::sync::Mutex::new(());
    let mut outcomes: Vec<FileOutcome> = std::thread::scope(|scope| {
        let lanes: Vec<_> = servers
            .iter()
            .map(|server| {
                let (queue, print, reports) = (&queue, &print, reports.as_path());
                scope.spawn(move || -> Result<Vec<FileOutcome>> {
                    let mut done = Vec::new();
                    loop {
                        let Some(file) = queue.lock().map_err(|_| anyhow::anyhow!("a lane panicked"))?.pop_front()
                        else {
                            return Ok(done);
                        };
                        done.push(run_file(root, run, &server.url, &file, reports, Some(print))?);
                    }
                })
            })
            .collect();
        lanes.into_iter().try_fold(Vec::new(), |mut all, lane| {
            all.extend(lane.join().map_err(|_| anyhow::anyhow!("a lane of browser tests panicked"))??);
            Ok::<_, anyhow::Error>(all)
        })
    })?;
    for file in &alone {
        outcomes.push(run_file(root, run, &servers[0].url, file, &reports, None)?);
    }
    let mut counts = TestCounts::default();
    let mut failed_files = Vec::new();
    for outcome in &outcomes {
        counts.passed += outcome.counts.passed;
        counts.failed += outcome.counts.failed;
        counts.ignored += outcome.counts.ignored;
        if !outcome.success || outcome.counts.failed > 0 {
            failed_files.push(outcome.name.clone());
        }
    }
    if !failed_files.is_empty() {
        // Again at the end, where a CI log's tail shows it: why each failing file failed.
        for name in &failed_files {
            let report = std::fs::read_to_string(reports.join(format!("{name}.spec"))).unwrap_or_default();
            eprintln!("--- {name}: {}", failures_of(&report));
        }
        bail!(
            "the browser end-to-end tests failed ({} passed, {} failed; in {})",
            counts.passed,
            counts.failed,
            failed_files.join(", ")
        );
    }
    if counts.passed == 0 {
        bail!("the browser end-to-end tests ran no test");
    }
    Ok(counts)
}

/// The failing tests of a spec report (Node's closing "failing tests" section), at most 6,000
/// characters of it; the report's last lines when it has none (the file did not finish).
fn failures_of(spec: &str) -> String {
    const MAX_CHARS: usize = 6000;
    let section = match spec.rfind("failing tests:") {
        Some(at) => &spec[at..],
        None => &spec[spec.len() - spec.chars().rev().take(MAX_CHARS).map(char::len_utf8).sum::<usize>()..],
    };
    let mut shown: String = section.chars().take(MAX_CHARS).collect();
    if shown.len() < section.len() {
        shown.push_str(" …");
    }
    shown
}

/// `tests/e2e/*.test.mjs` by name: (those in [`RUN_ALONE`], the others).
fn test_files(dir: &Path) -> Result<(Vec<PathBuf>, Vec<PathBuf>)> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .map(|e| e.map(|e| e.path()))
        .collect::<std::io::Result<_>>()?;
    files.retain(|p| p.to_string_lossy().ends_with(".test.mjs"));
    files.sort();
    for name in RUN_ALONE {
        if !files.iter().any(|f| f.file_name().is_some_and(|n| n == *name)) {
            bail!("{} has no {name}, which e2e::RUN_ALONE names", dir.display());
        }
    }
    Ok(files.into_iter().partition(|f| f.file_name().is_some_and(|n| RUN_ALONE.iter().any(|a| n == *a))))
}

/// One test file's run.
#[derive(Debug)]
struct FileOutcome {
    name: String,
    success: bool,
    counts: TestCounts,
}

/// Runs one test file against the server at `url`. Its spec and TAP reports go to `reports/`;
/// in a lane (`print` given) the spec report is printed whole, under `print`, when the file
/// ends; alone, it is also printed as it runs.
fn run_file(
    root: &Path,
    run: &BrowserRun,
    url: &str,
    file: &Path,
    reports: &Path,
    print: Option<&std::sync::Mutex<()>>,
) -> Result<FileOutcome> {
    let name = file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tap = reports.join(format!("{name}.tap"));
    let spec = reports.join(format!("{name}.spec"));
    let mut c = run.node(root, url);
    c.args(["--test", "--test-reporter=spec"]).arg(format!("--test-reporter-destination={}", spec.display()));
    if print.is_none() {
        c.args(["--test-reporter=spec", "--test-reporter-destination=stdout"]);
    }
    c.arg("--test-reporter=tap").arg(format!("--test-reporter-destination={}", tap.display())).arg(file);
    let started = std::time::Instant::now();
    if print.is_none() {
        eprintln!("$ node --test {name} (alone, app at {url})");
    }
    let status = c.status().with_context(|| format!("running node on {name} (is Node.js installed?)"))?;
    let counts = tap_counts(&std::fs::read_to_string(&tap).unwrap_or_default());
    if let Some(print) = print {
        let _turn = print.lock().map_err(|_| anyhow::anyhow!("a lane panicked while printing"))?;
        eprintln!("$ node --test {name} (app at {url}): {:.0} s", started.elapsed().as_secs_f64());
        let report = std::fs::read_to_string(&spec).unwrap_or_default();
        print!("{report}");
        use std::io::Write as _;
        std::io::stdout().flush()?;
    }
    Ok(FileOutcome { name, success: status.success(), counts })
}

/// Counts from a TAP report's closing `# pass N` / `# fail N` / `# skipped N` lines.
fn tap_counts(tap: &str) -> TestCounts {
    let mut counts = TestCounts::default();
    for line in tap.lines() {
        let mut words = line.split_whitespace();
        let (Some("#"), Some(kind), Some(n)) = (words.next(), words.next(), words.next()) else { continue };
        let Ok(n) = n.parse::<u64>() else { continue };
        match kind {
            "pass" => counts.passed = n,
            "fail" => counts.failed = n,
            "skipped" | "todo" => counts.ignored += n,
            _ => {}
        }
    }
    counts
}

/// The bench page's result.
#[derive(Clone, Debug)]
pub struct BenchResult {
    pub frames: u64,
    pub runs: u64,
    pub median_fps: f64,
    /// The whole job the app runs (ego-exo + ego-only overlay + scene), median frames/s.
    pub median_app_fps: f64,
    /// Median milliseconds per stage of a fresh open + the whole job + an npz export, as
    /// the worker times them (`import`, `align`, `ego-features`, …, `scene`, `export`).
    pub stages: Vec<(String, f64)>,
    /// The page's engine comparison (`web/bench-networks.js`), when it ran.
    pub networks: Option<serde_json::Value>,
    /// The whole job shared by a pool of workers: (workers, median frames/s, speed-up over
    /// one worker in the same run, median share of chunks the helpers computed).
    pub pool: Option<(u64, f64, f64, f64)>,
    /// The 3D view's median frame time: (backend, width, height, bodies ms, stick figures ms).
    pub render: Option<(String, u64, u64, f64, f64)>,
}

/// Serves `dist/` and runs `web/bench.html` `runs` times through `tests/e2e/bench.mjs`.
pub fn run_bench(root: &Path, run: &BrowserRun, runs: u32) -> Result<BenchResult> {
    std::fs::create_dir_all(&run.out)?;
    let server = run.serve(root, 0)?;
    let script = root.join("tests").join("e2e").join("bench.mjs");
    let out = cmd::output_checked(run.node(root, &server.url).arg(&script).arg(runs.to_string()))?;
    parse_bench_line(&out, "BENCH")
}

/// The last `<prefix> {json}` line of a bench's output as a [`BenchResult`].
fn parse_bench_line(out: &str, prefix: &str) -> Result<BenchResult> {
    let line = out
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix(prefix).and_then(|rest| rest.strip_prefix(' ')))
        .with_context(|| format!("the bench printed no {prefix} line"))?;
    let v: serde_json::Value = serde_json::from_str(line).with_context(|| format!("{prefix} result `{line}`"))?;
    let number = |k: &str| v[k].as_f64().with_context(|| format!("{prefix} result has no `{k}`: {line}"));
    Ok(BenchResult {
        frames: number("frames")? as u64,
        runs: number("runs")? as u64,
        median_fps: number("median_fps")?,
        median_app_fps: number("median_app_fps")?,
        stages: v["stages"]
            .as_array()
            .map(|stages| {
                stages.iter().filter_map(|s| Some((s["stage"].as_str()?.to_string(), s["ms"].as_f64()?))).collect()
            })
            .unwrap_or_default(),
        networks: v.get("networks").cloned(),
        pool: (|| {
            Some((
                v["pool_workers"].as_u64()?,
                v["median_pool_fps"].as_f64()?,
                v["pool_speedup"].as_f64()?,
                v["median_helper_share"].as_f64()?,
            ))
        })(),
        render: (|| {
            let r = &v["render"];
            Some((
                r["backend"].as_str()?.to_string(),
                r["width"].as_u64()?,
                r["height"].as_u64()?,
                r["body_ms"].as_f64()?,
                r["stick_ms"].as_f64()?,
            ))
        })(),
    })
}

/// The native network bench (`crates/egoexo-infer/examples/bench_networks.rs`, release):
/// FLOPs, ms and attainable GFLOP/s per network of `points`-point tracking. Returns its
/// `BENCH_NETWORKS` JSON.
pub fn run_native_networks(models: &Path, points: u8, runs: u32) -> Result<serde_json::Value> {
    let out = cmd::output_checked(
        Command::new("cargo")
            .args(["run", "--quiet", "--release", "-p", "egoexo-infer", "--example", "bench_networks", "--"])
            .arg(models)
            .arg(points.to_string())
            .arg(runs.to_string()),
    )?;
    let line = out
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("BENCH_NETWORKS "))
        .context("the network bench printed no BENCH_NETWORKS line")?;
    serde_json::from_str(line).with_context(|| format!("BENCH_NETWORKS `{line}`"))
}

/// Serves `dist/` and runs the live bench (`tests/e2e/live-bench.mjs`): the page in Live
/// mode fed by `egoexo live replay`, `seconds` at each lookahead. Returns its `LIVEBENCH`
/// JSON.
pub fn run_live_bench(root: &Path, run: &BrowserRun, seconds: u32) -> Result<serde_json::Value> {
    run_script_bench(root, run, "live-bench.mjs", seconds, "LIVEBENCH")
}

/// Serves `dist/` and runs the observer page's detection bench (`tests/e2e/observe-bench.mjs`):
/// the page alone with a film as its camera, one detector and two, `seconds` of readings each.
/// Returns its `OBSERVEBENCH` JSON.
pub fn run_observe_bench(root: &Path, run: &BrowserRun, seconds: u32) -> Result<serde_json::Value> {
    run_script_bench(root, run, "observe-bench.mjs", seconds, "OBSERVEBENCH")
}

/// Serves `dist/`, runs `tests/e2e/<script> <seconds>` and parses the JSON of its last line
/// that starts with `<tag> `.
fn run_script_bench(root: &Path, run: &BrowserRun, script: &str, seconds: u32, tag: &str) -> Result<serde_json::Value> {
    std::fs::create_dir_all(&run.out)?;
    let server = run.serve(root, 0)?;
    let path = root.join("tests").join("e2e").join(script);
    let out = cmd::output_checked(run.node(root, &server.url).arg(&path).arg(seconds.to_string()))?;
    let prefix = format!("{tag} ");
    let line = out
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix(prefix.as_str()))
        .with_context(|| format!("{script} printed no {tag} line"))?;
    serde_json::from_str(line).with_context(|| format!("{tag} result `{line}`"))
}

/// The relay under load on loopback (`egoexo live load`, which starts its own server):
/// `streams` device streams (10 rooms) at 30 Hz for `seconds`. Returns its JSON report.
pub fn run_relay_load(egoexo: &Path, streams: usize, seconds: u32) -> Result<serde_json::Value> {
    let rooms = 10.min(streams.max(1));
    let out = cmd::output_checked(
        Command::new(egoexo)
            .args(["live", "load", "--rooms", &rooms.to_string(), "--devices-per-room"])
            .arg((streams / rooms).max(1).to_string())
            .args(["--duration-s", &seconds.to_string()]),
    )?;
    let line = out.lines().last().context("egoexo live load printed nothing")?;
    serde_json::from_str(line).with_context(|| format!("egoexo live load printed `{line}`"))
}

/// The bench's native reference: the same sample, models and jobs timed natively (release
/// build of `crates/egoexo-web-worker/examples/bench_native.rs`).
pub fn run_native_reference(root: &Path, models: &Path, runs: u32) -> Result<BenchResult> {
    let samples: serde_json::Value = serde_json::from_slice(&std::fs::read(root.join("public/samples/samples.json"))?)?;
    let file = samples["samples"][0]["file"].as_str().context("public/samples/samples.json lists no sample")?;
    let sample = root.join("public").join("samples").join(file);
    let out = cmd::output_checked(
        Command::new("cargo")
            .args(["run", "--quiet", "--release", "-p", "egoexo-web-worker", "--example", "bench_native", "--"])
            .arg(models)
            .arg(&sample)
            .arg(runs.to_string()),
    )?;
    parse_bench_line(&out, "BENCH_NATIVE")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_measuring_and_real_time_files_run_alone_and_the_rest_in_lanes() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("tests").join("e2e");
        let (alone, shared) = test_files(&dir).unwrap();
        let names = |files: &[PathBuf]| -> Vec<String> {
            files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect()
        };
        assert_eq!(names(&alone), RUN_ALONE);
        let shared = names(&shared);
        assert!(shared.contains(&"app.test.mjs".to_string()), "{shared:?}");
        assert!(shared.iter().all(|n| n.ends_with(".test.mjs") && !RUN_ALONE.contains(&n.as_str())), "{shared:?}");
        // A name that is not there is refused, not skipped.
        let empty = std::env::temp_dir().join(format!("egoexo-e2e-empty-{}", std::process::id()));
        std::fs::create_dir_all(&empty).unwrap();
        let error = test_files(&empty).unwrap_err().to_string();
        std::fs::remove_dir_all(&empty).unwrap();
        assert!(error.contains("hour.test.mjs"), "{error}");
    }

    #[test]
    fn a_failing_file_is_summed_up_by_its_failing_tests_or_its_last_lines() {
        let spec =
            "▶ live\n  ✔ one (1ms)\n  ✖ two (2ms)\n✖ failing tests:\n\ntest at x.mjs:3:1\n✖ two (2ms)\n  Error: é\n";
        assert_eq!(failures_of(spec), "failing tests:\n\ntest at x.mjs:3:1\n✖ two (2ms)\n  Error: é\n");
        // A file that did not finish: its last lines, cut on a character boundary.
        let long = format!("{}é tail", "ø".repeat(7000));
        let shown = failures_of(&long);
        assert!(shown.ends_with("é tail") && shown.chars().count() == 6000, "{}", shown.chars().count());
        let sectioned = format!("failing tests:\n{}", "x".repeat(7000));
        assert!(failures_of(&sectioned).ends_with("x …"));
    }

    #[test]
    fn bench_lines_parse_by_their_own_prefix() {
        let out = "warm-up\nBENCH_NATIVE {\"frames\": 10, \"runs\": 3, \"median_fps\": 5.5, \"median_app_fps\": 2}\n\
                   BENCH {\"frames\": 1161, \"runs\": 3, \"median_fps\": 4013.0, \"median_app_fps\": 2095.0}\n";
        let web = parse_bench_line(out, "BENCH").unwrap();
        assert_eq!((web.frames, web.runs, web.median_fps, web.median_app_fps), (1161, 3, 4013.0, 2095.0));
        let native = parse_bench_line(out, "BENCH_NATIVE").unwrap();
        assert_eq!((native.frames, native.median_fps), (10, 5.5));
        assert!(parse_bench_line("BENCH {\"frames\": 1}", "BENCH").is_err());
        assert!(parse_bench_line("nothing", "BENCH").is_err());
    }

    #[test]
    fn counts_from_the_tap_summary() {
        let tap = "TAP version 13\n# Subtest: a\nok 1 - a\n1..7\n# tests 7\n# suites 0\n# pass 6\n# fail 1\n\
                   # cancelled 0\n# skipped 0\n# todo 0\n# duration_ms 1234.5\n";
        let c = tap_counts(tap);
        assert_eq!((c.passed, c.failed, c.ignored), (6, 1, 0));
    }
}
