//! The pool in the browser: the glue's helper workers (`web/worker.js` spawns them and
//! moves their messages), started once a job is long enough or the first is done, and a
//! pooled job driven turn by turn by [`PoolCoordinator`] — this file only posts its requests,
//! yields or waits for a helper, and forgets helpers that died.

use egoexo_protocol::JsBytes;
use egoexo_protocol::worker::{JobId, WorkerRequest};
use js_sys::Promise;
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;

use super::{HelperMessage, Request, Runtime, console_error, js_message, js_message_with_transfer};
use crate::coordinator::{NextTurn, PoolCoordinator};
use crate::worker::{ReconstructionTask, WorkerError};

/// The glue's pool of helper workers (see [`WorkerApp::new`]).
#[derive(Debug)]
pub(super) struct PoolGlue {
    /// Helpers in the pool (the coordinator not counted).
    pub(super) size: usize,
    start: js_sys::Function,
    post: js_sys::Function,
}

impl PoolGlue {
    pub(super) fn from_js(pool: &js_sys::Object) -> Result<Self, JsValue> {
        let get = |name: &str| js_sys::Reflect::get(pool, &JsValue::from_str(name));
        let size = get("size")?.as_f64().unwrap_or(0.0).max(0.0) as usize;
        let function = |name: &str| -> Result<js_sys::Function, JsValue> {
            get(name)?.dyn_into().map_err(|_| JsValue::from_str(&format!("pool.{name} is not a function")))
        };
        Ok(PoolGlue { size, start: function("start")?, post: function("post")? })
    }
}

impl Runtime {
    /// The helpers that may take work: none without a pool or before they are started.
    pub(super) fn live_helpers(&self) -> Vec<usize> {
        let Some(pool) = self.pool.as_ref().filter(|_| self.helpers_started.get()) else { return Vec::new() };
        let dead = self.dead_helpers.borrow();
        (0..pool.size).filter(|i| !dead.contains(i)).collect()
    }

    /// Has the glue spawn the pool's helpers (once) and has them load their models (from the
    /// cache, where this worker's are by now) and prepare the networks. Called when a job is
    /// long enough to pay for it ([`POOL_EAGER_FRAMES`]) — they join that job as they become
    /// ready — or once the first job is done, so that the start of the page (the time to the
    /// first skeleton) never shares the two cores with compiling more workers.
    pub(super) fn start_helpers(&self) {
        let Some(pool) = &self.pool else { return };
        if self.helpers_started.replace(true) {
            return;
        }
        if let Err(e) = pool.start.call0(&JsValue::UNDEFINED) {
            console_error(&format!("egoexo worker: cannot start the pool's helpers: {}", js_message(&e)));
            self.dead_helpers.borrow_mut().extend(0..pool.size);
            return;
        }
        for helper in 0..pool.size {
            self.post_to_helper(helper, &WorkerRequest::WarmUp);
        }
    }

    /// Posts `request` to helper `helper`, its byte buffers transferred.
    fn post_to_helper(&self, helper: usize, request: &Request) {
        let Some(pool) = &self.pool else { return };
        let posted = js_message_with_transfer(request, request.byte_buffers()).and_then(|(value, transfer)| {
            pool.post.call3(&JsValue::UNDEFINED, &JsValue::from(helper as u32), &value, &transfer)
        });
        if let Err(e) = posted {
            console_error(&format!("egoexo worker: cannot post to helper {helper}: {}", js_message(&e)));
            self.helper_inbox.borrow_mut().push_back((helper, Err("a request could not be posted to it".into())));
        }
    }

    /// Wakes a pooled reconstruction waiting for a helper (a message or a cancel arrived).
    pub(super) fn wake(&self) {
        if let Some(resolve) = self.wake.borrow_mut().take() {
            let _ = resolve.call0(&JsValue::UNDEFINED);
        }
    }

    /// Waits until a helper's message (or a cancel) arrives.
    async fn wait_for_helper(&self) {
        if !self.helper_inbox.borrow().is_empty() || self.cancel_requested.get() {
            return;
        }
        let arrived = Promise::new(&mut |resolve, _reject| {
            *self.wake.borrow_mut() = Some(resolve);
        });
        let _ = JsFuture::from(arrived).await;
    }

    /// Every chunk of `task`, shared with `helpers` ([`PoolCoordinator`]: each gets the
    /// session, then one chunk at a time once ready; this worker computes chunks too, one
    /// window per turn, and decodes them in order). `Ok(false)` when cancelled.
    pub(super) async fn reconstruct_pooled(
        &self,
        job: JobId,
        overlay: bool,
        helpers: &[usize],
        task: &mut ReconstructionTask,
    ) -> Result<bool, WorkerError> {
        let (mut coordinator, requests) =
            PoolCoordinator::start::<JsBytes>(&self.worker.borrow(), task, job, overlay, helpers)?;
        // Messages of an earlier job are stale; a helper that could not be reached stays so.
        self.helper_inbox.borrow_mut().retain(|(_, message)| message.is_err());
        for (helper, request) in requests {
            self.post_to_helper(helper, &request);
        }
        loop {
            if self.stopped(job) {
                for (helper, request) in coordinator.cancel_requests::<JsBytes>() {
                    self.post_to_helper(helper, &request);
                }
                return Ok(false);
            }
            let arrived: Vec<HelperMessage> = self.helper_inbox.borrow_mut().drain(..).collect();
            let turn = coordinator.turn(&self.worker.borrow(), task, arrived)?;
            for lost in turn.lost {
                console_error(&format!("egoexo worker: helper {} failed during job {job}: {}", lost.helper, lost.why));
                if lost.dead {
                    self.dead_helpers.borrow_mut().insert(lost.helper);
                }
            }
            for (helper, request) in turn.to_helpers {
                self.post_to_helper(helper, &request);
            }
            for progress in turn.progress {
                self.post_progress(job, progress);
            }
            match turn.next {
                NextTurn::Done => break,
                NextTurn::Yield => self.yield_now().await,
                NextTurn::WaitForHelpers => self.wait_for_helper().await,
            }
        }
        task.set_pool_summary(coordinator.summary(task));
        Ok(true)
    }
}
