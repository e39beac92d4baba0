//! CMU trials in BVH form: a real ASF/AMC trial is written as a CMU-style BVH (joint names of
//! the community conversions, ZYX or ZXY channels, CMU units or centimetres) with the
//! project's BVH writer, and importing that BVH must give the AMC import's library clips.

use crate::common;

use egoexo_core::euler::EulerOrder;
use egoexo_core::glam::DVec3;
use egoexo_mocap::bvh::{CMU_BVH_JOINTS, import_bvh_trial};
use egoexo_mocap::fs::{import_tree, scan_cmu_tree};
use egoexo_mocap::retarget::RetargetError;
use egoexo_mocap::{CatalogEntry, ImportError, ImportOptions, SubjectImporter, TrialImport};
use egoexo_motion_io::bvh::{Bvh, BvhJoint, Channel};

/// The trial as BVH text; lengths in file units of `metres_per_unit`.
fn to_cmu_bvh(importer: &SubjectImporter, amc: &str, file: &str, metres_per_unit: f64, order: EulerOrder) -> String {
    let skeleton = importer.cmu_skeleton();
    let bones = skeleton.bones();
    // Depth-first order (BVH requires contiguous subtrees).
    let mut order_dfs = Vec::new();
    let mut stack = vec![0usize];
    while let Some(b) = stack.pop() {
        order_dfs.push(b);
        let children: Vec<usize> = (0..bones.len()).filter(|&c| bones[c].parent == Some(b)).collect();
        stack.extend(children.into_iter().rev());
    }
    let position_in_file = |b: usize| order_dfs.iter().position(|&x| x == b).unwrap();
    let name = |b: usize| {
        let asf = bones[b].name.as_str();
        CMU_BVH_JOINTS.iter().find(|(a, _)| *a == asf).map_or(asf.to_owned(), |(_, n)| (*n).to_owned())
    };
    let units = |v: egoexo_core::glam::Vec3| v.as_dvec3() / metres_per_unit;
    let joints: Vec<BvhJoint> = order_dfs
        .iter()
        .map(|&b| {
            let mut channels = Vec::new();
            if b == 0 {
                channels.extend(
                    [Channel::parse("Xposition"), Channel::parse("Yposition"), Channel::parse("Zposition")]
                        .map(Option::unwrap),
                );
            }
            channels.extend(Channel::rotations(order));
            let is_leaf = !(0..bones.len()).any(|c| bones[c].parent == Some(b));
            BvhJoint {
                name: name(b),
                parent: bones[b].parent.map(position_in_file),
                offset: bones[b].parent.map_or(DVec3::ZERO, |p| units(bones[p].rest_offset)),
                channels,
                end_site: is_leaf.then(|| units(bones[b].rest_offset)),
            }
        })
        .collect();
    let poses = importer.parse_motion(amc, file).unwrap();
    let mut values = Vec::new();
    for pose in &poses {
        for &b in &order_dfs {
            if b == 0 {
                values.extend(units(pose.root_translation).to_array());
            }
            values.extend(order.angles_f64(pose.local_rotations[b].as_dquat()).map(f64::to_degrees));
        }
    }
    Bvh::new(joints, 1.0 / 120.0, values).unwrap().to_bvh_string(6)
}

fn assert_same_import(a: &TrialImport, b: &TrialImport) {
    assert_eq!(a.clips.len(), b.clips.len());
    for (x, y) in a.clips.iter().zip(&b.clips) {
        assert_eq!(x.info.source_range, y.info.source_range);
        assert_eq!(x.poses.len(), y.poses.len());
        assert!((x.info.head_height_m - y.info.head_height_m).abs() < 1e-4);
        assert!((x.info.retarget.mean_cm - y.info.retarget.mean_cm).abs() < 0.02);
        for (f, (p, q)) in x.poses.iter().zip(&y.poses).enumerate() {
            assert!(p.translation.distance(q.translation) < 1e-3, "frame {f}: {} vs {}", p.translation, q.translation);
            assert!(p.root_orientation.angle_between(q.root_orientation) < 2e-3, "frame {f}");
            for (k, (r, s)) in p.body.iter().zip(&q.body).enumerate() {
                assert!(r.angle_between(*s) < 5e-3, "frame {f}, joint {}: {}", k + 1, r.angle_between(*s));
            }
        }
    }
}

#[test]
fn a_cmu_bvh_imports_like_its_amc_in_any_unit_and_channel_order() {
    let dir = require_cmu!();
    let importer = common::subject(&dir, 2);
    let (amc, file) = common::amc(&dir, 2, 1);
    let entry = common::catalog(&dir).get(2, 1).unwrap().clone();
    let options = ImportOptions::default();
    let from_amc = importer.import_trial(1, &amc, &file, &entry, &options).unwrap();

    let cmu_units = to_cmu_bvh(&importer, &amc, &file, 0.0254 / 0.45, EulerOrder::ZYX);
    let from_bvh = import_bvh_trial(&cmu_units, "02_01.bvh", 2, 1, &entry, &options).unwrap();
    assert_same_import(&from_amc, &from_bvh);

    let centimetres = to_cmu_bvh(&importer, &amc, &file, 0.01, EulerOrder::ZXY);
    let from_cm = import_bvh_trial(&centimetres, "02_01.bvh", 2, 1, &entry, &options).unwrap();
    assert_same_import(&from_amc, &from_cm);

    // An explicit unit is used as given: twice the true unit doubles the subject.
    let doubled = ImportOptions { bvh_metres_per_unit: Some(2.0 * 0.0254 / 0.45), ..ImportOptions::default() };
    let giant = import_bvh_trial(&cmu_units, "02_01.bvh", 2, 1, &entry, &doubled).unwrap();
    let ratio = giant.clips[0].info.head_height_m / from_amc.clips[0].info.head_height_m;
    assert!((ratio - 2.0).abs() < 1e-3, "{ratio}");
    let bad = ImportOptions { bvh_metres_per_unit: Some(-1.0), ..ImportOptions::default() };
    assert!(matches!(import_bvh_trial(&cmu_units, "02_01.bvh", 2, 1, &entry, &bad), Err(ImportError::BvhUnit { .. })));
}

#[test]
fn bvh_files_in_a_tree_are_imported_unless_their_amc_is_there() {
    let dir = require_cmu!();
    let importer = common::subject(&dir, 2);
    let (amc, file) = common::amc(&dir, 2, 1);
    let root = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("mocap_bvh_tree");
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(root.join("cmuconvert/02")).unwrap();
    std::fs::write(
        root.join("cmuconvert/02/02_01.bvh"),
        to_cmu_bvh(&importer, &amc, &file, 0.0254 / 0.45, EulerOrder::ZYX),
    )
    .unwrap();
    std::fs::copy(dir.join("CMU_data.csv"), root.join("CMU_data.csv")).unwrap();

    let tree = scan_cmu_tree(&root).unwrap();
    assert_eq!(tree.bvh_trials.len(), 1);
    assert_eq!(tree.subject_numbers(), vec![2]);
    let catalog = common::catalog(&dir);
    let result = import_tree(&tree, &catalog, &ImportOptions::default(), None, &|_| {}).unwrap();
    assert!(result.failures.is_empty(), "{:?}", result.failures);
    assert_eq!(result.library.clips().len(), 1);
    assert_eq!(result.library.clips()[0].name, "02_01");
    assert_eq!(result.library.clips()[0].description, "walk");

    // With the ASF/AMC beside it, the AMC wins and the BVH is noted as ignored.
    std::fs::create_dir_all(root.join("subjects/02")).unwrap();
    std::fs::copy(dir.join("02/02.asf"), root.join("subjects/02/02.asf")).unwrap();
    std::fs::copy(dir.join("02/02_01.amc"), root.join("subjects/02/02_01.amc")).unwrap();
    let tree = scan_cmu_tree(&root).unwrap();
    assert!(tree.bvh_trials.is_empty());
    assert!(tree.ignored.iter().any(|(p, why)| p.ends_with("02_01.bvh") && why.contains("AMC")));
}

#[test]
fn bvh_errors_name_the_file() {
    let entry = CatalogEntry { description: String::new(), framerate: 120.0 };
    let options = ImportOptions::default();
    let err = import_bvh_trial("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n", "x.bvh", 1, 1, &entry, &options).unwrap_err();
    assert!(err.to_string().starts_with("x.bvh: ") && err.to_string().contains("line 4"), "{err}");
    // A valid BVH that is not a CMU skeleton.
    let other = "HIERARCHY\nROOT pelvis\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n  End Site\n  {\n    OFFSET 0 1 0\n  }\n}\nMOTION\nFrames: 1\nFrame Time: 0.01\n0 0 0\n";
    let err = import_bvh_trial(other, "y.bvh", 1, 1, &entry, &options).unwrap_err();
    assert!(matches!(err, ImportError::Retarget { source: RetargetError::MissingBone { .. }, .. }), "{err}");
    assert!(err.to_string().starts_with("y.bvh: "), "{err}");
}
