//! The live reconstruction natively: the fixture session streamed frame by frame into a
//! [`LiveReconstructor`] as the relay delivers it (channel list, calibrations, then every
//! device's frames in time order), a frame reconstructed whenever one can be shown.
#![cfg(not(target_arch = "wasm32"))]

use std::sync::Arc;

use crate::common::*;
use egoexo_infer::{InferError, Method};
use egoexo_protocol::live::{
    ChannelInfo, DataFrame, DeviceHello, DeviceMount, DeviceRole, DeviceWorld, FramePayload, RelayMessage, Stream,
    WorldState,
};
use egoexo_scene::SceneData;
use egoexo_session::{FileTree, ImportOptions, Limits, Session, import_session};
use egoexo_synth::worlds::{WorldPerturbation, perturb_observer_worlds, unpose_static_cameras};
use egoexo_web_worker::SessionWorker;
use egoexo_web_worker::live::{LiveFrame, LiveReconstructor};

fn worker() -> SessionWorker {
    worker_with(MANIFEST)
}

fn worker_with(manifest: &[u8]) -> SessionWorker {
    let mut worker = SessionWorker::new();
    worker
        .load_models(manifest, |file| {
            model_file(file).map(<[u8]>::to_vec).ok_or(InferError::ReadModel { file: file.into(), message: "?".into() })
        })
        .unwrap();
    worker
}

fn session() -> Session {
    let tree = FileTree::from_zip(SESSION_NAME, Arc::<[u8]>::from(SESSION), Limits::default()).unwrap();
    import_session(&tree, &ImportOptions::default()).unwrap().session
}

/// The relay's view of the session: its channel list, calibrations and frames in time order.
fn as_relay(session: &Session, observers: bool) -> (Vec<RelayMessage>, Vec<DataFrame>) {
    let mut channels = Vec::new();
    let mut frames = Vec::new();
    let world_of = |o: &egoexo_session::model::Observer| match o.placement.world {
        egoexo_session::placement::WorldRef::Own => DeviceWorld::Own,
        egoexo_session::placement::WorldRef::Shared => DeviceWorld::Shared,
    };
    let mut add = |device: &str, role, stream, t: &egoexo_session::model::Trajectory, world| {
        let channel = channels.len() as u16;
        let hello = DeviceHello { world, ..DeviceHello::worn(device, role, vec![]) };
        channels.push(ChannelInfo::of(channel, &hello, stream));
        for (ts, pose) in t.timestamps_ns.iter().zip(&t.poses) {
            frames.push(DataFrame { channel, timestamp_ns: *ts, payload: FramePayload::Pose(Some(*pose)) });
        }
    };
    let w = &session.wearer;
    add("wearer", DeviceRole::Wearer, Stream::Head, &w.head, DeviceWorld::Shared);
    add("wearer", DeviceRole::Wearer, Stream::LeftWrist, w.left_wrist.as_ref().unwrap(), DeviceWorld::Shared);
    add("wearer", DeviceRole::Wearer, Stream::RightWrist, w.right_wrist.as_ref().unwrap(), DeviceWorld::Shared);
    let mut messages = Vec::new();
    for o in session.observers.iter().filter(|_| observers) {
        add(&o.id, DeviceRole::Observer, Stream::Head, &o.head, world_of(o));
        messages.push(RelayMessage::Calibration { device: o.id.clone(), camera: o.camera });
    }
    for o in session.observers.iter().filter(|_| observers) {
        let channel = channels.len() as u16;
        let hello = DeviceHello { world: world_of(o), ..DeviceHello::worn(&o.id, DeviceRole::Observer, vec![]) };
        channels.push(ChannelInfo::of(channel, &hello, Stream::Keypoints));
        let k = o.keypoints.as_ref().unwrap();
        for (ts, points) in k.timestamps_ns.iter().zip(&k.frames) {
            frames.push(DataFrame { channel, timestamp_ns: *ts, payload: FramePayload::Keypoints(*points) });
        }
    }
    frames.sort_by_key(|f| f.timestamp_ns);
    messages.insert(0, RelayMessage::Channels { channels });
    (messages, frames)
}

#[test]
fn a_streamed_take_is_shown_frame_by_frame_at_the_models_rate_and_kept() {
    let mut worker = worker();
    let session = session();
    let (messages, frames) = as_relay(&session, true);
    let lookahead = 8;
    let mut live = LiveReconstructor::new(worker.live_fps(), lookahead);
    for m in &messages {
        live.handle_relay_message(m);
    }
    let head_channel = 0;
    let mut shown = Vec::new();
    for frame in &frames {
        live.add_frame(frame);
        if frame.channel == head_channel
            && let Some(f) = worker.live_frame(&mut live).unwrap()
        {
            shown.push(f);
        }
    }
    let (first, last) = session.wearer.head.time_range_ns().unwrap();
    let grid_frames = ((last - first) as f64 * 30.0 / 1e9 + 1e-6).floor() as usize + 1;
    // Every frame up to the lookahead before the end, once each, in order.
    assert_eq!(shown.len(), grid_frames - lookahead);
    assert!(shown.windows(2).all(|w| w[1].frame == w[0].frame + 1 && w[1].skipped == 0));
    let head = &session.wearer.head;
    for f in &shown {
        assert_eq!(f.window.end, f.frame + lookahead + 1);
        assert!(f.window.len() <= 96 && f.window.contains(&f.frame));
        let on_grid = first + (f.frame as f64 * 1e9 / 30.0).round() as i64;
        assert!((f.timestamp_ns - on_grid).abs() < 1_000_000, "frame {} at {} ns", f.frame, f.timestamp_ns);
        assert!(f.tracked);
        assert!(!f.trained_for_lookahead, "the fixture manifest has no live variants");
        assert!(f.exo_observers.is_empty() || f.method == Method::EgoExo);
        let scene: SceneData = serde_json::from_slice(&f.scene_json).unwrap();
        scene.check().unwrap();
        assert_eq!(scene.frames, 1);
        assert!(scene.joints.iter().all(|v| v.is_finite()));
        assert_eq!(scene.observers.len(), 2);
        // The head drawn is the head pose at the frame's time (the sample nearest to it).
        let nearest = head.timestamps_ns.iter().position(|t| (t - f.timestamp_ns).abs() < 2_000_000).unwrap();
        let drawn = egoexo_core::glam::Vec3::from_slice(&scene.devices[0].positions);
        assert!(drawn.distance(head.poses[nearest].translation) < 0.01, "frame {}", f.frame);
    }
    assert!(shown.iter().any(|f| !f.exo_observers.is_empty()), "no frame had an observer's ray");
    // Frames without keypoints of any observer (occlusion, out of view) are ego-only.
    let ego_exo = shown.iter().filter(|f| f.method == Method::EgoExo).count();
    assert!(ego_exo * 10 > shown.len() * 8, "{ego_exo} of {} frames ego-exo", shown.len());

    // Stop and keep: the take is an ordinary session with every frame.
    let take = live.into_take();
    let summary = worker.keep_take(&take, "take").unwrap();
    assert_eq!(summary.frames, grid_frames);
    assert_eq!(summary.observers.len(), 2);
    let saved = worker.save_session().unwrap();
    assert_eq!(saved.file_name, "take.egoexo");
    let mut again = SessionWorker::new();
    assert_eq!(again.import_archive("take.egoexo", saved.bytes).unwrap().frames, grid_frames);
}

#[test]
fn a_busy_worker_skips_to_the_newest_frame_and_without_observers_says_ego_only() {
    let worker = worker();
    let session = session();
    let (messages, frames) = as_relay(&session, false);
    let mut live = LiveReconstructor::new(worker.live_fps(), 0);
    for m in &messages {
        live.handle_relay_message(m);
    }
    let mut shown = Vec::new();
    // The worker gets to reconstruct only after every 30th frame (10 frames of each stream).
    for (i, frame) in frames.iter().enumerate() {
        live.add_frame(frame);
        if i % 30 == 29
            && let Some(f) = worker.live_frame(&mut live).unwrap()
        {
            shown.push(f);
        }
    }
    assert!(shown.len() > 3);
    assert!(shown.iter().all(|f| f.method == Method::EgoOnly && f.exo_observers.is_empty()));
    assert!(shown.iter().skip(1).all(|f| f.skipped > 0), "frames passed over are counted");
    let (count, skipped) = live.counts();
    assert_eq!(count as usize, shown.len());
    assert_eq!(skipped as usize, shown.iter().map(|f| f.skipped).sum::<usize>());
    // The newest frame, then nothing new: nothing to show.
    assert!(worker.live_frame(&mut live).unwrap().is_some());
    assert!(worker.live_frame(&mut live).unwrap().is_none());
}

#[test]
fn a_live_variant_for_the_lookahead_reads_the_frames_out_and_other_lookaheads_use_the_offline_networks() {
    // The fixture manifest with a 3-point live set for lookahead 2 (the fixture's 3-point
    // files: the choice of networks is what is tested here, not their training).
    let mut manifest: serde_json::Value = serde_json::from_slice(MANIFEST).unwrap();
    let sets = manifest["model_sets"].as_array_mut().unwrap();
    let mut live_set = sets.iter().find(|s| s["tracking"] == "three_point").unwrap().clone();
    live_set["lookahead"] = serde_json::Value::from(2);
    sets.push(live_set);
    let manifest = manifest.to_string();
    let worker = worker_with(manifest.as_bytes());
    assert_eq!(SessionWorker::model_files(manifest.as_bytes()).unwrap().len(), 8, "shared files listed once");
    let session = session();
    let (messages, frames) = as_relay(&session, true);
    for (lookahead, trained) in [(2, true), (3, false)] {
        let mut live = LiveReconstructor::new(worker.live_fps(), lookahead);
        for m in &messages {
            live.handle_relay_message(m);
        }
        let mut shown = Vec::new();
        for frame in frames.iter().take(600) {
            live.add_frame(frame);
            if frame.channel == 0
                && let Some(f) = worker.live_frame(&mut live).unwrap()
            {
                shown.push(f);
            }
        }
        assert!(shown.len() > 10);
        assert!(shown.iter().all(|f| f.trained_for_lookahead == trained), "lookahead {lookahead}");
        assert_eq!(shown[0].info(lookahead).trained_for_lookahead, trained);
    }
}

/// A capture's devices (`egoexo_session::live::capture_devices`) as the relay delivers them:
/// the channel list (observers naming their target wearer), calibrations, then every frame in
/// time order.
fn capture_as_relay(capture: &egoexo_session::capture::Capture) -> (Vec<RelayMessage>, Vec<DataFrame>) {
    let mut channels = Vec::new();
    let mut frames = Vec::new();
    let mut messages = Vec::new();
    for device in egoexo_session::live::capture_devices(capture).unwrap() {
        let mut channel_of = |stream| {
            let channel = channels.len() as u16;
            channels.push(ChannelInfo::of(channel, &device.hello, stream));
            channel
        };
        for (stream, t) in &device.poses {
            let channel = channel_of(*stream);
            for (ts, pose) in t.timestamps_ns.iter().zip(&t.poses) {
                frames.push(DataFrame { channel, timestamp_ns: *ts, payload: FramePayload::Pose(Some(*pose)) });
            }
        }
        if let Some(k) = &device.keypoints {
            let channel = channel_of(Stream::Keypoints);
            for (ts, points) in k.timestamps_ns.iter().zip(&k.frames) {
                frames.push(DataFrame { channel, timestamp_ns: *ts, payload: FramePayload::Keypoints(*points) });
            }
        }
        if let Some(camera) = device.camera {
            messages.push(RelayMessage::Calibration { device: device.hello.id.clone(), camera });
        }
    }
    frames.sort_by_key(|f| f.timestamp_ns);
    messages.insert(0, RelayMessage::Channels { channels });
    (messages, frames)
}

/// Two participants in one room, each a wearer and each one's glasses an observer of the
/// other: both are drawn in every live frame, and the kept take is a capture of both.
#[test]
fn a_room_of_two_wearers_shows_both_and_keeps_a_capture() {
    use egoexo_synth::group::{GroupConfig, group_walk, simulate_group};
    let sim = simulate_group(&group_walk(2, 5.0), "pair", &GroupConfig::default(), 5).unwrap();
    let capture = sim.with_true_identities();
    let (messages, frames) = capture_as_relay(&capture);
    let mut worker = worker();
    let mut live = LiveReconstructor::new(worker.live_fps(), 8);
    for m in &messages {
        live.handle_relay_message(m);
    }
    let mut shown = Vec::new();
    for frame in &frames {
        live.add_frame(frame);
        if frame.channel == 0
            && let Some(f) = worker.live_frame(&mut live).unwrap()
        {
            shown.push(f);
        }
    }
    assert!(shown.len() > 100, "{} frames shown", shown.len());
    let mut both = 0;
    for f in &shown {
        assert_eq!(f.wearers, ["participant-1", "participant-2"]);
        let scene: SceneData = serde_json::from_slice(&f.scene_json).unwrap();
        scene.check().unwrap();
        assert_eq!(scene.participant.as_ref().map(|p| p.id.as_str()), Some("participant-1"));
        assert_eq!(
            scene.observers.iter().map(|o| o.id.as_str()).collect::<Vec<_>>(),
            ["participant-2-sees-participant-1"]
        );
        assert_eq!(scene.others.len(), 1);
        assert_eq!((scene.others[0].participant.id.as_str(), scene.others[0].participant.colour), ("participant-2", 1));
        both += usize::from(scene.others[0].valid[0]);
    }
    assert!(both * 10 > shown.len() * 9, "participant-2 drawn in {both} of {} frames", shown.len());
    assert!(shown.iter().any(|f| f.method == Method::EgoExo), "participant-2's glasses see participant-1");

    let summary = worker.keep_take(&live.into_take(), "room").unwrap();
    let reconstructed: Vec<_> = summary.participants.iter().filter(|p| p.reconstruct).map(|p| p.id.as_str()).collect();
    assert_eq!(reconstructed, ["participant-1", "participant-2"]);
    assert_eq!(worker.participants_to_reconstruct(), ["participant-1", "participant-2"]);
    let result = worker.reconstruct(false, &mut |_| true).unwrap();
    assert_eq!(result.participants.len(), 2);
    assert!(result.participants.iter().all(|p| p.method == "ego-exo"), "{:?}", result.participants);
}

/// The frames a reconstructor shows for `frames`, asked for on every third head pose (a busy
/// worker).
fn stream_live(worker: &mut SessionWorker, messages: &[RelayMessage], frames: &[DataFrame]) -> Vec<LiveFrame> {
    let mut live = LiveReconstructor::new(worker.live_fps(), 8);
    for m in messages {
        live.handle_relay_message(m);
    }
    let mut shown = Vec::new();
    let mut heads = 0;
    for frame in frames {
        live.add_frame(frame);
        if frame.channel == 0 {
            heads += 1;
            if heads % 3 == 0
                && let Some(f) = worker.live_frame(&mut live).unwrap()
            {
                shown.push(f);
            }
        }
    }
    shown
}

/// A worker with the shipped networks (`models/`): the skeleton must mean something.
fn worker_with_shipped_models() -> SessionWorker {
    let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    let manifest = std::fs::read(models.join("manifest.json")).unwrap();
    let mut worker = SessionWorker::new();
    worker
        .load_models(&manifest, |file| {
            std::fs::read(models.join(file))
                .map_err(|e| InferError::ReadModel { file: file.into(), message: e.to_string() })
        })
        .unwrap();
    worker
}

fn joints(frame: &LiveFrame) -> Vec<f32> {
    serde_json::from_slice::<SceneData>(&frame.scene_json).unwrap().joints
}

#[test]
fn observers_in_worlds_of_their_own_are_registered_while_they_stream_then_fused_as_in_the_shared_world() {
    let mut worker = worker_with_shipped_models();
    // 16 s of a wearer wandering (turning, walking) watched by two observers.
    let config = egoexo_synth::SynthConfig { observers: 2, ..egoexo_synth::SynthConfig::default() };
    let shared =
        egoexo_synth::simulate(&egoexo_synth::procedural::wandering(16.0), "wander", &config, 7).unwrap().session;
    let mut own = shared.clone();
    let truth = perturb_observer_worlds(&mut own, &WorldPerturbation::default(), 11);
    let (messages, frames) = as_relay(&shared, true);
    let reference = stream_live(&mut worker, &messages, &frames);
    let (messages, frames) = as_relay(&own, true);
    let shown = stream_live(&mut worker, &messages, &frames);
    assert_eq!(shown.len(), reference.len());
    let first_ns = shared.wearer.head.timestamps_ns[0];
    let registered = |f: &LiveFrame| {
        f.observer_worlds.len() == 2 && f.observer_worlds.iter().all(|o| o.state == WorldState::Registered)
    };
    let span_s = (shared.wearer.head.timestamps_ns.last().unwrap() - first_ns) as f64 / 1e9;
    let Some(at) = shown.iter().position(registered) else {
        panic!("not registered in {span_s:.1} s: {:#?}", shown.last().unwrap().observer_worlds)
    };
    let after_s = (shown[at].timestamp_ns - first_ns) as f64 / 1e9;
    eprintln!(
        "registered {after_s:.1} s into the stream (of {:.1} s): {:#?}",
        (shared.wearer.head.timestamps_ns.last().unwrap() - first_ns) as f64 / 1e9,
        shown[at].observer_worlds
    );
    assert!(after_s <= 10.0 + 8.0 / 30.0, "registered {after_s:.1} s into the stream");
    // Until then the own worlds are not fused: every frame is the wearer alone.
    for f in &shown[..at] {
        assert!(f.exo_observers.is_empty(), "frame {} fused {:?} before registration", f.frame, f.exo_observers);
        assert!(
            f.observer_worlds
                .iter()
                .all(|o| o.state == WorldState::Registering && o.message.starts_with("registering"))
        );
    }
    // The registration is the truth within its uncertainty (and the goal's 1°, 3 cm).
    for (o, t) in shown.last().unwrap().observer_worlds.iter().zip(&truth) {
        assert_eq!(o.observer, t.id);
        let yaw_error = ((o.yaw_deg.unwrap() - t.yaw_deg() + 540.0).rem_euclid(360.0) - 180.0).abs();
        let [x, y, z] = o.translation_m.unwrap();
        let moved = egoexo_core::glam::Vec3::new(x as f32, y as f32, z as f32).distance(t.t_session_world.translation);
        eprintln!("{}: yaw error {yaw_error:.2}°, translation error {:.1} cm", o.observer, moved * 100.0);
        assert!(yaw_error < 1.0 && moved < 0.05, "{o:?} against {t:?}");
    }
    // Then the frames are the shared world's: the same observers fused, the same skeleton.
    let mut worst = 0.0f32;
    let mut differences = Vec::new();
    for (f, r) in shown[at..].iter().zip(&reference[at..]) {
        assert_eq!(f.frame, r.frame);
        assert_eq!(f.exo_observers, r.exo_observers, "frame {}", f.frame);
        let (a, b) = (joints(f), joints(r));
        for (p, q) in a.chunks(3).zip(b.chunks(3)) {
            let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
            worst = worst.max(d);
            differences.push(d);
        }
    }
    differences.sort_by(f32::total_cmp);
    let median = differences[differences.len() / 2];
    eprintln!(
        "after registration the skeleton's joints are within {:.1} cm (median {:.2} cm) of the shared world's",
        worst * 100.0,
        median * 100.0
    );
    assert!(median < 0.01 && worst < 0.05, "median {median} m, worst {worst} m");
}

#[test]
fn a_static_camera_without_a_pose_streams_keypoints_only_and_is_registered_in_six_dof_then_fused() {
    let mut worker = worker_with_shipped_models();
    // 20 s of a wearer wandering, watched by a tripod that knows nothing of its pose.
    let mut config = egoexo_synth::SynthConfig { observers: 1, ..egoexo_synth::SynthConfig::default() };
    config.observer.static_camera = true;
    config.observer_noise = egoexo_synth::config::DeviceNoise::none();
    let posed =
        egoexo_synth::simulate(&egoexo_synth::procedural::wandering(20.0), "tripod", &config, 31).unwrap().session;
    let mut unposed = posed.clone();
    let truth = unpose_static_cameras(&mut unposed, true);
    let (messages, frames) = as_relay(&posed, true);
    let reference = stream_live(&mut worker, &messages, &frames);
    // The camera joins as `"mount": "fixed"` and streams its keypoints only: no head channel.
    let (messages, frames) = capture_as_relay(&egoexo_session::capture::Capture::from_session(&unposed));
    let RelayMessage::Channels { channels } = &messages[0] else { panic!("{:?}", messages[0]) };
    let camera: Vec<&ChannelInfo> = channels.iter().filter(|c| c.role == DeviceRole::Observer).collect();
    assert_eq!(camera.len(), 1, "{channels:?}");
    assert_eq!((camera[0].stream, camera[0].mount), (Stream::Keypoints, DeviceMount::Fixed));
    let shown = stream_live(&mut worker, &messages, &frames);
    assert_eq!(shown.len(), reference.len());
    let first_ns = posed.wearer.head.timestamps_ns[0];
    let Some(at) = shown.iter().position(|f| f.observer_worlds.iter().any(|o| o.state == WorldState::Registered))
    else {
        panic!("not registered: {:#?}", shown.last().unwrap().observer_worlds)
    };
    let after_s = (shown[at].timestamp_ns - first_ns) as f64 / 1e9;
    eprintln!("registered {after_s:.1} s into the stream: {:#?}", shown[at].observer_worlds);
    assert!(after_s <= 15.0, "registered {after_s:.1} s into the stream");
    for f in &shown[..at] {
        assert!(f.exo_observers.is_empty(), "frame {} fused {:?} before registration", f.frame, f.exo_observers);
        assert!(f.wearer_regions.is_empty(), "frame {} proposed a region before registration", f.frame);
    }
    // Once placed, the camera is told where the wearer is in its image (the region its page
    // crops): around the true head there, down to the legs.
    let filmed = &posed.observers[0];
    let t_camera_world = filmed.camera.t_world_camera(&filmed.head.poses[0]).inverse();
    let truth_px = |at_ns: i64, below_m: f32| {
        let head = &posed.wearer.head;
        let i = head.timestamps_ns.partition_point(|&t| t < at_ns).min(head.poses.len() - 1);
        let p = head.poses[i].translation - egoexo_core::glam::Vec3::Y * below_m;
        filmed.camera.project(t_camera_world.transform_point(p)).filter(|&px| filmed.camera.is_valid_pixel(px))
    };
    let (mut proposed, mut checked) = (0, 0);
    for f in &shown[at..] {
        let Some(r) = f.wearer_regions.iter().find(|r| r.observer == filmed.id) else { continue };
        proposed += 1;
        for (below_m, what) in [(0.0, "head"), (1.2, "legs")] {
            if let Some(px) = truth_px(r.at_ns, below_m) {
                checked += 1;
                assert!(r.region.contains(px), "frame {}: the true {what} at {px} is outside {:?}", f.frame, r.region);
            }
        }
    }
    eprintln!(
        "{proposed} of {} frames after registration proposed a region; {checked} true points inside",
        shown.len() - at
    );
    assert!(
        proposed * 10 >= (shown.len() - at) * 9 && checked > proposed,
        "{proposed} regions, {checked} points checked"
    );
    // Where it stands: the truth within 5 cm and 2° of heading.
    let o = &shown.last().unwrap().observer_worlds[0];
    let t = &truth[0];
    let yaw_error = ((o.yaw_deg.unwrap() - t.yaw_deg() + 540.0).rem_euclid(360.0) - 180.0).abs();
    let [x, y, z] = o.translation_m.unwrap();
    let moved = egoexo_core::glam::Vec3::new(x as f32, y as f32, z as f32).distance(t.t_session_world.translation);
    eprintln!("{}: yaw error {yaw_error:.2}°, translation error {:.1} cm", o.observer, moved * 100.0);
    assert!(yaw_error < 2.0 && moved < 0.05, "{o:?} against {t:?}");
    // Once registered it is fused as the posed camera is, and the skeleton is the same.
    let fused = shown[at..].iter().filter(|f| !f.exo_observers.is_empty()).count();
    let fused_reference = reference[at..].iter().filter(|f| !f.exo_observers.is_empty()).count();
    assert!(fused * 10 >= fused_reference * 9, "{fused} frames fused after registration, {fused_reference} posed");
    let mut differences: Vec<f32> = shown[at..]
        .iter()
        .zip(&reference[at..])
        .flat_map(|(f, r)| {
            let (a, b) = (joints(f), joints(r));
            a.chunks(3)
                .zip(b.chunks(3))
                .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
                .collect::<Vec<_>>()
        })
        .collect();
    differences.sort_by(f32::total_cmp);
    let median = differences[differences.len() / 2];
    eprintln!("after registration the joints are within a median {:.2} cm of the posed camera's", median * 100.0);
    assert!(median < 0.02, "median {median} m");
}

/// The relay's view of `session` with every observer's keypoints arriving `late_ns` after the
/// wearer's head pose of the same instant (a camera's capture, detection and network).
fn as_relay_with_late_keypoints(session: &Session, late_ns: i64) -> (Vec<RelayMessage>, Vec<DataFrame>) {
    let (messages, mut frames) = as_relay(session, true);
    let RelayMessage::Channels { channels } = &messages[0] else { panic!("{:?}", messages[0]) };
    let keypoints: Vec<u16> = channels.iter().filter(|c| c.stream == Stream::Keypoints).map(|c| c.channel).collect();
    // In arrival order: a keypoints frame after the head poses up to its time + `late_ns`.
    frames.sort_by_key(|f| f.timestamp_ns + if keypoints.contains(&f.channel) { late_ns } else { 0 });
    (messages, frames)
}

/// MPJPE (metres) of the drawn joints against the truth's at each frame's time, through the
/// core's per-frame term (`egoexo_core::metrics::frame_position_error_cm`, all 24 joints).
fn mean_joint_error(frames: &[&LiveFrame], session: &Session) -> f32 {
    use egoexo_core::metrics::{ALL_JOINTS, JointPositions, frame_position_error_cm};
    let truth = &session.ground_truth.as_ref().unwrap().motion;
    let sum: f64 = frames
        .iter()
        .map(|f| {
            let i = (0..truth.len()).min_by_key(|&i| (truth.timestamp_ns(i) - f.timestamp_ns).abs()).unwrap();
            let expected = truth.skeleton.forward_kinematics(&truth.poses[i]).positions;
            let drawn = joints(f);
            let drawn: JointPositions =
                std::array::from_fn(|j| egoexo_core::glam::Vec3::from_slice(&drawn[3 * j..3 * j + 3]));
            frame_position_error_cm(&drawn, &expected, &ALL_JOINTS)
        })
        .sum();
    (sum / frames.len() as f64 / 100.0) as f32
}

#[test]
fn observers_whose_keypoints_arrive_just_after_the_lookahead_are_fused_and_beat_ego_only_later_ones_are_not() {
    let mut worker = worker_with_shipped_models();
    let config = egoexo_synth::SynthConfig { observers: 2, ..egoexo_synth::SynthConfig::default() };
    let session =
        egoexo_synth::simulate(&egoexo_synth::procedural::wandering(12.0), "wander", &config, 5).unwrap().session;
    let (messages, frames) = as_relay(&session, false);
    let ego_only = stream_live(&mut worker, &messages, &frames);
    let alone: Vec<&LiveFrame> = ego_only.iter().filter(|f| f.frame >= 30).collect();
    assert!(alone.iter().all(|f| f.method == Method::EgoOnly));
    let alone_error = mean_joint_error(&alone, &session);
    // `stream_live` reads out at lookahead 8 (267 ms): keypoints 300 ms late have not come for
    // the frame shown, those of a frame 33 ms before it have.
    let (messages, frames) = as_relay_with_late_keypoints(&session, 300_000_000);
    let late = stream_live(&mut worker, &messages, &frames);
    assert_eq!(late.len(), ego_only.len());
    // After the first second every frame is ego-exo with both observers' rays …
    let settled: Vec<&LiveFrame> = late.iter().filter(|f| f.frame >= 30).collect();
    let fused = settled.iter().filter(|f| f.method == Method::EgoExo && f.exo_observers.len() == 2).count();
    assert!(fused * 10 >= settled.len() * 9, "{fused} of {} frames fused", settled.len());
    // … and closer to the truth than the wearer alone over the same frames.
    let late_error = mean_joint_error(&settled, &session);
    eprintln!(
        "keypoints 300 ms late: mean joint error {:.1} cm fused, {:.1} cm ego-only",
        late_error * 100.0,
        alone_error * 100.0
    );
    assert!(late_error < alone_error * 0.95, "{late_error} m fused against {alone_error} m ego-only");
    // 600 ms late, fusing would not help (measured with a one-second span: 9.9 against 9.8 cm
    // over 22 joints): ego-only.
    let (messages, frames) = as_relay_with_late_keypoints(&session, 600_000_000);
    let later = stream_live(&mut worker, &messages, &frames);
    assert!(later.iter().filter(|f| f.frame >= 30).all(|f| f.method == Method::EgoOnly && f.exo_observers.is_empty()));
}
