//! thermode-serve: the network adapters of `thermode serve` on the loop core's two ports (`thermode-runtime`: a
//! command sender in, snapshots and events out). A new network face is a new module here, not an edit of the core.
//!
//! - [`api`]: HTTP (`/`, `/api/status`, `/api/materials`, `/api/history`) and the WebSocket contact API
//!   (`/api/ws`), with access control (token, Host and Origin checks) and limits, served by an own accept loop that
//!   slow clients cannot starve ([`api::server`]); the status is a set of serde types ([`api::status`]).
//! - [`osc`]: the same commands over OSC/UDP.
//! - [`program_events`]: a stimulus program's events (segment starts, responses, its end), read from the loop's
//!   tick records, for WebSocket subscribers and LSL markers.
//! - [`lsl`]: `serve --lsl`, Lab Streaming Layer outlets (telemetry and markers) through liblsl loaded at run
//!   time, fed off the loop thread.
//! - [`daemon`]: starts and stops the loop core and all of the above ([`Daemon`]); [`mod@bench`]: loop jitter and
//!   touch-to-drive latency.
//!
//! The adapters talk to the loop only through the bounded queue and the snapshot. The protocol is documented in
//! `docs/api.md`, the threat model in `docs/security.md`.

pub mod api;
pub mod bench;
pub mod daemon;
pub mod error;
pub mod lsl;
pub mod osc;
pub mod program_events;
pub mod wire;

pub use daemon::{Daemon, DaemonConfig, ServerConfig, StopReport, DEFAULT_OSC_PORT, DEFAULT_PORT};
pub use error::ServeError;
