//! The `Viewer` JS class: a canvas, a GPU device behind it, the scene, and the 3D view's UI
//! state (orbit camera, playback, layer toggles), advanced by `requestAnimationFrame`.

use std::cell::RefCell;
use std::rc::{Rc, Weak};

use egoexo_scene::SceneData;
use wasm_bindgen::prelude::*;
use web_sys::{Event, EventTarget, HtmlCanvasElement, KeyboardEvent, PointerEvent, WheelEvent};

use glam::Vec3;

use crate::camera::{OrbitCamera, ViewPoint};
use crate::error::{ActiveBackend, BackendPreference, ViewerError};
use crate::playback::Playback;
use crate::plots::{PlotLayout, describe_frame, frame_at, render_plots, x_of_frame};
use crate::scene::{
    FrameDrawList, LayerToggles, SceneGeometry, build_frame, follow_anchor, follow_bounds, observer_pose, parse_scene,
    static_lines, view_bounds,
};

use super::gpu::{self, Gpu};
use super::renderer::Renderer;

fn js_error(e: ViewerError) -> JsError {
    JsError::new(&e.to_string())
}

fn log_error(message: &str) {
    web_sys::console::error_1(&format!("egoexo viewer: {message}").into());
}

fn log_warn(message: &str) {
    web_sys::console::warn_1(&format!("egoexo viewer: {message}").into());
}

/// The canvas, its device and surface, and the renderer drawing into it.
struct CanvasTarget {
    canvas: HtmlCanvasElement,
    gpu: Gpu,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    renderer: Renderer,
}

impl CanvasTarget {
    fn new(canvas: HtmlCanvasElement, gpu: Gpu, surface: wgpu::Surface<'static>) -> Result<Self, ViewerError> {
        let (width, height) = (canvas.width().max(1), canvas.height().max(1));
        let config = gpu::configure_surface(&gpu, &surface, width, height)?;
        let renderer = Renderer::new(&gpu.device, &gpu.queue, config.format, gpu::msaa_supported(&gpu, config.format));
        Ok(Self { canvas, gpu, surface, config, renderer })
    }

    /// Sets the drawing buffer to `width × height` pixels (clamped to the device's limit).
    fn resize(&mut self, width: u32, height: u32) {
        let max = gpu::max_texture_side(&self.gpu);
        let (width, height) = (width.clamp(1, max), height.clamp(1, max));
        if (width, height) == (self.config.width, self.config.height) {
            return;
        }
        self.canvas.set_width(width);
        self.canvas.set_height(height);
        self.config.width = width;
        self.config.height = height;
        self.surface.configure(&self.gpu.device, &self.config);
    }

    /// Draws `list` seen by `camera` and presents it. `false` when the canvas gave no texture
    /// this time (draw again on the next animation frame).
    fn draw(&mut self, view_point: &ViewPoint, list: &FrameDrawList) -> Result<bool, ViewerError> {
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(frame) | wgpu::CurrentSurfaceTexture::Suboptimal(frame) => frame,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.gpu.device, &self.config);
                return Ok(false);
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(false),
            wgpu::CurrentSurfaceTexture::Validation => {
                return Err(ViewerError::Gpu("the canvas surface raised a validation error".into()));
            }
        };
        let view = frame.texture.create_view(&Default::default());
        self.renderer.render(&view, (self.config.width, self.config.height), view_point, list);
        self.gpu.queue.present(frame);
        Ok(true)
    }
}

/// A fresh canvas in place of `old` (same attributes: id, classes, style, size), for when `old`
/// already holds a context of the other kind (a canvas keeps its first context type for life).
fn replace_canvas(old: &HtmlCanvasElement) -> Result<HtmlCanvasElement, ViewerError> {
    let fresh = gpu::scratch_canvas(old.width(), old.height())?;
    for name in old.get_attribute_names().iter() {
        if let Some(name) = name.as_string()
            && name != "style"
            && let Some(value) = old.get_attribute(&name)
        {
            fresh.set_attribute(&name, &value).map_err(|e| ViewerError::Dom(format!("copying {name}: {e:?}")))?;
        }
    }
    // Inline styles through the CSSOM: a Content-Security-Policy without 'unsafe-inline'
    // refuses a `style` attribute set by script.
    fresh.style().set_css_text(&old.style().css_text());
    if old.parent_node().is_some() {
        old.replace_with_with_node_1(&fresh).map_err(|e| ViewerError::Dom(format!("replacing the canvas: {e:?}")))?;
    }
    Ok(fresh)
}

/// Pauses between WebGL2 attempts, ms: right after a WebGPU device is lost the browser's GPU
/// process may still be restarting and refuse new contexts for a moment.
const WEBGL2_RETRY_DELAYS_MS: [i32; 4] = [100, 250, 500, 1000];

/// A WebGL2 target on `canvas` (unless `fresh_canvas`), else on a fresh canvas put in its
/// place (a canvas that holds another kind of context cannot give a WebGL2 one), retried a few
/// times when the browser refuses the context.
async fn webgl2_target(canvas: HtmlCanvasElement, fresh_canvas: bool) -> Result<CanvasTarget, ViewerError> {
    let canvas = if fresh_canvas {
        replace_canvas(&canvas)?
    } else {
        match gpu::webgl2(&canvas).await {
            Ok((gpu, surface)) => return CanvasTarget::new(canvas, gpu, surface),
            Err(e) => {
                log_warn(&format!("{e}; retrying on a fresh canvas element"));
                replace_canvas(&canvas)?
            }
        }
    };
    let mut attempt = gpu::webgl2(&canvas).await;
    for delay in WEBGL2_RETRY_DELAYS_MS {
        match attempt {
            Ok(_) => break,
            Err(e) => log_warn(&format!("{e}; retrying in {delay} ms")),
        }
        gpu::sleep_ms(delay).await;
        attempt = gpu::webgl2(&canvas).await;
    }
    let (gpu, surface) = attempt?;
    CanvasTarget::new(canvas, gpu, surface)
}

/// A WebGPU target on `canvas`, after checking that WebGPU can present at all when `check`.
async fn webgpu_target(canvas: HtmlCanvasElement, check: bool) -> Result<CanvasTarget, ViewerError> {
    let gpu = gpu::webgpu().await?;
    if check {
        gpu::probe_webgpu_presentation(&gpu).await.map_err(ViewerError::WebGpuCannotPresent)?;
    }
    let surface = match gpu::webgpu_surface(&gpu, &canvas) {
        Ok(surface) => (canvas, surface),
        Err(_) => {
            let fresh = replace_canvas(&canvas)?;
            let surface = gpu::webgpu_surface(&gpu, &fresh)?;
            (fresh, surface)
        }
    };
    CanvasTarget::new(surface.0, gpu, surface.1)
}

/// The target for `preference`: forced backends or an error; `Auto` tries WebGPU (verified)
/// and falls back to WebGL2, logging why.
async fn connect(canvas: HtmlCanvasElement, preference: BackendPreference) -> Result<CanvasTarget, ViewerError> {
    match preference {
        BackendPreference::WebGpu => webgpu_target(canvas, true).await,
        BackendPreference::WebGpuUnchecked => webgpu_target(canvas, false).await,
        BackendPreference::WebGl2 => webgl2_target(canvas, false).await,
        BackendPreference::Auto => match webgpu_target(canvas.clone(), true).await {
            Ok(target) => Ok(target),
            Err(e) => {
                web_sys::console::info_1(&format!("egoexo viewer: using WebGL2 ({e})").into());
                webgl2_target(canvas, false).await
            }
        },
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DragMode {
    Orbit,
    Pan,
}

#[derive(Clone, Copy, Debug)]
struct Drag {
    pointer_id: i32,
    mode: DragMode,
    last: (f32, f32),
}

/// An attached event listener: its target, event name and closure.
type Listener = (EventTarget, &'static str, Closure<dyn FnMut(Event)>);

/// Event listeners to remove when the viewer goes away or the canvas is replaced.
#[derive(Default)]
struct Listeners(Vec<Listener>);

impl Listeners {
    fn add(&mut self, target: &EventTarget, event: &'static str, passive: bool, closure: Closure<dyn FnMut(Event)>) {
        let options = web_sys::AddEventListenerOptions::new();
        options.set_passive(passive);
        if target
            .add_event_listener_with_callback_and_add_event_listener_options(
                event,
                closure.as_ref().unchecked_ref(),
                &options,
            )
            .is_err()
        {
            log_warn(&format!("could not listen to {event}"));
        }
        self.0.push((target.clone(), event, closure));
    }

    /// Detaches every listener; the closures are dropped after the current task, so a
    /// listener may end the viewer from inside itself.
    fn remove_all(&mut self) {
        let entries = std::mem::take(&mut self.0);
        for (target, event, closure) in &entries {
            let _ = target.remove_event_listener_with_callback(event, closure.as_ref().unchecked_ref());
        }
        drop_later(entries);
    }
}

/// Drops `value` after the current JS task (closures must not be dropped while running).
fn drop_later<T: 'static>(value: T) {
    wasm_bindgen_futures::spawn_local(async move { drop(value) });
}

struct State {
    target: CanvasTarget,
    canvas_listeners: Listeners,
    scene: Option<SceneData>,
    /// [`SceneGeometry::of`] the scene.
    geometry: Option<SceneGeometry>,
    camera: OrbitCamera,
    /// The orbit camera's target follows the wearer: target = follow anchor (x, z) + offset
    /// (whose y is the target's height).
    follow: bool,
    follow_offset: Vec3,
    /// Set once the page chose follow on or off; until then each scene decides
    /// ([`SceneGeometry::moving_wearer`]).
    follow_chosen: bool,
    playback: Playback,
    layers: LayerToggles,
    /// CSS size of the canvas (pixels) and the device pixel ratio.
    css_size: (f32, f32),
    device_pixel_ratio: f32,
    dirty: bool,
    /// Timestamp of the last animation frame that found playback running, ms.
    last_tick_ms: Option<f64>,
    on_frame: Option<js_sys::Function>,
    /// The frame, scene generation and playing state last reported to `on_frame`.
    notified: Option<(usize, u64, bool)>,
    scene_generation: u64,
    drag: Option<Drag>,
    drawing: DrawState,
}

/// Whether the viewer can draw.
#[derive(Clone, Debug, PartialEq)]
enum DrawState {
    /// Drawing on the target's backend.
    Drawing,
    /// The WebGPU device was lost; a WebGL2 target on a fresh canvas is being made.
    Recovering,
    /// Drawing failed for good (why); nothing is drawn any more.
    Broken(String),
}

impl State {
    fn aspect(&self) -> f32 {
        self.target.config.width as f32 / self.target.config.height.max(1) as f32
    }

    /// Shows `scene` from frame 0 at the current playback speed; `frame_camera` points the
    /// camera at it (otherwise the camera stays where the user put it).
    fn show_scene(&mut self, scene: SceneData, frame_camera: bool) -> Result<(), ViewerError> {
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
    fn reset_camera(&mut self) {
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
    fn anchor(&self) -> Option<Vec3> {
        let anchor = follow_anchor(self.scene.as_ref()?, self.playback.frame())?;
        Some(Vec3::new(anchor.x, 0.0, anchor.z))
    }

    /// Where this frame is drawn from, and the layers drawn: through the chosen observer's
    /// camera while it is tracked (its own frustum and rays hidden), else the orbit camera —
    /// moved with the wearer when following — which shows that observer's frustum as usual.
    fn view(&mut self) -> (ViewPoint, LayerToggles) {
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

    fn draw(&mut self) -> Result<(), ViewerError> {
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

struct Animation {
    closure: Option<Closure<dyn FnMut(f64)>>,
    handle: Option<i32>,
    stopped: bool,
}

/// The egoexo 3D view on a canvas. See the crate docs for the JS API.
/// The CSS colour the viewer draws participant colour `index` in (a capture's participants,
/// `ParticipantSummary::colour`), for the page's legend.
#[wasm_bindgen]
pub fn participant_colour(index: usize) -> String {
    crate::colors::css(crate::colors::participant_colour(index))
}

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
            animation.stopped = true;
            if let (Some(handle), Some(window)) = (animation.handle.take(), web_sys::window()) {
                let _ = window.cancel_animation_frame(handle);
            }
            if let Some(closure) = animation.closure.take() {
                drop_later(closure);
            }
        }
        self.window_listeners.remove_all();
        if let Ok(mut state) = self.state.try_borrow_mut() {
            state.canvas_listeners.remove_all();
            state.on_frame = None;
        }
    }
}

/// Calls `on_frame` when the shown frame (or the playing state) changed since the last call;
/// never while the state is borrowed (the callback may call back into the viewer).
fn notify_frame(state: &Rc<RefCell<State>>) {
    let call = {
        let Ok(mut s) = state.try_borrow_mut() else { return };
        let now = (s.playback.frame(), s.scene_generation, s.playback.is_playing());
        if s.notified == Some(now) {
            return;
        }
        s.notified = Some(now);
        s.on_frame.clone().map(|f| (f, now.0, s.playback.time_s()))
    };
    if let Some((callback, frame, time)) = call
        && let Err(e) = callback.call2(&JsValue::NULL, &JsValue::from(frame as f64), &JsValue::from(time))
    {
        log_error(&format!("on_frame callback threw: {e:?}"));
    }
}

/// One animation frame: advance playback, recover from a lost WebGPU device, draw if needed.
fn tick(weak: &Weak<RefCell<State>>, now_ms: f64) {
    let Some(state) = weak.upgrade() else { return };
    let recover = {
        let Ok(mut s) = state.try_borrow_mut() else { return };
        // Time only counts between two ticks that both found playback running: the first tick
        // after `play` does not catch up on the time spent paused.
        let playing = s.playback.is_playing();
        let dt_s = match (playing, s.last_tick_ms) {
            (true, Some(last)) => (now_ms - last) / 1000.0,
            _ => 0.0,
        };
        s.last_tick_ms = playing.then_some(now_ms);
        if s.playback.advance(dt_s) {
            s.dirty = true;
        }
        let lost = s.target.gpu.health.lost();
        if let Some(reason) = lost {
            if s.target.gpu.backend == ActiveBackend::WebGpu && s.drawing == DrawState::Drawing {
                s.drawing = DrawState::Recovering;
                log_warn(&format!("the WebGPU device was lost ({reason}); switching to WebGL2"));
                true
            } else {
                false
            }
        } else {
            if s.dirty
                && !matches!(s.drawing, DrawState::Broken(_))
                && let Err(e) = s.draw()
            {
                log_error(&e.to_string());
                s.drawing = DrawState::Broken(e.to_string());
            }
            false
        }
    };
    if recover {
        wasm_bindgen_futures::spawn_local(recover_on_webgl2(Rc::downgrade(&state)));
    }
    notify_frame(&state);
}

/// Replaces a lost WebGPU target with WebGL2 on a fresh canvas in the same place.
async fn recover_on_webgl2(weak: Weak<RefCell<State>>) {
    let Some(old_canvas) = weak.upgrade().and_then(|s| s.try_borrow().ok().map(|s| s.target.canvas.clone())) else {
        return;
    };
    let result = webgl2_target(old_canvas, true).await;
    let Some(state) = weak.upgrade() else { return };
    let Ok(mut s) = state.try_borrow_mut() else { return };
    match result {
        Ok(mut target) => {
            s.drawing = DrawState::Drawing;
            target.renderer.set_static_lines(&static_lines_or_grid(s.scene.as_ref()));
            s.canvas_listeners.remove_all();
            s.canvas_listeners = attach_canvas_listeners(&weak, &target.canvas);
            s.target = target;
            s.dirty = true;
        }
        Err(e) => {
            log_error(&format!("could not switch to WebGL2: {e}"));
            s.drawing = DrawState::Broken(e.to_string());
        }
    }
}

fn static_lines_or_grid(scene: Option<&SceneData>) -> Vec<crate::mesh::LineVertex> {
    match scene {
        Some(scene) => static_lines(scene),
        None => static_lines(&SceneData::new("", 30.0, 0, "")),
    }
}

fn start_animation(weak: Weak<RefCell<State>>) -> Rc<RefCell<Animation>> {
    let animation = Rc::new(RefCell::new(Animation { closure: None, handle: None, stopped: false }));
    let animation_weak = Rc::downgrade(&animation);
    let closure = Closure::<dyn FnMut(f64)>::new(move |now_ms: f64| {
        tick(&weak, now_ms);
        if let Some(animation) = animation_weak.upgrade() {
            request_frame(&animation);
        }
    });
    animation.borrow_mut().closure = Some(closure);
    request_frame(&animation);
    animation
}

fn request_frame(animation: &Rc<RefCell<Animation>>) {
    let Ok(mut a) = animation.try_borrow_mut() else { return };
    if a.stopped {
        return;
    }
    let handle = match (web_sys::window(), a.closure.as_ref()) {
        (Some(window), Some(closure)) => window.request_animation_frame(closure.as_ref().unchecked_ref()).ok(),
        _ => None,
    };
    a.handle = handle;
}

fn with_state(weak: &Weak<RefCell<State>>, f: impl FnOnce(&mut State)) {
    if let Some(state) = weak.upgrade()
        && let Ok(mut s) = state.try_borrow_mut()
    {
        f(&mut s);
    }
}

fn listener(f: impl FnMut(Event) + 'static) -> Closure<dyn FnMut(Event)> {
    Closure::<dyn FnMut(Event)>::new(f)
}

/// Pointer orbit (left drag) and pan (right or middle drag, or left with Shift/Ctrl/⌘), wheel
/// zoom, double-click to re-frame the scene.
fn attach_canvas_listeners(weak: &Weak<RefCell<State>>, canvas: &HtmlCanvasElement) -> Listeners {
    let mut listeners = Listeners::default();
    // Touch drags orbit instead of scrolling the page.
    let _ = canvas.style().set_property("touch-action", "none");
    let target: &EventTarget = canvas.as_ref();

    let w = weak.clone();
    let c = canvas.clone();
    listeners.add(
        target,
        "pointerdown",
        true,
        listener(move |event| {
            let Some(e) = event.dyn_ref::<PointerEvent>() else { return };
            let pan = e.button() == 1 || e.button() == 2 || e.shift_key() || e.ctrl_key() || e.meta_key();
            let mode = if pan { DragMode::Pan } else { DragMode::Orbit };
            let _ = c.set_pointer_capture(e.pointer_id());
            with_state(&w, |s| {
                s.drag =
                    Some(Drag { pointer_id: e.pointer_id(), mode, last: (e.client_x() as f32, e.client_y() as f32) });
            });
        }),
    );
    let w = weak.clone();
    listeners.add(
        target,
        "pointermove",
        true,
        listener(move |event| {
            let Some(e) = event.dyn_ref::<PointerEvent>() else { return };
            with_state(&w, |s| {
                let Some(drag) = s.drag.as_mut().filter(|d| d.pointer_id == e.pointer_id()) else { return };
                let now = (e.client_x() as f32, e.client_y() as f32);
                let (dx, dy) = (now.0 - drag.last.0, now.1 - drag.last.1);
                drag.last = now;
                if s.layers.through_observer.is_some() {
                    return; // an observer's view stays where its camera is
                }
                match drag.mode {
                    DragMode::Orbit => s.camera.orbit(dx, dy),
                    DragMode::Pan => {
                        let height = s.css_size.1;
                        let before = s.camera.target;
                        s.camera.pan(dx, dy, height);
                        // Following: the pan moves the view relative to the wearer.
                        s.follow_offset += s.camera.target - before;
                    }
                }
                s.dirty = true;
            });
        }),
    );
    for event in ["pointerup", "pointercancel"] {
        let w = weak.clone();
        let c = canvas.clone();
        listeners.add(
            target,
            event,
            true,
            listener(move |event| {
                let Some(e) = event.dyn_ref::<PointerEvent>() else { return };
                let _ = c.release_pointer_capture(e.pointer_id());
                with_state(&w, |s| {
                    if s.drag.is_some_and(|d| d.pointer_id == e.pointer_id()) {
                        s.drag = None;
                    }
                });
            }),
        );
    }
    let w = weak.clone();
    listeners.add(
        target,
        "wheel",
        false,
        listener(move |event| {
            let Some(e) = event.dyn_ref::<WheelEvent>() else { return };
            e.prevent_default();
            with_state(&w, |s| {
                let scale = match e.delta_mode() {
                    WheelEvent::DOM_DELTA_LINE => 16.0,
                    WheelEvent::DOM_DELTA_PAGE => f64::from(s.css_size.1),
                    _ => 1.0,
                };
                s.camera.zoom((e.delta_y() * scale) as f32);
                s.dirty = true;
            });
        }),
    );
    listeners.add(target, "contextmenu", false, listener(|event| event.prevent_default()));
    let w = weak.clone();
    listeners.add(target, "dblclick", true, listener(move |_| with_state(&w, State::reset_camera)));
    listeners
}

/// Keyboard shortcuts on the window: Space play/pause; ←/→ one frame back/forward (pauses);
/// Shift+←/→ one second back/forward; Home/End first/last frame. Keys typed into form fields
/// (and Space on a focused button) are left to the page.
fn attach_window_listeners(weak: &Weak<RefCell<State>>) -> Listeners {
    let mut listeners = Listeners::default();
    let Some(window) = web_sys::window() else { return listeners };
    let w = weak.clone();
    listeners.add(
        window.as_ref(),
        "keydown",
        false,
        listener(move |event| {
            let Some(e) = event.dyn_ref::<KeyboardEvent>() else { return };
            if e.ctrl_key() || e.meta_key() || e.alt_key() || e.default_prevented() {
                return;
            }
            let key = e.key();
            let tag = e
                .target()
                .and_then(|t| t.dyn_into::<web_sys::HtmlElement>().ok())
                .map(|el| (el.tag_name().to_ascii_uppercase(), el.is_content_editable()));
            if let Some((tag, editable)) = &tag {
                if *editable || matches!(tag.as_str(), "INPUT" | "TEXTAREA" | "SELECT") {
                    return;
                }
                if tag == "BUTTON" && (key == " " || key == "Enter") {
                    return;
                }
            }
            let Some(state) = w.upgrade() else { return };
            let handled = {
                let Ok(mut s) = state.try_borrow_mut() else { return };
                let last = s.playback.frames().saturating_sub(1) as f64;
                let p = &mut s.playback;
                let handled = match (key.as_str(), e.shift_key()) {
                    (" ", _) => {
                        p.toggle_play();
                        true
                    }
                    ("ArrowLeft", false) => p.step(-1.0).is_ok(),
                    ("ArrowRight", false) => p.step(1.0).is_ok(),
                    ("ArrowLeft", true) => p.seek_by_seconds(-1.0).is_ok(),
                    ("ArrowRight", true) => p.seek_by_seconds(1.0).is_ok(),
                    ("Home", _) => p.seek(0.0).is_ok(),
                    ("End", _) => p.seek(last).is_ok(),
                    _ => false,
                };
                if handled {
                    s.dirty = true;
                }
                handled
            };
            if handled {
                e.prevent_default();
                notify_frame(&state);
            }
        }),
    );
    listeners
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
