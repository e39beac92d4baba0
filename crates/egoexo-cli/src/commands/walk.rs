//! `egoexo walk`: one simulated session of any length without a motion library — the wearer
//! walks in a circle (`egoexo_synth::procedural::walking_circle`) watched by observers — for
//! long-session tests and benchmarks (the browser's hour-long test reconstructs one).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_session::format::save_egoexo;
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::{SynthConfig, simulate};

use super::tracking::TrackingArg;

/// The longest walk written: four hours (a session of 432,000 frames at 30 fps).
const MAX_SECONDS: f32 = 4.0 * 3600.0;

#[derive(clap::Args)]
pub struct Args {
    /// Length of the session, seconds (at most four hours).
    #[arg(long)]
    pub seconds: f32,
    /// Observers watching the wearer.
    #[arg(long, default_value_t = 2)]
    pub observers: usize,
    /// Wearer tracking: 1 (glasses), 3 (glasses + wrist devices), 3-hand-tracking.
    #[arg(long, value_enum, default_value = "3")]
    pub tracking: TrackingArg,
    /// Seed of the simulation.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// The `.egoexo` file to write (a folder with `--folder`).
    #[arg(short = 'o', long)]
    pub out: PathBuf,
    /// Write a folder instead of a zip file.
    #[arg(long)]
    pub folder: bool,
}

pub fn run(args: Args) -> Result<()> {
    if !(args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= MAX_SECONDS) {
        bail!("--seconds {}: expected a length above 0 and at most {MAX_SECONDS} s", args.seconds);
    }
    let config = SynthConfig {
        tracking: TrackingMode::from(args.tracking),
        wrists: args.tracking.wrists().for_simulation(0),
        observers: args.observers,
        ..SynthConfig::default()
    };
    let name = format!("walk-{}s", args.seconds);
    let sim = simulate(&walking_circle(args.seconds), &name, &config, args.seed)?;
    save_egoexo(&sim.session, &args.out, args.folder).with_context(|| format!("writing {}", args.out.display()))?;
    let bytes = std::fs::metadata(&args.out).map(|m| m.len()).unwrap_or(0);
    println!(
        "wrote {} ({:.0} s of walking, {} observers{})",
        args.out.display(),
        args.seconds,
        args.observers,
        if args.folder { String::new() } else { format!(", {:.1} MB", bytes as f64 / 1e6) }
    );
    Ok(())
}
