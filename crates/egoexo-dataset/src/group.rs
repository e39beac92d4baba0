//! Evaluation of captures of several participants (`egoexo eval-group`): group scenes from
//! `egoexo_synth::group` (participants who walk together and look at each other, bystanders
//! crossing), every camera's people without identity. Per scene: how well association assigns
//! the people to the participants (against the simulator's identities); per participant:
//! MPJPE ego-only, ego-exo with the associated keypoints, and ego-exo with the true identities
//! (what perfect association would give).

use egoexo_core::TrackingMode;
use egoexo_core::aligned::AlignedSession;
use egoexo_core::association::AssociationOptions;
use egoexo_detect::people::{CoarseParticipant, associate_views};
use egoexo_infer::{Engine, Method, ReconstructOptions, Reconstruction};
use egoexo_session::capture::Capture;
use egoexo_session::{AlignOptions, align};
use egoexo_synth::group::{GroupConfig, group_walk, simulate_group};
use serde::{Deserialize, Serialize};

use crate::DatasetError;
use crate::table::{Align, Column, markdown_table};

/// One group scene to simulate and score.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupScene {
    pub participants: usize,
    pub seconds: f32,
    pub seed: u64,
    pub config: GroupConfig,
}

/// Association against the simulator's identities, over one scene's cameras.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AssociationRow {
    pub participants: usize,
    pub bystanders: usize,
    pub seed: u64,
    /// Detections that are participants, and what association made of them.
    pub participant_detections: usize,
    pub right: usize,
    pub wrong_participant: usize,
    pub missed: usize,
    /// Detections that are bystanders, and how many were taken for a participant.
    pub bystander_detections: usize,
    pub bystanders_taken: usize,
}

impl AssociationRow {
    /// (wrong participant + missed + bystanders taken) / all detections.
    pub fn error_rate(&self) -> f64 {
        let all = self.participant_detections + self.bystander_detections;
        (self.wrong_participant + self.missed + self.bystanders_taken) as f64 / all.max(1) as f64
    }
}

/// One participant's reconstruction errors, cm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParticipantRow {
    pub participants: usize,
    pub seed: u64,
    pub participant: String,
    pub frames: usize,
    pub ego_only_mpjpe_cm: f64,
    pub ego_exo_mpjpe_cm: f64,
    pub true_identities_mpjpe_cm: f64,
    /// Frames where an observer's ray passed the gate.
    pub exo_evidence_frames: usize,
}

/// Everything `evaluate_group` measured.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GroupReport {
    pub association: Vec<AssociationRow>,
    pub participants: Vec<ParticipantRow>,
}

fn aligned_session(capture: &Capture, participant: usize) -> Result<AlignedSession, DatasetError> {
    let session = capture.session_for(participant).map_err(|e| DatasetError::Simulate(e.to_string()))?;
    align(&session, &AlignOptions::default()).map_err(|e| DatasetError::Simulate(e.to_string()))
}

fn reconstruct(engine: &Engine, aligned: &AlignedSession, method: Method) -> Result<Reconstruction, DatasetError> {
    engine
        .reconstruct(aligned, &ReconstructOptions { method, ..ReconstructOptions::default() }, &mut |_| true)
        .map_err(|e| DatasetError::Reconstruct { method: method.to_string(), message: e.to_string() })
}

fn mpjpe_cm(aligned: &AlignedSession, r: &Reconstruction) -> Result<f64, DatasetError> {
    aligned.ground_truth_mpjpe_cm(&r.joints, &r.valid).ok_or(DatasetError::NoGroundTruth)
}

/// Simulates and scores `scenes` with `engine` (models for the scenes' tracking mode);
/// `progress(done, total)` after each scene.
pub fn evaluate_group(
    engine: &Engine,
    scenes: &[GroupScene],
    options: &AssociationOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<GroupReport, DatasetError> {
    let mut report = GroupReport::default();
    for (done, scene) in scenes.iter().enumerate() {
        if scene.participants < 2 {
            return Err(DatasetError::Options(format!(
                "a group scene needs 2 or more participants, not {}",
                scene.participants
            )));
        }
        let name = format!("group-{}-{}", scene.participants, scene.seed);
        let sim = simulate_group(&group_walk(scene.participants, scene.seconds), &name, &scene.config, scene.seed)
            .map_err(|e| DatasetError::Simulate(e.to_string()))?;
        let n = sim.capture.participants.len();

        // EgoNet per participant from their own devices, then association.
        let aligned: Vec<_> = (0..n).map(|p| aligned_session(&sim.capture, p)).collect::<Result<_, _>>()?;
        let coarse: Vec<_> =
            aligned.iter().map(|a| reconstruct(engine, a, Method::EgoNet)).collect::<Result<_, _>>()?;
        let participants: Vec<_> =
            (0..n).map(|p| CoarseParticipant { participant: p, aligned: &aligned[p], coarse: &coarse[p] }).collect();
        let mut capture = sim.capture.clone();
        let views = associate_views(&mut capture, &participants, options);

        let mut row = AssociationRow {
            participants: n,
            bystanders: scene.config.bystanders,
            seed: scene.seed,
            ..AssociationRow::default()
        };
        for (view, truth) in views.iter().zip(&sim.identities) {
            for (assigned, who) in view.assignment.iter().zip(truth) {
                for (a, w) in assigned.iter().zip(who) {
                    match (w, a) {
                        (Some(w), Some(a)) if w == a => row.right += 1,
                        (Some(_), Some(_)) => row.wrong_participant += 1,
                        (Some(_), None) => row.missed += 1,
                        (None, Some(_)) => row.bystanders_taken += 1,
                        (None, None) => {}
                    }
                    if w.is_some() {
                        row.participant_detections += 1;
                    } else {
                        row.bystander_detections += 1;
                    }
                }
            }
        }
        report.association.push(row);

        // Each participant: ego-only, with the associated keypoints, with the true identities.
        let truth = sim.with_true_identities();
        for p in 0..n {
            let ego_only = reconstruct(engine, &aligned[p], Method::EgoOnly)?;
            let associated = aligned_session(&capture, p)?;
            let ego_exo = reconstruct(engine, &associated, Method::EgoExo)?;
            let ideal = aligned_session(&truth, p)?;
            let ideal_recon = reconstruct(engine, &ideal, Method::EgoExo)?;
            report.participants.push(ParticipantRow {
                participants: n,
                seed: scene.seed,
                participant: capture.participants[p].id.clone(),
                frames: associated.timeline.frames,
                ego_only_mpjpe_cm: mpjpe_cm(&aligned[p], &ego_only)?,
                ego_exo_mpjpe_cm: mpjpe_cm(&associated, &ego_exo)?,
                true_identities_mpjpe_cm: mpjpe_cm(&ideal, &ideal_recon)?,
                exo_evidence_frames: ego_exo.exo_evidence.iter().filter(|&&e| e).count(),
            });
        }
        progress(done + 1, scenes.len());
    }
    Ok(report)
}

/// The two tables: association per scene, MPJPE per participant (plus the mean per method).
pub fn format_group_table(report: &GroupReport) -> String {
    use Align::{Left, Right};
    let association: [Column<AssociationRow>; 10] = [
        ("participants", Right, |r| r.participants.to_string()),
        ("bystanders", Right, |r| r.bystanders.to_string()),
        ("seed", Right, |r| r.seed.to_string()),
        ("participant detections", Right, |r| r.participant_detections.to_string()),
        ("right", Right, |r| r.right.to_string()),
        ("wrong participant", Right, |r| r.wrong_participant.to_string()),
        ("missed", Right, |r| r.missed.to_string()),
        ("bystander detections", Right, |r| r.bystander_detections.to_string()),
        ("taken for a participant", Right, |r| r.bystanders_taken.to_string()),
        ("association error rate", Right, |r| format!("{:.3}", r.error_rate())),
    ];
    let participants: [Column<ParticipantRow>; 8] = [
        ("participants", Right, |r| r.participants.to_string()),
        ("seed", Right, |r| r.seed.to_string()),
        ("participant", Left, |r| r.participant.clone()),
        ("frames", Right, |r| r.frames.to_string()),
        ("MPJPE ego-only (cm)", Right, |r| format!("{:.2}", r.ego_only_mpjpe_cm)),
        ("ego-exo, associated", Right, |r| format!("{:.2}", r.ego_exo_mpjpe_cm)),
        ("ego-exo, true identities", Right, |r| format!("{:.2}", r.true_identities_mpjpe_cm)),
        ("frames with exo evidence", Right, |r| r.exo_evidence_frames.to_string()),
    ];
    let mut out = markdown_table(&association, &report.association);
    out += "\n";
    out += &markdown_table(&participants, &report.participants);
    let n = report.participants.len().max(1) as f64;
    let mean = |f: fn(&ParticipantRow) -> f64| report.participants.iter().map(f).sum::<f64>() / n;
    out += &format!(
        "| mean | | {} participants | | {:.2} | {:.2} | {:.2} | |\n",
        report.participants.len(),
        mean(|r| r.ego_only_mpjpe_cm),
        mean(|r| r.ego_exo_mpjpe_cm),
        mean(|r| r.true_identities_mpjpe_cm)
    );
    out
}

/// The default scenes of `egoexo eval-group`: `scenes` seeds each of 2 and 3 participants.
pub fn default_scenes(scenes: usize, seconds: f32, bystanders: usize, tracking: TrackingMode) -> Vec<GroupScene> {
    [2, 3]
        .into_iter()
        .flat_map(|participants| {
            (0..scenes as u64).map(move |s| GroupScene {
                participants,
                seconds,
                seed: 1000 * participants as u64 + s,
                config: GroupConfig { tracking, bystanders, ..GroupConfig::default() },
            })
        })
        .collect()
}
