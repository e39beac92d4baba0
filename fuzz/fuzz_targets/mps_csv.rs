//! Aria MPS CSV readers: `closed_loop_trajectory.csv` (both clocks, both world conventions)
//! and `time_sync.csv`.
#![no_main]

use egoexo_session::aria::time_sync::read_time_sync;
use egoexo_session::aria::trajectory::{Clock, WorldUp, read_closed_loop_trajectory};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = read_closed_loop_trajectory("f.csv", data, Clock::Device, WorldUp::Z);
    let _ = read_closed_loop_trajectory("f.csv", data, Clock::Utc, WorldUp::Y);
    if let Ok(sync) = read_time_sync("t.csv", data) {
        for t in [i64::MIN, -1, 0, 1, 1_000_000_000, i64::MAX] {
            let _ = sync.map(t);
        }
    }
});
