//! `egoexo live …`: the command-line end of live capture (docs/live-protocol.md).
//!
//! - `live room` creates a room on a server and prints its device code and links;
//! - `live replay` streams a session as its devices would (the demo source and load generator);
//! - `live record` watches a room and keeps the take as a `.egoexo` session;
//! - `live load` measures the relay under many device streams (latency, losses, CPU, memory).

use anyhow::Result;
use egoexo_protocol::live::LiveLink;

pub mod client;
pub mod load;
pub mod record;
pub mod replay;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(clap::Subcommand)]
pub enum Command {
    /// Create a room: prints its device code, the devices' link and the watch link.
    Room(RoomArgs),
    /// Stream a session in real time as its devices would, one WebSocket per device.
    Replay(replay::Args),
    /// Watch a room and keep what arrives as a `.egoexo` session.
    Record(record::Args),
    /// Load the relay with many device streams and report latency, losses, CPU and memory.
    Load(load::Args),
}

#[derive(clap::Args)]
pub struct RoomArgs {
    /// The server: http://host:port.
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    pub url: String,
    /// Print the room as one JSON line (for scripts) instead of sentences.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> Result<()> {
    match args.command {
        Command::Room(args) => room(args),
        Command::Replay(args) => replay::run(args),
        Command::Record(args) => record::run(args),
        Command::Load(args) => load::run(args),
    }
}

fn room(args: RoomArgs) -> Result<()> {
    let server = client::ServerAddress::parse(&args.url)?;
    let room = client::create_room(&server)?;
    let device = LiveLink { room: room.room.clone(), secret: room.device_secret.clone() };
    let watch = LiveLink { room: room.room.clone(), secret: room.viewer_secret.clone() };
    if args.json {
        let value = serde_json::json!({
            "room": room.room,
            "device_code": room.device_code,
            "device_link": server.device_link(&device),
            "camera_link": server.camera_link(&device),
            "watch_link": server.watch_link(&watch),
            "device_join": device.fragment().trim_start_matches("live="),
            "watch_join": watch.fragment().trim_start_matches("live="),
            "expires_at": room.expires_at,
        });
        println!("{value}");
    } else {
        println!("device code: {}   (type it on a headset at {}/xr.html)", room.device_code, server.http);
        println!("devices:     {}", server.device_link(&device));
        println!("cameras:     {}", server.camera_link(&device));
        println!("watch:       {}", server.watch_link(&watch));
        println!("expires:     {}", room.expires_at);
    }
    Ok(())
}
