//! Version 3 of the manifest: a capture of several participants (`participants`, each worn
//! devices and maybe a camera) and the views between them (`views`: one participant's
//! keypoints in another's camera, or everyone it saw without identity).

use std::collections::BTreeMap;

use egoexo_core::glam::Vec3;

use super::manifest::{self, CaptureManifest, ParticipantEntry, ViewEntry, from_wire, to_wire};
use super::read::{ManifestReader, check_floor};
use super::write::{self, DataFiles, camera_entry, subject_entry};
use super::{CAPTURE_FORMAT_VERSION, FORMAT_NAME, WriteError};
use crate::capture::{Capture, Participant, View, ViewPeople, spread_fixed_poses_in_capture};
use crate::error::{ImportError, ImportWarning, Location};
use crate::json::join;
use crate::keypoints::{read_keypoints_jsonl, read_people_jsonl, write_people_jsonl};
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
        let poses =
            files.poses_and_placement(format!("{dir}/head/closed_loop_trajectory.csv"), &p.placement, &p.head, &dir)?;
        participants.push(ParticipantEntry {
            id: p.id.clone(),
            reconstruct: p.reconstruct,
            head: poses.trajectory,
            left_wrist: files
                .optional_trajectory(format!("{dir}/left_wrist/closed_loop_trajectory.csv"), p.left_wrist.as_ref()),
            right_wrist: files
                .optional_trajectory(format!("{dir}/right_wrist/closed_loop_trajectory.csv"), p.right_wrist.as_ref()),
            wrist_source: (!p.wrist_source.is_devices()).then(|| p.wrist_source.clone()),
            head_joint_in_device: to_wire(p.head_joint_in_device.to_array()),
            camera: p.camera.as_ref().map(camera_entry),
            video: p.video.as_ref().map(|video| files.video(&dir, video)),
            context_features: p.context_features.as_ref().map(|f| files.context_features(&dir, f)).transpose()?,
            subject: subject_entry(&p.subject),
            ground_truth: p
                .ground_truth
                .as_ref()
                .map(|gt| files.ground_truth(format!("{dir}/ground_truth.npz"), gt))
                .transpose()?,
            pose: poses.pose,
            placement: poses.placement,
        });
    }
    let mut views = Vec::new();
    for view in &capture.views {
        let dir = format!("views/{}", view.observer);
        let observer = view.observer.clone();
        views.push(match &view.people {
            ViewPeople::Assigned { target, keypoints } => ViewEntry {
                observer,
                target: Some(target.clone()),
                keypoints: Some(files.keypoints(format!("{dir}/{target}.keypoints.jsonl"), &view.observer, keypoints)),
                people: None,
            },
            ViewPeople::Unassigned(people) => {
                let bytes = write_people_jsonl(&view.observer, people).into_bytes();
                ViewEntry {
                    observer,
                    target: None,
                    keypoints: None,
                    people: Some(files.insert(format!("{dir}/people.jsonl"), bytes)),
                }
            }
        });
    }
    let manifest = CaptureManifest {
        format: FORMAT_NAME.into(),
        version: CAPTURE_FORMAT_VERSION,
        name: capture.name.clone(),
        created_by: write::created_by(),
        conventions: write::conventions(),
        participants,
        views,
        floor: capture.floor.clone(),
    };
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
    doc: &serde_json::Value,
) -> Result<(Capture, Vec<ImportWarning>), ImportError> {
    let mut reader = ManifestReader { root, file: manifest_file, warnings: Vec::new() };
    let manifest: CaptureManifest = manifest::from_json(manifest_file, doc, &mut reader.warnings)?;
    let count = manifest.participants.len();
    if count == 0 || count > MAX_PARTICIPANTS {
        return Err(reader.invalid(
            "participants",
            format!("1 to {MAX_PARTICIPANTS} participants"),
            format!("an array of {count} items"),
        ));
    }
    let mut participants = Vec::with_capacity(count);
    for (i, entry) in manifest.participants.iter().enumerate() {
        participants.push(reader.participant(entry, &format!("participants[{i}]"))?);
    }
    let mut views = Vec::with_capacity(manifest.views.len());
    for (i, entry) in manifest.views.iter().enumerate() {
        views.push(reader.view(entry, &format!("views[{i}]"))?);
    }
    if let Some(floor) = &manifest.floor {
        check_floor(manifest_file, floor)?;
    }
    let mut capture = Capture { name: manifest.name, participants, views, floor: manifest.floor };
    spread_fixed_poses_in_capture(&mut capture);
    capture
        .validate()
        .map_err(|e| ImportError::invalid(manifest_file, Location::File, "a consistent capture", e.to_string()))?;
    Ok((capture, reader.warnings))
}

impl ManifestReader<'_> {
    /// A participant of a capture (version 3).
    fn participant(&mut self, p: &ParticipantEntry, path: &str) -> Result<Participant, ImportError> {
        let id = self.id(&p.id, &join(path, "id"), "a participant")?;
        let (head, placement) =
            self.poses_and_placement(path, ("head", p.head.as_ref()), p.pose.as_ref(), p.placement.as_ref())?;
        let left_wrist = self.optional_trajectory(p.left_wrist.as_ref(), &join(path, "left_wrist"))?;
        let right_wrist = self.optional_trajectory(p.right_wrist.as_ref(), &join(path, "right_wrist"))?;
        let camera = p.camera.as_ref().map(|c| self.camera(c, &join(path, "camera"))).transpose()?;
        let video = p.video.as_ref().map(|v| self.video(v, &join(path, "video"), &id)).transpose()?;
        if video.is_some() && camera.is_none() {
            return Err(self.invalid(
                &join(path, "video"),
                "a video only with the camera that filmed it (`camera`)",
                "a video without a camera",
            ));
        }
        Ok(Participant {
            reconstruct: p.reconstruct,
            head,
            left_wrist,
            right_wrist,
            wrist_source: p.wrist_source.clone().unwrap_or_default(),
            head_joint_in_device: Vec3::from_array(from_wire(&p.head_joint_in_device)),
            camera,
            video,
            context_features: self.context_features_at(p.context_features.as_ref(), &join(path, "context_features"))?,
            subject: self.subject(&p.subject, &join(path, "subject"))?,
            ground_truth: p
                .ground_truth
                .as_ref()
                .map(|g| self.ground_truth(g, &join(path, "ground_truth")))
                .transpose()?,
            placement,
            id,
        })
    }

    /// A view of a capture (version 3): `{observer, target, keypoints}` or `{observer, people}`.
    fn view(&mut self, v: &ViewEntry, path: &str) -> Result<View, ImportError> {
        let observer = v.observer.clone();
        let people = match (&v.target, &v.keypoints, &v.people) {
            (Some(target), Some(keypoints), None) => {
                let file = self.data_path(keypoints, &join(path, "keypoints"))?;
                let keypoints =
                    read_keypoints_jsonl(&self.root.display_path(&file), &self.root.read_text(&file)?, &observer)?;
                ViewPeople::Assigned { target: target.clone(), keypoints }
            }
            (None, None, Some(people)) => {
                let file = self.data_path(people, &join(path, "people"))?;
                ViewPeople::Unassigned(read_people_jsonl(
                    &self.root.display_path(&file),
                    &self.root.read_text(&file)?,
                    &observer,
                )?)
            }
            _ => {
                let named: Vec<&str> = [
                    ("target", v.target.is_some()),
                    ("keypoints", v.keypoints.is_some()),
                    ("people", v.people.is_some()),
                ]
                .into_iter()
                .filter_map(|(key, there)| there.then_some(key))
                .collect();
                return Err(self.invalid(
                    path,
                    "either `target` and `keypoints` (one participant's keypoints) or `people` (everyone, without identity)",
                    if named.is_empty() { "none of them".to_owned() } else { format!("`{}`", named.join("`, `")) },
                ));
            }
        };
        Ok(View { observer, people })
    }
}
