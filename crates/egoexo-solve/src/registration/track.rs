//! The body being looked at, over time: COCO-17 points in the target's world with their
//! uncertainty ([`TargetTrack`]), built from a wearer's head device (the five face points it
//! fixes exactly) and, where available, a coarse body pose (the twelve body points).
//!
//! Times are seconds on the target's clock; positions metres in its Y-up world.

use egoexo_core::exo_keypoints::{COCO17_COUNT, ExoKeypoint, face_points_from_device};
use egoexo_core::glam::Vec3;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::NUM_JOINTS;
use serde::{Deserialize, Serialize};

use super::RegistrationError;
use crate::geometry::{V3, v3};

/// One point of the body at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TargetPoint {
    /// Metres, target world.
    pub position: V3,
    /// 1σ of where the point truly is (metres): the model's own uncertainty, not the
    /// detector's.
    pub sigma_m: f64,
}

/// A target point interpolated at some time, with its velocity (m/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointAt {
    pub position: V3,
    pub velocity: V3,
    pub sigma_m: f64,
}

/// COCO-17 points of one body over time.
#[derive(Clone, Debug, PartialEq)]
pub struct TargetTrack {
    times_s: Vec<f64>,
    points: Vec<[Option<TargetPoint>; COCO17_COUNT]>,
    /// Samples further apart than this are not interpolated across (a gap in tracking).
    max_gap_s: f64,
}

/// How well each part of a wearer's body is known from the devices (1σ, metres).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointSigmas {
    /// Nose, eyes and ears, from the head device: the face against the glasses.
    pub face_m: f64,
    /// Shoulders and hips from a coarse body pose.
    pub torso_m: f64,
    /// Elbows and knees.
    pub middle_m: f64,
    /// Wrists and ankles.
    pub extremity_m: f64,
}

impl Default for PointSigmas {
    fn default() -> Self {
        Self { face_m: 0.025, torso_m: 0.16, middle_m: 0.24, extremity_m: 0.32 }
    }
}

/// One time sample of a wearer: the head device's pose, where tracked, and the coarse body's
/// 24 SMPL joint positions, where estimated (both in the wearer's world).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WearerSample {
    pub time_s: f64,
    pub t_world_device: Option<RigidTransform>,
    pub joints: Option<[Vec3; NUM_JOINTS]>,
}

/// The fixed facts of a wearer's body the points need.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WearerBody {
    /// SMPL head joint in the head-device (CPF) frame, metres.
    pub head_joint_in_device: Vec3,
    /// The skeleton's size against the mean shape (1 for the mean shape).
    pub scale: f32,
    pub sigmas: PointSigmas,
}

impl TargetTrack {
    /// Gap beyond which samples are not interpolated across.
    pub const DEFAULT_MAX_GAP_S: f64 = 0.25;

    /// A track from strictly increasing, finite `times_s` and one set of points each.
    pub fn new(times_s: Vec<f64>, points: Vec<[Option<TargetPoint>; COCO17_COUNT]>) -> Result<Self, RegistrationError> {
        if times_s.len() != points.len() {
            return Err(RegistrationError::Lengths { what: "target track", times: times_s.len(), items: points.len() });
        }
        if let Some(i) = times_s.iter().position(|t| !t.is_finite()) {
            return Err(RegistrationError::NotFinite { what: "target track time", index: i });
        }
        if let Some(i) = times_s.windows(2).position(|w| w[1] <= w[0]) {
            return Err(RegistrationError::TimesNotIncreasing { what: "target track", index: i + 1 });
        }
        for (i, frame) in points.iter().enumerate() {
            if frame
                .iter()
                .flatten()
                .any(|p| !p.position.iter().all(|v| v.is_finite()) || p.sigma_m.is_nan() || p.sigma_m <= 0.0)
            {
                return Err(RegistrationError::NotFinite { what: "target point", index: i });
            }
        }
        Ok(Self { times_s, points, max_gap_s: Self::DEFAULT_MAX_GAP_S })
    }

    /// A wearer's track: the face points from the head device (exact up to the face) and the
    /// body points from the coarse joints where a sample has them.
    pub fn from_wearer(samples: &[WearerSample], body: &WearerBody) -> Result<Self, RegistrationError> {
        let sigma = &body.sigmas;
        let mut times = Vec::with_capacity(samples.len());
        let mut points = Vec::with_capacity(samples.len());
        for s in samples {
            let mut frame = [None; COCO17_COUNT];
            if let Some(device) = &s.t_world_device {
                for (k, p) in face_points_from_device(device, body.head_joint_in_device, body.scale).iter().enumerate()
                {
                    frame[k] = Some(TargetPoint { position: v3(*p), sigma_m: sigma.face_m });
                }
            }
            if let Some(joints) = &s.joints {
                for k in ExoKeypoint::ALL.into_iter().skip(1) {
                    let sigma_m = match k {
                        ExoKeypoint::LeftShoulder
                        | ExoKeypoint::RightShoulder
                        | ExoKeypoint::LeftHip
                        | ExoKeypoint::RightHip => sigma.torso_m,
                        ExoKeypoint::LeftElbow
                        | ExoKeypoint::RightElbow
                        | ExoKeypoint::LeftKnee
                        | ExoKeypoint::RightKnee => sigma.middle_m,
                        _ => sigma.extremity_m,
                    };
                    frame[k.coco17_index()] =
                        Some(TargetPoint { position: v3(joints[k.smpl_joint().index()]), sigma_m });
                }
            }
            if frame.iter().any(Option::is_some) {
                times.push(s.time_s);
                points.push(frame);
            }
        }
        Self::new(times, points)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.times_s.len()
    }

    /// No samples.
    pub fn is_empty(&self) -> bool {
        self.times_s.is_empty()
    }

    /// `(first, last)` time.
    pub fn span(&self) -> Option<(f64, f64)> {
        Some((*self.times_s.first()?, *self.times_s.last()?))
    }

    /// The points at time `t` (target clock), linearly interpolated between the samples
    /// around it; `None` outside the track or across a gap.
    pub fn sample(&self, t: f64) -> Option<[Option<PointAt>; COCO17_COUNT]> {
        let n = self.times_s.len();
        if n == 0 || !t.is_finite() {
            return None;
        }
        let i = self.times_s.partition_point(|&x| x <= t);
        if i == 0 {
            return None;
        }
        let i0 = i - 1;
        if i0 == n - 1 {
            // Exactly on the last sample (or past it).
            return (t - self.times_s[i0] <= 1e-9).then(|| {
                self.points[i0]
                    .map(|p| p.map(|p| PointAt { position: p.position, velocity: V3::zeros(), sigma_m: p.sigma_m }))
            });
        }
        let (t0, t1) = (self.times_s[i0], self.times_s[i0 + 1]);
        if t1 - t0 > self.max_gap_s {
            return None;
        }
        let a = (t - t0) / (t1 - t0);
        let mut out = [None; COCO17_COUNT];
        for k in 0..COCO17_COUNT {
            if let (Some(p0), Some(p1)) = (self.points[i0][k], self.points[i0 + 1][k]) {
                out[k] = Some(PointAt {
                    position: p0.position + (p1.position - p0.position) * a,
                    velocity: (p1.position - p0.position) / (t1 - t0),
                    sigma_m: p0.sigma_m.max(p1.sigma_m),
                });
            }
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    fn point(x: f64) -> Option<TargetPoint> {
        Some(TargetPoint { position: V3::new(x, 1.0, 0.0), sigma_m: 0.02 })
    }

    #[test]
    fn interpolates_between_samples_but_not_across_gaps() {
        let track = TargetTrack::new(
            vec![0.0, 0.1, 1.0],
            vec![[point(0.0); COCO17_COUNT], [point(1.0); COCO17_COUNT], [point(2.0); COCO17_COUNT]],
        )
        .unwrap();
        let p = track.sample(0.025).unwrap()[3].unwrap();
        assert!((p.position.x - 0.25).abs() < 1e-12 && (p.velocity.x - 10.0).abs() < 1e-9);
        assert!(track.sample(0.5).is_none(), "0.1 → 1.0 s is a gap");
        assert!(track.sample(-0.1).is_none() && track.sample(1.1).is_none());
        assert!(track.sample(1.0).is_some());
    }

    #[test]
    fn refuses_tracks_that_go_back_in_time() {
        let err = TargetTrack::new(vec![0.0, 0.0], vec![[None; COCO17_COUNT]; 2]).unwrap_err();
        assert!(err.to_string().contains("index 1"), "{err}");
    }

    #[test]
    fn a_wearer_brings_face_points_from_the_device_and_body_points_from_the_joints() {
        let body = WearerBody {
            head_joint_in_device: egoexo_core::skeleton::DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE,
            scale: 1.0,
            sigmas: PointSigmas::default(),
        };
        let head_only = WearerSample { time_s: 0.0, t_world_device: Some(RigidTransform::IDENTITY), joints: None };
        let both = WearerSample { time_s: 0.1, joints: Some([Vec3::ONE; NUM_JOINTS]), ..head_only };
        let track = TargetTrack::from_wearer(&[head_only, both], &body).unwrap();
        let first = track.sample(0.0).unwrap();
        assert!(first[..5].iter().all(Option::is_some) && first[5..].iter().all(Option::is_none));
        assert!(track.points[1].iter().all(Option::is_some));
        // The eyes sit near the glasses' origin (CPF: the pupils' centre).
        let eyes = (track.points[0][1].unwrap().position + track.points[0][2].unwrap().position) * 0.5;
        assert!(eyes.norm() < 0.05, "{eyes}");
    }
}
