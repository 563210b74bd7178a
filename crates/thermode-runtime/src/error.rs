//! Typed errors of the loop core: refused configurations, engines that cannot be built, device failures at
//! start-up, the dose ledger, and I/O errors of the recorder and the loop's threads.

use thermode_device::DeviceError;
use thermode_model::params::BadValue;
use thiserror::Error;

use crate::ledger::LedgerError;
use crate::limits::EngineError;

/// Why the runtime could not start (or a part of it failed).
#[derive(Debug, Error)]
pub enum RuntimeError {
    /// A configuration value is out of range or inconsistent.
    #[error("invalid runtime configuration: {0}")]
    Config(String),
    /// A configuration number is out of range.
    #[error("invalid runtime configuration: {0}")]
    BadValue(#[from] BadValue),
    /// The channel engines could not be built.
    #[error("cannot build the channel engines: {0}")]
    Engine(EngineError),
    /// The device refused an operation at start-up.
    #[error("device: {0}")]
    Device(#[from] DeviceError),
    /// The dose ledger of the state directory cannot be used (corrupt, unreadable, unwritable, or in use by
    /// another process): the daemon refuses to start rather than forget a dose.
    #[error("dose ledger: {0}")]
    Ledger(#[from] LedgerError),
    /// Another I/O failure (recording directory, the loop's and the writers' threads).
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
}
