//! The CLI built here must be the version of the `wasm-bindgen` crate in Cargo.lock: the
//! bindings it generates and the runtime compiled into the wasm modules must match exactly.

use std::process::Command;

/// The version of package `name` in the workspace's Cargo.lock.
fn locked_version(name: &str) -> String {
    let lock = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../Cargo.lock")).expect("Cargo.lock");
    let mut lines = lock.lines();
    while let Some(line) = lines.next() {
        if line.trim() == format!("name = \"{name}\"") {
            let version = lines.next().expect("a version line after the name");
            return version.trim().trim_start_matches("version = ").trim_matches('"').to_string();
        }
    }
    panic!("Cargo.lock has no {name} package")
}

#[test]
fn the_cli_is_the_locked_wasm_bindgen_version() {
    let out = Command::new(env!("CARGO_BIN_EXE_wasm-bindgen")).arg("--version").output().expect("wasm-bindgen runs");
    assert!(out.status.success());
    let printed = String::from_utf8(out.stdout).unwrap();
    assert_eq!(printed.trim(), format!("wasm-bindgen {}", locked_version("wasm-bindgen")));
    assert_eq!(locked_version("wasm-bindgen-cli"), locked_version("wasm-bindgen"));
    assert_eq!(env!("CARGO_PKG_VERSION"), locked_version("wasm-bindgen"), "this package's version is the one it wraps");
}

#[test]
fn the_test_runner_starts() {
    // Without arguments it prints its usage and fails; it must not crash or hang.
    let out = Command::new(env!("CARGO_BIN_EXE_wasm-bindgen-test-runner")).output().expect("the runner runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("Usage"), "{}", String::from_utf8_lossy(&out.stderr));
}
