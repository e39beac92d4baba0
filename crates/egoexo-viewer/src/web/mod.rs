//! The browser side: wgpu devices and surfaces, the renderer, off-screen rendering, the
//! `Viewer` JS class, and the page's end of the worker protocol (`WorkerClient`). Compiled
//! only for `wasm32`.

mod gpu;
mod links;
mod offscreen;
mod renderer;
mod video_export;
mod viewer;
mod worker_client;

pub use links::{fragment_with_time, parse_fragment, share_fragment};
pub use video_export::mux_h264_mp4;
pub use viewer::{Viewer, participant_colour};
pub use worker_client::WorkerClient;
