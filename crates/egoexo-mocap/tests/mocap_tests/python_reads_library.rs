//! The library file is plain safetensors: Python with nothing but numpy reads its arrays and
//! header, and gets the numbers Rust wrote. Uses the test venv's Python (`EGOEXO_PYTHON`,
//! set by `cargo xtask test`, else `target/py`; the test fails without one); skipped with a
//! message when the CMU data is absent.

use crate::common;

use std::path::PathBuf;
use std::process::Command;

use egoexo_mocap::{ImportOptions, MotionLibrary};
use egoexo_test_support::python;

const READER: &str = r#"
import json, struct, sys
import numpy as np
data = open(sys.argv[1], "rb").read()
(n,) = struct.unpack("<Q", data[:8])
header = json.loads(data[8:8 + n])
meta = json.loads(header.pop("__metadata__")["egoexo_motion_library"])
arrays = {}
for name, info in header.items():
    start, end = info["data_offsets"]
    dtype = {"F32": "<f4", "U32": "<u4"}[info["dtype"]]
    arrays[name] = np.frombuffer(data[8 + n + start:8 + n + end], dtype=dtype).reshape(info["shape"])
clip = meta["clips"][1]
a, b = clip["frame_offset"], clip["frame_offset"] + clip["frames"]
q = np.concatenate([arrays["root_orientation"][a:b], arrays["body_rotations"][a:b].reshape(-1, 4)])
print(json.dumps({
    "shapes": {k: list(v.shape) for k, v in arrays.items()},
    "clips": len(meta["clips"]),
    "fps": meta["fps"],
    "name": clip["name"],
    "translation": arrays["root_translation"][b - 1].tolist(),
    "max_quat_norm_error": float(np.abs(np.linalg.norm(q, axis=1) - 1).max()),
    "histogram_total": int(arrays["retarget_error_histogram"][1].sum()),
}))
"#;

#[test]
fn numpy_reads_the_library() {
    let dir = require_cmu!();
    let python = python();
    let catalog = common::catalog(&dir);
    let importer = common::subject(&dir, 2);
    let mut clips = Vec::new();
    for trial in [1, 2] {
        let (text, file) = common::amc(&dir, 2, trial);
        let entry = catalog.get(2, trial).unwrap();
        clips.extend(importer.import_trial(trial, &text, &file, entry, &ImportOptions::default()).unwrap().clips);
    }
    let library = MotionLibrary::build(30.0, "test", clips).unwrap();
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("numpy_reads_the_library.safetensors");
    egoexo_mocap::fs::save_library(&library, &path).unwrap();

    let out = Command::new(python).arg("-c").arg(READER).arg(&path).output().expect("python runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let got: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let frames = library.total_frames();
    assert_eq!(got["shapes"]["root_translation"], serde_json::json!([frames, 3]));
    assert_eq!(got["shapes"]["root_orientation"], serde_json::json!([frames, 4]));
    assert_eq!(got["shapes"]["body_rotations"], serde_json::json!([frames, 21, 4]));
    assert_eq!(got["shapes"]["retarget_error_histogram"], serde_json::json!([2, 501]));
    assert_eq!(got["clips"], 2);
    assert_eq!(got["fps"], 30.0);
    assert_eq!(got["name"], "02_02");
    assert!(got["max_quat_norm_error"].as_f64().unwrap() < 1e-5);
    let last = library.motion(1).unwrap().poses.last().unwrap().translation;
    let t: Vec<f32> = serde_json::from_value(got["translation"].clone()).unwrap();
    assert_eq!(t, last.to_array().to_vec(), "numpy reads the same f32 values");
    assert_eq!(got["histogram_total"].as_u64().unwrap(), library.clips()[1].frames as u64 * 24);
}
