//! Live capture from the command line, as users run it: a real `egoexo serve`, `live room`,
//! `live replay` of the sample session (a wearer with wrists and two observers, each device
//! with its own drifting, offset clock) watched by `live record`. The take holds every frame
//! that was sent, on one clock with no gaps but the injected one, even when a device leaves and
//! comes back and another's clock jumps; it reconstructs offline. `live load` accounts for every
//! frame.
#![cfg(not(target_arch = "wasm32"))]

use crate::common;

use std::path::PathBuf;
use std::process::{Command, Stdio};

use egoexo_session::model::Trajectory;
use egoexo_test_support::workspace_root;
use serde_json::Value;

/// `egoexo serve` with its page and store in folders that live as long as it.
struct LiveServer {
    served: common::Served,
    url: String,
    _dirs: (tempfile::TempDir, tempfile::TempDir),
}

fn serve() -> LiveServer {
    let (dist, store) = (common::dist(), tempfile::tempdir().unwrap());
    let served = common::serve(dist.path(), &store.path().display().to_string(), &[], &[]);
    LiveServer { url: served.url.clone(), served, _dirs: (dist, store) }
}

fn egoexo(args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_egoexo"));
    command.args(args);
    command
}

/// Runs to the end; its last stdout line as JSON.
fn json_of(mut command: Command) -> Value {
    let out = command.output().expect("egoexo runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{command:?} failed:\n{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(stdout.lines().last().unwrap_or_default()).unwrap_or_else(|e| panic!("{e}: {stdout}"))
}

fn sample() -> PathBuf {
    workspace_root().join("public/samples/cmu-14_20.egoexo")
}

/// Largest interval between consecutive samples, seconds.
fn largest_gap_s(t: &Trajectory) -> f64 {
    t.timestamps_ns.windows(2).map(|w| (w[1] - w[0]) as f64 / 1e9).fold(0.0, f64::max)
}

#[test]
fn a_replayed_session_is_recorded_frame_for_frame_and_reconstructs() {
    let served = serve();
    let dir = tempfile::tempdir().unwrap();
    let room = json_of(egoexo(&["live", "room", "--url", &served.url, "--json"]));
    let code = room["device_code"].as_str().unwrap();
    assert!(room["watch_link"].as_str().unwrap().starts_with(&format!("{}/#live=", served.url)));
    let take = dir.path().join("take.egoexo");
    let recorder = egoexo(&["live", "record", "--url", &served.url, "--until-idle-s", "3", "--out"])
        .arg(&take)
        .arg("--room")
        .arg(room["watch_link"].as_str().unwrap())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The recorder's hello takes a moment; frames only flow 1.5 s after the replay starts.
    let mut replay = egoexo(&["live", "replay", "--url", &served.url, "--room", code, "--duration-s", "4"]);
    replay.arg(sample()).args(["--disconnect", "observer-1@1+1", "--clock-jump", "observer-2@2+5"]);
    let sent = json_of(replay);
    let recorded = recorder.wait_with_output().unwrap();
    assert!(recorded.status.success(), "live record failed:\n{}", String::from_utf8_lossy(&recorded.stderr));
    let recorded: Value =
        serde_json::from_str(String::from_utf8_lossy(&recorded.stdout).lines().last().unwrap_or_default()).unwrap();

    // Every frame sent is in the take; nothing was dropped (nobody was overloaded).
    for device in sent["devices"].as_array().unwrap() {
        let id = device["id"].as_str().unwrap();
        assert_eq!(recorded["frames"][id], device["sent"], "device {id}: sent vs recorded");
        assert!(device["sent"].as_object().unwrap().values().all(|n| n.as_u64().unwrap() > 60), "{device}");
    }
    let observer_1 = sent["devices"].as_array().unwrap().iter().find(|d| d["id"] == "observer-1").unwrap();
    assert_eq!(observer_1["connections"], 2);
    assert!(observer_1["not_sent"].as_u64().unwrap() > 40, "{observer_1}");
    assert_eq!(recorded["dropped_by_relay"], 0);
    assert_eq!(recorded["duplicates"], 0);

    // One clock: offsets of ±1000 s, 50 ppm drifts and a 5 s jump leave no trace but the
    // disconnection.
    let session = egoexo_session::import::import_path(&take, &Default::default()).unwrap().session;
    assert!(largest_gap_s(&session.wearer.head) < 0.1);
    let observer = |id: &str| session.observers.iter().find(|o| o.id == id).unwrap();
    assert!(largest_gap_s(&observer("observer-2").head) < 0.1, "the clock jump left a gap");
    let gap = largest_gap_s(&observer("observer-1").head);
    assert!((0.9..1.2).contains(&gap), "the disconnection spans {gap} s");
    let (first, last) = session.wearer.head.time_range_ns().unwrap();
    let span_s = (last - first) as f64 / 1e9;
    assert!((3.9..4.1).contains(&span_s), "the take spans {span_s} s");
    for o in &session.observers {
        let (a, b) = o.head.time_range_ns().unwrap();
        assert!(
            (a - first).abs() < 50_000_000 && (b - last).abs() < 50_000_000,
            "{} is not on the wearer's clock",
            o.id
        );
    }

    // The take is an ordinary session: it reconstructs offline with the shipped models.
    let csv = dir.path().join("take.csv");
    let out = egoexo(&["reconstruct", "--models"])
        .arg(workspace_root().join("models"))
        .arg(&take)
        .arg("-o")
        .arg(&csv)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = std::fs::read_to_string(&csv).unwrap().lines().count();
    assert!((115..=125).contains(&(rows - 1)), "{rows} rows for 4 s at 30 fps");
}

#[test]
fn a_short_load_accounts_for_every_frame() {
    let served = serve();
    let report = json_of(egoexo(&[
        "live",
        "load",
        "--url",
        &served.url,
        "--relay-pid",
        &served.served.child.id().to_string(),
        "--rooms",
        "2",
        "--devices-per-room",
        "3",
        "--viewers-per-room",
        "2",
        "--duration-s",
        "3",
    ]));
    let n = |k: &str| report[k].as_u64().unwrap_or_else(|| panic!("no {k} in {report}"));
    // 6 streams × 30 Hz × 3 s, each seen by 2 viewers.
    assert!((500..=560).contains(&n("frames_sent")), "{report}");
    assert_eq!(n("frames_expected"), 2 * n("frames_sent"));
    // What a viewer did not receive, the relay dropped and reported (a healthy viewer: none).
    assert_eq!(n("frames_received") + n("dropped_by_relay"), n("frames_expected"), "{report}");
    assert!(report["latency_ms"]["samples"].as_u64().unwrap() > 500);
    assert!(report["relay"]["rss_peak_mib"].as_f64().unwrap() > 1.0);
}

#[test]
fn bad_rooms_and_servers_are_clear_errors() {
    let served = serve();
    let out = egoexo(&["live", "replay", "--url", &served.url, "--room", "ZZZ-ZZZ", "--duration-s", "1"])
        .arg(sample())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("4001") || err.to_lowercase().contains("room"), "{err}");
    let out = egoexo(&["live", "record", "--url", "ftp://x", "--room", "a.b", "--out", "/tmp/never.egoexo"])
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("ftp"));
    let out =
        egoexo(&["live", "replay", "--url", &served.url, "--disconnect", "nobody@1+1"]).arg(sample()).output().unwrap();
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("no device `nobody`"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
