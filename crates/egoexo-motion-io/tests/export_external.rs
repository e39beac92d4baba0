//! The exporters' files read by other people's tools: numpy loads the AMASS npz, the
//! independent `bvhio` reader (PyPI) plays the BVH, and the Khronos glTF-Validator (npm)
//! accepts the `.glb`. Geometry is always checked here, with the project's own forward
//! kinematics; the Python and Node scripts only read files and dump what they read.
//!
//! The tools come from `cargo xtask setup` (run by `cargo xtask test`): a venv at `target/py`
//! from `tests/requirements.txt` and `tests/node_modules` from `tests/package-lock.json`,
//! passed in as `EGOEXO_PYTHON` and `EGOEXO_NODE_MODULES`. Without them these tests fail
//! and say so; they never pass silently.
#![cfg(not(target_arch = "wasm32"))]

use std::path::PathBuf;
use std::process::Command;

use egoexo_core::SmplMotion;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rotation::quat_from_axis_angle;
use egoexo_core::skeleton::{JOINT_NAMES, NUM_BODY_JOINTS, NUM_JOINTS, SmplPose, SmplSkeleton};
use egoexo_motion_io::amass::{AmassArrays, motion_from_amass, write_npz};
use egoexo_motion_io::smpl_bvh::{BvhOptions, LengthUnit, write_bvh};
use egoexo_motion_io::{Format, write};
use egoexo_test_support::{node_modules, python, run_tool as run, workspace_root};
use serde_json::Value;

fn script(name: &str) -> PathBuf {
    workspace_root().join("tests").join(name)
}

/// A deterministic motion: walking, turning, leaning, every body joint moving a lot.
fn motion(frames: usize, skeleton: SmplSkeleton, betas: Option<Vec<f32>>) -> SmplMotion {
    let poses = (0..frames)
        .map(|f| {
            let t = f as f32 * 0.29;
            let mut body = [Quat::IDENTITY; NUM_BODY_JOINTS];
            for (j, q) in body.iter_mut().enumerate() {
                let k = j as f32 + 1.0;
                *q = quat_from_axis_angle(
                    Vec3::new((t + 0.5 * k).cos(), (0.8 * t + k).sin(), (1.1 * t - 2.0 * k).cos()) * (0.3 + 0.07 * k),
                );
            }
            SmplPose {
                root_orientation: Quat::from_rotation_y(1.3 * t) * Quat::from_rotation_z(0.4 * t.cos()),
                body,
                translation: Vec3::new(0.4 * t.sin(), 0.95, 0.3 * t),
            }
        })
        .collect();
    SmplMotion::new(50.0, 7_000_000_000, skeleton, betas, poses).unwrap()
}

fn max_distance(a: &[[Vec3; NUM_JOINTS]], b: &[[Vec3; NUM_JOINTS]]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).flat_map(|(fa, fb)| fa.iter().zip(fb).map(|(x, y)| x.distance(*y))).fold(0.0, f32::max)
}

fn floats(array: &Value) -> Vec<f64> {
    array["values"].as_array().expect("values").iter().map(|v| v.as_f64().expect("number")).collect()
}

#[test]
fn amass_npz_loads_in_numpy_and_reproduces_the_joint_positions() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("mean", SmplSkeleton::mean_shape(), None),
        ("scaled", SmplSkeleton::mean_shape().scaled(1.12), None),
        (
            "betas",
            SmplSkeleton::mean_shape().scaled(0.93),
            Some(vec![0.8, -0.3, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.2]),
        ),
    ];
    for (name, skeleton, betas) in cases {
        let motion = motion(60, skeleton, betas.clone());
        let npz = dir.path().join(format!("{name}.npz"));
        let json = dir.path().join(format!("{name}.json"));
        std::fs::write(&npz, write_npz(&motion).unwrap()).unwrap();
        run(Command::new(python()).arg(script("python/npz_dump.py")).arg(&npz).arg(&json));
        let dump: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
        let arrays = &dump["arrays"];

        // What AMASS loaders expect.
        let expect = |key: &str, dtype: &str, shape: &[usize]| {
            let a = &arrays[key];
            assert_eq!(a["dtype"], dtype, "{name}: {key} dtype");
            let got: Vec<usize> = a["shape"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
            assert_eq!(got, shape, "{name}: {key} shape");
        };
        let n_betas = betas.as_ref().map_or(10, Vec::len);
        expect("poses", "<f8", &[60, 72]);
        expect("trans", "<f8", &[60, 3]);
        expect("betas", "<f8", &[n_betas]);
        expect("gender", "<U7", &[]);
        expect("mocap_framerate", "<f8", &[]);
        expect("rest_joints", "<f8", &[24, 3]);
        assert_eq!(arrays["gender"]["values"], "neutral");
        assert_eq!(floats(&arrays["mocap_framerate"]), [50.0]);
        let poses = floats(&arrays["poses"]);
        assert!(poses.chunks(72).all(|row| row[66..].iter().all(|&v| v == 0.0)), "hands must be zero");

        let a = AmassArrays {
            poses,
            trans: floats(&arrays["trans"]),
            betas: floats(&arrays["betas"]),
            mocap_framerate: floats(&arrays["mocap_framerate"])[0],
            rest_joints: Some(floats(&arrays["rest_joints"])),
        };
        // Back through the project's FK, in the project's Y-up world.
        let back = motion_from_amass(&a, motion.start_ns).unwrap();
        let err = max_distance(&motion.joint_positions(), &back.joint_positions());
        assert!(err <= 1e-4, "{name}: joints differ by up to {err} m after numpy");

        // Read as AMASS tools do (root orientation and trans taken as they are, SMPL's
        // pelvis J0 for the betas): the same motion, rotated into the Z-up world.
        let j0 = if betas.is_some() {
            motion.skeleton.rest_joints()[0]
        } else {
            SmplSkeleton::mean_shape().rest_joints()[0]
        };
        let as_amass_tools_see_it = SmplMotion {
            poses: a
                .poses
                .chunks(72)
                .zip(a.trans.chunks(3))
                .map(|(row, t)| {
                    let aa = |i: usize| {
                        quat_from_axis_angle(Vec3::new(row[3 * i] as f32, row[3 * i + 1] as f32, row[3 * i + 2] as f32))
                    };
                    SmplPose {
                        root_orientation: aa(0),
                        body: std::array::from_fn(|i| aa(i + 1)),
                        translation: j0 + Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32)
                            - motion.skeleton.rest_joints()[0],
                    }
                })
                .collect(),
            ..motion.clone()
        };
        // Z up: (x, y, z) in the Y-up world is (x, −z, y) in AMASS's.
        let z_up: Vec<[Vec3; NUM_JOINTS]> =
            motion.joint_positions().iter().map(|frame| frame.map(|p| Vec3::new(p.x, -p.z, p.y))).collect();
        let err = max_distance(&z_up, &as_amass_tools_see_it.joint_positions());
        assert!(err <= 1e-4, "{name}: AMASS-world joints differ from the Z-up motion by {err} m");
    }
}

#[test]
fn bvh_plays_back_in_the_independent_bvhio_reader() {
    let dir = tempfile::tempdir().unwrap();
    for (unit, skeleton) in [
        (LengthUnit::Metres, SmplSkeleton::mean_shape()),
        (LengthUnit::Centimetres, SmplSkeleton::mean_shape().scaled(1.08)),
    ] {
        let motion = motion(45, skeleton, None);
        let bvh = dir.path().join(format!("{unit:?}.bvh"));
        let json = dir.path().join(format!("{unit:?}.json"));
        std::fs::write(&bvh, write_bvh(&motion, &BvhOptions { unit, ..BvhOptions::default() }).unwrap()).unwrap();
        run(Command::new(python()).arg(script("python/bvh_world_positions.py")).arg(&bvh).arg(&json));
        let dump: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
        assert_eq!(dump["frame_count"], 45);
        assert!((dump["frame_time"].as_f64().unwrap() - 1.0 / 50.0).abs() < 1e-9);
        let names: Vec<&str> = dump["joints"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
        let mut sorted = names.clone();
        sorted.sort_unstable();
        let mut expected = JOINT_NAMES.to_vec();
        expected.sort_unstable();
        assert_eq!(sorted, expected, "bvhio sees the 24 SMPL joints");
        let per_metre = unit.per_metre() as f32;
        let theirs: Vec<[Vec3; NUM_JOINTS]> = dump["positions"]
            .as_array()
            .unwrap()
            .iter()
            .map(|frame| {
                let frame = frame.as_array().unwrap();
                std::array::from_fn(|j| {
                    let i = names.iter().position(|n| *n == JOINT_NAMES[j]).unwrap();
                    let p: Vec<f32> = frame[i].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect();
                    Vec3::new(p[0], p[1], p[2]) / per_metre
                })
            })
            .collect();
        let err = max_distance(&motion.joint_positions(), &theirs);
        assert!(err <= 1e-4, "{unit:?}: bvhio's joints differ from the project's FK by up to {err} m");
    }
}

#[test]
fn glb_passes_the_khronos_validator() {
    let dir = tempfile::tempdir().unwrap();
    let node_modules = node_modules("gltf-validator");
    for (name, frames) in [("one_frame", 1), ("walk", 90)] {
        let glb = dir.path().join(format!("{name}.glb"));
        let motion = motion(frames, SmplSkeleton::mean_shape().scaled(1.04), None);
        std::fs::write(&glb, write(Format::Glb, &motion).unwrap()).unwrap();
        let out = run(Command::new(std::env::var_os("EGOEXO_NODE").unwrap_or_else(|| "node".into()))
            .arg(script("node/validate_gltf.mjs"))
            .arg(&glb)
            .env("EGOEXO_NODE_MODULES", &node_modules));
        let report: Value = serde_json::from_str(&out).unwrap();
        let issues = &report["issues"];
        let messages = serde_json::to_string_pretty(&issues["messages"]).unwrap();
        eprintln!(
            "{name}: gltf-validator {}: {} errors, {} warnings, {} infos, {} hints",
            report["validatorVersion"],
            issues["numErrors"],
            issues["numWarnings"],
            issues["numInfos"],
            issues["numHints"]
        );
        assert_eq!(issues["numErrors"], 0, "{name}: validator errors:\n{messages}");
        assert_eq!(issues["numWarnings"], 0, "{name}: validator warnings:\n{messages}");
        let info = &report["info"];
        assert_eq!(info["animationCount"], 1, "{info}");
        assert_eq!(info["hasSkins"], true, "{info}");
    }
}
