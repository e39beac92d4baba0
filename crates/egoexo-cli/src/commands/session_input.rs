//! Arguments shared by the commands that read a session (`inspect`, `convert`).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_session::aria::trajectory::Clock;
use std::sync::{Arc, Mutex};

use egoexo_session::format::{CAPTURE_FORMAT_VERSION, manifest_version};
use egoexo_session::import::{
    ImportOptions, ImportProgress, Imported, ImportedCapture, KeypointFile, SourceKind, detect_source,
    has_people_files, import_capture, import_path,
};
use egoexo_session::keypoints::CocoTiming;
use egoexo_session::vfs::{FileTree, Limits};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Which MPS timestamp column puts the devices on one clock.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ClockArg {
    /// `tracking_timestamp_us`: each device's own clock (mapped by time_sync.csv files if present).
    Device,
    /// `utc_timestamp_ns`: wall-clock time.
    Utc,
}

#[derive(Clone, Debug, clap::Args)]
pub struct SessionInput {
    /// A `.egoexo` (zip or folder), an Aria MPS folder (one device, or the multi-device layout
    /// wearer/ + observers/<id>/), a Nymeria sequence folder, or a zip of any of them.
    pub session: PathBuf,
    #[command(flatten)]
    pub options: ImportArgs,
}

/// How a session is read: keypoint files to attach, the clock, COCO timing.
#[derive(Clone, Debug, clap::Args)]
pub struct ImportArgs {
    /// Attach a keypoint file to an observer: `<observer-id>=<file>` (JSON lines, or COCO
    /// JSON). Repeatable; replaces keypoints the session already has.
    #[arg(long = "keypoints", value_name = "ID=FILE")]
    pub keypoints: Vec<String>,
    /// Which MPS timestamps to use.
    #[arg(long, value_enum, default_value_t = ClockArg::Device)]
    pub clock: ClockArg,
    /// Frame rate of the image sequences COCO keypoint files number.
    #[arg(long, default_value_t = 30.0, value_name = "FPS")]
    pub coco_fps: f64,
    /// Session-clock time (ns) of COCO frame 0 [default: the observer trajectory's first timestamp].
    #[arg(long, value_name = "NS", allow_negative_numbers = true)]
    pub coco_start_ns: Option<i64>,
}

impl SessionInput {
    /// Imports the session with the chosen options.
    pub fn import(&self) -> Result<Imported> {
        self.options.import(&self.session)
    }

    /// The input as a capture of several participants, when it is one (a `.egoexo` of
    /// version 3 with more than one participant to reconstruct or people without identity, or
    /// a multi-device recording with people files); `None` for everything that is one session.
    pub fn import_several(&self) -> Result<Option<ImportedCapture>> {
        let tree = FileTree::open(&self.session, Limits::default())?;
        let (source, root) = detect_source(&tree)?;
        let several = match source {
            SourceKind::Egoexo => manifest_version(&root)? >= u64::from(CAPTURE_FORMAT_VERSION),
            _ => has_people_files(&root, source),
        };
        if !several {
            return Ok(None);
        }
        let imported = import_capture(&tree, &self.options.import_options()?)?;
        Ok((!imported.capture.is_one_session()).then_some(imported))
    }
}

impl ImportArgs {
    /// Imports the session at `path` with these options.
    pub fn import(&self, path: &std::path::Path) -> Result<Imported> {
        Ok(import_path(path, &self.import_options()?)?)
    }

    /// The importer's options these arguments ask for (keypoint files read).
    pub fn import_options(&self) -> Result<ImportOptions> {
        let mut keypoint_files = Vec::new();
        for spec in &self.keypoints {
            let Some((id, path)) = spec.split_once('=') else {
                bail!("--keypoints {spec:?}: expected <observer-id>=<file>");
            };
            let bytes = std::fs::read(path).with_context(|| format!("cannot read keypoint file {path}"))?;
            keypoint_files.push(KeypointFile { observer_id: id.to_owned(), name: path.to_owned(), bytes });
        }
        let options = ImportOptions {
            clock: match self.clock {
                ClockArg::Device => Clock::Device,
                ClockArg::Utc => Clock::Utc,
            },
            coco: CocoTiming { fps: self.coco_fps, start_ns: self.coco_start_ns },
            keypoint_files,
            progress: Some(progress_bar()),
        };
        Ok(options)
    }
}

/// Files at least this big get a progress bar while they are read.
const PROGRESS_MIN_BYTES: u64 = 16 << 20;

/// A progress bar on stderr for the big files of an import (an hour of 1 kHz trajectory is
/// ~0.8 GB); hidden when stderr is not a terminal.
fn progress_bar() -> ImportProgress {
    let bar = ProgressBar::hidden();
    let current = Mutex::new(String::new());
    ImportProgress(Arc::new(move |file: &str, done: u64, total: u64| {
        let Ok(mut current) = current.lock() else { return };
        if *current != file {
            *current = file.to_owned();
            bar.finish_and_clear();
            if total >= PROGRESS_MIN_BYTES {
                bar.set_draw_target(ProgressDrawTarget::stderr());
                bar.set_style(
                    ProgressStyle::with_template(
                        "{msg} {wide_bar} {bytes}/{total_bytes} ({binary_bytes_per_sec}, {eta})",
                    )
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                bar.set_message(format!("reading {file}"));
                bar.reset();
                bar.set_length(total);
            } else {
                bar.set_draw_target(ProgressDrawTarget::hidden());
            }
        }
        bar.set_position(done);
        if total > 0 && done >= total {
            bar.finish_and_clear();
        }
    }))
}

/// The observers' video files of `session`, read from the session at `path` by the paths the
/// session names them (what a rewritten session must carry along).
pub fn video_files(
    path: &std::path::Path,
    session: &egoexo_session::Session,
) -> Result<std::collections::BTreeMap<String, Vec<u8>>> {
    let mut videos = std::collections::BTreeMap::new();
    if session.observers.iter().all(|o| o.video.is_none()) {
        return Ok(videos);
    }
    let tree = egoexo_session::vfs::FileTree::open(path, egoexo_session::vfs::Limits::default())?;
    let (_, root) = egoexo_session::import::detect_source(&tree)?;
    for video in session.observers.iter().filter_map(|o| o.video.as_ref()) {
        videos.insert(video.path.clone(), root.read(&video.path)?.into_owned());
    }
    Ok(videos)
}
