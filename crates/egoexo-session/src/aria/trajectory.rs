//! Aria MPS `closed_loop_trajectory.csv`: reader and writer.
//!
//! Columns (MPS): `graph_uid, tracking_timestamp_us, utc_timestamp_ns, tx_world_device,
//! ty_world_device, tz_world_device, qx_world_device, qy_world_device, qz_world_device,
//! qw_world_device, device_linear_velocity_{x,y,z}_device, angular_velocity_{x,y,z}_device,
//! gravity_{x,y,z}_world, quality_score`; extra columns are ignored, columns are found by
//! name. The reader needs the timestamp of the chosen [`Clock`], the pose columns and
//! `gravity_*_world`: MPS worlds are gravity-aligned with gravity along −Z, but other Aria
//! tooling writes this layout in Y-up worlds (Aria Digital Twin: gravity (0, −9.81, 0)), so the
//! file's gravity, not an assumption, says which way is down. It must be present, non-zero and
//! the same on every row; `graph_uid` must not change within a file (poses of different graphs
//! do not share a world frame). Runs of rows with `quality_score` below [`LOW_QUALITY_SCORE`]
//! are reported (SLAM starts with such a stretch), not dropped. The reader streams: an hour at
//! 1 kHz (3.6 M rows) costs the poses it keeps, not the file.
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

use crate::error::{ImportError, ImportErrorKind, Location, check_strictly_after, quote};

/// Which timestamp column gives the time of a pose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Clock {
    /// `tracking_timestamp_us` (or `tracking_timestamp_ns`): the device's own clock.
    #[default]
    Device,
    /// `utc_timestamp_ns`: wall-clock time, shared by devices whose phones were synchronised.
    Utc,
}

/// Tolerance on `|q|` before normalising a stored quaternion.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;
/// Largest accepted change of `gravity_*_world` within one file, as a fraction of its length
/// (MPS writes one gravity vector per world; a change means two worlds were concatenated).
pub const MAX_GRAVITY_CHANGE: f64 = 1e-3;
/// Shortest accepted `|gravity_world|`, m/s² (a zero vector has no direction).
pub const MIN_GRAVITY_NORM: f64 = 0.1;
/// `quality_score` below this marks a pose as low quality (MPS scores lie in [0, 1]; a
/// closed-loop trajectory starts with a stretch of low scores while SLAM initialises).
pub const LOW_QUALITY_SCORE: f64 = 0.5;
/// Rows between two progress reports of [`read_closed_loop_trajectory`].
pub const PROGRESS_EVERY_ROWS: usize = 1 << 16;
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

/// A trajectory as stored in a file: strictly increasing timestamps (ns) and `T_world_device`
/// of the file's world, plus what the file says about that world and the poses' quality.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CsvTrajectory {
    pub timestamps_ns: Vec<i64>,
    pub poses: Vec<RigidTransform>,
    /// `gravity_{x,y,z}_world`, m/s² in the file's world (the same on every row).
    pub gravity_world: Vec3,
    /// Runs of consecutive rows whose `quality_score` is below [`LOW_QUALITY_SCORE`].
    pub low_quality: Vec<QualitySpan>,
}

/// Consecutive low-quality rows of a trajectory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QualitySpan {
    /// Timestamps of the first and last row of the run, ns (the file's clock).
    pub start_ns: i64,
    pub end_ns: i64,
    pub rows: usize,
}

/// Reads a `closed_loop_trajectory.csv` from `reader`, streaming (memory grows with the poses
/// kept, not with the file). `file` names it in errors; `progress` is called with the bytes
/// read so far every [`PROGRESS_EVERY_ROWS`] rows and once at the end.
///
/// Gravity is required: every row's `gravity_*_world` must be finite, at least
/// [`MIN_GRAVITY_NORM`] long, and equal to the first row's within [`MAX_GRAVITY_CHANGE`]. Its
/// direction is the file's "down" (see [`crate::aria::t_session_world_from_gravity`]).
pub fn read_closed_loop_trajectory(
    file: &str,
    reader: impl std::io::Read,
    clock: Clock,
    progress: &mut dyn FnMut(u64),
) -> Result<CsvTrajectory, ImportError> {
    // Fields are trimmed where they are read, not by the CSV reader (which would rebuild every
    // record: a tenth of the time at 1 kHz).
    let mut reader = csv::ReaderBuilder::new().has_headers(true).from_reader(reader);
    let headers = match reader.headers() {
        Ok(h) => h.iter().map(str::trim).collect::<csv::StringRecord>(),
        Err(e) => return Err(csv_error(file, &e)),
    };
    if headers.iter().all(str::is_empty) {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: "a closed_loop_trajectory.csv header and poses".into() },
        ));
    }
    let find = |name: &str| headers.iter().position(|h| h == name);
    let found = || {
        let mut s = headers.iter().take(24).map(|h| quote(h, 40)).collect::<Vec<_>>().join(", ");
        if headers.len() > 24 {
            s.push_str(", …");
        }
        s
    };
    let required = |name: &str, expected: &str| {
        find(name).ok_or_else(|| {
            ImportError::new(
                file,
                Location::Line(1),
                ImportErrorKind::MissingColumn { column: name.into(), expected: expected.into(), found: found() },
            )
        })
    };
    const OF_MPS: &str = "of Aria MPS closed_loop_trajectory.csv";
    let (time_column, time_scale): (usize, i64) = match clock {
        Clock::Device => match find("tracking_timestamp_ns") {
            Some(c) => (c, 1),
            None => (required("tracking_timestamp_us", OF_MPS)?, 1000),
        },
        Clock::Utc => (required("utc_timestamp_ns", OF_MPS)?, 1),
    };
    let time_name = headers.get(time_column).unwrap_or_default().to_owned();
    let mut pose_columns = [0usize; 7];
    for (slot, name) in pose_columns.iter_mut().zip(POSE_COLUMNS) {
        *slot = required(name, OF_MPS)?;
    }
    const GRAVITY: &str = "of Aria MPS closed_loop_trajectory.csv (the world's gravity gives its up axis)";
    let gravity_columns = [
        required("gravity_x_world", GRAVITY)?,
        required("gravity_y_world", GRAVITY)?,
        required("gravity_z_world", GRAVITY)?,
    ];
    let graph_column = find("graph_uid");
    let quality_column = find("quality_score");

    let mut out = CsvTrajectory::default();
    let mut graph: Option<String> = None;
    // The first row's gravity fields as written: rows that repeat them are not parsed again.
    let mut gravity_text: Option<[String; 3]> = None;
    let mut first_gravity = egoexo_core::glam::DVec3::ZERO;
    let mut low_run: Option<QualitySpan> = None;
    let mut record = csv::ByteRecord::new();
    loop {
        match reader.read_byte_record(&mut record) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(csv_error(file, &e)),
        }
        let line = record.position().map_or(0, |p| p.line());
        let at = |c: usize| Location::LineField { line, field: headers.get(c).unwrap_or_default().to_owned() };
        let field = |c: usize| -> Result<&str, ImportError> {
            std::str::from_utf8(record.get(c).unwrap_or_default().trim_ascii())
                .map_err(|_| ImportError::invalid(file, at(c), "UTF-8 text", "invalid UTF-8"))
        };

        let raw_time = field(time_column)?;
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
        check_strictly_after(file, || at(time_column), out.timestamps_ns.last().copied(), t_ns)?;

        let mut values = [0f64; 7];
        for (value, &c) in values.iter_mut().zip(&pose_columns) {
            *value = parse_finite(file, || at(c), field(c)?)?;
        }
        for (i, &c) in pose_columns.iter().enumerate().take(3) {
            if values[i].abs() > MAX_ABS_POSITION_M {
                return Err(ImportError::invalid(
                    file,
                    at(c),
                    format!("a position within ±{MAX_ABS_POSITION_M} m"),
                    field(c)?.to_owned(),
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

        let raw_gravity = [field(gravity_columns[0])?, field(gravity_columns[1])?, field(gravity_columns[2])?];
        let repeats_first =
            gravity_text.as_ref().is_some_and(|first| first.iter().zip(raw_gravity).all(|(a, b)| a == b));
        if !repeats_first {
            let gravity_at = || Location::LineField { line, field: "gravity_x_world..gravity_z_world".into() };
            let written = || format!("({}, {}, {})", raw_gravity[0], raw_gravity[1], raw_gravity[2]);
            let mut g = [0f64; 3];
            for ((v, &c), raw) in g.iter_mut().zip(&gravity_columns).zip(raw_gravity) {
                *v = parse_finite(file, || at(c), raw)?;
            }
            let g = egoexo_core::glam::DVec3::from_array(g);
            if g.length() < MIN_GRAVITY_NORM {
                return Err(ImportError::invalid(
                    file,
                    gravity_at(),
                    format!(
                        "a gravity vector at least {MIN_GRAVITY_NORM} m/s² long (its direction is the world's down)"
                    ),
                    written(),
                ));
            }
            match &gravity_text {
                None => {
                    out.gravity_world = g.as_vec3();
                    first_gravity = g;
                    gravity_text = Some(raw_gravity.map(str::to_owned));
                }
                Some(first_text) => {
                    if (g - first_gravity).length() > MAX_GRAVITY_CHANGE * first_gravity.length() {
                        return Err(ImportError::invalid(
                            file,
                            gravity_at(),
                            format!(
                                "the same gravity on every row (({}, {}, {}) from the first row — a world has one gravity)",
                                first_text[0], first_text[1], first_text[2]
                            ),
                            written(),
                        ));
                    }
                }
            }
        }
        if let Some(c) = quality_column {
            let raw = field(c)?;
            let score = parse_finite(file, || at(c), raw)?;
            if score < LOW_QUALITY_SCORE {
                let run = low_run.get_or_insert(QualitySpan { start_ns: t_ns, end_ns: t_ns, rows: 0 });
                run.end_ns = t_ns;
                run.rows += 1;
            } else if let Some(run) = low_run.take() {
                out.low_quality.push(run);
            }
        }
        if let Some(c) = graph_column {
            let uid = field(c)?;
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
        if out.poses.len().is_multiple_of(PROGRESS_EVERY_ROWS) {
            progress(record.position().map_or(0, |p| p.byte()));
        }
    }
    out.low_quality.extend(low_run);
    if out.poses.is_empty() {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: "at least one pose row after the header".into() },
        ));
    }
    progress(reader.position().byte());
    Ok(out)
}

/// `raw` as a finite number; `at` (built only on error) says where it was.
fn parse_finite(file: &str, at: impl FnOnce() -> Location, raw: &str) -> Result<f64, ImportError> {
    match raw.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(ImportError::invalid(file, at(), "a finite number", quote(raw, 40))),
    }
}

pub(crate) fn csv_error(file: &str, e: &csv::Error) -> ImportError {
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
        let t = read_closed_loop_trajectory("x.csv", csv.as_bytes(), Clock::Device, &mut |_| {}).unwrap();
        assert_eq!(t.gravity_world, Vec3::new(0.0, 0.0, -9.81));
        assert_eq!(t.timestamps_ns, vec![1_000_000, 2_000_000]);
        assert!(t.poses[1].rotation.abs_diff_eq(Quat::from_rotation_z(std::f32::consts::FRAC_PI_2), 1e-6));
        let utc = read_closed_loop_trajectory("x.csv", csv.as_bytes(), Clock::Utc, &mut |_| {}).unwrap();
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
        let back = read_closed_loop_trajectory("t.csv", text.as_bytes(), Clock::Device, &mut |_| {}).unwrap();
        assert_eq!(back.timestamps_ns, ts);
        for (a, b) in back.poses.iter().zip(&poses) {
            assert!(a.rotation.abs_diff_eq(b.rotation, 1e-7) && a.translation == b.translation);
        }
    }
}
