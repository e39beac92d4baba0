//! What the worker reports about sessions, models, reconstructions, live takes and its pool:
//! the summaries carried by [`WorkerEvent`](super::WorkerEvent)s.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::live::WorldState;

/// What a live take holds.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LiveTakeSummary {
    /// Frames kept, in all.
    pub frames: u64,
    /// Frames kept per device and stream (`wearer` → `head` → 1234).
    pub streams: BTreeMap<String, BTreeMap<String, u64>>,
    /// Seconds from the wearer's first to last head pose.
    pub head_span_s: f64,
    /// Live frames shown, and passed over because the worker was busy.
    pub shown: u64,
    pub skipped: u64,
}

/// A live frame's facts (beside its scene).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LiveFrameInfo {
    /// The frame's number, at 30 fps from the take's first head pose.
    pub frame: usize,
    /// When it happened, relay clock, Unix milliseconds.
    pub timestamp_ms: f64,
    /// The frames its window spans and the lookahead it was read out at.
    pub window_frames: usize,
    pub lookahead: usize,
    /// `ego-exo`, or `ego-only` when no observer has keypoints of this frame.
    pub method: String,
    /// Whether the networks were trained for this lookahead (a live variant); `false`: the
    /// offline networks, trained for windows read out near their centre.
    #[serde(default)]
    pub trained_for_lookahead: bool,
    /// Observers whose rays (gate ≥ 0.5) shaped this frame.
    pub exo_observers: Vec<String>,
    /// Whether the wearer's head was tracked at this frame.
    pub tracked: bool,
    /// Frames passed over before it (the worker was busy).
    pub skipped: usize,
    /// What making it took in the worker (the take's window, alignment, engine, scene),
    /// milliseconds, by the glue's clock (`None` without one).
    pub compute_ms: Option<f64>,
    /// When the worker posted it, Unix milliseconds by the glue's clock (the worker's own
    /// clock; `None` without one): with the page's offset to the relay clock it splits the
    /// latency into the part up to the worker's post and the part after.
    #[serde(default)]
    pub posted_ms: Option<f64>,
    /// A room of several wearers: every wearer drawn, the one `frame`'s facts are about
    /// first (added in version 6; absent for one wearer).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub wearers: Vec<String>,
    /// Observers in worlds of their own (their hello said `"world": "own"`) and where their
    /// registration stands (added in version 6; absent when every device shares the room's
    /// world).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub observer_worlds: Vec<LiveObserverWorld>,
}

/// A live observer in a world of its own, as the worker's rolling registration sees it
/// (`docs/registration.md`, "Live").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LiveObserverWorld {
    pub observer: String,
    /// `registering` (not fused: the wearer is reconstructed without it) or `registered`
    /// (fused): the word the relay passes on to the observer ([`WorldState`]).
    pub state: WorldState,
    /// Seconds of its views (frames with keypoints) in its current world so far.
    pub views_s: f64,
    /// Seconds from its first view to its registration (relay clock).
    pub registered_after_s: Option<f64>,
    /// The registration fused: `p_wearer_world = R_y(yaw_deg) · p_observer_world +
    /// translation_m`, with 1σ.
    pub yaw_deg: Option<f64>,
    pub translation_m: Option<[f64; 3]>,
    pub sigma_yaw_deg: Option<f64>,
    pub sigma_translation_m: Option<f64>,
    /// Times its world jumped (a re-centred headset) and it was registered again.
    pub jumps: u32,
    /// In words, for the device list.
    pub message: String,
}

/// One file a models manifest lists.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelFileRef {
    /// Path relative to the models folder.
    pub file: String,
    /// Lowercase hex sha256 the file must have.
    pub sha256: String,
    pub bytes: u64,
}

/// The networks of one tracking mode.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelSetSummary {
    pub tracking_points: u8,
    pub max_observers: usize,
    pub hidden_dim: usize,
    /// A live variant's read-out lookahead (frames); `None` for the offline networks.
    #[serde(default)]
    pub lookahead: Option<usize>,
}

/// The loaded models.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelsSummary {
    pub model_sets: Vec<ModelSetSummary>,
    /// Total size of the ONNX files.
    pub bytes: u64,
    /// How long the worker took, by the glue's clock (absent without one; added within
    /// version 3): reading the manifest and the files (Cache API or network), ms.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub read_ms: Option<u32>,
    /// ... checking every file's sha256 and loading it (tract: parse, optimise), ms.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_ms: Option<u32>,
    /// Files that came from the Cache API (the others from the network).
    #[serde(default)]
    pub cached_files: usize,
}

/// One observer of an imported session.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ObserverSummary {
    pub id: String,
    /// Projection model and image size, e.g. `fisheye624 1408×1408`.
    pub camera: String,
    /// Timeline frames with at least one 2D keypoint.
    pub keypoint_frames: usize,
    /// The observer's video (its path in the session), when it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<String>,
    /// Whether a reconstruction first finds its keypoints in that video (it has none yet).
    #[serde(default)]
    pub needs_detection: bool,
    /// Its world against the wearer's, in words: as given, registered (with the transform and
    /// its 1σ), or why it is not (docs/registration.md).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub world: String,
    /// Whether its rays are fused (its world is the wearer's, as given or registered).
    #[serde(default = "fused_by_default")]
    pub fused: bool,
}

fn fused_by_default() -> bool {
    true
}

/// An imported session, on the models' timeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionSummary {
    pub name: String,
    /// What the input was recognised as (`.egoexo session`, `Nymeria sequence`, …).
    pub source: String,
    /// Frames of the aligned timeline.
    pub frames: usize,
    pub fps: f32,
    pub duration_s: f32,
    /// Wearer devices: `head`, and `left_wrist` / `right_wrist` when tracked.
    pub devices: Vec<String>,
    /// 1 (glasses) or 3 (glasses + both wrists): the model a reconstruction uses by default.
    pub tracking_points: u8,
    /// How the 3-point model uses wrists that are tracked only part of the time (hand
    /// tracking), or that only one wrist exists; `None` when the wrists are complete or absent.
    #[serde(default)]
    pub tracking_reason: Option<String>,
    /// Per wrist the session has: where it comes from and how much of the timeline it covers.
    #[serde(default)]
    pub wrists: Vec<WristSummary>,
    /// The floor's height and how it was found.
    #[serde(default)]
    pub floor: Option<FloorSummary>,
    pub observers: Vec<ObserverSummary>,
    /// Whether the session carries ground-truth motion.
    pub ground_truth: bool,
    /// What the import noticed (each `file: message`).
    pub warnings: Vec<String>,
    /// A capture of several participants (`.egoexo` version 3, a multi-device recording with
    /// people files): everyone in it, in the capture's order; empty for one wearer. The rest
    /// of the summary is about `participant`'s session (the others are its observers).
    /// (Added in version 6.)
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub participants: Vec<ParticipantSummary>,
    /// The participant shown, in a capture of several.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub participant: Option<String>,
}

/// One participant of a capture ([`SessionSummary::participants`]).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ParticipantSummary {
    pub id: String,
    /// Whether the capture reconstructs them (else they are only an observer).
    pub reconstruct: bool,
    /// Their colour in the viewer: an index into the page's participant palette, fixed by the
    /// capture's order so it does not change with the selection.
    pub colour: usize,
    /// Their devices: `head`, and `left_wrist` / `right_wrist` when tracked.
    pub devices: Vec<String>,
    /// Their camera (projection and image size), when it sees the others.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<String>,
}

/// One wrist of the wearer on the timeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WristSummary {
    /// `left` or `right`.
    pub side: String,
    /// Where its poses come from (wrist devices, MPS hand tracking and its form).
    pub source: String,
    /// Timeline frames on which it is tracked, percent.
    pub tracked_percent: f32,
    /// The longest stretch without it, seconds.
    pub longest_gap_s: f32,
}

/// The floor under the wearer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FloorSummary {
    /// World Y, metres.
    pub height_m: f32,
    /// How it was found, in words.
    pub source: String,
}

/// Errors against ground truth, where the session has it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Accuracy {
    /// Frames scored (reconstructed and with ground truth).
    pub frames: usize,
    pub ego_exo_mpjpe_cm: f64,
    pub ego_only_mpjpe_cm: Option<f64>,
}

/// How often each network ran for one job (one run = one 96-frame window).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct NetworkRuns {
    pub egonet: u64,
    pub gate: u64,
    pub fusion: u64,
    /// Runs of the fusion with every observer masked as its own graph (the ego-only overlay
    /// when the models ship it; added within version 3, 0 from a peer that does not send it).
    #[serde(default)]
    pub fusion_ego_only: u64,
}

/// A finished reconstruction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReconstructionSummary {
    pub method: String,
    pub tracking_points: u8,
    pub frames: usize,
    /// Frames with valid wearer tracking (the rest hold the nearest valid pose).
    pub valid_frames: usize,
    /// 96-frame windows over the tracked frames.
    pub windows: usize,
    /// Network runs of this job: EgoNet once per window, shared by ego-exo and the overlay.
    pub network_runs: NetworkRuns,
    /// Frames where an observer ray had gate ≥ 0.5.
    pub exo_evidence_frames: usize,
    /// Per observer: frames where it contributed at least one ray.
    pub observer_ray_frames: BTreeMap<String, usize>,
    pub accuracy: Option<Accuracy>,
    /// Where the job's time went, per stage in pipeline order (import and align of the open
    /// session, the engine's stages, the scene); empty when the worker has no clock.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub timings: Vec<StageTiming>,
    /// How a pool of workers shared the job; absent when one worker ran it all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pool: Option<PoolSummary>,
    /// The detector step of this job, per observer whose keypoints it found in video (the
    /// session keeps them: later jobs skip the step).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub detection: Vec<DetectionSummary>,
    /// A capture of several participants: the participant this summary is about (the rest of
    /// its fields), in `participants`' order. (Added in version 6.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub participant: Option<String>,
    /// Every participant the job reconstructed, in the capture's order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub participants: Vec<ParticipantResult>,
    /// Who is who in the cameras whose people had no identity, per camera.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub association: Vec<AssociationSummary>,
}

/// One participant's reconstruction ([`ReconstructionSummary::participants`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParticipantResult {
    pub id: String,
    pub method: String,
    pub tracking_points: u8,
    pub frames: usize,
    pub valid_frames: usize,
    pub exo_evidence_frames: usize,
    /// Per observer (the other participants' cameras): frames it contributed a ray.
    pub observer_ray_frames: BTreeMap<String, usize>,
    pub accuracy: Option<Accuracy>,
}

/// The association of one camera's people without identity with the participants
/// ([`ReconstructionSummary::association`]).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AssociationSummary {
    /// The participant whose camera it is.
    pub observer: String,
    /// Frames of its people file.
    pub frames: usize,
    /// People detected over all frames.
    pub detections: usize,
    /// Detections assigned, per participant id.
    pub assigned: BTreeMap<String, usize>,
    /// Detections that matched nobody (bystanders).
    pub unassigned: usize,
}

/// What the detector step did for one observer ([`ReconstructionSummary::detection`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectionSummary {
    pub observer: String,
    /// The video's path in the session.
    pub video: String,
    /// Video frames decoded.
    pub frames: usize,
    /// Frames with the wearer's region, each one detection.
    pub detected: usize,
    /// Detections whose left and right sides were exchanged to agree with EgoNet's pose.
    pub mirrored: usize,
    /// Decoding, cropping and detecting, milliseconds (absent without a clock).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ms: Option<f64>,
}

/// How a pool of workers shared a reconstruction ([`ReconstructionSummary::pool`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct PoolSummary {
    /// Workers in the pool, the page's worker (the coordinator) included.
    pub workers: usize,
    /// Chunks of `chunk_windows` windows in the job.
    pub chunks: usize,
    pub chunk_windows: usize,
    /// Chunks the helpers computed (the coordinator computed the rest).
    pub helper_chunks: usize,
    /// Helpers that failed during the job (their chunks were computed again elsewhere).
    pub failed_helpers: usize,
}

/// One stage's time in a job ([`ReconstructionSummary::timings`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageTiming {
    /// `import`, `align`, `ego-features`, `egonet`, `exo-features`, `gate`, `fusion`,
    /// `decode` or `scene`.
    pub stage: String,
    /// Milliseconds, summed over its calls.
    pub ms: f64,
    /// How many times it ran (windows, for the engine's stages).
    pub calls: u32,
}
