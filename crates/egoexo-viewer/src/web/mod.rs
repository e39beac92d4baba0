//! The browser side: wgpu devices and surfaces (`gpu`), the renderer, off-screen rendering,
//! the `Viewer` JS class (`viewer`: its state and JS API; `canvas`: the backend and its
//! fallback and recovery; `input`: pointer, wheel and key listeners; `frame_loop`: the
//! `requestAnimationFrame` loop), and the page's end of the worker protocol (`WorkerClient`).
//! Compiled only for `wasm32`.

mod canvas;
mod frame_loop;
mod gpu;
mod input;
mod links;
mod offscreen;
mod renderer;
mod video_export;
mod viewer;
mod worker_client;

pub use links::{fragment_with_time, link_qr_svg, parse_fragment, share_fragment};
pub use video_export::mux_h264_mp4;
pub use viewer::{Viewer, participant_colour};
pub use worker_client::WorkerClient;

/// A viewer error as the JS exception it throws.
fn js_error(e: crate::error::ViewerError) -> wasm_bindgen::JsError {
    wasm_bindgen::JsError::new(&e.to_string())
}

fn log_error(message: &str) {
    web_sys::console::error_1(&format!("egoexo viewer: {message}").into());
}

fn log_warn(message: &str) {
    web_sys::console::warn_1(&format!("egoexo viewer: {message}").into());
}
