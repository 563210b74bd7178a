//! SIGINT and SIGTERM as a clean stop for the commands that run a display (`serve`, `demo`, `lab run --device`).
//!
//! [`StopSignals::install`] installs handlers for both signals (`signal-hook`: the handler writes to a self-pipe) and
//! starts one thread that reads them. A handler, not a blocked mask and `sigwait`, because any thread may take a
//! process-directed signal: the serial reader waits in `ppoll` with an empty signal mask (serialport), so a signal
//! blocked everywhere else reached it and killed the process with the drives still on (found by the test
//! `sigterm_stops_serve_cleanly`). The first signal is handed to whoever waits on [`StopSignals::wait`] (the command
//! then stops the daemon: every drive to 0 A at once, the recording flushed and synced, a one-line summary, exit 0).
//! A second signal while that stop is still running ends the process at once with exit code 130 (the devices' own
//! watchdogs then switch the drives off).

use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::Duration;

use anyhow::{Context, Result};
use nix::sys::signal::Signal;
use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::iterator::Signals;

/// Exit code when a second signal cuts the clean stop short: 130 (128 + SIGINT, the shell's convention).
pub const SECOND_SIGNAL_EXIT_CODE: i32 = 130;

/// The stop signals, taken by a thread of their own.
#[derive(Debug)]
pub struct StopSignals {
    received: Receiver<Signal>,
}

impl StopSignals {
    /// Installs the handlers of SIGINT and SIGTERM and starts the thread that takes them.
    pub fn install() -> Result<StopSignals> {
        let mut signals = Signals::new([SIGINT, SIGTERM]).context("cannot install the SIGINT and SIGTERM handlers")?;
        let (send, received) = channel();
        std::thread::Builder::new()
            .name("thermode-signals".into())
            .spawn(move || {
                for (seen, number) in signals.forever().enumerate() {
                    let signal = Signal::try_from(number).unwrap_or(Signal::SIGTERM);
                    if seen > 0 {
                        eprintln!("thermode: {} again: exiting at once", signal.as_str());
                        std::process::exit(SECOND_SIGNAL_EXIT_CODE);
                    }
                    // The receiver is gone only when the command has returned; the process is ending then anyway.
                    let _ = send.send(signal);
                }
            })
            .context("cannot start the signal thread")?;
        Ok(StopSignals { received })
    }

    /// Waits up to `timeout` for a stop signal; `Some` with it once one arrived.
    pub fn wait(&self, timeout: Duration) -> Option<Signal> {
        match self.received.recv_timeout(timeout) {
            Ok(signal) => Some(signal),
            Err(RecvTimeoutError::Timeout) => None,
            Err(RecvTimeoutError::Disconnected) => {
                // The signal thread ended: no signal will come; wait out the time all the same.
                std::thread::sleep(timeout);
                None
            }
        }
    }
}
