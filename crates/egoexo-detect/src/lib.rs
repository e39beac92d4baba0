//! The detector step (paper § Ego-Guided Wearer Localization): for an observer that brings
//! RGB video instead of keypoints, each video frame is cropped to the region the wearer's
//! coarse pose (EgoNet's, [`egoexo_infer::Method::EgoNet`]) projects to, a top-down 2D pose
//! model ([`egoexo_infer::KeypointDetector`]) finds the 17 COCO keypoints in the crop, and
//! they are mapped back to full-image pixels ([`egoexo_core::crop::CropWindow`]) and kept as
//! the observer's [`KeypointTrack`] — timestamps on the session clock, the detector's
//! confidence as the score the gate reads. A frame without a region gets no detection (the
//! keypoints' usual validity path).
//!
//! The work is split so that decoding can be anyone's: [`plan_observer`] says, per video
//! frame in presentation order, which sample it is, when it was shown and which window to
//! crop; the caller decodes (WebCodecs in the browser's worker; OpenH264 natively,
//! [`native`] with the `openh264` feature), crops ([`egoexo_core::crop::resample_rgb`] or the
//! browser's `drawImage`), runs the detector and hands each result to
//! [`ObserverDetections::record`].
//!
//! Conventions: pixels with the centre of the top-left pixel at (0, 0); session-clock
//! nanoseconds.

pub mod live;
#[cfg(feature = "openh264")]
pub mod native;
pub mod people;
pub mod photos;

use egoexo_core::aligned::AlignedSession;
use egoexo_core::crop::CropWindow;
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::Vec2;
use egoexo_core::region::{DEFAULT_REGION_MARGIN, propose_region};
use egoexo_core::skeleton::NUM_JOINTS;
use egoexo_infer::{CropKeypoint, Reconstruction};
use egoexo_session::model::{KeypointTrack, Session};
use egoexo_video::{H264Track, VideoError};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The smallest crop side, pixels: a wearer far away is not blown up past this (the model
/// would see a few pixels stretched over its whole input).
pub const MIN_CROP_SIDE_PX: f32 = 48.0;

/// Why an observer's video could not be used.
#[derive(Debug, Error)]
pub enum DetectError {
    #[error("observer `{observer}`'s video `{path}`: {source}")]
    Video {
        observer: String,
        path: String,
        #[source]
        source: VideoError,
    },
    #[error(
        "observer `{observer}`'s video `{path}` is {video_w}×{video_h} px, its camera calibration {camera_w}×{camera_h} px; expected the same size (export the RGB stream at the calibration's resolution)"
    )]
    SizeMismatch { observer: String, path: String, video_w: u32, video_h: u32, camera_w: u32, camera_h: u32 },
    #[error(
        "observer `{observer}`'s video `{path}` has {frames} frames but {times} frame times; expected one time per frame"
    )]
    FrameTimes { observer: String, path: String, times: usize, frames: usize },
    #[error("observer {0} does not exist in the session")]
    NoSuchObserver(usize),
    #[error("observer `{0}` has no video")]
    NoVideo(String),
    #[error("the coarse pose covers {coarse} frames, the aligned session {aligned}")]
    CoarseMismatch { coarse: usize, aligned: usize },
    #[error("detection {index} recorded for an observer video of {frames} frames")]
    NoSuchFrame { index: usize, frames: usize },
}

/// One video frame to detect on.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlannedFrame {
    /// The frame's sample in the track (decode order).
    pub sample: usize,
    /// When it was shown, session-clock nanoseconds.
    pub time_ns: i64,
    /// The aligned frame whose coarse pose and observer pose made the window.
    pub aligned_frame: Option<usize>,
    /// Where to crop; `None`: the wearer has no region in this frame (not tracked, outside
    /// the session's timeline, or not in view) — no detection.
    pub window: Option<CropWindow>,
    /// EgoNet's joints projected into the image, per COCO-17 keypoint (`None` for the face
    /// keypoints and joints outside the image): the reference of the left–right check.
    pub expected: [Option<Vec2>; COCO17_COUNT],
}

/// One observer's video and where to look in each of its frames.
#[derive(Clone, Debug, PartialEq)]
pub struct ObserverVideoPlan {
    /// Index of the observer in the session (and the aligned session).
    pub observer: usize,
    pub observer_id: String,
    pub video_path: String,
    pub track: H264Track,
    /// Every frame, in presentation order (the order decoders output them).
    pub frames: Vec<PlannedFrame>,
}

impl ObserverVideoPlan {
    /// Frames that get a detection.
    pub fn frames_with_region(&self) -> usize {
        self.frames.iter().filter(|f| f.window.is_some()).count()
    }
}

/// Observers that have a video and no keypoints: the ones the detector step is for.
pub fn observers_needing_detection(session: &Session) -> Vec<usize> {
    session
        .observers
        .iter()
        .enumerate()
        .filter(|(_, o)| o.video.is_some() && o.keypoints.is_none())
        .map(|(i, _)| i)
        .collect()
}

/// Plans the detector step for observer `observer` of `session`, whose video file's bytes are
/// `mp4`: each frame's session time (the recording's frame times, else the video's `start_ns`
/// plus the frame's presentation time) and
/// the crop window around the region that `coarse` (EgoNet's pose on `aligned`'s timeline)
/// projects to at the aligned frame nearest that time, seen from the observer's pose there.
pub fn plan_observer(
    session: &Session,
    aligned: &AlignedSession,
    coarse: &Reconstruction,
    observer: usize,
    mp4: &[u8],
) -> Result<ObserverVideoPlan, DetectError> {
    let o = session.observers.get(observer).ok_or(DetectError::NoSuchObserver(observer))?;
    let video = o.video.as_ref().ok_or_else(|| DetectError::NoVideo(o.id.clone()))?;
    let track = H264Track::read(mp4).map_err(|source| DetectError::Video {
        observer: o.id.clone(),
        path: video.path.clone(),
        source,
    })?;
    if track.width != o.camera.width || track.height != o.camera.height {
        return Err(DetectError::SizeMismatch {
            observer: o.id.clone(),
            path: video.path.clone(),
            video_w: track.width,
            video_h: track.height,
            camera_w: o.camera.width,
            camera_h: o.camera.height,
        });
    }
    if !video.frame_times_ns.is_empty() && video.frame_times_ns.len() != track.samples.len() {
        return Err(DetectError::FrameTimes {
            observer: o.id.clone(),
            path: video.path.clone(),
            times: video.frame_times_ns.len(),
            frames: track.samples.len(),
        });
    }
    if coarse.joints.len() != aligned.timeline.frames {
        return Err(DetectError::CoarseMismatch { coarse: coarse.joints.len(), aligned: aligned.timeline.frames });
    }
    let aligned_observer = aligned.observers.get(observer).ok_or(DetectError::NoSuchObserver(observer))?;
    let timeline = &aligned.timeline;
    let frame_ns = 1e9 / f64::from(timeline.fps);
    let frames = track
        .presentation_order()
        .into_iter()
        .enumerate()
        .map(|(shown, sample)| {
            let time_ns = match video.frame_times_ns.get(shown) {
                Some(&t) => t,
                None => video.start_ns.saturating_add(track.presentation_ns(sample)),
            };
            let position = (time_ns - timeline.start_ns) as f64 / frame_ns;
            let nearest = position.round();
            let aligned_frame = (nearest >= 0.0 && (nearest as usize) < timeline.frames).then_some(nearest as usize);
            let tracked = aligned_frame.filter(|&f| {
                coarse.valid.get(f).copied().unwrap_or(false)
                    && aligned_observer.head.valid.get(f).copied().unwrap_or(false)
            });
            let (window, expected) = match tracked {
                Some(f) => {
                    let (camera, pose) = (&aligned_observer.camera, &aligned_observer.head.poses[f]);
                    let region = propose_region(&coarse.joints[f][..NUM_JOINTS], camera, pose, DEFAULT_REGION_MARGIN);
                    let expected =
                        people::project_coarse(coarse, aligned_observer, f, 0.0).unwrap_or([None; COCO17_COUNT]);
                    (region.bbox().and_then(|b| CropWindow::around(&b, MIN_CROP_SIDE_PX)), expected)
                }
                None => (None, [None; COCO17_COUNT]),
            };
            PlannedFrame { sample, time_ns, aligned_frame, window, expected }
        })
        .collect();
    Ok(ObserverVideoPlan { observer, observer_id: o.id.clone(), video_path: video.path.clone(), track, frames })
}

pub use egoexo_core::exo_keypoints::COCO17_MIRROR;

/// A detection is mirrored (left and right exchanged) when its keypoints, exchanged, lie this
/// much closer (in summed distance) to EgoNet's projected joints than as detected.
pub const MIRROR_GAIN: f32 = 0.6;

/// Keypoints below this score are dropped (MoveNet's own demos draw keypoints above 0.3).
pub const MIN_KEYPOINT_SCORE: f32 = 0.3;

/// Exchanges left and right in `keypoints` when that brings them closer to `expected` (the
/// wearer's EgoNet joints projected into the image) by more than [`MIRROR_GAIN`] — the
/// ego-guided check against a single-image pose model's front/back confusion, which puts a
/// person's left keypoints on their right side. Returns whether it exchanged them.
pub fn mirror_towards(
    keypoints: &mut [Option<Keypoint2d>; COCO17_COUNT],
    expected: &[Option<Vec2>; COCO17_COUNT],
) -> bool {
    let cost = |mirrored: bool| -> (f32, usize) {
        let mut sum = 0.0;
        let mut n = 0;
        for k in 0..COCO17_COUNT {
            let detected = keypoints[if mirrored { COCO17_MIRROR[k] } else { k }];
            if let (Some(d), Some(e)) = (detected, expected[k]) {
                sum += d.pixel.distance(e);
                n += 1;
            }
        }
        (sum, n)
    };
    let ((as_detected, n), (mirrored, m)) = (cost(false), cost(true));
    if n >= 4 && n == m && mirrored < MIRROR_GAIN * as_detected {
        *keypoints = std::array::from_fn(|k| keypoints[COCO17_MIRROR[k]]);
        true
    } else {
        false
    }
}

/// The detections of one observer's video as they come in, frame by frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ObserverDetections {
    expected: Vec<[Option<Vec2>; COCO17_COUNT]>,
    mirrored: usize,
    windows: Vec<Option<CropWindow>>,
    track: KeypointTrack,
    detected: usize,
}

impl ObserverDetections {
    /// Empty detections for every frame of `plan` (frames never recorded stay undetected).
    pub fn new(plan: &ObserverVideoPlan) -> Self {
        Self {
            expected: plan.frames.iter().map(|f| f.expected).collect(),
            mirrored: 0,
            windows: plan.frames.iter().map(|f| f.window).collect(),
            track: KeypointTrack {
                timestamps_ns: plan.frames.iter().map(|f| f.time_ns).collect(),
                frames: vec![[None; COCO17_COUNT]; plan.frames.len()],
            },
            detected: 0,
        }
    }

    /// Records the detector's output for planned frame `index` (presentation order), mapping
    /// its crop coordinates through the frame's window to full-image pixels. A frame without a
    /// window keeps no keypoints whatever is recorded.
    pub fn record(&mut self, index: usize, keypoints: &[CropKeypoint; COCO17_COUNT]) -> Result<(), DetectError> {
        let frames = self.windows.len();
        let window = self.windows.get(index).ok_or(DetectError::NoSuchFrame { index, frames })?;
        let Some(window) = window else { return Ok(()) };
        let mut frame = keypoints.map(|k| {
            let pixel = window.full_from_normalized(k.at);
            (pixel.is_finite() && k.score.is_finite() && k.score >= MIN_KEYPOINT_SCORE)
                .then_some(Keypoint2d { pixel, score: k.score })
        });
        if mirror_towards(&mut frame, &self.expected[index]) {
            self.mirrored += 1;
        }
        self.track.frames[index] = frame;
        self.detected += 1;
        Ok(())
    }

    /// Detections whose left and right were exchanged ([`mirror_towards`]).
    pub fn mirrored_frames(&self) -> usize {
        self.mirrored
    }

    /// Frames with a detection so far.
    pub fn detected_frames(&self) -> usize {
        self.detected
    }

    /// The keypoint track (every planned frame, in presentation order).
    pub fn into_track(self) -> KeypointTrack {
        self.track
    }
}

/// Frames per second of detection measured so far, and what is left: for progress reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DetectionProgress {
    pub observer: usize,
    pub done: usize,
    pub total: usize,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keypoints(points: &[(f32, f32)]) -> [Option<Keypoint2d>; COCO17_COUNT] {
        std::array::from_fn(|k| points.get(k).map(|&(x, y)| Keypoint2d { pixel: Vec2::new(x, y), score: 0.8 }))
    }

    /// A body seen from behind by a model that took it for the front: every left keypoint on
    /// the right. Against EgoNet's projection the check exchanges them; a right detection, or
    /// one too ambiguous, is left alone.
    #[test]
    fn a_mirrored_detection_is_exchanged_towards_egonet() {
        // x grows with the person's left side (seen from behind); y down the body.
        let truth: Vec<(f32, f32)> = (0..COCO17_COUNT)
            .map(|k| {
                let side = if k == 0 {
                    0.0
                } else if k % 2 == 1 {
                    20.0
                } else {
                    -20.0
                };
                (100.0 + side, 10.0 * k as f32)
            })
            .collect();
        let expected: [Option<Vec2>; COCO17_COUNT] =
            std::array::from_fn(|k| (k >= 5).then(|| Vec2::new(truth[k].0, truth[k].1)));
        let mut right = keypoints(&truth);
        assert!(!mirror_towards(&mut right, &expected));
        let swapped: Vec<(f32, f32)> = (0..COCO17_COUNT).map(|k| truth[COCO17_MIRROR[k]]).collect();
        let mut mirrored = keypoints(&swapped);
        assert!(mirror_towards(&mut mirrored, &expected));
        assert_eq!(mirrored, keypoints(&truth));
        // Nothing to compare against: left as detected.
        let mut alone = keypoints(&swapped);
        assert!(!mirror_towards(&mut alone, &[None; COCO17_COUNT]));
        for k in 0..COCO17_COUNT {
            assert_eq!(COCO17_MIRROR[COCO17_MIRROR[k]], k);
        }
    }
}
