//! `egoexo reconstruct <session> -o out.{npz,bvh,glb,csv,json}`: the wearer's motion through
//! the same engine the app runs.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_infer::plan::resolve_tracking;
use egoexo_infer::{Engine, Method, ReconstructOptions, Stage};
use egoexo_motion_io::{Format, write};
use egoexo_session::align::{AlignOptions, align};
use indicatif::{ProgressBar, ProgressStyle};

use super::models::{load_model_set, models_dir, read_manifest};
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
    /// Wearer tracking [default: 3 when both wrists are tracked on at least 98% of the head's
    /// frames, else 1 — wrists from hand tracking come and go].
    #[arg(long, value_enum)]
    pub tracking: Option<TrackingArg>,
    /// Output frame rate.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
}

pub fn run(args: Args) -> Result<()> {
    if args.output.exists() && !args.force {
        bail!("{} exists; pass --force to replace it", args.output.display());
    }
    let json = args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let format = if json { None } else { Some(Format::from_path(&args.output.to_string_lossy())?) };

    let imported = args.input.import()?;
    for warning in &imported.warnings {
        eprintln!("warning: {warning}");
    }
    let aligned = align(&imported.session, &AlignOptions { fps: args.fps, ..AlignOptions::default() })?;
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
    let method = if args.ego_only || aligned.observers.is_empty() { Method::EgoOnly } else { Method::EgoExo };

    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{msg:>8} {bar:40} {pos}/{len} windows [{elapsed_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let options = ReconstructOptions { method, tracking: Some(tracking), ..ReconstructOptions::default() };
    let recon = engine.reconstruct(&aligned, &options, &mut |p| {
        bar.set_message(match p.stage {
            Stage::Ego => "ego",
            Stage::Fusion(_) => "fusion",
        });
        bar.set_length(p.total as u64);
        bar.set_position(p.done as u64);
        true
    })?;
    bar.finish_and_clear();

    let bytes = match format {
        Some(format) => write(format, &recon.motion)?,
        None => serde_json::to_vec(&recon)?,
    };
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
    Ok(())
}
