//! Robust least squares over bodies and cameras.
//!
//! - [`lsq`] — the Levenberg–Marquardt driver on dense normal equations (small problems:
//!   tens of unknowns, many residuals), with robust losses ([`robust`]) applied by
//!   iteratively reweighting, and the covariance of its solution (model-based and
//!   cluster-robust).
//! - [`dense`] — fixed-size Gauss–Newton algebra over a body's joints (cross and outer
//!   matrices, a Cholesky solve of a few unknowns without allocating), used by the CMU
//!   retargeting.
//! - [`geometry`] — the few f64 rotation helpers the solvers share (yaw about +Y, skew
//!   matrices, the nearest rotation), and conversions from the core's f32 types.
//! - [`registration`] — which transform (and clock offset, and focal length) puts an
//!   observer's world into the wearer's, from the observer camera's 2D keypoints of the
//!   wearer: RANSAC over frames for the start, the robust fit, its uncertainty and a verdict;
//!   and the joint refinement of several worlds that see each other ([`registration::graph`]).
//!
//! Conventions as the core's: metres, seconds, radians; Y-up worlds; `T_a_b` maps frame-b
//! points into frame a; camera optical frames are OpenCV/Aria (+X right, +Y down, +Z forward).
//! Nothing here does I/O, spawns threads or reads the clock: the same code runs in the
//! browser's worker. Numerics are f64 throughout.

pub mod dense;
pub mod geometry;
pub mod lsq;
pub mod registration;
pub mod robust;

pub use lsq::{LeastSquaresProblem, LmOptions, LmReport, NormalEquations, levenberg_marquardt};
pub use robust::RobustLoss;
