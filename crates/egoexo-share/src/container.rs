//! The share container, version [`SHARE_FORMAT_VERSION`]: a zip (deflate, fixed timestamps)
//! of
//!
//! | entry | content |
//! |---|---|
//! | `share.json` | [`ShareManifest`]: format, version, name, who made it, the reconstruction summary, the session summary |
//! | `scene.json` | the viewer's `SceneData` (JSON), exactly as the worker built it |
//! | `motion.json` | the reconstructed `SmplMotion` (JSON: fps, start time, skeleton, betas, poses) for the exports |
//! | `session.egoexo` | optional: the recording as a `.egoexo` session, so the reconstruction can be re-run |
//! | `participants/<id>/scene.json`, `participants/<id>/motion.json` | a capture of several participants (version 2): each reconstructed participant's own scene and motion; `share.json` lists them |
//!
//! Version 2 added `participants`; version 1 containers are read as before.
//!
//! Reading checks every entry against size limits before decompressing it (a share is
//! untrusted input: the key is in a link anybody may have changed).

use std::collections::BTreeMap;

use egoexo_core::SmplMotion;
use egoexo_protocol::worker::{ParticipantSummary, ReconstructionSummary, SessionSummary};
use egoexo_session::{FileTree, Limits};
use serde::{Deserialize, Serialize};

use crate::ShareError;

/// The container's `format` field.
pub const SHARE_FORMAT: &str = "egoexo-share";
/// The container's version.
pub const SHARE_FORMAT_VERSION: u32 = 2;
/// The most participants a share carries (as a capture's format allows).
pub const MAX_SHARED_PARTICIPANTS: usize = 16;

/// Entry names.
pub const MANIFEST_FILE: &str = "share.json";
pub const SCENE_FILE: &str = "scene.json";
pub const MOTION_FILE: &str = "motion.json";
pub const SESSION_FILE: &str = "session.egoexo";

/// Most bytes one entry may decompress to (the share limit is on the compressed whole).
pub const MAX_ENTRY_BYTES: u64 = 1 << 30;

/// `share.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShareManifest {
    /// Always [`SHARE_FORMAT`].
    pub format: String,
    /// [`SHARE_FORMAT_VERSION`] when written.
    pub version: u32,
    /// The session's name.
    pub name: String,
    /// `egoexo <version>` (page or CLI).
    pub created_by: String,
    /// The reconstruction.
    pub summary: ReconstructionSummary,
    /// The session it was made from.
    pub session: SessionSummary,
    /// Whether `session.egoexo` is included.
    pub includes_recording: bool,
    /// A capture of several participants: every reconstructed participant, whose scene and
    /// motion are under `participants/<id>/` (version 2; empty for one wearer). `scene.json`
    /// and `motion.json` are the participant shown when it was shared (`summary.participant`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub participants: Vec<SharedParticipantEntry>,
}

/// One participant in `share.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SharedParticipantEntry {
    pub participant: ParticipantSummary,
    /// Their reconstruction.
    pub summary: ReconstructionSummary,
    /// Their session (the capture's participant as a wearer).
    pub session: SessionSummary,
}

/// One participant of a capture in a share.
#[derive(Clone, Debug, PartialEq)]
pub struct SharedParticipant {
    /// Who they are and their summaries (as `share.json` lists them).
    pub entry: SharedParticipantEntry,
    /// Their own `SceneData` JSON (without the others).
    pub scene_json: Vec<u8>,
    pub motion: SmplMotion,
}

/// Everything in a share.
#[derive(Clone, Debug, PartialEq)]
pub struct ShareContents {
    pub manifest: ShareManifest,
    /// `SceneData` JSON.
    pub scene_json: Vec<u8>,
    /// The reconstructed motion (ego-exo).
    pub motion: SmplMotion,
    /// The recording as `.egoexo` zip bytes, when included.
    pub session_egoexo: Option<Vec<u8>>,
    /// A capture's participants (empty for one wearer).
    pub participants: Vec<SharedParticipant>,
}

/// Where participant `id`'s entries live; `id` must be a participant id of the capture
/// format (`egoexo_session::validate::is_valid_observer_id`), so it is one path component.
pub fn participant_entry(id: &str, file: &str) -> Result<String, ShareError> {
    if !egoexo_session::validate::is_valid_observer_id(id) {
        return Err(ShareError::Container(format!(
            "participant id `{id}`: expected 1–64 characters from A–Z, a–z, 0–9, `.`, `_`, `-`"
        )));
    }
    Ok(format!("participants/{id}/{file}"))
}

impl ShareManifest {
    /// A manifest of the current version.
    pub fn new(name: &str, created_by: &str, summary: ReconstructionSummary, session: SessionSummary) -> Self {
        ShareManifest {
            format: SHARE_FORMAT.into(),
            version: SHARE_FORMAT_VERSION,
            name: name.into(),
            created_by: created_by.into(),
            summary,
            session,
            includes_recording: false,
            participants: Vec::new(),
        }
    }
}

/// Packs a share into container bytes (not yet sealed).
pub fn pack(contents: &ShareContents) -> Result<Vec<u8>, ShareError> {
    let json = |what: &str, e: serde_json::Error| ShareError::Container(format!("cannot write {what}: {e}"));
    let mut manifest = contents.manifest.clone();
    manifest.includes_recording = contents.session_egoexo.is_some();
    let mut files = BTreeMap::new();
    files.insert(SCENE_FILE.to_string(), contents.scene_json.clone());
    files.insert(MOTION_FILE.to_string(), serde_json::to_vec(&contents.motion).map_err(|e| json(MOTION_FILE, e))?);
    if let Some(session) = &contents.session_egoexo {
        files.insert(SESSION_FILE.to_string(), session.clone());
    }
    if contents.participants.len() > MAX_SHARED_PARTICIPANTS {
        return Err(ShareError::Container(format!(
            "{} participants: a share carries at most {MAX_SHARED_PARTICIPANTS}",
            contents.participants.len()
        )));
    }
    manifest.participants = Vec::new();
    for p in &contents.participants {
        let id = &p.entry.participant.id;
        let motion = serde_json::to_vec(&p.motion).map_err(|e| json(MOTION_FILE, e))?;
        files.insert(participant_entry(id, SCENE_FILE)?, p.scene_json.clone());
        files.insert(participant_entry(id, MOTION_FILE)?, motion);
        manifest.participants.push(p.entry.clone());
    }
    files.insert(MANIFEST_FILE.to_string(), serde_json::to_vec_pretty(&manifest).map_err(|e| json(MANIFEST_FILE, e))?);
    egoexo_motion_io::npz::write_zip(&files).map_err(|e| ShareError::Container(format!("cannot write the zip: {e}")))
}

/// Reads container bytes (already opened from their envelope).
pub fn unpack(bytes: Vec<u8>) -> Result<ShareContents, ShareError> {
    let limits = Limits { max_entries: 8 + 2 * MAX_SHARED_PARTICIPANTS, max_file_bytes: MAX_ENTRY_BYTES };
    let tree = FileTree::from_zip("share", bytes, limits).map_err(|e| ShareError::Container(e.to_string()))?;
    let read = |name: &str| tree.read(name).map(|b| b.into_owned()).map_err(|e| ShareError::Container(e.to_string()));
    let manifest: ShareManifest = serde_json::from_slice(&read(MANIFEST_FILE)?)
        .map_err(|e| ShareError::Container(format!("{MANIFEST_FILE}: {e}")))?;
    if manifest.format != SHARE_FORMAT {
        return Err(ShareError::Container(format!(
            "{MANIFEST_FILE}: format is `{}`, expected `{SHARE_FORMAT}`",
            manifest.format
        )));
    }
    if !(1..=SHARE_FORMAT_VERSION).contains(&manifest.version) {
        return Err(ShareError::ContainerVersion { found: manifest.version, supported: SHARE_FORMAT_VERSION });
    }
    let read_motion = |name: &str| -> Result<SmplMotion, ShareError> {
        let motion: SmplMotion =
            serde_json::from_slice(&read(name)?).map_err(|e| ShareError::Container(format!("{name}: {e}")))?;
        SmplMotion::new(motion.fps, motion.start_ns, motion.skeleton, motion.betas, motion.poses)
            .map_err(|e| ShareError::Container(format!("{name}: {e}")))
    };
    let motion = read_motion(MOTION_FILE)?;
    let scene_json = read(SCENE_FILE)?;
    let session_egoexo = if manifest.includes_recording { Some(read(SESSION_FILE)?) } else { None };
    if manifest.participants.len() > MAX_SHARED_PARTICIPANTS {
        return Err(ShareError::Container(format!(
            "{MANIFEST_FILE}: {} participants, at most {MAX_SHARED_PARTICIPANTS} expected",
            manifest.participants.len()
        )));
    }
    let mut participants = Vec::new();
    for entry in &manifest.participants {
        let id = &entry.participant.id;
        if participants.iter().any(|p: &SharedParticipant| p.entry.participant.id == *id) {
            return Err(ShareError::Container(format!("{MANIFEST_FILE}: participant `{id}` is listed twice")));
        }
        participants.push(SharedParticipant {
            entry: entry.clone(),
            scene_json: read(&participant_entry(id, SCENE_FILE)?)?,
            motion: read_motion(&participant_entry(id, MOTION_FILE)?)?,
        });
    }
    Ok(ShareContents { manifest, scene_json, motion, session_egoexo, participants })
}
