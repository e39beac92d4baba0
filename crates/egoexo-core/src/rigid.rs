//! Rigid transforms (elements of SE(3)).
//!
//! Units: metres. Naming: a `RigidTransform` held in a variable `t_a_b` maps points
//! expressed in frame `b` into frame `a` (`p_a = t_a_b.transform_point(p_b)`), so
//! `t_a_b * t_b_c == t_a_c` and `t_a_b.inverse() == t_b_a`. A device trajectory is a
//! sequence of `T_world_device`.

use std::ops::Mul;

use glam::{Mat3, Mat4, Quat, Vec3};
use serde::{Deserialize, Serialize};

/// A rotation followed by a translation: `p ↦ R p + t`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RigidTransform {
    /// Unit quaternion `R`.
    pub rotation: Quat,
    /// Translation `t` in metres (the origin of the source frame, seen from the target frame).
    pub translation: Vec3,
}

impl Default for RigidTransform {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl RigidTransform {
    /// Maps every point to itself.
    pub const IDENTITY: Self = Self { rotation: Quat::IDENTITY, translation: Vec3::ZERO };

    /// `p ↦ rotation · p + translation`. The rotation is normalised.
    pub fn new(rotation: Quat, translation: Vec3) -> Self {
        Self { rotation: rotation.normalize(), translation }
    }

    /// A pure rotation.
    pub fn from_rotation(rotation: Quat) -> Self {
        Self::new(rotation, Vec3::ZERO)
    }

    /// A pure translation.
    pub fn from_translation(translation: Vec3) -> Self {
        Self { rotation: Quat::IDENTITY, translation }
    }

    /// From a rotation matrix (assumed orthonormal) and a translation.
    pub fn from_rotation_matrix(rotation: Mat3, translation: Vec3) -> Self {
        Self::new(Quat::from_mat3(&rotation), translation)
    }

    /// The rotation as a matrix.
    pub fn rotation_matrix(&self) -> Mat3 {
        Mat3::from_quat(self.rotation)
    }

    /// Homogeneous 4×4 matrix.
    pub fn to_mat4(&self) -> Mat4 {
        Mat4::from_rotation_translation(self.rotation, self.translation)
    }

    /// `R p + t`.
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    /// `R v` (directions and displacements ignore the translation).
    pub fn transform_vector(&self, v: Vec3) -> Vec3 {
        self.rotation * v
    }

    /// The inverse transform `p ↦ Rᵀ (p − t)`.
    pub fn inverse(&self) -> Self {
        let r_inv = self.rotation.conjugate();
        Self { rotation: r_inv, translation: -(r_inv * self.translation) }
    }

    /// Interpolates from `self` (`alpha = 0`) to `other` (`alpha = 1`): spherical linear
    /// interpolation of the rotation along the shortest arc, linear interpolation of the
    /// translation. Used to resample trajectories between timestamps.
    pub fn interpolate(&self, other: &Self, alpha: f32) -> Self {
        Self {
            rotation: self.rotation.slerp(other.rotation, alpha).normalize(),
            translation: self.translation.lerp(other.translation, alpha),
        }
    }

    /// All components are finite.
    pub fn is_finite(&self) -> bool {
        self.rotation.is_finite() && self.translation.is_finite()
    }

    /// `T_world_device` of a head device (CPF convention: +X left, +Y up, +Z forward) at `eye`
    /// looking at `target`, with its up axis in the vertical plane (no roll). Falls back to
    /// facing world +Z when `target` is straight above or below `eye`.
    pub fn cpf_looking_at(eye: Vec3, target: Vec3) -> Self {
        let forward = (target - eye).normalize_or_zero();
        let left = Vec3::Y.cross(forward);
        if forward == Vec3::ZERO || left.length() < 1e-6 {
            return Self::from_translation(eye);
        }
        let left = left.normalize();
        let up = forward.cross(left);
        Self::from_rotation_matrix(Mat3::from_cols(left, up, forward), eye)
    }
}

/// Composition: `(t_a_b * t_b_c).transform_point(p) == t_a_b.transform_point(t_b_c.transform_point(p))`.
impl Mul for RigidTransform {
    type Output = RigidTransform;

    fn mul(self, rhs: RigidTransform) -> RigidTransform {
        RigidTransform {
            rotation: (self.rotation * rhs.rotation).normalize(),
            translation: self.rotation * rhs.translation + self.translation,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn cpf_looking_at_points_forward_axis_at_target() {
        let eye = Vec3::new(1.0, 1.6, -2.0);
        let target = Vec3::new(-3.0, 1.0, 4.0);
        let t = RigidTransform::cpf_looking_at(eye, target);
        assert!((t.transform_vector(Vec3::Z) - (target - eye).normalize()).length() < 1e-6);
        assert!(t.transform_vector(Vec3::X).y.abs() < 1e-6, "no roll");
        assert!(t.transform_vector(Vec3::Y).y > 0.0, "up stays up");
    }

    #[test]
    fn compose_then_inverse_is_identity() {
        let t =
            RigidTransform::new(Quat::from_rotation_y(0.7) * Quat::from_rotation_x(-0.3), Vec3::new(1.0, 2.0, -3.0));
        let id = t * t.inverse();
        assert!(id.translation.length() < 1e-6);
        assert!(id.rotation.abs_diff_eq(Quat::IDENTITY, 1e-6) || id.rotation.abs_diff_eq(-Quat::IDENTITY, 1e-6));
    }

    #[test]
    fn interpolation_endpoints_and_midpoint() {
        let a = RigidTransform::new(Quat::IDENTITY, Vec3::ZERO);
        let b = RigidTransform::new(Quat::from_rotation_z(1.0), Vec3::new(2.0, 0.0, 0.0));
        let mid = a.interpolate(&b, 0.5);
        assert!(mid.rotation.abs_diff_eq(Quat::from_rotation_z(0.5), 1e-6));
        assert!(mid.translation.abs_diff_eq(Vec3::new(1.0, 0.0, 0.0), 1e-6));
        assert_eq!(a.interpolate(&b, 0.0).translation, a.translation);
    }

    #[test]
    fn interpolation_takes_the_short_arc() {
        let a = RigidTransform::from_rotation(Quat::from_rotation_y(0.1));
        // The same rotation as angle 0.3 but with the opposite quaternion sign.
        let b = RigidTransform::from_rotation(-Quat::from_rotation_y(0.3));
        let mid = a.interpolate(&b, 0.5);
        assert!(crate::rotation::angle_between(mid.rotation, Quat::from_rotation_y(0.2)) < 1e-5);
    }
}
