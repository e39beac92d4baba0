//! The arguments `synth` and `eval` share: which motion to simulate, how many observers watch
//! it, how the wearer is tracked, and the seed.

use std::path::PathBuf;

use anyhow::{Context, Result};
use egoexo_core::TrackingMode;
use egoexo_mocap::MotionLibrary;

use super::tracking::TrackingArg;

/// Simulated sessions of chosen subjects of the motion library.
#[derive(Clone, Debug, clap::Args)]
pub struct SimulationArgs {
    /// The motion library (`egoexo mocap import`).
    #[arg(long)]
    pub lib: PathBuf,
    /// CMU subject numbers, comma-separated (e.g. `5,16`).
    #[arg(long, value_delimiter = ',', required = true)]
    pub subjects: Vec<u32>,
    /// Observers per simulated session (for shards: the most per session, and the networks'
    /// slots).
    #[arg(long, default_value_t = 1)]
    pub observers: usize,
    /// Wearer tracking: 1 (glasses), 3 (glasses + wrist devices), 3-hand-tracking (the
    /// glasses' own hand tracking: wrists only while in view; alias 3-intermittent) or
    /// 3-mixed (simulations alternate between the two kinds of wrists; for training shards).
    #[arg(long, value_enum, default_value = "3")]
    pub tracking: TrackingArg,
    /// Seed of the simulations (and of everything else random in the command).
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
}

impl SimulationArgs {
    /// Opens `--lib`.
    pub fn open_library(&self) -> Result<MotionLibrary> {
        egoexo_mocap::fs::open_library(&self.lib).with_context(|| format!("opening {}", self.lib.display()))
    }

    /// How `--tracking` simulates the wrists.
    pub fn wrists(&self) -> egoexo_dataset::shards::WristKind {
        self.tracking.wrists()
    }

    /// `--tracking` as the core's mode.
    pub fn tracking_mode(&self) -> TrackingMode {
        TrackingMode::from(self.tracking)
    }
}
