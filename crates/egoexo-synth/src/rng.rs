//! The simulator's random source: a seeded ChaCha8 stream, identical on every platform, with
//! the few distributions the simulator draws from.

use egoexo_core::glam::Vec3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Deterministic random numbers (same seed → same draws, natively and in wasm).
#[derive(Clone, Debug)]
pub struct SimRng(ChaCha8Rng);

impl SimRng {
    /// A stream for `seed`.
    pub fn new(seed: u64) -> Self {
        Self(ChaCha8Rng::seed_from_u64(seed))
    }

    /// An independent stream derived from this one (for a sub-simulation), so adding draws
    /// to one part of the simulator does not shift the others.
    pub fn fork(&mut self, label: u64) -> Self {
        let base: u64 = self.0.random();
        Self::new(base ^ label.wrapping_mul(0x9E37_79B9_7F4A_7C15))
    }

    /// Uniform in `[lo, hi)`; `lo` when the range is empty.
    pub fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        if hi > lo { self.0.random_range(lo..hi) } else { lo }
    }

    /// Normal with the given mean and standard deviation.
    pub fn normal(&mut self, mean: f32, sd: f32) -> f32 {
        let z: f32 = StandardNormal.sample(&mut self.0);
        mean + sd * z
    }

    /// A vector of three independent normals.
    pub fn normal_vec3(&mut self, sd: f32) -> Vec3 {
        Vec3::new(self.normal(0.0, sd), self.normal(0.0, sd), self.normal(0.0, sd))
    }

    /// True with probability `p` (clamped to [0, 1]).
    pub fn chance(&mut self, p: f32) -> bool {
        self.0.random_bool(f64::from(p.clamp(0.0, 1.0)))
    }

    /// Uniform integer in `[lo, hi]`.
    pub fn int(&mut self, lo: usize, hi: usize) -> usize {
        if hi > lo { self.0.random_range(lo..=hi) } else { lo }
    }

    /// A uniformly distributed unit vector.
    pub fn unit_vec3(&mut self) -> Vec3 {
        loop {
            let v = self.normal_vec3(1.0);
            if v.length() > 1e-3 {
                return v.normalize();
            }
        }
    }

    /// Exponentially distributed waiting time with the given mean.
    pub fn exponential(&mut self, mean: f32) -> f32 {
        -mean * (1.0 - self.uniform(0.0, 1.0)).max(1e-9).ln()
    }
}
