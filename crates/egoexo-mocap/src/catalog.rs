//! `CMU_data.csv`: the list of CMU trials with their descriptions and true capture rates.
//!
//! Columns used (by header name): `Subject`, `Trial #`, `Motion Description`, `framerate`
//! (frames per second: 120 for most subjects, 60 for some). Parsed from bytes.

use std::collections::BTreeMap;

use crate::error::{ParseError, ParseErrorKind};

/// One trial of the catalogue.
#[derive(Clone, Debug, PartialEq)]
pub struct CatalogEntry {
    /// Motion description, e.g. `walk`.
    pub description: String,
    /// True capture rate, frames per second.
    pub framerate: f32,
}

/// The CMU trial catalogue, keyed by (subject, trial).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Catalog {
    entries: BTreeMap<(u32, u32), CatalogEntry>,
}

impl Catalog {
    /// Parses `CMU_data.csv` bytes. `file` names the input in errors.
    pub fn parse(bytes: &[u8], file: &str) -> Result<Self, ParseError> {
        let mut reader = csv::ReaderBuilder::new().flexible(true).from_reader(bytes);
        let headers = reader
            .headers()
            .map_err(|e| ParseError::at(file, 1, ParseErrorKind::Invalid(format!("cannot read the header: {e}"))))?
            .clone();
        let column = |name: &'static str| {
            headers.iter().position(|h| h.trim().eq_ignore_ascii_case(name)).ok_or_else(|| {
                ParseError::at(
                    file,
                    1,
                    ParseErrorKind::Expected { expected: name, found: headers.iter().collect::<Vec<_>>().join(",") },
                )
            })
        };
        let subject_col = column("Subject")?;
        let trial_col = column("Trial #")?;
        let description_col = column("Motion Description")?;
        let rate_col = column("framerate")?;

        let mut entries = BTreeMap::new();
        for record in reader.records() {
            let record = record.map_err(|e| {
                let line = e.position().map_or(0, |p| p.line() as usize);
                ParseError::at(file, line, ParseErrorKind::Invalid(e.to_string()))
            })?;
            let line = record.position().map_or(0, |p| p.line() as usize);
            if record.iter().all(|f| f.trim().is_empty()) {
                continue;
            }
            let field = |col: usize| record.get(col).unwrap_or("").trim();
            let integer = |col: usize, expected: &'static str| {
                field(col).parse::<u32>().map_err(|_| {
                    ParseError::at(file, line, ParseErrorKind::Expected { expected, found: field(col).to_owned() })
                })
            };
            let subject = integer(subject_col, "a subject number")?;
            let trial = integer(trial_col, "a trial number")?;
            let framerate = match field(rate_col).parse::<f32>() {
                Ok(r) if r.is_finite() && r > 0.0 => r,
                _ => {
                    return Err(ParseError::at(
                        file,
                        line,
                        ParseErrorKind::Expected {
                            expected: "a positive frame rate in `framerate`",
                            found: field(rate_col).to_owned(),
                        },
                    ));
                }
            };
            let description = field(description_col).to_owned();
            entries.insert((subject, trial), CatalogEntry { description, framerate });
        }
        Ok(Self { entries })
    }

    /// The entry of a trial.
    pub fn get(&self, subject: u32, trial: u32) -> Option<&CatalogEntry> {
        self.entries.get(&(subject, trial))
    }

    /// Adds or replaces an entry.
    pub fn insert(&mut self, subject: u32, trial: u32, entry: CatalogEntry) {
        self.entries.insert((subject, trial), entry);
    }

    /// Number of trials listed.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// No trials listed.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_quoted_descriptions_and_rates() {
        let csv = "\"Subject\",\"Trial #\",\"Motion Description\",\"framerate\",\"Frames 60fps\"\n\
                   2,1,\"walk\",120,171\n33,2,\"football - throw, catch\",60,,\n";
        let c = Catalog::parse(csv.as_bytes(), "CMU_data.csv").unwrap();
        assert_eq!(c.len(), 2);
        assert_eq!(c.get(33, 2).unwrap().description, "football - throw, catch");
        assert_eq!(c.get(33, 2).unwrap().framerate, 60.0);
        assert_eq!(c.get(2, 1).unwrap().framerate, 120.0);
    }

    #[test]
    fn a_bad_rate_names_the_line() {
        let csv = "Subject,Trial #,Motion Description,framerate\n2,1,walk,120\n2,2,walk,fast\n";
        let err = Catalog::parse(csv.as_bytes(), "c.csv").unwrap_err();
        assert_eq!(err.location.line, Some(3), "{err}");
    }
}
