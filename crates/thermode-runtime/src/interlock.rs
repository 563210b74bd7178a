//! The interlock: a latch that stops every stimulus until an operator acknowledges why. The recorder trips it when
//! the session file cannot be written and the daemon's policy is `--on-record-error stop` (a lab records because it
//! needs the data: a stimulus given while nothing is recorded is a lost trial, or worse, an unrecorded one).
//!
//! Tripping is an atomic store any thread can make; the control loop reads one atomic per tick. At the first tick
//! after a trip, the loop stops all (every channel released and held at 0 A, as `stop_all`) and, while the interlock
//! is engaged, refuses every new stimulus with `CommandError::RecordingFailed`. [`Interlock::acknowledge`] (the
//! `ack_recording` request, the dashboard's button) disengages it; releases, fault clearing and stop-all are never
//! refused.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;

/// See the module documentation.
#[derive(Debug, Default)]
pub struct Interlock {
    /// Trips so far; the loop stops all once per new trip.
    trips: AtomicU64,
    /// Tripped and not yet acknowledged.
    engaged: AtomicBool,
    /// Why it tripped last.
    reason: Mutex<Option<String>>,
}

impl Interlock {
    /// An interlock that has never tripped.
    pub fn new() -> Self {
        Interlock::default()
    }

    /// Trips the interlock for `reason`: the loop stops all at its next tick and refuses stimuli until
    /// [`Interlock::acknowledge`].
    pub fn trip(&self, reason: impl Into<String>) {
        if let Ok(mut last) = self.reason.lock() {
            *last = Some(reason.into());
        }
        self.engaged.store(true, Ordering::SeqCst);
        self.trips.fetch_add(1, Ordering::SeqCst);
    }

    /// An operator acknowledged the trip: stimuli are accepted again. Returns whether it was engaged.
    pub fn acknowledge(&self) -> bool {
        self.engaged.swap(false, Ordering::SeqCst)
    }

    /// Tripped and not yet acknowledged.
    pub fn engaged(&self) -> bool {
        self.engaged.load(Ordering::SeqCst)
    }

    /// Number of trips so far.
    pub fn trips(&self) -> u64 {
        self.trips.load(Ordering::SeqCst)
    }

    /// Why it tripped last, if it ever did.
    pub fn reason(&self) -> Option<String> {
        self.reason.lock().ok().and_then(|r| r.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_trip_engages_until_acknowledged() {
        let interlock = Interlock::new();
        assert!(!interlock.engaged());
        interlock.trip("disk full");
        assert!(interlock.engaged());
        assert_eq!(
            (interlock.trips(), interlock.reason().as_deref()),
            (1, Some("disk full"))
        );
        assert!(interlock.acknowledge());
        assert!(!interlock.engaged() && !interlock.acknowledge());
    }
}
