//! The observer page's side of the live protocol (`web/observe.html`, `docs/live-protocol.md`,
//! "The observer page"): a phone's or a laptop's camera joins a room as a static observer and
//! streams the keypoints its detector finds of the wearer.
//!
//! The page owns the camera, the clock and the socket; its Web Worker
//! (`web/observe-worker.js`) owns a [`LiveDetector`] and hands it each frame's crop. Everything
//! that is geometry or protocol is here:
//!
//! - [`observer_hello`] — a static camera (`"mount": "fixed"`, keypoints only) watching a
//!   target wearer; [`calibration_message`] — its camera from the image size and the field of
//!   view the browser reports, or a default it says is a guess;
//! - [`LiveDetector`] — where to crop the next frame ([`egoexo_detect::live::LiveCropTracker`]:
//!   the wearer region a watching page proposes, the person tracked, or the whole frame), the
//!   detector on that crop, and the keypoints as a binary data frame (op 2) stamped with the
//!   frame's capture time ([`egoexo_detect::live::frame_time_ns`]).
//!
//! Nothing here reads a clock: the page passes every time in.

use egoexo_core::crop::CanvasDraw;
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::Vec2;
use egoexo_core::region::BoundingBox;
use egoexo_detect::live::{CropPlan, CropSource, LiveCropTracker, browser_camera};
use egoexo_infer::manifest::Manifest;
use egoexo_infer::{InferError, KeypointDetector};
use egoexo_protocol::live::{
    ClientMessage, DataFrame, DeviceHello, DeviceMount, DeviceRole, DeviceWorld, FramePayload, Join,
    LIVE_PROTOCOL_VERSION, Stream, region_problem, valid_device_id,
};

/// What went wrong on the observer page, in words for the person holding the camera.
#[derive(Debug, thiserror::Error)]
pub enum ObserveError {
    #[error("“{0}” cannot be a device id: use 1–64 letters, digits, '.', '_' or '-'.")]
    BadDeviceId(String),
    #[error("“{0}” cannot be the wearer's id: use 1–64 letters, digits, '.', '_' or '-', not this camera's own id.")]
    BadTarget(String),
    #[error("the camera's {width}×{height} frames cannot be calibrated: {message}")]
    Camera { width: u32, height: u32, message: String },
    #[error("the models' manifest has no keypoint detector: this server cannot detect people in a camera's frames")]
    NoDetector,
    #[error("the keypoint detector: {0}")]
    Detector(#[from] InferError),
    #[error("a crop of {got} bytes, expected {expected} ({side}×{side} RGBA)")]
    CropSize { got: usize, expected: usize, side: u32 },
    #[error("the frame's time must be a finite number of nanoseconds, got {0}")]
    Timestamp(f64),
    #[error("no frame was cropped before this detection")]
    NoCrop,
    #[error("a wearer region from the relay: {0}")]
    Region(&'static str),
    #[error("could not write a protocol message: {0}")]
    Json(String),
}

/// The hello of a static camera `device_id` that watches `target` (the wearer's device id;
/// `None`: the room's only wearer), its focal length measured or a guess.
pub fn observer_hello(
    join: &Join,
    device_id: &str,
    target: Option<&str>,
    focal_known: bool,
) -> Result<String, ObserveError> {
    let id = device_id.trim();
    if !valid_device_id(id) {
        return Err(ObserveError::BadDeviceId(id.chars().take(70).collect()));
    }
    let target = target.map(str::trim).filter(|t| !t.is_empty());
    if let Some(t) = target.filter(|t| !valid_device_id(t) || *t == id) {
        return Err(ObserveError::BadTarget(t.chars().take(70).collect()));
    }
    let message = ClientMessage::Hello {
        protocol: LIVE_PROTOCOL_VERSION,
        join: join.clone(),
        device: Some(DeviceHello {
            target: target.map(str::to_owned),
            world: DeviceWorld::Own,
            mount: DeviceMount::Fixed,
            focal_known,
            ..DeviceHello::worn(id, DeviceRole::Observer, vec![Stream::Keypoints])
        }),
    };
    serde_json::to_string(&message).map_err(|e| ObserveError::Json(e.to_string()))
}

/// The calibration message of a camera giving `width × height` frames with a horizontal
/// field of view (degrees) where the browser reports one, and whether its focal length is
/// known (else a default, for the hello's `focal_known`).
pub fn calibration_message(
    width: u32,
    height: u32,
    horizontal_fov_deg: Option<f64>,
) -> Result<(String, bool), ObserveError> {
    let (camera, known) = browser_camera(width, height, horizontal_fov_deg).map_err(|e| ObserveError::Camera {
        width,
        height,
        message: e.to_string(),
    })?;
    let json =
        serde_json::to_string(&ClientMessage::Calibration { camera }).map_err(|e| ObserveError::Json(e.to_string()))?;
    Ok((json, known))
}

/// A page time in nanoseconds since the epoch (an f64 from JS) as an integer.
fn nanoseconds(ns: f64) -> Result<i64, ObserveError> {
    crate::page_time_ns(ns).ok_or(ObserveError::Timestamp(ns))
}

/// The detector of one camera's frames, and the crop that follows the person it finds.
#[derive(Debug)]
pub struct LiveDetector {
    detector: KeypointDetector,
    tracker: LiveCropTracker,
    /// The crop of the frame being detected (set by [`LiveDetector::crop`]).
    cropped: Option<CropPlan>,
    /// The last frame's keypoints (full-image pixels) and the crop they came from.
    last: [Option<Keypoint2d>; COCO17_COUNT],
    last_crop: Option<CropPlan>,
    frames: u64,
    found: u64,
}

impl LiveDetector {
    /// The detector of the models' `manifest.json` (`manifest`), its ONNX file's bytes given
    /// by `read` (file name → bytes, checked against the manifest's sha256).
    pub fn load(manifest: &[u8], read: impl FnOnce(&str) -> Option<Vec<u8>>) -> Result<Self, ObserveError> {
        let manifest = Manifest::from_json(manifest)?;
        let entry = manifest.detector.ok_or(ObserveError::NoDetector)?;
        let file = entry.file.file.clone();
        let bytes = read(&file).ok_or(InferError::ReadModel { file, message: "not fetched".into() })?;
        let detector = KeypointDetector::load(&entry, &bytes)?;
        Ok(Self {
            detector,
            tracker: LiveCropTracker::new(1, 1),
            cropped: None,
            last: [None; COCO17_COUNT],
            last_crop: None,
            frames: 0,
            found: 0,
        })
    }

    /// The model's square input side, pixels.
    pub fn input_size(&self) -> u32 {
        self.detector.input_size()
    }

    /// The crop of the next frame (`width × height`, captured at `timestamp_ns` on the page's
    /// clock) as one `drawImage` onto a black `input_size²` canvas. A frame of another size
    /// than the last restarts the search from the whole frame.
    pub fn crop(&mut self, width: u32, height: u32, timestamp_ns: f64) -> Result<Option<CanvasDraw>, ObserveError> {
        let frame_ns = nanoseconds(timestamp_ns)?;
        if self.tracker.size() != (width, height) {
            self.tracker = LiveCropTracker::new(width, height);
        }
        let plan = self.tracker.plan(frame_ns);
        self.cropped = Some(plan);
        Ok(plan.window.canvas_draw(width, height, self.input_size()))
    }

    /// Where the crop of the frame being detected (or else the last) comes from.
    pub fn crop_source(&self) -> CropSource {
        self.cropped.or(self.last_crop).map_or(CropSource::WholeFrame, |c| c.source)
    }

    /// A watching page's wearer region ([`egoexo_protocol::live::RelayMessage::WearerRegion`]):
    /// its corners in full-image pixels, for the moment `at_ns` on the page's clock.
    pub fn propose(&mut self, min: [f32; 2], max: [f32; 2], at_ns: f64) -> Result<(), ObserveError> {
        let region = BoundingBox { min: Vec2::from(min), max: Vec2::from(max) };
        if let Some(problem) = region_problem(&region) {
            return Err(ObserveError::Region(problem));
        }
        self.tracker.propose(region, nanoseconds(at_ns)?);
        Ok(())
    }

    /// Detects on the crop of the frame [`LiveDetector::crop`] planned (`input_size²` pixels,
    /// RGBA as a canvas gives them) and returns the keypoints data frame (op 2, the device's
    /// keypoints channel) stamped `timestamp_ns` (the frame's time on the page's clock).
    pub fn detect(&mut self, crop_rgba: &[u8], timestamp_ns: f64) -> Result<Vec<u8>, ObserveError> {
        let timestamp_ns = nanoseconds(timestamp_ns)?;
        let side = self.input_size();
        let pixels = side as usize * side as usize;
        if crop_rgba.len() != pixels * 4 {
            return Err(ObserveError::CropSize { got: crop_rgba.len(), expected: pixels * 4, side });
        }
        let crop = self.cropped.take().ok_or(ObserveError::NoCrop)?;
        let rgb: Vec<u8> = crop_rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        let found = self.detector.detect(&rgb)?;
        let keypoints = self.tracker.record(&crop.window, &found);
        self.frames += 1;
        if keypoints.iter().any(Option::is_some) {
            self.found += 1;
        }
        self.last = keypoints;
        self.last_crop = Some(crop);
        let frame = DataFrame {
            channel: Stream::Keypoints.channel(),
            timestamp_ns,
            payload: FramePayload::Keypoints(keypoints),
        };
        Ok(frame.encode())
    }

    /// The last frame's keypoints for the page's overlay: 17 × (x, y, score), full-image
    /// pixels; NaN where none was found.
    pub fn keypoints(&self) -> Vec<f32> {
        self.last
            .iter()
            .flat_map(|k| match k {
                Some(k) => [k.pixel.x, k.pixel.y, k.score],
                None => [f32::NAN; 3],
            })
            .collect()
    }

    /// The last frame's crop window for the overlay: [x, y, side] of its top-left edge,
    /// full-image pixels (empty before the first detection).
    pub fn window(&self) -> Vec<f32> {
        self.last_crop.map(|c| vec![c.window.min.x + 0.5, c.window.min.y + 0.5, c.window.side]).unwrap_or_default()
    }

    /// The wearer region the last frame was cropped in, for the overlay: [x0, y0, x1, y1] of its
    /// edges, full-image pixels (empty when the frame had none).
    pub fn region(&self) -> Vec<f32> {
        self.last_crop
            .and_then(|c| c.region)
            .map(|r| vec![r.min.x + 0.5, r.min.y + 0.5, r.max.x + 0.5, r.max.y + 0.5])
            .unwrap_or_default()
    }

    /// Frames detected on, and of those, frames with a person found.
    pub fn counts(&self) -> (u64, u64) {
        (self.frames, self.found)
    }
}

#[cfg(target_arch = "wasm32")]
mod bindings {
    use wasm_bindgen::prelude::*;

    use super::ObserveError;

    fn js(e: ObserveError) -> JsError {
        JsError::new(&e.to_string())
    }

    /// The calibration message (JSON) of a camera of `width × height` frames and horizontal
    /// field of view `fov_deg` (NaN when the browser reports none); `focalKnown` says whether
    /// the focal length is measured.
    #[wasm_bindgen(js_name = observeCalibration)]
    pub fn observe_calibration(width: u32, height: u32, fov_deg: f64) -> Result<ObserveCalibration, JsError> {
        let (json, focal_known) =
            super::calibration_message(width, height, fov_deg.is_finite().then_some(fov_deg)).map_err(js)?;
        Ok(ObserveCalibration { json, focal_known })
    }

    /// A camera's calibration message and whether its focal length is known.
    #[wasm_bindgen]
    #[derive(Debug)]
    pub struct ObserveCalibration {
        json: String,
        focal_known: bool,
    }

    #[wasm_bindgen]
    impl ObserveCalibration {
        #[wasm_bindgen(getter)]
        pub fn json(&self) -> String {
            self.json.clone()
        }

        #[wasm_bindgen(getter, js_name = focalKnown)]
        pub fn focal_known(&self) -> bool {
            self.focal_known
        }
    }

    /// A video frame's time (nanoseconds since the epoch on the page's clock) from its
    /// `requestVideoFrameCallback` metadata: `captureTime` (NaN when absent) where plausible,
    /// else `presentationTime`; both milliseconds on `performance.now()`'s clock.
    #[wasm_bindgen(js_name = observeFrameTimeNs)]
    pub fn observe_frame_time_ns(time_origin_ms: f64, capture_ms: f64, presentation_ms: f64) -> Option<f64> {
        let capture = capture_ms.is_finite().then_some(capture_ms);
        egoexo_detect::live::frame_time_ns(time_origin_ms, capture, presentation_ms).map(|(ns, _)| ns as f64)
    }

    /// The observer page worker's detector ([`super::LiveDetector`] in JS).
    #[wasm_bindgen(js_name = LiveDetector)]
    #[derive(Debug)]
    pub struct LiveDetectorJs {
        inner: super::LiveDetector,
    }

    #[wasm_bindgen(js_class = LiveDetector)]
    impl LiveDetectorJs {
        /// The detector file's name in the models' `manifest.json` (to fetch it).
        #[wasm_bindgen(js_name = detectorFile)]
        pub fn detector_file(manifest: &[u8]) -> Result<String, JsError> {
            let manifest = egoexo_infer::manifest::Manifest::from_json(manifest).map_err(|e| js(e.into()))?;
            Ok(manifest.detector.ok_or_else(|| js(ObserveError::NoDetector))?.file.file)
        }

        /// Loads the detector from the manifest and the model's bytes (sha256-checked).
        #[wasm_bindgen(constructor)]
        pub fn new(manifest: &[u8], model: Vec<u8>) -> Result<LiveDetectorJs, JsError> {
            let inner = super::LiveDetector::load(manifest, |_| Some(model)).map_err(js)?;
            Ok(Self { inner })
        }

        #[wasm_bindgen(getter, js_name = inputSize)]
        pub fn input_size(&self) -> u32 {
            self.inner.input_size()
        }

        /// The crop of the next frame (captured at `timestamp_ns`, the page's clock):
        /// `Float32Array` [sx, sy, sw, sh, dx, dy, dw, dh] for `drawImage`, empty when the
        /// window misses the frame.
        pub fn crop(&mut self, width: u32, height: u32, timestamp_ns: f64) -> Result<Vec<f32>, JsError> {
            Ok(self
                .inner
                .crop(width, height, timestamp_ns)
                .map_err(js)?
                .map(|d| [d.source, d.dest].concat())
                .unwrap_or_default())
        }

        /// A watching page's wearer region (the relay's `wearer-region`): corners in
        /// full-image pixels, for `at_ns` on the page's clock.
        pub fn propose(&mut self, min_x: f32, min_y: f32, max_x: f32, max_y: f32, at_ns: f64) -> Result<(), JsError> {
            self.inner.propose([min_x, min_y], [max_x, max_y], at_ns).map_err(js)
        }

        /// The wearer region the last frame was cropped in: [x0, y0, x1, y1] (edges), or empty.
        pub fn region(&self) -> Vec<f32> {
            self.inner.region()
        }

        /// `whole frame`, `tracking` or `ego signals`.
        #[wasm_bindgen(getter, js_name = cropSource)]
        pub fn crop_source(&self) -> String {
            self.inner.crop_source().name().into()
        }

        /// Detects on the planned crop (RGBA); the keypoints data frame to send.
        pub fn detect(&mut self, crop_rgba: &[u8], timestamp_ns: f64) -> Result<Vec<u8>, JsError> {
            self.inner.detect(crop_rgba, timestamp_ns).map_err(js)
        }

        /// The last keypoints: `Float32Array` of 17 × (x, y, score), NaN where none.
        pub fn keypoints(&self) -> Vec<f32> {
            self.inner.keypoints()
        }

        /// The last crop window: [x, y, side] (edges, full-image pixels).
        pub fn window(&self) -> Vec<f32> {
            self.inner.window()
        }

        /// The skeleton's bones to draw: `Uint8Array` of keypoint index pairs.
        pub fn bones() -> Vec<u8> {
            egoexo_core::exo_keypoints::COCO17_BONES.iter().flat_map(|&(a, b)| [a, b]).collect()
        }

        /// Frames detected on.
        #[wasm_bindgen(getter)]
        pub fn frames(&self) -> f64 {
            self.inner.counts().0 as f64
        }

        /// Frames with a person found.
        #[wasm_bindgen(getter)]
        pub fn found(&self) -> f64 {
            self.inner.counts().1 as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hello_is_a_fixed_camera_publishing_keypoints_of_its_target() {
        let join = Join::Code { code: "7KQ-M4T".into() };
        let json = observer_hello(&join, " laptop ", Some("bob"), false).unwrap();
        assert_eq!(
            serde_json::from_str::<serde_json::Value>(&json).unwrap(),
            serde_json::json!({"type": "hello", "protocol": 1, "join": {"code": "7KQ-M4T"},
                "device": {"id": "laptop", "role": "observer", "streams": ["keypoints"], "target": "bob",
                    "world": "own", "mount": "fixed", "focal_known": false}})
        );
        let ClientMessage::Hello { device: Some(device), .. } = serde_json::from_str(&json).unwrap() else { panic!() };
        assert_eq!(device.refused_stream(), None);
        let only = observer_hello(&join, "phone", Some(" "), true).unwrap();
        assert!(!only.contains("target") && !only.contains("focal_known"), "{only}");
        assert!(observer_hello(&join, "my phone", None, true).unwrap_err().to_string().contains("device id"));
        let err = observer_hello(&join, "phone", Some("phone"), true).unwrap_err().to_string();
        assert!(err.contains("wearer's id"), "{err}");
    }

    #[test]
    fn the_calibration_is_a_centred_pinhole_from_the_field_of_view() {
        let (json, known) = calibration_message(640, 480, None).unwrap();
        assert!(!known);
        let ClientMessage::Calibration { camera } = serde_json::from_str(&json).unwrap() else { panic!("{json}") };
        assert_eq!((camera.width, camera.height), (640, 480));
        assert!(calibration_message(640, 480, Some(70.0)).unwrap().1);
        assert!(calibration_message(0, 480, None).unwrap_err().to_string().contains("0×480"));
    }

    #[test]
    fn a_detection_is_a_keypoints_frame_on_the_devices_channel_at_the_frames_time() {
        let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
        let manifest = std::fs::read(models.join("manifest.json")).unwrap();
        let mut detector = LiveDetector::load(&manifest, |file| std::fs::read(models.join(file)).ok()).unwrap();
        let side = detector.input_size();
        assert!(detector.detect(&[0; 4], 1.0).unwrap_err().to_string().contains("RGBA"));
        let blank = vec![0u8; side as usize * side as usize * 4];
        assert!(matches!(detector.detect(&blank, 1.0), Err(ObserveError::NoCrop)));
        let draw = detector.crop(640, 480, 1_764_600_000_000_000_000.0).unwrap().unwrap();
        // The whole frame, letterboxed into the square input.
        assert_eq!(draw.source, [0.0, 0.0, 640.0, 480.0]);
        assert_eq!(detector.crop_source(), CropSource::WholeFrame);
        let bytes = detector.detect(&blank, 1_764_600_000_123_456_789.0).unwrap();
        let frame = DataFrame::decode(&bytes).unwrap();
        assert_eq!(frame.channel, Stream::Keypoints.channel());
        assert!((frame.timestamp_ns - 1_764_600_000_123_456_789).abs() < 512, "{}", frame.timestamp_ns);
        assert!(matches!(frame.payload, FramePayload::Keypoints(_)));
        assert_eq!(detector.keypoints().len(), 3 * COCO17_COUNT);
        assert_eq!(detector.window(), vec![0.0, -80.0, 640.0]);
        assert_eq!(detector.counts().0, 1);
        assert!(matches!(detector.detect(&blank, f64::NAN), Err(ObserveError::Timestamp(_))));
    }

    #[test]
    fn a_watching_pages_wearer_region_is_where_the_next_frames_are_cropped() {
        let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
        let manifest = std::fs::read(models.join("manifest.json")).unwrap();
        let mut detector = LiveDetector::load(&manifest, |file| std::fs::read(models.join(file)).ok()).unwrap();
        let side = detector.input_size() as usize;
        let at = 1_764_600_000_000_000_000.0;
        let blank = vec![0u8; side * side * 4];
        // The first frame: nobody found, and no region yet.
        detector.crop(640, 480, at - 1e8).unwrap();
        assert_eq!(detector.crop_source(), CropSource::WholeFrame);
        detector.detect(&blank, at - 1e8).unwrap();
        assert_eq!(detector.region(), Vec::<f32>::new());
        detector.propose([200.0, 100.0], [300.0, 400.0], at).unwrap();
        // A frame 0.2 s later is cropped in the region (the square around it).
        let draw = detector.crop(640, 480, at + 2e8).unwrap().unwrap();
        assert_eq!(detector.crop_source(), CropSource::EgoSignals);
        let [sx, sy, sw, sh] = draw.source;
        let e = 1e-3;
        assert!(sx <= 200.5 + e && sx + sw >= 300.5 - e && sy <= 100.5 + e && sy + sh >= 400.5 - e, "{draw:?}");
        assert!(sw < 640.0, "{draw:?}");
        detector.detect(&blank, at + 2e8).unwrap();
        assert_eq!(detector.region(), vec![200.5, 100.5, 300.5, 400.5]);
        // A second later the region is stale: the whole frame (nobody found on a black crop).
        detector.crop(640, 480, at + 1.2e9).unwrap();
        assert_eq!(detector.crop_source(), CropSource::WholeFrame);
        // What a relay could not have sent is refused, saying what it was.
        let err = detector.propose([f32::NAN, 0.0], [10.0, 10.0], at).unwrap_err().to_string();
        assert!(err.contains("wearer region"), "{err}");
        assert!(matches!(detector.propose([0.0, 0.0], [1.0, 1.0], f64::INFINITY), Err(ObserveError::Timestamp(_))));
    }
}
