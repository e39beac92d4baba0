//! Everyone in the session, end to end on simulated group scenes: 2 and 3 participants who
//! walk and look at each other, three bystanders crossing; every camera's detections come
//! without identity. Each participant's EgoNet pose (from their own devices) is projected into
//! the others' cameras, the detections are associated, and each participant is reconstructed
//! with the others as observers — against ego-only and against the true identities. Prints the
//! tables the model card quotes (`cargo test -p egoexo-dataset --test dataset_tests group:: -- --nocapture`;
//! `egoexo eval-group` runs more scenes).

use egoexo_core::TrackingMode;
use egoexo_core::association::AssociationOptions;
use egoexo_dataset::group::{default_scenes, evaluate_group, format_group_table};
use egoexo_infer::Engine;
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;
use egoexo_test_support::workspace_root;

#[test]
fn detections_are_associated_to_the_right_participant_and_everyone_is_reconstructed() {
    let models = workspace_root().join("models");
    let manifest = Manifest::from_json(&std::fs::read(models.join("manifest.json")).unwrap()).unwrap();
    let set = ModelSet::load(manifest.model_set(TrackingMode::ThreePoint).unwrap(), |f| {
        std::fs::read(models.join(f))
            .map_err(|e| egoexo_infer::InferError::ReadModel { file: f.to_string(), message: e.to_string() })
    })
    .unwrap();
    let engine = Engine::new().with_models(set);
    let scenes = default_scenes(1, 10.0, 3, TrackingMode::ThreePoint);
    let report = evaluate_group(&engine, &scenes, &AssociationOptions::default(), &mut |_, _| {}).unwrap();
    println!("{}", format_group_table(&report));

    assert_eq!(report.association.len(), 2);
    assert_eq!(report.participants.len(), 5, "2 + 3 participants");
    for row in &report.association {
        assert!(row.bystander_detections > 0, "bystanders were seen: {row:?}");
        assert!(row.error_rate() < 0.05, "association error rate {:.3}: {row:?}", row.error_rate());
        assert!(row.wrong_participant * 50 <= row.participant_detections, "{row:?}");
    }
    for row in &report.participants {
        assert!(row.exo_evidence_frames > row.frames / 3, "{row:?}");
        assert!(row.ego_exo_mpjpe_cm < row.ego_only_mpjpe_cm, "the others' views help: {row:?}");
        assert!(
            (row.ego_exo_mpjpe_cm - row.true_identities_mpjpe_cm).abs() < 0.5,
            "association costs little against the true identities: {row:?}"
        );
    }
}
