//! The native session format, `.egoexo`: a zip archive (or the same files as a plain folder)
//! with a versioned `session.json` manifest and data files. Specified, with a JSON Schema and
//! an example, in `docs/session-format.md`.
//!
//! ```text
//! session.json                                  manifest (format "egoexo-session", version 2; 1 is read)
//! wearer/head/closed_loop_trajectory.csv        trajectories: the Aria MPS CSV layout
//! wearer/left_wrist/closed_loop_trajectory.csv  (optional)
//! wearer/right_wrist/closed_loop_trajectory.csv (optional)
//! observers/<id>/closed_loop_trajectory.csv    a worn observer (a static camera has `pose`, or
//!                                               none and a `placement`, in the manifest)
//! observers/<id>/keypoints.jsonl                (optional) JSON-lines keypoints
//! observers/<id>/context_features.npz           (optional) timestamps_ns (N,), values (N, D)
//! ground_truth.npz                              (optional) SMPL motion + occlusion labels
//! ```
//! A capture of several participants ([`crate::capture::Capture`]) is manifest version 3:
//! `participants/<id>/…` and `views/<observer>/…` instead of `wearer/` and `observers/`
//! ([`write_capture_files`], [`read_capture`]; every version reads as a capture).
//!
//! Everything is in session conventions: Y-up world, metres, CPF head-device frames,
//! nanoseconds on one clock. The manifest names every data file, so the layout above is what
//! the writer produces, not something the reader assumes.
//!
//! `ground_truth.npz` arrays: `fps` (1,) f32; `start_ns` (1,) i64; `rest_joints` (24, 3) f32,
//! metres, SMPL body frame; `betas` (B,) f32 (optional); `root_orientation_xyzw` (N, 4) f32;
//! `body_rotations_xyzw` (N, 21, 4) f32 (joints 1..=21, local to their parents);
//! `translation` (N, 3) f32 (SMPL `transl`: pelvis = rest pelvis + translation); `occluded`
//! (O, N) u16 (optional; bit k = exo keypoint k occluded, rows in the order of the manifest's
//! `ground_truth.occlusion_observers`). Quaternions are stored, not axis-angle, so a
//! write → read round trip is exact.

use std::collections::BTreeMap;

use egoexo_core::camera::{CameraCalibration, Fisheye624, Pinhole, Projection};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::motion::SmplMotion;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, NUM_JOINTS, SmplPose, SmplSkeleton};
use serde_json::{Value, json};
use thiserror::Error;

use crate::aria::trajectory::{Clock, read_closed_loop_trajectory, write_closed_loop_trajectory};
use crate::capture::{Capture, CaptureError, Participant, View, ViewPeople};
use crate::capture::{spread_fixed_poses, spread_fixed_poses_in_capture};
use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::json::{JsonCtx, join};
use crate::keypoints::{read_keypoints_jsonl, write_keypoints_jsonl};
use crate::keypoints::{read_people_jsonl, write_people_jsonl};
use crate::model::{
    ContextFeatureTrack, Floor, GroundTruth, Observer, ObserverOcclusion, Session, SubjectInfo, Trajectory, VideoRef,
    Wearer, WristSource,
};
use crate::placement::{Mount, Placement, WorldRef};
use egoexo_motion_io::npz::NpzWriter;

use crate::npz::{NpyArray, NpyData, Npz};
use crate::vfs::{FileTree, normalize_path};

/// The manifest's file name.
pub const MANIFEST_FILE: &str = "session.json";
/// The manifest's `format` value.
pub const FORMAT_NAME: &str = "egoexo-session";
/// The manifest version this build writes for a one-wearer session. Version 2 added the
/// optional `floor` and `wearer.wrist_source` fields; version 1 files (without them) are read
/// too.
pub const FORMAT_VERSION: u32 = 2;
/// The manifest version of a capture of several participants ([`Capture`]): `participants`
/// and `views` instead of `wearer` and `observers`. Every older version reads as a capture
/// too ([`read_capture`]).
pub const CAPTURE_FORMAT_VERSION: u32 = 3;
/// The oldest manifest version this build reads.
pub const MIN_FORMAT_VERSION: u32 = 1;
/// Largest accepted angle between a session trajectory's gravity and −Y, degrees (session
/// worlds are Y-up by definition).
pub const MAX_SESSION_GRAVITY_TILT_DEG: f32 = 1.0;
/// The fixed `conventions` object (the same in every version).
pub fn conventions_json() -> Value {
    json!({"world": "y_up", "device_frame": "cpf", "time": "nanoseconds", "length": "metres"})
}

/// Why a session could not be written.
#[derive(Debug, Error)]
pub enum WriteError {
    /// The session fails validation.
    #[error("the session is invalid: {0}")]
    Invalid(#[from] ImportError),
    /// The capture's participants and views do not fit together.
    #[error("the capture is invalid: {0}")]
    InvalidCapture(#[from] CaptureError),
    /// Building an archive failed.
    #[error("could not build {what}: {message}")]
    Encode { what: String, message: String },
    /// Writing to disk failed (native only).
    #[error("could not write {path}: {source}")]
    Io { path: String, source: std::io::Error },
}

/// The files of a session in `.egoexo` layout (path → bytes). Validates first.
pub fn write_egoexo_files(session: &Session) -> Result<BTreeMap<String, Vec<u8>>, WriteError> {
    crate::validate::validate_session(session)?;
    let gravity = Vec3::new(0.0, -9.81, 0.0);
    let mut files = BTreeMap::new();
    let put_trajectory = |files: &mut BTreeMap<String, Vec<u8>>, path: String, t: &Trajectory| {
        files.insert(path, write_closed_loop_trajectory(&t.timestamps_ns, &t.poses, "egoexo", gravity).into_bytes());
    };
    let head = "wearer/head/closed_loop_trajectory.csv".to_owned();
    put_trajectory(&mut files, head.clone(), &session.wearer.head);
    let mut wearer =
        json!({"head": head, "head_joint_in_device": f32s(&session.wearer.head_joint_in_device.to_array())});
    if !session.wearer.wrist_source.is_devices() {
        wearer["wrist_source"] = serde_json::to_value(&session.wearer.wrist_source)
            .map_err(|e| WriteError::Encode { what: "wearer.wrist_source".into(), message: e.to_string() })?;
    }
    for (key, wrist) in [("left_wrist", &session.wearer.left_wrist), ("right_wrist", &session.wearer.right_wrist)] {
        if let Some(wrist) = wrist {
            let path = format!("wearer/{key}/closed_loop_trajectory.csv");
            put_trajectory(&mut files, path.clone(), wrist);
            wearer[key] = json!(path);
        }
    }
    let mut observers = Vec::new();
    for observer in &session.observers {
        let dir = format!("observers/{}", observer.id);
        let mut entry = json!({"id": observer.id, "camera": camera_json(&observer.camera)});
        match placement_poses_json(&observer.placement, &observer.head)? {
            PosesJson::Trajectory => {
                let trajectory = format!("{dir}/closed_loop_trajectory.csv");
                put_trajectory(&mut files, trajectory.clone(), &observer.head);
                entry["trajectory"] = json!(trajectory);
            }
            PosesJson::Pose(pose) => entry["pose"] = pose,
            PosesJson::None => {}
        }
        if !observer.placement.is_default() {
            entry["placement"] = placement_json(&observer.placement, &format!("{dir} placement"))?;
        }
        if let Some(kp) = &observer.keypoints {
            let path = format!("{dir}/keypoints.jsonl");
            files.insert(path.clone(), write_keypoints_jsonl(&observer.id, kp).into_bytes());
            entry["keypoints"] = json!(path);
        }
        if let Some(video) = &observer.video {
            entry["video"] = json!({"path": video.path, "start_ns": video.start_ns});
            if !video.frame_times_ns.is_empty() {
                let path = format!("{dir}/video_timestamps.csv");
                files.insert(path.clone(), crate::video::write_frame_timestamps(&video.frame_times_ns).into_bytes());
                entry["video"]["timestamps"] = json!(path);
            }
        }
        if let Some(features) = &observer.context_features {
            let path = format!("{dir}/context_features.npz");
            let mut npz = NpzWriter::new();
            let n = features.timestamps_ns.len() as u64;
            encode(npz.add("timestamps_ns", &[n], &features.timestamps_ns), &path)?;
            encode(npz.add("values", &[n, features.dim as u64], &features.values), &path)?;
            files.insert(path.clone(), encode(npz.finish(), &path)?);
            entry["context_features"] = json!(path);
        }
        observers.push(entry);
    }
    let mut manifest = json!({
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "name": session.name,
        "created_by": format!("egoexo-session {}", env!("CARGO_PKG_VERSION")),
        "conventions": conventions_json(),
        "subject": subject_json(&session.subject),
        "wearer": wearer,
        "observers": observers,
    });
    if let Some(floor) = &session.floor {
        manifest["floor"] = serde_json::to_value(floor)
            .map_err(|e| WriteError::Encode { what: "floor".into(), message: e.to_string() })?;
    }
    if let Some(gt) = &session.ground_truth {
        let path = "ground_truth.npz".to_owned();
        files.insert(path.clone(), ground_truth_npz(gt, &path)?);
        let mut entry = json!({"motion": path});
        if !gt.occlusion.is_empty() {
            entry["occlusion_observers"] =
                json!(gt.occlusion.iter().map(|o| o.observer_id.clone()).collect::<Vec<_>>());
        }
        manifest["ground_truth"] = entry;
    }
    let text = serde_json::to_string_pretty(&manifest)
        .map_err(|e| WriteError::Encode { what: MANIFEST_FILE.into(), message: e.to_string() })?;
    files.insert(MANIFEST_FILE.into(), text.into_bytes());
    Ok(files)
}

/// The session as `.egoexo` zip bytes.
pub fn write_egoexo_zip(session: &Session) -> Result<Vec<u8>, WriteError> {
    let files = write_egoexo_files(session)?;
    egoexo_motion_io::npz::write_zip(&files)
        .map_err(|e| WriteError::Encode { what: "the .egoexo zip".into(), message: e.to_string() })
}

/// [`write_egoexo_zip`] with the files the session refers to but does not hold (its
/// observers' videos, by their paths) stored in the zip too.
pub fn write_egoexo_zip_with(session: &Session, extra: BTreeMap<String, Vec<u8>>) -> Result<Vec<u8>, WriteError> {
    let files = with_extra_files(write_egoexo_files(session)?, extra)?;
    egoexo_motion_io::npz::write_zip(&files)
        .map_err(|e| WriteError::Encode { what: "the .egoexo zip".into(), message: e.to_string() })
}

/// The session's files and `extra`, which must not replace any of them.
fn with_extra_files(
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
    let files = with_extra_files(write_egoexo_files(session)?, extra)?;
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
        let zip = egoexo_motion_io::npz::write_zip(&files)
            .map_err(|e| WriteError::Encode { what: "the .egoexo zip".into(), message: e.to_string() })?;
        std::fs::write(path, zip).map_err(io)
    }
}

fn encode<T, E: std::fmt::Display>(result: Result<T, E>, what: &str) -> Result<T, WriteError> {
    result.map_err(|e| WriteError::Encode { what: what.into(), message: e.to_string() })
}

/// An f32 as the JSON number with the same shortest decimal form (`1.7`, not
/// `1.7000000476837158`); reading it as f64 and casting back gives the same f32.
fn f32_json(x: f32) -> Value {
    x.to_string().parse::<f64>().ok().and_then(serde_json::Number::from_f64).map_or(Value::Null, Value::Number)
}

fn f32s(values: &[f32]) -> Value {
    Value::Array(values.iter().map(|&x| f32_json(x)).collect())
}

fn transform_json(t: &RigidTransform) -> Value {
    json!({"translation": f32s(&t.translation.to_array()), "rotation_xyzw": f32s(&t.rotation.to_array())})
}

/// How a device's poses are written: a trajectory file (a worn device), one `pose` (a static
/// camera), or nothing (a static camera that knows no pose: its own world is its optical frame).
enum PosesJson {
    Trajectory,
    Pose(Value),
    None,
}

fn placement_poses_json(placement: &Placement, head: &Trajectory) -> Result<PosesJson, WriteError> {
    if placement.mount == Mount::Worn {
        return Ok(PosesJson::Trajectory);
    }
    let pose = head.poses.first().copied().unwrap_or(RigidTransform::IDENTITY);
    if head.poses.iter().any(|p| *p != pose) {
        return Err(WriteError::Encode {
            what: "a static camera's poses".into(),
            message: "a fixed mount has one pose; its trajectory moves".into(),
        });
    }
    Ok(if placement.world == WorldRef::Own && pose == RigidTransform::IDENTITY {
        PosesJson::None
    } else {
        PosesJson::Pose(transform_json(&pose))
    })
}

fn placement_json(placement: &Placement, what: &str) -> Result<Value, WriteError> {
    serde_json::to_value(placement).map_err(|e| WriteError::Encode { what: what.into(), message: e.to_string() })
}

fn camera_json(camera: &CameraCalibration) -> Value {
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

fn subject_json(subject: &SubjectInfo) -> Value {
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

/// The manifest of a `.egoexo` rooted at `root`, parsed, with its checked version.
fn read_manifest_header(root: &FileTree) -> Result<(String, Value, u64), ImportError> {
    let manifest_file = root.display_path(MANIFEST_FILE);
    let ctx = JsonCtx::file(&manifest_file);
    let text = root.read_text(MANIFEST_FILE)?;
    if text.trim().is_empty() {
        return Err(ImportError::new(
            &manifest_file,
            Location::File,
            ImportErrorKind::Empty { expected: "the session manifest (JSON)".into() },
        ));
    }
    let doc = ctx.parse(&text)?;
    let format = ctx.field(&doc, "", "format")?;
    if format.as_str() != Some(FORMAT_NAME) {
        return Err(ctx.invalid("format", format!("\"{FORMAT_NAME}\""), format));
    }
    let version = ctx.field(&doc, "", "version")?;
    let unsupported = |got: String| {
        ctx.error(
            "version",
            ImportErrorKind::UnsupportedVersion { got, oldest: MIN_FORMAT_VERSION, newest: CAPTURE_FORMAT_VERSION },
        )
    };
    let version = match version.as_u64() {
        Some(v) if (u64::from(MIN_FORMAT_VERSION)..=u64::from(CAPTURE_FORMAT_VERSION)).contains(&v) => v,
        Some(v) => return Err(unsupported(v.to_string())),
        None => return Err(unsupported(crate::json::describe(version))),
    };
    let conventions = ctx.field(&doc, "", "conventions")?;
    if *conventions != conventions_json() {
        return Err(ctx.invalid("conventions", conventions_json().to_string(), conventions));
    }
    Ok((manifest_file, doc, version))
}

/// Reads a `.egoexo` session (zip or folder) rooted at `root`. A capture of several
/// participants (version 3) reads as a session when it has exactly one participant to
/// reconstruct and every view is assigned; otherwise [`read_capture`] reads it.
pub fn read_egoexo(root: &FileTree) -> Result<(Session, Vec<ImportWarning>), ImportError> {
    let (manifest_file, doc, version) = read_manifest_header(root)?;
    if version >= u64::from(CAPTURE_FORMAT_VERSION) {
        let (capture, warnings) = read_capture_manifest(root, &manifest_file, &doc)?;
        return Ok((single_session(&manifest_file, &capture)?, warnings));
    }
    read_session_manifest(root, &manifest_file, &doc)
}

/// The manifest version of the `.egoexo` rooted at `root` (checked to be one this build reads).
pub fn manifest_version(root: &FileTree) -> Result<u64, ImportError> {
    Ok(read_manifest_header(root)?.2)
}

/// The one session a capture stands for: its only participant to reconstruct, with every
/// view assigned.
pub fn single_session(file: &str, capture: &Capture) -> Result<Session, ImportError> {
    let reconstructed: Vec<usize> = capture.reconstructed().collect();
    let [participant] = reconstructed[..] else {
        return Err(ImportError::invalid(
            file,
            Location::Field("participants".into()),
            "exactly one participant to reconstruct for a one-wearer session (a capture of several is reconstructed participant by participant)",
            format!("{} participants to reconstruct", reconstructed.len()),
        ));
    };
    if let Some(index) = capture.views.iter().position(|v| matches!(v.people, ViewPeople::Unassigned(_))) {
        return Err(ImportError::invalid(
            file,
            Location::Field(format!("views[{index}]")),
            "keypoints assigned to a participant (people without identity need association first)",
            "people without identity",
        ));
    }
    capture.session_for(participant).map_err(|e| {
        ImportError::invalid(file, Location::Field("participants".into()), "a valid capture", e.to_string())
    })
}

/// Reads a `.egoexo` (zip or folder) rooted at `root` as a capture: version 3 as written,
/// older versions as their one wearer plus observers ([`Capture::from_session`]).
pub fn read_capture(root: &FileTree) -> Result<(Capture, Vec<ImportWarning>), ImportError> {
    let (manifest_file, doc, version) = read_manifest_header(root)?;
    if version >= u64::from(CAPTURE_FORMAT_VERSION) {
        return read_capture_manifest(root, &manifest_file, &doc);
    }
    let (session, warnings) = read_session_manifest(root, &manifest_file, &doc)?;
    Ok((Capture::from_session(&session), warnings))
}

fn read_session_manifest(
    root: &FileTree,
    manifest_file: &str,
    doc: &Value,
) -> Result<(Session, Vec<ImportWarning>), ImportError> {
    let ctx = JsonCtx::file(manifest_file);
    let mut reader = ManifestReader { root, ctx, warnings: Vec::new() };
    reader.known_keys(
        doc,
        "",
        &[
            "format",
            "version",
            "name",
            "created_by",
            "conventions",
            "subject",
            "wearer",
            "observers",
            "ground_truth",
            "floor",
        ],
    );
    let name = ctx.str(ctx.field(doc, "", "name")?, "name")?.to_owned();
    let subject = reader.subject(ctx.field(doc, "", "subject")?)?;
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
    reader.known_keys(&doc, "", &["camera", "pose", "placement"]);
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

fn read_capture_manifest(
    root: &FileTree,
    manifest_file: &str,
    doc: &Value,
) -> Result<(Capture, Vec<ImportWarning>), ImportError> {
    let ctx = JsonCtx::file(manifest_file);
    let mut reader = ManifestReader { root, ctx, warnings: Vec::new() };
    reader.known_keys(
        doc,
        "",
        &["format", "version", "name", "created_by", "conventions", "participants", "views", "floor"],
    );
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
    let gravity = Vec3::new(0.0, -9.81, 0.0);
    let mut files = BTreeMap::new();
    let mut put_trajectory = |path: String, t: &Trajectory| {
        files.insert(
            path.clone(),
            write_closed_loop_trajectory(&t.timestamps_ns, &t.poses, "egoexo", gravity).into_bytes(),
        );
        json!(path)
    };
    let mut participants = Vec::new();
    let mut data = BTreeMap::new();
    for p in &capture.participants {
        let dir = format!("participants/{}", p.id);
        let mut entry = json!({
            "id": p.id,
            "reconstruct": p.reconstruct,
            "head_joint_in_device": f32s(&p.head_joint_in_device.to_array()),
            "subject": subject_json(&p.subject),
        });
        match placement_poses_json(&p.placement, &p.head)? {
            PosesJson::Trajectory => {
                entry["head"] = put_trajectory(format!("{dir}/head/closed_loop_trajectory.csv"), &p.head);
            }
            PosesJson::Pose(pose) => entry["pose"] = pose,
            PosesJson::None => {}
        }
        if !p.placement.is_default() {
            entry["placement"] = placement_json(&p.placement, &format!("{dir} placement"))?;
        }
        for (key, wrist) in [("left_wrist", &p.left_wrist), ("right_wrist", &p.right_wrist)] {
            if let Some(wrist) = wrist {
                entry[key] = put_trajectory(format!("{dir}/{key}/closed_loop_trajectory.csv"), wrist);
            }
        }
        if !p.wrist_source.is_devices() {
            entry["wrist_source"] = serde_json::to_value(&p.wrist_source)
                .map_err(|e| WriteError::Encode { what: format!("{dir} wrist_source"), message: e.to_string() })?;
        }
        if let Some(camera) = &p.camera {
            entry["camera"] = camera_json(camera);
        }
        if let Some(video) = &p.video {
            entry["video"] = json!({"path": video.path, "start_ns": video.start_ns});
            if !video.frame_times_ns.is_empty() {
                let path = format!("{dir}/video_timestamps.csv");
                data.insert(path.clone(), crate::video::write_frame_timestamps(&video.frame_times_ns).into_bytes());
                entry["video"]["timestamps"] = json!(path);
            }
        }
        if let Some(features) = &p.context_features {
            let path = format!("{dir}/context_features.npz");
            let mut npz = NpzWriter::new();
            let n = features.timestamps_ns.len() as u64;
            encode(npz.add("timestamps_ns", &[n], &features.timestamps_ns), &path)?;
            encode(npz.add("values", &[n, features.dim as u64], &features.values), &path)?;
            data.insert(path.clone(), encode(npz.finish(), &path)?);
            entry["context_features"] = json!(path);
        }
        if let Some(gt) = &p.ground_truth {
            let path = format!("{dir}/ground_truth.npz");
            data.insert(path.clone(), ground_truth_npz(gt, &path)?);
            entry["ground_truth"] = json!({"motion": path});
            if !gt.occlusion.is_empty() {
                entry["ground_truth"]["occlusion_observers"] =
                    json!(gt.occlusion.iter().map(|o| o.observer_id.clone()).collect::<Vec<_>>());
            }
        }
        participants.push(entry);
    }
    let mut views = Vec::new();
    for view in &capture.views {
        let dir = format!("views/{}", view.observer);
        views.push(match &view.people {
            ViewPeople::Assigned { target, keypoints } => {
                let path = format!("{dir}/{target}.keypoints.jsonl");
                data.insert(path.clone(), write_keypoints_jsonl(&view.observer, keypoints).into_bytes());
                json!({"observer": view.observer, "target": target, "keypoints": path})
            }
            ViewPeople::Unassigned(people) => {
                let path = format!("{dir}/people.jsonl");
                data.insert(path.clone(), write_people_jsonl(&view.observer, people).into_bytes());
                json!({"observer": view.observer, "people": path})
            }
        });
    }
    files.extend(data);
    let mut manifest = json!({
        "format": FORMAT_NAME,
        "version": CAPTURE_FORMAT_VERSION,
        "name": capture.name,
        "created_by": format!("egoexo-session {}", env!("CARGO_PKG_VERSION")),
        "conventions": conventions_json(),
        "participants": participants,
        "views": views,
    });
    if let Some(floor) = &capture.floor {
        manifest["floor"] = serde_json::to_value(floor)
            .map_err(|e| WriteError::Encode { what: "floor".into(), message: e.to_string() })?;
    }
    let text = serde_json::to_string_pretty(&manifest)
        .map_err(|e| WriteError::Encode { what: MANIFEST_FILE.into(), message: e.to_string() })?;
    files.insert(MANIFEST_FILE.into(), text.into_bytes());
    Ok(files)
}

/// The capture as `.egoexo` zip bytes, with `extra` files (its participants' videos) stored
/// in the zip too.
pub fn write_capture_zip(capture: &Capture, extra: BTreeMap<String, Vec<u8>>) -> Result<Vec<u8>, WriteError> {
    let files = with_extra_files(write_capture_files(capture)?, extra)?;
    egoexo_motion_io::npz::write_zip(&files)
        .map_err(|e| WriteError::Encode { what: "the .egoexo zip".into(), message: e.to_string() })
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
        let files = with_extra_files(write_capture_files(capture)?, extra)?;
        crate::vfs::write_dir(path, &files).map_err(io)
    } else {
        std::fs::write(path, write_capture_zip(capture, extra)?).map_err(io)
    }
}

/// The `floor` object.
fn read_floor(ctx: &JsonCtx<'_>, v: &Value) -> Result<Floor, ImportError> {
    let floor: Floor = serde_json::from_value(v.clone()).map_err(|e| {
        ctx.invalid(
            "floor",
            format!("{{\"height_m\": metres, \"source\": {{\"kind\": \"semidense_points\" | \"standing_head\" | \"ground_truth\", …}}}} ({e})"),
            v,
        )
    })?;
    if !(floor.height_m.is_finite() && floor.height_m.abs() <= 10_000.0) {
        return Err(ctx.invalid("floor.height_m", "a finite height within ±10000 m", &v["height_m"]));
    }
    Ok(floor)
}

struct ManifestReader<'a> {
    root: &'a FileTree,
    ctx: JsonCtx<'a>,
    warnings: Vec<ImportWarning>,
}

impl ManifestReader<'_> {
    fn known_keys(&mut self, v: &Value, path: &str, known: &[&str]) {
        if let Value::Object(map) = v {
            for key in map.keys().filter(|k| !known.contains(&k.as_str())) {
                self.warnings.push(ImportWarning {
                    file: self.ctx.file.to_owned(),
                    message: format!("unknown field `{}` ignored", join(path, key)),
                });
            }
        }
    }

    /// A data file named by the manifest: a safe relative path that exists.
    fn data_path(&self, v: &Value, path: &str) -> Result<String, ImportError> {
        let raw = self.ctx.str(v, path)?;
        let normalized = normalize_path(raw)
            .ok_or_else(|| self.ctx.error(path, ImportErrorKind::UnsafePath { path: raw.to_owned() }))?;
        if !self.root.contains(&normalized) {
            return Err(ImportError::missing_file(
                self.root.display_path(&normalized),
                format!("the file named by {} field `{path}`", self.ctx.file),
            ));
        }
        Ok(normalized)
    }

    fn trajectory(&self, v: &Value, path: &str) -> Result<Trajectory, ImportError> {
        let file = self.data_path(v, path)?;
        let display = self.root.display_path(&file);
        let t = read_closed_loop_trajectory(&display, self.root.open_reader(&file)?, Clock::Device, &mut |_| {})?;
        let g = t.gravity_world;
        if g.normalize().dot(Vec3::NEG_Y) < MAX_SESSION_GRAVITY_TILT_DEG.to_radians().cos() {
            return Err(ImportError::invalid(
                display,
                Location::LineField { line: 2, field: "gravity_x_world..gravity_z_world".into() },
                format!("gravity along −Y (a session world is Y-up, within {MAX_SESSION_GRAVITY_TILT_DEG}°)"),
                format!("({}, {}, {})", g.x, g.y, g.z),
            ));
        }
        Ok(Trajectory { timestamps_ns: t.timestamps_ns, poses: t.poses })
    }

    fn subject(&mut self, v: &Value) -> Result<SubjectInfo, ImportError> {
        self.subject_at(v, "subject")
    }

    fn subject_at(&mut self, v: &Value, path: &str) -> Result<SubjectInfo, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, path, &["height_m", "betas", "rest_joints"]);
        let field = |key: &str| join(path, key);
        let height_m = ctx.optional(v, path, "height_m")?.map(|h| ctx.f32(h, &field("height_m"))).transpose()?;
        let betas = match ctx.optional(v, path, "betas")? {
            Some(b) => {
                let items = ctx.array(b, &field("betas"))?;
                if items.is_empty() || items.len() > 300 {
                    return Err(ctx.invalid(&field("betas"), "1 to 300 SMPL shape coefficients", b));
                }
                Some(
                    items
                        .iter()
                        .enumerate()
                        .map(|(i, x)| ctx.f32(x, &format!("{path}.betas[{i}]")))
                        .collect::<Result<_, _>>()?,
                )
            }
            None => None,
        };
        let rest_joints = match ctx.optional(v, path, "rest_joints")? {
            Some(j) => {
                let items = ctx.array(j, &field("rest_joints"))?;
                if items.len() != NUM_JOINTS {
                    return Err(ctx.invalid(&field("rest_joints"), format!("{NUM_JOINTS} joints [x, y, z]"), j));
                }
                let mut joints = [Vec3::ZERO; NUM_JOINTS];
                for (i, (slot, item)) in joints.iter_mut().zip(items).enumerate() {
                    *slot = Vec3::from_array(ctx.f32_array::<3>(item, &format!("{path}.rest_joints[{i}]"))?);
                }
                Some(joints)
            }
            None => None,
        };
        Ok(SubjectInfo { height_m, betas, rest_joints })
    }

    fn wearer(&mut self, v: &Value) -> Result<Wearer, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, "wearer", &["head", "left_wrist", "right_wrist", "head_joint_in_device", "wrist_source"]);
        let head = self.trajectory(ctx.field(v, "wearer", "head")?, "wearer.head")?;
        let left_wrist =
            ctx.optional(v, "wearer", "left_wrist")?.map(|w| self.trajectory(w, "wearer.left_wrist")).transpose()?;
        let right_wrist =
            ctx.optional(v, "wearer", "right_wrist")?.map(|w| self.trajectory(w, "wearer.right_wrist")).transpose()?;
        let head_joint_in_device = Vec3::from_array(
            ctx.f32_array::<3>(ctx.field(v, "wearer", "head_joint_in_device")?, "wearer.head_joint_in_device")?,
        );
        let wrist_source = match ctx.optional(v, "wearer", "wrist_source")? {
            Some(w) => serde_json::from_value(w.clone()).map_err(|e| {
                ctx.invalid(
                    "wearer.wrist_source",
                    format!("{{\"kind\": \"devices\"}} or {{\"kind\": \"hand_tracking\", \"file\", \"form\", \"orientation\"}} ({e})"),
                    w,
                )
            })?,
            None => WristSource::Devices,
        };
        Ok(Wearer { head, left_wrist, right_wrist, wrist_source, head_joint_in_device })
    }

    /// A device's poses and placement: `trajectory_key` (a worn device's trajectory file), or
    /// `pose` (a static camera), or neither with `placement.mount: fixed` and `world: own` (a
    /// static camera to register). A static camera's trajectory holds its pose once here;
    /// [`spread_fixed_poses`] spans it over the recording once everything is read.
    fn poses_and_placement(
        &mut self,
        v: &Value,
        path: &str,
        trajectory_key: &str,
    ) -> Result<(Trajectory, Placement), ImportError> {
        let ctx = self.ctx;
        let placement_path = join(path, "placement");
        let placement: Option<Placement> = match ctx.optional(v, path, "placement")? {
            Some(p) => Some(serde_json::from_value(p.clone()).map_err(|e| {
                ctx.invalid(
                    &placement_path,
                    format!("a placement {{world, gravity, clock, mount, focal_known, registration}} ({e})"),
                    p,
                )
            })?),
            None => None,
        };
        let trajectory = ctx.optional(v, path, trajectory_key)?;
        let pose = ctx.optional(v, path, "pose")?;
        let fixed = placement.as_ref().is_some_and(|p| p.mount == Mount::Fixed);
        match (trajectory, pose) {
            (Some(_), Some(p)) => Err(ctx.invalid(
                &join(path, "pose"),
                format!("either `{trajectory_key}` (a worn device) or `pose` (a static camera), not both"),
                p,
            )),
            (Some(t), None) => {
                if fixed {
                    return Err(ctx.invalid(
                        &join(&placement_path, "mount"),
                        format!("`worn` for a device with a `{trajectory_key}` (a static camera has `pose`)"),
                        &v["placement"]["mount"],
                    ));
                }
                let trajectory = self.trajectory(t, &join(path, trajectory_key))?;
                Ok((trajectory, placement.unwrap_or_default()))
            }
            (None, Some(p)) => {
                let pose = self.transform(p, &join(path, "pose"))?;
                let placement = Placement { mount: Mount::Fixed, ..placement.unwrap_or_default() };
                Ok((Trajectory { timestamps_ns: vec![0], poses: vec![pose] }, placement))
            }
            (None, None) => match placement {
                Some(placement) if fixed && placement.world == WorldRef::Own => {
                    Ok((Trajectory { timestamps_ns: vec![0], poses: vec![RigidTransform::IDENTITY] }, placement))
                }
                _ => Err(ImportError::invalid(
                    ctx.file,
                    Location::Field(join(path, trajectory_key)),
                    format!(
                        "`{trajectory_key}` (a worn device), `pose` (a static camera), or `placement` with \
                         `mount: fixed` and `world: own` (a static camera to register)"
                    ),
                    "none of them",
                )),
            },
        }
    }

    fn transform(&self, v: &Value, path: &str) -> Result<RigidTransform, ImportError> {
        let ctx = self.ctx;
        let t = ctx.f32_array::<3>(ctx.field(v, path, "translation")?, &join(path, "translation"))?;
        let q_path = join(path, "rotation_xyzw");
        let q = ctx.f32_array::<4>(ctx.field(v, path, "rotation_xyzw")?, &q_path)?;
        let q = Quat::from_array(q);
        let norm = f64::from(q.length());
        if (norm - 1.0).abs() > crate::aria::trajectory::QUATERNION_NORM_TOLERANCE {
            return Err(ctx.error(
                &q_path,
                ImportErrorKind::NonUnitQuaternion {
                    norm,
                    tolerance: crate::aria::trajectory::QUATERNION_NORM_TOLERANCE,
                },
            ));
        }
        Ok(RigidTransform { rotation: unit(q), translation: Vec3::from_array(t) })
    }

    fn camera(&mut self, v: &Value, path: &str) -> Result<CameraCalibration, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, path, &["model", "params", "width", "height", "t_device_camera", "valid_radius_px"]);
        let model_path = join(path, "model");
        let model = ctx.field(v, path, "model")?;
        let params_path = join(path, "params");
        let params = ctx.field(v, path, "params")?;
        let bad = |e: egoexo_core::camera::CameraError| {
            ImportError::invalid(ctx.file, ctx.at(&params_path), "valid camera parameters", e.to_string())
        };
        let projection = match model.as_str() {
            Some("fisheye624") => {
                Projection::Fisheye624(Fisheye624::new(ctx.f32_array::<15>(params, &params_path)?).map_err(bad)?)
            }
            Some("pinhole") => {
                let [fx, fy, cx, cy] = ctx.f32_array::<4>(params, &params_path)?;
                Projection::Pinhole(Pinhole::new(fx, fy, cx, cy).map_err(bad)?)
            }
            _ => return Err(ctx.invalid(&model_path, "\"fisheye624\" or \"pinhole\"", model)),
        };
        let side = |key: &str| -> Result<u32, ImportError> {
            let p = join(path, key);
            let value = ctx.field(v, path, key)?;
            match value.as_u64() {
                Some(s) if (1..=crate::aria::calibration::MAX_IMAGE_SIDE_PX).contains(&s) => Ok(s as u32),
                _ => Err(ctx.invalid(
                    &p,
                    format!("an image side of 1..={} pixels", crate::aria::calibration::MAX_IMAGE_SIDE_PX),
                    value,
                )),
            }
        };
        let (width, height) = (side("width")?, side("height")?);
        let t_device_camera = self.transform(ctx.field(v, path, "t_device_camera")?, &join(path, "t_device_camera"))?;
        let mut camera = CameraCalibration::new(projection, width, height, t_device_camera)
            .map_err(|e| ImportError::invalid(ctx.file, ctx.at(path), "a valid camera", e.to_string()))?;
        if let Some(r) = ctx.optional(v, path, "valid_radius_px")? {
            let radius = ctx.f32(r, &join(path, "valid_radius_px"))?;
            if radius <= 0.0 {
                return Err(ctx.invalid(&join(path, "valid_radius_px"), "a positive radius in pixels", r));
            }
            camera = camera.with_valid_radius(radius);
        }
        Ok(camera)
    }

    fn observer(&mut self, v: &Value, path: &str) -> Result<Observer, ImportError> {
        let ctx = self.ctx;
        self.known_keys(
            v,
            path,
            &["id", "trajectory", "pose", "placement", "camera", "keypoints", "video", "context_features"],
        );
        let id_path = join(path, "id");
        let id = ctx.str(ctx.field(v, path, "id")?, &id_path)?.to_owned();
        if !crate::validate::is_valid_observer_id(&id) {
            return Err(ctx.invalid(
                &id_path,
                "an observer id of 1–64 characters from A–Z, a–z, 0–9, `.`, `_`, `-`",
                ctx.field(v, path, "id")?,
            ));
        }
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
        let context_features = match ctx.optional(v, path, "context_features")? {
            Some(f) => {
                let file = self.data_path(f, &join(path, "context_features"))?;
                Some(self.context_features(&file)?)
            }
            None => None,
        };
        Ok(Observer { id, head, camera, keypoints, video, context_features, placement })
    }

    /// An RGB video reference `{path, start_ns, timestamps?}` of `owner`'s camera.
    fn video(&mut self, video: &Value, vpath: &str, owner: &str) -> Result<VideoRef, ImportError> {
        let ctx = self.ctx;
        let raw = ctx.str(ctx.field(video, vpath, "path")?, &join(vpath, "path"))?;
        let normalized = normalize_path(raw)
            .ok_or_else(|| ctx.error(&join(vpath, "path"), ImportErrorKind::UnsafePath { path: raw.to_owned() }))?;
        if !self.root.contains(&normalized) {
            self.warnings.push(ImportWarning {
                file: self.root.display_path(&normalized),
                message: format!("the video of `{owner}` is not inside the session"),
            });
        }
        let start_ns = ctx.i64(ctx.field(video, vpath, "start_ns")?, &join(vpath, "start_ns"))?;
        let frame_times_ns = match ctx.optional(video, vpath, "timestamps")? {
            Some(t) => {
                let file = self.data_path(t, &join(vpath, "timestamps"))?;
                crate::video::read_frame_timestamps(
                    &self.root.display_path(&file),
                    &self.root.read(&file)?,
                    crate::video::SESSION_TIMESTAMP_COLUMN,
                )?
            }
            None => Vec::new(),
        };
        Ok(VideoRef { path: normalized, start_ns, frame_times_ns })
    }

    /// A participant of a capture (version 3).
    fn participant(&mut self, v: &Value, path: &str) -> Result<Participant, ImportError> {
        let ctx = self.ctx;
        self.known_keys(
            v,
            path,
            &[
                "id",
                "reconstruct",
                "head",
                "left_wrist",
                "right_wrist",
                "wrist_source",
                "head_joint_in_device",
                "camera",
                "video",
                "context_features",
                "subject",
                "ground_truth",
                "pose",
                "placement",
            ],
        );
        let id_path = join(path, "id");
        let id = ctx.str(ctx.field(v, path, "id")?, &id_path)?.to_owned();
        if !crate::validate::is_valid_observer_id(&id) {
            return Err(ctx.invalid(
                &id_path,
                "a participant id of 1–64 characters from A–Z, a–z, 0–9, `.`, `_`, `-`",
                ctx.field(v, path, "id")?,
            ));
        }
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
        let wrist_source = match ctx.optional(v, path, "wrist_source")? {
            Some(w) => serde_json::from_value(w.clone()).map_err(|e| {
                ctx.invalid(
                    &join(path, "wrist_source"),
                    format!("{{\"kind\": \"devices\"}} or {{\"kind\": \"hand_tracking\", …}} ({e})"),
                    w,
                )
            })?,
            None => WristSource::Devices,
        };
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
        let context_features = match ctx.optional(v, path, "context_features")? {
            Some(f) => {
                let file = self.data_path(f, &join(path, "context_features"))?;
                Some(self.context_features(&file)?)
            }
            None => None,
        };
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
        self.known_keys(v, path, &["observer", "target", "keypoints", "people"]);
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

    fn context_features(&self, file: &str) -> Result<ContextFeatureTrack, ImportError> {
        let display = self.root.display_path(file);
        let npz = Npz::open(&display, self.root.read(file)?.into_owned(), self.root.limits())?;
        let ts = npz.array_with_shape("timestamps_ns", &[None])?;
        let n = ts.len();
        let values = npz.array_with_shape("values", &[Some(n), None])?;
        let timestamps_ns = ints(&display, "timestamps_ns", ts)?;
        let dim = values.shape[1];
        let values = floats(&display, "values", values)?;
        Ok(ContextFeatureTrack { timestamps_ns, dim, values })
    }

    fn ground_truth(&mut self, v: &Value, path: &str) -> Result<GroundTruth, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, path, &["motion", "occlusion_observers"]);
        let file = self.data_path(ctx.field(v, path, "motion")?, &join(path, "motion"))?;
        let display = self.root.display_path(&file);
        let npz = Npz::open(&display, self.root.read(&file)?.into_owned(), self.root.limits())?;
        let scalar = |name: &str| npz.array_with_shape(name, &[Some(1)]);
        let fps = floats(&display, "fps", scalar("fps")?)?[0];
        let start_ns = ints(&display, "start_ns", scalar("start_ns")?)?[0];
        let rest = floats(&display, "rest_joints", npz.array_with_shape("rest_joints", &[Some(NUM_JOINTS), Some(3)])?)?;
        let mut joints = [Vec3::ZERO; NUM_JOINTS];
        for (j, p) in joints.iter_mut().enumerate() {
            *p = Vec3::new(rest[3 * j], rest[3 * j + 1], rest[3 * j + 2]);
        }
        let skeleton = SmplSkeleton::from_rest_joints(joints).map_err(|e| {
            ImportError::invalid(&display, Location::Field("rest_joints".into()), "a valid skeleton", e.to_string())
        })?;
        let betas = if npz.contains("betas") {
            Some(floats(&display, "betas", npz.array_with_shape("betas", &[None])?)?)
        } else {
            None
        };
        let root = npz.array_with_shape("root_orientation_xyzw", &[None, Some(4)])?;
        let n = root.shape[0];
        let root = floats(&display, "root_orientation_xyzw", root)?;
        let body = floats(
            &display,
            "body_rotations_xyzw",
            npz.array_with_shape("body_rotations_xyzw", &[Some(n), Some(NUM_BODY_JOINTS), Some(4)])?,
        )?;
        let trans = floats(&display, "translation", npz.array_with_shape("translation", &[Some(n), Some(3)])?)?;
        let quat = |values: &[f32], at: usize, field: &str| -> Result<Quat, ImportError> {
            let q = Quat::from_xyzw(values[at], values[at + 1], values[at + 2], values[at + 3]);
            let norm = f64::from(q.length());
            if !q.is_finite() || (norm - 1.0).abs() > crate::aria::trajectory::QUATERNION_NORM_TOLERANCE {
                return Err(ImportError::new(
                    &display,
                    Location::Field(field.to_owned()),
                    ImportErrorKind::NonUnitQuaternion {
                        norm,
                        tolerance: crate::aria::trajectory::QUATERNION_NORM_TOLERANCE,
                    },
                ));
            }
            Ok(unit(q))
        };
        let mut poses = Vec::with_capacity(n);
        for i in 0..n {
            let mut b = [Quat::IDENTITY; NUM_BODY_JOINTS];
            for (j, q) in b.iter_mut().enumerate() {
                *q = quat(&body, 4 * (i * NUM_BODY_JOINTS + j), &format!("body_rotations_xyzw[{i}, {j}]"))?;
            }
            poses.push(SmplPose {
                root_orientation: quat(&root, 4 * i, &format!("root_orientation_xyzw[{i}]"))?,
                body: b,
                translation: Vec3::new(trans[3 * i], trans[3 * i + 1], trans[3 * i + 2]),
            });
        }
        let motion = SmplMotion::new(fps, start_ns, skeleton, betas, poses)
            .map_err(|e| ImportError::invalid(&display, Location::File, "a valid SMPL motion", e.to_string()))?;
        let mut occlusion = Vec::new();
        if let Some(ids) = ctx.optional(v, path, "occlusion_observers")? {
            let ids_path = join(path, "occlusion_observers");
            let ids = ctx.array(ids, &ids_path)?;
            let masks = ints(&display, "occluded", npz.array_with_shape("occluded", &[Some(ids.len()), Some(n)])?)?;
            for (o, id) in ids.iter().enumerate() {
                let observer_id = ctx.str(id, &format!("{ids_path}[{o}]"))?.to_owned();
                let mut occluded = Vec::with_capacity(n);
                for (i, &m) in masks[o * n..(o + 1) * n].iter().enumerate() {
                    occluded.push(u16::try_from(m).map_err(|_| {
                        ImportError::invalid(
                            &display,
                            Location::Field(format!("occluded[{o}, {i}]")),
                            "a 16-bit mask",
                            m.to_string(),
                        )
                    })?);
                }
                occlusion.push(ObserverOcclusion { observer_id, occluded });
            }
        }
        Ok(GroundTruth { motion, occlusion })
    }
}

/// Renormalises a quaternion that is not unit to f32 precision already (so that what the
/// writer stored reads back bit for bit).
fn unit(q: Quat) -> Quat {
    if (q.length() - 1.0).abs() > 1e-6 { q.normalize() } else { q }
}

fn floats(file: &str, name: &str, array: NpyArray) -> Result<Vec<f32>, ImportError> {
    let values: Vec<f32> = match array.data {
        NpyData::F32(v) => v,
        NpyData::F64(v) => v.into_iter().map(|x| x as f32).collect(),
        NpyData::Int(_) => {
            return Err(ImportError::invalid(file, Location::Field(name.into()), "a float array", "an integer array"));
        }
    };
    if let Some(i) = values.iter().position(|x| !x.is_finite()) {
        return Err(ImportError::invalid(
            file,
            Location::Field(format!("{name}[{i}]")),
            "a finite number",
            values[i].to_string(),
        ));
    }
    Ok(values)
}

fn ints(file: &str, name: &str, array: NpyArray) -> Result<Vec<i64>, ImportError> {
    match array.data {
        NpyData::Int(v) => Ok(v),
        _ => Err(ImportError::invalid(file, Location::Field(name.into()), "an integer array", "a float array")),
    }
}
