//! [`LinkHealth`]: the state of the link to a real display, shared between the device (which updates it from its
//! own threads) and whoever reports it (the daemon's status page). A device without a link (the simulated
//! display) has none ([`crate::Device::link_health`] returns `None`).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;

/// See the module documentation.
#[derive(Debug)]
pub struct LinkHealth {
    up: AtomicBool,
    reconnects: AtomicU64,
    failures: AtomicU64,
    attempts: AtomicU64,
    error: Mutex<Option<String>>,
    command_set: Mutex<Option<String>>,
}

impl Default for LinkHealth {
    fn default() -> Self {
        LinkHealth {
            up: AtomicBool::new(true),
            reconnects: AtomicU64::new(0),
            failures: AtomicU64::new(0),
            attempts: AtomicU64::new(0),
            error: Mutex::new(None),
            command_set: Mutex::new(None),
        }
    }
}

impl LinkHealth {
    /// A link that is up and never failed.
    pub fn new() -> Self {
        LinkHealth::default()
    }

    /// The link went down for `reason`.
    pub fn down(&self, reason: impl Into<String>) {
        self.set_error(reason);
        self.failures.fetch_add(1, Ordering::SeqCst);
        self.up.store(false, Ordering::SeqCst);
    }

    /// A reconnection attempt starts.
    pub fn attempt(&self) {
        self.attempts.fetch_add(1, Ordering::SeqCst);
    }

    /// Why the last attempt (or the link) failed.
    pub fn set_error(&self, reason: impl Into<String>) {
        if let Ok(mut error) = self.error.lock() {
            *error = Some(reason.into());
        }
    }

    /// The link is up again after a reconnection.
    pub fn reconnected(&self) {
        self.reconnects.fetch_add(1, Ordering::SeqCst);
        self.up.store(true, Ordering::SeqCst);
    }

    /// Whether the link is up.
    pub fn is_up(&self) -> bool {
        self.up.load(Ordering::SeqCst)
    }

    /// Successful reconnections so far.
    pub fn reconnects(&self) -> u64 {
        self.reconnects.load(Ordering::SeqCst)
    }

    /// Times the link went down so far.
    pub fn failures(&self) -> u64 {
        self.failures.load(Ordering::SeqCst)
    }

    /// Reconnection attempts so far.
    pub fn attempts(&self) -> u64 {
        self.attempts.load(Ordering::SeqCst)
    }

    /// The last failure's reason (kept after a reconnection, for the record).
    pub fn error(&self) -> Option<String> {
        self.error.lock().ok().and_then(|e| e.clone())
    }

    /// Records which of the protocol's commands the device is driven with (e.g. a MeCom firmware without the newer
    /// commands), found at connect; set again at each reconnection.
    pub fn set_command_set(&self, description: impl Into<String>) {
        if let Ok(mut set) = self.command_set.lock() {
            *set = Some(description.into());
        }
    }

    /// Which commands the device is driven with, when the host records it.
    pub fn command_set(&self) -> Option<String> {
        self.command_set.lock().ok().and_then(|s| s.clone())
    }
}
