//! The `Viewer` JS class: a canvas, a GPU device behind it, the scene, and the 3D view's UI
//! state (orbit camera, playback, layer toggles), advanced by `requestAnimationFrame`
//! (`frame_loop.rs`), drawn on the backend `canvas.rs` chose, moved by `input.rs`.

use std::cell::RefCell;
use std::rc::Rc;

use egoexo_scene::SceneData;
use glam::Vec3;
use wasm_bindgen::prelude::*;
use web_sys::HtmlCanvasElement;

use super::canvas::{CanvasTarget, connect};
use super::frame_loop::{Animation, notify_frame, start_animation, static_lines_or_grid};
use super::input::{Drag, Listeners, attach_canvas_listeners, attach_window_listeners};
use super::js_error;
use crate::camera::{OrbitCamera, ViewPoint};
use crate::error::{BackendPreference, ViewerError};
use crate::playback::Playback;
use crate::plots::{PlotLayout, describe_frame, frame_at, render_plots, x_of_frame};
use crate::scene::{
    FrameDrawList, LayerToggles, SceneGeometry, build_frame, follow_anchor, follow_bounds, observer_pose, parse_scene,
    static_lines, view_bounds,
};

pub(super) struct State {
    pub(super) target: CanvasTarget,
    pub(super) canvas_listeners: Listeners,
    pub(super) scene: Option<SceneData>,
    /// [`SceneGeometry::of`] the scene.
    pub(super) geometry: Option<SceneGeometry>,
    pub(super) camera: OrbitCamera,
    /// The orbit camera's target follows the wearer: target = follow anchor (x, z) + offset
    /// (whose y is the target's height).
    pub(super) follow: bool,
    pub(super) follow_offset: Vec3,
    /// Set once the page chose follow on or off; until then each scene decides
    /// ([`SceneGeometry::moving_wearer`]).
    pub(super) follow_chosen: bool,
    pub(super) playback: Playback,
    pub(super) layers: LayerToggles,
    /// CSS size of the canvas (pixels) and the device pixel ratio.
    pub(super) css_size: (f32, f32),
    pub(super) device_pixel_ratio: f32,
    pub(super) dirty: bool,
    /// Timestamp of the last animation frame that found playback running, ms.
    pub(super) last_tick_ms: Option<f64>,
    pub(super) on_frame: Option<js_sys::Function>,
    /// The frame, scene generation and playing state last reported to `on_frame`.
    pub(super) notified: Option<(usize, u64, bool)>,
    pub(super) scene_generation: u64,
    pub(super) drag: Option<Drag>,
    pub(super) drawing: DrawState,
}

/// Whether the viewer can draw.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum DrawState {
    /// Drawing on the target's backend.
    Drawing,
    /// The WebGPU device was lost; a WebGL2 target on a fresh canvas is being made.
    Recovering,
    /// Drawing failed for good (why); nothing is drawn any more.
    Broken(String),
}

impl State {
    pub(super) fn aspect(&self) -> f32 {
        self.target.config.width as f32 / self.target.config.height.max(1) as f32
    }

    /// Shows `scene` from frame 0 at the current playback speed; `frame_camera` points the
    /// camera at it (otherwise the camera stays where the user put it).
    pub(super) fn show_scene(&mut self, scene: SceneData, frame_camera: bool) -> Result<(), ViewerError> {
        let speed = self.playback.speed();
        self.playback = Playback::new(scene.frames, f64::from(scene.fps));
        self.playback.set_speed(speed)?;
        self.target.renderer.set_static_lines(&static_lines(&scene));
        let geometry = SceneGeometry::of(&scene);
        if !self.follow_chosen {
            self.follow = geometry.moving_wearer;
        }
        if self.layers.through_observer.is_some_and(|i| i >= scene.observers.len()) {
            self.layers.through_observer = None;
        }
        self.geometry = Some(geometry);
        self.scene = Some(scene);
        self.scene_generation += 1;
        self.dirty = true;
        if frame_camera {
            self.reset_camera();
        }
        Ok(())
    }

    /// Frames the scene at the shown frame: the wearer's whole session and the observers, or,
    /// when following, the wearer and the observers now.
    pub(super) fn reset_camera(&mut self) {
        let aspect = self.aspect();
        let frame = self.playback.frame();
        let bounds = self
            .scene
            .as_ref()
            .and_then(|scene| if self.follow { follow_bounds(scene, frame) } else { view_bounds(scene, frame) });
        self.camera = bounds.map(|b| OrbitCamera::framing(b, aspect)).unwrap_or_default();
        self.follow_offset = self.camera.target - self.anchor().unwrap_or(Vec3::ZERO);
        self.follow_offset.y = self.camera.target.y;
        self.dirty = true;
    }

    /// The followed point at the shown frame, with y = 0 (the view keeps its height).
    pub(super) fn anchor(&self) -> Option<Vec3> {
        let anchor = follow_anchor(self.scene.as_ref()?, self.playback.frame())?;
        Some(Vec3::new(anchor.x, 0.0, anchor.z))
    }

    /// Where this frame is drawn from, and the layers drawn: through the chosen observer's
    /// camera while it is tracked (its own frustum and rays hidden), else the orbit camera —
    /// moved with the wearer when following — which shows that observer's frustum as usual.
    pub(super) fn view(&mut self) -> (ViewPoint, LayerToggles) {
        let aspect = self.aspect();
        let mut layers = self.layers;
        if let Some(index) = layers.through_observer {
            let observer = self.scene.as_ref().and_then(|s| s.observers.get(index));
            match observer.and_then(|o| observer_pose(o, self.playback.frame()).map(|pose| (o, pose))) {
                Some((observer, (rotation, centre))) => {
                    let view_point = ViewPoint::through_camera(rotation, centre, observer.half_fov[1], aspect);
                    return (view_point, layers);
                }
                None => layers.through_observer = None,
            }
        }
        if self.follow
            && let Some(anchor) = self.anchor()
        {
            self.camera.target = anchor + self.follow_offset;
        }
        (self.camera.view_point(aspect), layers)
    }

    pub(super) fn draw(&mut self) -> Result<(), ViewerError> {
        let (view_point, layers) = self.view();
        let list = match (&self.scene, &self.geometry) {
            (Some(scene), Some(geometry)) => build_frame(scene, geometry, self.playback.frame(), layers),
            _ => FrameDrawList::default(),
        };
        if self.target.draw(&view_point, &list)? {
            self.dirty = false;
        }
        Ok(())
    }
}

/// The CSS colour the viewer draws participant colour `index` in (a capture's participants,
/// `ParticipantSummary::colour`), for the page's legend.
#[wasm_bindgen]
pub fn participant_colour(index: usize) -> String {
    crate::colors::css(crate::colors::participant_colour(index))
}

/// The egoexo 3D view on a canvas. See the crate docs for the JS API.
#[wasm_bindgen]
pub struct Viewer {
    state: Rc<RefCell<State>>,
    window_listeners: Listeners,
    animation: Rc<RefCell<Animation>>,
}

impl std::fmt::Debug for Viewer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Viewer").finish_non_exhaustive()
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        if let Ok(mut animation) = self.animation.try_borrow_mut() {
            animation.stop();
        }
        self.window_listeners.remove_all();
        if let Ok(mut state) = self.state.try_borrow_mut() {
            state.canvas_listeners.remove_all();
            state.on_frame = None;
        }
    }
}

#[wasm_bindgen]
impl Viewer {
    /// Creates a viewer drawing into `canvas` with `backend_preference` = `"auto"`, `"webgpu"` or
    /// `"webgl2"`. `auto` uses WebGPU only after checking it can present to a canvas, else
    /// WebGL2. When the canvas cannot give the chosen context (it already has another kind), a
    /// fresh canvas with the same attributes takes its place: use [`Viewer::canvas`] afterwards.
    pub async fn create(canvas: HtmlCanvasElement, backend_preference: String) -> Result<Viewer, JsError> {
        console_error_panic_hook::set_once();
        let preference: BackendPreference = backend_preference.parse().map_err(js_error)?;
        let window = web_sys::window().ok_or_else(|| js_error(ViewerError::Dom("no window".into())))?;
        let dpr = window.device_pixel_ratio() as f32;
        let css = (canvas.client_width() as f32, canvas.client_height() as f32);
        let (css_size, dpr) = if css.0 > 0.0 && css.1 > 0.0 {
            (css, if dpr.is_finite() && dpr > 0.0 { dpr } else { 1.0 })
        } else {
            // Not laid out (e.g. detached): keep the canvas's own pixel size.
            ((canvas.width().max(1) as f32, canvas.height().max(1) as f32), 1.0)
        };
        canvas.set_width((css_size.0 * dpr).round().max(1.0) as u32);
        canvas.set_height((css_size.1 * dpr).round().max(1.0) as u32);

        let mut target = connect(canvas, preference).await.map_err(js_error)?;
        target.renderer.set_static_lines(&static_lines_or_grid(None));
        let state = Rc::new(RefCell::new(State {
            target,
            canvas_listeners: Listeners::default(),
            scene: None,
            geometry: None,
            camera: OrbitCamera::default(),
            follow: false,
            follow_offset: Vec3::ZERO,
            follow_chosen: false,
            playback: Playback::new(0, 30.0),
            layers: LayerToggles::default(),
            css_size,
            device_pixel_ratio: dpr,
            dirty: true,
            last_tick_ms: None,
            on_frame: None,
            notified: None,
            scene_generation: 0,
            drag: None,
            drawing: DrawState::Drawing,
        }));
        let weak = Rc::downgrade(&state);
        {
            let mut s = state.borrow_mut();
            let canvas = s.target.canvas.clone();
            s.canvas_listeners = attach_canvas_listeners(&weak, &canvas);
        }
        let window_listeners = attach_window_listeners(&weak);
        let animation = start_animation(weak);
        Ok(Viewer { state, window_listeners, animation })
    }

    /// Renders frame `frame` of the scene (`scene_json`: `serde_json` bytes of a `SceneData`)
    /// off-screen at `width × height` pixels with the default view and returns its RGBA pixels
    /// (rows top to bottom, `4 × width × height` bytes). `"auto"` prefers WebGPU (no canvas is
    /// involved, so it works where WebGPU cannot present), else WebGL2.
    pub async fn render_offscreen(
        scene_json: Vec<u8>,
        frame: f64,
        width: u32,
        height: u32,
        backend_preference: String,
    ) -> Result<js_sys::Uint8Array, JsError> {
        console_error_panic_hook::set_once();
        let preference: BackendPreference = backend_preference.parse().map_err(js_error)?;
        let pixels = super::offscreen::render_offscreen(&scene_json, frame, width, height, preference)
            .await
            .map_err(js_error)?;
        Ok(js_sys::Uint8Array::from(pixels.as_slice()))
    }

    fn update<R>(&self, f: impl FnOnce(&mut State) -> Result<R, ViewerError>) -> Result<R, JsError> {
        let result = {
            let mut s = self
                .state
                .try_borrow_mut()
                .map_err(|_| JsError::new("the viewer is busy (called again from inside one of its callbacks)"))?;
            let result = f(&mut s).map_err(js_error)?;
            s.dirty = true;
            result
        };
        notify_frame(&self.state);
        Ok(result)
    }

    fn read<R: Default>(&self, f: impl FnOnce(&State) -> R) -> R {
        self.state.try_borrow().map(|s| f(&s)).unwrap_or_default()
    }

    /// The backend in use: `"webgpu"` or `"webgl2"`.
    pub fn backend(&self) -> String {
        self.read(|s| s.target.gpu.backend.as_str().to_string())
    }

    /// The canvas the viewer draws into (a replacement when the original could not be used).
    pub fn canvas(&self) -> Option<HtmlCanvasElement> {
        self.read(|s| Some(s.target.canvas.clone()))
    }

    /// Shows a scene: `bytes` are `serde_json` of a `SceneData`. Throws (and keeps the current
    /// scene) when the bytes are not a valid scene. Playback restarts paused at frame 0 with the
    /// current speed; the camera frames the wearer's session and the observers at frame 0.
    pub fn set_scene_json(&self, bytes: &[u8]) -> Result<(), JsError> {
        let scene = parse_scene(bytes).map_err(|e| js_error(e.into()))?;
        self.update(|s| s.show_scene(scene, true))
    }

    /// Shows one live frame: `bytes` are `serde_json` of a one-frame `SceneData`. Unlike
    /// [`Viewer::set_scene_json`] the camera stays where the user put it (it frames the
    /// wearer only for the first live frame, or after a recorded scene). Throws (and keeps
    /// the current frame) when the bytes are not a valid scene.
    pub fn set_live_scene_json(&self, bytes: &[u8]) -> Result<(), JsError> {
        let scene = parse_scene(bytes).map_err(|e| js_error(e.into()))?;
        self.update(|s| {
            let first = s.scene.as_ref().is_none_or(|old| old.frames != 1 || old.name != scene.name);
            s.show_scene(scene, first)
        })
    }

    /// Whether the scene has an ego-only reconstruction to overlay.
    pub fn has_ego_only(&self) -> bool {
        self.read(|s| s.scene.as_ref().is_some_and(|sc| sc.ego_only_joints.is_some()))
    }

    /// Whether the scene has ground truth to show as a ghost.
    pub fn has_ground_truth(&self) -> bool {
        self.read(|s| s.scene.as_ref().is_some_and(|sc| sc.ground_truth_joints.is_some()))
    }

    /// Overlays the ego-only reconstruction (off by default).
    pub fn set_show_ego_only(&self, show: bool) -> Result<(), JsError> {
        self.update(|s| {
            s.layers.ego_only = show;
            Ok(())
        })
    }

    /// Shows the ground-truth ghost (on by default).
    pub fn set_show_ground_truth(&self, show: bool) -> Result<(), JsError> {
        self.update(|s| {
            s.layers.ground_truth = show;
            Ok(())
        })
    }

    /// Shows the observers' rays (on by default).
    pub fn set_show_rays(&self, show: bool) -> Result<(), JsError> {
        self.update(|s| {
            s.layers.rays = show;
            Ok(())
        })
    }

    /// Draws bodies of capsules (`true`, the default) or stick figures.
    pub fn set_show_body(&self, show: bool) -> Result<(), JsError> {
        self.update(|s| {
            s.layers.body = show;
            Ok(())
        })
    }

    /// Keeps the wearer centred as it moves (the view turns only when the user turns it).
    /// Until the page sets it, each scene decides: on for a wearer who walks about.
    pub fn set_follow(&self, follow: bool) -> Result<(), JsError> {
        self.update(|s| {
            s.follow_chosen = true;
            if s.follow != follow {
                s.follow = follow;
                s.reset_camera();
            }
            Ok(())
        })
    }

    /// Whether the view follows the wearer.
    pub fn follows(&self) -> bool {
        self.read(|s| s.follow)
    }

    /// The scene's observers' ids, in order (the indices of [`Viewer::set_view_from_observer`]).
    pub fn observer_ids(&self) -> Vec<String> {
        self.read(|s| {
            s.scene.as_ref().map(|sc| sc.observers.iter().map(|o| o.id.clone()).collect()).unwrap_or_default()
        })
    }

    /// Looks through observer `index`'s camera (its frustum becomes the view, its keypoints are
    /// drawn over it); `-1` returns to the orbit view. Throws for an observer the scene lacks.
    /// While the observer is not tracked the orbit view is shown.
    pub fn set_view_from_observer(&self, index: i32) -> Result<(), JsError> {
        self.update(|s| {
            let count = s.scene.as_ref().map_or(0, |sc| sc.observers.len());
            s.layers.through_observer = match usize::try_from(index) {
                Err(_) => None,
                Ok(i) if i < count => Some(i),
                Ok(i) => return Err(ViewerError::NoSuchObserver { index: i, count }),
            };
            Ok(())
        })
    }

    /// The observer looked through, or `-1` for the orbit view.
    pub fn view_from_observer(&self) -> i32 {
        self.read(|s| s.layers.through_observer.map_or(-1, |i| i as i32))
    }

    /// The timeline plots' rows for the scene: `{ rows: [{ kind, label, top, height, index }],
    /// height, error_max_cm }` in pixels from the plots' top (no rows without a scene or its
    /// timeline data).
    /// A capture's participants in the scene: `[{id, colour, shown}]` — the one shown (drawn in
    /// side colours) first, then the others (drawn in `colour`, a CSS colour); empty for a
    /// one-wearer scene.
    pub fn participants(&self) -> Result<JsValue, JsError> {
        let list = self.read(|s| s.scene.as_ref().map(crate::scene::participant_legend).unwrap_or_default());
        serde_wasm_bindgen::to_value(&list).map_err(|e| JsError::new(&e.to_string()))
    }

    pub fn plot_layout(&self) -> Result<JsValue, JsError> {
        let layout = self.read(|s| s.scene.as_ref().map(PlotLayout::of));
        let layout = layout.unwrap_or(PlotLayout { rows: Vec::new(), height: 0, error_max_cm: 0.0 });
        serde_wasm_bindgen::to_value(&layout).map_err(|e| JsError::new(&e.to_string()))
    }

    /// The timeline plots drawn `width` pixels wide (the layout's height tall) as RGBA bytes,
    /// rows top to bottom, for an `ImageData`; one pixel column per slice of frames.
    pub fn plot_image(&self, width: u32) -> Result<js_sys::Uint8ClampedArray, JsError> {
        if width == 0 || width > 8192 {
            return Err(js_error(ViewerError::BadSize { width, height: 1, max: 8192 }));
        }
        let pixels = self.read(|s| {
            s.scene.as_ref().map(|scene| render_plots(scene, &PlotLayout::of(scene), width).pixels).unwrap_or_default()
        });
        Ok(js_sys::Uint8ClampedArray::from(pixels.as_slice()))
    }

    /// The frame under `x` pixels of a plot `width` pixels wide (what a click there seeks to).
    pub fn plot_frame_at(&self, x: f64, width: f64) -> usize {
        self.read(|s| frame_at(x as f32, width as f32, s.playback.frames()))
    }

    /// Where frame `frame` sits on a plot `width` pixels wide (the playhead's x).
    pub fn plot_x_of_frame(&self, frame: usize, width: f64) -> f64 {
        self.read(|s| f64::from(x_of_frame(frame, width as f32, s.playback.frames())))
    }

    /// The plots' values at `frame`, one line per row (the hover text).
    pub fn plot_text(&self, frame: usize) -> String {
        self.read(|s| s.scene.as_ref().map(|scene| describe_frame(scene, frame)).unwrap_or_default())
    }

    pub fn play(&self) -> Result<(), JsError> {
        self.update(|s| {
            s.playback.play();
            Ok(())
        })
    }

    pub fn pause(&self) -> Result<(), JsError> {
        self.update(|s| {
            s.playback.pause();
            Ok(())
        })
    }

    pub fn toggle_play(&self) -> Result<(), JsError> {
        self.update(|s| {
            s.playback.toggle_play();
            Ok(())
        })
    }

    pub fn is_playing(&self) -> bool {
        self.read(|s| s.playback.is_playing())
    }

    /// Playback speed, × real time, within [0.05, 16]; throws outside.
    pub fn set_speed(&self, speed: f64) -> Result<(), JsError> {
        self.update(|s| Ok(s.playback.set_speed(speed)?))
    }

    pub fn speed(&self) -> f64 {
        self.read(|s| s.playback.speed())
    }

    /// Moves `delta_frames` whole frames (clamped to the timeline) and pauses; returns the frame.
    pub fn step(&self, delta_frames: f64) -> Result<usize, JsError> {
        self.update(|s| Ok(s.playback.step(delta_frames)?))
    }

    /// Shows frame `frame` (rounded, clamped to the timeline); playback continues if it was
    /// running. Returns the frame shown.
    pub fn seek(&self, frame: f64) -> Result<usize, JsError> {
        self.update(|s| Ok(s.playback.seek(frame)?))
    }

    /// Plays frames `start..=end` in a loop (a link's `t=a-b`); `clear_loop` plays everything.
    pub fn set_loop(&self, start: usize, end: usize) -> Result<(), JsError> {
        self.update(|s| {
            s.playback.set_loop(Some((start, end)));
            Ok(())
        })
    }

    /// The looped frames `[start, end]`, or `undefined` when the whole timeline plays.
    pub fn loop_range(&self) -> Option<Vec<u32>> {
        self.read(|s| s.playback.loop_range().map(|(a, b)| vec![a as u32, b as u32]))
    }

    /// Plays the whole timeline again.
    pub fn clear_loop(&self) -> Result<(), JsError> {
        self.update(|s| {
            s.playback.set_loop(None);
            Ok(())
        })
    }

    /// The frame shown (0-based).
    pub fn frame(&self) -> usize {
        self.read(|s| s.playback.frame())
    }

    /// Number of frames of the scene (0 before a scene is set).
    pub fn frames(&self) -> usize {
        self.read(|s| s.playback.frames())
    }

    /// Seconds from the first frame to the shown one (session clock: add the scene's `start_s`).
    pub fn time(&self) -> f64 {
        self.read(|s| s.playback.time_s())
    }

    /// Frames per second of the scene.
    pub fn fps(&self) -> f64 {
        self.read(|s| s.playback.fps())
    }

    /// Session-clock time of the scene's frame 0, seconds (`SceneData::start_s`; 0 without a
    /// scene): `start_s() + time()` is the shown moment on the session clock.
    pub fn start_s(&self) -> f64 {
        self.read(|s| s.scene.as_ref().map_or(0.0, |sc| sc.start_s))
    }

    /// Registers `callback(frame, timeSeconds)`, called whenever the shown frame changes (by
    /// playback, keys, `step`, `seek`, a new scene), whenever playback starts or stops (so a
    /// play button can follow the Space key), and once right away. Replaces any previous
    /// callback.
    pub fn on_frame(&self, callback: js_sys::Function) -> Result<(), JsError> {
        self.update(|s| {
            s.on_frame = Some(callback);
            s.notified = None;
            Ok(())
        })
    }

    /// Sets the canvas's drawing buffer for a CSS size (`css_width × css_height` CSS pixels) at
    /// `device_pixel_ratio`; call it when the canvas's layout size changes.
    pub fn resize(&self, css_width: f64, css_height: f64, device_pixel_ratio: f64) -> Result<(), JsError> {
        for (what, value) in
            [("css_width", css_width), ("css_height", css_height), ("device_pixel_ratio", device_pixel_ratio)]
        {
            if !(value.is_finite() && value > 0.0) {
                return Err(js_error(ViewerError::BadNumber { what, value }));
            }
        }
        self.update(|s| {
            s.css_size = (css_width as f32, css_height as f32);
            s.device_pixel_ratio = device_pixel_ratio as f32;
            let width = (css_width * device_pixel_ratio).round().max(1.0) as u32;
            let height = (css_height * device_pixel_ratio).round().max(1.0) as u32;
            s.target.resize(width, height);
            Ok(())
        })
    }

    /// Frames the wearer's session and the observers at the shown frame (also on double-click).
    pub fn reset_camera(&self) -> Result<(), JsError> {
        self.update(|s| {
            s.reset_camera();
            Ok(())
        })
    }

    /// Draws now instead of on the next animation frame, so that the canvas can be read back in
    /// the same task (tests); throws when drawing fails.
    pub fn render_now(&self) -> Result<(), JsError> {
        self.update(|s| {
            if let Some(lost) = s.target.gpu.health.lost() {
                return Err(ViewerError::Gpu(format!(
                    "the {} device was lost ({lost})",
                    s.target.gpu.backend.as_str()
                )));
            }
            s.draw()
        })
    }

    /// Why drawing stopped for good, if it did (`undefined` while all is well).
    pub fn failure(&self) -> Option<String> {
        self.read(|s| match &s.drawing {
            DrawState::Broken(why) => Some(why.clone()),
            DrawState::Drawing | DrawState::Recovering => None,
        })
    }
}
