//! The blocks every manifest version writes the same way: data files (trajectories in the
//! Aria MPS CSV layout, keypoints, videos' frame times, context features, ground truth) and
//! the JSON of cameras, transforms, subjects and placements.

use std::collections::BTreeMap;

use egoexo_core::camera::{CameraCalibration, Projection};
use egoexo_core::glam::Vec3;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, NUM_JOINTS};
use egoexo_motion_io::npz::NpzWriter;
use serde_json::{Value, json};

use super::{FORMAT_NAME, MANIFEST_FILE, WriteError, conventions_json};
use crate::aria::trajectory::write_closed_loop_trajectory;
use crate::keypoints::write_keypoints_jsonl;
use crate::model::{ContextFeatureTrack, GroundTruth, KeypointTrack, SubjectInfo, Trajectory, VideoRef};
use crate::placement::{Mount, Placement, WorldRef};

/// Gravity written into every trajectory file, m/s² in the session world (Y-up by definition).
const SESSION_GRAVITY: Vec3 = Vec3::new(0.0, -9.81, 0.0);

/// The files of a `.egoexo` being written (path → bytes); each method writes one data file and
/// returns the manifest's JSON naming it.
#[derive(Default)]
pub(super) struct DataFiles {
    files: BTreeMap<String, Vec<u8>>,
}

impl DataFiles {
    /// A trajectory (`T_world_device` per timestamp) at `path`, in the Aria MPS CSV layout.
    pub(super) fn trajectory(&mut self, path: String, t: &Trajectory) -> Value {
        let csv = write_closed_loop_trajectory(&t.timestamps_ns, &t.poses, "egoexo", SESSION_GRAVITY);
        self.files.insert(path.clone(), csv.into_bytes());
        json!(path)
    }

    /// `observer`'s keypoints at `path` (JSON lines).
    pub(super) fn keypoints(&mut self, path: String, observer: &str, keypoints: &KeypointTrack) -> Value {
        self.files.insert(path.clone(), write_keypoints_jsonl(observer, keypoints).into_bytes());
        json!(path)
    }

    /// A file written elsewhere (e.g. people without identity) at `path`.
    pub(super) fn insert(&mut self, path: String, bytes: Vec<u8>) -> Value {
        self.files.insert(path.clone(), bytes);
        json!(path)
    }

    /// A video reference `{path, start_ns, timestamps?}`; its frame times, when known, in
    /// `<dir>/video_timestamps.csv`. The video itself is not written here.
    pub(super) fn video(&mut self, dir: &str, video: &VideoRef) -> Value {
        let mut entry = json!({"path": video.path, "start_ns": video.start_ns});
        if !video.frame_times_ns.is_empty() {
            let path = format!("{dir}/video_timestamps.csv");
            let csv = crate::video::write_frame_timestamps(&video.frame_times_ns);
            entry["timestamps"] = self.insert(path, csv.into_bytes());
        }
        entry
    }

    /// Context features as `<dir>/context_features.npz`: `timestamps_ns` (N,), `values` (N, D).
    pub(super) fn context_features(&mut self, dir: &str, features: &ContextFeatureTrack) -> Result<Value, WriteError> {
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
    pub(super) fn ground_truth(&mut self, path: String, gt: &GroundTruth) -> Result<Value, WriteError> {
        let bytes = ground_truth_npz(gt, &path)?;
        let mut entry = json!({"motion": self.insert(path, bytes)});
        if !gt.occlusion.is_empty() {
            entry["occlusion_observers"] =
                json!(gt.occlusion.iter().map(|o| o.observer_id.clone()).collect::<Vec<_>>());
        }
        Ok(entry)
    }

    /// A device's poses and placement into its manifest `entry`: a worn device's trajectory at
    /// `trajectory_path` under `trajectory_key`, a static camera's one `pose`, or nothing (a
    /// static camera that knows no pose); `placement` unless it is the default. `what` names
    /// the device in errors.
    pub(super) fn poses_and_placement(
        &mut self,
        entry: &mut Value,
        (trajectory_key, trajectory_path): (&str, String),
        placement: &Placement,
        poses: &Trajectory,
        what: &str,
    ) -> Result<(), WriteError> {
        if placement.mount == Mount::Worn {
            entry[trajectory_key] = self.trajectory(trajectory_path, poses);
        } else {
            let pose = poses.poses.first().copied().unwrap_or(RigidTransform::IDENTITY);
            if poses.poses.iter().any(|p| *p != pose) {
                return Err(WriteError::Encode {
                    what: format!("{what}: a static camera's poses"),
                    message: "a fixed mount has one pose; its trajectory moves".into(),
                });
            }
            // A static camera in its own world without a pose: that world is its optical frame.
            if !(placement.world == WorldRef::Own && pose == RigidTransform::IDENTITY) {
                entry["pose"] = transform_json(&pose);
            }
        }
        if !placement.is_default() {
            entry["placement"] = to_json(placement, &format!("{what} placement"))?;
        }
        Ok(())
    }

    /// The files with the manifest added as `session.json`.
    pub(super) fn finish(mut self, manifest: &Value) -> Result<BTreeMap<String, Vec<u8>>, WriteError> {
        let text = serde_json::to_string_pretty(manifest)
            .map_err(|e| WriteError::Encode { what: MANIFEST_FILE.into(), message: e.to_string() })?;
        self.files.insert(MANIFEST_FILE.into(), text.into_bytes());
        Ok(self.files)
    }
}

/// The fields every manifest starts with: `format`, `version`, `name`, `created_by`,
/// `conventions`.
pub(super) fn manifest_header(version: u32, name: &str) -> Value {
    json!({
        "format": FORMAT_NAME,
        "version": version,
        "name": name,
        "created_by": format!("egoexo-session {}", env!("CARGO_PKG_VERSION")),
        "conventions": conventions_json(),
    })
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

/// A serde value as JSON; `what` names it in the error.
pub(super) fn to_json<T: serde::Serialize>(value: &T, what: &str) -> Result<Value, WriteError> {
    serde_json::to_value(value).map_err(|e| WriteError::Encode { what: what.into(), message: e.to_string() })
}

fn encode<T, E: std::fmt::Display>(result: Result<T, E>, what: &str) -> Result<T, WriteError> {
    result.map_err(|e| WriteError::Encode { what: what.into(), message: e.to_string() })
}

/// An f32 as the JSON number with the same shortest decimal form (`1.7`, not
/// `1.7000000476837158`); reading it as f64 and casting back gives the same f32.
fn f32_json(x: f32) -> Value {
    x.to_string().parse::<f64>().ok().and_then(serde_json::Number::from_f64).map_or(Value::Null, Value::Number)
}

pub(super) fn f32s(values: &[f32]) -> Value {
    Value::Array(values.iter().map(|&x| f32_json(x)).collect())
}

fn transform_json(t: &RigidTransform) -> Value {
    json!({"translation": f32s(&t.translation.to_array()), "rotation_xyzw": f32s(&t.rotation.to_array())})
}

pub(super) fn camera_json(camera: &CameraCalibration) -> Value {
    let (model, params): (&str, Vec<f32>) = match &camera.projection {
        Projection::Pinhole(k) => ("pinhole", vec![k.fx, k.fy, k.cx, k.cy]),
        Projection::Fisheye624(f) => ("fisheye624", f.params().to_vec()),
    };
    let mut v = json!({
        "model": model,
        "params": f32s(&params),
        "width": camera.width,
        "height": camera.height,
        "t_device_camera": transform_json(&camera.t_device_camera),
    });
    if let Some(r) = camera.valid_radius_px {
        v["valid_radius_px"] = f32_json(r);
    }
    v
}

pub(super) fn subject_json(subject: &SubjectInfo) -> Value {
    let mut v = json!({});
    if let Some(h) = subject.height_m {
        v["height_m"] = f32_json(h);
    }
    if let Some(b) = &subject.betas {
        v["betas"] = f32s(b);
    }
    if let Some(j) = &subject.rest_joints {
        v["rest_joints"] = Value::Array(j.iter().map(|p| f32s(&p.to_array())).collect());
    }
    v
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
