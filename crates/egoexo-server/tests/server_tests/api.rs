//! The server end to end on loopback: the share API against a running server (byte-exact
//! round trips, expiry, deletion, limits, bad ids, a bounded load test), and the hosting
//! headers (CSP, caching, media types, compression).
#![cfg(not(target_arch = "wasm32"))]

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use egoexo_protocol::share::{ApiError, ApiErrorKind, CreatedShare, ServerConfig, ShareId};
use egoexo_server::store::{EXPIRED_RECORD_GRACE_S, ShareRecord, now_s, sha256_hex};
use egoexo_server::{ApiLimits, Server, ServerOptions, open_store};

/// A server on a free loopback port, serving a small dist/ and storing shares in a temporary
/// directory; stopped when dropped.
struct Running {
    url: String,
    addr: SocketAddr,
    store_dir: tempfile::TempDir,
    _dist: tempfile::TempDir,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Running {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

fn start(limits: ApiLimits) -> Running {
    let dist = tempfile::tempdir().unwrap();
    write(
        &dist.path().join("index.html"),
        b"<!doctype html><title>egoexo</title><script type=module src=v/b1/main.js></script>",
    );
    write(&dist.path().join("v/b1/main.js"), &b"console.log('egoexo');\n".repeat(200));
    write(&dist.path().join("v/b1/pkg/module_bg.wasm"), b"\0asm\x01\0\0\0");
    let store_dir = tempfile::tempdir().unwrap();
    let options = ServerOptions {
        dist: dist.path().to_path_buf(),
        store: store_dir.path().display().to_string(),
        listen: "127.0.0.1:0".parse().unwrap(),
        limits,
        live_limits: egoexo_server::LiveLimits::default(),
        cors_origins: vec!["https://app.example.org".into()],
        sweep_interval: Duration::from_secs(3600),
    };
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let server = runtime.block_on(Server::bind(&options)).unwrap();
    let addr = server.local_addr;
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let thread = std::thread::spawn(move || {
        runtime
            .block_on(server.run(async move {
                let _ = stopped.await;
            }))
            .unwrap();
    });
    Running { url: format!("http://{addr}"), addr, store_dir, _dist: dist, stop: Some(stop), thread: Some(thread) }
}

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder().http_status_as_error(false).build().into()
}

/// Status and body of a response.
fn answer(response: Result<ureq::http::Response<ureq::Body>, ureq::Error>) -> (u16, Vec<u8>) {
    let mut response = response.expect("the request reaches the server");
    let status = response.status().as_u16();
    (status, response.body_mut().with_config().limit(1 << 30).read_to_vec().unwrap())
}

fn api_error(body: &[u8]) -> ApiError {
    serde_json::from_slice(body).unwrap_or_else(|e| panic!("not an API error ({e}): {}", String::from_utf8_lossy(body)))
}

fn upload(agent: &ureq::Agent, url: &str, bytes: &[u8], expires: &str) -> CreatedShare {
    let (status, body) = answer(agent.post(format!("{url}/api/shares?expires={expires}")).send(bytes));
    assert_eq!(status, 201, "{}", String::from_utf8_lossy(&body));
    serde_json::from_slice(&body).unwrap()
}

fn random(len: usize, seed: u64) -> Vec<u8> {
    egoexo_test_support::pseudo_random_bytes(len, seed)
}

/// Every file under `dir`, relative.
fn files(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push(path.strip_prefix(dir).unwrap().display().to_string());
            }
        }
    }
    out.sort();
    out
}

#[test]
fn a_share_round_trips_byte_exact_and_ids_are_fresh() {
    let server = start(ApiLimits::default());
    let agent = agent();
    let (status, body) = answer(agent.get(format!("{}/api/config", server.url)).call());
    assert_eq!(status, 200);
    let config: ServerConfig = serde_json::from_slice(&body).unwrap();
    assert_eq!(config.max_share_bytes, 64 << 20);

    let bytes = random(3 << 20, 1);
    let created = upload(&agent, &server.url, &bytes, "1d");
    assert_eq!(created.id.as_str().len(), 22);
    assert_eq!(created.delete_token.len(), 22);
    assert!(created.expires_at.ends_with('Z'), "{}", created.expires_at);
    let (status, back) = answer(agent.get(format!("{}/api/shares/{}", server.url, created.id)).call());
    assert_eq!(status, 200);
    assert!(back == bytes, "byte-exact");
    // The store holds the ciphertext and a record with the token's hash only.
    let stored = files(server.store_dir.path());
    assert_eq!(stored, [format!("shares/{}.data", created.id), format!("shares/{}.json", created.id)]);
    let record = std::fs::read_to_string(server.store_dir.path().join(&stored[1])).unwrap();
    assert!(!record.contains(&created.delete_token) && record.contains(&sha256_hex(created.delete_token.as_bytes())));

    let again = upload(&agent, &server.url, &bytes, "1h");
    assert_ne!(again.id, created.id);
    let (status, body) = answer(agent.post(format!("{}/api/shares?expires=2d", server.url)).send(&b"x"[..]));
    assert_eq!((status, api_error(&body).error.kind), (400, ApiErrorKind::BadRequest));
}

#[test]
fn ids_are_checked_before_the_store_is_touched() {
    let server = start(ApiLimits::default());
    let agent = agent();
    for bad in [
        "short",
        "..%2F..%2Fetc%2Fpasswd",
        "AAAAAAAAAAAAAAAAAAAAAAA",
        "AAAAAAAAAAAAAAAAAAAA%20B",
        "AAAAAAAAAAAAAAAAAAAAAB",
    ] {
        let (status, body) = answer(agent.get(format!("{}/api/shares/{bad}", server.url)).call());
        assert_eq!(status, 400, "{bad}");
        assert_eq!(api_error(&body).error.kind, ApiErrorKind::BadRequest);
    }
    let unknown = ShareId::from_bytes([9; 16]);
    let (status, body) = answer(agent.get(format!("{}/api/shares/{unknown}", server.url)).call());
    assert_eq!((status, api_error(&body).error.kind), (404, ApiErrorKind::NotFound));
    let (status, _) = answer(agent.get(format!("{}/api/nothing", server.url)).call());
    assert_eq!(status, 404);
}

#[test]
fn deleting_needs_the_right_token() {
    let server = start(ApiLimits::default());
    let agent = agent();
    let created = upload(&agent, &server.url, b"sealed", "1h");
    let url = format!("{}/api/shares/{}", server.url, created.id);
    let (status, body) = answer(agent.delete(&url).call());
    assert_eq!((status, api_error(&body).error.kind), (401, ApiErrorKind::Unauthorized));
    let (status, body) = answer(agent.delete(&url).header("Authorization", "Bearer not-the-token").call());
    assert_eq!((status, api_error(&body).error.kind), (403, ApiErrorKind::Forbidden));
    assert_eq!(answer(agent.get(&url).call()).0, 200, "a wrong token deletes nothing");
    let bearer = format!("Bearer {}", created.delete_token);
    assert_eq!(answer(agent.delete(&url).header("Authorization", &bearer).call()).0, 204);
    assert_eq!(answer(agent.get(&url).call()).0, 404);
    assert_eq!(answer(agent.delete(&url).header("Authorization", &bearer).call()).0, 404);
    assert!(files(server.store_dir.path()).is_empty());
}

#[test]
fn expired_shares_answer_410_and_the_sweep_removes_them() {
    let server = start(ApiLimits::default());
    let agent = agent();
    let store = open_store(&server.store_dir.path().display().to_string()).unwrap();
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let id = ShareId::from_bytes([3; 16]);
    let created_at = now_s() - 7200;
    let record = ShareRecord {
        created_at,
        expires_at: created_at + 3600,
        delete_token_sha256: sha256_hex(b"t"),
        bytes: 6,
        data_removed: false,
    };
    runtime.block_on(store.put(&id, bytes::Bytes::from_static(b"sealed"), &record)).unwrap();
    let url = format!("{}/api/shares/{id}", server.url);
    let (status, body) = answer(agent.get(&url).call());
    assert_eq!((status, api_error(&body).error.kind), (410, ApiErrorKind::Expired));
    let live = upload(&agent, &server.url, b"alive", "1h");

    let report = runtime.block_on(store.sweep(now_s())).unwrap();
    assert_eq!((report.expired, report.records_removed), (1, 0));
    assert!(!files(server.store_dir.path()).contains(&format!("shares/{id}.data")), "the data is gone");
    assert_eq!(answer(agent.get(&url).call()).0, 410, "the record still says expired");
    assert_eq!(answer(agent.get(format!("{}/api/shares/{}", server.url, live.id)).call()).0, 200);

    let later = record.expires_at + EXPIRED_RECORD_GRACE_S;
    let report = runtime.block_on(store.sweep(later)).unwrap();
    assert_eq!(report.records_removed, 1);
    assert_eq!(answer(agent.get(&url).call()).0, 404);
}

#[test]
fn oversized_uploads_are_refused_and_nothing_is_stored() {
    let limits = ApiLimits { max_share_bytes: 100_000, ..ApiLimits::default() };
    let server = start(limits);
    let agent = agent();
    let (status, body) = answer(agent.post(format!("{}/api/shares", server.url)).send(&random(150_000, 2)[..]));
    let error = api_error(&body);
    assert_eq!((status, error.error.kind), (413, ApiErrorKind::TooLarge));
    assert!(error.error.message.contains("100000"), "{}", error.error.message);
    // A declared size far beyond the limit is refused before the body is read.
    let request = format!("POST /api/shares HTTP/1.1\r\nHost: x\r\nContent-Length: {}\r\n\r\n", 1u64 << 40);
    let (status, _) = raw(server.addr, &request, Duration::ZERO);
    assert!(status.contains(" 413 "), "{status}");
    // Without a Content-Length (chunked), the body is cut off at the limit.
    let mut chunked = std::io::Cursor::new(random(150_000, 3));
    let (status, _) =
        answer(agent.post(format!("{}/api/shares", server.url)).send(ureq::SendBody::from_reader(&mut chunked)));
    assert_eq!(status, 413);
    assert_eq!(answer(agent.post(format!("{}/api/shares", server.url)).send(&b""[..])).0, 400, "empty");
    assert!(files(server.store_dir.path()).is_empty());
    upload(&agent, &server.url, &random(100_000, 4), "1h");
}

#[test]
fn a_store_that_cannot_write_answers_507_and_says_so_in_json() {
    let server = start(ApiLimits::default());
    let agent = agent();
    // Where the shares folder should be stands a file: every write fails.
    let shares = server.store_dir.path().join("shares");
    let _ = std::fs::remove_dir_all(&shares);
    std::fs::write(&shares, b"not a folder").unwrap();
    let (status, body) = answer(agent.post(format!("{}/api/shares", server.url)).send(&b"sealed"[..]));
    let error = api_error(&body);
    assert_eq!((status, error.error.kind), (507, ApiErrorKind::Storage));
    assert!(
        !error.error.message.contains(&server.store_dir.path().display().to_string()),
        "no paths leak: {}",
        error.error.message
    );
}

#[test]
fn uploads_are_rate_limited_per_client() {
    let server = start(ApiLimits { uploads_per_minute: 5, ..ApiLimits::default() });
    let agent = agent();
    for i in 0..5 {
        upload(&agent, &server.url, &random(100, i), "1h");
    }
    let (status, body) = answer(agent.post(format!("{}/api/shares", server.url)).send(&b"one more"[..]));
    assert_eq!((status, api_error(&body).error.kind), (429, ApiErrorKind::RateLimited));
    assert_eq!(files(server.store_dir.path()).len(), 10);
}

/// Raw HTTP/1.1 on a socket: the status line and headers (lowercased names), and whether the
/// server answered at all within the timeout.
fn raw(addr: SocketAddr, request: &str, then_sleep: Duration) -> (String, Vec<(String, String)>) {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    stream.write_all(request.as_bytes()).unwrap();
    std::thread::sleep(then_sleep);
    let mut response = Vec::new();
    let _ = stream.read_to_end(&mut response);
    let text = String::from_utf8_lossy(&response).into_owned();
    let head = text.split("\r\n\r\n").next().unwrap_or_default();
    let mut lines = head.lines();
    let status = lines.next().unwrap_or_default().to_string();
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    (status, headers)
}

fn header<'a>(headers: &'a [(String, String)], name: &str) -> Option<&'a str> {
    headers.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
}

#[test]
fn a_stalled_upload_times_out() {
    let server = start(ApiLimits { body_timeout: Duration::from_secs(1), ..ApiLimits::default() });
    let request = "POST /api/shares HTTP/1.1\r\nHost: x\r\nContent-Length: 1000\r\nConnection: close\r\n\r\n0123456789";
    let (status, _) = raw(server.addr, request, Duration::from_millis(1500));
    assert!(status.contains(" 408 "), "{status}");
    assert!(files(server.store_dir.path()).is_empty());
}

#[test]
fn the_page_is_served_with_a_strict_policy_and_immutable_versioned_assets() {
    let server = start(ApiLimits::default());
    let get = |path: &str, encoding: &str| {
        raw(
            server.addr,
            &format!("GET {path} HTTP/1.1\r\nHost: x\r\nAccept-Encoding: {encoding}\r\nConnection: close\r\n\r\n"),
            Duration::ZERO,
        )
    };
    let (status, page) = get("/", "identity");
    assert!(status.contains(" 200 "), "{status}");
    assert_eq!(header(&page, "content-type"), Some("text/html"));
    assert_eq!(header(&page, "cache-control"), Some("no-cache"));
    let csp = header(&page, "content-security-policy").unwrap();
    assert!(csp.contains("script-src 'self' 'wasm-unsafe-eval'") && !csp.contains("unsafe-inline"), "{csp}");
    assert_eq!(header(&page, "x-content-type-options"), Some("nosniff"));
    assert_eq!(header(&page, "referrer-policy"), Some("no-referrer"));

    let (_, script) = get("/v/b1/main.js", "br");
    assert_eq!(header(&script, "cache-control"), Some("public, max-age=31536000, immutable"));
    assert_eq!(header(&script, "content-type"), Some("text/javascript"));
    assert_eq!(header(&script, "content-encoding"), Some("br"));
    let (_, gzipped) = get("/v/b1/main.js", "gzip");
    assert_eq!(header(&gzipped, "content-encoding"), Some("gzip"));
    let (_, wasm) = get("/v/b1/pkg/module_bg.wasm", "identity");
    assert_eq!(header(&wasm, "content-type"), Some("application/wasm"));
    let (status, _) = get("/v/b1/../../../etc/passwd", "identity");
    assert!(status.contains(" 404 ") || status.contains(" 400 "), "{status}");

    // CORS: the allow-listed origin may call the API; others get no grant.
    let preflight = |origin: &str| {
        raw(
            server.addr,
            &format!(
                "OPTIONS /api/shares HTTP/1.1\r\nHost: x\r\nOrigin: {origin}\r\nAccess-Control-Request-Method: POST\r\nConnection: close\r\n\r\n"
            ),
            Duration::ZERO,
        )
        .1
    };
    assert_eq!(
        header(&preflight("https://app.example.org"), "access-control-allow-origin"),
        Some("https://app.example.org")
    );
    assert_eq!(header(&preflight("https://evil.example"), "access-control-allow-origin"), None);
}

/// A bounded load: 16 clients upload 200 shares and read each back (byte-exact) while
/// re-reading others; prints request counts and latency percentiles.
#[test]
fn concurrent_uploads_and_downloads_stay_byte_exact() {
    let server = start(ApiLimits { uploads_per_minute: 10_000, ..ApiLimits::default() });
    let url = Arc::new(server.url.clone());
    let clients = 16;
    let per_client = 12;
    let started = Instant::now();
    let threads: Vec<_> = (0..clients)
        .map(|c| {
            let url = url.clone();
            std::thread::spawn(move || {
                let agent = agent();
                let mut latencies = Vec::new();
                let mut mine = Vec::new();
                for i in 0..per_client {
                    let bytes = random(20_000 + 997 * i, (c * 1000 + i) as u64);
                    let t = Instant::now();
                    let created = upload(&agent, &url, &bytes, "1h");
                    latencies.push(t.elapsed());
                    mine.push((created.id, bytes));
                    for (id, expected) in &mine {
                        let t = Instant::now();
                        let (status, back) = answer(agent.get(format!("{url}/api/shares/{id}")).call());
                        latencies.push(t.elapsed());
                        assert_eq!(status, 200);
                        assert!(&back == expected, "byte-exact under load");
                    }
                }
                latencies
            })
        })
        .collect();
    let mut latencies: Vec<Duration> = threads.into_iter().flat_map(|t| t.join().unwrap()).collect();
    let elapsed = started.elapsed();
    latencies.sort();
    let pct = |p: f64| latencies[((latencies.len() - 1) as f64 * p).round() as usize];
    let uploads = clients * per_client;
    assert_eq!(latencies.len(), uploads + clients * per_client * (per_client + 1) / 2);
    eprintln!(
        "LOAD {} requests ({uploads} uploads) from {clients} clients in {:.2} s, 0 errors; p50 {:.1} ms, p95 {:.1} ms, max {:.1} ms",
        latencies.len(),
        elapsed.as_secs_f64(),
        pct(0.5).as_secs_f64() * 1e3,
        pct(0.95).as_secs_f64() * 1e3,
        latencies.last().unwrap().as_secs_f64() * 1e3,
    );
    assert_eq!(files(server.store_dir.path()).len(), 2 * uploads);
}
