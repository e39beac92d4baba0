//! Aria MPS semidense points (`global_points.csv.gz`, older outputs `semidense_points.csv.gz`;
//! plain `.csv` too) read as a histogram of heights for the floor estimate
//! ([`crate::floor`]).
//!
//! Columns: `uid, graph_uid, px_world, py_world, pz_world, inv_dist_std, dist_std` (metres,
//! the trajectory's world). Only well-constrained points are kept, with projectaria_tools'
//! defaults (`filterPointsFromConfidence`): `inv_dist_std ≤ 0.001` and `dist_std ≤ 0.05`.
//! The file is streamed through the decompressor: a recording's millions of points cost a
//! fixed-size histogram, not a list.

use std::io::Read;

use egoexo_core::glam::DVec3;
use egoexo_core::rigid::RigidTransform;

use crate::error::{ImportError, ImportErrorKind, Location, quote};
use crate::floor::HeightHistogram;

/// The MPS file names, newest first.
pub const SEMIDENSE_FILES: [&str; 4] =
    ["global_points.csv.gz", "semidense_points.csv.gz", "global_points.csv", "semidense_points.csv"];
/// Largest accepted `inv_dist_std` (projectaria_tools' default).
pub const MAX_INV_DIST_STD: f64 = 0.001;
/// Largest accepted `dist_std`, metres (projectaria_tools' default).
pub const MAX_DIST_STD_M: f64 = 0.05;
/// Rows between progress reports.
pub const PROGRESS_EVERY_ROWS: u64 = 1 << 17;

/// What reading the points found.
#[derive(Clone, Debug, PartialEq)]
pub struct SemidenseHeights {
    /// Heights (session Y) of the kept points.
    pub heights: HeightHistogram,
    /// Rows in the file.
    pub rows: u64,
}

/// Reads semidense points from `reader` (gzip when `file` ends in `.gz`), keeps the
/// well-constrained ones and bins their heights in the session world, with `t_session_file`
/// from [`crate::aria::t_session_world_from_gravity`] of the trajectory in the same world.
/// `progress` gets the rows read so far.
pub fn read_semidense_heights(
    file: &str,
    reader: impl Read,
    t_session_file: &RigidTransform,
    progress: &mut dyn FnMut(u64),
) -> Result<SemidenseHeights, ImportError> {
    let reader: Box<dyn Read + '_> = if file.ends_with(".gz") {
        Box::new(flate2::read::MultiGzDecoder::new(std::io::BufReader::new(reader)))
    } else {
        Box::new(reader)
    };
    let mut csv = csv::ReaderBuilder::new().has_headers(true).trim(csv::Trim::All).from_reader(reader);
    let headers = match csv.headers() {
        Ok(h) => h.clone(),
        Err(e) => return Err(gzip_or_csv_error(file, &e)),
    };
    if headers.iter().all(str::is_empty) {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: "a semidense point header and rows".into() },
        ));
    }
    let required = |name: &str| {
        headers.iter().position(|h| h == name).ok_or_else(|| {
            ImportError::new(
                file,
                Location::Line(1),
                ImportErrorKind::MissingColumn {
                    column: name.into(),
                    expected: "of MPS global_points.csv (px_world, py_world, pz_world, inv_dist_std, dist_std)".into(),
                    found: headers.iter().take(12).map(|h| quote(h, 40)).collect::<Vec<_>>().join(", "),
                },
            )
        })
    };
    let columns = [
        required("px_world")?,
        required("py_world")?,
        required("pz_world")?,
        required("inv_dist_std")?,
        required("dist_std")?,
    ];
    let rotation = t_session_file.rotation.as_dquat();
    let mut out = SemidenseHeights { heights: HeightHistogram::new(), rows: 0 };
    let mut record = csv::ByteRecord::new();
    loop {
        match csv.read_byte_record(&mut record) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(gzip_or_csv_error(file, &e)),
        }
        out.rows += 1;
        let line = record.position().map_or(0, |p| p.line());
        let mut v = [0f64; 5];
        for (slot, &c) in v.iter_mut().zip(&columns) {
            let raw = record.get(c).unwrap_or_default();
            *slot = match std::str::from_utf8(raw).ok().and_then(|s| s.parse::<f64>().ok()) {
                Some(x) if x.is_finite() => x,
                _ => {
                    return Err(ImportError::invalid(
                        file,
                        Location::LineField { line, field: headers.get(c).unwrap_or_default().to_owned() },
                        "a finite number",
                        quote(&String::from_utf8_lossy(raw), 40),
                    ));
                }
            };
        }
        if v[3] <= MAX_INV_DIST_STD && v[4] <= MAX_DIST_STD_M {
            out.heights.add((rotation * DVec3::new(v[0], v[1], v[2])).y);
        }
        if out.rows.is_multiple_of(PROGRESS_EVERY_ROWS) {
            progress(out.rows);
        }
    }
    progress(out.rows);
    Ok(out)
}

/// A CSV error, or the gzip stream's error surfaced through it.
fn gzip_or_csv_error(file: &str, e: &csv::Error) -> ImportError {
    match e.kind() {
        csv::ErrorKind::Io(io) => ImportError::invalid(
            file,
            e.position().map_or(Location::File, |p| Location::Line(p.line())),
            "a gzip-compressed CSV file",
            io.to_string(),
        ),
        _ => crate::aria::trajectory::csv_error(file, e),
    }
}
