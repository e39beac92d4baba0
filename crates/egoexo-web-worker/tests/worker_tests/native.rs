//! The worker natively: the fixture session through import → reconstruct → scene → export with
//! the fixture networks, errors, cancel. `reconstruction_matches_the_recording` also keeps
//! `tests/fixtures/expected_reconstruction.json`, which the browser test
//! (`tests/worker_wasm.rs`) compares the wasm build against; after an intended change of the
//! engine's output, rewrite it with `EGOEXO_BLESS=1 cargo test -p egoexo-web-worker --test worker_tests native::`.
#![cfg(not(target_arch = "wasm32"))]

use std::collections::BTreeMap;
use std::io::{Cursor, Read};

use crate::common::*;
use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_core::glam::Vec3;
use egoexo_infer::InferError;
use egoexo_protocol::worker::{ErrorKind, ExportFormat, JobStage, NetworkRuns};
use egoexo_scene::SceneData;
use egoexo_session::{FileTree, ImportError, Limits};
use egoexo_web_worker::worker::motion_format;
use egoexo_web_worker::{JobProgress, SessionWorker, WorkerError};

fn read_fixture_model(file: &str) -> Result<Vec<u8>, InferError> {
    model_file(file)
        .map(<[u8]>::to_vec)
        .ok_or_else(|| InferError::ReadModel { file: file.into(), message: "not a fixture file".into() })
}

fn worker_with_models() -> SessionWorker {
    let mut worker = SessionWorker::new();
    let summary = worker.load_models(MANIFEST, read_fixture_model).unwrap();
    assert_eq!(summary.model_sets.iter().map(|s| s.tracking_points).collect::<Vec<_>>(), [1, 3]);
    assert_eq!(summary.bytes, MODEL_FILES.iter().map(|(_, b)| b.len() as u64).sum::<u64>());
    worker
}

fn reconstructed() -> (SessionWorker, Vec<JobProgress>) {
    let mut worker = worker_with_models();
    worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let mut reports = Vec::new();
    worker
        .reconstruct(true, &mut |p| {
            reports.push(p);
            true
        })
        .unwrap();
    (worker, reports)
}

fn flat(joints: &[[egoexo_core::glam::Vec3; 24]]) -> Vec<f32> {
    joints.iter().flat_map(|f| f.iter().flat_map(|p| p.to_array())).collect()
}

#[test]
fn model_files_lists_every_network_with_its_checksum() {
    let files = SessionWorker::model_files(MANIFEST).unwrap();
    let names: Vec<&str> = files.iter().map(|f| f.file.as_str()).collect();
    assert_eq!(names, MODEL_FILES.iter().map(|(n, _)| *n).collect::<Vec<_>>());
    for f in &files {
        assert_eq!(f.sha256, egoexo_infer::manifest::sha256_hex(model_file(&f.file).unwrap()));
        assert_eq!(f.bytes, model_file(&f.file).unwrap().len() as u64);
    }
}

#[test]
fn import_summarises_the_session() {
    let mut worker = SessionWorker::new();
    let s = worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    assert_eq!(s.name, "105_36");
    assert_eq!(s.source, ".egoexo session");
    assert_eq!(s.fps, 30.0);
    assert!(s.frames > 200 && s.frames < 240, "{}", s.frames);
    assert!((s.duration_s - s.frames as f32 / 30.0).abs() < 1e-4);
    assert_eq!(s.devices, ["head", "left_wrist", "right_wrist"]);
    assert_eq!(s.tracking_points, 3);
    assert_eq!(s.observers.iter().map(|o| o.id.as_str()).collect::<Vec<_>>(), ["observer-1", "observer-2"]);
    assert!(s.observers.iter().all(|o| o.camera.starts_with("fisheye624 ") && o.keypoint_frames > 0));
    assert!(s.ground_truth);
    // The simulator's detector puts a keypoint just off the image once; the import says so.
    assert!(s.warnings.iter().all(|w| w.starts_with("105_36: observer `observer-")), "{:?}", s.warnings);
}

/// The same session dropped as a folder (its files, `/`-separated paths under one root
/// folder, as `webkitdirectory` gives them) imports to the same summary.
#[test]
fn a_dropped_folder_imports_like_the_archive() {
    let mut archive = zip::ZipArchive::new(Cursor::new(SESSION)).unwrap();
    let mut files = Vec::new();
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).unwrap();
        if entry.is_dir() {
            continue;
        }
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes).unwrap();
        files.push((format!("105_36/{}", entry.name().unwrap()), bytes));
    }
    let mut worker = SessionWorker::new();
    let from_folder = worker.import_files("105_36", files).unwrap();
    let from_archive = SessionWorker::new().import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    assert_eq!(from_folder, from_archive);
}

#[test]
fn reconstruction_matches_the_recording() {
    let (worker, _) = reconstructed();
    let ego_exo = worker.reconstruction().unwrap();
    let ego_only = worker.ego_only_reconstruction().unwrap();
    let frames = ego_exo.joints.len();
    let samples = sample_frames(frames);
    let actual = Expected {
        session: SESSION_NAME.into(),
        frames,
        valid_frames: ego_exo.valid.iter().filter(|&&v| v).count(),
        sample_frames: samples.clone(),
        ego_exo: sample(&flat(&ego_exo.joints), &samples),
        ego_only: sample(&flat(&ego_only.joints), &samples),
    };
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/expected_reconstruction.json");
    if std::env::var_os("EGOEXO_BLESS").is_some() {
        std::fs::write(&path, serde_json::to_string(&actual).unwrap() + "\n").unwrap();
        return;
    }
    let expected: Expected = serde_json::from_str(EXPECTED_JSON).unwrap();
    let hint = "the engine's output changed; if intended, rewrite the recording with \
                `EGOEXO_BLESS=1 cargo test -p egoexo-web-worker --test worker_tests native::`";
    assert_eq!((actual.frames, actual.valid_frames), (expected.frames, expected.valid_frames), "{hint}");
    assert_eq!(actual.sample_frames, expected.sample_frames, "{hint}");
    // Natively the numbers reproduce to float rounding.
    for (what, a, e) in
        [("ego-exo", &actual.ego_exo, &expected.ego_exo), ("ego-only", &actual.ego_only, &expected.ego_only)]
    {
        let (d, i, j) = max_difference(a, e);
        assert!(d <= 1e-5, "{what}: joint {j} of frame {} is {d} m off; {hint}", expected.sample_frames[i]);
    }
    // The overlay really is another reconstruction.
    assert!(max_difference(&actual.ego_exo, &actual.ego_only).0 > 1e-3);
}

#[test]
fn progress_covers_every_window_of_every_pass_in_order() {
    let (worker, reports) = reconstructed();
    let total = reports[0].total;
    assert!(reports.iter().all(|p| p.total == total));
    assert_eq!(reports.iter().map(|p| p.done).collect::<Vec<_>>(), (1..=total).collect::<Vec<_>>());
    // Three equal parts: the shared ego pass, ego-exo's fusion, then the overlay's fusion.
    assert_eq!(total % 3, 0);
    let windows = total / 3;
    assert!(windows >= 3, "{windows} windows");
    let stages: Vec<JobStage> = reports.iter().map(|p| p.stage).collect();
    assert!(stages[..windows].iter().all(|&s| s == JobStage::EgoPass));
    assert!(stages[windows..2 * windows].iter().all(|&s| s == JobStage::ExoFusion));
    assert!(stages[2 * windows..].iter().all(|&s| s == JobStage::EgoOnlyOverlay));
    let summary = worker.reconstruction_summary().unwrap();
    assert_eq!(summary.method, "ego-exo");
    assert_eq!(summary.tracking_points, 3);
    assert_eq!(summary.valid_frames, summary.frames);
    assert_eq!(summary.windows, windows);
    let accuracy = summary.accuracy.as_ref().unwrap();
    assert_eq!(accuracy.frames, summary.frames);
    assert!(accuracy.ego_exo_mpjpe_cm.is_finite() && accuracy.ego_exo_mpjpe_cm > 0.0);
    assert!(accuracy.ego_only_mpjpe_cm.is_some_and(f64::is_finite));
    assert_eq!(summary.observer_ray_frames.keys().collect::<Vec<_>>(), ["observer-1", "observer-2"]);
}

/// The models are checked as they load and each tracking mode's networks are parsed and
/// optimised when a reconstruction first needs them: the 3-point fixture session prepares the
/// 3-point set and leaves the 1-point set as checked bytes.
#[test]
fn a_tracking_modes_networks_are_prepared_when_a_reconstruction_first_needs_them() {
    let mut worker = worker_with_models();
    assert_eq!(worker.prepared_tracking_points(), Vec::<u8>::new());
    worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    assert_eq!(worker.prepared_tracking_points(), Vec::<u8>::new(), "importing needs no network");
    let summary = worker.reconstruct(false, &mut |_| true).unwrap();
    assert_eq!(summary.tracking_points, 3);
    assert_eq!(worker.prepared_tracking_points(), [3]);
    // While idle, the worker prepares the rest one network at a time: the 1-point set's four.
    let mut prepared = 0;
    while worker.prepare_next_network().unwrap() {
        prepared += 1;
        assert!(prepared <= 4, "only the 1-point set was left");
    }
    assert_eq!(prepared, 4);
    assert_eq!(worker.prepared_tracking_points(), [1, 3]);
    // From the start, the 3-point set comes first.
    let fresh = worker_with_models();
    for _ in 0..4 {
        assert!(fresh.prepare_next_network().unwrap());
    }
    assert_eq!(fresh.prepared_tracking_points(), [3]);
    // A damaged file is still refused when the models load, not at first use.
    let mut damaged = SessionWorker::new();
    let err = damaged
        .load_models(MANIFEST, |file| {
            let mut bytes = read_fixture_model(file)?;
            if file == "1pt/fusion.onnx" {
                bytes[10] ^= 1;
            }
            Ok(bytes)
        })
        .unwrap_err();
    assert!(err.to_string().contains("1pt/fusion.onnx") && err.to_string().contains("sha256"), "{err}");
}

/// The app's whole job (ego-exo and the ego-only overlay) runs EgoNet once per window: the
/// overlay reuses the ego pass. Counted on the models themselves.
#[test]
fn egonet_runs_once_per_window_for_ego_exo_and_the_overlay() {
    let mut worker = worker_with_models();
    worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let before = worker.network_runs();
    let summary = worker.reconstruct(true, &mut |_| true).unwrap();
    let runs = worker.network_runs() - before;
    let windows = summary.windows as u64;
    assert!(windows >= 3);
    // The overlay runs the fusion's every-observer-masked graph (the shipped sets have it).
    let expected = NetworkRuns { egonet: windows, gate: windows, fusion: windows, fusion_ego_only: windows };
    assert_eq!((runs.egonet, runs.gate, runs.fusion, runs.fusion_ego_only), (windows, windows, windows, windows));
    assert_eq!(summary.network_runs, expected);
    // Without the overlay: one fusion per window.
    let alone = worker.reconstruct(false, &mut |_| true).unwrap();
    assert_eq!(alone.network_runs, NetworkRuns { fusion_ego_only: 0, ..expected });
}

#[test]
fn without_the_overlay_only_one_pass_runs() {
    let mut worker = worker_with_models();
    worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let mut last = None;
    worker
        .reconstruct(false, &mut |p| {
            last = Some(p);
            true
        })
        .unwrap();
    let last = last.unwrap();
    assert_eq!(last.done, last.total);
    assert_eq!(last.stage, JobStage::ExoFusion);
    assert!(worker.ego_only_reconstruction().is_none());
    let scene: SceneData = serde_json::from_slice(&worker.scene_json().unwrap()).unwrap();
    assert!(scene.ego_only_joints.is_none());
}

#[test]
fn with_a_clock_the_summary_says_where_the_time_went_stage_by_stage() {
    // Without a clock: no timings (and the recording's summary is unchanged).
    let (worker, _) = reconstructed();
    assert!(worker.reconstruction_summary().unwrap().timings.is_empty());

    // A clock that advances 1 ms per reading: each timed call takes exactly 1 ms.
    let now = std::cell::Cell::new(0.0);
    let mut worker = worker_with_models();
    worker.set_clock(egoexo_web_worker::WorkerClock::new(move || {
        now.set(now.get() + 1.0);
        now.get()
    }));
    worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let summary = worker.reconstruct(true, &mut |_| true).unwrap();
    let stages: Vec<&str> = summary.timings.iter().map(|t| t.stage.as_str()).collect();
    assert_eq!(
        stages,
        ["import", "align", "register", "ego-features", "egonet", "exo-features", "gate", "fusion", "decode", "scene"],
        "pipeline order"
    );
    let get = |stage: &str| summary.timings.iter().find(|t| t.stage == stage).unwrap();
    let windows = summary.windows as u32;
    assert_eq!((get("egonet").calls, get("egonet").ms), (windows, f64::from(windows)), "EgoNet once per window");
    assert_eq!(get("gate").calls, windows, "the gate only for ego-exo");
    assert_eq!(get("fusion").calls, 2 * windows, "fusion for ego-exo and the overlay");
    assert_eq!((get("import").calls, get("scene").calls), (1, 1));
    // The same result as without a clock.
    let (untimed, _) = reconstructed();
    assert_eq!(worker.scene_json().unwrap(), untimed.scene_json().unwrap());
}

#[test]
fn the_scene_holds_everything_the_viewer_draws() {
    let (worker, _) = reconstructed();
    let scene: SceneData = serde_json::from_slice(&worker.scene_json().unwrap()).unwrap();
    scene.check().unwrap();
    let r = worker.reconstruction().unwrap();
    assert_eq!(scene.frames, r.joints.len());
    assert_eq!(scene.method, "ego-exo");
    assert_eq!(scene.joints, flat(&r.joints));
    assert_eq!(scene.ego_only_joints.as_deref(), Some(&flat(&worker.ego_only_reconstruction().unwrap().joints)[..]));
    assert!(scene.ground_truth_joints.is_some());
    assert_eq!(scene.devices.len(), 3);
    assert_eq!(scene.observers.len(), 2);
    assert!(scene.observers.iter().any(|o| o.rays.chunks(4).any(|r| r[3] > 0.0)), "some ray has a gate");
}

/// The timeline plots' series agree with the rest of the scene and with the summary: the
/// per-frame errors average to the summary's MPJPE, a frame's mean gate is its rays' mean,
/// and an observer with keypoints at a frame has the wearer in view then.
#[test]
fn the_timeline_series_agree_with_the_scene_and_the_summary() {
    let (worker, _) = reconstructed();
    let scene: SceneData = serde_json::from_slice(&worker.scene_json().unwrap()).unwrap();
    let timeline = scene.timeline.as_ref().expect("the scene has its timeline");
    assert!(timeline.check(scene.frames, scene.observers.len()).is_empty());
    let summary = worker.reconstruction_summary().unwrap();
    let accuracy = summary.accuracy.as_ref().unwrap();
    let errors = timeline.errors.as_ref().expect("the fixture has ground truth");
    let mean = |v: &[f32]| {
        let scored: Vec<f64> = v.iter().filter(|e| **e >= 0.0).map(|&e| f64::from(e)).collect();
        (scored.len(), scored.iter().sum::<f64>() / scored.len() as f64)
    };
    let (scored, mpjpe) = mean(&errors.mpjpe_cm);
    assert_eq!(scored, accuracy.frames);
    assert!((mpjpe - accuracy.ego_exo_mpjpe_cm).abs() < 1e-3, "{mpjpe} vs {}", accuracy.ego_exo_mpjpe_cm);
    let (_, ego_only) = mean(errors.ego_only_mpjpe_cm.as_ref().unwrap());
    assert!((ego_only - accuracy.ego_only_mpjpe_cm.unwrap()).abs() < 1e-3);
    for (o, series) in scene.observers.iter().zip(&timeline.observers) {
        assert_eq!(o.id, series.id);
        let mut seen = 0;
        for f in 0..scene.frames {
            let rays = &o.rays[52 * f..52 * (f + 1)];
            let gates: Vec<f32> = rays.chunks(4).filter(|r| r.iter().any(|&v| v != 0.0)).map(|r| r[3]).collect();
            if gates.is_empty() {
                assert_eq!(series.gate_mean[f], -1.0, "{} frame {f}", o.id);
            } else {
                let expected = gates.iter().sum::<f32>() / gates.len() as f32;
                assert!((series.gate_mean[f] - expected).abs() < 1e-6);
                seen += 1;
                assert!(series.joints_in_view[f] > 0, "{} frame {f}: rays but the wearer not in view", o.id);
            }
        }
        assert!(seen > scene.frames / 4, "{}: rays in {seen} of {} frames", o.id, scene.frames);
    }
}

#[test]
fn cancelling_stops_the_job_and_keeps_no_result() {
    let mut worker = worker_with_models();
    worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let mut calls = 0;
    let err = worker
        .reconstruct(true, &mut |_| {
            calls += 1;
            calls < 3
        })
        .unwrap_err();
    assert!(err.is_cancelled(), "{err}");
    assert_eq!(calls, 3);
    assert!(worker.reconstruction().is_none());
    assert!(matches!(worker.scene_json(), Err(WorkerError::NoReconstruction)));
    // The session is still open: a new run works.
    worker.reconstruct(false, &mut |_| true).unwrap();
}

#[test]
fn exports_every_format_of_the_reconstruction() {
    let (worker, _) = reconstructed();
    let motion = &worker.reconstruction().unwrap().motion;
    for format in ExportFormat::ALL {
        let file = worker.export(format).unwrap();
        assert_eq!(file.file_name, format!("105_36-ego-exo.{}", format.extension()));
        assert_eq!(file.mime_type, motion_format(format).mime_type());
        assert_eq!(file.bytes, egoexo_motion_io::write(motion_format(format), motion).unwrap(), "{format:?}");
    }
}

#[test]
fn a_malformed_file_is_the_importers_error_verbatim() {
    let garbage = b"this is not a zip archive".to_vec();
    let expected: ImportError = FileTree::from_zip("broken.egoexo", garbage.clone(), Limits::default()).unwrap_err();
    let mut worker = worker_with_models();
    let err = worker.import_archive("broken.egoexo", garbage).unwrap_err();
    assert_eq!(err.to_string(), expected.to_string());
    assert!(err.to_string().starts_with("broken.egoexo"), "{err}");
    assert_eq!(err.kind(), ErrorKind::Import);

    // A folder that is no known layout names what it found.
    let err = worker.import_files("notes", [("notes/readme.txt".to_string(), b"hi".to_vec())]).unwrap_err();
    assert!(err.to_string().contains("readme.txt"), "{err}");

    // A session file with a broken field names the file and the field.
    let mut archive = zip::ZipArchive::new(Cursor::new(SESSION)).unwrap();
    let mut files = BTreeMap::new();
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).unwrap();
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes).unwrap();
        files.insert(entry.name().unwrap().to_string(), bytes);
    }
    let manifest = String::from_utf8(files["session.json"].clone()).unwrap();
    files.insert("session.json".into(), manifest.replacen("\"observers\"", "\"observerz\"", 1).into_bytes());
    let err = worker.import_files("bad", files.clone()).unwrap_err();
    let direct = egoexo_session::import_session(
        &FileTree::from_files("bad", files, Limits::default()).unwrap(),
        &Default::default(),
    )
    .unwrap_err();
    assert_eq!(err.to_string(), direct.to_string());
    assert!(err.to_string().contains("session.json"), "{err}");
    // A failed import closes the previous session rather than leaving stale state.
    assert!(matches!(worker.reconstruct(false, &mut |_| true), Err(WorkerError::NoSession)));
}

#[test]
fn operations_out_of_order_say_what_is_missing() {
    let mut worker = SessionWorker::new();
    assert!(matches!(worker.reconstruct(true, &mut |_| true), Err(WorkerError::NoModels)));
    let mut worker = worker_with_models();
    assert!(matches!(worker.reconstruct(true, &mut |_| true), Err(WorkerError::NoSession)));
    worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let err = worker.export(ExportFormat::Bvh).unwrap_err();
    assert!(matches!(err, WorkerError::NoReconstruction));
    assert_eq!(err.kind(), ErrorKind::NoReconstruction);
}

#[test]
fn a_model_file_that_does_not_match_the_manifest_is_refused() {
    let mut worker = SessionWorker::new();
    let err = worker
        .load_models(MANIFEST, |file| {
            let mut bytes = read_fixture_model(file)?;
            if file == "3pt/gate.onnx" {
                bytes[100] ^= 1;
            }
            Ok(bytes)
        })
        .unwrap_err();
    let message = err.to_string();
    assert!(message.contains("3pt/gate.onnx") && message.contains("sha256"), "{message}");
    assert_eq!(err.kind(), ErrorKind::ModelsInvalid);
    assert!(!worker.has_models());
    let err = SessionWorker::new().load_models(b"{\"format_version\": 99}", read_fixture_model).unwrap_err();
    assert!(err.to_string().contains("manifest.json"), "{err}");
    assert_eq!(err.kind(), ErrorKind::ModelsInvalid);
    // The kind comes from the engine's error wherever it arose: a manifest the engine refuses
    // is the models' fault even on a reconstruction's path; an untracked head is not.
    let refused = egoexo_web_worker::WorkerError::from(egoexo_infer::InferError::Manifest(
        egoexo_infer::manifest::ManifestError::Window { found: 64 },
    ));
    assert_eq!(refused.kind(), ErrorKind::ModelsInvalid);
    assert!(refused.to_string().contains("window 64"), "{refused}");
    let untracked = egoexo_web_worker::WorkerError::from(egoexo_infer::InferError::NoValidFrames);
    assert_eq!(untracked.kind(), ErrorKind::Reconstruct);
}

#[test]
fn the_scene_puts_rays_on_the_lines_of_sight_and_is_consistent() {
    let (worker, _) = reconstructed();
    let aligned = worker.aligned_session().unwrap();
    let recon = worker.reconstruction().unwrap();
    let scene: SceneData = serde_json::from_slice(&worker.scene_json().unwrap()).unwrap();
    scene.check().unwrap();
    assert_eq!(scene.frames, aligned.timeline.frames);
    assert_eq!(scene.devices.len(), 3);
    assert!(scene.ground_truth_joints.is_some() && scene.ego_only_joints.is_some());
    let mut rays = 0;
    for (o, observer) in scene.observers.iter().enumerate() {
        assert!(observer.half_fov.iter().all(|a| *a > 0.5 && *a < 1.5), "{:?}", observer.half_fov);
        for f in 0..scene.frames {
            let centre = Vec3::from_slice(&observer.camera_poses[7 * f + 4..7 * f + 7]);
            for k in 0..EXO_KEYPOINT_COUNT {
                let r = &observer.rays[4 * (f * EXO_KEYPOINT_COUNT + k)..4 * (f * EXO_KEYPOINT_COUNT + k) + 4];
                if r[3] == 0.0 && r[0] == 0.0 {
                    continue;
                }
                rays += 1;
                // The endpoint lies at the observer–wearer head distance from the camera.
                let head = aligned.head.poses[f].translation;
                assert!((Vec3::from_slice(&r[..3]).distance(centre) - head.distance(centre)).abs() < 1e-3);
                assert!((r[3] - recon.gates[o].gates[f][k]).abs() < 1e-6);
            }
        }
    }
    assert!(rays > 100, "{rays} rays drawn");
}

/// A share packed here opens in another worker with the same scene and exports, and with its
/// recording it can be reconstructed again; without, it cannot.
#[test]
fn a_packed_share_opens_elsewhere_with_the_same_scene_exports_and_recording() {
    let (worker, _) = reconstructed();
    let sealed_scene = worker.scene_json().unwrap();
    for include_recording in [true, false] {
        let container = worker.pack_share(include_recording, "egoexo test").unwrap();
        let key = egoexo_share::link::random_key().unwrap();
        let iv = egoexo_share::envelope::random_iv().unwrap();
        let sealed = egoexo_share::envelope::seal(&key, &iv, &container).unwrap();
        let opened_bytes = egoexo_share::envelope::open(&key, &sealed).unwrap();

        let mut other = worker_with_models();
        let opened = other.open_share(opened_bytes).unwrap();
        assert_eq!(opened.scene_json, sealed_scene);
        assert_eq!(opened.manifest.name, "105_36");
        assert_eq!(opened.manifest.created_by, "egoexo test");
        assert_eq!(opened.manifest.includes_recording, include_recording);
        assert_eq!(other.scene_json().unwrap(), sealed_scene);
        for format in ExportFormat::ALL {
            assert_eq!(other.export(format).unwrap(), worker.export(format).unwrap(), "{format:?}");
        }
        let rerun = other.reconstruct(true, &mut |_| true);
        if include_recording {
            assert_eq!(rerun.unwrap().frames, worker.reconstruction_summary().unwrap().frames);
            assert_eq!(other.scene_json().unwrap(), sealed_scene, "re-running gives the same scene");
        } else {
            assert!(matches!(rerun, Err(WorkerError::NoSession)));
        }
    }
    // An altered container is refused with the share's error kind.
    let mut other = worker_with_models();
    let err = other.open_share(b"PK not really".to_vec()).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::ShareInvalid);
}

/// A pool of three: the coordinator and two helpers as the wasm message loop drives them —
/// the same state machines ([`PoolCoordinator`], [`PoolHelper`]), the messages moved by hand
/// — with the helpers answering one turn late (so chunks arrive out of order) and the second
/// helper panicking on its first chunk.
#[test]
fn a_pool_of_workers_reconstructs_exactly_what_one_worker_does() {
    use egoexo_protocol::ByteBuf;
    use egoexo_protocol::worker::{WorkerEvent, WorkerRequest};
    use egoexo_web_worker::coordinator::{HelperMessage, NextTurn, PoolCoordinator, PoolHelper};

    const JOB: u32 = 7;
    let (single, _) = reconstructed();
    let mut coordinator = worker_with_models();
    coordinator.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let helper = worker_with_models();
    let mut task = coordinator.start_pooled_reconstruction(true, 2).unwrap();
    task.set_chunk_size(1).unwrap();
    let chunks = task.chunk_count();
    assert!(chunks >= 3, "{chunks} chunks");
    // Bytes that are not a session: a clear error.
    let session = coordinator.pool_session().unwrap();
    let err = helper.start_pool_helper(&session[..session.len() / 2], true, 1).unwrap_err();
    assert!(err.to_string().contains("not an aligned session"), "{err}");
    // A chunk of a job the helper does not hold: an error event, not a panic.
    let stray = WorkerRequest::<ByteBuf>::PoolChunk { job: JOB, chunk: 0 };
    let Some(WorkerEvent::Error { job: Some(JOB), message, .. }) = PoolHelper::default().answer(&helper, &stray) else {
        panic!("no error for a chunk of a job not held")
    };
    assert!(message.contains("no pool job 7"), "{message}");

    let (mut pool, mut posted) = PoolCoordinator::start::<ByteBuf>(&coordinator, &task, JOB, true, &[0, 1]).unwrap();
    assert!(matches!(posted[..], [(0, WorkerRequest::PoolJob { job: JOB, .. }), (1, WorkerRequest::PoolJob { .. })]));
    let mut helpers = [PoolHelper::default(), PoolHelper::default()];
    let (mut inbox, mut progress, mut lost) = (Vec::<HelperMessage<ByteBuf>>::new(), Vec::new(), Vec::new());
    for turns in 0.. {
        assert!(turns < 10_000, "the pool never finished");
        // What the helper answered last turn arrives now; it answers this turn's requests.
        let arrived = std::mem::take(&mut inbox);
        for (to, request) in posted.drain(..) {
            if to == 1 && matches!(request, WorkerRequest::PoolChunk { .. }) {
                inbox.push((to, Ok(WorkerEvent::Panic { message: "the helper panicked".into() })));
                continue;
            }
            if let Some(answer) = helpers[to].answer(&helper, &request) {
                inbox.push((to, Ok(answer)));
            }
        }
        let turn = pool.turn(&coordinator, &mut task, arrived).unwrap();
        posted = turn.to_helpers;
        progress.extend(turn.progress);
        lost.extend(turn.lost);
        if turn.next == NextTurn::Done {
            break;
        }
    }
    let shared = pool.summary(&task);
    assert_eq!((shared.workers, shared.chunks, shared.failed_helpers), (3, chunks, 1));
    assert!(shared.helper_chunks >= 1, "{shared:?}");
    assert!(matches!(&lost[..], [l] if l.helper == 1 && l.dead), "{lost:?}");
    assert_eq!(progress.len(), chunks);
    assert!(progress.windows(2).all(|p| p[0].done < p[1].done));
    let last = progress.last().unwrap();
    assert_eq!(last.done, last.total);
    task.set_pool_summary(shared);
    let summary = coordinator.finish_reconstruction(task).unwrap();
    // The same numbers, bit for bit, and every network run counted once wherever it ran.
    assert_eq!(coordinator.scene_json().unwrap(), single.scene_json().unwrap());
    for format in ExportFormat::ALL {
        assert_eq!(coordinator.export(format).unwrap(), single.export(format).unwrap(), "{format:?}");
    }
    let expected = single.reconstruction_summary().unwrap();
    assert_eq!(summary.network_runs, expected.network_runs);
    assert_eq!(summary.windows, expected.windows);
}

#[test]
fn observers_in_worlds_of_their_own_are_registered_when_the_session_opens() {
    use egoexo_session::Imported;
    use egoexo_session::import::SourceKind;
    use egoexo_synth::procedural::walking_circle;
    use egoexo_synth::worlds::{WorldPerturbation, perturb_observer_worlds};
    use egoexo_synth::{SynthConfig, simulate};
    let config = SynthConfig { observers: 2, tracking: egoexo_core::TrackingMode::OnePoint, ..SynthConfig::default() };
    let mut session = simulate(&walking_circle(15.0), "own-worlds", &config, 5).unwrap().session;
    let mut left_out = session.clone();
    perturb_observer_worlds(&mut session, &WorldPerturbation::default(), 5);
    let imported = |session| Imported { session, source: SourceKind::Egoexo, warnings: Vec::new() };

    // Registered as the session opens: the summary says so, and the observers bring rays.
    let mut worker = worker_with_models();
    let summary = worker.open_imported(imported(session)).unwrap();
    for o in &summary.observers {
        assert!(o.fused && o.world.contains("registered (yaw"), "{}: {}", o.id, o.world);
        assert!(summary.warnings.iter().any(|w| w.starts_with(&format!("{}: its world is its own: registered", o.id))));
    }
    let recon = worker.reconstruct(false, &mut |_| true).unwrap();
    assert!(recon.observer_ray_frames.values().all(|&frames| frames > 300), "{:?}", recon.observer_ray_frames);
    // A share carries what registration did: its summary, and the recording with each
    // observer moved and its registration recorded (opened again, nothing is re-registered).
    let share = worker.pack_share(true, "test").unwrap();
    let mut other = worker_with_models();
    let opened = other.open_share(share).unwrap();
    let shared = &opened.manifest.session.observers;
    assert!(shared.len() == 2 && shared.iter().all(|o| o.fused && o.world.contains("registered (yaw")));
    let reopened = other.session_summary().unwrap();
    assert_eq!(reopened.observers.len(), 2);
    for o in &reopened.observers {
        assert!(o.fused && o.world.contains("registered (yaw"), "{}: {}", o.id, o.world);
    }
    assert!(reopened.warnings.iter().all(|w| !w.contains("its world is its own")), "{:?}", reopened.warnings);

    // An observer seeing someone else entirely (another walk's keypoints) is left out, and
    // the summary says why.
    let other = simulate(&walking_circle(15.0), "other", &SynthConfig { observers: 1, ..config }, 77).unwrap().session;
    left_out.observers[0].keypoints = other.observers[0].keypoints.clone();
    perturb_observer_worlds(&mut left_out, &WorldPerturbation::default(), 6);
    let summary = worker.open_imported(imported(left_out)).unwrap();
    let o = &summary.observers[0];
    assert!(!o.fused && o.world.contains("own world"), "{}", o.world);
    assert!(
        summary.warnings.iter().any(|w| w.contains("observer-1") && w.contains("not fused")),
        "{:?}",
        summary.warnings
    );
    let recon = worker.reconstruct(false, &mut |_| true).unwrap();
    assert_eq!(recon.observer_ray_frames.get("observer-1").copied().unwrap_or(0), 0);
}
