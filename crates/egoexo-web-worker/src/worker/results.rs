//! What is done with the results: the scene, exports, shares (packed and opened), saving the
//! session, and a live take kept as the open session.

use super::*;

/// A share opened by [`SessionWorker::open_share`].
#[derive(Clone, Debug, PartialEq)]
pub struct OpenedShare {
    pub manifest: ShareManifest,
    /// The viewer's scene (JSON).
    pub scene_json: Vec<u8>,
}

/// A file made by [`SessionWorker::export`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExportedFile {
    pub bytes: Vec<u8>,
    /// `<session>-<method>.<extension>`.
    pub file_name: String,
    pub mime_type: &'static str,
}

/// The motion file format of a protocol export format.
pub fn motion_format(format: ExportFormat) -> Format {
    match format {
        ExportFormat::Npz => Format::Npz,
        ExportFormat::Bvh => Format::Bvh,
        ExportFormat::Glb => Format::Glb,
        ExportFormat::Csv => Format::Csv,
    }
}

impl SessionWorker {
    /// The models' frame rate, for a [`LiveReconstructor`](crate::live::LiveReconstructor).
    pub fn live_fps(&self) -> f32 {
        self.fps()
    }

    /// Reconstructs the newest frame of a live take that can be shown, if any.
    pub fn live_frame(
        &self,
        live: &mut crate::live::LiveReconstructor,
    ) -> Result<Option<crate::live::LiveFrame>, WorkerError> {
        let models = self.models.as_ref().ok_or(WorkerError::NoModels)?;
        Ok(live.reconstruct_next(models.for_lookahead(live.lookahead()))?)
    }

    /// "Stop and keep": the take becomes the open session (replacing any), ready for the
    /// offline reconstruction, exports, sharing and [`SessionWorker::save_session`].
    pub fn keep_take(
        &mut self,
        take: &egoexo_session::live::LiveTake,
        name: &str,
    ) -> Result<SessionSummary, WorkerError> {
        if take.wearers().len() > 1 {
            // Several wearers: the take is a capture of them all, opened like a dropped one.
            let (capture, warnings) = take.to_capture(name)?;
            let imported = egoexo_session::import::ImportedCapture {
                capture,
                source: egoexo_session::SourceKind::Egoexo,
                warnings,
            };
            return self.open_capture(None, imported, StageTimings::default());
        }
        let (session, warnings) = take.to_session(name, None)?;
        self.open_imported(Imported { session, source: egoexo_session::SourceKind::Egoexo, warnings })
    }

    /// The open session as a `.egoexo` file.
    pub fn save_session(&self) -> Result<ExportedFile, WorkerError> {
        let open = self.opened.session().ok_or(WorkerError::NoSession)?;
        // A capture of several participants is saved whole (version 3), with every keypoint
        // the detector step found.
        if let Some((name, bytes)) = self.capture_zip(true) {
            return Ok(ExportedFile {
                bytes: bytes.map_err(|e| WorkerError::SaveSession(e.to_string()))?,
                file_name: format!("{}.egoexo", file_name(&name)),
                mime_type: "application/zip",
            });
        }
        // The observers' videos go with it: a saved session opens again as it was.
        let videos = open.videos.iter().map(|(path, bytes)| (path.clone(), bytes.to_vec())).collect();
        let bytes = write_egoexo_zip_with(&open.imported.session, videos)
            .map_err(|e| WorkerError::SaveSession(e.to_string()))?;
        let name = file_name(&open.imported.session.name);
        Ok(ExportedFile { bytes, file_name: format!("{name}.egoexo"), mime_type: "application/zip" })
    }

    /// The last reconstruction made here (the full method), if any.
    pub fn reconstruction(&self) -> Option<&Reconstruction> {
        self.opened.results().and_then(|r| r.made_here.as_ref()).map(|(ego_exo, _)| ego_exo)
    }

    /// The ego-only reconstruction of the overlay, if any.
    pub fn ego_only_reconstruction(&self) -> Option<&Reconstruction> {
        self.opened.results().and_then(|r| r.made_here.as_ref()).and_then(|(_, ego_only)| ego_only.as_ref())
    }

    /// The summary of the last reconstruction.
    pub fn reconstruction_summary(&self) -> Option<&ReconstructionSummary> {
        self.opened.results().map(|r| &r.summary)
    }

    /// The viewer's scene of what is shown ([`egoexo_scene::SceneData`]) as JSON.
    pub fn scene_json(&self) -> Result<Vec<u8>, WorkerError> {
        Ok(self.opened.results().ok_or(WorkerError::NoReconstruction)?.scene_json.clone())
    }

    /// Writes the shown motion (the full method) in `format`.
    pub fn export(&self, format: ExportFormat) -> Result<ExportedFile, WorkerError> {
        let results = self.opened.results().ok_or(WorkerError::NoReconstruction)?;
        let format = motion_format(format);
        let bytes = egoexo_motion_io::write(format, &results.motion)?;
        Ok(ExportedFile {
            bytes,
            file_name: format!("{}-{}.{}", file_name(&results.name), results.method, format.extension()),
            mime_type: format.mime_type(),
        })
    }

    /// What is shown, as a share container (`egoexo_share::container`; not yet sealed),
    /// with the recording as a `.egoexo` session when `include_recording` and the session is
    /// open here. `created_by` names the app (`egoexo 0.1.0 (page)`).
    pub fn pack_share(&self, include_recording: bool, created_by: &str) -> Result<Vec<u8>, WorkerError> {
        let results = self.opened.results().ok_or(WorkerError::NoReconstruction)?;
        // The recording: a capture of several participants whole, else the open session.
        let session_egoexo = match (self.opened.session(), include_recording) {
            (Some(open), true) => Some(
                match self.capture_zip(false) {
                    Some((_, bytes)) => bytes,
                    None => write_egoexo_zip(&open.imported.session),
                }
                .map_err(|e| WorkerError::ShareRecording(e.to_string()))?,
            ),
            _ => None,
        };
        let contents = ShareContents {
            manifest: ShareManifest::new(&results.name, created_by, results.summary.clone(), results.session.clone()),
            scene_json: results.scene_json.clone(),
            motion: results.motion.clone(),
            session_egoexo,
            participants: self.shared_participants(),
        };
        Ok(egoexo_share::pack(&contents)?)
    }

    /// Whether a share made now could include the recording (a session is open here).
    pub fn can_share_recording(&self) -> bool {
        self.opened.session().is_some()
    }

    /// Opens a share container (already opened from its envelope): shows its scene and motion
    /// (exports work), and when it includes the recording, opens that session so it can be
    /// reconstructed again.
    pub fn open_share(&mut self, container: Vec<u8>) -> Result<OpenedShare, WorkerError> {
        let contents = egoexo_share::unpack(container)?;
        self.opened = Opened::Nothing;
        if let Some(recording) = contents.session_egoexo {
            let name = format!("{}.egoexo", contents.manifest.name);
            self.import(&FileTree::from_zip(name, recording, Limits::default())?)?;
        }
        let manifest = contents.manifest;
        let shown = Results {
            name: manifest.name.clone(),
            method: manifest.summary.method.clone(),
            motion: contents.motion,
            scene_json: contents.scene_json.clone(),
            summary: manifest.summary.clone(),
            session: manifest.session.clone(),
            made_here: None,
        };
        // A share without its recording opens as a wearer with results and no session.
        match self.opened.shown_mut() {
            Some(opened) => opened.results = Some(shown),
            None => self.opened = Opened::Wearer(Shown { session: None, results: Some(shown) }),
        }
        self.open_shared_participants(contents.participants, manifest.summary.participant.as_deref())?;
        Ok(OpenedShare { manifest, scene_json: contents.scene_json })
    }
}
