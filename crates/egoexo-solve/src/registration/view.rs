//! What an observer's camera saw, prepared for the solvers: per frame the camera's pose in
//! the observer's own world and, per person in the image, the detected keypoints as bearings
//! (unit rays in the camera's optical frame) with the detector's angular noise.

use egoexo_core::camera::{CameraCalibration, Projection};
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::Vec2;
use egoexo_core::rigid::RigidTransform;

use super::RegistrationError;
use crate::geometry::{M3, V3, isometry};

/// One frame of an observer camera.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewFrame {
    /// Seconds on the observer's clock.
    pub time_s: f64,
    /// The camera's optical frame in the observer's own world, `T_ownworld_camera`. A static
    /// camera that knows no pose uses the identity: its own world is its optical frame.
    pub t_world_camera: RigidTransform,
    /// Every person the detector found in the image (COCO-17 pixels and scores); a view
    /// assigned to one person has at most one.
    pub people: Vec<[Option<Keypoint2d>; COCO17_COUNT]>,
}

/// An observer camera's frames.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewTrack {
    pub camera: CameraCalibration,
    /// The camera's focal length is a guess to estimate (a pinhole camera only): the
    /// registration solves for it.
    pub estimate_focal: bool,
    pub frames: Vec<ViewFrame>,
}

/// One keypoint prepared.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Observation {
    /// COCO-17 index.
    pub k: usize,
    /// Unit ray in the camera frame (at the calibration's focal length).
    pub bearing: V3,
    /// Rows `e₁, e₂, b`: a rotation taking the bearing to +Z (the residual's tangent plane).
    pub basis: M3,
    /// Pixel minus principal point, divided by the focal lengths (pinhole), for the
    /// focal-length residual.
    pub normalised: [f64; 2],
}

/// One person in one frame.
#[derive(Clone, Debug)]
pub(crate) struct PersonView {
    pub observations: Vec<Observation>,
}

/// One frame prepared.
#[derive(Clone, Debug)]
pub(crate) struct FrameView {
    pub time_s: f64,
    /// `R_ownworld_camera` and the camera centre.
    pub rotation: M3,
    pub centre: V3,
    pub people: Vec<PersonView>,
    /// The one-second block of the view it falls in (residuals of a block err together).
    pub cluster: usize,
}

/// A view prepared for the solvers.
#[derive(Clone, Debug)]
pub(crate) struct PreparedView {
    pub frames: Vec<FrameView>,
    pub clusters: usize,
    /// The detector's noise as an angle, radians.
    pub sigma_detector_rad: f64,
    /// `Some` when the focal length is estimated: the pinhole's `(fx, fy)`.
    pub focal_estimated: Option<(f64, f64)>,
    /// Typical seconds between frames (median).
    pub frame_interval_s: f64,
    /// The image's width, pixels.
    pub image_width: f64,
}

/// Fewer keypoints than this in a person: no use.
pub(crate) const MIN_KEYPOINTS: usize = 3;

/// The bearing basis: rows `e₁, e₂, b`.
pub(crate) fn tangent_basis(b: &V3) -> M3 {
    let helper = if b.x.abs() < 0.9 { V3::x() } else { V3::y() };
    let e1 = b.cross(&helper).normalize();
    let e2 = b.cross(&e1);
    M3::from_rows(&[e1.transpose(), e2.transpose(), b.transpose()])
}

impl PreparedView {
    /// Keeps keypoints scored at least `min_score`, persons with at least [`MIN_KEYPOINTS`]
    /// of them, frames with at least one such person; at most `max_frames` frames, evenly
    /// spread over the view. The detector's noise is `pixel_noise_px` at 1408 px of width.
    pub fn new(
        view: &ViewTrack,
        min_score: f32,
        pixel_noise_px: f64,
        max_frames: usize,
    ) -> Result<Self, RegistrationError> {
        let camera = &view.camera;
        let (focal, focal_estimated) = match camera.projection {
            Projection::Pinhole(k) => {
                (f64::from(k.fx.max(k.fy)), view.estimate_focal.then_some((f64::from(k.fx), f64::from(k.fy))))
            }
            Projection::Fisheye624(f) => {
                if view.estimate_focal {
                    return Err(RegistrationError::FocalOfFisheye);
                }
                (f64::from(f.focal()), None)
            }
        };
        if let Some(i) = view.frames.iter().position(|f| !f.time_s.is_finite() || !f.t_world_camera.is_finite()) {
            return Err(RegistrationError::NotFinite { what: "view frame", index: i });
        }
        if let Some(i) = view.frames.windows(2).position(|w| w[1].time_s <= w[0].time_s) {
            return Err(RegistrationError::TimesNotIncreasing { what: "view", index: i + 1 });
        }
        let principal = camera.projection.principal_point();
        // Frames with anyone in them, at most `max_frames` of them evenly spread (before the
        // per-keypoint work, so that an hour of views costs what `max_frames` do).
        let seen: Vec<usize> = (0..view.frames.len())
            .filter(|&i| view.frames[i].people.iter().any(|p| p.iter().any(Option::is_some)))
            .collect();
        let limit = max_frames.max(1);
        let picked: Vec<usize> =
            if seen.len() > limit { (0..limit).map(|i| seen[i * seen.len() / limit]).collect() } else { seen.clone() };
        let all_times: Vec<f64> = seen.iter().map(|&i| view.frames[i].time_s).collect();
        let mut frames = Vec::with_capacity(picked.len());
        for i in picked {
            let frame = &view.frames[i];
            let people: Vec<PersonView> = frame
                .people
                .iter()
                .filter_map(|person| {
                    let observations: Vec<Observation> = person
                        .iter()
                        .enumerate()
                        .filter_map(|(k, kp)| {
                            let kp = kp.as_ref().filter(|kp| kp.score >= min_score && kp.pixel.is_finite())?;
                            let ray = camera.unproject(kp.pixel)?;
                            let bearing = V3::new(f64::from(ray.x), f64::from(ray.y), f64::from(ray.z)).normalize();
                            let offset: Vec2 = kp.pixel - principal;
                            let normalised = match camera.projection {
                                Projection::Pinhole(p) => {
                                    [f64::from(offset.x) / f64::from(p.fx), f64::from(offset.y) / f64::from(p.fy)]
                                }
                                Projection::Fisheye624(_) => [0.0, 0.0],
                            };
                            Some(Observation { k, bearing, basis: tangent_basis(&bearing), normalised })
                        })
                        .collect();
                    (observations.len() >= MIN_KEYPOINTS).then_some(PersonView { observations })
                })
                .collect();
            if people.is_empty() {
                continue;
            }
            let pose = isometry(&frame.t_world_camera);
            frames.push(FrameView {
                time_s: frame.time_s,
                rotation: pose.rotation.to_rotation_matrix().into_inner(),
                centre: pose.translation.vector,
                people,
                cluster: 0,
            });
        }
        let start = frames.first().map_or(0.0, |f| f.time_s);
        let mut clusters = 0;
        for f in &mut frames {
            f.cluster = ((f.time_s - start).max(0.0)) as usize;
            clusters = clusters.max(f.cluster + 1);
        }
        let mut gaps: Vec<f64> = all_times.windows(2).map(|w| w[1] - w[0]).collect();
        gaps.sort_by(f64::total_cmp);
        let frame_interval_s = gaps.get(gaps.len() / 2).copied().unwrap_or(1.0 / 30.0);
        let pixel_noise = pixel_noise_px * f64::from(camera.width) / 1408.0;
        Ok(Self {
            frames,
            clusters,
            sigma_detector_rad: pixel_noise / focal.max(1.0),
            focal_estimated,
            frame_interval_s,
            image_width: f64::from(camera.width),
        })
    }

    /// Seconds of view the frames cover: each frame counts up to the typical interval
    /// (several frames at one instant do not add up).
    pub fn seconds(&self, frames: impl Iterator<Item = usize>) -> f64 {
        let mut times: Vec<f64> = frames.map(|f| self.frames[f].time_s).collect();
        times.sort_by(f64::total_cmp);
        let step = self.frame_interval_s.clamp(1e-3, 0.5);
        times.windows(2).map(|w| (w[1] - w[0]).min(step)).sum::<f64>() + if times.is_empty() { 0.0 } else { step }
    }

    /// The bearing of an observation at focal scale `exp(log_focal)` (an estimated focal),
    /// else its calibrated bearing.
    pub fn bearing(&self, o: &Observation, log_focal: f64) -> V3 {
        if self.focal_estimated.is_some() {
            let s = (-log_focal).exp();
            V3::new(o.normalised[0] * s, o.normalised[1] * s, 1.0).normalize()
        } else {
            o.bearing
        }
    }
}
