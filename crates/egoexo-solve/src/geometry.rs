//! f64 rotation helpers shared by the solvers, and conversions from the core's f32 types.
//!
//! Yaw is the right-handed rotation about +Y (Y up): a positive yaw turns +X towards −Z.

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};

/// A 3-vector in f64.
pub type V3 = Vector3<f64>;
/// A 3×3 matrix in f64.
pub type M3 = Matrix3<f64>;

/// `R_y(ψ)`: the right-handed rotation by `psi` radians about +Y.
pub fn yaw_matrix(psi: f64) -> M3 {
    let (s, c) = psi.sin_cos();
    M3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// `dR_y(ψ)/dψ`.
pub fn yaw_matrix_derivative(psi: f64) -> M3 {
    let (s, c) = psi.sin_cos();
    M3::new(-s, 0.0, c, 0.0, 0.0, 0.0, -c, 0.0, -s)
}

/// The heading of a rotation: the yaw whose `R_y` turns +Z where `rotation` turns it,
/// projected on the horizontal plane (radians in `(−π, π]`).
pub fn heading(rotation: &M3) -> f64 {
    let z = rotation * V3::z();
    z.x.atan2(z.z)
}

/// `[v]×`: the matrix with `[v]× w = v × w`.
pub fn skew(v: &V3) -> M3 {
    M3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// `exp([ω]×)`: the rotation by `|ω|` radians about `ω`.
pub fn exp_rotation(omega: &V3) -> M3 {
    Rotation3::new(*omega).into_inner()
}

/// The rotation nearest to `m` in the Frobenius norm (its polar factor), or `None` when `m`
/// is degenerate or not finite.
pub fn nearest_rotation(m: &M3) -> Option<M3> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut d = M3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    Some(u * d * v_t)
}

/// The angle of a rotation matrix, radians.
pub fn rotation_angle(rotation: &M3) -> f64 {
    ((rotation.trace() - 1.0) * 0.5).clamp(-1.0, 1.0).acos()
}

/// A glam vector in f64.
pub fn v3(v: Vec3) -> V3 {
    V3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
}

/// A rigid transform in f64.
pub fn isometry(t: &RigidTransform) -> Isometry3<f64> {
    let q = t.rotation;
    let rotation = UnitQuaternion::from_quaternion(Quaternion::new(
        f64::from(q.w),
        f64::from(q.x),
        f64::from(q.y),
        f64::from(q.z),
    ));
    Isometry3::from_parts(Translation3::from(v3(t.translation)), rotation)
}

/// A rotation matrix and translation as the core's f32 rigid transform.
pub fn rigid_transform(rotation: &M3, translation: &V3) -> RigidTransform {
    let q = UnitQuaternion::from_matrix(rotation);
    RigidTransform::new(
        Quat::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize(),
        Vec3::new(translation.x as f32, translation.y as f32, translation.z as f32),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn yaw_follows_the_documented_convention() {
        let r = yaw_matrix(90f64.to_radians());
        let x = r * V3::x();
        assert!((x - V3::new(0.0, 0.0, -1.0)).norm() < 1e-12, "a positive yaw turns +X towards −Z");
        let glam = Quat::from_rotation_y(0.7);
        let ours = yaw_matrix(0.7);
        let theirs = isometry(&RigidTransform::from_rotation(glam)).rotation.to_rotation_matrix().into_inner();
        assert!((ours - theirs).norm() < 1e-6);
        assert!((heading(&ours) - 0.7).abs() < 1e-12);
        let h = 1e-6;
        let numeric = (yaw_matrix(0.3 + h) - yaw_matrix(0.3 - h)) / (2.0 * h);
        assert!((numeric - yaw_matrix_derivative(0.3)).norm() < 1e-8);
    }

    #[test]
    fn nearest_rotation_of_a_scaled_rotation_is_the_rotation() {
        let r = exp_rotation(&V3::new(0.3, -1.2, 0.5));
        let back = nearest_rotation(&(r * 2.5)).unwrap();
        assert!((back - r).norm() < 1e-12);
        assert!((rotation_angle(&r) - V3::new(0.3, -1.2, 0.5).norm()).abs() < 1e-12);
        assert!(nearest_rotation(&M3::from_element(f64::NAN)).is_none());
    }
}
