//! When the world published each robot's recent scans, so that a command is timed from the scan
//! it answered (its `tick`), not from the tick during which it arrived.
//!
//! In realtime a command may answer a scan up to the stale window old (`lag_ticks` > 0); timing it
//! from the current tick's scan would hide the lag and, under a slow link, report a round trip
//! shorter than either one-way delay. [`ScanStamps`] keeps the stamps of the last few ticks in a
//! ring sized to cover the stale window plus a margin ([`ScanStamps::for_window`]), so its memory
//! is bounded whatever the run's length.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// When one scan was handed over to its robot's link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScanStamp {
    /// On the world's clock, just before the hand-over.
    pub at: Instant,
    /// On the system clock ([`formation_proto::wire::wall_clock_ns`]), as the scan message carries
    /// it, for the uplink latency the agent's own stamp is compared with.
    pub wall_ns: u64,
}

/// The stamps of one robot's most recent scans, by tick.
#[derive(Debug, Clone)]
pub struct ScanStamps {
    /// The most ticks remembered.
    capacity: usize,
    /// (tick, stamp), oldest first, ticks increasing.
    recent: VecDeque<(u64, ScanStamp)>,
}

/// Ticks remembered beyond the stale window: a command answering a scan that old is already
/// braked as stale, so its stamp only serves a command that arrived just at the edge.
const MARGIN_TICKS: usize = 2;

/// The most ticks a ring remembers, whatever the stale window: 51 s at 20 Hz.
const MAX_TICKS: usize = 1024;

impl ScanStamps {
    /// A ring that remembers `capacity` ticks (at least one).
    pub fn new(capacity: usize) -> ScanStamps {
        let capacity = capacity.max(1);
        ScanStamps {
            capacity,
            recent: VecDeque::with_capacity(capacity.min(64)),
        }
    }

    /// A ring that covers `stale_after` at one tick per `dt`, plus a margin, and at most
    /// 1024 ticks (51 s at 20 Hz).
    pub fn for_window(stale_after: Duration, dt: Duration) -> ScanStamps {
        let ticks = if dt.is_zero() {
            MAX_TICKS
        } else {
            let ticks = stale_after.as_nanos().div_ceil(dt.as_nanos());
            usize::try_from(ticks).unwrap_or(MAX_TICKS)
        };
        ScanStamps::new(ticks.saturating_add(MARGIN_TICKS).min(MAX_TICKS))
    }

    /// How many ticks the ring remembers.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Remembers that tick `tick`'s scan was published at `stamp`, forgetting the oldest tick
    /// when the ring is full. A tick not after the newest one (a new episode that was not
    /// [`cleared`](ScanStamps::clear)) starts the ring afresh.
    pub fn record(&mut self, tick: u64, stamp: ScanStamp) {
        if self
            .recent
            .back()
            .is_some_and(|&(newest, _)| tick <= newest)
        {
            self.recent.clear();
        }
        if self.recent.len() == self.capacity {
            self.recent.pop_front();
        }
        self.recent.push_back((tick, stamp));
    }

    /// When tick `tick`'s scan was published, if the ring still remembers it.
    pub fn of(&self, tick: u64) -> Option<ScanStamp> {
        let &(oldest, _) = self.recent.front()?;
        // Ticks are recorded one after another, so a tick's place is its distance from the
        // oldest; a gap (a tick never published) falls back to a search.
        let index = usize::try_from(tick.checked_sub(oldest)?).ok()?;
        match self.recent.get(index) {
            Some(&(found, stamp)) if found == tick => Some(stamp),
            _ => self
                .recent
                .iter()
                .find(|&&(found, _)| found == tick)
                .map(|&(_, stamp)| stamp),
        }
    }

    /// Forgets every tick (a new episode begins).
    pub fn clear(&mut self) {
        self.recent.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stamp(base: Instant, ms: u64) -> ScanStamp {
        ScanStamp {
            at: base + Duration::from_millis(ms),
            wall_ns: ms * 1_000_000,
        }
    }

    #[test]
    fn a_ring_remembers_the_stale_window_and_a_margin_and_no_more() {
        let base = Instant::now();
        let mut ring =
            ScanStamps::for_window(Duration::from_millis(150), Duration::from_millis(50));
        assert_eq!(ring.capacity(), 3 + MARGIN_TICKS);
        for tick in 0..100 {
            ring.record(tick, stamp(base, tick * 50));
        }
        assert_eq!(ring.of(99), Some(stamp(base, 99 * 50)));
        assert_eq!(ring.of(95), Some(stamp(base, 95 * 50)), "the oldest kept");
        assert_eq!(ring.of(94), None, "forgotten");
        assert_eq!(ring.of(100), None, "not published yet");
        assert_eq!(ring.recent.len(), ring.capacity(), "bounded");
    }

    #[test]
    fn a_new_episode_or_a_gap_is_handled_and_absurd_windows_are_bounded() {
        let base = Instant::now();
        let mut ring = ScanStamps::new(4);
        ring.record(7, stamp(base, 0));
        ring.record(9, stamp(base, 100));
        assert_eq!(ring.of(9), Some(stamp(base, 100)), "found across a gap");
        assert_eq!(ring.of(8), None);
        ring.record(0, stamp(base, 500));
        assert_eq!(ring.of(7), None, "an older tick starts afresh");
        assert_eq!(ring.of(0), Some(stamp(base, 500)));
        ring.clear();
        assert_eq!(ring.of(0), None);
        let huge = ScanStamps::for_window(Duration::from_secs(3600), Duration::from_millis(50));
        assert_eq!(huge.capacity(), MAX_TICKS);
        let zero_dt = ScanStamps::for_window(Duration::from_millis(150), Duration::ZERO);
        assert_eq!(zero_dt.capacity(), MAX_TICKS);
        assert_eq!(ScanStamps::new(0).capacity(), 1);
    }
}
