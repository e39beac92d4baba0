//! Registration speed, and this crate's Levenberg–Marquardt driver against the
//! `levenberg-marquardt` crate on the same problem.
//!
//! - `register/<seconds>s`: the whole solver (RANSAC starts, robust fit, covariance, verdict)
//!   on a synthetic observer that sees a walking wearer for 10, 60 and 600 seconds at 30 fps
//!   (frames beyond `max_frames` are subsampled evenly).
//! - `driver/*`: one robust 4-DoF fit of bearings (300 frames × 17 keypoints, Cauchy weights
//!   held fixed) from the same start, by this crate's dense normal equations and by the
//!   `levenberg-marquardt` crate (QR of the whole 10 200 × 4 Jacobian per iteration).

use criterion::{Criterion, criterion_group, criterion_main};
use egoexo_core::camera::aria_rgb;
use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_solve::geometry::{V3, yaw_matrix, yaw_matrix_derivative};
use egoexo_solve::lsq::{LeastSquaresProblem, LmOptions, NormalEquations, levenberg_marquardt};
use egoexo_solve::registration::{RegisterOptions, TargetPoint, TargetTrack, ViewFrame, ViewTrack, register};
use nalgebra::{DMatrix, DVector, Dyn, Owned};

/// A wearer walking a 1.5 m circle with a body of 17 points; a static-standing observer at
/// 4 m following them; the observer's world yawed by 60° and moved 5 m.
fn scene(seconds: f64) -> (TargetTrack, ViewTrack) {
    let camera = aria_rgb::camera(1408).expect("Aria RGB preset");
    let fps = 30.0;
    let frames = (seconds * fps) as usize;
    let body = |t: f64| -> [Vec3; COCO17_COUNT] {
        let a = 0.5 * t;
        let head = Vec3::new((1.5 * a.cos()) as f32, 1.6, (1.5 * a.sin()) as f32);
        let yaw = Quat::from_rotation_y((-a.sin()).atan2(a.cos()) as f32 + 0.4 * (0.7 * t).sin() as f32);
        std::array::from_fn(|k| {
            let side = if k % 2 == 1 { 1.0 } else { -1.0 };
            let level = [
                0.0, 0.02, 0.02, 0.0, 0.0, -0.3, -0.3, -0.58, -0.58, -0.84, -0.84, -0.8, -0.8, -1.22, -1.22, -1.62,
                -1.62,
            ][k];
            let lateral = if k == 0 {
                0.0
            } else if k < 5 {
                0.05
            } else {
                0.18
            };
            head + yaw * Vec3::new(side * lateral, level, if k < 3 { 0.08 } else { -0.05 })
        })
    };
    let times: Vec<f64> = (0..frames).map(|i| i as f64 / fps).collect();
    let points = times
        .iter()
        .map(|&t| {
            body(t).map(|p| Some(TargetPoint { position: V3::new(p.x.into(), p.y.into(), p.z.into()), sigma_m: 0.05 }))
        })
        .collect();
    let track = TargetTrack::new(times.clone(), points).expect("track");
    let x_inv = RigidTransform::new(Quat::from_rotation_y(1.05), Vec3::new(5.0, 0.0, -2.0)).inverse();
    let eye = Vec3::new(4.0, 1.65, 0.3);
    let view_frames = times
        .iter()
        .map(|&t| {
            let p = body(t);
            let z = ((p[5] + p[6]) * 0.5 - eye).normalize();
            let x = -Vec3::Y.cross(z).normalize();
            let pose = RigidTransform::from_rotation_matrix(egoexo_core::glam::Mat3::from_cols(x, z.cross(x), z), eye);
            let keypoints = p.map(|q| {
                camera.project(pose.inverse().transform_point(q)).map(|pixel| Keypoint2d { pixel, score: 0.9 })
            });
            ViewFrame { time_s: t, t_world_camera: x_inv * pose, people: vec![keypoints] }
        })
        .collect();
    (track, ViewTrack { camera, estimate_focal: false, frames: view_frames })
}

/// A 4-DoF bearing fit (yaw, translation) with fixed Cauchy-like weights.
struct BearingFit {
    rays: Vec<(V3, V3, V3)>, // camera centre, direction (own world), point (target world)
    weights: Vec<f64>,
    params: DVector<f64>,
}

impl BearingFit {
    fn new(track: &TargetTrack, view: &ViewTrack) -> Self {
        let mut rays = Vec::new();
        for frame in view.frames.iter().take(300) {
            let pose = egoexo_solve::geometry::isometry(&frame.t_world_camera);
            let Some(points) = track.sample(frame.time_s) else { continue };
            for (k, kp) in frame.people[0].iter().enumerate() {
                let (Some(kp), Some(p)) = (kp, points[k]) else { continue };
                let Some(b) = view.camera.unproject(kp.pixel) else { continue };
                let d = pose.rotation * V3::new(b.x.into(), b.y.into(), b.z.into());
                rays.push((pose.translation.vector, d, p.position));
            }
        }
        let weights = (0..rays.len()).map(|i| if i % 11 == 0 { 0.3 } else { 1.0 }).collect();
        Self { rays, weights, params: DVector::from_vec(vec![0.9, 4.8, 0.1, -1.8]) }
    }

    /// Residual (2) and its Jacobian (2 × 4) of ray `i` at `x`.
    fn ray(&self, i: usize, x: &DVector<f64>) -> ([f64; 2], [[f64; 4]; 2]) {
        let (c, d, p) = self.rays[i];
        let r = yaw_matrix(x[0]);
        let t = V3::new(x[1], x[2], x[3]);
        let v = r.transpose() * (p - t) - c;
        let dv_dyaw = yaw_matrix_derivative(x[0]).transpose() * (p - t);
        let (e1, e2) = {
            let helper = if d.x.abs() < 0.9 { V3::x() } else { V3::y() };
            let e1 = d.cross(&helper).normalize();
            (e1, d.cross(&e1))
        };
        let z = d.dot(&v);
        let res = [e1.dot(&v) / z, e2.dot(&v) / z];
        let mut jac = [[0.0; 4]; 2];
        for (row, e) in [e1, e2].iter().enumerate() {
            let grad = (e - d * (e.dot(&v) / z)) / z; // d(e·v / d·v)/dv
            jac[row][0] = grad.dot(&dv_dyaw);
            for j in 0..3 {
                jac[row][1 + j] = -grad.dot(&r.transpose().column(j).into_owned());
            }
        }
        (res, jac)
    }
}

impl LeastSquaresProblem for BearingFit {
    type State = DVector<f64>;
    fn dimension(&self) -> usize {
        4
    }
    fn linearize(&self, x: &DVector<f64>) -> NormalEquations {
        let mut n = NormalEquations::new(4, 0);
        for i in 0..self.rays.len() {
            let (r, j) = self.ray(i, x);
            let w = self.weights[i];
            n.cost += w * (r[0] * r[0] + r[1] * r[1]);
            let columns: Vec<(usize, [f64; 2])> = (0..4).map(|c| (c, [j[0][c], j[1][c]])).collect();
            n.add_residual2(r, &columns, w, None);
        }
        n
    }
    fn retract(&self, x: &DVector<f64>, step: &DVector<f64>) -> DVector<f64> {
        x + step
    }
}

impl levenberg_marquardt::LeastSquaresProblem<f64, Dyn, Dyn> for BearingFit {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;
    fn set_params(&mut self, x: &DVector<f64>) {
        self.params.copy_from(x);
    }
    fn params(&self) -> DVector<f64> {
        self.params.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        let mut out = DVector::zeros(2 * self.rays.len());
        for i in 0..self.rays.len() {
            let (r, _) = self.ray(i, &self.params);
            let w = self.weights[i].sqrt();
            out[2 * i] = w * r[0];
            out[2 * i + 1] = w * r[1];
        }
        Some(out)
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let mut out = DMatrix::zeros(2 * self.rays.len(), 4);
        for i in 0..self.rays.len() {
            let (_, j) = self.ray(i, &self.params);
            let w = self.weights[i].sqrt();
            for c in 0..4 {
                out[(2 * i, c)] = w * j[0][c];
                out[(2 * i + 1, c)] = w * j[1][c];
            }
        }
        Some(out)
    }
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("register");
    group.sample_size(10);
    for seconds in [10.0, 60.0, 600.0] {
        let (track, view) = scene(seconds);
        group.bench_function(format!("{seconds}s"), |b| {
            b.iter(|| register(&track, &view, &RegisterOptions::default()).expect("valid inputs"))
        });
    }
    group.finish();

    let (track, view) = scene(10.0);
    let problem = BearingFit::new(&track, &view);
    let ours = levenberg_marquardt(&problem, problem.params.clone(), &LmOptions::default());
    let (theirs, report) = levenberg_marquardt::LevenbergMarquardt::new().minimize(BearingFit::new(&track, &view));
    println!(
        "driver agreement: ours cost {:.6e} ({} linearisations) at {:?}, levenberg-marquardt {:.6e} ({} evaluations, {:?}); |Δx| {:.2e}",
        ours.cost,
        ours.iterations,
        ours.state.as_slice(),
        2.0 * report.objective_function,
        report.number_of_evaluations,
        report.termination,
        (&ours.state - &theirs.params).norm()
    );
    let mut group = c.benchmark_group("driver");
    group.bench_function("dense-normal-equations", |b| {
        b.iter(|| levenberg_marquardt(&problem, problem.params.clone(), &LmOptions::default()))
    });
    group.bench_function("levenberg-marquardt-crate", |b| {
        b.iter(|| levenberg_marquardt::LevenbergMarquardt::new().minimize(BearingFit::new(&track, &view)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
