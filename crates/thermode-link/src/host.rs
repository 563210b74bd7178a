//! The host skeleton every protocol's host runs on:
//!
//! - [`Port`]: a byte stream both ways with a read timeout; `open_serial`, `split` and `open_tcp` open one and set
//!   its timeouts, with typed failures (`LinkFault::Open`).
//! - `Reader`: the background thread that reads the port into a host's `LineState` behind a mutex held for
//!   microseconds, stamps what arrives with the injected clock's time, sleeps 1 ms on `WouldBlock`, rides out
//!   timeouts and interrupts, and ends on stop, on the port's end or on a read error, which it records once.
//! - `Line`: the port's writer, the reader's shared state, the clock and the link's latched failure: writing a frame
//!   (a failed write fails the link for good), reading the shared state, typed errors naming the device; and
//!   `retry_until`, the handshake's loop (send every so often until the reader saw the answer) timed on the clock.
//! - `Reconnector`: re-opening a failed link in a thread of its own with back-off on the clock
//!   ([`FIRST_BACKOFF_S`], doubling), handing the new link over without blocking the control loop.
//!
//! thermode's own protocol ([`crate::own::host`]) and the TCS II host ([`crate::tcs2::host`]) run on a `Line`; the
//! MeCom host ([`crate::mecom::host`]) asks and waits request by request in a worker that owns its [`Port`], opened
//! here, with its handshake on the same clock.

use std::io::{self, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use thermode_device::{DeviceError, DownReason, LinkError, LinkFault, LinkHealth, OpenStep, OsError};
use thermode_platform::Clock;

/// A port both ways with a read timeout.
pub trait Port: Read + Write + Send {}
impl<T: Read + Write + Send> Port for T {}

/// What one read of a port with a read timeout gave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ReadStep {
    /// This many bytes.
    Data(usize),
    /// Nothing at once (`WouldBlock`): the caller sleeps before it reads again.
    Idle,
    /// Nothing within the timeout, or interrupted: read again.
    Retry,
    /// The port reached its end (the other side closed).
    Closed,
    /// The port failed.
    Failed(OsError),
}

/// Reads `port` once into `buf`: how every host, reader and emulator runner reads its port.
pub(crate) fn read_step<P: Read + ?Sized>(port: &mut P, buf: &mut [u8]) -> ReadStep {
    match port.read(buf) {
        Ok(0) => ReadStep::Closed,
        Ok(n) => ReadStep::Data(n),
        Err(e) if e.kind() == io::ErrorKind::WouldBlock => ReadStep::Idle,
        Err(e) if matches!(e.kind(), io::ErrorKind::TimedOut | io::ErrorKind::Interrupted) => ReadStep::Retry,
        Err(e) => ReadStep::Failed(OsError::from(e)),
    }
}

/// The system's error behind a serial port error (its kind; `serialport` keeps no errno).
pub(crate) fn serial_error_kind(error: &serialport::Error) -> OsError {
    let kind = match error.kind() {
        serialport::ErrorKind::Io(kind) => kind,
        serialport::ErrorKind::NoDevice => io::ErrorKind::NotFound,
        serialport::ErrorKind::InvalidInput => io::ErrorKind::InvalidInput,
        serialport::ErrorKind::Unknown => io::ErrorKind::Other,
    };
    OsError::from(kind)
}

/// The link error of `device` failing to open at `step` with an error of `kind`.
fn open_failed(device: &Path, step: OpenStep, error: impl Into<OsError>) -> DeviceError {
    let error = error.into();
    LinkError::device(device, LinkFault::Open { step, error }).into()
}

/// Opens the serial port `path` raw, 8N1, at `baud_rate` \[bit/s\], exclusively (Unix), with reads timing out after
/// `read_timeout`, and discards what is buffered in the directions `clear` names.
pub(crate) fn open_serial(
    path: &str,
    baud_rate: u32,
    read_timeout: Duration,
    clear: serialport::ClearBuffer,
) -> Result<Box<dyn serialport::SerialPort>, DeviceError> {
    let builder = serialport::new(path, baud_rate).timeout(read_timeout);
    // Exclusive: TIOCEXCL (no other process opens the terminal, root excepted) and an exclusive `flock` (no other
    // serialport user, root included), so no second client shares thermode's line.
    #[cfg(unix)]
    let builder = builder.exclusive(true);
    let port = builder
        .open()
        .map_err(|e| open_failed(Path::new(path), OpenStep::Open, serial_error_kind(&e)))?;
    let _ = port.clear(clear);
    Ok(port)
}

/// The reading and the writing end of `port` (named `path`), writes timing out after `write_timeout`.
pub(crate) fn split(
    port: Box<dyn serialport::SerialPort>,
    path: &str,
    write_timeout: Duration,
) -> Result<Streams, DeviceError> {
    let failed = |step, e: serialport::Error| open_failed(Path::new(path), step, serial_error_kind(&e));
    let mut writer = port.try_clone().map_err(|e| failed(OpenStep::Share, e))?;
    writer
        .set_timeout(write_timeout)
        .map_err(|e| failed(OpenStep::WriteTimeout, e))?;
    Ok((port, writer))
}

/// Connects to `address` (`HOST:PORT`) within `connect_timeout`, reads timing out after `read_timeout`, writes
/// after `write_timeout`, without Nagle's delay.
pub(crate) fn open_tcp(
    address: &str,
    connect_timeout: Duration,
    read_timeout: Duration,
    write_timeout: Duration,
) -> Result<TcpStream, DeviceError> {
    let device = Path::new(address);
    let target = address
        .to_socket_addrs()
        .map_err(|e| open_failed(device, OpenStep::Resolve, e))?
        .next()
        .ok_or_else(|| DeviceError::from(LinkError::device(device, LinkFault::NoAddress)))?;
    let stream =
        TcpStream::connect_timeout(&target, connect_timeout).map_err(|e| open_failed(device, OpenStep::Connect, e))?;
    stream
        .set_read_timeout(Some(read_timeout))
        .and_then(|()| stream.set_write_timeout(Some(write_timeout)))
        .and_then(|()| stream.set_nodelay(true))
        .map_err(|e| open_failed(device, OpenStep::Configure, e))?;
    Ok(stream)
}

/// The reading and the writing end of a port.
pub(crate) type Streams = (Box<dyn Read + Send>, Box<dyn Write + Send>);

/// Starts `body` in a thread named `name`; a thread that cannot start fails the link of `device`.
pub(crate) fn start_thread<T: Send + 'static>(
    device: &Path,
    name: &str,
    body: impl FnOnce() -> T + Send + 'static,
) -> Result<JoinHandle<T>, DeviceError> {
    std::thread::Builder::new()
        .name(name.to_string())
        .spawn(body)
        .map_err(|e| open_failed(device, OpenStep::Thread, e))
}

/// The state a host's reader thread keeps: what it decoded, and the port's failure.
pub(crate) trait LineState: Default + Send + 'static {
    /// Takes the bytes that arrived at `received_s` \[s\] on the host clock.
    fn take(&mut self, bytes: &[u8], received_s: f64);
    /// The port's failure, once it failed (permanent).
    fn port_fault(&self) -> Option<&LinkFault>;
    /// Records the port's failure.
    fn set_port_fault(&mut self, fault: LinkFault);
}

/// A host's reader thread.
#[derive(Debug)]
pub(crate) struct Reader {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// Whether dropping waits for the thread (a port opened by path; a stream given by the caller may not time out).
    join: bool,
}

impl Reader {
    /// Asks the thread to end and lets it go without waiting (it ends within its read timeout and closes its port).
    pub(crate) fn detach(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        drop(self.thread.take());
    }

    /// Whether dropping waits for the thread.
    pub(crate) fn set_join(&mut self, join: bool) {
        self.join = join;
    }
}

impl Drop for Reader {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            if self.join {
                let _ = thread.join();
            }
        }
    }
}

/// Reads `port` into a buffer of `buffer_len` bytes until `stop` is set, handing each read's bytes to the state with
/// the clock's time \[s\]. A closed port or a read error is recorded in the state and ends the loop; so does a
/// poisoned lock.
fn read_until_stopped<S: LineState>(
    mut port: Box<dyn Read + Send>,
    shared: &Mutex<S>,
    stop: &AtomicBool,
    clock: &dyn Clock,
    buffer_len: usize,
) {
    let mut buf = vec![0u8; buffer_len];
    let failed = |fault| {
        if let Ok(mut state) = shared.lock() {
            state.set_port_fault(fault);
        }
    };
    while !stop.load(Ordering::SeqCst) {
        match read_step(port.as_mut(), &mut buf) {
            ReadStep::Closed => return failed(LinkFault::PortClosed),
            ReadStep::Data(n) => {
                let received_s = clock.now_s();
                let Ok(mut state) = shared.lock() else {
                    return;
                };
                state.take(&buf[..n], received_s);
            }
            ReadStep::Idle => std::thread::sleep(Duration::from_millis(1)),
            ReadStep::Retry => {}
            ReadStep::Failed(error) => return failed(LinkFault::ReadFailed { error }),
        }
    }
}

/// One port of a host: its writer, the reader's shared state, the clock and the link's latched failure.
pub(crate) struct Line<S> {
    /// The device, in messages.
    pub(crate) name: PathBuf,
    pub(crate) writer: Box<dyn Write + Send>,
    pub(crate) shared: Arc<Mutex<S>>,
    pub(crate) reader: Reader,
    pub(crate) clock: Arc<dyn Clock>,
    /// Set when a write failed or the link was taken down; permanent for this line.
    pub(crate) failed: Option<LinkFault>,
}

/// How a [`Line`]'s reader thread runs.
pub(crate) struct ReaderSpec {
    /// The thread's name.
    pub(crate) thread: &'static str,
    /// The read buffer \[bytes\].
    pub(crate) buffer_len: usize,
}

impl<S: LineState> Line<S> {
    /// Starts the reader thread on `reader` and keeps `writer` for frames to the device `name`; `join`: dropping
    /// waits for the reader (a port opened by path; a stream given by the caller may not time out).
    pub(crate) fn start(
        name: &str,
        (reader, writer): Streams,
        clock: Arc<dyn Clock>,
        spec: &ReaderSpec,
        join: bool,
    ) -> Result<Self, DeviceError> {
        let shared = Arc::new(Mutex::new(S::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let name = PathBuf::from(name);
        let thread = {
            let (shared, stop, clock) = (Arc::clone(&shared), Arc::clone(&stop), Arc::clone(&clock));
            let buffer_len = spec.buffer_len;
            start_thread(&name, spec.thread, move || {
                read_until_stopped(reader, &shared, &stop, clock.as_ref(), buffer_len);
            })?
        };
        Ok(Line {
            name,
            writer,
            shared,
            reader: Reader {
                stop,
                thread: Some(thread),
                join,
            },
            clock,
            failed: None,
        })
    }

    /// The link error `fault` of this device.
    pub(crate) fn link_error(&self, fault: LinkFault) -> LinkError {
        LinkError::device(&self.name, fault)
    }

    /// The device error of the link error `fault` of this device.
    pub(crate) fn error(&self, fault: LinkFault) -> DeviceError {
        self.link_error(fault).into()
    }

    /// The reader's state, or why it is gone.
    pub(crate) fn lock(&self) -> Result<MutexGuard<'_, S>, DeviceError> {
        self.shared.lock().map_err(|_| self.error(LinkFault::ReaderFailed))
    }

    /// `Err` once the link failed (a failed write, or taken down).
    pub(crate) fn check_failed(&self) -> Result<(), DeviceError> {
        match &self.failed {
            Some(fault) => Err(self.error(fault.clone())),
            None => Ok(()),
        }
    }

    /// `Err` with the port's failure once the reader saw one.
    pub(crate) fn check_port(&self, state: &S) -> Result<(), DeviceError> {
        match state.port_fault() {
            Some(fault) => Err(self.error(fault.clone())),
            None => Ok(()),
        }
    }

    /// Writes `bytes` and flushes; a write that fails (or times out) fails the link for good.
    pub(crate) fn write(&mut self, bytes: &[u8]) -> Result<(), DeviceError> {
        self.check_failed()?;
        let result = self.writer.write_all(bytes).and_then(|()| self.writer.flush());
        result.map_err(|e| {
            let fault = LinkFault::WriteFailed {
                error: OsError::from(e),
            };
            self.failed = Some(fault.clone());
            self.error(fault)
        })
    }

    /// The clock's time at which a handshake of `timeout_s` \[s\] begun now must be over.
    pub(crate) fn deadline_s(&self, timeout_s: f64) -> f64 {
        self.clock.now_s() + timeout_s
    }
}

/// A host running on a [`Line`].
pub(crate) trait OnLine {
    /// What its reader keeps.
    type State: LineState;
    /// Its line.
    fn line(&self) -> &Line<Self::State>;
}

/// Calls `send` on `host` every `every_s` \[s\] until `done` finds what it waits for in the reader's state, or the
/// host's clock reaches `deadline_s` (None). A port failure ends it at once. The handshake of every host on a line.
pub(crate) fn retry_until<H: OnLine, T>(
    host: &mut H,
    deadline_s: f64,
    every_s: f64,
    mut send: impl FnMut(&mut H) -> Result<(), DeviceError>,
    done: impl Fn(&H::State) -> Option<T>,
) -> Result<Option<T>, DeviceError> {
    let clock = Arc::clone(&host.line().clock);
    let mut next_send_s = clock.now_s();
    while clock.now_s() < deadline_s {
        {
            let line = host.line();
            let state = line.lock()?;
            line.check_port(&state)?;
            if let Some(found) = done(&state) {
                return Ok(Some(found));
            }
        }
        if clock.now_s() >= next_send_s {
            send(host)?;
            next_send_s = clock.now_s() + every_s;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    Ok(None)
}

/// The first wait between reconnection attempts \[s\]; it doubles up to the host's maximum.
pub const FIRST_BACKOFF_S: f64 = 0.5;

/// A host's reconnector thread, which makes new links of type `D` (opened and handshaken) on request.
pub(crate) struct Reconnector<D> {
    /// Asks the thread for a new link.
    wanted: SyncSender<()>,
    /// Links the thread made.
    fresh: Receiver<D>,
    /// Ends the thread.
    stop: Arc<AtomicBool>,
    /// The link is down and a new one has been asked for.
    pub(crate) down: bool,
}

impl<D: Send + 'static> Reconnector<D> {
    /// Starts the thread for the device `name`: on each request it calls `open` until it succeeds (waiting
    /// [`FIRST_BACKOFF_S`] on `clock` before the first attempt, doubling up to `backoff_max_s` \[s\]), counting
    /// attempts and failures in `health`, then hands the new link over.
    pub(crate) fn spawn(
        name: &str,
        backoff_max_s: f64,
        clock: Arc<dyn Clock>,
        health: Arc<LinkHealth>,
        open: impl Fn() -> Result<D, DeviceError> + Send + 'static,
    ) -> Result<Self, DeviceError> {
        let (wanted, requests) = sync_channel(1);
        let (made, fresh) = sync_channel(1);
        let stop = Arc::new(AtomicBool::new(false));
        let thread_stop = Arc::clone(&stop);
        let device = PathBuf::from(name);
        let name = name.to_string();
        start_thread(&device, "thermode-link-reconnect", move || {
            let backoff = Backoff {
                clock,
                stop: thread_stop,
                max_s: backoff_max_s,
            };
            while requests.recv().is_ok() {
                let Some(link) = backoff.retry(&name, &health, &open) else {
                    return;
                };
                if made.send(link).is_err() {
                    return;
                }
            }
        })?;
        Ok(Reconnector {
            wanted,
            fresh,
            stop,
            down: false,
        })
    }

    /// Asks for a new link (at most one request is pending).
    pub(crate) fn request(&mut self) {
        self.down = true;
        let _ = self.wanted.try_send(());
    }

    /// A new link, if the thread made one.
    pub(crate) fn take(&mut self) -> Option<D> {
        self.fresh.try_recv().ok()
    }

    /// What a host's supervision finds here: the link up (the host checks it), a new link being made, or a new link
    /// to adopt.
    pub(crate) fn supervision(&mut self) -> Supervision<D> {
        if !self.down {
            return Supervision::Up;
        }
        match self.take() {
            Some(fresh) => Supervision::Fresh(fresh),
            None => Supervision::Waiting,
        }
    }
}

/// A host whose link a [`Reconnector`] re-opens: the supervision every such host runs at its control loop's calls.
pub(crate) trait Recovering: Sized + Send + 'static {
    /// Its reconnector (None: a link that is not re-opened, e.g. streams given by the caller).
    fn recovery(&mut self) -> Option<&mut Reconnector<Self>>;
    /// Takes over a freshly opened and handshaken link.
    fn adopt(&mut self, fresh: Self);
    /// Why the link, up until now, must go down (it failed, or fell silent), if it must.
    fn down_reason(&mut self) -> Option<DownReason>;
    /// Takes the link down and asks the reconnector for a new one.
    fn take_down(&mut self, reason: DownReason);

    /// Adopts a link the reconnector made, or takes a failed or silent link down. Never blocks.
    fn supervise(&mut self) {
        match self.recovery().map(Reconnector::supervision) {
            None | Some(Supervision::Waiting) => {}
            Some(Supervision::Fresh(fresh)) => self.adopt(fresh),
            Some(Supervision::Up) => {
                if let Some(reason) = self.down_reason() {
                    self.take_down(reason);
                }
            }
        }
    }
}

/// What a host's supervision finds at its reconnector ([`Reconnector::supervision`]).
pub(crate) enum Supervision<D> {
    /// The link is up: the host checks whether it failed or fell silent.
    Up,
    /// The link is down and no new one is ready yet.
    Waiting,
    /// A new link, opened and handshaken, to adopt.
    Fresh(D),
}

impl<D> Drop for Reconnector<D> {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

/// The reconnector's waits.
struct Backoff {
    clock: Arc<dyn Clock>,
    stop: Arc<AtomicBool>,
    max_s: f64,
}

impl Backoff {
    /// Calls `open` until it succeeds, waiting before each attempt; None once stopped.
    fn retry<D>(&self, name: &str, health: &LinkHealth, open: &impl Fn() -> Result<D, DeviceError>) -> Option<D> {
        // The first wait also lets the old port's reader close its end and a restarting device get going.
        let mut wait_s = FIRST_BACKOFF_S;
        loop {
            let until_s = self.clock.now_s() + wait_s;
            while self.clock.now_s() < until_s {
                if self.stop.load(Ordering::SeqCst) {
                    return None;
                }
                std::thread::sleep(Duration::from_millis(10));
            }
            health.attempt();
            match open() {
                Ok(link) => return Some(link),
                Err(e) => health.set_error(format!("reconnecting to {name}: {e}")),
            }
            wait_s = (wait_s * 2.0).min(self.max_s);
        }
    }
}
