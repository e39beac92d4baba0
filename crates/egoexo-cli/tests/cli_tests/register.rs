//! `egoexo register` and `reconstruct --register` through the real binary on simulated
//! sessions and captures whose observers `walk --perturb-worlds` moved into worlds of their
//! own: the JSON names every observer with the transform that undoes the move, a wandering
//! walk's clocks are found, `reconstruct` fuses the registered observers (and with `--register
//! off` none), the registered session's manifest records it, and a capture lands in the
//! anchor's world.

use crate::common;

use std::path::{Path, PathBuf};

use crate::common::run;
use serde_json::Value;

fn dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("register").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

fn json(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("{e}: {text}"))
}

/// Checks each entry of `register --json` against `walk`'s truth file: registered and fused,
/// the yaw within `max_yaw_deg`, the translation within `max_m` (the observer world's origin
/// lies up to 10 m from the scene, so this is looser than the error at the scene), the clock
/// within 50 ms, and a σ and frame count given.
fn assert_near_truth(report: &Value, truth_file: &Path, max_yaw_deg: f64, max_m: f64) {
    let truth = json(&std::fs::read_to_string(truth_file).unwrap());
    for t in truth["observers"].as_array().unwrap() {
        let id = t["id"].as_str().unwrap();
        let found =
            report["observers"].as_array().unwrap().iter().find(|o| o["id"] == id).unwrap_or_else(|| panic!("{id}"));
        assert_eq!(found["status"], "registered", "{found}");
        assert_eq!(found["fused"], true);
        let dyaw = (found["yaw_deg"].as_f64().unwrap() - t["yaw_deg"].as_f64().unwrap() + 540.0) % 360.0 - 180.0;
        assert!(dyaw.abs() < max_yaw_deg, "{id}: yaw {found} vs {t}");
        let d: f64 = (0..3)
            .map(|i| found["translation_m"][i].as_f64().unwrap() - t["translation_m"][i].as_f64().unwrap())
            .map(|x| x * x)
            .sum::<f64>()
            .sqrt();
        assert!(d < max_m, "{id}: translation {found} vs {t}");
        assert!((found["clock_offset_s"].as_f64().unwrap() - t["clock_offset_s"].as_f64().unwrap()).abs() < 0.05);
        for key in ["sigma_yaw_deg", "sigma_translation_m", "frames"] {
            assert!(found[key].as_f64().unwrap() > 0.0, "{key}: {found}");
        }
    }
}

#[test]
fn observers_in_worlds_of_their_own_are_registered_and_fused() {
    let d = dir("session");
    let walk = d.join("walk.egoexo");
    run(&["walk", "--seconds", "20", "--observers", "2", "--tracking", "1", "--perturb-worlds", "-o", &s(&walk)]);
    let truth = d.join("walk.egoexo.worlds.json");

    // `register --json`: one object, an entry per observer, near the truth.
    let registered = d.join("registered.egoexo");
    let (out, _) = run(&["register", &s(&walk), "--json", "-o", &s(&registered)]);
    let report = json(&out);
    assert_eq!(report["observers"].as_array().unwrap().len(), 2);
    assert_near_truth(&report, &truth, 1.0, 0.3);

    // The written session records it; registering it again keeps it.
    let (out, _) = run(&["inspect", &s(&registered), "--json"]);
    let inspected = json(&out);
    for o in inspected["observers"].as_array().unwrap() {
        assert_eq!(o["fused"], true, "{o}");
        assert_eq!(o["placement"]["registration"]["status"], "registered");
        assert_eq!(o["placement"]["registration"]["applied"], true);
    }
    let (out, _) = run(&["register", &s(&registered), "--json"]);
    for o in json(&out)["observers"].as_array().unwrap() {
        assert_eq!(o["status"], "as-given", "{o}");
    }

    // `reconstruct` registers by default and fuses; `--register off` leaves them out and says so.
    let (out, err) = run(&["reconstruct", &s(&walk), "-o", &s(&d.join("auto.json"))]);
    assert!(err.contains("observer-1: its world is its own: registered"), "{err}");
    let evidence = |file: &str| {
        let recon = json(&std::fs::read_to_string(d.join(file)).unwrap());
        recon["exo_evidence"].as_array().unwrap().iter().filter(|v| v.as_bool() == Some(true)).count()
    };
    assert!(evidence("auto.json") > 500, "{out}");
    let (_, err) = run(&["reconstruct", &s(&walk), "-o", &s(&d.join("off.json")), "--register", "off"]);
    assert!(err.contains("observer-1: not fused: own world") && err.contains("registration is off"), "{err}");
    assert_eq!(evidence("off.json"), 0);
}

#[test]
fn clocks_of_their_own_are_found_on_a_wandering_walk() {
    let d = dir("clock");
    let walk = d.join("walk.egoexo");
    run(&[
        "walk",
        "--seconds",
        "20",
        "--observers",
        "1",
        "--tracking",
        "1",
        "--wander",
        "--perturb-worlds",
        "--perturb-clocks",
        "1.5",
        "--seed",
        "3",
        "-o",
        &s(&walk),
    ]);
    let (out, _) = run(&["register", &s(&walk), "--json"]);
    assert_near_truth(&json(&out), &d.join("walk.egoexo.worlds.json"), 1.0, 0.3);
}

#[test]
fn a_capture_lands_in_the_anchors_world() {
    let d = dir("capture");
    let walk = d.join("group.egoexo");
    run(&["walk", "--seconds", "20", "--participants", "3", "--tracking", "1", "--perturb-worlds", "-o", &s(&walk)]);
    let (out, _) = run(&["register", &s(&walk), "--json"]);
    let report = json(&out);
    assert_eq!(report["anchor"], "participant-1");
    assert_eq!(report["observers"].as_array().unwrap().len(), 2, "every participant but the anchor");
    assert!(report["pairs"].as_array().unwrap().iter().all(|p| p["observer"].is_string() && p["target"].is_string()));
    assert_near_truth(&report, &d.join("group.egoexo.worlds.json"), 1.0, 0.3);
    // Another anchor: its world is the reference now, and a name that is no participant is refused.
    let (out, _) = run(&["register", &s(&walk), "--json", "--anchor", "participant-2"]);
    assert_eq!(json(&out)["anchor"], "participant-2");
    let failed = common::egoexo(&["register", &s(&walk), "--anchor", "nobody"]);
    assert!(!failed.status.success());
    assert!(String::from_utf8_lossy(&failed.stderr).contains("--anchor nobody: the capture's participants are"));
}
