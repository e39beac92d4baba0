//! Aria MPS CSV readers: `closed_loop_trajectory.csv` (both clocks; any gravity), hand
//! tracking (`wrist_and_palm_poses.csv` v1/v2, `hand_tracking_results.csv`, and the wrist
//! frames built from them), semidense points (plain and gzip) and `time_sync.csv`.
#![no_main]

use egoexo_core::glam::Vec3;
use egoexo_core::rigid::RigidTransform;
use egoexo_session::aria::hand_tracking::{Side, read_hand_tracking, t_device_wrist};
use egoexo_session::aria::semidense::read_semidense_heights;
use egoexo_session::aria::t_session_world_from_gravity;
use egoexo_session::aria::time_sync::read_time_sync;
use egoexo_session::aria::trajectory::{Clock, read_closed_loop_trajectory};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for clock in [Clock::Device, Clock::Utc] {
        if let Ok(t) = read_closed_loop_trajectory("f.csv", data, clock, &mut |_| {}) {
            let _ = t_session_world_from_gravity(t.gravity_world);
        }
    }
    for name in ["hand_tracking/wrist_and_palm_poses.csv", "hand_tracking/hand_tracking_results.csv"] {
        if let Ok(hands) = read_hand_tracking(name, data) {
            for side in [Side::Left, Side::Right] {
                for o in &hands.hand(side).observations {
                    let _ = t_device_wrist(side, o, Vec3::NEG_Y);
                }
            }
        }
    }
    for name in ["global_points.csv", "global_points.csv.gz"] {
        if let Ok(points) = read_semidense_heights(name, data, &RigidTransform::IDENTITY, &mut |_| {}) {
            let _ = points.heights.floor_between(-2.0, 2.0);
        }
    }
    if let Ok(sync) = read_time_sync("t.csv", data) {
        for t in [i64::MIN, -1, 0, 1, 1_000_000_000, i64::MAX] {
            let _ = sync.map(t);
        }
    }
});
