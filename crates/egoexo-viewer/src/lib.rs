//! The page-side egoexo module: renders an [`egoexo_scene::SceneData`] with wgpu (WebGPU, with
//! a WebGL2 fallback) and owns the 3D view's UI state — orbit camera, playback, layer toggles,
//! keyboard shortcuts — and, as `WorkerClient`, speaks the page's end of the worker protocol
//! (`egoexo_protocol::worker`). It computes no geometry: every position in the scene is
//! already in the world (Y-up, metres).
//!
//! # What is drawn
//! A floor (a disc under a grid) at `floor_y`, with soft contact shadows under the wearer's
//! feet and pelvis; the reconstruction as a body of lit, tapered capsules per SMPL bone sized
//! from the subject's bone lengths (or, with the body off, the stick figure: joints as spheres,
//! bones as cylinders); left blue, right orange, centre white — translucent grey on frames
//! that were not reconstructed (`valid[f] == false`), hidden where a frame holds no pose (all
//! zeros) or a joint is not finite; the head and wrist device trajectories (a trail of 2 s before / 1 s
//! after the current frame and a ball at the device; the head's whole path as a faint line);
//! each tracked observer as a camera frustum (from `camera_poses` and `half_fov`, with a small
//! "up" marker) and its rays from the camera centre to the ray endpoints, coloured by gate
//! (red 0 → yellow 0.5 → green 1); the ground truth as a translucent cyan ghost; the ego-only
//! reconstruction as a translucent violet overlay; in a capture of several participants, the
//! others' bodies beside the wearer, each in its own colour (`colors::PARTICIPANTS`).
//!
//! # JS API (`wasm-bindgen --target web`)
//! ```js
//! import init, { Viewer } from './pkg/egoexo_viewer.js';
//! await init();
//! const viewer = await Viewer.create(canvas, 'auto');   // or 'webgpu' | 'webgl2'
//! viewer.backend();                  // 'webgpu' | 'webgl2': the one in use
//! viewer.canvas();                   // the canvas drawn into (see "Canvas replacement")
//! viewer.set_scene_json(bytes);      // Uint8Array of serde_json SceneData; throws Error on bad data
//! viewer.has_ego_only(); viewer.has_ground_truth();
//! viewer.set_show_ego_only(b); viewer.set_show_ground_truth(b); viewer.set_show_rays(b);
//! viewer.set_show_body(b);           // bodies of capsules (default) or stick figures
//! viewer.set_follow(b); viewer.follows();   // the orbit target moves with the wearer
//! viewer.observer_ids();             // ['observer-1', …]
//! viewer.participants();             // a capture's: [{id, colour, shown}], the shown one first; [] for one wearer
//! participant_colour(i);             // CSS colour of participant colour index i
//! viewer.set_view_from_observer(i);  // look through observer i's camera; -1: the orbit view
//! viewer.view_from_observer();
//! viewer.plot_layout();              // the timeline plots' rows {kind, label, top, height, index}, height, error_max_cm
//! viewer.plot_image(width);          // Uint8ClampedArray RGBA, width × layout height
//! viewer.plot_frame_at(x, width); viewer.plot_x_of_frame(frame, width); viewer.plot_text(frame);
//! viewer.loop_range();               // [start, end] of a looped range, or undefined
//! viewer.play(); viewer.pause(); viewer.toggle_play(); viewer.is_playing();
//! viewer.set_speed(x);               // × real time, 0.05..=16, throws outside
//! viewer.step(n);                    // ±n whole frames, clamped, pauses; returns the frame
//! viewer.seek(f);                    // rounded, clamped; keeps playing; returns the frame
//! viewer.frame(); viewer.frames(); viewer.time(); viewer.fps(); viewer.speed();
//! viewer.start_s();                  // the session-clock time of frame 0 (start_s() + time(): the moment shown)
//! viewer.on_frame((frame, timeSeconds) => {});   // on each change of frame or play state, and once now
//! viewer.resize(cssWidth, cssHeight, devicePixelRatio);
//! viewer.reset_camera();             // frame the wearer + observers now (also: double-click)
//! viewer.render_now();               // draw synchronously (tests read the canvas back after it)
//! viewer.failure();                  // undefined, or why drawing stopped for good
//! viewer.free();
//! const rgba = await Viewer.render_offscreen(sceneJsonBytes, frame, width, height, 'auto');
//! const mp4 = mux_h264_mp4(avcc, width, height, fps, data, sizes, keys);  // WebCodecs frames → MP4
//! link_qr_svg(link);                 // a link as an SVG QR code (black on white, quiet zone included)
//!
//! const client = new WorkerClient(new Worker('worker.js', { type: 'module' }));
//! client.warm_up();                            // load the models now
//! const job = client.open_archive(name, bytes); // or open_files(name, paths, contents)
//! client.reconstruct(true); client.export('glb'); client.cancel();
//! client.select_participant('participant-2');  // a capture: show another participant
//! worker.onmessage = (e) => { const event = client.receive(e.data); if (event) … };
//! ```
//! `timeSeconds` counts from the first frame (`frame / fps`); the session clock adds
//! `SceneData::start_s`. Errors are JS `Error`s whose message says what was wrong (the scene's
//! field and expected length, the bad number, the missing backend).
//!
//! # Input
//! Left drag orbits, right/middle drag (or Shift/Ctrl/⌘ + left drag) pans, the wheel zooms,
//! double-click re-frames. Keys (on the window; ignored while typing in form fields, and Space
//! is left to a focused button): Space play/pause, ←/→ one frame (pauses), Shift+←/→ one
//! second, Home/End first/last frame. The page adds B (bodies), F (follow), O (next view), R
//! (re-frame) and ? (help) through the methods above. Playback runs on `requestAnimationFrame` inside the
//! module and loops at the end.
//!
//! # Backends
//! `auto` first gets a WebGPU device and *checks* that it can present: it clears a scratch
//! canvas to a known colour, presents it, waits ~150 ms watching for a lost device or errors,
//! and reads the canvas back. Headless Chromium with `--enable-unsafe-webgpu` gives a device
//! that renders off-screen but loses it when presenting, so `auto` lands on WebGL2 there;
//! without the flag there is no adapter and `auto` lands on WebGL2 too. `webgpu` runs the same
//! check and throws when it fails; `webgl2` never touches WebGPU. If a WebGPU device is lost
//! later, the viewer switches to WebGL2 by itself (on a fresh canvas in the same place).
//! `webgpu-unchecked` (tests and diagnosis) skips the check, so that fallback can be seen.
//!
//! # Canvas replacement
//! A canvas keeps the first context type it was given. When the canvas already has another
//! context (a viewer re-created on a canvas that held WebGPU, or the runtime fallback), the
//! viewer puts a fresh `<canvas>` with the same attributes (id, class, style, size) in its
//! place; the page should then use `viewer.canvas()` (or look the canvas up by id again).
//!
//! # Native builds
//! Only the pure parts build natively ([`camera`], [`playback`], [`scene`], [`plots`], [`mesh`],
//! [`colors`], [`example`], [`qr`]); wgpu, web-sys and the `Viewer` class exist on `wasm32` only.

pub mod camera;
pub mod colors;
pub mod error;
pub mod example;
pub mod mesh;
pub mod playback;
pub mod plots;
pub mod qr;
pub mod scene;

#[cfg(target_arch = "wasm32")]
mod web;

#[cfg(target_arch = "wasm32")]
pub use web::{
    Viewer, WorkerClient, fragment_with_time, link_qr_svg, mux_h264_mp4, parse_fragment, participant_colour,
    share_fragment,
};

pub use error::{ActiveBackend, BackendPreference, ViewerError};

#[cfg(all(test, target_arch = "wasm32"))]
wasm_bindgen_test::wasm_bindgen_test_configure!(run_in_browser);
