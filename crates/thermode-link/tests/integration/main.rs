//! The crate's integration tests in one binary (one link instead of one per file keeps the test build short).

mod calibration;
mod emulator;
mod guard;
mod hardware_common;
mod mecom;
mod protocol;
mod serial_pty;
mod tcs2;
