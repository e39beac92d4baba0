//! Retargeting checked on the real CMU subset (`shared/data/cmu`) with numbers, not eyes:
//! head heights, feet on the floor, left is left, facing the walking direction, retarget
//! error, resampling durations, corrupt-frame trimming and the library round trip.
//! Skipped, with a message, when the data is absent.

use crate::common;

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::skeleton::{NUM_JOINTS, PARENTS, SmplJoint, SmplPose};
use egoexo_mocap::kinematics::CmuBoneTransforms;
use egoexo_mocap::{CatalogEntry, ImportOptions, MotionLibrary, SubjectImporter, TrialImport};

const FEET: [usize; 4] = [7, 8, 10, 11];

fn import(importer: &SubjectImporter, dir: &std::path::Path, trial: u32, entry: &CatalogEntry) -> TrialImport {
    let (text, file) = common::amc(dir, importer.subject(), trial);
    importer.import_trial(trial, &text, &file, entry, &ImportOptions::default()).expect("trial imports")
}

fn catalog_entry(dir: &std::path::Path, subject: u32, trial: u32) -> CatalogEntry {
    common::catalog(dir).get(subject, trial).expect("trial is in CMU_data.csv").clone()
}

/// Mapped CMU joint positions at the library's frames of clip 0 (every 4th source frame at
/// 120 Hz).
fn cmu_targets_at_30fps(
    importer: &SubjectImporter,
    dir: &std::path::Path,
    trial: u32,
    start: usize,
) -> Vec<[Vec3; NUM_JOINTS]> {
    let (text, file) = common::amc(dir, importer.subject(), trial);
    let poses = importer.parse_motion(&text, &file).unwrap();
    importer.joint_positions(&poses).into_iter().skip(start).step_by(4).collect()
}

#[test]
fn standing_head_heights_are_human() {
    let dir = require_cmu!();
    for subject in [2, 5, 6, 9, 10, 14, 16, 35, 55, 93, 105] {
        let importer = common::subject(&dir, subject);
        let h = importer.retargeter().head_height();
        let expected = if subject == 105 { 1.25..1.36 } else { 1.42..1.62 };
        assert!(expected.contains(&h), "subject {subject}: standing head height {h} m");
        // The scaled SMPL skeleton has exactly that head height.
        let smpl_h = importer.retargeter().smpl_skeleton().head_height();
        assert!((smpl_h - h).abs() < 1e-4, "subject {subject}: {smpl_h} vs {h}");
    }
}

#[test]
fn walking_clip_stands_on_the_floor_faces_forward_and_keeps_left_left() {
    let dir = require_cmu!();
    let importer = common::subject(&dir, 2);
    let import = import(&importer, &dir, 1, &catalog_entry(&dir, 2, 1));
    assert_eq!(import.clips.len(), 1);
    let clip = &import.clips[0];
    let skeleton = importer.retargeter().smpl_skeleton();
    let smpl: Vec<[Vec3; NUM_JOINTS]> = clip.poses.iter().map(|p| skeleton.forward_kinematics(p).positions).collect();
    let cmu = cmu_targets_at_30fps(&importer, &dir, 1, clip.info.source_range[0] as usize);
    assert_eq!(smpl.len(), cmu.len());

    // Feet on the floor: walking has no flight phase, so in every frame the lowest SMPL
    // foot joint is where the lowest CMU foot joint is (a few cm above the floor, y = 0).
    let lowest = |p: &[Vec3; NUM_JOINTS]| FEET.iter().map(|&j| p[j].y).fold(f32::INFINITY, f32::min);
    for (f, (s, c)) in smpl.iter().zip(&cmu).enumerate() {
        let (ls, lc) = (lowest(s), lowest(c));
        assert!((ls - lc).abs() < 0.03, "frame {f}: lowest SMPL foot joint {ls} m, CMU {lc} m");
        assert!((-0.02..0.08).contains(&ls), "frame {f}: lowest foot joint {ls} m above the floor");
    }
    // Upright: the head joint stays near the standing head height above the lowest foot.
    let head = importer.retargeter().head_height();
    for (f, s) in smpl.iter().enumerate() {
        let h = s[SmplJoint::Head.index()].y - lowest(s);
        assert!((h - head).abs() < 0.08, "frame {f}: head {h} m above the feet, standing {head} m");
    }

    // Faces the walking direction: SMPL's body frame faces +Z.
    let walk = {
        let d = smpl.last().unwrap()[0] - smpl[0][0];
        Vec3::new(d.x, 0.0, d.z)
    };
    assert!(walk.length() > 1.5, "walked only {} m", walk.length());
    let walk = walk.normalize();
    for (f, pose) in clip.poses.iter().enumerate() {
        let facing = pose.root_orientation * Vec3::Z;
        let facing = Vec3::new(facing.x, 0.0, facing.z).normalize();
        assert!(facing.dot(walk) > 0.85, "frame {f}: facing {facing} while walking {walk}");
    }

    // Left is left: the subject's left (up × forward) is where SMPL's left joints are, and
    // each SMPL left joint follows the CMU left limb, not the right one.
    let left = Vec3::Y.cross(walk);
    for (f, (s, c)) in smpl.iter().zip(&cmu).enumerate() {
        for (l, r) in [(1, 2), (16, 17), (13, 14)] {
            assert!((s[l] - s[r]).dot(left) > 0.05, "frame {f}: joint {l} is not left of {r}");
        }
        for (l, r) in [(20, 21), (7, 8), (10, 11), (18, 19)] {
            assert!(s[l].distance(c[l]) < s[l].distance(c[r]), "frame {f}: SMPL joint {l} is nearer CMU's right side");
            assert!(s[r].distance(c[r]) < s[r].distance(c[l]), "frame {f}: SMPL joint {r} is nearer CMU's left side");
        }
    }
}

#[test]
fn a_planted_foot_does_not_slide() {
    // With the wrong Euler convention the stance foot skates; with ASF semantics it rests.
    let dir = require_cmu!();
    let importer = common::subject(&dir, 2);
    let import = import(&importer, &dir, 1, &catalog_entry(&dir, 2, 1));
    let skeleton = importer.retargeter().smpl_skeleton();
    let smpl: Vec<[Vec3; NUM_JOINTS]> =
        import.clips[0].poses.iter().map(|p| skeleton.forward_kinematics(p).positions).collect();
    for foot in [10, 11] {
        let slowest = smpl.windows(2).map(|w| w[0][foot].distance(w[1][foot]) * 30.0).fold(f32::INFINITY, f32::min);
        assert!(slowest < 0.05, "foot joint {foot} never rests: slowest {slowest} m/s");
    }
}

#[test]
fn retarget_error_is_within_target_on_a_sample_of_clips() {
    let dir = require_cmu!();
    let catalog = common::catalog(&dir);
    let (mut sum, mut frames) = (0.0f64, 0.0f64);
    for (subject, trial) in [(2, 1), (16, 15), (35, 18), (93, 6), (10, 5)] {
        let importer = common::subject(&dir, subject);
        let entry = catalog.get(subject, trial).unwrap();
        let import = import(&importer, &dir, trial, entry);
        for clip in &import.clips {
            let r = &clip.info.retarget;
            // The target is 3 cm; the retarget reaches 2.71 cm over the whole subset
            // (see `retarget`'s design note) and 1.8–2.9 cm per clip here.
            eprintln!("{}: mean {:.3} cm, p95 {:.2} cm", clip.info.label(), r.mean_cm, r.p95_cm);
            assert!(
                r.mean_cm <= 3.2 && r.p95_cm <= 6.0,
                "{}: mean {} cm, p95 {} cm",
                clip.info.label(),
                r.mean_cm,
                r.p95_cm
            );
            assert_eq!(r.per_joint_mean_cm.len(), NUM_JOINTS);
            let n: u64 = clip.error_histogram.iter().map(|&c| u64::from(c)).sum();
            assert_eq!(n, clip.poses.len() as u64 * NUM_JOINTS as u64);
            sum += f64::from(r.mean_cm) * clip.poses.len() as f64;
            frames += clip.poses.len() as f64;
        }
    }
    let mean = sum / frames;
    eprintln!("mean over the sample {mean:.3} cm");
    assert!(mean <= 3.0, "mean over the sample {mean} cm");
}

/// SMPL torso joints and the CMU segment each follows.
const TORSO_SEGMENTS: [(usize, &str); 8] = [
    (0, "root"),
    (3, "upperback"),
    (6, "thorax"),
    (9, "thorax"),
    (12, "upperneck"),
    (13, "lclavicle"),
    (14, "rclavicle"),
    (15, "head"),
];
const COLLARS: [usize; 2] = [13, 14];

/// Largest bend (degrees) of a torso joint away from the CMU segments, in the neutral pose and
/// while walking: pelvis, spine, neck and head lean a few degrees at most, the collars
/// (shoulder girdle) a bit more. (Fitting the torso to positions freely bent the neck ~80°.)
fn bend_limit(joint: usize) -> f32 {
    if COLLARS.contains(&joint) { 16.0 } else { 8.0 }
}

/// How far each SMPL torso joint bends away from the CMU segments it follows, degrees: the
/// angle between its local rotation and the relative rotation of its own and its parent's
/// CMU segments (for the pelvis, between its orientation and the CMU root's).
fn torso_bends(importer: &SubjectImporter, fk: &CmuBoneTransforms, pose: &SmplPose) -> [(usize, f32); 8] {
    let global = importer.retargeter().smpl_skeleton().forward_kinematics(pose).rotations;
    let segment = |j: usize| {
        let (_, bone) = TORSO_SEGMENTS.iter().find(|(t, _)| *t == j).expect("a torso joint");
        fk.rotations[importer.cmu_skeleton().bone_index(bone).expect("CMU bone")]
    };
    TORSO_SEGMENTS.map(|(j, _)| {
        let (smpl, cmu) = match PARENTS[j] {
            p if p < 0 => (global[j], segment(j)),
            p => {
                let p = p as usize;
                (global[p].conjugate() * global[j], segment(p).conjugate() * segment(j))
            }
        };
        (j, smpl.angle_between(cmu).to_degrees())
    })
}

#[test]
fn a_neutral_cmu_posture_gives_a_neutral_smpl_torso_and_the_head_follows_the_real_head() {
    let dir = require_cmu!();
    for subject in [2, 5, 6, 9, 10, 14, 16, 35, 55, 93, 105] {
        let importer = common::subject(&dir, subject);
        let skeleton = importer.cmu_skeleton();
        let fk = skeleton.forward_kinematics(&skeleton.rest_pose());
        let frame = importer.retargeter().retarget(&fk);
        // SMPL's own rest shape, leaning a little to absorb the skeletons' different
        // proportions.
        for (j, bend) in torso_bends(&importer, &fk, &frame.pose) {
            assert!(bend < bend_limit(j), "subject {subject}: joint {j} bent {bend}° in the neutral pose");
        }
        // The head is exactly the CMU head.
        let head = importer.retargeter().smpl_skeleton().forward_kinematics(&frame.pose).rotations[15];
        assert!(head.angle_between(Quat::IDENTITY).to_degrees() < 0.1, "subject {subject}");
        // Limbs: only CMU's rest-pose differences (legs splayed ~20°, arms straight out).
        for j in 1..=21 {
            let angle = frame.pose.local_rotation(j).angle_between(Quat::IDENTITY).to_degrees();
            assert!(angle < 30.0, "subject {subject}: joint {j} turned {angle}° in the neutral pose");
        }
    }

    // While walking, the SMPL head has the CMU head segment's orientation (a head-mounted
    // device follows the subject's real head), and the torso bends only a little away from
    // the CMU torso.
    let importer = common::subject(&dir, 2);
    let import = import(&importer, &dir, 1, &catalog_entry(&dir, 2, 1));
    let (text, file) = common::amc(&dir, 2, 1);
    let cmu = importer.parse_motion(&text, &file).unwrap();
    let head_bone = importer.cmu_skeleton().bone_index("head").unwrap();
    let smpl_skeleton = importer.retargeter().smpl_skeleton();
    let mut largest = [0.0f32; NUM_JOINTS];
    for (k, pose) in import.clips[0].poses.iter().enumerate() {
        let fk = importer.cmu_skeleton().forward_kinematics(&cmu[4 * k]);
        let head = smpl_skeleton.forward_kinematics(pose).rotations[SmplJoint::Head.index()];
        assert!(head.angle_between(fk.rotations[head_bone]).to_degrees() < 0.5, "frame {k}");
        for (j, bend) in torso_bends(&importer, &fk, pose) {
            largest[j] = largest[j].max(bend);
            assert!(bend < bend_limit(j), "frame {k}: joint {j} bent {bend}° away from the CMU torso");
        }
    }
    eprintln!("largest torso bends while walking (°): {:?}", TORSO_SEGMENTS.map(|(j, _)| (j, largest[j])));
}

#[test]
fn stored_error_statistics_match_a_recomputation_from_the_library() {
    let dir = require_cmu!();
    let importer = common::subject(&dir, 2);
    let import = import(&importer, &dir, 1, &catalog_entry(&dir, 2, 1));
    let library = MotionLibrary::build(30.0, "test", import.clips).unwrap();
    let library = MotionLibrary::from_bytes(library.as_bytes().to_vec()).unwrap();
    let motion = library.motion(0).unwrap();
    let info = &library.clips()[0];
    let cmu = cmu_targets_at_30fps(&importer, &dir, 1, info.source_range[0] as usize);
    let mut sum = 0.0f64;
    for (p, c) in motion.joint_positions().iter().zip(&cmu) {
        for j in 0..NUM_JOINTS {
            sum += f64::from(p[j].distance(c[j]));
        }
    }
    let mean_cm = (sum / (cmu.len() * NUM_JOINTS) as f64 * 100.0) as f32;
    assert!(
        (mean_cm - info.retarget.mean_cm).abs() < 0.01,
        "recomputed {mean_cm} cm, stored {} cm",
        info.retarget.mean_cm
    );
}

#[test]
fn the_parallel_tree_import_is_deterministic() {
    let dir = require_cmu!();
    let tree = egoexo_mocap::fs::scan_cmu_tree(&dir).unwrap();
    let catalog = common::catalog(&dir);
    let subjects = [2, 16];
    let run =
        || egoexo_mocap::fs::import_tree(&tree, &catalog, &ImportOptions::default(), Some(&subjects), &|_| {}).unwrap();
    let (a, b) = (run(), run());
    assert!(a.failures.is_empty() && a.trials > 0);
    assert_eq!(a.library.as_bytes(), b.library.as_bytes(), "two imports give the same library, byte for byte");
    // Each clip is what a sequential import of its trial gives.
    let importer = common::subject(&dir, 16);
    let sequential = import(&importer, &dir, 15, &catalog_entry(&dir, 16, 15));
    let i = a.library.find("16_15").unwrap();
    assert_eq!(a.library.motion(i).unwrap().poses, sequential.clips[0].poses);
}

#[test]
fn resampling_follows_the_true_capture_rate() {
    let dir = require_cmu!();
    let importer = common::subject(&dir, 2);
    let at_120 = catalog_entry(&dir, 2, 1);
    assert_eq!(at_120.framerate, 120.0);
    let fast = import(&importer, &dir, 1, &at_120);
    // The same file declared as a 60 Hz capture (as subjects 60–62, 74, … are) lasts twice
    // as long.
    let at_60 = CatalogEntry { framerate: 60.0, ..at_120.clone() };
    let slow = import(&importer, &dir, 1, &at_60);
    let (fast, slow) = (&fast.clips[0], &slow.clips[0]);
    let source = (fast.info.source_range[1] - fast.info.source_range[0]) as usize;
    assert_eq!(source, 343);
    assert_eq!(fast.poses.len(), (source - 1) / 4 + 1);
    assert_eq!(slow.poses.len(), (source - 1) / 2 + 1);
    let duration = |c: &egoexo_mocap::LibraryClip| c.info.duration_s(30.0);
    assert!((duration(fast) - 342.0 / 120.0).abs() < 1.0 / 30.0);
    assert!((duration(slow) - 342.0 / 60.0).abs() < 1.0 / 30.0);
    // Output frame k is source frame 4k at 120 Hz and 2k at 60 Hz: frame 1 of the first is
    // frame 2 of the second.
    assert_eq!(fast.poses[1], slow.poses[2]);
    assert_eq!(fast.poses[0], slow.poses[0]);
    // A rate that is not a multiple interpolates (slerp/lerp) between source frames.
    let at_100 = CatalogEntry { framerate: 100.0, ..at_120 };
    let odd = import(&importer, &dir, 1, &at_100);
    assert_eq!(odd.clips[0].poses.len(), (342.0f32 * 0.3).floor() as usize + 1);
    let t = odd.clips[0].poses[1].translation;
    let (a, b) = (slow.poses[0].translation, slow.poses[3].translation);
    assert!(t.is_finite() && t.distance(a) < a.distance(b) + 0.05);
}

#[test]
fn corrupt_first_frames_are_trimmed() {
    let dir = require_cmu!();
    let importer = common::subject(&dir, 16);
    let catalog = common::catalog(&dir);
    for (trial, first_good, frames) in [(15, 2, 471), (23, 3, 299), (28, 6, 271)] {
        let import = import(&importer, &dir, trial, catalog.get(16, trial).unwrap());
        assert_eq!(import.clips.len(), 1, "16_{trial}");
        assert_eq!(import.clips[0].info.source_range, [first_good, frames], "16_{trial}");
        assert_eq!(import.dropped_frames, first_good as usize, "16_{trial}");
        assert!(import.glitches >= 1);
        // What is left moves like a body: no joint faster than 20 m/s between library frames.
        let skeleton = importer.retargeter().smpl_skeleton();
        let p: Vec<_> = import.clips[0].poses.iter().map(|q| skeleton.forward_kinematics(q).positions).collect();
        for w in p.windows(2) {
            for j in 0..NUM_JOINTS {
                assert!(w[0][j].distance(w[1][j]) * 30.0 < 20.0, "16_{trial}: joint {j} jumps");
            }
        }
    }
    // A clean trial loses nothing.
    let clean = import(&importer, &dir, 2, catalog.get(16, 2).unwrap());
    assert_eq!(clean.clips[0].info.source_range, [0, clean.source_frames as u32]);
    assert_eq!(clean.dropped_frames, 0);
}

#[test]
fn library_round_trip_and_subject_split() {
    let dir = require_cmu!();
    let catalog = common::catalog(&dir);
    let mut clips = Vec::new();
    for (subject, trials) in [(2u32, [1u32, 2]), (16, [15, 2])] {
        let importer = common::subject(&dir, subject);
        for trial in trials {
            clips.extend(import(&importer, &dir, trial, catalog.get(subject, trial).unwrap()).clips);
        }
    }
    let originals = clips.clone();
    let built = MotionLibrary::build(30.0, "test", clips).unwrap();
    let library = MotionLibrary::from_bytes(built.as_bytes().to_vec()).unwrap();
    assert_eq!(library.subjects(), vec![2, 16]);
    assert_eq!(library.clips_of_subjects(&[16]).len(), 2);
    assert_eq!(library.clips_of_subjects(&[2, 16]).len(), 4);
    assert_eq!(library.total_frames(), originals.iter().map(|c| c.poses.len()).sum::<usize>());
    for (i, original) in originals.iter().enumerate() {
        let motion = library.motion(i).unwrap();
        assert_eq!(motion.fps, 30.0);
        assert_eq!(motion.poses, original.poses, "clip {i} decodes bit for bit");
        assert_eq!(library.error_histogram(i), original.error_histogram);
        assert_eq!(library.clips()[i].description, original.info.description);
        assert_eq!(library.find(&original.info.label()), Some(i));
    }
    assert_eq!(library.find("16_15"), Some(2));
    let importer = common::subject(&dir, 16);
    assert_eq!(&library.motion(2).unwrap().skeleton, importer.retargeter().smpl_skeleton());
    assert_eq!(library.clips()[0].description, "walk");
    let summary = library.retarget_summary(&(0..4).collect::<Vec<_>>());
    assert!(summary.mean_cm > 0.5 && summary.mean_cm <= 3.3 && summary.p95_cm >= summary.mean_cm);
}
