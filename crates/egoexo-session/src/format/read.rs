//! The blocks every manifest version reads the same way: data paths, trajectories (gravity
//! checked: session worlds are Y-up), subjects, cameras, transforms, placements, videos,
//! context features, ground truth and the floor. Errors name the file and the field.

use egoexo_core::camera::{CameraCalibration, Fisheye624, Pinhole, Projection};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::motion::SmplMotion;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, NUM_JOINTS, SmplPose, SmplSkeleton};
use serde_json::Value;

use super::{MAX_SESSION_GRAVITY_TILT_DEG, keys};
use crate::aria::trajectory::{Clock, read_closed_loop_trajectory};
use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::json::{JsonCtx, join};
use crate::model::{
    ContextFeatureTrack, Floor, GroundTruth, ObserverOcclusion, SubjectInfo, Trajectory, VideoRef, WristSource,
};
use crate::npz::{NpyArray, NpyData, Npz};
use crate::placement::{Mount, Placement, WorldRef};
use crate::vfs::{FileTree, normalize_path};

/// The `floor` object.
pub(super) fn read_floor(ctx: &JsonCtx<'_>, v: &Value) -> Result<Floor, ImportError> {
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

/// Reads a manifest's objects, collecting warnings (unknown keys, a video outside the
/// session); each version's module adds the objects of its own (`session.rs`, `capture.rs`).
pub(super) struct ManifestReader<'a> {
    pub(super) root: &'a FileTree,
    pub(super) ctx: JsonCtx<'a>,
    pub(super) warnings: Vec<ImportWarning>,
}

impl ManifestReader<'_> {
    pub(super) fn known_keys(&mut self, v: &Value, path: &str, known: &[&str]) {
        if let Value::Object(map) = v {
            for key in map.keys().filter(|k| !known.contains(&k.as_str())) {
                self.warnings.push(ImportWarning {
                    file: self.ctx.file.to_owned(),
                    message: format!("unknown field `{}` ignored", join(path, key)),
                });
            }
        }
    }

    /// The `id` of the object at `path` (an observer's or a participant's, `what`): 1–64
    /// characters from A–Z, a–z, 0–9, `.`, `_`, `-`.
    pub(super) fn id(&self, v: &Value, path: &str, what: &str) -> Result<String, ImportError> {
        let ctx = self.ctx;
        let id_path = join(path, "id");
        let value = ctx.field(v, path, "id")?;
        let id = ctx.str(value, &id_path)?;
        if !crate::validate::is_valid_observer_id(id) {
            return Err(ctx.invalid(
                &id_path,
                format!("{what} id of 1–64 characters from A–Z, a–z, 0–9, `.`, `_`, `-`"),
                value,
            ));
        }
        Ok(id.to_owned())
    }

    /// A data file named by the manifest: a safe relative path that exists.
    pub(super) fn data_path(&self, v: &Value, path: &str) -> Result<String, ImportError> {
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

    pub(super) fn trajectory(&self, v: &Value, path: &str) -> Result<Trajectory, ImportError> {
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

    pub(super) fn subject_at(&mut self, v: &Value, path: &str) -> Result<SubjectInfo, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, path, keys::SUBJECT);
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

    /// A device's poses and placement: `trajectory_key` (a worn device's trajectory file), or
    /// `pose` (a static camera), or neither with `placement.mount: fixed` and `world: own` (a
    /// static camera to register). A static camera's trajectory holds its pose once here;
    /// [`spread_fixed_poses`] spans it over the recording once everything is read.
    pub(super) fn poses_and_placement(
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

    pub(super) fn camera(&mut self, v: &Value, path: &str) -> Result<CameraCalibration, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, path, keys::CAMERA);
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

    /// An RGB video reference `{path, start_ns, timestamps?}` of `owner`'s camera.
    pub(super) fn video(&mut self, video: &Value, vpath: &str, owner: &str) -> Result<VideoRef, ImportError> {
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

    /// `wrist_source` at `path` (`devices` where absent).
    pub(super) fn wrist_source(&self, v: &Value, parent: &str) -> Result<WristSource, ImportError> {
        let ctx = self.ctx;
        Ok(match ctx.optional(v, parent, "wrist_source")? {
            Some(w) => serde_json::from_value(w.clone()).map_err(|e| {
                ctx.invalid(
                    &join(parent, "wrist_source"),
                    format!("{{\"kind\": \"devices\"}} or {{\"kind\": \"hand_tracking\", \"file\", \"form\", \"orientation\"}} ({e})"),
                    w,
                )
            })?,
            None => WristSource::Devices,
        })
    }

    /// The context features a manifest names at `path` (`timestamps_ns` (N,), `values` (N, D)).
    pub(super) fn context_features_at(
        &self,
        v: &Value,
        parent: &str,
    ) -> Result<Option<ContextFeatureTrack>, ImportError> {
        match self.ctx.optional(v, parent, "context_features")? {
            Some(f) => {
                let file = self.data_path(f, &join(parent, "context_features"))?;
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

    pub(super) fn ground_truth(&mut self, v: &Value, path: &str) -> Result<GroundTruth, ImportError> {
        let ctx = self.ctx;
        self.known_keys(v, path, keys::GROUND_TRUTH);
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
