//! The manifest's wire form: one typed struct per version ([`SessionManifest`] for versions
//! 1–2, [`CaptureManifest`] for version 3, [`StaticCameraFile`] for a static camera's file in
//! the multi-device folder layout), shared by the writer (which fills and serialises them) and
//! the reader (which deserialises them, then checks what types cannot say: safe paths that
//! exist, ids, unit quaternions, parameter counts, ranges). Their fields are the manifest's
//! keys, in one place: the reader warns about any other key (`unknown field … ignored`) and
//! the writer cannot write one. `docs/session-format.md`'s JSON Schema lists the same keys.
//!
//! An `Option` field is a key that may be absent (or `null`): read as `None`, and left out
//! when written (`skip_serializing_none`). Units and frames are the session's: metres, Y-up
//! world, CPF device frames, nanoseconds.

use serde::de::{DeserializeOwned, Error as _};
use serde::{Deserialize, Deserializer, Serialize};
use serde_json::Value;
use serde_with::skip_serializing_none;

use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::model::{Floor, WristSource};
use crate::placement::Placement;

/// A number that fits `f32` (finite), as the manifest writes and reads it: serialised in its
/// shortest decimal form (`1.7`, not `1.7000000476837158`), so that reading it back gives the
/// same `f32`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(transparent)]
pub(super) struct F32(pub f32);

impl<'de> Deserialize<'de> for F32 {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let x = f64::deserialize(deserializer)?;
        let y = x as f32;
        if y.is_finite() {
            Ok(F32(y))
        } else {
            Err(D::Error::custom(format!("expected a number within the f32 range, got {x:e}")))
        }
    }
}

pub(super) fn to_wire<const N: usize>(values: [f32; N]) -> [F32; N] {
    values.map(F32)
}

pub(super) fn from_wire<const N: usize>(values: &[F32; N]) -> [f32; N] {
    values.map(|x| x.0)
}

/// The fixed `conventions` object (the same in every version).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(super) struct Conventions {
    pub world: String,
    pub device_frame: String,
    pub time: String,
    pub length: String,
}

impl Conventions {
    /// Y-up world, CPF device frames, nanoseconds, metres.
    pub fn session() -> Self {
        Self { world: "y_up".into(), device_frame: "cpf".into(), time: "nanoseconds".into(), length: "metres".into() }
    }
}

impl std::fmt::Display for Conventions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Self { world, device_frame, time, length } = self;
        write!(
            f,
            "{{\"world\": \"{world}\", \"device_frame\": \"{device_frame}\", \"time\": \"{time}\", \"length\": \"{length}\"}}"
        )
    }
}

/// Versions 1–2: one wearer and the observers who see them.
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct SessionManifest {
    pub format: String,
    pub version: u32,
    pub name: String,
    pub created_by: Option<String>,
    pub conventions: Conventions,
    pub subject: SubjectEntry,
    pub wearer: WearerEntry,
    pub observers: Vec<ObserverEntry>,
    pub ground_truth: Option<GroundTruthEntry>,
    /// Since version 2.
    pub floor: Option<Floor>,
}

/// Version 3: a capture of several participants and the views between them.
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct CaptureManifest {
    pub format: String,
    pub version: u32,
    pub name: String,
    pub created_by: Option<String>,
    pub conventions: Conventions,
    pub participants: Vec<ParticipantEntry>,
    #[serde(default)]
    pub views: Vec<ViewEntry>,
    pub floor: Option<Floor>,
}

/// `subject` (and a participant's): stature, SMPL shape, rest joints — each optional.
#[skip_serializing_none]
#[derive(Debug, Default, Serialize, Deserialize)]
pub(super) struct SubjectEntry {
    /// Metres.
    pub height_m: Option<F32>,
    pub betas: Option<Vec<F32>>,
    /// The 24 SMPL joints at rest, metres, body frame.
    pub rest_joints: Option<Vec<[F32; 3]>>,
}

/// `wearer` (versions 1–2): trajectory files (Aria MPS CSV layout, `T_world_device`).
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct WearerEntry {
    pub head: String,
    pub left_wrist: Option<String>,
    pub right_wrist: Option<String>,
    /// The head joint in the head device's frame (CPF), metres.
    pub head_joint_in_device: [F32; 3],
    /// Absent: `devices`. Since version 2.
    pub wrist_source: Option<WristSource>,
}

/// `observers[i]` (versions 1–2). Poses: a worn device's `trajectory`, a static camera's one
/// `pose`, or neither with a `placement` of a static camera to register.
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct ObserverEntry {
    pub id: String,
    pub trajectory: Option<String>,
    pub pose: Option<TransformEntry>,
    /// Absent: the default placement (worn, shared world and clock).
    pub placement: Option<Placement>,
    pub camera: CameraEntry,
    pub keypoints: Option<String>,
    pub video: Option<VideoEntry>,
    pub context_features: Option<String>,
}

/// `participants[i]` (version 3): worn devices (or a static camera's `pose` / `placement`),
/// maybe a camera, and what is known of the person.
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct ParticipantEntry {
    pub id: String,
    pub reconstruct: bool,
    pub head: Option<String>,
    pub left_wrist: Option<String>,
    pub right_wrist: Option<String>,
    pub wrist_source: Option<WristSource>,
    pub head_joint_in_device: [F32; 3],
    pub camera: Option<CameraEntry>,
    pub video: Option<VideoEntry>,
    pub context_features: Option<String>,
    pub subject: SubjectEntry,
    pub ground_truth: Option<GroundTruthEntry>,
    pub pose: Option<TransformEntry>,
    pub placement: Option<Placement>,
}

/// `views[i]` (version 3): one participant's keypoints in `observer`'s camera (`target` and
/// `keypoints`), or everyone it saw, without identity (`people`).
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct ViewEntry {
    pub observer: String,
    pub target: Option<String>,
    pub keypoints: Option<String>,
    pub people: Option<String>,
}

/// A camera's projection model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum CameraModel {
    /// Aria's FisheyeRadTanThinPrism: 15 parameters.
    Fisheye624,
    /// `fx, fy, cx, cy`, pixels.
    Pinhole,
}

/// A camera (`observers[i].camera`, `participants[i].camera`, a static camera's file).
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct CameraEntry {
    pub model: CameraModel,
    pub params: Vec<F32>,
    /// Pixels.
    pub width: u32,
    pub height: u32,
    /// The camera's pose in its device's frame (CPF).
    pub t_device_camera: TransformEntry,
    pub valid_radius_px: Option<F32>,
}

/// A rigid transform `T_a_b`: metres, unit quaternion `[x, y, z, w]`.
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct TransformEntry {
    pub translation: [F32; 3],
    pub rotation_xyzw: [F32; 4],
}

/// An RGB video: where it is, when its first frame is (ns), and its frame times' file.
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct VideoEntry {
    pub path: String,
    pub start_ns: i64,
    pub timestamps: Option<String>,
}

/// `ground_truth` (and a participant's): the motion's npz and, per row of its occlusion masks,
/// the observer it is of.
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct GroundTruthEntry {
    pub motion: String,
    pub occlusion_observers: Option<Vec<String>>,
}

/// A static camera's file (`observers/<id>/static_camera.json`): its camera, and its `pose`
/// or a `placement` of a camera to register.
#[skip_serializing_none]
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct StaticCameraFile {
    pub camera: CameraEntry,
    pub pose: Option<TransformEntry>,
    pub placement: Option<Placement>,
}

/// `doc` (from `file`) as `T`: an error names the field (`observers[1].camera.model`) and what
/// was expected; every key `T` does not know becomes a warning.
pub(super) fn from_json<T: DeserializeOwned>(
    file: &str,
    doc: &Value,
    warnings: &mut Vec<ImportWarning>,
) -> Result<T, ImportError> {
    let mut unknown = Vec::new();
    let mut track = |path: serde_ignored::Path<'_>| unknown.push(ignored_path(&path));
    let ignoring = serde_ignored::Deserializer::new(doc, &mut track);
    let typed = serde_path_to_error::deserialize(ignoring).map_err(|e| {
        let path = e.path().to_string();
        let location = if path == "." { Location::File } else { Location::Field(path) };
        ImportError::new(file, location, ImportErrorKind::Manifest(e.into_inner().to_string()))
    })?;
    warnings.extend(
        unknown
            .into_iter()
            .map(|key| ImportWarning { file: file.to_owned(), message: format!("unknown field `{key}` ignored") }),
    );
    Ok(typed)
}

/// `a.b[2].c`, as the reader's errors name fields.
fn ignored_path(path: &serde_ignored::Path<'_>) -> String {
    use serde_ignored::Path;
    match path {
        Path::Root => String::new(),
        Path::Seq { parent, index } => format!("{}[{index}]", ignored_path(parent)),
        Path::Map { parent, key } => crate::json::join(&ignored_path(parent), key),
        Path::Some { parent } | Path::NewtypeStruct { parent } | Path::NewtypeVariant { parent } => {
            ignored_path(parent)
        }
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    #[test]
    fn keys_an_entry_does_not_know_are_warnings_naming_their_path() {
        let doc = json!({"motion": "gt.npz", "occlusion_observers": ["a"], "extra": {"deep": 1}});
        let mut warnings = Vec::new();
        let gt: GroundTruthEntry = from_json("m.json", &doc, &mut warnings).unwrap();
        assert_eq!(gt.motion, "gt.npz");
        let messages: Vec<String> = warnings.iter().map(ToString::to_string).collect();
        assert_eq!(messages, ["m.json: unknown field `extra` ignored"]);
        let doc = json!({"format": "egoexo-session", "version": 2, "name": "n", "extra": 1,
            "conventions": {"world": "y_up", "device_frame": "cpf", "time": "nanoseconds", "length": "metres"},
            "subject": {}, "wearer": {"head": "h.csv", "head_joint_in_device": [0, 0, 0], "note": 1}, "observers": []});
        let mut warnings = Vec::new();
        let _: SessionManifest = from_json("m.json", &doc, &mut warnings).unwrap();
        let messages: Vec<String> = warnings.iter().map(ToString::to_string).collect();
        assert_eq!(messages, ["m.json: unknown field `extra` ignored", "m.json: unknown field `wearer.note` ignored"]);
    }

    #[test]
    fn a_value_of_the_wrong_shape_names_its_field() {
        let doc = json!({"translation": [0, 0, 0], "rotation_xyzw": [0, 0, "one", 1]});
        let error = from_json::<TransformEntry>("m.json", &doc, &mut Vec::new()).unwrap_err().to_string();
        assert_eq!(error, "m.json, field `rotation_xyzw[2]`: invalid type: string \"one\", expected f64");
        let doc = json!({"translation": [0, 1e39, 0], "rotation_xyzw": [0, 0, 0, 1]});
        let error = from_json::<TransformEntry>("m.json", &doc, &mut Vec::new()).unwrap_err().to_string();
        assert_eq!(error, "m.json, field `translation[1]`: expected a number within the f32 range, got 1e39");
    }
}
