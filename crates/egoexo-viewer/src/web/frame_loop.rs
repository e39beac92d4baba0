//! The viewer's frame loop: one `requestAnimationFrame` callback per frame advances playback,
//! draws when something changed, reports the frame to the page (`on_frame`), and moves a lost
//! WebGPU device's view onto WebGL2 ([`super::viewer::DrawState`]).

use std::cell::RefCell;
use std::rc::{Rc, Weak};

use egoexo_scene::SceneData;
use wasm_bindgen::prelude::*;

use super::canvas::webgl2_target;
use super::input::{attach_canvas_listeners, drop_later};
use super::viewer::{DrawState, State};
use super::{log_error, log_warn};
use crate::error::ActiveBackend;
use crate::scene::static_lines;

/// The frame loop's callback and its pending request.
pub(super) struct Animation {
    closure: Option<Closure<dyn FnMut(f64)>>,
    handle: Option<i32>,
    stopped: bool,
}

impl Animation {
    /// Stops the loop: cancels the pending frame and drops the callback after this task.
    pub(super) fn stop(&mut self) {
        self.stopped = true;
        if let (Some(handle), Some(window)) = (self.handle.take(), web_sys::window()) {
            let _ = window.cancel_animation_frame(handle);
        }
        if let Some(closure) = self.closure.take() {
            drop_later(closure);
        }
    }
}

/// Calls `on_frame` when the shown frame (or the playing state) changed since the last call;
/// never while the state is borrowed (the callback may call back into the viewer).
pub(super) fn notify_frame(state: &Rc<RefCell<State>>) {
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

pub(super) fn static_lines_or_grid(scene: Option<&SceneData>) -> Vec<crate::mesh::LineVertex> {
    match scene {
        Some(scene) => static_lines(scene),
        None => static_lines(&SceneData::new("", 30.0, 0, "")),
    }
}

pub(super) fn start_animation(weak: Weak<RefCell<State>>) -> Rc<RefCell<Animation>> {
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

pub(super) fn with_state(weak: &Weak<RefCell<State>>, f: impl FnOnce(&mut State)) {
    if let Some(state) = weak.upgrade()
        && let Ok(mut s) = state.try_borrow_mut()
    {
        f(&mut s);
    }
}
