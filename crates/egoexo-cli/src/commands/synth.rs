//! `egoexo synth`: simulated sessions (`.egoexo`) or training shards from the motion library.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_core::ego_features::EGO_FEATURE_DIM;
use egoexo_dataset::shards::{EgoNetForShards, ShardOptions, ShardStage, write_shards};
use egoexo_infer::manifest::sha256_hex;
use egoexo_infer::models::OnnxModel;
use egoexo_infer::windows::WINDOW;
use egoexo_session::format::save_egoexo;
use egoexo_synth::{SynthConfig, simulate};
use indicatif::{ProgressBar, ProgressStyle};

use super::simulation::SimulationArgs;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StageArg {
    /// EgoNet inputs and targets.
    Ego,
    /// Everything the gate and fusion networks read (needs a trained EgoNet: --models).
    Fusion,
}

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub simulation: SimulationArgs,
    /// Output folder.
    #[arg(short = 'o', long)]
    pub out: PathBuf,
    /// Write training shards of this stage instead of sessions.
    #[arg(long, value_enum)]
    pub shards: Option<StageArg>,
    /// The trained EgoNet (`egonet.onnx`) that makes the fusion shards' coarse poses.
    #[arg(long)]
    pub egonet: Option<PathBuf>,
    /// Shards: simulations of every clip.
    #[arg(long, default_value_t = 3)]
    pub simulations: usize,
    /// Shards: frames between training windows.
    #[arg(long, default_value_t = 24)]
    pub stride: usize,
    /// Shards: do not add left↔right mirrored copies of the motions.
    #[arg(long)]
    pub no_mirror: bool,
    /// Sessions: write folders instead of zip files.
    #[arg(long)]
    pub folders: bool,
    /// Keep only the clips of fold K of N (`K/N`, K from 0): clip `c` of the library is in
    /// fold `c mod N`, so a fold keeps whole clips and their mirrored copies together. For
    /// cross-fitted stage-2 shards (training/README.md).
    #[arg(long, value_parser = parse_fold, conflicts_with = "exclude_fold")]
    pub fold: Option<Fold>,
    /// Drop the clips of fold K of N (`K/N`): the training set of fold K's EgoNet.
    #[arg(long, value_parser = parse_fold)]
    pub exclude_fold: Option<Fold>,
}

/// Fold `index` of `count` of the library's clips (clip `c` is in fold `c mod count`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fold {
    pub index: usize,
    pub count: usize,
}

impl Fold {
    fn contains(self, clip: usize) -> bool {
        clip % self.count == self.index
    }
}

fn parse_fold(text: &str) -> Result<Fold, String> {
    let (k, n) = text.split_once('/').ok_or_else(|| format!("expected K/N (e.g. 0/3), got {text:?}"))?;
    let index: usize = k.trim().parse().map_err(|_| format!("fold index {k:?} is not a number"))?;
    let count: usize = n.trim().parse().map_err(|_| format!("fold count {n:?} is not a number"))?;
    if count < 2 || index >= count {
        return Err(format!("expected K/N with N >= 2 and 0 <= K < N, got {text:?}"));
    }
    Ok(Fold { index, count })
}

pub fn run(args: Args) -> Result<()> {
    let sim = &args.simulation;
    let library = sim.open_library()?;
    let mut clips = library.clips_of_subjects(&sim.subjects);
    if clips.is_empty() {
        bail!("{} has no clips of subjects {:?} (it has {:?})", sim.lib.display(), sim.subjects, library.subjects());
    }
    if let Some(fold) = args.fold {
        clips.retain(|&c| fold.contains(c));
    }
    if let Some(fold) = args.exclude_fold {
        clips.retain(|&c| !fold.contains(c));
    }
    if clips.is_empty() {
        bail!("no clips of subjects {:?} are left after the fold selection", sim.subjects);
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let tracking = sim.tracking_mode();
    let bar = ProgressBar::new(clips.len() as u64).with_style(
        ProgressStyle::with_template("{msg} {bar:40} {pos}/{len} clips [{elapsed_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );

    if let Some(stage) = args.shards {
        let stage = match stage {
            StageArg::Ego => ShardStage::Ego,
            StageArg::Fusion => ShardStage::Fusion,
        };
        let egonet = match stage {
            ShardStage::Ego => None,
            ShardStage::Fusion => {
                let path =
                    args.egonet.as_ref().context("--shards fusion needs --egonet FILE (a trained egonet.onnx)")?;
                let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
                let model = OnnxModel::load(&path.display().to_string(), &bytes, &[vec![1, WINDOW, EGO_FEATURE_DIM]])?;
                Some((model, sha256_hex(&bytes)))
            }
        };
        let options = ShardOptions {
            tracking,
            wrists: sim.wrists(),
            max_observers: sim.observers.max(1),
            observers: (0, sim.observers.max(1)),
            simulations_per_clip: args.simulations.max(1),
            stride: args.stride.max(1),
            seed: sim.seed,
            mirror: !args.no_mirror,
            ..ShardOptions::default()
        };
        bar.set_message("shards");
        let out = args.out.clone();
        let index = write_shards(
            &library,
            &clips,
            stage,
            &options,
            egonet.as_ref().map(|(model, sha256)| EgoNetForShards { model, sha256 }),
            &mut |name, bytes| {
                std::fs::write(out.join(name), bytes)
                    .map_err(|e| egoexo_dataset::DatasetError::Write(format!("{name}: {e}")))
            },
            &mut |done, _| bar.set_position(done as u64),
        )?;
        bar.finish();
        println!(
            "wrote {} windows in {} shards ({} simulated frames, subjects {:?}) to {}",
            index.windows,
            index.shards.len(),
            index.frames_simulated,
            index.subjects,
            args.out.display()
        );
        return Ok(());
    }

    bar.set_message("sessions");
    for (i, &clip) in clips.iter().enumerate() {
        let config = SynthConfig {
            tracking,
            wrists: sim.wrists().for_simulation(i as u64),
            observers: sim.observers,
            ..SynthConfig::default()
        };
        let info = &library.clips()[clip];
        let motion = library.motion(clip)?;
        let name = info.label().replace('/', "-");
        let sim = simulate(&motion, &name, &config, egoexo_dataset::shards::mix(sim.seed, clip as u64, 0x5E55))?;
        let path = args.out.join(if args.folders { name.clone() } else { format!("{name}.egoexo") });
        save_egoexo(&sim.session, &path, args.folders).with_context(|| format!("writing {}", path.display()))?;
        bar.set_position(i as u64 + 1);
    }
    bar.finish();
    println!("wrote {} sessions to {}", clips.len(), args.out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folds_parse_and_partition_the_clips() {
        let folds: Vec<Fold> = (0..3).map(|k| parse_fold(&format!("{k}/3")).unwrap()).collect();
        for clip in 0..30 {
            assert_eq!(folds.iter().filter(|f| f.contains(clip)).count(), 1, "clip {clip} is in exactly one fold");
        }
        assert!(parse_fold("3/3").is_err());
        assert!(parse_fold("0/1").is_err());
        assert!(parse_fold("a/3").unwrap_err().contains("\"a\""));
        assert!(parse_fold("2").unwrap_err().contains("K/N"));
    }
}
