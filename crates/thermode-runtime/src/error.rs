//! Typed errors of the runtime: refused configurations (including an insecure bind), engines that cannot be built,
//! device failures at start-up, and I/O errors of the listeners and the recorder.

use thermode_device::DeviceError;
use thermode_model::params::BadValue;
use thiserror::Error;

use crate::engine::EngineError;
use crate::ledger::LedgerError;

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
    /// Binding a non-loopback address without a token is refused (a stranger on the network could heat a finger).
    #[error(
        "refusing to listen on {addr} without --token: a non-loopback address is reachable from the network, and \
         anyone who can reach it could drive the display. Give --token SECRET (clients then present it), or bind \
         127.0.0.1"
    )]
    InsecureBind {
        /// The address asked for.
        addr: String,
    },
    /// The device refused an operation at start-up.
    #[error("device: {0}")]
    Device(#[from] DeviceError),
    /// A socket could not be bound.
    #[error("cannot listen on {addr}{}: {source}", bind_hint(source))]
    Bind {
        /// The address.
        addr: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// The dose ledger of the state directory cannot be used (corrupt, unreadable, unwritable, or in use by
    /// another process): the daemon refuses to start rather than forget a dose.
    #[error("dose ledger: {0}")]
    Ledger(#[from] LedgerError),
    /// `--lsl` was asked for but Lab Streaming Layer cannot be used (liblsl missing or unusable).
    #[error("Lab Streaming Layer: {0}")]
    Lsl(#[from] crate::lsl::LslError),
    /// Another I/O failure (recording directory, thread start).
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
}

/// What to do about a port that is taken: the usual cause is another thermode daemon.
fn bind_hint(source: &std::io::Error) -> &'static str {
    if source.kind() == std::io::ErrorKind::AddrInUse {
        " (another program, perhaps another `thermode serve` or `thermode demo`, holds this port; stop it, or choose \
         another with --port or --osc-port, 0 for a free one)"
    } else {
        ""
    }
}
