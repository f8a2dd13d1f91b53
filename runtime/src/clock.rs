//! The clock every deadline, staleness and schedule decision of the runtime reads.
//!
//! The exchange and the agent loop never call `Instant::now()` themselves: they ask a [`Clock`].
//! The processes use [`SystemClock`]; unit tests use [`FakeClock`], whose time moves only when a
//! test (or a simulated wait) advances it, so timeouts, the realtime schedule and the watchdog
//! can be tested without real time passing.

use std::sync::Mutex;
use std::time::{Duration, Instant};

/// A source of monotonic time, and a way to let time pass.
pub trait Clock: Send + Sync {
    /// The current instant.
    fn now(&self) -> Instant;
    /// Lets `duration` pass (a real sleep on the system clock).
    fn sleep(&self, duration: Duration);
}

/// The operating system's monotonic clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct SystemClock;

impl Clock for SystemClock {
    fn now(&self) -> Instant {
        Instant::now()
    }

    fn sleep(&self, duration: Duration) {
        std::thread::sleep(duration);
    }
}

/// A clock for tests: it starts at the instant it was made and moves only when advanced
/// ([`FakeClock::advance`], or [`Clock::sleep`], which advances it at once).
#[derive(Debug)]
pub struct FakeClock {
    origin: Instant,
    elapsed: Mutex<Duration>,
}

impl FakeClock {
    /// A clock standing at the current instant.
    pub fn new() -> FakeClock {
        FakeClock {
            origin: Instant::now(),
            elapsed: Mutex::new(Duration::ZERO),
        }
    }

    /// Moves the clock on by `duration`.
    pub fn advance(&self, duration: Duration) {
        let mut elapsed = self.elapsed.lock().unwrap_or_else(|e| e.into_inner());
        *elapsed += duration;
    }

    /// How far the clock has moved since it was made.
    pub fn elapsed(&self) -> Duration {
        *self.elapsed.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Default for FakeClock {
    fn default() -> FakeClock {
        FakeClock::new()
    }
}

impl Clock for FakeClock {
    fn now(&self) -> Instant {
        self.origin + self.elapsed()
    }

    fn sleep(&self, duration: Duration) {
        self.advance(duration);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fake_clock_moves_only_when_advanced() {
        let clock = FakeClock::new();
        let start = clock.now();
        assert_eq!(clock.now(), start);
        clock.advance(Duration::from_millis(30));
        clock.sleep(Duration::from_millis(20));
        assert_eq!(clock.now() - start, Duration::from_millis(50));
    }
}
