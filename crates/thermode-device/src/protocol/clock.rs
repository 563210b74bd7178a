//! The time base of both ends of the device protocol: the host's link timeout and drive-frame pacing, the
//! device's watchdog and report schedule. Injected, so the runtime can hand the serial device the clock its control
//! loop runs on (then a reading's `time_s` and the loop's `now_s` are on one time axis), and tests can use a manual
//! clock.

use std::fmt::Debug;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// A monotonic clock in seconds.
pub trait Clock: Send + Sync + Debug {
    /// Seconds since the clock's origin; never decreases.
    fn now_s(&self) -> f64;
}

/// The machine's monotonic clock ([`Instant`]), in seconds since the clock was made.
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    origin: Instant,
}

impl MonotonicClock {
    /// A clock whose origin is now.
    pub fn new() -> Self {
        MonotonicClock { origin: Instant::now() }
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        MonotonicClock::new()
    }
}

impl Clock for MonotonicClock {
    fn now_s(&self) -> f64 {
        self.origin.elapsed().as_secs_f64()
    }
}

/// A clock that moves only when told to (tests); clones share one time. Resolution 1 ns.
#[derive(Debug, Clone, Default)]
pub struct ManualClock {
    nanos: Arc<AtomicU64>,
}

impl ManualClock {
    /// A clock at 0 s.
    pub fn new() -> Self {
        ManualClock::default()
    }

    /// Moves the clock forward by `dt_s` \[s\]; a step that is not finite and positive does nothing.
    pub fn advance_s(&self, dt_s: f64) {
        if dt_s.is_finite() && dt_s > 0.0 {
            self.nanos.fetch_add((dt_s * 1e9).round() as u64, Ordering::SeqCst);
        }
    }
}

impl Clock for ManualClock {
    fn now_s(&self) -> f64 {
        self.nanos.load(Ordering::SeqCst) as f64 * 1e-9
    }
}
