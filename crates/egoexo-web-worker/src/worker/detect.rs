//! The detector step's side of [`SessionWorker`]: which observers need it, the detector
//! model, and a [`DetectionTask`] whose keypoints go into the open session.

use super::*;

impl SessionWorker {
    /// Observers of the open session whose keypoints the detector step finds first (video
    /// and no keypoints), by id.
    pub fn observers_needing_detection(&self) -> Vec<String> {
        let Some(open) = self.opened.session() else { return Vec::new() };
        observers_needing_detection(&open.imported.session)
            .into_iter()
            .map(|o| open.imported.session.observers[o].id.clone())
            .collect()
    }

    /// The detector's file in the models folder, when the manifest has one.
    pub fn detector_file(&self) -> Option<ModelFileRef> {
        let file = &self.manifest.as_ref()?.detector.as_ref()?.file;
        Some(ModelFileRef { file: file.file.clone(), sha256: file.sha256.clone(), bytes: file.bytes })
    }

    /// Whether the detector is loaded.
    pub fn has_detector(&self) -> bool {
        self.detector.is_some()
    }

    /// Loads the detector from its file's bytes (sha256-checked against the manifest).
    pub fn load_detector(&mut self, bytes: &[u8]) -> Result<(), WorkerError> {
        let manifest = self.manifest.as_ref().ok_or(WorkerError::NoModels)?;
        let observer = self.observers_needing_detection().into_iter().next().unwrap_or_default();
        let entry = manifest.detector.as_ref().ok_or(crate::detection::DetectionError::NoDetector(observer))?;
        self.detector = Some(Arc::new(KeypointDetector::load(entry, bytes).map_err(WorkerError::Infer)?));
        Ok(())
    }

    /// Starts the detector step for the open session ([`Self::observers_needing_detection`];
    /// `None` when there are none): EgoNet's coarse pose over the session (one pass) plans
    /// every video frame's crop window. Hand each decoded frame's crop to
    /// [`DetectionTask::detect_crop`], then call [`Self::finish_detection`].
    pub fn start_detection(&mut self) -> Result<Option<DetectionTask>, WorkerError> {
        let Some(first) = self.observers_needing_detection().into_iter().next() else { return Ok(None) };
        let detector = match &self.detector {
            Some(detector) => detector.clone(),
            None if self.detector_file().is_none() => {
                return Err(crate::detection::DetectionError::NoDetector(first).into());
            }
            None => return Err(WorkerError::NoDetectorLoaded),
        };
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let fps = self.fps();
        let open = self.opened.session_mut().ok_or(WorkerError::NoSession)?;
        if open.aligned.timeline.fps != fps {
            open.aligned = align_for(&open.imported, fps)?;
        }
        let options = ReconstructOptions { method: Method::EgoNet, ..ReconstructOptions::default() };
        let coarse = engine.reconstruct(&open.aligned, &options, &mut |_| true)?;
        let session = &open.imported.session;
        let mut observers = Vec::new();
        for o in observers_needing_detection(session) {
            let observer = &session.observers[o];
            let path = observer.video.as_ref().map(|v| v.path.clone()).unwrap_or_default();
            let mp4 = open.videos.get(&path).cloned().ok_or_else(|| {
                crate::detection::DetectionError::MissingVideo { observer: observer.id.clone(), path: path.clone() }
            })?;
            let plan = plan_observer(session, &open.aligned, &coarse, o, &mp4)
                .map_err(crate::detection::DetectionError::from)?;
            observers.push(ObserverDetectionJob::new(plan, mp4));
        }
        Ok(Some(DetectionTask { detector, observers }))
    }

    /// Puts the keypoints `task` found into the open session (which is aligned again; later
    /// jobs skip the step) and returns what was done per observer.
    pub fn finish_detection(&mut self, task: DetectionTask) -> Result<Vec<protocol::DetectionSummary>, WorkerError> {
        let fps = self.fps();
        let open = self.opened.session_mut().ok_or(WorkerError::NoSession)?;
        let mut summaries = Vec::new();
        let mut found = Vec::new();
        for (o, track, summary) in task.finish() {
            let observer = open.imported.session.observers.get_mut(o).ok_or(WorkerError::NoSession)?;
            found.push((observer.id.clone(), track.clone()));
            observer.keypoints = Some(track);
            summaries.push(summary);
        }
        open.aligned = align_for(&open.imported, fps)?;
        open.detection = summaries.clone();
        let summary = session_summary(&open.imported, &open.aligned, &open.videos);
        // In a capture, the found keypoints are the capture's too (saved, shared, reopened).
        for (id, track) in found {
            self.keep_detected_keypoints(&id, track);
        }
        let summary = self.with_group(summary);
        self.opened.session_mut().ok_or(WorkerError::NoSession)?.summary = summary;
        Ok(summaries)
    }
}
