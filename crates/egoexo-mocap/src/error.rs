//! Errors of the parsers: every one names the file and, where there is one, the line.

use std::fmt;

use thiserror::Error;

/// Where in an input a problem is: a file (as the caller named it) and a 1-based line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceLocation {
    /// The name the caller gave the input (usually its path).
    pub file: String,
    /// 1-based line number; `None` when the problem concerns the file as a whole.
    pub line: Option<usize>,
}

impl fmt::Display for SourceLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{line}", self.file),
            None => write!(f, "{}", self.file),
        }
    }
}

/// A malformed ASF, AMC or catalogue file.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{location}: {kind}")]
pub struct ParseError {
    pub location: SourceLocation,
    pub kind: ParseErrorKind,
}

/// What was wrong.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ParseErrorKind {
    #[error("expected {expected}, found `{found}`")]
    Expected { expected: &'static str, found: String },
    #[error("expected {expected}, found the end of the file")]
    UnexpectedEnd { expected: &'static str },
    #[error("`{0}` is not a finite number")]
    BadNumber(String),
    #[error("unknown bone `{0}`")]
    UnknownBone(String),
    #[error("bone `{0}` is defined twice")]
    DuplicateBone(String),
    #[error("bone `{bone}` has {expected} degrees of freedom but {found} values")]
    WrongValueCount { bone: String, expected: usize, found: usize },
    #[error("bone `{bone}` has {dofs} degrees of freedom but {limits} limits")]
    LimitCountMismatch { bone: String, dofs: usize, limits: usize },
    #[error("frame {frame} does not give bone `{bone}`")]
    MissingBoneInFrame { frame: i64, bone: String },
    #[error("bone `{bone}` appears twice in frame {frame}")]
    RepeatedBoneInFrame { frame: i64, bone: String },
    #[error("frame number {found} follows frame {previous}; frames must count up by one")]
    FrameOutOfSequence { previous: i64, found: i64 },
    #[error("bone `{0}` is not attached to the root by the hierarchy")]
    Unattached(String),
    #[error("bone `{child}` has two parents (`{first}` and `{second}`)")]
    TwoParents { child: String, first: String, second: String },
    #[error("the hierarchy has a cycle through `{0}`")]
    Cycle(String),
    #[error("missing section `{0}`")]
    MissingSection(&'static str),
    #[error("{0}")]
    Invalid(String),
}

impl ParseError {
    pub(crate) fn at(file: &str, line: usize, kind: ParseErrorKind) -> Self {
        Self { location: SourceLocation { file: file.to_owned(), line: Some(line) }, kind }
    }

    pub(crate) fn in_file(file: &str, kind: ParseErrorKind) -> Self {
        Self { location: SourceLocation { file: file.to_owned(), line: None }, kind }
    }
}

/// Parses a finite number token.
pub(crate) fn parse_number(file: &str, line: usize, token: &str) -> Result<f64, ParseError> {
    match token.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(ParseError::at(file, line, ParseErrorKind::BadNumber(token.to_owned()))),
    }
}
