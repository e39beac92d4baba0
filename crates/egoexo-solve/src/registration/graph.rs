//! Several worlds registered together: the worlds of a capture's participants (each pair of
//! Aria glasses processed alone has its own), linked by whoever's camera sees whom.
//!
//! Every edge (a camera of world `a` seeing a body of world `b`) is first registered alone
//! ([`super::register`]); a spanning tree of the registered edges from the anchor, preferring
//! the best-determined, places every reachable world; then one robust fit over every edge
//! refines all the worlds at once, so that when the graph has cycles (A sees B, B sees A, C
//! sees both) the whole capture lands in one world: the anchor's.

use serde::{Deserialize, Serialize};

use super::problem::{Edge, NodeSpec, NodeState, Problem};
use super::view::PreparedView;
use super::{RegisterOptions, Registration, RegistrationError, RegistrationStatus, TargetTrack, ViewTrack};
use crate::geometry::{heading, rigid_transform};
use crate::lsq::{LmOptions, levenberg_marquardt};

/// One camera seeing one body, between two worlds of the graph.
#[derive(Clone, Debug)]
pub struct GraphEdge {
    /// The camera's world.
    pub observer: usize,
    /// The body's world.
    pub target: usize,
    pub view: ViewTrack,
    pub track: TargetTrack,
}

/// A world's place after the joint fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NodeResult {
    /// The world's registration into the anchor's (the anchor: as given).
    pub registration: Registration,
    /// The edges whose pairwise registration placed it (the spanning tree's path).
    pub path: Vec<usize>,
}

/// The graph's outcome.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GraphResult {
    /// Per world, its transform into the anchor's world.
    pub nodes: Vec<NodeResult>,
    /// Per edge, the pairwise registration (`T_targetworld_observerworld`).
    pub edges: Vec<Registration>,
}

/// Registers every world of the graph into `anchor`'s. `nodes[n]` says what is unknown about
/// world `n` (`fixed` is ignored: the anchor is held, the others are solved).
pub fn register_graph(
    nodes: &[NodeSpec],
    anchor: usize,
    edges: &[GraphEdge],
    options: &RegisterOptions,
) -> Result<GraphResult, RegistrationError> {
    if anchor >= nodes.len() {
        return Err(RegistrationError::BadAnchor { anchor, nodes: nodes.len() });
    }
    for (i, e) in edges.iter().enumerate() {
        for node in [e.observer, e.target] {
            if node >= nodes.len() {
                return Err(RegistrationError::BadEdge { edge: i, node, nodes: nodes.len() });
            }
        }
    }
    let prepared: Vec<PreparedView> = edges
        .iter()
        .map(|e| PreparedView::new(&e.view, options.min_score, options.pixel_noise_px, options.max_frames))
        .collect::<Result<_, _>>()?;
    // Pairwise: each edge's observer world into its target world.
    let pairwise: Vec<Registration> = edges
        .iter()
        .zip(&prepared)
        .map(|(e, view)| {
            let spec = nodes[e.observer];
            let pair_options = RegisterOptions {
                dof: if spec.dof == super::Dof::Six || nodes[e.target].dof == super::Dof::Six {
                    super::Dof::Six
                } else {
                    super::Dof::Four
                },
                clock_search_s: if spec.clock || nodes[e.target].clock { options.clock_search_s.max(0.0) } else { 0.0 },
                ..options.clone()
            };
            if e.observer == e.target {
                Registration::as_given(
                    view.frames.len(),
                    0,
                    0.0,
                    0.0,
                    None,
                    "a camera of the target's own world".into(),
                )
            } else {
                super::register_prepared(&e.track, view, &pair_options)
            }
        })
        .collect();

    // Spanning tree from the anchor over registered edges, best-determined first (a
    // Dijkstra on the translation σ).
    let n = nodes.len();
    let mut placed: Vec<Option<(NodeState, f64, Vec<usize>)>> = vec![None; n];
    placed[anchor] = Some((NodeState::identity(), 0.0, Vec::new()));
    loop {
        let mut best: Option<(usize, NodeState, f64, Vec<usize>)> = None;
        for (i, (e, r)) in edges.iter().zip(&pairwise).enumerate() {
            if r.status != RegistrationStatus::Registered {
                continue;
            }
            let (rot, t) = super::transform_parts(r);
            let weight = r.sigma_translation_m.unwrap_or(1.0) + 0.05 * r.sigma_yaw_deg.unwrap_or(10.0);
            // T_b_a = (rot, t), clocks t_b = t_a + offset.
            let candidate = match (&placed[e.observer], &placed[e.target]) {
                (None, Some((b, cost, path))) => {
                    // X_a = X_b · T_b_a.
                    let state = NodeState {
                        rotation: b.rotation * rot,
                        translation: b.rotation * t + b.translation,
                        clock_s: b.clock_s + r.clock_offset_s,
                        log_focal: r.focal_px.map_or(0.0, |f| focal_scale(&e.view, f)),
                    };
                    Some((e.observer, state, cost + weight, path))
                }
                (Some((a, cost, path)), None) => {
                    // X_b = X_a · T_b_a⁻¹.
                    let inv_rot = rot.transpose();
                    let state = NodeState {
                        rotation: a.rotation * inv_rot,
                        translation: a.translation - a.rotation * inv_rot * t,
                        clock_s: a.clock_s - r.clock_offset_s,
                        log_focal: 0.0,
                    };
                    Some((e.target, state, cost + weight, path))
                }
                _ => None,
            };
            if let Some((node, state, cost, path)) = candidate
                && best.as_ref().is_none_or(|b| cost < b.2)
            {
                let mut path = path.clone();
                path.push(i);
                best = Some((node, state, cost, path));
            }
        }
        let Some((node, state, cost, path)) = best else { break };
        placed[node] = Some((state, cost, path));
    }

    // Joint refinement over every edge between placed worlds.
    let specs: Vec<NodeSpec> =
        nodes.iter().enumerate().map(|(i, s)| NodeSpec { fixed: i == anchor || placed[i].is_none(), ..*s }).collect();
    let joint_edges: Vec<Edge<'_>> = edges
        .iter()
        .zip(&prepared)
        .filter(|(e, _)| e.observer != e.target && placed[e.observer].is_some() && placed[e.target].is_some())
        .map(|(e, view)| Edge { observer: e.observer, target: e.target, view, track: &e.track })
        .collect();
    let problem = Problem::new(specs.clone(), joint_edges, options.loss);
    let start: Vec<NodeState> = placed.iter().map(|p| p.as_ref().map_or(NodeState::identity(), |p| p.0)).collect();
    let report = levenberg_marquardt(&problem, start, &LmOptions::default());
    let covariance = report.normal.covariance();

    let mut results = Vec::with_capacity(n);
    let mut column = 0;
    for (i, spec) in specs.iter().enumerate() {
        let dims = if spec.fixed {
            0
        } else {
            spec.dof.rotation_dims() + 3 + usize::from(spec.clock) + usize::from(spec.focal)
        };
        let registration = if i == anchor {
            Registration::as_given(0, 0, 0.0, 0.0, None, "the anchor: every other world is registered into it".into())
        } else if let Some((_, _, path)) = &placed[i] {
            let state = &report.state[i];
            let sigma = |j: usize| covariance.as_ref().map(|c| c[(column + j, column + j)].max(0.0).sqrt());
            let rot_dims = spec.dof.rotation_dims();
            let sigma_translation_m = covariance.as_ref().map(|c| {
                (0..3).map(|j| c[(column + rot_dims + j, column + rot_dims + j)]).sum::<f64>().max(0.0).sqrt()
            });
            let (sigma_yaw_deg, sigma_rotation_deg) = match spec.dof {
                super::Dof::Four => (sigma(0).map(f64::to_degrees), sigma(0).map(f64::to_degrees)),
                super::Dof::Six => (
                    sigma(1).map(f64::to_degrees),
                    covariance
                        .as_ref()
                        .map(|c| (0..3).map(|j| c[(column + j, column + j)]).sum::<f64>().max(0.0).sqrt().to_degrees()),
                ),
            };
            let sigma_clock_offset_s = spec.clock.then(|| sigma(rot_dims + 3)).flatten();
            let last = &pairwise[*path.last().unwrap_or(&0)];
            let limits = &options.limits;
            let within = sigma_yaw_deg.is_some_and(|s| s <= limits.max_sigma_yaw_deg)
                && sigma_translation_m.is_some_and(|s| s <= limits.max_sigma_translation_m);
            Registration {
                status: if within { RegistrationStatus::Registered } else { RegistrationStatus::NotEnoughMotion },
                dof: spec.dof,
                transform: rigid_transform(&state.rotation, &state.translation),
                yaw_deg: heading(&state.rotation).to_degrees(),
                clock_offset_s: state.clock_s,
                focal_px: last.focal_px,
                sigma_yaw_deg,
                sigma_rotation_deg,
                sigma_translation_m,
                sigma_clock_offset_s,
                sigma_focal_px: None,
                frames: path.iter().map(|&e| pairwise[e].frames).sum(),
                inlier_frames: path.iter().map(|&e| pairwise[e].inlier_frames).sum(),
                view_s: path.iter().map(|&e| pairwise[e].view_s).sum(),
                inlier_view_s: path.iter().map(|&e| pairwise[e].inlier_view_s).sum(),
                median_residual_deg: last.median_residual_deg,
                reason: format!(
                    "placed through {} view{} and refined jointly with every view between registered worlds",
                    path.len(),
                    if path.len() == 1 { "" } else { "s" }
                ),
            }
        } else {
            // Unreachable: the verdict of its best edge says why.
            let touching: Vec<&Registration> =
                edges.iter().zip(&pairwise).filter(|(e, _)| e.observer == i || e.target == i).map(|(_, r)| r).collect();
            let status = if touching.iter().any(|r| r.status == RegistrationStatus::Inconsistent) {
                RegistrationStatus::Inconsistent
            } else {
                RegistrationStatus::NotEnoughMotion
            };
            let reason = touching.iter().find(|r| r.status == status).map_or_else(
                || "no camera sees this world's people, and its camera sees no one else".into(),
                |r| r.reason.clone(),
            );
            Registration { status, dof: spec.dof, ..Registration::as_given(0, 0, 0.0, 0.0, None, reason) }
        };
        results.push(NodeResult { registration, path: placed[i].as_ref().map_or(Vec::new(), |p| p.2.clone()) });
        column += dims;
    }
    Ok(GraphResult { nodes: results, edges: pairwise })
}

/// The log focal scale of focal length `f` against the view's calibration.
fn focal_scale(view: &ViewTrack, f: f64) -> f64 {
    match view.camera.projection {
        egoexo_core::camera::Projection::Pinhole(k) => (f / f64::from(k.fx)).ln(),
        egoexo_core::camera::Projection::Fisheye624(_) => 0.0,
    }
}
