//! `egoexo walk`: one simulated session of any length without a motion library — the wearer
//! walks in a circle (`egoexo_synth::procedural::walking_circle`) watched by observers — for
//! long-session tests and benchmarks (the browser's hour-long test reconstructs one).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_session::format::save_egoexo_with;
use egoexo_session::model::VideoRef;
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::video::{Appearance, CameraRays, render_frame};
use egoexo_synth::{SimulatedSession, SynthConfig, simulate};

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
    /// Give the observers RGB video instead of keypoints: the wearer's body rendered through
    /// each observer's camera (`egoexo_synth::video`), H.264 in MP4 at 30 fps, for the detector
    /// step. The value is the cameras' image size, pixels (square; ≤ 1408).
    #[arg(long, value_name = "PX")]
    pub video: Option<u32>,
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
    let mut config = config;
    if let Some(px) = args.video {
        if !(64..=1408).contains(&px) || px % 2 == 1 {
            bail!("--video {px}: expected an even image size of 64..=1408 px");
        }
        config.camera.image_sizes = vec![px];
    }
    let name = format!("walk-{}s", args.seconds);
    let motion = walking_circle(args.seconds);
    let mut sim = simulate(&motion, &name, &config, args.seed)?;
    let videos = if args.video.is_some() { observer_videos(&mut sim, &motion)? } else { Default::default() };
    save_egoexo_with(&sim.session, videos, &args.out, args.folder)
        .with_context(|| format!("writing {}", args.out.display()))?;
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

/// Renders every observer's video of `sim` (the wearer's `motion` seen from the observer's
/// true head poses), replaces the observer's simulated keypoints by it, and returns the MP4
/// files by their session paths.
pub fn observer_videos(
    sim: &mut SimulatedSession,
    motion: &egoexo_core::SmplMotion,
) -> Result<std::collections::BTreeMap<String, Vec<u8>>> {
    let scale = motion.skeleton.head_height() / egoexo_core::SmplSkeleton::mean_shape().head_height();
    let floor_y = sim.session.floor.as_ref().map_or(0.0, |f| f.height_m);
    let look = Appearance::default();
    let mut files = std::collections::BTreeMap::new();
    for (o, observer) in sim.session.observers.iter_mut().enumerate() {
        let rays = CameraRays::new(&observer.camera);
        let heads = &sim.true_observer_heads[o];
        let frames = motion.poses.iter().zip(heads).map(|(pose, head)| {
            render_frame(&motion.skeleton.forward_kinematics(pose), scale, &rays, head, floor_y, &look)
        });
        let (w, h) = (observer.camera.width, observer.camera.height);
        let mp4 = egoexo_detect::native::encode_mp4(frames, w, h, f64::from(motion.fps), 6_000_000)?;
        let path = format!("observers/{}/rgb.mp4", observer.id);
        observer.keypoints = None;
        observer.video = Some(VideoRef { path: path.clone(), start_ns: motion.start_ns, frame_times_ns: Vec::new() });
        files.insert(path, mp4);
    }
    Ok(files)
}
