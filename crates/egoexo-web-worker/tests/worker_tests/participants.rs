//! Captures of several participants in the worker (what the page does with them): everyone
//! reconstructed in one job, one shown with the others drawn beside them, `select-participant`
//! switching who is shown without computing again, exports per participant, a share carrying
//! all of them, and a saved capture that opens again as one.
#![cfg(not(target_arch = "wasm32"))]

use std::collections::BTreeMap;
use std::path::Path;

use egoexo_protocol::worker::ExportFormat;
use egoexo_scene::SceneData;
use egoexo_synth::group::{GroupConfig, group_walk, simulate_group};
use egoexo_test_support::workspace_root;
use egoexo_web_worker::{SessionWorker, WorkerError};

/// The shipped networks: the association needs EgoNet poses that look like the people.
fn worker_with_models() -> SessionWorker {
    let models = workspace_root().join("models");
    let manifest = std::fs::read(models.join("manifest.json")).unwrap();
    let mut worker = SessionWorker::new();
    worker
        .load_models(&manifest, |file| {
            std::fs::read(models.join(file))
                .map_err(|e| egoexo_infer::InferError::ReadModel { file: file.into(), message: e.to_string() })
        })
        .unwrap();
    worker
}

/// Two participants walking around each other, every camera's people without identity.
fn pair_capture() -> Vec<u8> {
    let simulated = simulate_group(&group_walk(2, 5.0), "pair", &GroupConfig::default(), 11).unwrap();
    egoexo_session::format::write_capture_zip(&simulated.capture, BTreeMap::new()).unwrap()
}

fn scene(json: &[u8]) -> SceneData {
    serde_json::from_slice(json).unwrap()
}

fn reconstruct(worker: &mut SessionWorker) -> egoexo_protocol::worker::ReconstructionSummary {
    let mut done = Vec::new();
    let summary = worker
        .reconstruct(false, &mut |p| {
            done.push(p.done);
            true
        })
        .unwrap();
    assert!(!done.is_empty());
    summary
}

#[test]
fn a_capture_of_two_reconstructs_both_and_shows_one_at_a_time() {
    let mut worker = worker_with_models();
    let opened = worker.import_archive("pair.egoexo", pair_capture()).unwrap();
    let ids: Vec<_> = opened.participants.iter().map(|p| p.id.as_str()).collect();
    assert_eq!(ids, ["participant-1", "participant-2"]);
    assert_eq!(opened.participants.iter().map(|p| p.colour).collect::<Vec<_>>(), [0, 1]);
    assert_eq!(opened.participant.as_deref(), Some("participant-1"));
    // The shown participant's session: the other's camera is its observer.
    assert_eq!(opened.observers.iter().map(|o| o.id.as_str()).collect::<Vec<_>>(), ["participant-2"]);
    assert_eq!(worker.participants_to_reconstruct(), ["participant-1", "participant-2"]);

    let summary = reconstruct(&mut worker);
    assert_eq!(summary.participant.as_deref(), Some("participant-1"));
    assert_eq!(summary.participants.iter().map(|p| p.id.as_str()).collect::<Vec<_>>(), ids);
    assert!(summary.participants.iter().all(|p| p.accuracy.is_some() && p.valid_frames > 0));
    // Each camera's people were associated: the other participant in most frames.
    assert_eq!(summary.association.len(), 2);
    for a in &summary.association {
        let other = if a.observer == "participant-1" { "participant-2" } else { "participant-1" };
        assert!(a.assigned.get(other).copied().unwrap_or(0) > a.frames / 2, "{a:?}");
    }
    let first = scene(&worker.scene_json().unwrap());
    first.check().unwrap();
    assert_eq!(first.participant.as_ref().map(|p| p.id.as_str()), Some("participant-1"));
    assert_eq!(first.others.len(), 1);
    assert_eq!(first.others[0].participant.id, "participant-2");
    assert!(first.others[0].valid.iter().filter(|&&v| v).count() > first.frames * 9 / 10);
    let export_1 = worker.export(ExportFormat::Csv).unwrap();

    // Selecting the other: their session and their part of the same reconstruction.
    let selected = worker.select_participant("participant-2").unwrap();
    assert_eq!(selected.session.participant.as_deref(), Some("participant-2"));
    assert_eq!(selected.session.observers[0].id, "participant-1");
    let (summary_2, scene_json) = selected.reconstruction.expect("participant-2 is reconstructed");
    assert_eq!(summary_2.participant.as_deref(), Some("participant-2"));
    assert_eq!(summary_2.participants, summary.participants);
    let second = scene(&scene_json);
    assert_eq!(second.others[0].participant.id, "participant-1");
    // The same bodies, swapped: participant-1 as shown first is participant-1 drawn beside.
    let overlap = first.frames.min(second.frames);
    let valid = (0..overlap).find(|&f| first.valid[f] && second.others[0].valid[f]).unwrap();
    let at = |j: &[f32]| j[valid * 72..valid * 72 + 3].to_vec();
    if first.start_s == second.start_s {
        assert_eq!(at(&first.joints), at(&second.others[0].joints));
    }
    let export_2 = worker.export(ExportFormat::Csv).unwrap();
    assert!(export_1.file_name.contains("participant-1") && export_2.file_name.contains("participant-2"));
    assert_ne!(export_1.bytes, export_2.bytes);

    let err = worker.select_participant("nobody").unwrap_err();
    assert!(matches!(err, WorkerError::NoSuchParticipant(_)), "{err}");

    // Saved, the capture opens again as a capture of both.
    let saved = worker.save_session().unwrap();
    let mut again = worker_with_models();
    let reopened = again.import_archive(&saved.file_name, saved.bytes).unwrap();
    assert_eq!(reopened.participants.len(), 2);
}

#[test]
fn a_share_of_a_capture_carries_every_participant() {
    let mut worker = worker_with_models();
    worker.import_archive("pair.egoexo", pair_capture()).unwrap();
    reconstruct(&mut worker);
    worker.select_participant("participant-2").unwrap();
    for include_recording in [false, true] {
        let container = worker.pack_share(include_recording, "egoexo test").unwrap();
        let mut other = worker_with_models();
        let opened = other.open_share(container).unwrap();
        assert_eq!(opened.manifest.participants.len(), 2);
        assert_eq!(opened.manifest.summary.participant.as_deref(), Some("participant-2"));
        assert_eq!(opened.scene_json, worker.scene_json().unwrap(), "shown as it was shared");
        // Everyone can be shown from the share alone (with or without the recording).
        let selected = other.select_participant("participant-1").unwrap();
        assert_eq!(selected.session.participant.as_deref(), Some("participant-1"));
        let (_, scene_json) = selected.reconstruction.unwrap();
        assert_eq!(scene(&scene_json).others[0].participant.id, "participant-2");
        let export = other.export(ExportFormat::Bvh).unwrap();
        assert!(export.file_name.contains("participant-1"), "{}", export.file_name);
        // With the recording, the capture itself is open again: it reconstructs.
        assert_eq!(other.participants_to_reconstruct().len(), if include_recording { 2 } else { 0 });
    }
}

/// Every file of `dirs` (merged) as a dropped folder named `name`.
fn dropped_folder(name: &str, dirs: &[&Path]) -> Vec<(String, Vec<u8>)> {
    fn walk(root: &Path, dir: &Path, name: &str, out: &mut BTreeMap<String, Vec<u8>>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(root, &path, name, out);
            } else {
                let rel = path.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
                out.insert(format!("{name}/{rel}"), std::fs::read(&path).unwrap());
            }
        }
    }
    let mut files = BTreeMap::new();
    for dir in dirs {
        walk(dir, dir, name, &mut files);
    }
    files.into_iter().collect()
}

/// The Nymeria-shaped fixture with people files, dropped as a folder: both people are
/// reconstructed, the cameras' people associated with them.
#[test]
fn a_dropped_nymeria_sequence_with_two_participants_reconstructs_both() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../egoexo-session/tests/fixtures");
    let files = dropped_folder("sequence", &[&fixtures.join("nymeria"), &fixtures.join("nymeria_people")]);
    let mut worker = worker_with_models();
    let opened = worker.import_files("sequence", files).unwrap();
    assert_eq!(opened.participants.iter().map(|p| p.id.as_str()).collect::<Vec<_>>(), ["wearer", "observer"]);
    let summary = reconstruct(&mut worker);
    assert_eq!(summary.participants.len(), 2);
    let observer_camera = summary.association.iter().find(|a| a.observer == "observer").unwrap();
    assert_eq!(observer_camera.assigned.get("wearer"), Some(&61), "{observer_camera:?}");
    assert!(observer_camera.unassigned > 0, "the bystander matches nobody: {observer_camera:?}");
    let shown = scene(&worker.scene_json().unwrap());
    assert_eq!(shown.others.len(), 1);
}
