//! Helpers shared by the CLI's integration tests: the real `egoexo` binary and the CMU data.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output};

/// Runs the `egoexo` binary built for these tests.
pub fn egoexo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_egoexo")).args(args).output().expect("egoexo runs")
}

/// The CMU ASF/AMC folder (`EGOEXO_CMU_DIR`, else `../shared/data/cmu`), or `None` with a
/// SKIPPED message when it is absent.
pub fn cmu_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("EGOEXO_CMU_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/cmu"));
    if dir.join("CMU_data.csv").is_file() {
        Some(dir)
    } else {
        eprintln!("SKIPPED: the CMU data is not at {} (set EGOEXO_CMU_DIR)", dir.display());
        None
    }
}
