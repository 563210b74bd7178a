//! The reader loop every host's background thread runs over its port: read what arrives, hand it on with the time
//! it arrived, sleep 1 ms on `WouldBlock`, ride out timeouts and interrupts, and end on `stop`, on the port's end or
//! on a read error, which it reports once.

use std::io::{self, Read};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use thermode_platform::Clock;

/// Reads `port` into a buffer of `buffer_len` bytes until `stop` is set. Each read's bytes go to `received` with
/// the clock's time \[s\]; `received` returns false to end the loop (its state is gone, e.g. a poisoned lock). A
/// closed port or a read error goes to `failed` with a message, and ends the loop.
pub(crate) fn read_until_stopped(
    mut port: Box<dyn Read + Send>,
    stop: &AtomicBool,
    clock: &dyn Clock,
    buffer_len: usize,
    mut received: impl FnMut(&[u8], f64) -> bool,
    failed: impl FnOnce(String),
) {
    let mut buf = vec![0u8; buffer_len];
    while !stop.load(Ordering::SeqCst) {
        match port.read(&mut buf) {
            Ok(0) => return failed("the serial port reached its end (closed)".to_string()),
            Ok(n) => {
                if !received(&buf[..n], clock.now_s()) {
                    return;
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => std::thread::sleep(Duration::from_millis(1)),
            Err(e) if matches!(e.kind(), io::ErrorKind::TimedOut | io::ErrorKind::Interrupted) => {}
            Err(e) => return failed(format!("serial port read failed: {e}")),
        }
    }
}

/// The I/O error kind behind a serial port error (`Other` when it has none).
pub(crate) fn serial_error_kind(error: &serialport::Error) -> io::ErrorKind {
    match error.kind() {
        serialport::ErrorKind::Io(kind) => kind,
        serialport::ErrorKind::NoDevice => io::ErrorKind::NotFound,
        serialport::ErrorKind::InvalidInput => io::ErrorKind::InvalidInput,
        serialport::ErrorKind::Unknown => io::ErrorKind::Other,
    }
}
