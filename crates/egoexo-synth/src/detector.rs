//! A 2D keypoint detector's behaviour on an observer image: COCO-17 keypoints at the true
//! projections plus pixel noise that grows with distance, detector scores, truncation at the
//! image border, missed keypoints and frames, and occlusion — an occluded keypoint is either
//! reported at a plausible but wrong place with a *high* score (the failure the learned gate
//! must catch) or with a low score. Which of the two, and where the wrong place is, holds for
//! the whole occlusion episode ([`DetectorState`]): the same occluder fools a detector the
//! same way on consecutive frames, so its mistakes do not average out over time.
//!
//! Pixels in the observer's RGB image (centre of the top-left pixel at 0, 0); world Y-up, metres.

use egoexo_core::camera::CameraCalibration;
use egoexo_core::exo_keypoints::{COCO17_COUNT, ExoKeypoint, Keypoint2d};
use egoexo_core::glam::{Vec2, Vec3};
use egoexo_core::rigid::RigidTransform;

use crate::config::DetectorModel;
use crate::rng::SimRng;
use crate::scene::Scene;

/// COCO index → exo keypoint index (the four face points have none).
fn exo_index_of_coco(coco: usize) -> Option<usize> {
    ExoKeypoint::ALL.iter().find(|k| k.coco17_index() == coco).map(|k| k.index())
}

/// How the detector reports one keypoint for as long as it stays occluded.
#[derive(Clone, Copy, Debug, PartialEq)]
enum OcclusionEpisode {
    /// At the true joint displaced by this much (world axes, metres), with a high score.
    ConfidentlyWrong { displacement: Vec3 },
    /// Near the true joint with wide noise and a low score.
    LowScore,
}

/// The detector's memory across one observer's consecutive frames: the ongoing occlusion
/// episode of each COCO keypoint. Start each observer with `DetectorState::default()`.
#[derive(Clone, Debug, Default)]
pub struct DetectorState {
    episodes: [Option<OcclusionEpisode>; COCO17_COUNT],
}

/// One observer frame's detection result.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameDetection {
    pub keypoints: [Option<Keypoint2d>; COCO17_COUNT],
    /// Bit `k`: exo keypoint `k` was occluded by the scene (not self-occlusion).
    pub occluded: u16,
    /// Bit `k`: exo keypoint `k` was occluded and reported confidently at a wrong place.
    pub confidently_wrong: u16,
    /// Number of the 17 keypoints whose true projection lies in the image's valid region.
    pub in_view: usize,
    /// The detector missed the whole frame.
    pub frame_missed: bool,
}

/// Simulates the detector on one frame seen by a camera on a device truly at
/// `t_world_device`, at time `t` (seconds), for the wearer's 17 COCO points; `state` carries
/// the occlusion episodes from this observer's previous frame to the next.
#[allow(clippy::too_many_arguments)]
pub fn detect(
    points: &[Vec3; COCO17_COUNT],
    camera: &CameraCalibration,
    t_world_device: &RigidTransform,
    scene: &Scene,
    t: f32,
    model: &DetectorModel,
    state: &mut DetectorState,
    rng: &mut SimRng,
) -> FrameDetection {
    let t_world_camera = camera.t_world_camera(t_world_device);
    let eye = t_world_camera.translation;
    let pixel_scale = camera.width as f32 / 1408.0;
    let projected: [Option<Vec2>; COCO17_COUNT] =
        points.map(|p| camera.project_world(p, t_world_device).filter(|px| camera.is_valid_pixel(*px)));
    let in_view = projected.iter().filter(|p| p.is_some()).count();
    let mut result = FrameDetection {
        keypoints: [None; COCO17_COUNT],
        occluded: 0,
        confidently_wrong: 0,
        in_view,
        frame_missed: false,
    };

    // Occlusion is a property of the scene, labelled even when the detector sees nothing.
    for k in ExoKeypoint::ALL {
        if projected[k.coco17_index()].is_some() && scene.blocks(t, eye, points[k.coco17_index()]) {
            result.occluded |= 1 << k.index();
        }
    }
    if in_view < model.min_keypoints_in_view {
        return result;
    }
    if rng.chance(model.frame_miss_probability) {
        result.frame_missed = true;
        return result;
    }

    let distance = points[0].distance(eye);
    let sigma = (model.pixel_noise_base_px + model.pixel_noise_per_metre_px * distance) * pixel_scale;
    for (coco, point) in points.iter().enumerate() {
        let Some(true_pixel) = projected[coco] else {
            state.episodes[coco] = None;
            continue; // truncated by the image border or outside the image circle
        };
        let exo = exo_index_of_coco(coco);
        let occluded = match exo {
            Some(k) => result.occluded & (1 << k) != 0,
            None => scene.blocks(t, eye, *point),
        };
        let episode = if occluded {
            Some(*state.episodes[coco].get_or_insert_with(|| {
                if rng.chance(model.occluded_confident_probability) {
                    // Hallucinated where a joint plausibly could be: the true joint displaced in 3D.
                    let magnitude = rng.uniform(model.occluded_displacement_m.0, model.occluded_displacement_m.1);
                    let direction = (rng.unit_vec3() + Vec3::new(0.0, -0.5, 0.0)).normalize_or(Vec3::NEG_Y);
                    OcclusionEpisode::ConfidentlyWrong { displacement: direction * magnitude }
                } else {
                    OcclusionEpisode::LowScore
                }
            }))
        } else {
            state.episodes[coco] = None;
            None
        };
        if rng.chance(model.keypoint_miss_probability) {
            continue;
        }
        let keypoint = match episode {
            None => {
                let score = rng.normal(model.visible_score_mean, model.visible_score_sd).clamp(0.0, 1.0);
                Keypoint2d { pixel: true_pixel + Vec2::new(rng.normal(0.0, sigma), rng.normal(0.0, sigma)), score }
            }
            Some(OcclusionEpisode::ConfidentlyWrong { displacement }) => {
                let Some(pixel) = camera.project_world(*point + displacement, t_world_device) else { continue };
                if let Some(k) = exo {
                    result.confidently_wrong |= 1 << k;
                }
                let score = rng.uniform(model.occluded_confident_score.0, model.occluded_confident_score.1);
                Keypoint2d { pixel: pixel + Vec2::new(rng.normal(0.0, sigma), rng.normal(0.0, sigma)), score }
            }
            Some(OcclusionEpisode::LowScore) => {
                let score = rng.uniform(model.occluded_low_score.0, model.occluded_low_score.1);
                let wide = 4.0 * sigma + 10.0 * pixel_scale;
                Keypoint2d { pixel: true_pixel + Vec2::new(rng.normal(0.0, wide), rng.normal(0.0, wide)), score }
            }
        };
        result.keypoints[coco] = Some(keypoint);
    }
    result
}
