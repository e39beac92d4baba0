//! The CLI end to end on real CMU motion: `mocap import` → `synth` (sessions and shards) →
//! `inspect` accepts every simulated session → `reconstruct` writes every format → `eval`
//! prints both tables. Networks are the engine's untrained fixture (the numbers are not the
//! point here; the plumbing is). Skipped, with a message, when `shared/data/cmu` is absent.

use std::path::Path;

use crate::common::egoexo;
use egoexo_test_support::cmu_dir;

fn ok(args: &[&str]) -> String {
    let out = egoexo(args);
    assert!(out.status.success(), "egoexo {args:?} failed:\n{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn fixture_models() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../egoexo-infer/tests/fixtures/models").display().to_string()
}

#[test]
fn simulate_inspect_reconstruct_and_evaluate() {
    let Some(cmu) = cmu_dir() else { return };
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("pipeline");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let lib = dir.join("lib.safetensors");
    let s = |p: &Path| p.display().to_string();
    ok(&["mocap", "import", &s(&cmu), "-o", &s(&lib), "--subjects", "2,9"]);

    // Sessions that inspect accepts.
    let sessions = dir.join("sessions");
    let out = ok(&[
        "synth",
        "--lib",
        &s(&lib),
        "--subjects",
        "2",
        "--observers",
        "2",
        "--tracking",
        "3",
        "--seed",
        "7",
        "-o",
        &s(&sessions),
    ]);
    assert!(out.contains("wrote 3 sessions"), "{out}");
    let mut files: Vec<_> = std::fs::read_dir(&sessions).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    assert_eq!(files.len(), 3);
    for f in &files {
        let report = ok(&["inspect", &s(f)]);
        assert!(report.contains("observer-2") && report.contains("Ground truth"), "{report}");
    }

    // Every output format.
    for ext in ["npz", "bvh", "glb", "csv", "json"] {
        let out_file = dir.join(format!("motion.{ext}"));
        let out = ok(&["reconstruct", &s(&files[0]), "-o", &s(&out_file), "--models", &fixture_models()]);
        assert!(out.contains("ego-exo, 3-point"), "{out}");
        assert!(std::fs::metadata(&out_file).unwrap().len() > 1000);
    }
    let ego_only = ok(&[
        "reconstruct",
        &s(&files[0]),
        "-o",
        &s(&dir.join("ego.csv")),
        "--models",
        &fixture_models(),
        "--ego-only",
        "--tracking",
        "1",
    ]);
    assert!(ego_only.contains("ego-only, 1-point"), "{ego_only}");

    // Windows spread over threads write the same file as one after another; `--timings`
    // prints the stage table and the scaling over threads.
    let one = dir.join("one-thread.npz");
    let two = dir.join("two-threads.npz");
    let models = fixture_models();
    ok(&["reconstruct", &s(&files[0]), "-o", &s(&one), "--models", &models, "--threads", "1"]);
    ok(&["reconstruct", &s(&files[0]), "-o", &s(&two), "--models", &models, "--threads", "2"]);
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap());
    let timed = dir.join("timed.npz");
    let report =
        ok(&["reconstruct", &s(&files[0]), "-o", &s(&timed), "--models", &models, "--threads", "2", "--timings", "2"]);
    for stage in ["import", "align", "ego-features", "egonet", "exo-features", "gate", "fusion", "decode", "export"] {
        assert!(report.lines().any(|l| l.starts_with(stage)), "no {stage} row: {report}");
    }
    assert!(report.contains("frames/s for the whole job") && report.contains("2 threads:"), "{report}");
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&timed).unwrap());

    // Training shards.
    let shards = dir.join("shards");
    let out = ok(&[
        "synth",
        "--lib",
        &s(&lib),
        "--subjects",
        "2",
        "--observers",
        "3",
        "--shards",
        "ego",
        "--simulations",
        "1",
        "-o",
        &s(&shards),
    ]);
    assert!(out.contains("windows in"), "{out}");
    assert!(shards.join("index.json").is_file() && shards.join("shard-0000.npz").is_file());

    // The evaluation table, with and without networks.
    let table =
        ok(&["eval", "--lib", &s(&lib), "--subjects", "9", "--observers", "1", "--tracking", "3", "--seed", "7"]);
    assert!(
        table.contains("rest-pose") && table.contains("nearest-neighbour") && table.contains("occluded frames"),
        "{table}"
    );
    // 1-point, one observer, the fixture networks; `extra` chooses the table.
    let (lib_path, models) = (s(&lib), fixture_models());
    let eval_networks = |extra: &[&str]| {
        let mut args = vec!["eval", "--lib", &lib_path, "--subjects", "9", "--observers", "1", "--tracking", "1"];
        args.extend(["--models", &models, "--json"]);
        args.extend(extra);
        ok(&args)
    };
    let json = eval_networks(&[]);
    let report: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(report["tracking"], 1);
    let methods: Vec<_> =
        report["rows"].as_array().unwrap().iter().map(|r| r["method"].as_str().unwrap().to_string()).collect();
    assert_eq!(methods, ["rest-pose", "nearest-neighbour", "ego-only", "ego-exo", "ego-exo-ungated"]);
    assert!(report["occluded_rows"].is_array());
    // The networks' rows come with clip-paired differences (observers' and gate's effect).
    let paired = report["paired"].as_array().unwrap();
    assert!(
        !paired.is_empty() && paired.iter().all(|p| p["mpjpe_cm"]["low"].as_f64() <= p["mpjpe_cm"]["high"].as_f64())
    );
    assert_eq!(paired[0]["method"], "ego-exo");
    assert_eq!(paired[0]["baseline"], "ego-only");

    // The live table: each lookahead against the offline result on the same frames.
    let json = eval_networks(&["--live", "--lookaheads", "0,8"]);
    let live: serde_json::Value = serde_json::from_str(&json).unwrap();
    let rows = live["rows"].as_array().unwrap();
    let cells: Vec<_> =
        rows.iter().map(|r| (r["method"].as_str().unwrap(), r["lookahead"].as_u64().unwrap())).collect();
    assert_eq!(cells, [("ego-only", 0), ("ego-only", 8), ("ego-exo", 0), ("ego-exo", 8)]);
    assert_eq!(live["offline"].as_array().unwrap().len(), 2);
    assert!(live["frames"].as_u64().unwrap() > 100);
    for row in rows {
        let (ratio, vs) = (row["mpjpe_ratio"].as_f64().unwrap(), row["vs_offline_cm"].as_f64().unwrap());
        assert!(ratio.is_finite() && ratio > 0.0 && vs.is_finite() && vs >= 0.0, "{row}");
        assert_eq!(row["trained_for_lookahead"], false);
    }

    // A models folder whose manifest adds a 1-point live variant for lookahead 0 (the fixture's
    // 1-point files): its rows come beside the offline networks' at 0, none at 8, and, being
    // the same networks, they read out the same joints.
    let live_models = dir.join("live-models");
    for sub in ["1pt", "3pt"] {
        std::fs::create_dir_all(live_models.join(sub)).unwrap();
        for file in ["egonet.onnx", "gate.onnx", "fusion.onnx", "fusion_ego_only.onnx"] {
            std::fs::copy(Path::new(&models).join(sub).join(file), live_models.join(sub).join(file)).unwrap();
        }
    }
    let mut manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(Path::new(&models).join("manifest.json")).unwrap()).unwrap();
    let sets = manifest["model_sets"].as_array_mut().unwrap();
    let mut variant = sets.iter().find(|s| s["tracking"] == "one_point").unwrap().clone();
    variant["lookahead"] = serde_json::Value::from(0);
    sets.push(variant);
    std::fs::write(live_models.join("manifest.json"), manifest.to_string()).unwrap();
    let json = ok(&[
        "eval",
        "--lib",
        &lib_path,
        "--subjects",
        "9",
        "--observers",
        "1",
        "--tracking",
        "1",
        "--models",
        &s(&live_models),
        "--json",
        "--live",
        "--lookaheads",
        "0,8",
    ]);
    let with_variant: serde_json::Value = serde_json::from_str(&json).unwrap();
    let rows = with_variant["rows"].as_array().unwrap();
    let cell = |method: &str, lookahead: u64, trained: bool| {
        rows.iter()
            .find(|r| r["method"] == method && r["lookahead"] == lookahead && r["trained_for_lookahead"] == trained)
            .unwrap_or_else(|| panic!("no row {method} {lookahead} {trained}: {with_variant}"))
    };
    assert_eq!(rows.len(), 6);
    assert!(rows.iter().all(|r| r["trained_for_lookahead"] == false || r["lookahead"] == 0));
    for method in ["ego-only", "ego-exo"] {
        assert_eq!(cell(method, 0, true)["mpjpe_cm"], cell(method, 0, false)["mpjpe_cm"]);
    }
}

#[test]
fn bad_arguments_fail_with_a_message() {
    let out = egoexo(&["eval", "--lib", "/nonexistent.safetensors", "--subjects", "1"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent.safetensors"));
    let out = egoexo(&["reconstruct", "/nonexistent.egoexo", "-o", "/tmp/x.xyz"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("xyz") || err.contains("nonexistent"), "{err}");
}
