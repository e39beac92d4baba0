//! The blocks every manifest version writes the same way: data files (trajectories in the
//! Aria MPS CSV layout, keypoints, videos' frame times, context features, ground truth) and
//! the typed entries (`manifest.rs`) of cameras, transforms, subjects and placements.

use std::collections::BTreeMap;

use egoexo_core::camera::{CameraCalibration, Projection};
use egoexo_core::glam::Vec3;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, NUM_JOINTS};
use egoexo_motion_io::npz::NpzWriter;

use super::manifest::{
    CameraEntry, CameraModel, Conventions, F32, GroundTruthEntry, SubjectEntry, TransformEntry, VideoEntry, to_wire,
};
use super::{MANIFEST_FILE, WriteError};
use crate::aria::trajectory::write_closed_loop_trajectory;
use crate::keypoints::write_keypoints_jsonl;
use crate::model::{ContextFeatureTrack, GroundTruth, KeypointTrack, SubjectInfo, Trajectory, VideoRef};
use crate::placement::{Mount, Placement, WorldRef};

/// Gravity written into every trajectory file, m/s² in the session world (Y-up by definition).
const SESSION_GRAVITY: Vec3 = Vec3::new(0.0, -9.81, 0.0);

/// The files of a `.egoexo` being written (path → bytes); each method writes one data file and
/// returns what the manifest names it by.
#[derive(Default)]
pub(super) struct DataFiles {
    files: BTreeMap<String, Vec<u8>>,
}

impl DataFiles {
    /// A trajectory (`T_world_device` per timestamp) at `path`, in the Aria MPS CSV layout.
    pub(super) fn trajectory(&mut self, path: String, t: &Trajectory) -> String {
        let csv = write_closed_loop_trajectory(&t.timestamps_ns, &t.poses, "egoexo", SESSION_GRAVITY);
        self.insert(path, csv.into_bytes())
    }

    /// An optional trajectory (a wrist) at `path`.
    pub(super) fn optional_trajectory(&mut self, path: String, t: Option<&Trajectory>) -> Option<String> {
        t.map(|t| self.trajectory(path, t))
    }

    /// `observer`'s keypoints at `path` (JSON lines).
    pub(super) fn keypoints(&mut self, path: String, observer: &str, keypoints: &KeypointTrack) -> String {
        self.insert(path, write_keypoints_jsonl(observer, keypoints).into_bytes())
    }

    /// A file written elsewhere (e.g. people without identity) at `path`.
    pub(super) fn insert(&mut self, path: String, bytes: Vec<u8>) -> String {
        self.files.insert(path.clone(), bytes);
        path
    }

    /// A video reference `{path, start_ns, timestamps?}`; its frame times, when known, in
    /// `<dir>/video_timestamps.csv`. The video itself is not written here.
    pub(super) fn video(&mut self, dir: &str, video: &VideoRef) -> VideoEntry {
        let timestamps = (!video.frame_times_ns.is_empty()).then(|| {
            let csv = crate::video::write_frame_timestamps(&video.frame_times_ns);
            self.insert(format!("{dir}/video_timestamps.csv"), csv.into_bytes())
        });
        VideoEntry { path: video.path.clone(), start_ns: video.start_ns, timestamps }
    }

    /// Context features as `<dir>/context_features.npz`: `timestamps_ns` (N,), `values` (N, D).
    pub(super) fn context_features(&mut self, dir: &str, features: &ContextFeatureTrack) -> Result<String, WriteError> {
        let path = format!("{dir}/context_features.npz");
        let mut npz = NpzWriter::new();
        let n = features.timestamps_ns.len() as u64;
        encode(npz.add("timestamps_ns", &[n], &features.timestamps_ns), &path)?;
        encode(npz.add("values", &[n, features.dim as u64], &features.values), &path)?;
        let bytes = encode(npz.finish(), &path)?;
        Ok(self.insert(path, bytes))
    }

    /// Ground truth: its motion at `path` (the arrays of the module docs) and the manifest's
    /// `{motion, occlusion_observers?}`.
    pub(super) fn ground_truth(&mut self, path: String, gt: &GroundTruth) -> Result<GroundTruthEntry, WriteError> {
        let bytes = ground_truth_npz(gt, &path)?;
        let occlusion_observers =
            (!gt.occlusion.is_empty()).then(|| gt.occlusion.iter().map(|o| o.observer_id.clone()).collect());
        Ok(GroundTruthEntry { motion: self.insert(path, bytes), occlusion_observers })
    }

    /// A device's poses and placement as its manifest entry holds them: a worn device's
    /// trajectory file at `trajectory_path`, or a static camera's one pose (none for a static
    /// camera in its own world that knows no pose: that world is its optical frame); the
    /// placement unless it is the default. `what` names the device in errors.
    pub(super) fn poses_and_placement(
        &mut self,
        trajectory_path: String,
        placement: &Placement,
        poses: &Trajectory,
        what: &str,
    ) -> Result<WrittenPoses, WriteError> {
        let mut written = WrittenPoses {
            trajectory: None,
            pose: None,
            placement: (!placement.is_default()).then(|| placement.clone()),
        };
        if placement.mount == Mount::Worn {
            written.trajectory = Some(self.trajectory(trajectory_path, poses));
        } else {
            let pose = poses.poses.first().copied().unwrap_or(RigidTransform::IDENTITY);
            if poses.poses.iter().any(|p| *p != pose) {
                return Err(WriteError::Encode {
                    what: format!("{what}: a static camera's poses"),
                    message: "a fixed mount has one pose; its trajectory moves".into(),
                });
            }
            if !(placement.world == WorldRef::Own && pose == RigidTransform::IDENTITY) {
                written.pose = Some(transform_entry(&pose));
            }
        }
        Ok(written)
    }

    /// The files with the manifest added as `session.json`.
    pub(super) fn finish(mut self, manifest: &impl serde::Serialize) -> Result<BTreeMap<String, Vec<u8>>, WriteError> {
        let text = serde_json::to_string_pretty(manifest)
            .map_err(|e| WriteError::Encode { what: MANIFEST_FILE.into(), message: e.to_string() })?;
        self.files.insert(MANIFEST_FILE.into(), text.into_bytes());
        Ok(self.files)
    }
}

/// A device's poses and placement as a manifest entry holds them
/// ([`DataFiles::poses_and_placement`]).
pub(super) struct WrittenPoses {
    pub trajectory: Option<String>,
    pub pose: Option<TransformEntry>,
    pub placement: Option<Placement>,
}

/// `created_by` of every manifest this build writes.
pub(super) fn created_by() -> Option<String> {
    Some(format!("egoexo-session {}", env!("CARGO_PKG_VERSION")))
}

/// The `conventions` every manifest holds.
pub(super) fn conventions() -> Conventions {
    Conventions::session()
}

/// The `.egoexo` zip of `files`.
pub(super) fn zip(files: &BTreeMap<String, Vec<u8>>) -> Result<Vec<u8>, WriteError> {
    egoexo_motion_io::npz::write_zip(files)
        .map_err(|e| WriteError::Encode { what: "the .egoexo zip".into(), message: e.to_string() })
}

/// `files` and `extra` (files the recording refers to but does not hold, e.g. videos), which
/// must not replace any of them.
pub(super) fn with_extra_files(
    mut files: BTreeMap<String, Vec<u8>>,
    extra: BTreeMap<String, Vec<u8>>,
) -> Result<BTreeMap<String, Vec<u8>>, WriteError> {
    for (name, bytes) in extra {
        if files.contains_key(&name) {
            return Err(WriteError::Encode { what: name, message: "is one of the session's own files".into() });
        }
        files.insert(name, bytes);
    }
    Ok(files)
}

fn encode<T, E: std::fmt::Display>(result: Result<T, E>, what: &str) -> Result<T, WriteError> {
    result.map_err(|e| WriteError::Encode { what: what.into(), message: e.to_string() })
}

pub(super) fn transform_entry(t: &RigidTransform) -> TransformEntry {
    TransformEntry { translation: to_wire(t.translation.to_array()), rotation_xyzw: to_wire(t.rotation.to_array()) }
}

pub(super) fn camera_entry(camera: &CameraCalibration) -> CameraEntry {
    let (model, params): (CameraModel, Vec<f32>) = match &camera.projection {
        Projection::Pinhole(k) => (CameraModel::Pinhole, vec![k.fx, k.fy, k.cx, k.cy]),
        Projection::Fisheye624(f) => (CameraModel::Fisheye624, f.params().to_vec()),
    };
    CameraEntry {
        model,
        params: params.into_iter().map(F32).collect(),
        width: camera.width,
        height: camera.height,
        t_device_camera: transform_entry(&camera.t_device_camera),
        valid_radius_px: camera.valid_radius_px.map(F32),
    }
}

pub(super) fn subject_entry(subject: &SubjectInfo) -> SubjectEntry {
    SubjectEntry {
        height_m: subject.height_m.map(F32),
        betas: subject.betas.as_ref().map(|b| b.iter().copied().map(F32).collect()),
        rest_joints: subject.rest_joints.as_ref().map(|j| j.iter().map(|p| to_wire(p.to_array())).collect()),
    }
}

fn ground_truth_npz(gt: &GroundTruth, path: &str) -> Result<Vec<u8>, WriteError> {
    let m = &gt.motion;
    let n = m.len() as u64;
    let mut npz = NpzWriter::new();
    encode(npz.add("fps", &[1], &[m.fps]), path)?;
    encode(npz.add("start_ns", &[1], &[m.start_ns]), path)?;
    let rest: Vec<f32> = m.skeleton.rest_joints().iter().flat_map(|p| p.to_array()).collect();
    encode(npz.add("rest_joints", &[NUM_JOINTS as u64, 3], &rest), path)?;
    if let Some(b) = &m.betas {
        encode(npz.add("betas", &[b.len() as u64], b), path)?;
    }
    let root: Vec<f32> = m.poses.iter().flat_map(|p| p.root_orientation.to_array()).collect();
    encode(npz.add("root_orientation_xyzw", &[n, 4], &root), path)?;
    let body: Vec<f32> = m.poses.iter().flat_map(|p| p.body.iter().flat_map(|q| q.to_array())).collect();
    encode(npz.add("body_rotations_xyzw", &[n, NUM_BODY_JOINTS as u64, 4], &body), path)?;
    let trans: Vec<f32> = m.poses.iter().flat_map(|p| p.translation.to_array()).collect();
    encode(npz.add("translation", &[n, 3], &trans), path)?;
    if !gt.occlusion.is_empty() {
        let masks: Vec<u16> = gt.occlusion.iter().flat_map(|o| o.occluded.iter().copied()).collect();
        encode(npz.add("occluded", &[gt.occlusion.len() as u64, n], &masks), path)?;
    }
    encode(npz.finish(), path)
}
