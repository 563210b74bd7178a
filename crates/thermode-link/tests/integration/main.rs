//! The crate's integration tests in one binary (one link instead of one per file keeps the test build short).

mod emulator;
mod guard;
mod protocol;
mod serial_pty;
