//! The detector step's decoding in the browser: WebCodecs' `VideoDecoder` decodes an
//! observer's H.264 samples (demuxed in Rust, [`crate::detection`]), each frame is cropped
//! and scaled to the detector's input in one `drawImage` onto a small `OffscreenCanvas`
//! (the window computed by the core: [`egoexo_core::crop::CropWindow::canvas_draw`]) — no
//! full frame is ever copied into wasm memory — and the crop goes to the detector.
//!
//! Each sample is decoded with its index (decode order) as its timestamp, which the frame
//! carries back. At most [`MAX_IN_FLIGHT`] samples wait in the decoder, so memory stays a few
//! frames whatever the video's length.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

use egoexo_protocol::worker::JobStage;
use js_sys::{Function, Object, Promise, Reflect, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;
use web_sys::{
    CodecState, EncodedVideoChunk, EncodedVideoChunkInit, EncodedVideoChunkType, OffscreenCanvas,
    OffscreenCanvasRenderingContext2d, VideoDecoder, VideoDecoderConfig, VideoDecoderInit, VideoFrame,
};

use super::{Event, Runtime};
use crate::detection::{DetectionError, DetectionTask};
use crate::worker::WorkerError;
use egoexo_protocol::worker::JobId;

/// Samples handed to the decoder and not yet given back as frames, at most.
const MAX_IN_FLIGHT: usize = 6;

/// A progress event every this many frames (and at the last).
const PROGRESS_EVERY: usize = 4;

/// The decoder's failure, as the detector step reports it.
fn decode_error(task: &DetectionTask, observer: usize, sample: usize, message: impl Into<String>) -> WorkerError {
    let plan = &task.observers()[observer].plan;
    DetectionError::Sample {
        observer: plan.observer_id.clone(),
        video: plan.video_path.clone(),
        sample,
        message: message.into(),
    }
    .into()
}

fn js_text(value: &JsValue) -> String {
    super::js_message(value)
}

/// A `VideoDecoder` with its callbacks: frames queue up in `frames`, an error lands in
/// `error`, and either resolves the promise [`FrameDecoder::wait`] waits on.
struct FrameDecoder {
    decoder: VideoDecoder,
    frames: Rc<RefCell<VecDeque<VideoFrame>>>,
    error: Rc<RefCell<Option<String>>>,
    wake: Rc<RefCell<Option<Function>>>,
    _output: Closure<dyn FnMut(JsValue)>,
    _failed: Closure<dyn FnMut(JsValue)>,
    _dequeued: Closure<dyn FnMut(JsValue)>,
}

impl FrameDecoder {
    /// A decoder configured for `codec` (`avc1.PPCCLL`) with the track's `avcC` record, once
    /// the browser says it can decode it.
    async fn new(codec: &str, width: u32, height: u32, avcc: &[u8]) -> Result<Self, String> {
        let config = VideoDecoderConfig::new(codec);
        config.set_coded_width(width);
        config.set_coded_height(height);
        config.set_description_u8_array(&Uint8Array::from(avcc));
        let support = JsFuture::from(VideoDecoder::is_config_supported(&config))
            .await
            .map_err(|e| format!("the browser cannot check {codec} decoding: {}", js_text(&e)))?;
        if !Reflect::get(&support, &"supported".into()).map(|v| v.is_truthy()).unwrap_or(false) {
            return Err(format!("this browser's WebCodecs cannot decode {codec} video of {width}×{height}"));
        }
        let frames = Rc::new(RefCell::new(VecDeque::new()));
        let error = Rc::new(RefCell::new(None));
        let wake: Rc<RefCell<Option<Function>>> = Rc::new(RefCell::new(None));
        let notify = |wake: &Rc<RefCell<Option<Function>>>| {
            if let Some(resolve) = wake.borrow_mut().take() {
                let _ = resolve.call0(&JsValue::UNDEFINED);
            }
        };
        let output = {
            let (frames, wake) = (frames.clone(), wake.clone());
            Closure::<dyn FnMut(JsValue)>::new(move |frame: JsValue| {
                frames.borrow_mut().push_back(frame.unchecked_into::<VideoFrame>());
                notify(&wake);
            })
        };
        let failed = {
            let (error, wake) = (error.clone(), wake.clone());
            Closure::<dyn FnMut(JsValue)>::new(move |e: JsValue| {
                error.borrow_mut().get_or_insert_with(|| js_text(&e));
                notify(&wake);
            })
        };
        let dequeued = {
            let wake = wake.clone();
            Closure::<dyn FnMut(JsValue)>::new(move |_: JsValue| notify(&wake))
        };
        let init = VideoDecoderInit::new(failed.as_ref().unchecked_ref(), output.as_ref().unchecked_ref());
        let decoder = VideoDecoder::new(&init).map_err(|e| format!("cannot make a video decoder: {}", js_text(&e)))?;
        decoder.set_ondequeue(Some(dequeued.as_ref().unchecked_ref()));
        decoder.configure(&config).map_err(|e| format!("cannot configure the decoder for {codec}: {}", js_text(&e)))?;
        Ok(Self { decoder, frames, error, wake, _output: output, _failed: failed, _dequeued: dequeued })
    }

    fn decode(&self, sample: usize, key: bool, bytes: &[u8]) -> Result<(), String> {
        let kind = if key { EncodedVideoChunkType::Key } else { EncodedVideoChunkType::Delta };
        let init = EncodedVideoChunkInit::new(&Uint8Array::from(bytes), sample as f64 as i32, kind);
        let chunk = EncodedVideoChunk::new(&init).map_err(|e| js_text(&e))?;
        self.decoder.decode(&chunk).map_err(|e| js_text(&e))
    }

    fn next_frame(&self) -> Option<VideoFrame> {
        self.frames.borrow_mut().pop_front()
    }

    fn failure(&self) -> Option<String> {
        self.error.borrow().clone()
    }

    /// Waits until a frame, a dequeue or an error arrives (or 50 ms pass).
    async fn wait(&self, scope: &web_sys::DedicatedWorkerGlobalScope) {
        if !self.frames.borrow().is_empty() || self.error.borrow().is_some() {
            return;
        }
        let woken = Promise::new(&mut |resolve, _reject| {
            let _ = scope.set_timeout_with_callback_and_timeout_and_arguments_0(&resolve, 50);
            *self.wake.borrow_mut() = Some(resolve);
        });
        let _ = JsFuture::from(woken).await;
    }

    async fn flush(&self) -> Result<(), String> {
        JsFuture::from(self.decoder.flush()).await.map(|_| ()).map_err(|e| js_text(&e))
    }
}

impl Drop for FrameDecoder {
    fn drop(&mut self) {
        // A `dequeue` event may still be queued: it must not reach the dropped closure. A
        // closed decoder calls neither `output` nor `error` (closing is an AbortError).
        self.decoder.set_ondequeue(None);
        if self.decoder.state() != CodecState::Closed {
            let _ = self.decoder.close();
        }
        for frame in self.frames.borrow_mut().drain(..) {
            frame.close();
        }
    }
}

/// A `size × size` canvas the crops are drawn on.
struct CropCanvas {
    context: OffscreenCanvasRenderingContext2d,
    size: u32,
}

impl CropCanvas {
    fn new(size: u32) -> Result<Self, String> {
        let canvas = OffscreenCanvas::new(size, size).map_err(|e| js_text(&e))?;
        let options = Object::new();
        let _ = Reflect::set(&options, &"willReadFrequently".into(), &JsValue::TRUE);
        let context = canvas
            .get_context_with_context_options("2d", &options)
            .map_err(|e| js_text(&e))?
            .and_then(|c| c.dyn_into::<OffscreenCanvasRenderingContext2d>().ok())
            .ok_or("no 2D context for an OffscreenCanvas")?;
        context.set_image_smoothing_enabled(true);
        Ok(Self { context, size })
    }

    /// The crop of `frame` that `draw` describes, black outside the image, as RGBA bytes.
    fn crop(&self, frame: &VideoFrame, draw: egoexo_core::crop::CanvasDraw) -> Result<Vec<u8>, String> {
        let side = f64::from(self.size);
        self.context.set_fill_style_str("#000");
        self.context.fill_rect(0.0, 0.0, side, side);
        let [sx, sy, sw, sh] = draw.source.map(f64::from);
        let [dx, dy, dw, dh] = draw.dest.map(f64::from);
        self.context
            .draw_image_with_video_frame_and_sw_and_sh_and_dx_and_dy_and_dw_and_dh(
                frame, sx, sy, sw, sh, dx, dy, dw, dh,
            )
            .map_err(|e| js_text(&e))?;
        let data = self.context.get_image_data(0, 0, self.size as i32, self.size as i32).map_err(|e| js_text(&e))?;
        Ok(data.data().0)
    }
}

impl Runtime {
    /// Decodes observer `observer`'s video of `task` and detects on every frame with a
    /// region; `Ok(false)` when the job was cancelled. `done_before` frames of the stage were
    /// done before this video (progress).
    pub(super) async fn detect_in_video(
        &self,
        job: JobId,
        task: &mut DetectionTask,
        observer: usize,
        done_before: usize,
    ) -> Result<bool, WorkerError> {
        let total = task.total_frames();
        let size = task.input_size();
        let (codec, width, height, avcc, samples) = {
            let track = task.observers()[observer].track();
            let keys: Vec<bool> = track.samples.iter().map(|s| s.key).collect();
            (track.codec.clone(), track.width, track.height, track.avcc.clone(), keys)
        };
        let decoder = FrameDecoder::new(&codec, width, height, &avcc)
            .await
            .map_err(|message| decode_error(task, observer, 0, message))?;
        let canvas = CropCanvas::new(size).map_err(|message| decode_error(task, observer, 0, message))?;
        let (mut next, mut flushed) = (0usize, false);
        loop {
            if self.cancel_requested.get() {
                return Ok(false);
            }
            if let Some(message) = decoder.failure() {
                return Err(decode_error(task, observer, next.saturating_sub(1), message));
            }
            let in_flight = next - task.observers()[observer].seen();
            if next < samples.len() && in_flight < MAX_IN_FLIGHT {
                let bytes = task.observers()[observer].sample_bytes(next)?;
                decoder
                    .decode(next, samples[next], bytes)
                    .map_err(|message| decode_error(task, observer, next, message))?;
                next += 1;
                continue;
            }
            if let Some(frame) = decoder.next_frame() {
                let sample = frame.timestamp().max(0.0) as usize;
                let cropped =
                    task.observers()[observer].canvas_draw(sample, size).map(|draw| canvas.crop(&frame, draw));
                frame.close();
                let crop = cropped.transpose().map_err(|message| decode_error(task, observer, sample, message))?;
                task.detect_crop(observer, sample, crop.as_deref(), self.clock_ms())?;
                let done = done_before + task.observers()[observer].seen();
                if done.is_multiple_of(PROGRESS_EVERY) || done == total {
                    let stage = JobStage::Detection;
                    self.post(Event::Progress { job, stage, label: stage.label().into(), done, total });
                }
                // A cancel, and the decoder's callbacks, get their turn between detections.
                self.yield_now().await;
                continue;
            }
            if next == samples.len() {
                if flushed {
                    break;
                }
                decoder.flush().await.map_err(|message| decode_error(task, observer, next - 1, message))?;
                flushed = true;
                continue;
            }
            decoder.wait(&self.scope).await;
        }
        let job_ref = &task.observers()[observer];
        if job_ref.seen() != job_ref.frames() {
            let message = format!("the decoder gave back {} of {} frames", job_ref.seen(), job_ref.frames());
            return Err(decode_error(task, observer, samples.len().saturating_sub(1), message));
        }
        Ok(true)
    }
}

/// Why the detector step stopped a job.
pub(super) enum DetectFailure {
    /// The detector could not be fetched or loaded (the error's kind and message).
    Models(egoexo_protocol::worker::ErrorKind, String),
    Worker(WorkerError),
}

impl From<WorkerError> for DetectFailure {
    fn from(e: WorkerError) -> Self {
        DetectFailure::Worker(e)
    }
}

impl Runtime {
    /// The detector step of job `job`, when the open session has observers with video and
    /// no keypoints: the detector fetched (Cache API, keyed by its sha256) and loaded on
    /// first use, EgoNet's coarse pose planned, every video decoded and detected on, the
    /// keypoints put into the session. `Ok(false)` when cancelled.
    pub(super) async fn detect_keypoints(&self, job: JobId) -> Result<bool, DetectFailure> {
        if self.worker.borrow().observers_needing_detection().is_empty() {
            return Ok(true);
        }
        if !self.worker.borrow().has_detector() {
            let file = self.worker.borrow().detector_file();
            if let Some(file) = file {
                self.post(Event::Status { text: "loading the keypoint detector…".into() });
                self.load_detector(&file).await?;
            }
        }
        let stage = JobStage::Detection;
        self.post(Event::Progress { job, stage, label: stage.label().into(), done: 0, total: 1 });
        // EgoNet's pass over the session (the regions) runs here, in one go.
        self.yield_now().await;
        let started = self.worker.borrow_mut().start_detection()?;
        let Some(mut task) = started else { return Ok(true) };
        let mut done = 0;
        for observer in 0..task.observers().len() {
            if !self.detect_in_video(job, &mut task, observer, done).await? {
                return Ok(false);
            }
            done += task.observers()[observer].frames();
        }
        self.worker.borrow_mut().finish_detection(task)?;
        Ok(true)
    }

    /// Fetches (or reads from the cache) and loads the detector; a cached copy that fails
    /// its check is dropped and fetched again once.
    async fn load_detector(&self, file: &egoexo_protocol::worker::ModelFileRef) -> Result<(), DetectFailure> {
        let models = |(kind, message)| DetectFailure::Models(kind, message);
        let key = self.cache_key(file).map_err(models)?;
        let cache = super::models::open_cache(&self.scope).await;
        if let Some(cache) = &cache
            && let Some(bytes) = super::models::cached_bytes(cache, &key).await
        {
            if self.worker.borrow_mut().load_detector(&bytes).is_ok() {
                return Ok(());
            }
            let _ = JsFuture::from(cache.delete_with_str(&key)).await;
        }
        let url = super::models::resolve_url(&file.file, &self.models_url).map_err(models)?;
        let bytes = super::models::fetch_bytes(&self.scope, &url, false).await.map_err(models)?;
        self.worker.borrow_mut().load_detector(&bytes).map_err(|e| DetectFailure::Models(e.kind(), e.to_string()))?;
        if let Some(cache) = &cache {
            let body = Uint8Array::from(bytes.as_slice());
            if let Ok(response) = web_sys::Response::new_with_opt_buffer_source(Some(&body)) {
                let _ = JsFuture::from(cache.put_with_str(&key, &response)).await;
            }
        }
        Ok(())
    }
}
