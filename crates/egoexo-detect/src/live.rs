//! A camera that detects while it streams (the observer page, `web/observe.html`): where to
//! crop each frame, the camera's calibration when all a browser gives is the image size and
//! maybe a field of view, and when a frame was captured.
//!
//! Without the ego signals' region (a recorded session's detector step has EgoNet's coarse
//! pose; a live camera does not yet), each frame is cropped around the person the previous
//! frame found — the tracking crop of top-down pose models such as MoveNet — and a frame
//! after a miss is searched whole ([`LiveCropTracker`]).
//!
//! Conventions as the detector step's: pixels with the centre of the top-left pixel at
//! (0, 0); nanoseconds since the Unix epoch on the page's clock (the one its pongs report).

use egoexo_core::camera::{CameraCalibration, CameraError, Pinhole, Projection};
use egoexo_core::crop::CropWindow;
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::Vec2;
use egoexo_core::region::BoundingBox;
use egoexo_core::rigid::RigidTransform;
use egoexo_infer::CropKeypoint;

use crate::{MIN_CROP_SIDE_PX, MIN_KEYPOINT_SCORE};

/// Keypoints a detection needs (of 17, scoring at least [`MIN_KEYPOINT_SCORE`]) to be a
/// person the next frame is cropped around; fewer is a miss.
pub const MIN_TRACKED_KEYPOINTS: usize = 5;

/// The tracking crop's margin: the box around the found keypoints grows by this fraction of
/// its longer side on every edge (a person moves between frames, and keypoints sit inside
/// the body's outline).
pub const TRACKING_MARGIN: f32 = 0.3;

/// Horizontal field of view assumed for a camera that reports none, degrees: a typical
/// laptop webcam or phone's main camera (60–78°). Registration refines the focal length.
pub const DEFAULT_HORIZONTAL_FOV_DEG: f64 = 65.0;

/// Where the next frame's crop comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CropSource {
    /// No one found yet (or lost): the whole frame.
    WholeFrame,
    /// Around the person the previous frame found.
    Tracking,
}

impl CropSource {
    /// In words, for the page.
    pub fn name(self) -> &'static str {
        match self {
            CropSource::WholeFrame => "whole frame",
            CropSource::Tracking => "tracking",
        }
    }
}

/// The crop of each frame of one camera: around the previous frame's person, else the whole
/// frame (a square around it, black bars on the short sides).
#[derive(Clone, Debug, PartialEq)]
pub struct LiveCropTracker {
    width: u32,
    height: u32,
    tracked: Option<BoundingBox>,
}

impl LiveCropTracker {
    /// A tracker for frames of `width × height` pixels, searching the whole frame first.
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height, tracked: None }
    }

    /// The frames' size.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Where the next frame's window comes from.
    pub fn source(&self) -> CropSource {
        if self.tracked.is_some() { CropSource::Tracking } else { CropSource::WholeFrame }
    }

    /// The next frame's window.
    pub fn window(&self) -> CropWindow {
        let whole = || {
            let (w, h) = (self.width as f32, self.height as f32);
            let side = w.max(h).max(1.0);
            // The image spans [-0.5, size - 0.5]; the square is centred on it.
            CropWindow { min: Vec2::new(0.5 * (w - side) - 0.5, 0.5 * (h - side) - 0.5), side }
        };
        self.tracked.as_ref().and_then(|b| CropWindow::around(b, MIN_CROP_SIDE_PX)).unwrap_or_else(whole)
    }

    /// Takes the detector's output for a frame cropped to `window`: its keypoints in
    /// full-image pixels (those scoring below [`MIN_KEYPOINT_SCORE`] dropped), and the next
    /// frame's crop follows them — or searches the whole frame again when fewer than
    /// [`MIN_TRACKED_KEYPOINTS`] were found.
    pub fn record(
        &mut self,
        window: &CropWindow,
        found: &[CropKeypoint; COCO17_COUNT],
    ) -> [Option<Keypoint2d>; COCO17_COUNT] {
        let keypoints = found.map(|k| {
            let pixel = window.full_from_normalized(k.at);
            (pixel.is_finite() && k.score.is_finite() && k.score >= MIN_KEYPOINT_SCORE)
                .then_some(Keypoint2d { pixel, score: k.score.min(1.0) })
        });
        let kept: Vec<Vec2> = keypoints.iter().flatten().map(|k| k.pixel).collect();
        self.tracked = (kept.len() >= MIN_TRACKED_KEYPOINTS)
            .then(|| BoundingBox::around(kept))
            .flatten()
            .map(|b| {
                let grow = Vec2::splat(TRACKING_MARGIN * b.size().max_element());
                BoundingBox { min: b.min - grow, max: b.max + grow }
            })
            .filter(|b| self.overlaps_image(b));
        keypoints
    }

    fn overlaps_image(&self, b: &BoundingBox) -> bool {
        b.max.x >= -0.5 && b.max.y >= -0.5 && b.min.x <= self.width as f32 - 0.5 && b.min.y <= self.height as f32 - 0.5
    }
}

/// A browser camera's calibration: a pinhole of `width × height` pixels with the principal
/// point at the centre and square pixels, its focal length from the horizontal field of view
/// where the browser reports one — else [`DEFAULT_HORIZONTAL_FOV_DEG`], and the second value
/// says the focal length is a guess (the hello's `focal_known: false`). The camera frame is the
/// device frame (a static camera's pose is its registration's to find).
pub fn browser_camera(
    width: u32,
    height: u32,
    horizontal_fov_deg: Option<f64>,
) -> Result<(CameraCalibration, bool), CameraError> {
    let known = horizontal_fov_deg.filter(|f| f.is_finite() && *f > 1.0 && *f < 179.0);
    let fov = known.unwrap_or(DEFAULT_HORIZONTAL_FOV_DEG).to_radians();
    let focal = (0.5 * width as f64 / (0.5 * fov).tan()) as f32;
    let pinhole = Pinhole::new(focal, focal, 0.5 * width as f32 - 0.5, 0.5 * height as f32 - 0.5)?;
    let camera = CameraCalibration::new(Projection::Pinhole(pinhole), width, height, RigidTransform::IDENTITY)?;
    Ok((camera, known.is_some()))
}

/// Which of a video frame's times stamped it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameTimeSource {
    /// When the camera captured it (`requestVideoFrameCallback`'s `captureTime`).
    Capture,
    /// When the browser had it to show (the callback's `presentationTime`): later than the
    /// capture by the camera's and the browser's delay.
    Presentation,
}

/// A video frame's time in nanoseconds since the Unix epoch, from its
/// `requestVideoFrameCallback` metadata (milliseconds on the page's `performance.now()` clock,
/// whose zero is `time_origin_ms` since the epoch): its capture time where the browser gives a
/// plausible one (not after the presentation, at most 1 s before it), else its presentation
/// time. `None` when neither is a finite time.
pub fn frame_time_ns(
    time_origin_ms: f64,
    capture_ms: Option<f64>,
    presentation_ms: f64,
) -> Option<(i64, FrameTimeSource)> {
    // The origin's whole milliseconds apart from the rest: epoch nanoseconds overflow an f64's
    // 53 bits, the whole milliseconds and a small remainder do not.
    let whole_ms = time_origin_ms.floor();
    let to_ns = |ms: f64| {
        let rest_ns = (time_origin_ms - whole_ms + ms) * 1e6;
        let ok = whole_ms.is_finite() && rest_ns.is_finite() && whole_ms.abs() < 9.0e12 && rest_ns.abs() < 1.0e18;
        ok.then(|| whole_ms as i64 * 1_000_000 + rest_ns.round() as i64)
    };
    let capture = capture_ms.filter(|c| c.is_finite() && *c <= presentation_ms && presentation_ms - *c <= 1000.0);
    match capture.and_then(to_ns) {
        Some(ns) => Some((ns, FrameTimeSource::Capture)),
        None => to_ns(presentation_ms).map(|ns| (ns, FrameTimeSource::Presentation)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn detection(points: &[(f32, f32)], score: f32) -> [CropKeypoint; COCO17_COUNT] {
        let mut out = [CropKeypoint { at: Vec2::ZERO, score: 0.0 }; COCO17_COUNT];
        for (k, &(x, y)) in out.iter_mut().zip(points) {
            *k = CropKeypoint { at: Vec2::new(x, y), score };
        }
        out
    }

    #[test]
    fn the_whole_frame_first_then_around_the_person_found_then_whole_again_after_a_miss() {
        let mut tracker = LiveCropTracker::new(640, 480);
        assert_eq!(tracker.source(), CropSource::WholeFrame);
        let whole = tracker.window();
        assert_eq!(whole.side, 640.0);
        // The square is centred on the image: 80 px of black above and below.
        assert_eq!(whole.min, Vec2::new(-0.5, -80.5));
        assert_eq!(whole.full_from_normalized(Vec2::splat(0.5)), Vec2::new(319.5, 239.5));
        // A person in the middle of the crop: 6 keypoints spanning a tenth of it each way.
        let person = [(0.45, 0.45), (0.55, 0.45), (0.45, 0.55), (0.55, 0.55), (0.5, 0.5), (0.5, 0.4)];
        let keypoints = tracker.record(&whole, &detection(&person, 0.8));
        assert_eq!(keypoints.iter().flatten().count(), 6);
        assert_eq!(keypoints[0].unwrap().pixel, whole.full_from_normalized(Vec2::new(0.45, 0.45)));
        assert_eq!(tracker.source(), CropSource::Tracking);
        let next = tracker.window();
        // Around the person: their box is 64 × 96 px (0.1 × 0.15 of 640), 30 % of its longer side
        // added each side → 153.6 px, centred on it.
        assert!((next.side - 153.6).abs() < 1e-3, "{next:?}");
        assert!(next.full_from_normalized(Vec2::splat(0.5)).distance(Vec2::new(319.5, 223.5)) < 1e-3, "{next:?}");
        // Keypoints below the score floor are dropped; too few kept is a miss.
        let keypoints = tracker.record(&next, &detection(&person, 0.2));
        assert!(keypoints.iter().all(Option::is_none));
        assert_eq!((tracker.source(), tracker.window()), (CropSource::WholeFrame, whole));
        // A tiny person still gets a crop of at least MIN_CROP_SIDE_PX.
        let tiny = [(0.5, 0.5), (0.501, 0.5), (0.5, 0.501), (0.501, 0.501), (0.5005, 0.5005)];
        tracker.record(&whole, &detection(&tiny, 0.9));
        assert_eq!(tracker.window().side, MIN_CROP_SIDE_PX);
    }

    #[test]
    fn a_camera_without_a_field_of_view_gets_the_default_and_says_so() {
        let (camera, known) = browser_camera(1280, 720, Some(90.0)).unwrap();
        assert!(known);
        let Projection::Pinhole(p) = camera.projection else { panic!() };
        assert!((p.fx - 640.0).abs() < 1e-3 && p.fx == p.fy, "{p:?}");
        assert_eq!((p.cx, p.cy), (639.5, 359.5));
        for fov in [None, Some(f64::NAN), Some(0.0), Some(200.0)] {
            let (camera, known) = browser_camera(640, 480, fov).unwrap();
            assert!(!known, "{fov:?}");
            let Projection::Pinhole(p) = camera.projection else { panic!() };
            let expected = 320.0 / (DEFAULT_HORIZONTAL_FOV_DEG.to_radians() / 2.0).tan();
            assert!((f64::from(p.fx) - expected).abs() < 1e-3, "{p:?}");
        }
        assert!(browser_camera(0, 480, None).is_err());
    }

    #[test]
    fn a_frame_is_stamped_with_its_capture_time_where_the_browser_gives_a_plausible_one() {
        let origin = 1_764_600_000_000.0;
        assert_eq!(
            frame_time_ns(origin, Some(1000.25), 1040.0),
            Some((1_764_600_001_000_250_000, FrameTimeSource::Capture))
        );
        // Missing, after the presentation, or more than a second before it: the presentation.
        for capture in [None, Some(1041.0), Some(10.0), Some(f64::NAN)] {
            assert_eq!(
                frame_time_ns(origin, capture, 1040.0),
                Some((1_764_600_001_040_000_000, FrameTimeSource::Presentation)),
                "{capture:?}"
            );
        }
        assert_eq!(frame_time_ns(origin, None, f64::INFINITY), None);
    }
}
