//! Running an emulated device in real time: the byte-in, byte-out core of any protocol's emulator ([`Firmware`])
//! driven over a port by [`run_firmware`], on a pseudo-terminal ([`PtyFirmware`]) or a TCP listener
//! ([`TcpFirmware`]), each in its own thread. The MeCom and TCS II emulators ([`crate::mecom::emulator`],
//! [`crate::tcs2::emulator`]) run this way; thermode's own protocol keeps its [`crate::own::emulator::PtyEmulator`].
//!
//! The loop is the one of the own protocol's emulator: read what arrived (reads wait about a tick), hand it to the
//! firmware stamped with the clock's time, let the firmware's time run to now, write what it answered. A
//! [`FirmwareControl`] stops it, closes its port, makes the device fall silent (it then takes commands but answers
//! nothing) and publishes a [`FirmwareStatus`] after every loop.

use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use thermode_device::MAX_CHANNELS;
use thermode_platform::Clock;

use thermode_device::DeviceError;
use thiserror::Error;

/// Why the emulator refused a setting or stopped.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EmulatorError {
    /// A setting outside its range.
    #[error("emulator setting {what} = {value} is invalid: {requirement}")]
    BadSetting {
        /// Which setting.
        what: &'static str,
        /// Its value.
        value: f64,
        /// What it must satisfy.
        requirement: &'static str,
    },
    /// The simulated display refused something.
    #[error(transparent)]
    Device(#[from] DeviceError),
    /// The port failed.
    #[error("emulator port: {0}")]
    Io(String),
}

/// How a run of an emulated device ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunEnd {
    /// `stop` was called.
    Stopped,
    /// `close_port` was called: the port is dropped (the host sees it vanish).
    PortClosed,
    /// The port reported its end (a read of 0 bytes, or the other end closed: broken pipe, connection reset).
    HostClosed,
}

/// What an emulated device shows of itself between loops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FirmwareStatus {
    /// Device time \[s\].
    pub time_s: f64,
    /// Number of channels.
    pub channel_count: usize,
    /// True plate temperature per channel \[°C\] (NaN past `channel_count`).
    pub plate_c: [f64; MAX_CHANNELS],
    /// Current delivered in the last plant step per channel \[A\] (positive heats).
    pub applied_a: [f64; MAX_CHANNELS],
    /// Whether each channel's output stage is enabled.
    pub output_on: [bool; MAX_CHANNELS],
    /// Valid frames or commands taken from the host.
    pub frames_in: u64,
    /// Frames or bytes from the host that were refused (bad CRC, malformed, unknown).
    pub frames_refused: u64,
    /// Answers and unsolicited lines sent.
    pub frames_out: u64,
    /// Why the device stopped driving, if it did (its error state, e.g. `183` after its watchdog).
    pub error: Option<i32>,
}

impl FirmwareStatus {
    /// A status of `channel_count` channels at time 0, every output off.
    pub fn new(channel_count: usize) -> Self {
        FirmwareStatus {
            time_s: 0.0,
            channel_count,
            plate_c: [f64::NAN; MAX_CHANNELS],
            applied_a: [0.0; MAX_CHANNELS],
            output_on: [false; MAX_CHANNELS],
            frames_in: 0,
            frames_refused: 0,
            frames_out: 0,
            error: None,
        }
    }
}

/// The I/O-free core of an emulated device.
pub trait Firmware: Send {
    /// Takes bytes from the host that arrived at `now_s` \[s\] (after running the device's time up to then); answers
    /// are appended to `out`.
    fn receive(&mut self, bytes: &[u8], now_s: f64, out: &mut Vec<u8>);
    /// Runs the device's time up to `now_s` \[s\]; anything it sends by itself is appended to `out`.
    fn advance_to(&mut self, now_s: f64, out: &mut Vec<u8>);
    /// The device's tick \[s\]: the port's read timeout.
    fn tick_s(&self) -> f64;
    /// A snapshot of the device.
    fn status(&self) -> FirmwareStatus;
}

/// Controls a running emulated device from another thread and reads its status.
#[derive(Debug, Default)]
pub struct FirmwareControl {
    stop: AtomicBool,
    close: AtomicBool,
    mute: AtomicBool,
    corrupt_one_in: AtomicU64,
    status: Mutex<Option<FirmwareStatus>>,
}

impl FirmwareControl {
    /// A control with nothing requested.
    pub fn new() -> Arc<Self> {
        Arc::new(FirmwareControl::default())
    }

    /// Asks the device to stop.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }

    /// Asks the device to stop and drop its port at once (the host sees it vanish).
    pub fn close_port(&self) {
        self.close.store(true, Ordering::SeqCst);
    }

    /// Makes the device silent (`true`: it takes commands and runs, but nothing it says reaches the host) or
    /// talkative again.
    pub fn set_mute(&self, mute: bool) {
        self.mute.store(mute, Ordering::SeqCst);
    }

    /// Corrupts one byte (its lowest bit flipped, in the middle) of every `n`-th write to the host from now on; 0
    /// stops it. Deterministic, for tests of the host's CRC and format checks.
    pub fn set_corrupt_one_in(&self, n: u64) {
        self.corrupt_one_in.store(n, Ordering::SeqCst);
    }

    /// The latest published status (None before the first loop).
    pub fn status(&self) -> Option<FirmwareStatus> {
        self.status.lock().ok().and_then(|s| *s)
    }

    fn publish(&self, status: FirmwareStatus) {
        if let Ok(mut slot) = self.status.lock() {
            *slot = Some(status);
        }
    }
}

/// Whether a port error means the other end went away.
fn host_went_away(error: &io::Error) -> bool {
    matches!(
        error.kind(),
        io::ErrorKind::BrokenPipe | io::ErrorKind::ConnectionReset | io::ErrorKind::ConnectionAborted
    )
}

/// Drives `firmware` over `port` in real time on `clock` until `control` says stop or close, or the port ends.
/// The port's reads should wait at most about a tick; one that returns at once without data makes the loop sleep
/// half a tick.
pub fn run_firmware<P: Read + Write>(
    firmware: &mut dyn Firmware,
    port: &mut P,
    clock: &dyn Clock,
    control: &FirmwareControl,
) -> Result<RunEnd, EmulatorError> {
    let mut buf = [0u8; 512];
    let mut out = Vec::with_capacity(4096);
    let mut writes = 0u64;
    loop {
        if control.stop.load(Ordering::SeqCst) {
            return Ok(RunEnd::Stopped);
        }
        if control.close.load(Ordering::SeqCst) {
            return Ok(RunEnd::PortClosed);
        }
        let (n, idle) = match port.read(&mut buf) {
            Ok(0) => return Ok(RunEnd::HostClosed),
            Ok(n) => (n, false),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => (0, true),
            Err(e) if matches!(e.kind(), io::ErrorKind::TimedOut | io::ErrorKind::Interrupted) => (0, false),
            Err(e) if host_went_away(&e) => return Ok(RunEnd::HostClosed),
            Err(e) => return Err(EmulatorError::Io(e.to_string())),
        };
        let now_s = clock.now_s();
        if n > 0 {
            firmware.receive(&buf[..n], now_s, &mut out);
        } else {
            firmware.advance_to(now_s, &mut out);
        }
        if control.mute.load(Ordering::SeqCst) {
            out.clear();
        }
        if !out.is_empty() {
            writes += 1;
            let every = control.corrupt_one_in.load(Ordering::SeqCst);
            if every > 0 && writes.is_multiple_of(every) {
                let middle = out.len() / 2;
                out[middle] ^= 0x01;
            }
            let result = port.write_all(&out).and_then(|()| port.flush());
            out.clear();
            match result {
                Ok(()) => {}
                Err(e) if matches!(e.kind(), io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock) => {}
                Err(e) if host_went_away(&e) => return Ok(RunEnd::HostClosed),
                Err(e) => return Err(EmulatorError::Io(e.to_string())),
            }
        }
        control.publish(firmware.status());
        if idle {
            std::thread::sleep(Duration::from_secs_f64(firmware.tick_s() / 2.0));
        }
    }
}

/// An emulated device in its own thread on a pseudo-terminal (Unix): the host opens [`PtyFirmware::path`] as its
/// serial port. Dropping it stops the device and removes the pseudo-terminal.
#[cfg(unix)]
#[derive(Debug)]
pub struct PtyFirmware {
    path: String,
    control: Arc<FirmwareControl>,
    thread: Option<JoinHandle<Result<RunEnd, EmulatorError>>>,
}

#[cfg(unix)]
impl PtyFirmware {
    /// Creates a pseudo-terminal pair and runs `firmware` on its master side in real time on `clock`.
    pub fn spawn(mut firmware: Box<dyn Firmware>, clock: Arc<dyn Clock>) -> Result<Self, EmulatorError> {
        use serialport::{SerialPort, TTYPort};
        let io_error = |e: serialport::Error| EmulatorError::Io(format!("pseudo-terminal: {e}"));
        let (mut master, slave) = TTYPort::pair().map_err(io_error)?;
        let path = slave
            .name()
            .ok_or_else(|| EmulatorError::Io("pseudo-terminal has no path".to_string()))?;
        master
            .set_timeout(Duration::from_secs_f64(firmware.tick_s()))
            .map_err(io_error)?;
        let control = FirmwareControl::new();
        let thread_control = Arc::clone(&control);
        let thread = std::thread::Builder::new()
            .name("thermode-firmware".to_string())
            .spawn(move || {
                // The slave side stays open with the device, so the master never reads end-of-file while no host
                // is attached.
                let _slave = slave;
                run_firmware(firmware.as_mut(), &mut master, clock.as_ref(), &thread_control)
            })
            .map_err(|e| EmulatorError::Io(format!("cannot start the emulator thread: {e}")))?;
        Ok(PtyFirmware {
            path,
            control,
            thread: Some(thread),
        })
    }

    /// Path of the side the host opens, e.g. `/dev/pts/7`.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The control of the running device.
    pub fn control(&self) -> &Arc<FirmwareControl> {
        &self.control
    }

    /// Waits until the device ends (stopped, port closed, or an error).
    pub fn wait(mut self) -> Result<RunEnd, EmulatorError> {
        join(&mut self.thread)
    }
}

fn join(thread: &mut Option<JoinHandle<Result<RunEnd, EmulatorError>>>) -> Result<RunEnd, EmulatorError> {
    match thread.take() {
        Some(thread) => thread
            .join()
            .map_err(|_| EmulatorError::Io("the emulator thread panicked".to_string()))?,
        None => Ok(RunEnd::Stopped),
    }
}

#[cfg(unix)]
impl Drop for PtyFirmware {
    fn drop(&mut self) {
        self.control.stop();
        let _ = join(&mut self.thread);
    }
}

/// An emulated device in its own thread behind a TCP listener (as a device with an Ethernet port): one host
/// connection at a time; when it closes, the device goes on running and the next connection is taken. Dropping it
/// stops the device.
#[derive(Debug)]
pub struct TcpFirmware {
    address: SocketAddr,
    control: Arc<FirmwareControl>,
    thread: Option<JoinHandle<Result<RunEnd, EmulatorError>>>,
}

impl TcpFirmware {
    /// Listens on `bind` (e.g. `127.0.0.1:0` for a free port) and runs `firmware` in real time on `clock`.
    pub fn spawn(mut firmware: Box<dyn Firmware>, bind: &str, clock: Arc<dyn Clock>) -> Result<Self, EmulatorError> {
        let io_error = |e: io::Error| EmulatorError::Io(format!("TCP listener on {bind}: {e}"));
        let listener = TcpListener::bind(bind).map_err(io_error)?;
        listener.set_nonblocking(true).map_err(io_error)?;
        let address = listener.local_addr().map_err(io_error)?;
        let control = FirmwareControl::new();
        let thread_control = Arc::clone(&control);
        let thread = std::thread::Builder::new()
            .name("thermode-firmware-tcp".to_string())
            .spawn(move || serve_tcp(firmware.as_mut(), &listener, clock.as_ref(), &thread_control))
            .map_err(|e| EmulatorError::Io(format!("cannot start the emulator thread: {e}")))?;
        Ok(TcpFirmware {
            address,
            control,
            thread: Some(thread),
        })
    }

    /// The address it listens on (with the port picked for port 0).
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// The control of the running device.
    pub fn control(&self) -> &Arc<FirmwareControl> {
        &self.control
    }

    /// Waits until the device ends (stopped, or an error).
    pub fn wait(mut self) -> Result<RunEnd, EmulatorError> {
        join(&mut self.thread)
    }
}

impl Drop for TcpFirmware {
    fn drop(&mut self) {
        self.control.stop();
        let _ = join(&mut self.thread);
    }
}

/// Accepts one connection after the other; between connections the device's time runs on.
fn serve_tcp(
    firmware: &mut dyn Firmware,
    listener: &TcpListener,
    clock: &dyn Clock,
    control: &FirmwareControl,
) -> Result<RunEnd, EmulatorError> {
    let tick = Duration::from_secs_f64(firmware.tick_s());
    let mut sink = Vec::new();
    loop {
        if control.stop.load(Ordering::SeqCst) || control.close.load(Ordering::SeqCst) {
            return Ok(RunEnd::Stopped);
        }
        match listener.accept() {
            Ok((stream, _)) => {
                let mut stream = configure(stream, tick)?;
                match run_firmware(firmware, &mut stream, clock, control)? {
                    RunEnd::HostClosed => {}
                    end => return Ok(end),
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                firmware.advance_to(clock.now_s(), &mut sink);
                sink.clear();
                control.publish(firmware.status());
                std::thread::sleep(tick);
            }
            Err(e) => return Err(EmulatorError::Io(format!("TCP accept: {e}"))),
        }
    }
}

fn configure(stream: TcpStream, tick: Duration) -> Result<TcpStream, EmulatorError> {
    let io_error = |e: io::Error| EmulatorError::Io(format!("TCP connection: {e}"));
    stream.set_nonblocking(false).map_err(io_error)?;
    stream.set_read_timeout(Some(tick)).map_err(io_error)?;
    stream
        .set_write_timeout(Some(Duration::from_millis(100)))
        .map_err(io_error)?;
    stream.set_nodelay(true).map_err(io_error)?;
    Ok(stream)
}
