//! thermode-runtime: the loop core of thermode — what every front end (the daemon `thermode serve`, the lab's
//! runner, the bench) drives. It depends on no network crate; the adapters in `thermode-serve` talk to it through
//! two ports: a command sender in ([`CommandSender`]), snapshots and events out ([`snapshot::Shared`],
//! [`recorder::RecordStatus::listen`]).
//!
//! - [`control_loop`]: the loop core one tick at a time ([`ControlLoop`]: no thread, no clock) and its real-time
//!   driver, the fixed-rate control loop on its own std thread ([`LoopHandle`]), with an injected
//!   `thermode_platform::Clock` (`MonotonicClock`, `ManualClock`) and drift-free `Ticker`, no allocation and no async per
//!   tick, missed-deadline counting and period statistics ([`stats`]).
//! - [`virtual_time`]: the core's virtual-time driver ([`VirtualLoop`]), for the lab's simulated displays and
//!   offline renders.
//! - [`engine`]: the [`ChannelEngine`] trait the loop drives per channel (renderer → controller → safety envelope);
//!   every drive it returns is a gated `DriveCommand`.
//! - [`command`]: the one command vocabulary ([`Command`]: a channel's [`Stimulus`], release, clear fault, stop
//!   all) and the bounded queue between the adapters and the loop ([`CommandSender`]); [`reply`]: the one-shot slot
//!   of each answer, usable from any thread or async executor.
//! - [`limits`]: what a channel accepts as a stimulus ([`StimulusLimits`], from the envelope it runs); the loop and
//!   the adapters enforce them and the status publishes them.
//! - [`snapshot`]: what the loop publishes (per-channel telemetry, loop statistics).
//! - [`recorder`]: `--record DIR`, one CSV per session, written by its own thread; a write error is reported
//!   everywhere and, under the policy `stop`, trips the [`interlock`] (every stimulus released, new ones refused
//!   until an operator acknowledges).
//! - [`ledger`]: the dose ledger of a state directory, so that each channel's thermal dose survives restarts
//!   (`--state-dir DIR`; `thermode dose show` and `thermode dose reset`).
//! - [`loop_core`]: all of the above as one service ([`LoopCore`]), started and stopped in the order that keeps
//!   every dose and every row.
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
//! let control = LoopHandle::spawn(LoopConfig::default(), Box::new(display), engines, clock.clone(), vec![], Arc::default())?;
//! let answer = control.commands().request(Command::StopAll)?;
//! clock.set(0.01); // the tick at 10 ms runs (if the one at 0 s has not taken the command already)
//! let applied = answer.blocking_recv()??;
//! assert!(applied.time_s <= 0.01);
//! assert!(control.snapshot().channels.iter().all(|c| c.held_off));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod command;
pub mod control_loop;
pub mod engine;
pub mod error;
pub mod interlock;
pub mod ledger;
pub mod limits;
pub mod loop_core;
pub mod program;
pub mod recorder;
pub mod reply;
pub mod snapshot;
pub mod stats;
pub mod virtual_time;

pub use command::{Applied, Command, CommandError, CommandSender, Owner};
pub use control_loop::{ControlLoop, LoopConfig, LoopHandle, MAX_RATE_HZ};
pub use engine::{ChannelEngine, EngineError, EngineFactory, Stimulus, Telemetry, TrackingEngine};
pub use error::RuntimeError;
pub use interlock::Interlock;
pub use limits::StimulusLimits;
pub use loop_core::{CoreConfig, CoreStop, LoopCore, PreparedCore};
pub use snapshot::{ChannelStatus, LoopStats, MaterialProperties, Mode, Snapshot, TickRecord};
pub use virtual_time::{SimulatedPhysics, VirtualLoop};
