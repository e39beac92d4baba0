//! `egoexo inspect` and `egoexo convert`, run as the real binary on the session fixtures.

use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::common::{copy_dir, egoexo};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../egoexo-session/tests/fixtures")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "cli-sessions-{name}-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn path_str(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn inspect_reports_devices_rates_observers_coverage_and_problems() {
    let o = egoexo(&["inspect", path_str(&fixtures().join("aria_mps"))]);
    let out = stdout(&o);
    assert!(o.status.success(), "{}", stderr(&o));
    for needle in [
        "aria_mps — multi-device Aria MPS folder",
        "head         101 poses, 2.000 s, 50.0 Hz, +0.000 s .. +2.000 s",
        "Observers (2)",
        "camera fisheye624 1408×1408",
        "keypoints: 61 frames, 2.000 s, 30.0 Hz",
        "Problems (2):",
        "kept the highest-scoring person per frame",
        "no device folder has a time_sync.csv: 3 devices",
    ] {
        assert!(out.contains(needle), "missing {needle:?} in\n{out}");
    }
    let row = out.lines().find(|l| l.trim_start().starts_with("observer-2/keypoints ")).unwrap();
    let cells: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(cells, ["observer-2/keypoints", "61", "/", "61", "100.0%"]);
}

/// The wearer's glasses as MPS writes them: `trajectory/` (1 kHz, 3 s, gravity −Z, semidense
/// points with a floor at z = 0) and `hand_tracking/wrist_and_palm_poses.csv` v2 at 30 Hz with
/// the right hand out of view from 1 s to 2 s.
fn write_mps_wearer(dir: &Path) {
    use std::fmt::Write as _;
    use std::io::Write as _;

    use egoexo_core::glam::{Quat, Vec3};
    use egoexo_core::rigid::RigidTransform;
    use egoexo_session::aria::trajectory::write_closed_loop_trajectory;

    std::fs::create_dir_all(dir.join("trajectory")).unwrap();
    std::fs::create_dir_all(dir.join("hand_tracking")).unwrap();
    let times: Vec<i64> = (0..3000).map(|i| 5_000_000_000 + i * 1_000_000).collect();
    let poses: Vec<RigidTransform> = (0..3000)
        .map(|i| RigidTransform::new(Quat::from_rotation_z(0.001 * i as f32), Vec3::new(0.0005 * i as f32, 0.0, 1.6)))
        .collect();
    let csv = write_closed_loop_trajectory(&times, &poses, "graph", Vec3::new(0.0, 0.0, -9.81));
    std::fs::write(dir.join("trajectory/closed_loop_trajectory.csv"), csv).unwrap();
    let mut hands = String::from(
        "tracking_timestamp_us,left_tracking_confidence,tx_left_wrist_device,ty_left_wrist_device,tz_left_wrist_device,tx_left_palm_device,ty_left_palm_device,tz_left_palm_device,right_tracking_confidence,tx_right_wrist_device,ty_right_wrist_device,tz_right_wrist_device,tx_right_palm_device,ty_right_palm_device,tz_right_palm_device,nx_left_palm_device,ny_left_palm_device,nz_left_palm_device,nx_left_wrist_device,ny_left_wrist_device,nz_left_wrist_device,nx_right_palm_device,ny_right_palm_device,nz_right_palm_device,nx_right_wrist_device,ny_right_wrist_device,nz_right_wrist_device\n",
    );
    for i in 0..90 {
        let us = 5_000_000 + i * 33_333;
        let right_seen = !(30..60).contains(&i);
        let right = if right_seen { "0.9,-0.2,-0.3,0.35,-0.25,-0.35,0.42" } else { "-1,0,0,0,0,0,0" };
        let right_normals = if right_seen { "0,-1,0,0,-1,0" } else { "0,0,0,0,0,0" };
        let _ = writeln!(hands, "{us},0.95,0.2,-0.3,0.35,0.25,-0.35,0.42,{right},0,-1,0,0,-1,0,{right_normals}");
    }
    std::fs::write(dir.join("hand_tracking/wrist_and_palm_poses.csv"), hands).unwrap();
    let mut points = String::from("uid,graph_uid,px_world,py_world,pz_world,inv_dist_std,dist_std\n");
    for i in 0..600 {
        let (x, y) = ((i % 30) as f32 * 0.1 - 1.5, (i / 30) as f32 * 0.1 - 1.0);
        let _ = writeln!(points, "{i},graph,{x},{y},{:.4},0.0003,0.01", 0.002 * ((i % 5) as f32 - 2.0));
    }
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(points.as_bytes()).unwrap();
    std::fs::write(dir.join("trajectory/global_points.csv.gz"), gz.finish().unwrap()).unwrap();
}

#[test]
fn inspect_an_mps_folder_shows_wrist_coverage_floor_and_how_3_point_uses_them() {
    let dir = scratch("mps-wearer").join("mps_wearer_vrs");
    write_mps_wearer(&dir);
    let o = egoexo(&["inspect", path_str(&dir)]);
    let out = stdout(&o);
    assert!(o.status.success(), "{}", stderr(&o));
    for needle in [
        "head         3000 poses, 2.999 s, 1000.0 Hz",
        // The hand samples end 33 ms before the head: the last frame has no left wrist.
        "left wrist tracked on 98.9% of frames, longest gap 0.03 s",
        "right wrist tracked on 6",
        "wrists from  MPS wrist_and_palm_poses.csv v2 (positions and normals); orientation from the hand direction and the wrist normal",
        "tracking     3-point (the wrists are tracked on 99% (left) and 6",
        "m, from semidense points (600 well-constrained points at the floor, trajectory/global_points.csv.gz)",
    ] {
        assert!(out.contains(needle), "missing {needle:?} in\n{out}");
    }
    let gap: f64 = out
        .lines()
        .find(|l| l.contains("right wrist tracked on"))
        .and_then(|l| l.rsplit("longest gap ").next())
        .and_then(|s| s.trim_end_matches(" s").parse().ok())
        .unwrap();
    assert!((0.95..1.1).contains(&gap), "right wrist gap {gap} s");
    let o = egoexo(&["inspect", path_str(&dir), "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["tracking"]["points"], 3);
    assert!(v["tracking"]["reason"].as_str().unwrap().contains("uses them where they are"), "{}", v["tracking"]);
    assert_eq!(v["wrist_source"]["form"], "wrist_and_palm_v2");
    assert!(v["floor"]["height_m"].as_f64().unwrap().abs() < 0.005);
    assert!((v["wrists"][0]["tracked_percent"].as_f64().unwrap() - 98.9).abs() < 0.1);
    // Reconstructing it takes the 3-point model by default (wrists where they are tracked)
    // and says how much of the time that is.
    let out = dir.with_file_name("motion.json");
    let o = egoexo(&["reconstruct", path_str(&dir), "-o", path_str(&out), "--ego-only", "--force"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("note: 3-point with wrists that come and go: the wrists are tracked on"),
        "{}",
        stderr(&o)
    );
    assert!(stdout(&o).contains("(ego-only, 3-point)"), "{}", stdout(&o));
}

#[test]
fn inspect_nymeria_with_side_keypoints_and_json() {
    let f = fixtures();
    let kp = format!("observer={}", path_str(&f.join("nymeria_observer_keypoints.jsonl")));
    let o = egoexo(&["inspect", path_str(&f.join("nymeria")), "--keypoints", &kp, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["source"], "Nymeria sequence");
    assert_eq!(v["ground_truth_frames"], 61);
    assert_eq!(v["observers"][0]["keypoints"]["samples"], 61);
    assert_eq!(v["wearer"]["left_wrist"]["samples"], 101);
    let coverage = v["coverage"].as_array().unwrap();
    assert!(coverage.iter().all(|c| c["valid_frames"] == c["frames"]), "{coverage:?}");
    assert!(v["problems"].as_array().unwrap().iter().any(|p| p.as_str().unwrap().contains("mean-shape skeleton")));
}

#[test]
fn convert_writes_an_egoexo_that_inspect_accepts() {
    let dir = scratch("convert");
    for (input, extra) in [
        ("aria_mps", vec![]),
        (
            "nymeria",
            vec![
                "--keypoints".to_owned(),
                format!("observer={}", path_str(&fixtures().join("nymeria_observer_keypoints.jsonl"))),
            ],
        ),
    ] {
        let out = dir.join(format!("{input}.egoexo"));
        let mut args = vec![
            "convert".to_owned(),
            path_str(&fixtures().join(input)).to_owned(),
            "-o".into(),
            path_str(&out).to_owned(),
        ];
        args.extend(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = egoexo(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stdout(&o).contains("wrote"), "{}", stdout(&o));
        let o = egoexo(&["inspect", path_str(&out)]);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = stdout(&o);
        assert!(text.contains(".egoexo session"), "{text}");
        assert!(text.contains("keypoints: 61 frames"), "{text}");
        // Writing over it needs --force.
        let o = egoexo(&args);
        assert_eq!(o.status.code(), Some(1));
        assert!(stderr(&o).contains("exists; pass --force"), "{}", stderr(&o));
    }
    // The folder form, converted again to a zip, still inspects the same.
    let folder = dir.join("folder.egoexo");
    let o = egoexo(&["convert", path_str(&dir.join("nymeria.egoexo")), "-o", path_str(&folder), "--folder"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(folder.join("session.json").is_file() && folder.join("ground_truth.npz").is_file());
    let o = egoexo(&["inspect", path_str(&folder)]);
    assert!(stdout(&o).contains("Ground truth: 61 SMPL frames"), "{}", stdout(&o));
}

#[test]
fn invalid_input_exits_1_with_the_error_on_stderr() {
    let dir = scratch("invalid");
    let session = dir.join("aria");
    copy_dir(&fixtures().join("aria_mps"), &session);
    let csv = session.join("observers/observer-1/mps/slam/closed_loop_trajectory.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let mut fields: Vec<&str> = lines[7].split(',').collect();
    fields[4] = "NaN";
    lines[7] = fields.join(",");
    std::fs::write(&csv, lines.join("\n")).unwrap();
    for command in ["inspect", "convert"] {
        let out = dir.join("out.egoexo");
        let args: Vec<&str> = if command == "inspect" {
            vec!["inspect", path_str(&session)]
        } else {
            vec!["convert", path_str(&session), "-o", path_str(&out)]
        };
        let o = egoexo(&args);
        assert_eq!(o.status.code(), Some(1), "{command}");
        assert!(stdout(&o).is_empty(), "{command}: {}", stdout(&o));
        assert!(
            stderr(&o).contains(
                "error: observers/observer-1/mps/slam/closed_loop_trajectory.csv, line 8, field `ty_world_device`: expected a finite number, got `NaN`"
            ),
            "{command}: {}",
            stderr(&o)
        );
        assert!(!out.exists());
    }
    let o = egoexo(&["inspect", path_str(&dir.join("does-not-exist"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("expected an existing file or folder"), "{}", stderr(&o));
    let o = egoexo(&["inspect", path_str(&fixtures().join("aria_mps")), "--keypoints", "observer-1"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("expected <observer-id>=<file>"), "{}", stderr(&o));
}
