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

/// What serving on `host` exposes, for a host that is not loopback: anyone who can reach it
/// can use the page, the share API and the live relay, over plain HTTP — where browsers give
/// no camera or WebXR to a page that is not `localhost`.
pub fn exposure_warning(host: std::net::IpAddr) -> Option<String> {
    (!host.is_loopback()).then(|| {
        format!(
            "serving on {host}: anyone who can reach this machine can open the page, make live rooms and \
             upload shares, over plain HTTP. Browsers give cameras and WebXR only to secure pages: for a \
             headset or a phone, put a TLS proxy in front (docs/hosting.md) or use `adb reverse` to a \
             loopback server (docs/live-protocol.md)."
        )
    })
}

#[cfg(test)]
mod tests {
    use super::exposure_warning;

    #[test]
    fn serving_beyond_loopback_says_what_it_exposes() {
        assert_eq!(exposure_warning("127.0.0.1".parse().unwrap()), None);
        assert_eq!(exposure_warning("::1".parse().unwrap()), None);
        for host in ["0.0.0.0", "192.168.1.20", "::"] {
            let warning = exposure_warning(host.parse().unwrap()).unwrap();
            assert!(warning.contains(host) && warning.contains("TLS proxy"), "{warning}");
        }
    }
}
