//! `egoexo live load`: the relay under load, on loopback. `--rooms` rooms of
//! `--devices-per-room` devices (a wearer and observers, one 30 Hz pose stream each by default)
//! stream for `--duration-s`, watched by `--viewers-per-room` viewers that read as fast as they
//! can. Reports the relay latency (device capture → viewer receipt, p50/p95/p99), frames lost
//! (sent × viewers − received; the goal is 0 with healthy viewers), the relay's drops, and —
//! for a relay this command starts, or one named by `--relay-pid` — its CPU time and memory.
//!
//! A benchmark, not a test: the figures depend on the machine (the load generator shares it).

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rigid::RigidTransform;
use egoexo_protocol::live::{
    ClientMessage, DataFrame, DeviceHello, DeviceRole, FramePayload, Join, LIVE_PROTOCOL_VERSION, RelayMessage, Stream,
};
use futures::{SinkExt, StreamExt};
use serde::Serialize;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::{Bytes, Message};

use super::client::{self, ServerAddress};

#[derive(clap::Args)]
pub struct Args {
    /// The server to load [default: start `egoexo serve` on a free loopback port].
    #[arg(long)]
    pub url: Option<String>,
    /// The process id of the server given by --url, to read its CPU time and memory.
    #[arg(long)]
    pub relay_pid: Option<u32>,
    /// Rooms (a server lets one address create 10 a minute).
    #[arg(long, default_value_t = 10)]
    pub rooms: usize,
    /// Devices in each room: a wearer and observers, one pose stream each.
    #[arg(long, default_value_t = 5)]
    pub devices_per_room: usize,
    /// Viewers in each room.
    #[arg(long, default_value_t = 1)]
    pub viewers_per_room: usize,
    /// Frames a second per device.
    #[arg(long, default_value_t = 30.0)]
    pub hz: f64,
    /// How long the devices stream.
    #[arg(long, default_value_t = 10.0)]
    pub duration_s: f64,
    /// Latencies of the first seconds are not counted (connections and clock sync settle).
    #[arg(long, default_value_t = 1.0)]
    pub warmup_s: f64,
}

/// The load's result (printed as one JSON line).
#[derive(Debug, Serialize)]
pub struct LoadReport {
    pub rooms: usize,
    pub device_streams: usize,
    pub viewers: usize,
    pub hz: f64,
    pub duration_s: f64,
    pub frames_sent: u64,
    /// Frames the viewers should have received: each room's frames × its viewers.
    pub frames_expected: u64,
    pub frames_received: u64,
    pub frames_lost: u64,
    /// Frames the relay dropped for slow viewers (reported in `status`).
    pub dropped_by_relay: u64,
    /// Device capture → viewer receipt, milliseconds, after the warm-up.
    pub latency_ms: Percentiles,
    pub relay: Option<RelayUsage>,
}

#[derive(Debug, Default, Serialize)]
pub struct Percentiles {
    pub samples: usize,
    pub p50: f64,
    pub p95: f64,
    pub p99: f64,
    pub max: f64,
}

impl Percentiles {
    fn of(mut values: Vec<f64>) -> Percentiles {
        if values.is_empty() {
            return Percentiles::default();
        }
        values.sort_by(f64::total_cmp);
        let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
        Percentiles { samples: values.len(), p50: at(0.5), p95: at(0.95), p99: at(0.99), max: at(1.0) }
    }
}

/// The relay process's resources over the run.
#[derive(Debug, Serialize)]
pub struct RelayUsage {
    pub pid: u32,
    /// CPU time (user + system) during the run, seconds.
    pub cpu_s: f64,
    /// That CPU time over the run's wall time: 100 % is one core busy.
    pub cpu_percent: f64,
    /// Peak and final resident memory, MiB.
    pub rss_peak_mib: f64,
    pub rss_end_mib: f64,
}

/// CPU time (s) and resident memory (KiB) of a process, from /proc.
fn process_usage(pid: u32) -> Option<(f64, u64, u64)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may hold spaces) start at state (field 3).
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kib = |key: &str| {
        status.lines().find(|l| l.starts_with(key)).and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
    };
    // Linux reports CPU time in USER_HZ ticks, 100 a second on every mainstream architecture.
    Some((ticks / 100.0, kib("VmHWM:")?, kib("VmRSS:")?))
}

/// `egoexo serve` started by this command; killed when dropped.
struct SpawnedRelay {
    child: Child,
    url: String,
    _dirs: (tempfile::TempDir, tempfile::TempDir),
}

impl Drop for SpawnedRelay {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn spawn_relay() -> Result<SpawnedRelay> {
    let dist = tempfile::tempdir()?;
    std::fs::write(dist.path().join("index.html"), "<!doctype html><title>egoexo load</title>")?;
    let store = tempfile::tempdir()?;
    let exe = std::env::current_exe().context("this program's path")?;
    let mut child = Command::new(exe)
        .args(["serve", "--listen", "127.0.0.1:0", "--dist"])
        .arg(dist.path())
        .arg("--store")
        .arg(store.path())
        .stdout(Stdio::piped())
        .spawn()
        .context("starting egoexo serve")?;
    let mut line = String::new();
    BufReader::new(child.stdout.take().context("its output")?).read_line(&mut line)?;
    let Some(url) = line.trim().strip_prefix("listening on ") else {
        let _ = child.kill();
        bail!("egoexo serve printed {line:?} instead of its address");
    };
    Ok(SpawnedRelay { url: url.trim_end_matches('/').to_string(), child, _dirs: (dist, store) })
}

/// A pose that moves (so frames differ) and stays a unit quaternion.
fn moving_pose(t_s: f64, k: usize) -> RigidTransform {
    let a = (t_s * 0.7 + k as f64) as f32;
    RigidTransform { rotation: Quat::from_rotation_y(a), translation: Vec3::new(a.sin(), 1.6, a.cos()) }
}

#[derive(Default)]
struct Counters {
    sent: AtomicU64,
}

/// One device of the load: streams a moving head pose at `hz` from `start` to `end`.
struct LoadDevice {
    server: ServerAddress,
    join: Join,
    hello: DeviceHello,
    /// Varies the pose between devices.
    k: usize,
    hz: f64,
    start: Instant,
    end: Instant,
    sent: Arc<Counters>,
}

async fn run_device(device: LoadDevice) -> Result<()> {
    let LoadDevice { server, join, hello, k, hz, start, end, sent } = device;
    let mut socket = client::connect(&server).await?;
    let message = ClientMessage::Hello { protocol: LIVE_PROTOCOL_VERSION, join, device: Some(hello.clone()) };
    client::hello(&mut socket, &message, client::system_ns).await.with_context(|| format!("device {}", hello.id))?;
    let period = Duration::from_secs_f64(1.0 / hz);
    let mut next = start;
    while next < end {
        client::answer_pings_until(&mut socket, next, client::system_ns, &hello.id).await?;
        let t_s = next.duration_since(start).as_secs_f64();
        let frame = DataFrame {
            channel: Stream::Head.channel(),
            timestamp_ns: client::system_ns(),
            payload: FramePayload::Pose(Some(moving_pose(t_s, k))),
        };
        socket.send(Message::Binary(Bytes::from(frame.encode()))).await?;
        sent.sent.fetch_add(1, Ordering::Relaxed);
        next += period;
    }
    let _ = tokio::time::timeout(Duration::from_secs(2), socket.close(None)).await;
    Ok(())
}

/// What one viewer saw.
struct ViewerResult {
    received: u64,
    dropped: u64,
    latencies_ms: Vec<f64>,
}

async fn run_viewer(
    server: ServerAddress,
    join: Join,
    mut times: tokio::sync::watch::Receiver<(Instant, Instant)>,
    ready: tokio::sync::oneshot::Sender<()>,
) -> Result<ViewerResult> {
    let mut socket = client::connect(&server).await?;
    let message = ClientMessage::Hello { protocol: LIVE_PROTOCOL_VERSION, join, device: None };
    client::hello(&mut socket, &message, client::system_ns).await.context("a viewer")?;
    let _ = ready.send(());
    let mut result = ViewerResult { received: 0, dropped: 0, latencies_ms: Vec::new() };
    // Relay clock minus this viewer's clock (the same machine: near 0, but measured).
    let mut offset_ns = 0i64;
    loop {
        // (latencies count from, stop at): known once the devices start.
        let (count_from, stop_at) = *times.borrow();
        let message = tokio::select! {
            _ = tokio::time::sleep_until(stop_at) => break,
            Ok(()) = times.changed() => continue,
            message = socket.next() => message,
        };
        match message {
            Some(Ok(Message::Binary(bytes))) => {
                let frame = DataFrame::decode(&bytes).context("a frame from the relay")?;
                result.received += 1;
                if Instant::now() >= count_from {
                    let now_relay = client::system_ns() + offset_ns;
                    result.latencies_ms.push((now_relay - frame.timestamp_ns) as f64 / 1e6);
                }
            }
            Some(Ok(Message::Text(text))) => match serde_json::from_str::<RelayMessage>(&text) {
                Ok(RelayMessage::Ping { relay_ns }) => {
                    socket
                        .send(client::json(&ClientMessage::Pong { relay_ns, device_ns: client::system_ns() }))
                        .await?;
                }
                Ok(RelayMessage::Status { dropped, clock_offset_ns, .. }) => {
                    result.dropped = dropped;
                    offset_ns = clock_offset_ns.unwrap_or(offset_ns);
                }
                _ => {}
            },
            Some(Ok(Message::Close(frame))) => bail!("a viewer: {}", client::describe_close(frame.as_ref())),
            Some(Ok(_)) => {}
            Some(Err(e)) => bail!("a viewer: {e}"),
            None => break,
        }
    }
    Ok(result)
}

pub fn run(args: Args) -> Result<()> {
    if args.rooms == 0 || args.devices_per_room == 0 || !(args.hz > 0.0 && args.hz <= 1000.0) {
        bail!("--rooms and --devices-per-room must be at least 1, --hz in (0, 1000]");
    }
    if !args.duration_s.is_finite() || args.duration_s <= 0.0 {
        bail!("--duration-s must be positive");
    }
    let spawned = match &args.url {
        Some(_) => None,
        None => Some(spawn_relay()?),
    };
    let url = spawned.as_ref().map(|s| s.url.clone()).or(args.url.clone()).context("a server")?;
    let pid = spawned.as_ref().map(|s| s.child.id()).or(args.relay_pid);
    let server = ServerAddress::parse(&url)?;
    let mut rooms = Vec::new();
    for _ in 0..args.rooms {
        rooms.push(client::create_room(&server)?);
    }
    eprintln!(
        "{} rooms × {} devices × {} Hz for {} s, {} viewers a room, relay {url}",
        args.rooms, args.devices_per_room, args.hz, args.duration_s, args.viewers_per_room
    );
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    let report = runtime.block_on(async {
        // Viewers first, so they see every frame live.
        let far = Instant::now() + Duration::from_secs(3600 * 24);
        let mut viewers = Vec::new();
        let mut viewer_rooms = Vec::new();
        let (times_tx, times_rx) = tokio::sync::watch::channel((far, far));
        for (r, room) in rooms.iter().enumerate() {
            for _ in 0..args.viewers_per_room {
                let (ready_tx, ready_rx) = tokio::sync::oneshot::channel();
                let join = Join::Secret { room: room.room.clone(), secret: room.viewer_secret.clone() };
                viewers.push(tokio::spawn(run_viewer(server.clone(), join, times_rx.clone(), ready_tx)));
                viewer_rooms.push(r);
                ready_rx.await.context("a viewer could not join")?;
            }
        }
        let start = Instant::now() + Duration::from_millis(1500);
        let end = start + Duration::from_secs_f64(args.duration_s);
        let usage_start = pid.and_then(process_usage);
        let usage_since = Instant::now();
        let counters: Vec<Arc<Counters>> = (0..args.rooms).map(|_| Arc::new(Counters::default())).collect();
        let mut devices = Vec::new();
        for (r, room) in rooms.iter().enumerate() {
            for k in 0..args.devices_per_room {
                let (id, role) = if k == 0 {
                    ("wearer".to_string(), DeviceRole::Wearer)
                } else {
                    (format!("observer-{k}"), DeviceRole::Observer)
                };
                let hello = DeviceHello::worn(id, role, vec![Stream::Head]);
                let join = Join::Secret { room: room.room.clone(), secret: room.device_secret.clone() };
                devices.push(tokio::spawn(run_device(LoadDevice {
                    server: server.clone(),
                    join,
                    hello,
                    k: r * 31 + k,
                    hz: args.hz,
                    start,
                    end,
                    sent: counters[r].clone(),
                })));
            }
        }
        // Viewers stop a moment after the devices, once the last frames are through.
        let count_from = start + Duration::from_secs_f64(args.warmup_s);
        let _ = times_tx.send((count_from, end + Duration::from_secs(2)));
        for device in devices {
            device.await.context("a device task")??;
        }
        let mut received = 0;
        let mut dropped = 0;
        let mut expected = 0;
        let mut latencies = Vec::new();
        for (viewer, r) in viewers.into_iter().zip(viewer_rooms) {
            let result = viewer.await.context("a viewer task")??;
            received += result.received;
            dropped += result.dropped;
            expected += counters[r].sent.load(Ordering::Relaxed);
            latencies.extend(result.latencies_ms);
        }
        let wall_s = usage_since.elapsed().as_secs_f64();
        let relay = match (pid, usage_start, pid.and_then(process_usage)) {
            (Some(pid), Some((cpu0, _, _)), Some((cpu1, peak, rss))) => Some(RelayUsage {
                pid,
                cpu_s: cpu1 - cpu0,
                cpu_percent: 100.0 * (cpu1 - cpu0) / wall_s,
                rss_peak_mib: peak as f64 / 1024.0,
                rss_end_mib: rss as f64 / 1024.0,
            }),
            _ => None,
        };
        let frames_sent: u64 = counters.iter().map(|c| c.sent.load(Ordering::Relaxed)).sum();
        anyhow::Ok(LoadReport {
            rooms: args.rooms,
            device_streams: args.rooms * args.devices_per_room,
            viewers: args.rooms * args.viewers_per_room,
            hz: args.hz,
            duration_s: args.duration_s,
            frames_sent,
            frames_expected: expected,
            frames_received: received,
            frames_lost: expected.saturating_sub(received),
            dropped_by_relay: dropped,
            latency_ms: Percentiles::of(latencies),
            relay,
        })
    })?;
    print_table(&report);
    println!("{}", serde_json::to_string(&report)?);
    drop(spawned);
    Ok(())
}

fn print_table(report: &LoadReport) {
    let mut rows: BTreeMap<&str, String> = BTreeMap::new();
    rows.insert("1 streams", format!("{} × {} Hz, {} viewers", report.device_streams, report.hz, report.viewers));
    rows.insert(
        "2 frames",
        format!(
            "{} sent, {} received of {}, {} lost, {} dropped by the relay",
            report.frames_sent,
            report.frames_received,
            report.frames_expected,
            report.frames_lost,
            report.dropped_by_relay
        ),
    );
    rows.insert(
        "3 latency",
        format!(
            "p50 {:.2} ms, p95 {:.2} ms, p99 {:.2} ms, max {:.2} ms ({} frames)",
            report.latency_ms.p50,
            report.latency_ms.p95,
            report.latency_ms.p99,
            report.latency_ms.max,
            report.latency_ms.samples
        ),
    );
    if let Some(relay) = &report.relay {
        rows.insert(
            "4 relay",
            format!(
                "CPU {:.2} s ({:.1} % of a core), memory peak {:.1} MiB, end {:.1} MiB",
                relay.cpu_s, relay.cpu_percent, relay.rss_peak_mib, relay.rss_end_mib
            ),
        );
    }
    for (key, value) in rows {
        eprintln!("{:>8}: {value}", &key[2..]);
    }
}
