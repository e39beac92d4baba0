//! The models in the browser: `manifest.json` and the files it lists fetched from the models
//! URL, kept in the Cache API keyed by their sha256 (only what checked out; other versions
//! forgotten), checked and loaded by [`SessionWorker`]; a failure with cached files clears
//! them and fetches once more. Failures name the file and say whether the models are missing
//! from the build or unreachable.

use std::collections::{BTreeMap, BTreeSet};

use egoexo_infer::InferError;
use egoexo_protocol::worker::{ErrorKind, ModelFileRef, ModelsSummary};
use js_sys::{Array, Promise, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen_futures::JsFuture;
use web_sys::{Cache, DedicatedWorkerGlobalScope, RequestCache, RequestInit, Response, Url};

use super::{ModelsFailure, Runtime, js_message};
use crate::worker::SessionWorker;

/// The Cache API cache holding the model files.
pub const MODEL_CACHE: &str = "egoexo-models";

impl Runtime {
    /// Fetches `manifest.json` and the files it lists (from the cache where it has them) and
    /// loads them; once more without the cache if that fails with cached files.
    pub(super) async fn load_models(&self) -> Result<ModelsSummary, ModelsFailure> {
        let started = self.clock_ms();
        let manifest_url = resolve_url("manifest.json", &self.models_url)?;
        let manifest = fetch_bytes(&self.scope, &manifest_url, true).await?;
        let listed = SessionWorker::model_files(&manifest).map_err(|e| (e.kind(), e.to_string()))?;
        let cache = open_cache(&self.scope).await;
        let first = self.load_listed(&manifest, &listed, cache.as_ref(), true, started).await;
        match (first, &cache) {
            (Ok(summary), _) => Ok(summary),
            (Err(failure), None) => Err(failure),
            (Err(_), Some(cache)) => {
                // A cached file may be stale or damaged: fetch everything again once.
                for f in &listed {
                    let _ = JsFuture::from(cache.delete_with_str(&self.cache_key(f)?)).await;
                }
                self.load_listed(&manifest, &listed, Some(cache), false, started).await
            }
        }
    }

    /// The cache key of a model file: its URL with its sha256 as the query.
    pub(super) fn cache_key(&self, file: &ModelFileRef) -> Result<String, ModelsFailure> {
        Ok(format!("{}?sha256={}", resolve_url(&file.file, &self.models_url)?, file.sha256))
    }

    async fn load_listed(
        &self,
        manifest: &[u8],
        listed: &[ModelFileRef],
        cache: Option<&Cache>,
        use_cache: bool,
        started: Option<f64>,
    ) -> Result<ModelsSummary, ModelsFailure> {
        let mut files: BTreeMap<String, Vec<u8>> = BTreeMap::new();
        // Every missing file's request starts before any is awaited, so they download together.
        let mut downloads = Vec::new();
        for f in listed {
            let cached = match cache.filter(|_| use_cache) {
                Some(cache) => cached_bytes(cache, &self.cache_key(f)?).await,
                None => None,
            };
            match cached {
                Some(bytes) => {
                    files.insert(f.file.clone(), bytes);
                }
                None => {
                    let url = resolve_url(&f.file, &self.models_url)?;
                    let response = self.scope.fetch_with_str(&url);
                    downloads.push((f, url, response));
                }
            }
        }
        let cached_files = files.len();
        let mut fetched = Vec::new();
        for (f, url, response) in downloads {
            files.insert(f.file.clone(), response_bytes(response, &url).await?);
            fetched.push(f);
        }
        let read = self.clock_ms();
        let mut summary = self
            .worker
            .borrow_mut()
            .load_models(manifest, |file| {
                files
                    .get(file)
                    .cloned()
                    .ok_or_else(|| InferError::ReadModel { file: file.to_string(), message: "not fetched".into() })
            })
            .map_err(|e| (e.kind(), e.to_string()))?;
        let loaded = self.clock_ms();
        let ms = |from: Option<f64>, to: Option<f64>| Some((to? - from?).max(0.0).round() as u32);
        summary.read_ms = ms(started, read);
        summary.load_ms = ms(read, loaded);
        summary.cached_files = cached_files;
        if let Some(cache) = cache {
            // Cache only what checked out, and forget other versions.
            for f in fetched {
                let body = Uint8Array::from(files[&f.file].as_slice());
                if let Ok(response) = Response::new_with_opt_buffer_source(Some(&body)) {
                    let _ = JsFuture::from(cache.put_with_str(&self.cache_key(f)?, &response)).await;
                }
            }
            // The detector (fetched when a session first needs it) stays too.
            let detector = self.worker.borrow().detector_file();
            let wanted = listed
                .iter()
                .chain(detector.as_ref())
                .map(|f| self.cache_key(f))
                .collect::<Result<BTreeSet<_>, _>>()?;
            if let Ok(keys) = JsFuture::from(cache.keys()).await {
                for request in Array::from(&keys).iter() {
                    let Ok(request) = request.dyn_into::<web_sys::Request>() else { continue };
                    if !wanted.contains(&request.url()) {
                        let _ = JsFuture::from(cache.delete_with_request(&request)).await;
                    }
                }
            }
        }
        Ok(summary)
    }
}

/// `relative` resolved against `base`.
pub(super) fn resolve_url(relative: &str, base: &str) -> Result<String, ModelsFailure> {
    Url::new_with_base(relative, base)
        .map(|u| u.href())
        .map_err(|e| (ErrorKind::ModelsUnavailable, format!("cannot resolve {relative} against {base}: {e:?}")))
}

/// The last two segments of a URL's path (`models/manifest.json`), for messages.
fn short_path(url: &str) -> String {
    let path = Url::new(url).map(|u| u.pathname()).unwrap_or_else(|_| url.to_string());
    let parts: Vec<&str> = path.rsplit('/').take(2).collect();
    parts.into_iter().rev().collect::<Vec<_>>().join("/")
}

pub(super) async fn fetch_bytes(
    scope: &DedicatedWorkerGlobalScope,
    url: &str,
    no_cache: bool,
) -> Result<Vec<u8>, ModelsFailure> {
    let init = RequestInit::new();
    if no_cache {
        init.set_cache(RequestCache::NoCache);
    }
    response_bytes(scope.fetch_with_str_and_init(url, &init), url).await
}

/// The body of a fetch's response; an HTTP error status or a network failure names the file.
async fn response_bytes(response: Promise, url: &str) -> Result<Vec<u8>, ModelsFailure> {
    let what = short_path(url);
    let unavailable = |detail: String| (ErrorKind::ModelsUnavailable, format!("cannot fetch {what}: {detail}"));
    let response: Response = JsFuture::from(response).await.map_err(|e| unavailable(js_message(&e)))?.unchecked_into();
    if !response.ok() {
        let status = response.status();
        let kind = if status == 404 && what.ends_with("manifest.json") {
            ErrorKind::ModelsMissing
        } else {
            ErrorKind::ModelsUnavailable
        };
        return Err((kind, format!("cannot fetch {what}: HTTP {status} {}", response.status_text())));
    }
    let body = response.array_buffer().map_err(|e| unavailable(js_message(&e)))?;
    let buffer = JsFuture::from(body).await.map_err(|e| unavailable(js_message(&e)))?;
    Ok(Uint8Array::new(&buffer).to_vec())
}

/// The Cache API cache of the models, where the context allows one (not in an insecure
/// context, nor with storage disabled: then every load fetches).
pub(super) async fn open_cache(scope: &DedicatedWorkerGlobalScope) -> Option<Cache> {
    let caches = scope.caches().ok()?;
    JsFuture::from(caches.open(MODEL_CACHE)).await.ok()?.dyn_into().ok()
}

pub(super) async fn cached_bytes(cache: &Cache, key: &str) -> Option<Vec<u8>> {
    let hit = JsFuture::from(cache.match_with_str(key)).await.ok()?;
    let response: Response = hit.dyn_into().ok()?;
    let buffer = JsFuture::from(response.array_buffer().ok()?).await.ok()?;
    Some(Uint8Array::new(&buffer).to_vec())
}
