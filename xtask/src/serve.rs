//! A small static file server for `dist/` (axum): correct media types (`application/wasm`
//! for streaming compilation, `text/javascript` for modules), no caching (a rebuilt app is
//! picked up on reload), nothing outside the folder.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::thread::JoinHandle;

use anyhow::{Context, Result};
use axum::Router;
use axum::extract::State;
use axum::http::{Method, StatusCode, Uri, header};
use axum::response::{IntoResponse, Response};
use tokio::sync::oneshot;

/// Media type by file extension.
pub fn content_type(path: &Path) -> &'static str {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or_default().to_ascii_lowercase();
    match ext.as_str() {
        "html" | "htm" => "text/html; charset=utf-8",
        "js" | "mjs" => "text/javascript; charset=utf-8",
        "css" => "text/css; charset=utf-8",
        "json" => "application/json",
        "wasm" => "application/wasm",
        "md" | "txt" => "text/plain; charset=utf-8",
        "svg" => "image/svg+xml",
        "png" => "image/png",
        "ico" => "image/x-icon",
        "egoexo" | "zip" => "application/zip",
        _ => "application/octet-stream",
    }
}

/// The file a request path names inside `root`, or `None` if it could leave it.
fn resolve(root: &Path, url: &str) -> Option<PathBuf> {
    let path = url.split(['?', '#']).next().unwrap_or_default();
    let mut out = root.to_path_buf();
    for part in path.split('/') {
        match part {
            "" | "." => {}
            ".." => return None,
            // dist/ has no names that need percent-encoding; refusing them closes `%2e%2e`.
            p if p.contains(['\\', '\0', '%']) => return None,
            p => out.push(p),
        }
    }
    if out.is_dir() {
        out.push("index.html");
    }
    Some(out)
}

/// `GET`/`HEAD` of a file under `root`, with its media type; 404 for anything else there is.
async fn serve_file(State(root): State<Arc<PathBuf>>, method: Method, uri: Uri) -> Response {
    if method != Method::GET && method != Method::HEAD {
        return (StatusCode::METHOD_NOT_ALLOWED, "method not allowed").into_response();
    }
    let Some(path) = resolve(&root, uri.path()) else {
        return (StatusCode::NOT_FOUND, "not found").into_response();
    };
    match tokio::fs::read(&path).await {
        Ok(bytes) => {
            ([(header::CONTENT_TYPE, content_type(&path)), (header::CACHE_CONTROL, "no-cache")], bytes).into_response()
        }
        Err(_) => (StatusCode::NOT_FOUND, "not found").into_response(),
    }
}

/// A running server; stops when dropped.
pub struct Running {
    pub url: String,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Running {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Running").field("url", &self.url).finish_non_exhaustive()
    }
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

/// Serves `root` on `addr` (`127.0.0.1:0` picks a free port) from its own thread (axum on a
/// two-thread tokio runtime; every connection is its own task, so a browser's parallel and
/// kept-alive connections never wait on each other).
pub fn spawn(root: &Path, addr: &str) -> Result<Running> {
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    let listener =
        runtime.block_on(tokio::net::TcpListener::bind(addr)).with_context(|| format!("cannot listen on {addr}"))?;
    let url = format!("http://{}/", listener.local_addr()?);
    let app = Router::new().fallback(serve_file).with_state(Arc::new(root.to_path_buf()));
    let (stop, stopped) = oneshot::channel::<()>();
    let thread = std::thread::spawn(move || {
        runtime.block_on(async move {
            tokio::select! {
                result = axum::serve(listener, app) => {
                    if let Err(e) = result {
                        eprintln!("serve: {e}");
                    }
                }
                _ = stopped => {}
            }
        });
        // Dropping the runtime here cancels the connections still open (kept-alive ones).
    });
    Ok(Running { url, stop: Some(stop), thread: Some(thread) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn media_types_that_browsers_insist_on() {
        assert_eq!(content_type(Path::new("pkg/egoexo_viewer_bg.wasm")), "application/wasm");
        assert_eq!(content_type(Path::new("main.js")), "text/javascript; charset=utf-8");
        assert_eq!(content_type(Path::new("models/manifest.json")), "application/json");
        assert_eq!(content_type(Path::new("index.HTML")), "text/html; charset=utf-8");
        assert_eq!(content_type(Path::new("models/1pt/egonet.onnx")), "application/octet-stream");
    }

    #[test]
    fn requests_stay_inside_the_folder() {
        let root = Path::new("/srv/dist");
        assert_eq!(resolve(root, "/main.js?v=1"), Some(root.join("main.js")));
        assert_eq!(resolve(root, "/models/1pt/egonet.onnx"), Some(root.join("models/1pt/egonet.onnx")));
        assert_eq!(resolve(root, "/../etc/passwd"), None);
        assert_eq!(resolve(root, "/a/%2e%2e/b"), None);
    }

    #[test]
    fn serves_files_with_their_types_and_404s_the_rest() {
        let dir = std::env::temp_dir().join(format!("egoexo-serve-test-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("pkg")).unwrap();
        std::fs::write(dir.join("index.html"), "<!doctype html>").unwrap();
        std::fs::write(dir.join("pkg/m_bg.wasm"), b"\0asm").unwrap();
        let running = spawn(&dir, "127.0.0.1:0").unwrap();
        let get = |path: &str| -> (u16, String, Vec<u8>) {
            use std::io::{Read, Write};
            let addr = running.url.trim_start_matches("http://").trim_end_matches('/');
            let mut stream = std::net::TcpStream::connect(addr).unwrap();
            write!(stream, "GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n").unwrap();
            let mut raw = Vec::new();
            stream.read_to_end(&mut raw).unwrap();
            let split = raw.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
            let head = String::from_utf8_lossy(&raw[..split]).to_string();
            let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
            // Header names are case-insensitive (hyper writes them in lower case).
            let content_type = head
                .lines()
                .find_map(|l| l.split_once(':').filter(|(name, _)| name.eq_ignore_ascii_case("content-type")))
                .map(|(_, value)| value.trim().to_string())
                .unwrap_or_default();
            (status, content_type, raw[split + 4..].to_vec())
        };
        assert_eq!(get("/"), (200, "text/html; charset=utf-8".into(), b"<!doctype html>".to_vec()));
        assert_eq!(get("/pkg/m_bg.wasm"), (200, "application/wasm".into(), b"\0asm".to_vec()));
        assert_eq!(get("/missing.js").0, 404);
        assert_eq!(get("/../Cargo.toml").0, 404);
        drop(running);
        std::fs::remove_dir_all(dir).unwrap();
    }
}
