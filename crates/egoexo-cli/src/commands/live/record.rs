//! `egoexo live record --url … --room <watch link> --out take.egoexo`: joins a room as a
//! viewer, files every frame into a [`LiveTake`] and, when stopped (Ctrl-C, `--duration-s`,
//! or `--until-idle-s` after the devices stop), writes the take as an ordinary session.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use egoexo_protocol::live::{ClientMessage, DataFrame, LIVE_PROTOCOL_VERSION, RelayMessage};
use egoexo_session::live::LiveTake;
use futures::{SinkExt, StreamExt};
use serde::Serialize;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::Message;

use super::client::{self, ServerAddress};

#[derive(clap::Args)]
pub struct Args {
    /// The server: http://host:port (its relay is ws://host:port/live).
    #[arg(long)]
    pub url: String,
    /// The room: a watch link (…#live=<room>.<viewer secret>) or `<room>.<secret>`.
    #[arg(long)]
    pub room: String,
    /// Where to write the take (`.egoexo`; a folder with --folder).
    #[arg(long)]
    pub out: PathBuf,
    /// Write the session as a folder instead of a zip.
    #[arg(long)]
    pub folder: bool,
    /// The session's name [default: the file name].
    #[arg(long)]
    pub name: Option<String>,
    /// Stop after this many seconds.
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Stop once frames have arrived and then none for this many seconds.
    #[arg(long)]
    pub until_idle_s: Option<f64>,
}

/// What was recorded (printed as one JSON line).
#[derive(Debug, Serialize)]
pub struct RecordReport {
    pub out: String,
    /// Frames kept per device and stream.
    pub frames: BTreeMap<String, BTreeMap<String, u64>>,
    pub total_frames: u64,
    pub lost_tracking: u64,
    pub duplicates: u64,
    /// Frames the relay dropped for this viewer (it read too slowly).
    pub dropped_by_relay: u64,
    pub head_span_s: f64,
    pub warnings: Vec<String>,
}

pub fn run(args: Args) -> Result<()> {
    let server = ServerAddress::parse(&args.url)?;
    let join = client::parse_join(&args.room)?;
    let name = args
        .name
        .clone()
        .or_else(|| args.out.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "live take".into());
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let (take, dropped) = runtime.block_on(record(&server, join, &args))?;
    let (session, warnings) = take.to_session(&name, None).context("the take cannot be kept")?;
    egoexo_session::format::save_egoexo(&session, &args.out, args.folder)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let stats = take.stats();
    let head_span_s = take.head_range_ns().map(|(a, b)| (b - a) as f64 / 1e9).unwrap_or(0.0);
    let report = RecordReport {
        out: args.out.display().to_string(),
        frames: take.frame_counts(),
        total_frames: stats.frames,
        lost_tracking: stats.lost_tracking,
        duplicates: stats.duplicates,
        dropped_by_relay: dropped,
        head_span_s,
        warnings: warnings.iter().map(ToString::to_string).collect(),
    };
    eprintln!(
        "kept {} frames ({:.1} s of head poses, {} observers) in {}",
        stats.frames,
        head_span_s,
        session.observers.len(),
        args.out.display()
    );
    println!("{}", serde_json::to_string(&report)?);
    Ok(())
}

/// Watches the room until stopped; returns the take and the relay's drop count.
async fn record(server: &ServerAddress, join: egoexo_protocol::live::Join, args: &Args) -> Result<(LiveTake, u64)> {
    let mut socket = client::connect(server).await?;
    let hello = ClientMessage::Hello { protocol: LIVE_PROTOCOL_VERSION, join, device: None };
    client::hello(&mut socket, &hello, client::system_ns).await?;
    eprintln!("recording; Ctrl-C stops and keeps the take");
    let started = Instant::now();
    let deadline = args.duration_s.map(|s| started + Duration::from_secs_f64(s.max(0.0)));
    let idle = args.until_idle_s.map(|s| Duration::from_secs_f64(s.max(0.0)));
    let mut take = LiveTake::new();
    let mut dropped = 0;
    let mut last_frame: Option<Instant> = None;
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    loop {
        // The next moment to stop at, if nothing arrives before it.
        let idle_stop = idle.zip(last_frame).map(|(idle, last)| last + idle);
        let stop_at = [deadline, idle_stop].into_iter().flatten().min();
        let wait = async {
            match stop_at {
                Some(at) => tokio::time::sleep_until(at).await,
                None => std::future::pending().await,
            }
        };
        let message = tokio::select! {
            _ = &mut ctrl_c => break,
            _ = wait => break,
            message = socket.next() => message,
        };
        match message {
            Some(Ok(Message::Binary(bytes))) => {
                let frame = DataFrame::decode(&bytes).context("a frame from the relay")?;
                take.add_frame(&frame);
                last_frame = Some(Instant::now());
            }
            Some(Ok(Message::Text(text))) => match serde_json::from_str::<RelayMessage>(&text) {
                Ok(RelayMessage::Channels { channels }) => take.set_channels(&channels),
                Ok(RelayMessage::Calibration { device, camera }) => take.set_camera(&device, camera),
                Ok(RelayMessage::Status { dropped: d, .. }) => dropped = d,
                Ok(RelayMessage::Ping { relay_ns }) => {
                    let pong = ClientMessage::Pong { relay_ns, device_ns: client::system_ns() };
                    socket.send(client::json(&pong)).await?;
                }
                // A recorder is a viewer: words on observers' worlds and their wearer regions go
                // to observers.
                Ok(
                    RelayMessage::Welcome { .. }
                    | RelayMessage::ObserverWorld { .. }
                    | RelayMessage::WearerRegion { .. },
                ) => {}
                Err(e) => bail!("a message from the relay: {e}"),
            },
            Some(Ok(Message::Close(frame))) => {
                eprintln!("{}; keeping what arrived", client::describe_close(frame.as_ref()));
                break;
            }
            Some(Ok(_)) => {}
            Some(Err(e)) => {
                eprintln!("the relay's socket: {e}; keeping what arrived");
                break;
            }
            None => break,
        }
    }
    let _ = tokio::time::timeout(Duration::from_secs(2), socket.close(None)).await;
    Ok((take, dropped))
}
