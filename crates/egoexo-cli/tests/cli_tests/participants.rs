//! Captures of several participants through the CLI: `walk --participants` writes one (format
//! version 3, every camera's people without identity, bystanders among them); `inspect` lists
//! who is in it; `reconstruct` associates the people and writes one motion per participant,
//! each scored against the capture's ground truth; bad requests get a reason.

use std::path::Path;

use crate::common::{copy_dir, egoexo, run};

#[test]
fn a_capture_of_two_participants_reconstructs_both() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("participants");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let s = |p: &Path| p.display().to_string();
    let capture = dir.join("pair.egoexo");
    run(&["walk", "--seconds", "8", "--participants", "2", "--bystanders", "3", "--seed", "5", "-o", &s(&capture)]);

    let (text, _) = run(&["inspect", &s(&capture)]);
    assert!(text.contains("(2 participants)") && text.contains("participant participant-2: reconstructed"), "{text}");
    assert!(text.contains("people without identity"), "{text}");
    let (json, _) = run(&["inspect", &s(&capture), "--json"]);
    let summary: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(summary["participants"].as_array().unwrap().len(), 2);
    assert_eq!(summary["sessions"].as_array().unwrap().len(), 2);

    let output = dir.join("pair.json");
    let (stdout, stderr) = run(&["reconstruct", &s(&capture), "-o", &s(&output)]);
    for (id, other) in [("participant-1", "participant-2"), ("participant-2", "participant-1")] {
        assert!(
            stderr.contains(&format!("associated {id}'s camera")) && stderr.contains(&format!("to {other}")),
            "{stderr}"
        );
        let file = dir.join(format!("pair.{id}.json"));
        let recon: serde_json::Value = serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
        assert_eq!(recon["joints"].as_array().unwrap().len(), 240, "{}", file.display());
        let line = stdout.lines().find(|l| l.contains(&format!("participant {id}"))).unwrap();
        assert!(line.contains("ego-exo") && line.contains("from 1 observers"), "{line}");
        let mpjpe: f64 = line.rsplit("MPJPE ").next().unwrap().split(' ').next().unwrap().parse().unwrap();
        assert!(mpjpe < 12.0, "{id}: MPJPE {mpjpe} cm");
    }
    assert!(stderr.contains("matched nobody (bystanders)"), "{stderr}");

    // Ego-only, the outputs exist now, keypoint files, video.
    let out = egoexo(&["reconstruct", &s(&capture), "-o", &s(&output)]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("pass --force"));
    let (stdout, _) = run(&["reconstruct", &s(&capture), "-o", &s(&dir.join("ego.npz")), "--ego-only"]);
    assert_eq!(stdout.matches("ego-only").count(), 2, "{stdout}");
    assert!(dir.join("ego.participant-2.npz").exists());
    let keypoints = dir.join("k.jsonl");
    std::fs::write(&keypoints, "").unwrap();
    let spec = format!("participant-1={}", s(&keypoints));
    let out = egoexo(&["reconstruct", &s(&capture), "-o", &s(&dir.join("k.npz")), "--keypoints", &spec]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("a capture of 2 participants"), "{out:?}");
    let hands = s(&dir.join("h.egoexo"));
    let out = egoexo(&["walk", "--seconds", "2", "--participants", "2", "--tracking", "3-hand-tracking", "-o", &hands]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("wrist devices or none"));
    let out =
        egoexo(&["walk", "--seconds", "2", "--participants", "2", "--video", "256", "-o", &s(&dir.join("v.egoexo"))]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("--video"));
}

/// The Nymeria-shaped fixture with people files (the observer's camera sees the wearer and a
/// bystander; the wearer's camera sees the observer): both people are reconstructed, the
/// wearer against Nymeria's body, the observer from their glasses and the wearer's view.
#[test]
fn a_nymeria_sequence_with_two_participants_reconstructs_both() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../egoexo-session/tests/fixtures");
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("nymeria-two");
    let _ = std::fs::remove_dir_all(&dir);
    let sequence = dir.join("sequence");
    copy_dir(&fixtures.join("nymeria"), &sequence);
    copy_dir(&fixtures.join("nymeria_people"), &sequence);
    let s = |p: &Path| p.display().to_string();

    let (text, _) = run(&["inspect", &s(&sequence)]);
    assert!(text.contains("participant observer: reconstructed, RGB camera"), "{text}");
    let output = dir.join("motion.npz");
    let (stdout, stderr) = run(&["reconstruct", &s(&sequence), "-o", &s(&output)]);
    assert!(stderr.contains("associated observer's camera") && stderr.contains("61 to wearer"), "{stderr}");
    let seen: usize = stderr
        .split("associated wearer's camera: ")
        .nth(1)
        .and_then(|rest| rest.split(" to observer").next())
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    assert!(seen > 40, "the wearer's camera sees the observer in most frames: {stderr}");
    let wearer = stdout.lines().find(|l| l.contains("participant wearer")).unwrap();
    assert!(wearer.contains("ego-exo, 3-point") && wearer.contains("MPJPE"), "{wearer}");
    let observer = stdout.lines().find(|l| l.contains("participant observer")).unwrap();
    assert!(observer.contains("ego-exo, 1-point"), "{observer}");
    assert!(dir.join("motion.wearer.npz").exists() && dir.join("motion.observer.npz").exists());
}

/// `eval-group` through the CLI: one short scene each of 2 and 3 participants, as JSON.
#[test]
fn eval_group_scores_association_and_every_participant() {
    let (stdout, _) = run(&["eval-group", "--scenes", "1", "--seconds", "6", "--json"]);
    let report: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(report["association"].as_array().unwrap().len(), 2, "{report}");
    let participants = report["participants"].as_array().unwrap();
    assert_eq!(participants.len(), 5, "2 + 3 participants: {report}");
    for row in participants {
        assert!(row["ego_exo_mpjpe_cm"].as_f64().unwrap() > 0.0, "{row}");
    }
    let (table, _) = run(&["eval-group", "--scenes", "1", "--seconds", "6"]);
    assert!(table.contains("| association error rate |") && table.contains("| mean |"), "{table}");
    let out = egoexo(&["eval-group", "--tracking", "3-hand-tracking"]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("wrist devices or none"));
    let out = egoexo(&["eval-group", "--scenes", "0"]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("--scenes 0"));
}
