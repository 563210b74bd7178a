//! thermode-runtime: the real-time side of thermode — what `thermode serve` runs.
//!
//! - [`control_loop`]: the fixed-rate control loop on its own std thread ([`LoopHandle`]), with an injected
//!   `thermode_platform::Clock` (`MonotonicClock`, `ManualClock`) and drift-free `Ticker`, no allocation and no async per
//!   tick, missed-deadline counting and period statistics ([`stats`]).
//! - [`engine`]: the [`ChannelEngine`] trait the loop drives per channel (renderer → controller → safety envelope);
//!   every drive it returns is a gated `DriveCommand`.
//! - [`command`]: the one command vocabulary ([`Command`]: a channel's [`Stimulus`], release, clear fault, stop
//!   all) and the bounded queue between the network side and the loop ([`CommandSender`]).
//! - [`limits`]: what a channel accepts as a stimulus ([`StimulusLimits`], from the envelope it runs); the loop and
//!   the API enforce them and `/api/status` publishes them.
//! - [`snapshot`]: what the loop publishes (per-channel telemetry, loop statistics).
//! - [`recorder`]: `--record DIR`, one CSV per session, written by its own thread; a write error is reported
//!   everywhere and, under the policy `stop`, trips the [`interlock`] (every stimulus released, new ones refused
//!   until an operator acknowledges).
//! - [`ledger`]: the dose ledger of a state directory, so that each channel's thermal dose survives restarts
//!   (`--state-dir DIR`; `thermode dose show` and `thermode dose reset`).
//! - [`api`]: HTTP (`/`, `/api/status`, `/api/materials`) and the WebSocket contact API (`/api/ws`), with access
//!   control (token, Host and Origin checks) and limits, served by an own accept loop that slow clients cannot
//!   starve ([`api::server`]); [`osc`]: the same commands over OSC/UDP.
//! - [`lsl`]: `serve --lsl`, Lab Streaming Layer outlets (telemetry and markers) through liblsl loaded at run
//!   time, fed off the loop thread.
//! - [`daemon`]: starts and stops all of it ([`Daemon`]); [`mod@bench`]: loop jitter and touch-to-drive latency.
//!
//! The network side talks to the loop only through the bounded queue and the snapshot. The protocol is documented
//! in `docs/api.md`, the threat model in `docs/security.md`.
//!
//! A loop on a manual clock, driven by hand (tests do this; the daemon uses `MonotonicClock` and the render
//! pipelines):
//! ```
//! use std::sync::Arc;
//! use thermode_device::{DefaultFinger, DeviceConfig, SimulatedDisplay};
//! use thermode_runtime::engine::tracking_engines;
//! use thermode_platform::ManualClock;
//! use thermode_runtime::{Command, LoopConfig, LoopHandle};
//!
//! let display = SimulatedDisplay::<DefaultFinger>::fingertips(&DeviceConfig::default(), 2, 1)?;
//! let clock = Arc::new(ManualClock::new());
//! let engines = tracking_engines(32.0, 0.5, 2.8);
//! let control = LoopHandle::spawn(LoopConfig::default(), Box::new(display), engines, clock.clone(), vec![])?;
//! let answer = control.commands().request(Command::StopAll)?;
//! clock.set(0.01); // the tick at 10 ms runs (if the one at 0 s has not taken the command already)
//! let applied = answer.blocking_recv()??;
//! assert!(applied.time_s <= 0.01);
//! assert!(control.snapshot().channels.iter().all(|c| c.held_off));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod api;
pub mod bench;
pub mod command;
pub mod control_loop;
pub mod daemon;
pub mod engine;
pub mod error;
pub mod interlock;
pub mod ledger;
pub mod limits;
pub mod lsl;
pub mod osc;
pub mod recorder;
pub mod snapshot;
pub mod stats;

pub use command::{Applied, Command, CommandError, CommandSender, Owner};
pub use control_loop::{LoopConfig, LoopHandle, MAX_RATE_HZ};
pub use daemon::{Daemon, DaemonConfig, ServerConfig, StopReport, DEFAULT_OSC_PORT, DEFAULT_PORT};
pub use engine::{ChannelEngine, EngineError, EngineFactory, Stimulus, Telemetry, TrackingEngine};
pub use error::RuntimeError;
pub use interlock::Interlock;
pub use limits::StimulusLimits;
pub use snapshot::{ChannelStatus, LoopStats, Mode, Snapshot, TickRecord};
