//! `egoexo eval`: the paper's metric table on simulated sessions of chosen subjects.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_dataset::eval::{EvalOptions, evaluate, format_table, nearest_neighbour_index};
use egoexo_infer::{Engine, Method};
use indicatif::{ProgressBar, ProgressStyle};

use super::models::{load_model_set, read_manifest};
use super::tracking::TrackingArg;

#[derive(clap::Args)]
pub struct Args {
    /// The motion library (`egoexo mocap import`).
    #[arg(long)]
    pub lib: PathBuf,
    /// CMU subjects to evaluate on, comma-separated. The nearest-neighbour baseline looks up
    /// poses among all other subjects of the library.
    #[arg(long, value_delimiter = ',', required = true)]
    pub subjects: Vec<u32>,
    /// Observers per simulated session.
    #[arg(long, default_value_t = 1)]
    pub observers: usize,
    /// Wearer tracking: 1 or 3.
    #[arg(long, value_enum, default_value = "3")]
    pub tracking: TrackingArg,
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Models folder: adds the `ego-only`, `ego-exo` and `ego-exo-ungated` rows.
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> Result<()> {
    let library =
        egoexo_mocap::fs::open_library(&args.lib).with_context(|| format!("opening {}", args.lib.display()))?;
    let tracking = TrackingMode::from(args.tracking);
    let training: Vec<u32> = library.subjects().into_iter().filter(|s| !args.subjects.contains(s)).collect();
    if training.is_empty() {
        bail!("every subject of the library is being evaluated; the nearest-neighbour baseline needs other subjects");
    }
    let mut engine = Engine::new()
        .with_nearest_neighbour(tracking, nearest_neighbour_index(&library, &training, tracking, args.seed, 2)?);
    let mut methods = vec![Method::RestPose, Method::NearestNeighbour];
    if let Some(dir) = &args.models {
        let manifest = read_manifest(dir)?;
        let set = load_model_set(dir, &manifest, tracking)?
            .with_context(|| format!("{} has no {}-point models", dir.display(), tracking.points()))?;
        engine = engine.with_models(set);
        methods.extend([Method::EgoOnly, Method::EgoExo, Method::EgoExoUngated]);
    }
    let options =
        EvalOptions { subjects: args.subjects.clone(), observers: args.observers, tracking, seed: args.seed, methods };
    let bar = if args.json { ProgressBar::hidden() } else { ProgressBar::new(0) };
    bar.set_style(
        ProgressStyle::with_template("eval {bar:40} {pos}/{len} clips [{elapsed_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let report = evaluate(&library, &engine, &options, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", format_table(&report));
        if args.models.is_none() {
            println!("\n(baselines only: pass --models DIR for the networks' rows)");
        }
    }
    Ok(())
}
