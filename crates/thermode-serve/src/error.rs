//! Typed errors of the network side: a refused configuration (including an insecure bind), a socket that cannot be
//! bound, Lab Streaming Layer unavailable, the listeners' I/O, and whatever the loop core refused.

use thermode_model::params::BadValue;
use thermode_runtime::RuntimeError;
use thiserror::Error;

/// Why the daemon could not start (or a part of it failed).
#[derive(Debug, Error)]
pub enum ServeError {
    /// The loop core refused (configuration, engines, device, dose ledger, recorder).
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
    /// A configuration value of the network side is out of range or inconsistent.
    #[error("invalid server configuration: {0}")]
    Config(String),
    /// A configuration number of the network side is out of range.
    #[error("invalid server configuration: {0}")]
    BadValue(#[from] BadValue),
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
    /// A socket could not be bound.
    #[error("cannot listen on {addr}{}: {source}", bind_hint(source))]
    Bind {
        /// The address.
        addr: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// `--lsl` was asked for but Lab Streaming Layer cannot be used (liblsl missing or unusable).
    #[error("Lab Streaming Layer: {0}")]
    Lsl(#[from] crate::lsl::LslError),
    /// Another I/O failure (the network threads, the recording's sidecars).
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
