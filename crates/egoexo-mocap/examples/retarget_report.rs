//! Retarget quality on a CMU tree: per-subject mean/p95 joint error (as `egoexo mocap info`
//! reports it), per-joint means, import time, and how far SMPL's torso joints turn away from
//! the CMU segments they follow (local rotations, degrees).
//!
//! `cargo run --release -p egoexo-mocap --example retarget_report -- <cmu dir> [subjects,..]
//! [--no-bends]` (`--no-bends`: only the import and its errors, e.g. for timing).

use std::path::PathBuf;
use std::time::Instant;

use egoexo_core::glam::Quat;
use egoexo_core::skeleton::{JOINT_NAMES, NUM_JOINTS, PARENTS};
use egoexo_mocap::fs::{import_tree, read_catalog, read_text, scan_cmu_tree};
use egoexo_mocap::{ImportOptions, SubjectImporter};

/// Torso joints and the CMU segment each follows.
const TORSO: [(usize, &str); 8] = [
    (0, "root"),
    (3, "upperback"),
    (6, "thorax"),
    (9, "thorax"),
    (12, "upperneck"),
    (15, "head"),
    (13, "lclavicle"),
    (14, "rclavicle"),
];

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let bends = !args.iter().any(|a| a == "--no-bends");
    let mut args = args.iter().filter(|a| !a.starts_with("--"));
    let root = PathBuf::from(args.next().expect("usage: retarget_report <cmu dir> [subjects] [--no-bends]"));
    let subjects: Option<Vec<u32>> = args.next().map(|s| s.split(',').map(|n| n.parse().unwrap()).collect());
    let tree = scan_cmu_tree(&root).unwrap();
    let catalog = read_catalog(&tree.catalog.clone().unwrap()).unwrap();

    let start = Instant::now();
    let import = import_tree(&tree, &catalog, &ImportOptions::default(), subjects.as_deref(), &|_| {}).unwrap();
    let seconds = start.elapsed().as_secs_f64();
    let library = &import.library;
    println!(
        "import: {} trials, {} frames, {:.2} s ({} failures)",
        import.trials,
        library.total_frames(),
        seconds,
        import.failures.len()
    );
    let all: Vec<usize> = (0..library.clips().len()).collect();
    let s = library.retarget_summary(&all);
    println!("ALL      mean {:.3} cm  p95 {:.2} cm  max {:.1} cm", s.mean_cm, s.p95_cm, s.max_cm);
    for (subject, clips) in library.clips_by_subject() {
        let s = library.retarget_summary(&clips);
        println!("subject {subject:3}  mean {:.3} cm  p95 {:.2} cm  max {:.1} cm", s.mean_cm, s.p95_cm, s.max_cm);
    }
    let mut per_joint = [0.0f64; NUM_JOINTS];
    let mut frames = 0.0f64;
    for clip in library.clips() {
        for (j, e) in clip.retarget.per_joint_mean_cm.iter().enumerate() {
            per_joint[j] += f64::from(*e) * f64::from(clip.frames);
        }
        frames += f64::from(clip.frames);
    }
    let line: Vec<String> =
        per_joint.iter().enumerate().map(|(j, e)| format!("{}:{:.1}", JOINT_NAMES[j], e / frames)).collect();
    println!("per joint (cm): {}", line.join(" "));
    if !bends {
        return;
    }

    // Torso deviation from the CMU segments, over every 4th source frame of every trial.
    let mut worst: [(f32, String); TORSO.len()] = Default::default();
    let mut sums = [0.0f64; TORSO.len()];
    let mut over20 = [0usize; TORSO.len()];
    let mut count = 0usize;
    let mut rest_worst = [0.0f32; TORSO.len()];
    for files in &tree.subjects {
        if subjects.as_ref().is_some_and(|l| !l.contains(&files.subject)) {
            continue;
        }
        let importer = SubjectImporter::new(files.subject, &read_text(&files.asf).unwrap(), "asf").unwrap();
        let skeleton = importer.cmu_skeleton();
        let bones = TORSO.map(|(_, b)| skeleton.bone_index(b).unwrap());
        let smpl = importer.retargeter().smpl_skeleton();
        let mut check = |fk: &egoexo_mocap::kinematics::CmuBoneTransforms, label: &str| {
            let frame = importer.retargeter().retarget(fk);
            let global = smpl.forward_kinematics(&frame.pose).rotations;
            for (k, &(j, _)) in TORSO.iter().enumerate() {
                let reference = fk.rotations[bones[k]];
                let deviation = if j == 0 {
                    global[0].angle_between(reference)
                } else {
                    let p = PARENTS[j] as usize;
                    let pk = TORSO.iter().position(|&(t, _)| t == p).unwrap_or(k);
                    let smpl_local: Quat = global[p].conjugate() * global[j];
                    let cmu_local: Quat = fk.rotations[bones[pk]].conjugate() * reference;
                    smpl_local.angle_between(cmu_local)
                }
                .to_degrees();
                if label.ends_with("rest") {
                    rest_worst[k] = rest_worst[k].max(deviation);
                    continue;
                }
                sums[k] += f64::from(deviation);
                if deviation > 20.0 {
                    over20[k] += 1;
                }
                if deviation > worst[k].0 {
                    worst[k] = (deviation, label.to_owned());
                }
            }
        };
        check(&skeleton.forward_kinematics(&skeleton.rest_pose()), &format!("{:02} rest", files.subject));
        for (trial, path) in &files.trials {
            let poses = importer.parse_motion(&read_text(path).unwrap(), "amc").unwrap();
            for (f, pose) in poses.iter().enumerate().step_by(4) {
                check(&skeleton.forward_kinematics(pose), &format!("{:02}_{:02}#{f}", files.subject, trial));
                count += 1;
            }
        }
    }
    println!(
        "torso local deviation from the CMU segments ({count} frames): mean / >20° frames / worst / worst rest pose"
    );
    for (k, &(j, bone)) in TORSO.iter().enumerate() {
        println!(
            "  {:12} vs {:10} {:6.2}° {:6} {:6.1}° at {:14} rest {:5.1}°",
            JOINT_NAMES[j],
            bone,
            sums[k] / count as f64,
            over20[k],
            worst[k].0,
            worst[k].1,
            rest_worst[k]
        );
    }
}
