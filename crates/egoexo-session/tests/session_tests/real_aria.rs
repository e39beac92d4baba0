//! What real Aria users hold, written by the tests from the documented column sets and
//! imported: MPS's own `trajectory/` + `hand_tracking/` layout with a 1 kHz trajectory (sample
//! gaps from 1 µs to 1.2 ms, a low-quality start), hand tracking in every published form
//! (wrists that come and go), gzipped semidense points with a floor, tables and walls, a Y-up
//! (Aria Digital Twin) world, and both calibration forms.

use crate::support;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write as _;

use crate::support::*;
use egoexo_core::ego_features::TrackingMode;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_session::aria::hand_tracking::{HandTrackingForm, WristOrientation};
use egoexo_session::aria::{AriaFrameSize, aria_pose_from_session, nominal_t_device_cpf};
use egoexo_session::format::write_egoexo_zip;
use egoexo_session::import::{ImportOptions, import_session};
use egoexo_session::model::{FloorSource, WristSource};
use egoexo_session::{AlignOptions, FileTree, Imported, Limits, align};

/// Hand tracking rate, Hz (the SLAM cameras' rate; 10 Hz in many recordings).
const HAND_HZ: f64 = 30.0;
/// Scene seconds where the left / right hand is out of view.
const LEFT_UNSEEN: (f64, f64) = (0.8, 1.3);
const RIGHT_UNSEEN: (f64, f64) = (0.2, 0.5);
/// Scene seconds of low SLAM quality at the start.
const LOW_QUALITY_UNTIL: f64 = 0.3;

const TRAJECTORY_HEADER: &str = "graph_uid,tracking_timestamp_us,utc_timestamp_ns,tx_world_device,ty_world_device,tz_world_device,qx_world_device,qy_world_device,qz_world_device,qw_world_device,device_linear_velocity_x_device,device_linear_velocity_y_device,device_linear_velocity_z_device,angular_velocity_x_device,angular_velocity_y_device,angular_velocity_z_device,gravity_x_world,gravity_y_world,gravity_z_world,quality_score,geo_available,tx_ecef_device,ty_ecef_device,tz_ecef_device,qx_ecef_device,qy_ecef_device,qz_ecef_device,qw_ecef_device";

fn t_device_cpf() -> RigidTransform {
    nominal_t_device_cpf(AriaFrameSize::Small)
}

/// The glasses' device frame (left SLAM camera) in the session world.
fn device_at(t: f64) -> RigidTransform {
    head_cpf_at(t) * t_device_cpf().inverse()
}

/// Scene times of the 1 kHz rows: intervals of 1 ms, with a 1 µs and a 1.2 ms one now and then
/// (as MPS writes them).
fn mps_times() -> Vec<f64> {
    mps_times_every(1000)
}

/// Rows every `step_us` µs, with a 1 µs and a 1.2-step interval now and then.
fn mps_times_every(step_us: i64) -> Vec<f64> {
    let mut times = Vec::new();
    let mut us = 0i64;
    let mut i = 0u64;
    while (us as f64) * 1e-6 <= DURATION_S {
        times.push(us as f64 * 1e-6);
        us += match i % 97 {
            13 => 1,
            51 => step_us * 6 / 5,
            _ => step_us,
        };
        i += 1;
    }
    times
}

/// A closed-loop trajectory in a world with gravity `gravity` (Z-up: the MPS world; Y-up: the
/// session world itself, as Aria Digital Twin writes).
fn trajectory_csv(y_up: bool) -> String {
    trajectory_csv_at(y_up, &mps_times())
}

fn trajectory_csv_at(y_up: bool, times: &[f64]) -> String {
    let mut out = format!("{TRAJECTORY_HEADER}\n");
    let gravity = if y_up { "0.000000,-9.810000,0.000000" } else { "0.000000,0.000000,-9.810000" };
    for &t in times {
        let pose = if y_up { device_at(t) } else { aria_pose_from_session(&device_at(t), None) };
        let (q, p) = (pose.rotation, pose.translation);
        let quality = if t < LOW_QUALITY_UNTIL { 0.12 } else { 0.93 };
        let _ = writeln!(
            out,
            "graph-1,{},-1,{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},0,0,0,0,0,0,{gravity},{quality},0,,,,,,,",
            session_ns(t) / 1000,
            p.x,
            p.y,
            p.z,
            q.x,
            q.y,
            q.z,
            q.w
        );
    }
    out
}

/// Is `side` (left = true) in view at scene time `t`?
fn seen(t: f64, left: bool) -> bool {
    let (a, b) = if left { LEFT_UNSEEN } else { RIGHT_UNSEEN };
    !(a..b).contains(&t)
}

/// The hand of `side` at `t` in the device frame: wrist, palm centre, palm normal (out of the
/// palm), and `T_device_wrist` in SMPL wrist-joint convention.
fn hand_in_device(t: f64, left: bool) -> (Vec3, Vec3, Vec3, RigidTransform) {
    let t_world_wrist = wrist_at(t, left);
    let t_device_wrist = device_at(t).inverse() * t_world_wrist;
    let r = t_device_wrist.rotation;
    let along = if left { Vec3::X } else { Vec3::NEG_X };
    let wrist = t_device_wrist.translation;
    (wrist, wrist + r * along * 0.08, r * Vec3::NEG_Y, t_device_wrist)
}

fn hand_times() -> Vec<f64> {
    let n = (DURATION_S * HAND_HZ) as usize;
    (0..n).map(|i| i as f64 / HAND_HZ).collect()
}

fn xyz(v: Vec3) -> String {
    format!("{:.6},{:.6},{:.6}", v.x, v.y, v.z)
}

/// `wrist_and_palm_poses.csv`, v1 (positions) or v2 (with normals), in MPS column order.
fn wrist_and_palm_csv(v2: bool) -> String {
    let mut header = String::from(
        "tracking_timestamp_us,left_tracking_confidence,tx_left_wrist_device,ty_left_wrist_device,tz_left_wrist_device,tx_left_palm_device,ty_left_palm_device,tz_left_palm_device,right_tracking_confidence,tx_right_wrist_device,ty_right_wrist_device,tz_right_wrist_device,tx_right_palm_device,ty_right_palm_device,tz_right_palm_device",
    );
    if v2 {
        header.push_str(",nx_left_palm_device,ny_left_palm_device,nz_left_palm_device,nx_left_wrist_device,ny_left_wrist_device,nz_left_wrist_device,nx_right_palm_device,ny_right_palm_device,nz_right_palm_device,nx_right_wrist_device,ny_right_wrist_device,nz_right_wrist_device");
    }
    let mut out = header + "\n";
    for t in hand_times() {
        let mut row = format!("{}", session_ns(t) / 1000);
        let mut normals = String::new();
        for left in [true, false] {
            if seen(t, left) {
                let (wrist, palm, normal, _) = hand_in_device(t, left);
                let _ = write!(row, ",0.98,{},{}", xyz(wrist), xyz(palm));
                let _ = write!(normals, ",{},{}", xyz(normal), xyz(normal));
            } else {
                row.push_str(",-1,0,0,0,0,0,0");
                normals.push_str(",0,0,0,0,0,0");
            }
        }
        if v2 {
            row.push_str(&normals);
        }
        out.push_str(&row);
        out.push('\n');
    }
    out
}

/// `hand_tracking_results.csv` (v2: landmarks, `T_device_wrist`, normals).
fn hand_tracking_results_csv() -> String {
    let mut header = String::from("tracking_timestamp_us");
    for side in ["left", "right"] {
        let _ = write!(header, ",{side}_tracking_confidence");
        for k in 0..21 {
            let _ = write!(
                header,
                ",tx_{side}_landmark_{k}_device,ty_{side}_landmark_{k}_device,tz_{side}_landmark_{k}_device"
            );
        }
    }
    for side in ["left", "right"] {
        let _ = write!(
            header,
            ",tx_{side}_device_wrist,ty_{side}_device_wrist,tz_{side}_device_wrist,qx_{side}_device_wrist,qy_{side}_device_wrist,qz_{side}_device_wrist,qw_{side}_device_wrist"
        );
    }
    for side in ["left", "right"] {
        let _ = write!(
            header,
            ",nx_{side}_palm_device,ny_{side}_palm_device,nz_{side}_palm_device,nx_{side}_wrist_device,ny_{side}_wrist_device,nz_{side}_wrist_device"
        );
    }
    let mut out = header + "\n";
    for t in hand_times() {
        let mut row = format!("{}", session_ns(t) / 1000);
        let mut poses = String::new();
        let mut normals = String::new();
        for left in [true, false] {
            if seen(t, left) {
                let (wrist, palm, normal, t_device_wrist) = hand_in_device(t, left);
                row.push_str(",0.97");
                for k in 0..21 {
                    // Landmark 5 is the wrist, 20 the palm centre; the fingers are not read.
                    let p = match k {
                        5 => wrist,
                        20 => palm,
                        _ => palm + Vec3::splat(0.01 * k as f32),
                    };
                    let _ = write!(row, ",{}", xyz(p));
                }
                let q = t_device_wrist.rotation;
                let _ = write!(poses, ",{},{:.7},{:.7},{:.7},{:.7}", xyz(wrist), q.x, q.y, q.z, q.w);
                let _ = write!(normals, ",{},{}", xyz(normal), xyz(normal));
            } else {
                row.push_str(",-1");
                row.push_str(&",0,0,0".repeat(21));
                poses.push_str(",0,0,0,0,0,0,1");
                normals.push_str(",0,0,0,0,0,0");
            }
        }
        out.push_str(&row);
        out.push_str(&poses);
        out.push_str(&normals);
        out.push('\n');
    }
    out
}

fn gzip(text: &str) -> Vec<u8> {
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    encoder.write_all(text.as_bytes()).unwrap();
    encoder.finish().unwrap()
}

/// Semidense points in the MPS world: a floor at session y = 0, a table top at 0.74 m with more
/// points than the floor, two walls, a ceiling, and badly constrained points below the floor.
fn global_points_csv(floor_y: f32) -> String {
    let mut out = String::from("uid,graph_uid,px_world,py_world,pz_world,inv_dist_std,dist_std\n");
    let mut uid = 0;
    let mut point = |out: &mut String, p: Vec3, inv_std: f32, std: f32| {
        let aria = aria_pose_from_session(&RigidTransform::from_translation(p), None).translation;
        let _ = writeln!(out, "{uid},graph-1,{:.5},{:.5},{:.5},{inv_std},{std}", aria.x, aria.y, aria.z);
        uid += 1;
    };
    let wobble = |i: usize| ((i * 7919) % 100) as f32 / 100.0 - 0.5;
    for i in 0..1500 {
        let p =
            Vec3::new(-2.0 + 4.0 * wobble(i) + 2.0, floor_y + 0.006 * wobble(i + 3), -2.0 + 4.0 * wobble(i + 11) + 2.0);
        point(&mut out, p, 0.0004, 0.02);
    }
    for i in 0..2500 {
        point(
            &mut out,
            Vec3::new(1.0 + 0.6 * wobble(i), floor_y + 0.74 + 0.004 * wobble(i + 5), 2.0 + 0.4 * wobble(i + 9)),
            0.0003,
            0.01,
        );
    }
    for i in 0..2000 {
        point(&mut out, Vec3::new(3.0, floor_y + 2.6 * (wobble(i) + 0.5), 3.0 * wobble(i + 1)), 0.0005, 0.03);
        point(&mut out, Vec3::new(3.0 * wobble(i + 2), floor_y + 2.6 * (wobble(i + 4) + 0.5), -2.5), 0.0005, 0.03);
    }
    for i in 0..800 {
        point(&mut out, Vec3::new(2.0 * wobble(i), floor_y + 2.6, 2.0 * wobble(i + 7)), 0.0008, 0.04);
    }
    for i in 0..1200 {
        // Far and uncertain: filtered out.
        point(&mut out, Vec3::new(2.0 * wobble(i), floor_y - 0.5, 2.0 * wobble(i + 7)), 0.01, 0.4);
    }
    out
}

/// MPS's own output folder of the wearer's glasses: `trajectory/` and `hand_tracking/`.
fn mps_device_folder(hand_file: Option<(&str, String)>, points: bool, y_up: bool) -> BTreeMap<String, Vec<u8>> {
    let mut files = BTreeMap::new();
    files.insert("trajectory/closed_loop_trajectory.csv".to_owned(), trajectory_csv(y_up).into_bytes());
    files.insert(
        "trajectory/online_calibration.jsonl".to_owned(),
        online_calibration_jsonl(DeviceClock::SHARED, false).into_bytes(),
    );
    if points {
        files.insert("trajectory/global_points.csv.gz".to_owned(), gzip(&global_points_csv(0.0)));
    }
    if let Some((name, text)) = hand_file {
        files.insert(format!("hand_tracking/{name}"), text.into_bytes());
    }
    files
}

/// The committed fixture `aria_mps_hands/` (what the CLI and browser tests drop): the folder
/// above with hand tracking v2 and points, the trajectory at 200 Hz to keep it small.
fn aria_mps_hands_fixture() -> BTreeMap<String, Vec<u8>> {
    let mut files = mps_device_folder(Some(("wrist_and_palm_poses.csv", wrist_and_palm_csv(true))), true, false);
    files.insert(
        "trajectory/closed_loop_trajectory.csv".into(),
        trajectory_csv_at(false, &mps_times_every(5000)).into_bytes(),
    );
    files
}

#[test]
fn the_committed_fixture_matches_the_generator() {
    let dir = fixtures_dir().join("aria_mps_hands");
    let files = aria_mps_hands_fixture();
    if std::env::var_os("EGOEXO_REGENERATE_FIXTURES").is_some() {
        let _ = std::fs::remove_dir_all(&dir);
        egoexo_session::vfs::write_dir(&dir, &files).unwrap();
    }
    let total: usize = files.values().map(Vec::len).sum();
    assert!(total < 400_000, "aria_mps_hands is {total} bytes; keep fixtures small");
    for (path, bytes) in &files {
        let on_disk = std::fs::read(dir.join(path))
            .unwrap_or_else(|e| panic!("aria_mps_hands/{path}: {e}; run with EGOEXO_REGENERATE_FIXTURES=1"));
        assert!(
            on_disk == *bytes,
            "aria_mps_hands/{path} differs from the generator; run with EGOEXO_REGENERATE_FIXTURES=1"
        );
    }
    let imported = egoexo_session::import::import_path(&dir, &ImportOptions::default()).unwrap();
    assert!(matches!(imported.session.wearer.wrist_source, WristSource::HandTracking { .. }));
}

fn import(files: BTreeMap<String, Vec<u8>>) -> Imported {
    let tree = FileTree::from_files("mps_wearer", files, Limits::default()).unwrap();
    match import_session(&tree, &ImportOptions::default()) {
        Ok(imported) => imported,
        Err(e) => panic!("import failed: {e}"),
    }
}

fn angle(a: Quat, b: Quat) -> f32 {
    a.angle_between(b).to_degrees()
}

#[test]
fn hand_tracking_in_every_form_gives_wrists_that_come_and_go() {
    let forms = [
        (
            "wrist_and_palm_poses.csv",
            wrist_and_palm_csv(false),
            HandTrackingForm::WristAndPalmV1,
            WristOrientation::PalmDownAssumed,
        ),
        (
            "wrist_and_palm_poses.csv",
            wrist_and_palm_csv(true),
            HandTrackingForm::WristAndPalmV2,
            WristOrientation::FromNormals,
        ),
        (
            "hand_tracking_results.csv",
            hand_tracking_results_csv(),
            HandTrackingForm::HandTrackingResults,
            WristOrientation::FromWristPose,
        ),
    ];
    for (name, text, form, orientation) in forms {
        let imported = import(mps_device_folder(Some((name, text)), true, false));
        let wearer = &imported.session.wearer;
        match &wearer.wrist_source {
            WristSource::HandTracking { file, form: f, orientation: o } => {
                assert!(file.ends_with(&format!("hand_tracking/{name}")), "{file}");
                assert_eq!((*f, *o), (form, orientation));
            }
            other => panic!("{form:?}: wrist source {other:?}"),
        }
        for (left, wrist) in
            [(true, wearer.left_wrist.as_ref().unwrap()), (false, wearer.right_wrist.as_ref().unwrap())]
        {
            // Exactly the tracked samples are kept, each in the world at its own time.
            let expected = hand_times().into_iter().filter(|&t| seen(t, left)).count();
            assert_eq!(wrist.len(), expected, "{form:?} left={left}");
            for (&ns, pose) in wrist.timestamps_ns.iter().zip(&wrist.poses) {
                let t = (ns - START_NS) as f64 * 1e-9;
                let truth = wrist_at(t, left);
                let error_mm = (pose.translation - truth.translation).length() * 1000.0;
                assert!(error_mm < 1.0, "{form:?} left={left} t={t:.3}: {error_mm:.2} mm");
                let hand_axis = if left { Vec3::X } else { Vec3::NEG_X };
                let direction = (pose.rotation * hand_axis).angle_between(truth.rotation * hand_axis).to_degrees();
                assert!(direction < 0.5, "{form:?}: hand direction off by {direction:.2}°");
                if orientation == WristOrientation::PalmDownAssumed {
                    // Roll is a guess: the palm faces as far down as the hand direction allows.
                    assert!((pose.rotation * Vec3::NEG_Y).y <= 1e-4, "{form:?}: palm faces up");
                } else {
                    assert!(
                        angle(pose.rotation, truth.rotation) < 0.5,
                        "{form:?}: {:.2}°",
                        angle(pose.rotation, truth.rotation)
                    );
                }
            }
        }
        // On the timeline: untracked while out of view; the 3-point model reads them where
        // they are, with a note on how much of the time that is.
        let aligned = align(&imported.session, &AlignOptions::default()).unwrap();
        let frame = |t: f64| ((t * 30.0).round()) as usize;
        let left = aligned.left_wrist.as_ref().unwrap();
        let right = aligned.right_wrist.as_ref().unwrap();
        assert!(!left.valid[frame(1.0)] && left.valid[frame(0.5)] && left.valid[frame(1.6)]);
        assert!(!right.valid[frame(0.35)] && right.valid[frame(1.0)]);
        let choice = aligned.tracking_choice();
        assert_eq!(choice.mode, TrackingMode::ThreePoint);
        let reason = choice.reason.unwrap();
        assert!(
            reason.contains("tracked on") && reason.contains("(left)") && reason.contains("where they are"),
            "{reason}"
        );
        // Kept through .egoexo.
        let zip = write_egoexo_zip(&imported.session).unwrap();
        let back =
            import_session(&FileTree::from_zip("s.egoexo", zip, Limits::default()).unwrap(), &ImportOptions::default())
                .unwrap();
        assert_eq!(back.session.wearer.wrist_source, imported.session.wearer.wrist_source);
        assert_eq!(back.session.floor, imported.session.floor);
    }
}

#[test]
fn a_1khz_trajectory_with_a_low_quality_start_imports_with_a_warning() {
    let imported = import(mps_device_folder(None, false, false));
    let head = &imported.session.wearer.head;
    assert_eq!(head.len(), mps_times().len());
    let gaps: Vec<i64> = head.timestamps_ns.windows(2).map(|w| w[1] - w[0]).collect();
    assert_eq!((gaps.iter().min(), gaps.iter().max()), (Some(&1_000), Some(&1_200_000)));
    let warning = imported
        .warnings
        .iter()
        .map(ToString::to_string)
        .find(|w| w.contains("quality_score below 0.5"))
        .expect("a low-quality warning");
    assert!(warning.contains("trajectory/closed_loop_trajectory.csv") && warning.contains("0.00–0.30 s"), "{warning}");
    // No hand tracking: no wrists, no reason.
    let aligned = align(&imported.session, &AlignOptions::default()).unwrap();
    assert_eq!(aligned.tracking_choice().reason, None);
}

#[test]
fn big_files_report_progress_up_to_their_size() {
    use std::sync::{Arc, Mutex};
    let files = mps_device_folder(None, true, false);
    let size = files["trajectory/closed_loop_trajectory.csv"].len() as u64;
    let reports = Arc::new(Mutex::new(Vec::<(String, u64, u64)>::new()));
    let sink = reports.clone();
    let options = ImportOptions {
        progress: Some(egoexo_session::import::ImportProgress(Arc::new(move |file: &str, done: u64, total: u64| {
            sink.lock().unwrap().push((file.to_owned(), done, total));
        }))),
        ..ImportOptions::default()
    };
    import_session(&FileTree::from_files("mps", files, Limits::default()).unwrap(), &options).unwrap();
    let reports = reports.lock().unwrap();
    let trajectory: Vec<_> = reports.iter().filter(|r| r.0.ends_with("closed_loop_trajectory.csv")).collect();
    assert!(trajectory.iter().all(|r| r.2 == size && r.1 <= size));
    assert_eq!(trajectory.last().map(|r| r.1), Some(size), "the last report is the whole file");
    let points = reports.iter().rfind(|r| r.0.ends_with("global_points.csv.gz")).unwrap();
    assert_eq!((points.1, points.2), (10_000, 0), "rows of a compressed file, total unknown");
}

#[test]
fn a_y_up_world_imports_as_the_z_up_one() {
    let z_up = import(mps_device_folder(None, false, false)).session;
    let y_up = import(mps_device_folder(None, false, true)).session;
    for (a, b) in z_up.wearer.head.poses.iter().zip(&y_up.wearer.head.poses) {
        let (d, r) = ((a.translation - b.translation).length(), angle(a.rotation, b.rotation));
        assert!(d < 2e-5 && r < 0.1, "{d} m, {r}° (f32 angle noise)");
    }
    // And upright: the glasses stay above the floor.
    assert!(y_up.wearer.head.poses.iter().all(|p| p.translation.y > 1.4));
}

#[test]
fn the_floor_comes_from_semidense_points_else_from_the_standing_head() {
    let with_points = import(mps_device_folder(None, true, false)).session;
    let floor = with_points.floor.unwrap();
    assert!(floor.height_m.abs() < 0.01, "{floor:?}");
    match &floor.source {
        FloorSource::SemidensePoints { file, points } => {
            assert!(file.ends_with("trajectory/global_points.csv.gz"));
            assert!(*points > 1000, "{points}");
        }
        other => panic!("{other:?}"),
    }
    let without = import(mps_device_folder(None, false, false)).session;
    let floor = without.floor.unwrap();
    assert!(matches!(floor.source, FloorSource::StandingHead { stature_known: false, .. }), "{floor:?}");
    assert!(floor.height_m.abs() < 0.06, "{floor:?}");
    // Points with no floor below the head (all too high): the standing head, and a warning.
    let mut files = mps_device_folder(None, false, false);
    files.insert("trajectory/global_points.csv.gz".into(), gzip(&global_points_csv(1.5)));
    let imported = import(files);
    assert!(matches!(imported.session.floor.unwrap().source, FloorSource::StandingHead { .. }));
    assert!(imported.warnings.iter().any(|w| w.to_string().contains("none form a floor")));
}

#[test]
fn full_resolution_calibrations_meet_keypoints_at_the_stream_resolution() {
    let mut files = aria_fixture();
    // observer-1 with an older MPS calibration: no ImageSizes, parameters at 2880 px; its
    // keypoints were detected on the 1408 px stream.
    files.insert(
        "observers/observer-1/mps/slam/online_calibration.jsonl".into(),
        online_calibration_jsonl(DeviceClock::SHARED, true).into_bytes(),
    );
    let imported = import_session(&support::tree("aria_mps", files), &ImportOptions::default()).unwrap();
    let reference = import_session(&support::tree("aria_mps", aria_fixture()), &ImportOptions::default()).unwrap();
    let (camera, expected) = (&imported.session.observers[0].camera, &reference.session.observers[0].camera);
    assert_eq!((camera.width, camera.height), (1408, 1408));
    let (a, b) = (camera.projection.principal_point(), expected.projection.principal_point());
    assert!((a - b).length() < 0.01, "{a} vs {b}");
    let warnings: Vec<String> = imported.warnings.iter().map(ToString::to_string).collect();
    assert!(warnings.iter().any(|w| w.contains("no ImageSizes") && w.contains("2880×2880")), "{warnings:#?}");
    assert!(warnings.iter().any(|w| w.contains("rescaled to 1408×1408")), "{warnings:#?}");
    assert!(
        !reference.warnings.iter().any(|w| w.to_string().contains("ImageSizes")),
        "ImageSizes given: nothing to say"
    );
}
