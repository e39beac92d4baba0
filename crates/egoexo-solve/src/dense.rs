//! Small fixed-size dense algebra for Gauss–Newton steps over a body's joints (glam f64):
//! the cross-product and outer-product matrices of a joint's derivative, and solving the
//! normal equations of a handful of unknowns without allocating. The CMU retargeting's torso
//! and limb fits use them (`egoexo-mocap`); larger, robust problems use [`crate::lsq`].

use egoexo_core::glam::{DMat3, DVec3};

/// `[v]×`: the matrix with `[v]× · u = v × u`.
pub fn skew(v: DVec3) -> DMat3 {
    DMat3::from_cols(DVec3::new(0.0, v.z, -v.y), DVec3::new(-v.z, 0.0, v.x), DVec3::new(v.y, -v.x, 0.0))
}

/// `a bᵀ`: the matrix with `(a bᵀ) · u = a (b · u)`.
pub fn outer_d(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// Solves `h · x = g` for a symmetric positive definite `h` (Cholesky, f64).
pub fn solve_spd<const N: usize>(mut h: [[f64; N]; N], g: [f64; N]) -> Option<[f64; N]> {
    for j in 0..N {
        let mut d = h[j][j];
        for k in 0..j {
            d -= h[j][k] * h[j][k];
        }
        if d.is_nan() || d <= 0.0 {
            return None;
        }
        let d = d.sqrt();
        h[j][j] = d;
        for i in (j + 1)..N {
            let mut s = h[i][j];
            for k in 0..j {
                s -= h[i][k] * h[j][k];
            }
            h[i][j] = s / d;
        }
    }
    let mut y = [0.0f64; N];
    for i in 0..N {
        let mut s = g[i];
        for k in 0..i {
            s -= h[i][k] * y[k];
        }
        y[i] = s / h[i][i];
    }
    let mut x = [0.0f64; N];
    for i in (0..N).rev() {
        let mut s = y[i];
        for k in (i + 1)..N {
            s -= h[k][i] * x[k];
        }
        x[i] = s / h[i][i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solve_spd_solves_a_positive_definite_system() {
        const N: usize = 6;
        let m: [[f64; N]; N] = std::array::from_fn(|r| std::array::from_fn(|c| ((r * 7 + c * 3) % 5) as f64 - 2.0));
        let mut h = [[0.0; N]; N];
        for r in 0..N {
            for c in 0..N {
                h[r][c] = (0..N).map(|k| m[k][r] * m[k][c]).sum::<f64>() + if r == c { 0.5 } else { 0.0 };
            }
        }
        let x: [f64; N] = std::array::from_fn(|i| i as f64 - 2.5);
        let g: [f64; N] = std::array::from_fn(|r| (0..N).map(|c| h[r][c] * x[c]).sum());
        let solved = solve_spd(h, g).unwrap();
        for i in 0..N {
            assert!((solved[i] - x[i]).abs() < 1e-9, "{solved:?}");
        }
        assert_eq!(solve_spd([[0.0; N]; N], g), None);
    }

    #[test]
    fn the_cross_and_outer_matrices_act_as_their_products() {
        let (a, b, u) = (DVec3::new(1.0, -2.0, 0.5), DVec3::new(0.3, 4.0, -1.0), DVec3::new(-2.0, 0.25, 3.0));
        assert!((skew(a) * u - a.cross(u)).length() < 1e-12);
        assert!((outer_d(a, b) * u - a * b.dot(u)).length() < 1e-12);
    }
}
