//! What a reconstruction will do before any network runs: the tracking mode, the frames
//! where the wearer can be reconstructed, the windows over them, and which observers take
//! the networks' slots.
//!
//! This is the only step that looks at the whole session (to order the observers and plan
//! windows over the tracked spans); every pass after it works one window at a time.

use egoexo_core::aligned::AlignedSession;
use egoexo_core::ego_features::TrackingMode;

use crate::InferError;
use crate::windows::WindowError;
use crate::windows::{WINDOW, WindowPlan, plan_windows, valid_spans};

/// How to cut the timeline into windows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WindowOptions {
    /// Frames between window starts (overlapping windows are cross-faded).
    pub stride: usize,
    /// The paper's evaluation protocol: non-overlapping 96-frame segments, no cross-fade.
    pub non_overlapping: bool,
}

impl Default for WindowOptions {
    /// Half-overlapping windows (stride 48), cross-faded.
    fn default() -> Self {
        Self { stride: WINDOW / 2, non_overlapping: false }
    }
}

impl WindowOptions {
    /// Frames over which overlapping windows are cross-faded (1: no overlap).
    pub fn crossfade_ramp(&self) -> usize {
        if self.non_overlapping { 1 } else { WINDOW.saturating_sub(self.stride).max(1) }
    }
}

/// The tracking mode to reconstruct with: `requested`, else the session's default
/// ([`AlignedSession::tracking_mode`]: 3-point whenever a wrist exists, however much of the
/// time it is tracked). 3-point without any wrist trajectory is an error.
pub fn resolve_tracking(aligned: &AlignedSession, requested: Option<TrackingMode>) -> Result<TrackingMode, InferError> {
    let tracking = requested.unwrap_or_else(|| aligned.tracking_mode());
    if tracking == TrackingMode::ThreePoint && !aligned.has_wrists() {
        return Err(InferError::MissingWrists);
    }
    Ok(tracking)
}

/// Observers in the order they take the networks' slots: most frames with keypoints first
/// (ties keep session order).
pub fn observer_order(aligned: &AlignedSession) -> Vec<usize> {
    let mut order: Vec<(usize, usize)> = aligned
        .observers
        .iter()
        .enumerate()
        .map(|(i, o)| (i, o.keypoints.iter().filter(|f| f.iter().any(Option::is_some)).count()))
        .collect();
    order.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    order.into_iter().map(|(i, _)| i).collect()
}

/// The plan of one reconstruction of a session.
#[derive(Clone, Debug, PartialEq)]
pub struct ReconstructionPlan {
    pub tracking: TrackingMode,
    /// Frames of the aligned timeline.
    pub frames: usize,
    /// Per timeline frame: the wearer is tracked ([`AlignedSession::wearer_tracked`]).
    pub valid: Vec<bool>,
    /// The windows, in timeline order (each inside one tracked span).
    pub windows: Vec<WindowPlan>,
    /// Session observers in slot order ([`observer_order`]), at most `slots` of them.
    pub observers: Vec<usize>,
    /// The networks' observer slots (0 for the baselines).
    pub slots: usize,
    /// Cross-fade ramp between overlapping windows, frames.
    pub crossfade_ramp: usize,
}

impl ReconstructionPlan {
    /// Plans `aligned` in `tracking` mode for networks with `slots` observer slots.
    pub fn new(
        aligned: &AlignedSession,
        tracking: TrackingMode,
        windows: &WindowOptions,
        slots: usize,
    ) -> Result<Self, InferError> {
        let frames = aligned.timeline.frames;
        let valid: Vec<bool> = (0..frames).map(|f| aligned.wearer_tracked(f)).collect();
        if !valid.iter().any(|&v| v) {
            return Err(InferError::NoValidFrames);
        }
        Ok(Self {
            tracking,
            frames,
            windows: plan_windows(&valid_spans(&valid), windows.stride, windows.non_overlapping),
            valid,
            observers: observer_order(aligned).into_iter().take(slots).collect(),
            slots,
            crossfade_ramp: windows.crossfade_ramp(),
        })
    }

    /// Checks that `aligned` is the session this plan was made for (same timeline length and
    /// observer count), so a step never indexes another session's frames.
    pub fn check_session(&self, aligned: &AlignedSession) -> Result<(), InferError> {
        let max_observer = self.observers.iter().max().map_or(0, |&o| o + 1);
        if aligned.timeline.frames != self.frames || aligned.observers.len() < max_observer {
            return Err(WindowError::SessionMismatch {
                frames: aligned.timeline.frames,
                observers: aligned.observers.len(),
                plan_frames: self.frames,
                plan_observers: max_observer,
            }
            .into());
        }
        Ok(())
    }
}
