//! The JS-facing API (wasm-bindgen): [`WorkerApp`] wraps [`SessionWorker`] and converts
//! values; [`install_panic_reporter`] turns a Rust panic into a message the worker's JS posts
//! to the page instead of dying silently.
//!
//! Errors are thrown as JS `Error`s whose message is the Rust error's, word for word (for an
//! import, the importer's message naming the file, line/field and what was expected).

use std::cell::RefCell;
use std::fmt::Display;

use egoexo_infer::InferError;
use egoexo_session::export::Format;
use js_sys::{Function, Map, Uint8Array};
use serde::Serialize;
use wasm_bindgen::prelude::*;

use crate::worker::{ExportedFile, SessionWorker};

fn js_error(e: impl Display) -> JsValue {
    JsError::new(&e.to_string()).into()
}

fn to_js(value: &impl Serialize) -> Result<JsValue, JsValue> {
    value.serialize(&serde_wasm_bindgen::Serializer::json_compatible()).map_err(js_error)
}

#[wasm_bindgen]
extern "C" {
    #[wasm_bindgen(js_namespace = console, js_name = error)]
    fn console_error(message: &str);
}

thread_local! {
    static PANIC_REPORTER: RefCell<Option<Function>> = const { RefCell::new(None) };
}

/// Installs a panic hook that logs the panic to the console and calls `report(message)`
/// (the worker's JS posts it to the page). After a panic the module is unusable (wasm32
/// aborts): the worker must be replaced.
#[wasm_bindgen]
pub fn install_panic_reporter(report: Function) {
    PANIC_REPORTER.with(|r| *r.borrow_mut() = Some(report));
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        std::panic::set_hook(Box::new(|info| {
            let message = info.to_string();
            console_error(&format!("egoexo worker panicked: {message}"));
            PANIC_REPORTER.with(|r| {
                if let Ok(reporter) = r.try_borrow()
                    && let Some(report) = reporter.as_ref()
                {
                    let _ = report.call1(&JsValue::NULL, &JsValue::from_str(&message));
                }
            });
        }));
    });
}

/// Panics on purpose with `message`, so that the page's panic reporting is tested end to end.
#[wasm_bindgen]
pub fn panic_for_test(message: &str) {
    panic!("{message}");
}

/// A file made by [`WorkerApp::export`].
#[wasm_bindgen(js_name = ExportedFile)]
#[derive(Debug)]
pub struct ExportedFileJs {
    inner: ExportedFile,
}

#[wasm_bindgen(js_class = ExportedFile)]
impl ExportedFileJs {
    /// The file's bytes (a copy, as a `Uint8Array`).
    #[wasm_bindgen(getter)]
    pub fn bytes(&self) -> Vec<u8> {
        self.inner.bytes.clone()
    }

    /// `<session>-<method>.<extension>`.
    #[wasm_bindgen(getter)]
    pub fn file_name(&self) -> String {
        self.inner.file_name.clone()
    }

    /// The media type for the download.
    #[wasm_bindgen(getter)]
    pub fn mime_type(&self) -> String {
        self.inner.mime_type.to_string()
    }
}

/// The worker's state: loaded models, the open session and its reconstruction.
#[wasm_bindgen]
#[derive(Debug, Default)]
pub struct WorkerApp {
    inner: SessionWorker,
}

#[wasm_bindgen]
impl WorkerApp {
    #[wasm_bindgen(constructor)]
    pub fn new() -> WorkerApp {
        WorkerApp::default()
    }

    /// The files `manifest.json` lists: `[{file, sha256, bytes}]`, paths relative to the
    /// models folder. Fetch them, then call [`WorkerApp::load_models`].
    pub fn model_files(manifest_json: &[u8]) -> Result<JsValue, JsValue> {
        to_js(&SessionWorker::model_files(manifest_json).map_err(js_error)?)
    }

    /// Loads the networks: `files` maps each listed path to its bytes (`Uint8Array`); every
    /// file's sha256 is checked against the manifest. Returns `{model_sets, bytes}`.
    pub fn load_models(&mut self, manifest_json: &[u8], files: &Map) -> Result<JsValue, JsValue> {
        let summary = self
            .inner
            .load_models(manifest_json, |file| {
                let bytes = files.get(&JsValue::from_str(file));
                bytes.dyn_into::<Uint8Array>().map(|b| b.to_vec()).map_err(|_| InferError::ReadModel {
                    file: file.to_string(),
                    message: "not fetched (no Uint8Array for it)".into(),
                })
            })
            .map_err(js_error)?;
        to_js(&summary)
    }

    /// Whether models are loaded.
    pub fn has_models(&self) -> bool {
        self.inner.has_models()
    }

    /// Imports a zip archive (`.egoexo`, or a zipped Aria MPS / Nymeria folder) named `name`.
    /// Returns the session summary `{name, source, frames, fps, duration_s, devices,
    /// tracking_points, observers: [{id, camera, keypoint_frames}], ground_truth, warnings}`.
    pub fn import_archive(&mut self, name: &str, bytes: Vec<u8>) -> Result<JsValue, JsValue> {
        to_js(&self.inner.import_archive(name, bytes).map_err(js_error)?)
    }

    /// Imports a folder given as parallel arrays of relative paths and file bytes (what a
    /// dropped folder or `webkitdirectory` picker yields). Returns the session summary.
    pub fn import_files(
        &mut self,
        name: &str,
        paths: Vec<String>,
        contents: Vec<Uint8Array>,
    ) -> Result<JsValue, JsValue> {
        if paths.len() != contents.len() {
            return Err(js_error(format!("{} paths but {} file contents", paths.len(), contents.len())));
        }
        let files = paths.into_iter().zip(contents.iter().map(Uint8Array::to_vec));
        to_js(&self.inner.import_files(name, files).map_err(js_error)?)
    }

    /// Reconstructs the open session (ego-exo, then ego-only for the overlay when
    /// `ego_only_overlay`), calling `on_progress(stage, done, total)` after every window;
    /// `on_progress` returning `false` cancels. Returns the viewer's scene as JSON bytes
    /// (for `Viewer.set_scene_json`).
    pub fn reconstruct(&mut self, on_progress: &Function, ego_only_overlay: bool) -> Result<Vec<u8>, JsValue> {
        let mut thrown = None;
        let result = self.inner.reconstruct(ego_only_overlay, &mut |p| {
            let call = on_progress.call3(
                &JsValue::NULL,
                &JsValue::from_str(p.stage.label()),
                &JsValue::from(p.done as u32),
                &JsValue::from(p.total as u32),
            );
            match call {
                Ok(v) => v.as_bool() != Some(false),
                Err(e) => {
                    thrown = Some(e);
                    false
                }
            }
        });
        if let Some(e) = thrown {
            return Err(e);
        }
        result.map_err(js_error)?;
        self.inner.scene_json().map_err(js_error)
    }

    /// The last reconstruction's summary `{method, tracking_points, frames, valid_frames,
    /// exo_evidence_frames, observer_ray_frames, accuracy}` (or `undefined`).
    pub fn reconstruction_summary(&self) -> Result<JsValue, JsValue> {
        match self.inner.reconstruction_summary() {
            Some(s) => to_js(s),
            None => Ok(JsValue::UNDEFINED),
        }
    }

    /// World joint positions of the last reconstruction (ego-exo): `frames × 24 × 3`, metres.
    pub fn joint_positions(&self) -> Result<Vec<f32>, JsValue> {
        let r = self.inner.reconstruction().ok_or_else(|| js_error("nothing is reconstructed yet"))?;
        Ok(r.joints.iter().flat_map(|f| f.iter().flat_map(|p| p.to_array())).collect())
    }

    /// Writes the reconstructed motion as `format` (`npz`, `bvh`, `glb` or `csv`).
    pub fn export(&self, format: &str) -> Result<ExportedFileJs, JsValue> {
        let format: Format = format.parse().map_err(js_error)?;
        Ok(ExportedFileJs { inner: self.inner.export(format).map_err(js_error)? })
    }
}
