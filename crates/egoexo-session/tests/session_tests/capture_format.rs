//! Broken captures (format version 3) are clear errors naming the manifest field and what was
//! expected: a view with both a target and people, a video without its camera, a view from a
//! participant without a camera, two participants with one id, too many people in a frame.

use std::collections::BTreeMap;

use crate::support::*;
use egoexo_session::format::{read_capture, write_capture_files};
use serde_json::Value;

/// The Aria fixture as a capture of three participants, everyone reconstructed.
fn capture_files() -> BTreeMap<String, Vec<u8>> {
    let (mut capture, _) = read_capture(&tree("aria", egoexo_fixture_files())).unwrap();
    for p in &mut capture.participants {
        p.reconstruct = true;
    }
    write_capture_files(&capture).unwrap()
}

fn error_after(edit: impl Fn(&mut Value, &mut BTreeMap<String, Vec<u8>>)) -> String {
    let mut files = capture_files();
    let mut manifest: Value = serde_json::from_slice(&files["session.json"]).unwrap();
    edit(&mut manifest, &mut files);
    files.insert("session.json".into(), serde_json::to_vec(&manifest).unwrap());
    read_capture(&tree("capture", files)).map(|_| ()).unwrap_err().to_string()
}

#[test]
fn broken_captures_name_the_field_and_what_was_expected() {
    let e = error_after(|m, _| m["views"][0]["people"] = m["views"][0]["keypoints"].clone());
    assert!(e.contains("field `views[0]`") && e.contains("either `target` and `keypoints`"), "{e}");
    let e = error_after(|m, _| {
        m["participants"][1]["video"] = serde_json::json!({"path": "v.mp4", "start_ns": 0});
        m["participants"][1].as_object_mut().unwrap().remove("camera");
    });
    assert!(e.contains("field `participants[1].video`") && e.contains("only with the camera"), "{e}");
    // The view's keypoints name their camera; a view from one without a camera is refused.
    let e = error_after(|m, _| m["views"][0]["observer"] = "wearer".into());
    assert!(e.contains("field `observer`: observer id `observer-1` does not match `wearer`"), "{e}");
    let e = error_after(|m, files| {
        let text = String::from_utf8(files["views/observer-1/wearer.keypoints.jsonl"].clone()).unwrap();
        files.insert("w.jsonl".into(), text.replace("\"observer-1\"", "\"wearer\"").into_bytes());
        m["views"][0] = serde_json::json!({"observer": "wearer", "target": "observer-2", "keypoints": "w.jsonl"});
    });
    assert!(e.contains("view 0 names observer `wearer`, which is no participant with a camera"), "{e}");
    let e = error_after(|m, _| m["participants"][2]["id"] = m["participants"][1]["id"].clone());
    assert!(e.contains("are both called"), "{e}");
    let e = error_after(|m, _| m["participants"][0]["reconstruct"] = "yes".into());
    assert!(e.contains("field `participants[0].reconstruct`: invalid type: string \"yes\", expected a boolean"), "{e}");
    let e = error_after(|m, files| {
        let person = format!("[{}]", vec!["null"; 17].join(","));
        let people = vec![person; 65].join(",");
        let line = format!("{{\"timestamp_ns\": 1, \"people\": [{people}]}}\n");
        files.insert("views/observer-1/people.jsonl".into(), line.into_bytes());
        m["views"][0] = serde_json::json!({"observer": "observer-1", "people": "views/observer-1/people.jsonl"});
    });
    assert!(e.contains("people.jsonl, line 1, field `people`: expected at most 64 people"), "{e}");
}

/// A Nymeria sequence whose two pairs of glasses both saw people: the wearer and the observer
/// become two participants to reconstruct, the wearer's glasses get their RGB camera, and each
/// camera's people are a view without identity. Without people files it stays one session.
#[test]
fn a_nymeria_sequence_with_people_files_is_a_capture_of_two() {
    use egoexo_session::capture::ViewPeople;
    use egoexo_session::import::{ImportOptions, detect_source, has_people_files, import_capture};

    let plain = import_capture(&tree("nymeria", nymeria_fixture()), &ImportOptions::default()).unwrap().capture;
    assert!(plain.is_one_session());
    assert_eq!(plain.participants.iter().map(|p| p.reconstruct).collect::<Vec<_>>(), [true, false]);

    let mut files = nymeria_fixture();
    // The observer's camera: the wearer (the fixture's keypoints) and a second person.
    files.insert(
        "recording_observer/people.jsonl".into(),
        people_jsonl("observer", |t| vec![keypoints_at(t, 0), keypoints_at(t + 0.5, 1)]).into_bytes(),
    );
    // The wearer's camera: one person, or nobody every third frame.
    files.insert(
        "recording_head/people.jsonl".into(),
        people_jsonl(
            "wearer",
            |t| if (t * 30.0).round() as i64 % 3 == 0 { Vec::new() } else { vec![keypoints_at(t, 1)] },
        )
        .into_bytes(),
    );
    let tree = tree("nymeria", files);
    let (source, root) = detect_source(&tree).unwrap();
    assert!(has_people_files(&root, source));
    let imported = import_capture(&tree, &ImportOptions::default()).unwrap();
    let capture = &imported.capture;
    assert!(!capture.is_one_session());
    let ids: Vec<_> = capture.participants.iter().map(|p| (p.id.as_str(), p.reconstruct, p.camera.is_some())).collect();
    assert_eq!(ids, [("wearer", true, true), ("observer", true, true)]);
    let unassigned: Vec<_> = capture
        .views
        .iter()
        .filter(|v| matches!(v.people, ViewPeople::Unassigned(_)))
        .map(|v| v.observer.as_str())
        .collect();
    assert_eq!(unassigned, ["wearer", "observer"]);
    // Each participant's session: the other one observes.
    assert_eq!(capture.session_for(1).unwrap().observers[0].id, "wearer");
    assert!(capture.session_for(0).unwrap().ground_truth.is_some(), "the wearer keeps Nymeria's body");
}
