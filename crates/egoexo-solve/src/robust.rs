//! Robust losses of a whitened residual: `ρ(s)` of its squared norm `s = ‖r/σ‖²`. The
//! Gauss–Newton step weighs each residual by `ρ'(s)` (iteratively reweighted least squares),
//! so a residual far outside its noise pulls with a bounded force.

use serde::{Deserialize, Serialize};

/// A loss of the squared whitened residual norm.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RobustLoss {
    /// `ρ(s) = s`: plain least squares.
    Squared,
    /// Quadratic up to `scale` standard deviations, linear beyond.
    Huber { scale: f64 },
    /// `ρ(s) = c² ln(1 + s / c²)`: residuals beyond `scale` standard deviations count
    /// logarithmically (a redescending influence, for gross outliers).
    Cauchy { scale: f64 },
}

impl RobustLoss {
    /// `ρ(s)`, for `s ≥ 0`.
    pub fn cost(self, s: f64) -> f64 {
        match self {
            RobustLoss::Squared => s,
            RobustLoss::Huber { scale } => {
                let c2 = scale * scale;
                if s <= c2 { s } else { 2.0 * scale * s.sqrt() - c2 }
            }
            RobustLoss::Cauchy { scale } => {
                let c2 = scale * scale;
                c2 * (s / c2).ln_1p()
            }
        }
    }

    /// `ρ'(s)`: the weight of a residual with squared whitened norm `s` in the normal
    /// equations, in `(0, 1]`.
    pub fn weight(self, s: f64) -> f64 {
        match self {
            RobustLoss::Squared => 1.0,
            RobustLoss::Huber { scale } => {
                if s <= scale * scale {
                    1.0
                } else {
                    scale / s.sqrt()
                }
            }
            RobustLoss::Cauchy { scale } => 1.0 / (1.0 + s / (scale * scale)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn weights_are_the_derivative_of_the_cost() {
        for loss in [RobustLoss::Squared, RobustLoss::Huber { scale: 2.0 }, RobustLoss::Cauchy { scale: 2.5 }] {
            for s in [0.0, 0.3, 1.0, 3.9, 4.1, 20.0, 400.0] {
                let h = 1e-6;
                let numeric = (loss.cost(s + h) - loss.cost((s - h).max(0.0))) / (s + h - (s - h).max(0.0));
                assert!((numeric - loss.weight(s)).abs() < 1e-5, "{loss:?} at {s}: {numeric} vs {}", loss.weight(s));
            }
        }
    }

    #[test]
    fn robust_losses_bound_the_influence_of_outliers() {
        let cauchy = RobustLoss::Cauchy { scale: 2.0 };
        assert!(cauchy.weight(1e6) < 1e-5);
        assert!(cauchy.cost(1e6) < 100.0);
        assert_eq!(RobustLoss::Huber { scale: 1.0 }.weight(0.5), 1.0);
    }
}
