//! Versions 1–2 of the manifest: one wearer (`wearer`) and the observers who see them
//! (`observers`); and a static camera's file in the multi-device folder layout, whose
//! `camera`, `pose` and `placement` are those of an observer here.

use std::collections::BTreeMap;

use egoexo_core::camera::CameraCalibration;
use egoexo_core::glam::Vec3;

use super::manifest::{self, ObserverEntry, SessionManifest, StaticCameraFile, WearerEntry, from_wire, to_wire};
use super::read::{ManifestReader, check_floor};
use super::write::{self, DataFiles, camera_entry, subject_entry};
use super::{FORMAT_NAME, FORMAT_VERSION, WriteError};
use crate::capture::spread_fixed_poses;
use crate::error::{ImportError, ImportWarning, Location};
use crate::json::{JsonCtx, join};
use crate::keypoints::read_keypoints_jsonl;
use crate::model::{Observer, Session, Trajectory, Wearer};
use crate::placement::{Mount, Placement};
use crate::vfs::FileTree;

/// The files of a session in `.egoexo` layout (path → bytes). Validates first.
pub fn write_egoexo_files(session: &Session) -> Result<BTreeMap<String, Vec<u8>>, WriteError> {
    crate::validate::validate_session(session)?;
    let mut files = DataFiles::default();
    let w = &session.wearer;
    let wearer = WearerEntry {
        head: files.trajectory("wearer/head/closed_loop_trajectory.csv".into(), &w.head),
        left_wrist: files
            .optional_trajectory("wearer/left_wrist/closed_loop_trajectory.csv".into(), w.left_wrist.as_ref()),
        right_wrist: files
            .optional_trajectory("wearer/right_wrist/closed_loop_trajectory.csv".into(), w.right_wrist.as_ref()),
        head_joint_in_device: to_wire(w.head_joint_in_device.to_array()),
        wrist_source: (!w.wrist_source.is_devices()).then(|| w.wrist_source.clone()),
    };
    let mut observers = Vec::new();
    for observer in &session.observers {
        let dir = format!("observers/{}", observer.id);
        let poses = files.poses_and_placement(
            format!("{dir}/closed_loop_trajectory.csv"),
            &observer.placement,
            &observer.head,
            &dir,
        )?;
        observers.push(ObserverEntry {
            id: observer.id.clone(),
            trajectory: poses.trajectory,
            pose: poses.pose,
            placement: poses.placement,
            camera: camera_entry(&observer.camera),
            keypoints: observer
                .keypoints
                .as_ref()
                .map(|kp| files.keypoints(format!("{dir}/keypoints.jsonl"), &observer.id, kp)),
            video: observer.video.as_ref().map(|video| files.video(&dir, video)),
            context_features: observer
                .context_features
                .as_ref()
                .map(|f| files.context_features(&dir, f))
                .transpose()?,
        });
    }
    let ground_truth =
        session.ground_truth.as_ref().map(|gt| files.ground_truth("ground_truth.npz".into(), gt)).transpose()?;
    let manifest = SessionManifest {
        format: FORMAT_NAME.into(),
        version: FORMAT_VERSION,
        name: session.name.clone(),
        created_by: write::created_by(),
        conventions: write::conventions(),
        subject: subject_entry(&session.subject),
        wearer,
        observers,
        ground_truth,
        floor: session.floor.clone(),
    };
    files.finish(&manifest)
}

/// The session as `.egoexo` zip bytes.
pub fn write_egoexo_zip(session: &Session) -> Result<Vec<u8>, WriteError> {
    write::zip(&write_egoexo_files(session)?)
}

/// [`write_egoexo_zip`] with the files the session refers to but does not hold (its
/// observers' videos, by their paths) stored in the zip too.
pub fn write_egoexo_zip_with(session: &Session, extra: BTreeMap<String, Vec<u8>>) -> Result<Vec<u8>, WriteError> {
    write::zip(&write::with_extra_files(write_egoexo_files(session)?, extra)?)
}

#[cfg(not(target_arch = "wasm32"))]
/// Writes the session to `path`: a zip file, or (with `as_folder`) a folder (native only).
pub fn save_egoexo(session: &Session, path: &std::path::Path, as_folder: bool) -> Result<(), WriteError> {
    save_egoexo_with(session, BTreeMap::new(), path, as_folder)
}

#[cfg(not(target_arch = "wasm32"))]
/// [`save_egoexo`] with files the session refers to but does not hold — its observers'
/// videos (`Observer::video`'s paths) — written next to the session's own (native only).
/// Every video the session names must be among them.
pub fn save_egoexo_with(
    session: &Session,
    extra: BTreeMap<String, Vec<u8>>,
    path: &std::path::Path,
    as_folder: bool,
) -> Result<(), WriteError> {
    let io = |source| WriteError::Io { path: path.display().to_string(), source };
    let files = write::with_extra_files(write_egoexo_files(session)?, extra)?;
    for observer in &session.observers {
        if let Some(video) = &observer.video
            && !files.contains_key(&video.path)
        {
            return Err(WriteError::Encode {
                what: format!("observer `{}`", observer.id),
                message: format!("its video `{}` was not given to write", video.path),
            });
        }
    }
    if as_folder {
        crate::vfs::write_dir(path, &files).map_err(io)
    } else {
        std::fs::write(path, write::zip(&files)?).map_err(io)
    }
}

pub(super) fn read_session_manifest(
    root: &FileTree,
    manifest_file: &str,
    doc: &serde_json::Value,
) -> Result<(Session, Vec<ImportWarning>), ImportError> {
    let mut reader = ManifestReader { root, file: manifest_file, warnings: Vec::new() };
    let manifest: SessionManifest = manifest::from_json(manifest_file, doc, &mut reader.warnings)?;
    let subject = reader.subject(&manifest.subject, "subject")?;
    let wearer = reader.wearer(&manifest.wearer)?;
    let mut observers = Vec::new();
    for (i, entry) in manifest.observers.iter().enumerate() {
        observers.push(reader.observer(entry, &format!("observers[{i}]"))?);
    }
    let ground_truth = manifest.ground_truth.as_ref().map(|gt| reader.ground_truth(gt, "ground_truth")).transpose()?;
    if let Some(floor) = &manifest.floor {
        check_floor(manifest_file, floor)?;
    }
    let mut session = Session { name: manifest.name, wearer, observers, subject, ground_truth, floor: manifest.floor };
    spread_fixed_poses(&mut session);
    Ok((session, reader.warnings))
}

/// File name of a static camera in an observer folder of the multi-device layout.
pub const STATIC_CAMERA_FILE: &str = "static_camera.json";

/// A static camera's file (`observers/<id>/static_camera.json` in the multi-device layout,
/// `docs/session-format.md`): its `camera` as in a `.egoexo` observer, and `pose` (its
/// `T_world_device` in the session's world) or a `placement` with `mount: fixed` and
/// `world: own` (a camera to register). `file` is relative to `root`. The trajectory holds
/// the pose once; [`spread_fixed_poses`] spans it over the recording.
pub fn read_static_camera(
    root: &FileTree,
    file: &str,
) -> Result<(CameraCalibration, Trajectory, Placement, Vec<ImportWarning>), ImportError> {
    let display = root.display_path(file);
    let text = root.read_text(file)?;
    let ctx = JsonCtx::file(&display);
    let doc = ctx.parse(&text)?;
    if let Some(t) = doc.get("trajectory").filter(|t| !t.is_null()) {
        return Err(ctx.invalid(
            "trajectory",
            "`pose` or a `placement` (a static camera); a worn device is an MPS device folder",
            t,
        ));
    }
    let mut reader = ManifestReader { root, file: &display, warnings: Vec::new() };
    let entry: StaticCameraFile = manifest::from_json(&display, &doc, &mut reader.warnings)?;
    let camera = reader.camera(&entry.camera, "camera")?;
    let (trajectory, placement) =
        reader.poses_and_placement("", ("trajectory", None), entry.pose.as_ref(), entry.placement.as_ref())?;
    if placement.mount != Mount::Fixed {
        return Err(ImportError::invalid(
            &display,
            Location::Field("placement.mount".into()),
            "`fixed` (or no placement with a `pose`): this file is a static camera",
            "`worn`",
        ));
    }
    Ok((camera, trajectory, placement, reader.warnings))
}

impl ManifestReader<'_> {
    fn wearer(&mut self, w: &WearerEntry) -> Result<Wearer, ImportError> {
        Ok(Wearer {
            head: self.trajectory(&w.head, "wearer.head")?,
            left_wrist: self.optional_trajectory(w.left_wrist.as_ref(), "wearer.left_wrist")?,
            right_wrist: self.optional_trajectory(w.right_wrist.as_ref(), "wearer.right_wrist")?,
            wrist_source: w.wrist_source.clone().unwrap_or_default(),
            head_joint_in_device: Vec3::from_array(from_wire(&w.head_joint_in_device)),
        })
    }

    fn observer(&mut self, o: &ObserverEntry, path: &str) -> Result<Observer, ImportError> {
        let id = self.id(&o.id, &join(path, "id"), "an observer")?;
        let (head, placement) = self.poses_and_placement(
            path,
            ("trajectory", o.trajectory.as_ref()),
            o.pose.as_ref(),
            o.placement.as_ref(),
        )?;
        let camera = self.camera(&o.camera, &join(path, "camera"))?;
        let keypoints = match &o.keypoints {
            Some(k) => {
                let file = self.data_path(k, &join(path, "keypoints"))?;
                Some(read_keypoints_jsonl(&self.root.display_path(&file), &self.root.read_text(&file)?, &id)?)
            }
            None => None,
        };
        let video = o.video.as_ref().map(|v| self.video(v, &join(path, "video"), &id)).transpose()?;
        let context_features =
            self.context_features_at(o.context_features.as_ref(), &join(path, "context_features"))?;
        Ok(Observer { id, head, camera, keypoints, video, context_features, placement })
    }
}
