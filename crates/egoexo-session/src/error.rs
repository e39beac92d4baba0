//! Import errors: every one names the file, the place in it (line, column or field) and what
//! was expected, so a person can fix the input.

use std::fmt;

use thiserror::Error;

/// Where in a file a problem was found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Location {
    /// The file as a whole.
    File,
    /// A 1-based line (CSV row, JSON-lines record).
    Line(u64),
    /// A 1-based line and a named column or field on it.
    LineField { line: u64, field: String },
    /// A named field (JSON path such as `observers[0].camera.params`, or an npz array name).
    Field(String),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::File => Ok(()),
            Location::Line(line) => write!(f, ", line {line}"),
            Location::LineField { line, field } => write!(f, ", line {line}, field `{field}`"),
            Location::Field(field) => write!(f, ", field `{field}`"),
        }
    }
}

/// What went wrong (see [`ImportError`] for where).
#[derive(Clone, Debug, PartialEq, Error)]
pub enum ImportErrorKind {
    /// A required file is absent.
    #[error("file not found; expected {expected}")]
    MissingFile { expected: String },
    /// A CSV header lacks a required column.
    #[error("missing column `{column}`; expected the columns {expected} (found: {found})")]
    MissingColumn { column: String, expected: String, found: String },
    /// A value is malformed or out of range.
    #[error("expected {expected}, got {got}")]
    Invalid { expected: String, got: String },
    /// The file has no content.
    #[error("the file is empty; expected {expected}")]
    Empty { expected: String },
    /// Timestamps must increase strictly.
    #[error(
        "timestamp {got} ns is not after the previous one ({previous} ns); expected strictly increasing timestamps"
    )]
    NonMonotonicTimestamp { previous: i64, got: i64 },
    /// Two records share one timestamp.
    #[error("duplicate timestamp {0} ns; expected strictly increasing timestamps")]
    DuplicateTimestamp(i64),
    /// A rotation quaternion is far from unit length.
    #[error("quaternion has norm {norm}; expected a unit quaternion (|q| = 1 ± {tolerance})")]
    NonUnitQuaternion { norm: f64, tolerance: f64 },
    /// A size or count exceeds a safety limit.
    #[error("{what} is {size}, over the limit of {limit}")]
    TooLarge { what: String, size: u64, limit: u64 },
    /// A zip entry's path leaves the archive root or is otherwise unsafe.
    #[error(
        "entry path `{path}` is not a safe relative path (absolute, `..`, or empty components); expected paths inside the session root"
    )]
    UnsafePath { path: String },
    /// The container is not a readable zip archive.
    #[error("not a readable zip archive (truncated or corrupt?): {0}")]
    Zip(String),
    /// Syntactically invalid JSON.
    #[error("invalid JSON: {0}")]
    Json(String),
    /// A manifest that does not have the format's shape: a missing field, a value of the wrong
    /// type, an unknown variant (serde's words; the location names the field).
    #[error("{0}")]
    Manifest(String),
    /// A CSV row could not be read.
    #[error("invalid CSV: {0}")]
    Csv(String),
    /// An `.npy` array inside an `.npz` could not be read.
    #[error("invalid .npy array: {0}")]
    Npy(String),
    /// A manifest of a schema version this build cannot read.
    #[error("unsupported schema version {got}; this build reads versions {oldest} to {newest}")]
    UnsupportedVersion { got: String, oldest: u32, newest: u32 },
    /// A file names an observer other than the one it belongs to.
    #[error("observer id `{got}` does not match `{expected}`")]
    ObserverMismatch { expected: String, got: String },
    /// A keypoint record does not hold the 17 COCO keypoints.
    #[error("expected 17 COCO keypoints (x, y, score), got {got}")]
    KeypointCount { got: usize },
    /// Streams that should share a clock do not.
    #[error("mixed clocks: {detail}")]
    MixedClocks { detail: String },
    /// No importer recognises the input.
    #[error(
        "not a recognised session; expected a `.egoexo` (session.json), a Nymeria sequence (recording_head/), a multi-device Aria MPS folder (wearer/, observers/<id>/) or one Aria MPS device folder (closed_loop_trajectory.csv); found: {found}"
    )]
    Unrecognized { found: String },
}

/// An import (or validation) error: the file, where in it, and what was expected.
#[derive(Clone, Debug, PartialEq, Error)]
#[error("{file}{location}: {kind}")]
pub struct ImportError {
    /// Path of the offending file relative to the session root (or the input's name).
    pub file: String,
    /// Where in the file.
    pub location: Location,
    /// What went wrong (boxed to keep `Result<_, ImportError>` small).
    pub kind: Box<ImportErrorKind>,
}

impl ImportError {
    /// A new error.
    pub fn new(file: impl Into<String>, location: Location, kind: ImportErrorKind) -> Self {
        Self { file: file.into(), location, kind: Box::new(kind) }
    }

    /// "expected …, got …" at a location.
    pub fn invalid(
        file: impl Into<String>,
        location: Location,
        expected: impl Into<String>,
        got: impl Into<String>,
    ) -> Self {
        Self::new(file, location, ImportErrorKind::Invalid { expected: expected.into(), got: got.into() })
    }

    /// A required file is missing.
    pub fn missing_file(file: impl Into<String>, expected: impl Into<String>) -> Self {
        Self::new(file, Location::File, ImportErrorKind::MissingFile { expected: expected.into() })
    }
}

/// Something an importer noticed that does not stop the import (an assumption it made, data
/// it dropped on purpose); `egoexo inspect` lists these as problems.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImportWarning {
    /// The file concerned (relative to the session root), or the stream.
    pub file: String,
    pub message: String,
}

impl fmt::Display for ImportWarning {
    /// `file: message`, or the message alone when the warning is about the whole session
    /// (no file: a dropped folder's root has an empty path).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.file.is_empty() { f.write_str(&self.message) } else { write!(f, "{}: {}", self.file, self.message) }
    }
}

/// Shortens untrusted text quoted in an error message (at most `max` characters).
pub(crate) fn quote(text: &str, max: usize) -> String {
    let mut out: String = text.chars().take(max).collect();
    if text.chars().count() > max {
        out.push('…');
    }
    format!("`{out}`")
}

/// `t_ns` must come strictly after `previous` (the last timestamp read, if any): a duplicate
/// or a step back is an error at `at`, built only then.
pub(crate) fn check_strictly_after(
    file: &str,
    at: impl FnOnce() -> Location,
    previous: Option<i64>,
    t_ns: i64,
) -> Result<(), ImportError> {
    match previous {
        Some(previous) if t_ns == previous => {
            Err(ImportError::new(file, at(), ImportErrorKind::DuplicateTimestamp(t_ns)))
        }
        Some(previous) if t_ns < previous => {
            Err(ImportError::new(file, at(), ImportErrorKind::NonMonotonicTimestamp { previous, got: t_ns }))
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_warning_about_the_whole_session_has_no_stray_colon() {
        let w = |file: &str| ImportWarning { file: file.into(), message: "one device: no observers".into() };
        assert_eq!(w("").to_string(), "one device: no observers");
        assert_eq!(w("wearer/a.csv").to_string(), "wearer/a.csv: one device: no observers");
    }

    #[test]
    fn message_names_file_line_field_and_expectation() {
        let e = ImportError::invalid(
            "wearer/closed_loop_trajectory.csv",
            Location::LineField { line: 7, field: "qw_world_device".into() },
            "a finite number",
            "`NaN`",
        );
        assert_eq!(
            e.to_string(),
            "wearer/closed_loop_trajectory.csv, line 7, field `qw_world_device`: expected a finite number, got `NaN`"
        );
    }

    #[test]
    fn quote_truncates_long_text() {
        assert_eq!(quote("abcdef", 3), "`abc…`");
        assert_eq!(quote("ab", 3), "`ab`");
    }
}
