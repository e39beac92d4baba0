//! `egoexo mocap import|info`: the motion library built from CMU motion capture.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use egoexo_core::skeleton::JOINT_NAMES;
use egoexo_mocap::fs::{import_tree, open_library, read_catalog, save_library, scan_cmu_trees};
use egoexo_mocap::{ImportOptions, MotionLibrary};
use indicatif::{ProgressBar, ProgressStyle};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: MocapCommand,
}

#[derive(clap::Subcommand)]
enum MocapCommand {
    /// Retarget CMU ASF/AMC motion capture to SMPL and write a motion library (.safetensors).
    ///
    /// Each DIR is searched for subject folders holding NN.asf and NN_TT.amc: the project's
    /// shared/data/cmu, or CMU's own allasfamc.zip unpacked (all_asfamc/subjects/NN/...).
    /// Trials in BVH form (NN_TT.bvh) are imported too — cgspeed's MotionBuilder, 3dsMax and
    /// DAZ releases, recognised by their joint names — unless the same trial is there as AMC.
    /// Capture rates and descriptions come from CMU_data.csv (found in a DIR, or --catalog).
    /// The retarget error is printed per data source.
    Import(ImportArgs),
    /// Print a library's clips, subjects, hours and retarget error.
    Info(InfoArgs),
}

#[derive(clap::Args)]
struct ImportArgs {
    /// Folders with the CMU subject folders (e.g. shared/data/cmu shared/data/cmu-extra).
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// The library file to write.
    #[arg(short, long)]
    output: PathBuf,
    /// CMU_data.csv, when it is not inside DIR.
    #[arg(long)]
    catalog: Option<PathBuf>,
    /// Only these subjects (comma-separated CMU subject numbers, e.g. 2,5,105).
    #[arg(long, value_delimiter = ',')]
    subjects: Option<Vec<u32>>,
    /// Metres per length unit of BVH trials (default: inferred from the skeleton's height;
    /// CMU conversions use 0.056444, i.e. 1/0.45 inch).
    #[arg(long)]
    bvh_unit: Option<f64>,
}

#[derive(clap::Args)]
struct InfoArgs {
    /// A library written by `egoexo mocap import`.
    library: PathBuf,
    /// Also list every clip.
    #[arg(long)]
    clips: bool,
    /// Print one JSON object instead of tables.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> Result<()> {
    match args.command {
        MocapCommand::Import(args) => import(args),
        MocapCommand::Info(args) => info(args),
    }
}

fn import(args: ImportArgs) -> Result<()> {
    let started = Instant::now();
    let tree = scan_cmu_trees(&args.dirs)?;
    let catalog_path = args
        .catalog
        .clone()
        .or_else(|| tree.catalog.clone())
        .with_context(|| format!("no CMU_data.csv in {}; pass it with --catalog", tree.display_roots()))?;
    let catalog = read_catalog(&catalog_path)?;
    if let Some(wanted) = &args.subjects {
        let present = tree.subject_numbers();
        let missing: Vec<u32> = wanted.iter().copied().filter(|s| !present.contains(s)).collect();
        if !missing.is_empty() {
            bail!("subjects {missing:?} are not in {}", tree.display_roots());
        }
    }
    for (path, why) in &tree.ignored {
        eprintln!("note: ignoring {}: {why}", path.display());
    }
    let trials = tree.trial_count_of(args.subjects.as_deref());
    let bar = ProgressBar::new(trials as u64);
    bar.set_style(
        ProgressStyle::with_template("{spinner} importing {bar:40} {pos}/{len} trials {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let options = ImportOptions { bvh_metres_per_unit: args.bvh_unit, ..ImportOptions::default() };
    let result = import_tree(&tree, &catalog, &options, args.subjects.as_deref(), &|outcome| {
        bar.inc(1);
        if let Some(name) = outcome.path.file_name() {
            bar.set_message(name.to_string_lossy().into_owned());
        }
    });
    bar.finish_and_clear();
    let result = result?;
    save_library(&result.library, &args.output)?;
    let elapsed = started.elapsed().as_secs_f64();

    let library = &result.library;
    let all: Vec<usize> = (0..library.clips().len()).collect();
    let error = library.retarget_summary(&all);
    println!(
        "wrote {}: {} clips from {} trials of {} subjects, {:.3} h at {} fps, in {elapsed:.1} s",
        args.output.display(),
        library.clips().len(),
        result.trials,
        library.subjects().len(),
        library.hours(),
        library.fps(),
    );
    println!("retarget error: mean {:.2} cm, p95 {:.2} cm, max {:.2} cm", error.mean_cm, error.p95_cm, error.max_cm);
    print_sources(library);
    if !result.reference_rows_skipped.is_empty() {
        println!(
            "left out the prepended reference pose rows (T-pose) of {} BVH trial(s)",
            result.reference_rows_skipped.len()
        );
    }
    if !result.restored_thorax.is_empty() {
        let lengths: Vec<f32> = result.restored_thorax.iter().map(|(_, l)| l * 100.0).collect();
        println!(
            "restored the collapsed thorax (neck and collars starting at the spine's top joint) of {} BVH trial(s): {:.1}–{:.1} cm",
            lengths.len(),
            lengths.iter().copied().fold(f32::INFINITY, f32::min),
            lengths.iter().copied().fold(0.0, f32::max),
        );
    }
    for (path, frames, dropped) in &result.trimmed {
        println!(
            "trimmed {}: {dropped} of {frames} frames were corrupt (joint jumps) or in too-short pieces",
            path.display()
        );
    }
    if !result.failures.is_empty() {
        for failure in &result.failures {
            eprintln!("error: {failure}");
        }
        bail!(
            "{} trial(s) or subject(s) could not be imported (listed above); {} holds the rest",
            result.failures.len(),
            args.output.display()
        );
    }
    Ok(())
}

fn info(args: InfoArgs) -> Result<()> {
    let library = open_library(&args.library)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&info_json(&library, &args.library))?);
        return Ok(());
    }
    let all: Vec<usize> = (0..library.clips().len()).collect();
    let error = library.retarget_summary(&all);
    let fps = library.fps();
    let trials = {
        let mut t: Vec<(u32, u32)> = library.clips().iter().map(|c| (c.subject, c.trial)).collect();
        t.dedup();
        t.len()
    };
    println!("{} ({} bytes)", args.library.display(), library.as_bytes().len());
    println!(
        "clips {} (from {trials} trials), subjects {}, frames {} at {fps} fps, hours {:.3}",
        library.clips().len(),
        library.subjects().len(),
        library.total_frames(),
        library.hours()
    );
    println!(
        "retarget error (mapped CMU joints vs SMPL forward kinematics, 24 joints): mean {:.2} cm, p95 {:.2} cm, max {:.2} cm",
        error.mean_cm, error.p95_cm, error.max_cm
    );
    print_sources(&library);
    println!();
    println!("{:>7} {:>6} {:>8} {:>12} {:>8} {:>7}", "subject", "clips", "minutes", "head height", "mean cm", "p95 cm");
    for (subject, clips) in library.clips_by_subject() {
        let s = library.retarget_summary(&clips);
        let frames: u64 = clips.iter().map(|&c| u64::from(library.clips()[c].frames)).sum();
        let head = library.clips()[clips[0]].head_height_m;
        println!(
            "{subject:>7} {:>6} {:>8.2} {:>10.3} m {:>8.2} {:>7.2}",
            clips.len(),
            frames as f64 / f64::from(fps) / 60.0,
            head,
            s.mean_cm,
            s.p95_cm
        );
    }
    println!();
    let joint_means = per_joint_means(&library);
    let worst: Vec<String> = {
        let mut order: Vec<usize> = (0..joint_means.len()).collect();
        order.sort_by(|&a, &b| joint_means[b].total_cmp(&joint_means[a]));
        order.iter().take(5).map(|&j| format!("{} {:.1}", JOINT_NAMES[j], joint_means[j])).collect()
    };
    println!("largest mean errors by joint (cm): {}", worst.join(", "));
    let trimmed: Vec<String> = library
        .clips()
        .iter()
        .filter(|c| c.segment > 0 || c.source_range != [0, c.source_frames])
        .map(|c| format!("{} [{}..{} of {}]", c.label(), c.source_range[0], c.source_range[1], c.source_frames))
        .collect();
    if !trimmed.is_empty() {
        println!("clips trimmed of corrupt frames: {}", trimmed.join(", "));
    }
    if args.clips {
        println!();
        println!(
            "{:<10} {:>6} {:>7} {:>8} {:>8} {:>7}  description",
            "clip", "src Hz", "frames", "seconds", "mean cm", "p95 cm"
        );
        for c in library.clips() {
            println!(
                "{:<10} {:>6} {:>7} {:>8.2} {:>8.2} {:>7.2}  {}",
                c.label(),
                c.source_fps,
                c.frames,
                c.duration_s(fps),
                c.retarget.mean_cm,
                c.retarget.p95_cm,
                c.description
            );
        }
    }
    Ok(())
}

/// One data source's share of a library and its retarget error.
struct SourceRow {
    source: String,
    subjects: Vec<u32>,
    clips: usize,
    frames: u64,
    error: egoexo_mocap::RetargetSummary,
}

/// The library's clips grouped by data source (ASF/AMC, each BVH conversion).
fn source_rows(library: &MotionLibrary) -> Vec<SourceRow> {
    library
        .clips_by_source_format()
        .into_iter()
        .map(|(source, clips)| {
            let mut subjects: Vec<u32> = clips.iter().map(|&c| library.clips()[c].subject).collect();
            subjects.sort_unstable();
            subjects.dedup();
            SourceRow {
                source,
                subjects,
                clips: clips.len(),
                frames: clips.iter().map(|&c| u64::from(library.clips()[c].frames)).sum(),
                error: library.retarget_summary(&clips),
            }
        })
        .collect()
}

/// The retarget error per data source.
fn print_sources(library: &MotionLibrary) {
    println!();
    println!(
        "{:<36} {:>8} {:>6} {:>8} {:>8} {:>7} {:>7}",
        "source", "subjects", "clips", "minutes", "mean cm", "p95 cm", "max cm"
    );
    for row in source_rows(library) {
        println!(
            "{:<36} {:>8} {:>6} {:>8.2} {:>8.2} {:>7.2} {:>7.2}",
            row.source,
            row.subjects.len(),
            row.clips,
            row.frames as f64 / f64::from(library.fps()) / 60.0,
            row.error.mean_cm,
            row.error.p95_cm,
            row.error.max_cm
        );
    }
}

/// Frame-weighted mean error per joint over the library, cm.
fn per_joint_means(library: &MotionLibrary) -> Vec<f64> {
    let mut sums = vec![0.0f64; JOINT_NAMES.len()];
    let mut frames = 0.0f64;
    for c in library.clips() {
        for (s, v) in sums.iter_mut().zip(&c.retarget.per_joint_mean_cm) {
            *s += f64::from(*v) * f64::from(c.frames);
        }
        frames += f64::from(c.frames);
    }
    sums.iter().map(|s| if frames > 0.0 { s / frames } else { 0.0 }).collect()
}

fn info_json(library: &MotionLibrary, path: &Path) -> serde_json::Value {
    let all: Vec<usize> = (0..library.clips().len()).collect();
    let error = library.retarget_summary(&all);
    let subjects: Vec<serde_json::Value> = library
        .clips_by_subject()
        .into_iter()
        .map(|(subject, clips)| {
            let s = library.retarget_summary(&clips);
            let frames: u64 = clips.iter().map(|&c| u64::from(library.clips()[c].frames)).sum();
            serde_json::json!({
                "subject": subject,
                "clips": clips.len(),
                "frames": frames,
                "head_height_m": library.clips()[clips[0]].head_height_m,
                "retarget_mean_cm": s.mean_cm,
                "retarget_p95_cm": s.p95_cm,
            })
        })
        .collect();
    let sources: Vec<serde_json::Value> = source_rows(library)
        .into_iter()
        .map(|row| {
            serde_json::json!({
                "source": row.source,
                "subjects": row.subjects,
                "clips": row.clips,
                "frames": row.frames,
                "retarget_mean_cm": row.error.mean_cm,
                "retarget_p95_cm": row.error.p95_cm,
                "retarget_max_cm": row.error.max_cm,
            })
        })
        .collect();
    serde_json::json!({
        "library": path.display().to_string(),
        "fps": library.fps(),
        "clips": library.clips().len(),
        "subjects": library.subjects(),
        "frames": library.total_frames(),
        "hours": library.hours(),
        "retarget_mean_cm": error.mean_cm,
        "retarget_p95_cm": error.p95_cm,
        "retarget_max_cm": error.max_cm,
        "per_joint_mean_cm": per_joint_means(library),
        "per_subject": subjects,
        "per_source": sources,
        "clip_list": library.clips(),
    })
}
