//! Shards and evaluation end to end on a small library of procedural motions, with the
//! untrained fixture networks; numpy reads the shards as the training code does.
#![cfg(not(target_arch = "wasm32"))]

use std::collections::BTreeMap;
use std::process::Command;

use egoexo_core::TrackingMode;
use egoexo_dataset::eval::{EvalOptions, evaluate, format_table, nearest_neighbour_index};
use egoexo_dataset::shards::{EgoNetForShards, ShardIndex, ShardOptions, ShardStage, WristKind, write_shards};
use egoexo_infer::manifest::Manifest;
use egoexo_infer::models::ModelSet;
use egoexo_infer::{Engine, InferError, Method};
use egoexo_mocap::library::{HISTOGRAM_BINS, LibraryClip, RetargetStats};
use egoexo_mocap::{ClipInfo, MotionLibrary};
use egoexo_synth::procedural::walking_circle;
use egoexo_test_support::{python, workspace_root};

/// Three "subjects" walking for different durations.
fn library() -> MotionLibrary {
    let clips = [(1, 5.0), (2, 4.0), (3, 6.5)]
        .into_iter()
        .map(|(subject, seconds)| {
            let motion = walking_circle(seconds);
            LibraryClip {
                info: ClipInfo {
                    subject,
                    trial: 1,
                    name: format!("{subject:02}_01"),
                    segment: 0,
                    description: "walking a circle (procedural)".into(),
                    source_fps: 30.0,
                    source_format: "procedural".into(),
                    source_frames: motion.len() as u32,
                    source_range: [0, motion.len() as u32],
                    frames: 0,
                    frame_offset: 0,
                    head_height_m: motion.skeleton.head_height(),
                    skeleton_scale: motion.skeleton.head_height() / 1.4963,
                    retarget: RetargetStats {
                        mean_cm: 0.0,
                        p95_cm: 0.0,
                        max_cm: 0.0,
                        per_joint_mean_cm: vec![0.0; 24],
                    },
                },
                poses: motion.poses,
                error_histogram: vec![0; HISTOGRAM_BINS],
            }
        })
        .collect();
    MotionLibrary::build(30.0, "procedural test motions", clips).unwrap()
}

fn fixture_models(tracking: TrackingMode) -> ModelSet {
    let dir = workspace_root().join("crates/egoexo-infer/tests/fixtures/models");
    let manifest = Manifest::from_json(&std::fs::read(dir.join("manifest.json")).unwrap()).unwrap();
    ModelSet::load(manifest.model_set(tracking).unwrap(), |f| {
        std::fs::read(dir.join(f)).map_err(|e| InferError::ReadModel { file: f.into(), message: e.to_string() })
    })
    .unwrap()
}

fn make_shards(stage: ShardStage, egonet: Option<EgoNetForShards<'_>>) -> (ShardIndex, BTreeMap<String, Vec<u8>>) {
    let lib = library();
    let options = ShardOptions { simulations_per_clip: 2, stride: 48, windows_per_shard: 5, ..ShardOptions::default() };
    let mut files = BTreeMap::new();
    let mut progress = Vec::new();
    let index = write_shards(
        &lib,
        &lib.clips_of_subjects(&[1, 3]),
        stage,
        &options,
        egonet,
        &mut |name, bytes| {
            files.insert(name.to_string(), bytes);
            Ok(())
        },
        &mut |done, total| progress.push((done, total)),
    )
    .unwrap();
    assert_eq!(progress.last(), Some(&(2, 2)));
    (index, files)
}

#[test]
fn ego_shards_count_windows_of_the_chosen_subjects_with_mirrors() {
    let (index, files) = make_shards(ShardStage::Ego, None);
    assert_eq!(index.subjects, vec![1, 3]);
    // 5 s = 150 frames → 3 windows at stride 48 (0, 48, 54); 6.5 s = 195 → 4 (0, 48, 96, 99);
    // × 2 simulations × 2 (mirrored) = 28.
    assert_eq!(index.windows, 28);
    assert_eq!(index.shards.iter().map(|s| s.windows).sum::<usize>(), 28);
    assert!(index.shards.iter().all(|s| s.windows <= 9), "flushed every ≥5 windows");
    assert!(files.contains_key("index.json"));
    assert_eq!(files.len(), index.shards.len() + 1);
    // Deterministic: the same options give the same bytes.
    let (_, again) = make_shards(ShardStage::Ego, None);
    assert_eq!(files, again);
}

#[test]
fn fusion_shards_need_an_egonet_and_carry_the_exo_side() {
    let lib = library();
    let err = write_shards(
        &lib,
        &[0],
        ShardStage::Fusion,
        &ShardOptions::default(),
        None,
        &mut |_, _| Ok(()),
        &mut |_, _| {},
    )
    .unwrap_err();
    assert!(err.to_string().contains("trained EgoNet"), "{err}");

    let models = fixture_models(TrackingMode::ThreePoint);
    let (index, files) = make_shards(
        ShardStage::Fusion,
        Some(EgoNetForShards { model: &models.egonet, sha256: &models.manifest.egonet.sha256 }),
    );
    assert_eq!(index.egonet_sha256.as_deref(), Some(models.manifest.egonet.sha256.as_str()));

    // numpy reads them with the documented shapes and ranges, and the training code loads them.
    let dir = std::env::temp_dir().join(format!("egoexo-shards-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (name, bytes) in &files {
        std::fs::write(dir.join(name), bytes).unwrap();
    }
    let script = r#"
import json, sys
import numpy as np
folder = sys.argv[1]
index = json.load(open(f"{folder}/index.json"))
T, N, K = index["window"], index["options"]["max_observers"], index["keypoints"]
W = 0
for entry in index["shards"]:
    z = np.load(f"{folder}/{entry['file']}")
    w = entry["windows"]
    W += w
    shapes = {"ego": (w, T, 62), "target": (w, T, 132), "frame_mask": (w, T), "rest_joints": (w, 24, 3),
              "egonet": (w, T, 132), "rays": (w, T, N, K, 3), "ray_offsets": (w, T, N, K, 3),
              "ray_valid": (w, T, N, K),
              "gate_features": (w, T, N, K, 6), "observer_mask": (w, T, N), "occluded": (w, T, N, K),
              "ray_error": (w, T, N, K)}
    for key, shape in shapes.items():
        assert z[key].shape == shape, (key, z[key].shape, shape)
        assert z[key].dtype == np.float32, (key, z[key].dtype)
        assert np.isfinite(z[key]).all(), key
    assert z["subject"].dtype == np.int32
    assert set(np.unique(z["ray_valid"])) <= {0.0, 1.0}
    # Invalid rays are zero; valid ones lie within a few metres of the head.
    assert (z["rays"][z["ray_valid"] == 0] == 0).all()
    assert np.abs(z["rays"]).max() < 10
    # Offsets from the coarse joints to their rays: zero where invalid, some nonzero, and
    # within a few metres (the fixture EgoNet is untrained, so its coarse pose is anywhere
    # near the head, not near the body).
    assert (z["ray_offsets"][z["ray_valid"] == 0] == 0).all()
    assert 0 < np.abs(z["ray_offsets"]).max() < 10
    assert (z["gate_features"][..., 0] >= 0).all() and (z["gate_features"][..., 0] <= 1).all()
    assert (z["observer_mask"] == (z["ray_valid"].max(axis=-1) > 0)).all()
    # Distances of the rays from the true keypoints: zero where invalid; the rays of visible
    # keypoints pass within centimetres of them (detector and device noise).
    valid = z["ray_valid"] > 0
    assert (z["ray_error"][~valid] == 0).all() and (z["ray_error"] >= 0).all()
    visible = valid & (z["occluded"] == 0)
    assert visible.any() and np.median(z["ray_error"][visible]) < 0.10, np.median(z["ray_error"][visible])
# The training code itself accepts them (shard format version, keys, FK of the targets).
from pathlib import Path
from egoexo_train.train import FUSION_KEYS, load_shards
assert load_shards(Path(folder), FUSION_KEYS)["rays"].shape[0] == W
print(W)
"#;
    let out = Command::new(python())
        .arg("-c")
        .arg(script)
        .arg(&dir)
        .env("PYTHONPATH", workspace_root().join("training"))
        .output()
        .unwrap();
    std::fs::remove_dir_all(&dir).ok();
    assert!(out.status.success(), "numpy check failed:\n{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), index.windows.to_string());
}

#[test]
fn evaluation_scores_every_method_on_all_and_occluded_frames() {
    let lib = library();
    let mut engine = Engine::new();
    for mode in [TrackingMode::ThreePoint, TrackingMode::OnePoint] {
        engine = engine
            .with_models(fixture_models(mode))
            .with_nearest_neighbour(mode, nearest_neighbour_index(&lib, &[1, 2], mode, 7, 2).unwrap());
    }
    let methods =
        vec![Method::RestPose, Method::NearestNeighbour, Method::EgoOnly, Method::EgoExo, Method::EgoExoUngated];
    let options = EvalOptions {
        subjects: vec![3],
        observers: 2,
        tracking: TrackingMode::ThreePoint,
        wrists: WristKind::Devices,
        floor_contact: true,
        min_head_drop_m: None,
        seed: 7,
        methods: methods.clone(),
    };
    let report = evaluate(&lib, &engine, &options, &mut |_, _| {}).unwrap();
    assert!(report.wrist_coverage.iter().all(|&c| c > 0.98), "{:?}", report.wrist_coverage);
    // The same clip with hand-tracking wrists: tracked only part of the time, said in the
    // table's title, and every method still scores every frame.
    let hands = EvalOptions { wrists: WristKind::HandTracking, ..options.clone() };
    let hands_report = evaluate(&lib, &engine, &hands, &mut |_, _| {}).unwrap();
    assert_eq!(hands_report.frames, 195);
    assert!(hands_report.wrist_coverage.iter().all(|c| (0.0..1.0).contains(c)), "{:?}", hands_report.wrist_coverage);
    // A clip whose hands never came into view reconstructs 1-point, as a real one would.
    let no_wrists = hands_report.wrist_coverage == [0.0, 0.0];
    assert_eq!(hands_report.one_point_clips, usize::from(no_wrists));
    assert!(format_table(&hands_report).starts_with("3-point tracking (hand-tracking wrists: left wrist tracked on"));
    assert_eq!(report.clips, 1);
    assert_eq!(report.frames, 195);
    assert_eq!(report.rows.iter().map(|r| r.method).collect::<Vec<_>>(), methods);
    for row in report.rows.iter().chain(&report.occluded_rows) {
        assert!(row.metrics.mpjpe_cm.is_finite() && row.metrics.mpjpe_cm > 0.0, "{row:?}");
        assert!(row.metrics.jitter.is_finite());
    }
    // The nearest neighbour of a walk among walks beats a T-pose.
    let mpjpe = |m: Method| report.rows.iter().find(|r| r.method == m).unwrap().metrics.mpjpe_cm;
    assert!(mpjpe(Method::NearestNeighbour) < mpjpe(Method::RestPose));
    // The true motion's own jitter is the reference row: no error, a walk's (non-zero) jerk.
    let truth = report.ground_truth.as_ref().expect("segments of 96 frames have jerk");
    assert_eq!((truth.mpjpe_cm, truth.mpjve_cm_s), (0.0, 0.0));
    assert!(truth.jitter.is_finite() && truth.jitter > 0.0, "{truth:?}");
    let rest = report.rows.iter().find(|r| r.method == Method::RestPose).unwrap();
    assert_ne!(truth.jitter, rest.metrics.jitter);
    // Same seed, same numbers.
    assert_eq!(report, evaluate(&lib, &engine, &options, &mut |_, _| {}).unwrap());
    // Feet against the simulator's floor: the truth stands on it (never through it, little
    // sliding while it stands), every method gets a row.
    assert_eq!(report.feet.iter().map(|r| r.method).collect::<Vec<_>>(), methods);
    let truth_feet = report.ground_truth_feet.expect("the truth's feet");
    assert_eq!(truth_feet.penetration_worst_cm, 0.0);
    let truth_skating = truth_feet.skating_cm_s.expect("a walk stands on its feet");
    assert!(truth_skating < 25.0, "{truth_feet:?}");
    for row in &report.feet {
        assert!(
            row.metrics.penetration_mean_cm >= 0.0
                && row.metrics.penetration_worst_cm >= row.metrics.penetration_mean_cm
        );
        assert_eq!(row.metrics.contact_pairs, truth_feet.contact_pairs, "stance comes from the truth");
    }
    let table = format_table(&report);
    assert!(table.contains("feet and floor") && table.contains("skating"), "{table}");
    assert!(table.contains("occluded frames") && table.contains("ego-exo-ungated"), "{table}");
    assert!(table.contains("(ground truth)"), "{table}");
    let json = serde_json::to_value(&report).unwrap();
    for key in ["tracking", "observers", "subjects", "frames", "rows", "occluded_rows", "ground_truth"] {
        assert!(json.get(key).is_some(), "--json lacks {key}");
    }
    assert!(json["rows"][0].get("mpjve_cm_s").is_some());

    // Clip-paired differences, for the observers' and the gate's effect on all and occluded
    // frames: the frame-weighted mean over clips is exactly the rows' difference.
    let pairs: Vec<_> = report.paired.iter().map(|p| (p.method, p.baseline, p.occluded)).collect();
    assert_eq!(
        pairs,
        [
            (Method::EgoExo, Method::EgoOnly, false),
            (Method::EgoExo, Method::EgoOnly, true),
            (Method::EgoExo, Method::EgoExoUngated, false),
            (Method::EgoExo, Method::EgoExoUngated, true),
        ]
    );
    for p in &report.paired {
        let rows = if p.occluded { &report.occluded_rows } else { &report.rows };
        let row = |m: Method| &rows.iter().find(|r| r.method == m).unwrap().metrics;
        assert!((p.mpjpe_cm.mean - (row(p.method).mpjpe_cm - row(p.baseline).mpjpe_cm)).abs() < 1e-9, "{p:?}");
        assert!((p.lower_cm.mean - (row(p.method).lower_cm - row(p.baseline).lower_cm)).abs() < 1e-9, "{p:?}");
        // One clip: resampling clips cannot move the mean.
        assert_eq!(p.clips, 1);
        assert_eq!((p.mpjpe_cm.low, p.mpjpe_cm.high), (p.mpjpe_cm.mean, p.mpjpe_cm.mean));
    }
    assert!(table.contains("paired by clip") && table.contains("ego-exo - ego-exo-ungated"), "{table}");
    assert_eq!(json["paired"].as_array().map(Vec::len), Some(4));
    // Without networks there is nothing to pair.
    let baselines = EvalOptions { methods: vec![Method::RestPose, Method::NearestNeighbour], ..options.clone() };
    let report = evaluate(&lib, &engine, &baselines, &mut |_, _| {}).unwrap();
    assert!(report.paired.is_empty());
    assert!(!format_table(&report).contains("paired by clip"));
}

#[test]
fn unknown_subjects_are_a_clear_error() {
    let lib = library();
    let options = EvalOptions {
        subjects: vec![42],
        observers: 1,
        tracking: TrackingMode::OnePoint,
        wrists: WristKind::Devices,
        floor_contact: true,
        min_head_drop_m: None,
        seed: 1,
        methods: vec![Method::RestPose],
    };
    let err = evaluate(&lib, &Engine::new(), &options, &mut |_, _| {}).unwrap_err();
    assert!(err.to_string().contains("no clips of subjects [42]"), "{err}");
}
