//! Aria MPS `closed_loop_trajectory.csv`: reader and writer.
//!
//! Columns (MPS): `graph_uid, tracking_timestamp_us, utc_timestamp_ns, tx_world_device,
//! ty_world_device, tz_world_device, qx_world_device, qy_world_device, qz_world_device,
//! qw_world_device, device_linear_velocity_{x,y,z}_device, angular_velocity_{x,y,z}_device,
//! gravity_{x,y,z}_world, quality_score`; extra columns are ignored, columns are found by
//! name. The reader needs the timestamp of the chosen [`Clock`] and the pose columns; when
//! `gravity_*_world` is present it must point down the file's world (−Z for MPS, within
//! [`MAX_GRAVITY_TILT_DEG`]), and `graph_uid` must not change within a file (poses of
//! different graphs do not share a world frame).
//!
//! `.egoexo` sessions store trajectories in this layout too (in session conventions: Y-up
//! world, CPF device frame, see `docs/session-format.md`) with one extra column,
//! `tracking_timestamp_ns`, which the reader prefers over `tracking_timestamp_us` so
//! nanosecond timestamps survive a round trip.
//!
//! The reader returns poses exactly as stored (`T_world_device` of the file's world and
//! device frames); conversion to session conventions is the caller's (see [`crate::aria`]).

use std::fmt::Write as _;

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;

use crate::error::{ImportError, ImportErrorKind, Location, quote};

/// Which timestamp column gives the time of a pose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Clock {
    /// `tracking_timestamp_us` (or `tracking_timestamp_ns`): the device's own clock.
    #[default]
    Device,
    /// `utc_timestamp_ns`: wall-clock time, shared by devices whose phones were synchronised.
    Utc,
}

/// Which axis of the file's world is up (gravity points the other way).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WorldUp {
    /// Aria MPS worlds: +Z up.
    Z,
    /// Session (`.egoexo`) worlds: +Y up.
    Y,
}

impl WorldUp {
    fn index(self) -> usize {
        match self {
            WorldUp::Z => 2,
            WorldUp::Y => 1,
        }
    }

    fn name(self) -> &'static str {
        match self {
            WorldUp::Z => "−Z",
            WorldUp::Y => "−Y",
        }
    }
}

/// Tolerance on `|q|` before normalising a stored quaternion.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;
/// Largest accepted angle between `gravity_world` and −Z, degrees.
pub const MAX_GRAVITY_TILT_DEG: f64 = 10.0;
/// Largest accepted |coordinate| of a device position, metres (anything beyond is not a
/// room-scale or building-scale recording and indicates a unit or column mix-up).
pub const MAX_ABS_POSITION_M: f64 = 100_000.0;

/// The MPS column names, in MPS order.
pub const MPS_COLUMNS: [&str; 20] = [
    "graph_uid",
    "tracking_timestamp_us",
    "utc_timestamp_ns",
    "tx_world_device",
    "ty_world_device",
    "tz_world_device",
    "qx_world_device",
    "qy_world_device",
    "qz_world_device",
    "qw_world_device",
    "device_linear_velocity_x_device",
    "device_linear_velocity_y_device",
    "device_linear_velocity_z_device",
    "angular_velocity_x_device",
    "angular_velocity_y_device",
    "angular_velocity_z_device",
    "gravity_x_world",
    "gravity_y_world",
    "gravity_z_world",
    "quality_score",
];

const POSE_COLUMNS: [&str; 7] = [
    "tx_world_device",
    "ty_world_device",
    "tz_world_device",
    "qx_world_device",
    "qy_world_device",
    "qz_world_device",
    "qw_world_device",
];

/// A trajectory as stored in a file: strictly increasing timestamps (ns) and `T_world_device`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CsvTrajectory {
    pub timestamps_ns: Vec<i64>,
    pub poses: Vec<RigidTransform>,
}

/// Reads a `closed_loop_trajectory.csv` whose world has `up` as its up axis. `file` names it
/// in errors.
pub fn read_closed_loop_trajectory(
    file: &str,
    bytes: &[u8],
    clock: Clock,
    up: WorldUp,
) -> Result<CsvTrajectory, ImportError> {
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: "a closed_loop_trajectory.csv header and poses".into() },
        ));
    }
    let mut reader = csv::ReaderBuilder::new().has_headers(true).trim(csv::Trim::All).from_reader(bytes);
    let headers = reader.headers().map_err(|e| csv_error(file, &e))?.clone();
    let find = |name: &str| headers.iter().position(|h| h == name);
    let found = || {
        let mut s = headers.iter().take(24).map(|h| quote(h, 40)).collect::<Vec<_>>().join(", ");
        if headers.len() > 24 {
            s.push_str(", …");
        }
        s
    };
    let required = |name: &str| {
        find(name).ok_or_else(|| {
            ImportError::new(
                file,
                Location::Line(1),
                ImportErrorKind::MissingColumn {
                    column: name.into(),
                    expected: "of Aria MPS closed_loop_trajectory.csv".into(),
                    found: found(),
                },
            )
        })
    };
    let (time_column, time_scale): (usize, i64) = match clock {
        Clock::Device => match find("tracking_timestamp_ns") {
            Some(c) => (c, 1),
            None => (required("tracking_timestamp_us")?, 1000),
        },
        Clock::Utc => (required("utc_timestamp_ns")?, 1),
    };
    let time_name = headers.get(time_column).unwrap_or_default().to_owned();
    let mut pose_columns = [0usize; 7];
    for (slot, name) in pose_columns.iter_mut().zip(POSE_COLUMNS) {
        *slot = required(name)?;
    }
    let gravity_columns = match (find("gravity_x_world"), find("gravity_y_world"), find("gravity_z_world")) {
        (Some(x), Some(y), Some(z)) => Some([x, y, z]),
        _ => None,
    };
    let graph_column = find("graph_uid");

    let mut out = CsvTrajectory::default();
    let mut graph: Option<String> = None;
    let mut record = csv::StringRecord::new();
    loop {
        match reader.read_record(&mut record) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(csv_error(file, &e)),
        }
        let line = record.position().map_or(0, |p| p.line());
        let field = |c: usize| record.get(c).unwrap_or_default();
        let at = |c: usize| Location::LineField { line, field: headers.get(c).unwrap_or_default().to_owned() };

        let raw_time = field(time_column);
        let t: i64 = raw_time
            .parse()
            .map_err(|_| ImportError::invalid(file, at(time_column), "an integer timestamp", quote(raw_time, 40)))?;
        if clock == Clock::Utc && t <= 0 {
            return Err(ImportError::invalid(
                file,
                at(time_column),
                "a positive UTC timestamp in nanoseconds (this recording may have no UTC time; use the device clock)",
                t.to_string(),
            ));
        }
        let t_ns = t.checked_mul(time_scale).ok_or_else(|| {
            ImportError::invalid(
                file,
                at(time_column),
                format!("a timestamp that fits in i64 nanoseconds ({time_name})"),
                raw_time.to_owned(),
            )
        })?;
        if let Some(&previous) = out.timestamps_ns.last() {
            if t_ns == previous {
                return Err(ImportError::new(file, at(time_column), ImportErrorKind::DuplicateTimestamp(t_ns)));
            }
            if t_ns < previous {
                return Err(ImportError::new(
                    file,
                    at(time_column),
                    ImportErrorKind::NonMonotonicTimestamp { previous, got: t_ns },
                ));
            }
        }

        let mut values = [0f64; 7];
        for (value, &c) in values.iter_mut().zip(&pose_columns) {
            *value = parse_finite(file, at(c), field(c))?;
        }
        for (i, &c) in pose_columns.iter().enumerate().take(3) {
            if values[i].abs() > MAX_ABS_POSITION_M {
                return Err(ImportError::invalid(
                    file,
                    at(c),
                    format!("a position within ±{MAX_ABS_POSITION_M} m"),
                    values[i].to_string(),
                ));
            }
        }
        let q = [values[3], values[4], values[5], values[6]];
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
            return Err(ImportError::new(
                file,
                Location::LineField { line, field: "qx_world_device..qw_world_device".into() },
                ImportErrorKind::NonUnitQuaternion { norm, tolerance: QUATERNION_NORM_TOLERANCE },
            ));
        }
        // Renormalise only what is not unit already, so written → read round trips are exact.
        let scale = if (norm - 1.0).abs() > 1e-6 { norm } else { 1.0 };
        let rotation =
            Quat::from_xyzw((q[0] / scale) as f32, (q[1] / scale) as f32, (q[2] / scale) as f32, (q[3] / scale) as f32);
        let translation = Vec3::new(values[0] as f32, values[1] as f32, values[2] as f32);

        if let Some(cols) = gravity_columns {
            let mut g = [0f64; 3];
            for (v, &c) in g.iter_mut().zip(&cols) {
                *v = parse_finite(file, at(c), field(c))?;
            }
            let len = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            let cos_tilt = if len > 0.0 { -g[up.index()] / len } else { -1.0 };
            if cos_tilt < MAX_GRAVITY_TILT_DEG.to_radians().cos() {
                return Err(ImportError::invalid(
                    file,
                    Location::LineField { line, field: "gravity_x_world..gravity_z_world".into() },
                    format!(
                        "gravity along {} of the world (a gravity-aligned world, within {MAX_GRAVITY_TILT_DEG}°)",
                        up.name()
                    ),
                    format!("({}, {}, {})", g[0], g[1], g[2]),
                ));
            }
        }
        if let Some(c) = graph_column {
            let uid = field(c);
            match &graph {
                None => graph = Some(uid.to_owned()),
                Some(first) if first != uid => {
                    return Err(ImportError::invalid(
                        file,
                        at(c),
                        format!(
                            "one graph_uid per trajectory ({} — poses of different graphs do not share a world frame)",
                            quote(first, 40)
                        ),
                        quote(uid, 40),
                    ));
                }
                Some(_) => {}
            }
        }
        out.timestamps_ns.push(t_ns);
        out.poses.push(RigidTransform { rotation, translation });
    }
    if out.poses.is_empty() {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: "at least one pose row after the header".into() },
        ));
    }
    Ok(out)
}

fn parse_finite(file: &str, at: Location, raw: &str) -> Result<f64, ImportError> {
    match raw.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(ImportError::invalid(file, at, "a finite number", quote(raw, 40))),
    }
}

fn csv_error(file: &str, e: &csv::Error) -> ImportError {
    let line = e.position().map_or(0, |p| p.line());
    let location = if line > 0 { Location::Line(line) } else { Location::File };
    match e.kind() {
        csv::ErrorKind::UnequalLengths { expected_len, len, .. } => ImportError::invalid(
            file,
            location,
            format!("{expected_len} fields (as many as the header has)"),
            format!("{len} fields"),
        ),
        csv::ErrorKind::Utf8 { .. } => ImportError::invalid(file, location, "UTF-8 text", "invalid UTF-8"),
        _ => ImportError::new(file, location, ImportErrorKind::Csv(e.to_string())),
    }
}

/// Writes an MPS-layout `closed_loop_trajectory.csv` plus the `tracking_timestamp_ns`
/// column. `gravity_world` is written per row (the session world's gravity); velocities are
/// not kept by sessions and are written as 0; `utc_timestamp_ns` as −1 (unknown);
/// `quality_score` as 1.
pub fn write_closed_loop_trajectory(
    timestamps_ns: &[i64],
    poses: &[RigidTransform],
    graph_uid: &str,
    gravity_world: Vec3,
) -> String {
    let mut out = String::with_capacity(timestamps_ns.len() * 200 + 512);
    out.push_str(&MPS_COLUMNS.join(","));
    out.push_str(",tracking_timestamp_ns\n");
    for (&t, pose) in timestamps_ns.iter().zip(poses) {
        let q = pose.rotation;
        let p = pose.translation;
        let _ = writeln!(
            out,
            "{graph_uid},{},-1,{},{},{},{},{},{},{},0,0,0,0,0,0,{},{},{},1,{t}",
            t.div_euclid(1000),
            p.x,
            p.y,
            p.z,
            q.x,
            q.y,
            q.z,
            q.w,
            gravity_world.x,
            gravity_world.y,
            gravity_world.z,
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "graph_uid,tracking_timestamp_us,utc_timestamp_ns,tx_world_device,ty_world_device,tz_world_device,qx_world_device,qy_world_device,qz_world_device,qw_world_device,device_linear_velocity_x_device,device_linear_velocity_y_device,device_linear_velocity_z_device,angular_velocity_x_device,angular_velocity_y_device,angular_velocity_z_device,gravity_x_world,gravity_y_world,gravity_z_world,quality_score";

    #[test]
    fn reads_mps_rows_in_nanoseconds() {
        let csv = format!(
            "{HEADER},geo_available\n\
             g1,1000,1700000000000000000,0.1,0.2,1.5,0,0,0,1,0,0,0,0,0,0,0,0,-9.81,1.0,0\n\
             g1,2000,1700000000001000000,0.1,0.2,1.5,0,0,0.7071068,0.7071068,0,0,0,0,0,0,0,0,-9.81,1.0,0\n"
        );
        let t = read_closed_loop_trajectory("x.csv", csv.as_bytes(), Clock::Device, WorldUp::Z).unwrap();
        assert_eq!(t.timestamps_ns, vec![1_000_000, 2_000_000]);
        assert!(t.poses[1].rotation.abs_diff_eq(Quat::from_rotation_z(std::f32::consts::FRAC_PI_2), 1e-6));
        let utc = read_closed_loop_trajectory("x.csv", csv.as_bytes(), Clock::Utc, WorldUp::Z).unwrap();
        assert_eq!(utc.timestamps_ns, vec![1_700_000_000_000_000_000, 1_700_000_000_001_000_000]);
    }

    #[test]
    fn writer_round_trips_exactly() {
        let poses = vec![
            RigidTransform::new(Quat::from_rotation_y(0.3), Vec3::new(1.25, -0.1, 3.0)),
            RigidTransform::new(Quat::from_rotation_x(-1.1), Vec3::new(0.123_456_79, 7.0, -2.5)),
        ];
        let ts = vec![-5, 33_333_333];
        let text = write_closed_loop_trajectory(&ts, &poses, "session", Vec3::new(0.0, -9.81, 0.0));
        let back = read_closed_loop_trajectory("t.csv", text.as_bytes(), Clock::Device, WorldUp::Y).unwrap();
        assert_eq!(back.timestamps_ns, ts);
        for (a, b) in back.poses.iter().zip(&poses) {
            assert!(a.rotation.abs_diff_eq(b.rotation, 1e-7) && a.translation == b.translation);
        }
    }
}
