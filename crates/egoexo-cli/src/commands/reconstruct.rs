//! `egoexo reconstruct <session> -o out.{npz,bvh,glb,csv,json}`: the wearer's motion through
//! the same engine the app runs.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_infer::job::WINDOW_CHUNK;
use egoexo_infer::plan::resolve_tracking;
use egoexo_infer::{Engine, Method, Progress, ReconstructOptions, Stage, StageTimer, StageTimings, TimedStage};
use egoexo_motion_io::{Format, write};
use egoexo_register::{Outcome, RegisterSettings, register_session};
use egoexo_session::align::{AlignOptions, align};
use egoexo_session::import::ImportedCapture;
use indicatif::{ProgressBar, ProgressStyle};

use super::capture::{mpjpe_cm, participant_output, print_association, reconstruct_capture};
use super::detection::{detect_missing_keypoints, print_reports};
use super::models::{load_model_set, models_dir, read_manifest};
use super::register::{RegisterArg, print_session};
use super::session_input::SessionInput;
use super::tracking::TrackingArg;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub input: SessionInput,
    /// Output file; the extension picks the format: `.npz` (AMASS), `.bvh`, `.glb`, `.csv`
    /// (joint positions) or `.json` (the full reconstruction: SMPL parameters, joints, gate
    /// values, exo evidence).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Ignore the observers (the networks' ego-only mode).
    #[arg(long)]
    pub ego_only: bool,
    /// Models folder [default: ./models, else the repository's models/].
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// Wearer tracking [default: 3 whenever the session has a wrist — the network reads, frame
    /// by frame, which wrists are tracked, so hand-tracking wrists that come and go are used
    /// where they exist — else 1].
    #[arg(long, value_enum)]
    pub tracking: Option<TrackingArg>,
    /// Output frame rate.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
    /// Observers' worlds: `auto` keeps worlds given as shared whose views agree and registers
    /// the others (docs/registration.md), `off` keeps every world as given (observers in a
    /// world of their own are left out), `force` registers every observer.
    #[arg(long, value_enum, default_value_t = RegisterArg::Auto)]
    pub register: RegisterArg,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Threads the session's windows are spread over [default: every core]; 1 runs them one
    /// after another.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Print the median milliseconds per stage (import, align, ego features, EgoNet, exo
    /// features, gate, fusion, decode, export) over this many runs of the whole job.
    #[arg(long, value_name = "RUNS", num_args = 0..=1, default_missing_value = "5")]
    pub timings: Option<u32>,
}

pub fn run(args: Args) -> Result<()> {
    if args.output.exists() && !args.force {
        bail!("{} exists; pass --force to replace it", args.output.display());
    }
    let json = args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let format = if json { None } else { Some(Format::from_path(&args.output.to_string_lossy())?) };
    if let Some(imported) = args.input.import_several()? {
        return run_capture(&args, imported, format);
    }

    let started = Instant::now();
    let mut clock = move || started.elapsed().as_secs_f64() * 1e3;
    let (mut imported, mut aligned, mut setup) = import_and_align(&args, &mut clock)?;
    for warning in &imported.warnings {
        eprintln!("warning: {warning}");
    }
    let tracking = resolve_tracking(&aligned, args.tracking.map(TrackingMode::from))?;
    if args.tracking.is_none()
        && let Some(reason) = aligned.tracking_choice().reason
    {
        eprintln!("note: 3-point with wrists that come and go: {reason}");
    }
    let dir = models_dir(args.models.as_deref());
    let manifest = read_manifest(&dir)?;
    let set = load_model_set(&dir, &manifest, tracking)?
        .with_context(|| format!("{} has no {}-point models", dir.display(), tracking.points()))?;
    let engine = Engine::new().with_models(set);
    setup.merge(&register_observers(&args, &engine, tracking, &mut imported, &mut aligned, &mut clock, true)?);
    let method = if args.ego_only || aligned.observers.is_empty() { Method::EgoOnly } else { Method::EgoExo };

    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{msg:>8} {bar:40} {pos}/{len} windows [{elapsed_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let options = ReconstructOptions { method, tracking: Some(tracking), ..ReconstructOptions::default() };
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())).max(1);
    let mut show = |p: Progress| {
        bar.set_message(match p.stage {
            Stage::Ego => "ego",
            Stage::Fusion(_) => "fusion",
        });
        bar.set_length(p.total as u64);
        bar.set_position(p.done as u64);
        true
    };
    let mut job = engine.start(&aligned, &options, &[method])?;
    // Stage timings are per stage of one thread: `--timings` runs the windows in order.
    let (recons, mut timings) = if threads > 1 && args.timings.is_none() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
        pool.install(|| job.run_in_parallel(&engine, &aligned, WINDOW_CHUNK, &mut show))?;
        (job.finish(&aligned)?, StageTimings::default())
    } else {
        while let Some(p) = job.step_timed(&engine, &aligned, &mut clock)? {
            show(p);
        }
        job.finish_timed(&aligned, &mut clock)?
    };
    let recon = recons.into_iter().next().context("the engine returned no reconstruction")?;
    bar.finish_and_clear();

    let mut timer = StageTimer::new(&mut clock);
    let bytes = timer.time(TimedStage::Export, || encode(format, &recon))?;
    timings.merge(&setup);
    timings.merge(&timer.timings);
    std::fs::write(&args.output, bytes).with_context(|| format!("cannot write {}", args.output.display()))?;
    let untracked = recon.valid.iter().filter(|v| !**v).count();
    let evidence = recon.exo_evidence.iter().filter(|v| **v).count();
    println!(
        "wrote {} ({}, {}-point): {} frames at {} fps, {} with exo evidence{}",
        args.output.display(),
        method,
        tracking.points(),
        recon.motion.len(),
        recon.motion.fps,
        evidence,
        if untracked > 0 { format!(", {untracked} untracked frames hold the nearest pose") } else { String::new() }
    );
    if let Some(runs) = args.timings {
        print_timings(&args, &engine, &options, method, format, (timings, recon.motion.len()), runs.max(1))?;
        print_scaling(&engine, &aligned, &options, method, threads, runs.max(1))?;
    }
    Ok(())
}

/// A capture of several participants: every participant's motion, each in its own file
/// ([`participant_output`]).
fn run_capture(args: &Args, imported: ImportedCapture, format: Option<Format>) -> Result<()> {
    if args.timings.is_some() {
        bail!("--timings measures one session; this is a capture of several participants");
    }
    for warning in &imported.warnings {
        eprintln!("warning: {warning}");
    }
    let outputs: Vec<PathBuf> = imported
        .capture
        .reconstructed()
        .map(|p| participant_output(&args.output, &imported.capture.participants[p].id))
        .collect();
    if let Some(existing) = outputs.iter().find(|o| o.exists())
        && !args.force
    {
        bail!("{} exists; pass --force to replace it", existing.display());
    }
    let done = reconstruct_capture(
        &args.input.session,
        imported.capture,
        &models_dir(args.models.as_deref()),
        args.tracking.map(TrackingMode::from),
        args.ego_only,
        args.fps,
        args.register.into(),
    )?;
    print_association(&done.association);
    for (p, output) in done.participants.iter().zip(&outputs) {
        let recon = &p.reconstruction;
        std::fs::write(output, encode(format, recon)?).with_context(|| format!("cannot write {}", output.display()))?;
        let evidence = recon.exo_evidence.iter().filter(|v| **v).count();
        let mpjpe = match mpjpe_cm(p) {
            Some(cm) => format!("; MPJPE {cm:.2} cm against the capture's ground truth"),
            None => String::new(),
        };
        println!(
            "wrote {} (participant {}, {}, {}-point): {} frames at {} fps, {} with exo evidence from {} observers{mpjpe}",
            output.display(),
            p.id,
            p.method,
            p.tracking.points(),
            recon.motion.len(),
            recon.motion.fps,
            evidence,
            p.session.observers.iter().filter(|o| o.keypoints.is_some()).count()
        );
    }
    Ok(())
}

/// Imports and aligns the session, timing both with `clock`.
fn import_and_align(
    args: &Args,
    clock: &mut dyn egoexo_infer::Clock,
) -> Result<(egoexo_session::import::Imported, egoexo_core::aligned::AlignedSession, StageTimings)> {
    let mut timer = StageTimer::new(clock);
    let mut imported = timer.time(TimedStage::Import, || args.input.import())?;
    if !args.ego_only {
        let models = models_dir(args.models.as_deref());
        let tracking = args.tracking.map(TrackingMode::from);
        let reports = detect_missing_keypoints(&args.input.session, &mut imported, &models, tracking, &[])?;
        print_reports(&reports);
    }
    let options = AlignOptions { fps: args.fps, ..AlignOptions::default() };
    let aligned = timer.time(TimedStage::Align, || align(&imported.session, &options))?;
    Ok((imported, aligned, timer.timings))
}

/// The registration step (`--register`) on the imported session, realigned when an observer
/// moved; its timings. `report`: print what it did.
fn register_observers(
    args: &Args,
    engine: &Engine,
    tracking: TrackingMode,
    imported: &mut egoexo_session::import::Imported,
    aligned: &mut egoexo_core::aligned::AlignedSession,
    clock: &mut dyn egoexo_infer::Clock,
    report: bool,
) -> Result<StageTimings> {
    let mut timer = StageTimer::new(clock);
    if args.ego_only || imported.session.observers.is_empty() {
        return Ok(timer.timings);
    }
    let settings = RegisterSettings { mode: args.register.into(), ..RegisterSettings::default() };
    let registration = timer
        .time(TimedStage::Register, || register_session(Some(engine), tracking, &mut imported.session, &settings))?;
    if report {
        print_session(&registration);
    }
    if registration.observers.iter().any(|o| o.outcome == Outcome::Registered) {
        let options = AlignOptions { fps: args.fps, ..AlignOptions::default() };
        *aligned = timer.time(TimedStage::Align, || align(&imported.session, &options))?;
    }
    Ok(timer.timings)
}

/// The output file's bytes: the motion in `format`, or the whole reconstruction as JSON.
fn encode(format: Option<Format>, recon: &egoexo_infer::Reconstruction) -> Result<Vec<u8>> {
    Ok(match format {
        Some(format) => write(format, &recon.motion)?,
        None => serde_json::to_vec(recon)?,
    })
}

/// `--timings`: the engine's wall time with the windows on 1, 2, 4, … `threads` threads
/// (median of `runs` each) against the sequential job, as frames per second and speed-up.
fn print_scaling(
    engine: &Engine,
    aligned: &egoexo_core::aligned::AlignedSession,
    options: &ReconstructOptions,
    method: Method,
    threads: usize,
    runs: u32,
) -> Result<()> {
    let frames = aligned.timeline.frames as f64;
    let median_s = |f: &mut dyn FnMut() -> Result<()>| -> Result<f64> {
        let mut times = Vec::new();
        for _ in 0..runs {
            let started = Instant::now();
            f()?;
            times.push(started.elapsed().as_secs_f64());
        }
        Ok(egoexo_infer::timing::median(&times))
    };
    let sequential = median_s(&mut || {
        engine.reconstruct(aligned, &ReconstructOptions { method, ..*options }, &mut |_| true)?;
        Ok(())
    })?;
    println!("threads (engine only, median of {runs}): sequential {:.0} frames/s", frames / sequential);
    let mut counts: Vec<usize> = (0..).map(|i| 1 << i).take_while(|&n| n < threads).collect();
    counts.push(threads);
    for n in counts {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build()?;
        let s = median_s(&mut || {
            pool.install(|| engine.reconstruct_each_in_parallel(aligned, options, &[method], &mut |_| true))?;
            Ok(())
        })?;
        println!(
            "  {n:>2} thread{}: {:>8.0} frames/s, {:.2}x sequential",
            if n == 1 { " " } else { "s" },
            frames / s,
            sequential / s
        );
    }
    Ok(())
}

/// `--timings`: the whole job `runs` times (the first run is the one that wrote the output),
/// median milliseconds per stage and frames per second.
fn print_timings(
    args: &Args,
    engine: &Engine,
    options: &ReconstructOptions,
    method: Method,
    format: Option<Format>,
    (first, mut frames): (StageTimings, usize),
    runs: u32,
) -> Result<()> {
    let started = Instant::now();
    let mut clock = move || started.elapsed().as_secs_f64() * 1e3;
    let mut all = vec![first];
    for _ in 1..runs {
        let (mut imported, mut aligned, mut setup) = import_and_align(args, &mut clock)?;
        let tracking = options.tracking.unwrap_or_else(|| aligned.tracking_mode());
        setup.merge(&register_observers(args, engine, tracking, &mut imported, &mut aligned, &mut clock, false)?);
        let mut job = engine.start(&aligned, options, &[method])?;
        while job.step_timed(engine, &aligned, &mut clock)?.is_some() {}
        let (recons, mut timings) = job.finish_timed(&aligned, &mut clock)?;
        let recon = recons.into_iter().next().context("the engine returned no reconstruction")?;
        frames = recon.motion.len();
        let mut timer = StageTimer::new(&mut clock);
        timer.time(TimedStage::Export, || encode(format, &recon))?;
        timings.merge(&setup);
        timings.merge(&timer.timings);
        all.push(timings);
    }
    let median = StageTimings::median(&all);
    println!("timings: median of {runs} runs, {method}, {frames} frames, one thread");
    print!("{}", median.table());
    let total = median.total_ms();
    let networks: f64 = median.stages.iter().filter(|s| s.stage.is_network()).map(|s| s.ms).sum();
    if frames > 0 && total > 0.0 {
        println!(
            "{:.0} frames/s for the whole job; networks {:.0}% of it",
            frames as f64 / (total / 1e3),
            100.0 * networks / total
        );
    }
    Ok(())
}
