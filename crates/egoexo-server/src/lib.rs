//! The egoexo server, `egoexo serve`: the hosted page and the share API, on one axum router.
//!
//! - [`hosting`] — `dist/` with immutable versioned assets, a strict Content-Security-Policy
//!   and compression.
//! - [`api`] — `/api/shares`: create, read and delete end-to-end-encrypted shares (the server
//!   sees ciphertext only), `/api/config`; size, time, rate and concurrency limits.
//! - [`store`] — the shares in an `object_store` backend: a local directory (the default) or
//!   an S3-compatible bucket (`s3://bucket/prefix`), atomic writes, an expiry sweep.
//! - [`live`] — the live relay: `/api/live/rooms` and the `/live` WebSocket that devices
//!   publish into and viewers watch.

pub mod api;
pub mod hosting;
pub mod live;
pub mod store;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use axum::Router;
use axum::http::{HeaderValue, Method};
use axum::routing::get;
use object_store::ObjectStore;
use object_store::path::Path as StorePath;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::services::ServeDir;

pub use api::ApiLimits;
pub use live::{LiveLimits, LiveState};
pub use store::ShareStore;

/// Everything `egoexo serve` takes.
#[derive(Clone, Debug)]
pub struct ServerOptions {
    /// The built page (`cargo xtask dist`).
    pub dist: PathBuf,
    /// Where shares go: a directory path or `file:///…` URL, or `s3://bucket/prefix`
    /// (credentials, region and endpoint from the usual `AWS_*` variables).
    pub store: String,
    /// Address to listen on (`127.0.0.1:0` picks a free port).
    pub listen: SocketAddr,
    pub limits: ApiLimits,
    pub live_limits: LiveLimits,
    /// Origins (`https://app.example.org`) whose pages may call the API from another origin.
    pub cors_origins: Vec<String>,
    /// How often expired shares are swept.
    pub sweep_interval: Duration,
}

/// Opens the share store named by `location` (see [`ServerOptions::store`]).
pub fn open_store(location: &str) -> Result<ShareStore> {
    if let Some(rest) = location.strip_prefix("s3://") {
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        if bucket.is_empty() {
            bail!("`{location}`: expected s3://bucket[/prefix]");
        }
        let store = object_store::aws::AmazonS3Builder::from_env()
            .with_bucket_name(bucket)
            .build()
            .with_context(|| format!("opening {location} (AWS_* variables give credentials, region, endpoint)"))?;
        return Ok(ShareStore::new(Arc::new(store) as Arc<dyn ObjectStore>, StorePath::from(prefix)));
    }
    if location.contains("://") && !location.starts_with("file://") {
        bail!("`{location}`: the share store is a directory, a file:// URL or s3://bucket/prefix");
    }
    let dir = PathBuf::from(location.strip_prefix("file://").unwrap_or(location));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating the share store {}", dir.display()))?;
    let store = object_store::local::LocalFileSystem::new_with_prefix(&dir)
        .with_context(|| format!("opening the share store {}", dir.display()))?;
    Ok(ShareStore::new(Arc::new(store), StorePath::from("")))
}

/// The whole router: `/api/*`, `/live` and the page.
pub fn router(options: &ServerOptions, store: ShareStore) -> Result<(Router, Arc<api::ApiState>, Arc<LiveState>)> {
    if !options.dist.join("index.html").is_file() {
        bail!(
            "{} has no index.html: build the page first (`cargo xtask dist`, or `cargo xtask serve`, which builds and serves it)",
            options.dist.display()
        );
    }
    let state = Arc::new(api::ApiState::new(store, options.limits.clone()));
    let live = Arc::new(LiveState::new(options.live_limits.clone(), options.limits.trust_forwarded_for));
    let origins: Vec<HeaderValue> = options
        .cors_origins
        .iter()
        .map(|o| HeaderValue::from_str(o.trim_end_matches('/')).with_context(|| format!("CORS origin `{o}`")))
        .collect::<Result<_>>()?;
    let cors = CorsLayer::new()
        .allow_origin(AllowOrigin::list(origins))
        .allow_methods([Method::GET, Method::POST, Method::DELETE])
        .allow_headers([axum::http::header::AUTHORIZATION, axum::http::header::CONTENT_TYPE])
        .max_age(Duration::from_secs(600));
    let live_routes = Router::new()
        .route("/api/live/rooms", axum::routing::post(live::create_room))
        .route("/live", get(live::live_socket))
        .with_state(live.clone());
    let api = Router::new()
        .merge(live_routes)
        .route("/api/shares", axum::routing::post(api::create_share))
        .route("/api/shares/{id}", get(api::get_share).delete(api::delete_share))
        .route("/api/config", get(api::config))
        .route("/api/{*rest}", axum::routing::any(api::unknown_api))
        // The body is bounded by the handler (size and time); axum's own limit is lifted so
        // the handler can say 413 with the numbers.
        .layer(axum::extract::DefaultBodyLimit::disable())
        .layer(cors)
        .with_state(state.clone());
    let app = Router::new()
        .merge(api)
        .fallback_service(ServeDir::new(&options.dist).append_index_html_on_directories(true))
        .layer(axum::middleware::from_fn(hosting::security_headers))
        .layer(CompressionLayer::new().gzip(true).br(true));
    Ok((app, state, live))
}

/// A bound server: its address, and the future that runs it until `shutdown` resolves.
pub struct Server {
    pub local_addr: SocketAddr,
    listener: tokio::net::TcpListener,
    app: Router,
    state: Arc<api::ApiState>,
    live: Arc<LiveState>,
    sweep_interval: Duration,
}

impl std::fmt::Debug for Server {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Server").field("local_addr", &self.local_addr).finish_non_exhaustive()
    }
}

impl Server {
    /// Opens the store, builds the router and binds the address.
    pub async fn bind(options: &ServerOptions) -> Result<Server> {
        let store = open_store(&options.store)?;
        let (app, state, live) = router(options, store)?;
        let listener = tokio::net::TcpListener::bind(options.listen)
            .await
            .with_context(|| format!("cannot listen on {}", options.listen))?;
        Ok(Server {
            local_addr: listener.local_addr()?,
            listener,
            app,
            state,
            live,
            sweep_interval: options.sweep_interval,
        })
    }

    /// Where shares are stored, in words.
    pub fn store_description(&self) -> String {
        self.state.store.describe()
    }

    /// The live relay's state.
    pub fn live(&self) -> Arc<LiveState> {
        self.live.clone()
    }

    /// Serves until `shutdown` resolves, sweeping expired shares and ticking the live rooms
    /// meanwhile. At shutdown, live clients are closed ("going away") so that the server
    /// need not wait for their sockets.
    pub async fn run(self, shutdown: impl Future<Output = ()> + Send + 'static) -> Result<()> {
        let sweep = tokio::spawn(self.state.store.clone().sweep_every(self.sweep_interval));
        let rooms = tokio::spawn(self.live.clone().run());
        let live = self.live.clone();
        let shutdown = async move {
            shutdown.await;
            live.close_all();
        };
        let state = self.state.clone();
        let tidy = tokio::spawn(async move {
            let mut ticks = tokio::time::interval(Duration::from_secs(60));
            loop {
                ticks.tick().await;
                state.forget_idle_clients();
            }
        });
        let service = self.app.into_make_service_with_connect_info::<SocketAddr>();
        let result = axum::serve(self.listener, service).with_graceful_shutdown(shutdown).await;
        sweep.abort();
        tidy.abort();
        rooms.abort();
        result.context("serving")
    }
}
