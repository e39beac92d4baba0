//! Shared helpers for the tests that read the real CMU subset in `shared/data/cmu`.

#![allow(dead_code)]

use std::path::PathBuf;

use egoexo_mocap::fs::{read_catalog, read_text};
use egoexo_mocap::{Catalog, SubjectImporter};

/// The CMU subset: `$EGOEXO_CMU_DIR`, else `shared/data/cmu` beside the repository.
pub fn cmu_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("EGOEXO_CMU_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/cmu"));
    if dir.join("CMU_data.csv").is_file() {
        Some(dir)
    } else {
        eprintln!(
            "SKIPPED: the CMU data is not at {} (set EGOEXO_CMU_DIR to the folder with CMU_data.csv)",
            dir.display()
        );
        None
    }
}

/// Returns from the test (skipping it, with a message) when the data is absent.
#[macro_export]
macro_rules! require_cmu {
    () => {
        match common::cmu_dir() {
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
