//! Registering a capture's participants into one world: the anchor's (the first
//! participant's, or one named).
//!
//! Participants whose placement says their world is the capture's form one world together;
//! every participant in a world of its own is another (with `force`, every participant is). A
//! camera of one world seeing a reconstructed participant of another links the two:
//! [`register_graph`] registers each link alone, places every world through the
//! best-determined links from the anchor's and refines all of them jointly, so that cycles (A
//! sees B, B sees A, C sees both) agree. Views without identity link too: each frame's best
//! fitting person is used.

use egoexo_core::ego_features::TrackingMode;
use egoexo_core::rigid::RigidTransform;
use egoexo_infer::Engine;
use egoexo_infer::plan::resolve_tracking;
use egoexo_session::align::{AlignOptions, align};
use egoexo_session::capture::{Capture, ViewPeople};
use egoexo_session::placement::{ClockRef, Placement, RegistrationRecord, WorldRef};
use egoexo_solve::registration::graph::{GraphEdge, register_graph};
use egoexo_solve::registration::{Dof, NodeSpec, Registration, RegistrationStatus, TargetTrack, check_agreement};
use serde::{Deserialize, Serialize};

use crate::tracks::{frames_seen_at, target_track, view_track};
use crate::{
    Outcome, RegisterError, RegisterMode, RegisterSettings, camera_with_focal, clock_offset_ns, move_trajectory,
    registered_placement, shift_streams, shift_times,
};

/// One participant's registration step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParticipantReport {
    pub id: String,
    pub outcome: Outcome,
    /// Its world's registration into the anchor's (`None`: nothing was solved for it).
    pub registration: Option<Registration>,
    pub message: String,
}

/// One camera's view of one participant of another world, registered alone:
/// `T_targetworld_observerworld`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairReport {
    pub observer: String,
    pub target: String,
    pub registration: Registration,
}

/// The registration step of a capture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CaptureRegistration {
    pub mode: RegisterMode,
    pub anchor: String,
    pub participants: Vec<ParticipantReport>,
    pub pairs: Vec<PairReport>,
    /// Windows EgoNet ran on for the coarse bodies, over every participant seen.
    pub coarse_windows: usize,
}

/// Registers `capture`'s participants into `anchor`'s world (index; the first by default)
/// per `settings`, in place (see the module docs). `tracking`: as the reconstruction's
/// (`None`: per participant from their devices).
pub fn register_capture(
    engine: Option<&Engine>,
    tracking: Option<TrackingMode>,
    capture: &mut Capture,
    anchor: usize,
    settings: &RegisterSettings,
) -> Result<CaptureRegistration, RegisterError> {
    let n = capture.participants.len();
    let anchor_id = capture.participants.get(anchor).map(|p| p.id.clone()).unwrap_or_default();
    let mut report = CaptureRegistration {
        mode: settings.mode,
        anchor: anchor_id,
        participants: Vec::new(),
        pairs: Vec::new(),
        coarse_windows: 0,
    };
    if settings.mode == RegisterMode::Off || n < 2 {
        report.participants =
            (0..n).filter(|&p| p != anchor).map(|p| untouched(capture, p, "registration off")).collect();
        return Ok(report);
    }
    let origin = capture.participants.iter().filter_map(|p| p.head.timestamps_ns.first().copied()).min().unwrap_or(0);

    // The wearers' tracks: every reconstructed participant some camera sees.
    let mut tracks: Vec<Option<TargetTrack>> = vec![None; n];
    for target in capture.reconstructed().collect::<Vec<_>>() {
        let target_id = capture.participants[target].id.clone();
        let seen_by: Vec<(Vec<i64>, bool)> = capture
            .views
            .iter()
            .filter(|v| v.observer != target_id && seen_in(&v.people, &target_id))
            .filter_map(|v| {
                let observer = capture.participants.iter().find(|p| p.id == v.observer)?;
                Some((view_times(&v.people).to_vec(), observer.placement.clock == ClockRef::Own))
            })
            .collect();
        if seen_by.is_empty() {
            continue;
        }
        let session = capture.session_for(target)?;
        let aligned = align(&session, &AlignOptions::default())?;
        let wanted = frames_seen_at(&aligned.timeline, &seen_by, settings.own_clock_search_s);
        let coarse = match engine {
            Some(engine) => {
                let tracking = resolve_tracking(&aligned, tracking)?;
                let coarse = engine.coarse_body(&aligned, tracking, settings.coarse_windows, &|f| wanted[f])?;
                report.coarse_windows += coarse.windows;
                Some(coarse)
            }
            None => None,
        };
        tracks[target] = Some(
            target_track(&aligned, coarse.as_ref(), origin)
                .map_err(|source| RegisterError::Solve { observer: target_id.clone(), source })?,
        );
    }

    // Worlds: the capture's shared one, and one per participant on its own.
    let shared_world = |p: usize| {
        let placement = &capture.participants[p].placement;
        settings.mode != RegisterMode::Force
            && placement.world == WorldRef::Shared
            && placement.clock == ClockRef::Shared
    };
    let mut node_of = vec![usize::MAX; n];
    let mut members: Vec<Vec<usize>> = Vec::new();
    for p in 0..n {
        if shared_world(p)
            && let Some(node) = (0..p).find(|&q| shared_world(q)).map(|q| node_of[q])
        {
            node_of[p] = node;
            members[node].push(p);
            continue;
        }
        node_of[p] = members.len();
        members.push(vec![p]);
    }

    // The links: each camera's view of each reconstructed participant of another world.
    let mut edges = Vec::new();
    let mut edge_ids = Vec::new();
    let mut same_world_views = Vec::new();
    for view in &capture.views {
        let Some(o) = capture.participants.iter().position(|p| p.id == view.observer) else { continue };
        let observer = &capture.participants[o];
        let Some(camera) = &observer.camera else { continue };
        for (target, track) in tracks.iter().enumerate() {
            let Some(track) = track else { continue };
            let target_id = &capture.participants[target].id;
            if target == o || !seen_in(&view.people, target_id) {
                continue;
            }
            let times = view_times(&view.people);
            let people = |i: usize| match &view.people {
                ViewPeople::Assigned { keypoints, .. } => vec![keypoints.frames[i]],
                ViewPeople::Unassigned(people) => people.frames[i].clone(),
            };
            let track_view = view_track(&observer.head, camera, &observer.placement, times, people, origin);
            if node_of[o] == node_of[target] {
                same_world_views.push((o, target, track_view, track.clone()));
            } else {
                edge_ids.push((o, target));
                edges.push(GraphEdge {
                    observer: node_of[o],
                    target: node_of[target],
                    view: track_view,
                    track: track.clone(),
                });
            }
        }
    }

    // One shared world whose views agree with it: nothing to solve.
    if members.len() == 1 {
        for (o, target, view, track) in &same_world_views {
            let agreement = check_agreement(track, view, &RigidTransform::IDENTITY, &settings.options)
                .map_err(|source| RegisterError::Solve { observer: capture.participants[*o].id.clone(), source })?;
            if !agreement.agrees && !agreement.undetermined {
                // The capture's claim of one world is contradicted: register everyone.
                let forced = RegisterSettings { mode: RegisterMode::Force, ..settings.clone() };
                let mut result = register_capture(engine, tracking, capture, anchor, &forced)?;
                result.mode = settings.mode;
                for p in &mut result.participants {
                    p.message = format!(
                        "{} sees {} away from where the capture's one world puts them; {}",
                        capture.participants[*o].id, capture.participants[*target].id, p.message
                    );
                }
                return Ok(result);
            }
        }
        report.participants =
            (0..n).filter(|&p| p != anchor).map(|p| untouched(capture, p, "one world, views agree")).collect();
        return Ok(report);
    }

    let specs: Vec<NodeSpec> = members
        .iter()
        .map(|m| {
            let first = &capture.participants[m[0]];
            let pinhole =
                first.camera.is_some_and(|c| matches!(c.projection, egoexo_core::camera::Projection::Pinhole(_)));
            NodeSpec {
                dof: if m.iter().all(|&p| capture.participants[p].placement.gravity) { Dof::Four } else { Dof::Six },
                fixed: false,
                clock: m.iter().any(|&p| capture.participants[p].placement.clock == ClockRef::Own),
                focal: m.len() == 1 && !first.placement.focal_known && pinhole,
            }
        })
        .collect();
    let options = egoexo_solve::registration::RegisterOptions {
        clock_search_s: if specs.iter().any(|s| s.clock) { settings.own_clock_search_s } else { 0.0 },
        ..settings.options.clone()
    };
    let graph = register_graph(&specs, node_of[anchor], &edges, &options)
        .map_err(|source| RegisterError::Solve { observer: report.anchor.clone(), source })?;
    report.pairs = edge_ids
        .iter()
        .zip(&graph.edges)
        .map(|(&(o, t), r)| PairReport {
            observer: capture.participants[o].id.clone(),
            target: capture.participants[t].id.clone(),
            registration: r.clone(),
        })
        .collect();

    for (node, result) in graph.nodes.iter().enumerate() {
        let registration = &result.registration;
        for &p in &members[node] {
            let participant = &mut capture.participants[p];
            let id = participant.id.clone();
            if node == node_of[anchor] {
                if p != anchor {
                    report.participants.push(ParticipantReport {
                        id,
                        outcome: Outcome::Kept,
                        registration: None,
                        message: format!("in the anchor's world ({})", report.anchor),
                    });
                }
                continue;
            }
            let outcome = if registration.status == RegistrationStatus::Registered {
                let offset_ns = clock_offset_ns(registration);
                move_trajectory(&mut participant.head, &registration.transform, offset_ns);
                for wrist in [&mut participant.left_wrist, &mut participant.right_wrist].into_iter().flatten() {
                    move_trajectory(wrist, &registration.transform, offset_ns);
                }
                shift_streams(&mut participant.video, &mut participant.context_features, offset_ns);
                if let Some(camera) = &participant.camera {
                    participant.camera = Some(camera_with_focal(camera, registration, &id)?);
                }
                participant.placement = registered_placement(&participant.placement, registration);
                for view in capture.views.iter_mut().filter(|v| v.observer == id) {
                    match &mut view.people {
                        ViewPeople::Assigned { keypoints, .. } => shift_times(&mut keypoints.timestamps_ns, offset_ns),
                        ViewPeople::Unassigned(people) => shift_times(&mut people.timestamps_ns, offset_ns),
                    }
                }
                Outcome::Registered
            } else {
                participant.placement = Placement {
                    world: WorldRef::Own,
                    registration: Some(RegistrationRecord { result: registration.clone(), applied: false }),
                    ..participant.placement.clone()
                };
                Outcome::LeftOut
            };
            let message = match outcome {
                Outcome::Registered => egoexo_session::placement::describe_registration(registration, true),
                _ => format!("its own world, not fused: {} — {}", registration.status, registration.reason),
            };
            report.participants.push(ParticipantReport {
                id,
                outcome,
                registration: Some(registration.clone()),
                message,
            });
        }
    }
    report.participants.sort_by_key(|r| capture.participants.iter().position(|p| p.id == r.id));
    Ok(report)
}

fn untouched(capture: &Capture, p: usize, why: &str) -> ParticipantReport {
    let participant = &capture.participants[p];
    let shared = participant.placement.fusable();
    ParticipantReport {
        id: participant.id.clone(),
        outcome: if shared { Outcome::Kept } else { Outcome::LeftOut },
        registration: None,
        message: if shared {
            format!("as given ({why})")
        } else {
            format!("not fused: {} ({why})", participant.placement.describe())
        },
    }
}

/// Whether `people` may hold participant `target`: assigned to them, or unidentified.
fn seen_in(people: &ViewPeople, target: &str) -> bool {
    match people {
        ViewPeople::Assigned { target: t, keypoints } => t == target && !keypoints.frames.is_empty(),
        ViewPeople::Unassigned(people) => !people.frames.is_empty(),
    }
}

fn view_times(people: &ViewPeople) -> &[i64] {
    match people {
        ViewPeople::Assigned { keypoints, .. } => &keypoints.timestamps_ns,
        ViewPeople::Unassigned(people) => &people.timestamps_ns,
    }
}
