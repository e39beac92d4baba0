//! The start of a fit: hypotheses of the observer's world from a few keypoints each, kept by
//! how many frames they explain (RANSAC with a truncated cost, MSAC).
//!
//! The keypoints used here do not depend on the detector's left–right labels: the nose, and
//! the midpoints of the eyes, the ears, the shoulders and the hips. Each is a ray in the
//! observer's own world (camera centre `c`, direction `d`) and a point `h` of the body in the
//! target's world, related by `d × (R⁻¹(h − t) − c) = 0`. With `τ = R⁻¹t` that is linear in
//! `R⁻¹` and `τ`:
//! - **4 DoF** (`R = R_y(ψ)`): linear in `(cos ψ, sin ψ, τ)`; `τ` is eliminated and `ψ` found
//!   on the unit circle — three rays make a hypothesis.
//! - **6 DoF**: linear in the 9 entries of `R⁻¹`, `τ` and a scale on `c` (a homogeneous
//!   system, smallest eigenvector), then the nearest rotation — six rays make one. It also
//!   serves a static camera whose own world is its optical frame (`c = 0`).

use nalgebra::{DMatrix, Matrix2, SMatrix, Vector2};
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::problem::Dof;
use super::track::TargetTrack;
use super::view::PreparedView;
use crate::geometry::{M3, V3, nearest_rotation, skew, yaw_matrix};

/// Left–right-free keypoint groups (COCO-17 indices averaged).
const INVARIANT_GROUPS: [&[usize]; 5] = [&[0], &[1, 2], &[3, 4], &[5, 6], &[11, 12]];

/// One ray and the body point it should pass through.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Correspondence {
    /// Camera centre, observer's own world.
    pub centre: V3,
    /// Unit direction, observer's own world.
    pub direction: V3,
    /// The body point, target world.
    pub point: V3,
    /// 1σ of the angle between them (radians) at distance 1 m: `(σ_det, σ_point)`.
    pub sigma: (f64, f64),
}

/// A frame's correspondences, per person.
#[derive(Clone, Debug)]
pub(crate) struct FrameCorrespondences {
    pub people: Vec<Vec<Correspondence>>,
}

/// A world transform hypothesis: `p_target = R p_own + t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Hypothesis {
    pub rotation: M3,
    pub translation: V3,
}

/// The invariant correspondences of every frame of `view` against `track`, the target's
/// clock `clock_offset_s` ahead of the camera's, bearings at focal scale `exp(log_focal)`.
pub(crate) fn correspondences(
    view: &PreparedView,
    track: &TargetTrack,
    clock_offset_s: f64,
    log_focal: f64,
) -> Vec<FrameCorrespondences> {
    view.frames
        .iter()
        .map(|frame| {
            let points = track.sample(frame.time_s + clock_offset_s);
            let people = frame
                .people
                .iter()
                .map(|person| {
                    let Some(points) = &points else { return Vec::new() };
                    INVARIANT_GROUPS
                        .iter()
                        .filter_map(|group| {
                            let mut bearing = V3::zeros();
                            let mut point = V3::zeros();
                            let mut sigma: f64 = 0.0;
                            for &k in group.iter() {
                                let o = person.observations.iter().find(|o| o.k == k)?;
                                let p = points[k]?;
                                bearing += view.bearing(o, log_focal);
                                point += p.position;
                                sigma = sigma.max(p.sigma_m);
                            }
                            let n = group.len() as f64;
                            let direction = frame.rotation * bearing.normalize();
                            Some(Correspondence {
                                centre: frame.centre,
                                direction,
                                point: point / n,
                                sigma: (view.sigma_detector_rad, sigma),
                            })
                        })
                        .collect()
                })
                .collect();
            FrameCorrespondences { people }
        })
        .collect()
}

/// 4 DoF from three or more correspondences: `ψ` on the unit circle, `τ` eliminated.
pub(crate) fn solve_four_dof(cs: &[Correspondence]) -> Option<Hypothesis> {
    let mut n_tt = M3::zeros();
    let mut n_tz = SMatrix::<f64, 3, 2>::zeros();
    let mut n_zz = Matrix2::zeros();
    let mut b_t = V3::zeros();
    let mut b_z = Vector2::zeros();
    for c in cs {
        let d = c.direction;
        let h = c.point;
        let dx = skew(&d);
        let a_cs =
            SMatrix::<f64, 3, 2>::from_columns(&[d.cross(&V3::new(h.x, 0.0, h.z)), d.cross(&V3::new(-h.z, 0.0, h.x))]);
        let a_t = -dx;
        let y = d.cross(&c.centre) - d.cross(&V3::y()) * h.y;
        n_tt += a_t.transpose() * a_t;
        n_tz += a_t.transpose() * a_cs;
        n_zz += a_cs.transpose() * a_cs;
        b_t += a_t.transpose() * y;
        b_z += a_cs.transpose() * y;
    }
    let n_tt_inv = n_tt.try_inverse()?;
    let m = n_zz - n_tz.transpose() * n_tt_inv * n_tz;
    let n = b_z - n_tz.transpose() * n_tt_inv * b_t;
    let f = |phi: f64| {
        let z = Vector2::new(phi.cos(), phi.sin());
        (z.transpose() * m * z)[0] - 2.0 * n.dot(&z)
    };
    // Coarse scan, then golden-section refinement around the best.
    let steps = 120;
    let step = std::f64::consts::TAU / steps as f64;
    let best = (0..steps).map(|i| i as f64 * step).min_by(|a, b| f(*a).total_cmp(&f(*b)))?;
    let (mut lo, mut hi) = (best - step, best + step);
    let golden = 0.618_033_988_749_895;
    for _ in 0..40 {
        let x1 = hi - golden * (hi - lo);
        let x2 = lo + golden * (hi - lo);
        if f(x1) < f(x2) {
            hi = x2;
        } else {
            lo = x1;
        }
    }
    let phi = 0.5 * (lo + hi);
    let z = Vector2::new(phi.cos(), phi.sin());
    let tau = n_tt_inv * (b_t - n_tz * z);
    // (cos ψ, sin ψ) = z.
    let rotation = yaw_matrix(z.y.atan2(z.x));
    let h = Hypothesis { rotation, translation: rotation * tau };
    (h.translation.iter().all(|v| v.is_finite())).then_some(h)
}

/// 6 DoF from six or more correspondences (the homogeneous linear system, then the nearest
/// rotation).
pub(crate) fn solve_six_dof(cs: &[Correspondence]) -> Option<Hypothesis> {
    if cs.len() < 5 {
        return None;
    }
    // A camera that never moves (a static camera: every ray from one centre) leaves the
    // scale on `c` undetermined: solve about that centre with 12 unknowns instead of 13.
    let origin = cs[0].centre;
    let moving = cs.iter().any(|c| (c.centre - origin).norm() > 1e-6);
    let unknowns = if moving { 13 } else { 12 };
    let mut ata = DMatrix::<f64>::zeros(unknowns, unknowns);
    for c in cs {
        let dx = skew(&c.direction);
        let mut rows = DMatrix::<f64>::zeros(3, unknowns);
        for i in 0..3 {
            for j in 0..3 {
                // (M h)_j = Σ_l m[j][l] h_l → column 3j + l of the product [d]× H.
                for l in 0..3 {
                    rows[(i, 3 * j + l)] += dx[(i, j)] * c.point[l];
                }
                rows[(i, 9 + j)] = -dx[(i, j)];
            }
        }
        if moving {
            let dc = dx * (c.centre - origin);
            for i in 0..3 {
                rows[(i, 12)] = -dc[i];
            }
        }
        ata += rows.transpose() * rows;
    }
    let eigen = ata.symmetric_eigen();
    let smallest = eigen.eigenvalues.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?.0;
    let mut w: Vec<f64> = eigen.eigenvectors.column(smallest).iter().copied().collect();
    let mut m = M3::from_row_slice(&w[..9]);
    if m.determinant() < 0.0 {
        w.iter_mut().for_each(|v| *v = -*v);
        m = -m;
    }
    let r_inv = nearest_rotation(&m)?;
    let scale = m.svd(false, false).singular_values.mean();
    if scale.is_nan() || scale <= 1e-12 {
        return None;
    }
    // Solved about `origin`: d × (M h − τ' − λ(c − origin)) = 0 with τ' = τ + origin.
    let tau = V3::new(w[9], w[10], w[11]) / scale - origin;
    let rotation = r_inv.transpose();
    let h = Hypothesis { rotation, translation: rotation * tau };
    (h.translation.iter().all(|v| v.is_finite())).then_some(h)
}

/// The whitened angle between a correspondence's ray and its point under `h` (∞ behind).
pub(crate) fn whitened_error(c: &Correspondence, h: &Hypothesis) -> f64 {
    let p_own = h.rotation.transpose() * (c.point - h.translation);
    let v = p_own - c.centre;
    let distance = v.norm();
    if distance < 0.05 {
        return f64::INFINITY;
    }
    let cos = c.direction.dot(&v) / distance;
    if cos <= 0.0 {
        return f64::INFINITY;
    }
    let angle = cos.clamp(-1.0, 1.0).acos();
    let sigma = (c.sigma.0.powi(2) + (c.sigma.1 / distance).powi(2)).sqrt();
    angle / sigma
}

/// A frame's error under `h`: the best person's median whitened error.
fn frame_error(frame: &FrameCorrespondences, h: &Hypothesis) -> Option<f64> {
    frame
        .people
        .iter()
        .filter(|p| !p.is_empty())
        .map(|p| {
            let mut e: Vec<f64> = p.iter().map(|c| whitened_error(c, h)).collect();
            e.sort_by(f64::total_cmp);
            e[e.len() / 2]
        })
        .min_by(f64::total_cmp)
}

/// A hypothesis and how well it explains the frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Scored {
    pub hypothesis: Hypothesis,
    /// `Σ min(e², τ²)` over the frames (lower is better).
    pub cost: f64,
    pub inliers: usize,
}

/// Scores `h` on `frames` with truncation `threshold` (whitened).
pub(crate) fn score(frames: &[FrameCorrespondences], h: &Hypothesis, threshold: f64) -> Scored {
    let cap = threshold * threshold;
    let mut cost = 0.0;
    let mut inliers = 0;
    for frame in frames {
        match frame_error(frame, h) {
            Some(e) => {
                cost += (e * e).min(cap);
                inliers += usize::from(e < threshold);
            }
            None => cost += cap,
        }
    }
    Scored { hypothesis: *h, cost, inliers }
}

/// RANSAC over frames: `iterations` hypotheses from random frames' correspondences, scored
/// on (at most 300 of) the frames. Deterministic for a seed.
pub(crate) fn ransac(
    frames: &[FrameCorrespondences],
    dof: Dof,
    iterations: usize,
    threshold: f64,
    seed: u64,
) -> Option<Scored> {
    let usable: Vec<usize> = (0..frames.len()).filter(|&f| frames[f].people.iter().any(|p| !p.is_empty())).collect();
    let needed = match dof {
        Dof::Four => 3,
        Dof::Six => 6,
    };
    if usable.len() < 2 {
        return None;
    }
    let scoring: Vec<FrameCorrespondences> = if usable.len() > 300 {
        (0..300).map(|i| frames[usable[i * usable.len() / 300]].clone()).collect()
    } else {
        usable.iter().map(|&f| frames[f].clone()).collect()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut best: Option<Scored> = None;
    let mut sample = Vec::with_capacity(needed);
    for _ in 0..iterations {
        sample.clear();
        let mut tries = 0;
        while sample.len() < needed && tries < 4 * needed {
            tries += 1;
            let frame = &frames[usable[rng.random_range(0..usable.len())]];
            let people: Vec<&Vec<Correspondence>> = frame.people.iter().filter(|p| !p.is_empty()).collect();
            let person = people[rng.random_range(0..people.len())];
            // Six-DoF samples take two rays of a frame (its body's extent), four-DoF one.
            let per_frame = if dof == Dof::Six { 2 } else { 1 };
            for _ in 0..per_frame.min(person.len()) {
                if sample.len() < needed {
                    sample.push(person[rng.random_range(0..person.len())]);
                }
            }
        }
        if sample.len() < needed {
            continue;
        }
        let hypothesis = match dof {
            Dof::Four => solve_four_dof(&sample),
            Dof::Six => solve_six_dof(&sample),
        };
        let Some(hypothesis) = hypothesis else { continue };
        let scored = score(&scoring, &hypothesis, threshold);
        if best.is_none_or(|b| scored.cost < b.cost) {
            best = Some(scored);
        }
    }
    // Polish the best on all its inliers' correspondences (a least-squares hypothesis).
    let best = best?;
    let inlier_rays: Vec<Correspondence> = scoring
        .iter()
        .filter_map(|frame| {
            frame
                .people
                .iter()
                .filter(|p| !p.is_empty())
                .map(|p| {
                    let mut e: Vec<f64> = p.iter().map(|c| whitened_error(c, &best.hypothesis)).collect();
                    e.sort_by(f64::total_cmp);
                    (e[e.len() / 2], p)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .filter(|(e, _)| *e < threshold)
                .map(|(_, p)| p.clone())
        })
        .flatten()
        .collect();
    let polished = match dof {
        Dof::Four if inlier_rays.len() >= 3 => solve_four_dof(&inlier_rays),
        Dof::Six if inlier_rays.len() >= 6 => solve_six_dof(&inlier_rays),
        _ => None,
    }
    .map(|h| score(&scoring, &h, threshold))
    .filter(|s| s.cost < best.cost);
    Some(polished.unwrap_or(best))
}

/// A seed derived from a base seed and a label (so candidates draw different samples).
pub(crate) fn derive_seed(seed: u64, label: u64) -> u64 {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ label.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    rng.next_u64()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::exp_rotation;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    fn rays(truth: &Hypothesis, static_camera: bool) -> Vec<Correspondence> {
        (0..12)
            .map(|i| {
                let f = i as f64;
                let point = V3::new(1.5 * (0.7 * f).sin(), 1.0 + 0.4 * (1.3 * f).cos(), 3.0 + 0.5 * (0.4 * f).cos());
                let centre = if static_camera { V3::zeros() } else { V3::new(0.3 * f.cos(), 1.6, -0.2 * f) };
                let p_own = truth.rotation.transpose() * (point - truth.translation);
                Correspondence { centre, direction: (p_own - centre).normalize(), point, sigma: (0.002, 0.02) }
            })
            .collect()
    }

    #[test]
    fn four_dof_is_exact_on_exact_rays() {
        for yaw in [-170.0f64, -30.0, 0.0, 45.0, 179.0] {
            let truth = Hypothesis { rotation: yaw_matrix(yaw.to_radians()), translation: V3::new(4.0, -0.3, -7.5) };
            let h = solve_four_dof(&rays(&truth, false)[..3]).unwrap();
            assert!((h.rotation - truth.rotation).norm() < 1e-6, "yaw {yaw}");
            assert!((h.translation - truth.translation).norm() < 1e-5, "yaw {yaw}: {}", h.translation);
        }
    }

    #[test]
    fn six_dof_is_exact_on_exact_rays_for_moving_and_static_cameras() {
        let truth =
            Hypothesis { rotation: exp_rotation(&V3::new(0.4, -2.0, 0.3)), translation: V3::new(-2.0, 0.5, 3.0) };
        for static_camera in [false, true] {
            let h = solve_six_dof(&rays(&truth, static_camera)).unwrap();
            assert!((h.rotation - truth.rotation).norm() < 1e-7, "static {static_camera}");
            assert!((h.translation - truth.translation).norm() < 1e-6, "static {static_camera}: {}", h.translation);
        }
    }
}
