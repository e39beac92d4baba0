//! The extra CMU subjects (`shared/data/cmu-extra`): original ASF/AMC beside cgspeed's three
//! BVH releases (MotionBuilder with a prepended T-pose row, 3dsMax with zero hip-joint
//! offsets, DAZ on one standard 43-joint figure). Each release must be recognised by its
//! joint names and retargeted; a trial present both ways must come out as the same motion.
//! Skipped, with a message, when the data is absent.

use crate::common;

use std::collections::BTreeMap;

use egoexo_core::glam::Vec3;
use egoexo_core::skeleton::NUM_JOINTS;
use egoexo_mocap::bvh::{CmuBvhNaming, import_bvh_trial, leading_reference_rows};
use egoexo_mocap::fs::{import_tree, scan_cmu_trees};
use egoexo_mocap::{ImportOptions, SubjectImporter, TrialImport};
use egoexo_motion_io::bvh::Bvh;

fn extra_dirs() -> Option<(std::path::PathBuf, std::path::PathBuf)> {
    Some((common::cmu_dir()?, egoexo_test_support::cmu_extra_dir()?))
}

fn bvh_file(extra: &std::path::Path, release: &str, subject: u32, trial: u32) -> (String, String) {
    let path = extra.join(format!("bvh/{release}/{subject:02}/{subject:02}_{trial:02}.bvh"));
    (std::fs::read_to_string(&path).unwrap(), path.display().to_string())
}

fn import_bvh(cmu: &std::path::Path, extra: &std::path::Path, release: &str, subject: u32, trial: u32) -> TrialImport {
    let (text, file) = bvh_file(extra, release, subject, trial);
    let entry = common::catalog(cmu).get(subject, trial).unwrap().clone();
    import_bvh_trial(&text, &file, subject, trial, &entry, &ImportOptions::default()).expect("BVH imports")
}

#[test]
fn each_cgspeed_release_is_recognised_and_only_motionbuilder_has_reference_rows() {
    let Some((_, extra)) = extra_dirs() else { return };
    for (release, subject, trial, naming, reference_rows) in [
        ("cgspeed-mb2", 1, 2, CmuBvhNaming::CgspeedMotionBuilder, 1),
        ("cgspeed-mb2", 8, 3, CmuBvhNaming::CgspeedMotionBuilder, 1),
        // A T-pose row, then a row of zeros.
        ("cgspeed-mb2", 7, 12, CmuBvhNaming::CgspeedMotionBuilder, 2),
        ("cgspeed-max", 131, 1, CmuBvhNaming::Cgspeed3dsMax, 0),
        ("cgspeed-daz", 12, 1, CmuBvhNaming::CgspeedDaz, 0),
    ] {
        let (text, file) = bvh_file(&extra, release, subject, trial);
        let bvh = Bvh::parse(&text).unwrap();
        assert_eq!(CmuBvhNaming::detect(&bvh), Some(naming), "{file}");
        assert_eq!(leading_reference_rows(&bvh), reference_rows, "{file}");
    }
}

#[test]
fn the_whole_extra_tree_imports_with_a_retarget_error_per_source() {
    let Some((cmu, extra)) = extra_dirs() else { return };
    let tree = scan_cmu_trees(std::slice::from_ref(&extra)).unwrap();
    assert_eq!(tree.subject_numbers(), vec![1, 3, 7, 8, 11, 12, 131, 135]);
    // 01_01 and 07_05 exist as AMC too: the AMC wins.
    let skipped: Vec<String> =
        tree.ignored.iter().map(|(p, _)| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    assert_eq!(skipped, vec!["01_01.bvh", "07_05.bvh"]);
    let catalog = common::catalog(&cmu);
    let result = import_tree(&tree, &catalog, &ImportOptions::default(), None, &|_| {}).unwrap();
    assert!(result.failures.is_empty(), "{:?}", result.failures);
    assert_eq!(result.trials, 50);
    // Every MotionBuilder trial had its T-pose row left out, and no other.
    assert_eq!(result.reference_rows_skipped.len(), 39);
    assert!(result.reference_rows_skipped.iter().all(|p| p.to_string_lossy().contains("cgspeed-mb2")));
    let library = &result.library;
    let by_source: BTreeMap<String, f32> = library
        .clips_by_source_format()
        .into_iter()
        .map(|(source, clips)| (source, library.retarget_summary(&clips).mean_cm))
        .collect();
    eprintln!("retarget mean per source (cm): {by_source:?}");
    let expected: [(&str, f32); 4] = [
        ("ASF/AMC", 3.0),
        // With the collapsed thorax restored (4.6 and 4.1 cm without).
        ("BVH (cgspeed MotionBuilder)", 3.5),
        ("BVH (cgspeed 3dsMax)", 3.2),
        // One standard figure, not the subject's bones.
        ("BVH (cgspeed DAZ, standard figure)", 3.5),
    ];
    assert_eq!(by_source.len(), expected.len(), "{by_source:?}");
    for (source, limit) in expected {
        let mean = by_source[source];
        assert!(mean > 0.5 && mean < limit, "{source}: retarget mean {mean} cm (limit {limit})");
    }
    // Heads at human heights whatever the release's units.
    for c in library.clips() {
        assert!((1.2..1.75).contains(&c.head_height_m), "{}: head height {}", c.label(), c.head_height_m);
    }
}

/// 01_01 is in the extra data both as ASF/AMC and as MotionBuilder BVH (the same capture
/// with a T-pose row in front): both imports must give the same motion — same frames, the
/// same subject height once the conversion's collapsed thorax is restored (without it the
/// BVH subject came out 11.7 cm shorter and the pelvis 4 cm off), the joints within 2 cm.
#[test]
fn a_trial_imported_from_bvh_matches_its_amc_import() {
    let Some((cmu, extra)) = extra_dirs() else { return };
    let asf = extra.join("asfamc/01/01.asf");
    let importer =
        SubjectImporter::new(1, &std::fs::read_to_string(&asf).unwrap(), &asf.display().to_string()).unwrap();
    let amc_path = extra.join("asfamc/01/01_01.amc");
    let entry = common::catalog(&cmu).get(1, 1).unwrap().clone();
    let amc = importer
        .import_trial(1, &std::fs::read_to_string(&amc_path).unwrap(), "01_01.amc", &entry, &ImportOptions::default())
        .unwrap();
    let bvh = import_bvh(&cmu, &extra, "cgspeed-mb2", 1, 1);
    assert_eq!(bvh.reference_rows_skipped, 1);
    assert_eq!(amc.source_frames, bvh.source_frames, "the same capture once the T-pose row is out");
    let (a, b) = (&amc.clips[0], &bvh.clips[0]);
    assert_eq!(b.info.source_format, "BVH (cgspeed MotionBuilder)");
    let n = a.poses.len().min(b.poses.len());
    assert!(n + 2 >= a.poses.len().max(b.poses.len()), "{} vs {} frames", a.poses.len(), b.poses.len());
    let fk = |clip: &egoexo_mocap::LibraryClip| -> Vec<[Vec3; NUM_JOINTS]> {
        let skeleton = clip.info.skeleton();
        clip.poses.iter().take(n).map(|p| skeleton.forward_kinematics(p).positions).collect()
    };
    let (pa, pb) = (fk(a), fk(b));
    // Source ranges count file rows: the BVH's row 1 is the AMC's frame 0.
    assert_eq!(b.info.source_range[0], a.info.source_range[0] + 1, "both clips start at the same captured frame");
    assert_eq!(b.info.source_frames, a.info.source_frames + 1);
    let pelvis: f32 = pa.iter().zip(&pb).map(|(x, y)| x[0].distance(y[0])).sum::<f32>() / n as f32;
    let mpjpe: f32 =
        pa.iter().zip(&pb).map(|(x, y)| (0..NUM_JOINTS).map(|j| x[j].distance(y[j])).sum::<f32>() / 24.0).sum::<f32>()
            / n as f32;
    let head_gap = (a.info.head_height_m - b.info.head_height_m).abs();
    eprintln!(
        "01_01 AMC vs BVH: pelvis {:.2} cm, all joints {:.2} cm, head heights {:.3} / {:.3} m",
        pelvis * 100.0,
        mpjpe * 100.0,
        a.info.head_height_m,
        b.info.head_height_m
    );
    assert!(bvh.restored_thorax_m.is_some_and(|l| (0.10..0.13).contains(&l)), "{:?}", bvh.restored_thorax_m);
    assert!(pelvis < 0.01, "pelvis paths differ by {pelvis} m on average");
    assert!(mpjpe < 0.02, "joints differ by {mpjpe} m on average");
    assert!(head_gap < 0.01, "head heights differ by {head_gap} m");
}
