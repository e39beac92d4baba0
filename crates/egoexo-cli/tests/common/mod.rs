//! Helpers shared by the CLI's integration tests: the real `egoexo` binary.
#![allow(dead_code)]

use std::process::{Command, Output};

/// Runs the `egoexo` binary built for these tests.
pub fn egoexo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_egoexo")).args(args).output().expect("egoexo runs")
}
