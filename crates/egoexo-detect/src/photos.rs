//! The detector on annotated photographs: how well the shipped pose model finds people's
//! keypoints in real images with human-made COCO keypoint labels, on the whole frame vs on the
//! region a proposal gives it (the paper's reason for the ego-guided region). No I/O: the
//! caller reads the annotation file and decodes the images.
//!
//! What a photograph has no EgoNet for, the region is made from the annotation: the person's
//! annotated box grown by the proposal's margin ([`DEFAULT_REGION_MARGIN`]) — the proposal a
//! perfect coarse pose would give — and the same box shifted by a fraction of its longer side
//! (a coarse pose that is off).
//!
//! Scores, per labelled keypoint (COCO visibility 1 or 2): PCK (within `r` × the annotated
//! box's diagonal; a keypoint the detector drops counts as a miss) and COCO's object keypoint
//! similarity (OKS, the per-keypoint σ of the COCO keypoint challenge, the annotation's area).
//!
//! Conventions: COCO pixel coordinates, converted on reading to the pipeline's (centre of the
//! top-left pixel at (0, 0); COCO puts that pixel's top-left *edge* there: −0.5).

use egoexo_core::crop::{CropWindow, resample_rgb};
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::Vec2;
use egoexo_core::region::{BoundingBox, DEFAULT_REGION_MARGIN};
use egoexo_infer::{InferError, KeypointDetector};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::{MIN_CROP_SIDE_PX, MIN_KEYPOINT_SCORE};

/// COCO's per-keypoint σ for OKS (the keypoint challenge's, in COCO-17 order: nose, eyes,
/// ears, shoulders, elbows, wrists, hips, knees, ankles).
pub const COCO17_OKS_SIGMAS: [f32; COCO17_COUNT] = [
    0.026, 0.025, 0.025, 0.035, 0.035, 0.079, 0.079, 0.072, 0.072, 0.062, 0.062, 0.107, 0.107, 0.087, 0.087, 0.089,
    0.089,
];

/// Why an annotation file cannot be used.
#[derive(Debug, Error)]
pub enum PhotoError {
    #[error("{file}: not a COCO keypoints file: {message}")]
    Json { file: String, message: String },
    #[error("{file}: annotation {id}: `{field}` {message}")]
    Annotation { file: String, id: u64, field: &'static str, message: String },
    #[error("{file}: image {id} (`{name}`): `{field}` {message}")]
    Image { file: String, id: u64, name: String, field: &'static str, message: String },
    #[error("image `{name}` is {width}×{height} px with {bytes} bytes of RGB; expected {width}×{height}×3")]
    Pixels { name: String, width: u32, height: u32, bytes: usize },
    #[error(transparent)]
    Detector(#[from] InferError),
}

/// An image of a COCO file (the fields read).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
pub struct CocoImage {
    pub id: u64,
    pub file_name: String,
    pub width: u32,
    pub height: u32,
}

/// One annotated person, checked and in the pipeline's pixel convention.
#[derive(Clone, Debug, PartialEq)]
pub struct AnnotatedPerson {
    /// The annotation's id.
    pub id: u64,
    pub image_id: u64,
    /// Labelled keypoints (COCO visibility 1 or 2), COCO-17 order, pipeline pixels.
    pub keypoints: [Option<Vec2>; COCO17_COUNT],
    /// The annotated person box, pipeline pixels.
    pub bbox: BoundingBox,
    /// The segmentation's area, pixels² (OKS's scale; the box's when the file has none).
    pub area: f32,
}

impl AnnotatedPerson {
    /// How many keypoints are labelled.
    pub fn labelled(&self) -> usize {
        self.keypoints.iter().flatten().count()
    }
}

/// A COCO person-keypoints file: its images and every labelled person not marked as a crowd.
#[derive(Clone, Debug, PartialEq)]
pub struct CocoKeypoints {
    pub images: Vec<CocoImage>,
    pub people: Vec<AnnotatedPerson>,
}

#[derive(Deserialize)]
struct RawFile {
    images: Vec<CocoImage>,
    annotations: Vec<RawAnnotation>,
}

#[derive(Deserialize)]
struct RawAnnotation {
    id: u64,
    image_id: u64,
    #[serde(default)]
    keypoints: Vec<f32>,
    bbox: Vec<f32>,
    #[serde(default)]
    area: Option<f32>,
    #[serde(default)]
    iscrowd: u8,
}

impl CocoKeypoints {
    /// Reads the JSON text of the COCO keypoints file `file` (its name is for errors). People
    /// with no labelled keypoint and crowd regions are left out, as COCO's evaluation does.
    pub fn from_json(file: &str, text: &str) -> Result<Self, PhotoError> {
        let raw: RawFile =
            serde_json::from_str(text).map_err(|e| PhotoError::Json { file: file.into(), message: e.to_string() })?;
        for image in &raw.images {
            if image.width == 0 || image.height == 0 {
                return Err(PhotoError::Image {
                    file: file.into(),
                    id: image.id,
                    name: image.file_name.clone(),
                    field: "width/height",
                    message: format!("is {}×{}; expected a positive size", image.width, image.height),
                });
            }
        }
        let mut people = Vec::new();
        for a in raw.annotations {
            let bad = |field, message: String| PhotoError::Annotation { file: file.into(), id: a.id, field, message };
            if !raw.images.iter().any(|i| i.id == a.image_id) {
                return Err(bad("image_id", format!("is {}, which names no image of the file", a.image_id)));
            }
            if a.iscrowd != 0 {
                continue;
            }
            if a.keypoints.len() != 3 * COCO17_COUNT {
                return Err(bad(
                    "keypoints",
                    format!("has {} numbers; expected 17 × (x, y, v) = 51", a.keypoints.len()),
                ));
            }
            let [x, y, w, h] = a.bbox[..] else {
                return Err(bad("bbox", format!("has {} numbers; expected [x, y, width, height]", a.bbox.len())));
            };
            if !(x.is_finite() && y.is_finite() && w.is_finite() && h.is_finite() && w > 0.0 && h > 0.0) {
                return Err(bad("bbox", format!("is {:?}; expected finite numbers and a positive size", a.bbox)));
            }
            let mut keypoints = [None; COCO17_COUNT];
            for (k, slot) in keypoints.iter_mut().enumerate() {
                let (px, py, v) = (a.keypoints[3 * k], a.keypoints[3 * k + 1], a.keypoints[3 * k + 2]);
                if !(px.is_finite() && py.is_finite()) || !(v == 0.0 || v == 1.0 || v == 2.0) {
                    return Err(bad(
                        "keypoints",
                        format!("keypoint {k} is ({px}, {py}, v = {v}); expected finite pixels and v ∈ {{0, 1, 2}}"),
                    ));
                }
                *slot = (v > 0.0).then(|| Vec2::new(px, py) - Vec2::splat(0.5));
            }
            if keypoints.iter().all(Option::is_none) {
                continue;
            }
            let min = Vec2::new(x, y) - Vec2::splat(0.5);
            let area = a.area.filter(|a| a.is_finite() && *a > 0.0).unwrap_or(w * h);
            people.push(AnnotatedPerson {
                id: a.id,
                image_id: a.image_id,
                keypoints,
                bbox: BoundingBox { min, max: min + Vec2::new(w, h) },
                area,
            });
        }
        Ok(Self { images: raw.images, people })
    }

    /// The people annotated in image `image_id`.
    pub fn people_in(&self, image_id: u64) -> impl Iterator<Item = &AnnotatedPerson> {
        self.people.iter().filter(move |p| p.image_id == image_id)
    }
}

/// What part of a photograph the model sees.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PhotoCrop {
    /// The whole image, letterboxed to a square (one model run per image, whoever it finds).
    FullFrame,
    /// The person's annotated box grown by the proposal's margin, clipped to the image, as a
    /// square window (what a perfect coarse pose would propose).
    Region,
    /// [`PhotoCrop::Region`] moved by `offset` × the box's longer side (x right, y down).
    ShiftedRegion { offset: [f32; 2] },
}

impl PhotoCrop {
    /// The window of a `width × height` image that the model sees for `person`.
    pub fn window(&self, person: &AnnotatedPerson, width: u32, height: u32) -> Option<CropWindow> {
        let image = BoundingBox { min: Vec2::splat(-0.5), max: Vec2::new(width as f32, height as f32) - 0.5 };
        let region = |shift: Vec2| {
            let grown = person.bbox.expanded(DEFAULT_REGION_MARGIN);
            let shift = shift * grown.size().max_element();
            BoundingBox { min: grown.min + shift, max: grown.max + shift }
                .intersection(&image)
                .and_then(|b| CropWindow::around(&b, MIN_CROP_SIDE_PX))
        };
        match *self {
            PhotoCrop::FullFrame => CropWindow::around(&image, MIN_CROP_SIDE_PX),
            PhotoCrop::Region => region(Vec2::ZERO),
            PhotoCrop::ShiftedRegion { offset } => region(Vec2::from(offset)),
        }
    }

    /// A short name for tables.
    pub fn label(&self) -> String {
        match self {
            PhotoCrop::FullFrame => "full frame".into(),
            PhotoCrop::Region => "region (annotated box + 15 % margin)".into(),
            PhotoCrop::ShiftedRegion { offset } => {
                format!("region shifted by ({:+.0} %, {:+.0} %) of its side", 100.0 * offset[0], 100.0 * offset[1])
            }
        }
    }
}

/// Runs `detector` on `window` of an RGB image (`width × height`, 3 bytes a pixel, rows top to
/// bottom) and maps its keypoints to full-image pixels, dropping those scoring below
/// [`MIN_KEYPOINT_SCORE`] — what the detector step does with a video frame, without the
/// left–right check (a photograph has no coarse pose to check against).
pub fn detect_in_window(
    detector: &KeypointDetector,
    name: &str,
    rgb: &[u8],
    width: u32,
    height: u32,
    window: &CropWindow,
) -> Result<[Option<Keypoint2d>; COCO17_COUNT], PhotoError> {
    let crop = resample_rgb(rgb, width, height, window, detector.input_size()).ok_or_else(|| PhotoError::Pixels {
        name: name.into(),
        width,
        height,
        bytes: rgb.len(),
    })?;
    let found = detector.detect(&crop)?;
    Ok(found.map(|k| {
        let pixel = window.full_from_normalized(k.at);
        (pixel.is_finite() && k.score.is_finite() && k.score >= MIN_KEYPOINT_SCORE)
            .then_some(Keypoint2d { pixel, score: k.score })
    }))
}

/// One person's detection scored against their annotation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PersonScore {
    /// Each labelled keypoint's error over the annotated box's diagonal (`None`: the detector
    /// dropped it), COCO-17 order; unlabelled keypoints are absent.
    pub errors: Vec<Option<f32>>,
    /// Object keypoint similarity in `[0, 1]`.
    pub oks: f32,
}

/// Scores `detected` against `person`'s labelled keypoints.
pub fn score_person(person: &AnnotatedPerson, detected: &[Option<Keypoint2d>; COCO17_COUNT]) -> PersonScore {
    let diagonal = person.bbox.diagonal().max(1.0);
    let (mut errors, mut similarity) = (Vec::new(), 0.0);
    for (k, truth) in person.keypoints.iter().enumerate() {
        let Some(truth) = truth else { continue };
        let distance = detected[k].map(|d| d.pixel.distance(*truth));
        errors.push(distance.map(|d| d / diagonal));
        if let Some(d) = distance {
            let kappa = 2.0 * COCO17_OKS_SIGMAS[k];
            similarity += (-(d * d) / (2.0 * person.area * kappa * kappa)).exp();
        }
    }
    let oks = similarity / errors.len().max(1) as f32;
    PersonScore { errors, oks }
}

/// Scores of many people under one [`PhotoCrop`], summarised.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhotoSummary {
    pub people: usize,
    pub keypoints: usize,
    /// Labelled keypoints the detector kept (score ≥ [`MIN_KEYPOINT_SCORE`]).
    pub found: usize,
    pub pck_01: f32,
    pub pck_02: f32,
    pub mean_oks: f32,
}

impl PhotoSummary {
    /// Summarises `scores`.
    pub fn of<'a>(scores: impl IntoIterator<Item = &'a PersonScore>) -> Self {
        let (mut people, mut keypoints, mut found, mut within_01, mut within_02, mut oks) = (0, 0, 0, 0, 0, 0.0);
        for score in scores {
            people += 1;
            oks += score.oks;
            for error in &score.errors {
                keypoints += 1;
                if let Some(e) = error {
                    found += 1;
                    within_01 += usize::from(*e <= 0.1);
                    within_02 += usize::from(*e <= 0.2);
                }
            }
        }
        let n = keypoints.max(1) as f32;
        Self {
            people,
            keypoints,
            found,
            pck_01: within_01 as f32 / n,
            pck_02: within_02 as f32 / n,
            mean_oks: oks / people.max(1) as f32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = r#"{"images": [{"id": 7, "file_name": "a.jpg", "width": 100, "height": 80}],
        "annotations": [
            {"id": 1, "image_id": 7, "bbox": [10, 20, 30, 40], "area": 900, "iscrowd": 0,
             "keypoints": [15, 25, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                           0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 35, 55, 1]},
            {"id": 2, "image_id": 7, "bbox": [0, 0, 5, 5], "iscrowd": 1, "keypoints": []},
            {"id": 3, "image_id": 7, "bbox": [0, 0, 5, 5], "keypoints": [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
             0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
             0, 0, 0, 0, 0, 0]}]}"#;

    #[test]
    fn a_coco_file_reads_in_the_pipelines_pixel_convention() {
        let coco = CocoKeypoints::from_json("a.json", FILE).unwrap();
        assert_eq!(coco.people.len(), 1, "crowds and people without labels are left out");
        let person = &coco.people[0];
        assert_eq!(person.labelled(), 2);
        assert_eq!(person.keypoints[0], Some(Vec2::new(14.5, 24.5)));
        assert_eq!(person.keypoints[16], Some(Vec2::new(34.5, 54.5)));
        assert_eq!(person.bbox, BoundingBox { min: Vec2::new(9.5, 19.5), max: Vec2::new(39.5, 59.5) });
        assert_eq!(coco.people_in(7).count(), 1);
    }

    #[test]
    fn bad_annotations_name_the_file_the_annotation_and_the_field() {
        let short = FILE.replacen("[15, 25, 2,", "[15, 25,", 1);
        let error = CocoKeypoints::from_json("a.json", &short).unwrap_err().to_string();
        assert!(error.starts_with("a.json: annotation 1: `keypoints` has 50 numbers"), "{error}");
        let orphan = FILE.replacen("\"image_id\": 7, \"bbox\": [10", "\"image_id\": 8, \"bbox\": [10", 1);
        let error = CocoKeypoints::from_json("a.json", &orphan).unwrap_err().to_string();
        assert!(error.contains("annotation 1: `image_id` is 8"), "{error}");
        let flat = FILE.replacen("[10, 20, 30, 40]", "[10, 20, 0, 40]", 1);
        assert!(CocoKeypoints::from_json("a.json", &flat).unwrap_err().to_string().contains("`bbox`"));
        let visibility = FILE.replacen("35, 55, 1", "35, 55, 3", 1);
        assert!(CocoKeypoints::from_json("a.json", &visibility).unwrap_err().to_string().contains("keypoint 16"));
        assert!(matches!(CocoKeypoints::from_json("a.json", "[]"), Err(PhotoError::Json { .. })));
    }

    #[test]
    fn exact_keypoints_score_one_and_dropped_ones_count_as_misses() {
        let coco = CocoKeypoints::from_json("a.json", FILE).unwrap();
        let person = &coco.people[0];
        let exact = person.keypoints.map(|k| k.map(|pixel| Keypoint2d { pixel, score: 0.9 }));
        let score = score_person(person, &exact);
        assert_eq!(score.errors, [Some(0.0), Some(0.0)]);
        assert!((score.oks - 1.0).abs() < 1e-6);
        let mut half = exact;
        half[16] = None;
        half[0] = Some(Keypoint2d { pixel: person.keypoints[0].unwrap() + Vec2::new(8.0, 0.0), score: 0.9 });
        let score = score_person(person, &half);
        let summary = PhotoSummary::of([&score]);
        assert_eq!((summary.keypoints, summary.found), (2, 1));
        assert_eq!(summary.pck_02, 0.5, "the nose is 8 px off over a 50 px diagonal (0.16), the ankle dropped");
        assert_eq!(summary.pck_01, 0.0);
        assert!(score.oks < 0.5);
    }

    #[test]
    fn the_region_is_the_grown_box_and_the_full_frame_the_whole_image() {
        let coco = CocoKeypoints::from_json("a.json", FILE).unwrap();
        let person = &coco.people[0];
        let full = PhotoCrop::FullFrame.window(person, 100, 80).unwrap();
        assert_eq!(full.side, 100.0);
        assert_eq!(full.min, Vec2::new(-0.5, -10.5));
        let region = PhotoCrop::Region.window(person, 100, 80).unwrap();
        // 40 px tall, grown by 6 px a side: 52 px, centred on the box.
        assert_eq!(region.side, 52.0);
        assert_eq!(region.min + Vec2::splat(26.0), person.bbox.center());
        let shifted = PhotoCrop::ShiftedRegion { offset: [0.1, 0.0] }.window(person, 100, 80).unwrap();
        assert!((shifted.min.x - region.min.x - 5.2).abs() < 1e-4);
    }
}
