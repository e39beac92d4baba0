//! What the viewer draws, as plain data: built by the worker (`egoexo_web_worker::scene`) from a
//! reconstruction, sent to the page (serde / structured clone), rendered by `egoexo-viewer`.
//! Nothing here computes geometry; every position is already in the world.
//!
//! Conventions: world Y-up, metres; arrays are flat and row-major (`frames × …`) so they cross
//! the worker boundary as typed arrays; quaternions are `[x, y, z, w]`.

use egoexo_core::exo_keypoints::EXO_KEYPOINT_COUNT;
use egoexo_core::skeleton::{NUM_JOINTS, PARENTS};
use serde::{Deserialize, Serialize};

pub mod timeline;

pub use timeline::{ErrorTimeline, ObserverTimeline, TimelineData};

/// Version of this layout (the page refuses other versions).
pub const SCENE_FORMAT_VERSION: u32 = 1;

/// Everything the viewer shows for one reconstructed session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneData {
    pub format_version: u32,
    /// Session name.
    pub name: String,
    pub fps: f32,
    pub frames: usize,
    /// Session-clock time of frame 0, seconds.
    pub start_s: f64,
    /// SMPL parents (`-1` for the root).
    pub parents: Vec<i8>,
    /// The reconstruction: `frames × 24 × 3` joint positions.
    pub joints: Vec<f32>,
    /// Frames actually reconstructed (tracking valid).
    pub valid: Vec<bool>,
    /// Frames with exo evidence (an observer ray with gate ≥ 0.5).
    pub exo_evidence: Vec<bool>,
    /// The ego-only reconstruction for the comparison overlay, `frames × 24 × 3`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ego_only_joints: Option<Vec<f32>>,
    /// Ground truth as a ghost, `frames × 24 × 3`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_truth_joints: Option<Vec<f32>>,
    /// Wearer devices: head and (3-point) wrists, `frames × 3` positions each.
    pub devices: Vec<DeviceTrack>,
    pub observers: Vec<ObserverScene>,
    /// Estimated floor height (lowest reconstructed foot joint), metres.
    pub floor_y: f32,
    /// Method that produced `joints` (`ego-exo`, …).
    pub method: String,
    /// Series for the timeline plots (scenes from before they existed have none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeline: Option<TimelineData>,
    /// In a capture of several participants: who `joints` is (the others are in `others`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub participant: Option<SceneParticipant>,
    /// The capture's other reconstructed participants, on this scene's frames (same world).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub others: Vec<OtherBody>,
}

/// A participant of a capture, as the viewer names and colours them.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneParticipant {
    pub id: String,
    /// Index into the viewer's participant palette (the capture's order, so a participant
    /// keeps their colour whoever is selected).
    pub colour: usize,
}

/// Another participant's reconstructed body, drawn with the scene's wearer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OtherBody {
    pub participant: SceneParticipant,
    /// `frames × 24 × 3` joint positions (world), on the scene's frames.
    pub joints: Vec<f32>,
    /// Frames where they were reconstructed (and the scene's time lies in their timeline).
    pub valid: Vec<bool>,
}

/// A device trajectory.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeviceTrack {
    /// `head`, `left_wrist`, `right_wrist`.
    pub name: String,
    /// `frames × 3`.
    pub positions: Vec<f32>,
    pub valid: Vec<bool>,
}

/// An observer's camera and gated rays.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObserverScene {
    pub id: String,
    /// `T_world_camera` per frame: `frames × 7` (`[qx, qy, qz, qw, tx, ty, tz]`), optical frame
    /// +X right, +Y down, +Z forward.
    pub camera_poses: Vec<f32>,
    pub valid: Vec<bool>,
    /// Half field of view (radians) horizontally and vertically, for drawing the frustum.
    pub half_fov: [f32; 2],
    /// Image size in pixels.
    pub image_size: [u32; 2],
    /// Per frame and exo keypoint: ray endpoint in the world (`x, y, z`) and gate value, i.e.
    /// `frames × 13 × 4`; gate 0 and a zero endpoint where there is no valid ray.
    pub rays: Vec<f32>,
}

impl ObserverScene {
    /// The ray to exo keypoint `keypoint` at `frame`: its world endpoint and gate, or `None`
    /// where there is none (a zero endpoint with gate 0, or out of range).
    pub fn ray(&self, frame: usize, keypoint: usize) -> Option<([f32; 3], f32)> {
        if keypoint >= EXO_KEYPOINT_COUNT {
            return None;
        }
        let at = 4 * (frame.checked_mul(EXO_KEYPOINT_COUNT)? + keypoint);
        let r = self.rays.get(at..at + 4)?;
        (r.iter().any(|&v| v != 0.0)).then(|| ([r[0], r[1], r[2]], r[3]))
    }
}

impl SceneData {
    /// An empty scene for `frames` frames (no observers, no devices).
    pub fn new(name: &str, fps: f32, frames: usize, method: &str) -> Self {
        Self {
            format_version: SCENE_FORMAT_VERSION,
            name: name.to_string(),
            fps,
            frames,
            start_s: 0.0,
            parents: PARENTS.to_vec(),
            joints: vec![0.0; frames * NUM_JOINTS * 3],
            valid: vec![false; frames],
            exo_evidence: vec![false; frames],
            ego_only_joints: None,
            ground_truth_joints: None,
            devices: Vec::new(),
            observers: Vec::new(),
            floor_y: 0.0,
            method: method.to_string(),
            timeline: None,
            participant: None,
            others: Vec::new(),
        }
    }

    /// Checks that every array has the length its frame count implies.
    pub fn check(&self) -> Result<(), String> {
        let f = self.frames;
        let joints = f * NUM_JOINTS * 3;
        let mut problems = Vec::new();
        let mut expect = |what: &str, got: usize, want: usize| {
            if got != want {
                problems.push(format!("{what} has {got} values, expected {want}"));
            }
        };
        expect("joints", self.joints.len(), joints);
        expect("valid", self.valid.len(), f);
        expect("exo_evidence", self.exo_evidence.len(), f);
        expect("parents", self.parents.len(), NUM_JOINTS);
        if let Some(j) = &self.ego_only_joints {
            expect("ego_only_joints", j.len(), joints);
        }
        if let Some(j) = &self.ground_truth_joints {
            expect("ground_truth_joints", j.len(), joints);
        }
        for d in &self.devices {
            expect(&format!("device {} positions", d.name), d.positions.len(), 3 * f);
            expect(&format!("device {} valid", d.name), d.valid.len(), f);
        }
        for o in &self.observers {
            expect(&format!("observer {} camera_poses", o.id), o.camera_poses.len(), 7 * f);
            expect(&format!("observer {} valid", o.id), o.valid.len(), f);
            expect(&format!("observer {} rays", o.id), o.rays.len(), 4 * EXO_KEYPOINT_COUNT * f);
        }
        for o in &self.others {
            expect(&format!("participant {} joints", o.participant.id), o.joints.len(), joints);
            expect(&format!("participant {} valid", o.participant.id), o.valid.len(), f);
        }
        if let Some(t) = &self.timeline {
            problems.extend(t.check(f, self.observers.len()));
        }
        if self.format_version != SCENE_FORMAT_VERSION {
            problems.push(format!("format_version {} (expected {SCENE_FORMAT_VERSION})", self.format_version));
        }
        if problems.is_empty() { Ok(()) } else { Err(problems.join("; ")) }
    }

    /// The scene of frames `range` only (clamped to the scene), e.g. the one frame a live
    /// reconstruction shows out of its window. `start_s` moves with the first frame.
    pub fn frames_slice(&self, range: std::ops::Range<usize>) -> SceneData {
        let start = range.start.min(self.frames);
        let end = range.end.clamp(start, self.frames);
        let per = |values: &[f32], width: usize| values[start * width..end * width].to_vec();
        let flags = |values: &[bool]| values[start..end].to_vec();
        let joints = NUM_JOINTS * 3;
        SceneData {
            format_version: self.format_version,
            name: self.name.clone(),
            fps: self.fps,
            frames: end - start,
            start_s: self.start_s + start as f64 / f64::from(self.fps),
            parents: self.parents.clone(),
            joints: per(&self.joints, joints),
            valid: flags(&self.valid),
            exo_evidence: flags(&self.exo_evidence),
            ego_only_joints: self.ego_only_joints.as_deref().map(|j| per(j, joints)),
            ground_truth_joints: self.ground_truth_joints.as_deref().map(|j| per(j, joints)),
            devices: self
                .devices
                .iter()
                .map(|d| DeviceTrack { name: d.name.clone(), positions: per(&d.positions, 3), valid: flags(&d.valid) })
                .collect(),
            observers: self
                .observers
                .iter()
                .map(|o| ObserverScene {
                    id: o.id.clone(),
                    camera_poses: per(&o.camera_poses, 7),
                    valid: flags(&o.valid),
                    half_fov: o.half_fov,
                    image_size: o.image_size,
                    rays: per(&o.rays, 4 * EXO_KEYPOINT_COUNT),
                })
                .collect(),
            floor_y: self.floor_y,
            method: self.method.clone(),
            timeline: self.timeline.as_ref().map(|t| t.frames_slice(start, end)),
            participant: self.participant.clone(),
            others: self
                .others
                .iter()
                .map(|o| OtherBody {
                    participant: o.participant.clone(),
                    joints: per(&o.joints, joints),
                    valid: flags(&o.valid),
                })
                .collect(),
        }
    }
}

impl SceneData {
    /// This scene with `others` drawn along: each of their scenes (the same capture's other
    /// participants, reconstructed on their own timelines) resampled onto this scene's frames
    /// by time — the nearest frame, valid where theirs is and the time lies in their timeline.
    pub fn with_others<'a>(mut self, others: impl IntoIterator<Item = &'a SceneData>) -> SceneData {
        let joints = NUM_JOINTS * 3;
        for other in others {
            let Some(participant) = other.participant.clone() else { continue };
            let mut body =
                OtherBody { participant, joints: vec![0.0; self.frames * joints], valid: vec![false; self.frames] };
            for i in 0..self.frames {
                let t = self.start_s + i as f64 / f64::from(self.fps);
                let at = ((t - other.start_s) * f64::from(other.fps)).round();
                if at < 0.0 || at >= other.frames as f64 {
                    continue;
                }
                let j = at as usize;
                body.joints[i * joints..(i + 1) * joints].copy_from_slice(&other.joints[j * joints..(j + 1) * joints]);
                body.valid[i] = other.valid[j];
            }
            self.others.push(body);
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slice_keeps_its_frames_and_stays_consistent() {
        let mut scene = SceneData::new("s", 30.0, 10, "ego-exo");
        scene.joints.iter_mut().enumerate().for_each(|(i, v)| *v = i as f32);
        scene.valid[7] = true;
        let one = scene.frames_slice(7..8);
        one.check().unwrap();
        assert_eq!((one.frames, one.valid.clone()), (1, vec![true]));
        assert_eq!(one.joints[0], (7 * NUM_JOINTS * 3) as f32);
        assert!((one.start_s - 7.0 / 30.0).abs() < 1e-9);
        assert_eq!(scene.frames_slice(8..99).frames, 2);
    }

    #[test]
    fn a_ray_is_there_unless_its_slot_is_all_zero() {
        let mut o = ObserverScene {
            id: "o".into(),
            camera_poses: vec![0.0; 14],
            valid: vec![true; 2],
            half_fov: [0.5, 0.5],
            image_size: [640, 480],
            rays: vec![0.0; 4 * EXO_KEYPOINT_COUNT * 2],
        };
        let at = 4 * (EXO_KEYPOINT_COUNT + 3);
        o.rays[at..at + 4].copy_from_slice(&[1.0, 2.0, 3.0, 0.0]);
        assert_eq!(o.ray(1, 3), Some(([1.0, 2.0, 3.0], 0.0)), "a ray with gate 0 is still a ray");
        assert_eq!(o.ray(1, 2), None);
        assert_eq!(o.ray(2, 0), None);
        assert_eq!(o.ray(0, EXO_KEYPOINT_COUNT), None);
        assert_eq!(o.ray(usize::MAX, 0), None);
    }

    #[test]
    fn others_are_resampled_onto_the_scene_by_time() {
        let mut scene = SceneData::new("a", 30.0, 6, "ego-exo");
        scene.participant = Some(SceneParticipant { id: "a".into(), colour: 0 });
        let mut other = SceneData::new("b", 30.0, 4, "ego-exo");
        other.participant = Some(SceneParticipant { id: "b".into(), colour: 1 });
        other.start_s = 2.0 / 30.0; // their frame 0 is our frame 2
        for (f, v) in other.valid.iter_mut().enumerate() {
            *v = f != 1;
        }
        other.joints.chunks_mut(NUM_JOINTS * 3).enumerate().for_each(|(f, j)| j.fill(f as f32 + 1.0));
        let mut unnamed = other.clone();
        unnamed.participant = None;
        let both = scene.with_others([&other, &unnamed]);
        both.check().unwrap();
        assert_eq!(both.others.len(), 1, "a scene without a participant is nobody to draw");
        let b = &both.others[0];
        assert_eq!(b.valid, vec![false, false, true, false, true, true]);
        let first_joint: Vec<f32> = b.joints.chunks(NUM_JOINTS * 3).map(|j| j[0]).collect();
        assert_eq!(first_joint, vec![0.0, 0.0, 1.0, 2.0, 3.0, 4.0]);
        let sliced = both.frames_slice(4..6);
        sliced.check().unwrap();
        assert_eq!(sliced.others[0].valid, vec![true, true]);
    }

    #[test]
    fn a_new_scene_is_consistent_and_survives_json() {
        let scene = SceneData::new("s", 30.0, 4, "ego-exo");
        scene.check().unwrap();
        let back: SceneData = serde_json::from_str(&serde_json::to_string(&scene).unwrap()).unwrap();
        assert_eq!(back, scene);
        let mut broken = scene;
        broken.joints.pop();
        assert!(broken.check().unwrap_err().contains("joints has 287 values"));
    }
}
