//! Helpers shared by the CLI's integration tests: the real `egoexo` binary.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};

/// Runs the `egoexo` binary built for these tests.
pub fn egoexo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_egoexo")).args(args).output().expect("egoexo runs")
}

/// Runs `egoexo` and asserts it succeeded: `(stdout, stderr)`.
pub fn run(args: &[&str]) -> (String, String) {
    let out = egoexo(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "egoexo {args:?} failed:\n{stderr}");
    (String::from_utf8_lossy(&out.stdout).into_owned(), stderr)
}

/// Copies the folder `from` to `to`, recursively.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

/// A running `egoexo serve`; killed when dropped.
pub struct Served {
    pub child: Child,
    /// `http://127.0.0.1:<port>`, no trailing slash.
    pub url: String,
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A `dist/` with only a page, for servers whose page is not under test.
pub fn dist() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("index.html"), "<!doctype html><title>egoexo</title>").unwrap();
    dir
}

/// Starts `egoexo serve` on a free loopback port with `dist`, `store` and `extra` arguments,
/// and waits for its address line.
pub fn serve(dist: &Path, store: &str, extra: &[&str], envs: &[(&str, String)]) -> Served {
    let mut child = Command::new(env!("CARGO_BIN_EXE_egoexo"))
        .args(["serve", "--listen", "127.0.0.1:0", "--store", store, "--dist"])
        .arg(dist)
        .args(extra)
        .envs(envs.iter().map(|(k, v)| (*k, v.as_str())))
        .stdout(Stdio::piped())
        .spawn()
        .expect("egoexo serve starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
    let url = line.trim().strip_prefix("listening on ").unwrap_or_else(|| panic!("unexpected first line {line:?}"));
    Served { url: url.trim_end_matches('/').to_string(), child }
}
