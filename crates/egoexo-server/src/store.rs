//! The share store: sealed shares (ciphertext only) in any `object_store` backend — a local
//! directory by default, an S3-compatible bucket for deployments.
//!
//! Layout, under the store's prefix:
//!
//! | object | content |
//! |---|---|
//! | `shares/<id>.data` | the sealed bytes, exactly as uploaded |
//! | `shares/<id>.json` | [`ShareRecord`]: expiry, the SHA-256 of the delete token, size |
//!
//! A share is written data first, record second; each `put` is atomic (a local store writes
//! a staging file and renames it, S3 makes an object visible whole), so a share exists
//! exactly when its record does, complete. Reads go record first. Deleting removes the
//! record first. The sweep deletes the data of expired shares but keeps their records for
//! [`EXPIRED_RECORD_GRACE_S`], so an expired link still answers 410 rather than 404; it also
//! removes data left without a record by a crash between the two writes.

use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use bytes::Bytes;
use egoexo_protocol::share::ShareId;
use futures::TryStreamExt;
use object_store::path::Path;
use object_store::{ObjectStore, ObjectStoreExt, PutPayload};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use thiserror::Error;

/// How long the record of an expired share is kept after the expiry (so its link answers
/// 410), seconds: 30 days.
pub const EXPIRED_RECORD_GRACE_S: u64 = 30 * 86_400;

/// How old data without a record must be before the sweep removes it (an upload still in
/// progress has its data written a moment before its record), seconds.
pub const ORPHAN_AGE_S: u64 = 3600;

/// What is stored beside a share's data.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShareRecord {
    /// Unix seconds.
    pub created_at: u64,
    /// Unix seconds.
    pub expires_at: u64,
    /// Lowercase hex SHA-256 of the delete token.
    pub delete_token_sha256: String,
    /// Size of the sealed share.
    pub bytes: u64,
    /// The sweep removed the data (the share expired).
    #[serde(default)]
    pub data_removed: bool,
}

/// What a store operation found.
#[derive(Debug, Error)]
pub enum StoreError {
    #[error("no share {0}")]
    NotFound(ShareId),
    #[error("share {0} has expired")]
    Expired(ShareId),
    #[error("the delete token does not match share {0}")]
    Forbidden(ShareId),
    #[error("the share store failed: {0}")]
    Storage(String),
}

impl From<object_store::Error> for StoreError {
    fn from(e: object_store::Error) -> Self {
        StoreError::Storage(e.to_string())
    }
}

/// Unix seconds now.
pub fn now_s() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs())
}

/// Lowercase hex SHA-256.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// Counts of one sweep.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SweepReport {
    /// Expired shares whose data was removed.
    pub expired: usize,
    /// Records of long-expired shares removed.
    pub records_removed: usize,
    /// Data without a record removed.
    pub orphans_removed: usize,
}

/// Shares in an object store.
#[derive(Clone, Debug)]
pub struct ShareStore {
    store: Arc<dyn ObjectStore>,
    prefix: Path,
}

impl ShareStore {
    /// Shares under `prefix` of `store`.
    pub fn new(store: Arc<dyn ObjectStore>, prefix: Path) -> Self {
        Self { store, prefix }
    }

    /// A human description of where shares go.
    pub fn describe(&self) -> String {
        format!("{} (prefix `{}`)", self.store, self.prefix)
    }

    fn data_path(&self, id: &ShareId) -> Path {
        self.prefix.clone().join("shares").join(format!("{id}.data"))
    }

    fn record_path(&self, id: &ShareId) -> Path {
        self.prefix.clone().join("shares").join(format!("{id}.json"))
    }

    /// Stores a share (data, then record).
    pub async fn put(&self, id: &ShareId, data: Bytes, record: &ShareRecord) -> Result<(), StoreError> {
        self.store.put(&self.data_path(id), PutPayload::from_bytes(data)).await?;
        let json = serde_json::to_vec(record).map_err(|e| StoreError::Storage(e.to_string()))?;
        self.store.put(&self.record_path(id), PutPayload::from(json)).await?;
        Ok(())
    }

    async fn record(&self, id: &ShareId) -> Result<ShareRecord, StoreError> {
        let got = match self.store.get(&self.record_path(id)).await {
            Ok(got) => got,
            Err(object_store::Error::NotFound { .. }) => return Err(StoreError::NotFound(id.clone())),
            Err(e) => return Err(e.into()),
        };
        let bytes = got.bytes().await?;
        serde_json::from_slice(&bytes).map_err(|e| StoreError::Storage(format!("record of {id}: {e}")))
    }

    /// The sealed bytes of a live share.
    pub async fn get(&self, id: &ShareId, now: u64) -> Result<Bytes, StoreError> {
        let (_, stream) = self.get_stream(id, now).await?;
        let chunks: Vec<Bytes> = stream.try_collect().await?;
        Ok(chunks.concat().into())
    }

    /// The size and a stream of the sealed bytes of a live share (the server answers with it,
    /// so a download holds no more than a chunk in memory).
    pub async fn get_stream(
        &self,
        id: &ShareId,
        now: u64,
    ) -> Result<(u64, futures::stream::BoxStream<'static, object_store::Result<Bytes>>), StoreError> {
        let record = self.record(id).await?;
        if record.data_removed || now >= record.expires_at {
            return Err(StoreError::Expired(id.clone()));
        }
        match self.store.get(&self.data_path(id)).await {
            Ok(got) => Ok((got.meta.size, got.into_stream())),
            // Deleted between the two reads.
            Err(object_store::Error::NotFound { .. }) => Err(StoreError::NotFound(id.clone())),
            Err(e) => Err(e.into()),
        }
    }

    /// Deletes a share if `token` is its delete token (record first, so it vanishes whole).
    pub async fn delete(&self, id: &ShareId, token: &str) -> Result<(), StoreError> {
        let record = self.record(id).await?;
        if !constant_time_eq(sha256_hex(token.as_bytes()).as_bytes(), record.delete_token_sha256.as_bytes()) {
            return Err(StoreError::Forbidden(id.clone()));
        }
        self.store.delete(&self.record_path(id)).await?;
        match self.store.delete(&self.data_path(id)).await {
            Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
            Err(e) => Err(e.into()),
        }
    }

    /// Removes the data of expired shares, old records and orphaned data (see the module
    /// docs).
    pub async fn sweep(&self, now: u64) -> Result<SweepReport, StoreError> {
        let mut report = SweepReport::default();
        let listed: Vec<_> = self.store.list(Some(&self.prefix.clone().join("shares"))).try_collect().await?;
        let name = |p: &Path| p.filename().map(str::to_owned).unwrap_or_default();
        let records: std::collections::BTreeSet<String> =
            listed.iter().filter_map(|m| name(&m.location).strip_suffix(".json").map(str::to_owned)).collect();
        for meta in &listed {
            let file = name(&meta.location);
            if let Some(id) = file.strip_suffix(".json").and_then(|s| ShareId::parse(s).ok()) {
                let Ok(mut record) = self.record(&id).await else { continue };
                if now >= record.expires_at.saturating_add(EXPIRED_RECORD_GRACE_S) {
                    self.store.delete(&meta.location).await?;
                    let _ = self.store.delete(&self.data_path(&id)).await;
                    report.records_removed += 1;
                } else if now >= record.expires_at && !record.data_removed {
                    match self.store.delete(&self.data_path(&id)).await {
                        Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                        Err(e) => return Err(e.into()),
                    }
                    record.data_removed = true;
                    let json = serde_json::to_vec(&record).map_err(|e| StoreError::Storage(e.to_string()))?;
                    self.store.put(&meta.location, PutPayload::from(json)).await?;
                    report.expired += 1;
                }
            } else if let Some(stem) = file.strip_suffix(".data") {
                let age = now.saturating_sub(meta.last_modified.timestamp().max(0) as u64);
                if !records.contains(stem) && age >= ORPHAN_AGE_S {
                    self.store.delete(&meta.location).await?;
                    report.orphans_removed += 1;
                }
            }
        }
        Ok(report)
    }

    /// Runs [`ShareStore::sweep`] every `interval` (the first one interval after the start),
    /// forever, logging failures.
    pub async fn sweep_every(self, interval: Duration) {
        let mut ticks = tokio::time::interval_at(tokio::time::Instant::now() + interval, interval);
        loop {
            ticks.tick().await;
            match self.sweep(now_s()).await {
                Ok(r) if r != SweepReport::default() => eprintln!(
                    "egoexo serve: sweep removed {} expired shares, {} old records, {} orphaned uploads",
                    r.expired, r.records_removed, r.orphans_removed
                ),
                Ok(_) => {}
                Err(e) => eprintln!("egoexo serve: sweep failed: {e}"),
            }
        }
    }
}

/// Compares two byte strings in time independent of where they differ.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}
