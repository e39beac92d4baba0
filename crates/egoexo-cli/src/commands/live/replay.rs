//! `egoexo live replay <session> --url … --room CODE`: streams a recorded or simulated session
//! in real time as its devices would, one WebSocket per device (the wearer; each observer with
//! its camera and keypoints). Each device has its own clock (a random offset and drift from
//! the relay's) and its frames leave with network jitter; faults (a device leaving and coming
//! back, a clock that jumps) can be injected. With `--own-worlds` every observer streams in
//! a world of its own (moved by a random yaw and translation, its hello saying so) and
//! `--recentre` makes a device's world jump mid-stream, as a re-centred headset's does: the
//! test of the viewers' registration. The demo source and the load generator.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use egoexo_core::camera::CameraCalibration;
use egoexo_core::ego_features::heading_yaw;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_protocol::live::{
    ClientMessage, DataFrame, DeviceHello, DeviceRole, FramePayload, Join, LIVE_PROTOCOL_VERSION, LiveLink, Stream,
};
use egoexo_session::align::resample_trajectory;
use egoexo_session::import::import_capture_path;
use egoexo_session::live::{CaptureDevice, capture_devices};
use egoexo_session::model::Trajectory;
use egoexo_synth::worlds::{WorldPerturbation, perturb_capture_worlds};
use futures::SinkExt;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::{Bytes, Message};

use super::client::{self, ServerAddress, Socket};
use crate::commands::session_input::ImportArgs;

#[derive(clap::Args)]
pub struct Args {
    /// The session to stream: a `.egoexo`, an Aria MPS folder, a Nymeria sequence, or a zip.
    pub session: PathBuf,
    #[command(flatten)]
    pub import: ImportArgs,
    /// The server: http://host:port (its relay is ws://host:port/live) or the relay's ws:// URL.
    #[arg(long)]
    pub url: String,
    /// The room: a device code (7KQ-M4T) or a device link (…#live=<room>.<secret>). Without
    /// it a room is created and its code and links are printed.
    #[arg(long)]
    pub room: Option<String>,
    /// Playback speed (2 = twice real time).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Where in the session to start, seconds after the wearer's first head pose.
    #[arg(long, default_value_t = 0.0)]
    pub start_s: f64,
    /// Keep time with something that started at this wall-clock time (Unix milliseconds):
    /// the session's `--start-s` moment is then, and streaming begins where the session is by
    /// the time the devices are connected (e.g. a browser's fake camera filming a rendering of
    /// the same session, started first).
    #[arg(long, value_name = "UNIX_MS")]
    pub start_at_unix_ms: Option<f64>,
    /// How much of the session to stream, seconds [default: to its end].
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Start again at the end, until Ctrl-C.
    #[arg(long = "loop")]
    pub repeat: bool,
    /// Most pose samples a second per stream: faster trajectories (Aria's 1 kHz) are resampled
    /// to this rate, as a headset streams at 72–90 Hz.
    #[arg(long, default_value_t = 90.0)]
    pub max_pose_hz: f64,
    /// Each device's clock starts at a random offset within ± this many seconds of the
    /// relay's.
    #[arg(long, default_value_t = 1000.0)]
    pub clock_spread_s: f64,
    /// Each device's clock runs fast or slow by up to this many parts per million.
    #[arg(long, default_value_t = 50.0)]
    pub drift_ppm: f64,
    /// Each frame leaves up to this many milliseconds after its capture (uniform).
    #[arg(long, default_value_t = 8.0)]
    pub jitter_ms: f64,
    /// Seed of the clocks and jitter.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Stream the wearer only.
    #[arg(long)]
    pub no_observers: bool,
    /// A device leaves and comes back: `ID@START+SECONDS` (seconds into the replay); its
    /// frames meanwhile are not sent. Repeatable.
    #[arg(long = "disconnect", value_parser = parse_fault, value_name = "ID@AT+S")]
    pub disconnects: Vec<Fault>,
    /// A device's clock jumps by ±SECONDS at AT: `ID@AT+SECONDS` or `ID@AT-SECONDS`. Repeatable.
    #[arg(long = "clock-jump", value_parser = parse_fault, value_name = "ID@AT±S")]
    pub clock_jumps: Vec<Fault>,
    /// Every observer (in a capture of several, every participant but the first) streams in a
    /// world of its own: its poses moved by a random yaw (any), a translation (up to 10 m) and
    /// a floor offset (±0.3 m), drawn from `--seed`, and its hello says `"world": "own"`. The
    /// truth is in the summary (`worlds`).
    #[arg(long)]
    pub own_worlds: bool,
    /// A device's world jumps at AT seconds into the replay (`ID@AT`), as a headset's does when
    /// it re-centres: its poses from then on are moved by another random yaw and translation
    /// (up to 3 m). Repeatable.
    #[arg(long = "recentre", value_parser = parse_recentre, value_name = "ID@AT")]
    pub recentres: Vec<Recentre>,
}

/// A device's world jumping at a time into the replay.
#[derive(Clone, Debug, PartialEq)]
pub struct Recentre {
    pub device: String,
    pub at_s: f64,
}

fn parse_recentre(text: &str) -> Result<Recentre, String> {
    let expected = || format!("`{text}`: expected ID@AT (e.g. observer-1@8)");
    let (device, at) = text.split_once('@').ok_or_else(expected)?;
    let at_s: f64 = at.parse().map_err(|_| expected())?;
    if device.is_empty() || !at_s.is_finite() || at_s < 0.0 {
        return Err(expected());
    }
    Ok(Recentre { device: device.to_string(), at_s })
}

/// The world a device streamed in, against the session's (the truth for a registration).
#[derive(Clone, Debug, Serialize)]
pub struct WorldReport {
    pub id: String,
    /// Seconds into the replay from which this world holds (0, or a `--recentre`).
    pub from_s: f64,
    /// `p_session = R_y(yaw_deg) · p_device_world + translation_m`.
    pub yaw_deg: f64,
    pub translation_m: [f64; 3],
}

impl WorldReport {
    fn new(id: &str, from_s: f64, t_session_world: &RigidTransform) -> Self {
        let t = t_session_world.translation;
        Self {
            id: id.to_string(),
            from_s,
            yaw_deg: f64::from(heading_yaw(t_session_world.rotation).to_degrees()),
            translation_m: [f64::from(t.x), f64::from(t.y), f64::from(t.z)],
        }
    }
}

/// A fault for one device at a time into the replay.
#[derive(Clone, Debug, PartialEq)]
pub struct Fault {
    pub device: String,
    pub at_s: f64,
    pub value_s: f64,
}

fn parse_fault(text: &str) -> Result<Fault, String> {
    let expected = || format!("`{text}`: expected ID@AT+SECONDS (e.g. observer-1@2.5+1)");
    let (device, rest) = text.split_once('@').ok_or_else(expected)?;
    let sign_at = rest.find(['+', '-']).ok_or_else(expected)?;
    let at_s: f64 = rest[..sign_at].parse().map_err(|_| expected())?;
    let value_s: f64 = rest[sign_at..].parse().map_err(|_| expected())?;
    if device.is_empty() || !at_s.is_finite() || at_s < 0.0 || !value_s.is_finite() {
        return Err(expected());
    }
    Ok(Fault { device: device.to_string(), at_s, value_s })
}

/// One frame a device will send, at a session time.
#[derive(Clone, Debug)]
struct Sample {
    t_ns: i64,
    stream: Stream,
    payload: FramePayload,
}

/// The plans from where the session is `elapsed_ns` of wall time after its first streamed
/// moment (at `speed`): the samples before then dropped, the range starting there.
fn skip_elapsed(
    mut plans: Vec<DevicePlan>,
    range: (i64, i64),
    elapsed_ns: i64,
    speed: f64,
) -> Result<(Vec<DevicePlan>, (i64, i64))> {
    if elapsed_ns < 0 {
        bail!("--start-at-unix-ms is {:.1} s in the future", -elapsed_ns as f64 / 1e9);
    }
    let from = range.0.saturating_add((elapsed_ns as f64 * speed) as i64);
    if from >= range.1 {
        bail!("--start-at-unix-ms: the session's streamed part ended {:.1} s ago", (from - range.1) as f64 / 1e9);
    }
    for plan in &mut plans {
        plan.samples.retain(|s| s.t_ns >= from);
    }
    Ok((plans, (from, range.1)))
}

/// What one device sends.
#[derive(Clone, Debug)]
struct DevicePlan {
    hello: DeviceHello,
    camera: Option<CameraCalibration>,
    samples: Vec<Sample>,
}

/// A trajectory as a headset streams it: its own samples, or (when faster than `max_hz`)
/// resampled at `max_hz` with the session's interpolation, invalid where it has gaps.
fn pose_samples(trajectory: &Trajectory, stream: Stream, max_hz: f64, range: (i64, i64)) -> Vec<Sample> {
    let Some((first, last)) = trajectory.time_range_ns() else { return Vec::new() };
    let span_s = (last - first) as f64 / 1e9;
    let native_hz = if span_s > 0.0 { (trajectory.len() - 1) as f64 / span_s } else { 0.0 };
    let in_range = |t: i64| (range.0..=range.1).contains(&t);
    if native_hz <= max_hz * 1.05 {
        return trajectory
            .timestamps_ns
            .iter()
            .zip(&trajectory.poses)
            .filter(|(t, _)| in_range(**t))
            .map(|(&t_ns, pose)| Sample { t_ns, stream, payload: FramePayload::Pose(Some(*pose)) })
            .collect();
    }
    let step = 1e9 / max_hz;
    let times: Vec<i64> = (0..)
        .map(|k| first + (k as f64 * step).round() as i64)
        .take_while(|t| *t <= last)
        .filter(|t| in_range(*t))
        .collect();
    let resampled = resample_trajectory(trajectory, &times, egoexo_session::align::DEFAULT_MAX_GAP_NS);
    times
        .iter()
        .zip(resampled.poses.iter().zip(&resampled.valid))
        .map(|(&t_ns, (pose, valid))| Sample { t_ns, stream, payload: FramePayload::Pose(valid.then_some(*pose)) })
        .collect()
}

/// What each device streams: a capture's devices (`capture_devices`: one wearer and its
/// observers, or every participant of several as a wearer and each camera's keypoints of
/// each of them as an observer naming its target) within `--start-s` / `--duration-s` of the
/// first wearer's head.
fn plan_devices(devices: Vec<CaptureDevice>, args: &Args) -> Result<(Vec<DevicePlan>, (i64, i64))> {
    let head = devices
        .iter()
        .find(|d| d.hello.role == DeviceRole::Wearer)
        .and_then(|d| d.poses.iter().find(|(s, _)| *s == Stream::Head))
        .and_then(|(_, head)| head.time_range_ns());
    let (head_first, head_last) = head.context("the session has no wearer head poses")?;
    let start = head_first + (args.start_s * 1e9) as i64;
    let end = match args.duration_s {
        Some(d) => (start + (d * 1e9) as i64).min(head_last),
        None => head_last,
    };
    if start >= end {
        bail!("--start-s {} is past the session's end ({:.1} s)", args.start_s, (head_last - head_first) as f64 / 1e9);
    }
    let range = (start, end);
    let mut plans = Vec::new();
    for device in devices {
        if args.no_observers && device.hello.role == DeviceRole::Observer {
            continue;
        }
        let mut samples = Vec::new();
        for (stream, trajectory) in &device.poses {
            samples.extend(pose_samples(trajectory, *stream, args.max_pose_hz, range));
        }
        if let Some(keypoints) = &device.keypoints {
            samples.extend(
                keypoints.timestamps_ns.iter().zip(&keypoints.frames).filter(|(t, _)| (start..=end).contains(*t)).map(
                    |(&t_ns, frame)| Sample {
                        t_ns,
                        stream: Stream::Keypoints,
                        payload: FramePayload::Keypoints(*frame),
                    },
                ),
            );
        }
        plans.push(DevicePlan { hello: device.hello, camera: device.camera, samples });
    }
    for plan in &mut plans {
        plan.samples.sort_by_key(|s| s.t_ns);
    }
    let faulted = args.disconnects.iter().chain(&args.clock_jumps).map(|f| &f.device);
    for device in faulted.chain(args.recentres.iter().map(|r| &r.device)) {
        if !plans.iter().any(|p| p.hello.id == *device) {
            let ids: Vec<_> = plans.iter().map(|p| p.hello.id.as_str()).collect();
            bail!("no device `{device}` in this replay (devices: {})", ids.join(", "));
        }
    }
    Ok((plans, range))
}

/// A device's clock: the system clock offset by `base_ns`, running `1 + drift` times as
/// fast from `origin`, plus the jumps that have happened.
#[derive(Clone, Debug)]
struct DeviceClock {
    origin: Instant,
    origin_ns: i64,
    drift: f64,
    /// `(seconds after origin, jump ns)`.
    jumps: Vec<(f64, i64)>,
}

impl DeviceClock {
    fn at(&self, instant: Instant) -> i64 {
        // Signed: the clock runs (and is asked, by pings) before the replay starts too.
        let elapsed = if instant >= self.origin {
            instant.duration_since(self.origin).as_secs_f64()
        } else {
            -self.origin.duration_since(instant).as_secs_f64()
        };
        let jumped: i64 = self.jumps.iter().filter(|(at, _)| elapsed >= *at).map(|(_, d)| d).sum();
        self.origin_ns + (elapsed * 1e9 * (1.0 + self.drift)) as i64 + jumped
    }

    fn now(&self) -> i64 {
        self.at(Instant::now())
    }
}

/// What one device sent.
#[derive(Debug, Default, Serialize)]
pub struct DeviceReport {
    pub id: String,
    pub role: String,
    /// Frames sent per stream (kebab-case names).
    pub sent: BTreeMap<String, u64>,
    /// Frames captured while disconnected (not sent).
    pub not_sent: u64,
    pub connections: u32,
    /// Frames in one pass over the session.
    pub planned: u64,
    /// The clock's offset from the system clock at the start, ns, and its drift (ppm).
    pub clock_offset_ns: i64,
    pub drift_ppm: f64,
}

/// The replay's summary (printed as one JSON line at the end).
#[derive(Debug, Serialize)]
pub struct ReplayReport {
    pub devices: Vec<DeviceReport>,
    pub session_span_s: f64,
    /// With `--own-worlds` or `--recentre`: each moved device's world against the session's.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub worlds: Vec<WorldReport>,
}

/// Moves the pose samples of each `--recentre`d device from its time on by a random yaw and
/// translation (up to 3 m), as a re-centred headset's world jumps; the worlds it streams in
/// from then on (`T_session_world`, composed with the world it was in) are returned.
fn recentre_worlds(
    plans: &mut [DevicePlan],
    range: (i64, i64),
    args: &Args,
    before: &[WorldReport],
    rng: &mut ChaCha8Rng,
) -> Vec<WorldReport> {
    let mut worlds = Vec::new();
    for recentre in &args.recentres {
        let Some(plan) = plans.iter_mut().find(|p| p.hello.id == recentre.device) else { continue };
        let yaw = rng.random_range(-std::f32::consts::PI..std::f32::consts::PI);
        let (distance, heading) = (rng.random_range(0.5f32..3.0), rng.random_range(0.0..std::f32::consts::TAU));
        // The jump: new world ← old world.
        let jump = RigidTransform {
            rotation: Quat::from_rotation_y(yaw),
            translation: Vec3::new(distance * heading.cos(), 0.0, distance * heading.sin()),
        };
        let from_ns = range.0 + (recentre.at_s * 1e9) as i64;
        for sample in plan.samples.iter_mut().filter(|s| s.t_ns >= from_ns) {
            if let FramePayload::Pose(Some(pose)) = &mut sample.payload {
                *pose = jump * *pose;
            }
        }
        // T_session_newworld = T_session_oldworld · jump⁻¹.
        let old = before.iter().rev().find(|w| w.id == recentre.device).map_or(RigidTransform::IDENTITY, |w| {
            let [x, y, z] = w.translation_m;
            RigidTransform {
                rotation: Quat::from_rotation_y((w.yaw_deg as f32).to_radians()),
                translation: Vec3::new(x as f32, y as f32, z as f32),
            }
        });
        worlds.push(WorldReport::new(&recentre.device, recentre.at_s, &(old * jump.inverse())));
    }
    worlds
}

struct DeviceRun {
    server: ServerAddress,
    join: Join,
    plan: DevicePlan,
    clock: DeviceClock,
    /// Replay time 0 (capture of the first sample).
    start: Instant,
    range: (i64, i64),
    speed: f64,
    repeat: bool,
    jitter: Duration,
    rng: ChaCha8Rng,
    /// `(from, to)` seconds after start.
    disconnects: Vec<(f64, f64)>,
}

impl DeviceRun {
    /// The capture instant of the `n`-th frame to send (over cycles), or `None` past the end.
    fn capture(&self, n: usize) -> Option<(Instant, &Sample)> {
        let count = self.plan.samples.len();
        if count == 0 || (!self.repeat && n >= count) {
            return None;
        }
        let cycle = (n / count) as i64;
        let sample = &self.plan.samples[n % count];
        let period = self.range.1 - self.range.0 + 1;
        let session_ns = cycle * period + sample.t_ns - self.range.0;
        Some((self.start + Duration::from_secs_f64(session_ns as f64 / 1e9 / self.speed), sample))
    }

    fn disconnected_at(&self, instant: Instant) -> Option<Instant> {
        let t = instant.saturating_duration_since(self.start).as_secs_f64();
        self.disconnects
            .iter()
            .find(|(from, to)| (*from..*to).contains(&t))
            .map(|(_, to)| self.start + Duration::from_secs_f64(*to))
    }

    async fn connect(&self, report: &mut DeviceReport) -> Result<Socket> {
        let mut socket = client::connect(&self.server).await?;
        let hello = ClientMessage::Hello {
            protocol: LIVE_PROTOCOL_VERSION,
            join: self.join.clone(),
            device: Some(self.plan.hello.clone()),
        };
        let clock = self.clock.clone();
        client::hello(&mut socket, &hello, move || clock.now())
            .await
            .with_context(|| format!("device `{}`", self.plan.hello.id))?;
        if let Some(camera) = self.plan.camera {
            socket.send(client::json(&ClientMessage::Calibration { camera })).await?;
        }
        report.connections += 1;
        Ok(socket)
    }

    async fn run(mut self, stop: tokio::sync::watch::Receiver<bool>) -> Result<DeviceReport> {
        let mut report = DeviceReport {
            id: self.plan.hello.id.clone(),
            role: self.plan.hello.role.name().to_string(),
            clock_offset_ns: self.clock.origin_ns - client::system_ns(),
            drift_ppm: self.clock.drift * 1e6,
            planned: self.plan.samples.len() as u64,
            ..DeviceReport::default()
        };
        let mut socket = self.connect(&mut report).await?;
        let mut n = 0usize;
        let mut last_send = Instant::now();
        loop {
            if *stop.borrow() {
                break;
            }
            let Some((capture, sample)) = self.capture(n) else { break };
            let sample = sample.clone();
            if let Some(back) = self.disconnected_at(capture) {
                // The device is away: close, let the frames of that span go, come back.
                let _ = socket.close(None).await;
                while self.capture(n).is_some_and(|(c, _)| c < back) {
                    report.not_sent += 1;
                    n += 1;
                }
                tokio::time::sleep_until(back).await;
                socket = self.connect(&mut report).await?;
                continue;
            }
            let jitter = self.jitter.mul_f64(self.rng.random::<f64>());
            let send_at = (capture + jitter).max(last_send);
            // Answer pings while waiting to send.
            let clock = &self.clock;
            client::answer_pings_until(&mut socket, send_at, || clock.now(), &self.plan.hello.id).await?;
            let frame = DataFrame {
                channel: sample.stream.channel(),
                timestamp_ns: self.clock.at(capture),
                payload: sample.payload,
            };
            socket.send(Message::Binary(Bytes::from(frame.encode()))).await.context("sending a frame")?;
            *report.sent.entry(sample.stream.name().to_string()).or_default() += 1;
            last_send = send_at;
            n += 1;
        }
        // Let the last frames reach the relay before leaving.
        let _ = tokio::time::timeout(Duration::from_secs(2), socket.close(None)).await;
        Ok(report)
    }
}

pub fn run(args: Args) -> Result<()> {
    if !(args.speed.is_finite() && args.speed > 0.0) {
        bail!("--speed must be positive");
    }
    if !(args.max_pose_hz.is_finite() && args.max_pose_hz > 0.0) {
        bail!("--max-pose-hz must be positive");
    }
    let server = ServerAddress::parse(&args.url)?;
    // A capture of several participants streams every one of them as a wearer.
    let mut imported = import_capture_path(&args.session, &args.import.import_options()?)?;
    let name = imported.capture.name.clone();
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let mut worlds = Vec::new();
    if args.own_worlds {
        let truth = perturb_capture_worlds(&mut imported.capture, &WorldPerturbation::default(), args.seed);
        worlds.extend(truth.iter().map(|t| WorldReport::new(&t.id, 0.0, &t.t_session_world)));
    }
    let (mut plans, range) = plan_devices(capture_devices(&imported.capture)?, &args)?;
    let recentred = recentre_worlds(&mut plans, range, &args, &worlds, &mut rng);
    worlds.extend(recentred);
    for w in &worlds {
        eprintln!(
            "{} streams in a world of its own from {:.1} s: yaw {:.1}°, translation ({:.2}, {:.2}, {:.2}) m",
            w.id, w.from_s, w.yaw_deg, w.translation_m[0], w.translation_m[1], w.translation_m[2]
        );
    }
    let join = match &args.room {
        Some(room) => client::parse_join(room)?,
        None => {
            let room = client::create_room(&server)?;
            let device = LiveLink { room: room.room.clone(), secret: room.device_secret.clone() };
            let watch = LiveLink { room: room.room.clone(), secret: room.viewer_secret.clone() };
            eprintln!("room created: device code {} (expires {})", room.device_code, room.expires_at);
            eprintln!("  watch:   {}", server.watch_link(&watch));
            eprintln!("  devices: {}", server.device_link(&device));
            Join::Secret { room: device.room, secret: device.secret }
        }
    };
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    let session_span_s = (range.1 - range.0) as f64 / 1e9;
    eprintln!(
        "replaying {:.1} s of `{}` at {}×: {}",
        session_span_s,
        name,
        args.speed,
        plans.iter().map(|p| format!("{} ({} frames)", p.hello.id, p.samples.len())).collect::<Vec<_>>().join(", ")
    );
    runtime.block_on(async move {
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        tokio::spawn(async move {
            let _ = tokio::signal::ctrl_c().await;
            let _ = stop_tx.send(true);
        });
        // A moment for every device to connect and the relay to learn its clock.
        let start = Instant::now() + Duration::from_millis(1500);
        let system_at_start = client::system_ns() + 1_500_000_000;
        let (plans, range) = match args.start_at_unix_ms {
            Some(ms) => skip_elapsed(plans, range, system_at_start - (ms * 1e6) as i64, args.speed)?,
            None => (plans, range),
        };
        let mut tasks = Vec::new();
        for plan in plans {
            let id = plan.hello.id.clone();
            let spread = args.clock_spread_s * 1e9;
            let clock = DeviceClock {
                origin: start,
                origin_ns: system_at_start + if spread > 0.0 { rng.random_range(-spread..=spread) as i64 } else { 0 },
                drift: if args.drift_ppm > 0.0 {
                    rng.random_range(-args.drift_ppm..=args.drift_ppm) * 1e-6
                } else {
                    0.0
                },
                jumps: args
                    .clock_jumps
                    .iter()
                    .filter(|f| f.device == id)
                    .map(|f| (f.at_s, (f.value_s * 1e9) as i64))
                    .collect(),
            };
            let run = DeviceRun {
                server: server.clone(),
                join: join.clone(),
                clock,
                start,
                range,
                speed: args.speed,
                repeat: args.repeat,
                jitter: Duration::from_secs_f64(args.jitter_ms.max(0.0) / 1e3),
                rng: ChaCha8Rng::seed_from_u64(rng.random()),
                disconnects: args
                    .disconnects
                    .iter()
                    .filter(|f| f.device == id)
                    .map(|f| (f.at_s, f.at_s + f.value_s.abs()))
                    .collect(),
                plan,
            };
            tasks.push(tokio::spawn(run.run(stop_rx.clone())));
        }
        let mut devices = Vec::new();
        for task in tasks {
            devices.push(task.await.context("a device task")??);
        }
        let report = ReplayReport { devices, session_span_s, worlds };
        println!("{}", serde_json::to_string(&report)?);
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_replay_that_keeps_time_starts_where_the_session_is_now() {
        let plan = |times: &[i64]| DevicePlan {
            hello: DeviceHello::worn("wearer", DeviceRole::Wearer, vec![Stream::Head]),
            camera: None,
            samples: times
                .iter()
                .map(|&t_ns| Sample { t_ns, stream: Stream::Head, payload: FramePayload::Pose(None) })
                .collect(),
        };
        let ms = 1_000_000;
        // 1.2 s of wall time after the anchor, at twice real time: 2.4 s into the session.
        let (plans, range) =
            skip_elapsed(vec![plan(&[0, 1000 * ms, 2400 * ms, 3000 * ms])], (0, 4000 * ms), 1200 * ms, 2.0).unwrap();
        assert_eq!(range, (2400 * ms, 4000 * ms));
        assert_eq!(plans[0].samples.iter().map(|s| s.t_ns).collect::<Vec<_>>(), vec![2400 * ms, 3000 * ms]);
        let future = skip_elapsed(vec![plan(&[0])], (0, 10), -5 * ms, 1.0).unwrap_err().to_string();
        assert!(future.contains("in the future"), "{future}");
        let over = skip_elapsed(vec![plan(&[0])], (0, 4000 * ms), 5000 * ms, 1.0).unwrap_err().to_string();
        assert!(over.contains("ended 1.0 s ago"), "{over}");
    }

    #[test]
    fn faults_parse() {
        assert_eq!(
            parse_fault("observer-1@2.5+1").unwrap(),
            Fault { device: "observer-1".into(), at_s: 2.5, value_s: 1.0 }
        );
        assert_eq!(parse_fault("wearer@3-0.5").unwrap().value_s, -0.5);
        for bad in ["wearer", "wearer@3", "@3+1", "wearer@x+1", "wearer@-1+1"] {
            assert!(parse_fault(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_recentre_moves_the_poses_after_it_and_reports_the_world_they_are_in() {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: Args,
        }
        let cli = Cli::parse_from(["replay", "s.egoexo", "--url", "http://127.0.0.1:1", "--recentre", "observer-1@1"]);
        assert_eq!(cli.args.recentres, [Recentre { device: "observer-1".into(), at_s: 1.0 }]);
        assert!(
            parse_recentre("observer-1").is_err() && parse_recentre("@2").is_err() && parse_recentre("a@-1").is_err()
        );
        // Two seconds of a device standing at (1, 1.6, 0) in the session's world, 10 Hz.
        let pose = RigidTransform { translation: Vec3::new(1.0, 1.6, 0.0), ..RigidTransform::IDENTITY };
        let samples = (0..20)
            .map(|i| Sample { t_ns: i * 100_000_000, stream: Stream::Head, payload: FramePayload::Pose(Some(pose)) })
            .collect();
        let hello = DeviceHello::worn("observer-1", DeviceRole::Observer, vec![Stream::Head]);
        let mut plans = vec![DevicePlan { hello, camera: None, samples }];
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let worlds = recentre_worlds(&mut plans, (0, 1_900_000_000), &cli.args, &[], &mut rng);
        assert_eq!(worlds.len(), 1);
        let world = RigidTransform {
            rotation: Quat::from_rotation_y((worlds[0].yaw_deg as f32).to_radians()),
            translation: Vec3::from_array(worlds[0].translation_m.map(|v| v as f32)),
        };
        for s in &plans[0].samples {
            let FramePayload::Pose(Some(p)) = s.payload else { panic!() };
            if s.t_ns < 1_000_000_000 {
                assert_eq!(p, pose);
            } else {
                // Moved into a new world, which the report maps back to the session's.
                assert!(p.translation.distance(pose.translation) > 0.4);
                assert!((world * p).translation.distance(pose.translation) < 1e-4);
            }
        }
    }

    #[test]
    fn a_fast_trajectory_streams_at_the_headset_rate_and_gaps_stay_invalid() {
        // 1 kHz for one second with a 300 ms hole.
        let mut t = Trajectory::default();
        for ms in (0..=1000).filter(|ms| !(400..700).contains(ms)) {
            t.timestamps_ns.push(ms * 1_000_000);
            t.poses.push(RigidTransform { translation: Vec3::new(ms as f32, 0.0, 0.0), ..RigidTransform::IDENTITY });
        }
        let samples = pose_samples(&t, Stream::Head, 90.0, (0, 1_000_000_000));
        assert_eq!(samples.len(), 91);
        let invalid = samples.iter().filter(|s| matches!(s.payload, FramePayload::Pose(None))).count();
        assert!((25..=28).contains(&invalid), "{invalid} frames in the hole");
        // A 30 Hz trajectory goes out as it is.
        let slow = Trajectory {
            timestamps_ns: (0..30).map(|i| i * 33_333_333).collect(),
            poses: vec![RigidTransform::IDENTITY; 30],
        };
        assert_eq!(pose_samples(&slow, Stream::Head, 90.0, (0, i64::MAX)).len(), 30);
    }
}
