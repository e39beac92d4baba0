//! The detector step in the worker (paper § Ego-Guided Wearer Localization), in plain Rust:
//! for each observer that brought H.264 video and no keypoints, EgoNet's coarse pose plans a
//! crop window per video frame ([`egoexo_detect::plan_observer`]); whoever decodes the video
//! — WebCodecs in the browser's runtime, OpenH264 in the native tests — hands each frame's
//! crop to [`DetectionTask::detect_crop`], and [`crate::SessionWorker::finish_detection`]
//! puts the keypoints into the open session.
//!
//! The decoder is told each sample's index (decode order) as its timestamp and gives it
//! back with the frame, so frames are matched to their plan whatever order they come out in.

use std::sync::Arc;

use egoexo_core::crop::{CanvasDraw, CropWindow};
use egoexo_detect::{ObserverDetections, ObserverVideoPlan};
use egoexo_infer::{InferError, KeypointDetector};
use egoexo_protocol::worker::DetectionSummary;
use egoexo_video::H264Track;
use thiserror::Error;

/// What can go wrong in the detector step.
#[derive(Debug, Error)]
pub enum DetectionError {
    #[error(
        "the models have no detector: observer `{0}` has video and no keypoints, and a detector is needed to find them"
    )]
    NoDetector(String),
    #[error("observer `{observer}`: its video `{path}` is not among the session's files")]
    MissingVideo { observer: String, path: String },
    #[error(transparent)]
    Plan(#[from] egoexo_detect::DetectError),
    #[error("observer `{observer}`: sample {sample} of {video}: {message}")]
    Sample { observer: String, video: String, sample: usize, message: String },
    #[error("observer `{observer}`: a crop of {got} bytes, expected {expected} ({side}×{side} RGBA)")]
    CropSize { observer: String, got: usize, expected: usize, side: u32 },
    #[error(transparent)]
    Detector(#[from] InferError),
    #[error("no observer {0} in the detection task")]
    NoSuchObserver(usize),
}

/// One observer's video being detected on.
#[derive(Debug)]
pub struct ObserverDetectionJob {
    pub plan: ObserverVideoPlan,
    mp4: Arc<[u8]>,
    detections: ObserverDetections,
    /// The plan's frame (presentation order) of each sample (decode order).
    frame_of_sample: Vec<usize>,
    /// Frames handed in so far (with or without a region).
    seen: usize,
    /// The worker's clock when the first frame of this video arrived, and at the last.
    first_ms: Option<f64>,
    last_ms: Option<f64>,
}

impl ObserverDetectionJob {
    pub(crate) fn new(plan: ObserverVideoPlan, mp4: Arc<[u8]>) -> Self {
        let mut frame_of_sample = vec![usize::MAX; plan.track.samples.len()];
        for (frame, planned) in plan.frames.iter().enumerate() {
            if let Some(slot) = frame_of_sample.get_mut(planned.sample) {
                *slot = frame;
            }
        }
        let detections = ObserverDetections::new(&plan);
        Self { plan, mp4, detections, frame_of_sample, seen: 0, first_ms: None, last_ms: None }
    }

    /// The video track (codec string, `avcC`, size, samples in decode order).
    pub fn track(&self) -> &H264Track {
        &self.plan.track
    }

    /// Sample `sample`'s bytes (length-prefixed NAL units, as WebCodecs' `avc` format takes).
    pub fn sample_bytes(&self, sample: usize) -> Result<&[u8], DetectionError> {
        self.plan.track.sample_bytes(&self.mp4, sample).map_err(|e| self.sample_error(sample, e.to_string()))
    }

    /// The MP4 file's bytes.
    pub fn mp4(&self) -> &[u8] {
        &self.mp4
    }

    /// Where to crop the frame of sample `sample`; `None`: no region there, no detection.
    pub fn window(&self, sample: usize) -> Option<CropWindow> {
        let frame = *self.frame_of_sample.get(sample)?;
        self.plan.frames.get(frame)?.window
    }

    /// The `drawImage` that crops the frame of sample `sample` to a `size × size` model
    /// input; `None` when there is nothing to draw (no region, or it misses the image).
    pub fn canvas_draw(&self, sample: usize, size: u32) -> Option<CanvasDraw> {
        self.window(sample)?.canvas_draw(self.plan.track.width, self.plan.track.height, size)
    }

    /// Frames of the video.
    pub fn frames(&self) -> usize {
        self.plan.frames.len()
    }

    /// Frames handed in so far.
    pub fn seen(&self) -> usize {
        self.seen
    }

    fn sample_error(&self, sample: usize, message: String) -> DetectionError {
        DetectionError::Sample {
            observer: self.plan.observer_id.clone(),
            video: self.plan.video_path.clone(),
            sample,
            message,
        }
    }

    fn summary(&self) -> DetectionSummary {
        DetectionSummary {
            observer: self.plan.observer_id.clone(),
            video: self.plan.video_path.clone(),
            frames: self.seen,
            detected: self.detections.detected_frames(),
            mirrored: self.detections.mirrored_frames(),
            ms: self.first_ms.zip(self.last_ms).map(|(a, b)| (b - a).max(0.0)),
        }
    }
}

/// The detector step of a reconstruction: every observer that needs it, and the detector.
#[derive(Debug)]
pub struct DetectionTask {
    pub(crate) detector: Arc<KeypointDetector>,
    pub(crate) observers: Vec<ObserverDetectionJob>,
}

impl DetectionTask {
    /// The observers' videos, in session order.
    pub fn observers(&self) -> &[ObserverDetectionJob] {
        &self.observers
    }

    /// The detector's square input side, pixels.
    pub fn input_size(&self) -> u32 {
        self.detector.input_size()
    }

    /// Video frames over every observer (the stage's progress total).
    pub fn total_frames(&self) -> usize {
        self.observers.iter().map(ObserverDetectionJob::frames).sum()
    }

    /// Frames handed in so far over every observer.
    pub fn seen_frames(&self) -> usize {
        self.observers.iter().map(|o| o.seen).sum()
    }

    /// Hands in the decoded frame of sample `sample` of observer `observer`'s video: with
    /// `crop` (its window, `input_size²` pixels, RGBA as a canvas gives them, or RGB) it is
    /// detected on; without (no region there) it is only counted. `now_ms` is the worker's
    /// clock, when it has one (the summary's time).
    pub fn detect_crop(
        &mut self,
        observer: usize,
        sample: usize,
        crop: Option<&[u8]>,
        now_ms: Option<f64>,
    ) -> Result<(), DetectionError> {
        let side = self.detector.input_size();
        let job = self.observers.get_mut(observer).ok_or(DetectionError::NoSuchObserver(observer))?;
        let frame = match job.frame_of_sample.get(sample) {
            Some(&frame) if frame != usize::MAX => frame,
            _ => return Err(job.sample_error(sample, "the decoder gave back a frame the video does not have".into())),
        };
        if let Some(now) = now_ms {
            job.first_ms.get_or_insert(now);
            job.last_ms = Some(now);
        }
        job.seen += 1;
        let Some(crop) = crop else { return Ok(()) };
        let pixels = side as usize * side as usize;
        let rgb: std::borrow::Cow<'_, [u8]> = if crop.len() == pixels * 4 {
            crop.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect::<Vec<_>>().into()
        } else if crop.len() == pixels * 3 {
            crop.into()
        } else {
            return Err(DetectionError::CropSize {
                observer: job.plan.observer_id.clone(),
                got: crop.len(),
                expected: pixels * 4,
                side,
            });
        };
        let keypoints = self.detector.detect(&rgb)?;
        job.detections.record(frame, &keypoints)?;
        Ok(())
    }

    /// Each observer's keypoints (session observer index, track) and what was done.
    pub(crate) fn finish(self) -> Vec<(usize, egoexo_session::model::KeypointTrack, DetectionSummary)> {
        self.observers
            .into_iter()
            .map(|job| {
                let summary = job.summary();
                (job.plan.observer, job.detections.into_track(), summary)
            })
            .collect()
    }
}
