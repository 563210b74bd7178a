//! [`SerialDevice`]: a real display (or the emulator) behind a serial port, speaking the device protocol
//! ([`crate::own::codec`], `docs/protocol.md`), as a [`Device`].
//!
//! - **Open** (`serial:PATH`): the port in raw mode at [`SerialConfig::baud_rate`], then the handshake: `Hello`
//!   until the device answers `Identify`, then `ClearFault` until a report shows the drives released, all within
//!   [`SerialConfig::handshake_timeout_s`]. A device whose announced watchdog is longer than
//!   [`MAX_DEVICE_WATCHDOG_MS`] (or 0) is refused before its drives are released
//!   ([`DeviceError::WatchdogTooLong`]).
//! - **Reading**: a small background thread reads the port (short read timeouts), decodes frames and keeps the
//!   newest state of every channel behind a mutex held for microseconds; [`Device::read`] only copies it, so the
//!   control loop never waits for the port. A reading's `sample_seq` advances only when the device reports a new
//!   sample (so the envelope's stale-sensor check works through the link), and its `time_s` is the host
//!   [`Clock`] time the sample was taken (arrival time minus the sample's age; never decreasing).
//! - **Errors** ([`DeviceError::Link`]): no report for longer than [`SerialConfig::link_timeout_s`] (the device
//!   stopped answering), a port that fails or vanishes, or drives latched off by the device (after its watchdog
//!   expired or a restart). A channel whose heating or cooling the device's own over- or under-temperature cut
//!   latched off (report bits `OVER_TEMPERATURE`, `UNDER_TEMPERATURE`) reads [`DeviceError::Cut`]. Either way the
//!   caller's envelope sees no fresh samples and faults the channel.
//! - **Driving**: [`Device::apply`] takes only envelope-gated [`DriveCommand`]s, in mA. One `Drive` frame for all
//!   channels goes out when every channel has been applied (a control round), at most once per
//!   [`SerialConfig::drive_interval_s`] — except that switching a channel off is sent at once. When nothing was
//!   sent for a quarter of the device's watchdog period, a `Heartbeat` goes out from `read` or `apply`, so the
//!   watchdog stays fed exactly as long as the control loop calls the device. Drives latched off by the device are
//!   released (`ClearFault`) only once the host commands 0 A on every channel; a channel's over- or
//!   under-temperature cut only once the host commands 0 A on every cut channel (and the device releases it only
//!   once its plate is back inside).
//! - **Recovery** (a port opened by path): when a write fails (times out: the device stopped reading), the port
//!   fails or vanishes (the device was unplugged, the emulator ended), or no report arrives for
//!   [`SerialConfig::reconnect_after_silence_s`], the link is *down*: the port is closed and a thread of its own
//!   re-opens the same path and repeats the handshake, with back-off (0.5 s doubling to
//!   [`SerialConfig::reconnect_backoff_max_s`]), stale bytes in either direction discarded. The control loop is
//!   never blocked: the new link is adopted at its next read. Meanwhile every read fails (so the envelope faults
//!   every channel and holds it at 0 A), and after the new handshake the channels stay faulted until the operator
//!   clears them. [`LinkHealth`] (via [`Device::link_health`]) says whether the link is up and how often it came
//!   back.
//! - **Stopping**: [`Device::all_off`] sends `AllOff` (every drive 0 A at once); so does dropping the device.

use std::io::{self, Read, Write};
use std::sync::Arc;
use std::time::Duration;

use thermode_model::{BadValue, Rule};
use thermode_platform::Clock;
use thermode_safety::DriveCommand;

use super::codec::{
    encode_frame, to_milliamps, ChannelFaults, ChannelReport, DeviceMessage, DriveFrame, Frame, HostMessage, Identify,
    LinkCounters, NackCode, SensorReport, StreamDecoder, DEFAULT_BAUD_RATE, DELIMITER, MAX_ENCODED_LEN,
};
pub use crate::host::FIRST_BACKOFF_S;
use crate::host::{self, Line, LineState, OnLine, ReaderSpec, Reconnector, Recovering};
use thermode_device::{
    Awaited, Device, DeviceCut, DeviceError, DownReason, LinkError, LinkFault, LinkHealth, Reading, Silence,
    MAX_CHANNELS,
};

/// The prefix of a serial device specification: `serial:PATH`.
pub const SERIAL_PREFIX: &str = "serial:";

/// The port path of a `serial:PATH` specification (None if `spec` is not one or the path is empty).
pub fn serial_path(spec: &str) -> Option<&str> {
    spec.strip_prefix(SERIAL_PREFIX).filter(|path| !path.is_empty())
}

/// The longest watchdog period a device may announce \[ms\]: 250, compiled in. A device whose drives stay on for
/// longer after the host's last frame is refused at the handshake: a host that dies mid-heating leaves the current on
/// until the watchdog cuts it, and at full current the plate rises about 25 K/s (`docs/protocol.md` §6).
pub const MAX_DEVICE_WATCHDOG_MS: u16 = 250;

/// Settings of the host side of a serial link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SerialConfig {
    /// Baud rate \[bit/s\]. Default [`DEFAULT_BAUD_RATE`] (115200).
    pub baud_rate: u32,
    /// Longest time for the handshake (`Hello` → `Identify`, `ClearFault` → released) \[s\], on the host clock, in
    /// (0, 60]. Default 3 (boards that reset when the port opens take 1–2 s to boot; `Hello` is repeated every
    /// 0.2 s meanwhile).
    pub handshake_timeout_s: f64,
    /// Longest time without a sensor report before [`Device::read`] fails \[s\], in (0, 10]. Default 0.1 (ten
    /// report intervals at 100 Hz; the envelope's stale-sensor timeout is 0.2 s).
    pub link_timeout_s: f64,
    /// Shortest interval between two `Drive` frames \[s\], in \[0, 1\] (switching off is never delayed). Default
    /// 0.005 (at most 200 frames/s: 32 bytes each for ten channels, 6.4 kB/s of the 11.5 kB/s of 115200 baud).
    pub drive_interval_s: f64,
    /// Longest time a write may wait for the port \[s\], in (0, 1]; a write that cannot finish fails the link.
    /// Default 0.05.
    pub write_timeout_s: f64,
    /// Read timeout of the background reader \[s\], in (0, 0.1]; also how long dropping the device may wait for it.
    /// Default 0.005.
    pub read_poll_s: f64,
    /// No report for this long takes the link down and starts a reconnection (a port opened by path) \[s\], in
    /// (0, 60]. Default 1.
    pub reconnect_after_silence_s: f64,
    /// Longest wait between two reconnection attempts \[s\] (the wait starts at 0.5 s and doubles), in
    /// \[0.5, 60\]. Default 5.
    pub reconnect_backoff_max_s: f64,
}

impl Default for SerialConfig {
    fn default() -> Self {
        SerialConfig {
            baud_rate: DEFAULT_BAUD_RATE,
            handshake_timeout_s: 3.0,
            link_timeout_s: 0.1,
            drive_interval_s: 0.005,
            write_timeout_s: 0.05,
            read_poll_s: 0.005,
            reconnect_after_silence_s: 1.0,
            reconnect_backoff_max_s: 5.0,
        }
    }
}

impl SerialConfig {
    /// `Ok` if every setting is in its range.
    pub fn validate(&self) -> Result<(), DeviceError> {
        // (name, value, lower rule, largest allowed value)
        let checks = [
            (
                "serial handshake_timeout_s [s]",
                self.handshake_timeout_s,
                Rule::Positive,
                60.0,
            ),
            ("serial link_timeout_s [s]", self.link_timeout_s, Rule::Positive, 10.0),
            (
                "serial drive_interval_s [s]",
                self.drive_interval_s,
                Rule::NonNegative,
                1.0,
            ),
            ("serial write_timeout_s [s]", self.write_timeout_s, Rule::Positive, 1.0),
            ("serial read_poll_s [s]", self.read_poll_s, Rule::Positive, 0.1),
            (
                "serial reconnect_after_silence_s [s]",
                self.reconnect_after_silence_s,
                Rule::Positive,
                60.0,
            ),
            (
                "serial reconnect_backoff_max_s [s]",
                self.reconnect_backoff_max_s,
                Rule::Positive,
                60.0,
            ),
        ];
        for (name, value, lower, max) in checks {
            lower.check(name, value)?;
            Rule::Within { min: 0.0, max }.check(name, value)?;
        }
        Rule::Positive.check("serial baud_rate [bit/s]", f64::from(self.baud_rate))?;
        Rule::Within {
            min: FIRST_BACKOFF_S,
            max: 60.0,
        }
        .check("serial reconnect_backoff_max_s [s]", self.reconnect_backoff_max_s)?;
        Ok(())
    }
}

/// The newest sensor report and when it arrived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReportSnapshot {
    /// The device's sequence number of the report frame.
    pub seq: u16,
    /// The report.
    pub report: SensorReport,
    /// Host clock time of its arrival \[s\].
    pub received_s: f64,
}

/// What the host side has seen and done on the link.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SerialStats {
    /// Received bytes and frames, dropped frames by reason, device sequence gaps (lost frames).
    pub rx: LinkCounters,
    /// Sensor reports taken.
    pub reports: u64,
    /// Reports refused because their channel count differs from the device's.
    pub report_mismatches: u64,
    /// Acks received.
    pub acks: u64,
    /// Nacks received.
    pub nacks: u64,
    /// The latest Nack: (refused host seq, code).
    pub last_nack: Option<(u16, NackCode)>,
    /// Frames sent.
    pub frames_sent: u64,
    /// `Drive` frames sent.
    pub drive_frames: u64,
    /// `Heartbeat` frames sent.
    pub heartbeats: u64,
    /// `ClearFault` frames sent.
    pub clear_faults: u64,
}

/// The host's view of one channel, built from the reports.
#[derive(Debug, Clone, Copy, Default)]
struct Track {
    /// The last report's 16-bit sample sequence number, once a report has been seen.
    seq16: Option<u16>,
    sample_seq: u64,
    time_s: f64,
    sensor_c: f64,
    hot_side_c: f64,
    current_a: f64,
    faults: ChannelFaults,
}

impl Track {
    fn update(&mut self, report: &ChannelReport, received_s: f64) {
        let sample_time_s = received_s - f64::from(report.sample_age_ms) * 1e-3;
        match self.seq16 {
            None => {
                self.sample_seq = u64::from(report.sample_seq);
                self.time_s = sample_time_s;
                self.sensor_c = report.sensor_c();
            }
            Some(last) if last != report.sample_seq => {
                self.sample_seq += u64::from(report.sample_seq.wrapping_sub(last));
                self.time_s = self.time_s.max(sample_time_s);
                self.sensor_c = report.sensor_c();
            }
            Some(_) => {}
        }
        self.seq16 = Some(report.sample_seq);
        self.hot_side_c = report.hot_side_c();
        self.current_a = report.applied_a();
        self.faults = report.faults;
    }
}

/// State shared between the reader thread and the device.
#[derive(Debug)]
pub(crate) struct Shared {
    decoder: StreamDecoder<DeviceMessage>,
    identify: Option<Identify>,
    tracks: [Track; MAX_CHANNELS],
    last_report: Option<ReportSnapshot>,
    stats: SerialStats,
    /// Set when the port failed; permanent.
    error: Option<LinkFault>,
}

impl Default for Shared {
    fn default() -> Self {
        Shared {
            decoder: StreamDecoder::new(),
            identify: None,
            tracks: [Track::default(); MAX_CHANNELS],
            last_report: None,
            stats: SerialStats::default(),
            error: None,
        }
    }
}

impl LineState for Shared {
    /// Decodes everything the port delivered.
    fn take(&mut self, bytes: &[u8], received_s: f64) {
        for &byte in bytes {
            if let Some(Ok(frame)) = self.decoder.push(byte) {
                self.take_frame(frame, received_s);
            }
        }
        self.stats.rx = *self.decoder.counters();
    }

    fn port_fault(&self) -> Option<&LinkFault> {
        self.error.as_ref()
    }

    fn set_port_fault(&mut self, fault: LinkFault) {
        self.error = Some(fault);
    }
}

impl Shared {
    fn take_frame(&mut self, frame: Frame<DeviceMessage>, received_s: f64) {
        match frame.message {
            DeviceMessage::Identify(identify) => self.identify = Some(identify),
            DeviceMessage::SensorReport(report) => self.take_report(frame.seq, report, received_s),
            DeviceMessage::Ack { .. } => self.stats.acks += 1,
            DeviceMessage::Nack { seq, code } => {
                self.stats.nacks += 1;
                self.stats.last_nack = Some((seq, code));
            }
        }
    }

    fn take_report(&mut self, seq: u16, report: SensorReport, received_s: f64) {
        let Some(identify) = self.identify else {
            return;
        };
        if report.channels().len() != identify.channel_count as usize {
            self.stats.report_mismatches += 1;
            return;
        }
        for (track, channel) in self.tracks.iter_mut().zip(report.channels()) {
            track.update(channel, received_s);
        }
        self.stats.reports += 1;
        self.last_report = Some(ReportSnapshot {
            seq,
            report,
            received_s,
        });
    }
}

/// The reader thread of a serial link.
const READER: ReaderSpec = ReaderSpec {
    thread: "thermode-serial-reader",
    buffer_len: 1024,
};

/// A display behind a serial port. See the module documentation.
pub struct SerialDevice {
    line: Line<Shared>,
    config: SerialConfig,
    identify: Identify,
    tx_seq: u16,
    out: Vec<u8>,
    pending_ma: [i16; MAX_CHANNELS],
    sent_ma: [i16; MAX_CHANNELS],
    /// Channels applied since the last drive frame (bit per channel).
    round: u16,
    dirty: bool,
    last_drive_s: f64,
    last_sent_s: f64,
    last_clear_s: f64,
    tx: SerialStats,
    /// Re-opening the port after a failure (only for a port opened by path).
    recovery: Option<Reconnector<SerialDevice>>,
    /// Added to a link's sample numbers, so they keep rising across reconnections (a restarted device counts from
    /// 0 again, and the envelope takes only rising numbers as fresh).
    seq_base: [u64; MAX_CHANNELS],
    /// The last sample number handed out per channel.
    seq_seen: [u64; MAX_CHANNELS],
    health: Arc<LinkHealth>,
}

/// A writer for a link that is down: every write fails.
struct Closed;

impl Write for Closed {
    fn write(&mut self, _: &[u8]) -> io::Result<usize> {
        Err(io::Error::new(io::ErrorKind::NotConnected, "the serial link is down"))
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl std::fmt::Debug for SerialDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialDevice")
            .field("name", &self.line.name)
            .field("identify", &self.identify)
            .field("config", &self.config)
            .field("failed", &self.line.failed)
            .finish_non_exhaustive()
    }
}

impl SerialDevice {
    /// Opens the serial port at `path` (raw, 8N1, `config.baud_rate`) and performs the handshake. Reading times
    /// are on `clock`: give it the clock of the control loop. A failed link is re-opened on the same path (see the
    /// module documentation).
    pub fn open(path: &str, config: &SerialConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        let mut device = SerialDevice::open_once(path, config, clock.clone())?;
        let (owned_path, config) = (path.to_string(), *config);
        let reopen_clock = Arc::clone(&clock);
        device.recovery = Some(Reconnector::spawn(
            path,
            config.reconnect_backoff_max_s,
            clock,
            device.health.clone(),
            move || SerialDevice::open_once(&owned_path, &config, reopen_clock.clone()),
        )?);
        Ok(device)
    }

    /// Opens the port and performs the handshake, without recovery.
    fn open_once(path: &str, config: &SerialConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        config.validate()?;
        let read_timeout = Duration::from_secs_f64(config.read_poll_s);
        // Stale bytes in either direction (an earlier session's frames) are discarded.
        let port = host::open_serial(path, config.baud_rate, read_timeout, serialport::ClearBuffer::All)?;
        let streams = host::split(port, path, Duration::from_secs_f64(config.write_timeout_s))?;
        SerialDevice::start(Line::start(path, streams, clock, &READER, true)?, config)
    }

    /// As [`SerialDevice::open`] for a `serial:PATH` specification.
    pub fn open_spec(spec: &str, config: &SerialConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        let path = serial_path(spec).ok_or_else(|| LinkError::device(spec, LinkFault::NotSerial))?;
        SerialDevice::open(path, config, clock)
    }

    /// A device over any byte streams (e.g. a socket or an in-memory pipe), named `name` in messages. `reader`
    /// should return within about [`SerialConfig::read_poll_s`] (a read timeout, or `WouldBlock`); the reader thread
    /// is not waited for when the device is dropped.
    pub fn from_streams(
        name: &str,
        reader: Box<dyn Read + Send>,
        writer: Box<dyn Write + Send>,
        config: &SerialConfig,
        clock: Arc<dyn Clock>,
    ) -> Result<Self, DeviceError> {
        config.validate()?;
        SerialDevice::start(Line::start(name, (reader, writer), clock, &READER, false)?, config)
    }

    /// The device on `line`, after the handshake.
    fn start(line: Line<Shared>, config: &SerialConfig) -> Result<Self, DeviceError> {
        let mut device = SerialDevice {
            line,
            config: *config,
            identify: Identify {
                channel_count: 0,
                firmware: Default::default(),
                current_limit_ma: 0,
                watchdog_ms: 0,
                report_interval_ms: 0,
            },
            tx_seq: 0,
            out: Vec::with_capacity(MAX_ENCODED_LEN + 1),
            pending_ma: [0; MAX_CHANNELS],
            sent_ma: [0; MAX_CHANNELS],
            round: 0,
            dirty: false,
            last_drive_s: f64::NEG_INFINITY,
            last_sent_s: f64::NEG_INFINITY,
            last_clear_s: f64::NEG_INFINITY,
            tx: SerialStats::default(),
            recovery: None,
            seq_base: [0; MAX_CHANNELS],
            seq_seen: [0; MAX_CHANNELS],
            health: Arc::new(LinkHealth::new()),
        };
        device.handshake()?;
        Ok(device)
    }

    /// `Hello` until `Identify`, then `ClearFault` until a report shows the drives released, on the clock.
    fn handshake(&mut self) -> Result<(), DeviceError> {
        let timeout_s = self.config.handshake_timeout_s;
        let deadline_s = self.line.deadline_s(timeout_s);
        self.line.write(&[DELIMITER])?;
        let identify = self.retry_until(deadline_s, HostMessage::Hello, |s| s.identify)?;
        let Some(identify) = identify else {
            let nack = self.line.lock()?.stats.last_nack;
            let other_version = matches!(nack, Some((_, NackCode::UnsupportedVersion)));
            return Err(self.line.error(LinkFault::Handshake {
                awaited: Awaited::Identify,
                timeout_s,
                other_version,
            }));
        };
        if identify.watchdog_ms == 0 || identify.watchdog_ms > MAX_DEVICE_WATCHDOG_MS {
            return Err(DeviceError::WatchdogTooLong {
                device: self.line.name.clone(),
                device_ms: identify.watchdog_ms,
                max_ms: MAX_DEVICE_WATCHDOG_MS,
            });
        }
        self.identify = identify;
        let released = self.retry_until(deadline_s, HostMessage::ClearFault, |s| {
            s.last_report.filter(|r| !r.report.flags.latched()).map(|_| ())
        })?;
        if released.is_none() {
            return Err(self.line.error(LinkFault::Handshake {
                awaited: Awaited::Released,
                timeout_s,
                other_version: false,
            }));
        }
        Ok(())
    }

    /// Sends `message` every 0.2 s until `done` finds what it waits for in the shared state, or `deadline_s` on the
    /// clock.
    fn retry_until<T>(
        &mut self,
        deadline_s: f64,
        message: HostMessage,
        done: impl Fn(&Shared) -> Option<T>,
    ) -> Result<Option<T>, DeviceError> {
        let send = |device: &mut SerialDevice| {
            if message == HostMessage::ClearFault {
                device.tx.clear_faults += 1;
            }
            device.send(&message)
        };
        host::retry_until(self, deadline_s, 0.2, send, done)
    }

    /// What the device said about itself.
    pub fn identify(&self) -> Identify {
        self.identify
    }

    /// The settings.
    pub fn config(&self) -> &SerialConfig {
        &self.config
    }

    /// The clock reading times are on.
    pub fn clock(&self) -> &Arc<dyn Clock> {
        &self.line.clock
    }

    /// What has been seen and done on the link so far.
    pub fn stats(&self) -> SerialStats {
        let mut stats = self.lock().map(|s| s.stats).unwrap_or_default();
        stats.frames_sent = self.tx.frames_sent;
        stats.drive_frames = self.tx.drive_frames;
        stats.heartbeats = self.tx.heartbeats;
        stats.clear_faults = self.tx.clear_faults;
        stats
    }

    /// The newest sensor report, if any.
    pub fn last_report(&self) -> Option<ReportSnapshot> {
        self.lock().ok().and_then(|s| s.last_report)
    }

    /// The fault bits of `channel` in the newest report.
    pub fn channel_faults(&self, channel: usize) -> Result<ChannelFaults, DeviceError> {
        self.check_channel(channel)?;
        Ok(self.lock()?.tracks[channel].faults)
    }

    /// Sends a `Heartbeat` now.
    pub fn heartbeat(&mut self) -> Result<(), DeviceError> {
        self.tx.heartbeats += 1;
        self.send(&HostMessage::Heartbeat)
    }

    /// Switches every drive off now (`AllOff`); the held commands become 0 A.
    pub fn all_off(&mut self) -> Result<(), DeviceError> {
        self.pending_ma = [0; MAX_CHANNELS];
        self.sent_ma = [0; MAX_CHANNELS];
        self.dirty = false;
        self.send(&HostMessage::AllOff)
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, Shared>, DeviceError> {
        self.line.lock()
    }

    fn check_channel(&self, channel: usize) -> Result<(), DeviceError> {
        let count = self.channel_count();
        if channel < count {
            Ok(())
        } else {
            Err(DeviceError::NoSuchChannel { channel, count })
        }
    }

    fn check_failed(&self) -> Result<(), DeviceError> {
        self.line.check_failed()
    }

    /// Encodes and writes one frame.
    fn send(&mut self, message: &HostMessage) -> Result<(), DeviceError> {
        self.check_failed()?;
        self.out.clear();
        encode_frame(self.tx_seq, message, &mut self.out).map_err(|_| self.line.error(LinkFault::Encode))?;
        self.tx_seq = self.tx_seq.wrapping_add(1);
        let out = std::mem::take(&mut self.out);
        let result = self.line.write(&out);
        self.out = out;
        result?;
        self.tx.frames_sent += 1;
        self.last_sent_s = self.line.clock.now_s();
        Ok(())
    }

    /// Sends the held currents of every channel as one `Drive` frame, releasing a device latch first when every
    /// channel is at 0 A. Unless `force`, waits for the drive interval (the currents stay pending).
    fn flush_drive(&mut self, force: bool) -> Result<(), DeviceError> {
        self.round = 0;
        let now = self.line.clock.now_s();
        if !force && now - self.last_drive_s < self.config.drive_interval_s {
            self.dirty = true;
            return Ok(());
        }
        self.release_latch_if_off(now)?;
        let count = self.channel_count();
        let drive = DriveFrame::new(0, &self.pending_ma[..count]).map_err(|_| self.line.error(LinkFault::Encode))?;
        self.send(&HostMessage::Drive(drive))?;
        self.tx.drive_frames += 1;
        self.sent_ma = self.pending_ma;
        self.dirty = false;
        self.last_drive_s = now;
        Ok(())
    }

    /// Sends `ClearFault` (at most every 0.1 s) when the device reports its drives latched and the host holds 0 A on
    /// every channel, or when it reports a channel cut (and no device-wide latch) and the host holds 0 A on every cut
    /// channel.
    fn release_latch_if_off(&mut self, now: f64) -> Result<(), DeviceError> {
        let count = self.channel_count();
        let (latched, any_cut, cuts_idle) = {
            let state = self.lock()?;
            let latched = state.last_report.is_some_and(|r| r.report.flags.latched());
            let cut = |ch: usize| cut_of(state.tracks[ch].faults).is_some();
            let any_cut = (0..count).any(cut);
            let cuts_idle = (0..count).all(|ch| !cut(ch) || self.pending_ma[ch] == 0);
            (latched, any_cut, cuts_idle)
        };
        let all_off = self.pending_ma.iter().all(|&ma| ma == 0);
        let wanted = if latched { all_off } else { any_cut && cuts_idle };
        if wanted && now - self.last_clear_s >= 0.1 {
            self.tx.clear_faults += 1;
            self.last_clear_s = now;
            self.send(&HostMessage::ClearFault)?;
        }
        Ok(())
    }

    /// Keeps the watchdog fed: a pending drive or a heartbeat when nothing went out for a quarter period.
    fn keep_alive(&mut self) -> Result<(), DeviceError> {
        let now = self.line.clock.now_s();
        let quarter_s = f64::from(self.identify.watchdog_ms) * 1e-3 / 4.0;
        if self.dirty && now - self.last_drive_s >= self.config.drive_interval_s {
            return self.flush_drive(true);
        }
        if now - self.last_sent_s >= quarter_s {
            self.release_latch_if_off(now)?;
            return self.heartbeat();
        }
        Ok(())
    }

    /// The reading of `channel` from the shared state, or why there is none.
    fn reading(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        let now = self.line.clock.now_s();
        let state = self.lock()?;
        self.line.check_port(&state)?;
        let Some(last) = state.last_report else {
            return Err(self.line.error(LinkFault::NothingYet {
                silence: Silence::SensorReport,
            }));
        };
        let silent_s = now - last.received_s;
        if silent_s > self.config.link_timeout_s {
            return Err(self.line.error(LinkFault::Silent {
                silence: Silence::SensorReport,
                silent_s,
                timeout_s: self.config.link_timeout_s,
            }));
        }
        if last.report.flags.latched() {
            return Err(self.line.error(LinkFault::Latched {
                watchdog: last.report.flags.watchdog_expired(),
            }));
        }
        let track = state.tracks[channel];
        drop(state);
        let sample_seq = self.seq_base[channel] + track.sample_seq;
        self.seq_seen[channel] = sample_seq;
        let reading = Reading {
            sensor_c: track.sensor_c,
            hot_side_c: track.hot_side_c,
            time_s: track.time_s,
            sample_seq,
            current_a: track.current_a,
            voltage_v: f64::NAN,
            heating_limit_a: f64::INFINITY,
        };
        match cut_of(track.faults) {
            // The firmware goes on reporting its plate while cut.
            Some(cut) => Err(DeviceError::Cut {
                channel,
                cut,
                reading: Some(reading),
            }),
            None => Ok(reading),
        }
    }
}

impl Recovering for SerialDevice {
    fn recovery(&mut self) -> Option<&mut Reconnector<Self>> {
        self.recovery.as_mut()
    }

    /// Why the link must go down: it failed, or fell silent for longer than the configured limit.
    fn down_reason(&mut self) -> Option<DownReason> {
        let now = self.line.clock.now_s();
        self.line
            .failed
            .clone()
            .map(|f| DownReason::Failed(Box::new(f)))
            .or_else(|| {
                let state = self.line.shared.lock().ok()?;
                if let Some(error) = &state.error {
                    return Some(DownReason::Failed(Box::new(error.clone())));
                }
                let silent_s = now - state.last_report.map_or(f64::NEG_INFINITY, |r| r.received_s);
                (silent_s > self.config.reconnect_after_silence_s).then_some(DownReason::Silent {
                    silent_s,
                    limit_s: self.config.reconnect_after_silence_s,
                })
            })
    }

    /// Closes the port (so the same path can be opened again) and asks the reconnector for a new link.
    fn take_down(&mut self, reason: DownReason) {
        let fault = LinkFault::Down { reason };
        self.health.down(self.line.link_error(fault.clone()).to_string());
        self.line.failed = Some(fault);
        self.line.writer = Box::new(Closed);
        // The reader thread ends within its read timeout and closes its end of the port; not waited for here.
        self.line.reader.detach();
        if let Some(recovery) = &mut self.recovery {
            recovery.request();
        }
    }

    /// Takes over a freshly opened and handshaken link. Every held current starts at 0 A; the engines keep their
    /// faults until the operator clears them.
    fn adopt(&mut self, mut fresh: SerialDevice) {
        if fresh.identify.channel_count != self.identify.channel_count {
            let fault = LinkFault::ChannelsChanged {
                now: usize::from(fresh.identify.channel_count),
                before: usize::from(self.identify.channel_count),
            };
            self.health.set_error(self.line.link_error(fault).to_string());
            fresh.line.failed = Some(LinkFault::Replaced);
            if let Some(recovery) = &mut self.recovery {
                recovery.request();
            }
            return;
        }
        std::mem::swap(&mut self.line.writer, &mut fresh.line.writer);
        std::mem::swap(&mut self.line.shared, &mut fresh.line.shared);
        std::mem::swap(&mut self.line.reader, &mut fresh.line.reader);
        self.line.reader.set_join(true);
        self.identify = fresh.identify;
        self.tx_seq = fresh.tx_seq;
        self.pending_ma = [0; MAX_CHANNELS];
        self.sent_ma = [0; MAX_CHANNELS];
        self.round = 0;
        self.dirty = false;
        self.last_drive_s = f64::NEG_INFINITY;
        self.last_sent_s = fresh.last_sent_s;
        self.last_clear_s = fresh.last_clear_s;
        for (base, seen) in self.seq_base.iter_mut().zip(self.seq_seen) {
            *base = seen + 1;
        }
        self.line.failed = None;
        // `fresh` now holds the old link's remains: dropped without a frame and without waiting for its reader.
        fresh.line.failed = Some(LinkFault::Replaced);
        fresh.line.reader.set_join(false);
        drop(fresh);
        if let Some(recovery) = &mut self.recovery {
            recovery.down = false;
        }
        self.health.reconnected();
    }
}

impl Device for SerialDevice {
    fn channel_count(&self) -> usize {
        self.identify.channel_count as usize
    }

    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        self.check_channel(channel)?;
        let current_a = command.current_a();
        let ma = to_milliamps(current_a)
            .ok_or_else(|| BadValue::custom("drive current [A]", current_a, "must be finite and within ±32.767 A"))?;
        self.check_failed()?;
        let bit = 1u16 << channel;
        if self.round & bit != 0 {
            // The channel comes round again before every channel was applied: a new control round began.
            self.flush_drive(false)?;
        }
        self.pending_ma[channel] = ma;
        self.round |= bit;
        let switching_off = ma == 0 && self.sent_ma[channel] != 0;
        let round_complete = self.round.count_ones() as usize == self.channel_count();
        if switching_off || round_complete {
            self.flush_drive(switching_off)?;
        }
        self.keep_alive()
    }

    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        self.check_channel(channel)?;
        if channel == 0 {
            self.supervise();
        }
        self.keep_alive()?;
        self.reading(channel)
    }

    fn link_health(&self) -> Option<Arc<LinkHealth>> {
        Some(self.health.clone())
    }

    /// A real device runs in real time: nothing to do.
    fn poll(&mut self, _now_s: f64) {}

    /// `AllOff`: every drive 0 A in one frame.
    fn all_off(&mut self) -> Result<(), DeviceError> {
        SerialDevice::all_off(self)
    }
}

/// The device's own cut of a channel, from its report's fault bits.
fn cut_of(faults: ChannelFaults) -> Option<DeviceCut> {
    DeviceCut::from_latches(
        faults.has(ChannelFaults::OVER_TEMPERATURE),
        faults.has(ChannelFaults::UNDER_TEMPERATURE),
    )
}

impl OnLine for SerialDevice {
    type State = Shared;

    fn line(&self) -> &Line<Shared> {
        &self.line
    }
}

impl Drop for SerialDevice {
    /// `AllOff` unless the link failed; the reader and the reconnector end with their fields.
    fn drop(&mut self) {
        if self.line.failed.is_none() {
            let _ = self.send(&HostMessage::AllOff);
        }
    }
}
