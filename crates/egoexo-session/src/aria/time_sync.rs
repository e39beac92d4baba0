//! `time_sync.csv`: maps one device's clock onto a clock shared by all devices of a session.
//!
//! Aria devices each have their own clock (MPS `tracking_timestamp_us`). When a recording was
//! synchronised (Aria TimeCode / TICSync, as in Nymeria, whose `body/` timestamps are on the
//! TimeCode clock), export the mapping next to each device's MPS output as
//! `time_sync.csv` with the header `device_time_ns,common_time_ns` and one row per sample,
//! e.g. with projectaria_tools (one row per second is plenty):
//!
//! ```python
//! for t in range(t_first, t_last, 1_000_000_000):
//!     print(f"{t},{vrs.convert_from_device_time_to_timecode_ns(t)}")
//! ```
//!
//! Rows must be strictly increasing in both columns. Between rows the mapping is linear;
//! before the first and after the last row the nearest row's offset is used.

use crate::error::{ImportError, ImportErrorKind, Location, quote};

/// The file name looked for in each device folder.
pub const TIME_SYNC_FILE: &str = "time_sync.csv";

/// A monotonic piecewise-linear map from a device clock to the common clock (ns).
#[derive(Clone, Debug, PartialEq)]
pub struct TimeSync {
    device_ns: Vec<i64>,
    common_ns: Vec<i64>,
}

impl TimeSync {
    /// Maps a device time; `None` if the result overflows i64.
    pub fn map(&self, t: i64) -> Option<i64> {
        let n = self.device_ns.len();
        let i = self.device_ns.partition_point(|&d| d <= t);
        if i == 0 || i == n {
            let j = if i == 0 { 0 } else { n - 1 };
            let offset = i128::from(self.common_ns[j]) - i128::from(self.device_ns[j]);
            return i64::try_from(i128::from(t) + offset).ok();
        }
        let (d0, d1) = (i128::from(self.device_ns[i - 1]), i128::from(self.device_ns[i]));
        let (c0, c1) = (i128::from(self.common_ns[i - 1]), i128::from(self.common_ns[i]));
        let value = c0 + (i128::from(t) - d0) * (c1 - c0) / (d1 - d0);
        i64::try_from(value).ok()
    }
}

/// Reads a `time_sync.csv`.
pub fn read_time_sync(file: &str, bytes: &[u8]) -> Result<TimeSync, ImportError> {
    let mut reader = csv::ReaderBuilder::new().has_headers(true).trim(csv::Trim::All).from_reader(bytes);
    let headers = reader
        .headers()
        .map_err(|e| ImportError::new(file, Location::Line(1), ImportErrorKind::Csv(e.to_string())))?
        .clone();
    let column = |name: &str| {
        headers.iter().position(|h| h == name).ok_or_else(|| {
            ImportError::new(
                file,
                Location::Line(1),
                ImportErrorKind::MissingColumn {
                    column: name.into(),
                    expected: "`device_time_ns,common_time_ns`".into(),
                    found: headers.iter().take(8).map(|h| quote(h, 40)).collect::<Vec<_>>().join(", "),
                },
            )
        })
    };
    let (dc, cc) = (column("device_time_ns")?, column("common_time_ns")?);
    let mut sync = TimeSync { device_ns: Vec::new(), common_ns: Vec::new() };
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            ImportError::new(file, Location::Line(line), ImportErrorKind::Csv(e.to_string()))
        })?;
        let line = record.position().map_or(0, |p| p.line());
        let mut values = [0i64; 2];
        for (slot, (c, name)) in values.iter_mut().zip([(dc, "device_time_ns"), (cc, "common_time_ns")]) {
            let raw = record.get(c).unwrap_or_default();
            *slot = raw.parse().map_err(|_| {
                ImportError::invalid(
                    file,
                    Location::LineField { line, field: name.into() },
                    "an integer timestamp in nanoseconds",
                    quote(raw, 40),
                )
            })?;
        }
        if let (Some(&d), Some(&c)) = (sync.device_ns.last(), sync.common_ns.last())
            && (values[0] <= d || values[1] <= c)
        {
            return Err(ImportError::invalid(
                file,
                Location::Line(line),
                "rows strictly increasing in both device_time_ns and common_time_ns",
                format!("{},{} after {d},{c}", values[0], values[1]),
            ));
        }
        sync.device_ns.push(values[0]);
        sync.common_ns.push(values[1]);
    }
    if sync.device_ns.is_empty() {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: "at least one `device_time_ns,common_time_ns` row".into() },
        ));
    }
    Ok(sync)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_linearly_and_extends_offsets() {
        let sync = read_time_sync("t.csv", b"device_time_ns,common_time_ns\n100,1100\n200,1300\n").unwrap();
        assert_eq!(sync.map(150), Some(1200));
        assert_eq!(sync.map(50), Some(1050));
        assert_eq!(sync.map(300), Some(1400));
        assert_eq!(sync.map(i64::MAX), None);
        let err = read_time_sync("t.csv", b"device_time_ns,common_time_ns\n100,1100\n100,1300\n").unwrap_err();
        assert!(err.to_string().starts_with("t.csv, line 3: expected rows strictly increasing"), "{err}");
    }
}
