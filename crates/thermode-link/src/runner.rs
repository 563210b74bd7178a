//! The emulator runner: any protocol's emulated device in real time, on a port ([`run`]), on a pseudo-terminal
//! ([`PtyRunner`]) or behind a TCP listener ([`TcpRunner`]), each in its own thread. All three protocols run this
//! way: thermode's own emulator ([`crate::own::emulator::Emulator`], whose runner is
//! [`crate::own::emulator::PtyEmulator`]) and the MeCom and TCS II emulators (through the [`Firmware`] trait:
//! [`PtyFirmware`], [`TcpFirmware`]).
//!
//! The loop: read what arrived (reads wait about a tick), hand it to the device stamped with the clock's time (or,
//! with nothing read, let its time run to now), write what it answered, publish its status. A [`Control`] stops it,
//! closes its port, makes the device fall silent (it then takes commands but answers nothing), corrupts its writes
//! for tests, and hands the device a command of its own kind (the own emulator's link faults) at the next loop.

use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use thermode_device::{Device, DeviceError, OsError, PlateFinger, SensorSample, SimulatedDisplay, MAX_CHANNELS};
use thermode_platform::Clock;
use thiserror::Error;

use crate::host::{read_step, serial_error_kind, ReadStep};

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
    Io(PortFailure),
}

/// What the runner was doing when its port failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum PortStep {
    /// Reading from or writing to the host.
    #[error("host I/O")]
    Transfer,
    /// Opening the pseudo-terminal pair.
    #[error("pseudo-terminal")]
    PseudoTerminal,
    /// The pseudo-terminal's side for the host has no path.
    #[error("pseudo-terminal has no path")]
    PseudoTerminalPath,
    /// Starting the emulator's thread.
    #[error("cannot start the emulator thread")]
    Thread,
    /// The emulator's thread panicked.
    #[error("the emulator thread panicked")]
    Panicked,
    /// Binding or configuring the TCP listener.
    #[error("TCP listener")]
    TcpListener,
    /// Accepting a TCP connection.
    #[error("TCP accept")]
    TcpAccept,
    /// Configuring an accepted TCP connection.
    #[error("TCP connection")]
    TcpConnection,
}

/// A failed step of the runner and the kind of I/O error behind it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
#[error("{step}: {error}")]
pub struct PortFailure {
    /// What the runner was doing.
    pub step: PortStep,
    /// The system's error.
    pub error: OsError,
}

impl EmulatorError {
    /// A port failure at `step` with `error`.
    pub fn io(step: PortStep, error: impl Into<OsError>) -> Self {
        EmulatorError::Io(PortFailure {
            step,
            error: error.into(),
        })
    }
}

/// How a run of an emulated device ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunEnd {
    /// [`Control::stop`] was called.
    Stopped,
    /// [`Control::close_port`] was called: the port is dropped (the host sees it vanish).
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
    /// Writes of the device's stored settings to its non-volatile memory (a MeCom controller's flash: a stored
    /// parameter set while saving to flash is on); 0 for a device without one.
    pub stored_writes: u64,
}

impl FirmwareStatus {
    /// The status of the first `channel_count` channels of `display` at device time `time_s` \[s\]: each plate from
    /// the display, each channel's delivered current \[A\] and output state from `channel`; no frames counted yet.
    pub fn of_display<F: PlateFinger>(
        display: &SimulatedDisplay<F>,
        channel_count: usize,
        time_s: f64,
        channel: impl Fn(usize) -> (f64, bool),
    ) -> Self {
        let mut status = FirmwareStatus::new(channel_count);
        status.time_s = time_s;
        for i in 0..channel_count.min(MAX_CHANNELS) {
            if let Ok(plate) = display.channel(i) {
                status.plate_c[i] = plate.state().plate_c;
            }
            (status.applied_a[i], status.output_on[i]) = channel(i);
        }
        status
    }

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
            stored_writes: 0,
        }
    }
}

/// The I/O-free core of a MeCom or TCS II emulated device (run through [`Emulated`] as a `Box<dyn Firmware>`).
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

/// A command no device takes (the [`Firmware`] devices have none of their own).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoCommand {}

/// What the runner drives: an emulated device, byte in, byte out, with its own status and command types.
pub trait Emulated: Send {
    /// What the device publishes after every loop.
    type Status: Copy + Send + 'static;
    /// What a [`Control`] can hand the device between loops.
    type Command: Send + 'static;
    /// Takes bytes from the host that arrived at `now_s` \[s\]; answers are appended to `out`.
    fn receive(&mut self, bytes: &[u8], now_s: f64, out: &mut Vec<u8>);
    /// Runs the device's time up to `now_s` \[s\]; anything it sends by itself is appended to `out`.
    fn advance_to(&mut self, now_s: f64, out: &mut Vec<u8>);
    /// The device's tick \[s\]: the port's read timeout.
    fn tick_s(&self) -> f64;
    /// A snapshot of the device.
    fn snapshot(&self) -> Self::Status;
    /// Carries out a command handed over by the control; an error stops the run.
    fn command(&mut self, command: Self::Command) -> Result<(), EmulatorError>;
    /// A write to the host timed out and its bytes are lost. Default: nothing to count.
    fn write_stalled(&mut self) {}
}

impl<T: Firmware + ?Sized> Emulated for Box<T> {
    type Status = FirmwareStatus;
    type Command = NoCommand;

    fn receive(&mut self, bytes: &[u8], now_s: f64, out: &mut Vec<u8>) {
        (**self).receive(bytes, now_s, out);
    }

    fn advance_to(&mut self, now_s: f64, out: &mut Vec<u8>) {
        (**self).advance_to(now_s, out);
    }

    fn tick_s(&self) -> f64 {
        (**self).tick_s()
    }

    fn snapshot(&self) -> FirmwareStatus {
        (**self).status()
    }

    fn command(&mut self, command: NoCommand) -> Result<(), EmulatorError> {
        match command {}
    }
}

/// Controls a running emulated device from another thread and reads its status `S`; hands it commands `C`.
#[derive(Debug)]
pub struct Control<S, C> {
    stop: AtomicBool,
    close: AtomicBool,
    drop_host: AtomicBool,
    mute: AtomicBool,
    corrupt_one_in: AtomicU64,
    command: Mutex<Option<C>>,
    status: Mutex<Option<S>>,
}

/// The control of a MeCom or TCS II emulated device.
pub type FirmwareControl = Control<FirmwareStatus, NoCommand>;

impl<S: Copy, C> Control<S, C> {
    /// A control with nothing requested.
    pub fn new() -> Arc<Self> {
        Arc::new(Control {
            stop: AtomicBool::new(false),
            close: AtomicBool::new(false),
            drop_host: AtomicBool::new(false),
            mute: AtomicBool::new(false),
            corrupt_one_in: AtomicU64::new(0),
            command: Mutex::new(None),
            status: Mutex::new(None),
        })
    }

    /// Asks the device to stop.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }

    /// Asks the device to stop and drop its port at once (the host sees it vanish).
    pub fn close_port(&self) {
        self.close.store(true, Ordering::SeqCst);
    }

    /// Drops the present host's connection as if the host had gone: behind a TCP listener the device runs on and
    /// takes the next connection; on a pseudo-terminal the run ends.
    pub fn drop_host(&self) {
        self.drop_host.store(true, Ordering::SeqCst);
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

    /// Hands `command` to the device at its next loop (replacing one not yet taken).
    pub fn send(&self, command: C) {
        if let Ok(mut slot) = self.command.lock() {
            *slot = Some(command);
        }
    }

    /// The latest published status (None before the first loop).
    pub fn status(&self) -> Option<S> {
        self.status.lock().ok().and_then(|s| *s)
    }

    /// How the run must end now, if it must.
    fn requested_end(&self) -> Option<RunEnd> {
        if self.stop.load(Ordering::SeqCst) {
            Some(RunEnd::Stopped)
        } else if self.close.load(Ordering::SeqCst) {
            Some(RunEnd::PortClosed)
        } else if self.drop_host.swap(false, Ordering::SeqCst) {
            Some(RunEnd::HostClosed)
        } else {
            None
        }
    }

    fn take_command(&self) -> Option<C> {
        self.command.lock().ok().and_then(|mut c| c.take())
    }

    fn publish(&self, status: S) {
        if let Ok(mut slot) = self.status.lock() {
            *slot = Some(status);
        }
    }

    /// Applies mute and corruption to `out`, counting the writes that remain in `writes`.
    fn tamper(&self, out: &mut Vec<u8>, writes: &mut u64) {
        if self.mute.load(Ordering::SeqCst) {
            out.clear();
        }
        if out.is_empty() {
            return;
        }
        *writes += 1;
        let every = self.corrupt_one_in.load(Ordering::SeqCst);
        if every > 0 && writes.is_multiple_of(every) {
            let middle = out.len() / 2;
            out[middle] ^= 0x01;
        }
    }
}

/// Whether a port error of `kind` means the other end went away.
fn host_went_away(kind: io::ErrorKind) -> bool {
    matches!(
        kind,
        io::ErrorKind::BrokenPipe | io::ErrorKind::ConnectionReset | io::ErrorKind::ConnectionAborted
    )
}

/// Drives `device` over `port` in real time on `clock` until `control` says stop or close, or the port ends.
/// The port's reads should wait at most about a tick; one that returns at once without data makes the loop sleep
/// half a tick.
pub fn run<E: Emulated + ?Sized, P: Read + Write>(
    device: &mut E,
    port: &mut P,
    clock: &dyn Clock,
    control: &Control<E::Status, E::Command>,
) -> Result<RunEnd, EmulatorError> {
    let mut buf = [0u8; 512];
    let mut out = Vec::with_capacity(4096);
    let mut writes = 0u64;
    loop {
        if let Some(end) = control.requested_end() {
            return Ok(end);
        }
        if let Some(command) = control.take_command() {
            device.command(command)?;
        }
        let (n, idle) = match read_step(port, &mut buf) {
            ReadStep::Data(n) => (n, false),
            ReadStep::Idle => (0, true),
            ReadStep::Retry => (0, false),
            ReadStep::Closed => return Ok(RunEnd::HostClosed),
            ReadStep::Failed(error) if host_went_away(error.kind) => return Ok(RunEnd::HostClosed),
            ReadStep::Failed(error) => return Err(EmulatorError::io(PortStep::Transfer, error)),
        };
        let now_s = clock.now_s();
        if n > 0 {
            device.receive(&buf[..n], now_s, &mut out);
        } else {
            device.advance_to(now_s, &mut out);
        }
        control.tamper(&mut out, &mut writes);
        if let Some(end) = write_out(device, port, &mut out)? {
            return Ok(end);
        }
        control.publish(device.snapshot());
        if idle {
            std::thread::sleep(Duration::from_secs_f64(device.tick_s() / 2.0));
        }
    }
}

/// Writes `out` to the port; a write that times out loses its bytes (the device counts it). `Some` when the host
/// is gone.
fn write_out<E: Emulated + ?Sized, P: Write>(
    device: &mut E,
    port: &mut P,
    out: &mut Vec<u8>,
) -> Result<Option<RunEnd>, EmulatorError> {
    if out.is_empty() {
        return Ok(None);
    }
    let result = port.write_all(out).and_then(|()| port.flush());
    out.clear();
    match result {
        Ok(()) => Ok(None),
        Err(e) if matches!(e.kind(), io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock) => {
            device.write_stalled();
            Ok(None)
        }
        Err(e) if host_went_away(e.kind()) => Ok(Some(RunEnd::HostClosed)),
        Err(e) => Err(EmulatorError::io(PortStep::Transfer, e)),
    }
}

/// The thread a runner runs its device in.
type RunThread = Option<JoinHandle<Result<RunEnd, EmulatorError>>>;

fn join(thread: &mut RunThread) -> Result<RunEnd, EmulatorError> {
    match thread.take() {
        Some(thread) => thread
            .join()
            .map_err(|_| EmulatorError::io(PortStep::Panicked, io::ErrorKind::Other))?,
        None => Ok(RunEnd::Stopped),
    }
}

/// Starts `body` in a thread named `name`.
fn start(
    name: &str,
    body: impl FnOnce() -> Result<RunEnd, EmulatorError> + Send + 'static,
) -> Result<RunThread, EmulatorError> {
    std::thread::Builder::new()
        .name(name.to_string())
        .spawn(body)
        .map(Some)
        .map_err(|e| EmulatorError::io(PortStep::Thread, e))
}

/// An emulated device in its own thread on a pseudo-terminal (Unix): the host opens [`PtyRunner::path`] as its
/// serial port. Dropping it stops the device and removes the pseudo-terminal.
#[cfg(unix)]
#[derive(Debug)]
pub struct PtyRunner<S, C> {
    path: String,
    control: Arc<Control<S, C>>,
    thread: RunThread,
}

/// A MeCom or TCS II emulated device on a pseudo-terminal.
#[cfg(unix)]
pub type PtyFirmware = PtyRunner<FirmwareStatus, NoCommand>;

/// A reference thermometer on a pseudo-terminal of its own, as USB lab thermometers are: every `period_s` \[s\]
/// it writes the true plate temperature of `channel` of the emulated device that `control` runs, plus Gaussian
/// noise of standard deviation `noise_c` \[°C\] (ChaCha8 seeded with `seed`), as one line in °C (`23.412`). Returns
/// the path a reader opens; the thread runs until the process ends or its port fails.
#[cfg(unix)]
pub fn spawn_reference_thermometer(
    control: Arc<FirmwareControl>,
    channel: usize,
    noise_c: f64,
    seed: u64,
    period_s: f64,
) -> Result<String, EmulatorError> {
    use rand::{Rng, SeedableRng};
    use serialport::{SerialPort, TTYPort};
    let io_error = |e: serialport::Error| EmulatorError::io(PortStep::PseudoTerminal, serial_error_kind(&e));
    let (mut master, slave) = TTYPort::pair().map_err(io_error)?;
    let path = slave
        .name()
        .ok_or(EmulatorError::io(PortStep::PseudoTerminalPath, io::ErrorKind::NotFound))?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    // Detached: it ends with the device's run or the process.
    let _thread = start("thermode-reference", move || {
        let _slave = slave;
        loop {
            std::thread::sleep(Duration::from_secs_f64(period_s));
            if control.stop.load(Ordering::SeqCst) {
                return Ok(RunEnd::Stopped);
            }
            let Some(plate_c) = control.status().map(|s| s.plate_c[channel.min(MAX_CHANNELS - 1)]) else {
                continue;
            };
            // Box–Muller: one standard normal from two uniforms in (0, 1].
            let (u1, u2): (f64, f64) = (1.0 - rng.gen::<f64>(), rng.gen::<f64>());
            let normal = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
            let line = format!("{:.3}\n", plate_c + noise_c * normal);
            if master.write_all(line.as_bytes()).and_then(|()| master.flush()).is_err() {
                return Ok(RunEnd::HostClosed);
            }
        }
    })?;
    Ok(path)
}

#[cfg(unix)]
impl<S: Copy + Send + 'static, C: Send + 'static> PtyRunner<S, C> {
    /// Creates a pseudo-terminal pair and runs `device` on its master side in real time on `clock`.
    pub fn spawn<E>(mut device: E, clock: Arc<dyn Clock>) -> Result<Self, EmulatorError>
    where
        E: Emulated<Status = S, Command = C> + 'static,
    {
        use serialport::{SerialPort, TTYPort};
        let io_error = |e: serialport::Error| EmulatorError::io(PortStep::PseudoTerminal, serial_error_kind(&e));
        let (mut master, slave) = TTYPort::pair().map_err(io_error)?;
        let path = slave
            .name()
            .ok_or(EmulatorError::io(PortStep::PseudoTerminalPath, io::ErrorKind::NotFound))?;
        master
            .set_timeout(Duration::from_secs_f64(device.tick_s()))
            .map_err(io_error)?;
        let control = Control::new();
        let thread_control = Arc::clone(&control);
        let thread = start("thermode-emulator", move || {
            // The slave side stays open with the device, so the master never reads end-of-file while no host is
            // attached; both close when the run ends.
            let _slave = slave;
            run(&mut device, &mut master, clock.as_ref(), &thread_control)
        })?;
        Ok(PtyRunner { path, control, thread })
    }

    /// Path of the side the host opens, e.g. `/dev/pts/7`.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The control of the running device.
    pub fn control(&self) -> &Arc<Control<S, C>> {
        &self.control
    }

    /// Waits until the device ends (stopped, port closed, or an error).
    pub fn wait(mut self) -> Result<RunEnd, EmulatorError> {
        join(&mut self.thread)
    }
}

#[cfg(unix)]
impl<S, C> Drop for PtyRunner<S, C> {
    fn drop(&mut self) {
        self.control.stop.store(true, Ordering::SeqCst);
        let _ = join(&mut self.thread);
    }
}

/// An emulated device in its own thread behind a TCP listener (as a device with an Ethernet port): one host
/// connection at a time; when it closes, the device goes on running and the next connection is taken. Dropping it
/// stops the device.
#[derive(Debug)]
pub struct TcpRunner<S, C> {
    address: SocketAddr,
    control: Arc<Control<S, C>>,
    thread: RunThread,
}

/// A MeCom or TCS II emulated device behind a TCP listener.
pub type TcpFirmware = TcpRunner<FirmwareStatus, NoCommand>;

impl<S: Copy + Send + 'static, C: Send + 'static> TcpRunner<S, C> {
    /// Listens on `bind` (e.g. `127.0.0.1:0` for a free port) and runs `device` in real time on `clock`.
    pub fn spawn<E>(mut device: E, bind: &str, clock: Arc<dyn Clock>) -> Result<Self, EmulatorError>
    where
        E: Emulated<Status = S, Command = C> + 'static,
    {
        let io_error = |e: io::Error| EmulatorError::io(PortStep::TcpListener, e);
        let listener = TcpListener::bind(bind).map_err(io_error)?;
        listener.set_nonblocking(true).map_err(io_error)?;
        let address = listener.local_addr().map_err(io_error)?;
        let control = Control::new();
        let thread_control = Arc::clone(&control);
        let thread = start("thermode-emulator-tcp", move || {
            serve_tcp(&mut device, &listener, clock.as_ref(), &thread_control)
        })?;
        Ok(TcpRunner {
            address,
            control,
            thread,
        })
    }

    /// The address it listens on (with the port picked for port 0).
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// The control of the running device.
    pub fn control(&self) -> &Arc<Control<S, C>> {
        &self.control
    }

    /// Waits until the device ends (stopped, or an error).
    pub fn wait(mut self) -> Result<RunEnd, EmulatorError> {
        join(&mut self.thread)
    }
}

impl<S, C> Drop for TcpRunner<S, C> {
    fn drop(&mut self) {
        self.control.stop.store(true, Ordering::SeqCst);
        let _ = join(&mut self.thread);
    }
}

/// Accepts one connection after the other; between connections the device's time runs on.
fn serve_tcp<E: Emulated + ?Sized>(
    device: &mut E,
    listener: &TcpListener,
    clock: &dyn Clock,
    control: &Control<E::Status, E::Command>,
) -> Result<RunEnd, EmulatorError> {
    let tick = Duration::from_secs_f64(device.tick_s());
    let mut sink = Vec::new();
    loop {
        match control.requested_end() {
            // No host to drop between connections.
            None | Some(RunEnd::HostClosed) => {}
            Some(_) => return Ok(RunEnd::Stopped),
        }
        match listener.accept() {
            Ok((stream, _)) => {
                let mut stream = configure(stream, tick)?;
                match run(device, &mut stream, clock, control)? {
                    RunEnd::HostClosed => {}
                    end => return Ok(end),
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                device.advance_to(clock.now_s(), &mut sink);
                sink.clear();
                control.publish(device.snapshot());
                std::thread::sleep(tick);
            }
            Err(e) => return Err(EmulatorError::io(PortStep::TcpAccept, e)),
        }
    }
}

fn configure(stream: TcpStream, tick: Duration) -> Result<TcpStream, EmulatorError> {
    let io_error = |e: io::Error| EmulatorError::io(PortStep::TcpConnection, e);
    stream.set_nonblocking(false).map_err(io_error)?;
    stream.set_read_timeout(Some(tick)).map_err(io_error)?;
    stream
        .set_write_timeout(Some(Duration::from_millis(100)))
        .map_err(io_error)?;
    stream.set_nodelay(true).map_err(io_error)?;
    Ok(stream)
}

/// The accessors every emulator around a `SimulatedDisplay` offers, written once: `time_s` (device time \[s\], whole
/// ticks since start: its `tick` field times its config's `tick_s`), `display` and `display_mut` (its `display` field:
/// initial temperatures, plant faults).
macro_rules! display_accessors {
    () => {
        /// Device time \[s\]: whole ticks since start.
        pub fn time_s(&self) -> f64 {
            self.tick as f64 * self.config.tick_s
        }

        /// The simulated display.
        pub fn display(&self) -> &SimulatedDisplay<F> {
            &self.display
        }

        /// The simulated display, mutable (initial temperatures, plant faults).
        pub fn display_mut(&mut self) -> &mut SimulatedDisplay<F> {
            &mut self.display
        }
    };
}
pub(crate) use display_accessors;

/// The trace accessors every emulator offers, written once: `trace_to` (starts a [`Trace`] of the plant into a sink,
/// kept in its `trace: Option<Trace>` field) and `trace_error`.
macro_rules! trace_accessors {
    () => {
        /// Writes a trace of the plant to `out` from now on: the header [`crate::runner::TRACE_HEADER`], then after
        /// every plant step one CSV row per channel with the true plate (see [`crate::runner::Trace`]). A step is one
        /// tick, or several merged while catching up. A write that fails stops the trace (see `trace_error`); the
        /// emulator runs on.
        pub fn trace_to(&mut self, out: Box<dyn std::io::Write + Send>) {
            self.trace = Some(crate::runner::Trace::new(out));
        }

        /// Why the trace stopped, if it did: the kind of the error of the write to its sink that failed.
        pub fn trace_error(&self) -> Option<std::io::ErrorKind> {
            self.trace.as_ref().and_then(crate::runner::Trace::error)
        }
    };
}
pub(crate) use trace_accessors;

/// The tick a device whose ticks last `tick_s` \[s\] has reached at `now_s` \[s\] (None for a time that is not finite).
pub(crate) fn tick_at(now_s: f64, tick_s: f64) -> Option<u64> {
    now_s
        .is_finite()
        .then(|| (now_s / tick_s + 1e-9).floor().max(0.0) as u64)
}

/// The error of an emulated device's plate sensor as the device sees it: it reads `gain · T + offset_c` at a true
/// plate (sensor element) temperature T, and the device regulates, cuts, clamps and reports on that reading (a
/// mounted sensor off the truth, for `thermode calibrate` and the tests of the device-side lines under a
/// calibration). The same for every protocol's emulator (`thermode emulate --sensor-offset-c --sensor-gain`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorError {
    /// The sensor's gain \[-\], positive. Default 1.
    pub gain: f64,
    /// The sensor's offset \[°C\], finite. Default 0.
    pub offset_c: f64,
}

impl Default for SensorError {
    fn default() -> Self {
        SensorError {
            gain: 1.0,
            offset_c: 0.0,
        }
    }
}

impl SensorError {
    /// What the sensor reads \[°C\] at the true temperature `true_c` \[°C\].
    pub fn reads_c(&self, true_c: f64) -> f64 {
        self.gain * true_c + self.offset_c
    }

    /// `sample` as the device reads it (its value through [`SensorError::reads_c`]).
    pub fn sample(&self, sample: SensorSample) -> SensorSample {
        SensorSample {
            value_c: self.reads_c(sample.value_c),
            ..sample
        }
    }

    /// `Ok` for a positive gain and a finite offset.
    pub fn check(&self) -> Result<(), EmulatorError> {
        if self.gain.is_finite() && self.gain > 0.0 && self.offset_c.is_finite() {
            return Ok(());
        }
        Err(EmulatorError::BadSetting {
            what: "sensor gain",
            value: self.gain,
            requirement: "must be positive, the offset finite",
        })
    }
}

/// The one merged plant step \[s\] from `tick` to `target` when that is more than 0.1 s (the plant is implicit and
/// stable for any step), else None (step tick by tick).
pub(crate) fn merged_step_s(tick: u64, target: u64, tick_s: f64) -> Option<f64> {
    (target > tick + (0.1 / tick_s) as u64).then(|| (target - tick) as f64 * tick_s)
}

/// The header of an emulator's trace of its plant (`trace_to` of each emulator, `thermode emulate --trace`).
pub const TRACE_HEADER: &str = "time_s,channel,plate_c,sensor_c,current_a";

/// An emulator's trace of its plant: after every plant step one CSV row per channel (`time_s,channel,plate_c,
/// sensor_c,current_a`: the emulator's time at the end of the step \[s\], channel from 0, the true plate \[°C\], the
/// sensor's latest sample \[°C\], the current delivered during the step \[A\]), each step's rows in one `write_all`
/// followed by `flush` (with an unbuffered sink a reader following the file sees whole rows only, and a kill between
/// ticks tears none). A write that fails stops the trace; the emulator runs on. The same for every protocol.
pub struct Trace {
    out: Box<dyn Write + Send>,
    line: Vec<u8>,
    error: Option<io::ErrorKind>,
}

impl Trace {
    /// A trace into `out`, its header [`TRACE_HEADER`] written at once.
    pub fn new(out: Box<dyn Write + Send>) -> Self {
        let mut trace = Trace {
            out,
            line: Vec::with_capacity(64 * MAX_CHANNELS),
            error: None,
        };
        trace.line.extend_from_slice(TRACE_HEADER.as_bytes());
        trace.line.push(b'\n');
        trace.write();
        trace
    }

    /// Why the trace stopped, if it did: the kind of the error of the write to its sink that failed.
    pub fn error(&self) -> Option<io::ErrorKind> {
        self.error
    }

    /// One row per channel of `display` for the step that ended at `time_s` \[s\], written at once.
    pub fn step<F: PlateFinger>(&mut self, time_s: f64, display: &SimulatedDisplay<F>) {
        if self.error.is_some() {
            return;
        }
        self.line.clear();
        for i in 0..display.channel_count() {
            if let Ok(channel) = display.channel(i) {
                let state = channel.state();
                // Writing into a Vec cannot fail.
                let _ = writeln!(
                    self.line,
                    "{time_s:.3},{i},{:.4},{:.4},{:.4}",
                    state.plate_c, state.sensor.value_c, state.applied_current_a
                );
            }
        }
        self.write();
    }

    /// Writes the pending rows in one call and flushes; a failure stops the trace.
    fn write(&mut self) {
        if let Err(e) = self.out.write_all(&self.line).and_then(|()| self.out.flush()) {
            self.error = Some(e.kind());
        }
        self.line.clear();
    }
}

impl std::fmt::Debug for Trace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trace")
            .field("error", &self.error)
            .finish_non_exhaustive()
    }
}
