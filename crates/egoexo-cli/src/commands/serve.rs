//! `egoexo serve`: the hosted page, the share API and the live relay (`egoexo-server`).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Result, bail};
use egoexo_server::{ApiLimits, LiveLimits, Server, ServerOptions};

#[derive(clap::Args)]
pub struct Args {
    /// The built page (`cargo xtask dist`).
    #[arg(long, default_value = "dist")]
    pub dist: PathBuf,
    /// Where shares are stored: a directory (created if missing), a file:// URL, or
    /// s3://bucket/prefix (credentials, region and endpoint from AWS_* variables, e.g.
    /// AWS_ENDPOINT and AWS_ALLOW_HTTP for MinIO or R2).
    #[arg(long, default_value = "egoexo-shares")]
    pub store: String,
    /// Address to listen on (port 0 picks a free one; the URL is printed first).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Largest share accepted, bytes.
    #[arg(long, default_value_t = 64 << 20)]
    pub max_share_bytes: u64,
    /// Uploads a minute one client (IP address) may start.
    #[arg(long, default_value_t = 30)]
    pub uploads_per_minute: u32,
    /// Uploads received at once (more wait, then get 429).
    #[arg(long, default_value_t = 8)]
    pub max_concurrent_uploads: usize,
    /// Seconds a client may take to send a share.
    #[arg(long, default_value_t = 300)]
    pub body_timeout_s: u64,
    /// An origin whose page may use the API from elsewhere (repeatable), e.g.
    /// https://app.example.org for a statically hosted page.
    #[arg(long = "cors-origin")]
    pub cors_origins: Vec<String>,
    /// Take the client address from X-Forwarded-For (only behind a proxy that sets it).
    #[arg(long)]
    pub trust_forwarded_for: bool,
    /// Live rooms open at once (each lives 12 h, or 30 min with nobody connected).
    #[arg(long, default_value_t = 256)]
    pub max_live_rooms: usize,
    /// Seconds between sweeps of expired shares.
    #[arg(long, default_value_t = 600)]
    pub sweep_interval_s: u64,
}

pub fn run(args: Args) -> Result<()> {
    if args.max_share_bytes == 0 {
        bail!("--max-share-bytes must be positive");
    }
    let options = ServerOptions {
        dist: args.dist,
        store: args.store,
        listen: args.listen,
        limits: ApiLimits {
            max_share_bytes: args.max_share_bytes,
            uploads_per_minute: args.uploads_per_minute,
            max_concurrent_uploads: args.max_concurrent_uploads,
            body_timeout: Duration::from_secs(args.body_timeout_s.max(1)),
            trust_forwarded_for: args.trust_forwarded_for,
            ..ApiLimits::default()
        },
        live_limits: LiveLimits { max_rooms: args.max_live_rooms.max(1), ..LiveLimits::default() },
        cors_origins: args.cors_origins,
        sweep_interval: Duration::from_secs(args.sweep_interval_s.max(1)),
    };
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(async move {
        let server = Server::bind(&options).await?;
        // The first line is the address (tools read it when the port was 0).
        println!("listening on http://{}/", server.local_addr);
        eprintln!("egoexo serve: page from {}, shares in {}", options.dist.display(), server.store_description());
        server.run(shutdown_signal()).await
    })
}

/// Ctrl-C or SIGTERM.
async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut signal) => {
                signal.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {}
        _ = terminate => {}
    }
}
