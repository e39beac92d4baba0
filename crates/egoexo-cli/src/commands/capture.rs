//! Captures of several participants in the CLI (`egoexo reconstruct`, `egoexo inspect`): each
//! participant to reconstruct gets EgoNet's coarse pose from their own devices; every camera's
//! people without identity are associated with the participants by those poses
//! (`egoexo_detect::people`); cameras with video get the detector step per participant (the
//! crop is that participant's region); and each participant is reconstructed with the others
//! as observers — one motion per participant, all in one world.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use egoexo_core::TrackingMode;
use egoexo_core::aligned::AlignedSession;
use egoexo_core::association::AssociationOptions;
use egoexo_detect::people::{CoarseParticipant, ViewAssociation, associate_views};
use egoexo_infer::plan::resolve_tracking;
use egoexo_infer::{Engine, Method, ReconstructOptions, Reconstruction};
use egoexo_register::capture::register_capture;
use egoexo_register::{RegisterMode, RegisterSettings};
use egoexo_session::Session;
use egoexo_session::align::{AlignOptions, align};
use egoexo_session::capture::{Capture, ViewPeople};
use egoexo_session::import::{Imported, SourceKind};

use super::detection::{detect_missing_keypoints, print_reports};
use super::models::{load_model_set, read_manifest};
use super::register::{engine_for, print_capture};

/// MPJPE (cm) of a participant's reconstruction against the ground truth on its timeline,
/// when the capture has one.
pub fn mpjpe_cm(p: &ParticipantReconstruction) -> Option<f64> {
    p.aligned.ground_truth_mpjpe_cm(&p.reconstruction.joints, &p.reconstruction.valid)
}

/// One participant's reconstruction.
pub struct ParticipantReconstruction {
    pub id: String,
    pub session: Session,
    pub aligned: AlignedSession,
    pub method: Method,
    pub tracking: TrackingMode,
    pub reconstruction: Reconstruction,
}

/// Everything `reconstruct_capture` did.
pub struct CaptureReconstruction {
    pub association: Vec<ViewAssociation>,
    pub participants: Vec<ParticipantReconstruction>,
}

/// Engines by tracking mode, loaded on first need.
struct Engines<'a> {
    models: &'a Path,
    manifest: egoexo_infer::manifest::Manifest,
    loaded: BTreeMap<u8, Engine>,
}

impl Engines<'_> {
    fn get(&mut self, tracking: TrackingMode) -> Result<&Engine> {
        let key = tracking.points();
        if !self.loaded.contains_key(&key) {
            let set = load_model_set(self.models, &self.manifest, tracking)?
                .with_context(|| format!("{} has no {}-point models", self.models.display(), tracking.points()))?;
            self.loaded.insert(key, Engine::new().with_models(set));
        }
        Ok(&self.loaded[&key])
    }
}

/// Reconstructs every participant of `capture` (read from `path`, where its videos are).
pub fn reconstruct_capture(
    path: &Path,
    mut capture: Capture,
    models: &Path,
    tracking: Option<TrackingMode>,
    ego_only: bool,
    fps: f32,
    register: RegisterMode,
) -> Result<CaptureReconstruction> {
    let mut engines = Engines { models, manifest: read_manifest(models)?, loaded: BTreeMap::new() };
    let align_options = AlignOptions { fps, ..AlignOptions::default() };
    let reconstructed: Vec<usize> = capture.reconstructed().collect();

    // Registration first: association projects every participant into every camera, which
    // needs one world.
    if !ego_only && capture.participants.len() > 1 {
        let engine = engine_for(models, &[TrackingMode::OnePoint, TrackingMode::ThreePoint])?;
        let settings = RegisterSettings { mode: register, ..RegisterSettings::default() };
        let report = register_capture(Some(&engine), tracking, &mut capture, 0, &settings)?;
        print_capture(&report);
    }

    // Association: every participant's EgoNet pose from their own devices.
    let mut association = Vec::new();
    if !ego_only && capture.views.iter().any(|v| matches!(v.people, ViewPeople::Unassigned(_))) {
        let mut coarse = Vec::new();
        for &p in &reconstructed {
            let aligned = align(&capture.session_for(p)?, &align_options)?;
            let tracking = resolve_tracking(&aligned, tracking)?;
            let egonet = ReconstructOptions { method: Method::EgoNet, tracking: Some(tracking), ..Default::default() };
            let pose = engines.get(tracking)?.reconstruct(&aligned, &egonet, &mut |_| true)?;
            coarse.push((p, aligned, pose));
        }
        let participants: Vec<_> = coarse
            .iter()
            .map(|(p, aligned, pose)| CoarseParticipant { participant: *p, aligned, coarse: pose })
            .collect();
        association = associate_views(&mut capture, &participants, &AssociationOptions::default());
    }

    let mut participants = Vec::new();
    for &p in &reconstructed {
        let id = capture.participants[p].id.clone();
        let mut imported =
            Imported { session: capture.session_for(p)?, source: SourceKind::Egoexo, warnings: Vec::new() };
        if !ego_only {
            let reports = detect_missing_keypoints(path, &mut imported, models, tracking, &[])
                .with_context(|| format!("the detector step for participant `{id}`"))?;
            print_reports(&reports);
        }
        let session = imported.session;
        let aligned = align(&session, &align_options).with_context(|| format!("participant `{id}`"))?;
        let tracking = resolve_tracking(&aligned, tracking)?;
        let method = if ego_only || !session.observers.iter().any(|o| o.keypoints.is_some()) {
            Method::EgoOnly
        } else {
            Method::EgoExo
        };
        let options = ReconstructOptions { method, tracking: Some(tracking), ..ReconstructOptions::default() };
        let engine = engines.get(tracking)?;
        let reconstruction = engine
            .reconstruct_each_in_parallel(&aligned, &options, &[method], &mut |_| true)?
            .into_iter()
            .next()
            .context("the engine returned no reconstruction")?;
        participants.push(ParticipantReconstruction { id, session, aligned, method, tracking, reconstruction });
    }
    Ok(CaptureReconstruction { association, participants })
}

/// Where participant `id`'s motion goes when the capture's output is `output`:
/// `walk.npz` → `walk.participant-1.npz`.
pub fn participant_output(output: &Path, id: &str) -> PathBuf {
    let stem = output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = match output.extension() {
        Some(ext) => format!("{stem}.{id}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{id}"),
    };
    output.with_file_name(name)
}

/// The association's figures, one line per camera.
pub fn print_association(reports: &[ViewAssociation]) {
    for r in reports {
        let assigned: Vec<String> = r.assigned.iter().map(|(id, n)| format!("{n} to {id}")).collect();
        eprintln!(
            "associated {}'s camera: {} people over {} frames — {}; {} matched nobody (bystanders)",
            r.observer,
            r.detections,
            r.frames,
            if assigned.is_empty() { "none assigned".to_owned() } else { assigned.join(", ") },
            r.unassigned
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_participant_gets_a_file_next_to_the_output() {
        assert_eq!(participant_output(Path::new("out/walk.npz"), "p-1"), Path::new("out/walk.p-1.npz"));
        assert_eq!(participant_output(Path::new("walk"), "p-1"), Path::new("walk.p-1"));
    }
}
