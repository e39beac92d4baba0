//! `egoexo walk`: one simulated session of any length without a motion library — the wearer
//! walks in a circle (`egoexo_synth::procedural::walking_circle`) watched by observers — for
//! long-session tests and benchmarks (the browser's hour-long test reconstructs one).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_session::format::{save_capture, save_egoexo_with};
use egoexo_synth::group::{GroupConfig, group_walk, simulate_group};
use egoexo_synth::procedural::{walking_circle, wandering};
use egoexo_synth::video::{Appearance, render_observer_videos};
use egoexo_synth::worlds::{WorldPerturbation, WorldTruth, perturb_capture_worlds, perturb_observer_worlds};
use egoexo_synth::{SynthConfig, simulate};
use egoexo_video::y4m::Y4mWriter;

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
    /// Participants wearing glasses (2 or 3: a capture of several people who walk together
    /// and look at each other, `egoexo_synth::group`, written as format version 3 with every
    /// camera's people unidentified; `--observers` and `--video` do not apply).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=3))]
    pub participants: u8,
    /// People without glasses crossing a capture of several participants.
    #[arg(long, default_value_t = 2)]
    pub bystanders: usize,
    /// A capture of several participants with the simulator's own identities: every camera's
    /// keypoints assigned to the participant they are of (bystanders left out) instead of
    /// people without identity — what a live room streams (`egoexo live replay`).
    #[arg(long)]
    pub identities: bool,
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
    /// With `--video`: also write each observer's video as `<DIR>/<id>.y4m` (uncompressed YUV
    /// 4:2:0, what Chromium's fake camera plays: `--use-file-for-fake-video-capture`) and its
    /// camera as `<DIR>/<id>.camera.json` (`width`, `height`, `horizontal_fov_deg`); the
    /// cameras are then pinholes, as a browser's camera is.
    #[arg(long, value_name = "DIR", requires = "video")]
    pub y4m: Option<PathBuf>,
    /// Observers are tripods: static cameras aimed at the middle of the wearer's path, their
    /// one pose given in the session's world (`egoexo_synth::config::ObserverBehaviour`).
    #[arg(long)]
    pub static_cameras: bool,
    /// Move every observer (every participant but the first) into a world of its own — any
    /// yaw, up to 10 m away, ±0.3 m of floor (`egoexo_synth::worlds`) — as two Aria glasses
    /// processed by MPS one by one would be; the truth goes to `<out>.worlds.json`.
    #[arg(long)]
    pub perturb_worlds: bool,
    /// With `--perturb-worlds`: put each on a clock of its own too, up to this many seconds
    /// off (at most 2).
    #[arg(long, value_name = "S", requires = "perturb_worlds")]
    pub perturb_clocks: Option<f32>,
    /// Wander a Lissajous figure instead of the circle: speed and curvature keep changing, so
    /// a clock offset cannot pass for a turn of the world (`--perturb-clocks` needs it).
    #[arg(long)]
    pub wander: bool,
}

/// The perturbation `--perturb-worlds` / `--perturb-clocks` ask for.
fn perturbation(args: &Args) -> Result<Option<WorldPerturbation>> {
    if !args.perturb_worlds {
        return Ok(None);
    }
    let clock = args.perturb_clocks.unwrap_or(0.0);
    if !(0.0..=2.0).contains(&clock) {
        bail!("--perturb-clocks {clock}: expected 0 to 2 s");
    }
    Ok(Some(WorldPerturbation { max_clock_offset_s: clock, ..WorldPerturbation::default() }))
}

/// Writes the moved worlds' truth beside the output: `<out>.worlds.json`, one entry per
/// observer: `{"id", "yaw_deg", "translation_m", "clock_offset_s"}` (`p_session = R_y(yaw) ·
/// p_observer + translation`, `t_session = t_observer + clock_offset_s`).
fn write_truth(out: &std::path::Path, truth: &[WorldTruth]) -> Result<PathBuf> {
    let entries: Vec<serde_json::Value> = truth
        .iter()
        .map(|t| {
            serde_json::json!({
                "id": t.id,
                "yaw_deg": t.yaw_deg(),
                "translation_m": t.t_session_world.translation.to_array(),
                "clock_offset_s": t.clock_offset_s,
            })
        })
        .collect();
    let mut name = out.as_os_str().to_owned();
    name.push(".worlds.json");
    let path = PathBuf::from(name);
    std::fs::write(&path, serde_json::to_vec_pretty(&serde_json::json!({"observers": entries}))?)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

pub fn run(args: Args) -> Result<()> {
    if !(args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= MAX_SECONDS) {
        bail!("--seconds {}: expected a length above 0 and at most {MAX_SECONDS} s", args.seconds);
    }
    if args.participants > 1 {
        return write_group(&args);
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
    if args.y4m.is_some() {
        config.camera.fisheye_probability = 0.0;
    }
    config.observer.static_camera = args.static_cameras;
    let name = format!("walk-{}s", args.seconds);
    let motion = if args.wander { wandering(args.seconds) } else { walking_circle(args.seconds) };
    let mut sim = simulate(&motion, &name, &config, args.seed)?;
    let mut raw_videos = Vec::new();
    let videos = if args.video.is_some() {
        render_observer_videos(&mut sim, &motion, &Appearance::default(), |frames, w, h, fps| -> Result<Vec<u8>> {
            let mut y4m = args.y4m.as_ref().map(|_| Y4mWriter::new(w, h, fps.round() as u32)).transpose()?;
            let mut failed = None;
            let frames = frames.inspect(|rgb| {
                if let Some(Err(e)) = y4m.as_mut().map(|y| y.push_rgb(rgb)) {
                    failed.get_or_insert(e);
                }
            });
            let mp4 = egoexo_detect::native::encode_mp4(frames, w, h, fps, 6_000_000)?;
            if let Some(e) = failed {
                return Err(e.into());
            }
            raw_videos.extend(y4m.map(Y4mWriter::finish).transpose()?);
            Ok(mp4)
        })?
    } else {
        Default::default()
    };
    if let Some(dir) = &args.y4m {
        write_y4m(dir, &sim, raw_videos)?;
    }
    let perturbation = perturbation(&args)?;
    let truth = perturbation.map(|p| perturb_observer_worlds(&mut sim.session, &p, args.seed));
    save_egoexo_with(&sim.session, videos, &args.out, args.folder)
        .with_context(|| format!("writing {}", args.out.display()))?;
    report_written(
        &args,
        truth.as_deref(),
        "observers",
        format!("{:.0} s of walking, {} observers", args.seconds, args.observers),
    )
}

/// Writes each observer's raw video and camera for a browser's fake camera (`--y4m`): its
/// size, field of view, true pose at the first frame (`t_world_camera`: the camera frame, +Z
/// forward and +Y down, in the session's world — what registering a browser camera, whose
/// device frame is its camera frame, should find) and mean distance to the wearer's head.
fn write_y4m(dir: &std::path::Path, sim: &egoexo_synth::SimulatedSession, videos: Vec<Vec<u8>>) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for ((observer, bytes), heads) in sim.session.observers.iter().zip(videos).zip(&sim.true_observer_heads) {
        let camera = &observer.camera;
        let egoexo_core::camera::Projection::Pinhole(pinhole) = camera.projection else {
            bail!("observer `{}`: a fake browser camera needs a pinhole camera", observer.id);
        };
        let fov = 2.0 * (0.5 * f64::from(camera.width) / f64::from(pinhole.fx)).atan().to_degrees();
        let video = dir.join(format!("{}.y4m", observer.id));
        std::fs::write(&video, bytes).with_context(|| format!("writing {}", video.display()))?;
        let pose = camera.t_world_camera(heads.first().context("an observer without poses")?);
        let wearer = &sim.session.wearer.head.poses;
        let distance =
            wearer.iter().map(|p| p.translation.distance(pose.translation)).sum::<f32>() / wearer.len().max(1) as f32;
        let json = serde_json::json!({
            "width": camera.width,
            "height": camera.height,
            "horizontal_fov_deg": fov,
            "t_world_camera": {"rotation": pose.rotation.to_array(), "translation": pose.translation.to_array()},
            "mean_distance_to_wearer_m": distance,
        });
        let path = dir.join(format!("{}.camera.json", observer.id));
        std::fs::write(&path, serde_json::to_vec_pretty(&json)?)
            .with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {} ({:.0}° horizontal field of view)", video.display(), fov);
    }
    Ok(())
}

/// Says what was written (`what`, and its size for a file) and, for worlds moved apart
/// (`truth`, of `moved`), where the truth went.
fn report_written(args: &Args, truth: Option<&[WorldTruth]>, moved: &str, what: String) -> Result<()> {
    if let Some(truth) = truth {
        println!(
            "moved {} {moved} into worlds of their own; the truth is in {}",
            truth.len(),
            write_truth(&args.out, truth)?.display()
        );
    }
    let bytes = std::fs::metadata(&args.out).map(|m| m.len()).unwrap_or(0);
    let size = if args.folder { String::new() } else { format!(", {:.1} MB", bytes as f64 / 1e6) };
    println!("wrote {} ({what}{size})", args.out.display());
    Ok(())
}

/// `--participants 2|3`: a group walk with bystanders, as a capture.
fn write_group(args: &Args) -> Result<()> {
    if args.video.is_some() {
        bail!("--video films one wearer for their observers; a capture of several participants has keypoints");
    }
    if !matches!(args.tracking.wrists(), egoexo_dataset::shards::WristKind::Devices) {
        bail!("--tracking: a group capture simulates wrist devices or none; use 1 or 3");
    }
    if args.bystanders > 20 {
        bail!("--bystanders {}: at most 20", args.bystanders);
    }
    let config = GroupConfig {
        tracking: TrackingMode::from(args.tracking),
        bystanders: args.bystanders,
        ..GroupConfig::default()
    };
    let name = format!("group-{}x{}s", args.participants, args.seconds);
    let sim = simulate_group(&group_walk(usize::from(args.participants), args.seconds), &name, &config, args.seed)?;
    let mut capture = if args.identities { sim.with_true_identities() } else { sim.capture };
    let truth = perturbation(args)?.map(|p| perturb_capture_worlds(&mut capture, &p, args.seed));
    save_capture(&capture, Default::default(), &args.out, args.folder)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let what = format!(
        "{:.0} s, {} participants walking together, {} bystanders",
        args.seconds, args.participants, args.bystanders
    );
    report_written(args, truth.as_deref(), "participants", what)
}
