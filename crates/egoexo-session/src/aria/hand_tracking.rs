//! Aria MPS hand tracking as wrist input: `hand_tracking/wrist_and_palm_poses.csv` and
//! `hand_tracking/hand_tracking_results.csv`, and the wrist poses they give.
//!
//! # The published forms (projectaria_tools, `core/mps/HandTrackingReader.cpp`)
//! | file | columns per hand (`left`/`right`) | orientation |
//! |---|---|---|
//! | `wrist_and_palm_poses.csv` v1 | `{side}_tracking_confidence`, `t{x,y,z}_{side}_wrist_device`, `t{x,y,z}_{side}_palm_device` | none: [`WristOrientation::PalmDownAssumed`] |
//! | `wrist_and_palm_poses.csv` v2 | v1 + `n{x,y,z}_{side}_wrist_device`, `n{x,y,z}_{side}_palm_device` | [`WristOrientation::FromNormals`] |
//! | `hand_tracking_results.csv` | `{side}_tracking_confidence`, `t{x,y,z}_{side}_landmark_{0..20}_device`, `t{x,y,z}_{side}_device_wrist`, `q{x,y,z,w}_{side}_device_wrist` (+ normals in v2) | [`WristOrientation::FromWristPose`] |
//!
//! Every file has `tracking_timestamp_us` (device clock, the trajectory's). A confidence of
//! −1 means the hand was not tracked on that row and its other columns are meaningless: the
//! sample is left out, so a wrist trajectory holds exactly the samples where that wrist was
//! tracked (per-sample validity), and alignment marks the frames between samples further apart
//! than the bridging limit as untracked.
//!
//! # Wrist frame
//! The networks' wrist input is the SMPL wrist joint's global pose (what the simulator's wrist
//! devices report): at the rest pose, the left hand points along +X and the right along −X,
//! palms facing −Y. So the wrist frame is built from the hand's direction `d` (wrist → palm
//! centre) and its palm normal `n` (out of the palm): left `X = d`, right `X = −d`, both
//! `Y = −n⊥` (`n` made orthogonal to `d`), `Z = X × Y`. The normal comes from the file when it
//! has one — `hand_tracking_results.csv`: −Y of `T_device_wrist` (MPS's wrist normal); v2:
//! the wrist normal (the palm normal where the wrist normal is zero) — and otherwise the palm
//! is assumed to face the floor (v1 gives positions only: the hand's pointing direction is
//! measured, its roll about it is a guess).

use egoexo_core::glam::{DVec3, Mat3, Quat, Vec3};
use egoexo_core::rigid::RigidTransform;

use super::trajectory::QUATERNION_NORM_TOLERANCE;
use crate::error::{ImportError, ImportErrorKind, Location, check_strictly_after, quote};

/// `wrist_and_palm_poses.csv`.
pub const WRIST_AND_PALM_FILE: &str = "wrist_and_palm_poses.csv";
/// `hand_tracking_results.csv`.
pub const HAND_TRACKING_RESULTS_FILE: &str = "hand_tracking_results.csv";
/// MPS's folder of hand tracking outputs.
pub const HAND_TRACKING_DIR: &str = "hand_tracking/";
/// Largest accepted |coordinate| of a hand point in the device frame, metres (an arm's reach
/// with a wide margin; beyond it the columns are mixed up).
pub const MAX_HAND_DISTANCE_M: f64 = 3.0;
/// Shortest wrist → palm distance that gives a hand direction, metres.
pub const MIN_HAND_LENGTH_M: f32 = 0.01;
/// The MPS landmark index of the wrist joint in `hand_tracking_results.csv`.
pub const WRIST_LANDMARK: usize = 5;
/// The MPS landmark index of the palm centre in `hand_tracking_results.csv`.
pub const PALM_CENTER_LANDMARK: usize = 20;

pub use crate::model::{HandTrackingForm, WristOrientation};

/// Left or right.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Left,
    Right,
}

impl Side {
    /// `"left"` / `"right"`, as in the column names.
    pub fn name(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
        }
    }
}

/// One hand on one row, in the Aria device frame (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HandObservation {
    pub confidence: f32,
    pub wrist_device: Vec3,
    pub palm_device: Vec3,
    /// The palm normal to build the frame with (out of the palm), when the file gives one.
    pub normal_device: Option<Vec3>,
}

/// The samples of one hand: device-clock timestamps (ns) and observations, tracked rows only.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HandSamples {
    pub timestamps_ns: Vec<i64>,
    pub observations: Vec<HandObservation>,
}

/// A hand tracking file as read.
#[derive(Clone, Debug, PartialEq)]
pub struct HandTracking {
    pub form: HandTrackingForm,
    /// Rows in the file.
    pub rows: usize,
    pub left: HandSamples,
    pub right: HandSamples,
}

impl HandTracking {
    /// The orientation the wrist frames get.
    pub fn orientation(&self) -> WristOrientation {
        match self.form {
            HandTrackingForm::WristAndPalmV1 => WristOrientation::PalmDownAssumed,
            HandTrackingForm::WristAndPalmV2 => WristOrientation::FromNormals,
            HandTrackingForm::HandTrackingResults => WristOrientation::FromWristPose,
        }
    }

    /// The samples of `side`.
    pub fn hand(&self, side: Side) -> &HandSamples {
        match side {
            Side::Left => &self.left,
            Side::Right => &self.right,
        }
    }
}

/// Column indices of one hand.
struct HandColumns {
    side: &'static str,
    confidence: usize,
    wrist: [usize; 3],
    palm: [usize; 3],
    /// `hand_tracking_results.csv`: `q{x,y,z,w}_{side}_device_wrist`.
    rotation: Option<[usize; 4]>,
    /// v2: wrist normal, then palm normal.
    normals: Option<([usize; 3], [usize; 3])>,
}

/// Reads a hand tracking file; the form is told by its name (`hand_tracking_results.csv`
/// or else `wrist_and_palm_poses.csv`) and, for the latter, by whether it has normals.
pub fn read_hand_tracking(file: &str, reader: impl std::io::Read) -> Result<HandTracking, ImportError> {
    let results = file.rsplit('/').next() == Some(HAND_TRACKING_RESULTS_FILE);
    let mut reader = csv::ReaderBuilder::new().has_headers(true).trim(csv::Trim::All).from_reader(reader);
    let headers = match reader.headers() {
        Ok(h) => h.clone(),
        Err(e) => return Err(super::trajectory::csv_error(file, &e)),
    };
    let expected = if results { "of MPS hand_tracking_results.csv" } else { "of MPS wrist_and_palm_poses.csv" };
    if headers.iter().all(str::is_empty) {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: format!("the header and rows {expected}") },
        ));
    }
    let find = |name: &str| headers.iter().position(|h| h == name);
    let required = |name: &str| {
        find(name).ok_or_else(|| {
            let mut found = headers.iter().take(16).map(|h| quote(h, 40)).collect::<Vec<_>>().join(", ");
            if headers.len() > 16 {
                found.push_str(", …");
            }
            ImportError::new(
                file,
                Location::Line(1),
                ImportErrorKind::MissingColumn { column: name.into(), expected: expected.into(), found },
            )
        })
    };
    let xyz = |prefix: char, middle: &str| -> Result<[usize; 3], ImportError> {
        Ok([
            required(&format!("{prefix}x_{middle}"))?,
            required(&format!("{prefix}y_{middle}"))?,
            required(&format!("{prefix}z_{middle}"))?,
        ])
    };
    let has_normals = find("nx_left_wrist_device").is_some() || find("nx_left_palm_device").is_some();
    let columns = |side: &'static str| -> Result<HandColumns, ImportError> {
        let normals = if has_normals {
            Some((xyz('n', &format!("{side}_wrist_device"))?, xyz('n', &format!("{side}_palm_device"))?))
        } else {
            None
        };
        Ok(if results {
            HandColumns {
                side,
                confidence: required(&format!("{side}_tracking_confidence"))?,
                wrist: xyz('t', &format!("{side}_device_wrist"))?,
                palm: xyz('t', &format!("{side}_landmark_{PALM_CENTER_LANDMARK}_device"))?,
                rotation: Some([
                    required(&format!("qx_{side}_device_wrist"))?,
                    required(&format!("qy_{side}_device_wrist"))?,
                    required(&format!("qz_{side}_device_wrist"))?,
                    required(&format!("qw_{side}_device_wrist"))?,
                ]),
                normals,
            }
        } else {
            HandColumns {
                side,
                confidence: required(&format!("{side}_tracking_confidence"))?,
                wrist: xyz('t', &format!("{side}_wrist_device"))?,
                palm: xyz('t', &format!("{side}_palm_device"))?,
                rotation: None,
                normals,
            }
        })
    };
    let time_column = required("tracking_timestamp_us")?;
    let hands = [columns("left")?, columns("right")?];
    let form = match (results, has_normals) {
        (true, _) => HandTrackingForm::HandTrackingResults,
        (false, false) => HandTrackingForm::WristAndPalmV1,
        (false, true) => HandTrackingForm::WristAndPalmV2,
    };

    let mut out = HandTracking { form, rows: 0, left: HandSamples::default(), right: HandSamples::default() };
    let mut previous: Option<i64> = None;
    let mut record = csv::StringRecord::new();
    loop {
        match reader.read_record(&mut record) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(super::trajectory::csv_error(file, &e)),
        }
        out.rows += 1;
        let line = record.position().map_or(0, |p| p.line());
        let at = |c: usize| Location::LineField { line, field: headers.get(c).unwrap_or_default().to_owned() };
        let field = |c: usize| record.get(c).unwrap_or_default();
        let number = |c: usize| -> Result<f64, ImportError> {
            match field(c).parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(ImportError::invalid(file, at(c), "a finite number", quote(field(c), 40))),
            }
        };
        let raw_time = field(time_column);
        let t_us: i64 = raw_time
            .parse()
            .map_err(|_| ImportError::invalid(file, at(time_column), "an integer timestamp", quote(raw_time, 40)))?;
        let t_ns = t_us.checked_mul(1000).ok_or_else(|| {
            ImportError::invalid(file, at(time_column), "a timestamp that fits in i64 nanoseconds", raw_time.to_owned())
        })?;
        check_strictly_after(file, || at(time_column), previous, t_ns)?;
        previous = Some(t_ns);
        for (hand, samples) in hands.iter().zip([&mut out.left, &mut out.right]) {
            let confidence = number(hand.confidence)?;
            if confidence < 0.0 {
                // −1: not tracked on this row; the other columns are placeholders.
                continue;
            }
            if confidence > 1.0 {
                return Err(ImportError::invalid(
                    file,
                    at(hand.confidence),
                    "a confidence in [0, 1], or −1 where the hand is not tracked",
                    field(hand.confidence).to_owned(),
                ));
            }
            let point = |cols: [usize; 3]| -> Result<Vec3, ImportError> {
                let mut v = [0f64; 3];
                for (slot, &c) in v.iter_mut().zip(&cols) {
                    *slot = number(c)?;
                    if slot.abs() > MAX_HAND_DISTANCE_M {
                        return Err(ImportError::invalid(
                            file,
                            at(c),
                            format!("a coordinate within ±{MAX_HAND_DISTANCE_M} m of the glasses"),
                            field(c).to_owned(),
                        ));
                    }
                }
                Ok(DVec3::from_array(v).as_vec3())
            };
            let wrist_device = point(hand.wrist)?;
            let palm_device = point(hand.palm)?;
            let normal_device = match (hand.rotation, hand.normals) {
                (Some(q), _) => {
                    let q = [number(q[0])?, number(q[1])?, number(q[2])?, number(q[3])?];
                    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
                        return Err(ImportError::new(
                            file,
                            Location::LineField {
                                line,
                                field: format!("qx_{0}_device_wrist..qw_{0}_device_wrist", hand.side),
                            },
                            ImportErrorKind::NonUnitQuaternion { norm, tolerance: QUATERNION_NORM_TOLERANCE },
                        ));
                    }
                    let r = Quat::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32).normalize();
                    Some(r * Vec3::NEG_Y)
                }
                (None, Some((wrist_normal, palm_normal))) => {
                    let wrist_normal = point(wrist_normal)?;
                    let palm_normal = point(palm_normal)?;
                    [wrist_normal, palm_normal].into_iter().find(|n| n.length() > 1e-3).map(Vec3::normalize)
                }
                (None, None) => None,
            };
            samples.timestamps_ns.push(t_ns);
            samples.observations.push(HandObservation {
                confidence: confidence as f32,
                wrist_device,
                palm_device,
                normal_device,
            });
        }
    }
    if out.rows == 0 {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: "at least one row after the header".into() },
        ));
    }
    Ok(out)
}

/// The wrist frame of `side` from a hand direction and a palm normal, both in one frame
/// (see the module docs); `None` when the hand direction is shorter than
/// [`MIN_HAND_LENGTH_M`]. `down` replaces a normal that is missing or along the hand.
pub fn wrist_rotation(side: Side, wrist: Vec3, palm: Vec3, normal: Option<Vec3>, down: Vec3) -> Option<Quat> {
    let along = palm - wrist;
    if along.length() < MIN_HAND_LENGTH_M {
        return None;
    }
    let d = along.normalize();
    let orthogonal = |n: Vec3| {
        let n = n - n.dot(d) * d;
        (n.length() > 1e-3).then(|| n.normalize())
    };
    let n = normal.and_then(orthogonal).or_else(|| orthogonal(down)).unwrap_or_else(|| d.any_orthonormal_vector());
    let x = match side {
        Side::Left => d,
        Side::Right => -d,
    };
    let y = -n;
    let z = x.cross(y);
    Some(Quat::from_mat3(&Mat3::from_cols(x, y, z)).normalize())
}

/// A hand observation as a wrist pose: `T_device_wrist` in the Aria device frame, with
/// `down_device` (the world's down in the device frame) for a missing normal.
pub fn t_device_wrist(side: Side, observation: &HandObservation, down_device: Vec3) -> Option<RigidTransform> {
    let rotation = wrist_rotation(
        side,
        observation.wrist_device,
        observation.palm_device,
        observation.normal_device,
        down_device,
    )?;
    Some(RigidTransform::new(rotation, observation.wrist_device))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rest_pose_hands_give_the_identity() {
        // SMPL rest pose: left hand along +X, right along −X, palms down.
        let left = wrist_rotation(Side::Left, Vec3::ZERO, Vec3::X * 0.08, Some(Vec3::NEG_Y), Vec3::NEG_Y).unwrap();
        let right = wrist_rotation(Side::Right, Vec3::ZERO, -Vec3::X * 0.08, Some(Vec3::NEG_Y), Vec3::NEG_Y).unwrap();
        assert!(left.abs_diff_eq(Quat::IDENTITY, 1e-6) || left.abs_diff_eq(-Quat::IDENTITY, 1e-6), "{left:?}");
        assert!(right.abs_diff_eq(Quat::IDENTITY, 1e-6) || right.abs_diff_eq(-Quat::IDENTITY, 1e-6), "{right:?}");
    }

    #[test]
    fn any_wrist_rotation_is_recovered_from_direction_and_normal() {
        for (i, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let r = Quat::from_euler(egoexo_core::glam::EulerRot::YXZ, 0.7 + i as f32, -0.4, 1.2);
            let hand_x = if side == Side::Left { Vec3::X } else { Vec3::NEG_X };
            let wrist = Vec3::new(0.2, -0.3, 0.4);
            let palm = wrist + r * hand_x * 0.08;
            let got = wrist_rotation(side, wrist, palm, Some(r * Vec3::NEG_Y), Vec3::NEG_Y).unwrap();
            assert!(got.angle_between(r) < 1e-4, "{side:?}: {}", got.angle_between(r));
            // Without a normal the direction is still right; roll comes from `down`.
            let guessed = wrist_rotation(side, wrist, palm, None, Vec3::NEG_Y).unwrap();
            assert!((guessed * hand_x).abs_diff_eq(r * hand_x, 1e-5));
            assert!((guessed * Vec3::NEG_Y).dot(Vec3::NEG_Y) > 0.0, "palm faces down");
        }
        assert!(wrist_rotation(Side::Left, Vec3::ZERO, Vec3::X * 0.001, None, Vec3::NEG_Y).is_none());
    }
}
