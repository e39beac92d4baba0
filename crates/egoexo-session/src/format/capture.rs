//! Version 3 of the manifest: a capture of several participants (`participants`, each worn
//! devices and maybe a camera) and the views between them (`views`: one participant's
//! keypoints in another's camera, or everyone it saw without identity).

use std::collections::BTreeMap;

use egoexo_core::glam::Vec3;
use serde_json::{Value, json};

use super::read::{ManifestReader, read_floor};
use super::write::{self, DataFiles, camera_json, f32s, subject_json};
use super::{CAPTURE_FORMAT_VERSION, WriteError, keys};
use crate::capture::{Capture, Participant, View, ViewPeople, spread_fixed_poses_in_capture};
use crate::error::{ImportError, ImportWarning, Location};
use crate::json::{JsonCtx, join};
use crate::keypoints::{read_keypoints_jsonl, read_people_jsonl, write_people_jsonl};
use crate::model::Trajectory;
use crate::vfs::FileTree;

/// Most participants a capture may hold.
pub const MAX_PARTICIPANTS: usize = 16;

/// The files of a capture of several participants in `.egoexo` layout (manifest version 3;
/// path → bytes). Validates first: the capture's own consistency, and every participant to
/// reconstruct as a session ([`Capture::session_for`]).
pub fn write_capture_files(capture: &Capture) -> Result<BTreeMap<String, Vec<u8>>, WriteError> {
    capture.validate()?;
    for p in capture.reconstructed() {
        crate::validate::validate_session(&capture.session_for(p)?)?;
    }
    let mut files = DataFiles::default();
    let mut participants = Vec::new();
    for p in &capture.participants {
        let dir = format!("participants/{}", p.id);
        let mut entry = json!({
            "id": p.id,
            "reconstruct": p.reconstruct,
            "head_joint_in_device": f32s(&p.head_joint_in_device.to_array()),
            "subject": subject_json(&p.subject),
        });
        let head = ("head", format!("{dir}/head/closed_loop_trajectory.csv"));
        files.poses_and_placement(&mut entry, head, &p.placement, &p.head, &dir)?;
        for (key, wrist) in [("left_wrist", &p.left_wrist), ("right_wrist", &p.right_wrist)] {
            if let Some(wrist) = wrist {
                entry[key] = files.trajectory(format!("{dir}/{key}/closed_loop_trajectory.csv"), wrist);
            }
        }
        if !p.wrist_source.is_devices() {
            entry["wrist_source"] = write::to_json(&p.wrist_source, &format!("{dir} wrist_source"))?;
        }
        if let Some(camera) = &p.camera {
            entry["camera"] = camera_json(camera);
        }
        if let Some(video) = &p.video {
            entry["video"] = files.video(&dir, video);
        }
        if let Some(features) = &p.context_features {
            entry["context_features"] = files.context_features(&dir, features)?;
        }
        if let Some(gt) = &p.ground_truth {
            entry["ground_truth"] = files.ground_truth(format!("{dir}/ground_truth.npz"), gt)?;
        }
        participants.push(entry);
    }
    let mut views = Vec::new();
    for view in &capture.views {
        let dir = format!("views/{}", view.observer);
        views.push(match &view.people {
            ViewPeople::Assigned { target, keypoints } => {
                let path = files.keypoints(format!("{dir}/{target}.keypoints.jsonl"), &view.observer, keypoints);
                json!({"observer": view.observer, "target": target, "keypoints": path})
            }
            ViewPeople::Unassigned(people) => {
                let bytes = write_people_jsonl(&view.observer, people).into_bytes();
                json!({"observer": view.observer, "people": files.insert(format!("{dir}/people.jsonl"), bytes)})
            }
        });
    }
    let mut manifest = write::manifest_header(CAPTURE_FORMAT_VERSION, &capture.name);
    manifest["participants"] = Value::Array(participants);
    manifest["views"] = Value::Array(views);
    if let Some(floor) = &capture.floor {
        manifest["floor"] = write::to_json(floor, "floor")?;
    }
    files.finish(&manifest)
}

/// The capture as `.egoexo` zip bytes, with `extra` files (its participants' videos) stored
/// in the zip too.
pub fn write_capture_zip(capture: &Capture, extra: BTreeMap<String, Vec<u8>>) -> Result<Vec<u8>, WriteError> {
    write::zip(&write::with_extra_files(write_capture_files(capture)?, extra)?)
}

#[cfg(not(target_arch = "wasm32"))]
/// Writes the capture to `path`: a zip file, or (with `as_folder`) a folder (native only).
pub fn save_capture(
    capture: &Capture,
    extra: BTreeMap<String, Vec<u8>>,
    path: &std::path::Path,
    as_folder: bool,
) -> Result<(), WriteError> {
    let io = |source| WriteError::Io { path: path.display().to_string(), source };
    if as_folder {
        let files = write::with_extra_files(write_capture_files(capture)?, extra)?;
        crate::vfs::write_dir(path, &files).map_err(io)
    } else {
        std::fs::write(path, write_capture_zip(capture, extra)?).map_err(io)
    }
}

pub(super) fn read_capture_manifest(
    root: &FileTree,
    manifest_file: &str,
    doc: &Value,
) -> Result<(Capture, Vec<ImportWarning>), ImportError> {
    let ctx = JsonCtx::file(manifest_file);
    let mut reader = ManifestReader { root, ctx, warnings: Vec::new() };
    reader.known_keys(doc, "", keys::CAPTURE);
    let name = ctx.str(ctx.field(doc, "", "name")?, "name")?.to_owned();
    let participants_value = ctx.field(doc, "", "participants")?;
    let items = ctx.array(participants_value, "participants")?;
    if items.is_empty() || items.len() > MAX_PARTICIPANTS {
        return Err(ctx.invalid("participants", format!("1 to {MAX_PARTICIPANTS} participants"), participants_value));
    }
    let mut participants = Vec::with_capacity(items.len());
    for (i, v) in items.iter().enumerate() {
        participants.push(reader.participant(v, &format!("participants[{i}]"))?);
    }
    let mut views = Vec::new();
    if let Some(list) = ctx.optional(doc, "", "views")? {
        for (i, v) in ctx.array(list, "views")?.iter().enumerate() {
            views.push(reader.view(v, &format!("views[{i}]"))?);
        }
    }
    let floor = match ctx.optional(doc, "", "floor")? {
        Some(v) => Some(read_floor(&ctx, v)?),
        None => None,
    };
    let mut capture = Capture { name, participants, views, floor };
    spread_fixed_poses_in_capture(&mut capture);
    capture
        .validate()
        .map_err(|e| ImportError::invalid(manifest_file, Location::File, "a consistent capture", e.to_string()))?;
    Ok((capture, reader.warnings))
}

impl ManifestReader<'_> {
    /// A participant of a capture (version 3).
    fn participant(&mut self, v: &Value, path: &str) -> Result<Participant, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, path, keys::PARTICIPANT);
        let id = self.id(v, path, "a participant")?;
        let reconstruct_path = join(path, "reconstruct");
        let reconstruct = ctx.field(v, path, "reconstruct")?;
        let reconstruct =
            reconstruct.as_bool().ok_or_else(|| ctx.invalid(&reconstruct_path, "true or false", reconstruct))?;
        let (head, placement) = self.poses_and_placement(v, path, "head")?;
        let wrist = |key: &str| -> Result<Option<Trajectory>, ImportError> {
            ctx.optional(v, path, key)?.map(|w| self.trajectory(w, &join(path, key))).transpose()
        };
        let (left_wrist, right_wrist) = (wrist("left_wrist")?, wrist("right_wrist")?);
        let head_joint_path = join(path, "head_joint_in_device");
        let head_joint_in_device =
            Vec3::from_array(ctx.f32_array::<3>(ctx.field(v, path, "head_joint_in_device")?, &head_joint_path)?);
        let wrist_source = self.wrist_source(v, path)?;
        let camera = match ctx.optional(v, path, "camera")? {
            Some(c) => Some(self.camera(c, &join(path, "camera"))?),
            None => None,
        };
        let video = match ctx.optional(v, path, "video")? {
            Some(video) => Some(self.video(video, &join(path, "video"), &id)?),
            None => None,
        };
        if video.is_some() && camera.is_none() {
            return Err(ctx.invalid(
                &join(path, "video"),
                "a video only with the camera that filmed it (`camera`)",
                &v["video"],
            ));
        }
        let context_features = self.context_features_at(v, path)?;
        let subject = self.subject_at(ctx.field(v, path, "subject")?, &join(path, "subject"))?;
        let ground_truth = match ctx.optional(v, path, "ground_truth")? {
            Some(g) => Some(self.ground_truth(g, &join(path, "ground_truth"))?),
            None => None,
        };
        Ok(Participant {
            id,
            reconstruct,
            head,
            left_wrist,
            right_wrist,
            wrist_source,
            head_joint_in_device,
            camera,
            video,
            context_features,
            subject,
            ground_truth,
            placement,
        })
    }

    /// A view of a capture (version 3): `{observer, target, keypoints}` or `{observer, people}`.
    fn view(&mut self, v: &Value, path: &str) -> Result<View, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, path, keys::VIEW);
        let observer = ctx.str(ctx.field(v, path, "observer")?, &join(path, "observer"))?.to_owned();
        let people = match (ctx.optional(v, path, "target")?, ctx.optional(v, path, "people")?) {
            (Some(target), None) => {
                let target = ctx.str(target, &join(path, "target"))?.to_owned();
                let file = self.data_path(ctx.field(v, path, "keypoints")?, &join(path, "keypoints"))?;
                let keypoints =
                    read_keypoints_jsonl(&self.root.display_path(&file), &self.root.read_text(&file)?, &observer)?;
                ViewPeople::Assigned { target, keypoints }
            }
            (None, Some(people)) => {
                let file = self.data_path(people, &join(path, "people"))?;
                ViewPeople::Unassigned(read_people_jsonl(
                    &self.root.display_path(&file),
                    &self.root.read_text(&file)?,
                    &observer,
                )?)
            }
            _ => {
                return Err(ctx.invalid(
                    path,
                    "either `target` and `keypoints` (one participant's keypoints) or `people` (everyone, without identity)",
                    v,
                ));
            }
        };
        Ok(View { observer, people })
    }
}
