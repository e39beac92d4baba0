//! A pool of workers sharing one reconstruction: the plain-Rust half (the wasm message loop
//! only moves the messages; `docs/worker-protocol.md`, "The worker pool").
//!
//! The worker the page talks to (the *coordinator*) starts the job with chunks of
//! [`pool_chunk_windows`] windows and hands each *helper* (a nested worker running the same
//! module) the aligned session ([`encode_pool_session`]) and the job's settings; the helper
//! makes the same job ([`crate::SessionWorker::start_pool_helper`]) and computes whole chunks
//! on request ([`crate::SessionWorker::run_pool_chunk`]), while the coordinator computes chunks
//! itself window by window. [`ChunkSchedule`] decides who computes which chunk and hands the
//! finished ones back in chunk order, which is the order the job decodes them in
//! ([`egoexo_infer::ReconstructionJob::add_chunk`]) — so a pool of any size gives exactly the
//! result of one worker.

use std::collections::{BTreeMap, BTreeSet};

use egoexo_core::aligned::AlignedSession;
use egoexo_infer::ChunkOutputs;
use egoexo_infer::job::WINDOW_CHUNK;
use thiserror::Error;

/// Why the pool's messages could not be made or read.
#[derive(Debug, Error)]
pub enum PoolError {
    #[error("cannot encode the aligned session for the pool's helpers: {0}")]
    EncodeSession(String),
    #[error("{bytes} bytes from the pool's coordinator are not an aligned session: {message}")]
    DecodeSession { bytes: usize, message: String },
    #[error("no pool job {job} here (this helper holds {held})")]
    NoJob { job: u32, held: String },
}

/// The aligned session as bytes (MessagePack with field names: every float bit-exact, and
/// optional fields may be absent), for a helper to make the same job from.
pub fn encode_pool_session(aligned: &AlignedSession) -> Result<Vec<u8>, PoolError> {
    rmp_serde::to_vec_named(aligned).map_err(|e| PoolError::EncodeSession(e.to_string()))
}

/// An aligned session from [`encode_pool_session`]'s bytes.
pub fn decode_pool_session(bytes: &[u8]) -> Result<AlignedSession, PoolError> {
    rmp_serde::from_slice(bytes).map_err(|e| PoolError::DecodeSession { bytes: bytes.len(), message: e.to_string() })
}

/// Windows per chunk when `workers` workers share a job of `windows` windows: about four
/// chunks per worker, so that the last chunks finish close together, but at least 2 windows
/// (a chunk's round trip costs a message each way, well under a window's time) and at most
/// [`WINDOW_CHUNK`].
pub fn pool_chunk_windows(windows: usize, workers: usize) -> usize {
    (windows / (4 * workers.max(1))).clamp(MIN_POOL_CHUNK, WINDOW_CHUNK)
}

/// The fewest windows in a pooled chunk.
pub const MIN_POOL_CHUNK: usize = 2;

/// Who computes which chunk of a pooled job, and the finished chunks waiting for their turn
/// to be decoded. Helpers are numbered by the coordinator (`0..`); the coordinator itself
/// takes chunks with [`Self::take_own`].
#[derive(Debug)]
pub struct ChunkSchedule {
    chunks: usize,
    /// The first chunk never handed out.
    next_new: usize,
    /// Chunks handed back by failed helpers, to hand out again first.
    retry: BTreeSet<usize>,
    /// The chunk each busy helper is computing.
    assigned: BTreeMap<usize, usize>,
    /// Helpers that failed: never given a chunk again.
    failed: BTreeSet<usize>,
    /// Finished chunks not yet decoded.
    finished: BTreeMap<usize, ChunkOutputs>,
    /// The next chunk to decode.
    next_decode: usize,
}

impl ChunkSchedule {
    /// A schedule of `chunks` chunks, none handed out.
    pub fn new(chunks: usize) -> Self {
        ChunkSchedule {
            chunks,
            next_new: 0,
            retry: BTreeSet::new(),
            assigned: BTreeMap::new(),
            failed: BTreeSet::new(),
            finished: BTreeMap::new(),
            next_decode: 0,
        }
    }

    /// The next chunk to compute, if any is left: a failed helper's first, then the lowest
    /// never handed out (so that decoding can follow closely).
    fn take(&mut self) -> Option<usize> {
        if let Some(chunk) = self.retry.pop_first() {
            return Some(chunk);
        }
        (self.next_new < self.chunks).then(|| {
            self.next_new += 1;
            self.next_new - 1
        })
    }

    /// A chunk for idle helper `helper`, if one is left (none for a failed or busy helper).
    pub fn assign(&mut self, helper: usize) -> Option<usize> {
        if self.failed.contains(&helper) || self.assigned.contains_key(&helper) {
            return None;
        }
        let chunk = self.take()?;
        self.assigned.insert(helper, chunk);
        Some(chunk)
    }

    /// A chunk for the coordinator to compute itself, if one is left.
    pub fn take_own(&mut self) -> Option<usize> {
        self.take()
    }

    /// Helper `helper` failed (an error, a panic, a broken message): its chunk goes back to
    /// be computed by someone else, and it gets no more.
    pub fn helper_failed(&mut self, helper: usize) {
        self.failed.insert(helper);
        if let Some(chunk) = self.assigned.remove(&helper) {
            self.retry.insert(chunk);
        }
    }

    /// The helpers that have failed.
    pub fn failed_helpers(&self) -> usize {
        self.failed.len()
    }

    /// Chunk `outputs.chunk` is computed (by helper `from`, or by the coordinator when
    /// `None`). `false` when it was not expected from there (a stale or repeated answer,
    /// which is dropped).
    pub fn finished(&mut self, from: Option<usize>, outputs: ChunkOutputs) -> bool {
        let chunk = outputs.chunk;
        if let Some(helper) = from {
            if self.assigned.get(&helper) != Some(&chunk) {
                return false;
            }
            self.assigned.remove(&helper);
        }
        if chunk < self.next_decode || chunk >= self.chunks || self.finished.contains_key(&chunk) {
            return false;
        }
        self.finished.insert(chunk, outputs);
        true
    }

    /// The next chunk to decode, once it is computed.
    pub fn next_to_decode(&mut self) -> Option<ChunkOutputs> {
        let outputs = self.finished.remove(&self.next_decode)?;
        self.next_decode += 1;
        Some(outputs)
    }

    /// Whether every chunk has been handed back for decoding.
    pub fn is_done(&self) -> bool {
        self.next_decode == self.chunks
    }

    /// Whether helper `helper` is computing a chunk now.
    pub fn is_busy(&self, helper: usize) -> bool {
        self.assigned.contains_key(&helper)
    }

    /// Finished chunks waiting for an earlier one (what the pool holds beyond the job).
    pub fn waiting(&self) -> usize {
        self.finished.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outputs(chunk: usize) -> ChunkOutputs {
        ChunkOutputs::new(chunk, 0)
    }

    #[test]
    fn chunks_are_small_enough_to_share_and_large_enough_to_pay_for_a_message() {
        assert_eq!(pool_chunk_windows(24, 2), 3);
        assert_eq!(pool_chunk_windows(10, 4), MIN_POOL_CHUNK);
        assert_eq!(pool_chunk_windows(2_300, 2), WINDOW_CHUNK);
        assert_eq!(pool_chunk_windows(200, 2), 25);
        assert_eq!(pool_chunk_windows(0, 0), MIN_POOL_CHUNK);
    }

    #[test]
    fn chunks_come_back_in_order_whoever_finishes_first() {
        let mut s = ChunkSchedule::new(4);
        assert_eq!(s.assign(0), Some(0));
        assert_eq!(s.take_own(), Some(1));
        assert_eq!(s.assign(0), None, "a busy helper gets nothing more");
        assert!(s.finished(None, outputs(1)));
        assert!(s.next_to_decode().is_none(), "chunk 1 waits for chunk 0");
        assert_eq!(s.waiting(), 1);
        assert!(!s.finished(Some(1), outputs(0)), "helper 1 was not computing chunk 0");
        assert!(s.finished(Some(0), outputs(0)));
        assert_eq!(s.next_to_decode().map(|o| o.chunk), Some(0));
        assert_eq!(s.next_to_decode().map(|o| o.chunk), Some(1));
        assert_eq!(s.assign(0), Some(2));
        assert_eq!(s.take_own(), Some(3));
        assert!(s.finished(None, outputs(3)));
        assert!(s.finished(Some(0), outputs(2)));
        assert!(!s.finished(None, outputs(2)), "a repeated chunk is dropped");
        assert_eq!([s.next_to_decode(), s.next_to_decode()].map(|o| o.unwrap().chunk), [2, 3]);
        assert!(s.is_done());
        assert_eq!(s.take_own(), None);
    }

    #[test]
    fn a_failed_helpers_chunk_is_computed_again_and_it_gets_no_more() {
        let mut s = ChunkSchedule::new(3);
        assert_eq!(s.assign(0), Some(0));
        assert_eq!(s.assign(1), Some(1));
        s.helper_failed(0);
        assert_eq!(s.failed_helpers(), 1);
        assert_eq!(s.assign(0), None);
        assert_eq!(s.take_own(), Some(0), "the lost chunk first");
        assert!(!s.finished(Some(0), outputs(0)), "a late answer of the failed helper is dropped");
        assert!(s.finished(None, outputs(0)));
        assert!(s.is_busy(1));
        assert!(s.finished(Some(1), outputs(1)));
        assert_eq!(s.assign(1), Some(2));
        assert!(s.finished(Some(1), outputs(2)));
        while s.next_to_decode().is_some() {}
        assert!(s.is_done());
    }
}
