//! The fixed-rate ticker of the control loop: deadlines on the grid `start + k·period` (computed by
//! multiplication, so they never drift), a sleep on the injected [`Clock`] until each one, and an honest count of
//! the deadlines the loop missed.
//!
//! A *missed deadline* is a deadline that got no tick of its own: when the loop wakes so late that one or more later
//! deadlines have passed too, it runs one tick for the newest passed deadline and counts the ones in between as
//! missed. A tick that starts late but before the next deadline is not missed; its lateness shows in the period
//! statistics ([`crate::stats`]).

use std::sync::atomic::{AtomicBool, Ordering};

use crate::clock::Clock;
use crate::error::RuntimeError;

/// One tick handed out by [`Ticker::wait`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Index of the deadline this tick serves (`scheduled_s = start_s + index · period_s`).
    pub index: u64,
    /// The deadline \[s, clock time\]: the loop's time for this tick.
    pub scheduled_s: f64,
    /// Time since the previous tick's deadline \[s\] (one period unless deadlines were missed; one period for the
    /// first tick).
    pub dt_s: f64,
    /// When the loop actually woke \[s, clock time\] (at or after `scheduled_s`).
    pub woke_s: f64,
    /// Deadlines skipped just before this one (0 when on time).
    pub missed: u64,
}

/// Hands out ticks at a fixed rate on a [`Clock`].
#[derive(Debug, Clone)]
pub struct Ticker {
    period_s: f64,
    start_s: f64,
    next_index: u64,
    last_scheduled_s: Option<f64>,
    missed_total: u64,
}

impl Ticker {
    /// A ticker whose first deadline is `start_s` \[s\] and which then ticks every `period_s` \[s\] (finite, > 0).
    pub fn new(period_s: f64, start_s: f64) -> Result<Self, RuntimeError> {
        if !(period_s.is_finite() && period_s > 0.0) {
            return Err(RuntimeError::Config(format!(
                "loop period {period_s} s must be finite and positive"
            )));
        }
        if !start_s.is_finite() {
            return Err(RuntimeError::Config(format!("loop start {start_s} s must be finite")));
        }
        Ok(Ticker {
            period_s,
            start_s,
            next_index: 0,
            last_scheduled_s: None,
            missed_total: 0,
        })
    }

    /// The period \[s\].
    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// The first deadline \[s, clock time\]: loop time 0.
    pub fn start_s(&self) -> f64 {
        self.start_s
    }

    /// Deadlines missed since the start.
    pub fn missed_total(&self) -> u64 {
        self.missed_total
    }

    fn deadline_s(&self, index: u64) -> f64 {
        self.start_s + index as f64 * self.period_s
    }

    /// Sleeps until the next deadline and returns its tick, or `None` as soon as `stop` is set.
    pub fn wait(&mut self, clock: &dyn Clock, stop: &AtomicBool) -> Option<Tick> {
        let mut deadline_s = self.deadline_s(self.next_index);
        loop {
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            if clock.now_s() >= deadline_s {
                break;
            }
            clock.sleep_until(deadline_s);
        }
        let woke_s = clock.now_s();
        let behind = ((woke_s - deadline_s) / self.period_s).floor();
        // Saturating float-to-int conversion: a clock that jumped absurdly far only makes `missed` large.
        let missed = if behind >= 1.0 { behind as u64 } else { 0 };
        let index = self.next_index.saturating_add(missed);
        deadline_s = self.deadline_s(index);
        let dt_s = self.last_scheduled_s.map_or(self.period_s, |last| deadline_s - last);
        self.last_scheduled_s = Some(deadline_s);
        self.next_index = index.saturating_add(1);
        self.missed_total = self.missed_total.saturating_add(missed);
        Some(Tick {
            index,
            scheduled_s: deadline_s,
            dt_s,
            woke_s,
            missed,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::ManualClock;

    #[test]
    fn deadlines_are_on_the_grid_and_late_wakes_count_missed_deadlines() {
        let clock = ManualClock::new();
        let stop = AtomicBool::new(false);
        let mut ticker = Ticker::new(0.01, 0.0).expect("valid period");
        let first = ticker.wait(&clock, &stop).expect("tick");
        assert_eq!((first.index, first.scheduled_s, first.missed), (0, 0.0, 0));
        clock.set(0.013); // 3 ms late for the deadline at 10 ms: jitter, not a miss
        let second = ticker.wait(&clock, &stop).expect("tick");
        assert_eq!((second.index, second.missed), (1, 0));
        assert!(
            (second.scheduled_s - 0.01).abs() < 1e-15,
            "deadline {}",
            second.scheduled_s
        );
        clock.set(0.045); // deadlines at 20, 30 and 40 ms passed: run 40 ms, miss 20 and 30
        let third = ticker.wait(&clock, &stop).expect("tick");
        assert_eq!((third.index, third.missed), (4, 2));
        assert!((third.dt_s - 0.03).abs() < 1e-12, "dt {} vs 0.03", third.dt_s);
        assert_eq!(ticker.missed_total(), 2);
    }

    #[test]
    fn a_million_periods_do_not_drift() {
        let ticker = Ticker::new(1e-3, 0.0).expect("valid period");
        let at = ticker.deadline_s(1_000_000);
        assert!((at - 1000.0).abs() < 1e-9, "deadline {at} vs 1000 s");
    }

    #[test]
    fn stop_ends_the_wait_and_bad_periods_are_refused() {
        let clock = ManualClock::new();
        let stop = AtomicBool::new(true);
        let mut ticker = Ticker::new(0.01, 1.0).expect("valid period");
        assert_eq!(ticker.wait(&clock, &stop), None);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(Ticker::new(bad, 0.0).is_err(), "period {bad} accepted");
        }
    }
}
