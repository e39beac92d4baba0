//! Finding corrupt frames and resampling to the library rate.
//!
//! A few CMU trials contain frames where a limb jumps tens of centimetres between two
//! frames (e.g. the first frames of 16_15, 16_23 and 16_28, or a leg flipping during the
//! cartwheels of subject 05). No body part moves that fast: a step between consecutive
//! frames faster than a speed limit splits the trial there, and only the clean stretches
//! that are long enough are kept. Nothing is interpolated across a glitch.

use std::ops::Range;

use egoexo_core::glam::Vec3;

/// Joint speed above which a frame-to-frame step is a glitch, metres per second. Real kicks
/// and punches in CMU peak around 15 m/s at the foot or hand; glitches are 30–100 m/s.
pub const DEFAULT_MAX_JOINT_SPEED_MPS: f32 = 20.0;

/// Largest per-joint step between frame `i` and `i + 1`, metres, for each `i`
/// (`positions.len() − 1` values; infinity when a position is not finite).
pub fn frame_steps<const J: usize>(positions: &[[Vec3; J]]) -> Vec<f32> {
    positions
        .windows(2)
        .map(|w| {
            (0..J).fold(0.0f32, |m, j| {
                let d = w[0][j].distance(w[1][j]);
                if d.is_finite() { m.max(d) } else { f32::INFINITY }
            })
        })
        .collect()
}

/// The stretches of frames `[start, end)` with no step above `max_speed_mps / fps`, at
/// least `min_frames` long, in order. A frame with a non-finite position belongs to no
/// stretch.
pub fn clean_segments<const J: usize>(
    positions: &[[Vec3; J]],
    fps: f32,
    max_speed_mps: f32,
    min_frames: usize,
) -> Vec<Range<usize>> {
    let limit = max_speed_mps / fps;
    let finite: Vec<bool> = positions.iter().map(|p| p.iter().all(|v| v.is_finite())).collect();
    let steps = frame_steps(positions);
    let mut segments = Vec::new();
    let mut start: Option<usize> = None;
    for i in 0..positions.len() {
        if !finite[i] {
            if let Some(s) = start.take() {
                segments.push(s..i);
            }
            continue;
        }
        let s = *start.get_or_insert(i);
        // `frame_steps` is infinite for non-finite positions, so this also catches those.
        let breaks_after = i + 1 < positions.len() && steps[i] > limit;
        if breaks_after {
            segments.push(s..i + 1);
            start = None;
        }
    }
    if let Some(s) = start {
        segments.push(s..positions.len());
    }
    segments.retain(|r| r.len() >= min_frames.max(1));
    segments
}

/// Where each output frame falls between source frames when `frames` source frames at
/// `source_fps` are resampled to `target_fps`, both clips starting at time 0: pairs
/// `(i, alpha)` meaning `(1 − alpha)·frame[i] + alpha·frame[i + 1]`. The output covers the
/// source's duration `(frames − 1) / source_fps` and never extrapolates.
pub fn resample_plan(frames: usize, source_fps: f32, target_fps: f32) -> Vec<(usize, f32)> {
    if frames == 0 || !(source_fps > 0.0 && target_fps > 0.0) {
        return Vec::new();
    }
    let ratio = f64::from(source_fps) / f64::from(target_fps);
    let last = (frames - 1) as f64;
    // A small tolerance keeps exact multiples (120 → 30 Hz) from losing their last frame.
    let count = (last / ratio + 1e-9).floor() as usize + 1;
    (0..count)
        .map(|k| {
            let s = (k as f64 * ratio).min(last);
            let i = s.floor() as usize;
            let alpha = (s - i as f64) as f32;
            if i + 1 >= frames || alpha < 1e-6 { (i, 0.0) } else { (i, alpha) }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn track(xs: &[f32]) -> Vec<[Vec3; 1]> {
        xs.iter().map(|&x| [Vec3::new(x, 0.0, 0.0)]).collect()
    }

    #[test]
    fn a_jump_at_the_start_is_trimmed() {
        let mut xs = vec![0.8, 0.8];
        xs.extend((0..200).map(|i| i as f32 * 0.01));
        let segments = clean_segments(&track(&xs), 120.0, 20.0, 10);
        assert_eq!(segments, vec![2..202]);
    }

    #[test]
    fn a_glitch_in_the_middle_splits_and_short_pieces_are_dropped() {
        let mut xs: Vec<f32> = (0..100).map(|i| i as f32 * 0.001).collect();
        xs.extend([5.0, 5.0, 5.0]);
        xs.extend((0..50).map(|i| 0.1 + i as f32 * 0.001));
        let segments = clean_segments(&track(&xs), 120.0, 20.0, 20);
        assert_eq!(segments, vec![0..100, 103..153]);
        let mut with_nan = xs.clone();
        with_nan[10] = f32::NAN;
        assert_eq!(clean_segments(&track(&with_nan), 120.0, 20.0, 20), vec![11..100, 103..153]);
    }

    #[test]
    fn resampling_keeps_the_duration() {
        // 121 frames at 120 Hz = 1 s → 31 frames at 30 Hz, exactly every 4th.
        let plan = resample_plan(121, 120.0, 30.0);
        assert_eq!(plan.len(), 31);
        assert!(plan.iter().enumerate().all(|(k, &(i, a))| i == 4 * k && a == 0.0));
        // 61 frames at 60 Hz = 1 s → 31 frames.
        assert_eq!(resample_plan(61, 60.0, 30.0).len(), 31);
        // 100 Hz → 30 Hz: fractional positions.
        let plan = resample_plan(101, 100.0, 30.0);
        assert_eq!(plan.len(), 31);
        assert_eq!(plan[1].0, 3);
        assert!((plan[1].1 - 1.0 / 3.0).abs() < 1e-5);
        assert!(resample_plan(0, 120.0, 30.0).is_empty());
        assert_eq!(resample_plan(1, 120.0, 30.0), vec![(0, 0.0)]);
    }
}
