//! Table-driven malformed inputs: every one must give an error (never a panic) whose message
//! names the file, the line or field, and what was expected.

use std::collections::BTreeMap;

use crate::support::*;
use egoexo_motion_io::npz::NpzWriter;
use egoexo_session::import::{ImportOptions, KeypointFile, import_session};
use egoexo_session::npz::{NpyData, Npz};
use egoexo_session::{FileTree, Limits};
use serde_json::Value;

type Files = BTreeMap<String, Vec<u8>>;

const WEARER_CSV: &str = "wearer/closed_loop_trajectory.csv";
const OBS1_CSV: &str = "observers/observer-1/mps/slam/closed_loop_trajectory.csv";
const OBS1_CALIB: &str = "observers/observer-1/mps/slam/online_calibration.jsonl";
const OBS1_KP: &str = "observers/observer-1/keypoints.jsonl";
const OBS2_CSV: &str = "observers/observer-2/slam/closed_loop_trajectory.csv";
const OBS2_COCO: &str = "observers/observer-2/keypoints.json";
const SMPL: &str = "body/xdata_smpl_neutral.npz";
const HAND_V1: &str = "wearer/hand_tracking/wrist_and_palm_poses.csv";
const HAND_V1_HEADER: &str = "tracking_timestamp_us,left_tracking_confidence,tx_left_wrist_device,ty_left_wrist_device,tz_left_wrist_device,tx_left_palm_device,ty_left_palm_device,tz_left_palm_device,right_tracking_confidence,tx_right_wrist_device,ty_right_wrist_device,tz_right_wrist_device,tx_right_palm_device,ty_right_palm_device,tz_right_palm_device";

fn text(files: &Files, path: &str) -> String {
    String::from_utf8(files[path].clone()).unwrap()
}

/// Edits a CSV as rows of fields (row 0 = header).
fn edit_csv(files: &mut Files, path: &str, edit: impl FnOnce(&mut Vec<Vec<String>>)) {
    let mut rows: Vec<Vec<String>> =
        text(files, path).lines().map(|l| l.split(',').map(str::to_owned).collect()).collect();
    edit(&mut rows);
    let out: Vec<String> = rows.iter().map(|r| r.join(",")).collect();
    files.insert(path.into(), (out.join("\n") + "\n").into_bytes());
}

fn column(rows: &[Vec<String>], name: &str) -> usize {
    rows[0].iter().position(|h| h == name).unwrap()
}

/// Sets one CSV cell (data row `row`, 0-based; it sits on file line `row + 2`).
fn set_cell(files: &mut Files, path: &str, row: usize, name: &str, value: &str) {
    edit_csv(files, path, |rows| {
        let c = column(rows, name);
        rows[row + 1][c] = value.into();
    });
}

/// Edits a JSON-lines file as values.
fn edit_jsonl(files: &mut Files, path: &str, edit: impl FnOnce(&mut Vec<Value>)) {
    let mut values: Vec<Value> = text(files, path).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    edit(&mut values);
    let out: Vec<String> = values.iter().map(Value::to_string).collect();
    files.insert(path.into(), (out.join("\n") + "\n").into_bytes());
}

fn edit_json(files: &mut Files, path: &str, edit: impl FnOnce(&mut Value)) {
    let mut value: Value = serde_json::from_slice(&files[path]).unwrap();
    edit(&mut value);
    files.insert(path.into(), serde_json::to_vec_pretty(&value).unwrap());
}

/// Re-encodes the Nymeria SMPL npz after editing its arrays (name → (shape, values as f64 or i64)).
fn edit_smpl(files: &mut Files, edit: impl FnOnce(&mut BTreeMap<String, (Vec<u64>, NpyData)>)) {
    edit_npz(files, SMPL, edit);
}

/// Re-encodes an npz after editing its arrays.
fn edit_npz(files: &mut Files, path: &str, edit: impl FnOnce(&mut BTreeMap<String, (Vec<u64>, NpyData)>)) {
    let npz = Npz::open("x", files[path].clone(), Limits::default()).unwrap();
    let mut arrays: BTreeMap<String, (Vec<u64>, NpyData)> = npz
        .names()
        .into_iter()
        .map(|n| {
            let a = npz.array(&n).unwrap();
            (n, (a.shape.iter().map(|&d| d as u64).collect(), a.data))
        })
        .collect();
    edit(&mut arrays);
    let mut w = NpzWriter::new();
    for (name, (shape, data)) in &arrays {
        match data {
            NpyData::F64(v) => w.add(name, shape, v).unwrap(),
            NpyData::F32(v) => w.add(name, shape, v).unwrap(),
            NpyData::Int(v) => w.add(name, shape, v).unwrap(),
        }
    }
    files.insert(path.into(), w.finish().unwrap());
}

fn f64s<'a>(arrays: &'a mut BTreeMap<String, (Vec<u64>, NpyData)>, name: &str) -> (&'a mut Vec<u64>, &'a mut Vec<f64>) {
    let (shape, data) = arrays.get_mut(name).unwrap();
    match data {
        NpyData::F64(v) => (shape, v),
        _ => panic!("{name} is not f64"),
    }
}

fn ints<'a>(arrays: &'a mut BTreeMap<String, (Vec<u64>, NpyData)>, name: &str) -> &'a mut Vec<i64> {
    match &mut arrays.get_mut(name).unwrap().1 {
        NpyData::Int(v) => v,
        _ => panic!("{name} is not int"),
    }
}

fn egoexo_files() -> Files {
    egoexo_fixture_files()
}

fn zip(files: &Files) -> Vec<u8> {
    egoexo_motion_io::npz::write_zip(files).unwrap()
}

/// A zip archive with raw entry names (the writer refuses nothing; `zip` accepts any name).
fn zip_raw(entries: &[(&str, &[u8])]) -> Vec<u8> {
    use std::io::Write;
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, bytes) in entries {
        w.start_file(*name, zip::write::SimpleFileOptions::default()).unwrap();
        w.write_all(bytes).unwrap();
    }
    w.finish().unwrap().into_inner()
}

enum Input {
    Aria(fn(&mut Files)),
    Nymeria(fn(&mut Files)),
    Egoexo(fn(&mut Files)),
    /// Zip bytes and limits.
    Zip(fn() -> (Vec<u8>, Limits)),
    /// The Aria fixture plus a keypoint file given on the side.
    ExtraKeypoints(fn() -> KeypointFile),
}

struct Case {
    name: &'static str,
    input: Input,
    /// Substrings the error message must contain (file, location, expectation).
    expected: &'static [&'static str],
}

fn cases() -> Vec<Case> {
    use Input::*;
    vec![
        // ---- closed_loop_trajectory.csv ------------------------------------------------
        Case {
            name: "missing column",
            input: Aria(|f| {
                edit_csv(f, WEARER_CSV, |rows| {
                    let c = column(rows, "qw_world_device");
                    for r in rows.iter_mut() {
                        r.remove(c);
                    }
                })
            }),
            expected: &[
                "wearer/closed_loop_trajectory.csv, line 1",
                "missing column `qw_world_device`",
                "found: `graph_uid`",
            ],
        },
        Case {
            name: "renamed position column",
            input: Aria(|f| edit_csv(f, WEARER_CSV, |rows| rows[0][3] = "tx_world".into())),
            expected: &["wearer/closed_loop_trajectory.csv, line 1", "missing column `tx_world_device`", "`tx_world`"],
        },
        Case {
            name: "renamed timestamp column",
            input: Aria(|f| edit_csv(f, OBS1_CSV, |rows| rows[0][1] = "tracking_timestamp_ms".into())),
            expected: &[OBS1_CSV, "line 1", "missing column `tracking_timestamp_us`"],
        },
        Case {
            name: "NaN position",
            input: Aria(|f| set_cell(f, WEARER_CSV, 3, "ty_world_device", "NaN")),
            expected: &[
                "wearer/closed_loop_trajectory.csv, line 5, field `ty_world_device`: expected a finite number, got `NaN`",
            ],
        },
        Case {
            name: "infinite quaternion component",
            input: Aria(|f| set_cell(f, WEARER_CSV, 0, "qx_world_device", "inf")),
            expected: &["line 2, field `qx_world_device`: expected a finite number, got `inf`"],
        },
        Case {
            name: "empty cell",
            input: Aria(|f| set_cell(f, OBS2_CSV, 7, "tz_world_device", "")),
            expected: &[OBS2_CSV, "line 9, field `tz_world_device`: expected a finite number, got ``"],
        },
        Case {
            name: "non-integer timestamp",
            input: Aria(|f| set_cell(f, WEARER_CSV, 2, "tracking_timestamp_us", "3600040000.5")),
            expected: &["line 4, field `tracking_timestamp_us`: expected an integer timestamp, got `3600040000.5`"],
        },
        Case {
            name: "non-monotonic timestamps",
            input: Aria(|f| edit_csv(f, WEARER_CSV, |rows| rows.swap(4, 5))),
            expected: &[
                "wearer/closed_loop_trajectory.csv, line 6, field `tracking_timestamp_us`",
                "is not after the previous one",
                "expected strictly increasing timestamps",
            ],
        },
        Case {
            name: "duplicate timestamp",
            input: Aria(|f| {
                edit_csv(f, OBS1_CSV, |rows| {
                    let c = column(rows, "tracking_timestamp_us");
                    rows[11][c] = rows[10][c].clone();
                })
            }),
            expected: &[
                OBS1_CSV,
                "line 12",
                "duplicate timestamp 3600180000000 ns; expected strictly increasing timestamps",
            ],
        },
        Case {
            name: "non-unit quaternion",
            input: Aria(|f| {
                edit_csv(f, WEARER_CSV, |rows| {
                    for name in ["qx_world_device", "qy_world_device", "qz_world_device", "qw_world_device"] {
                        let c = column(rows, name);
                        let v: f64 = rows[9][c].parse().unwrap();
                        rows[9][c] = format!("{}", 2.0 * v);
                    }
                })
            }),
            expected: &[
                "line 10, field `qx_world_device..qw_world_device`: quaternion has norm 2.0000",
                "expected a unit quaternion (|q| = 1 ± 0.001)",
            ],
        },
        Case {
            name: "zero quaternion",
            input: Aria(|f| {
                edit_csv(f, OBS2_CSV, |rows| {
                    for name in ["qx_world_device", "qy_world_device", "qz_world_device", "qw_world_device"] {
                        let c = column(rows, name);
                        rows[1][c] = "0".into();
                    }
                })
            }),
            expected: &[OBS2_CSV, "line 2", "quaternion has norm 0"],
        },
        Case {
            name: "empty trajectory file",
            input: Aria(|f| {
                f.insert(WEARER_CSV.into(), Vec::new());
            }),
            expected: &[
                "wearer/closed_loop_trajectory.csv: the file is empty; expected a closed_loop_trajectory.csv header and poses",
            ],
        },
        Case {
            name: "header only",
            input: Aria(|f| edit_csv(f, OBS1_CSV, |rows| rows.truncate(1))),
            expected: &[OBS1_CSV, "the file is empty; expected at least one pose row after the header"],
        },
        Case {
            name: "truncated row",
            input: Aria(|f| edit_csv(f, WEARER_CSV, |rows| rows[20].truncate(10))),
            expected: &[
                "wearer/closed_loop_trajectory.csv, line 21: expected 28 fields (as many as the header has), got 10 fields",
            ],
        },
        Case {
            name: "gravity changes within a file",
            input: Aria(|f| {
                edit_csv(f, WEARER_CSV, |rows| {
                    let (y, z) = (column(rows, "gravity_y_world"), column(rows, "gravity_z_world"));
                    rows[40][y] = "-9.81".into();
                    rows[40][z] = "0".into();
                })
            }),
            expected: &[
                "wearer/closed_loop_trajectory.csv, line 41, field `gravity_x_world..gravity_z_world`: expected the same gravity on every row ((0.000000, 0.000000, -9.810000) from the first row",
                "got (0.000000, -9.81, 0)",
            ],
        },
        Case {
            name: "zero gravity",
            input: Aria(|f| {
                edit_csv(f, OBS1_CSV, |rows| {
                    let z = column(rows, "gravity_z_world");
                    for row in rows.iter_mut().skip(1) {
                        row[z] = "0".into();
                    }
                })
            }),
            expected: &[
                OBS1_CSV,
                "line 2, field `gravity_x_world..gravity_z_world`: expected a gravity vector at least 0.1 m/s² long (its direction is the world's down), got (0.000000, 0.000000, 0)",
            ],
        },
        Case {
            name: "gravity column missing",
            input: Aria(|f| {
                edit_csv(f, WEARER_CSV, |rows| {
                    let y = column(rows, "gravity_y_world");
                    for row in rows.iter_mut() {
                        row.remove(y);
                    }
                })
            }),
            expected: &[
                "wearer/closed_loop_trajectory.csv, line 1: missing column `gravity_y_world`; expected the columns of Aria MPS closed_loop_trajectory.csv (the world's gravity gives its up axis)",
            ],
        },
        Case {
            name: "quality_score not a number",
            input: Aria(|f| set_cell(f, WEARER_CSV, 7, "quality_score", "good")),
            expected: &[
                "wearer/closed_loop_trajectory.csv, line 9, field `quality_score`: expected a finite number, got `good`",
            ],
        },
        Case {
            name: "graph_uid changes",
            input: Aria(|f| set_cell(f, OBS1_CSV, 30, "graph_uid", "another-graph")),
            expected: &[
                OBS1_CSV,
                "line 32, field `graph_uid`: expected one graph_uid per trajectory",
                "got `another-graph`",
            ],
        },
        Case {
            name: "absurd position",
            input: Aria(|f| set_cell(f, WEARER_CSV, 12, "tx_world_device", "1e9")),
            expected: &["line 14, field `tx_world_device`: expected a position within ±100000 m, got 1e9"],
        },
        Case {
            name: "timestamp overflows nanoseconds",
            input: Aria(|f| set_cell(f, WEARER_CSV, 100, "tracking_timestamp_us", "9223372036854776")),
            expected: &["line 102, field `tracking_timestamp_us`: expected a timestamp that fits in i64 nanoseconds"],
        },
        Case {
            name: "invalid UTF-8",
            input: Aria(|f| {
                let bytes = f.get_mut(WEARER_CSV).unwrap();
                let line3 = bytes.iter().enumerate().filter(|(_, b)| **b == b'\n').nth(1).unwrap().0 + 1;
                bytes.splice(line3..line3 + 1, [0xff, 0xfe]);
            }),
            expected: &["wearer/closed_loop_trajectory.csv, line 3, field `graph_uid`: expected UTF-8 text"],
        },
        // ---- MPS hand tracking and semidense points (the wearer's folder) ---------------
        Case {
            name: "hand confidence out of range",
            input: Aria(|f| {
                f.insert(HAND_V1.into(), format!("{HAND_V1_HEADER}\n3600000000,0.9,0.1,-0.2,0.3,0.12,-0.25,0.35,-1,0,0,0,0,0,0\n3600033333,1.7,0.1,-0.2,0.3,0.12,-0.25,0.35,-1,0,0,0,0,0,0\n").into_bytes());
            }),
            expected: &[
                "wearer/hand_tracking/wrist_and_palm_poses.csv, line 3, field `left_tracking_confidence`: expected a confidence in [0, 1], or −1 where the hand is not tracked, got 1.7",
            ],
        },
        Case {
            name: "hand tracking column missing",
            input: Aria(|f| {
                let header = HAND_V1_HEADER.replace(",tz_right_palm_device", "");
                f.insert(
                    HAND_V1.into(),
                    format!("{header}\n3600000000,0.9,0.1,-0.2,0.3,0.12,-0.25,0.35,-1,0,0,0,0,0\n").into_bytes(),
                );
            }),
            expected: &[
                "wearer/hand_tracking/wrist_and_palm_poses.csv, line 1: missing column `tz_right_palm_device`; expected the columns of MPS wrist_and_palm_poses.csv",
            ],
        },
        Case {
            name: "hand tracking time goes back",
            input: Aria(|f| {
                f.insert(HAND_V1.into(), format!("{HAND_V1_HEADER}\n3600033333,0.9,0.1,-0.2,0.3,0.12,-0.25,0.35,-1,0,0,0,0,0,0\n3600000000,0.9,0.1,-0.2,0.3,0.12,-0.25,0.35,-1,0,0,0,0,0,0\n").into_bytes());
            }),
            expected: &[
                "wearer/hand_tracking/wrist_and_palm_poses.csv, line 3, field `tracking_timestamp_us`: timestamp 3600000000000 ns is not after the previous one",
            ],
        },
        Case {
            name: "hand far from the glasses",
            input: Aria(|f| {
                f.insert(
                    HAND_V1.into(),
                    format!("{HAND_V1_HEADER}\n3600000000,0.9,12.0,-0.2,0.3,0.12,-0.25,0.35,-1,0,0,0,0,0,0\n")
                        .into_bytes(),
                );
            }),
            expected: &[
                "line 2, field `tx_left_wrist_device`: expected a coordinate within ±3 m of the glasses, got 12.0",
            ],
        },
        Case {
            name: "hand_tracking_results wrist quaternion not unit",
            input: Aria(|f| {
                let header = "tracking_timestamp_us,left_tracking_confidence,tx_left_landmark_20_device,ty_left_landmark_20_device,tz_left_landmark_20_device,tx_left_device_wrist,ty_left_device_wrist,tz_left_device_wrist,qx_left_device_wrist,qy_left_device_wrist,qz_left_device_wrist,qw_left_device_wrist,right_tracking_confidence,tx_right_landmark_20_device,ty_right_landmark_20_device,tz_right_landmark_20_device,tx_right_device_wrist,ty_right_device_wrist,tz_right_device_wrist,qx_right_device_wrist,qy_right_device_wrist,qz_right_device_wrist,qw_right_device_wrist";
                f.insert(
                    "wearer/hand_tracking/hand_tracking_results.csv".into(),
                    format!("{header}\n3600000000,-1,0,0,0,0,0,0,0,0,0,1,0.8,0.1,-0.2,0.3,0.12,-0.25,0.35,0,0,0,2\n")
                        .into_bytes(),
                );
            }),
            expected: &[
                "wearer/hand_tracking/hand_tracking_results.csv, line 2, field `qx_right_device_wrist..qw_right_device_wrist`: quaternion has norm 2",
            ],
        },
        Case {
            name: "semidense points not gzip",
            input: Aria(|f| {
                f.insert("wearer/global_points.csv.gz".into(), b"uid,graph_uid,px_world\n".to_vec());
            }),
            expected: &["wearer/global_points.csv.gz", "expected a gzip-compressed CSV file"],
        },
        Case {
            name: "semidense column missing",
            input: Aria(|f| {
                f.insert(
                    "wearer/global_points.csv".into(),
                    b"uid,graph_uid,px_world,py_world,pz_world,inv_dist_std\n1,g,0,0,0,0.0001\n".to_vec(),
                );
            }),
            expected: &["wearer/global_points.csv, line 1: missing column `dist_std`"],
        },
        Case {
            name: "semidense coordinate not a number",
            input: Aria(|f| {
                f.insert(
                    "wearer/global_points.csv".into(),
                    b"uid,graph_uid,px_world,py_world,pz_world,inv_dist_std,dist_std\n1,g,0,0,0,0.0001,0.01\n2,g,0,zero,0,0.0001,0.01\n".to_vec(),
                );
            }),
            expected: &["wearer/global_points.csv, line 3, field `py_world`: expected a finite number, got `zero`"],
        },
        // ---- online_calibration.jsonl -------------------------------------------------
        Case {
            name: "calibration line is not JSON",
            input: Aria(|f| {
                let b = f.get_mut(OBS1_CALIB).unwrap();
                b.truncate(300);
            }),
            expected: &[OBS1_CALIB, "line 1: invalid JSON"],
        },
        Case {
            name: "RGB projection has 12 parameters",
            input: Aria(|f| {
                edit_jsonl(f, OBS1_CALIB, |v| {
                    v[1]["CameraCalibrations"][2]["Projection"]["Params"].as_array_mut().unwrap().truncate(12);
                })
            }),
            expected: &[
                OBS1_CALIB,
                "line 2, field `CameraCalibrations[2].Projection.Params`: expected an array of 15 numbers, got an array of 12 items",
            ],
        },
        Case {
            name: "RGB parameter is null",
            input: Aria(|f| {
                edit_jsonl(f, OBS1_CALIB, |v| v[0]["CameraCalibrations"][2]["Projection"]["Params"][4] = Value::Null)
            }),
            expected: &[
                "line 1, field `CameraCalibrations[2].Projection.Params[4]`: expected a finite number, got null",
            ],
        },
        Case {
            name: "T_Device_Camera quaternion not unit",
            input: Aria(|f| {
                edit_jsonl(f, OBS1_CALIB, |v| {
                    v[0]["CameraCalibrations"][2]["T_Device_Camera"]["UnitQuaternion"][0] = 3.0.into()
                })
            }),
            expected: &["line 1, field `CameraCalibrations[2].T_Device_Camera.UnitQuaternion`: quaternion has norm"],
        },
        Case {
            name: "UnitQuaternion in the wrong layout",
            input: Aria(|f| {
                edit_jsonl(f, OBS1_CALIB, |v| {
                    v[2]["CameraCalibrations"][2]["T_Device_Camera"]["UnitQuaternion"] =
                        serde_json::json!([1.0, 0.0, 0.0, 0.0])
                })
            }),
            expected: &[
                "line 3, field `CameraCalibrations[2].T_Device_Camera.UnitQuaternion`: expected [w, [x, y, z]], got an array of 4 items",
            ],
        },
        Case {
            name: "no RGB camera",
            input: Aria(|f| {
                edit_jsonl(f, OBS1_CALIB, |v| {
                    for r in v.iter_mut() {
                        r["CameraCalibrations"].as_array_mut().unwrap().truncate(2);
                    }
                })
            }),
            expected: &[
                OBS1_CALIB,
                "field `CameraCalibrations`: expected a `camera-rgb` calibration, got none in any record",
            ],
        },
        Case {
            name: "unsupported RGB projection model",
            input: Aria(|f| {
                edit_jsonl(f, OBS1_CALIB, |v| {
                    v[0]["CameraCalibrations"][2]["Projection"]["Name"] = "KannalaBrandtK3".into()
                })
            }),
            expected: &[
                "line 1, field `CameraCalibrations[2].Projection.Name`: expected the projection model `FisheyeRadTanThinPrism` (or `Linear`), got the string `KannalaBrandtK3`",
            ],
        },
        Case {
            name: "observer without calibration",
            input: Aria(|f| {
                f.remove(OBS1_CALIB);
            }),
            expected: &[OBS1_CALIB, "file not found; expected the observer's MPS online_calibration.jsonl"],
        },
        Case {
            name: "calibration records out of order",
            input: Aria(|f| edit_jsonl(f, OBS1_CALIB, |v| v.swap(0, 1))),
            expected: &[OBS1_CALIB, "line 2, field `tracking_timestamp_us`", "is not after the previous one"],
        },
        Case {
            name: "absurd image size",
            input: Aria(|f| edit_jsonl(f, OBS1_CALIB, |v| v[0]["ImageSizes"][2] = serde_json::json!([100000, 100000]))),
            expected: &[
                "line 1, field `ImageSizes[2]`: expected an image side of 1..=16384 pixels, got the number 100000",
            ],
        },
        Case {
            name: "negative focal length",
            input: Aria(|f| {
                edit_jsonl(f, OBS1_CALIB, |v| {
                    v[0]["CameraCalibrations"][2]["Projection"]["Params"][0] = (-610.0).into()
                })
            }),
            expected: &[
                "line 1, field `CameraCalibrations[2].Projection.Params`: expected valid Fisheye624 parameters, got camera focal length `f` must be positive",
            ],
        },
        Case {
            name: "empty calibration file",
            input: Aria(|f| {
                f.insert(OBS1_CALIB.into(), b"\n\n".to_vec());
            }),
            expected: &[OBS1_CALIB, "the file is empty; expected at least one calibration record"],
        },
        // ---- keypoints ------------------------------------------------------------------
        Case {
            name: "keypoints of another observer",
            input: Aria(|f| edit_jsonl(f, OBS1_KP, |v| v[5]["observer"] = "observer-9".into())),
            expected: &[OBS1_KP, "line 6, field `observer`: observer id `observer-9` does not match `observer-1`"],
        },
        Case {
            name: "16 keypoints",
            input: Aria(|f| {
                edit_jsonl(f, OBS1_KP, |v| {
                    v[0]["keypoints"].as_array_mut().unwrap().pop();
                })
            }),
            expected: &[OBS1_KP, "line 1, field `keypoints`: expected 17 COCO keypoints (x, y, score), got 16"],
        },
        Case {
            name: "keypoint score above 1",
            input: Aria(|f| edit_jsonl(f, OBS1_KP, |v| v[2]["keypoints"][0][2] = 1.5.into())),
            expected: &["line 3, field `keypoints[0][2]`: expected a score in [0, 1], got the number 1.5"],
        },
        Case {
            name: "keypoint coordinate null",
            input: Aria(|f| edit_jsonl(f, OBS1_KP, |v| v[4]["keypoints"][6][0] = Value::Null)),
            expected: &["line 5, field `keypoints[6][0]`: expected a finite number, got null"],
        },
        Case {
            name: "keypoint timestamps out of order",
            input: Aria(|f| edit_jsonl(f, OBS1_KP, |v| v.swap(7, 8))),
            expected: &[OBS1_KP, "line 9, field `timestamp_ns`", "is not after the previous one"],
        },
        Case {
            name: "duplicate keypoint timestamp",
            input: Aria(|f| edit_jsonl(f, OBS1_KP, |v| v[3]["timestamp_ns"] = v[2]["timestamp_ns"].clone())),
            expected: &["line 4, field `timestamp_ns`: duplicate timestamp"],
        },
        Case {
            name: "keypoints in microseconds (mixed clocks)",
            input: Aria(|f| {
                edit_jsonl(f, OBS1_KP, |v| {
                    for r in v.iter_mut() {
                        let t = r["timestamp_ns"].as_i64().unwrap();
                        r["timestamp_ns"] = (t / 1000).into();
                    }
                })
            }),
            expected: &["field `observers[0].keypoints.timestamps_ns`: mixed clocks", "never overlap"],
        },
        Case {
            name: "absurd pixel",
            input: Aria(|f| edit_jsonl(f, OBS1_KP, |v| v[1]["keypoints"][5] = serde_json::json!([1e9, 3.0, 0.5]))),
            expected: &["line 2, field `keypoints[5]`: expected pixel coordinates within ±1000000"],
        },
        Case {
            name: "COCO annotation with 16 keypoints",
            input: Aria(|f| {
                edit_json(f, OBS2_COCO, |v| {
                    let k = v[4]["keypoints"].as_array_mut().unwrap();
                    k.truncate(48);
                })
            }),
            expected: &[OBS2_COCO, "field `[4].keypoints`: expected 17 COCO keypoints (x, y, score), got 16"],
        },
        Case {
            name: "COCO dataset with visibility 3",
            input: Aria(|f| {
                edit_json(f, OBS2_COCO, |v| {
                    let mut anns = v.as_array().unwrap().clone();
                    for a in &mut anns {
                        a.as_object_mut().unwrap().remove("score");
                        for k in 0..17 {
                            let v = a["keypoints"][3 * k + 2].as_f64().unwrap();
                            a["keypoints"][3 * k + 2] = if v > 0.0 { 2 } else { 0 }.into();
                        }
                    }
                    anns[3]["keypoints"][5] = 3.into();
                    let images: Vec<Value> =
                        (0..61).map(|i| serde_json::json!({"id": i, "file_name": format!("{i:06}.jpg")})).collect();
                    *v = serde_json::json!({"images": images, "annotations": anns, "categories": [{"id": 1, "name": "person"}]});
                })
            }),
            expected: &[OBS2_COCO, "field `annotations[3].keypoints[5]`: expected a COCO visibility of 0, 1 or 2"],
        },
        Case {
            name: "COCO image id without a frame number",
            input: Aria(|f| edit_json(f, OBS2_COCO, |v| v[2]["image_id"] = "cover.jpg".into())),
            expected: &[
                OBS2_COCO,
                "field `[2].image_id`: expected an image id with a frame number (e.g. `frame_000123.jpg`), got the string `cover.jpg`",
            ],
        },
        Case {
            name: "COCO file is not JSON",
            input: Aria(|f| {
                f.get_mut(OBS2_COCO).unwrap().truncate(1000);
            }),
            expected: &[OBS2_COCO, "line 1: invalid JSON"],
        },
        Case {
            name: "side keypoint file for an unknown observer",
            input: ExtraKeypoints(|| KeypointFile {
                observer_id: "observer-7".into(),
                name: "kp.jsonl".into(),
                bytes: keypoints_jsonl("observer-7", 0).into_bytes(),
            }),
            expected: &["kp.jsonl: observer id `observer-7` does not match `one of [\"observer-1\", \"observer-2\"]`"],
        },
        // ---- layout and clocks ------------------------------------------------------------
        Case {
            name: "observer on another clock",
            input: Aria(|f| {
                edit_csv(f, OBS2_CSV, |rows| {
                    let c = column(rows, "tracking_timestamp_us");
                    for r in rows.iter_mut().skip(1) {
                        let t: i64 = r[c].parse().unwrap();
                        r[c] = (t + 86_400_000_000).to_string();
                    }
                })
            }),
            expected: &[
                "field `observers[1].head`: mixed clocks: `observers[1].head` spans",
                "but `wearer.head` spans",
                "never overlap",
            ],
        },
        Case {
            name: "time_sync.csv on one device only",
            input: Aria(|f| {
                f.insert("observers/observer-2/time_sync.csv".into(), b"device_time_ns,common_time_ns\n0,0\n".to_vec());
            }),
            expected: &[
                "wearer/: mixed clocks: `observers/observer-2/` has a time_sync.csv (common clock) but `wearer/` has none",
            ],
        },
        Case {
            name: "time_sync.csv not increasing",
            input: Nymeria(|f| {
                f.insert(
                    "recording_rwrist/time_sync.csv".into(),
                    b"device_time_ns,common_time_ns\n10,100\n20,90\n".to_vec(),
                );
            }),
            expected: &[
                "recording_rwrist/time_sync.csv, line 3: expected rows strictly increasing in both device_time_ns and common_time_ns, got 20,90 after 10,100",
            ],
        },
        Case {
            name: "observer folder name with a space",
            input: Aria(|f| {
                let moved: Vec<(String, Vec<u8>)> = f
                    .iter()
                    .filter(|(k, _)| k.starts_with("observers/observer-2/"))
                    .map(|(k, v)| (k.replace("observer-2", "observer 2"), v.clone()))
                    .collect();
                f.retain(|k, _| !k.starts_with("observers/observer-2/"));
                f.extend(moved);
            }),
            expected: &["observers/observer 2/: expected an observer folder name of 1–64 characters"],
        },
        Case {
            name: "stature in centimetres",
            input: Aria(|f| {
                f.insert("subject.json".into(), b"{\"height_m\": 170}".to_vec());
            }),
            expected: &["subject.json, field `height_m`: expected a stature in metres within 0.5..=2.7, got 170"],
        },
        Case {
            name: "subject.json not JSON",
            input: Aria(|f| {
                f.insert("subject.json".into(), b"height: 1.7".to_vec());
            }),
            expected: &["subject.json, line 1: invalid JSON"],
        },
        Case {
            name: "wearer without trajectory",
            input: Aria(|f| {
                f.remove(WEARER_CSV);
            }),
            expected: &[
                "wearer/closed_loop_trajectory.csv: file not found; expected an Aria MPS device folder with closed_loop_trajectory.csv",
            ],
        },
        Case {
            name: "unrecognised folder",
            input: Aria(|f| {
                f.clear();
                f.insert("notes.txt".into(), b"hello".to_vec());
                f.insert("video.mp4".into(), vec![0; 10]);
            }),
            expected: &["not a recognised session", "found: notes.txt, video.mp4"],
        },
        // ---- zip containers ---------------------------------------------------------------
        Case {
            name: "truncated zip",
            input: Zip(|| {
                let mut z = zip(&egoexo_files());
                z.truncate(z.len() / 2);
                (z, Limits::default())
            }),
            expected: &["input.zip: not a readable zip archive (truncated or corrupt?)"],
        },
        Case {
            name: "zip entry escaping with ..",
            input: Zip(|| (zip_raw(&[("session.json", b"{}"), ("../evil.csv", b"x")]), Limits::default())),
            expected: &["input.zip: entry path `../evil.csv` is not a safe relative path"],
        },
        Case {
            name: "zip entry with an absolute path",
            input: Zip(|| (zip_raw(&[("/etc/passwd", b"x")]), Limits::default())),
            expected: &["entry path `/etc/passwd` is not a safe relative path"],
        },
        Case {
            name: "zip entry larger than the limit",
            input: Zip(|| (zip(&egoexo_files()), Limits { max_entries: 100, max_file_bytes: 10_000 })),
            expected: &["wearer/head/closed_loop_trajectory.csv: the file size in bytes is", "over the limit of 10000"],
        },
        Case {
            name: "too many zip entries",
            input: Zip(|| (zip(&egoexo_files()), Limits { max_entries: 3, max_file_bytes: 1 << 20 })),
            expected: &["input.zip: the number of files is 7, over the limit of 3"],
        },
        Case {
            name: "empty zip file",
            input: Zip(|| (Vec::new(), Limits::default())),
            expected: &["input.zip: the file is empty; expected a zip archive"],
        },
        // ---- .egoexo manifest ---------------------------------------------------------
        Case {
            name: "unknown schema version",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["version"] = 4.into())),
            expected: &[
                "session.json, field `version`: unsupported schema version 4; this build reads versions 1 to 3",
            ],
        },
        Case {
            name: "a version 2 manifest called version 3 (a capture)",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["version"] = 3.into())),
            expected: &["session.json: missing field `participants`"],
        },
        Case {
            name: "version as a string",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["version"] = "1".into())),
            expected: &["session.json, field `version`: unsupported schema version the string `1`"],
        },
        Case {
            name: "wrong format name",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["format"] = "egoexo".into())),
            expected: &["session.json, field `format`: expected \"egoexo-session\", got the string `egoexo`"],
        },
        Case {
            name: "manifest names a missing file",
            input: Egoexo(|f| {
                f.remove("observers/observer-1/keypoints.jsonl");
            }),
            expected: &[
                "observers/observer-1/keypoints.jsonl: file not found; expected the file named by session.json field `observers[0].keypoints`",
            ],
        },
        Case {
            name: "manifest path with ..",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["wearer"]["head"] = "../head.csv".into())),
            expected: &["session.json, field `wearer.head`: entry path `../head.csv` is not a safe relative path"],
        },
        Case {
            name: "occlusion labels of an unknown observer",
            input: Egoexo(|f| {
                edit_json(f, "session.json", |v| v["ground_truth"]["occlusion_observers"][0] = "ghost".into())
            }),
            expected: &[
                "field `ground_truth.occlusion[0].observer_id`: observer id `ghost` does not match `one of [\"observer-1\", \"observer-2\"]`",
            ],
        },
        Case {
            name: "changed conventions",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["conventions"]["world"] = "z_up".into())),
            expected: &[
                "session.json, field `conventions`: expected {\"world\": \"y_up\", \"device_frame\": \"cpf\"",
                "got an object with 4 fields",
            ],
        },
        Case {
            name: "unknown camera model",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["observers"][1]["camera"]["model"] = "kb4".into())),
            expected: &[
                "session.json, field `observers[1].camera.model`: unknown variant `kb4`, expected `fisheye624` or `pinhole`",
            ],
        },
        Case {
            name: "a camera width that is not a number",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["observers"][0]["camera"]["width"] = "wide".into())),
            expected: &["session.json, field `observers[0].camera.width`: invalid type: string \"wide\", expected u32"],
        },
        Case {
            name: "a pinhole camera with fisheye parameters",
            input: Egoexo(|f| {
                edit_json(f, "session.json", |v| v["observers"][0]["camera"]["model"] = "pinhole".into())
            }),
            expected: &[
                "session.json, field `observers[0].camera.params`: expected an array of 4 numbers, got an array of 15 items",
            ],
        },
        Case {
            name: "a head joint beyond the f32 range",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["wearer"]["head_joint_in_device"][1] = 1e300.into())),
            expected: &[
                "session.json, field `wearer.head_joint_in_device[1]`: expected a number within the f32 range, got 1e300",
            ],
        },
        Case {
            name: "a manifest without its wearer",
            input: Egoexo(|f| {
                edit_json(f, "session.json", |v| {
                    v.as_object_mut().unwrap().remove("wearer");
                })
            }),
            expected: &["session.json: missing field `wearer`"],
        },
        Case {
            name: "empty manifest",
            input: Egoexo(|f| {
                f.insert("session.json".into(), Vec::new());
            }),
            expected: &["session.json: the file is empty; expected the session manifest (JSON)"],
        },
        Case {
            name: "manifest observer id differs from its keypoint file",
            input: Egoexo(|f| edit_json(f, "session.json", |v| v["observers"][1]["id"] = "observer-1".into())),
            expected: &[
                "observers/observer-2/keypoints.jsonl, line 1, field `observer`: observer id `observer-2` does not match `observer-1`",
            ],
        },
        Case {
            name: "duplicate observer ids",
            input: Egoexo(|f| {
                edit_json(f, "session.json", |v| {
                    v["observers"][1]["id"] = "observer-1".into();
                    v["observers"][1].as_object_mut().unwrap().remove("keypoints");
                })
            }),
            expected: &["field `observers[1].id`: expected unique observer ids, got a second `observer-1`"],
        },
        Case {
            name: "ground-truth translation of the wrong shape",
            input: Egoexo(|f| {
                let npz = Npz::open("g", f["ground_truth.npz"].clone(), Limits::default()).unwrap();
                let mut w = NpzWriter::new();
                for name in npz.names() {
                    let a = npz.array(&name).unwrap();
                    let shape: Vec<u64> = a.shape.iter().map(|&d| d as u64).collect();
                    match (name.as_str(), a.data) {
                        ("translation", NpyData::F32(v)) => {
                            w.add("translation", &[shape[0], 2], &v[..v.len() / 3 * 2]).unwrap()
                        }
                        (_, NpyData::F32(v)) => w.add(&name, &shape, &v).unwrap(),
                        (_, NpyData::F64(v)) => w.add(&name, &shape, &v).unwrap(),
                        (_, NpyData::Int(v)) => w.add(&name, &shape, &v).unwrap(),
                    }
                }
                f.insert("ground_truth.npz".into(), w.finish().unwrap());
            }),
            expected: &["ground_truth.npz, field `translation`: expected shape (61, 3), got shape [61, 2]"],
        },
        Case {
            name: "ground-truth start beyond the clock's range",
            input: Egoexo(|f| edit_npz(f, "ground_truth.npz", |a| ints(a, "start_ns")[0] = i64::MAX - 10)),
            expected: &[
                "field `ground_truth.motion.start_ns`: expected a motion whose frame times fit in i64 nanoseconds",
            ],
        },
        Case {
            name: "ground-truth fps of zero",
            input: Egoexo(|f| {
                edit_npz(f, "ground_truth.npz", |a| {
                    if let Some((_, NpyData::F32(v))) = a.get_mut("fps") {
                        v[0] = 0.0;
                    }
                })
            }),
            expected: &[
                "ground_truth.npz: expected a valid SMPL motion, got frame rate must be positive and finite, got 0",
            ],
        },
        // ---- Nymeria ----------------------------------------------------------------------
        Case {
            name: "SMPL npz without transl",
            input: Nymeria(|f| {
                edit_smpl(f, |a| {
                    a.remove("transl");
                })
            }),
            expected: &[
                "body/xdata_smpl_neutral.npz, field `transl`: expected an array `transl`, got none (arrays: betas, body_pose, global_orient, timestamps)",
            ],
        },
        Case {
            name: "SMPL body_pose with 63 columns",
            input: Nymeria(|f| {
                edit_smpl(f, |a| {
                    let (s, v) = f64s(a, "body_pose");
                    let n = s[0] as usize;
                    *v = v.chunks(69).flat_map(|r| r[..63].to_vec()).collect();
                    *s = vec![n as u64, 63];
                })
            }),
            expected: &["body/xdata_smpl_neutral.npz, field `body_pose`: expected shape (61, 69), got shape [61, 63]"],
        },
        Case {
            name: "SMPL timestamps out of order",
            input: Nymeria(|f| edit_smpl(f, |a| ints(a, "timestamps").swap(10, 11))),
            expected: &["body/xdata_smpl_neutral.npz, field `timestamps[11]`", "is not after the previous one"],
        },
        Case {
            name: "SMPL timestamps in nanoseconds",
            input: Nymeria(|f| {
                edit_smpl(f, |a| {
                    for t in ints(a, "timestamps").iter_mut() {
                        *t *= 1000;
                    }
                })
            }),
            expected: &[
                "body/xdata_smpl_neutral.npz, field `timestamps[1]`: expected body samples at most 0.5 s apart, got a gap of 33.333 s",
            ],
        },
        Case {
            name: "SMPL translation NaN",
            input: Nymeria(|f| edit_smpl(f, |a| f64s(a, "transl").1[3 * 7 + 1] = f64::NAN)),
            expected: &["body/xdata_smpl_neutral.npz, field `transl[7, 1]`: expected a finite number, got NaN"],
        },
        Case {
            name: "SMPL fit upside down (another up axis)",
            input: Nymeria(|f| {
                edit_smpl(f, |a| {
                    for (i, v) in f64s(a, "global_orient").1.iter_mut().enumerate() {
                        *v = if i % 3 == 0 { std::f64::consts::PI } else { 0.0 };
                    }
                })
            }),
            expected: &[
                "body/xdata_smpl_neutral.npz, field `global_orient`: expected a Z-up SMPL fit (Nymeria's Aria world)",
                "got the head above the pelvis on 0% of the frames — is this fit Y-up or otherwise rotated?",
            ],
        },
        Case {
            name: "SMPL npz is not a zip",
            input: Nymeria(|f| {
                f.insert(SMPL.into(), b"this is not an npz".to_vec());
            }),
            expected: &["body/xdata_smpl_neutral.npz: not a readable zip archive"],
        },
        Case {
            name: "SMPL array with a corrupt header",
            input: Nymeria(|f| {
                let mut files = BTreeMap::new();
                files.insert("timestamps.npy".to_string(), b"\x93NUMPY\x01\x00\x10\x00{'descr': '<i8' ".to_vec());
                f.insert(SMPL.into(), egoexo_motion_io::npz::write_zip(&files).unwrap());
            }),
            expected: &["body/xdata_smpl_neutral.npz, field `timestamps`: invalid .npy array: malformed header"],
        },
        Case {
            name: "SMPL betas of the wrong shape",
            input: Nymeria(|f| {
                edit_smpl(f, |a| {
                    let (s, _) = f64s(a, "betas");
                    *s = vec![10, 61];
                })
            }),
            expected: &["field `betas`: expected shape (N, B) or (B,) with N = 61, got shape [10, 61]"],
        },
        Case {
            name: "Nymeria observer without calibration",
            input: Nymeria(|f| {
                f.remove("recording_observer/mps/slam/online_calibration.jsonl");
            }),
            expected: &[
                "recording_observer/mps/slam/online_calibration.jsonl: file not found; expected the observer's MPS online_calibration.jsonl",
            ],
        },
    ]
}

fn run(case: &Case) -> Result<(), egoexo_session::ImportError> {
    let options = ImportOptions::default();
    let result = match &case.input {
        Input::Aria(edit) => {
            let mut f = aria_fixture();
            edit(&mut f);
            import_session(&FileTree::from_files("aria", f, Limits::default())?, &options)
        }
        Input::Nymeria(edit) => {
            let mut f = nymeria_fixture();
            edit(&mut f);
            import_session(&FileTree::from_files("nymeria", f, Limits::default())?, &options)
        }
        Input::Egoexo(edit) => {
            let mut f = egoexo_files();
            edit(&mut f);
            import_session(&FileTree::from_files("s.egoexo", f, Limits::default())?, &options)
        }
        Input::Zip(make) => {
            let (bytes, limits) = make();
            FileTree::from_zip("input.zip", bytes, limits).and_then(|t| import_session(&t, &options))
        }
        Input::ExtraKeypoints(make) => {
            let options = ImportOptions { keypoint_files: vec![make()], ..ImportOptions::default() };
            import_session(&tree("aria", aria_fixture()), &options)
        }
    };
    result.map(|_| ())
}

#[test]
fn every_malformed_input_is_a_clear_error() {
    let cases = cases();
    assert!(cases.len() >= 40, "{} cases", cases.len());
    let mut failures = Vec::new();
    for case in &cases {
        match run(case) {
            Ok(()) => failures.push(format!("{}: imported without error", case.name)),
            Err(e) => {
                let message = e.to_string();
                let missing: Vec<&&str> = case.expected.iter().filter(|s| !message.contains(**s)).collect();
                if !missing.is_empty() {
                    failures.push(format!("{}:\n   message: {message}\n   missing: {missing:?}", case.name));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{} of {} cases failed:\n{}", failures.len(), cases.len(), failures.join("\n"));
}

#[test]
fn the_unmodified_fixtures_import() {
    for f in [aria_fixture(), nymeria_fixture(), egoexo_files()] {
        import_session(&tree("ok", f), &ImportOptions::default()).unwrap();
    }
}

/// Keys the format does not know are read past, each a warning that names it by its path.
#[test]
fn keys_the_format_does_not_know_are_warnings_that_name_them() {
    let mut f = egoexo_files();
    edit_json(&mut f, "session.json", |v| {
        v["extra"] = 1.into();
        v["observers"][1]["camera"]["lens"] = "wide".into();
        v["wearer"]["note"] = serde_json::json!({"written_by": "hand"});
    });
    let tree = FileTree::from_files("s.egoexo", f, Limits::default()).unwrap();
    let (_, warnings) = egoexo_session::format::read_egoexo(&tree).unwrap();
    let messages: Vec<String> = warnings.iter().map(ToString::to_string).collect();
    for key in ["extra", "observers[1].camera.lens", "wearer.note"] {
        let warned = format!("session.json: unknown field `{key}` ignored");
        assert!(messages.iter().any(|m| m.contains(&warned)), "{warned}: {messages:#?}");
    }
    assert_eq!(messages.len(), 3, "{messages:#?}");
}
