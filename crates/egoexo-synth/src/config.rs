//! Simulation parameters, with defaults chosen to resemble Aria glasses recordings.
//!
//! Units: metres, seconds, radians, pixels at the camera's own resolution unless a field says
//! "at 1408 px" (then it scales with the image width).

use egoexo_core::ego_features::TrackingMode;
use serde::{Deserialize, Serialize};

/// Everything the simulator needs besides the motion and the seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SynthConfig {
    /// Wearer devices: glasses only (1-point) or glasses + wrists (3-point).
    pub tracking: TrackingMode,
    /// How the wrists of a 3-point wearer are tracked: wrist devices on every frame, or the
    /// glasses' own hand tracking while the hands are in view.
    #[serde(default)]
    pub wrists: WristTracking,
    /// Number of observers (1 or more).
    pub observers: usize,
    pub wearer_noise: DeviceNoise,
    pub observer_noise: DeviceNoise,
    pub observer: ObserverBehaviour,
    pub camera: CameraChoice,
    pub detector: DetectorModel,
    pub occlusion: OcclusionConfig,
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            tracking: TrackingMode::ThreePoint,
            wrists: WristTracking::Devices,
            observers: 1,
            wearer_noise: DeviceNoise::default(),
            observer_noise: DeviceNoise::default(),
            observer: ObserverBehaviour::default(),
            camera: CameraChoice::default(),
            detector: DetectorModel::default(),
            occlusion: OcclusionConfig::default(),
        }
    }
}

/// How a 3-point wearer's wrists are tracked.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WristTracking {
    /// Wrist devices (wristbands, controllers): a pose on every frame, with device noise.
    #[default]
    Devices,
    /// The glasses' hand tracking (Aria MPS): a wrist only while it is inside the head
    /// cameras' view, with detection noise, short dropouts and a confidence.
    HandTracking(HandTrackingModel),
}

/// Aria-like hand tracking from the glasses' own cameras. Angles in radians, lengths in
/// metres, times in seconds; directions in the glasses' CPF frame (+X left, +Y up,
/// +Z forward).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HandTrackingModel {
    /// The cameras' joint viewing axis: forward, pitched down by this much (Aria's SLAM
    /// cameras look forward-down, where hands work).
    pub view_axis_pitch_down_rad: f32,
    /// Half-angle of the cone about that axis inside which a wrist can be seen.
    pub view_half_angle_rad: f32,
    /// Wrists nearer or farther than this from the glasses are not tracked.
    pub distance_m: (f32, f32),
    /// Confidence of a seen wrist: 1 on the axis, falling to 0 at the cone's edge as
    /// `1 − (angle / half-angle)^4`, with normal noise of this standard deviation.
    pub confidence_noise: f32,
    /// Samples below this confidence are not reported (MPS writes −1 for them).
    pub min_confidence: f32,
    /// Mean time between spontaneous dropouts while a wrist is in view, and their length
    /// (uniform range).
    pub dropout_interval_s: f32,
    pub dropout_duration_s: (f32, f32),
    /// White detection noise of a reported wrist: position (standard deviation, m) and
    /// orientation (rad), on top of the glasses' own tracking error.
    pub position_noise_m: f32,
    pub orientation_noise_rad: f32,
}

impl Default for HandTrackingModel {
    fn default() -> Self {
        Self {
            view_axis_pitch_down_rad: 35f32.to_radians(),
            view_half_angle_rad: 50f32.to_radians(),
            distance_m: (0.12, 0.95),
            confidence_noise: 0.05,
            min_confidence: 0.15,
            dropout_interval_s: 4.0,
            dropout_duration_s: (0.1, 0.5),
            position_noise_m: 0.01,
            orientation_noise_rad: 5f32.to_radians(),
        }
    }
}

/// Tracking error of a SLAM'd device (Aria MPS closed-loop quality).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeviceNoise {
    /// White position jitter per sample, standard deviation (m). Millimetre level.
    pub position_jitter_m: f32,
    /// White orientation jitter per sample, standard deviation (rad). Sub-degree.
    pub orientation_jitter_rad: f32,
    /// Position drift: random-walk standard deviation growth per √second (m/√s).
    pub position_drift_m_per_sqrt_s: f32,
    /// Heading (yaw) drift: random-walk standard deviation growth per √second (rad/√s).
    pub yaw_drift_rad_per_sqrt_s: f32,
}

impl Default for DeviceNoise {
    fn default() -> Self {
        Self {
            position_jitter_m: 0.002,
            orientation_jitter_rad: 0.3f32.to_radians(),
            position_drift_m_per_sqrt_s: 0.002,
            yaw_drift_rad_per_sqrt_s: 0.05f32.to_radians(),
        }
    }
}

impl DeviceNoise {
    /// No noise at all (for tests and clean references).
    pub fn none() -> Self {
        Self {
            position_jitter_m: 0.0,
            orientation_jitter_rad: 0.0,
            position_drift_m_per_sqrt_s: 0.0,
            yaw_drift_rad_per_sqrt_s: 0.0,
        }
    }
}

/// How observers stand, walk and look.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObserverBehaviour {
    /// Initial distance to the wearer is uniform in `[min_distance_m, max_distance_m]`.
    pub min_distance_m: f32,
    pub max_distance_m: f32,
    /// Probability that an observer walks (follows the wearer at a varying distance) rather
    /// than standing in place.
    pub walking_probability: f32,
    /// Observer eye height above the floor, uniform range (m).
    pub eye_height_m: (f32, f32),
    /// Smooth-pursuit lag of the head following the wearer (s).
    pub tracking_lag_s: f32,
    /// Mean time between gaze saccades (s).
    pub saccade_interval_s: f32,
    /// Saccade amplitude, uniform range (rad).
    pub saccade_amplitude_rad: (f32, f32),
    /// Mean time between look-aways (s) during which the wearer leaves the image.
    pub look_away_interval_s: f32,
    /// Look-away span, uniform range (s).
    pub look_away_duration_s: (f32, f32),
    /// Static cameras (a webcam, a GoPro on a tripod) instead of people: each stands where an
    /// observer would start, at eye height, aimed at the middle of the wearer's whole path, and
    /// never moves (no walking, sway, saccades or look-aways).
    #[serde(default)]
    pub static_camera: bool,
}

impl Default for ObserverBehaviour {
    fn default() -> Self {
        Self {
            min_distance_m: 1.5,
            max_distance_m: 8.0,
            walking_probability: 0.5,
            eye_height_m: (1.5, 1.8),
            tracking_lag_s: 0.2,
            saccade_interval_s: 1.5,
            saccade_amplitude_rad: (3f32.to_radians(), 12f32.to_radians()),
            look_away_interval_s: 12.0,
            look_away_duration_s: (0.5, 5.0),
            static_camera: false,
        }
    }
}

/// Which observer camera to simulate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraChoice {
    /// Probability of Aria's Fisheye624 RGB camera (else an ideal pinhole of similar field of
    /// view).
    pub fisheye_probability: f32,
    /// Image sizes (square) to draw from: Aria RGB streams at 1408² or full-resolution 2880².
    pub image_sizes: Vec<u32>,
}

impl Default for CameraChoice {
    fn default() -> Self {
        Self { fisheye_probability: 0.8, image_sizes: vec![1408, 2880] }
    }
}

/// The 2D keypoint detector's behaviour.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectorModel {
    /// Pixel noise standard deviation at 1408 px: `base + per_metre · distance`.
    pub pixel_noise_base_px: f32,
    pub pixel_noise_per_metre_px: f32,
    /// Score of a clearly visible keypoint: normal(mean, sd), clipped to [0, 1].
    pub visible_score_mean: f32,
    pub visible_score_sd: f32,
    /// Probability that a visible keypoint is missed.
    pub keypoint_miss_probability: f32,
    /// Probability that the detector misses the wearer entirely in a frame.
    pub frame_miss_probability: f32,
    /// Fewer keypoints than this inside the image: no detection at all.
    pub min_keypoints_in_view: usize,
    /// Probability that an occlusion episode of a keypoint (its consecutive occluded frames) is
    /// reported at a plausible but wrong place with a high score throughout (the failure the
    /// learned gate must catch); otherwise it gets a low score throughout.
    pub occluded_confident_probability: f32,
    /// High score range for confidently wrong occluded keypoints.
    pub occluded_confident_score: (f32, f32),
    /// Low score range for the other occluded keypoints.
    pub occluded_low_score: (f32, f32),
    /// The 3D displacement (m) of a confidently wrong keypoint from the true joint, uniform;
    /// drawn once per occlusion episode.
    pub occluded_displacement_m: (f32, f32),
}

impl Default for DetectorModel {
    fn default() -> Self {
        Self {
            pixel_noise_base_px: 1.5,
            pixel_noise_per_metre_px: 0.6,
            visible_score_mean: 0.85,
            visible_score_sd: 0.07,
            keypoint_miss_probability: 0.03,
            frame_miss_probability: 0.03,
            min_keypoints_in_view: 3,
            occluded_confident_probability: 0.6,
            occluded_confident_score: (0.6, 0.95),
            occluded_low_score: (0.05, 0.35),
            occluded_displacement_m: (0.15, 0.5),
        }
    }
}

/// Things between observers and the wearer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OcclusionConfig {
    /// Probability, per observer, of furniture standing between them and the wearer's start.
    pub furniture_probability: f32,
    /// Furniture boxes: height, width and depth ranges (m).
    pub furniture_height_m: (f32, f32),
    pub furniture_width_m: (f32, f32),
    pub furniture_depth_m: (f32, f32),
    /// Number of bystanders walking through the scene, uniform in `[0, max_bystanders]`.
    pub max_bystanders: usize,
    /// Bystander body radius (m) and height range (m).
    pub bystander_radius_m: f32,
    pub bystander_height_m: (f32, f32),
}

impl Default for OcclusionConfig {
    fn default() -> Self {
        Self {
            furniture_probability: 0.5,
            furniture_height_m: (0.45, 1.1),
            furniture_width_m: (0.6, 2.0),
            furniture_depth_m: (0.4, 1.0),
            max_bystanders: 2,
            bystander_radius_m: 0.22,
            bystander_height_m: (1.55, 1.9),
        }
    }
}
