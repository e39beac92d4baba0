//! The entries every manifest version reads the same way, from their typed form
//! (`manifest.rs`) into the session model: data paths, trajectories (gravity checked: session
//! worlds are Y-up), subjects, cameras, transforms, placements, videos, context features,
//! ground truth and the floor. Errors name the file and the field.

use egoexo_core::camera::{CameraCalibration, Fisheye624, Pinhole, Projection};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::motion::SmplMotion;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, NUM_JOINTS, SmplPose, SmplSkeleton};

use super::MAX_SESSION_GRAVITY_TILT_DEG;
use super::manifest::{
    CameraEntry, CameraModel, F32, GroundTruthEntry, SubjectEntry, TransformEntry, VideoEntry, from_wire,
};
use crate::aria::trajectory::{Clock, read_closed_loop_trajectory};
use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location, quote};
use crate::json::join;
use crate::model::{ContextFeatureTrack, Floor, GroundTruth, ObserverOcclusion, SubjectInfo, Trajectory, VideoRef};
use crate::npz::{NpyArray, NpyData, Npz};
use crate::placement::{Mount, Placement, WorldRef};
use crate::vfs::{FileTree, normalize_path};

/// The `floor` object's height: finite, within ±10 km.
pub(super) fn check_floor(file: &str, floor: &Floor) -> Result<(), ImportError> {
    if !(floor.height_m.is_finite() && floor.height_m.abs() <= 10_000.0) {
        return Err(ImportError::invalid(
            file,
            Location::Field("floor.height_m".into()),
            "a finite height within ±10000 m",
            floor.height_m.to_string(),
        ));
    }
    Ok(())
}

/// Turns a typed manifest's entries into the session model, checking what their types cannot
/// say (safe paths that exist, ids, unit quaternions, parameter counts, ranges) and reading
/// the data files they name; collects warnings (unknown keys, a video outside the session).
/// Each version's module adds the entries of its own (`session.rs`, `capture.rs`).
pub(super) struct ManifestReader<'a> {
    pub(super) root: &'a FileTree,
    /// The manifest's file, as errors name it.
    pub(super) file: &'a str,
    pub(super) warnings: Vec<ImportWarning>,
}

impl ManifestReader<'_> {
    /// An error at `path` (a field of the manifest): `expected`, `got`.
    pub(super) fn invalid(&self, path: &str, expected: impl Into<String>, got: impl Into<String>) -> ImportError {
        let location = if path.is_empty() { Location::File } else { Location::Field(path.to_owned()) };
        ImportError::invalid(self.file, location, expected, got)
    }

    /// `id` at `path` (an observer's or a participant's, `what`): 1–64 characters from A–Z,
    /// a–z, 0–9, `.`, `_`, `-`.
    pub(super) fn id(&self, id: &str, path: &str, what: &str) -> Result<String, ImportError> {
        if !crate::validate::is_valid_observer_id(id) {
            return Err(self.invalid(
                path,
                format!("{what} id of 1–64 characters from A–Z, a–z, 0–9, `.`, `_`, `-`"),
                format!("the string {}", quote(id, 40)),
            ));
        }
        Ok(id.to_owned())
    }

    /// A data file named by the manifest at `path`: a safe relative path that exists.
    pub(super) fn data_path(&self, raw: &str, path: &str) -> Result<String, ImportError> {
        let normalized = normalize_path(raw).ok_or_else(|| {
            ImportError::new(
                self.file,
                Location::Field(path.to_owned()),
                ImportErrorKind::UnsafePath { path: raw.to_owned() },
            )
        })?;
        if !self.root.contains(&normalized) {
            return Err(ImportError::missing_file(
                self.root.display_path(&normalized),
                format!("the file named by {} field `{path}`", self.file),
            ));
        }
        Ok(normalized)
    }

    /// The trajectory file at `raw` (manifest field `path`), its gravity checked: session
    /// worlds are Y-up.
    pub(super) fn trajectory(&self, raw: &str, path: &str) -> Result<Trajectory, ImportError> {
        let file = self.data_path(raw, path)?;
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

    /// An optional trajectory file (a wrist).
    pub(super) fn optional_trajectory(
        &self,
        raw: Option<&String>,
        path: &str,
    ) -> Result<Option<Trajectory>, ImportError> {
        raw.map(|raw| self.trajectory(raw, path)).transpose()
    }

    pub(super) fn subject(&self, subject: &SubjectEntry, path: &str) -> Result<SubjectInfo, ImportError> {
        let field = |key: &str| join(path, key);
        let betas = match &subject.betas {
            Some(b) if b.is_empty() || b.len() > 300 => {
                return Err(self.invalid(
                    &field("betas"),
                    "1 to 300 SMPL shape coefficients",
                    format!("an array of {} items", b.len()),
                ));
            }
            Some(b) => Some(b.iter().map(|x| x.0).collect()),
            None => None,
        };
        let rest_joints = match &subject.rest_joints {
            Some(j) if j.len() != NUM_JOINTS => {
                return Err(self.invalid(
                    &field("rest_joints"),
                    format!("{NUM_JOINTS} joints [x, y, z]"),
                    format!("an array of {} items", j.len()),
                ));
            }
            Some(j) => {
                let mut joints = [Vec3::ZERO; NUM_JOINTS];
                for (slot, p) in joints.iter_mut().zip(j) {
                    *slot = Vec3::from_array(from_wire(p));
                }
                Some(joints)
            }
            None => None,
        };
        Ok(SubjectInfo { height_m: subject.height_m.map(|h| h.0), betas, rest_joints })
    }

    /// A device's poses and placement: a worn device's trajectory (`trajectory`, under
    /// `trajectory_key`), or `pose` (a static camera), or neither with `placement.mount: fixed`
    /// and `world: own` (a static camera to register). A static camera's trajectory holds its
    /// pose once here; [`spread_fixed_poses`] spans it over the recording once everything is
    /// read.
    ///
    /// [`spread_fixed_poses`]: crate::capture::spread_fixed_poses
    pub(super) fn poses_and_placement(
        &self,
        path: &str,
        (trajectory_key, trajectory): (&str, Option<&String>),
        pose: Option<&TransformEntry>,
        placement: Option<&Placement>,
    ) -> Result<(Trajectory, Placement), ImportError> {
        let placement_path = join(path, "placement");
        let fixed = placement.is_some_and(|p| p.mount == Mount::Fixed);
        match (trajectory, pose) {
            (Some(_), Some(_)) => Err(self.invalid(
                &join(path, "pose"),
                format!("either `{trajectory_key}` (a worn device) or `pose` (a static camera), not both"),
                "both",
            )),
            (Some(t), None) => {
                if fixed {
                    return Err(self.invalid(
                        &join(&placement_path, "mount"),
                        format!("`worn` for a device with a `{trajectory_key}` (a static camera has `pose`)"),
                        "the string `fixed`",
                    ));
                }
                let trajectory = self.trajectory(t, &join(path, trajectory_key))?;
                Ok((trajectory, placement.cloned().unwrap_or_default()))
            }
            (None, Some(p)) => {
                let pose = self.transform(p, &join(path, "pose"))?;
                let placement = Placement { mount: Mount::Fixed, ..placement.cloned().unwrap_or_default() };
                Ok((Trajectory { timestamps_ns: vec![0], poses: vec![pose] }, placement))
            }
            (None, None) => match placement {
                Some(placement) if fixed && placement.world == WorldRef::Own => Ok((
                    Trajectory { timestamps_ns: vec![0], poses: vec![RigidTransform::IDENTITY] },
                    placement.clone(),
                )),
                _ => Err(self.invalid(
                    &join(path, trajectory_key),
                    format!(
                        "`{trajectory_key}` (a worn device), `pose` (a static camera), or `placement` with \
                         `mount: fixed` and `world: own` (a static camera to register)"
                    ),
                    "none of them",
                )),
            },
        }
    }

    /// `T_a_b` at `path`, its rotation a unit quaternion.
    fn transform(&self, t: &TransformEntry, path: &str) -> Result<RigidTransform, ImportError> {
        let q = Quat::from_array(from_wire(&t.rotation_xyzw));
        let norm = f64::from(q.length());
        if (norm - 1.0).abs() > crate::aria::trajectory::QUATERNION_NORM_TOLERANCE {
            return Err(ImportError::new(
                self.file,
                Location::Field(join(path, "rotation_xyzw")),
                ImportErrorKind::NonUnitQuaternion {
                    norm,
                    tolerance: crate::aria::trajectory::QUATERNION_NORM_TOLERANCE,
                },
            ));
        }
        Ok(RigidTransform { rotation: unit(q), translation: Vec3::from_array(from_wire(&t.translation)) })
    }

    pub(super) fn camera(&self, c: &CameraEntry, path: &str) -> Result<CameraCalibration, ImportError> {
        let params_path = join(path, "params");
        let bad =
            |e: egoexo_core::camera::CameraError| self.invalid(&params_path, "valid camera parameters", e.to_string());
        let params: Vec<f32> = c.params.iter().map(|x| x.0).collect();
        let count = |n: usize| {
            self.invalid(
                &params_path,
                format!("an array of {n} numbers"),
                format!("an array of {} items", params.len()),
            )
        };
        let projection = match c.model {
            CameraModel::Fisheye624 => {
                let params: [f32; 15] = params.as_slice().try_into().map_err(|_| count(15))?;
                Projection::Fisheye624(Fisheye624::new(params).map_err(bad)?)
            }
            CameraModel::Pinhole => {
                let [fx, fy, cx, cy]: [f32; 4] = params.as_slice().try_into().map_err(|_| count(4))?;
                Projection::Pinhole(Pinhole::new(fx, fy, cx, cy).map_err(bad)?)
            }
        };
        let max = crate::aria::calibration::MAX_IMAGE_SIDE_PX;
        for (key, side) in [("width", c.width), ("height", c.height)] {
            if !(1..=max).contains(&u64::from(side)) {
                return Err(self.invalid(
                    &join(path, key),
                    format!("an image side of 1..={max} pixels"),
                    format!("the number {side}"),
                ));
            }
        }
        let t_device_camera = self.transform(&c.t_device_camera, &join(path, "t_device_camera"))?;
        let mut camera = CameraCalibration::new(projection, c.width, c.height, t_device_camera)
            .map_err(|e| self.invalid(path, "a valid camera", e.to_string()))?;
        if let Some(F32(radius)) = c.valid_radius_px {
            if radius <= 0.0 {
                return Err(self.invalid(
                    &join(path, "valid_radius_px"),
                    "a positive radius in pixels",
                    format!("the number {radius}"),
                ));
            }
            camera = camera.with_valid_radius(radius);
        }
        Ok(camera)
    }

    /// An RGB video of `owner`'s camera at manifest field `path`; a video outside the session
    /// is a warning (it may be given beside it).
    pub(super) fn video(&mut self, video: &VideoEntry, path: &str, owner: &str) -> Result<VideoRef, ImportError> {
        let path_field = join(path, "path");
        let normalized = normalize_path(&video.path).ok_or_else(|| {
            ImportError::new(
                self.file,
                Location::Field(path_field),
                ImportErrorKind::UnsafePath { path: video.path.clone() },
            )
        })?;
        if !self.root.contains(&normalized) {
            self.warnings.push(ImportWarning {
                file: self.root.display_path(&normalized),
                message: format!("the video of `{owner}` is not inside the session"),
            });
        }
        let frame_times_ns = match &video.timestamps {
            Some(t) => {
                let file = self.data_path(t, &join(path, "timestamps"))?;
                crate::video::read_frame_timestamps(
                    &self.root.display_path(&file),
                    &self.root.read(&file)?,
                    crate::video::SESSION_TIMESTAMP_COLUMN,
                )?
            }
            None => Vec::new(),
        };
        Ok(VideoRef { path: normalized, start_ns: video.start_ns, frame_times_ns })
    }

    /// The context features file at manifest field `path` (`timestamps_ns` (N,), `values`
    /// (N, D)).
    pub(super) fn context_features_at(
        &self,
        raw: Option<&String>,
        path: &str,
    ) -> Result<Option<ContextFeatureTrack>, ImportError> {
        match raw {
            Some(raw) => {
                let file = self.data_path(raw, path)?;
                Ok(Some(self.context_features(&file)?))
            }
            None => Ok(None),
        }
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

    /// Ground truth: the motion's npz (the arrays of the module docs of `format`) and its
    /// occlusion masks, one row per observer named.
    pub(super) fn ground_truth(&self, gt: &GroundTruthEntry, path: &str) -> Result<GroundTruth, ImportError> {
        let file = self.data_path(&gt.motion, &join(path, "motion"))?;
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
        if let Some(ids) = &gt.occlusion_observers {
            let masks = ints(&display, "occluded", npz.array_with_shape("occluded", &[Some(ids.len()), Some(n)])?)?;
            for (o, id) in ids.iter().enumerate() {
                let observer_id = id.clone();
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
