//! What the relay has yet to send one client, bounded: the back-pressure policy.
//!
//! Data frames queue per channel. A frame that has waited past its deadline is dropped as
//! soon as a newer frame of its channel is queued (a viewer that falls behind sees the newest
//! poses, never a backlog of stale ones), and a channel never holds more than its capacity.
//! Drops are counted and reported to the viewer. Control messages are coalesced: the latest
//! channel list, the latest status and the latest calibration per device; pings and the
//! welcome queue in a short list. So a client that stops reading costs the relay at most
//! `channels × capacity` frames, whatever it does.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Mutex;

use bytes::Bytes;
use egoexo_protocol::live::Close;
use tokio::sync::Notify;

/// One thing to send.
#[derive(Clone, Debug, PartialEq)]
pub enum Outgoing {
    Text(String),
    Binary(Bytes),
    Close(Close),
}

/// Most queued one-off messages (welcome, pings); older pings give way.
const MAX_MESSAGES: usize = 32;

#[derive(Debug)]
struct QueuedFrame {
    seq: u64,
    /// Relay clock, nanoseconds: past it, the frame is stale once a newer one waits.
    deadline_ns: i64,
    bytes: Bytes,
}

#[derive(Debug, Default)]
struct OutboxInner {
    messages: VecDeque<String>,
    channels: Option<String>,
    calibrations: BTreeMap<String, String>,
    status: Option<String>,
    frames: BTreeMap<u16, VecDeque<QueuedFrame>>,
    next_seq: u64,
    queued_frames: usize,
    dropped: u64,
    close: Option<Close>,
    closed: bool,
}

impl OutboxInner {
    fn has_control(&self) -> bool {
        !self.messages.is_empty() || self.channels.is_some() || !self.calibrations.is_empty() || self.status.is_some()
    }

    /// Drops, in one channel, frames past their deadline that a newer frame follows.
    fn drop_stale(&mut self, channel: u16, now_ns: i64) {
        let Some(queue) = self.frames.get_mut(&channel) else { return };
        while queue.len() > 1 && queue.front().is_some_and(|f| f.deadline_ns < now_ns) {
            queue.pop_front();
            self.queued_frames -= 1;
            self.dropped += 1;
        }
    }
}

/// A client's outgoing queue (shared by the room, which fills it, and the connection's
/// writer, which empties it).
#[derive(Debug)]
pub struct Outbox {
    inner: Mutex<OutboxInner>,
    notify: Notify,
    per_channel: usize,
}

impl Outbox {
    /// An outbox keeping at most `per_channel` frames of each channel.
    pub fn new(per_channel: usize) -> Self {
        Self { inner: Mutex::new(OutboxInner::default()), notify: Notify::new(), per_channel: per_channel.max(1) }
    }

    fn with<R>(&self, f: impl FnOnce(&mut OutboxInner) -> R) -> R {
        let mut inner = self.inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        f(&mut inner)
    }

    /// Queues a data frame of `channel` that is stale after `deadline_ns` (relay clock).
    pub fn push_frame(&self, channel: u16, bytes: Bytes, deadline_ns: i64, now_ns: i64) {
        let per_channel = self.per_channel;
        let queued = self.with(|inner| {
            if inner.closed {
                return false;
            }
            let seq = inner.next_seq;
            inner.next_seq += 1;
            let queue = inner.frames.entry(channel).or_default();
            queue.push_back(QueuedFrame { seq, deadline_ns, bytes });
            let mut dropped = 0;
            while queue.len() > per_channel {
                queue.pop_front();
                dropped += 1;
            }
            inner.queued_frames += 1 - dropped;
            inner.dropped += dropped as u64;
            inner.drop_stale(channel, now_ns);
            true
        });
        if queued {
            self.notify.notify_one();
        }
    }

    /// Queues a one-off text message (the oldest gives way past [`MAX_MESSAGES`]).
    pub fn push_message(&self, text: String) {
        self.with(|inner| {
            if inner.messages.len() >= MAX_MESSAGES {
                inner.messages.pop_front();
            }
            inner.messages.push_back(text);
        });
        self.notify.notify_one();
    }

    /// Replaces the queued channel list.
    pub fn set_channels(&self, text: String) {
        self.with(|inner| inner.channels = Some(text));
        self.notify.notify_one();
    }

    /// Replaces the queued calibration of `device`.
    pub fn set_calibration(&self, device: &str, text: String) {
        self.with(|inner| inner.calibrations.insert(device.to_string(), text));
        self.notify.notify_one();
    }

    /// Replaces the queued status.
    pub fn set_status(&self, text: String) {
        self.with(|inner| inner.status = Some(text));
        self.notify.notify_one();
    }

    /// Closes the client: the close goes out next, and nothing after it.
    pub fn close(&self, close: Close) {
        self.with(|inner| {
            if !inner.closed {
                inner.close = Some(close);
                inner.closed = true;
            }
        });
        self.notify.notify_one();
    }

    /// Whether [`Self::close`] was called.
    pub fn is_closed(&self) -> bool {
        self.with(|inner| inner.closed)
    }

    /// Frames dropped so far because the client read too slowly.
    pub fn dropped(&self) -> u64 {
        self.with(|inner| inner.dropped)
    }

    /// Frames waiting.
    pub fn queued_frames(&self) -> usize {
        self.with(|inner| inner.queued_frames)
    }

    /// Takes up to `max` things to send, control before data, data in the order it was
    /// queued; an empty batch means nothing is waiting.
    pub fn take(&self, max: usize, now_ns: i64) -> Vec<Outgoing> {
        self.with(|inner| {
            let mut out = Vec::new();
            if let Some(close) = inner.close.take() {
                out.push(Outgoing::Close(close));
                return out;
            }
            if inner.closed {
                return out;
            }
            out.extend(inner.messages.drain(..).map(Outgoing::Text));
            out.extend(inner.channels.take().map(Outgoing::Text));
            out.extend(std::mem::take(&mut inner.calibrations).into_values().map(Outgoing::Text));
            out.extend(inner.status.take().map(Outgoing::Text));
            let channels: Vec<u16> = inner.frames.keys().copied().collect();
            for channel in channels {
                inner.drop_stale(channel, now_ns);
            }
            while out.len() < max {
                // The channel whose oldest frame was queued first.
                let Some((&channel, _)) =
                    inner.frames.iter().filter_map(|(c, q)| Some((c, q.front()?.seq))).min_by_key(|(_, seq)| *seq)
                else {
                    break;
                };
                let Some(frame) = inner.frames.get_mut(&channel).and_then(VecDeque::pop_front) else { break };
                inner.queued_frames -= 1;
                out.push(Outgoing::Binary(frame.bytes));
            }
            inner.frames.retain(|_, q| !q.is_empty());
            out
        })
    }

    /// Waits until something may be waiting (a wake-up is never lost: one queued while
    /// nobody waits is kept for the next call).
    pub async fn wait(&self) {
        self.notify.notified().await;
    }

    /// Whether anything is waiting.
    pub fn has_pending(&self) -> bool {
        self.with(|inner| inner.close.is_some() || (!inner.closed && (inner.has_control() || inner.queued_frames > 0)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use egoexo_protocol::live::CloseKind;

    fn frame(n: u8) -> Bytes {
        Bytes::from(vec![n])
    }

    #[test]
    fn control_goes_first_and_data_keeps_its_order() {
        let outbox = Outbox::new(8);
        outbox.push_frame(1, frame(1), 100, 0);
        outbox.push_frame(0, frame(2), 100, 0);
        outbox.set_status("s1".into());
        outbox.set_status("s2".into());
        outbox.set_channels("c".into());
        outbox.push_message("ping".into());
        let batch = outbox.take(10, 0);
        assert_eq!(
            batch,
            vec![
                Outgoing::Text("ping".into()),
                Outgoing::Text("c".into()),
                Outgoing::Text("s2".into()),
                Outgoing::Binary(frame(1)),
                Outgoing::Binary(frame(2)),
            ]
        );
        assert!(!outbox.has_pending());
    }

    #[test]
    fn a_slow_reader_gets_the_newest_frames_and_a_drop_count() {
        let outbox = Outbox::new(4);
        // Ten frames nobody reads: only the newest four stay.
        for n in 0..10 {
            outbox.push_frame(3, frame(n), 1_000, 0);
        }
        assert_eq!((outbox.queued_frames(), outbox.dropped()), (4, 6));
        // Past their deadline, frames give way to a newer one; the newest always stays.
        outbox.push_frame(3, frame(10), 3_000, 2_000);
        assert_eq!(outbox.take(10, 2_000), vec![Outgoing::Binary(frame(10))]);
        assert_eq!(outbox.dropped(), 10);
        outbox.push_frame(3, frame(11), 3_000, 2_000);
        assert_eq!(outbox.take(10, 9_000), vec![Outgoing::Binary(frame(11))]);
    }

    #[test]
    fn a_close_ends_the_queue() {
        let outbox = Outbox::new(4);
        outbox.push_frame(0, frame(0), 10, 0);
        outbox.close(Close::new(CloseKind::Replaced, "again"));
        outbox.close(Close::new(CloseKind::GoingAway, "ignored"));
        outbox.push_frame(0, frame(1), 10, 0);
        assert_eq!(outbox.take(10, 0), vec![Outgoing::Close(Close::new(CloseKind::Replaced, "again"))]);
        assert!(outbox.take(10, 0).is_empty() && outbox.is_closed());
    }
}
