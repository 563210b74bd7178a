//! thermode-link: the links between thermode and real thermal displays. Every link implements
//! `thermode_device::Device`, so the control loop drives a real display exactly as it drives the simulated one, and
//! every drive it sends is an envelope-gated `thermode_safety::DriveCommand`.
//!
//! One folder per protocol, each of the same shape — `codec` (the bytes on the wire), `host` (the display as a
//! `Device`), `emulator` (the device side around a simulated display):
//! - [`own`]: thermode's own binary protocol (COBS frames, CRC-32, sequence numbers, watchdog; specified in
//!   `docs/protocol.md`), `serial:PATH`; its emulator carries the firmware's own over- and under-temperature cut
//!   ([`own::guard`]).
//! - [`mecom`]: Meerstetter TEC controllers over MeCom (serial or TCP), `mecom:PATH`, `mecom-tcp:HOST:PORT`.
//! - [`tcs2`]: the QST.Lab TCS II stimulator in follow mode, `tcs2:PATH`.
//!
//! Beside them, what the three share:
//! - [`host`]: the host skeleton every protocol's host runs on — the [`host::Port`], opening a serial port or a
//!   TCP connection, the reader thread, the handshake timed on the injected clock, and reconnection.
//! - [`runner`]: the emulator runner — any emulated device ([`runner::Firmware`]) in real time on a port, a
//!   pseudo-terminal ([`runner::PtyFirmware`]) or a TCP listener ([`runner::TcpFirmware`]).
//! - [`spec`]: the `--device` spellings and opening the device they name.
//!
//! Link failures are typed ([`LinkError`], carried by `thermode_device::DeviceError::Link`). Time comes from an
//! injected `thermode_platform::Clock` on both ends.

pub mod host;
pub mod mecom;
pub mod own;
pub mod runner;
pub mod spec;
pub mod tcs2;

pub use mecom::emulator::{MecomEmulator, MecomEmulatorConfig};
pub use mecom::host::{MecomConfig, MecomDevice};
pub use own::emulator::{Emulator, EmulatorConfig, EmulatorControl, PtyEmulator};
pub use own::host::{SerialConfig, SerialDevice};
pub use runner::{EmulatorError, Firmware, FirmwareControl, FirmwareStatus, PtyFirmware, RunEnd, TcpFirmware};
pub use spec::{is_hardware, open_hardware, HardwareContext};
pub use tcs2::emulator::{Tcs2Emulator, Tcs2EmulatorConfig};
pub use tcs2::host::{Tcs2Config, Tcs2Device};
pub use thermode_device::{LinkError, LinkFault, OsError};
