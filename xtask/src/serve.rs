//! A small static file server for `dist/` (tiny_http): correct media types (`application/wasm`
//! for streaming compilation, `text/javascript` for modules), no caching (a rebuilt app is
//! picked up on reload), nothing outside the folder.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::thread::JoinHandle;

use anyhow::{Result, anyhow};
use tiny_http::{Header, Method, Request, Response, Server, StatusCode};

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

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("ASCII header")
}

fn respond(root: &Path, request: Request) {
    let found = match request.method() {
        Method::Get | Method::Head => resolve(root, request.url()).filter(|p| p.is_file()),
        _ => None,
    };
    let result = match found.and_then(|path| std::fs::File::open(&path).ok().map(|f| (path, f))) {
        Some((path, file)) => {
            let response = Response::from_file(file)
                .with_header(header("Content-Type", content_type(&path)))
                .with_header(header("Cache-Control", "no-cache"));
            request.respond(response)
        }
        None => {
            let status = if matches!(request.method(), Method::Get | Method::Head) { 404 } else { 405 };
            request.respond(Response::from_string("not found").with_status_code(StatusCode(status)))
        }
    };
    if let Err(e) = result {
        eprintln!("serve: {e}");
    }
}

/// A running server; stops when dropped.
pub struct Running {
    pub url: String,
    server: Arc<Server>,
    threads: Vec<JoinHandle<()>>,
}

impl std::fmt::Debug for Running {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Running").field("url", &self.url).finish_non_exhaustive()
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        for _ in &self.threads {
            self.server.unblock();
        }
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// Serves `root` on `addr` (`127.0.0.1:0` picks a free port) from a few threads.
pub fn spawn(root: &Path, addr: &str) -> Result<Running> {
    let server = Arc::new(Server::http(addr).map_err(|e| anyhow!("cannot listen on {addr}: {e}"))?);
    let url = format!("http://{}/", server.server_addr());
    let threads = (0..4)
        .map(|_| {
            let server = Arc::clone(&server);
            let root = root.to_path_buf();
            std::thread::spawn(move || {
                while let Ok(request) = server.recv() {
                    respond(&root, request);
                }
            })
        })
        .collect();
    Ok(Running { url, server, threads })
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
            let content_type =
                head.lines().find_map(|l| l.strip_prefix("Content-Type: ")).unwrap_or_default().to_string();
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
