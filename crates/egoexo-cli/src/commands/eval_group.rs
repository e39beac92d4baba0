//! `egoexo eval-group`: captures of several participants on simulated group scenes — how well
//! the cameras' people are associated with the participants (bystanders among them), and each
//! participant's MPJPE ego-only, with the associated keypoints and with the true identities
//! (`egoexo_dataset::group`).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_core::association::AssociationOptions;
use egoexo_dataset::group::{default_scenes, evaluate_group, format_group_table};
use egoexo_infer::Engine;
use indicatif::{ProgressBar, ProgressStyle};

use super::models::{load_model_set, models_dir, read_manifest};
use super::tracking::TrackingArg;

#[derive(clap::Args)]
pub struct Args {
    /// Scenes (seeds) of each size: 2 and 3 participants.
    #[arg(long, default_value_t = 3)]
    pub scenes: usize,
    /// Length of each scene, seconds.
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f32,
    /// People without glasses crossing each scene.
    #[arg(long, default_value_t = 3)]
    pub bystanders: usize,
    /// Participants' devices: 1 (glasses) or 3 (glasses + wrist devices).
    #[arg(long, value_enum, default_value = "3")]
    pub tracking: TrackingArg,
    /// Association: the largest cost (mean keypoint distance over the projected body's box
    /// diagonal) at which a detection is a participant.
    #[arg(long, default_value_t = AssociationOptions::default().max_cost)]
    pub max_cost: f32,
    /// Models folder [default: ./models, else the repository's models/].
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> Result<()> {
    if args.scenes == 0 || args.scenes > 50 {
        bail!("--scenes {}: expected 1 to 50", args.scenes);
    }
    if !(args.seconds >= 4.0 && args.seconds <= 600.0) {
        bail!("--seconds {}: expected 4 to 600", args.seconds);
    }
    if !(args.max_cost > 0.0 && args.max_cost.is_finite()) {
        bail!("--max-cost {}: expected a positive number", args.max_cost);
    }
    if !matches!(args.tracking.wrists(), egoexo_dataset::shards::WristKind::Devices) {
        bail!("--tracking: group scenes simulate wrist devices or none; use 1 or 3");
    }
    let tracking = TrackingMode::from(args.tracking);
    let dir = models_dir(args.models.as_deref());
    let set = load_model_set(&dir, &read_manifest(&dir)?, tracking)?
        .with_context(|| format!("{} has no {}-point models", dir.display(), tracking.points()))?;
    let engine = Engine::new().with_models(set);
    let scenes = default_scenes(args.scenes, args.seconds, args.bystanders, tracking);
    let bar = if args.json { ProgressBar::hidden() } else { ProgressBar::new(scenes.len() as u64) };
    bar.set_style(
        ProgressStyle::with_template("eval-group {bar:40} {pos}/{len} scenes [{elapsed_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let options = AssociationOptions { max_cost: args.max_cost, ..AssociationOptions::default() };
    let report = evaluate_group(&engine, &scenes, &options, &mut |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{} scenes of {} s, {} bystanders, {}-point, association max cost {}",
            scenes.len(),
            args.seconds,
            args.bystanders,
            tracking.points(),
            args.max_cost
        );
        print!("{}", format_group_table(&report));
    }
    Ok(())
}
