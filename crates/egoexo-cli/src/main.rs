//! `egoexo`: the native command-line tool. Each subcommand lives in `commands/<name>.rs`
//! with its own clap `Args` and a `run` function; errors are reported with `anyhow` here.

mod commands;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "egoexo",
    version,
    about = "Full-body motion capture from head-mounted devices worn by two or more people"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print a session's devices, time ranges, rates, observers, keypoint coverage and problems.
    Inspect(commands::inspect::Args),
    /// Convert an Aria MPS folder, a Nymeria sequence or a `.egoexo` (plus keypoint files) to `.egoexo`.
    Convert(commands::convert::Args),
    /// The CMU motion library: `mocap import` retargets ASF/AMC to SMPL, `mocap info` summarises it.
    Mocap(commands::mocap::Args),
    /// Simulate ego-exo sessions (or training shards) from motion-library subjects.
    Synth(commands::synth::Args),
    /// Simulate one session of any length without a motion library: the wearer walks in a circle.
    Walk(commands::walk::Args),
    /// Score reconstruction methods on simulated sessions of `--subjects` with the paper's metrics
    /// (the nearest-neighbour baseline looks up poses among the library's other subjects).
    Eval(commands::eval::Args),
    /// Score captures of several participants on simulated group scenes: association of the
    /// cameras' people (bystanders among them) and each participant's MPJPE.
    EvalGroup(commands::eval_group::Args),
    /// Detect the wearer's 2D keypoints in the observers' videos (inside EgoNet's regions) and
    /// write the session with them.
    Keypoints(commands::keypoints::Args),
    /// Score the shipped detector on photographs with COCO keypoint labels: PCK and OKS on the
    /// whole frame vs on the region a proposal gives it.
    DetectorEval(commands::detector_eval::Args),
    /// Reconstruct the wearer's motion and write it as AMASS npz, BVH, glb, CSV or JSON
    /// (observers with video and no keypoints get the detector step first).
    Reconstruct(commands::reconstruct::Args),
    /// Check or register every observer's world against the wearer's (a capture's participants
    /// into one world) from what their cameras see; `--json` prints the transforms.
    Register(commands::register::Args),
    /// Serve the page and the share API (share links), storing shares on disk or in S3.
    Serve(commands::serve::Args),
    /// Share a session's reconstruction by link (end-to-end encrypted), or `share get` one.
    Share(commands::share::Args),
    /// Live capture: create a room, replay a session as live devices, record a take, load-test the relay.
    Live(commands::live::Args),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result: Result<()> = match cli.command {
        Command::Inspect(args) => commands::inspect::run(args),
        Command::Convert(args) => commands::convert::run(args),
        Command::Mocap(args) => commands::mocap::run(args),
        Command::Synth(args) => commands::synth::run(args),
        Command::Walk(args) => commands::walk::run(args),
        Command::Eval(args) => commands::eval::run(args),
        Command::EvalGroup(args) => commands::eval_group::run(args),
        Command::Keypoints(args) => commands::keypoints::run(args),
        Command::DetectorEval(args) => commands::detector_eval::run(args),
        Command::Reconstruct(args) => commands::reconstruct::run(args),
        Command::Register(args) => commands::register::run(args),
        Command::Serve(args) => commands::serve::run(args),
        Command::Share(args) => commands::share::run(args),
        Command::Live(args) => commands::live::run(args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
