//! `egoexo mocap import` and `egoexo mocap info`, run as the real binary on two CMU subjects
//! laid out both ways (the project's `cmu/NN/` and CMU's `all_asfamc/subjects/NN/`).
//! Skipped, with a message, when `shared/data/cmu` is absent.

use std::path::{Path, PathBuf};

use crate::common::egoexo;
use egoexo_test_support::cmu_dir;

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Copies subjects 02 and 93 (small) into `dest/<prefix>/NN/`.
fn copy_subjects(cmu: &Path, dest: &Path) {
    for subject in ["02", "93"] {
        let to = dest.join(subject);
        std::fs::create_dir_all(&to).unwrap();
        for entry in std::fs::read_dir(cmu.join(subject)).unwrap() {
            let path = entry.unwrap().path();
            std::fs::copy(&path, to.join(path.file_name().unwrap())).unwrap();
        }
    }
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn import_then_info_on_two_subjects_in_both_layouts() {
    let Some(cmu) = cmu_dir() else { return };
    let root = scratch("mocap_cli");

    // The project's layout, with CMU_data.csv inside.
    let subset = root.join("cmu");
    copy_subjects(&cmu, &subset);
    std::fs::copy(cmu.join("CMU_data.csv"), subset.join("CMU_data.csv")).unwrap();
    let lib = root.join("out/lib.safetensors");
    let out = egoexo(&["mocap", "import", subset.to_str().unwrap(), "-o", lib.to_str().unwrap()]);
    assert!(out.status.success(), "import failed: {}{}", text(&out.stdout), text(&out.stderr));
    assert!(text(&out.stdout).contains("of 2 subjects"), "{}", text(&out.stdout));

    let out = egoexo(&["mocap", "info", lib.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).expect("info --json prints JSON");
    assert_eq!(info["subjects"], serde_json::json!([2, 93]));
    assert_eq!(info["fps"], 30.0);
    let clips = info["clips"].as_u64().unwrap();
    assert!(clips >= 4, "{clips} clips");
    assert!(info["hours"].as_f64().unwrap() > 0.002);
    let mean = info["retarget_mean_cm"].as_f64().unwrap();
    let p95 = info["retarget_p95_cm"].as_f64().unwrap();
    assert!(mean > 0.5 && mean <= 3.3 && p95 >= mean && p95 < 8.0, "mean {mean} cm, p95 {p95} cm");
    let first = &info["clip_list"][0];
    assert_eq!(first["name"], "02_01");
    assert_eq!(first["description"], "walk");
    assert_eq!(first["source_fps"], 120.0);

    let out = egoexo(&["mocap", "info", lib.to_str().unwrap(), "--clips"]);
    let table = text(&out.stdout);
    assert!(out.status.success());
    assert!(table.contains("subjects 2") && table.contains("retarget error") && table.contains("02_01"), "{table}");

    // CMU's allasfamc layout, catalogue passed separately, one subject chosen.
    let full = root.join("all_asfamc/subjects");
    copy_subjects(&cmu, &full);
    let lib93 = root.join("lib93.safetensors");
    let out = egoexo(&[
        "mocap",
        "import",
        root.join("all_asfamc").to_str().unwrap(),
        "-o",
        lib93.to_str().unwrap(),
        "--catalog",
        cmu.join("CMU_data.csv").to_str().unwrap(),
        "--subjects",
        "93",
    ]);
    assert!(out.status.success(), "{}{}", text(&out.stdout), text(&out.stderr));
    let out = egoexo(&["mocap", "info", lib93.to_str().unwrap(), "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(info["subjects"], serde_json::json!([93]));

    // Without a catalogue the rates are unknown: a clear error, not a guess.
    let out = egoexo(&["mocap", "import", root.join("all_asfamc").to_str().unwrap(), "-o", lib93.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("CMU_data.csv"), "{}", text(&out.stderr));
}

#[test]
fn bad_inputs_are_errors_naming_the_file() {
    let root = scratch("mocap_cli_bad");
    let out = egoexo(&["mocap", "import", root.to_str().unwrap(), "-o", root.join("x.safetensors").to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains(root.to_str().unwrap()), "{}", text(&out.stderr));

    let not_a_library = root.join("nope.safetensors");
    std::fs::write(&not_a_library, b"hello").unwrap();
    let out = egoexo(&["mocap", "info", not_a_library.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("not a motion library"), "{}", text(&out.stderr));

    // A broken AMC: the other trials are imported, the broken one is named with its line,
    // and the command fails.
    let subject = root.join("cmu/07");
    std::fs::create_dir_all(&subject).unwrap();
    let Some(cmu) = cmu_dir() else { return };
    std::fs::copy(cmu.join("02/02.asf"), subject.join("07.asf")).unwrap();
    std::fs::copy(cmu.join("02/02_01.amc"), subject.join("07_01.amc")).unwrap();
    let broken = std::fs::read_to_string(cmu.join("02/02_02.amc")).unwrap().replacen("lradius", "lradius x", 1);
    std::fs::write(subject.join("07_02.amc"), broken).unwrap();
    std::fs::copy(cmu.join("CMU_data.csv"), root.join("cmu/CMU_data.csv")).unwrap();
    let lib = root.join("lib.safetensors");
    let out = egoexo(&["mocap", "import", root.join("cmu").to_str().unwrap(), "-o", lib.to_str().unwrap()]);
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    assert!(stderr.contains("07_02.amc:") && stderr.contains("`x` is not a finite number"), "{stderr}");
    let out = egoexo(&["mocap", "info", lib.to_str().unwrap(), "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(info["clip_list"][0]["name"], "07_01");
    assert_eq!(info["clips"], 1);
}

/// The shared subset and `cmu-extra` in one library: two folders on the command line, the
/// three cgspeed BVH releases beside ASF/AMC, the retarget error printed and stored per
/// source.
#[test]
fn import_of_two_folders_reports_each_source() {
    let (Some(cmu), Some(extra)) = (cmu_dir(), egoexo_test_support::cmu_extra_dir()) else { return };
    let root = scratch("mocap_cli_extra");
    let lib = root.join("all.safetensors");
    let out = egoexo(&[
        "mocap",
        "import",
        cmu.to_str().unwrap(),
        extra.to_str().unwrap(),
        "--subjects",
        "2,11,12,131",
        "-o",
        lib.to_str().unwrap(),
    ]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "import failed: {stdout}{}", text(&out.stderr));
    assert!(stdout.contains("of 4 subjects"), "{stdout}");
    for source in ["ASF/AMC", "BVH (cgspeed 3dsMax)", "BVH (cgspeed DAZ, standard figure)"] {
        assert!(stdout.lines().any(|l| l.starts_with(source)), "no row for {source}:\n{stdout}");
    }
    assert!(stdout.contains("restored the collapsed thorax"), "{stdout}");

    let out = egoexo(&["mocap", "info", lib.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(info["subjects"], serde_json::json!([2, 11, 12, 131]));
    let sources = info["per_source"].as_array().unwrap();
    let find = |name: &str| sources.iter().find(|s| s["source"] == name).unwrap_or_else(|| panic!("{name}"));
    assert_eq!(find("ASF/AMC")["subjects"], serde_json::json!([2, 11, 131]));
    assert_eq!(find("BVH (cgspeed 3dsMax)")["subjects"], serde_json::json!([131]));
    assert_eq!(find("BVH (cgspeed DAZ, standard figure)")["subjects"], serde_json::json!([12]));
    for s in sources {
        let mean = s["retarget_mean_cm"].as_f64().unwrap();
        assert!(mean > 0.5 && mean < 3.5, "{s}");
    }
}
