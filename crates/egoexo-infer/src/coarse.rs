//! EgoNet's coarse body on a few windows only: what steps before the reconstruction (an
//! observer's registration) need of the body at a fraction of the ego pass's cost.

use egoexo_core::aligned::AlignedSession;
use egoexo_core::ego_features::TrackingMode;
use egoexo_core::glam::Vec3;
use egoexo_core::skeleton::NUM_JOINTS;

use crate::Engine;
use crate::InferError;
use crate::inputs::world_poses;
use crate::passes::{CoarsePoseSource, ego_pass};
use crate::timing::StageTimer;
use crate::windows::{WINDOW, plan_windows, valid_spans};

/// The coarse body's 24 SMPL joint positions (world, metres) per aligned frame, on the frames
/// of the windows that were run (`None` elsewhere).
#[derive(Clone, Debug, PartialEq)]
pub struct CoarseBody {
    pub joints: Vec<Option<[Vec3; NUM_JOINTS]>>,
    /// Windows EgoNet ran on.
    pub windows: usize,
}

impl Engine {
    /// EgoNet on at most `max_windows` non-overlapping windows of `aligned`: those holding the
    /// most frames for which `wanted(frame)` is true (ties: the earlier), each decoded to world
    /// joints as the reconstruction decodes its own (root from the head by forward
    /// kinematics).
    pub fn coarse_body(
        &self,
        aligned: &AlignedSession,
        tracking: TrackingMode,
        max_windows: usize,
        wanted: &dyn Fn(usize) -> bool,
    ) -> Result<CoarseBody, InferError> {
        let egonet = &self.require_models(tracking)?.egonet;
        let frames = aligned.timeline.frames;
        let valid: Vec<bool> = (0..frames).map(|f| aligned.wearer_tracked(f)).collect();
        let windows = plan_windows(&valid_spans(&valid), WINDOW, true);
        let mut scored: Vec<(usize, usize)> =
            windows.iter().enumerate().map(|(i, w)| (w.frames.clone().filter(|&f| wanted(f)).count(), i)).collect();
        scored.retain(|(count, _)| *count > 0);
        // Most wanted frames first; among equals the earlier window. Then spread: the chosen
        // windows in timeline order.
        scored.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        let mut chosen: Vec<usize> = scored.into_iter().take(max_windows).map(|(_, i)| i).collect();
        chosen.sort_unstable();
        let mut joints = vec![None; frames];
        let mut clock = || 0.0;
        let mut timer = StageTimer::new(&mut clock);
        for &i in &chosen {
            let plan = &windows[i];
            let ego = ego_pass(aligned, plan, tracking, CoarsePoseSource::EgoNet(egonet), &mut timer)?;
            let poses = world_poses(&ego.window, &ego.coarse, &aligned.skeleton, aligned.head_joint_in_device);
            for (f, pose) in plan.frames.clone().zip(&poses) {
                joints[f] = Some(aligned.skeleton.forward_kinematics(pose).positions);
            }
        }
        Ok(CoarseBody { joints, windows: chosen.len() })
    }
}
