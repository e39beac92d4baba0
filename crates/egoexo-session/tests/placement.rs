//! Observers' placements in the formats: static cameras (a fixed pose, or none to register)
//! in `.egoexo` v2 sessions and v3 captures, own worlds and clocks, registration records; and
//! the clear errors of placements that contradict themselves.

mod support;

use std::collections::BTreeMap;

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_session::format::{read_capture, read_egoexo, write_capture_files, write_egoexo_files};
use egoexo_session::placement::{ClockRef, Mount, Placement, WorldRef};
use serde_json::{Value, json};
use support::*;

fn fixture() -> egoexo_session::Session {
    read_egoexo(&tree("aria", egoexo_fixture_files())).unwrap().0
}

fn manifest(files: &BTreeMap<String, Vec<u8>>) -> Value {
    serde_json::from_slice(&files["session.json"]).unwrap()
}

#[test]
fn a_static_camera_without_pose_is_written_without_poses_and_spans_the_recording_when_read() {
    let mut session = fixture();
    let head_range = session.wearer.head.time_range_ns().unwrap();
    session.observers[0].placement = Placement::fixed_unposed(false);
    session.observers[0].head.poses.fill(RigidTransform::IDENTITY);
    let files = write_egoexo_files(&session).unwrap();
    let m = manifest(&files);
    let entry = &m["observers"][0];
    assert!(entry.get("trajectory").is_none() && entry.get("pose").is_none(), "{entry}");
    assert_eq!(entry["placement"], json!({"world": "own", "gravity": false, "mount": "fixed", "focal_known": false}));
    assert!(!files.contains_key("observers/observer-1/closed_loop_trajectory.csv"));
    let (read, warnings) = read_egoexo(&tree("static", files)).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let observer = &read.observers[0];
    assert_eq!(observer.placement, Placement::fixed_unposed(false));
    assert_eq!(observer.head.poses, [RigidTransform::IDENTITY; 2]);
    let (start, end) = observer.head.time_range_ns().unwrap();
    assert!(start <= head_range.0 && end >= head_range.1, "{start}..{end} covers the wearer's {head_range:?}");
    assert!(!observer.placement.fusable());
    // Written again, the same manifest.
    assert_eq!(manifest(&write_egoexo_files(&read).unwrap())["observers"][0], m["observers"][0]);
}

#[test]
fn a_static_camera_with_a_pose_keeps_it() {
    let mut session = fixture();
    let pose = RigidTransform { rotation: Quat::from_rotation_y(0.7), translation: Vec3::new(1.0, 1.5, -2.0) };
    session.observers[1].placement = Placement { mount: Mount::Fixed, ..Placement::default() };
    session.observers[1].head.poses.fill(pose);
    let files = write_egoexo_files(&session).unwrap();
    let entry = &manifest(&files)["observers"][1];
    assert!(entry.get("trajectory").is_none() && entry["pose"].is_object(), "{entry}");
    let (read, _) = read_egoexo(&tree("static", files)).unwrap();
    let observer = &read.observers[1];
    assert_eq!(observer.placement.mount, Mount::Fixed);
    assert!(observer.placement.fusable(), "a posed static camera in the session world is fused as given");
    for p in &observer.head.poses {
        assert!(p.translation.distance(pose.translation) < 1e-5 && p.rotation.angle_between(pose.rotation) < 1e-5);
    }
    // A fixed mount whose poses move cannot be written.
    let mut moving = session.clone();
    moving.observers[1].head.poses[0].translation.x += 0.1;
    let e = write_egoexo_files(&moving).unwrap_err().to_string();
    assert!(e.contains("a fixed mount has one pose"), "{e}");
}

#[test]
fn own_worlds_and_clocks_round_trip_in_sessions_and_captures() {
    let mut session = fixture();
    session.observers[0].placement =
        Placement { world: WorldRef::Own, clock: ClockRef::Own, gravity: true, ..Placement::default() };
    let files = write_egoexo_files(&session).unwrap();
    assert_eq!(manifest(&files)["observers"][0]["placement"], json!({"world": "own", "clock": "own"}));
    let (read, _) = read_egoexo(&tree("own", files)).unwrap();
    assert_eq!(read, session);
    // In a capture, a participant's placement is against the capture's world; a static camera
    // participant has a pose instead of a head trajectory.
    let (mut capture, _) = read_capture(&tree("aria", egoexo_fixture_files())).unwrap();
    capture.participants[2].placement = Placement::fixed_unposed(true);
    capture.participants[2].head.poses.fill(RigidTransform::IDENTITY);
    let files = write_capture_files(&capture).unwrap();
    let entry = &manifest(&files)["participants"][2];
    assert!(entry.get("head").is_none() && entry.get("pose").is_none(), "{entry}");
    let (read, _) = read_capture(&tree("capture", files)).unwrap();
    assert_eq!(read.participants[2].placement, Placement::fixed_unposed(true));
    let wearer = read.session_for(0).unwrap();
    let seen = wearer.observers.iter().find(|o| o.id == read.participants[2].id).unwrap();
    assert!(!seen.placement.fusable());
}

fn error_after(edit: impl Fn(&mut Value)) -> String {
    let mut files = egoexo_fixture_files();
    let mut m = manifest(&files);
    edit(&mut m);
    files.insert("session.json".into(), serde_json::to_vec(&m).unwrap());
    read_egoexo(&tree("broken", files)).map(|_| ()).unwrap_err().to_string()
}

#[test]
fn placements_that_contradict_themselves_are_clear_errors() {
    let pose = json!({"translation": [0.0, 1.0, 0.0], "rotation_xyzw": [0.0, 0.0, 0.0, 1.0]});
    let e = error_after(|m| m["observers"][0]["pose"] = pose.clone());
    assert!(e.contains("field `observers[0].pose`") && e.contains("not both"), "{e}");
    let e = error_after(|m| m["observers"][0]["placement"] = json!({"mount": "fixed"}));
    assert!(e.contains("field `observers[0].placement.mount`") && e.contains("a static camera has `pose`"), "{e}");
    let e = error_after(|m| {
        m["observers"][0].as_object_mut().unwrap().remove("trajectory");
    });
    assert!(e.contains("field `observers[0].trajectory`") && e.contains("none of them"), "{e}");
    let e = error_after(|m| {
        m["observers"][0].as_object_mut().unwrap().remove("trajectory");
        m["observers"][0]["placement"] = json!({"mount": "fixed"});
    });
    assert!(e.contains("`world: own`"), "a fixed camera without pose in the session world: {e}");
    let e = error_after(|m| m["observers"][1]["placement"] = json!({"world": "elsewhere"}));
    assert!(e.contains("field `observers[1].placement`") && e.contains("unknown variant `elsewhere`"), "{e}");
}
