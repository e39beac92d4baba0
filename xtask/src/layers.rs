//! The crate layers of ARCHITECTURE.md, checked: each workspace crate's normal (and build)
//! dependencies on other egoexo crates must be among the ones its layer allows. The test reads
//! the workspace with `cargo metadata`, so a new dependency edge that breaks the layering
//! fails `cargo test -p xtask` (part of `cargo xtask test`).

/// `(crate, the egoexo crates it may depend on)`, bottom up — the table in ARCHITECTURE.md.
pub const LAYERS: &[(&str, &[&str])] = &[
    ("egoexo-core", &[]),
    ("egoexo-protocol", &["egoexo-core"]),
    ("egoexo-test-support", &[]),
    ("egoexo-video", &[]),
    ("egoexo-motion-io", &["egoexo-core"]),
    ("egoexo-scene", &["egoexo-core"]),
    ("egoexo-infer", &["egoexo-core"]),
    ("egoexo-solve", &["egoexo-core"]),
    ("egoexo-session", &["egoexo-core", "egoexo-protocol", "egoexo-motion-io", "egoexo-solve"]),
    ("egoexo-mocap", &["egoexo-core", "egoexo-motion-io", "egoexo-solve"]),
    ("egoexo-server", &["egoexo-core", "egoexo-protocol"]),
    ("egoexo-synth", &["egoexo-core", "egoexo-session"]),
    ("egoexo-share", &["egoexo-core", "egoexo-motion-io", "egoexo-protocol", "egoexo-session"]),
    ("egoexo-detect", &["egoexo-core", "egoexo-session", "egoexo-infer", "egoexo-video"]),
    ("egoexo-register", &["egoexo-core", "egoexo-session", "egoexo-infer", "egoexo-solve"]),
    (
        "egoexo-dataset",
        &[
            "egoexo-core",
            "egoexo-motion-io",
            "egoexo-session",
            "egoexo-mocap",
            "egoexo-synth",
            "egoexo-infer",
            "egoexo-detect",
            "egoexo-register",
        ],
    ),
    (
        "egoexo-web-worker",
        &[
            "egoexo-core",
            "egoexo-motion-io",
            "egoexo-session",
            "egoexo-infer",
            "egoexo-scene",
            "egoexo-protocol",
            "egoexo-share",
            "egoexo-video",
            "egoexo-detect",
            "egoexo-register",
        ],
    ),
    ("egoexo-viewer", &["egoexo-core", "egoexo-scene", "egoexo-protocol", "egoexo-video"]),
    (
        "egoexo-cli",
        &[
            "egoexo-core",
            "egoexo-motion-io",
            "egoexo-session",
            "egoexo-mocap",
            "egoexo-synth",
            "egoexo-infer",
            "egoexo-dataset",
            "egoexo-protocol",
            "egoexo-share",
            "egoexo-server",
            "egoexo-web-worker",
            "egoexo-detect",
            "egoexo-video",
            "egoexo-register",
        ],
    ),
];

/// Edges of `metadata` (`cargo metadata --format-version 1 --no-deps` JSON) that the layers
/// forbid, as `crate → dependency` lines; crates missing from [`LAYERS`] are reported too.
pub fn violations(metadata: &serde_json::Value) -> Vec<String> {
    let mut out = Vec::new();
    let packages = metadata["packages"].as_array().map(Vec::as_slice).unwrap_or_default();
    for package in packages {
        let name = package["name"].as_str().unwrap_or_default();
        if !name.starts_with("egoexo-") {
            continue;
        }
        let Some((_, allowed)) = LAYERS.iter().find(|(crate_name, _)| *crate_name == name) else {
            out.push(format!("{name} is in no layer of ARCHITECTURE.md"));
            continue;
        };
        let dependencies = package["dependencies"].as_array().map(Vec::as_slice).unwrap_or_default();
        for dependency in dependencies {
            let dep = dependency["name"].as_str().unwrap_or_default();
            let dev = dependency["kind"].as_str() == Some("dev");
            if dep.starts_with("egoexo-") && !dev && !allowed.contains(&dep) {
                out.push(format!("{name} → {dep}"));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use std::process::Command;

    use super::*;

    #[test]
    fn every_crate_depends_only_on_its_lower_layers() {
        let root = crate::workspace_root();
        let out = Command::new(env!("CARGO"))
            .args(["metadata", "--format-version", "1", "--no-deps", "--offline"])
            .current_dir(&root)
            .output()
            .expect("cargo metadata runs");
        assert!(out.status.success(), "cargo metadata: {}", String::from_utf8_lossy(&out.stderr));
        let metadata: serde_json::Value = serde_json::from_slice(&out.stdout).expect("cargo metadata prints JSON");
        let crates = metadata["packages"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|p| p["name"].as_str().is_some_and(|n| n.starts_with("egoexo-")))
            .count();
        assert_eq!(crates, LAYERS.len(), "every egoexo crate has a row in LAYERS, and only those");
        assert_eq!(violations(&metadata), Vec::<String>::new(), "dependencies that break ARCHITECTURE.md's layers");
    }

    #[test]
    fn an_upward_edge_is_reported() {
        let metadata = serde_json::json!({"packages": [
            {"name": "egoexo-core", "dependencies": [{"name": "egoexo-session", "kind": null}]},
            {"name": "egoexo-infer", "dependencies": [{"name": "egoexo-session", "kind": "dev"}]},
            {"name": "egoexo-new", "dependencies": []},
        ]});
        assert_eq!(
            violations(&metadata),
            ["egoexo-core → egoexo-session", "egoexo-new is in no layer of ARCHITECTURE.md"]
        );
    }
}
