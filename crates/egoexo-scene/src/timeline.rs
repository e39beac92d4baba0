//! Per-frame series for the timeline plots under the 3D view: when each observer saw the
//! wearer and how the gate judged it, and, with ground truth, the errors over time. Built by
//! the worker from the session and the reconstruction; the page only draws them.
//!
//! Every series has one value per scene frame. Missing values are negative (JSON has no NaN):
//! `-1` = not defined at that frame (no ray, not scored).

use serde::{Deserialize, Serialize};

/// Everything the timeline plots show.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TimelineData {
    /// One strip per observer, in the scene's observer order.
    pub observers: Vec<ObserverTimeline>,
    /// Per-frame errors against the ground truth, when the session has it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub errors: Option<ErrorTimeline>,
}

/// What one observer contributed over time.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ObserverTimeline {
    pub id: String,
    /// Joints of the reconstruction (of 24) that project into the observer's image, per frame
    /// (0 where the observer is not tracked or the wearer is out of its view).
    pub joints_in_view: Vec<u8>,
    /// Exo keypoints (of 13) the session's 2D keypoints hold at the frame.
    pub keypoints: Vec<u8>,
    /// Keypoints (of 13) labelled occluded at the frame, when the session has such labels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub occluded: Option<Vec<u8>>,
    /// Mean gate (0 ignored … 1 trusted) over the frame's rays; `-1` without rays.
    pub gate_mean: Vec<f32>,
}

/// Per-frame position errors against the ground truth, cm; `-1` where the frame is not
/// scored (not reconstructed, or no ground truth).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorTimeline {
    /// MPJPE of the reconstruction (all 24 joints).
    pub mpjpe_cm: Vec<f32>,
    /// L-PE of the reconstruction (the lower body's joints).
    pub lower_cm: Vec<f32>,
    /// The same for the ego-only reconstruction, when the scene has it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ego_only_mpjpe_cm: Option<Vec<f32>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ego_only_lower_cm: Option<Vec<f32>>,
}

impl TimelineData {
    /// Checks that every series has `frames` values; the problems found, named by series.
    pub fn check(&self, frames: usize, observers: usize) -> Vec<String> {
        let mut problems = Vec::new();
        let mut expect = |what: String, got: usize| {
            if got != frames {
                problems.push(format!("timeline {what} has {got} values, expected {frames}"));
            }
        };
        for o in &self.observers {
            expect(format!("observer {} joints_in_view", o.id), o.joints_in_view.len());
            expect(format!("observer {} keypoints", o.id), o.keypoints.len());
            expect(format!("observer {} gate_mean", o.id), o.gate_mean.len());
            if let Some(occluded) = &o.occluded {
                expect(format!("observer {} occluded", o.id), occluded.len());
            }
        }
        if let Some(e) = &self.errors {
            expect("errors mpjpe_cm".into(), e.mpjpe_cm.len());
            expect("errors lower_cm".into(), e.lower_cm.len());
            if let Some(v) = &e.ego_only_mpjpe_cm {
                expect("errors ego_only_mpjpe_cm".into(), v.len());
            }
            if let Some(v) = &e.ego_only_lower_cm {
                expect("errors ego_only_lower_cm".into(), v.len());
            }
        }
        if self.observers.len() != observers {
            problems.push(format!("timeline has {} observers, the scene {observers}", self.observers.len()));
        }
        problems
    }

    /// Frames `start..end` only (in range; see `SceneData::frames_slice`).
    pub fn frames_slice(&self, start: usize, end: usize) -> Self {
        let slice_u8 = |v: &[u8]| v.get(start..end).map(<[u8]>::to_vec).unwrap_or_default();
        let slice_f32 = |v: &[f32]| v.get(start..end).map(<[f32]>::to_vec).unwrap_or_default();
        Self {
            observers: self
                .observers
                .iter()
                .map(|o| ObserverTimeline {
                    id: o.id.clone(),
                    joints_in_view: slice_u8(&o.joints_in_view),
                    keypoints: slice_u8(&o.keypoints),
                    occluded: o.occluded.as_deref().map(slice_u8),
                    gate_mean: slice_f32(&o.gate_mean),
                })
                .collect(),
            errors: self.errors.as_ref().map(|e| ErrorTimeline {
                mpjpe_cm: slice_f32(&e.mpjpe_cm),
                lower_cm: slice_f32(&e.lower_cm),
                ego_only_mpjpe_cm: e.ego_only_mpjpe_cm.as_deref().map(slice_f32),
                ego_only_lower_cm: e.ego_only_lower_cm.as_deref().map(slice_f32),
            }),
        }
    }
}
