//! Cutting a timeline into the networks' fixed-length windows, and blending overlapping
//! window outputs back into one sequence.
//!
//! A *span* is a run of frames where the wearer's tracking is valid; windows never cross a
//! span boundary. A span shorter than a window is padded at the end by repeating its last
//! frame (the padded outputs are dropped). Overlapping windows are cross-faded with weights
//! that ramp linearly over the overlap.

use std::ops::Range;

/// The networks' window length (frames), the paper's T.
pub const WINDOW: usize = 96;

/// One window: which timeline frames it covers and how many padded frames follow them.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct WindowPlan {
    /// Timeline frames covered (`len() ≤ WINDOW`).
    pub frames: Range<usize>,
    /// The span the window lies in.
    pub span: Range<usize>,
}

impl WindowPlan {
    /// Number of real (not padded) frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// No real frames (never produced by the planners).
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
}

/// Runs of `true` in `valid`.
pub fn valid_spans(valid: &[bool]) -> Vec<Range<usize>> {
    let mut spans = Vec::new();
    let mut start = None;
    for (i, &v) in valid.iter().enumerate() {
        match (v, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                spans.push(s..i);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        spans.push(s..valid.len());
    }
    spans
}

/// Windows of [`WINDOW`] frames every `stride` frames over each span, the last one aligned to
/// the span's end so every frame is covered; `stride = WINDOW` gives the paper's
/// non-overlapping segments (then the last segment may be shorter and is padded instead).
pub fn plan_windows(spans: &[Range<usize>], stride: usize, non_overlapping: bool) -> Vec<WindowPlan> {
    let stride = stride.clamp(1, WINDOW);
    let mut plans = Vec::new();
    for span in spans {
        if span.len() <= WINDOW {
            plans.push(WindowPlan { frames: span.clone(), span: span.clone() });
            continue;
        }
        if non_overlapping {
            let mut start = span.start;
            while start < span.end {
                let end = (start + WINDOW).min(span.end);
                plans.push(WindowPlan { frames: start..end, span: span.clone() });
                start = end;
            }
            continue;
        }
        let mut start = span.start;
        loop {
            let end = start + WINDOW;
            if end >= span.end {
                plans.push(WindowPlan { frames: span.end - WINDOW..span.end, span: span.clone() });
                break;
            }
            plans.push(WindowPlan { frames: start..end, span: span.clone() });
            start += stride;
        }
    }
    plans
}

/// Cross-fade weight of frame `i` of a window of `len` real frames: ramps up over the first
/// `ramp` frames unless the window starts its span, and down over the last `ramp` frames
/// unless it ends it. Always positive.
pub fn crossfade_weight(i: usize, len: usize, ramp: usize, starts_span: bool, ends_span: bool) -> f32 {
    let ramp = ramp.max(1) as f32;
    let up = if starts_span { 1.0 } else { ((i as f32 + 1.0) / ramp).min(1.0) };
    let down = if ends_span { 1.0 } else { ((len - i) as f32 / ramp).min(1.0) };
    up.min(down).max(1e-3)
}

/// A window, a job's step or a decode that does not fit what it was made for: a caller's
/// mistake (a plan used with another session, steps out of order), never bad input data.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WindowError {
    #[error("window {frames:?} does not fit the {timeline}-frame timeline")]
    OffTimeline { frames: std::ops::Range<usize>, timeline: usize },
    #[error("window {frames:?} arrives after frame {given_out} was given out, or with {pose_values} pose values")]
    OutOfOrder { frames: std::ops::Range<usize>, given_out: usize, pose_values: usize },
    #[error("{decoded} decoded frames do not cover the {timeline}-frame timeline in order")]
    Incomplete { decoded: usize, timeline: usize },
    #[error("the decoded motion: {0}")]
    Motion(#[from] egoexo_core::motion::MotionError),
    #[error("a job's chunk is set before its first step")]
    ChunkAfterStart,
    #[error("window {window} of a plan of {windows} windows")]
    NoSuchWindow { window: usize, windows: usize },
    #[error("a job runs in parallel only from its start")]
    ParallelAfterStart,
    #[error("the job is unfinished: {done} of {total} steps ran")]
    Unfinished { done: usize, total: usize },
    #[error(
        "the session has {frames} frames and {observers} observers; the plan was made for {plan_frames} frames and at least {plan_observers}"
    )]
    SessionMismatch { frames: usize, observers: usize, plan_frames: usize, plan_observers: usize },
    #[error("no reconstruction came out of the job")]
    NoResult,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_are_runs_of_valid_frames() {
        assert_eq!(valid_spans(&[false, true, true, false, true]), vec![1..3, 4..5]);
        assert!(valid_spans(&[false, false]).is_empty());
        assert_eq!(valid_spans(&[true; 3]), vec![0..3]);
    }

    #[test]
    fn overlapping_windows_cover_every_frame() {
        let span = 10..260;
        let plans = plan_windows(std::slice::from_ref(&span), 48, false);
        assert!(plans.iter().all(|p| p.len() == WINDOW));
        let mut covered = vec![false; 260];
        for p in &plans {
            covered[p.frames.clone()].iter_mut().for_each(|c| *c = true);
        }
        assert!(covered[10..].iter().all(|&c| c) && !covered[9]);
        assert_eq!(plans.last().unwrap().frames.end, 260);
    }

    #[test]
    fn segments_do_not_overlap_and_short_spans_are_one_window() {
        let plans = plan_windows(&[0..200, 300..350], WINDOW, true);
        let ranges: Vec<_> = plans.iter().map(|p| p.frames.clone()).collect();
        assert_eq!(ranges, vec![0..96, 96..192, 192..200, 300..350]);
    }

    #[test]
    fn crossfade_ramps_inside_spans_only() {
        assert_eq!(crossfade_weight(0, 96, 24, true, false), 1.0);
        assert!(crossfade_weight(0, 96, 24, false, false) < 0.1);
        assert_eq!(crossfade_weight(50, 96, 24, false, false), 1.0);
        assert!(crossfade_weight(95, 96, 24, false, false) < 0.1);
        assert_eq!(crossfade_weight(95, 96, 24, false, true), 1.0);
    }
}
