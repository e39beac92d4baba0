//! Aria MPS `online_calibration.jsonl`: one JSON record per line, each with
//! `tracking_timestamp_us`, `utc_timestamp_ns`, `CameraCalibrations` (and
//! `ImuCalibrations`, ignored). Only the `camera-rgb` calibration is read: its `Label`,
//! `Projection {Name, Params}` (`FisheyeRadTanThinPrism` with 15 parameters
//! `[f, cu, cv, k0..k5, p0, p1, s0..s3]`, or `Linear` with `[fx, fy, cu, cv]`) and
//! `T_Device_Camera {Translation: [x, y, z], UnitQuaternion: [w, [x, y, z]]}`.
//!
//! Records written before June 2023 store `tracking_timestamp_us` and the calibration lists
//! as quoted strings (with Python's `True`/`False` and single quotes); both forms are read.
//! Image sizes come from the record's `ImageSizes` (one `[width, height]` per camera, MPS ≥
//! 1.1) or else the sensor's full resolution (RGB 2880 × 2880), and the RGB
//! valid radius is projectaria_tools' 1415 px at full resolution, scaled with the width.
//!
//! Two optional top-level fields are honoured when present: `DeviceClassInfo.BuildVersion`
//! (`DVT-S`/`DVT-L`, selects the nominal `T_device_cpf`) and `T_Device_CPF` (same form as
//! `T_Device_Camera`; a calibrated CPF overrides the nominal one).

use egoexo_core::camera::{CameraCalibration, Fisheye624, Pinhole, Projection};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use serde_json::Value;

use super::AriaFrameSize;
use super::trajectory::QUATERNION_NORM_TOLERANCE;
use crate::error::{ImportError, ImportErrorKind, Location};
use crate::json::{JsonCtx, join};

/// The RGB camera's label.
pub const RGB_LABEL: &str = "camera-rgb";
/// projectaria_tools' valid radius of the full-resolution (2880 px) RGB image, pixels.
pub const RGB_VALID_RADIUS_FULL_RES_PX: f32 = 1415.0;
/// Full-resolution RGB width, pixels.
pub const RGB_FULL_RES_PX: u32 = 2880;
/// Largest accepted image side, pixels.
pub const MAX_IMAGE_SIDE_PX: u64 = 16_384;

/// The RGB camera of a calibration record, in the Aria device frame.
#[derive(Clone, Debug, PartialEq)]
pub struct AriaCamera {
    pub label: String,
    /// Whether the image size came from the record's `ImageSizes` (MPS ≥ 1.1) rather than the
    /// sensor's full resolution.
    pub size_from_image_sizes: bool,
    /// Intrinsics, image size and `T_device_camera` (Aria device frame).
    pub calibration: CameraCalibration,
}

/// One line of `online_calibration.jsonl`.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationRecord {
    /// Device clock, nanoseconds.
    pub tracking_timestamp_ns: i64,
    pub cameras: Vec<AriaCamera>,
    /// From `DeviceClassInfo.BuildVersion`, when present.
    pub frame_size: Option<AriaFrameSize>,
    /// From `T_Device_CPF`, when present.
    pub t_device_cpf: Option<RigidTransform>,
}

impl CalibrationRecord {
    /// The camera with `label`, if calibrated in this record.
    pub fn camera(&self, label: &str) -> Option<&AriaCamera> {
        self.cameras.iter().find(|c| c.label == label)
    }

    /// `T_device_cpf`: the record's own, else the nominal CAD value for its frame size.
    pub fn t_device_cpf(&self) -> RigidTransform {
        self.t_device_cpf.unwrap_or_else(|| super::nominal_t_device_cpf(self.frame_size.unwrap_or_default()))
    }
}

/// Reads every record of an `online_calibration.jsonl`. Blank lines are skipped.
pub fn read_online_calibration(file: &str, text: &str) -> Result<Vec<CalibrationRecord>, ImportError> {
    let mut records = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i as u64 + 1;
        if line.trim().is_empty() {
            continue;
        }
        let ctx = JsonCtx::line(file, line_no);
        let doc = ctx.parse(line)?;
        let record = read_record(&ctx, &doc)?;
        if let Some(prev) = records.last().map(|r: &CalibrationRecord| r.tracking_timestamp_ns)
            && record.tracking_timestamp_ns <= prev
        {
            let kind = if record.tracking_timestamp_ns == prev {
                ImportErrorKind::DuplicateTimestamp(prev)
            } else {
                ImportErrorKind::NonMonotonicTimestamp { previous: prev, got: record.tracking_timestamp_ns }
            };
            return Err(ctx.error("tracking_timestamp_us", kind));
        }
        records.push(record);
    }
    if records.is_empty() {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: "at least one calibration record (one JSON object per line)".into() },
        ));
    }
    Ok(records)
}

/// The record in the middle of the recording (a real calibration, not an average) and its
/// camera `label`. Errors when no record calibrates that camera.
pub fn middle_record_with<'a>(
    file: &str,
    records: &'a [CalibrationRecord],
    label: &str,
) -> Result<(&'a CalibrationRecord, &'a AriaCamera), ImportError> {
    let with: Vec<&CalibrationRecord> = records.iter().filter(|r| r.camera(label).is_some()).collect();
    let record = with.get(with.len() / 2).copied().ok_or_else(|| {
        ImportError::invalid(
            file,
            Location::Field("CameraCalibrations".into()),
            format!("a `{label}` calibration"),
            "none in any record",
        )
    })?;
    let camera = record.camera(label).ok_or_else(|| {
        ImportError::invalid(
            file,
            Location::Field("CameraCalibrations".into()),
            format!("a `{label}` calibration"),
            "none",
        )
    })?;
    Ok((record, camera))
}

fn read_record(ctx: &JsonCtx<'_>, doc: &Value) -> Result<CalibrationRecord, ImportError> {
    let ts = ctx.field(doc, "", "tracking_timestamp_us")?;
    // Before June 2023 the record's content was quoted.
    let legacy = ts.is_string();
    let us = if legacy {
        let s = ctx.str(ts, "tracking_timestamp_us")?;
        s.trim().parse::<i64>().map_err(|_| ctx.invalid("tracking_timestamp_us", "an integer timestamp (µs)", ts))?
    } else {
        ctx.i64(ts, "tracking_timestamp_us")?
    };
    let tracking_timestamp_ns = super::ns_from_us(us)
        .ok_or_else(|| ctx.invalid("tracking_timestamp_us", "a timestamp that fits in i64 nanoseconds", ts))?;

    let cams_value = ctx.field(doc, "", "CameraCalibrations")?;
    let unquoted;
    let cams_value = if let Value::String(s) = cams_value {
        let fixed = s.replace("True", "true").replace("False", "false").replace('\'', "\"");
        unquoted = serde_json::from_str::<Value>(&fixed).map_err(|e| {
            ctx.error("CameraCalibrations", ImportErrorKind::Json(format!("in the quoted calibration list: {e}")))
        })?;
        &unquoted
    } else {
        cams_value
    };
    let cams = ctx.array(cams_value, "CameraCalibrations")?;
    let sizes = match ctx.optional(doc, "", "ImageSizes")? {
        Some(v) => Some(ctx.array(v, "ImageSizes")?),
        None => None,
    };
    let mut cameras = Vec::with_capacity(cams.len().min(16));
    for (i, cam) in cams.iter().enumerate() {
        let path = format!("CameraCalibrations[{i}]");
        let size = match sizes {
            Some(sizes) => {
                let size_path = format!("ImageSizes[{i}]");
                let v = sizes.get(i).ok_or_else(|| {
                    ImportError::invalid(ctx.file, ctx.at(&size_path), "one image size per camera", "too few")
                })?;
                let wh = ctx.array(v, &size_path)?;
                if wh.len() != 2 {
                    return Err(ctx.invalid(&size_path, "[width, height]", v));
                }
                Some((image_side(ctx, &wh[0], &size_path)?, image_side(ctx, &wh[1], &size_path)?))
            }
            None => None,
        };
        if let Some(camera) = read_camera(ctx, cam, &path, size)? {
            cameras.push(camera);
        }
    }
    let frame_size = match ctx.optional(doc, "", "DeviceClassInfo")? {
        Some(info) => match ctx.optional(info, "DeviceClassInfo", "BuildVersion")? {
            Some(b) => AriaFrameSize::from_build_version(ctx.str(b, "DeviceClassInfo.BuildVersion")?),
            None => None,
        },
        None => None,
    };
    let t_device_cpf = match ctx.optional(doc, "", "T_Device_CPF")? {
        Some(v) => Some(read_se3(ctx, v, "T_Device_CPF")?),
        None => None,
    };
    Ok(CalibrationRecord { tracking_timestamp_ns, cameras, frame_size, t_device_cpf })
}

fn image_side(ctx: &JsonCtx<'_>, v: &Value, path: &str) -> Result<u32, ImportError> {
    match v.as_u64() {
        Some(n) if (1..=MAX_IMAGE_SIDE_PX).contains(&n) => Ok(n as u32),
        _ => Err(ctx.invalid(path, format!("an image side of 1..={MAX_IMAGE_SIDE_PX} pixels"), v)),
    }
}

/// The RGB camera; `None` for the other cameras, which sessions do not use.
fn read_camera(
    ctx: &JsonCtx<'_>,
    cam: &Value,
    path: &str,
    size: Option<(u32, u32)>,
) -> Result<Option<AriaCamera>, ImportError> {
    let label = ctx.str(ctx.field(cam, path, "Label")?, &join(path, "Label"))?.to_owned();
    if label != RGB_LABEL {
        // Only the RGB camera is used; other cameras (SLAM, eye tracking) are not validated.
        return Ok(None);
    }
    let (width, height) = size.unwrap_or((RGB_FULL_RES_PX, RGB_FULL_RES_PX));
    let projection_path = join(path, "Projection");
    let projection = ctx.field(cam, path, "Projection")?;
    let name_path = join(&projection_path, "Name");
    let name = ctx.str(ctx.field(projection, &projection_path, "Name")?, &name_path)?;
    let params_path = join(&projection_path, "Params");
    let params_value = ctx.field(projection, &projection_path, "Params")?;
    let projection = match name {
        "FisheyeRadTanThinPrism" => {
            let params = ctx.f32_array::<15>(params_value, &params_path)?;
            Projection::Fisheye624(Fisheye624::new(params).map_err(|e| {
                ImportError::invalid(ctx.file, ctx.at(&params_path), "valid Fisheye624 parameters", e.to_string())
            })?)
        }
        "Linear" => {
            let [fx, fy, cx, cy] = ctx.f32_array::<4>(params_value, &params_path)?;
            Projection::Pinhole(Pinhole::new(fx, fy, cx, cy).map_err(|e| {
                ImportError::invalid(ctx.file, ctx.at(&params_path), "valid pinhole parameters", e.to_string())
            })?)
        }
        _ => {
            return Err(ctx.invalid(
                &name_path,
                "the projection model `FisheyeRadTanThinPrism` (or `Linear`)",
                ctx.field(ctx.field(cam, path, "Projection")?, &projection_path, "Name")?,
            ));
        }
    };
    let t_device_camera = read_se3(ctx, ctx.field(cam, path, "T_Device_Camera")?, &join(path, "T_Device_Camera"))?;
    let calibration = CameraCalibration::new(projection, width, height, t_device_camera)
        .map_err(|e| ImportError::invalid(ctx.file, ctx.at(path), "a valid camera", e.to_string()))?
        .with_valid_radius(RGB_VALID_RADIUS_FULL_RES_PX * width as f32 / RGB_FULL_RES_PX as f32);
    Ok(Some(AriaCamera { label, size_from_image_sizes: size.is_some(), calibration }))
}

/// `{Translation: [x, y, z], UnitQuaternion: [w, [x, y, z]]}`.
pub(crate) fn read_se3(ctx: &JsonCtx<'_>, v: &Value, path: &str) -> Result<RigidTransform, ImportError> {
    let t_path = join(path, "Translation");
    let t = ctx.f32_array::<3>(ctx.field(v, path, "Translation")?, &t_path)?;
    let q_path = join(path, "UnitQuaternion");
    let q_value = ctx.field(v, path, "UnitQuaternion")?;
    let q = ctx.array(q_value, &q_path)?;
    if q.len() != 2 {
        return Err(ctx.invalid(&q_path, "[w, [x, y, z]]", q_value));
    }
    let w = ctx.f64(&q[0], &format!("{q_path}[0]"))?;
    let xyz_path = format!("{q_path}[1]");
    let xyz = ctx.array(&q[1], &xyz_path)?;
    if xyz.len() != 3 {
        return Err(ctx.invalid(&xyz_path, "[x, y, z]", &q[1]));
    }
    let mut v3 = [0f64; 3];
    for (i, (slot, item)) in v3.iter_mut().zip(xyz).enumerate() {
        *slot = ctx.f64(item, &format!("{xyz_path}[{i}]"))?;
    }
    let norm = (w * w + v3.iter().map(|x| x * x).sum::<f64>()).sqrt();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(
            ctx.error(&q_path, ImportErrorKind::NonUnitQuaternion { norm, tolerance: QUATERNION_NORM_TOLERANCE })
        );
    }
    let rotation =
        Quat::from_xyzw((v3[0] / norm) as f32, (v3[1] / norm) as f32, (v3[2] / norm) as f32, (w / norm) as f32);
    Ok(RigidTransform { rotation, translation: Vec3::from_array(t) })
}

/// Writes `T` as Aria's `{Translation, UnitQuaternion: [w, [x, y, z]]}`.
pub fn se3_json(t: &RigidTransform) -> Value {
    let q = t.rotation;
    serde_json::json!({
        "Translation": [t.translation.x, t.translation.y, t.translation.z],
        "UnitQuaternion": [q.w, [q.x, q.y, q.z]],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record_json(legacy: bool) -> String {
        let cams = serde_json::json!([
            {"Label": "camera-slam-left", "SerialNumber": "0", "Projection": {"Name": "FisheyeRadTanThinPrism", "Params": [241.0, 316.0, 237.0, -0.02, 0.1, -0.07, 0.008, 0.001, -0.0005, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]},
             "T_Device_Camera": {"Translation": [0.0, 0.0, 0.0], "UnitQuaternion": [1.0, [0.0, 0.0, 0.0]]}},
            {"Label": "camera-rgb", "SerialNumber": "1", "Projection": {"Name": "FisheyeRadTanThinPrism", "Params": [610.0, 715.0, 705.0, 0.39, -0.35, -0.2, 1.7, -2.1, 0.7, 0.0004, -0.0002, -0.0003, 0.0001, 0.0002, -0.0001]},
             "T_Device_Camera": {"Translation": [-0.004, -0.012, -0.005], "UnitQuaternion": [0.9432, [0.33, 0.02, 0.03]]}},
            {"Label": "camera-et-left", "SerialNumber": "2", "Projection": {"Name": "KannalaBrandtK3", "Params": [1.0]},
             "T_Device_Camera": {"Translation": [0.0, 0.0, 0.0], "UnitQuaternion": [1.0, [0.0, 0.0, 0.0]]}}
        ]);
        if legacy {
            let quoted = cams.to_string().replace('"', "'");
            serde_json::json!({"tracking_timestamp_us": "1000", "utc_timestamp_ns": "5", "CameraCalibrations": quoted, "ImuCalibrations": "[]"}).to_string()
        } else {
            serde_json::json!({"tracking_timestamp_us": 1000, "utc_timestamp_ns": 5, "CameraCalibrations": cams, "ImuCalibrations": [], "ImageSizes": [[640, 480], [1408, 1408], [640, 480]]}).to_string()
        }
    }

    #[test]
    fn reads_current_and_legacy_records() {
        let current = read_online_calibration("c.jsonl", &record_json(false)).unwrap();
        let legacy = read_online_calibration("c.jsonl", &record_json(true)).unwrap();
        for (records, width) in [(&current, 1408), (&legacy, 2880)] {
            let (record, rgb) = middle_record_with("c.jsonl", records, RGB_LABEL).unwrap();
            assert_eq!(record.tracking_timestamp_ns, 1_000_000);
            assert_eq!(rgb.calibration.width, width);
            assert!(matches!(rgb.calibration.projection, Projection::Fisheye624(_)));
            let r = rgb.calibration.valid_radius_px.unwrap();
            assert!((r - 1415.0 * width as f32 / 2880.0).abs() < 1e-3);
            assert!((rgb.calibration.t_device_camera.rotation.length() - 1.0).abs() < 1e-6);
        }
        // Only the RGB camera is kept (the eye-tracking camera's unknown model is no error).
        assert_eq!(legacy[0].cameras.len(), 1);
    }
}
