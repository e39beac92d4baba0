//! The training code's tests (`training/tests`, pytest): the PyTorch forward kinematics of the
//! position loss against this workspace's FK (a fixture the core writes, ≤ 1e-5 m), the
//! exported networks in onnxruntime against the stored PyTorch outputs (≤ 1e-4, the same
//! fixture tract is checked against in `parity.rs`), and the networks' input/output contracts.
//!
//! Python comes from `cargo xtask setup` (run by `cargo xtask test`): the venv `target/py`
//! from `tests/requirements.txt`, passed in as `EGOEXO_PYTHON`. Without it this test fails
//! and says so; it never passes silently.
#![cfg(not(target_arch = "wasm32"))]

use std::process::Command;

use egoexo_test_support::{SETUP_HINT, python, workspace_root};

#[test]
fn training_pytest_suite_passes() {
    let root = workspace_root();
    let out = Command::new(python())
        .args(["-m", "pytest", "training/tests", "-q", "-p", "no:cacheprovider"])
        .current_dir(&root)
        .env("PYTHONPATH", root.join("training"))
        .output()
        .unwrap_or_else(|e| panic!("cannot run pytest: {e}; {SETUP_HINT}"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "training/tests failed ({}):\n{stdout}\n{}\n(if a module is missing: {SETUP_HINT})",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    // pytest exits non-zero when it collects nothing; also make sure nothing was skipped.
    let summary = stdout.lines().rev().find(|l| l.contains("passed")).unwrap_or_default();
    let passed: usize = summary.split_whitespace().next().and_then(|n| n.parse().ok()).unwrap_or(0);
    assert!(passed >= 6, "expected the training suite's tests to pass, got: {summary:?}\n{stdout}");
    assert!(!summary.contains("skipped"), "training tests were skipped: {summary}");
}
