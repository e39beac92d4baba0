//! Running the real server, `egoexo serve` (crates/egoexo-server), on `dist/`: for
//! `cargo xtask serve`, and for the end-to-end tests and the bench page, which so exercise
//! the deployment's headers, CSP and share API.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use anyhow::{Context, Result, bail};

use crate::cmd;

/// A running `egoexo serve`; stopped when dropped.
#[derive(Debug)]
pub struct Running {
    pub url: String,
    child: Child,
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Running {
    /// Waits for the server to exit (it runs until Ctrl-C).
    pub fn wait(mut self) -> Result<()> {
        let status = self.child.wait()?;
        if !status.success() {
            bail!("egoexo serve exited with {status}");
        }
        Ok(())
    }
}

/// Builds the `egoexo` binary (dev profile). Its dependencies' features are those of
/// `egoexo-cli` alone, which differ from a `cargo test --workspace` build's: after that build,
/// use the `egoexo` it made instead ([`crate::test`] does), or cargo compiles much of the
/// workspace again (tract included) for this one binary.
pub fn build_server(root: &Path) -> Result<PathBuf> {
    cmd::run(Command::new("cargo").args(["build", "--quiet", "-p", "egoexo-cli"]))?;
    let binary = root.join("target").join("debug").join("egoexo");
    if !binary.is_file() {
        bail!("cargo built no {}", binary.display());
    }
    Ok(binary)
}

/// Starts `binary serve` (the `egoexo` CLI, [`build_server`]) on `dist` with shares in
/// `store`, listening on `listen` (`127.0.0.1:0` picks a free port), and waits for its address.
pub fn spawn(binary: &Path, dist: &Path, store: &Path, listen: &str) -> Result<Running> {
    std::fs::create_dir_all(store)?;
    let mut child = Command::new(binary)
        .args(["serve", "--listen", listen, "--dist"])
        .arg(dist)
        .arg("--store")
        .arg(store)
        .stdout(Stdio::piped())
        .spawn()
        .with_context(|| format!("starting {}", binary.display()))?;
    let mut line = String::new();
    BufReader::new(child.stdout.take().context("the server's stdout")?).read_line(&mut line)?;
    let Some(url) = line.trim().strip_prefix("listening on ") else {
        let _ = child.kill();
        bail!("egoexo serve did not start (first line {line:?})");
    };
    Ok(Running { url: url.to_string(), child })
}
