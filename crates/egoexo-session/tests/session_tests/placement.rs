//! Observers' placements in the formats: static cameras (a fixed pose, or none to register)
//! in `.egoexo` v2 sessions and v3 captures, own worlds and clocks, registration records; and
//! the clear errors of placements that contradict themselves.

use std::collections::BTreeMap;

use crate::support::*;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_session::format::{read_capture, read_egoexo, write_capture_files, write_egoexo_files};
use egoexo_session::placement::{ClockRef, Mount, Placement, WorldRef};
use serde_json::{Value, json};

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
    assert!(e.contains("field `observers[1].placement.world`: unknown variant `elsewhere`"), "{e}");
}

/// The multi-device Aria folder with observer-2 a static camera (`static_camera.json`
/// `camera` plus `static`: its pose or `placement`) and observer-1 localised alone.
fn aria_with_static_camera(static_camera: Value) -> BTreeMap<String, Vec<u8>> {
    let mut files = aria_fixture();
    files.retain(|path, _| !path.starts_with("observers/observer-2/slam/"));
    files.insert("observers/observer-2/static_camera.json".into(), static_camera.to_string().into_bytes());
    files.insert("observers/observer-1/placement.json".into(), br#"{"world": "own"}"#.to_vec());
    files
}

fn pinhole_json() -> Value {
    json!({"model": "pinhole", "params": [500.0, 500.0, 320.0, 240.0], "width": 640, "height": 480,
        "t_device_camera": {"translation": [0.0, 0.0, 0.0], "rotation_xyzw": [0.0, 0.0, 0.0, 1.0]}})
}

#[test]
fn the_multi_device_folder_takes_static_cameras_and_devices_in_worlds_of_their_own() {
    use egoexo_session::{ImportOptions, import_session};
    // A webcam that knows nothing of its pose nor its focal length: registration places it.
    let unposed = json!({"camera": pinhole_json(),
        "placement": {"mount": "fixed", "world": "own", "gravity": false, "focal_known": false}});
    let imported =
        import_session(&tree("aria_mps", aria_with_static_camera(unposed)), &ImportOptions::default()).unwrap();
    let session = &imported.session;
    let head_range = session.wearer.head.time_range_ns().unwrap();
    let webcam = session.observers.iter().find(|o| o.id == "observer-2").unwrap();
    assert_eq!(webcam.placement, Placement::fixed_unposed(false));
    let (start, end) = webcam.head.time_range_ns().unwrap();
    assert!(start <= head_range.0 && end >= head_range.1, "its one pose spans the recording");
    assert_eq!(webcam.keypoints.as_ref().unwrap().frames.len(), 61, "its COCO keypoints from the wearer's start");
    assert!(!webcam.placement.fusable());
    // The glasses MPS localised alone: their own world, gravity-aligned, not fused as given.
    let glasses = session.observers.iter().find(|o| o.id == "observer-1").unwrap();
    assert_eq!(glasses.placement.world, WorldRef::Own);
    assert!(glasses.placement.gravity && !glasses.placement.fusable());

    // A camera with a pose in the session's world is fused as given.
    let pose = json!({"translation": [1.0, 1.5, -2.0], "rotation_xyzw": [0.0, 0.0, 0.0, 1.0]});
    let posed = json!({"camera": pinhole_json(), "pose": pose});
    let session =
        import_session(&tree("aria_mps", aria_with_static_camera(posed)), &ImportOptions::default()).unwrap().session;
    let webcam = session.observers.iter().find(|o| o.id == "observer-2").unwrap();
    assert_eq!(webcam.placement.mount, Mount::Fixed);
    assert!(webcam.placement.fusable());
    assert!(webcam.head.poses.iter().all(|p| p.translation == Vec3::new(1.0, 1.5, -2.0)));
}

#[test]
fn static_cameras_and_placements_in_the_folder_layout_have_clear_errors() {
    use egoexo_session::{ImportOptions, import_session};
    let error = |files| import_session(&tree("aria_mps", files), &ImportOptions::default()).unwrap_err().to_string();
    // Neither a pose nor a placement to register it.
    let e = error(aria_with_static_camera(json!({"camera": pinhole_json()})));
    assert!(e.contains("observers/observer-2/static_camera.json") && e.contains("`pose` (a static camera)"), "{e}");
    // A static camera beside MPS output.
    let mut both = aria_with_static_camera(
        json!({"camera": pinhole_json(), "pose": {"translation": [0, 1, 0], "rotation_xyzw": [0, 0, 0, 1]}}),
    );
    both.insert(
        "observers/observer-2/slam/closed_loop_trajectory.csv".into(),
        aria_fixture()["observers/observer-2/slam/closed_loop_trajectory.csv"].clone(),
    );
    let e = error(both);
    assert!(e.contains("static_camera.json") && e.contains("closed_loop_trajectory.csv"), "{e}");
    // A placement file that says what an MPS folder cannot be, or is not a placement.
    let mut fixed = aria_fixture();
    fixed.insert("observers/observer-1/placement.json".into(), br#"{"mount": "fixed"}"#.to_vec());
    let e = error(fixed);
    assert!(e.contains("observers/observer-1/placement.json") && e.contains("`worn` for an MPS device folder"), "{e}");
    let mut bad = aria_fixture();
    bad.insert("observers/observer-1/placement.json".into(), br#"{"world": "elsewhere"}"#.to_vec());
    let e = error(bad);
    assert!(e.contains("observers/observer-1/placement.json") && e.contains("world: shared|own"), "{e}");
}
