//! Validation of an in-memory [`Session`]: the invariants every importer establishes and every
//! consumer (alignment, the `.egoexo` writer, reconstruction) relies on.
//!
//! Errors use the session's name as the file and a field path as the location
//! (`observers[1].keypoints.timestamps_ns[5]`). Warnings are things worth a look that do not
//! make the session unusable (little time overlap, keypoints off the image, …).

use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_core::rigid::RigidTransform;

use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::model::{Session, Trajectory};

/// Tolerance on `|q| − 1` of stored rotations.
pub const UNIT_QUATERNION_TOLERANCE: f32 = 1e-3;
/// Plausible stature range, metres.
pub const STATURE_RANGE_M: std::ops::RangeInclusive<f32> = 0.5..=2.7;
/// Largest plausible distance of the SMPL head joint from the head device, metres.
pub const MAX_HEAD_JOINT_OFFSET_M: f32 = 0.5;
/// Largest accepted context feature dimension.
pub const MAX_CONTEXT_FEATURE_DIM: usize = 65_536;

/// Whether an observer id is usable as a folder name: 1–64 of `[A-Za-z0-9._-]`, not `.`/`..`.
pub fn is_valid_observer_id(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= 64
        && id != "."
        && id != ".."
        && id.bytes().all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'))
}

struct Checker<'a> {
    file: &'a str,
    warnings: Vec<ImportWarning>,
}

impl Checker<'_> {
    fn invalid(&self, field: impl Into<String>, expected: impl Into<String>, got: impl Into<String>) -> ImportError {
        ImportError::invalid(self.file, Location::Field(field.into()), expected, got)
    }

    fn warn(&mut self, message: String) {
        self.warnings.push(ImportWarning { file: self.file.to_owned(), message });
    }

    fn timestamps(&self, field: &str, ts: &[i64]) -> Result<(), ImportError> {
        for (i, w) in ts.windows(2).enumerate() {
            let (previous, got) = (w[0], w[1]);
            if got == previous {
                return Err(ImportError::new(
                    self.file,
                    Location::Field(format!("{field}[{}]", i + 1)),
                    ImportErrorKind::DuplicateTimestamp(got),
                ));
            }
            if got < previous {
                return Err(ImportError::new(
                    self.file,
                    Location::Field(format!("{field}[{}]", i + 1)),
                    ImportErrorKind::NonMonotonicTimestamp { previous, got },
                ));
            }
        }
        Ok(())
    }

    fn pose(&self, field: String, pose: &RigidTransform) -> Result<(), ImportError> {
        if !pose.is_finite() {
            return Err(self.invalid(field, "a finite pose", format!("{pose:?}")));
        }
        let norm = pose.rotation.length();
        if (norm - 1.0).abs() > UNIT_QUATERNION_TOLERANCE {
            return Err(ImportError::new(
                self.file,
                Location::Field(field),
                ImportErrorKind::NonUnitQuaternion {
                    norm: f64::from(norm),
                    tolerance: f64::from(UNIT_QUATERNION_TOLERANCE),
                },
            ));
        }
        Ok(())
    }

    fn trajectory(&self, field: &str, t: &Trajectory) -> Result<(), ImportError> {
        if t.is_empty() {
            return Err(self.invalid(field, "a trajectory with at least one pose", "none"));
        }
        if t.timestamps_ns.len() != t.poses.len() {
            return Err(self.invalid(
                field,
                "as many poses as timestamps",
                format!("{} poses for {} timestamps", t.poses.len(), t.timestamps_ns.len()),
            ));
        }
        self.timestamps(&format!("{field}.timestamps_ns"), &t.timestamps_ns)?;
        for (i, pose) in t.poses.iter().enumerate() {
            self.pose(format!("{field}.poses[{i}]"), pose)?;
        }
        Ok(())
    }

    /// Errors when the ranges do not intersect at all: the streams are on different clocks.
    fn same_clock(
        &self,
        what: &str,
        range: (i64, i64),
        reference: &str,
        reference_range: (i64, i64),
    ) -> Result<(), ImportError> {
        if range.1 < reference_range.0 || range.0 > reference_range.1 {
            return Err(ImportError::new(
                self.file,
                Location::Field(what.into()),
                ImportErrorKind::MixedClocks {
                    detail: format!(
                        "`{what}` spans {} .. {} ns but `{reference}` spans {} .. {} ns; they never overlap, so they are not on one clock (check the time unit, the clock choice, or add time_sync.csv files)",
                        range.0, range.1, reference_range.0, reference_range.1
                    ),
                },
            ));
        }
        Ok(())
    }
}

/// Validates a session; `Ok` carries warnings.
pub fn validate_session(session: &Session) -> Result<Vec<ImportWarning>, ImportError> {
    let file = if session.name.is_empty() { "session" } else { session.name.as_str() };
    let mut c = Checker { file, warnings: Vec::new() };

    c.trajectory("wearer.head", &session.wearer.head)?;
    let head_range = session.wearer.head.time_range_ns().unwrap_or_default();
    for (name, wrist) in
        [("wearer.left_wrist", &session.wearer.left_wrist), ("wearer.right_wrist", &session.wearer.right_wrist)]
    {
        if let Some(wrist) = wrist {
            c.trajectory(name, wrist)?;
            c.same_clock(name, wrist.time_range_ns().unwrap_or_default(), "wearer.head", head_range)?;
        }
    }
    if session.wearer.left_wrist.is_some() != session.wearer.right_wrist.is_some() {
        c.warn("only one wrist trajectory; 3-point tracking needs both, so it will be ignored".into());
    }
    let offset = session.wearer.head_joint_in_device;
    if !offset.is_finite() || offset.length() > MAX_HEAD_JOINT_OFFSET_M {
        return Err(c.invalid(
            "wearer.head_joint_in_device",
            format!("a finite offset shorter than {MAX_HEAD_JOINT_OFFSET_M} m"),
            format!("{offset}"),
        ));
    }

    for (o, observer) in session.observers.iter().enumerate() {
        let base = format!("observers[{o}]");
        if !is_valid_observer_id(&observer.id) {
            return Err(c.invalid(
                format!("{base}.id"),
                "an observer id of 1–64 characters from A–Z, a–z, 0–9, `.`, `_`, `-`",
                format!("`{}`", observer.id),
            ));
        }
        if session.observers[..o].iter().any(|other| other.id == observer.id) {
            return Err(c.invalid(format!("{base}.id"), "unique observer ids", format!("a second `{}`", observer.id)));
        }
        let traj = format!("{base}.head");
        c.trajectory(&traj, &observer.head)?;
        let range = observer.head.time_range_ns().unwrap_or_default();
        c.same_clock(&traj, range, "wearer.head", head_range)?;
        let overlap = (range.1.min(head_range.1) - range.0.max(head_range.0)) as f64;
        let head_span = (head_range.1 - head_range.0).max(1) as f64;
        if overlap / head_span < 0.5 {
            c.warn(format!(
                "observer `{}` is tracked during only {:.0}% of the wearer's recording",
                observer.id,
                100.0 * overlap / head_span
            ));
        }
        c.pose(format!("{base}.camera.t_device_camera"), &observer.camera.t_device_camera)?;
        if let Some(r) = observer.camera.valid_radius_px
            && !(r.is_finite() && r > 0.0)
        {
            return Err(c.invalid(
                format!("{base}.camera.valid_radius_px"),
                "a positive radius in pixels",
                r.to_string(),
            ));
        }
        if let Some(kp) = &observer.keypoints {
            let field = format!("{base}.keypoints");
            if kp.timestamps_ns.len() != kp.frames.len() {
                return Err(c.invalid(
                    &field,
                    "one timestamp per keypoint frame",
                    format!("{} frames for {} timestamps", kp.frames.len(), kp.timestamps_ns.len()),
                ));
            }
            if kp.frames.is_empty() {
                return Err(c.invalid(&field, "at least one keypoint frame", "none"));
            }
            c.timestamps(&format!("{field}.timestamps_ns"), &kp.timestamps_ns)?;
            let mut off_image = 0usize;
            for (i, frame) in kp.frames.iter().enumerate() {
                for (k, point) in frame.iter().enumerate() {
                    let Some(point) = point else { continue };
                    if !point.pixel.is_finite() {
                        return Err(c.invalid(
                            format!("{field}.frames[{i}][{k}].pixel"),
                            "finite pixel coordinates",
                            format!("{}", point.pixel),
                        ));
                    }
                    if !(0.0..=1.0).contains(&point.score) {
                        return Err(c.invalid(
                            format!("{field}.frames[{i}][{k}].score"),
                            "a score in [0, 1]",
                            point.score.to_string(),
                        ));
                    }
                    let inside = point.pixel.x >= -0.5
                        && point.pixel.y >= -0.5
                        && point.pixel.x <= observer.camera.width as f32 - 0.5
                        && point.pixel.y <= observer.camera.height as f32 - 0.5;
                    if !inside {
                        off_image += 1;
                    }
                }
            }
            if off_image > 0 {
                c.warn(format!(
                    "observer `{}`: {off_image} keypoint(s) lie outside the {}×{} image (wrong image size or resolution?)",
                    observer.id, observer.camera.width, observer.camera.height
                ));
            }
            let kp_range = (kp.timestamps_ns[0], kp.timestamps_ns[kp.timestamps_ns.len() - 1]);
            c.same_clock(&format!("{field}.timestamps_ns"), kp_range, &traj, range)?;
        }
        if let Some(features) = &observer.context_features {
            let field = format!("{base}.context_features");
            if features.dim == 0 || features.dim > MAX_CONTEXT_FEATURE_DIM {
                return Err(c.invalid(
                    format!("{field}.dim"),
                    format!("a dimension in 1..={MAX_CONTEXT_FEATURE_DIM}"),
                    features.dim.to_string(),
                ));
            }
            let expected = features.timestamps_ns.len().checked_mul(features.dim);
            if expected != Some(features.values.len()) {
                return Err(c.invalid(
                    format!("{field}.values"),
                    format!("{} × {} values", features.timestamps_ns.len(), features.dim),
                    format!("{} values", features.values.len()),
                ));
            }
            c.timestamps(&format!("{field}.timestamps_ns"), &features.timestamps_ns)?;
            if let Some(i) = features.values.iter().position(|v| !v.is_finite()) {
                return Err(c.invalid(
                    format!("{field}.values[{i}]"),
                    "a finite number",
                    features.values[i].to_string(),
                ));
            }
        }
        if let Some(video) = &observer.video
            && crate::vfs::normalize_path(&video.path).is_none()
        {
            return Err(c.invalid(
                format!("{base}.video.path"),
                "a relative path inside the session",
                format!("`{}`", video.path),
            ));
        }
    }

    let subject = &session.subject;
    if let Some(h) = subject.height_m
        && !STATURE_RANGE_M.contains(&h)
    {
        return Err(c.invalid(
            "subject.height_m",
            format!("a stature in metres within {}..={}", STATURE_RANGE_M.start(), STATURE_RANGE_M.end()),
            h.to_string(),
        ));
    }
    if let Some(betas) = &subject.betas {
        if betas.is_empty() || betas.len() > 300 {
            return Err(c.invalid(
                "subject.betas",
                "1 to 300 SMPL shape coefficients",
                format!("{} values", betas.len()),
            ));
        }
        if let Some(i) = betas.iter().position(|b| !b.is_finite()) {
            return Err(c.invalid(format!("subject.betas[{i}]"), "a finite number", betas[i].to_string()));
        }
    }
    subject.skeleton().map_err(|e| c.invalid("subject", "a valid skeleton (rest joints or stature)", e.to_string()))?;

    if let Some(gt) = &session.ground_truth {
        let motion = &gt.motion;
        if !(motion.fps.is_finite() && motion.fps > 0.0) {
            return Err(c.invalid("ground_truth.motion.fps", "a positive frame rate", motion.fps.to_string()));
        }
        if motion.poses.is_empty() {
            return Err(c.invalid("ground_truth.motion.poses", "at least one pose", "none"));
        }
        if let Some(i) = motion.poses.iter().position(|p| !p.is_finite()) {
            return Err(c.invalid(format!("ground_truth.motion.poses[{i}]"), "a finite pose", "a non-finite value"));
        }
        let last = motion.timestamp_ns(motion.len() - 1);
        c.same_clock("ground_truth.motion", (motion.start_ns, last), "wearer.head", head_range)?;
        for (i, occlusion) in gt.occlusion.iter().enumerate() {
            let field = format!("ground_truth.occlusion[{i}]");
            if !session.observers.iter().any(|o| o.id == occlusion.observer_id) {
                let known: Vec<&str> = session.observers.iter().map(|o| o.id.as_str()).collect();
                return Err(ImportError::new(
                    c.file,
                    Location::Field(format!("{field}.observer_id")),
                    ImportErrorKind::ObserverMismatch {
                        expected: format!("one of {known:?}"),
                        got: occlusion.observer_id.clone(),
                    },
                ));
            }
            if gt.occlusion[..i].iter().any(|o| o.observer_id == occlusion.observer_id) {
                return Err(c.invalid(
                    format!("{field}.observer_id"),
                    "one occlusion track per observer",
                    format!("a second `{}`", occlusion.observer_id),
                ));
            }
            if occlusion.occluded.len() != motion.len() {
                return Err(c.invalid(
                    format!("{field}.occluded"),
                    format!("one mask per ground-truth frame ({})", motion.len()),
                    format!("{} masks", occlusion.occluded.len()),
                ));
            }
            if let Some(j) = occlusion.occluded.iter().position(|&m| m >> EXO_KEYPOINT_COUNT != 0) {
                return Err(c.invalid(
                    format!("{field}.occluded[{j}]"),
                    format!("a bitmask of the {EXO_KEYPOINT_COUNT} exo keypoints (< {})", 1u32 << EXO_KEYPOINT_COUNT),
                    occlusion.occluded[j].to_string(),
                ));
            }
        }
    }
    Ok(c.warnings)
}
