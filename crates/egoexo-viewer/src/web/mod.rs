//! The browser side: wgpu devices and surfaces, the renderer, off-screen rendering, and the
//! `Viewer` JS class. Compiled only for `wasm32`.

mod gpu;
mod offscreen;
mod renderer;
mod viewer;

pub use viewer::Viewer;
