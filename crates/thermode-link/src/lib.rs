//! thermode-link: the links between thermode and real thermal displays. Every link implements
//! `thermode_device::Device`, so the control loop drives a real display exactly as it drives the simulated one, and
//! every drive it sends is an envelope-gated `thermode_safety::DriveCommand`.
//!
//! - [`protocol`]: thermode's own binary host–device protocol (COBS frames, CRC-32, sequence numbers, watchdog;
//!   specified in `docs/protocol.md`).
//! - [`serial`]: [`serial::SerialDevice`], a display behind a serial port speaking that protocol (`serial:PATH`).
//! - [`emulator`]: the device side of the protocol running the simulated display on a pseudo-terminal, for
//!   `thermode emulate` and end-to-end tests without hardware.
//! - [`guard`]: the device's own over- and under-temperature cut (the emulated firmware's second line of
//!   protection, independent of the host), bounded from its own sensor and drive current.
//! - [`mecom`]: Meerstetter TEC controllers over MeCom (serial or TCP), host and emulator (`mecom:PATH`,
//!   `mecom-tcp:HOST:PORT`).
//! - [`tcs2`]: the QST.Lab TCS II stimulator in follow mode, host and emulator (`tcs2:PATH`).
//! - [`firmware`]: any emulated device in real time on a pseudo-terminal or a TCP listener.
//! - [`spec`]: the `--device` spellings and opening the device they name.
//!
//! Time comes from an injected `thermode_platform::Clock` on both ends.

pub mod emulator;
pub mod firmware;
pub mod guard;
pub mod mecom;
mod port;
pub mod protocol;
pub mod serial;
pub mod spec;
pub mod tcs2;
