//! Per-joint features of the learned visibility gate (paper § Learned Visibility Gating),
//! layout version [`GATE_FEATURE_LAYOUT_VERSION`].
//!
//! The paper's gate reads a DINOv3 CLS token of the observer's crop; no such backbone can ship
//! here, so the gate reads what the core can compute for each of the K = 13 exo keypoints of
//! one observer at one frame:
//!
//! | slot | feature | range |
//! |---|---|---|
//! | 0 | detector score (0 when not detected) | [0, 1] |
//! | 1 | agreement: distance between the detected keypoint and the same joint of EgoNet's coarse pose projected into the image, divided by the region box's diagonal; [`MAX_AGREEMENT`] when either is missing | [0, 2] |
//! | 2 | EgoNet's projected joint lies in the image's valid region | {0, 1} |
//! | 3 | the keypoint was detected and its ray is valid | {0, 1} |
//! | 4 | the region proposal found the wearer in this image | {0, 1} |
//! | 5 | jump: distance between the detected keypoint and the nearer of the same keypoint's detections at the previous and the next frame, divided by the region box's diagonal ([`detection_jumps`]); [`MAX_AGREEMENT`] when there is nothing to compare | [0, 2] |
//!
//! The jump is what a single frame cannot show: a true detection moves smoothly with the
//! body, while a keypoint hallucinated at a wrong place (an occluded joint reported with a
//! high score) jumps where the occlusion begins and ends, and wherever the detector's guess
//! wanders.
//!
//! A session that carries per-frame context features (e.g. a DINO CLS token) appends them
//! after these six; the models' manifest records whether a gate expects them.

use glam::Vec2;
use serde::{Deserialize, Serialize};

use crate::camera::CameraCalibration;
use crate::exo_keypoints::{EXO_KEYPOINT_COUNT, Keypoint2d};
use crate::region::RegionProposal;

/// Version of the layout documented above; recorded in the models' manifest. v2 added the
/// jump (slot 5).
pub const GATE_FEATURE_LAYOUT_VERSION: u32 = 2;
/// Numbers per keypoint (without context features).
pub const GATE_FEATURE_DIM: usize = 6;
/// Agreement value for "cannot compare" and the cap for large disagreements.
pub const MAX_AGREEMENT: f32 = 2.0;

/// The gate feature layout (serialised into the models' manifest).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GateFeatureLayout {
    pub version: u32,
    pub dim: usize,
    /// Length of the appended context feature vector (0 = none).
    pub context_dim: usize,
}

impl Default for GateFeatureLayout {
    fn default() -> Self {
        Self { version: GATE_FEATURE_LAYOUT_VERSION, dim: GATE_FEATURE_DIM, context_dim: 0 }
    }
}

/// Gate features of one observer at one frame.
///
/// `detected` are the keypoints (network order), `ray_valid` whether each unprojected to a
/// valid canonical ray, `predicted` the pixels of EgoNet's joints (same order; `None` behind
/// the camera or outside the model's field of view), `region` the proposal from EgoNet's pose,
/// `jumps` each keypoint's [`detection_jumps`] value at this frame.
pub fn gate_features(
    detected: &[Option<Keypoint2d>; EXO_KEYPOINT_COUNT],
    ray_valid: &[bool; EXO_KEYPOINT_COUNT],
    predicted: &[Option<Vec2>; EXO_KEYPOINT_COUNT],
    camera: &CameraCalibration,
    region: &RegionProposal,
    jumps: &[f32; EXO_KEYPOINT_COUNT],
) -> [[f32; GATE_FEATURE_DIM]; EXO_KEYPOINT_COUNT] {
    let diagonal = region.bbox().map(|b| b.diagonal()).filter(|d| *d > 1.0);
    std::array::from_fn(|k| {
        let score = detected[k].map_or(0.0, |kp| if kp.score.is_finite() { kp.score.clamp(0.0, 1.0) } else { 0.0 });
        let agreement = match (detected[k], predicted[k], diagonal) {
            (Some(kp), Some(px), Some(diag)) => (kp.pixel.distance(px) / diag).min(MAX_AGREEMENT),
            _ => MAX_AGREEMENT,
        };
        let agreement = if agreement.is_finite() { agreement } else { MAX_AGREEMENT };
        let predicted_in_image = predicted[k].is_some_and(|px| camera.is_valid_pixel(px));
        let present = detected[k].is_some() && ray_valid[k];
        [
            score,
            agreement,
            f32::from(u8::from(predicted_in_image)),
            f32::from(u8::from(present)),
            f32::from(u8::from(diagonal.is_some())),
            if jumps[k].is_finite() { jumps[k].clamp(0.0, MAX_AGREEMENT) } else { MAX_AGREEMENT },
        ]
    })
}

/// The jump feature along one keypoint's track of consecutive frames: at each frame, the
/// pixel distance from its detection to the nearer of its detections at the previous and the
/// next frame, divided by that frame's region box diagonal (pixels, > 1), capped at
/// [`MAX_AGREEMENT`]. [`MAX_AGREEMENT`] where the keypoint is not detected, neither neighbour
/// is, or there is no box. `pixels` and `diagonals` are per frame; the result has the length
/// of the shorter.
pub fn detection_jumps(pixels: &[Option<Vec2>], diagonals: &[Option<f32>]) -> Vec<f32> {
    let n = pixels.len().min(diagonals.len());
    (0..n)
        .map(|t| {
            let (Some(here), Some(diagonal)) = (pixels[t], diagonals[t].filter(|d| *d > 1.0)) else {
                return MAX_AGREEMENT;
            };
            let neighbours = [t.checked_sub(1), Some(t + 1).filter(|&s| s < n)];
            neighbours
                .into_iter()
                .flatten()
                .filter_map(|s| pixels[s])
                .map(|there| here.distance(there) / diagonal)
                .filter(|jump| jump.is_finite())
                .fold(MAX_AGREEMENT, f32::min)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    use crate::camera::{Pinhole, Projection};
    use crate::region::{BoundingBox, NotVisibleReason};
    use crate::rigid::RigidTransform;

    fn camera() -> CameraCalibration {
        CameraCalibration::new(
            Projection::Pinhole(Pinhole::new(500.0, 500.0, 319.5, 239.5).unwrap()),
            640,
            480,
            RigidTransform::IDENTITY,
        )
        .unwrap()
    }

    #[test]
    fn agreement_is_distance_over_box_diagonal() {
        let region = RegionProposal::Visible {
            bbox: BoundingBox { min: Vec2::new(100.0, 100.0), max: Vec2::new(160.0, 180.0) },
            joints_in_image: 13,
        };
        let mut detected = [None; EXO_KEYPOINT_COUNT];
        let mut predicted = [None; EXO_KEYPOINT_COUNT];
        detected[0] = Some(Keypoint2d { pixel: Vec2::new(130.0, 120.0), score: 0.9 });
        predicted[0] = Some(Vec2::new(130.0, 140.0)); // 20 px off; diagonal 100 px
        predicted[1] = Some(Vec2::new(-50.0, 10.0)); // off-image prediction, no detection
        let valid = [true; EXO_KEYPOINT_COUNT];
        let mut jumps = [MAX_AGREEMENT; EXO_KEYPOINT_COUNT];
        jumps[0] = 0.05;
        jumps[2] = f32::NAN;
        let f = gate_features(&detected, &valid, &predicted, &camera(), &region, &jumps);
        assert_eq!(f[0], [0.9, 0.2, 1.0, 1.0, 1.0, 0.05]);
        assert_eq!(f[1], [0.0, MAX_AGREEMENT, 0.0, 0.0, 1.0, MAX_AGREEMENT]);
        assert_eq!(f[2], [0.0, MAX_AGREEMENT, 0.0, 0.0, 1.0, MAX_AGREEMENT]);
    }

    #[test]
    fn no_region_means_no_agreement() {
        let region = RegionProposal::NotVisible(NotVisibleReason::OutOfFrame);
        let mut detected = [None; EXO_KEYPOINT_COUNT];
        detected[3] = Some(Keypoint2d { pixel: Vec2::new(10.0, 10.0), score: f32::NAN });
        let f = gate_features(
            &detected,
            &[false; EXO_KEYPOINT_COUNT],
            &[Some(Vec2::new(10.0, 10.0)); EXO_KEYPOINT_COUNT],
            &camera(),
            &region,
            &[0.0; EXO_KEYPOINT_COUNT],
        );
        assert_eq!(f[3], [0.0, MAX_AGREEMENT, 1.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn jumps_compare_each_detection_with_the_nearer_neighbour() {
        // A track moving 2 px per frame with a hallucination at frame 3, a gap at frame 6 and
        // no box at frame 8; box diagonal 100 px.
        let mut pixels: Vec<Option<Vec2>> = (0..10).map(|t| Some(Vec2::new(100.0 + 2.0 * t as f32, 50.0))).collect();
        pixels[3] = Some(Vec2::new(160.0, 90.0));
        pixels[6] = None;
        let mut diagonals = vec![Some(100.0); 10];
        diagonals[8] = None;
        let jumps = detection_jumps(&pixels, &diagonals);
        assert_eq!(jumps.len(), 10);
        for t in [0, 1, 4, 5, 7, 9] {
            assert!((jumps[t] - 0.02).abs() < 1e-6, "frame {t}: {}", jumps[t]);
        }
        assert!(jumps[3] > 0.5, "the hallucination stands out: {}", jumps[3]);
        assert!((jumps[2] - 0.02).abs() < 1e-6 && (jumps[4] - 0.02).abs() < 1e-6, "its neighbours do not");
        assert_eq!((jumps[6], jumps[8]), (MAX_AGREEMENT, MAX_AGREEMENT));
        // A lone detection has nothing to compare with; far jumps are capped.
        let lone = detection_jumps(&[None, Some(Vec2::ZERO), None], &[Some(50.0); 3]);
        assert_eq!(lone, vec![MAX_AGREEMENT; 3]);
        let far = detection_jumps(&[Some(Vec2::ZERO), Some(Vec2::new(1e4, 0.0))], &[Some(50.0); 2]);
        assert_eq!(far, vec![MAX_AGREEMENT; 2]);
    }
}
