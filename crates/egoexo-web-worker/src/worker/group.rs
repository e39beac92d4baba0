//! Captures of several participants in the worker (`.egoexo` version 3, multi-device
//! recordings with people files): each participant to reconstruct is opened in turn as their
//! own one-wearer session (`Capture::session_for`: the others' cameras are its observers),
//! reconstructed by the same job as any session, and kept; one participant is *shown* — their
//! facts, plots and exports — with everyone else's body drawn in the same world
//! (`SceneData::with_others`). The page's `select-participant` changes who is shown without
//! computing anything again.
//!
//! Cameras whose people have no identity are associated first, once per capture, from every
//! participant's EgoNet pose (`egoexo_detect::people::associate_views`, what the CLI does).

use egoexo_core::association::AssociationOptions;
use egoexo_detect::people::{CoarseParticipant, ViewAssociation, associate_views};
use egoexo_protocol::worker::{AssociationSummary, ParticipantResult, ParticipantSummary};
use egoexo_register::capture::register_capture;
use egoexo_register::{Outcome, RegisterSettings};
use egoexo_scene::{SceneData, SceneParticipant};
use egoexo_session::capture::{Capture, View, ViewPeople};
use egoexo_session::format::WriteError;
use egoexo_session::import::ImportedCapture;
use egoexo_session::model::KeypointTrack;
use egoexo_session::{ImportWarning, SourceKind};
use egoexo_share::container::SharedParticipantEntry;

use super::*;

/// A capture of several participants, open in the worker.
#[derive(Debug)]
pub(super) struct Group {
    /// The capture, when it is open here (a share opened without its recording has none).
    pub capture: Option<Capture>,
    pub source: SourceKind,
    pub warnings: Vec<ImportWarning>,
    /// Every video the capture's cameras name (path in the capture → bytes).
    pub videos: BTreeMap<String, Arc<[u8]>>,
    /// Everyone in the capture, in its order.
    pub participants: Vec<ParticipantSummary>,
    /// The participant shown (index into `participants`).
    pub selected: usize,
    /// The association of the cameras' people without identity, once made.
    pub association: Option<Vec<AssociationSummary>>,
    /// Each reconstructed participant's results (index into `participants`): their own scene
    /// (with `participant` set, without the others) and summary.
    pub results: BTreeMap<usize, Results>,
}

impl Group {
    fn new(imported: ImportedCapture, videos: BTreeMap<String, Arc<[u8]>>) -> Self {
        let capture = imported.capture;
        let participants = capture
            .participants
            .iter()
            .enumerate()
            .map(|(colour, p)| {
                let mut devices = vec!["head".to_string()];
                devices.extend(p.left_wrist.as_ref().map(|_| "left_wrist".to_string()));
                devices.extend(p.right_wrist.as_ref().map(|_| "right_wrist".to_string()));
                ParticipantSummary {
                    id: p.id.clone(),
                    reconstruct: p.reconstruct,
                    colour,
                    devices,
                    camera: p
                        .camera
                        .as_ref()
                        .map(|c| format!("{} {}×{}", projection_name(&c.projection), c.width, c.height)),
                }
            })
            .collect();
        let selected = capture.reconstructed().next().unwrap_or(0);
        Group {
            capture: Some(capture),
            source: imported.source,
            warnings: imported.warnings,
            videos,
            participants,
            selected,
            association: None,
            results: BTreeMap::new(),
        }
    }

    fn index_of(&self, id: &str) -> Result<usize, WorkerError> {
        self.participants.iter().position(|p| p.id == id).ok_or_else(|| WorkerError::NoSuchParticipant(id.to_string()))
    }

    pub(super) fn scene_participant(&self, index: usize) -> SceneParticipant {
        SceneParticipant { id: self.participants[index].id.clone(), colour: self.participants[index].colour }
    }

    /// Puts keypoints found in `observer`'s video of the shown participant into the capture
    /// (replacing what it held for that pair), so the capture saves and reopens with them.
    fn assign_keypoints(&mut self, observer: &str, keypoints: KeypointTrack) {
        let target = self.participants[self.selected].id.clone();
        let Some(capture) = &mut self.capture else { return };
        capture.views.retain(|v| {
            !(v.observer == observer && matches!(&v.people, ViewPeople::Assigned { target: t, .. } if *t == target))
        });
        capture.views.push(View { observer: observer.to_string(), people: ViewPeople::Assigned { target, keypoints } });
    }
}

/// A capture's reconstruction under way ([`SessionWorker::begin_group_reconstruction`]).
#[derive(Debug)]
pub struct GroupReconstruction {
    /// The participants to reconstruct, in the capture's order.
    pub participants: Vec<String>,
    /// Who was shown when it began (shown again at the end).
    shown: Option<String>,
}

/// What a `select-participant` shows.
#[derive(Debug)]
pub struct SelectedParticipant {
    /// Their session's summary (the capture's participant as the wearer).
    pub session: SessionSummary,
    /// Their part of the reconstruction, when there is one: the summary and the scene (JSON)
    /// with everyone drawn.
    pub reconstruction: Option<(ReconstructionSummary, Vec<u8>)>,
}

fn association_summary(report: &ViewAssociation) -> AssociationSummary {
    AssociationSummary {
        observer: report.observer.clone(),
        frames: report.frames,
        detections: report.detections,
        assigned: report.assigned.clone(),
        unassigned: report.unassigned,
    }
}

fn participant_result(id: &str, summary: &ReconstructionSummary) -> ParticipantResult {
    ParticipantResult {
        id: id.to_string(),
        method: summary.method.clone(),
        tracking_points: summary.tracking_points,
        frames: summary.frames,
        valid_frames: summary.valid_frames,
        exo_evidence_frames: summary.exo_evidence_frames,
        observer_ray_frames: summary.observer_ray_frames.clone(),
        accuracy: summary.accuracy.clone(),
    }
}

/// The bytes of every video a capture's cameras name, read from `tree`.
fn capture_videos(tree: &FileTree, capture: &Capture) -> Result<BTreeMap<String, Arc<[u8]>>, WorkerError> {
    let mut videos = BTreeMap::new();
    if capture.participants.iter().all(|p| p.video.is_none()) {
        return Ok(videos);
    }
    let (_, root) = detect_source(tree)?;
    for video in capture.participants.iter().filter_map(|p| p.video.as_ref()) {
        if root.contains(&video.path) {
            videos.insert(video.path.clone(), Arc::from(root.read(&video.path)?));
        }
    }
    Ok(videos)
}

impl SessionWorker {
    /// Opens an imported capture: one wearer as a session (as before), several as a group
    /// with its first participant to reconstruct open.
    pub(super) fn open_capture(
        &mut self,
        tree: Option<&FileTree>,
        imported: ImportedCapture,
        timings: StageTimings,
    ) -> Result<SessionSummary, WorkerError> {
        self.opened = Opened::Nothing;
        if imported.capture.is_one_session() {
            let wearer = imported.capture.reconstructed().next().ok_or(WorkerError::NoSession)?;
            let session = imported.capture.session_for(wearer)?;
            let imported = Imported { session, source: imported.source, warnings: imported.warnings };
            let videos = tree.map_or(Ok(BTreeMap::new()), |tree| session_videos(tree, &imported))?;
            self.open_imported_timed(imported, timings)?;
            let open = self.opened.session_mut().ok_or(WorkerError::NoSession)?;
            open.videos = videos;
            open.summary = session_summary(&open.imported, &open.aligned, &open.videos);
            return Ok(open.summary.clone());
        }
        let videos = tree.map_or(Ok(BTreeMap::new()), |tree| capture_videos(tree, &imported.capture))?;
        // Every participant into the first one's world before association, which needs one.
        let mut imported = imported;
        let mut timings = timings;
        let engine = self.models.as_ref().map(|m| m.offline());
        let report = self.timed(&mut timings, TimedStage::Register, || {
            register_capture(engine, None, &mut imported.capture, 0, &RegisterSettings::default())
        })?;
        for p in report.participants.iter().filter(|p| p.outcome != Outcome::Kept) {
            imported.warnings.push(ImportWarning { file: p.id.clone(), message: p.message.clone() });
        }
        let group = Group::new(imported, videos);
        let first = group.selected;
        self.opened = Opened::Capture(Box::new(group), Shown::default());
        self.open_participant(first, timings)
    }

    /// Opens participant `index` of the group as the session (reconstructions kept).
    fn open_participant(&mut self, index: usize, mut timings: StageTimings) -> Result<SessionSummary, WorkerError> {
        let fps = self.fps();
        let group = self.opened.group_mut().ok_or(WorkerError::NoSession)?;
        group.selected = index;
        if group.capture.is_none() {
            // A share's participants without the recording: nothing to open.
            self.opened.shown_mut().ok_or(WorkerError::NoSession)?.session = None;
            return Err(WorkerError::NoSession);
        }
        let group = self.opened.group().ok_or(WorkerError::NoSession)?;
        let capture = group.capture.as_ref().ok_or(WorkerError::NoSession)?;
        let session = capture.session_for(index)?;
        let imported = Imported { session, source: group.source, warnings: group.warnings.clone() };
        let aligned = self.timed(&mut timings, TimedStage::Align, || align_for(&imported, fps))?;
        let summary = self.with_group(session_summary(&imported, &aligned, &group.videos));
        let open = OpenSession {
            imported,
            aligned,
            summary: summary.clone(),
            timings,
            videos: group.videos.clone(),
            detection: Vec::new(),
        };
        self.opened.shown_mut().ok_or(WorkerError::NoSession)?.session = Some(open);
        Ok(summary)
    }

    /// The participants a reconstruction of the open capture reconstructs, in order (empty
    /// for a one-wearer session).
    pub fn participants_to_reconstruct(&self) -> Vec<String> {
        let Some(group) = self.opened.group() else { return Vec::new() };
        if group.capture.is_none() {
            return Vec::new();
        }
        group.participants.iter().filter(|p| p.reconstruct).map(|p| p.id.clone()).collect()
    }

    /// `summary` (of the open session) with the capture's participants and who is shown, when
    /// a capture of several is open.
    pub(super) fn with_group(&self, mut summary: SessionSummary) -> SessionSummary {
        if let Some(group) = self.opened.group() {
            summary.participants = group.participants.clone();
            summary.participant = Some(group.participants[group.selected].id.clone());
        }
        summary
    }

    /// Starts reconstructing everyone in the open capture: the association (once), then the
    /// participants to reconstruct in turn — open each with
    /// [`Self::open_participant_for_reconstruction`] and run the usual job on it — and end
    /// with [`Self::finish_group_reconstruction`]. `None` for a one-wearer session.
    pub fn begin_group_reconstruction(&mut self) -> Result<Option<GroupReconstruction>, WorkerError> {
        let participants = self.participants_to_reconstruct();
        if participants.is_empty() {
            return Ok(None);
        }
        let shown = self.session_summary().and_then(|s| s.participant);
        self.associate_people()?;
        Ok(Some(GroupReconstruction { participants, shown }))
    }

    /// Shows again the participant shown when `run` began, everyone drawn: their summary
    /// (with everyone's rows) and scene JSON.
    pub fn finish_group_reconstruction(
        &mut self,
        run: GroupReconstruction,
    ) -> Result<(ReconstructionSummary, Vec<u8>), WorkerError> {
        if let Some(id) = &run.shown {
            self.open_participant_for_reconstruction(id)?;
        }
        self.show_group()?.ok_or(WorkerError::NoReconstruction)
    }

    /// Opens participant `id` as the session for the next steps of a capture's
    /// reconstruction (the detector step, the job).
    pub fn open_participant_for_reconstruction(&mut self, id: &str) -> Result<(), WorkerError> {
        let index = self.opened.group().ok_or(WorkerError::NoSession)?.index_of(id)?;
        self.open_participant(index, StageTimings::default()).map(|_| ())
    }

    /// Associates the capture's people without identity with its participants, once: EgoNet
    /// on every participant's own devices, their joints projected into each camera. Returns
    /// the association's figures per camera (empty when every camera's people are named).
    pub fn associate_people(&mut self) -> Result<Vec<AssociationSummary>, WorkerError> {
        let fps = self.fps();
        let group = self.opened.group_mut().ok_or(WorkerError::NoSession)?;
        if let Some(done) = &group.association {
            return Ok(done.clone());
        }
        let capture = group.capture.as_mut().ok_or(WorkerError::NoSession)?;
        if !capture.views.iter().any(|v| matches!(v.people, ViewPeople::Unassigned(_))) {
            group.association = Some(Vec::new());
            return Ok(Vec::new());
        }
        let engine = self.models.as_ref().ok_or(WorkerError::NoModels)?.offline();
        let egonet = ReconstructOptions { method: Method::EgoNet, ..ReconstructOptions::default() };
        let mut coarse = Vec::new();
        for p in capture.reconstructed().collect::<Vec<_>>() {
            let session = capture.session_for(p)?;
            let aligned = align(&session, &AlignOptions { fps, ..AlignOptions::default() })
                .map_err(|source| WorkerError::Align { session: session.name.clone(), source })?;
            let pose = engine.reconstruct(&aligned, &egonet, &mut |_| true)?;
            coarse.push((p, aligned, pose));
        }
        let participants: Vec<_> = coarse
            .iter()
            .map(|(p, aligned, pose)| CoarseParticipant { participant: *p, aligned, coarse: pose })
            .collect();
        let reports = associate_views(capture, &participants, &AssociationOptions::default());
        let summaries: Vec<_> = reports.iter().map(association_summary).collect();
        group.association = Some(summaries.clone());
        let selected = group.selected;
        self.open_participant(selected, StageTimings::default())?;
        Ok(summaries)
    }

    /// Stores the shown participant's results in the group (after the scene is serialised).
    pub(super) fn store_participant_results(&mut self) {
        let Opened::Capture(group, Shown { results: Some(results), .. }) = &mut self.opened else { return };
        group.results.insert(group.selected, results.clone());
    }

    /// What is shown of a capture: the shown participant's results with everyone's bodies in
    /// the scene and every participant's row in the summary. `None` for a one-wearer session.
    pub fn show_group(&mut self) -> Result<Option<(ReconstructionSummary, Vec<u8>)>, WorkerError> {
        let Some(group) = self.opened.group() else { return Ok(None) };
        let shown = group.results.get(&group.selected).ok_or(WorkerError::NoReconstruction)?;
        let parse = |json: &[u8]| -> Result<SceneData, WorkerError> {
            serde_json::from_slice(json).map_err(|e| WorkerError::Scene(e.to_string()))
        };
        let others = group
            .results
            .iter()
            .filter(|&(&i, _)| i != group.selected)
            .map(|(_, r)| parse(&r.scene_json))
            .collect::<Result<Vec<_>, _>>()?;
        let scene = parse(&shown.scene_json)?.with_others(&others);
        scene.check().map_err(WorkerError::Scene)?;
        let scene_json = serde_json::to_vec(&scene).map_err(|e| WorkerError::Scene(e.to_string()))?;
        let mut summary = shown.summary.clone();
        summary.participants =
            group.results.iter().map(|(&i, r)| participant_result(&group.participants[i].id, &r.summary)).collect();
        summary.association = group.association.clone().unwrap_or_default();
        let mut shown = shown.clone();
        shown.summary = summary.clone();
        shown.scene_json = scene_json.clone();
        self.opened.shown_mut().ok_or(WorkerError::NoSession)?.results = Some(shown);
        Ok(Some((summary, scene_json)))
    }

    /// Shows participant `id` of the open capture (or share of one).
    pub fn select_participant(&mut self, id: &str) -> Result<SelectedParticipant, WorkerError> {
        let group = self.opened.group_mut().ok_or(WorkerError::NoSession)?;
        let index = group.index_of(id)?;
        if !group.participants[index].reconstruct {
            return Err(WorkerError::NotReconstructed(id.to_string()));
        }
        group.selected = index;
        let shared_session = group.results.get(&index).map(|r| r.session.clone());
        let session = if group.capture.is_some() {
            self.open_participant(index, StageTimings::default())?
        } else {
            shared_session.clone().ok_or(WorkerError::NoReconstruction)?
        };
        let reconstruction = match shared_session {
            Some(_) => self.show_group()?,
            None => None,
        };
        Ok(SelectedParticipant { session, reconstruction })
    }

    /// Keypoints the detector step found for the shown participant in `observer`'s video go
    /// into the capture too.
    pub(super) fn keep_detected_keypoints(&mut self, observer: &str, keypoints: KeypointTrack) {
        if let Some(group) = self.opened.group_mut() {
            group.assign_keypoints(observer, keypoints);
        }
    }

    /// The open capture (when one is open) as a `.egoexo` of version 3, with its videos when
    /// `with_videos`: its name and the bytes.
    pub(super) fn capture_zip(&self, with_videos: bool) -> Option<(String, Result<Vec<u8>, WriteError>)> {
        let group = self.opened.group()?;
        let capture = group.capture.as_ref()?;
        let videos = if with_videos {
            group.videos.iter().map(|(path, bytes)| (path.clone(), bytes.to_vec())).collect()
        } else {
            BTreeMap::new()
        };
        Some((capture.name.clone(), egoexo_session::format::write_capture_zip(capture, videos)))
    }

    /// Every reconstructed participant's part of what is shown, for a share.
    pub(super) fn shared_participants(&self) -> Vec<egoexo_share::SharedParticipant> {
        let Some(group) = self.opened.group() else { return Vec::new() };
        group
            .results
            .iter()
            .map(|(&i, r)| egoexo_share::SharedParticipant {
                entry: SharedParticipantEntry {
                    participant: group.participants[i].clone(),
                    summary: r.summary.clone(),
                    session: r.session.clone(),
                },
                scene_json: r.scene_json.clone(),
                motion: r.motion.clone(),
            })
            .collect()
    }

    /// Opens the participants of a share: a group of their results (with the capture, when
    /// the share's recording opened one), the shared one shown — and, with the capture, their
    /// session open.
    pub(super) fn open_shared_participants(
        &mut self,
        shared: Vec<egoexo_share::SharedParticipant>,
        shown: Option<&str>,
    ) -> Result<(), WorkerError> {
        if shared.is_empty() {
            return Ok(());
        }
        if self.opened.group().is_none() {
            let group = Group {
                capture: None,
                source: SourceKind::Egoexo,
                warnings: Vec::new(),
                videos: BTreeMap::new(),
                participants: shared.iter().map(|p| p.entry.participant.clone()).collect(),
                selected: 0,
                association: None,
                results: BTreeMap::new(),
            };
            // The share opened as one wearer (its shown results, maybe its recording): the
            // same shown, now a capture's.
            let shown = match std::mem::take(&mut self.opened) {
                Opened::Wearer(shown) => shown,
                Opened::Nothing | Opened::Capture(..) => Shown::default(),
            };
            self.opened = Opened::Capture(Box::new(group), shown);
        }
        // The association came with the shown participant's summary.
        let association = self.opened.results().map(|r| r.summary.association.clone());
        let group = self.opened.group_mut().ok_or(WorkerError::NoSession)?;
        for p in shared {
            let index = group.index_of(&p.entry.participant.id)?;
            let results = Results {
                name: p.entry.session.name.clone(),
                method: p.entry.summary.method.clone(),
                motion: p.motion,
                scene_json: p.scene_json,
                summary: p.entry.summary,
                session: p.entry.session,
                made_here: None,
            };
            group.results.insert(index, results);
        }
        if let Some(id) = shown {
            group.selected = group.index_of(id)?;
        }
        group.association = association;
        if group.capture.is_some() {
            let selected = group.selected;
            self.open_participant(selected, StageTimings::default())?;
        }
        Ok(())
    }
}
