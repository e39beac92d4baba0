//! The real-shaped fixtures import, align and convert, and what comes out matches the scene
//! they were generated from.

use std::collections::BTreeMap;
use std::path::Path;

use crate::support::*;
use egoexo_core::exo_keypoints::{EXO_KEYPOINT_COUNT, exo_from_coco17, exo_keypoints_from_smpl};
use egoexo_core::glam::Vec3;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::rotation::angle_between;
use egoexo_core::skeleton::SmplJoint;
use egoexo_session::format::{read_egoexo, write_egoexo_files, write_egoexo_zip};
use egoexo_session::import::{ImportOptions, KeypointFile, SourceKind, import_session};
use egoexo_session::{AlignOptions, FileTree, Limits, Session, align};

fn read_dir_files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let tree = FileTree::open(dir, Limits::default()).unwrap();
    tree.paths().into_iter().map(|p| (p.clone(), tree.read(&p).unwrap().into_owned())).collect()
}

fn expected_fixtures() -> Vec<(&'static str, BTreeMap<String, Vec<u8>>)> {
    let mut extra = BTreeMap::new();
    extra.insert("nymeria_observer_keypoints.jsonl".to_owned(), keypoints_jsonl("observer", 0).into_bytes());
    // Overlaid on `nymeria/`, they make it a capture of two participants (the CLI's test).
    for (path, bytes) in nymeria_people_files() {
        extra.insert(format!("nymeria_people/{path}"), bytes);
    }
    vec![("aria_mps", aria_fixture()), ("nymeria", nymeria_fixture()), ("extra", extra)]
}

#[test]
fn fixtures_match_the_generator() {
    let regenerate = std::env::var_os("EGOEXO_REGENERATE_FIXTURES").is_some();
    for (name, files) in expected_fixtures() {
        let dir = if name == "extra" { fixtures_dir() } else { fixtures_dir().join(name) };
        if regenerate {
            if name != "extra" {
                let _ = std::fs::remove_dir_all(&dir);
            }
            egoexo_session::vfs::write_dir(&dir, &files).unwrap();
            continue;
        }
        let total: usize = files.values().map(Vec::len).sum();
        assert!(total < 400_000, "fixture {name} is {total} bytes; keep fixtures small");
        for (path, bytes) in &files {
            let on_disk = std::fs::read(dir.join(path))
                .unwrap_or_else(|e| panic!("{name}/{path}: {e}; run with EGOEXO_REGENERATE_FIXTURES=1"));
            assert!(
                on_disk == *bytes,
                "{name}/{path} differs from the generator; run with EGOEXO_REGENERATE_FIXTURES=1"
            );
        }
        if name != "extra" {
            assert_eq!(read_dir_files(&dir).len(), files.len(), "{name}: unexpected extra files");
        }
    }
}

fn assert_pose_near(got: &RigidTransform, want: &RigidTransform, what: &str) {
    let dp = got.translation.distance(want.translation);
    let da = angle_between(got.rotation, want.rotation);
    assert!(dp < 2e-4 && da < 2e-4, "{what}: {dp} m, {da} rad\n got {got:?}\nwant {want:?}");
}

fn import_aria() -> egoexo_session::Imported {
    import_session(
        &FileTree::open(&fixtures_dir().join("aria_mps"), Limits::default()).unwrap(),
        &ImportOptions::default(),
    )
    .unwrap()
}

#[test]
fn aria_fixture_imports_in_session_conventions() {
    let imported = import_aria();
    assert_eq!(imported.source, SourceKind::AriaMultiDevice);
    let s = &imported.session;
    assert_eq!(s.name, "aria_mps");
    let times = sample_times(TRAJECTORY_HZ);
    assert_eq!(s.wearer.head.len(), times.len());
    for (i, &t) in times.iter().enumerate() {
        assert_eq!(s.wearer.head.timestamps_ns[i], session_ns(t));
        assert_pose_near(&s.wearer.head.poses[i], &head_cpf_at(t), "wearer head");
    }
    // The head device is upright: CPF +Y points up in the Y-up world.
    assert!(s.wearer.head.poses[0].transform_vector(Vec3::Y).y > 0.95);
    assert_eq!(s.observers.iter().map(|o| o.id.as_str()).collect::<Vec<_>>(), ["observer-1", "observer-2"]);
    for (k, o) in s.observers.iter().enumerate() {
        assert_pose_near(&o.head.poses[40], &observer_cpf_at(times[40], k), "observer head");
        assert_pose_near(&o.camera.t_device_camera, &rgb_t_cpf_camera(), "T_cpf_camera");
        assert_eq!((o.camera.width, o.camera.height), (1408, 1408));
        let kp = o.keypoints.as_ref().unwrap();
        assert_eq!(kp.frames.len(), sample_times(FRAME_HZ).len());
    }
    // COCO frames got timestamps from the observer trajectory's start at 30 fps.
    let coco = s.observers[1].keypoints.as_ref().unwrap();
    assert_eq!(coco.timestamps_ns[3], START_NS + 100_000_000);
    assert_eq!(coco.frames[3], keypoints_at(0.1, 1), "the higher-scoring person was kept");
    assert_eq!(s.subject.height_m, Some(1.70));
    let messages: Vec<String> = imported.warnings.iter().map(ToString::to_string).collect();
    assert!(messages.iter().any(|m| m.contains("kept the highest-scoring person")), "{messages:#?}");
    // No time_sync.csv anywhere: the import says which clock it took as shared, and how to
    // do otherwise.
    let clocks = messages.iter().find(|m| m.contains("no device folder has a time_sync.csv")).expect("a clock warning");
    assert!(clocks.contains("3 devices") && clocks.contains("taken as one clock"), "{clocks}");
    assert!(clocks.contains("--clock utc"), "{clocks}");
}

/// Projecting the true keypoints with the *imported* observer pose and camera reproduces the
/// pixels in the file: pose, CPF and camera conversions agree with each other end to end.
#[test]
fn imported_cameras_reproject_the_detections() {
    let s = import_aria().session;
    let o = &s.observers[0];
    let kp = o.keypoints.as_ref().unwrap();
    let mut checked = 0;
    for (i, t) in sample_times(FRAME_HZ).into_iter().enumerate() {
        // Observer pose at the keypoint time from the imported trajectory (50 Hz → interpolate).
        let ts = &o.head.timestamps_ns;
        let j = ts.partition_point(|&x| x <= kp.timestamps_ns[i]).clamp(1, ts.len() - 1);
        let alpha = (kp.timestamps_ns[i] - ts[j - 1]) as f32 / (ts[j] - ts[j - 1]) as f32;
        let pose = o.head.poses[j - 1].interpolate(&o.head.poses[j], alpha);
        let fk = egoexo_core::skeleton::SmplSkeleton::mean_shape().forward_kinematics(&body_pose_at(t));
        let world = exo_keypoints_from_smpl(&fk.positions, fk.rotations[SmplJoint::Head.index()], 1.0);
        let detected = exo_from_coco17(&kp.frames[i]);
        for k in 0..EXO_KEYPOINT_COUNT {
            if let Some(d) = detected[k] {
                let pixel = o.camera.project_world(world[k], &pose).unwrap();
                assert!(pixel.distance(d.pixel) < 1.5, "frame {i} keypoint {k}: {pixel} vs {}", d.pixel);
                checked += 1;
            }
        }
    }
    assert!(checked > 500, "{checked}");
}

#[test]
fn aria_fixture_aligns_with_full_coverage() {
    let s = import_aria().session;
    let aligned = align(&s, &AlignOptions::default()).unwrap();
    assert_eq!(aligned.timeline.frames, 61);
    assert_eq!(aligned.timeline.start_ns, START_NS);
    for c in &aligned.coverage {
        assert_eq!(c.valid_frames, c.frames, "{c:?}");
    }
    let names: Vec<&str> = aligned.coverage.iter().map(|c| c.stream.as_str()).collect();
    assert_eq!(
        names,
        ["wearer/head", "observer-1/head", "observer-1/keypoints", "observer-2/head", "observer-2/keypoints"]
    );
    assert_eq!(aligned.observers[0].keypoints[10], exo_from_coco17(&keypoints_at(10.0 / 30.0, 0)));
    // Frame 10 is at 1/3 s: between trajectory samples, interpolated to the truth.
    assert_pose_near(&aligned.head.poses[10], &head_cpf_at(1.0 / 3.0), "aligned head");
    // At 60 fps the timeline doubles and keypoints cover every other frame.
    let at60 = align(&s, &AlignOptions { fps: 60.0, ..AlignOptions::default() }).unwrap();
    assert_eq!(at60.timeline.frames, 121);
    let kp = at60.coverage.iter().find(|c| c.stream == "observer-1/keypoints").unwrap();
    assert_eq!(kp.valid_frames, 61);
}

#[test]
fn nymeria_fixture_imports_on_the_timecode_clock() {
    let tree = FileTree::open(&fixtures_dir().join("nymeria"), Limits::default()).unwrap();
    let keypoints = std::fs::read(fixtures_dir().join("nymeria_observer_keypoints.jsonl")).unwrap();
    let options = ImportOptions {
        keypoint_files: vec![KeypointFile {
            observer_id: "observer".into(),
            name: "kp.jsonl".into(),
            bytes: keypoints,
        }],
        ..ImportOptions::default()
    };
    let imported = import_session(&tree, &options).unwrap();
    assert_eq!(imported.source, SourceKind::Nymeria);
    let s = &imported.session;
    let times = sample_times(TRAJECTORY_HZ);
    for (i, &t) in times.iter().enumerate() {
        // time_sync.csv maps each device clock back onto TimeCode (= the scene's clock) to
        // within the microsecond rounding of MPS timestamps.
        assert!((s.wearer.head.timestamps_ns[i] - session_ns(t)).abs() <= 1_000, "{i}");
        assert_pose_near(&s.wearer.head.poses[i], &head_cpf_at(t), "head");
        let lw = s.wearer.left_wrist.as_ref().unwrap();
        assert!((lw.timestamps_ns[i] - session_ns(t)).abs() <= 1_000);
        assert_pose_near(&lw.poses[i], &wrist_at(t, true), "left wrist (device frame kept)");
        assert_pose_near(&s.wearer.right_wrist.as_ref().unwrap().poses[i], &wrist_at(t, false), "right wrist");
        assert_pose_near(&s.observers[0].head.poses[i], &observer_cpf_at(t, 0), "observer");
    }
    let gt = s.ground_truth.as_ref().unwrap();
    assert!((gt.motion.fps - 30.0).abs() < 0.01, "{}", gt.motion.fps);
    assert_eq!(gt.motion.start_ns, START_NS);
    assert_eq!(gt.motion.betas.as_deref(), Some(&[0.0; 10][..]));
    let truth = truth_motion().joint_positions();
    for (i, joints) in gt.motion.joint_positions().iter().enumerate() {
        for j in 0..24 {
            assert!(joints[j].distance(truth[i][j]) < 1e-3, "frame {i} joint {j}: {} vs {}", joints[j], truth[i][j]);
        }
    }
    assert_eq!(s.observers[0].keypoints.as_ref().unwrap().frames.len(), 61);
    let aligned = align(s, &AlignOptions::default()).unwrap();
    assert_eq!(aligned.timeline.frames, 61);
    let gt_cov = aligned.coverage.iter().find(|c| c.stream == "ground_truth").unwrap();
    assert_eq!(gt_cov.valid_frames, 61, "{gt_cov:?}");
    assert!(aligned.left_wrist.is_some() && aligned.right_wrist.is_some());
}

fn assert_sessions_equal(a: &Session, b: &Session) {
    assert_eq!(a.name, b.name);
    let traj = |x: &egoexo_session::model::Trajectory, y: &egoexo_session::model::Trajectory| {
        assert_eq!(x.timestamps_ns, y.timestamps_ns);
        for (p, q) in x.poses.iter().zip(&y.poses) {
            assert_pose_near(p, q, "trajectory");
        }
    };
    traj(&a.wearer.head, &b.wearer.head);
    assert_eq!(a.wearer.left_wrist.is_some(), b.wearer.left_wrist.is_some());
    if let (Some(x), Some(y)) = (&a.wearer.left_wrist, &b.wearer.left_wrist) {
        traj(x, y);
    }
    assert_eq!(a.observers.len(), b.observers.len());
    for (x, y) in a.observers.iter().zip(&b.observers) {
        assert_eq!(x.id, y.id);
        traj(&x.head, &y.head);
        assert_eq!(x.camera.projection, y.camera.projection);
        assert_eq!(x.keypoints, y.keypoints);
    }
    assert_eq!(a.subject, b.subject);
    assert_eq!(a.ground_truth.is_some(), b.ground_truth.is_some());
    if let (Some(x), Some(y)) = (&a.ground_truth, &b.ground_truth) {
        assert_eq!(x.motion, y.motion);
        assert_eq!(x.occlusion, y.occlusion);
    }
}

#[test]
fn fixtures_convert_to_egoexo_and_back() {
    for dir in ["aria_mps", "nymeria"] {
        let imported = import_session(
            &FileTree::open(&fixtures_dir().join(dir), Limits::default()).unwrap(),
            &ImportOptions::default(),
        )
        .unwrap();
        let zip = write_egoexo_zip(&imported.session).unwrap();
        let back =
            import_session(&FileTree::from_zip("x.egoexo", zip, Limits::default()).unwrap(), &ImportOptions::default())
                .unwrap();
        assert_eq!(back.source, SourceKind::Egoexo);
        assert_sessions_equal(&imported.session, &back.session);
        // The folder form reads the same.
        let files = write_egoexo_files(&imported.session).unwrap();
        let (folder, _) = read_egoexo(&tree("folder", files)).unwrap();
        assert_sessions_equal(&imported.session, &folder);
    }
}

#[test]
fn one_device_folder_and_zipped_folders_are_recognised() {
    // The wearer's device folder alone: a session without observers.
    let wearer: BTreeMap<String, Vec<u8>> = aria_fixture()
        .into_iter()
        .filter_map(|(p, b)| p.strip_prefix("wearer/").map(|p| (format!("slam/{p}"), b)))
        .collect();
    let single = import_session(&tree("glasses", wearer), &ImportOptions::default()).unwrap();
    assert_eq!(single.source, SourceKind::AriaSingleDevice);
    assert!(single.session.observers.is_empty());
    assert_eq!(single.session.wearer.head.len(), 101);
    // A zip whose files sit in one top-level folder (a zipped folder) is looked into, and the
    // session is named after that folder.
    let nested: BTreeMap<String, Vec<u8>> =
        nymeria_fixture().into_iter().map(|(p, b)| (format!("my_sequence/{p}"), b)).collect();
    let zip = egoexo_motion_io::npz::write_zip(&nested).unwrap();
    let imported =
        import_session(&FileTree::from_zip("upload.zip", zip, Limits::default()).unwrap(), &ImportOptions::default())
            .unwrap();
    assert_eq!(imported.source, SourceKind::Nymeria);
    assert_eq!(imported.session.name, "my_sequence");
    let messages: Vec<String> = imported.warnings.iter().map(ToString::to_string).collect();
    assert!(
        messages.iter().any(|m| m.starts_with("my_sequence/body/xdata_smpl_neutral.npz: no SMPL model")),
        "{messages:#?}"
    );
}

#[test]
fn utc_clock_reads_utc_timestamps() {
    let options = ImportOptions { clock: egoexo_session::aria::trajectory::Clock::Utc, ..ImportOptions::default() };
    let mut files = aria_fixture();
    // The JSON-lines keypoints carry session-clock times: with the UTC clock they are on
    // another clock than the trajectories, and say so.
    let err = import_session(&tree("aria", files.clone()), &options).unwrap_err();
    assert!(err.to_string().contains("observers[0].keypoints.timestamps_ns`: mixed clocks"), "{err}");
    files.remove("observers/observer-1/keypoints.jsonl");
    let s = import_session(&tree("aria", files), &options).unwrap().session;
    assert_eq!(s.wearer.head.timestamps_ns[0], START_NS + UTC_OFFSET_NS);
    // COCO frames are timed from the observer trajectory, so they follow the chosen clock.
    assert_eq!(s.observers[1].keypoints.as_ref().unwrap().timestamps_ns[0], START_NS + UTC_OFFSET_NS);
}

/// An observer folder's MP4 and its capture times: found next to the MPS files, timed on the
/// session clock, kept through `.egoexo`; a missing timestamps file or two videos are errors
/// naming the folder, and the UTC clock leaves the video out with a warning.
#[test]
fn an_observer_folder_video_is_found_and_timed() {
    let mut files = aria_fixture();
    let times: Vec<i64> = (0..5).map(|i| START_NS + 1_000_000 + i * 33_333_333).collect();
    let csv =
        std::iter::once("capture_timestamp_ns".to_owned()).chain(times.iter().map(i64::to_string)).collect::<Vec<_>>();
    files.insert("observers/observer-1/video/rgb.mp4".into(), b"an mp4 the import does not open".to_vec());
    files.insert("observers/observer-1/video/rgb.timestamps.csv".into(), (csv.join("\n") + "\n").into_bytes());
    let imported = import_session(&tree("aria", files.clone()), &ImportOptions::default()).unwrap();
    let video = imported.session.observers[0].video.clone().expect("observer-1 has its video");
    assert_eq!(video.path, "observers/observer-1/video/rgb.mp4");
    assert_eq!((video.start_ns, &video.frame_times_ns), (times[0], &times));
    assert!(imported.session.observers[1].video.is_none());

    // Through .egoexo: the frame times come back.
    let mut egoexo = write_egoexo_files(&imported.session).unwrap();
    egoexo.insert(video.path.clone(), files["observers/observer-1/video/rgb.mp4"].clone());
    let (back, warnings) = read_egoexo(&tree("s.egoexo", egoexo)).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(back.observers[0].video.as_ref(), Some(&video));

    let mut missing = files.clone();
    missing.remove("observers/observer-1/video/rgb.timestamps.csv");
    let err = import_session(&tree("aria", missing), &ImportOptions::default()).unwrap_err();
    assert!(err.to_string().starts_with("observers/observer-1/video/rgb.timestamps.csv: file not found"), "{err}");
    assert!(err.to_string().contains("capture_timestamp_ns"), "{err}");
    let mut two = files.clone();
    two.insert("observers/observer-1/other.mp4".into(), vec![0]);
    let err = import_session(&tree("aria", two), &ImportOptions::default()).unwrap_err();
    assert!(err.to_string().contains("at most one MP4 video per observer folder"), "{err}");
    let mut bad = files.clone();
    bad.insert("observers/observer-1/video/rgb.timestamps.csv".into(), b"capture_timestamp_ns\n5\n4\n".to_vec());
    let err = import_session(&tree("aria", bad), &ImportOptions::default()).unwrap_err();
    assert!(err.to_string().contains("rgb.timestamps.csv, line 3, field `capture_timestamp_ns`"), "{err}");

    let utc = ImportOptions { clock: egoexo_session::aria::trajectory::Clock::Utc, ..ImportOptions::default() };
    files.remove("observers/observer-1/keypoints.jsonl");
    let imported = import_session(&tree("aria", files), &utc).unwrap();
    assert!(imported.session.observers[0].video.is_none());
    assert!(
        imported.warnings.iter().any(|w| w.file.ends_with("rgb.mp4") && w.message.contains("UTC")),
        "{:?}",
        imported.warnings
    );
}
