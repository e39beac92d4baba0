//! The worker's JS API in headless Chromium, in a dedicated Web Worker (where the app runs it):
//! the fixture session through `WorkerApp` with the fixture networks must give the frame
//! count and joint positions the native engine recorded (`tests/native.rs`), and errors must
//! arrive as JS `Error`s carrying the importer's message.
#![cfg(target_arch = "wasm32")]

mod common;

use common::*;
use egoexo_scene::SceneData;
use egoexo_session::{FileTree, Limits};
use egoexo_web_worker::WorkerApp;
use js_sys::{Array, Function, Map, Reflect, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_test::*;

wasm_bindgen_test_configure!(run_in_dedicated_worker);

fn get(object: &JsValue, key: &str) -> JsValue {
    Reflect::get(object, &JsValue::from_str(key)).unwrap()
}

fn error_message(e: JsValue) -> String {
    let error: js_sys::Error = e.dyn_into().expect("a JS Error");
    String::from(error.message())
}

/// Loads the models the way `web/worker.js` does: list the files, fetch each (here: the
/// embedded fixture bytes), hand the name → bytes map over.
fn app_with_models() -> WorkerApp {
    let mut app = WorkerApp::new();
    let listed = Array::from(&WorkerApp::model_files(MANIFEST).unwrap());
    assert_eq!(listed.length() as usize, MODEL_FILES.len());
    let files = Map::new();
    for entry in listed.iter() {
        let name = get(&entry, "file").as_string().unwrap();
        let bytes = model_file(&name).unwrap();
        assert_eq!(get(&entry, "bytes").as_f64(), Some(bytes.len() as f64));
        files.set(&JsValue::from_str(&name), &Uint8Array::from(bytes));
    }
    let summary = app.load_models(MANIFEST, &files).unwrap();
    assert_eq!(Array::from(&get(&summary, "model_sets")).length(), 2);
    assert!(app.has_models());
    app
}

#[wasm_bindgen_test]
fn reconstructs_the_fixture_like_the_native_engine() {
    let mut app = app_with_models();
    let summary = app.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let expected: Expected = serde_json::from_str(EXPECTED_JSON).unwrap();
    assert_eq!(get(&summary, "frames").as_f64(), Some(expected.frames as f64));
    assert_eq!(Array::from(&get(&summary, "observers")).length(), 2);
    assert_eq!(get(&summary, "tracking_points").as_f64(), Some(3.0));

    let reports = Array::new();
    let sink = reports.clone();
    let on_progress =
        Closure::<dyn FnMut(String, u32, u32) -> bool>::new(move |stage: String, done: u32, total: u32| {
            sink.push(&Array::of3(&stage.into(), &done.into(), &total.into()));
            true
        });
    let scene = app.reconstruct(on_progress.as_ref().unchecked_ref::<Function>(), true).unwrap();

    // Progress: every window step once, in order, ending at the total, in the three stages.
    let steps: Vec<(String, u32, u32)> = reports
        .iter()
        .map(|r| {
            let r = Array::from(&r);
            (r.get(0).as_string().unwrap(), r.get(1).as_f64().unwrap() as u32, r.get(2).as_f64().unwrap() as u32)
        })
        .collect();
    let total = steps[0].2;
    assert_eq!(steps.iter().map(|s| s.1).collect::<Vec<_>>(), (1..=total).collect::<Vec<_>>());
    let mut stages: Vec<&str> = steps.iter().map(|s| s.0.as_str()).collect();
    stages.dedup();
    assert_eq!(stages, ["ego pass", "exo fusion", "ego-only overlay"]);

    // Joints: the same as natively, within float-kernel differences.
    let joints = app.joint_positions().unwrap();
    assert_eq!(joints.len(), expected.frames * 24 * 3);
    let (d, i, j) = max_difference(&sample(&joints, &expected.sample_frames), &expected.ego_exo);
    assert!(
        d <= TOLERANCE_M,
        "ego-exo joint {j} of frame {} is {d} m from the native result",
        expected.sample_frames[i]
    );

    // The scene bytes are what the viewer reads: same joints, the overlay, the observers.
    let scene: SceneData = serde_json::from_slice(&scene).unwrap();
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

    let summary = app.reconstruction_summary().unwrap();
    assert_eq!(get(&summary, "valid_frames").as_f64(), Some(expected.valid_frames as f64));

    // Export through the same API the page uses.
    for (format, magic) in [("npz", &b"PK"[..]), ("bvh", b"HIERARCHY"), ("glb", b"glTF"), ("csv", b"frame,time_s")] {
        let file = app.export(format).unwrap();
        assert!(file.bytes().starts_with(magic), "{format}");
        assert_eq!(file.file_name(), format!("105_36-ego-exo.{format}"));
    }
    assert!(error_message(app.export("obj").err().unwrap()).contains(".npz, .bvh, .glb or .csv"));
}

#[wasm_bindgen_test]
fn progress_returning_false_cancels_and_a_throwing_callback_propagates() {
    let mut app = app_with_models();
    app.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    let stop = Function::new_with_args("stage, done, total", "return done < 2;");
    assert_eq!(error_message(app.reconstruct(&stop, true).unwrap_err()), "cancelled");
    let throwing = Function::new_with_args("stage, done, total", "throw new RangeError('from the page');");
    let err = app.reconstruct(&throwing, true).unwrap_err();
    assert!(err.is_instance_of::<js_sys::RangeError>());
    // Still usable afterwards.
    let go_on = Function::new_no_args("return true;");
    assert!(!app.reconstruct(&go_on, false).unwrap().is_empty());
}

#[wasm_bindgen_test]
fn errors_are_js_errors_with_the_importers_message() {
    let mut app = app_with_models();
    let garbage = b"definitely not a zip".to_vec();
    let expected = FileTree::from_zip("broken.egoexo", garbage.clone(), Limits::default()).unwrap_err().to_string();
    assert_eq!(error_message(app.import_archive("broken.egoexo", garbage).unwrap_err()), expected);

    let err =
        app.import_files("notes", vec!["notes/readme.txt".into()], vec![Uint8Array::from(&b"hello"[..])]).unwrap_err();
    assert!(error_message(err).contains("readme.txt"));

    let never = Function::new_no_args("return true;");
    assert_eq!(error_message(app.reconstruct(&never, true).unwrap_err()), "no session is open: import one first");

    let mut without_models = WorkerApp::new();
    without_models.import_archive(SESSION_NAME, SESSION.to_vec()).unwrap();
    assert_eq!(error_message(without_models.reconstruct(&never, true).unwrap_err()), "the models are not loaded yet");

    let files = Map::new();
    let err = WorkerApp::new().load_models(MANIFEST, &files).unwrap_err();
    assert!(error_message(err).contains("not fetched"));
}
