//! The share API (`egoexo_protocol::share`, `docs/share-format.md`): create, read and delete
//! sealed shares, and the server's limits. Every request is hostile until checked: ids are
//! validated before storage is touched, bodies are bounded in size and time, uploads are
//! rate-limited per client and bounded in number at once.

use std::net::{IpAddr, SocketAddr};
use std::num::NonZeroU32;
use std::sync::Arc;
use std::time::Duration;

use axum::Json;
use axum::body::Body;
use axum::extract::{ConnectInfo, Path, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use egoexo_protocol::share::{
    ApiError, ApiErrorBody, ApiErrorKind, CreatedShare, Expiry, SHARE_API_VERSION, ServerConfig, ShareId, base64url,
};
use governor::{DefaultKeyedRateLimiter, Quota, RateLimiter};
use http_body_util::BodyExt;
use serde::Deserialize;
use tokio::sync::Semaphore;

use crate::store::{ShareRecord, ShareStore, StoreError, now_s, sha256_hex};

/// The API's limits.
#[derive(Clone, Debug)]
pub struct ApiLimits {
    /// Largest share accepted, bytes.
    pub max_share_bytes: u64,
    /// Uploads per minute one client (IP address) may start.
    pub uploads_per_minute: u32,
    /// Uploads received at once; more wait up to [`ApiLimits::upload_queue_wait`].
    pub max_concurrent_uploads: usize,
    /// How long an upload waits for its turn before it is refused (429).
    pub upload_queue_wait: Duration,
    /// How long a client may take to send a share's body (408 after).
    pub body_timeout: Duration,
    /// Take the client's address from the first `X-Forwarded-For` entry (behind a proxy).
    pub trust_forwarded_for: bool,
}

impl Default for ApiLimits {
    /// 64 MiB shares, 30 uploads a minute per client, 8 at once (waiting up to 10 s), 5 min to
    /// send a body.
    fn default() -> Self {
        Self {
            max_share_bytes: 64 << 20,
            uploads_per_minute: 30,
            max_concurrent_uploads: 8,
            upload_queue_wait: Duration::from_secs(10),
            body_timeout: Duration::from_secs(300),
            trust_forwarded_for: false,
        }
    }
}

/// What the API handlers share.
#[derive(Debug)]
pub struct ApiState {
    pub store: ShareStore,
    pub limits: ApiLimits,
    uploads: Semaphore,
    rate: DefaultKeyedRateLimiter<IpAddr>,
}

impl ApiState {
    pub fn new(store: ShareStore, limits: ApiLimits) -> Self {
        let per_minute = NonZeroU32::new(limits.uploads_per_minute.max(1)).unwrap_or(NonZeroU32::MIN);
        Self {
            store,
            uploads: Semaphore::new(limits.max_concurrent_uploads.max(1)),
            rate: RateLimiter::keyed(Quota::per_minute(per_minute)),
            limits,
        }
    }

    /// Forgets rate-limit state of clients that have not been seen for a while (bounds the
    /// memory it takes).
    pub fn forget_idle_clients(&self) {
        self.rate.retain_recent();
        self.rate.shrink_to_fit();
    }
}

/// An API error answer.
#[derive(Debug)]
pub struct Failure(pub ApiErrorKind, pub String);

impl IntoResponse for Failure {
    fn into_response(self) -> Response {
        let status = StatusCode::from_u16(self.0.status()).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        let body = ApiError { error: ApiErrorBody { kind: self.0, message: self.1 } };
        (status, [(header::CACHE_CONTROL, "no-store")], Json(body)).into_response()
    }
}

impl From<StoreError> for Failure {
    fn from(e: StoreError) -> Self {
        let kind = match &e {
            StoreError::NotFound(_) => ApiErrorKind::NotFound,
            StoreError::Expired(_) => ApiErrorKind::Expired,
            StoreError::Forbidden(_) => ApiErrorKind::Forbidden,
            StoreError::Storage(message) => {
                eprintln!("egoexo serve: {message}");
                ApiErrorKind::Storage
            }
        };
        let message = match e {
            StoreError::Storage(_) => "the share store cannot take or give this share now".to_string(),
            e => e.to_string(),
        };
        Failure(kind, message)
    }
}

fn parse_id(text: &str) -> Result<ShareId, Failure> {
    ShareId::parse(text).map_err(|message| Failure(ApiErrorKind::BadRequest, message))
}

/// The client's address: the connection's peer, or (when trusted) the first
/// `X-Forwarded-For` entry.
pub(crate) fn client_ip(trust_forwarded_for: bool, peer: SocketAddr, headers: &HeaderMap) -> IpAddr {
    let forwarded = || {
        let first = headers.get("x-forwarded-for")?.to_str().ok()?.split(',').next()?;
        first.trim().parse().ok()
    };
    if trust_forwarded_for { forwarded().unwrap_or(peer.ip()) } else { peer.ip() }
}

/// `POST /api/shares` query.
#[derive(Debug, Deserialize)]
pub struct CreateQuery {
    pub expires: Option<String>,
}

/// `POST /api/shares?expires=1h|1d|30d` (default 1d): stores the body, a sealed share.
pub async fn create_share(
    State(state): State<Arc<ApiState>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    Query(query): Query<CreateQuery>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, Failure> {
    let expiry = match query.expires.as_deref() {
        None => Expiry::OneDay,
        Some(text) => Expiry::parse(text).map_err(|m| Failure(ApiErrorKind::BadRequest, m))?,
    };
    let limits = &state.limits;
    let too_large = |size: String| {
        Failure(
            ApiErrorKind::TooLarge,
            format!("the share is {size}; this server takes shares up to {} bytes", limits.max_share_bytes),
        )
    };
    if let Some(length) = headers.get(header::CONTENT_LENGTH).and_then(|v| v.to_str().ok()?.parse::<u64>().ok())
        && length > limits.max_share_bytes.saturating_add(DRAIN_BYTES)
    {
        // Far too large to read and discard: answer at once (the connection closes).
        return Err(too_large(format!("{length} bytes")));
    }
    let ip = client_ip(limits.trust_forwarded_for, peer, &headers);
    if state.rate.check_key(&ip).is_err() {
        return Err(Failure(
            ApiErrorKind::RateLimited,
            format!("more than {} uploads a minute from {ip}; try again in a minute", limits.uploads_per_minute),
        ));
    }
    let _permit = tokio::time::timeout(limits.upload_queue_wait, state.uploads.acquire())
        .await
        .map_err(|_| Failure(ApiErrorKind::RateLimited, "too many uploads at once; try again shortly".into()))?
        .map_err(|_| Failure(ApiErrorKind::Storage, "the server is shutting down".into()))?;
    let data = read_limited(body, limits.max_share_bytes, limits.body_timeout).await.map_err(|e| match e {
        BodyFailure::TooLarge => too_large(format!("more than {} bytes", limits.max_share_bytes)),
        BodyFailure::Timeout => {
            Failure(ApiErrorKind::Timeout, format!("the upload took longer than {} s", limits.body_timeout.as_secs()))
        }
        BodyFailure::Broken(m) => Failure(ApiErrorKind::BadRequest, format!("the upload broke off: {m}")),
    })?;
    if data.is_empty() {
        return Err(Failure(ApiErrorKind::BadRequest, "the share is empty".into()));
    }
    let id = ShareId::from_bytes(random_bytes()?);
    let delete_token = base64url(&random_bytes()?);
    let created_at = now_s();
    let expires_at = created_at + expiry.seconds();
    let record = ShareRecord {
        created_at,
        expires_at,
        delete_token_sha256: sha256_hex(delete_token.as_bytes()),
        bytes: data.len() as u64,
        data_removed: false,
    };
    state.store.put(&id, data, &record).await?;
    let created = CreatedShare { id, delete_token, expires_at: rfc3339(expires_at) };
    Ok((StatusCode::CREATED, [(header::CACHE_CONTROL, "no-store")], Json(created)).into_response())
}

/// `GET /api/shares/{id}`: the sealed bytes, streamed from the store.
pub async fn get_share(State(state): State<Arc<ApiState>>, Path(id): Path<String>) -> Result<Response, Failure> {
    let id = parse_id(&id)?;
    let (size, stream) = state.store.get_stream(&id, now_s()).await?;
    Ok((
        [
            (header::CONTENT_TYPE, HeaderValue::from_static("application/octet-stream")),
            (header::CONTENT_LENGTH, HeaderValue::from(size)),
            // The link is the secret; caches between the client and the server need not keep it.
            (header::CACHE_CONTROL, HeaderValue::from_static("private, no-store")),
        ],
        Body::from_stream(stream),
    )
        .into_response())
}

/// `DELETE /api/shares/{id}` with `Authorization: Bearer <delete_token>`.
pub async fn delete_share(
    State(state): State<Arc<ApiState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, Failure> {
    let id = parse_id(&id)?;
    let token = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .ok_or_else(|| {
            Failure(ApiErrorKind::Unauthorized, "deleting a share needs `Authorization: Bearer <delete token>`".into())
        })?;
    state.store.delete(&id, token).await?;
    Ok(StatusCode::NO_CONTENT.into_response())
}

/// `GET /api/config`.
pub async fn config(State(state): State<Arc<ApiState>>) -> Json<ServerConfig> {
    Json(ServerConfig {
        api_version: SHARE_API_VERSION,
        max_share_bytes: state.limits.max_share_bytes,
        expiries: Expiry::ALL.to_vec(),
    })
}

/// Anything else under `/api/`.
pub async fn unknown_api() -> Failure {
    Failure(ApiErrorKind::NotFound, "no such API endpoint".into())
}

enum BodyFailure {
    TooLarge,
    Timeout,
    Broken(String),
}

/// How much of an oversized body is read and discarded before the 413, so that a client
/// still sending sees the answer rather than a reset connection.
const DRAIN_BYTES: u64 = 8 << 20;

/// Reads a body of at most `limit` bytes within `timeout` (an oversized one is discarded, up
/// to [`DRAIN_BYTES`] past the limit).
async fn read_limited(body: Body, limit: u64, timeout: Duration) -> Result<Bytes, BodyFailure> {
    let read = async {
        let mut body = body;
        let mut out = bytes::BytesMut::new();
        let mut discarded: u64 = 0;
        while let Some(frame) = body.frame().await {
            let frame = frame.map_err(|e| BodyFailure::Broken(e.to_string()))?;
            let Ok(data) = frame.into_data() else { continue };
            if discarded > 0 || (out.len() + data.len()) as u64 > limit {
                discarded += data.len() as u64;
                out = bytes::BytesMut::new();
                if discarded > DRAIN_BYTES {
                    break;
                }
                continue;
            }
            out.extend_from_slice(&data);
        }
        if discarded > 0 { Err(BodyFailure::TooLarge) } else { Ok(out.freeze()) }
    };
    tokio::time::timeout(timeout, read).await.map_err(|_| BodyFailure::Timeout)?
}

fn random_bytes() -> Result<[u8; 16], Failure> {
    let mut bytes = [0; 16];
    getrandom::fill(&mut bytes).map_err(|e| Failure(ApiErrorKind::Storage, format!("no random numbers: {e}")))?;
    Ok(bytes)
}

/// Unix seconds as RFC 3339 UTC.
pub fn rfc3339(unix_s: u64) -> String {
    humantime::format_rfc3339_seconds(std::time::UNIX_EPOCH + Duration::from_secs(unix_s)).to_string()
}
