//! Everyone in the session, end to end on simulated group scenes: 2 and 3 participants who
//! walk and look at each other, bystanders crossing; every camera's detections come without
//! identity. Each participant's EgoNet pose (from their own devices) is projected into the
//! others' cameras, detections are associated, and each participant is reconstructed with the
//! others as observers — against ego-only and against the true identities. Prints the figures
//! the model card quotes (`cargo test -p egoexo-detect --test people -- --nocapture`).

use egoexo_core::TrackingMode;
use egoexo_core::association::AssociationOptions;
use egoexo_core::metrics::MetricsAccumulator;
use egoexo_detect::people::{CoarseParticipant, associate_views};
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;
use egoexo_infer::{Engine, Method, ReconstructOptions, Reconstruction};
use egoexo_session::capture::{Capture, View, ViewPeople};
use egoexo_session::model::KeypointTrack;
use egoexo_session::{AlignOptions, align};
use egoexo_synth::group::{GroupConfig, SimulatedCapture, group_walk, simulate_group};
use egoexo_test_support::workspace_root;

fn engine() -> Engine {
    let models = workspace_root().join("models");
    let manifest = Manifest::from_json(&std::fs::read(models.join("manifest.json")).unwrap()).unwrap();
    let set = ModelSet::load(manifest.model_set(TrackingMode::ThreePoint).unwrap(), |f| {
        std::fs::read(models.join(f))
            .map_err(|e| egoexo_infer::InferError::ReadModel { file: f.to_string(), message: e.to_string() })
    })
    .unwrap();
    Engine::new().with_models(set)
}

/// The capture with every view assigned by the simulator's own identities.
fn with_true_identities(sim: &SimulatedCapture) -> Capture {
    let mut capture = sim.capture.clone();
    let mut views = Vec::new();
    for (view, identities) in sim.capture.views.iter().zip(&sim.identities) {
        let ViewPeople::Unassigned(people) = &view.people else { unreachable!("simulated views are unassigned") };
        for (q, participant) in sim.capture.participants.iter().enumerate() {
            if participant.id == view.observer {
                continue;
            }
            let frames = people
                .frames
                .iter()
                .zip(identities)
                .map(|(detections, who)| {
                    who.iter().position(|w| *w == Some(q)).map(|d| detections[d]).unwrap_or([None; 17])
                })
                .collect();
            views.push(View {
                observer: view.observer.clone(),
                people: ViewPeople::Assigned {
                    target: participant.id.clone(),
                    keypoints: KeypointTrack { timestamps_ns: people.timestamps_ns.clone(), frames },
                },
            });
        }
    }
    capture.views = views;
    capture
}

fn reconstruct(engine: &Engine, capture: &Capture, participant: usize, method: Method) -> (Reconstruction, f64) {
    let session = capture.session_for(participant).unwrap();
    let aligned = align(&session, &AlignOptions::default()).unwrap();
    let r = engine
        .reconstruct(&aligned, &ReconstructOptions { method, ..ReconstructOptions::default() }, &mut |_| true)
        .unwrap();
    let gt = aligned.ground_truth.as_ref().unwrap();
    let want: Vec<_> = gt.poses.iter().map(|p| aligned.skeleton.forward_kinematics(p).positions).collect();
    let mut acc = MetricsAccumulator::new();
    acc.add_segment(&r.joints, &want, aligned.timeline.fps, Some(&gt.valid)).unwrap();
    let mpjpe = acc.finish().unwrap().mpjpe_cm;
    (r, mpjpe)
}

#[test]
fn detections_are_associated_to_the_right_participant_and_everyone_is_reconstructed() {
    let engine = engine();
    println!(
        "participants | bystanders | participant detections | right | wrong person | missed | bystander detections | taken for a participant | association error rate"
    );
    let mut rows = Vec::new();
    for (n, seed) in [(2, 21), (3, 22)] {
        let config = GroupConfig { bystanders: 3, ..GroupConfig::default() };
        let sim = simulate_group(&group_walk(n, 10.0), &format!("group-{n}"), &config, seed).unwrap();

        // EgoNet per participant, from their own devices only.
        let sessions: Vec<_> = (0..n).map(|p| sim.capture.session_for(p).unwrap()).collect();
        let aligned: Vec<_> = sessions.iter().map(|s| align(s, &AlignOptions::default()).unwrap()).collect();
        let egonet = ReconstructOptions { method: Method::EgoNet, ..ReconstructOptions::default() };
        let coarse: Vec<_> = aligned.iter().map(|a| engine.reconstruct(a, &egonet, &mut |_| true).unwrap()).collect();
        let participants: Vec<_> =
            (0..n).map(|p| CoarseParticipant { participant: p, aligned: &aligned[p], coarse: &coarse[p] }).collect();
        let mut capture = sim.capture.clone();
        let reports = associate_views(&mut capture, &participants, &AssociationOptions::default());
        capture.validate().unwrap();
        assert_eq!(capture.views.len(), n * (n - 1), "one assigned view per (observer, other participant)");

        // Association against the simulator's identities.
        let (mut people, mut right, mut wrong, mut missed, mut strangers, mut taken) = (0, 0, 0, 0, 0, 0);
        for (report, truth) in reports.iter().zip(&sim.identities) {
            for (assigned, who) in report.assignment.iter().zip(truth) {
                for (a, w) in assigned.iter().zip(who) {
                    match (w, a) {
                        (Some(w), Some(a)) if w == a => right += 1,
                        (Some(_), Some(_)) => wrong += 1,
                        (Some(_), None) => missed += 1,
                        (None, Some(_)) => taken += 1,
                        (None, None) => {}
                    }
                    if w.is_some() {
                        people += 1;
                    } else {
                        strangers += 1;
                    }
                }
            }
        }
        let total = people + strangers;
        let error_rate = (wrong + missed + taken) as f32 / total.max(1) as f32;
        println!(
            "{n} | {} | {people} | {right} | {wrong} | {missed} | {strangers} | {taken} | {:.3}",
            config.bystanders, error_rate
        );
        assert!(strangers > 0, "bystanders were seen");
        assert!(error_rate < 0.1, "association error rate {error_rate:.3}");
        assert!(wrong as f32 <= 0.02 * people as f32, "{wrong} of {people} detections given to the wrong participant");

        // Each participant reconstructed with the others as observers.
        let truth = with_true_identities(&sim);
        for p in 0..n {
            let (_, ego_only) = reconstruct(&engine, &capture, p, Method::EgoOnly);
            let (r, associated) = reconstruct(&engine, &capture, p, Method::EgoExo);
            let (_, true_ids) = reconstruct(&engine, &truth, p, Method::EgoExo);
            let evidence = r.exo_evidence.iter().filter(|&&e| e).count();
            rows.push(format!(
                "{n} | {} | {ego_only:.2} | {associated:.2} | {true_ids:.2} | {evidence}/{}",
                capture.participants[p].id,
                r.exo_evidence.len()
            ));
            assert!(
                evidence > r.exo_evidence.len() / 3,
                "{}: exo evidence on {evidence} frames",
                capture.participants[p].id
            );
            assert!(
                associated < ego_only + 0.5,
                "{}: with the others' views {associated:.2} cm vs ego-only {ego_only:.2}",
                capture.participants[p].id
            );
        }
    }
    println!(
        "participants | participant | MPJPE ego-only | ego-exo, associated | ego-exo, true identities | frames with exo evidence"
    );
    for row in rows {
        println!("{row}");
    }
}
