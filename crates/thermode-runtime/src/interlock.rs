//! The interlock: a latch that stops every stimulus until an operator acknowledges why. The recorder trips it when
//! the session file cannot be written and the daemon's policy is `--on-record-error stop` (a lab records because it
//! needs the data: a stimulus given while nothing is recorded is a lost trial, or worse, an unrecorded one).
//!
//! Tripping is an atomic store any thread can make; the control loop reads one atomic per tick. At the first tick
//! after a trip, the loop stops all (every channel released and held at 0 A, as `stop_all`) and, while the interlock
//! is engaged, refuses every new stimulus with `CommandError::RecordingFailed`. [`Interlock::acknowledge`] (the
//! `ack_recording` request, the dashboard's button) disengages it; releases, fault clearing and stop-all are never
//! refused.
//!
//! Beside the latch, the dose hold: the dose ledger's writer puts it on when the ledger cannot be written (the dose
//! would be forgotten at the next start) and lifts it when a write succeeds again. While it is on, the loop refuses
//! every new stimulus with `CommandError::DoseNotRecorded`; putting it on stops all at the next tick, as a trip
//! does. No acknowledgement lifts it: only a successful write.

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
    /// The dose hold is on.
    dose_held: AtomicBool,
    /// Times the dose hold went on; the loop stops all once per new one.
    dose_holds: AtomicU64,
    /// Why the dose hold went on last.
    dose_reason: Mutex<Option<String>>,
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

    /// Puts the dose hold on for `reason` (the ledger cannot be written): the loop stops all at its next tick if the
    /// hold was off, and refuses stimuli until [`Interlock::lift_dose_hold`]. Returns whether it was off.
    pub fn hold_dose(&self, reason: impl Into<String>) -> bool {
        if let Ok(mut last) = self.dose_reason.lock() {
            *last = Some(reason.into());
        }
        let newly = !self.dose_held.swap(true, Ordering::SeqCst);
        if newly {
            self.dose_holds.fetch_add(1, Ordering::SeqCst);
        }
        newly
    }

    /// Lifts the dose hold (the ledger was written again). Returns whether it was on.
    pub fn lift_dose_hold(&self) -> bool {
        self.dose_held.swap(false, Ordering::SeqCst)
    }

    /// The dose hold is on: why, else `None`.
    pub fn dose_hold(&self) -> Option<String> {
        if self.dose_held.load(Ordering::SeqCst) {
            Some(self.dose_reason.lock().ok().and_then(|r| r.clone()).unwrap_or_default())
        } else {
            None
        }
    }

    /// The dose hold is on.
    pub fn dose_held(&self) -> bool {
        self.dose_held.load(Ordering::SeqCst)
    }

    /// Trips plus dose holds so far: the loop stops all once per new one.
    pub fn stops(&self) -> u64 {
        self.trips() + self.dose_holds.load(Ordering::SeqCst)
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

    #[test]
    fn the_dose_hold_stays_until_lifted_and_an_acknowledgement_does_not_lift_it() {
        let interlock = Interlock::new();
        assert_eq!((interlock.dose_hold(), interlock.stops()), (None, 0));
        assert!(interlock.hold_dose("No space left on device"));
        assert!(
            !interlock.hold_dose("still full"),
            "a hold already on is not a new stop"
        );
        assert_eq!(interlock.stops(), 1);
        assert!(!interlock.acknowledge(), "the recording's latch is separate");
        assert_eq!(interlock.dose_hold().as_deref(), Some("still full"));
        assert!(interlock.lift_dose_hold());
        assert!(!interlock.dose_held() && !interlock.lift_dose_hold());
    }
}
