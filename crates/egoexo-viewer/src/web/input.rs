//! The viewer's input: pointer orbit and pan, wheel zoom, double-click re-frame on the canvas;
//! playback keys on the window. Listeners are kept so that they can be removed when the viewer
//! goes away or the canvas is replaced.

use std::cell::RefCell;
use std::rc::Weak;

use wasm_bindgen::prelude::*;
use web_sys::{Event, EventTarget, HtmlCanvasElement, KeyboardEvent, PointerEvent, WheelEvent};

use super::frame_loop::{notify_frame, with_state};
use super::log_warn;
use super::viewer::State;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum DragMode {
    Orbit,
    Pan,
}

#[derive(Clone, Copy, Debug)]
pub(super) struct Drag {
    pointer_id: i32,
    mode: DragMode,
    last: (f32, f32),
}

/// An attached event listener: its target, event name and closure.
type Listener = (EventTarget, &'static str, Closure<dyn FnMut(Event)>);

/// Event listeners to remove when the viewer goes away or the canvas is replaced.
#[derive(Default)]
pub(super) struct Listeners(Vec<Listener>);

impl Listeners {
    pub(super) fn add(
        &mut self,
        target: &EventTarget,
        event: &'static str,
        passive: bool,
        closure: Closure<dyn FnMut(Event)>,
    ) {
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
    pub(super) fn remove_all(&mut self) {
        let entries = std::mem::take(&mut self.0);
        for (target, event, closure) in &entries {
            let _ = target.remove_event_listener_with_callback(event, closure.as_ref().unchecked_ref());
        }
        drop_later(entries);
    }
}

/// Drops `value` after the current JS task (closures must not be dropped while running).
pub(super) fn drop_later<T: 'static>(value: T) {
    wasm_bindgen_futures::spawn_local(async move { drop(value) });
}

fn listener(f: impl FnMut(Event) + 'static) -> Closure<dyn FnMut(Event)> {
    Closure::<dyn FnMut(Event)>::new(f)
}

/// Pointer orbit (left drag) and pan (right or middle drag, or left with Shift/Ctrl/⌘), wheel
/// zoom, double-click to re-frame the scene.
pub(super) fn attach_canvas_listeners(weak: &Weak<RefCell<State>>, canvas: &HtmlCanvasElement) -> Listeners {
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
pub(super) fn attach_window_listeners(weak: &Weak<RefCell<State>>) -> Listeners {
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
