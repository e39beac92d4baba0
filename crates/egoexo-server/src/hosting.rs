//! Hosting the page: `dist/` as `cargo xtask dist` builds it, with the headers a production
//! deployment wants.
//!
//! - Assets under `/v/<build>/` (everything but the pages `index.html`, `bench.html`, `xr.html`,
//!   `observe.html`, `config.json` and the icon; the build id changes with any file's content) are
//!   `Cache-Control: public, max-age=31536000, immutable`; the rest is `no-cache`, so a new
//!   build is picked up on the next load and old assets never mix with new ones.
//! - `Content-Security-Policy` without `unsafe-inline` or `unsafe-eval` (the wasm modules
//!   need only `'wasm-unsafe-eval'`), `X-Content-Type-Options: nosniff`,
//!   `Referrer-Policy: no-referrer`, `X-Frame-Options: DENY`.
//! - Media types by extension (`application/wasm`, so browsers compile while downloading);
//!   gzip or brotli for text and wasm, as the client accepts.

use axum::body::Body;
use axum::http::{HeaderValue, Request, Response, header};

/// The page's Content-Security-Policy. `connect-src` admits any https origin: the page opens
/// sessions by URL (`?url=`) and may talk to a share API on another origin.
pub const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; script-src 'self' 'wasm-unsafe-eval'; \
     worker-src 'self'; connect-src 'self' https:; img-src 'self' data: blob:; style-src 'self'; \
     font-src 'self'; object-src 'none'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// `Cache-Control` for a request path.
pub fn cache_control(path: &str) -> &'static str {
    if path.starts_with("/api/") {
        "no-store"
    } else if path.starts_with("/v/") {
        "public, max-age=31536000, immutable"
    } else {
        "no-cache"
    }
}

/// Adds the security and caching headers to a response for `request_path` (a response that
/// already says how to cache itself keeps that).
pub fn add_headers(request_path: &str, response: &mut Response<Body>) {
    let headers = response.headers_mut();
    let set = |headers: &mut axum::http::HeaderMap, name: header::HeaderName, value: &'static str| {
        headers.entry(name).or_insert(HeaderValue::from_static(value));
    };
    set(headers, header::CACHE_CONTROL, cache_control(request_path));
    set(headers, header::CONTENT_SECURITY_POLICY, CONTENT_SECURITY_POLICY);
    set(headers, header::X_CONTENT_TYPE_OPTIONS, "nosniff");
    set(headers, header::REFERRER_POLICY, "no-referrer");
    set(headers, header::X_FRAME_OPTIONS, "DENY");
}

/// Middleware applying [`add_headers`].
pub async fn security_headers(request: Request<Body>, next: axum::middleware::Next) -> Response<Body> {
    let path = request.uri().path().to_owned();
    let mut response = next.run(request).await;
    add_headers(&path, &mut response);
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn versioned_assets_are_immutable_and_the_rest_revalidates() {
        assert_eq!(cache_control("/v/0123abcd/pkg/egoexo_web_worker_bg.wasm"), "public, max-age=31536000, immutable");
        assert_eq!(cache_control("/"), "no-cache");
        assert_eq!(cache_control("/index.html"), "no-cache");
        assert_eq!(cache_control("/api/shares/x"), "no-store");
        assert!(
            !CONTENT_SECURITY_POLICY.contains("'unsafe-inline'") && !CONTENT_SECURITY_POLICY.contains("'unsafe-eval'")
        );
        assert!(CONTENT_SECURITY_POLICY.contains("'wasm-unsafe-eval'"));
    }
}
