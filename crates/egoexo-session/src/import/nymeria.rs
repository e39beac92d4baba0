//! Nymeria sequence importer.
//!
//! ```text
//! <sequence>/
//!   recording_head/      the wearer's glasses     → wearer.head (CPF)
//!   recording_lwrist/    left miniAria wristband  → wearer.left_wrist (device frame)
//!   recording_rwrist/    right miniAria wristband → wearer.right_wrist (device frame)
//!   recording_observer/  the observer's glasses   → observer "observer"
//!     keypoints.jsonl | keypoints.json            (optional; not part of Nymeria)
//!   body/xdata_smpl_neutral.npz                   → ground truth (optional)
//! ```
//! Each `recording_*` is a device folder (MPS output in `mps/slam/`, see
//! [`super::aria_mps`]). The SMPL file holds `betas` (N, 10), `body_pose` (N, 69) and
//! `global_orient` (N, 3) as axis-angle, `transl` (N, 3) in metres, and `timestamps` (N,) in
//! microseconds, all in the Aria (Z-up) world. It is converted to the Y-up world (pelvis =
//! `J0 + transl`, see [`crate::aria::session_smpl_pose_from_aria`]) and resampled onto a fixed
//! rate (the median sample interval; rotations slerped, translations lerped). SMPL's two hand
//! joints (22, 23) are dropped — the session skeleton's hands carry no rotation.
//!
//! No SMPL model is shipped (its licence forbids it), so `J0` and the skeleton are the
//! neutral mean shape's; the betas are kept in the subject info and the motion. Nymeria's body
//! timestamps are on the TimeCode clock: with `time_sync.csv` files in the recordings (device →
//! TimeCode) everything shares that clock; without them the device clocks are assumed to
//! equal it, and a warning says so.

use egoexo_core::glam::Vec3;
use egoexo_core::motion::SmplMotion;
use egoexo_core::rotation::quat_from_axis_angle;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, SmplPose, SmplSkeleton};

use super::ImportOptions;
use super::aria_mps::DeviceLoader;
use crate::aria::session_smpl_pose_from_aria;
use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::model::{GroundTruth, Session, SubjectInfo};
use crate::npz::{NpyArray, Npz};
use crate::vfs::FileTree;

/// The SMPL ground-truth file of a sequence.
pub const SMPL_FILE: &str = "body/xdata_smpl_neutral.npz";
/// The observer id given to `recording_observer`.
pub const OBSERVER_ID: &str = "observer";
/// Longest gap between body samples that resampling bridges, nanoseconds (0.5 s).
pub const MAX_BODY_GAP_NS: i64 = 500_000_000;
/// Largest accepted body sample rate, Hz.
pub const MAX_BODY_RATE_HZ: f64 = 1000.0;

/// Imports a Nymeria sequence (see the module docs).
pub fn import_nymeria(
    root: &FileTree,
    name: &str,
    options: &ImportOptions,
) -> Result<(Session, Vec<ImportWarning>), ImportError> {
    let mut warnings = Vec::new();
    let mut devices = DeviceLoader::new(options, &mut warnings);
    let loaded = devices.wearer(root, "recording_head", ["recording_lwrist", "recording_rwrist"])?;
    let mut observers = Vec::new();
    let observer_missing = !root.contains_dir("recording_observer");
    if !observer_missing {
        observers.push(devices.observer(root, "recording_observer", OBSERVER_ID, options)?);
    }
    let synced = devices.finish()?;
    if observer_missing {
        warnings.push(ImportWarning {
            file: root.display_path("recording_observer/"),
            message: "missing: a session without observers".into(),
        });
    }

    let mut subject = SubjectInfo::default();
    let ground_truth = if root.contains(SMPL_FILE) {
        let file = root.display_path(SMPL_FILE);
        let npz = Npz::open(&file, root.read(SMPL_FILE)?.into_owned(), root.limits())?;
        let (motion, mut more) = read_nymeria_smpl(&file, &npz)?;
        warnings.append(&mut more);
        if !synced {
            warnings.push(ImportWarning {
                file: file.clone(),
                message: "body timestamps are on Nymeria's TimeCode clock; without time_sync.csv files the device clocks are assumed to equal it".into(),
            });
        }
        subject.betas = motion.betas.clone();
        Some(GroundTruth { motion, occlusion: Vec::new() })
    } else {
        warnings.push(ImportWarning { file: root.display_path(SMPL_FILE), message: "missing: no ground truth".into() });
        None
    };
    let (wearer, floor) = loaded.into_wearer();
    if wearer.left_wrist.is_some() != wearer.right_wrist.is_some() {
        warnings.push(ImportWarning {
            file: root.display_path(""),
            message: "only one wrist recording; 3-point tracking needs both".into(),
        });
    }
    let session = Session {
        name: name.to_owned(),
        floor: floor.or_else(|| ground_truth.as_ref().and_then(|gt| crate::floor::floor_from_ground_truth(&gt.motion))),
        wearer,
        observers,
        subject,
        ground_truth,
    };
    Ok((session, warnings))
}

/// Fewest frames, as a fraction, on which the converted body's head must be above its pelvis.
pub const MIN_UPRIGHT_FRACTION: f32 = 0.5;

/// Upstream loaders disagree on whether Nymeria's SMPL fits are Z-up or Y-up; this importer
/// reads them as Z-up (the Aria world). Converted the wrong way, the body lies on its back or
/// stands on its head: refuse unless the head is above the pelvis (session +Y) on at least
/// [`MIN_UPRIGHT_FRACTION`] of the frames (people lie down, but not for most of a recording).
pub fn check_head_above_pelvis(file: &str, motion: &SmplMotion) -> Result<(), ImportError> {
    let head = egoexo_core::skeleton::SmplJoint::Head.index();
    let stride = (motion.len() / 2000).max(1);
    let (mut upright, mut checked) = (0usize, 0usize);
    for pose in motion.poses.iter().step_by(stride) {
        let fk = motion.skeleton.forward_kinematics(pose);
        let rise = fk.positions[head].y - fk.positions[0].y;
        upright += usize::from(rise > 0.2);
        checked += 1;
    }
    let fraction = upright as f32 / checked.max(1) as f32;
    if fraction < MIN_UPRIGHT_FRACTION {
        return Err(ImportError::invalid(
            file,
            Location::Field("global_orient".into()),
            format!(
                "a Z-up SMPL fit (Nymeria's Aria world), whose head is above the pelvis after conversion to Y-up on at least {:.0}% of the frames",
                MIN_UPRIGHT_FRACTION * 100.0
            ),
            format!(
                "the head above the pelvis on {:.0}% of the frames — is this fit Y-up or otherwise rotated? Convert it to Z-up first",
                fraction * 100.0
            ),
        ));
    }
    Ok(())
}

/// Reads `xdata_smpl_neutral.npz` into a fixed-rate motion in the session's Y-up world.
pub fn read_nymeria_smpl(file: &str, npz: &Npz) -> Result<(SmplMotion, Vec<ImportWarning>), ImportError> {
    let mut warnings = Vec::new();
    let timestamps = npz.array_with_shape("timestamps", &[None])?;
    let n = timestamps.len();
    if n < 2 {
        return Err(ImportError::invalid(
            file,
            Location::Field("timestamps".into()),
            "at least 2 body samples",
            n.to_string(),
        ));
    }
    let body_pose = npz.array_with_shape("body_pose", &[Some(n), Some(69)])?;
    let global_orient = npz.array_with_shape("global_orient", &[Some(n), Some(3)])?;
    let transl = npz.array_with_shape("transl", &[Some(n), Some(3)])?;
    let betas_array = npz.array("betas")?;
    let betas = read_betas(file, &betas_array, n, &mut warnings)?;

    // Timestamps: µs (integer or float) → ns, strictly increasing.
    let mut times = Vec::with_capacity(n);
    for i in 0..n {
        let at = || Location::Field(format!("timestamps[{i}]"));
        let ns = if timestamps.is_int() {
            timestamps.i64_at(i).and_then(|us| us.checked_mul(1000))
        } else {
            timestamps.f64_at(i).filter(|us| us.is_finite() && us.abs() < 9.0e15).map(|us| (us * 1000.0).round() as i64)
        };
        let ns = ns.ok_or_else(|| {
            ImportError::invalid(
                file,
                at(),
                "a timestamp in microseconds that fits in i64 nanoseconds",
                format!("{:?}", timestamps.f64_at(i)),
            )
        })?;
        if let Some(&previous) = times.last() {
            if ns == previous {
                return Err(ImportError::new(file, at(), ImportErrorKind::DuplicateTimestamp(ns)));
            }
            if ns < previous {
                return Err(ImportError::new(file, at(), ImportErrorKind::NonMonotonicTimestamp { previous, got: ns }));
            }
            if i128::from(ns) - i128::from(previous) > i128::from(MAX_BODY_GAP_NS) {
                return Err(ImportError::invalid(
                    file,
                    at(),
                    format!("body samples at most {} s apart", MAX_BODY_GAP_NS as f64 / 1e9),
                    format!("a gap of {:.3} s", (i128::from(ns) - i128::from(previous)) as f64 / 1e9),
                ));
            }
        }
        times.push(ns);
    }
    let mut intervals: Vec<i64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    intervals.sort_unstable();
    let median = intervals[intervals.len() / 2].max(1);
    // The rate whose grid runs from the first to the last sample: the median interval,
    // adjusted so that microsecond rounding of the timestamps does not drop the last frame.
    let span = times[n - 1] - times[0];
    let steps = (span as f64 / median as f64).round().max(1.0);
    let fps = steps * 1e9 / span as f64;
    if fps > MAX_BODY_RATE_HZ {
        return Err(ImportError::invalid(
            file,
            Location::Field("timestamps".into()),
            format!("a body sample rate of at most {MAX_BODY_RATE_HZ} Hz (timestamps in microseconds)"),
            format!("{fps:.0} Hz"),
        ));
    }

    // Source poses in the session world.
    let skeleton = SmplSkeleton::mean_shape();
    let j0 = skeleton.rest_joints()[0];
    let vec3 = |a: &NpyArray, row: usize, col: usize, name: &str| -> Result<Vec3, ImportError> {
        let mut v = [0f32; 3];
        for (k, slot) in v.iter_mut().enumerate() {
            let x = a.f64_at(row * a.shape[1] + col + k).unwrap_or(f64::NAN);
            if !x.is_finite() || x.abs() > 1.0e5 {
                return Err(ImportError::invalid(
                    file,
                    Location::Field(format!("{name}[{row}, {}]", col + k)),
                    "a finite number",
                    x.to_string(),
                ));
            }
            *slot = x as f32;
        }
        Ok(Vec3::from_array(v))
    };
    let mut source = Vec::with_capacity(n);
    for i in 0..n {
        let mut body = [egoexo_core::glam::Quat::IDENTITY; NUM_BODY_JOINTS];
        for (j, q) in body.iter_mut().enumerate() {
            *q = quat_from_axis_angle(vec3(&body_pose, i, 3 * j, "body_pose")?);
        }
        let aria = SmplPose {
            root_orientation: quat_from_axis_angle(vec3(&global_orient, i, 0, "global_orient")?),
            body,
            translation: vec3(&transl, i, 0, "transl")?,
        };
        source.push(session_smpl_pose_from_aria(&aria, j0));
    }

    // Resample onto start + round(k · 1e9 / fps).
    let start = times[0];
    let frames = steps as usize + 1;
    if frames > 2 * n + 16 {
        return Err(ImportError::invalid(
            file,
            Location::Field("timestamps".into()),
            "roughly regular body samples",
            format!("{n} samples that would need {frames} frames at their median rate ({fps:.1} Hz)"),
        ));
    }
    let mut poses = Vec::with_capacity(frames);
    let mut i = 0;
    for k in 0..frames {
        let t = start + (k as f64 * 1e9 / fps).round() as i64;
        while i + 1 < n && times[i + 1] <= t {
            i += 1;
        }
        let pose = if i + 1 >= n {
            source[n - 1]
        } else {
            let alpha = ((t - times[i]) as f64 / (times[i + 1] - times[i]) as f64) as f32;
            source[i].interpolate(&source[i + 1], alpha.clamp(0.0, 1.0))
        };
        poses.push(pose);
    }
    let motion = SmplMotion::new(fps as f32, start, skeleton, betas, poses)
        .map_err(|e| ImportError::invalid(file, Location::File, "a valid SMPL motion", e.to_string()))?;
    check_head_above_pelvis(file, &motion)?;
    warnings.push(ImportWarning {
        file: file.into(),
        message: "no SMPL model is shipped: the neutral mean-shape skeleton is used for the ground truth (betas kept)"
            .into(),
    });
    Ok((motion, warnings))
}

fn read_betas(
    file: &str,
    betas: &NpyArray,
    n: usize,
    warnings: &mut Vec<ImportWarning>,
) -> Result<Option<Vec<f32>>, ImportError> {
    let (rows, cols) = match betas.shape.as_slice() {
        [c] => (1, *c),
        [r, c] if *r == n || *r == 1 => (*r, *c),
        other => {
            return Err(ImportError::invalid(
                file,
                Location::Field("betas".into()),
                format!("shape (N, B) or (B,) with N = {n}"),
                format!("shape {other:?}"),
            ));
        }
    };
    if cols == 0 || cols > 300 {
        return Err(ImportError::invalid(
            file,
            Location::Field("betas".into()),
            "1 to 300 shape coefficients",
            cols.to_string(),
        ));
    }
    let value = |r: usize, c: usize| betas.f64_at(r * cols + c).unwrap_or(f64::NAN);
    let mut first = Vec::with_capacity(cols);
    for c in 0..cols {
        let v = value(0, c);
        if !v.is_finite() {
            return Err(ImportError::invalid(
                file,
                Location::Field(format!("betas[0, {c}]")),
                "a finite number",
                v.to_string(),
            ));
        }
        first.push(v as f32);
    }
    let varies = (1..rows).any(|r| (0..cols).any(|c| (value(r, c) - f64::from(first[c])).abs() > 1e-3));
    if varies {
        warnings.push(ImportWarning {
            file: file.into(),
            message: "betas vary over time; the first frame's are used".into(),
        });
    }
    Ok(Some(first))
}
