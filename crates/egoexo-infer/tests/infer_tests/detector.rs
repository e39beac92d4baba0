//! The shipped detector (`models/manifest.json`'s `detector`, MoveNet Lightning) in tract
//! against onnxruntime on the same crop — a rendered person (`egoexo_synth::video`) — within
//! 1e-4, and its keypoints on that person's projected joints. onnxruntime runs in the test venv
//! (`cargo xtask setup`); without it this test fails and says so.
#![cfg(not(target_arch = "wasm32"))]

use std::process::Command;

use egoexo_core::crop::{CropWindow, resample_rgb};
use egoexo_core::exo_keypoints::{ExoKeypoint, exo_keypoints_from_smpl};
use egoexo_core::glam::Vec3;
use egoexo_core::region::{DEFAULT_REGION_MARGIN, propose_region};
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{NUM_JOINTS, SmplJoint};
use egoexo_infer::KeypointDetector;
use egoexo_infer::manifest::Manifest;
use egoexo_synth::cameras::wide_pinhole_camera;
use egoexo_synth::procedural::walking_circle;
use egoexo_synth::video::{Appearance, CameraRays, render_frame};
use egoexo_test_support::{SETUP_HINT, python, workspace_root};

#[test]
fn tract_matches_onnxruntime_and_finds_a_rendered_person() {
    let models = workspace_root().join("models");
    let manifest = Manifest::from_json(&std::fs::read(models.join("manifest.json")).unwrap()).unwrap();
    let entry = manifest.detector.expect("the manifest ships a detector");
    let model_path = models.join(&entry.file.file);
    let detector = KeypointDetector::load(&entry, &std::fs::read(&model_path).unwrap()).unwrap();
    let size = detector.input_size();

    // A walking person 3.5 m in front of a 384 px pinhole at eye height.
    let motion = walking_circle(2.0);
    let fk = motion.skeleton.forward_kinematics(&motion.poses[20]);
    let pelvis = fk.positions[SmplJoint::Pelvis.index()];
    let eye = pelvis + Vec3::new(0.0, 0.6, 0.0) + (fk.rotations[0] * Vec3::Z) * 3.5;
    let device = RigidTransform::cpf_looking_at(eye, pelvis);
    let camera = wide_pinhole_camera(384).unwrap();
    let image = render_frame(&fk, 1.0, &CameraRays::new(&camera), &device, pelvis.y - 1.0, &Appearance::default());
    let region = propose_region(&fk.positions[..NUM_JOINTS], &camera, &device, DEFAULT_REGION_MARGIN);
    let window = CropWindow::around(&region.bbox().unwrap(), 48.0).unwrap();
    let crop = resample_rgb(&image, 384, 384, &window, size).unwrap();
    let tract = detector.detect(&crop).unwrap();

    let dir = tempfile_dir();
    std::fs::write(dir.join("crop.bin"), &crop).unwrap();
    let script = format!(
        "import numpy as np, onnxruntime as ort\n\
         o = ort.SessionOptions(); o.intra_op_num_threads = 1\n\
         s = ort.InferenceSession({model:?}, o)\n\
         x = np.fromfile({crop:?}, dtype=np.uint8).astype(np.float32).reshape(1, {size}, {size}, 3)\n\
         print(' '.join(repr(float(v)) for v in s.run(None, {{'image': x}})[0].ravel()))\n",
        model = model_path.display().to_string(),
        crop = dir.join("crop.bin").display().to_string(),
    );
    let out = Command::new(python())
        .args(["-c", &script])
        .output()
        .unwrap_or_else(|e| panic!("cannot run Python: {e}; {SETUP_HINT}"));
    assert!(out.status.success(), "onnxruntime failed: {}\n({SETUP_HINT})", String::from_utf8_lossy(&out.stderr));
    let ort: Vec<f32> = String::from_utf8_lossy(&out.stdout).split_whitespace().map(|v| v.parse().unwrap()).collect();
    assert_eq!(ort.len(), 17 * 3);
    let mut worst = 0f32;
    for (k, kp) in tract.iter().enumerate() {
        for (got, want) in
            [(kp.at.y, ort[3 * k]), (kp.at.x, ort[3 * k + 1]), (kp.score, ort[3 * k + 2].clamp(0.0, 1.0))]
        {
            worst = worst.max((got - want).abs());
        }
    }
    println!("tract vs onnxruntime: max |Δ| {worst:.2e}");
    assert!(worst <= 1e-4, "tract differs from onnxruntime by {worst}");

    // On the person: every body keypoint within a fifth of the box's diagonal of its joint.
    let truth = exo_keypoints_from_smpl(&fk.positions, fk.rotations[SmplJoint::Head.index()], 1.0);
    let diag = region.bbox().unwrap().diagonal() / (1.0 + 2.0 * DEFAULT_REGION_MARGIN);
    for k in ExoKeypoint::ALL {
        let want = camera.project_world(truth[k.index()], &device).unwrap();
        let got = window.full_from_normalized(tract[k.coco17_index()].at);
        assert!(got.distance(want) < 0.2 * diag, "{}: {got} vs {want} (box diagonal {diag:.0} px)", k.name());
    }
}

fn tempfile_dir() -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("egoexo-detector-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
