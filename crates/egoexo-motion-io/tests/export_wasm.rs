//! The exporters compiled to wasm32 and run in headless Chromium (as the browser's worker
//! runs them): every format is written without touching a clock, a file or a thread, and
//! what can be read back in Rust gives the motion's joint positions again.
#![cfg(target_arch = "wasm32")]

use std::io::Cursor;

use egoexo_core::SmplMotion;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rotation::quat_from_axis_angle;
use egoexo_core::skeleton::{NUM_BODY_JOINTS, SmplPose, SmplSkeleton};
use egoexo_motion_io::bvh::Bvh;
use egoexo_motion_io::smpl_bvh::{LengthUnit, motion_from_smpl_bvh};
use egoexo_motion_io::{Format, write};
use wasm_bindgen_test::{wasm_bindgen_test, wasm_bindgen_test_configure};

wasm_bindgen_test_configure!(run_in_browser);

fn motion() -> SmplMotion {
    let poses = (0..20)
        .map(|f| {
            let t = f as f32 * 0.3;
            let body: [Quat; NUM_BODY_JOINTS] = std::array::from_fn(|j| {
                let k = j as f32;
                quat_from_axis_angle(Vec3::new((t + k).sin(), (t - k).cos(), 0.5 * (t * k).sin()) * 0.6)
            });
            SmplPose { root_orientation: Quat::from_rotation_y(t), body, translation: Vec3::new(0.1 * t, 0.9, 0.0) }
        })
        .collect();
    SmplMotion::new(30.0, 0, SmplSkeleton::mean_shape(), None, poses).unwrap()
}

#[wasm_bindgen_test]
fn every_format_is_written_in_the_browser() {
    let motion = motion();
    let fk = motion.joint_positions();

    let bvh = Bvh::parse_bytes(&write(Format::Bvh, &motion).unwrap()).unwrap();
    let back = motion_from_smpl_bvh(&bvh, LengthUnit::Metres).unwrap();
    for (a, b) in fk.iter().zip(back.joint_positions()) {
        for (p, q) in a.iter().zip(b) {
            assert!(p.distance(q) < 1e-4, "{p} vs {q}");
        }
    }

    let npz = zip::ZipArchive::new(Cursor::new(write(Format::Npz, &motion).unwrap())).unwrap();
    assert_eq!(npz.len(), 6);

    let glb = write(Format::Glb, &motion).unwrap();
    assert_eq!(&glb[..4], b"glTF");
    assert_eq!(u32::from_le_bytes(glb[8..12].try_into().unwrap()) as usize, glb.len());

    let csv = String::from_utf8(write(Format::Csv, &motion).unwrap()).unwrap();
    let first: Vec<f32> = csv.lines().nth(1).unwrap().split(',').skip(2).map(|v| v.parse().unwrap()).collect();
    assert_eq!(first[..3], fk[0][0].to_array());
    assert_eq!(csv.lines().count(), 21);
}
