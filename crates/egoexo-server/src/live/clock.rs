//! Clocks: the relay's own clock, and each client's offset to it measured NTP-style from
//! ping/pong exchanges.

use std::collections::VecDeque;
use std::time::{Instant, SystemTime, UNIX_EPOCH};

/// The relay's clock: nanoseconds since the Unix epoch, advanced by a monotonic clock from
/// one reading of the wall clock at start (so it never steps back).
#[derive(Clone, Copy, Debug)]
pub struct RelayClock {
    origin: Instant,
    origin_unix_ns: i64,
}

impl RelayClock {
    pub fn new() -> Self {
        let unix = SystemTime::now().duration_since(UNIX_EPOCH).unwrap_or_default();
        Self { origin: Instant::now(), origin_unix_ns: i64::try_from(unix.as_nanos()).unwrap_or(0) }
    }

    /// Now, nanoseconds since the Unix epoch.
    pub fn now_ns(&self) -> i64 {
        let elapsed = i64::try_from(self.origin.elapsed().as_nanos()).unwrap_or(i64::MAX / 2);
        self.origin_unix_ns.saturating_add(elapsed)
    }
}

impl Default for RelayClock {
    fn default() -> Self {
        Self::new()
    }
}

/// One ping/pong exchange, on the relay clock.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClockSample {
    /// Relay clock minus client clock, nanoseconds.
    pub offset_ns: i64,
    /// Ping sent → pong received, nanoseconds.
    pub round_trip_ns: i64,
}

/// Longest round trip a sample may have and still count, nanoseconds (10 s).
pub const MAX_ROUND_TRIP_NS: i64 = 10_000_000_000;

impl ClockSample {
    /// The sample from a ping sent at `sent_ns` (relay clock) that the client answered with
    /// its own clock reading `client_ns`, the pong arriving at `received_ns`: the client read
    /// its clock, assumed halfway through the round trip, so
    /// `offset = sent + round_trip / 2 − client`. `None` for an impossible or too slow
    /// exchange.
    pub fn from_exchange(sent_ns: i64, client_ns: i64, received_ns: i64) -> Option<ClockSample> {
        let round_trip_ns = received_ns.checked_sub(sent_ns)?;
        if !(0..=MAX_ROUND_TRIP_NS).contains(&round_trip_ns) {
            return None;
        }
        let offset_ns = sent_ns.checked_add(round_trip_ns / 2)?.checked_sub(client_ns)?;
        Some(ClockSample { offset_ns, round_trip_ns })
    }
}

/// A client's clock offset: the recent sample with the shortest round trip (its offset is
/// the least disturbed by queueing), and jumps detected when a new sample disagrees with it
/// by more than both samples' uncertainties allow.
#[derive(Clone, Debug, Default)]
pub struct ClockEstimator {
    samples: VecDeque<ClockSample>,
    jumps: u32,
}

/// Samples kept (one a second: the last 16 s).
pub const CLOCK_WINDOW: usize = 16;
/// Disagreement beyond the uncertainties that counts as a jump, nanoseconds (20 ms).
pub const JUMP_MARGIN_NS: i64 = 20_000_000;

impl ClockEstimator {
    /// Adds a sample; returns whether the client's clock jumped (the older samples are then
    /// forgotten).
    pub fn add(&mut self, sample: ClockSample) -> bool {
        let mut jumped = false;
        if let Some(best) = self.best() {
            let tolerance = best.round_trip_ns / 2 + sample.round_trip_ns / 2 + JUMP_MARGIN_NS;
            if (sample.offset_ns - best.offset_ns).abs() > tolerance {
                self.samples.clear();
                self.jumps += 1;
                jumped = true;
            }
        }
        self.samples.push_back(sample);
        if self.samples.len() > CLOCK_WINDOW {
            self.samples.pop_front();
        }
        jumped
    }

    /// The sample the offset comes from.
    pub fn best(&self) -> Option<ClockSample> {
        self.samples.iter().copied().min_by_key(|s| s.round_trip_ns)
    }

    /// Relay clock minus client clock, nanoseconds.
    pub fn offset_ns(&self) -> Option<i64> {
        self.best().map(|s| s.offset_ns)
    }

    /// Half the best round trip: how far the true offset may be from [`Self::offset_ns`].
    pub fn uncertainty_ns(&self) -> Option<i64> {
        self.best().map(|s| s.round_trip_ns / 2)
    }

    /// Jumps seen so far.
    pub fn jumps(&self) -> u32 {
        self.jumps
    }

    /// A client timestamp on the relay clock.
    pub fn to_relay(&self, client_ns: i64) -> Option<i64> {
        self.offset_ns().map(|o| client_ns.saturating_add(o))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    #[test]
    fn the_offset_comes_from_the_shortest_round_trip() {
        // The client's clock is 5 s behind the relay's; the pong's way back is sometimes slow.
        let mut clock = ClockEstimator::default();
        let truth = 5_000 * MS;
        for (i, (out, back)) in [(2, 30), (3, 3), (2, 9)].into_iter().enumerate() {
            let sent = 1_000 * MS * i as i64;
            let client = sent + out * MS - truth;
            let sample = ClockSample::from_exchange(sent, client, sent + (out + back) * MS).unwrap();
            assert!(!clock.add(sample));
        }
        assert_eq!(clock.offset_ns(), Some(truth));
        assert_eq!(clock.uncertainty_ns(), Some(3 * MS));
        assert_eq!(clock.to_relay(-truth), Some(0));
    }

    #[test]
    fn a_jump_resets_the_estimate() {
        let mut clock = ClockEstimator::default();
        let sample =
            |offset_ms: i64, rtt_ms: i64| ClockSample { offset_ns: offset_ms * MS, round_trip_ns: rtt_ms * MS };
        assert!(!clock.add(sample(100, 4)));
        // Within the uncertainties and the margin: the same clock.
        assert!(!clock.add(sample(120, 6)));
        assert_eq!(clock.offset_ns(), Some(100 * MS));
        // Two seconds off: the device's clock was set.
        assert!(clock.add(sample(2_100, 8)));
        assert_eq!((clock.offset_ns(), clock.jumps()), (Some(2_100 * MS), 1));
    }

    #[test]
    fn impossible_exchanges_are_refused() {
        assert_eq!(ClockSample::from_exchange(10, 0, 5), None);
        assert_eq!(ClockSample::from_exchange(0, 0, MAX_ROUND_TRIP_NS + 1), None);
        assert_eq!(ClockSample::from_exchange(i64::MIN + 1, i64::MAX, i64::MIN + 2), None);
    }
}
