//! The injected clock of the control loop: [`MonotonicClock`] (real time, `std::time::Instant`) for the daemon and
//! [`ManualClock`] (time moves only when a test says so) for deterministic tests.
//!
//! Times are seconds since the clock was made. The loop asks the clock for the time and sleeps on it; it never
//! reads the wall clock itself.

use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// Longest a [`ManualClock`] sleeper waits in real time before it returns to let the loop look at its stop flag \[s\].
const MANUAL_POLL_S: f64 = 0.02;

/// A monotonic clock the control loop reads and sleeps on.
pub trait Clock: Send + Sync {
    /// Seconds since the clock's origin; never decreases.
    fn now_s(&self) -> f64;

    /// Sleeps until `now_s() >= deadline_s`, or returns earlier (spuriously, or so the caller can check for a stop);
    /// the caller re-checks the time.
    fn sleep_until(&self, deadline_s: f64);
}

/// Real monotonic time from `std::time::Instant`: the device layer's clock, so the loop and a serial device share one
/// implementation.
pub use thermode_device::protocol::MonotonicClock;

impl Clock for MonotonicClock {
    fn now_s(&self) -> f64 {
        thermode_device::protocol::Clock::now_s(self)
    }

    fn sleep_until(&self, deadline_s: f64) {
        let remaining_s = deadline_s - Clock::now_s(self);
        if remaining_s > 0.0 && remaining_s.is_finite() {
            std::thread::sleep(Duration::try_from_secs_f64(remaining_s).unwrap_or(Duration::MAX));
        }
    }
}

/// A clock that stands still until [`ManualClock::advance`] or [`ManualClock::set`] moves it. A sleeper wakes as
/// soon as the time reaches its deadline (and at least every 20 ms of real time, so a stopping loop is not stuck).
#[derive(Debug, Default)]
pub struct ManualClock {
    now_s: Mutex<f64>,
    moved: Condvar,
}

impl ManualClock {
    /// A manual clock at time 0.
    pub fn new() -> Self {
        ManualClock::default()
    }

    /// Moves the time forward by `dt_s` \[s\]; a step that is not finite and positive changes nothing.
    pub fn advance(&self, dt_s: f64) {
        if dt_s.is_finite() && dt_s > 0.0 {
            let mut now = self.lock();
            *now += dt_s;
            self.moved.notify_all();
        }
    }

    /// Sets the time to `time_s` \[s\] if that is later than now (the clock never goes back).
    pub fn set(&self, time_s: f64) {
        let mut now = self.lock();
        if time_s.is_finite() && time_s > *now {
            *now = time_s;
            self.moved.notify_all();
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, f64> {
        // A poisoned lock only means a panicking test thread held it; the number inside is still valid.
        self.now_s.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl Clock for ManualClock {
    fn now_s(&self) -> f64 {
        *self.lock()
    }

    fn sleep_until(&self, deadline_s: f64) {
        let now = self.lock();
        if *now >= deadline_s {
            return;
        }
        let _unused = self
            .moved
            .wait_timeout(now, Duration::from_secs_f64(MANUAL_POLL_S))
            .unwrap_or_else(|poisoned| poisoned.into_inner());
    }
}

/// The loop's clock as the device layer's clock (`thermode_device::protocol::Clock`), so a serial device stamps its
/// readings on the loop's time base.
#[derive(Clone)]
pub struct DeviceClock(pub Arc<dyn Clock>);

impl std::fmt::Debug for DeviceClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("DeviceClock")
    }
}

impl thermode_device::protocol::Clock for DeviceClock {
    fn now_s(&self) -> f64 {
        self.0.now_s()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_clock_moves_only_forward() {
        let clock = ManualClock::new();
        assert_eq!(clock.now_s(), 0.0);
        clock.advance(0.5);
        clock.advance(f64::NAN);
        clock.advance(-1.0);
        assert_eq!(clock.now_s(), 0.5);
        clock.set(0.25);
        assert_eq!(clock.now_s(), 0.5, "set must not move the clock back");
        clock.set(2.0);
        assert_eq!(clock.now_s(), 2.0);
    }

    #[test]
    fn manual_sleeper_wakes_when_time_reaches_deadline() {
        let clock = std::sync::Arc::new(ManualClock::new());
        let sleeper = {
            let clock = clock.clone();
            std::thread::spawn(move || {
                let mut wakes = 0;
                while clock.now_s() < 1.0 && wakes < 10_000 {
                    clock.sleep_until(1.0);
                    wakes += 1;
                }
                clock.now_s()
            })
        };
        clock.advance(1.0);
        let woke_at = sleeper.join().unwrap_or(f64::NAN);
        assert_eq!(woke_at, 1.0);
    }

    #[test]
    fn monotonic_clock_does_not_go_back() {
        let clock = MonotonicClock::new();
        let a = clock.now_s();
        clock.sleep_until(a + 0.001);
        let b = clock.now_s();
        assert!(b >= a + 0.001, "slept from {a} to {b}, wanted at least 1 ms");
    }
}
