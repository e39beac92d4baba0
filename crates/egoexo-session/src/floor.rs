//! The floor's height in the session world (Y up, metres): from MPS semidense points when a
//! recording has them, else from how high the wearer's glasses are when standing.
//!
//! **From points.** Heights of the well-constrained points ([`crate::aria::semidense`]) are
//! binned at 1 cm. The floor is searched between [`MIN_EYE_HEIGHT_M`] and
//! [`MAX_EYE_HEIGHT_M`] below the standing head height (the 95th percentile of the head
//! trajectory's heights: people stand for most of a recording): the lowest 3 cm band holding
//! at least [`MIN_FLOOR_POINTS`] points and at least a third of the fullest band's, refined to
//! the mean of its points. Lowest, not fullest, because a table top can hold more points than
//! the floor it stands on, and nothing the wearer stands on is below the floor.
//!
//! **From the standing head.** The glasses (CPF) stand `head_height + foot + eye` above the
//! soles, with the skeleton's head joint height ([`SmplSkeleton::head_height`], from the
//! subject's stature or the mean shape), the ankle/foot joints' height above the soles (3 cm
//! at the mean shape, as the simulator places them) and the head joint → glasses offset.

use egoexo_core::skeleton::SmplSkeleton;

use crate::model::{Session, Trajectory};

/// Histogram bin, metres.
pub const BIN_M: f64 = 0.01;
/// Histogram range, metres either side of the world origin (bigger than any building).
pub const RANGE_M: f64 = 200.0;
/// Fewest points in the floor's band.
pub const MIN_FLOOR_POINTS: u64 = 50;
/// Lowest standing glasses height above the floor searched, metres.
pub const MIN_EYE_HEIGHT_M: f32 = 0.9;
/// Highest standing glasses height above the floor searched, metres.
pub const MAX_EYE_HEIGHT_M: f32 = 2.3;
pub use egoexo_core::foot_contact::{FOOT_JOINT_ABOVE_SOLE_M, FOOT_JOINTS};
/// Percentile of the head's heights taken as its standing height.
pub const STANDING_PERCENTILE: f32 = 0.95;

pub use crate::model::{Floor, FloorSource};

/// Heights binned at [`BIN_M`] over ±[`RANGE_M`]: fixed memory however many points.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightHistogram {
    bins: Vec<u64>,
    /// Per bin, the sum of heights (for the refined mean).
    sums: Vec<f64>,
    outside: u64,
}

impl Default for HeightHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl HeightHistogram {
    pub fn new() -> Self {
        let n = (2.0 * RANGE_M / BIN_M) as usize;
        Self { bins: vec![0; n], sums: vec![0.0; n], outside: 0 }
    }

    fn bin(y: f64) -> Option<usize> {
        let i = ((y + RANGE_M) / BIN_M).floor();
        (0.0..2.0 * RANGE_M / BIN_M).contains(&i).then_some(i as usize)
    }

    /// Adds one height, metres.
    pub fn add(&mut self, y: f64) {
        match Self::bin(y) {
            Some(i) => {
                self.bins[i] += 1;
                self.sums[i] += y;
            }
            None => self.outside += 1,
        }
    }

    /// Points binned.
    pub fn count(&self) -> u64 {
        self.bins.iter().sum()
    }

    /// The floor between heights `low..high` (see the module docs): its height and the points
    /// in its band.
    pub fn floor_between(&self, low: f32, high: f32) -> Option<(f32, u64)> {
        let (first, last) = (Self::bin(f64::from(low))?, Self::bin(f64::from(high))?);
        if last < first + 3 {
            return None;
        }
        let band = |i: usize| self.bins[i - 1] + self.bins[i] + self.bins[i + 1];
        let fullest = (first + 1..last).map(band).max()?;
        let threshold = MIN_FLOOR_POINTS.max(fullest.div_ceil(3));
        let lowest = (first + 1..last).find(|&i| band(i) >= threshold)?;
        // The peak of the run of bands that starts there (a floor is a few cm thick in noise).
        let mut peak = lowest;
        while peak + 1 < last && band(peak + 1) > band(peak) {
            peak += 1;
        }
        let count = band(peak);
        let sum = self.sums[peak - 1] + self.sums[peak] + self.sums[peak + 1];
        Some(((sum / count as f64) as f32, count))
    }
}

/// The standing head height: the [`STANDING_PERCENTILE`] of the head's heights.
pub fn standing_head_height(head: &Trajectory) -> Option<f32> {
    let mut heights: Vec<f32> = head.poses.iter().map(|p| p.translation.y).filter(|y| y.is_finite()).collect();
    if heights.is_empty() {
        return None;
    }
    let k = ((heights.len() - 1) as f32 * STANDING_PERCENTILE).round() as usize;
    let (_, h, _) = heights.select_nth_unstable_by(k, f32::total_cmp);
    Some(*h)
}

/// Height of the glasses (CPF) above the soles when standing, metres, for `skeleton` with
/// the SMPL head joint at `head_joint_in_device` in the glasses' frame.
pub fn standing_eye_height(skeleton: &SmplSkeleton, head_joint_in_device: egoexo_core::glam::Vec3) -> f32 {
    let scale = skeleton.head_height() / SmplSkeleton::mean_shape().head_height();
    skeleton.head_height() + FOOT_JOINT_ABOVE_SOLE_M * scale - head_joint_in_device.y
}

/// The floor from semidense point heights, when they show one below the standing head.
pub fn floor_from_points(heights: &HeightHistogram, head: &Trajectory, file: &str) -> Option<Floor> {
    let standing = standing_head_height(head)?;
    let (height_m, points) = heights.floor_between(standing - MAX_EYE_HEIGHT_M, standing - MIN_EYE_HEIGHT_M)?;
    Some(Floor { height_m, source: FloorSource::SemidensePoints { file: file.to_owned(), points } })
}

/// The floor under a ground-truth body: the 5th percentile of each frame's lowest
/// ankle/foot joint, minus the joints' height above the soles.
pub fn floor_from_ground_truth(motion: &egoexo_core::motion::SmplMotion) -> Option<Floor> {
    let stride = (motion.len() / 5000).max(1);
    let mut lowest: Vec<f32> = motion
        .poses
        .iter()
        .step_by(stride)
        .map(|p| {
            let fk = motion.skeleton.forward_kinematics(p);
            FOOT_JOINTS.iter().map(|&j| fk.positions[j].y).fold(f32::INFINITY, f32::min)
        })
        .filter(|y| y.is_finite())
        .collect();
    if lowest.is_empty() {
        return None;
    }
    let k = ((lowest.len() - 1) as f32 * 0.05).round() as usize;
    let (_, y, _) = lowest.select_nth_unstable_by(k, f32::total_cmp);
    let scale = motion.skeleton.head_height() / SmplSkeleton::mean_shape().head_height();
    Some(Floor { height_m: *y - FOOT_JOINT_ABOVE_SOLE_M * scale, source: FloorSource::GroundTruth })
}

/// The floor from the standing head height and the subject's body (see the module docs).
pub fn floor_from_standing_head(session: &Session) -> Option<Floor> {
    let standing = standing_head_height(&session.wearer.head)?;
    let skeleton = session.subject.skeleton().unwrap_or_else(|_| SmplSkeleton::mean_shape());
    let stature_m = session.subject.height_m.unwrap_or(egoexo_core::skeleton::MEAN_SHAPE_STATURE_M);
    let eye = standing_eye_height(&skeleton, session.wearer.head_joint_in_device);
    Some(Floor {
        height_m: standing - eye,
        source: FloorSource::StandingHead {
            standing_head_m: standing,
            stature_m,
            stature_known: session.subject.height_m.is_some(),
        },
    })
}

/// `session`'s stored floor, else the estimate from its standing head
/// ([`floor_from_standing_head`]).
pub fn floor_or_estimate(session: &Session) -> Option<Floor> {
    session.floor.clone().or_else(|| floor_from_standing_head(session))
}

#[cfg(test)]
mod tests {
    use egoexo_core::rigid::RigidTransform;
    use egoexo_core::skeleton::DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE;

    use super::*;

    fn head_at(y: f32) -> Trajectory {
        Trajectory {
            timestamps_ns: (0..100).collect(),
            poses: (0..100)
                .map(|i| {
                    RigidTransform::from_translation(egoexo_core::glam::Vec3::new(0.0, y - (i % 7) as f32 * 0.01, 0.0))
                })
                .collect(),
        }
    }

    #[test]
    fn the_lowest_strong_band_is_the_floor_not_the_fullest() {
        let mut h = HeightHistogram::new();
        for i in 0..400 {
            h.add(-1.2 + (i % 5) as f64 * 0.004); // floor around −1.192
        }
        for i in 0..900 {
            h.add(-0.45 + (i % 3) as f64 * 0.003); // a table top, fuller than the floor
        }
        for i in 0..30 {
            h.add(-1.6 + i as f64 * 0.001); // a few noisy points below
        }
        let floor = floor_from_points(&h, &head_at(0.45), "p.csv.gz").unwrap();
        assert!((floor.height_m + 1.192).abs() < 0.01, "{floor:?}");
        assert!(matches!(floor.source, FloorSource::SemidensePoints { points, .. } if points >= 300));
        // Nothing in the searched band: no floor.
        assert!(floor_from_points(&h, &head_at(3.0), "p").is_none());
    }

    #[test]
    fn standing_eye_height_of_the_mean_shape_is_eye_level() {
        let eye = standing_eye_height(&SmplSkeleton::mean_shape(), DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE);
        let stature = egoexo_core::skeleton::MEAN_SHAPE_STATURE_M;
        // Eyes sit about 6–8 % of the stature below the top of the head.
        assert!(eye > 0.9 * stature && eye < 0.96 * stature, "{eye} for {stature}");
    }
}
