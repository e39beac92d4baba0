//! The detector step through the CLI, on video only: `walk --video` writes a session whose
//! observers have MP4s and no keypoints; `reconstruct` runs the detector step first (its report
//! on stderr) and uses the observers; `keypoints` writes the session with the detected
//! keypoints, which then reconstructs with no detection and the same motion; bad requests get
//! a reason.

use std::path::Path;

use crate::common::{egoexo, run};

#[test]
fn observers_with_video_get_keypoints_and_help_the_reconstruction() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("detect");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let s = |p: &Path| p.display().to_string();
    let session = dir.join("walk.egoexo");
    run(&["walk", "--seconds", "5", "--observers", "2", "--video", "256", "-o", &s(&session)]);
    let (inspected, _) = run(&["inspect", &s(&session)]);
    assert!(inspected.contains("observer-1"), "{inspected}");

    let direct = dir.join("direct.json");
    let (stdout, stderr) = run(&["reconstruct", &s(&session), "-o", &s(&direct)]);
    for id in ["observer-1", "observer-2"] {
        assert!(stderr.contains(&format!("detected keypoints for observer `{id}`")), "{stderr}");
    }
    let evidence: usize =
        stdout.split(" with exo evidence").next().unwrap().rsplit(' ').next().unwrap().parse().unwrap();
    assert!(evidence > 75, "the observers' detections reach the fusion on most of the 150 frames: {stdout}");

    let with_keypoints = dir.join("with-keypoints.egoexo");
    let (_, stderr) = run(&["keypoints", &s(&session), "-o", &s(&with_keypoints), "--json"]);
    assert!(stderr.contains("observer-2"), "{stderr}");
    let again = dir.join("again.json");
    let (_, stderr) = run(&["reconstruct", &s(&with_keypoints), "-o", &s(&again)]);
    assert!(!stderr.contains("detected keypoints"), "the keypoints are in the session now: {stderr}");
    let a: serde_json::Value = serde_json::from_slice(&std::fs::read(&direct).unwrap()).unwrap();
    let b: serde_json::Value = serde_json::from_slice(&std::fs::read(&again).unwrap()).unwrap();
    assert_eq!(a["joints"], b["joints"], "the same keypoints give the same motion");

    // Nothing left to detect, and an unknown observer.
    let out = egoexo(&["keypoints", &s(&with_keypoints), "-o", &s(&dir.join("x.egoexo"))]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("nothing to detect"));
    let out = egoexo(&["keypoints", &s(&session), "-o", &s(&dir.join("y.egoexo")), "--observer", "nobody"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("--observer nobody"));
}

/// The shipped detector on a real photograph with COCO's human-made keypoint labels
/// (`tests/data/coco`, CC BY 2.0 / CC BY 4.0): the whole frame and the region both find the
/// lone skier's keypoints; a file that does not match its image gets a reason.
#[test]
fn detector_eval_scores_a_real_annotated_photograph() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/coco");
    let coco = data.join("person_keypoints_785.json");
    let (stdout, _) = run(&["detector-eval", "--coco", &coco.display().to_string(), "--json"]);
    let reports: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    let reports = reports.as_array().unwrap();
    assert_eq!(reports.len(), 6, "full frame, region and four shifted regions: {stdout}");
    for report in reports {
        let all = &report["all"];
        assert_eq!((all["people"].as_u64(), all["keypoints"].as_u64()), (Some(1), Some(17)), "{report}");
        let pck = all["pck_02"].as_f64().unwrap();
        let oks = all["mean_oks"].as_f64().unwrap();
        assert!(pck >= 0.9 && oks >= 0.8, "{}: PCK@0.2 {pck}, OKS {oks}", report["label"]);
    }
    assert_eq!(reports[1]["crop"], "region");
    assert!(stdout.contains("| full frame |"), "{stdout}");

    // The annotation says another size than the image has; the image is missing.
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("detector-eval");
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(&coco).unwrap();
    let resized = dir.join("resized.json");
    std::fs::write(&resized, text.replace("\"width\": 640", "\"width\": 641")).unwrap();
    let images = data.display().to_string();
    let out = egoexo(&["detector-eval", "--coco", &resized.display().to_string(), "--images", &images]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("000000000785.jpg is 640×425 px") && stderr.contains("641×425"),
        "{stderr}"
    );
    let out = egoexo(&["detector-eval", "--coco", &resized.display().to_string()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("cannot decode") && stderr.contains("000000000785.jpg"),
        "{stderr}"
    );
}
