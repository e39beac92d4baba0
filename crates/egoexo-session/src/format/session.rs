//! Versions 1–2 of the manifest: one wearer (`wearer`) and the observers who see them
//! (`observers`); and a static camera's file in the multi-device folder layout, whose
//! `camera`, `pose` and `placement` are those of an observer here.

use std::collections::BTreeMap;

use egoexo_core::camera::CameraCalibration;
use egoexo_core::glam::Vec3;
use serde_json::{Value, json};

use super::read::{ManifestReader, read_floor};
use super::write::{self, DataFiles, camera_json, f32s, subject_json};
use super::{FORMAT_VERSION, WriteError, keys};
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
    let mut wearer = json!({
        "head": files.trajectory("wearer/head/closed_loop_trajectory.csv".into(), &w.head),
        "head_joint_in_device": f32s(&w.head_joint_in_device.to_array()),
    });
    if !w.wrist_source.is_devices() {
        wearer["wrist_source"] = write::to_json(&w.wrist_source, "wearer.wrist_source")?;
    }
    for (key, wrist) in [("left_wrist", &w.left_wrist), ("right_wrist", &w.right_wrist)] {
        if let Some(wrist) = wrist {
            wearer[key] = files.trajectory(format!("wearer/{key}/closed_loop_trajectory.csv"), wrist);
        }
    }
    let mut observers = Vec::new();
    for observer in &session.observers {
        let dir = format!("observers/{}", observer.id);
        let mut entry = json!({"id": observer.id, "camera": camera_json(&observer.camera)});
        let trajectory = ("trajectory", format!("{dir}/closed_loop_trajectory.csv"));
        files.poses_and_placement(&mut entry, trajectory, &observer.placement, &observer.head, &dir)?;
        if let Some(kp) = &observer.keypoints {
            entry["keypoints"] = files.keypoints(format!("{dir}/keypoints.jsonl"), &observer.id, kp);
        }
        if let Some(video) = &observer.video {
            entry["video"] = files.video(&dir, video);
        }
        if let Some(features) = &observer.context_features {
            entry["context_features"] = files.context_features(&dir, features)?;
        }
        observers.push(entry);
    }
    let mut manifest = write::manifest_header(FORMAT_VERSION, &session.name);
    manifest["subject"] = subject_json(&session.subject);
    manifest["wearer"] = wearer;
    manifest["observers"] = Value::Array(observers);
    if let Some(floor) = &session.floor {
        manifest["floor"] = write::to_json(floor, "floor")?;
    }
    if let Some(gt) = &session.ground_truth {
        manifest["ground_truth"] = files.ground_truth("ground_truth.npz".into(), gt)?;
    }
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
    doc: &Value,
) -> Result<(Session, Vec<ImportWarning>), ImportError> {
    let ctx = JsonCtx::file(manifest_file);
    let mut reader = ManifestReader { root, ctx, warnings: Vec::new() };
    reader.known_keys(doc, "", keys::SESSION);
    let name = ctx.str(ctx.field(doc, "", "name")?, "name")?.to_owned();
    let subject = reader.subject_at(ctx.field(doc, "", "subject")?, "subject")?;
    let wearer = reader.wearer(ctx.field(doc, "", "wearer")?)?;
    let observers_value = ctx.field(doc, "", "observers")?;
    let mut observers = Vec::new();
    for (i, v) in ctx.array(observers_value, "observers")?.iter().enumerate() {
        observers.push(reader.observer(v, &format!("observers[{i}]"))?);
    }
    let ground_truth = match ctx.optional(doc, "", "ground_truth")? {
        Some(v) => Some(reader.ground_truth(v, "ground_truth")?),
        None => None,
    };
    let floor = match ctx.optional(doc, "", "floor")? {
        Some(v) => Some(read_floor(&ctx, v)?),
        None => None,
    };
    let mut session = Session { name, wearer, observers, subject, ground_truth, floor };
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
    let mut reader = ManifestReader { root, ctx, warnings: Vec::new() };
    reader.known_keys(&doc, "", keys::STATIC_CAMERA);
    if let Some(t) = ctx.optional(&doc, "", "trajectory")? {
        return Err(ctx.invalid(
            "trajectory",
            "`pose` or a `placement` (a static camera); a worn device is an MPS device folder",
            t,
        ));
    }
    let camera = reader.camera(ctx.field(&doc, "", "camera")?, "camera")?;
    let (trajectory, placement) = reader.poses_and_placement(&doc, "", "trajectory")?;
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
    fn wearer(&mut self, v: &Value) -> Result<Wearer, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, "wearer", keys::WEARER);
        let head = self.trajectory(ctx.field(v, "wearer", "head")?, "wearer.head")?;
        let left_wrist =
            ctx.optional(v, "wearer", "left_wrist")?.map(|w| self.trajectory(w, "wearer.left_wrist")).transpose()?;
        let right_wrist =
            ctx.optional(v, "wearer", "right_wrist")?.map(|w| self.trajectory(w, "wearer.right_wrist")).transpose()?;
        let head_joint_in_device = Vec3::from_array(
            ctx.f32_array::<3>(ctx.field(v, "wearer", "head_joint_in_device")?, "wearer.head_joint_in_device")?,
        );
        let wrist_source = self.wrist_source(v, "wearer")?;
        Ok(Wearer { head, left_wrist, right_wrist, wrist_source, head_joint_in_device })
    }

    fn observer(&mut self, v: &Value, path: &str) -> Result<Observer, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, path, keys::OBSERVER);
        let id = self.id(v, path, "an observer")?;
        let (head, placement) = self.poses_and_placement(v, path, "trajectory")?;
        let camera = self.camera(ctx.field(v, path, "camera")?, &join(path, "camera"))?;
        let keypoints = match ctx.optional(v, path, "keypoints")? {
            Some(k) => {
                let file = self.data_path(k, &join(path, "keypoints"))?;
                Some(read_keypoints_jsonl(&self.root.display_path(&file), &self.root.read_text(&file)?, &id)?)
            }
            None => None,
        };
        let video = match ctx.optional(v, path, "video")? {
            Some(video) => Some(self.video(video, &join(path, "video"), &id)?),
            None => None,
        };
        let context_features = self.context_features_at(v, path)?;
        Ok(Observer { id, head, camera, keypoints, video, context_features, placement })
    }
}
