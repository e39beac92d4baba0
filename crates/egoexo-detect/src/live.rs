//! A camera that detects while it streams (the observer page, `web/observe.html`): where to
//! crop each frame, the camera's calibration when all a browser gives is the image size and
//! maybe a field of view, and when a frame was captured.
//!
//! Where to crop ([`LiveCropTracker`]): in the region the ego signals propose — a watching
//! page's newest reconstruction of the wearer projected into this camera once it knows where
//! the camera stands (`wearer-region` in `docs/live-protocol.md`; the recorded pipeline's
//! region, paper § Ego-Guided Wearer Localization) — widened to the person the previous frame
//! found when that is the same person. Without a fresh region (before registration, or no
//! page watching), around the person the previous frame found — the tracking crop of top-down
//! pose models such as MoveNet — and a frame after a miss is searched whole.
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

/// How far from a frame's capture a wearer region may be for the frame, nanoseconds. A region
/// is for the newest head pose a watching page has, and reaches the camera 0.2–0.4 s later
/// (the head pose to the relay and the page, a reconstruction, the region back through the
/// relay); a wearer walking at 1.5 m/s moves a few tenths of a metre meanwhile, which the
/// region's margin and the tracked person around it cover. Older regions are not used.
pub const MAX_REGION_AGE_NS: i64 = 600_000_000;

/// Where the next frame's crop comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CropSource {
    /// No one found yet (or lost), and no region: the whole frame.
    WholeFrame,
    /// Around the person the previous frame found.
    Tracking,
    /// The region the ego signals propose (with the previous frame's person, when they agree).
    EgoSignals,
}

impl CropSource {
    /// In words, for the page.
    pub fn name(self) -> &'static str {
        match self {
            CropSource::WholeFrame => "whole frame",
            CropSource::Tracking => "tracking",
            CropSource::EgoSignals => "ego signals",
        }
    }
}

/// The crop of one frame: its window, where that came from, and the wearer region used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CropPlan {
    pub window: CropWindow,
    pub source: CropSource,
    /// The wearer region the window holds ([`CropSource::EgoSignals`]).
    pub region: Option<BoundingBox>,
}

/// The crop of each frame of one camera: in the wearer region the ego signals propose, else
/// around the previous frame's person, else the whole frame (a square around it, black bars
/// on the short sides).
#[derive(Clone, Debug, PartialEq)]
pub struct LiveCropTracker {
    width: u32,
    height: u32,
    tracked: Option<BoundingBox>,
    /// The newest wearer region and the moment it is for (the page's clock, ns).
    proposed: Option<(BoundingBox, i64)>,
}

impl LiveCropTracker {
    /// A tracker for frames of `width × height` pixels, searching the whole frame first.
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height, tracked: None, proposed: None }
    }

    /// The frames' size.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Takes a wearer region (full-image pixels) for the moment `at_ns` (the page's clock). One
    /// older than the region held, or missing the image, is ignored.
    pub fn propose(&mut self, region: BoundingBox, at_ns: i64) {
        let sane = region.min.is_finite() && region.max.is_finite() && region.min.cmple(region.max).all();
        if sane && self.overlaps_image(&region) && self.proposed.is_none_or(|(_, held)| at_ns >= held) {
            self.proposed = Some((region, at_ns));
        }
    }

    /// The crop of a frame captured at `frame_ns` (the page's clock): the wearer region when
    /// one is within [`MAX_REGION_AGE_NS`] of it — grown to hold the previous frame's person
    /// where the two overlap (the same person, and the region may lag them) — else around the
    /// previous frame's person, else the whole frame.
    pub fn plan(&self, frame_ns: i64) -> CropPlan {
        let region = self
            .proposed
            .filter(|(_, at)| frame_ns.saturating_sub(*at).unsigned_abs() <= MAX_REGION_AGE_NS as u64)
            .map(|(region, _)| region);
        let (around, source) = match (region, self.tracked) {
            (Some(r), Some(t)) if r.intersection(&t).is_some() => {
                (Some(BoundingBox { min: r.min.min(t.min), max: r.max.max(t.max) }), CropSource::EgoSignals)
            }
            (Some(r), _) => (Some(r), CropSource::EgoSignals),
            (None, Some(t)) => (Some(t), CropSource::Tracking),
            (None, None) => (None, CropSource::WholeFrame),
        };
        match around.and_then(|b| CropWindow::around(&b, MIN_CROP_SIDE_PX)) {
            Some(window) => CropPlan { window, source, region },
            None => CropPlan { window: self.whole_frame(), source: CropSource::WholeFrame, region: None },
        }
    }

    /// The square around the whole frame.
    fn whole_frame(&self) -> CropWindow {
        let (w, h) = (self.width as f32, self.height as f32);
        let side = w.max(h).max(1.0);
        // The image spans [-0.5, size - 0.5]; the square is centred on it.
        CropWindow { min: Vec2::new(0.5 * (w - side) - 0.5, 0.5 * (h - side) - 0.5), side }
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
        assert_eq!(tracker.plan(0).source, CropSource::WholeFrame);
        let whole = tracker.plan(0).window;
        assert_eq!(whole.side, 640.0);
        // The square is centred on the image: 80 px of black above and below.
        assert_eq!(whole.min, Vec2::new(-0.5, -80.5));
        assert_eq!(whole.full_from_normalized(Vec2::splat(0.5)), Vec2::new(319.5, 239.5));
        // A person in the middle of the crop: 6 keypoints spanning a tenth of it each way.
        let person = [(0.45, 0.45), (0.55, 0.45), (0.45, 0.55), (0.55, 0.55), (0.5, 0.5), (0.5, 0.4)];
        let keypoints = tracker.record(&whole, &detection(&person, 0.8));
        assert_eq!(keypoints.iter().flatten().count(), 6);
        assert_eq!(keypoints[0].unwrap().pixel, whole.full_from_normalized(Vec2::new(0.45, 0.45)));
        assert_eq!(tracker.plan(0).source, CropSource::Tracking);
        let next = tracker.plan(0).window;
        // Around the person: their box is 64 × 96 px (0.1 × 0.15 of 640), 30 % of its longer side
        // added each side → 153.6 px, centred on it.
        assert!((next.side - 153.6).abs() < 1e-3, "{next:?}");
        assert!(next.full_from_normalized(Vec2::splat(0.5)).distance(Vec2::new(319.5, 223.5)) < 1e-3, "{next:?}");
        // Keypoints below the score floor are dropped; too few kept is a miss.
        let keypoints = tracker.record(&next, &detection(&person, 0.2));
        assert!(keypoints.iter().all(Option::is_none));
        assert_eq!(tracker.plan(0), CropPlan { window: whole, source: CropSource::WholeFrame, region: None });
        // A tiny person still gets a crop of at least MIN_CROP_SIDE_PX.
        let tiny = [(0.5, 0.5), (0.501, 0.5), (0.5, 0.501), (0.501, 0.501), (0.5005, 0.5005)];
        tracker.record(&whole, &detection(&tiny, 0.9));
        assert_eq!(tracker.plan(0).window.side, MIN_CROP_SIDE_PX);
    }

    #[test]
    fn the_ego_signals_region_is_cropped_while_fresh_and_widened_to_the_same_person_found() {
        const MS: i64 = 1_000_000;
        let mut tracker = LiveCropTracker::new(640, 480);
        let region = BoundingBox { min: Vec2::new(200.0, 100.0), max: Vec2::new(300.0, 400.0) };
        tracker.propose(region, 1_000 * MS);
        // A frame within MAX_REGION_AGE_NS of the region's moment, either side, is cropped there.
        for frame_ms in [1_000, 1_000 + 600, 1_000 - 600] {
            let plan = tracker.plan(frame_ms * MS);
            assert_eq!((plan.source, plan.region), (CropSource::EgoSignals, Some(region)), "{frame_ms} ms");
            assert_eq!(plan.window, CropWindow::around(&region, MIN_CROP_SIDE_PX).unwrap());
        }
        // Later than that: the whole frame again (nobody tracked), and `ego signals` is named.
        assert_eq!(tracker.plan(1_601 * MS).source, CropSource::WholeFrame);
        assert_eq!(CropSource::EgoSignals.name(), "ego signals");
        // The person found overlaps the region (the same person, a step ahead of it): the crop
        // holds both.
        let whole = tracker.plan(1_601 * MS).window;
        let person = [(0.45, 0.3), (0.55, 0.3), (0.45, 0.5), (0.55, 0.5), (0.5, 0.4)];
        tracker.record(&whole, &detection(&person, 0.8));
        let found = tracker.plan(1_601 * MS).window;
        let plan = tracker.plan(1_000 * MS);
        assert_eq!(plan.source, CropSource::EgoSignals);
        for corner in [region.min, region.max] {
            let u = plan.window.normalized_from_full(corner);
            assert!(u.cmpge(Vec2::ZERO).all() && u.cmple(Vec2::ONE).all(), "{corner} outside {plan:?}");
        }
        assert!(plan.window.side > CropWindow::around(&region, MIN_CROP_SIDE_PX).unwrap().side);
        assert!(found.full_from_normalized(Vec2::splat(0.5)).x > 300.0, "{found:?}");
        // A person elsewhere (a bystander): the region alone.
        let bystander = [(0.9, 0.3), (0.95, 0.3), (0.9, 0.5), (0.95, 0.5), (0.92, 0.4)];
        tracker.record(&whole, &detection(&bystander, 0.8));
        assert_eq!(tracker.plan(1_000 * MS).window, CropWindow::around(&region, MIN_CROP_SIDE_PX).unwrap());
        // An older region, one missing the image and one that is no box are ignored.
        let elsewhere = BoundingBox { min: Vec2::new(10.0, 10.0), max: Vec2::new(60.0, 200.0) };
        tracker.propose(elsewhere, 900 * MS);
        tracker.propose(BoundingBox { min: Vec2::new(700.0, 10.0), max: Vec2::new(800.0, 200.0) }, 1_100 * MS);
        tracker.propose(BoundingBox { min: region.max, max: region.min }, 1_100 * MS);
        tracker.propose(BoundingBox { min: Vec2::NAN, max: region.max }, 1_100 * MS);
        assert_eq!(tracker.plan(1_000 * MS).region, Some(region));
        tracker.propose(elsewhere, 1_100 * MS);
        assert_eq!(tracker.plan(1_000 * MS).region, Some(elsewhere));
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
