//! The worker module in headless Chromium, in a dedicated Web Worker (where the app runs it):
//! the fixture session through [`SessionWorker`] with the fixture networks must give the frame
//! count and joint positions the native engine recorded (`tests/worker_tests/native.rs`), run EgoNet once
//! per window for ego-exo and the overlay, and stop between steps when cancelled; and the
//! protocol's messages must cross serde-wasm-bindgen as documented, byte buffers as the very
//! same `Uint8Array` objects. (`WorkerApp`'s message loop, which fetches the models over HTTP,
//! is exercised by the end-to-end suite against the served app.)
#![cfg(target_arch = "wasm32")]

mod common;

use common::*;
use egoexo_infer::InferError;
use egoexo_protocol::JsBytes;
use egoexo_protocol::js::{event_from_js, request_from_js};
use egoexo_protocol::worker::{
    DroppedFile, ErrorKind, ErrorStage, ExportFormat, JobStage, SessionInput, WorkerEvent, WorkerRequest,
};
use egoexo_scene::SceneData;
use egoexo_web_worker::SessionWorker;
use js_sys::{Object, Reflect, Uint8Array};
use serde::Serialize as _;
use wasm_bindgen::JsValue;
use wasm_bindgen_test::*;

wasm_bindgen_test_configure!(run_in_dedicated_worker);

fn worker_with_models() -> SessionWorker {
    let mut worker = SessionWorker::new();
    let summary = worker
        .load_models(MANIFEST, |file| {
            model_file(file)
                .map(<[u8]>::to_vec)
                .ok_or_else(|| InferError::ReadModel { file: file.into(), message: "not a fixture file".into() })
        })
        .unwrap();
    assert_eq!(summary.model_sets.len(), 2);
    worker
}

/// A reconstruction summary as the worker sends it.
const SUMMARY_JSON: &str = r#"{"method": "ego-exo", "tracking_points": 3, "frames": 200, "valid_frames": 200,
    "windows": 3, "network_runs": {"egonet": 3, "gate": 3, "fusion": 6}, "exo_evidence_frames": 120,
    "observer_ray_frames": {"observer-1": 150}, "accuracy": null}"#;

fn get(object: &JsValue, key: &str) -> JsValue {
    Reflect::get(object, &JsValue::from_str(key)).unwrap()
}

#[wasm_bindgen_test]
fn reconstructs_the_fixture_like_the_native_engine() {
    let mut worker = worker_with_models();
    let summary = worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let expected: Expected = serde_json::from_str(EXPECTED_JSON).unwrap();
    assert_eq!(summary.frames, expected.frames);
    assert_eq!(summary.observers.len(), 2);
    assert_eq!(summary.tracking_points, 3);

    let mut reports = Vec::new();
    let summary = worker
        .reconstruct(true, &mut |p| {
            reports.push(p);
            true
        })
        .unwrap();

    // Progress: every window step once, in order, ending at the total, in the three stages.
    let total = reports[0].total;
    assert_eq!(reports.iter().map(|p| p.done).collect::<Vec<_>>(), (1..=total).collect::<Vec<_>>());
    let mut stages: Vec<JobStage> = reports.iter().map(|p| p.stage).collect();
    stages.dedup();
    assert_eq!(stages, [JobStage::EgoPass, JobStage::ExoFusion, JobStage::EgoOnlyOverlay]);
    // EgoNet once per window: the overlay reuses the ego pass.
    let windows = summary.windows as u64;
    assert_eq!(summary.network_runs.egonet, windows);
    assert_eq!(summary.network_runs.fusion, windows);
    assert_eq!(summary.network_runs.fusion_ego_only, windows);
    assert_eq!(summary.valid_frames, expected.valid_frames);

    // Joints: the same as natively, within float-kernel differences.
    let joints: Vec<f32> =
        worker.reconstruction().unwrap().joints.iter().flat_map(|f| f.iter().flat_map(|p| p.to_array())).collect();
    assert_eq!(joints.len(), expected.frames * 24 * 3);
    let (d, i, j) = max_difference(&sample(&joints, &expected.sample_frames), &expected.ego_exo);
    assert!(
        d <= TOLERANCE_M,
        "ego-exo joint {j} of frame {} is {d} m from the native result",
        expected.sample_frames[i]
    );

    // The scene bytes are what the viewer reads: same joints, the overlay, the observers.
    let scene: SceneData = serde_json::from_slice(&worker.scene_json().unwrap()).unwrap();
    scene.check().unwrap();
    assert_eq!(scene.frames, expected.frames);
    assert_eq!(scene.joints, joints);
    let overlay = scene.ego_only_joints.as_ref().unwrap();
    let (d, i, j) = max_difference(&sample(overlay, &expected.sample_frames), &expected.ego_only);
    assert!(
        d <= TOLERANCE_M,
        "ego-only joint {j} of frame {} is {d} m from the native result",
        expected.sample_frames[i]
    );
    assert_eq!(scene.observers.len(), 2);

    // Exports, as the page asks for them.
    for (format, magic) in [
        (ExportFormat::Npz, &b"PK"[..]),
        (ExportFormat::Bvh, b"HIERARCHY"),
        (ExportFormat::Glb, b"glTF"),
        (ExportFormat::Csv, b"frame,time_s"),
    ] {
        let file = worker.export(format).unwrap();
        assert!(file.bytes.starts_with(magic), "{format:?}");
        assert_eq!(file.file_name, format!("105_36-ego-exo.{}", format.extension()));
    }
}

#[wasm_bindgen_test]
fn a_cancel_between_steps_keeps_no_result_and_the_worker_goes_on() {
    let mut worker = worker_with_models();
    worker.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let mut task = worker.start_reconstruction(true).unwrap();
    worker.step_reconstruction(&mut task).unwrap().unwrap();
    drop(task); // what the message loop does when a cancel arrives between steps
    assert_eq!(worker.export(ExportFormat::Bvh).unwrap_err().kind(), ErrorKind::NoReconstruction);
    assert!(!worker.reconstruct(false, &mut |_| true).unwrap().method.is_empty());
    let err = worker.import_archive("broken.egoexo", b"definitely not a zip".to_vec()).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Import);
    assert!(err.to_string().starts_with("broken.egoexo: "), "{err}");
}

#[wasm_bindgen_test]
fn requests_carry_the_pages_own_byte_arrays() {
    let bytes = Uint8Array::from(&b"PK\x03\x04"[..]);
    let input = Object::new();
    Reflect::set(&input, &"kind".into(), &"archive".into()).unwrap();
    Reflect::set(&input, &"name".into(), &"walk.egoexo".into()).unwrap();
    Reflect::set(&input, &"bytes".into(), &bytes).unwrap();
    let message = Object::new();
    Reflect::set(&message, &"type".into(), &"open".into()).unwrap();
    Reflect::set(&message, &"job".into(), &7.into()).unwrap();
    Reflect::set(&message, &"input".into(), &input).unwrap();
    let request = request_from_js(&message).unwrap();
    let WorkerRequest::Open { job: 7, input: SessionInput::Archive { name, bytes: received } } = &request else {
        panic!("{request:?}");
    };
    assert_eq!(name, "walk.egoexo");
    assert!(Object::is(&received.0, &bytes), "the same Uint8Array, not a copy");
    // And back: the page's client builds the same object.
    let again = serde_wasm_bindgen::to_value(&request).unwrap();
    assert_eq!(get(&again, "type").as_string().as_deref(), Some("open"));
    assert!(Object::is(&get(&get(&again, "input"), "bytes"), &bytes));

    // Not a Uint8Array, or not a request: refused with what was wrong.
    Reflect::set(&input, &"bytes".into(), &"PK".into()).unwrap();
    let err = request_from_js(&message).unwrap_err().to_string();
    assert!(err.contains("$bytes") || err.contains("invalid type"), "{err}");
    assert!(!request_from_js(&JsValue::from_str("open")).unwrap_err().to_string().is_empty());
    // A placeholder that names an array twice (or none) is refused rather than aliased.
    let forged = js_sys::JSON::parse(
        r#"{"type":"open","job":1,"input":{"kind":"files","name":"x","files":[
        {"path":"a","bytes":{"$bytes":0}},{"path":"b","bytes":{"$bytes":0}}]}}"#,
    )
    .unwrap();
    assert!(request_from_js(&forged).unwrap_err().to_string().contains("missing or named twice"));

    // A dropped folder: every file keeps its own array.
    let (a, b) = (Uint8Array::from(&b"a"[..]), Uint8Array::from(&b"bb"[..]));
    let folder = WorkerRequest::Open {
        job: 2,
        input: SessionInput::Files {
            name: "walk".into(),
            files: vec![
                DroppedFile { path: "walk/a".into(), bytes: JsBytes(a.clone()) },
                DroppedFile { path: "walk/b".into(), bytes: JsBytes(b.clone()) },
            ],
        },
    };
    let value = folder.serialize(&serde_wasm_bindgen::Serializer::json_compatible()).unwrap();
    let WorkerRequest::Open { input: SessionInput::Files { files, .. }, .. } = request_from_js(&value).unwrap() else {
        panic!("not a folder");
    };
    assert!(Object::is(&files[0].bytes.0, &a) && Object::is(&files[1].bytes.0, &b));
}

#[wasm_bindgen_test]
fn events_are_plain_objects_the_page_reads() {
    let scene = JsBytes::copy_from(b"{}");
    let event: WorkerEvent<JsBytes> = WorkerEvent::Error {
        job: Some(4),
        stage: ErrorStage::Models,
        kind: ErrorKind::ModelsMissing,
        message: "cannot fetch models/manifest.json: HTTP 404 Not Found".into(),
    };
    let value = event.serialize(&serde_wasm_bindgen::Serializer::json_compatible()).unwrap();
    assert_eq!(get(&value, "type").as_string().as_deref(), Some("error"));
    assert_eq!(get(&value, "kind").as_string().as_deref(), Some("models-missing"));
    assert_eq!(get(&value, "job").as_f64(), Some(4.0));
    let done: WorkerEvent<JsBytes> = WorkerEvent::Cancelled { job: 4 };
    assert_eq!(done.job(), Some(4));

    // The page reads the scene back as the very array the worker posted.
    let reconstructed: WorkerEvent<JsBytes> = WorkerEvent::Reconstructed {
        job: 9,
        scene: scene.clone(),
        summary: serde_json::from_str(SUMMARY_JSON).unwrap(),
    };
    let value = reconstructed.serialize(&serde_wasm_bindgen::Serializer::json_compatible()).unwrap();
    assert!(get(&get(&value, "summary"), "network_runs").is_object());
    let WorkerEvent::Reconstructed { job: 9, scene: back, summary } = event_from_js(&value).unwrap() else {
        panic!("not the event");
    };
    assert!(Object::is(&back.0, &scene.0));
    assert_eq!(summary.windows, 3);
    assert_eq!(back.to_vec(), b"{}");
}
