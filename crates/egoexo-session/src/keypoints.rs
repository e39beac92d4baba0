//! Exo keypoint files: the project's JSON-lines form (read and written) and COCO-style
//! keypoint JSON as written by common 2D pose tools (read).
//!
//! # JSON lines (`keypoints.jsonl`)
//! One observer per file, one frame per line, strictly increasing timestamps:
//! ```json
//! {"observer": "observer-1", "timestamp_ns": 1700000000033333333, "keypoints": [[812.5, 403.0, 0.93], null, …]}
//! ```
//! `keypoints` holds the 17 COCO keypoints in COCO order, each `[x, y, score]` (pixels in the
//! observer's RGB image at its calibration's resolution, centre of the top-left pixel at
//! (0, 0); score in `[0, 1]`) or `null` when not detected. `observer` is optional; when present
//! it must equal the observer the file belongs to. `timestamp_ns` is on the session clock.
//!
//! # COCO JSON (`keypoints.json`)
//! Either the *results* form written by detectors (mmpose, detectron2, …) — an array of
//! `{"image_id", "keypoints": [x1, y1, v1, …, x17, y17, v17], "score"}` where `v` is the
//! keypoint's score — or the *dataset* form `{"images": [...], "annotations": [...]}` where
//! `v` is COCO visibility (0 = not labelled → not detected, 1 = labelled but occluded →
//! score 0.5, 2 = visible → score 1). Scores above 1 (some detectors) are clamped to 1; a
//! score ≤ 0 means not detected.
//!
//! COCO files carry frames, not times. Frame index: the integer `image_id` (or, when it is a
//! string such as `"frame_000123.jpg"`, its last run of digits); in the dataset form an image's
//! own `timestamp_ns` wins, then its `frame_index`, then its `id`. Timestamp =
//! `start_ns + round(frame_index · 10⁹ / fps)` with [`CocoTiming`] (30 fps; `start_ns`
//! defaults to the observer trajectory's first timestamp). When a frame has several persons
//! the highest-scoring one (annotation `score`, else mean keypoint score) is kept, and a
//! warning says how often that happened.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use egoexo_core::exo_keypoints::{COCO17_COUNT, Keypoint2d};
use egoexo_core::glam::Vec2;
use serde_json::Value;

use crate::capture::PeopleTrack;
use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::json::JsonCtx;
use crate::model::KeypointTrack;

/// How COCO frames get session timestamps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CocoTiming {
    /// Frames per second of the image sequence.
    pub fps: f64,
    /// Session-clock time of frame 0, nanoseconds; `None` = the observer trajectory's start.
    pub start_ns: Option<i64>,
}

impl Default for CocoTiming {
    fn default() -> Self {
        Self { fps: 30.0, start_ns: None }
    }
}

/// Largest accepted |pixel coordinate|.
pub const MAX_ABS_PIXEL: f32 = 1.0e6;

/// Which keypoint file format a file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeypointFormat {
    JsonLines,
    Coco,
}

impl KeypointFormat {
    /// `.jsonl` → JSON lines; otherwise by content: a leading `[` or a `{` document with
    /// `annotations` is COCO, anything else JSON lines.
    pub fn detect(file: &str, text: &str) -> Self {
        if file.ends_with(".jsonl") {
            return Self::JsonLines;
        }
        let trimmed = text.trim_start();
        if trimmed.starts_with('[') {
            return Self::Coco;
        }
        let first_line = trimmed.lines().next().unwrap_or_default();
        let is_one_line_record =
            serde_json::from_str::<Value>(first_line).is_ok_and(|v| v.get("timestamp_ns").is_some());
        if is_one_line_record { Self::JsonLines } else { Self::Coco }
    }
}

/// Reads a keypoint file of either format for observer `observer_id`.
/// `default_start_ns` is used for COCO files whose [`CocoTiming::start_ns`] is `None`.
pub fn read_keypoints(
    file: &str,
    text: &str,
    observer_id: &str,
    timing: CocoTiming,
    default_start_ns: i64,
) -> Result<(KeypointTrack, Vec<ImportWarning>), ImportError> {
    match KeypointFormat::detect(file, text) {
        KeypointFormat::JsonLines => Ok((read_keypoints_jsonl(file, text, observer_id)?, Vec::new())),
        KeypointFormat::Coco => read_coco_keypoints(file, text, timing, default_start_ns),
    }
}

/// Walks a JSON-lines file of one camera's frames (keypoints or people): every non-blank line
/// parsed, its optional `observer` checked against `observer_id`, its `timestamp_ns` checked
/// to increase strictly; `record(ctx, line, timestamp)` reads the rest. A file without a
/// record is an error naming `what` it should hold.
fn read_timed_lines(
    file: &str,
    text: &str,
    observer_id: &str,
    what: &str,
    mut record: impl FnMut(&JsonCtx<'_>, &Value, i64) -> Result<(), ImportError>,
) -> Result<(), ImportError> {
    let mut previous = None;
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let ctx = JsonCtx::line(file, i as u64 + 1);
        let doc = ctx.parse(line)?;
        if let Some(id) = ctx.optional(&doc, "", "observer")? {
            let id = ctx.str(id, "observer")?;
            if id != observer_id {
                return Err(ctx.error(
                    "observer",
                    ImportErrorKind::ObserverMismatch { expected: observer_id.into(), got: id.into() },
                ));
            }
        }
        let t = ctx.i64(ctx.field(&doc, "", "timestamp_ns")?, "timestamp_ns")?;
        if let Some(previous) = previous {
            if t == previous {
                return Err(ctx.error("timestamp_ns", ImportErrorKind::DuplicateTimestamp(t)));
            }
            if t < previous {
                return Err(ctx.error("timestamp_ns", ImportErrorKind::NonMonotonicTimestamp { previous, got: t }));
            }
        }
        previous = Some(t);
        record(&ctx, &doc, t)?;
    }
    if previous.is_none() {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: format!("at least one {what} record (one JSON object per line)") },
        ));
    }
    Ok(())
}

/// Reads the JSON-lines form (see the module docs).
pub fn read_keypoints_jsonl(file: &str, text: &str, observer_id: &str) -> Result<KeypointTrack, ImportError> {
    let mut track = KeypointTrack::default();
    read_timed_lines(file, text, observer_id, "keypoint", |ctx, doc, t| {
        let frame = coco17_frame(ctx, ctx.field(doc, "", "keypoints")?, "keypoints")?;
        track.timestamps_ns.push(t);
        track.frames.push(frame);
        Ok(())
    })?;
    Ok(track)
}

/// One person's 17 keypoints, `[[x, y, score] | null; 17]`, at field `path`.
fn coco17_frame(
    ctx: &JsonCtx<'_>,
    value: &Value,
    path: &str,
) -> Result<[Option<Keypoint2d>; COCO17_COUNT], ImportError> {
    let kps = ctx.array(value, path)?;
    if kps.len() != COCO17_COUNT {
        return Err(ctx.error(path, ImportErrorKind::KeypointCount { got: kps.len() }));
    }
    let mut frame = [None; COCO17_COUNT];
    for (k, (slot, v)) in frame.iter_mut().zip(kps).enumerate() {
        let path = format!("{path}[{k}]");
        if v.is_null() {
            continue;
        }
        let [x, y, score] = ctx.f32_array::<3>(v, &path)?;
        check_pixel(ctx, &path, x, y, v)?;
        if !(0.0..=1.0).contains(&score) {
            return Err(ctx.invalid(&format!("{path}[2]"), "a score in [0, 1]", &v[2]));
        }
        *slot = Some(Keypoint2d { pixel: Vec2::new(x, y), score });
    }
    Ok(frame)
}

/// Most people one frame of a people file may list.
pub const MAX_PEOPLE_PER_FRAME: usize = 64;

/// Reads a people file (JSON lines, one frame per line, strictly increasing timestamps) of
/// the camera of participant `observer_id`: every person its detector found, without identity:
/// ```json
/// {"observer": "participant-2", "timestamp_ns": 1700000000033333333, "people": [[[812.5, 403.0, 0.93], null, …], …]}
/// ```
/// Each person is 17 COCO keypoints as in `keypoints.jsonl`; `people` may be empty (nobody
/// seen) and holds at most [`MAX_PEOPLE_PER_FRAME`].
pub fn read_people_jsonl(file: &str, text: &str, observer_id: &str) -> Result<PeopleTrack, ImportError> {
    let mut track = PeopleTrack::default();
    read_timed_lines(file, text, observer_id, "people", |ctx, doc, t| {
        let people_value = ctx.field(doc, "", "people")?;
        let people = ctx.array(people_value, "people")?;
        if people.len() > MAX_PEOPLE_PER_FRAME {
            return Err(ctx.invalid("people", format!("at most {MAX_PEOPLE_PER_FRAME} people"), people_value));
        }
        let frame = people
            .iter()
            .enumerate()
            .map(|(p, person)| coco17_frame(ctx, person, &format!("people[{p}]")))
            .collect::<Result<Vec<_>, _>>()?;
        track.timestamps_ns.push(t);
        track.frames.push(frame);
        Ok(())
    })?;
    Ok(track)
}

/// Writes the people of participant `observer_id`'s camera as JSON lines
/// ([`read_people_jsonl`]'s format).
pub fn write_people_jsonl(observer_id: &str, track: &PeopleTrack) -> String {
    let mut out = String::with_capacity(track.frames.len() * 800);
    let id = serde_json::to_string(observer_id).unwrap_or_else(|_| "\"\"".into());
    for (t, people) in track.timestamps_ns.iter().zip(&track.frames) {
        let _ = write!(out, "{{\"observer\":{id},\"timestamp_ns\":{t},\"people\":[");
        for (p, person) in people.iter().enumerate() {
            if p > 0 {
                out.push(',');
            }
            write_coco17(&mut out, person);
        }
        out.push_str("]}\n");
    }
    out
}

/// `[[x, y, score] | null; 17]`.
fn write_coco17(out: &mut String, frame: &[Option<Keypoint2d>; COCO17_COUNT]) {
    out.push('[');
    for (k, kp) in frame.iter().enumerate() {
        if k > 0 {
            out.push(',');
        }
        match kp {
            Some(kp) => {
                let _ = write!(out, "[{},{},{}]", json_f32(kp.pixel.x), json_f32(kp.pixel.y), json_f32(kp.score));
            }
            None => out.push_str("null"),
        }
    }
    out.push(']');
}

fn check_pixel(ctx: &JsonCtx<'_>, path: &str, x: f32, y: f32, v: &Value) -> Result<(), ImportError> {
    if x.abs() > MAX_ABS_PIXEL || y.abs() > MAX_ABS_PIXEL {
        return Err(ctx.invalid(path, format!("pixel coordinates within ±{MAX_ABS_PIXEL}"), v));
    }
    Ok(())
}

/// Writes the JSON-lines form.
pub fn write_keypoints_jsonl(observer_id: &str, track: &KeypointTrack) -> String {
    let mut out = String::with_capacity(track.frames.len() * 400);
    let id = serde_json::to_string(observer_id).unwrap_or_else(|_| "\"\"".into());
    for (t, frame) in track.timestamps_ns.iter().zip(&track.frames) {
        let _ = write!(out, "{{\"observer\":{id},\"timestamp_ns\":{t},\"keypoints\":");
        write_coco17(&mut out, frame);
        out.push_str("}\n");
    }
    out
}

/// Shortest round-trip text of a finite f32 (non-finite values, which validation rejects
/// before writing, become `null`).
fn json_f32(x: f32) -> String {
    if x.is_finite() { serde_json::to_string(&x).unwrap_or_else(|_| "null".into()) } else { "null".into() }
}

/// Reads COCO keypoint JSON (results or dataset form; see the module docs).
pub fn read_coco_keypoints(
    file: &str,
    text: &str,
    timing: CocoTiming,
    default_start_ns: i64,
) -> Result<(KeypointTrack, Vec<ImportWarning>), ImportError> {
    let ctx = JsonCtx::file(file);
    if !(timing.fps.is_finite() && timing.fps > 0.0 && timing.fps <= 10_000.0) {
        return Err(ImportError::invalid(
            file,
            Location::File,
            "a keypoint frame rate in (0, 10000] fps",
            timing.fps.to_string(),
        ));
    }
    let start_ns = timing.start_ns.unwrap_or(default_start_ns);
    if text.trim().is_empty() {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty {
                expected: "COCO keypoint JSON (an array of results or {images, annotations})".into(),
            },
        ));
    }
    let doc = ctx.parse(text)?;
    // (annotations, where to find each one's frame time)
    let (annotations, path, images): (&[Value], &str, Option<BTreeMap<String, FrameTime>>) = match &doc {
        Value::Array(items) => (items.as_slice(), "", None),
        Value::Object(_) => {
            let anns = ctx.array(ctx.field(&doc, "", "annotations")?, "annotations")?;
            let images = ctx.array(ctx.field(&doc, "", "images")?, "images")?;
            let mut by_id = BTreeMap::new();
            for (i, image) in images.iter().enumerate() {
                let path = format!("images[{i}]");
                let id = ctx.field(image, &path, "id")?;
                let key = id_key(&ctx, id, &format!("{path}.id"))?;
                let time = if let Some(t) = ctx.optional(image, &path, "timestamp_ns")? {
                    FrameTime::Timestamp(ctx.i64(t, &format!("{path}.timestamp_ns"))?)
                } else if let Some(f) = ctx.optional(image, &path, "frame_index")? {
                    FrameTime::Frame(ctx.u64(f, &format!("{path}.frame_index"))?)
                } else {
                    FrameTime::Frame(frame_from_id(&ctx, id, &format!("{path}.id"))?)
                };
                if by_id.insert(key, time).is_some() {
                    return Err(ctx.invalid(&format!("{path}.id"), "unique image ids", id));
                }
            }
            (anns, "annotations", Some(by_id))
        }
        other => return Err(ctx.invalid("", "a COCO results array or a {images, annotations} object", other)),
    };
    let dataset_form = images.is_some();

    // timestamp → (score, keypoints)
    let mut frames: BTreeMap<i64, (f32, [Option<Keypoint2d>; COCO17_COUNT])> = BTreeMap::new();
    let mut crowded_frames = 0usize;
    for (i, ann) in annotations.iter().enumerate() {
        let p = if path.is_empty() { format!("[{i}]") } else { format!("{path}[{i}]") };
        if let Some(cat) = ctx.optional(ann, &p, "category_id")?
            && cat.as_u64() != Some(1)
        {
            continue; // not a person
        }
        let image_id = ctx.field(ann, &p, "image_id")?;
        let time = match &images {
            Some(by_id) => *by_id
                .get(&id_key(&ctx, image_id, &format!("{p}.image_id"))?)
                .ok_or_else(|| ctx.invalid(&format!("{p}.image_id"), "the id of an entry in `images`", image_id))?,
            None => FrameTime::Frame(frame_from_id(&ctx, image_id, &format!("{p}.image_id"))?),
        };
        let t = match time {
            FrameTime::Timestamp(t) => t,
            FrameTime::Frame(f) => frame_timestamp(f, timing.fps, start_ns).ok_or_else(|| {
                ctx.invalid(&format!("{p}.image_id"), "a frame index whose timestamp fits in i64 nanoseconds", image_id)
            })?,
        };
        let kp_path = format!("{p}.keypoints");
        let kps_value = ctx.field(ann, &p, "keypoints")?;
        let kps = ctx.array(kps_value, &kp_path)?;
        if kps.len() != 3 * COCO17_COUNT {
            return Err(ctx.error(&kp_path, ImportErrorKind::KeypointCount { got: kps.len() / 3 }));
        }
        let mut frame = [None; COCO17_COUNT];
        let mut score_sum = 0.0f32;
        for (k, slot) in frame.iter_mut().enumerate() {
            let kpath = format!("{kp_path}[{}]", 3 * k);
            let x = ctx.f32(&kps[3 * k], &kpath)?;
            let y = ctx.f32(&kps[3 * k + 1], &format!("{kp_path}[{}]", 3 * k + 1))?;
            let v_path = format!("{kp_path}[{}]", 3 * k + 2);
            let v = ctx.f32(&kps[3 * k + 2], &v_path)?;
            check_pixel(&ctx, &kpath, x, y, &kps[3 * k])?;
            let score = if dataset_form {
                match v {
                    0.0 => None,
                    1.0 => Some(0.5),
                    2.0 => Some(1.0),
                    _ => return Err(ctx.invalid(&v_path, "a COCO visibility of 0, 1 or 2", &kps[3 * k + 2])),
                }
            } else if v <= 0.0 {
                None
            } else {
                Some(v.min(1.0))
            };
            if let Some(score) = score {
                score_sum += score;
                *slot = Some(Keypoint2d { pixel: Vec2::new(x, y), score });
            }
        }
        let person_score = match ctx.optional(ann, &p, "score")? {
            Some(s) => ctx.f32(s, &format!("{p}.score"))?,
            None => score_sum / COCO17_COUNT as f32,
        };
        match frames.get_mut(&t) {
            Some(existing) => {
                crowded_frames += 1;
                if person_score > existing.0 {
                    *existing = (person_score, frame);
                }
            }
            None => {
                frames.insert(t, (person_score, frame));
            }
        }
    }
    if frames.is_empty() {
        return Err(ImportError::new(
            file,
            Location::File,
            ImportErrorKind::Empty { expected: "at least one person keypoint annotation".into() },
        ));
    }
    let mut warnings = Vec::new();
    if crowded_frames > 0 {
        warnings.push(ImportWarning {
            file: file.into(),
            message: format!(
                "{crowded_frames} extra person detection(s) on frames that already had one; kept the highest-scoring person per frame"
            ),
        });
    }
    let mut track = KeypointTrack::default();
    for (t, (_, frame)) in frames {
        track.timestamps_ns.push(t);
        track.frames.push(frame);
    }
    Ok((track, warnings))
}

#[derive(Clone, Copy, Debug)]
enum FrameTime {
    Timestamp(i64),
    Frame(u64),
}

fn id_key(ctx: &JsonCtx<'_>, id: &Value, path: &str) -> Result<String, ImportError> {
    match id {
        Value::Number(n) => Ok(n.to_string()),
        Value::String(s) => Ok(s.clone()),
        other => Err(ctx.invalid(path, "an image id (integer or string)", other)),
    }
}

/// The frame index of an image id: the integer itself, or a string's last run of digits.
fn frame_from_id(ctx: &JsonCtx<'_>, id: &Value, path: &str) -> Result<u64, ImportError> {
    match id {
        Value::Number(n) => n.as_u64().ok_or_else(|| ctx.invalid(path, "a non-negative integer frame index", id)),
        Value::String(s) => {
            let digits: String = {
                let end = s.rfind(|c: char| c.is_ascii_digit()).map(|i| i + 1);
                match end {
                    Some(end) => {
                        let start = s[..end].rfind(|c: char| !c.is_ascii_digit()).map_or(0, |i| i + 1);
                        s[start..end].to_owned()
                    }
                    None => String::new(),
                }
            };
            digits
                .parse()
                .map_err(|_| ctx.invalid(path, "an image id with a frame number (e.g. `frame_000123.jpg`)", id))
        }
        other => Err(ctx.invalid(path, "an image id (integer or string)", other)),
    }
}

fn frame_timestamp(frame: u64, fps: f64, start_ns: i64) -> Option<i64> {
    let offset = (frame as f64 * 1e9 / fps).round();
    if !(offset.is_finite() && offset < 9.0e18) {
        return None;
    }
    start_ns.checked_add(offset as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame_line(observer: &str, t: i64) -> String {
        let mut kps: Vec<Value> = (0..17).map(|k| serde_json::json!([100.0 + k as f64, 200.5, 0.9])).collect();
        kps[3] = Value::Null;
        serde_json::json!({"observer": observer, "timestamp_ns": t, "keypoints": kps}).to_string()
    }

    #[test]
    fn jsonl_round_trip() {
        let text = format!("{}\n\n{}\n", frame_line("o1", 10), frame_line("o1", 43));
        let track = read_keypoints_jsonl("k.jsonl", &text, "o1").unwrap();
        assert_eq!(track.timestamps_ns, vec![10, 43]);
        assert_eq!(track.frames[0][3], None);
        assert_eq!(track.frames[1][16].unwrap().pixel, Vec2::new(116.0, 200.5));
        let written = write_keypoints_jsonl("o1", &track);
        assert_eq!(read_keypoints_jsonl("k.jsonl", &written, "o1").unwrap(), track);
    }

    #[test]
    fn coco_results_form_picks_best_person_and_times_frames() {
        let kp = |s: f64| -> Vec<f64> { (0..17).flat_map(|k| [10.0 * k as f64, 5.0, s]).collect() };
        let doc = serde_json::json!([
            {"image_id": 0, "category_id": 1, "keypoints": kp(0.8), "score": 0.7},
            {"image_id": 0, "category_id": 1, "keypoints": kp(0.3), "score": 0.9},
            {"image_id": "frame_000002.jpg", "category_id": 1, "keypoints": kp(1.2), "score": 0.5},
        ]);
        let (track, warnings) =
            read_coco_keypoints("k.json", &doc.to_string(), CocoTiming { fps: 10.0, start_ns: Some(1000) }, 0).unwrap();
        assert_eq!(track.timestamps_ns, vec![1000, 1000 + 200_000_000]);
        assert_eq!(track.frames[0][0].unwrap().score, 0.3, "the person with score 0.9 wins");
        assert_eq!(track.frames[1][0].unwrap().score, 1.0, "clamped");
        assert_eq!(warnings.len(), 1);
    }

    #[test]
    fn coco_dataset_form_uses_visibility_and_image_times() {
        let mut kps: Vec<f64> = (0..17).flat_map(|k| [k as f64, 1.0, 2.0]).collect();
        kps[2] = 0.0;
        kps[5] = 1.0;
        let doc = serde_json::json!({
            "images": [{"id": 7, "file_name": "a.jpg", "timestamp_ns": 555}, {"id": 8, "frame_index": 3}],
            "annotations": [{"image_id": 7, "keypoints": kps}, {"image_id": 8, "keypoints": kps}],
            "categories": [{"id": 1, "name": "person"}]
        });
        let (track, _) = read_coco_keypoints("k.json", &doc.to_string(), CocoTiming::default(), 1_000_000_000).unwrap();
        assert_eq!(track.timestamps_ns, vec![555, 1_100_000_000]);
        assert_eq!(track.frames[0][0], None);
        assert_eq!(track.frames[0][1].unwrap().score, 0.5);
        assert_eq!(track.frames[0][2].unwrap().score, 1.0);
    }
}
