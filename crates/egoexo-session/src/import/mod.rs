//! Session import: recognises what a folder or archive holds and runs the matching importer.
//!
//! | input | recognised by | importer |
//! |---|---|---|
//! | `.egoexo` (zip or folder) | `session.json` | [`crate::format`] |
//! | Nymeria sequence | `recording_head/` | [`nymeria`] |
//! | multi-device Aria MPS folder | `wearer/` | [`aria_mps`] |
//! | one Aria MPS device folder | `closed_loop_trajectory.csv` (at the root, in `slam/` or `mps/slam/`) | [`aria_mps`] |
//!
//! When nothing is recognised at the root and every file lies in one top-level folder (a
//! zipped folder), that folder is tried. After import, extra keypoint files
//! ([`ImportOptions::keypoint_files`]) are attached and the session is validated
//! ([`crate::validate`]).

pub mod aria_mps;
mod folder_files;
pub mod nymeria;

use crate::aria::trajectory::Clock;
use egoexo_core::camera::CameraCalibration;
use egoexo_core::glam::Vec2;

use crate::capture::{Capture, View, ViewPeople};
use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::format::CAPTURE_FORMAT_VERSION;
use crate::keypoints::{CocoTiming, read_keypoints};
use crate::model::Session;
use crate::vfs::FileTree;

/// A keypoint file given alongside the session (e.g. `egoexo convert --keypoints id=file`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KeypointFile {
    /// The observer it belongs to.
    pub observer_id: String,
    /// Its name (for messages and format detection: `.jsonl` = JSON lines).
    pub name: String,
    pub bytes: Vec<u8>,
}

/// Called while big files are read (a 1 kHz trajectory of an hour is 3.6 M rows): the file
/// (as named in messages), what was read so far and the total, in bytes — or in rows with a
/// total of 0 where the size is unknown (compressed files).
#[derive(Clone)]
pub struct ImportProgress(pub std::sync::Arc<ProgressFn>);

/// `(file, done, total)`: see [`ImportProgress`].
pub type ProgressFn = dyn Fn(&str, u64, u64) + Send + Sync;

impl std::fmt::Debug for ImportProgress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ImportProgress(..)")
    }
}

impl PartialEq for ImportProgress {
    fn eq(&self, other: &Self) -> bool {
        std::sync::Arc::ptr_eq(&self.0, &other.0)
    }
}

impl ImportProgress {
    /// Reports `done` of `total` for `file`.
    pub fn report(&self, file: &str, done: u64, total: u64) {
        (self.0)(file, done, total);
    }
}

/// Import choices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImportOptions {
    /// Which MPS timestamp column to use (device clock by default).
    pub clock: Clock,
    /// How COCO keypoint frames get timestamps.
    pub coco: CocoTiming,
    /// Keypoint files to attach to observers (replacing any the session has).
    pub keypoint_files: Vec<KeypointFile>,
    /// Progress of big files, if anyone is watching.
    pub progress: Option<ImportProgress>,
}

impl ImportOptions {
    /// A progress callback for `file` (of `total` bytes, 0 if unknown) that forwards to
    /// [`ImportOptions::progress`], if set.
    pub(crate) fn progress_of<'a>(&'a self, file: &'a str, total: u64) -> impl FnMut(u64) + 'a {
        move |done| {
            if let Some(p) = &self.progress {
                p.report(file, done, total);
            }
        }
    }
}

/// What kind of input was recognised.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SourceKind {
    Egoexo,
    Nymeria,
    AriaMultiDevice,
    AriaSingleDevice,
}

impl SourceKind {
    /// A human-readable name.
    pub fn describe(self) -> &'static str {
        match self {
            SourceKind::Egoexo => ".egoexo session",
            SourceKind::Nymeria => "Nymeria sequence",
            SourceKind::AriaMultiDevice => "multi-device Aria MPS folder",
            SourceKind::AriaSingleDevice => "single Aria MPS device folder",
        }
    }
}

/// An imported, validated session and what the import noticed on the way.
#[derive(Clone, Debug, PartialEq)]
pub struct Imported {
    pub session: Session,
    pub source: SourceKind,
    pub warnings: Vec<ImportWarning>,
}

/// Recognises the input; returns its kind and the view of its root.
pub fn detect_source(tree: &FileTree) -> Result<(SourceKind, FileTree), ImportError> {
    let probe = |t: &FileTree| -> Option<SourceKind> {
        if t.contains(crate::format::MANIFEST_FILE) {
            Some(SourceKind::Egoexo)
        } else if t.contains_dir("recording_head") {
            Some(SourceKind::Nymeria)
        } else if t.contains_dir("wearer") {
            Some(SourceKind::AriaMultiDevice)
        } else if aria_mps::find_device(t).ok().flatten().is_some() {
            Some(SourceKind::AriaSingleDevice)
        } else {
            None
        }
    };
    if let Some(kind) = probe(tree) {
        return Ok((kind, tree.clone()));
    }
    let inner = tree.strip_single_root();
    if inner.prefix() != tree.prefix()
        && let Some(kind) = probe(&inner)
    {
        return Ok((kind, inner));
    }
    let mut found: Vec<String> = tree.paths().into_iter().take(12).collect();
    if found.len() == 12 {
        found.push("…".into());
    }
    let found = if found.is_empty() { "no files".to_owned() } else { found.join(", ") };
    Err(ImportError::new(tree.name(), Location::File, ImportErrorKind::Unrecognized { found }))
}

/// Imports any supported input (see the module docs).
pub fn import_session(tree: &FileTree, options: &ImportOptions) -> Result<Imported, ImportError> {
    let (source, root) = detect_source(tree)?;
    let name = session_name(&root);
    let (mut session, mut warnings) = match source {
        SourceKind::Egoexo => crate::format::read_egoexo(&root)?,
        SourceKind::Nymeria => nymeria::import_nymeria(&root, &name, options)?,
        SourceKind::AriaMultiDevice => aria_mps::import_multi_device(&root, &name, options)?,
        SourceKind::AriaSingleDevice => aria_mps::import_single_device(&root, &name, options)?,
    };
    for file in &options.keypoint_files {
        attach_keypoints(&mut session, file, options.coco, &mut warnings)?;
    }
    fit_full_resolution_cameras_to_keypoints(&mut session, &mut warnings);
    // A recording gets its floor here; a `.egoexo` keeps what it stores (readers estimate one
    // where it stores none: `floor::floor_or_estimate`).
    if session.floor.is_none() && source != SourceKind::Egoexo {
        session.floor = crate::floor::floor_from_standing_head(&session);
    }
    warnings.extend(crate::validate::validate_session(&session)?);
    Ok(Imported { session, source, warnings })
}

/// A capture of several participants, imported ([`import_capture`]).
#[derive(Clone, Debug)]
pub struct ImportedCapture {
    pub capture: Capture,
    pub source: SourceKind,
    pub warnings: Vec<ImportWarning>,
}

/// Recognises and imports the input as a capture: a `.egoexo` of version 3 as written (every
/// participant to reconstruct checked as a session), anything else through
/// [`import_session`] as one wearer and their observers ([`Capture::from_session`]) — and, for
/// multi-device recordings (Nymeria, the Aria layout) whose device folders have people files
/// ([`PEOPLE_FILE`]), with every device's wearer a participant to reconstruct.
/// Keypoint files attach to one-wearer sessions only (a capture's views are in its manifest).
pub fn import_capture(tree: &FileTree, options: &ImportOptions) -> Result<ImportedCapture, ImportError> {
    let (source, root) = detect_source(tree)?;
    if source == SourceKind::Egoexo && crate::format::manifest_version(&root)? >= u64::from(CAPTURE_FORMAT_VERSION) {
        let (capture, mut warnings) = crate::format::read_capture(&root)?;
        if !capture.is_one_session() {
            if let Some(file) = options.keypoint_files.first() {
                return Err(ImportError::invalid(
                    &file.name,
                    Location::File,
                    "keypoints for a one-wearer session (a capture of several participants names its keypoints in its manifest's `views`)",
                    format!("a capture of {} participants", capture.participants.len()),
                ));
            }
            for p in capture.reconstructed() {
                let session = capture.session_for(p).map_err(|e| {
                    ImportError::invalid(
                        root.display_path(crate::format::MANIFEST_FILE),
                        Location::File,
                        "a valid capture",
                        e.to_string(),
                    )
                })?;
                warnings.extend(crate::validate::validate_session(&session)?);
            }
            return Ok(ImportedCapture { capture, source, warnings });
        }
    }
    let imported = import_session(tree, options)?;
    let mut capture = Capture::from_session(&imported.session);
    let mut warnings = imported.warnings;
    add_people_views(&root, source, &mut capture, &mut warnings)?;
    Ok(ImportedCapture { capture, source, warnings })
}

/// The file in a device folder of a multi-device recording listing everyone that device's RGB
/// camera saw, without identity (the people-file format of `.egoexo` version 3).
pub const PEOPLE_FILE: &str = "people.jsonl";

/// The device folders of a multi-device recording, wearer first then each observer:
/// `(participant id, folder)`.
fn device_dirs(root: &FileTree, source: SourceKind) -> Vec<(String, String)> {
    match source {
        SourceKind::Nymeria => vec![
            (crate::capture::WEARER_ID.to_owned(), "recording_head".to_owned()),
            (nymeria::OBSERVER_ID.to_owned(), "recording_observer".to_owned()),
        ],
        SourceKind::AriaMultiDevice => std::iter::once((crate::capture::WEARER_ID.to_owned(), "wearer".to_owned()))
            .chain(root.subdirs("observers").into_iter().map(|id| (id.clone(), format!("observers/{id}"))))
            .collect(),
        SourceKind::Egoexo | SourceKind::AriaSingleDevice => Vec::new(),
    }
}

/// Whether the recording at `root` has people files ([`PEOPLE_FILE`]): then it is a capture
/// of several participants ([`import_capture`]).
pub fn has_people_files(root: &FileTree, source: SourceKind) -> bool {
    device_dirs(root, source).iter().any(|(_, dir)| root.contains(&format!("{dir}/{PEOPLE_FILE}")))
}

/// Every device folder's people file becomes a view of that participant's camera (the
/// wearer's glasses get their RGB camera from their calibration); with any, every participant
/// is reconstructed — the Nymeria observer, the layout's observers — each by their own glasses
/// and the others' cameras.
fn add_people_views(
    root: &FileTree,
    source: SourceKind,
    capture: &mut Capture,
    warnings: &mut Vec<ImportWarning>,
) -> Result<(), ImportError> {
    let mut found = false;
    for (id, dir) in device_dirs(root, source) {
        let file = format!("{dir}/{PEOPLE_FILE}");
        if !root.contains(&file) {
            continue;
        }
        let Some(p) = capture.participants.iter().position(|p| p.id == id) else { continue };
        let people = crate::keypoints::read_people_jsonl(&root.display_path(&file), &root.read_text(&file)?, &id)?;
        if capture.participants[p].camera.is_none() {
            let mut camera = aria_mps::device_rgb_camera(&root.view(&dir), warnings)?;
            let points: Vec<_> = people.frames.iter().flatten().flatten().flatten().map(|k| k.pixel).collect();
            fit_full_resolution_camera(&mut camera, &id, &points, warnings);
            capture.participants[p].camera = Some(camera);
        }
        capture.views.push(View { observer: id, people: ViewPeople::Unassigned(people) });
        found = true;
    }
    if found {
        for p in &mut capture.participants {
            p.reconstruct = true;
        }
    }
    Ok(())
}

#[cfg(not(target_arch = "wasm32"))]
/// Opens a folder or zip on disk and imports it as a capture (native only).
pub fn import_capture_path(path: &std::path::Path, options: &ImportOptions) -> Result<ImportedCapture, ImportError> {
    let tree = FileTree::open(path, crate::vfs::Limits::default())?;
    import_capture(&tree, options)
}

/// Keypoint detections needed before their extent is trusted to tell the image size.
pub const MIN_DETECTIONS_FOR_IMAGE_SIZE: usize = 50;
/// The Aria RGB stream's usual resolution, pixels.
pub const ARIA_RGB_STREAM_PX: u32 = 1408;

/// Calibrations without `ImageSizes` (MPS < 1.1) are at the RGB sensor's full resolution
/// (2880 px), but recordings usually stream 1408 px images, and keypoints detected on those
/// are in 1408 px coordinates. When every keypoint of an observer with such a calibration lies
/// inside 1408 × 1408 (at least [`MIN_DETECTIONS_FOR_IMAGE_SIZE`] of them), the camera is
/// rescaled to 1408 px — with a warning, as it is an inference from the keypoints' extent.
pub fn fit_full_resolution_cameras_to_keypoints(session: &mut Session, warnings: &mut Vec<ImportWarning>) {
    for observer in &mut session.observers {
        let Some(track) = &observer.keypoints else { continue };
        let points: Vec<_> = track.frames.iter().flatten().flatten().map(|k| k.pixel).collect();
        fit_full_resolution_camera(&mut observer.camera, &observer.id, &points, warnings);
    }
}

/// [`fit_full_resolution_cameras_to_keypoints`] for one camera of `owner` and the keypoints
/// detected in its images.
fn fit_full_resolution_camera(
    camera: &mut CameraCalibration,
    owner: &str,
    points: &[Vec2],
    warnings: &mut Vec<ImportWarning>,
) {
    let full = crate::aria::calibration::RGB_FULL_RES_PX;
    if camera.width != full || camera.height != full {
        return;
    }
    let limit = ARIA_RGB_STREAM_PX as f32 - 0.5;
    if points.len() < MIN_DETECTIONS_FOR_IMAGE_SIZE || points.iter().any(|p| p.x > limit || p.y > limit) {
        return;
    }
    if let Ok(scaled) = camera.scaled_to(ARIA_RGB_STREAM_PX, ARIA_RGB_STREAM_PX) {
        warnings.push(ImportWarning {
            file: format!("observer `{owner}`"),
            message: format!(
                "its calibration is at the RGB sensor's full {full} px (no ImageSizes) but all {} keypoints lie within {ARIA_RGB_STREAM_PX} px: they were detected on the {ARIA_RGB_STREAM_PX} px stream, so the camera was rescaled to {ARIA_RGB_STREAM_PX}×{ARIA_RGB_STREAM_PX}",
                points.len()
            ),
        });
        *camera = scaled;
    }
}

/// Reads a keypoint file into the observer it names.
pub fn attach_keypoints(
    session: &mut Session,
    file: &KeypointFile,
    coco: CocoTiming,
    warnings: &mut Vec<ImportWarning>,
) -> Result<(), ImportError> {
    let known: Vec<String> = session.observers.iter().map(|o| o.id.clone()).collect();
    let Some(observer) = session.observers.iter_mut().find(|o| o.id == file.observer_id) else {
        return Err(ImportError::new(
            &file.name,
            Location::File,
            ImportErrorKind::ObserverMismatch { expected: format!("one of {known:?}"), got: file.observer_id.clone() },
        ));
    };
    let text = std::str::from_utf8(&file.bytes)
        .map_err(|e| ImportError::invalid(&file.name, Location::File, "UTF-8 text", e.to_string()))?;
    let start = observer.head.timestamps_ns.first().copied().unwrap_or_default();
    let (track, more) = read_keypoints(&file.name, text, &observer.id, coco, start)?;
    if observer.keypoints.is_some() {
        warnings.push(ImportWarning {
            file: file.name.clone(),
            message: format!("replaces the keypoints observer `{}` already had", observer.id),
        });
    }
    observer.keypoints = Some(track);
    warnings.extend(more);
    Ok(())
}

/// The session's name: the root folder's name, else the input's file stem.
fn session_name(root: &FileTree) -> String {
    let from_prefix = root.prefix().trim_end_matches('/').rsplit('/').next().unwrap_or_default();
    let raw = if from_prefix.is_empty() {
        let name = root.name().trim_end_matches(['/', '\\']);
        let base = name.rsplit(['/', '\\']).next().unwrap_or(name);
        base.strip_suffix(".zip").or_else(|| base.strip_suffix(".egoexo")).unwrap_or(base).to_owned()
    } else {
        from_prefix.to_owned()
    };
    if raw.is_empty() { "session".into() } else { raw }
}

#[cfg(not(target_arch = "wasm32"))]
/// Opens a folder or zip on disk and imports it (native only).
pub fn import_path(path: &std::path::Path, options: &ImportOptions) -> Result<Imported, ImportError> {
    let tree = FileTree::open(path, crate::vfs::Limits::default())?;
    import_session(&tree, options)
}
