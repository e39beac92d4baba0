//! The fixture the training code's PyTorch FK is checked against
//! (`training/tests/test_fk_parity.py`): deterministic poses (6D), rest joints and this
//! crate's FK positions, committed at `training/tests/fixtures/fk_parity.json`. The test
//! fails when the Rust FK or 6D decoding changes; `EGOEXO_REGENERATE_FIXTURES=1` rewrites it.
#![cfg(not(target_arch = "wasm32"))]

use std::path::Path;

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rotation::{Rot6d, quat_from_axis_angle};
use egoexo_core::skeleton::{NUM_BODY_JOINTS, SmplPose, SmplSkeleton};
use serde_json::json;

/// xorshift64*: a tiny fixed random source so the fixture never depends on a crate version.
struct Random(u64);

impl Random {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32) / (1u64 << 24) as f32 * 2.0 - 1.0
    }
    fn rotation(&mut self, max_angle: f32) -> Quat {
        let v = Vec3::new(self.next(), self.next(), self.next());
        quat_from_axis_angle(v.normalize_or(Vec3::X) * max_angle * self.next().abs())
    }
}

fn fixture() -> serde_json::Value {
    let mut rng = Random(0x5EED_F00D);
    let cases: Vec<_> = (0..8)
        .map(|case| {
            let skeleton = SmplSkeleton::mean_shape().scaled(0.85 + 0.05 * case as f32);
            let frames: Vec<_> = (0..4)
                .map(|_| {
                    let pose = SmplPose {
                        root_orientation: rng.rotation(3.0),
                        body: std::array::from_fn::<_, NUM_BODY_JOINTS, _>(|_| rng.rotation(1.5)),
                        translation: Vec3::ZERO,
                    };
                    // What the networks output: 6D, possibly not orthonormal — scale and skew
                    // the columns so Gram–Schmidt is exercised too.
                    let mut six: Vec<f32> = Vec::new();
                    for q in std::iter::once(pose.root_orientation).chain(pose.body) {
                        let mut r = Rot6d::from_quat(q).0;
                        for (i, v) in r.iter_mut().enumerate() {
                            *v = *v * (1.3 + 0.1 * i as f32) + 0.05 * rng.next();
                        }
                        six.extend_from_slice(&r);
                    }
                    let decoded: Vec<Quat> =
                        six.chunks_exact(6).map(|c| Rot6d(c.try_into().unwrap()).to_quat()).collect();
                    let pose = SmplPose {
                        root_orientation: decoded[0],
                        body: std::array::from_fn(|j| decoded[j + 1]),
                        translation: Vec3::ZERO,
                    };
                    let fk = skeleton.forward_kinematics(&pose);
                    let pelvis = fk.positions[0];
                    let positions: Vec<f32> = fk.positions.iter().flat_map(|p| (*p - pelvis).to_array()).collect();
                    json!({ "pose_6d": six, "positions": positions })
                })
                .collect();
            let rest: Vec<f32> = skeleton.rest_joints().iter().flat_map(|p| p.to_array()).collect();
            json!({ "rest_joints": rest, "frames": frames })
        })
        .collect();
    json!({
        "about": "SMPL FK of egoexo-core: positions relative to the pelvis, metres; pose_6d = root then 21 body rotations, 6D first two columns (not orthonormalised)",
        "cases": cases,
    })
}

#[test]
fn the_committed_fk_fixture_matches_this_fk() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../training/tests/fixtures/fk_parity.json");
    let current = fixture();
    if std::env::var_os("EGOEXO_REGENERATE_FIXTURES").is_some() {
        std::fs::write(&path, serde_json::to_string(&current).unwrap()).unwrap();
    }
    let committed: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).expect("fixture missing: run with EGOEXO_REGENERATE_FIXTURES=1"))
            .unwrap();
    let flat = |v: &serde_json::Value| -> Vec<f64> {
        v["cases"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|c| {
                c["frames"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .flat_map(|f| f["positions"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
            })
            .collect()
    };
    let (a, b) = (flat(&current), flat(&committed));
    assert_eq!(a.len(), b.len());
    let worst = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    assert!(worst < 1e-6, "FK changed by {worst} m since the fixture was written");
}
