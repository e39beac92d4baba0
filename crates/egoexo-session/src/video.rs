//! Observers' RGB video in sessions: where a device folder keeps it and when its frames were
//! taken.
//!
//! An Aria observer folder (one device of the multi-device layout, or a single device) may hold
//! its RGB stream exported to MP4 — `<name>.mp4` at the folder's root or in `video/` — with a
//! timestamps file next to it, `<name>.timestamps.csv`: a header row with a
//! `capture_timestamp_ns` column, then one row per video frame in presentation order, the
//! frame's capture time on the device clock (what projectaria_tools' `ImageDataRecord.
//! capture_timestamp_ns` gives; `docs/session-format.md` shows the export). The import maps
//! them onto the session clock like the device's trajectory (its `time_sync.csv`). A `.egoexo`
//! stores the mapped times in `video_timestamps.csv` (column `timestamp_ns`).

use crate::error::{ImportError, ImportErrorKind, Location};
use crate::vfs::FileTree;

/// Column of the per-frame times in a device folder's `<name>.timestamps.csv`.
pub const CAPTURE_TIMESTAMP_COLUMN: &str = "capture_timestamp_ns";
/// Column of the per-frame session-clock times in a `.egoexo`'s `video_timestamps.csv`.
pub const SESSION_TIMESTAMP_COLUMN: &str = "timestamp_ns";
/// At most this many frames are read (10 hours at 30 fps).
pub const MAX_VIDEO_FRAMES: usize = 1_080_000;

/// The MP4 of a device folder `dir` and its timestamps file: `None` when there is no MP4;
/// an error when there are several or the timestamps file is missing.
pub fn find_device_video(dir: &FileTree) -> Result<Option<(String, String)>, ImportError> {
    let videos: Vec<String> = dir
        .paths()
        .into_iter()
        .filter(|p| {
            let lower = p.to_ascii_lowercase();
            lower.ends_with(".mp4")
                && (!p.contains('/') || (lower.starts_with("video/") && p.matches('/').count() == 1))
        })
        .collect();
    let video = match &videos[..] {
        [] => return Ok(None),
        [one] => one.clone(),
        several => {
            return Err(ImportError::invalid(
                dir.display_path(""),
                Location::File,
                "at most one MP4 video per observer folder (its RGB stream)",
                several.join(", "),
            ));
        }
    };
    let stem = &video[..video.len() - 4];
    let timestamps = format!("{stem}.timestamps.csv");
    if !dir.contains(&timestamps) {
        return Err(ImportError::missing_file(
            dir.display_path(&timestamps),
            format!(
                "the capture times of {}'s frames: a CSV with a `{CAPTURE_TIMESTAMP_COLUMN}` column, one row per frame in presentation order (docs/session-format.md shows how to export it with the MP4)",
                dir.display_path(&video)
            ),
        ));
    }
    Ok(Some((video, timestamps)))
}

/// Reads the `column` of a per-frame timestamps CSV (`file` names it in errors): integers,
/// nanoseconds, strictly increasing.
pub fn read_frame_timestamps(file: &str, bytes: &[u8], column: &str) -> Result<Vec<i64>, ImportError> {
    let mut reader = csv::ReaderBuilder::new().has_headers(true).trim(csv::Trim::All).from_reader(bytes);
    let headers = reader
        .headers()
        .map_err(|e| ImportError::new(file, Location::Line(1), ImportErrorKind::Csv(e.to_string())))?
        .clone();
    let c = headers.iter().position(|h| h == column).ok_or_else(|| {
        ImportError::new(
            file,
            Location::Line(1),
            ImportErrorKind::MissingColumn {
                column: column.into(),
                expected: format!("a `{column}` column (nanoseconds, one row per video frame)"),
                found: headers.iter().take(8).collect::<Vec<_>>().join(", "),
            },
        )
    })?;
    let mut times: Vec<i64> = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            ImportError::new(file, Location::Line(line), ImportErrorKind::Csv(e.to_string()))
        })?;
        let line = record.position().map_or(0, |p| p.line());
        let raw = record.get(c).unwrap_or_default();
        let at = Location::LineField { line, field: column.into() };
        let t: i64 = raw
            .parse()
            .map_err(|_| ImportError::invalid(file, at.clone(), "an integer timestamp in nanoseconds", raw))?;
        if let Some(&last) = times.last()
            && t <= last
        {
            return Err(ImportError::invalid(file, at, format!("a time after the previous frame's {last}"), raw));
        }
        if times.len() == MAX_VIDEO_FRAMES {
            return Err(ImportError::invalid(file, at, format!("at most {MAX_VIDEO_FRAMES} frames"), "more"));
        }
        times.push(t);
    }
    if times.is_empty() {
        return Err(ImportError::invalid(file, Location::File, "one row per video frame", "no rows"));
    }
    Ok(times)
}

/// A timestamps CSV of session-clock times (`.egoexo`'s `video_timestamps.csv`).
pub fn write_frame_timestamps(times: &[i64]) -> String {
    let mut out = String::with_capacity(times.len() * 20 + 16);
    out.push_str(SESSION_TIMESTAMP_COLUMN);
    out.push('\n');
    for t in times {
        out.push_str(&t.to_string());
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_read_back_and_bad_rows_are_named() {
        let text = write_frame_timestamps(&[10, 20, 35]);
        assert_eq!(read_frame_timestamps("t.csv", text.as_bytes(), SESSION_TIMESTAMP_COLUMN).unwrap(), [10, 20, 35]);
        let err = read_frame_timestamps("t.csv", b"timestamp_ns\n10\n10\n", SESSION_TIMESTAMP_COLUMN).unwrap_err();
        assert_eq!(err.location, Location::LineField { line: 3, field: "timestamp_ns".into() });
        let err = read_frame_timestamps("t.csv", b"timestamp_ns\n10\nabc\n", SESSION_TIMESTAMP_COLUMN).unwrap_err();
        assert!(err.to_string().contains("t.csv") && err.to_string().contains("abc"), "{err}");
        let err = read_frame_timestamps("t.csv", b"frame,time\n1,2\n", CAPTURE_TIMESTAMP_COLUMN).unwrap_err();
        assert!(matches!(*err.kind, ImportErrorKind::MissingColumn { .. }), "{err}");
        assert!(read_frame_timestamps("t.csv", b"timestamp_ns\n", SESSION_TIMESTAMP_COLUMN).is_err());
    }
}
