//! Rotation representations: the continuous 6D form used by the networks, 3×3 matrices,
//! unit quaternions and axis-angle (rotation) vectors.
//!
//! Units: radians. Rotations are active and right-handed; matrices act on column vectors.
//! Conversions between matrices and quaternions are glam's; this module adds the 6D form
//! (Zhou et al., "On the Continuity of Rotation Representations", CVPR 2019) and a
//! numerically careful axis-angle conversion (SMPL/AMASS store poses as axis-angle).

use glam::{Mat3, Quat, Vec3};
use serde::{Deserialize, Serialize};

/// A rotation as the first two **columns** of its matrix:
/// `[R00, R10, R20, R01, R11, R21]` (column 0, then column 1).
///
/// Any 6 numbers decode to a rotation through Gram–Schmidt ([`Rot6d::to_mat3`]), which is
/// what makes the form a good network output. Layout note: PyTorch3D's
/// `matrix_to_rotation_6d` takes *rows*; this project always takes columns, in Rust and in
/// the training code alike.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Rot6d(pub [f32; 6]);

/// Below this length a 6D column is treated as degenerate.
const DEGENERATE_EPS: f32 = 1e-8;

impl Rot6d {
    /// The identity rotation.
    pub const IDENTITY: Rot6d = Rot6d([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);

    /// Takes the first two columns of `m` (assumed orthonormal).
    pub fn from_mat3(m: Mat3) -> Self {
        Rot6d([m.x_axis.x, m.x_axis.y, m.x_axis.z, m.y_axis.x, m.y_axis.y, m.y_axis.z])
    }

    /// Encodes a unit quaternion.
    pub fn from_quat(q: Quat) -> Self {
        Self::from_mat3(Mat3::from_quat(q))
    }

    /// The two raw (not yet orthonormalised) columns.
    pub fn columns(&self) -> (Vec3, Vec3) {
        let a = self.0;
        (Vec3::new(a[0], a[1], a[2]), Vec3::new(a[3], a[4], a[5]))
    }

    /// Decodes by Gram–Schmidt: `b1 = a1/|a1|`, `b2 = normalize(a2 − (b1·a2) b1)` (projected
    /// twice for f32 accuracy), `b3 = b1 × b2`.
    ///
    /// Degenerate input never yields NaN: a zero or non-finite first column falls back to
    /// +X, and a second column parallel to the first falls back to a fixed perpendicular
    /// direction. Such outputs are still proper rotations.
    pub fn to_mat3(&self) -> Mat3 {
        let (a1, a2) = self.columns();
        let b1 = if a1.is_finite() && a1.length() > DEGENERATE_EPS { a1.normalize() } else { Vec3::X };
        let a2 = if a2.is_finite() { a2 } else { Vec3::ZERO };
        let ortho = a2 - b1.dot(a2) * b1;
        let b2 = if ortho.length() > DEGENERATE_EPS * a2.length().max(1.0) {
            // A second pass ("twice is enough"): when `a2` is nearly parallel to `a1` the
            // subtraction above cancels and leaves `b1·b2` at ~1e-5 in f32; projecting once
            // more brings it to rounding level, so decoding an output again changes nothing.
            let b2 = ortho.normalize();
            (b2 - b1.dot(b2) * b1).normalize()
        } else {
            b1.any_orthonormal_vector()
        };
        let b3 = b1.cross(b2);
        Mat3::from_cols(b1, b2, b3)
    }

    /// Decodes to a unit quaternion (via [`Rot6d::to_mat3`]).
    pub fn to_quat(&self) -> Quat {
        quat_from_rotation_matrix(self.to_mat3())
    }

    /// All six numbers are finite.
    pub fn is_finite(&self) -> bool {
        self.0.iter().all(|v| v.is_finite())
    }

    /// How much orientation the raw columns carry: the shorter of the first column and the
    /// part of the second perpendicular to it, before Gram–Schmidt normalises them (about 1 for
    /// a confident network output, 0 for a degenerate one; 0 when not finite).
    pub fn column_strength(&self) -> f32 {
        if !self.is_finite() {
            return 0.0;
        }
        let (a1, a2) = self.columns();
        let len1 = a1.length();
        if len1 <= DEGENERATE_EPS {
            return 0.0;
        }
        let b1 = a1 / len1;
        len1.min((a2 - b1.dot(a2) * b1).length())
    }
}

/// Column strength ([`Rot6d::column_strength`]) below which a network's 6D output is read as
/// carrying no orientation. A regressed 6D output that has to turn far within a few frames
/// (a wearer turning fast, where the network hesitates between turning left and right)
/// shrinks towards the origin, and Gram–Schmidt then swings the decoded rotation through
/// the turn within a frame or two.
pub const COLLAPSED_6D_STRENGTH: f32 = 0.3;

/// Replaces the collapsed rotations of a time series (column strength below `min_strength`)
/// by the geodesic interpolation (slerp, shortest arc) between the nearest strong rotations
/// before and after them; a collapsed run at either end takes its one strong neighbour. A
/// series without any strong rotation is left as it is. Replaced rotations have unit
/// columns. Returns how many were replaced.
pub fn interpolate_collapsed_6d(series: &mut [Rot6d], min_strength: f32) -> usize {
    let strong: Vec<usize> = (0..series.len()).filter(|&t| series[t].column_strength() >= min_strength).collect();
    let (Some(&first), Some(&last)) = (strong.first(), strong.last()) else { return 0 };
    let mut replaced = 0;
    for t in 0..series.len() {
        if series[t].column_strength() >= min_strength {
            continue;
        }
        let quat = if t < first {
            series[first].to_quat()
        } else if t > last {
            series[last].to_quat()
        } else {
            // `strong` is sorted and `first < t < last`: the neighbours exist.
            let after = strong[strong.partition_point(|&s| s < t)];
            let before = strong[strong.partition_point(|&s| s < t) - 1];
            let (q0, mut q1) = (series[before].to_quat(), series[after].to_quat());
            if q0.dot(q1) < 0.0 {
                q1 = -q1;
            }
            q0.slerp(q1, (t - before) as f32 / (after - before) as f32).normalize()
        };
        series[t] = Rot6d::from_quat(quat);
        replaced += 1;
    }
    replaced
}

/// Unit quaternion of an orthonormal matrix, with `w ≥ 0` (a canonical sign).
pub fn quat_from_rotation_matrix(m: Mat3) -> Quat {
    canonical_quat(Quat::from_mat3(&m).normalize())
}

/// `q` or `−q` (the same rotation), whichever has `w ≥ 0`.
pub fn canonical_quat(q: Quat) -> Quat {
    if q.w < 0.0 { -q } else { q }
}

/// Quaternion from an axis-angle (rotation) vector: direction = axis, length = angle in
/// radians. Exact near zero (uses the small-angle series, no division by the angle).
pub fn quat_from_axis_angle(v: Vec3) -> Quat {
    let angle = v.length();
    let half = 0.5 * angle;
    // sin(half)/angle, with its Taylor series where angle is tiny.
    let k = if angle < 1e-4 { 0.5 - angle * angle / 48.0 } else { half.sin() / angle };
    Quat::from_xyzw(v.x * k, v.y * k, v.z * k, half.cos()).normalize()
}

/// Axis-angle (rotation) vector of a unit quaternion, with the angle in `[0, π]`.
///
/// Uses `atan2` rather than `acos(w)`, so it stays accurate for tiny angles.
pub fn axis_angle_from_quat(q: Quat) -> Vec3 {
    let q = canonical_quat(q.normalize());
    let xyz = Vec3::new(q.x, q.y, q.z);
    let s = xyz.length();
    if s < 1e-7 {
        // angle ≈ 2 s / w and axis = xyz / s, so the vector is ≈ 2 xyz / w.
        return xyz * (2.0 / q.w.max(f32::MIN_POSITIVE));
    }
    let angle = 2.0 * s.atan2(q.w);
    xyz * (angle / s)
}

/// Geodesic angle between two rotations, radians in `[0, π]`.
pub fn angle_between(a: Quat, b: Quat) -> f32 {
    let d = (a.conjugate() * b).normalize();
    let s = Vec3::new(d.x, d.y, d.z).length();
    2.0 * s.atan2(d.w.abs())
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    /// A turn of `degrees` about the vertical axis.
    fn yaw(degrees: f32) -> Rot6d {
        Rot6d::from_quat(Quat::from_rotation_y(degrees.to_radians()))
    }

    #[test]
    fn collapsed_rotations_follow_the_short_arc_between_strong_neighbours() {
        // A fast 120° turn: frames 4..=6 collapse towards the origin with their first column
        // swinging the wrong way round, as a hesitating network's output does.
        let mut series: Vec<Rot6d> = (0..12).map(|t| yaw(t as f32 * 10.0)).collect();
        for (t, wrong) in [(4, -60.0f32), (5, 160.0), (6, 100.0)] {
            let (a1, a2) = yaw(wrong).columns();
            let a1 = a1 * 0.1;
            series[t] = Rot6d([a1.x, a1.y, a1.z, a2.x, a2.y, a2.z]);
        }
        assert!(series[5].column_strength() < 0.2 && series[3].column_strength() > 0.99);
        assert_eq!(interpolate_collapsed_6d(&mut series, COLLAPSED_6D_STRENGTH), 3);
        for t in 0..12 {
            let angle = angle_between(series[t].to_quat(), yaw(t as f32 * 10.0).to_quat()).to_degrees();
            assert!(angle < 1e-3 + 0.05, "frame {t} is {angle}° off the turn");
        }
    }

    #[test]
    fn strong_series_are_left_alone_and_collapsed_ends_take_their_neighbour() {
        let strong: Vec<Rot6d> = (0..5).map(|t| yaw(t as f32 * 30.0)).collect();
        let mut series = strong.clone();
        assert_eq!(interpolate_collapsed_6d(&mut series, COLLAPSED_6D_STRENGTH), 0);
        assert_eq!(series, strong);

        series[0] = Rot6d([0.0; 6]);
        series[4] = Rot6d([f32::NAN, 0.0, 0.0, 0.0, 1.0, 0.0]);
        assert_eq!(interpolate_collapsed_6d(&mut series, COLLAPSED_6D_STRENGTH), 2);
        assert!(angle_between(series[0].to_quat(), strong[1].to_quat()) < 1e-4);
        assert!(angle_between(series[4].to_quat(), strong[3].to_quat()) < 1e-4);

        let mut all_collapsed = vec![Rot6d([0.01, 0.0, 0.0, 0.0, 0.01, 0.0]); 3];
        assert_eq!(interpolate_collapsed_6d(&mut all_collapsed, COLLAPSED_6D_STRENGTH), 0);
        assert_eq!(all_collapsed[0].0[0], 0.01);
    }

    #[test]
    fn identity_round_trips() {
        assert_eq!(Rot6d::IDENTITY.to_mat3(), Mat3::IDENTITY);
        assert_eq!(Rot6d::from_mat3(Mat3::IDENTITY), Rot6d::IDENTITY);
    }

    #[test]
    fn degenerate_6d_decodes_to_a_rotation() {
        for raw in [[0.0; 6], [1.0, 0.0, 0.0, 2.0, 0.0, 0.0], [f32::NAN; 6], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0]] {
            let m = Rot6d(raw).to_mat3();
            assert!(m.is_finite(), "{raw:?}");
            assert!((m.determinant() - 1.0).abs() < 1e-5, "{raw:?}");
            assert!((m.transpose() * m).abs_diff_eq(Mat3::IDENTITY, 1e-5), "{raw:?}");
        }
    }

    #[test]
    fn axis_angle_half_turn() {
        let v = Vec3::new(0.0, std::f32::consts::PI, 0.0);
        let q = quat_from_axis_angle(v);
        let back = axis_angle_from_quat(q);
        assert!((back.length() - std::f32::consts::PI).abs() < 1e-5);
        assert!(back.normalize().abs().abs_diff_eq(Vec3::Y, 1e-5));
    }
}
