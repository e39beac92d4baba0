//! The importers compiled to wasm32 and run in headless Chromium, as the browser's worker runs
//! them: a dropped zip and a dropped folder (name → bytes) import, align and convert without
//! a clock, a file or a thread, and bad input is an error, not a panic (which would kill the
//! worker).
#![cfg(target_arch = "wasm32")]

mod support;

use egoexo_session::format::write_egoexo_zip;
use egoexo_session::import::{ImportOptions, SourceKind, import_session};
use egoexo_session::{AlignOptions, FileTree, Limits, align};
use support::*;
use wasm_bindgen_test::{wasm_bindgen_test, wasm_bindgen_test_configure};

wasm_bindgen_test_configure!(run_in_browser);

#[wasm_bindgen_test]
fn a_dropped_zip_imports_aligns_and_converts() {
    let zip = egoexo_motion_io::npz::write_zip(&aria_fixture()).unwrap();
    let tree = FileTree::from_zip("session.zip", zip, Limits::default()).unwrap();
    let imported = import_session(&tree, &ImportOptions::default()).unwrap();
    assert_eq!(imported.source, SourceKind::AriaMultiDevice);
    assert_eq!(imported.session.observers.len(), 2);
    let aligned = align(&imported.session, &AlignOptions::default()).unwrap();
    assert_eq!(aligned.timeline.frames, 61);
    assert!(aligned.coverage.iter().all(|c| c.valid_frames == c.frames));
    let egoexo = write_egoexo_zip(&imported.session).unwrap();
    let back =
        import_session(&FileTree::from_zip("s.egoexo", egoexo, Limits::default()).unwrap(), &ImportOptions::default())
            .unwrap();
    assert_eq!(back.session, imported.session);
}

#[wasm_bindgen_test]
fn a_dropped_folder_imports_with_ground_truth() {
    let imported = import_session(&tree("nymeria", nymeria_fixture()), &ImportOptions::default()).unwrap();
    assert_eq!(imported.source, SourceKind::Nymeria);
    assert_eq!(imported.session.ground_truth.as_ref().unwrap().motion.len(), 61);
    assert_eq!(imported.session.wearer.tracking_mode(), egoexo_core::TrackingMode::ThreePoint);
}

#[wasm_bindgen_test]
fn bad_input_is_an_error_in_the_browser() {
    let mut files = aria_fixture();
    files.insert("wearer/closed_loop_trajectory.csv".into(), b"graph_uid,tracking_timestamp_us\nx,1\n".to_vec());
    let err = import_session(&tree("bad", files), &ImportOptions::default()).unwrap_err();
    assert!(err.to_string().contains("missing column `tx_world_device`"), "{err}");
    let truncated = egoexo_motion_io::npz::write_zip(&aria_fixture()).unwrap()[..500].to_vec();
    assert!(FileTree::from_zip("x.zip", truncated, Limits::default()).is_err());
}
