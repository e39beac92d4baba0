//! JSON-lines and JSON readers: `online_calibration.jsonl` (current and quoted legacy forms),
//! keypoint JSON lines, COCO keypoint JSON.
#![no_main]

use egoexo_session::aria::calibration::{RGB_LABEL, middle_record_with, read_online_calibration};
use egoexo_session::keypoints::{CocoTiming, read_coco_keypoints, read_keypoints, read_keypoints_jsonl};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(records) = read_online_calibration("c.jsonl", text) {
        if let Ok((record, _)) = middle_record_with("c.jsonl", &records, RGB_LABEL) {
            let _ = record.t_device_cpf();
        }
    }
    let _ = read_keypoints_jsonl("k.jsonl", text, "observer-1");
    let _ = read_coco_keypoints("k.json", text, CocoTiming::default(), 0);
    let _ = read_coco_keypoints("k.json", text, CocoTiming { fps: 1e-3, start_ns: Some(i64::MAX - 5) }, 0);
    let _ = read_keypoints("k.json", text, "observer-1", CocoTiming::default(), i64::MIN);
});
