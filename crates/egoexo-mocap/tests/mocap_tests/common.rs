//! Shared helpers for the tests that read the real CMU subset in `shared/data/cmu`.

#![allow(dead_code)]

use egoexo_mocap::fs::{read_catalog, read_text};
use egoexo_mocap::{Catalog, SubjectImporter};
pub use egoexo_test_support::cmu_dir;

/// Returns from the test (skipping it, with a message) when the data is absent.
macro_rules! require_cmu {
    () => {
        match $crate::common::cmu_dir() {
            Some(dir) => dir,
            None => return,
        }
    };
}

pub fn catalog(dir: &std::path::Path) -> Catalog {
    read_catalog(&dir.join("CMU_data.csv")).expect("CMU_data.csv parses")
}

pub fn subject(dir: &std::path::Path, subject: u32) -> SubjectImporter {
    let path = dir.join(format!("{subject:02}/{subject:02}.asf"));
    SubjectImporter::new(subject, &read_text(&path).unwrap(), &path.display().to_string()).expect("ASF imports")
}

pub fn amc(dir: &std::path::Path, subject: u32, trial: u32) -> (String, String) {
    let path = dir.join(format!("{subject:02}/{subject:02}_{trial:02}.amc"));
    (read_text(&path).unwrap(), path.display().to_string())
}
