//! The robust fit of world transforms to what cameras saw: unknowns per world ("node") — its
//! rotation (yaw, or all three axes), translation, clock offset and, for a camera whose focal
//! length is estimated, its log focal scale — and residuals per keypoint: the angle between
//! where a camera saw it and where the target's body puts it, in the tangent plane of the
//! seen bearing, whitened by the detector's noise and the body point's own uncertainty.
//!
//! Every node `n` maps its world into the anchor's: `p_anchor = R_n p + t_n`, and its clock:
//! `t_anchor = t_n + clock_n`. An edge is one camera (of node `a`) looking at one body (of node
//! `b`): the body point at `t_b = t_cam + clock_a − clock_b` is carried `b → anchor → a →
//! camera`. Rotations move by left perturbations `R ← exp([δ]×) R` (about the anchor's axes;
//! a yaw-only node moves about +Y only). In each frame, the person and the left–right labelling
//! that fit best are used (detectors swap sides; a view may hold bystanders).

use egoexo_core::exo_keypoints::COCO17_MIRROR;
use nalgebra::DVector;
use serde::{Deserialize, Serialize};

use super::track::{PointAt, TargetTrack};
use super::view::PreparedView;
use crate::geometry::{M3, V3, exp_rotation};
use crate::lsq::{LeastSquaresProblem, NormalEquations};
use crate::robust::RobustLoss;

/// Degrees of freedom of a world's rotation against the anchor's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Dof {
    /// Both worlds are gravity-aligned (Y up): a yaw and a translation (MPS, WebXR).
    #[serde(rename = "4")]
    Four,
    /// No shared gravity: any rotation and a translation.
    #[serde(rename = "6")]
    Six,
}

impl Dof {
    /// Rotation unknowns.
    pub fn rotation_dims(self) -> usize {
        match self {
            Dof::Four => 1,
            Dof::Six => 3,
        }
    }

    /// 4 or 6.
    pub fn count(self) -> u8 {
        match self {
            Dof::Four => 4,
            Dof::Six => 6,
        }
    }
}

/// What is unknown about one world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeSpec {
    pub dof: Dof,
    /// The anchor (or any world held where it is).
    pub fixed: bool,
    /// Its clock is its own: the offset is estimated.
    pub clock: bool,
    /// Its camera's focal length is estimated.
    pub focal: bool,
}

/// One world's current transform into the anchor's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeState {
    pub rotation: M3,
    pub translation: V3,
    /// `t_anchor = t_node + clock_s`.
    pub clock_s: f64,
    /// The camera's focal length is its calibration's times `exp(log_focal)`.
    pub log_focal: f64,
}

impl NodeState {
    /// The anchor itself.
    pub fn identity() -> Self {
        Self { rotation: M3::identity(), translation: V3::zeros(), clock_s: 0.0, log_focal: 0.0 }
    }
}

/// One camera looking at one body.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Edge<'a> {
    /// The camera's node.
    pub observer: usize,
    /// The body's node.
    pub target: usize,
    pub view: &'a PreparedView,
    pub track: &'a TargetTrack,
}

/// Squared whitened residual charged to a keypoint the state cannot explain at all (behind the
/// camera, or no body point at that time): a gross outlier.
const UNEXPLAINED: f64 = 1e4;

/// The fit of several worlds to their edges.
#[derive(Debug)]
pub(crate) struct Problem<'a> {
    pub nodes: Vec<NodeSpec>,
    pub edges: Vec<Edge<'a>>,
    pub loss: RobustLoss,
    /// Column of each node's first unknown.
    offsets: Vec<Option<usize>>,
    dimension: usize,
    cluster_offsets: Vec<usize>,
    clusters: usize,
}

/// One keypoint's residual with its derivatives by the unknowns (at most 2 nodes × 8).
struct Residual {
    r: [f64; 2],
    columns: Vec<(usize, [f64; 2])>,
}

/// Per frame: the chosen person and labelling's cost, residuals (when derivatives were asked
/// for) and whitened errors.
pub(crate) struct FrameFit {
    pub cost: f64,
    /// Per keypoint of the chosen person: the whitened error `‖r/σ‖` and the raw angle (rad).
    pub errors: Vec<(f64, f64)>,
    residuals: Vec<(Residual, f64)>,
}

impl<'a> Problem<'a> {
    pub fn new(nodes: Vec<NodeSpec>, edges: Vec<Edge<'a>>, loss: RobustLoss) -> Self {
        let mut offsets = Vec::with_capacity(nodes.len());
        let mut dimension = 0;
        for n in &nodes {
            if n.fixed {
                offsets.push(None);
            } else {
                offsets.push(Some(dimension));
                dimension += n.dof.rotation_dims() + 3 + usize::from(n.clock) + usize::from(n.focal);
            }
        }
        let mut cluster_offsets = Vec::with_capacity(edges.len());
        let mut clusters = 0;
        for e in &edges {
            cluster_offsets.push(clusters);
            clusters += e.view.clusters;
        }
        Self { nodes, edges, loss, offsets, dimension, cluster_offsets, clusters }
    }

    /// Column of node `n`'s translation, clock and focal unknowns.
    fn columns_of(&self, n: usize) -> Option<(usize, usize, Option<usize>, Option<usize>)> {
        let start = self.offsets[n]?;
        let spec = &self.nodes[n];
        let t = start + spec.dof.rotation_dims();
        let clock = spec.clock.then_some(t + 3);
        let focal = spec.focal.then_some(t + 3 + usize::from(spec.clock));
        Some((start, t, clock, focal))
    }

    /// The best person and labelling of frame `f` of edge `e`.
    pub fn fit_frame(&self, state: &[NodeState], e: usize, f: usize, with_jacobian: bool) -> FrameFit {
        let edge = &self.edges[e];
        let frame = &edge.view.frames[f];
        let (a, b) = (&state[edge.observer], &state[edge.target]);
        let target_time = frame.time_s + a.clock_s - b.clock_s;
        let points = edge.track.sample(target_time);
        let mut best: Option<FrameFit> = None;
        for person in &frame.people {
            for mirrored in [false, true] {
                let mut fit = FrameFit { cost: 0.0, errors: Vec::new(), residuals: Vec::new() };
                for o in &person.observations {
                    let k = if mirrored { COCO17_MIRROR[o.k] } else { o.k };
                    // A keypoint the body has no point for (a face-only body) says nothing.
                    let Some(point) = points.as_ref().and_then(|p| p[k]) else { continue };
                    match self.residual(state, e, f, o, &point, with_jacobian) {
                        Some((res, sigma, angle)) => {
                            let s = (res.r[0] * res.r[0] + res.r[1] * res.r[1]) / (sigma * sigma);
                            fit.cost += self.loss.cost(s);
                            fit.errors.push((s.sqrt(), angle));
                            if with_jacobian {
                                fit.residuals.push((res, sigma));
                            }
                        }
                        None => {
                            fit.cost += self.loss.cost(UNEXPLAINED);
                            fit.errors.push((UNEXPLAINED.sqrt(), std::f64::consts::PI));
                        }
                    }
                }
                if best.as_ref().is_none_or(|b| fit.cost < b.cost) {
                    best = Some(fit);
                }
            }
        }
        best.unwrap_or(FrameFit { cost: 0.0, errors: Vec::new(), residuals: Vec::new() })
    }

    /// One keypoint's residual (radians in the bearing's tangent plane, or normalised image
    /// coordinates for an estimated focal), its σ and the raw angle; `None` when the point is
    /// behind the camera or too close to it.
    fn residual(
        &self,
        state: &[NodeState],
        e: usize,
        f: usize,
        o: &super::view::Observation,
        point: &PointAt,
        with_jacobian: bool,
    ) -> Option<(Residual, f64, f64)> {
        let edge = &self.edges[e];
        let frame = &edge.view.frames[f];
        let (a, b) = (&state[edge.observer], &state[edge.target]);
        let p_anchor = b.rotation * point.position + b.translation;
        let v = p_anchor - a.translation;
        let p_own = a.rotation.transpose() * v;
        let rc_t = frame.rotation.transpose();
        let q = rc_t * (p_own - frame.centre);
        let distance = q.norm();
        if distance.is_nan() || distance <= 0.05 {
            return None;
        }
        let view = edge.view;
        let mut sigma_point = point.sigma_m / distance;
        // With an estimated focal, the residual is the image error in the starting focal's
        // normalised units (pixels / f₀), whatever focal the state has: the detector's noise is
        // in pixels. (Measured in the state's own normalised units, the errors shrink as the
        // focal grows, and a camera infinitely far away with an infinitely long lens fits every
        // view perfectly.) `focal_column`: dr/d(log focal).
        let mut focal_column = [0.0; 2];
        // r = g(q); dr/dq as two rows.
        let (r, dr_dq, angle) = if view.focal_estimated.is_some() {
            if q.z < 0.1 * distance {
                return None;
            }
            let zoom = a.log_focal.exp();
            let (x, y) = (q.x / q.z, q.y / q.z);
            let r = [zoom * x - o.normalised[0], zoom * y - o.normalised[1]];
            focal_column = [zoom * x, zoom * y];
            sigma_point *= zoom;
            let rows = [
                V3::new(zoom / q.z, 0.0, -zoom * q.x / (q.z * q.z)),
                V3::new(0.0, zoom / q.z, -zoom * q.y / (q.z * q.z)),
            ];
            let bearing = V3::new(o.normalised[0] / zoom, o.normalised[1] / zoom, 1.0).normalize();
            (r, rows, (q / distance).dot(&bearing).clamp(-1.0, 1.0).acos())
        } else {
            let p = o.basis * q;
            if p.z < 0.1 * distance {
                return None;
            }
            let r = [p.x / p.z, p.y / p.z];
            let rows = [
                o.basis.transpose() * V3::new(1.0 / p.z, 0.0, -p.x / (p.z * p.z)),
                o.basis.transpose() * V3::new(0.0, 1.0 / p.z, -p.y / (p.z * p.z)),
            ];
            (r, rows, (p.z / distance).clamp(-1.0, 1.0).acos())
        };
        let sigma = (view.sigma_detector_rad.powi(2) + sigma_point.powi(2)).sqrt();
        let mut columns = Vec::new();
        if with_jacobian {
            let push = |columns: &mut Vec<(usize, [f64; 2])>, col: usize, dq: V3| {
                columns.push((col, [dr_dq[0].dot(&dq), dr_dq[1].dot(&dq)]));
            };
            let ra_t = a.rotation.transpose();
            // dq/dp_own = R_cᵀ.
            if let Some((rot, t, clock, focal)) = self.columns_of(edge.observer) {
                // p_own = R_aᵀ v; R_a ← exp(δ)R_a: dp_own/dδ = R_aᵀ [v]×.
                let d_rot = ra_t * crate::geometry::skew(&v);
                match self.nodes[edge.observer].dof {
                    Dof::Four => push(&mut columns, rot, rc_t * d_rot.column(1)),
                    Dof::Six => {
                        for i in 0..3 {
                            push(&mut columns, rot + i, rc_t * d_rot.column(i));
                        }
                    }
                }
                for i in 0..3 {
                    push(&mut columns, t + i, -(rc_t * ra_t.column(i)));
                }
                if let Some(c) = clock {
                    push(&mut columns, c, rc_t * ra_t * b.rotation * point.velocity);
                }
                if let Some(fc) = focal {
                    columns.push((fc, focal_column));
                }
            }
            if let Some((rot, t, clock, _)) = self.columns_of(edge.target) {
                // p_anchor = R_b p + t_b; R_b ← exp(δ)R_b: dp_anchor/dδ = −[R_b p]×.
                let d_rot = -(ra_t * crate::geometry::skew(&(b.rotation * point.position)));
                match self.nodes[edge.target].dof {
                    Dof::Four => push(&mut columns, rot, rc_t * d_rot.column(1)),
                    Dof::Six => {
                        for i in 0..3 {
                            push(&mut columns, rot + i, rc_t * d_rot.column(i));
                        }
                    }
                }
                for i in 0..3 {
                    push(&mut columns, t + i, rc_t * ra_t.column(i));
                }
                if let Some(c) = clock {
                    push(&mut columns, c, -(rc_t * ra_t * b.rotation * point.velocity));
                }
            }
        }
        Some((Residual { r, columns }, sigma, angle))
    }

    /// The total cost, with the normal equations accumulated into `normal`.
    fn evaluate(&self, state: &[NodeState], normal: &mut NormalEquations) -> f64 {
        let mut cost = 0.0;
        for (e, edge) in self.edges.iter().enumerate() {
            for f in 0..edge.view.frames.len() {
                let fit = self.fit_frame(state, e, f, true);
                cost += fit.cost;
                let cluster = self.cluster_offsets[e] + edge.view.frames[f].cluster;
                for (res, sigma) in &fit.residuals {
                    let s = (res.r[0] * res.r[0] + res.r[1] * res.r[1]) / (sigma * sigma);
                    let w = self.loss.weight(s);
                    let inv = 1.0 / sigma;
                    let columns: Vec<(usize, [f64; 2])> =
                        res.columns.iter().map(|(c, d)| (*c, [d[0] * inv, d[1] * inv])).collect();
                    normal.add_residual2([res.r[0] * inv, res.r[1] * inv], &columns, w, Some(cluster));
                }
            }
        }
        cost
    }
}

impl LeastSquaresProblem for Problem<'_> {
    type State = Vec<NodeState>;

    fn dimension(&self) -> usize {
        self.dimension
    }

    fn linearize(&self, state: &Vec<NodeState>) -> NormalEquations {
        let mut normal = NormalEquations::new(self.dimension, self.clusters);
        normal.cost = self.evaluate(state, &mut normal);
        normal
    }

    fn retract(&self, state: &Vec<NodeState>, step: &DVector<f64>) -> Vec<NodeState> {
        let mut next = state.clone();
        for (n, node) in next.iter_mut().enumerate() {
            let Some((rot, t, clock, focal)) = self.columns_of(n) else { continue };
            let omega = match self.nodes[n].dof {
                Dof::Four => V3::new(0.0, step[rot], 0.0),
                Dof::Six => V3::new(step[rot], step[rot + 1], step[rot + 2]),
            };
            node.rotation = exp_rotation(&omega) * node.rotation;
            node.translation += V3::new(step[t], step[t + 1], step[t + 2]);
            if let Some(c) = clock {
                node.clock_s += step[c];
            }
            if let Some(fc) = focal {
                node.log_focal += step[fc];
            }
        }
        next
    }
}

/// A frame whose keypoints lie within this angle of the body (median) is explained whatever
/// the assumed detector noise: detectors on real images (and older simulations) are noisier
/// on a distant face than the nominal 3 px, and a wrong world is off by far more.
pub(crate) const INLIER_ANGLE_FLOOR_RAD: f64 = 1.0 * std::f64::consts::PI / 180.0;

/// Per-frame statistics of a state: how many frames of each edge the body explains.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct FitStatistics {
    /// Frames (of the edge) whose median whitened keypoint error is under the threshold.
    pub inlier_frames: Vec<usize>,
    /// Frames with any keypoint the body has a point for (the others say nothing either way:
    /// a face-only body seen from behind).
    pub usable_frames: usize,
    /// Median angle (radians) over the inlier frames' keypoints.
    pub median_angle_rad: f64,
}

impl Problem<'_> {
    /// Which frames of edge `e` the state explains: a frame whose chosen person's median
    /// whitened error is below `threshold`, or whose median angle is below
    /// [`INLIER_ANGLE_FLOOR_RAD`].
    pub fn statistics(&self, state: &[NodeState], e: usize, threshold: f64) -> FitStatistics {
        let mut inliers = Vec::new();
        let mut angles = Vec::new();
        let mut usable_frames = 0;
        for f in 0..self.edges[e].view.frames.len() {
            let fit = self.fit_frame(state, e, f, false);
            if fit.errors.is_empty() {
                continue;
            }
            usable_frames += 1;
            let mut whitened: Vec<f64> = fit.errors.iter().map(|(w, _)| *w).collect();
            whitened.sort_by(f64::total_cmp);
            let mut angle: Vec<f64> = fit.errors.iter().map(|(_, a)| *a).collect();
            angle.sort_by(f64::total_cmp);
            if whitened[whitened.len() / 2] < threshold || angle[angle.len() / 2] < INLIER_ANGLE_FLOOR_RAD {
                inliers.push(f);
                angles.extend(fit.errors.iter().map(|(_, a)| *a));
            }
        }
        angles.sort_by(f64::total_cmp);
        FitStatistics {
            median_angle_rad: angles.get(angles.len() / 2).copied().unwrap_or(f64::NAN),
            inlier_frames: inliers,
            usable_frames,
        }
    }
}
