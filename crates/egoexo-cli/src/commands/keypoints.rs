//! `egoexo keypoints <session> -o <out.egoexo>`: the detector step alone — the observers'
//! videos → the wearer's keypoints inside EgoNet's regions, written into a copy of the session.

use std::path::PathBuf;

use anyhow::{Result, bail};
use egoexo_session::format::save_egoexo_with;

use super::detection::{detect_missing_keypoints, print_reports};
use super::models::models_dir;
use super::session_input::{SessionInput, video_files};
use super::tracking::TrackingArg;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub input: SessionInput,
    /// Where to write the session with the detected keypoints (`.egoexo`: a zip; a path
    /// without that extension: a folder).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Only this observer (repeatable) [default: every observer with video and no keypoints].
    /// A named observer's keypoints are detected again even if it has some.
    #[arg(long = "observer", value_name = "ID")]
    pub observers: Vec<String>,
    /// Models folder [default: ./models, else the repository's models/].
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// Wearer tracking for EgoNet's regions [default: what the devices allow].
    #[arg(long, value_enum)]
    pub tracking: Option<TrackingArg>,
    /// Also print the per-observer figures as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
}

pub fn run(args: Args) -> Result<()> {
    if args.output.exists() && !args.force {
        bail!("{} exists; pass --force to replace it", args.output.display());
    }
    let mut imported = args.input.import()?;
    for warning in &imported.warnings {
        eprintln!("warning: {warning}");
    }
    if !args.observers.is_empty() {
        for o in &mut imported.session.observers {
            if args.observers.contains(&o.id) && o.video.is_some() {
                o.keypoints = None;
            }
        }
    }
    let reports = detect_missing_keypoints(
        &args.input.session,
        &mut imported,
        &models_dir(args.models.as_deref()),
        args.tracking.map(Into::into),
        &args.observers,
    )?;
    if reports.is_empty() {
        bail!("no observer of this session has video without keypoints: nothing to detect");
    }
    print_reports(&reports);
    // The videos go along: the written session still names them.
    let videos = video_files(&args.input.session, &imported.session)?;
    let as_folder = !args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("egoexo"));
    save_egoexo_with(&imported.session, videos, &args.output, as_folder)?;
    println!("wrote {}", args.output.display());
    if args.json {
        println!("{}", serde_json::to_string(&reports)?);
    }
    Ok(())
}
