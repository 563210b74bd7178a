//! SIGINT and SIGTERM as a clean stop for the commands that run the daemon (`serve`, `demo`).
//!
//! [`StopSignals::install`] blocks both signals in the calling thread — and so in every thread started after it,
//! which inherit the mask: call it before starting any — and starts one thread that takes them with `sigwait`. The
//! first signal is handed to whoever waits on [`StopSignals::wait`] (the command then stops the daemon: every drive to
//! 0 A at once, the recording flushed and synced, a one-line summary, exit 0). A second signal while that stop is
//! still running ends the process at once with exit code 130 (the devices' own watchdogs then switch the drives off).

use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::Duration;

use anyhow::{Context, Result};
use nix::sys::signal::{SigSet, Signal};

/// Exit code when a second signal cuts the clean stop short: 130 (128 + SIGINT, the shell's convention).
pub const SECOND_SIGNAL_EXIT_CODE: i32 = 130;

/// The stop signals, taken by a thread of their own.
#[derive(Debug)]
pub struct StopSignals {
    received: Receiver<Signal>,
}

impl StopSignals {
    /// Blocks SIGINT and SIGTERM in this thread and its future threads, and starts the thread that takes them.
    pub fn install() -> Result<StopSignals> {
        let mut set = SigSet::empty();
        set.add(Signal::SIGINT);
        set.add(Signal::SIGTERM);
        set.thread_block().context("cannot block SIGINT and SIGTERM")?;
        let (send, received) = channel();
        std::thread::Builder::new()
            .name("thermode-signals".into())
            .spawn(move || {
                let mut seen = 0u32;
                while let Ok(signal) = set.wait() {
                    seen += 1;
                    if seen > 1 {
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
                // The signal thread ended (sigwait failed): no signal will come; wait out the time all the same.
                std::thread::sleep(timeout);
                None
            }
        }
    }
}
