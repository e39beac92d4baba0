//! Live reconstruction of a take as it streams in (plain Rust; the browser's message loop
//! feeds it from the relay's socket, the native tests from a recorded session).
//!
//! Frames from the relay go into a [`LiveTake`] (relay clock, every device on it). Frames are
//! numbered at the models' rate from the wearer's first head pose. A window ends at the newest
//! head pose — the frame it is nearest to — with its [`WINDOW`] frames (fewer at the start
//! of a take) at the models' rate before it, so reading out never waits for the head's next
//! sample (device clocks drift, so a fixed grid would fall just after the newest sample half
//! the time). To show frame `f` with lookahead `L`, the engine runs on the window ending at
//! `f + L` and `f` is read out of it, so the delay is at least `L` frames. Each call shows the newest frame that can
//! be shown; frames passed over while the worker was busy are counted, never queued, so
//! what is drawn is never stale. A gap in the head stream is a gap in the take (alignment
//! marks its frames invalid); nothing is repeated or invented.
//!
//! A room of several wearers: the grid is the first wearer's (whose head streamed first,
//! `LiveTake::wearers`); every other wearer is
//! reconstructed on the same window from their own devices and the observers that name them
//! (`LiveTake::to_session_of`) and drawn beside the first (`SceneData::with_others`), each in
//! their participant colour. The frame's facts are the first wearer's.
//!
//! Observers in worlds of their own (`"world": "own"` in their hello) are registered while
//! they stream ([`RollingRegistration`]): until a registration holds, each window is
//! reconstructed without them (ego-only when nobody else sees the wearer); once it holds,
//! their poses are mapped into the wearer's world and fused; a world that jumps is
//! registered again. Every frame says where each stands ([`LiveFrame::observer_worlds`]).
//!
//! Every observer whose pose in a wearer's world is known (registered, or shared) is told
//! where this viewer sees the wearer in its image ([`LiveFrame::wearer_regions`], sent by
//! [`RegionReports`]): the window's newest frame of the reconstruction projected with its
//! camera — the region a recorded session's detector step crops (paper § Ego-Guided Wearer
//! Localization), so a camera page crops there too.

use std::collections::BTreeMap;
use std::ops::Range;

use egoexo_core::aligned::{AlignedSession, Timeline};
use egoexo_core::region::{BoundingBox, DEFAULT_REGION_MARGIN, RegionProposal, propose_region};
use egoexo_infer::windows::WINDOW;
use egoexo_infer::{Engine, InferError, Method, ReconstructOptions, Reconstruction};
use egoexo_protocol::live::{ClientMessage, DataFrame, MAX_WORLD_MESSAGE_CHARS, RelayMessage, WorldState};
use egoexo_protocol::worker::{LiveFrameInfo, LiveObserverWorld, LiveTakeSummary};
use egoexo_register::RegisterError;
use egoexo_register::live::{RollingRegistration, RollingSettings, RollingState};
use egoexo_scene::SceneParticipant;
use egoexo_session::align::{AlignError, AlignOptions, align_on_timeline};
use egoexo_session::live::{FrameAdded, LiveTake, TakeError};
use thiserror::Error;

/// Why a live frame could not be made.
#[derive(Debug, Error)]
pub enum LiveError {
    #[error("the take's window cannot be aligned: {0}")]
    Align(#[from] AlignError),
    #[error(transparent)]
    Infer(#[from] InferError),
    #[error("the take's window: {0}")]
    Take(#[from] TakeError),
    #[error("the live frame's scene: {0}")]
    Scene(String),
    #[error("an observer's registration: {0}")]
    Register(#[from] RegisterError),
}

/// The most frames a lookahead may be (a window's length minus one).
pub const MAX_LOOKAHEAD: usize = WINDOW - 1;

/// Seconds of interpolation margin read around a window from the take.
const MARGIN_NS: i64 = 200_000_000;

/// How far back from the frame shown (grid frames: 133 ms at 30 Hz) an observer's keypoints
/// make the window ego-exo. A camera's keypoints reach the relay later than the wearer's head
/// pose of the same instant (a browser camera: ~100 ms of detection on a 2-core machine and
/// ~150 ms to the relay), often later than the lookahead: requiring keypoints of the very frame
/// shown left such a camera registered and never fused (CI, 2026-12-07). The fusion network
/// reads the window's newest frames without keypoints as masked, as it does any frame an
/// observer misses. Measured (`worker_tests`, 12 s wander, 2 observers, lookahead 8 = 267 ms,
/// MPJPE against the truth, ego-only 10.14 cm): keypoints 0 / 200 / 300 / 350 / 400 / 600 ms
/// late 8.79 / 8.84 / 9.36 / 9.98 / 10.21 / 10.14 cm (600 ms: ego-only). Rays much older than
/// the frame shown stop helping (with a one-second span, 600 ms late was worse than ego-only),
/// hence 4 frames; 3 would avoid the 0.07 cm lost at 400 ms but leave out a browser camera
/// ~120 ms past lookahead 4.
pub const RECENT_EXO_FRAMES: usize = 4;

/// How far back from a window's newest frame an observer's pose may be for its wearer region
/// (grid frames: 333 ms at 30 Hz): a worn camera turns, and an older pose would place the
/// region wrong. A fixed camera's one pose holds at every frame.
const REGION_POSE_FRAMES: usize = 10;

/// Where this viewer sees a wearer in an observer's image: the region it proposes to that
/// observer ([`ClientMessage::WearerRegion`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ObserverRegion {
    pub observer: String,
    /// The box around the wearer's projected joints with [`DEFAULT_REGION_MARGIN`], clipped
    /// to the image: full-image pixels of the observer's camera.
    pub region: BoundingBox,
    /// The moment it is for: the window's newest frame (relay clock, ns).
    pub at_ns: i64,
}

/// One frame to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct LiveFrame {
    /// The frame on the take's grid (0 at the wearer's first head pose).
    pub frame: usize,
    /// Its time on the relay clock, nanoseconds.
    pub timestamp_ns: i64,
    /// The window it was read out of (grid frames).
    pub window: Range<usize>,
    /// The viewer's scene of this one frame (`egoexo_scene::SceneData` as JSON).
    pub scene_json: Vec<u8>,
    /// The method that made it: ego-exo, or ego-only when no observer has keypoints within
    /// [`RECENT_EXO_FRAMES`] of this frame (or after it, within the window).
    pub method: Method,
    /// Whether the networks were a live variant trained for the reconstructor's lookahead
    /// (else the offline ones).
    pub trained_for_lookahead: bool,
    /// Observers that contributed a ray with gate ≥ 0.5 to the window within
    /// [`RECENT_EXO_FRAMES`] of this frame (or after it).
    pub exo_observers: Vec<String>,
    /// Whether the wearer's head was tracked at this frame.
    pub tracked: bool,
    /// Frames that became showable since the last frame shown but were passed over.
    pub skipped: usize,
    /// A room of several wearers: every wearer drawn, the first one (whose facts these are)
    /// first; empty for one wearer.
    pub wearers: Vec<String>,
    /// Observers in worlds of their own and where their registration stands.
    pub observer_worlds: Vec<LiveObserverWorld>,
    /// Where each observer placed in a wearer's world sees that wearer, at the window's newest
    /// frame (every wearer's, one region per observer).
    pub wearer_regions: Vec<ObserverRegion>,
}

/// A take and the state of its live reconstruction.
#[derive(Debug)]
pub struct LiveReconstructor {
    take: LiveTake,
    fps: f32,
    lookahead: usize,
    last_shown: Option<usize>,
    shown: u64,
    skipped: u64,
    registration: RollingRegistration,
    /// When the registration was last updated (relay ns).
    registration_updated_ns: Option<i64>,
}

impl LiveReconstructor {
    /// `fps`: the models' rate; `lookahead`: frames (clamped to [`MAX_LOOKAHEAD`]).
    pub fn new(fps: f32, lookahead: usize) -> Self {
        Self {
            take: LiveTake::new(),
            fps,
            lookahead: lookahead.min(MAX_LOOKAHEAD),
            last_shown: None,
            shown: 0,
            skipped: 0,
            registration: RollingRegistration::new(RollingSettings::default()),
            registration_updated_ns: None,
        }
    }

    /// The rolling registration of the observers in worlds of their own.
    pub fn registration(&self) -> &RollingRegistration {
        &self.registration
    }

    /// Where every observer in a world of its own stands, for the page.
    pub fn observer_worlds(&self) -> Vec<LiveObserverWorld> {
        self.registration
            .observers()
            .iter()
            .map(|(id, o)| {
                let r = o.registration.as_ref();
                LiveObserverWorld {
                    observer: id.clone(),
                    state: match o.state {
                        RollingState::Registering => WorldState::Registering,
                        RollingState::Registered => WorldState::Registered,
                    },
                    views_s: o.views_s,
                    registered_after_s: o.registered_after_s(),
                    yaw_deg: r.map(|r| r.yaw_deg),
                    translation_m: r.map(|r| r.translation_m()),
                    sigma_yaw_deg: r.and_then(|r| r.sigma_yaw_deg),
                    sigma_translation_m: r.and_then(|r| r.sigma_translation_m),
                    jumps: o.jumps,
                    message: o.message.clone(),
                }
            })
            .collect()
    }

    /// Updates the registration of observers in worlds of their own from the newest views
    /// (at most twice per solve interval; a solve runs only when one is due).
    fn update_registration(&mut self, engine: &Engine, newest_ns: i64, wearers: &[String]) {
        if !self.take.has_own_worlds() {
            return;
        }
        let settings = self.registration.settings();
        let step_ns = (settings.interval_s * 0.5e9) as i64;
        if self.registration_updated_ns.is_some_and(|t| newest_ns - t < step_ns) {
            return;
        }
        self.registration_updated_ns = Some(newest_ns);
        let range = newest_ns - (settings.window_s * 1e9) as i64..=newest_ns;
        for wearer in wearers {
            // A wearer without head poses in the range has nothing to register against.
            if let Ok((recent, _)) = self.take.to_session_of(wearer, "live", Some(range.clone())) {
                self.registration.update(Some(engine), &recent, newest_ns);
            }
        }
    }

    pub fn take(&self) -> &LiveTake {
        &self.take
    }

    /// The take, leaving an empty one (for "Stop and keep").
    pub fn into_take(self) -> LiveTake {
        self.take
    }

    pub fn lookahead(&self) -> usize {
        self.lookahead
    }

    pub fn set_lookahead(&mut self, frames: usize) {
        self.lookahead = frames.min(MAX_LOOKAHEAD);
    }

    /// Frames shown and passed over so far.
    pub fn counts(&self) -> (u64, u64) {
        (self.shown, self.skipped)
    }

    /// What the take holds, for the page.
    pub fn summary(&self) -> LiveTakeSummary {
        take_summary(&self.take, self.shown, self.skipped)
    }

    /// Files the relay's channel lists and calibrations; other messages are not the take's.
    pub fn handle_relay_message(&mut self, message: &RelayMessage) {
        match message {
            RelayMessage::Channels { channels } => self.take.set_channels(channels),
            RelayMessage::Calibration { device, camera } => self.take.set_camera(device, *camera),
            _ => {}
        }
    }

    pub fn add_frame(&mut self, frame: &DataFrame) -> FrameAdded {
        self.take.add_frame(frame)
    }

    fn frame_ns(&self) -> f64 {
        1e9 / f64::from(self.fps)
    }

    /// The newest head pose's time and the frame it is nearest to.
    fn newest(&self) -> Option<(i64, usize)> {
        let (first, last) = self.take.head_range_ns()?;
        Some((last, ((last - first) as f64 / self.frame_ns()).round() as usize))
    }

    /// The newest frame that can be shown now, if it is newer than the last one shown.
    pub fn next_frame(&self) -> Option<usize> {
        let (_, reached) = self.newest()?;
        let frame = reached.checked_sub(self.lookahead)?;
        (self.last_shown.is_none_or(|last| frame > last)).then_some(frame)
    }

    /// Reconstructs and returns the newest showable frame ([`LiveReconstructor::next_frame`]),
    /// or `None` when there is nothing new.
    pub fn reconstruct_next(&mut self, engine: &Engine) -> Result<Option<LiveFrame>, LiveError> {
        let Some(frame) = self.next_frame() else { return Ok(None) };
        let Some((newest_ns, _)) = self.newest() else { return Ok(None) };
        // The frame counts as shown even if it fails below, so a failing window is not retried.
        let skipped = self.last_shown.map_or(0, |last| frame - last - 1);
        self.last_shown = Some(frame);
        self.skipped += skipped as u64;
        let end = frame + self.lookahead;
        let start = (end + 1).saturating_sub(WINDOW);
        let timeline = Timeline {
            start_ns: newest_ns - ((end - start) as f64 * self.frame_ns()).round() as i64,
            fps: self.fps,
            frames: end + 1 - start,
        };
        let last_ns = timeline.timestamp_ns(timeline.frames - 1);
        let range = timeline.start_ns - MARGIN_NS..=last_ns + MARGIN_NS;
        let wearers = self.take.wearers();
        self.update_registration(engine, newest_ns, &wearers);
        let index = frame - start;
        let mut wearer_regions: Vec<ObserverRegion> = Vec::new();
        let mut reconstruct_wearer = |wearer: &str| -> Result<_, LiveError> {
            let (mut session, _) = self.take.to_session_of(wearer, "live", Some(range.clone()))?;
            self.registration.apply(&mut session)?;
            let aligned =
                align_on_timeline(&session, timeline, &AlignOptions { fps: self.fps, ..AlignOptions::default() })?;
            let (recon, scene) = reconstruct_frame(engine, &aligned, index)?;
            for region in wearer_regions_of(&aligned, &recon, last_ns) {
                if !wearer_regions.iter().any(|r| r.observer == region.observer) {
                    wearer_regions.push(region);
                }
            }
            Ok((recon, scene))
        };
        // `newest` found a head pose, so there is a first wearer.
        let Some(first) = wearers.first() else { return Ok(None) };
        let (recon, mut scene) = reconstruct_wearer(first)?;
        let method = recon.method;
        if wearers.len() > 1 {
            // Everyone else on the same window, drawn beside the first; a wearer whose head
            // poses within the window cannot make one (not yet joined, gone, too few) is not
            // drawn.
            let mut others = Vec::new();
            for (colour, wearer) in wearers.iter().enumerate().skip(1) {
                match reconstruct_wearer(wearer) {
                    Ok((_, mut other)) => {
                        other.participant = Some(SceneParticipant { id: wearer.clone(), colour });
                        others.push(other);
                    }
                    Err(LiveError::Take(TakeError::NoWearerHead(_)) | LiveError::Align(_)) => {}
                    Err(e) => return Err(e),
                }
            }
            scene.participant = Some(SceneParticipant { id: first.clone(), colour: 0 });
            scene = scene.with_others(&others);
        }
        scene.check().map_err(LiveError::Scene)?;
        let recent = recent_frames(index, end + 1 - start);
        let exo_observers = recon
            .gates
            .iter()
            .filter(|g| g.gates.get(recent.clone()).is_some_and(|f| f.iter().flatten().any(|&v| v >= 0.5)))
            .map(|g| g.observer_id.clone())
            .collect();
        self.shown += 1;
        Ok(Some(LiveFrame {
            frame,
            timestamp_ns: timeline.timestamp_ns(index),
            window: start..end + 1,
            scene_json: serde_json::to_vec(&scene).map_err(|e| LiveError::Scene(e.to_string()))?,
            method,
            trained_for_lookahead: engine.trained_for_lookahead(recon.tracking, self.lookahead),
            exo_observers,
            tracked: recon.valid.get(index).copied().unwrap_or(false),
            skipped,
            wearers: if wearers.len() > 1 { wearers } else { Vec::new() },
            observer_worlds: self.observer_worlds(),
            wearer_regions,
        }))
    }
}

/// Where each observer of `aligned` whose pose in the wearer's world is known (not masked by
/// alignment: shared, or registered) sees the wearer at the window's newest frame (`at_ns`):
/// the reconstruction's joints there projected with the observer's camera at its newest pose
/// within [`REGION_POSE_FRAMES`]. Observers the wearer is not in front of get none.
fn wearer_regions_of(aligned: &AlignedSession, recon: &Reconstruction, at_ns: i64) -> Vec<ObserverRegion> {
    let Some(newest) = aligned.timeline.frames.checked_sub(1) else { return Vec::new() };
    if !recon.valid.get(newest).copied().unwrap_or(false) {
        return Vec::new();
    }
    let Some(joints) = recon.joints.get(newest) else { return Vec::new() };
    aligned
        .observers
        .iter()
        .filter_map(|observer| {
            let head = &observer.head;
            let pose = (newest.saturating_sub(REGION_POSE_FRAMES)..=newest)
                .rev()
                .find(|&f| head.valid.get(f).copied().unwrap_or(false))
                .and_then(|f| head.poses.get(f))?;
            match propose_region(joints, &observer.camera, pose, DEFAULT_REGION_MARGIN) {
                RegionProposal::Visible { bbox, .. } => {
                    Some(ObserverRegion { observer: observer.id.clone(), region: bbox, at_ns })
                }
                RegionProposal::NotVisible(_) => None,
            }
        })
        .collect()
}

/// Reconstructs the window `aligned` and returns it with the scene of frame `index` (its rays
/// only), on the window's floor (the lowest foot over the window: steady while the feet lift).
fn reconstruct_frame(
    engine: &Engine,
    aligned: &egoexo_core::aligned::AlignedSession,
    index: usize,
) -> Result<(egoexo_infer::Reconstruction, egoexo_scene::SceneData), LiveError> {
    // Ego-exo when an observer has keypoints of a recent frame (`RECENT_EXO_FRAMES`);
    // otherwise (none connected, none streaming, or the wearer out of every view) the ego-only
    // network, which was trained without observers.
    let recent = recent_frames(index, aligned.timeline.frames);
    let has_exo =
        aligned.observers.iter().any(|o| o.keypoints[recent.clone()].iter().any(|k| k.iter().any(Option::is_some)));
    let method = if has_exo { Method::EgoExo } else { Method::EgoOnly };
    // Tracking as for a recording (`tracking: None`, `AlignedSession::tracking_mode`): 3-point
    // whenever a wrist device is connected; the network reads, frame by frame, which wrists
    // are tracked (ego feature layout v2), so a wrist arriving a sample after the head or
    // dropping out for a moment is simply untracked on those frames.
    let options = ReconstructOptions { method, tracking: None, stride: WINDOW, ..ReconstructOptions::default() };
    let recon = engine.reconstruct(aligned, &options, &mut |_| true)?;
    let one = index..index + 1;
    let mut scene = crate::scene::build_scene(&aligned.frames_slice(one.clone()), &recon.frames_slice(one), None);
    scene.floor_y = crate::scene::floor_y(&recon.joints, &recon.valid);
    Ok((recon, scene))
}

/// The frames of a window of `frames` whose observers' keypoints count for frame `index`: from
/// [`RECENT_EXO_FRAMES`] before it to the window's end.
fn recent_frames(index: usize, frames: usize) -> Range<usize> {
    index.saturating_sub(RECENT_EXO_FRAMES)..frames
}

/// What `take` holds, for the page (`shown` / `skipped`: live frames so far).
pub fn take_summary(take: &LiveTake, shown: u64, skipped: u64) -> LiveTakeSummary {
    LiveTakeSummary {
        frames: take.stats().frames,
        streams: take.frame_counts(),
        head_span_s: take.head_range_ns().map_or(0.0, |(a, b)| (b - a) as f64 / 1e9),
        shown,
        skipped,
    }
}

impl LiveFrame {
    /// The facts the page shows beside the scene.
    pub fn info(&self, lookahead: usize) -> LiveFrameInfo {
        LiveFrameInfo {
            frame: self.frame,
            timestamp_ms: self.timestamp_ns as f64 / 1e6,
            window_frames: self.window.len(),
            lookahead,
            method: self.method.name().to_string(),
            trained_for_lookahead: self.trained_for_lookahead,
            exo_observers: self.exo_observers.clone(),
            tracked: self.tracked,
            skipped: self.skipped,
            compute_ms: None,
            posted_ms: None,
            wearers: self.wearers.clone(),
            observer_worlds: self.observer_worlds.clone(),
        }
    }
}

/// What this viewer tells each observer in a world of its own about its registration
/// ([`ClientMessage::ObserverWorld`], which the relay passes to the observer so that a camera
/// page can show whether its view is used): a change of state at once, a new message at most
/// every [`WorldReports::MESSAGE_EVERY_MS`], and the same again every
/// [`WorldReports::REPEAT_EVERY_MS`] (an observer that reconnected hears it too).
#[derive(Debug, Default)]
pub struct WorldReports {
    /// Per observer: the state and message last sent, and when (viewer clock, ms).
    sent: BTreeMap<String, (WorldState, String, f64)>,
}

impl WorldReports {
    pub const MESSAGE_EVERY_MS: f64 = 1_000.0;
    pub const REPEAT_EVERY_MS: f64 = 5_000.0;

    /// The reports due at `now_ms` (the viewer's clock, ms) for a frame's `worlds`.
    pub fn due(&mut self, worlds: &[LiveObserverWorld], now_ms: f64) -> Vec<ClientMessage> {
        let mut due = Vec::new();
        for world in worlds {
            let state = world.state;
            let message: String = world.message.chars().take(MAX_WORLD_MESSAGE_CHARS).collect();
            let send = self.sent.get(&world.observer).is_none_or(|(sent_state, sent_message, at)| {
                let since_ms = now_ms - at;
                *sent_state != state
                    || (*sent_message != message && since_ms >= Self::MESSAGE_EVERY_MS)
                    || since_ms >= Self::REPEAT_EVERY_MS
            });
            if send {
                self.sent.insert(world.observer.clone(), (state, message.clone(), now_ms));
                due.push(ClientMessage::ObserverWorld { device: world.observer.clone(), state, message });
            }
        }
        due
    }
}

/// When this viewer tells an observer where it sees the wearer ([`ClientMessage::WearerRegion`]):
/// at most every [`RegionReports::EVERY_MS`] per observer — a camera page detects 7–15 frames
/// a second, and a region a frame older than the last one sent tells it little more.
#[derive(Debug, Default)]
pub struct RegionReports {
    /// Per observer: when its region was last sent (viewer clock, ms).
    sent: BTreeMap<String, f64>,
}

impl RegionReports {
    pub const EVERY_MS: f64 = 100.0;

    /// The proposals due at `now_ms` (the viewer's clock, ms) for a frame's `regions`.
    pub fn due(&mut self, regions: &[ObserverRegion], now_ms: f64) -> Vec<ClientMessage> {
        let mut due = Vec::new();
        for r in regions {
            if self.sent.get(&r.observer).is_none_or(|at| now_ms - at >= Self::EVERY_MS) {
                self.sent.insert(r.observer.clone(), now_ms);
                due.push(ClientMessage::WearerRegion { device: r.observer.clone(), region: r.region, at_ns: r.at_ns });
            }
        }
        due
    }
}

#[cfg(test)]
mod tests {
    use egoexo_core::glam::Vec2;
    use egoexo_core::region::BoundingBox;
    use egoexo_protocol::live::{ClientMessage, WorldState};
    use egoexo_protocol::worker::LiveObserverWorld;

    use super::{ObserverRegion, RegionReports, WorldReports};

    #[test]
    fn each_observer_hears_where_the_wearer_is_at_most_ten_times_a_second() {
        let mut reports = RegionReports::default();
        let region = |observer: &str, x: f32, at_ns: i64| ObserverRegion {
            observer: observer.into(),
            region: BoundingBox { min: Vec2::new(x, 10.0), max: Vec2::new(x + 50.0, 200.0) },
            at_ns,
        };
        let sent = |due: Vec<ClientMessage>| -> Vec<(String, f32, i64)> {
            due.into_iter()
                .map(|m| match m {
                    ClientMessage::WearerRegion { device, region, at_ns } => (device, region.min.x, at_ns),
                    other => panic!("{other:?}"),
                })
                .collect()
        };
        assert_eq!(sent(reports.due(&[region("tripod", 1.0, 10)], 0.0)), [("tripod".into(), 1.0, 10)]);
        assert!(reports.due(&[region("tripod", 2.0, 20)], 99.0).is_empty());
        // Each observer on its own clock of reports; the newest region goes.
        assert_eq!(
            sent(reports.due(&[region("tripod", 3.0, 30), region("phone", 4.0, 30)], 100.0)),
            [("tripod".into(), 3.0, 30), ("phone".into(), 4.0, 30)]
        );
        assert_eq!(sent(reports.due(&[region("phone", 5.0, 40)], 150.0)), []);
    }

    fn world(observer: &str, state: WorldState, message: &str) -> LiveObserverWorld {
        LiveObserverWorld {
            observer: observer.into(),
            state,
            views_s: 0.0,
            registered_after_s: None,
            yaw_deg: None,
            translation_m: None,
            sigma_yaw_deg: None,
            sigma_translation_m: None,
            jumps: 0,
            message: message.into(),
        }
    }

    fn said(reports: Vec<ClientMessage>) -> Vec<(String, WorldState, String)> {
        reports
            .into_iter()
            .map(|r| match r {
                ClientMessage::ObserverWorld { device, state, message } => (device, state, message),
                other => panic!("{other:?}"),
            })
            .collect()
    }

    #[test]
    fn observers_hear_a_new_state_at_once_a_new_message_each_second_and_the_same_every_five() {
        let mut reports = WorldReports::default();
        let registering = |s: u32| world("tripod", WorldState::Registering, &format!("registering — {s} s of views"));
        assert_eq!(said(reports.due(&[registering(3)], 0.0)).len(), 1);
        // The message changes every frame; it goes out once a second.
        assert!(reports.due(&[registering(3)], 100.0).is_empty());
        assert!(reports.due(&[registering(4)], 900.0).is_empty());
        assert_eq!(
            said(reports.due(&[registering(4)], 1_000.0)),
            [("tripod".to_string(), WorldState::Registering, "registering — 4 s of views".to_string())]
        );
        // A new state at once; the same state and message again after 5 s.
        let registered = world("tripod", WorldState::Registered, "registered after 4.2 s of views");
        assert_eq!(said(reports.due(std::slice::from_ref(&registered), 1_010.0))[0].1, WorldState::Registered);
        assert!(reports.due(std::slice::from_ref(&registered), 6_000.0).is_empty());
        assert_eq!(reports.due(std::slice::from_ref(&registered), 6_010.0).len(), 1);
        // Each observer on its own; a message over the limit is cut to it.
        let long = world("phone", WorldState::Registering, &"x".repeat(1_000));
        let out = said(reports.due(&[registered, long], 6_020.0));
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].2.chars().count(), egoexo_protocol::live::MAX_WORLD_MESSAGE_CHARS);
    }
}
