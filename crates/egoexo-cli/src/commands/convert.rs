//! `egoexo convert <input> -o <out.egoexo>`: any importer's input (Aria MPS, Nymeria,
//! `.egoexo`), plus keypoint files, written as a `.egoexo` zip (or folder).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_session::format::save_egoexo_with;

use super::session_input::SessionInput;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub input: SessionInput,
    /// The `.egoexo` file to write.
    #[arg(short, long, value_name = "OUT.egoexo")]
    pub output: PathBuf,
    /// Write the `.egoexo` layout as a folder instead of a zip.
    #[arg(long)]
    pub folder: bool,
    /// Replace the output if it exists.
    #[arg(long)]
    pub force: bool,
}

pub fn run(args: Args) -> Result<()> {
    if args.output.exists() && !args.force {
        bail!("{} exists; pass --force to replace it", args.output.display());
    }
    let imported = args.input.import()?;
    for warning in &imported.warnings {
        eprintln!("warning: {warning}");
    }
    if args.output.is_dir() && args.force {
        std::fs::remove_dir_all(&args.output).with_context(|| format!("cannot replace {}", args.output.display()))?;
    }
    let videos = super::session_input::video_files(&args.input.session, &imported.session)?;
    save_egoexo_with(&imported.session, videos, &args.output, args.folder)?;
    let s = &imported.session;
    let keypoint_frames: usize = s.observers.iter().filter_map(|o| o.keypoints.as_ref()).map(|k| k.frames.len()).sum();
    println!(
        "wrote {} from a {}: wearer head{}, {} observer(s), {keypoint_frames} keypoint frames, {}",
        args.output.display(),
        imported.source.describe(),
        if s.wearer.tracking_mode() == TrackingMode::ThreePoint { " + wrists" } else { "" },
        s.observers.len(),
        match &s.ground_truth {
            Some(gt) => format!("ground truth of {} frames", gt.motion.len()),
            None => "no ground truth".into(),
        }
    );
    Ok(())
}
