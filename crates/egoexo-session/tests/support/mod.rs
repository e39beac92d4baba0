//! Fixture generator: a 2-second scene (a wearer walking on an arc, observers watching) written
//! in the formats of real devices — Aria MPS folders and a Nymeria sequence — from the
//! documented columns. The committed fixtures under `tests/fixtures/` are exactly this
//! output (`fixtures_match_the_generator` checks; set `EGOEXO_REGENERATE_FIXTURES=1` to
//! rewrite them).
//!
//! The scene is analytic (functions of time), so tests can compare what an importer returns
//! with the truth at any time. Truth is in session conventions (Y-up world, CPF head
//! devices, ns); the writers convert to Aria conventions with `egoexo_session::aria`'s
//! inverse functions, whose forward directions are checked against hand-built cases in the
//! library's unit tests.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::fmt::Write as _;

use egoexo_core::camera::{CameraCalibration, Fisheye624, Projection};
use egoexo_core::exo_keypoints::{COCO17_COUNT, ExoKeypoint, Keypoint2d, exo_keypoints_from_smpl};
use egoexo_core::glam::{Mat3, Quat, Vec2, Vec3};
use egoexo_core::motion::SmplMotion;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::rotation::axis_angle_from_quat;
use egoexo_core::skeleton::{DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE, SmplJoint, SmplPose, SmplSkeleton};
use egoexo_motion_io::npz::NpzWriter;
use egoexo_session::aria::calibration::se3_json;
use egoexo_session::aria::{AriaFrameSize, aria_pose_from_session, aria_smpl_pose_from_session, nominal_t_device_cpf};
use serde_json::json;

/// Scene length, seconds.
pub const DURATION_S: f64 = 2.0;
/// Session-clock time of the scene's start, nanoseconds (one hour after the head device booted).
pub const START_NS: i64 = 3_600_000_000_000;
/// MPS trajectory rate in the fixtures (real MPS: 1 kHz; lower keeps the files small).
pub const TRAJECTORY_HZ: f64 = 50.0;
/// Keypoint / RGB / ground-truth rate.
pub const FRAME_HZ: f64 = 30.0;
/// Wall-clock (UTC) time of the session clock's zero, nanoseconds.
pub const UTC_OFFSET_NS: i64 = 1_717_000_000_000_000_000;

/// The wearer's SMPL pose at time `t` (seconds since the scene start): walking on an arc of
/// radius 1.5 m at 0.7 m/s, legs and arms swinging.
pub fn body_pose_at(t: f64) -> SmplPose {
    let radius = 1.5;
    let angle = 0.7 * t / radius;
    // The pelvis, ~0.97 m above the floor (the mean shape's feet are 0.92 m below it).
    let pelvis = Vec3::new((radius * angle.sin()) as f32, 0.97, (radius * (1.0 - angle.cos())) as f32);
    // Facing the direction of travel (the body faces +Z; heading rotates it about +Y).
    let heading = Quat::from_rotation_y(angle as f32);
    let phase = 2.0 * PI * 0.9 * t;
    let swing = (0.4 * phase.sin()) as f32;
    let mut body = [Quat::IDENTITY; 21];
    let set = |body: &mut [Quat; 21], joint: SmplJoint, q: Quat| body[joint.index() - 1] = q;
    set(&mut body, SmplJoint::LeftHip, Quat::from_rotation_x(-swing));
    set(&mut body, SmplJoint::RightHip, Quat::from_rotation_x(swing));
    set(&mut body, SmplJoint::LeftKnee, Quat::from_rotation_x(0.3 + 0.3 * swing.abs()));
    set(&mut body, SmplJoint::RightKnee, Quat::from_rotation_x(0.3 + 0.3 * swing.abs()));
    set(&mut body, SmplJoint::LeftShoulder, Quat::from_rotation_z(-1.25) * Quat::from_rotation_y(0.5 * swing));
    set(&mut body, SmplJoint::RightShoulder, Quat::from_rotation_z(1.25) * Quat::from_rotation_y(0.5 * swing));
    set(&mut body, SmplJoint::LeftElbow, Quat::from_rotation_y(-0.4));
    set(&mut body, SmplJoint::RightElbow, Quat::from_rotation_y(0.4));
    set(&mut body, SmplJoint::Neck, Quat::from_rotation_x((0.1 * (0.5 * phase).sin()) as f32));
    let skeleton = SmplSkeleton::mean_shape();
    SmplPose { root_orientation: heading, body, translation: pelvis - skeleton.rest_joints()[0] }
}

/// The wearer's glasses: `T_world_cpf` from the head joint and the default offset.
pub fn head_cpf_at(t: f64) -> RigidTransform {
    let fk = SmplSkeleton::mean_shape().forward_kinematics(&body_pose_at(t));
    let r = fk.rotations[SmplJoint::Head.index()];
    let p_head = fk.positions[SmplJoint::Head.index()];
    RigidTransform::new(r, p_head - r * DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE)
}

/// A wrist device: the SMPL wrist joint's frame.
pub fn wrist_at(t: f64, left: bool) -> RigidTransform {
    let fk = SmplSkeleton::mean_shape().forward_kinematics(&body_pose_at(t));
    let j = if left { SmplJoint::LeftWrist } else { SmplJoint::RightWrist }.index();
    RigidTransform::new(fk.rotations[j], fk.positions[j])
}

/// Observer `k`'s glasses (CPF): standing ~3 m away, swaying a little, looking at the
/// wearer's chest.
pub fn observer_cpf_at(t: f64, k: usize) -> RigidTransform {
    let base = [Vec3::new(0.6, 1.62, 3.4), Vec3::new(-2.4, 1.70, 0.4), Vec3::new(2.8, 1.55, -1.0)][k % 3];
    let sway = Vec3::new((0.03 * (1.3 * t).sin()) as f32, (0.01 * (2.1 * t).sin()) as f32, 0.0);
    let fk = SmplSkeleton::mean_shape().forward_kinematics(&body_pose_at(t));
    let chest = fk.positions[SmplJoint::Spine3.index()];
    RigidTransform::cpf_looking_at(base + sway, chest)
}

/// `T_cpf_camera` of Aria's RGB camera (CAD, DVT-S: `camera-rgb` row of
/// projectaria_tools' DeviceCadExtrinsics — mounted rotated by 90°, tilted 7.5° down).
pub fn rgb_t_cpf_camera() -> RigidTransform {
    let y = Vec3::new(1.0, 0.0, 0.0);
    let z = Vec3::new(0.0, -0.130526, 0.991445).normalize();
    RigidTransform::from_rotation_matrix(Mat3::from_cols(y.cross(z), y, z), Vec3::new(0.056, 0.007121, 0.012883))
}

/// Fisheye624 parameters of an Aria RGB camera at 1408 × 1408 (typical values).
pub const RGB_PARAMS: [f32; 15] = [
    610.9, 715.2, 716.4, 0.397, -0.353, -0.206, 1.674, -2.114, 0.733, 0.00043, -0.00021, -0.00037, 0.00011, 0.00024,
    -0.00009,
];

/// The RGB camera in session conventions (`T_cpf_camera`), 1408 × 1408.
pub fn rgb_camera() -> CameraCalibration {
    CameraCalibration::new(Projection::Fisheye624(Fisheye624::new(RGB_PARAMS).unwrap()), 1408, 1408, rgb_t_cpf_camera())
        .unwrap()
        .with_valid_radius(1415.0 * 1408.0 / 2880.0)
}

/// The 17 COCO keypoints observer `k` sees at time `t` (eyes and ears placed around the nose,
/// with lower scores, as detectors do).
pub fn keypoints_at(t: f64, k: usize) -> [Option<Keypoint2d>; COCO17_COUNT] {
    body_keypoints(&body_pose_at(t), &observer_cpf_at(t, k), t)
}

/// The 17 COCO keypoints of the mean-shape body in `pose` seen by the RGB camera of glasses
/// at `t_world_device` at time `t` (scores vary with `t`).
pub fn body_keypoints(pose: &SmplPose, t_world_device: &RigidTransform, t: f64) -> [Option<Keypoint2d>; COCO17_COUNT] {
    let skeleton = SmplSkeleton::mean_shape();
    let fk = skeleton.forward_kinematics(pose);
    let world = exo_keypoints_from_smpl(&fk.positions, fk.rotations[SmplJoint::Head.index()], 1.0);
    let camera = rgb_camera();
    let t_world_device = *t_world_device;
    let mut out = [None; COCO17_COUNT];
    for kp in ExoKeypoint::ALL {
        if let Some(pixel) = camera.project_world(world[kp.index()], &t_world_device)
            && camera.is_valid_pixel(pixel)
        {
            let score = 0.80 + 0.15 * ((kp.index() as f64 * 0.7 + 3.0 * t).sin() * 0.5 + 0.5) as f32;
            out[kp.coco17_index()] = Some(Keypoint2d { pixel: round2(pixel), score: round2s(score) });
        }
    }
    if let Some(nose) = out[0] {
        for (slot, dx, dy) in [(1, -6.0, -5.0), (2, 6.0, -5.0), (3, -14.0, 0.0), (4, 14.0, 0.0)] {
            out[slot] = Some(Keypoint2d { pixel: nose.pixel + Vec2::new(dx, dy), score: 0.55 });
        }
    }
    out
}

fn round2(p: Vec2) -> Vec2 {
    Vec2::new((p.x * 100.0).round() / 100.0, (p.y * 100.0).round() / 100.0)
}

fn round2s(s: f32) -> f32 {
    (s * 1000.0).round() / 1000.0
}

/// Observer `k`'s own body: standing under their glasses (arms down), facing the wearer's
/// chest.
pub fn observer_body_at(t: f64, k: usize) -> SmplPose {
    let glasses = observer_cpf_at(t, k).translation;
    let chest = SmplSkeleton::mean_shape().forward_kinematics(&body_pose_at(t)).positions[SmplJoint::Spine3.index()];
    let to = chest - glasses;
    let mut body = [Quat::IDENTITY; 21];
    body[SmplJoint::LeftShoulder.index() - 1] = Quat::from_rotation_z(-1.25);
    body[SmplJoint::RightShoulder.index() - 1] = Quat::from_rotation_z(1.25);
    let skeleton = SmplSkeleton::mean_shape();
    let pelvis = Vec3::new(glasses.x, glasses.y - 0.68, glasses.z);
    SmplPose {
        root_orientation: Quat::from_rotation_y(to.x.atan2(to.z)),
        body,
        translation: pelvis - skeleton.rest_joints()[0],
    }
}

/// A people file (`.egoexo` version 3's format) of `people(t)` at [`FRAME_HZ`].
pub fn people_jsonl(observer: &str, people: impl Fn(f64) -> Vec<[Option<Keypoint2d>; COCO17_COUNT]>) -> String {
    let times = sample_times(FRAME_HZ);
    let track = egoexo_session::capture::PeopleTrack {
        timestamps_ns: times.iter().map(|&t| START_NS + (t * 1e9).round() as i64).collect(),
        frames: times
            .iter()
            .map(|&t| people(t).into_iter().filter(|p| p.iter().any(Option::is_some)).collect())
            .collect(),
    };
    egoexo_session::keypoints::write_people_jsonl(observer, &track)
}

/// People files that make the Nymeria fixture a capture of two participants: the observer's
/// camera sees the wearer and a bystander standing by; the wearer's camera sees the observer
/// (when they face them).
pub fn nymeria_people_files() -> BTreeMap<String, Vec<u8>> {
    let bystander = |t: f64| {
        let skeleton = SmplSkeleton::mean_shape();
        let mut body = [Quat::IDENTITY; 21];
        body[SmplJoint::LeftShoulder.index() - 1] = Quat::from_rotation_z(-1.25);
        body[SmplJoint::RightShoulder.index() - 1] = Quat::from_rotation_z(1.25);
        let pose = SmplPose {
            root_orientation: Quat::from_rotation_y(2.5),
            body,
            translation: Vec3::new(-1.6, 0.97, 2.2) - skeleton.rest_joints()[0],
        };
        body_keypoints(&pose, &observer_cpf_at(t, 0), t)
    };
    let mut files = BTreeMap::new();
    files.insert(
        "recording_observer/people.jsonl".to_owned(),
        people_jsonl("observer", |t| vec![bystander(t), keypoints_at(t, 0)]).into_bytes(),
    );
    files.insert(
        "recording_head/people.jsonl".to_owned(),
        people_jsonl("wearer", |t| vec![body_keypoints(&observer_body_at(t, 0), &head_cpf_at(t), t)]).into_bytes(),
    );
    files
}

/// Truth: the wearer's motion at [`FRAME_HZ`] on the session clock.
pub fn truth_motion() -> SmplMotion {
    let frames = (DURATION_S * FRAME_HZ).round() as usize + 1;
    let poses = (0..frames).map(|i| body_pose_at(i as f64 / FRAME_HZ)).collect();
    SmplMotion::new(FRAME_HZ as f32, START_NS, SmplSkeleton::mean_shape(), None, poses).unwrap()
}

/// Sample times (seconds since the start) at `hz` covering the scene.
pub fn sample_times(hz: f64) -> Vec<f64> {
    let n = (DURATION_S * hz).round() as usize + 1;
    (0..n).map(|i| i as f64 / hz).collect()
}

/// Session-clock nanoseconds of scene time `t`, rounded to the microsecond (as MPS stores).
pub fn session_ns(t: f64) -> i64 {
    (START_NS as f64 / 1000.0 + (t * 1e6).round()) as i64 * 1000
}

/// A device's clock: `device = session + offset + drift · (session − START)`.
#[derive(Clone, Copy, Debug)]
pub struct DeviceClock {
    pub offset_ns: i64,
    pub drift_ppm: f64,
}

impl DeviceClock {
    pub const SHARED: DeviceClock = DeviceClock { offset_ns: 0, drift_ppm: 0.0 };

    pub fn device_ns(&self, session_ns: i64) -> i64 {
        session_ns + self.offset_ns + ((session_ns - START_NS) as f64 * self.drift_ppm * 1e-6).round() as i64
    }
}

/// `closed_loop_trajectory.csv` in MPS form for a device pose function (session conventions in,
/// Aria conventions out: Z-up world, device frame, µs).
pub fn mps_trajectory_csv(
    pose_at: impl Fn(f64) -> RigidTransform,
    cpf: Option<&RigidTransform>,
    clock: DeviceClock,
    graph_uid: &str,
) -> String {
    let mut out = String::from(
        "graph_uid,tracking_timestamp_us,utc_timestamp_ns,tx_world_device,ty_world_device,tz_world_device,qx_world_device,qy_world_device,qz_world_device,qw_world_device,device_linear_velocity_x_device,device_linear_velocity_y_device,device_linear_velocity_z_device,angular_velocity_x_device,angular_velocity_y_device,angular_velocity_z_device,gravity_x_world,gravity_y_world,gravity_z_world,quality_score,geo_available,tx_ecef_device,ty_ecef_device,tz_ecef_device,qx_ecef_device,qy_ecef_device,qz_ecef_device,qw_ecef_device\n",
    );
    let aria = |t: f64| aria_pose_from_session(&pose_at(t), cpf);
    let dt = 1.0 / TRAJECTORY_HZ;
    for t in sample_times(TRAJECTORY_HZ) {
        let pose = aria(t);
        let (before, after) = (aria(t - dt), aria(t + dt));
        let v_world = (after.translation - before.translation) / (2.0 * dt as f32);
        let v_device = pose.rotation.conjugate() * v_world;
        let dq = before.rotation.conjugate() * after.rotation;
        let w_device = axis_angle_from_quat(dq) / (2.0 * dt as f32);
        let q = pose.rotation;
        let p = pose.translation;
        let session = session_ns(t);
        let _ = writeln!(
            out,
            "{graph_uid},{},{},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},0.000000,0.000000,-9.810000,{:.6},0,,,,,,,",
            clock.device_ns(session) / 1000,
            session + UTC_OFFSET_NS,
            p.x,
            p.y,
            p.z,
            q.x,
            q.y,
            q.z,
            q.w,
            v_device.x,
            v_device.y,
            v_device.z,
            w_device.x,
            w_device.y,
            w_device.z,
            0.9 + 0.1 * (3.0 * t).cos().abs(),
        );
    }
    out
}

/// `online_calibration.jsonl`: one record per second with the SLAM and RGB cameras (RGB at
/// 1408 px, so `ImageSizes` is given; `legacy` writes the pre-June-2023 quoted form, which
/// has no image sizes — then the RGB parameters are scaled to the 2880 px full resolution).
pub fn online_calibration_jsonl(clock: DeviceClock, legacy: bool) -> String {
    let t_device_cpf = nominal_t_device_cpf(AriaFrameSize::Small);
    let t_device_rgb = t_device_cpf * rgb_t_cpf_camera();
    let mut rgb_params = RGB_PARAMS;
    if legacy {
        let s = 2880.0 / 1408.0;
        rgb_params[0] *= s;
        rgb_params[1] = (rgb_params[1] + 0.5) * s - 0.5;
        rgb_params[2] = (rgb_params[2] + 0.5) * s - 0.5;
    }
    let slam = |label: &str, x: f32| {
        json!({
            "Label": label,
            "SerialNumber": "0072510f1b0c0801",
            "Projection": {"Name": "FisheyeRadTanThinPrism", "Description": "see FisheyeRadTanThinPrism",
                "Params": [241.6, 316.8, 237.9, -0.0255, 0.0994, -0.0683, 0.0083, 0.0011, -0.0005, -0.00011, 0.00005, 0.00061, -0.00006, -0.00039, 0.00004]},
            "T_Device_Camera": se3_json(&RigidTransform::new(Quat::from_rotation_y(x * 0.9), Vec3::new(x * 0.14, 0.0, 0.0))),
            "TimeOffsetSec_Device_Camera": 0.0
        })
    };
    let cameras = json!([
        slam("camera-slam-left", 0.0),
        slam("camera-slam-right", -1.0),
        {
            "Label": "camera-rgb",
            "SerialNumber": "1WM093701M1276",
            "Projection": {"Name": "FisheyeRadTanThinPrism", "Description": "see FisheyeRadTanThinPrism", "Params": rgb_params},
            "T_Device_Camera": se3_json(&t_device_rgb),
            "TimeOffsetSec_Device_Camera": 0.0
        }
    ]);
    let imus = json!([{
        "Label": "imu-left",
        "Accelerometer": {"Bias": {"Name": "Constant", "Offset": [0.01, -0.02, 0.03]}, "Model": {"Name": "Linear", "RectificationMatrix": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]}, "TimeOffsetSec_Device_Accel": 0.0},
        "Gyroscope": {"Bias": {"Name": "Constant", "Offset": [0.001, 0.0, -0.001]}, "Model": {"Name": "Linear", "RectificationMatrix": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]}, "TimeOffsetSec_Device_Gyro": 0.0},
        "T_Device_Imu": se3_json(&RigidTransform::from_translation(Vec3::new(-0.005, 0.001, -0.006)))
    }]);
    let mut out = String::new();
    for s in [0.0, 1.0, 2.0] {
        let session = session_ns(s);
        let tracking_us = clock.device_ns(session) / 1000;
        let utc = session + UTC_OFFSET_NS;
        let record = if legacy {
            let quoted = |v: &serde_json::Value| v.to_string().replace('"', "'").replace("true", "True");
            json!({"tracking_timestamp_us": tracking_us.to_string(), "utc_timestamp_ns": utc.to_string(),
                   "ImuCalibrations": quoted(&imus), "CameraCalibrations": quoted(&cameras)})
        } else {
            json!({"tracking_timestamp_us": tracking_us, "utc_timestamp_ns": utc, "ImuCalibrations": imus,
                   "CameraCalibrations": cameras, "ImageSizes": [[640, 480], [640, 480], [1408, 1408]],
                   "ReadoutTimesSec": [[2, 0.016]]})
        };
        out.push_str(&record.to_string());
        out.push('\n');
    }
    out
}

/// Keypoints of observer `k` as JSON lines, at [`FRAME_HZ`] on the session clock.
pub fn keypoints_jsonl(id: &str, k: usize) -> String {
    let mut out = String::new();
    for t in sample_times(FRAME_HZ) {
        let kps: Vec<serde_json::Value> = keypoints_at(t, k)
            .iter()
            .map(|kp| kp.map_or(serde_json::Value::Null, |kp| json!([kp.pixel.x, kp.pixel.y, kp.score])))
            .collect();
        let line = json!({"observer": id, "timestamp_ns": START_NS + (t * 1e9).round() as i64, "keypoints": kps});
        out.push_str(&line.to_string());
        out.push('\n');
    }
    out
}

/// Keypoints of observer `k` in the COCO results form (`image_id` = frame index at 30 fps,
/// frame 0 at the observer trajectory's first sample = the scene start), with a second,
/// lower-scoring person in every tenth frame.
pub fn keypoints_coco(k: usize) -> String {
    let mut results = Vec::new();
    for (i, t) in sample_times(FRAME_HZ).into_iter().enumerate() {
        let flat = |shift: f32, scale: f32| -> Vec<f32> {
            keypoints_at(t, k)
                .iter()
                .flat_map(|kp| match kp {
                    Some(kp) => [kp.pixel.x + shift, kp.pixel.y, kp.score * scale],
                    None => [0.0, 0.0, 0.0],
                })
                .collect()
        };
        results.push(json!({"image_id": i, "category_id": 1, "keypoints": flat(0.0, 1.0), "score": 0.93}));
        if i % 10 == 0 {
            results.push(json!({"image_id": i, "category_id": 1, "keypoints": flat(250.0, 0.5), "score": 0.41}));
        }
    }
    serde_json::to_string(&results).unwrap()
}

/// The multi-device Aria MPS fixture: the wearer's glasses (legacy calibration at the folder
/// root), observer-1 (`mps/slam/`, JSON-lines keypoints), observer-2 (`slam/`, COCO keypoints)
/// and subject.json. All devices share the session clock.
pub fn aria_fixture() -> BTreeMap<String, Vec<u8>> {
    let cpf = nominal_t_device_cpf(AriaFrameSize::Small);
    let mut files = BTreeMap::new();
    let mut put = |path: &str, text: String| files.insert(path.to_owned(), text.into_bytes());
    let clock = DeviceClock::SHARED;
    put(
        "wearer/closed_loop_trajectory.csv",
        mps_trajectory_csv(head_cpf_at, Some(&cpf), clock, "6c4f3a52-2d2f-4d1b-a0e4-3f0e9c1b7d11"),
    );
    put("wearer/online_calibration.jsonl", online_calibration_jsonl(clock, true));
    put(
        "observers/observer-1/mps/slam/closed_loop_trajectory.csv",
        mps_trajectory_csv(|t| observer_cpf_at(t, 0), Some(&cpf), clock, "0d9b8e71-5a44-4c1e-9b1f-7f3e2a6c9d02"),
    );
    put("observers/observer-1/mps/slam/online_calibration.jsonl", online_calibration_jsonl(clock, false));
    put("observers/observer-1/keypoints.jsonl", keypoints_jsonl("observer-1", 0));
    put(
        "observers/observer-2/slam/closed_loop_trajectory.csv",
        mps_trajectory_csv(|t| observer_cpf_at(t, 1), Some(&cpf), clock, "a1e7c3d9-0b6f-4e8a-8c2d-5f4b3a2e1d03"),
    );
    put("observers/observer-2/slam/online_calibration.jsonl", online_calibration_jsonl(clock, false));
    put("observers/observer-2/keypoints.json", keypoints_coco(1));
    put("subject.json", "{\n  \"height_m\": 1.70\n}\n".into());
    files
}

/// Device clocks of the Nymeria fixture's recordings (each Aria device has its own).
pub const NYMERIA_CLOCKS: [(&str, DeviceClock); 4] = [
    ("recording_head", DeviceClock { offset_ns: -5_000_123_000, drift_ppm: 12.0 }),
    ("recording_lwrist", DeviceClock { offset_ns: 41_250_777_000, drift_ppm: -8.0 }),
    ("recording_rwrist", DeviceClock { offset_ns: 7_777_000_000, drift_ppm: 3.0 }),
    ("recording_observer", DeviceClock { offset_ns: 17_300_000_000, drift_ppm: -20.0 }),
];

/// `time_sync.csv`: device time → TimeCode (= the session clock), twice a second.
pub fn time_sync_csv(clock: DeviceClock) -> String {
    let mut out = String::from("device_time_ns,common_time_ns\n");
    // −1 s .. +3 s around the scene.
    for k in -2..=6 {
        let session = START_NS + k * 500_000_000;
        let _ = writeln!(out, "{},{}", clock.device_ns(session), session);
    }
    out
}

/// The Nymeria-shaped fixture: four recordings on their own device clocks with
/// `time_sync.csv` (→ TimeCode), and `body/xdata_smpl_neutral.npz` on the TimeCode clock.
pub fn nymeria_fixture() -> BTreeMap<String, Vec<u8>> {
    let cpf = nominal_t_device_cpf(AriaFrameSize::Small);
    let mut files = BTreeMap::new();
    for (recording, clock) in &NYMERIA_CLOCKS {
        let trajectory = match *recording {
            "recording_head" => mps_trajectory_csv(head_cpf_at, Some(&cpf), *clock, "nymeria-graph"),
            "recording_lwrist" => mps_trajectory_csv(|t| wrist_at(t, true), None, *clock, "nymeria-graph"),
            "recording_rwrist" => mps_trajectory_csv(|t| wrist_at(t, false), None, *clock, "nymeria-graph"),
            _ => mps_trajectory_csv(|t| observer_cpf_at(t, 0), Some(&cpf), *clock, "nymeria-graph"),
        };
        files.insert(format!("{recording}/mps/slam/closed_loop_trajectory.csv"), trajectory.into_bytes());
        // The head and left-wrist recordings use the pre-June-2023 calibration format.
        let legacy = matches!(*recording, "recording_head" | "recording_lwrist");
        files.insert(
            format!("{recording}/mps/slam/online_calibration.jsonl"),
            online_calibration_jsonl(*clock, legacy).into_bytes(),
        );
        files.insert(format!("{recording}/time_sync.csv"), time_sync_csv(*clock).into_bytes());
    }
    files.insert("body/xdata_smpl_neutral.npz".into(), nymeria_smpl_npz());
    files
}

/// `xdata_smpl_neutral.npz` of the truth motion in the Aria (Z-up) world, float64 like the
/// dataset, timestamps in µs (int64) on TimeCode.
pub fn nymeria_smpl_npz() -> Vec<u8> {
    let j0 = SmplSkeleton::mean_shape().rest_joints()[0];
    let times = sample_times(FRAME_HZ);
    let n = times.len() as u64;
    let (mut betas, mut body_pose, mut global_orient, mut transl, mut timestamps) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for &t in &times {
        let pose = aria_smpl_pose_from_session(&body_pose_at(t), j0);
        betas.extend([0.0f64; 10]);
        for q in pose.body {
            body_pose.extend(axis_angle_from_quat(q).to_array().map(f64::from));
        }
        body_pose.extend([0.0f64; 6]);
        global_orient.extend(axis_angle_from_quat(pose.root_orientation).to_array().map(f64::from));
        transl.extend(pose.translation.to_array().map(f64::from));
        timestamps.push(session_ns(t) / 1000);
    }
    let mut npz = NpzWriter::new();
    npz.add("betas", &[n, 10], &betas).unwrap();
    npz.add("body_pose", &[n, 69], &body_pose).unwrap();
    npz.add("global_orient", &[n, 3], &global_orient).unwrap();
    npz.add("transl", &[n, 3], &transl).unwrap();
    npz.add("timestamps", &[n], &timestamps).unwrap();
    npz.finish().unwrap()
}

/// The fixtures directory of this crate.
pub fn fixtures_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

/// In-memory tree of a generated fixture.
pub fn tree(name: &str, files: BTreeMap<String, Vec<u8>>) -> egoexo_session::FileTree {
    egoexo_session::FileTree::from_files(name, files, egoexo_session::Limits::default()).unwrap()
}

/// The `.egoexo` files of the Aria fixture with the truth motion as ground truth and occlusion
/// labels for observer-1 (the session `docs/session-format.md`'s example describes).
pub fn egoexo_fixture_files() -> BTreeMap<String, Vec<u8>> {
    use egoexo_session::model::{GroundTruth, ObserverOcclusion};
    let options = egoexo_session::ImportOptions::default();
    let mut session = egoexo_session::import_session(&tree("aria_mps", aria_fixture()), &options).unwrap().session;
    let motion = truth_motion();
    let n = motion.len();
    session.ground_truth = Some(GroundTruth {
        motion,
        occlusion: vec![ObserverOcclusion { observer_id: "observer-1".into(), occluded: vec![0b101; n] }],
    });
    egoexo_session::format::write_egoexo_files(&session).unwrap()
}
