//! The Levenberg–Marquardt driver on dense normal equations.
//!
//! A problem accumulates `H = Σ wᵢ Jᵢᵀ Jᵢ` and `g = Σ wᵢ Jᵢᵀ rᵢ` over its (whitened) residuals
//! with their robust weights `wᵢ = ρ'(‖rᵢ‖²)` at the current state, and its cost `Σ ρ(‖rᵢ‖²)`;
//! the driver solves `(H + λ diag H) δ = −g`, keeps a step only when the cost falls
//! (so the result is never worse than the start on the problem's own objective), and moves λ.
//! The unknowns live on whatever manifold the problem likes: it maps a step onto its state
//! ([`LeastSquaresProblem::retract`]).
//!
//! Dense normal equations suit the problems here — at most a few tens of unknowns and up to
//! some 10⁵ residuals — better than a QR of the stacked Jacobian: the residuals are never
//! stored, and one pass over them builds the system (`benches/registration.rs` measures it
//! against the `levenberg-marquardt` crate, which factors the whole Jacobian).

use nalgebra::{DMatrix, DVector};

/// The Gauss–Newton system of a problem at one state.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalEquations {
    /// `Σ wᵢ Jᵢᵀ Jᵢ`.
    pub h: DMatrix<f64>,
    /// `Σ wᵢ Jᵢᵀ rᵢ`.
    pub g: DVector<f64>,
    /// `Σ ρ(‖rᵢ‖²)`.
    pub cost: f64,
    /// Per cluster of residuals that may err together (e.g. one second of frames), its share
    /// of `g`: the cluster-robust covariance's "meat".
    pub cluster_gradients: Vec<DVector<f64>>,
}

impl NormalEquations {
    /// An empty system of `n` unknowns and `clusters` clusters.
    pub fn new(n: usize, clusters: usize) -> Self {
        Self {
            h: DMatrix::zeros(n, n),
            g: DVector::zeros(n),
            cost: 0.0,
            cluster_gradients: vec![DVector::zeros(n); clusters],
        }
    }

    /// Number of unknowns.
    pub fn dimension(&self) -> usize {
        self.g.len()
    }

    /// Adds one 2-D whitened residual `r` with weight `w`, whose derivative by unknown
    /// `columns[i].0` is `columns[i].1`, in cluster `cluster`.
    pub fn add_residual2(&mut self, r: [f64; 2], columns: &[(usize, [f64; 2])], w: f64, cluster: Option<usize>) {
        for (a, (i, ji)) in columns.iter().enumerate() {
            let gi = w * (ji[0] * r[0] + ji[1] * r[1]);
            self.g[*i] += gi;
            if let Some(c) = cluster.and_then(|c| self.cluster_gradients.get_mut(c)) {
                c[*i] += gi;
            }
            for (j, jj) in &columns[a..] {
                let hij = w * (ji[0] * jj[0] + ji[1] * jj[1]);
                self.h[(*i, *j)] += hij;
                if i != j {
                    self.h[(*j, *i)] += hij;
                }
            }
        }
    }

    /// The covariance of the unknowns at a solution: the larger (by trace) of the
    /// model-based `H⁻¹` — right when the residuals are whitened by their true noise and
    /// independent — and the cluster-robust sandwich `H⁻¹ (Σ_c g_c g_cᵀ) H⁻¹ · C/(C−1)`,
    /// which stays honest when residuals within a cluster err together or the noise model is
    /// off. `None` when `H` is singular (an unknown the residuals do not determine).
    pub fn covariance(&self) -> Option<DMatrix<f64>> {
        let n = self.dimension();
        if n == 0 {
            return Some(DMatrix::zeros(0, 0));
        }
        let scale = self.h.diagonal().iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if scale <= 0.0 || !scale.is_finite() {
            return None;
        }
        // Conditioning check: a tiny pivot relative to the largest diagonal is an unknown the
        // data do not pin down.
        let h_inv = self.h.clone().cholesky()?.inverse();
        if h_inv.iter().any(|v| !v.is_finite()) || h_inv.diagonal().iter().any(|v| *v * scale > 1e12) {
            return None;
        }
        let clusters: Vec<&DVector<f64>> = self.cluster_gradients.iter().filter(|g| g.norm() > 0.0).collect();
        if clusters.len() < 4 {
            return Some(h_inv);
        }
        let mut meat = DMatrix::zeros(n, n);
        for g in &clusters {
            meat += *g * g.transpose();
        }
        let c = clusters.len() as f64;
        let sandwich = &h_inv * meat * &h_inv * (c / (c - 1.0));
        Some(if sandwich.trace() > h_inv.trace() { sandwich } else { h_inv })
    }
}

/// A robust least-squares problem.
pub trait LeastSquaresProblem {
    /// The unknowns (a vector, or rotations and more).
    type State: Clone;

    /// Number of unknowns (the length of a step).
    fn dimension(&self) -> usize;

    /// The normal equations (and cost) at `state`.
    fn linearize(&self, state: &Self::State) -> NormalEquations;

    /// `state` moved by `step` (length [`LeastSquaresProblem::dimension`]).
    fn retract(&self, state: &Self::State, step: &DVector<f64>) -> Self::State;
}

/// When the driver stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LmOptions {
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the cost by less than this fraction.
    pub cost_tolerance: f64,
    /// Stop when the step's norm falls below this.
    pub step_tolerance: f64,
    /// λ relative to the largest diagonal entry of `H` at the start.
    pub initial_lambda: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self { max_iterations: 60, cost_tolerance: 1e-10, step_tolerance: 1e-10, initial_lambda: 1e-4 }
    }
}

/// What the driver did.
#[derive(Clone, Debug)]
pub struct LmReport<S> {
    pub state: S,
    pub initial_cost: f64,
    pub cost: f64,
    /// Linearisations done (steps tried, and the start).
    pub iterations: usize,
    /// Stopped on a tolerance rather than the iteration limit.
    pub converged: bool,
    /// The normal equations at `state` (for its covariance).
    pub normal: NormalEquations,
}

/// Minimises `problem`'s cost from `initial`. Deterministic; every accepted step lowers the
/// cost, so `report.cost ≤ report.initial_cost`.
pub fn levenberg_marquardt<P: LeastSquaresProblem>(
    problem: &P,
    initial: P::State,
    options: &LmOptions,
) -> LmReport<P::State> {
    let n = problem.dimension();
    let mut state = initial;
    let mut normal = problem.linearize(&state);
    let initial_cost = normal.cost;
    let mut lambda = options.initial_lambda * normal.h.diagonal().iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
    let mut iterations = 1;
    let mut converged = false;
    while iterations < options.max_iterations && n > 0 {
        let mut damped = normal.h.clone();
        for i in 0..n {
            damped[(i, i)] += lambda * normal.h[(i, i)].max(1e-12);
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&(-&normal.g))) else {
            lambda *= 10.0;
            if lambda > 1e16 {
                break;
            }
            continue;
        };
        if step.norm() < options.step_tolerance {
            converged = true;
            break;
        }
        // Linearise the candidate at once (its cost comes with it): most steps are kept.
        let candidate = problem.retract(&state, &step);
        let linearised = problem.linearize(&candidate);
        iterations += 1;
        if linearised.cost.is_finite() && linearised.cost < normal.cost {
            let decrease = (normal.cost - linearised.cost) / normal.cost.max(1e-300);
            state = candidate;
            normal = linearised;
            lambda = (lambda / 9.0).max(1e-15);
            if decrease < options.cost_tolerance {
                converged = true;
                break;
            }
        } else {
            lambda *= 4.0;
            if lambda > 1e16 {
                converged = true;
                break;
            }
        }
    }
    LmReport { cost: normal.cost, state, initial_cost, iterations, converged, normal }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robust::RobustLoss;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    /// Fit `y = a·exp(b·x)` to points, some of them gross outliers.
    struct Exponential {
        points: Vec<(f64, f64)>,
        loss: RobustLoss,
    }

    impl Exponential {
        fn each(&self, x: &DVector<f64>, mut f: impl FnMut(usize, f64, [f64; 2])) {
            for (i, (px, py)) in self.points.iter().enumerate() {
                let e = (x[1] * px).exp();
                f(i, x[0] * e - py, [e, x[0] * px * e]);
            }
        }
    }

    impl LeastSquaresProblem for Exponential {
        type State = DVector<f64>;
        fn dimension(&self) -> usize {
            2
        }
        fn linearize(&self, x: &DVector<f64>) -> NormalEquations {
            let mut n = NormalEquations::new(2, self.points.len());
            self.each(x, |i, r, j| {
                let s = r * r;
                n.cost += self.loss.cost(s);
                n.add_residual2([r, 0.0], &[(0, [j[0], 0.0]), (1, [j[1], 0.0])], self.loss.weight(s), Some(i));
            });
            n
        }
        fn retract(&self, x: &DVector<f64>, step: &DVector<f64>) -> DVector<f64> {
            x + step
        }
    }

    fn points(outliers: bool) -> Vec<(f64, f64)> {
        (0..40)
            .map(|i| {
                let x = i as f64 / 10.0;
                let noise = 0.01 * ((i * 7919 % 13) as f64 / 13.0 - 0.5);
                let y = 2.0 * (0.5 * x).exp() + noise + if outliers && i % 7 == 3 { 5.0 } else { 0.0 };
                (x, y)
            })
            .collect()
    }

    #[test]
    fn fits_a_curve_and_never_ends_above_its_start() {
        let problem = Exponential { points: points(false), loss: RobustLoss::Squared };
        let report = levenberg_marquardt(&problem, DVector::from_vec(vec![1.0, 0.1]), &LmOptions::default());
        assert!(report.converged);
        assert!(report.cost <= report.initial_cost);
        assert!((report.state[0] - 2.0).abs() < 0.01 && (report.state[1] - 0.5).abs() < 0.01, "{}", report.state);
        let covariance = report.normal.covariance().unwrap();
        assert!(covariance[(0, 0)] > 0.0 && covariance[(1, 1)] > 0.0);
    }

    #[test]
    fn a_robust_loss_ignores_gross_outliers_that_squares_follow() {
        let start = DVector::from_vec(vec![1.0, 0.1]);
        let squared = Exponential { points: points(true), loss: RobustLoss::Squared };
        let cauchy = Exponential { points: points(true), loss: RobustLoss::Cauchy { scale: 0.1 } };
        let plain = levenberg_marquardt(&squared, start.clone(), &LmOptions::default()).state;
        let robust = levenberg_marquardt(&cauchy, start, &LmOptions::default()).state;
        assert!((plain[0] - 2.0).abs() > 0.1, "least squares follows the outliers: {plain}");
        assert!((robust[0] - 2.0).abs() < 0.02 && (robust[1] - 0.5).abs() < 0.01, "{robust}");
    }

    #[test]
    fn an_undetermined_unknown_has_no_covariance() {
        let mut n = NormalEquations::new(2, 0);
        n.add_residual2([1.0, 0.0], &[(0, [1.0, 0.0])], 1.0, None);
        assert!(n.covariance().is_none());
    }
}
