//! The device side of the protocol, emulated: a [`SimulatedDisplay`] behind the firmware a real display's
//! microcontroller would run — it answers `Hello`, applies drive commands, sends sensor reports at a fixed rate,
//! enforces the watchdog — so the whole serial path is tested end to end without hardware.
//!
//! [`Emulator`] is the core, free of I/O: bytes in with the time they arrived ([`Emulator::receive`]), time moves
//! on ([`Emulator::advance_to`]), bytes out. [`Emulator::run`] drives it in real time over any `Read + Write` port
//! with an injected [`Clock`]; [`PtyEmulator`] runs it on a pseudo-terminal in a thread (what `thermode emulate`
//! does). Both are the emulator runner every protocol shares ([`crate::runner`]), with the link faults as the
//! device's command. For tests it injects link faults ([`LinkFaults`]: corrupted bytes, dropped frames, a device
//! that stops answering) and, through [`EmulatorControl`], closes the port.
//!
//! Time runs in fixed ticks (default 1 ms): each tick the watchdog is checked and the plant advanced; every
//! report interval (default 10 ms) a report is sent. The firmware's state machine:
//! - it starts **latched** (drives off); `ClearFault` releases the latch;
//! - while latched every `Drive` is refused (`Nack` code `Latched`);
//! - running, when the last valid host frame is older than the watchdog period at a tick, every drive is switched
//!   off and latched (the report flags say `LATCHED | WATCHDOG_EXPIRED`). A valid host frame is one whose CRC,
//!   version, type and body are good. The trip happens at the first tick more than one period after the last
//!   valid frame, so the drives are off at most one period plus one tick after the host went silent.
//!
//! - before every plant step, each channel's [`PlateGuard`] (the firmware's own over- and under-temperature cut,
//!   [`crate::own::guard`]) may remove heating or cooling from the step and latch that cut (report bits
//!   `OVER_TEMPERATURE`, `UNDER_TEMPERATURE`); `ClearFault` releases a cut once the plate is back inside.
//!
//! Bytes are stamped with the time they were handed over, after the ticks up to that time have run: a command that
//! arrived while the emulator was not scheduled counts as late, never as early (the watchdog errs on the safe side).
//! When the emulator falls behind by more than `max_catch_up_s`, it merges plant steps (the plant is implicit and
//! stable for any step) and skips the reports older than that, instead of falling further behind.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::sync::{Arc, Mutex};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use thermode_platform::Clock;

use super::codec::{
    encode_frame, to_centi_c, to_milli_c, ChannelFaults, ChannelReport, DecodeError, DeviceMessage, DriveFrame,
    FirmwareVersion, Frame, HostMessage, Identify, LinkCounters, NackCode, ReportFlags, SensorReport, StreamDecoder,
    DEFAULT_REPORT_INTERVAL_MS, DEFAULT_WATCHDOG_MS, SENSOR_OPEN_THRESHOLD_C, SENSOR_SHORT_THRESHOLD_C,
};
use super::guard::{Cuts, GuardTrip, PlateGuard};
#[cfg(unix)]
use crate::runner::PtyRunner;
use crate::runner::{Control, Emulated, EmulatorError, RunEnd, SensorError, Trace};
use thermode_device::DeviceError;
use thermode_device::PlateFinger;
use thermode_device::{Device, SimulatedDisplay, MAX_CHANNELS};

/// The firmware version the emulator announces: 0.1.0.
pub const EMULATOR_FIRMWARE: FirmwareVersion = FirmwareVersion {
    major: 0,
    minor: 1,
    patch: 0,
};

/// Timing and sensor of the emulated firmware.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmulatorConfig {
    /// Watchdog period \[ms\], 10 to 60000. Default [`DEFAULT_WATCHDOG_MS`] (250).
    pub watchdog_ms: u16,
    /// Interval between sensor reports \[ms\], 1 to 1000, rounded to whole ticks. Default
    /// [`DEFAULT_REPORT_INTERVAL_MS`] (10).
    pub report_interval_ms: u16,
    /// Tick of the firmware loop and the plant \[s\], 1e-4 to 0.01. Default 0.001 (1 kHz).
    pub tick_s: f64,
    /// Longest lag caught up tick by tick \[s\], at least one tick; beyond it plant steps are merged and older
    /// reports skipped. Default 0.1.
    pub max_catch_up_s: f64,
    /// Seed of the link-fault randomness (ChaCha8). Default 0.
    pub fault_seed: u64,
    /// The plate sensor's error: each channel reads `gain · T + offset_c` at T, and the firmware cuts
    /// ([`PlateGuard`]) and reports on that reading. Default none (gain 1, offset 0).
    pub sensor: SensorError,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        EmulatorConfig {
            watchdog_ms: DEFAULT_WATCHDOG_MS,
            report_interval_ms: DEFAULT_REPORT_INTERVAL_MS,
            tick_s: 1e-3,
            max_catch_up_s: 0.1,
            fault_seed: 0,
            sensor: SensorError::default(),
        }
    }
}

impl EmulatorConfig {
    /// `Ok` if every setting is in its range.
    pub fn validate(&self) -> Result<(), EmulatorError> {
        let checks: [(&'static str, f64, f64, f64, &'static str); 3] = [
            (
                "watchdog_ms",
                f64::from(self.watchdog_ms),
                10.0,
                60_000.0,
                "must be from 10 to 60000",
            ),
            (
                "report_interval_ms",
                f64::from(self.report_interval_ms),
                1.0,
                1000.0,
                "must be from 1 to 1000",
            ),
            ("tick_s", self.tick_s, 1e-4, 0.01, "must be from 1e-4 to 0.01"),
        ];
        for (what, value, min, max, requirement) in checks {
            if !(value >= min && value <= max) {
                return Err(EmulatorError::BadSetting {
                    what,
                    value,
                    requirement,
                });
            }
        }
        self.sensor.check()?;
        if !(self.max_catch_up_s.is_finite() && self.max_catch_up_s >= self.tick_s) {
            return Err(EmulatorError::BadSetting {
                what: "max_catch_up_s",
                value: self.max_catch_up_s,
                requirement: "must be finite and at least one tick",
            });
        }
        Ok(())
    }
}

/// Faults injected into what the emulator sends.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkFaults {
    /// Probability that an outgoing byte is corrupted (XOR with a random non-zero byte), in \[0, 1\]. Default 0.
    pub corrupt_byte_rate: f64,
    /// Probability that an outgoing frame is dropped whole (its sequence number is used up, so the host sees the
    /// gap), in \[0, 1\]. Default 0.
    pub drop_frame_rate: f64,
    /// The device stops answering: it sends nothing and uses up no sequence numbers (it still takes commands, runs
    /// the plant and the watchdog). Default false.
    pub mute: bool,
}

impl LinkFaults {
    /// `Ok` if both rates lie in \[0, 1\].
    pub fn validate(&self) -> Result<(), EmulatorError> {
        for (what, value) in [
            ("corrupt_byte_rate", self.corrupt_byte_rate),
            ("drop_frame_rate", self.drop_frame_rate),
        ] {
            if !(0.0..=1.0).contains(&value) {
                return Err(EmulatorError::BadSetting {
                    what,
                    value,
                    requirement: "must be from 0 to 1",
                });
            }
        }
        Ok(())
    }
}

/// When the watchdog switched the drives off.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WatchdogTrip {
    /// Emulator time of the trip \[s\].
    pub time_s: f64,
    /// Emulator time of the last valid host frame before it \[s\].
    pub last_valid_s: f64,
}

/// What the emulator has done so far.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EmulatorStats {
    /// What it received from the host (dropped frames by reason, host sequence gaps).
    pub rx: LinkCounters,
    /// Frames put on the wire.
    pub frames_sent: u64,
    /// Frames dropped by fault injection.
    pub frames_dropped: u64,
    /// Bytes corrupted by fault injection.
    pub bytes_corrupted: u64,
    /// Sensor reports made (sent or dropped).
    pub reports: u64,
    /// Reports skipped while catching up.
    pub reports_skipped: u64,
    /// Nacks made.
    pub nacks: u64,
    /// Watchdog trips.
    pub watchdog_trips: u64,
    /// The latest watchdog trip.
    pub last_trip: Option<WatchdogTrip>,
    /// Ticks whose plant step was merged with others while catching up.
    pub merged_ticks: u64,
    /// Writes to the port that timed out (their bytes are lost).
    pub write_stalls: u64,
    /// Cuts latched by the plate guards (heating or cooling, any channel).
    pub guard_trips: u64,
    /// The latest cut.
    pub last_guard_trip: Option<GuardTripAt>,
}

/// When and where a plate guard cut heating or cooling.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardTripAt {
    /// Emulator time of the cut \[s\] (the start of the step it changed).
    pub time_s: f64,
    /// The channel.
    pub channel: usize,
    /// The bound, reading and request behind it.
    pub trip: GuardTrip,
    /// The true plate temperature at the cut \[°C\] (the plant's, which the firmware does not know).
    pub plate_c: f64,
}

/// Why the drives are latched off.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Latch {
    PowerUp,
    Watchdog,
}

/// A bounded log of the frames the emulator made (before fault injection), shared with tests.
#[derive(Debug)]
pub struct SentLog {
    capacity: usize,
    frames: Mutex<VecDeque<Frame<DeviceMessage>>>,
}

impl SentLog {
    /// A log keeping the latest `capacity` frames (0 keeps none).
    pub fn new(capacity: usize) -> Arc<Self> {
        Arc::new(SentLog {
            capacity,
            frames: Mutex::new(VecDeque::with_capacity(capacity)),
        })
    }

    /// The logged frame with sequence number `seq`, if it is still in the log (the newest such frame).
    pub fn find(&self, seq: u16) -> Option<Frame<DeviceMessage>> {
        let frames = self.frames.lock().ok()?;
        frames.iter().rev().find(|f| f.seq == seq).copied()
    }

    /// Number of frames in the log.
    pub fn len(&self) -> usize {
        self.frames.lock().map(|f| f.len()).unwrap_or(0)
    }

    /// Whether the log is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn push(&self, frame: Frame<DeviceMessage>) {
        if self.capacity == 0 {
            return;
        }
        if let Ok(mut frames) = self.frames.lock() {
            if frames.len() == self.capacity {
                frames.pop_front();
            }
            frames.push_back(frame);
        }
    }
}

/// The emulated firmware around a simulated display of fingers `F`.
#[derive(Debug)]
pub struct Emulator<F> {
    display: SimulatedDisplay<F>,
    config: EmulatorConfig,
    identify: Identify,
    faults: LinkFaults,
    rng: ChaCha8Rng,
    decoder: StreamDecoder<HostMessage>,
    commanded_a: [f64; MAX_CHANNELS],
    tick: u64,
    report_every: u64,
    pending_s: f64,
    latch: Option<Latch>,
    last_valid_s: f64,
    last_command_seq: u16,
    tx_seq: u16,
    frame: Vec<u8>,
    stats: EmulatorStats,
    log: Option<Arc<SentLog>>,
    trace: Option<Trace>,
    guards: Vec<PlateGuard>,
}

impl<F: PlateFinger> Emulator<F> {
    /// The firmware around `display`, at time 0, latched (as after power-up).
    pub fn new(display: SimulatedDisplay<F>, config: EmulatorConfig) -> Result<Self, EmulatorError> {
        config.validate()?;
        let limit_a = display.channel(0)?.config().drive.current_limit_a;
        let limit_ma = (limit_a * 1e3).round();
        if !(1.0..=f64::from(i16::MAX)).contains(&limit_ma) {
            return Err(EmulatorError::BadSetting {
                what: "drive current_limit_a",
                value: limit_a,
                requirement: "must be from 0.001 to 32.767 A for the protocol's mA fields",
            });
        }
        let identify = Identify {
            channel_count: display.channel_count() as u8,
            firmware: EMULATOR_FIRMWARE,
            current_limit_ma: limit_ma as u16,
            watchdog_ms: config.watchdog_ms,
            report_interval_ms: config.report_interval_ms,
        };
        let mut guards = Vec::with_capacity(display.channel_count());
        for i in 0..display.channel_count() {
            let channel = display.channel(i)?;
            let sample = config.sensor.sample(channel.state().sensor);
            let guard = PlateGuard::new(channel.config(), sample).map_err(DeviceError::from)?;
            guards.push(guard);
        }
        let report_every = ((f64::from(config.report_interval_ms) * 1e-3 / config.tick_s).round() as u64).max(1);
        Ok(Emulator {
            display,
            config,
            identify,
            faults: LinkFaults::default(),
            rng: ChaCha8Rng::seed_from_u64(config.fault_seed),
            decoder: StreamDecoder::new(),
            commanded_a: [0.0; MAX_CHANNELS],
            tick: 0,
            report_every,
            pending_s: 0.0,
            latch: Some(Latch::PowerUp),
            last_valid_s: 0.0,
            last_command_seq: 0,
            tx_seq: 0,
            frame: Vec::with_capacity(super::codec::MAX_ENCODED_LEN + 1),
            stats: EmulatorStats::default(),
            log: None,
            trace: None,
            guards,
        })
    }

    /// What the emulator answers to `Hello`.
    pub fn identify(&self) -> Identify {
        self.identify
    }

    /// The settings.
    pub fn config(&self) -> &EmulatorConfig {
        &self.config
    }

    crate::runner::display_accessors!();

    /// The current commanded on `channel` \[A\] (0 for a channel that does not exist).
    pub fn commanded_current_a(&self, channel: usize) -> f64 {
        self.commanded_a.get(channel).copied().unwrap_or(0.0)
    }

    /// What the plate guard of `channel` has cut (nothing for a channel that does not exist).
    pub fn cuts(&self, channel: usize) -> Cuts {
        self.guards.get(channel).map(PlateGuard::cuts).unwrap_or_default()
    }

    /// The plate guard of `channel`'s bounds on its true plate \[°C\], (lower, upper).
    pub fn plate_bounds_c(&self, channel: usize) -> Option<(f64, f64)> {
        self.guards.get(channel).map(PlateGuard::plate_bounds_c)
    }

    /// Whether the drives are latched off.
    pub fn latched(&self) -> bool {
        self.latch.is_some()
    }

    /// Emulator time of the last valid host frame \[s\] (0 before any).
    pub fn last_valid_s(&self) -> f64 {
        self.last_valid_s
    }

    /// The statistics so far.
    pub fn stats(&self) -> EmulatorStats {
        let mut stats = self.stats;
        stats.rx = *self.decoder.counters();
        stats
    }

    /// The link faults in force.
    pub fn link_faults(&self) -> LinkFaults {
        self.faults
    }

    /// Sets the link faults (rates in \[0, 1\]).
    pub fn set_link_faults(&mut self, faults: LinkFaults) -> Result<(), EmulatorError> {
        faults.validate()?;
        self.faults = faults;
        Ok(())
    }

    /// Logs every frame made from now on (before fault injection) to `log`.
    pub fn log_sent_to(&mut self, log: Arc<SentLog>) {
        self.log = Some(log);
    }

    crate::runner::trace_accessors!();

    /// Takes bytes from the host that arrived at `now_s` \[s\]: first runs the ticks up to `now_s`, then decodes the
    /// bytes and carries out their commands. Answers are appended to `out`.
    pub fn receive(&mut self, bytes: &[u8], now_s: f64, out: &mut Vec<u8>) {
        self.advance_to(now_s, out);
        let now_s = self.time_s().max(now_s);
        for &byte in bytes {
            match self.decoder.push(byte) {
                Some(Ok(frame)) => self.handle(frame, now_s, out),
                Some(Err(error)) => self.refuse(&error, out),
                None => {}
            }
        }
    }

    /// Runs every tick up to `now_s` \[s\]: watchdog, plant, reports (appended to `out`). Earlier times do nothing.
    pub fn advance_to(&mut self, now_s: f64, out: &mut Vec<u8>) {
        if !now_s.is_finite() {
            return;
        }
        let target = (now_s / self.config.tick_s + 1e-9).floor().max(0.0) as u64;
        let behind_s = target.saturating_sub(self.tick) as f64 * self.config.tick_s;
        let merging = behind_s > self.config.max_catch_up_s;
        while self.tick < target {
            self.tick += 1;
            self.pending_s += self.config.tick_s;
            let t = self.time_s();
            let tripped = self.check_watchdog(t);
            let report_due = self.tick.is_multiple_of(self.report_every);
            if !merging || tripped || report_due {
                self.flush_plant();
            } else {
                self.stats.merged_ticks += 1;
            }
            if report_due {
                if merging && now_s - t > self.config.max_catch_up_s {
                    self.stats.reports_skipped += 1;
                } else {
                    self.send_report(t, out);
                }
            }
        }
        self.flush_plant();
    }

    /// Drives a port in real time until `control` says stop or close, or the port ends ([`crate::runner::run`]).
    /// The port's reads should wait at most about a tick (a read timeout); one that returns at once without data
    /// makes the loop sleep half a tick.
    pub fn run<P: Read + Write>(
        &mut self,
        port: &mut P,
        clock: &dyn Clock,
        control: &EmulatorControl,
    ) -> Result<RunEnd, EmulatorError>
    where
        F: Send,
    {
        crate::runner::run(self, port, clock, control)
    }

    /// A snapshot of the emulator's state.
    pub fn status(&self) -> EmulatorStatus {
        let mut status = EmulatorStatus {
            time_s: self.time_s(),
            latched: self.latched(),
            last_valid_s: self.last_valid_s,
            channel_count: self.display.channel_count(),
            commanded_a: self.commanded_a,
            applied_a: [0.0; MAX_CHANNELS],
            plate_c: [f64::NAN; MAX_CHANNELS],
            cuts: [Cuts::default(); MAX_CHANNELS],
            link_faults: self.faults,
            stats: self.stats(),
        };
        for i in 0..status.channel_count {
            if let Ok(ch) = self.display.channel(i) {
                status.applied_a[i] = ch.state().applied_current_a;
                status.plate_c[i] = ch.state().plate_c;
            }
            status.cuts[i] = self.cuts(i);
        }
        status
    }

    /// At tick time `t_s`: trips the watchdog if the last valid frame is older than the period.
    fn check_watchdog(&mut self, t_s: f64) -> bool {
        let period_s = f64::from(self.config.watchdog_ms) * 1e-3;
        if self.latch.is_some() || t_s - self.last_valid_s <= period_s {
            return false;
        }
        self.flush_plant();
        self.latch = Some(Latch::Watchdog);
        self.commanded_a = [0.0; MAX_CHANNELS];
        self.stats.watchdog_trips += 1;
        self.stats.last_trip = Some(WatchdogTrip {
            time_s: t_s,
            last_valid_s: self.last_valid_s,
        });
        true
    }

    /// Steps the plant over the time not yet simulated with the commanded currents.
    /// Each channel's guard first takes heating or cooling out of the step if the plate could pass its lines (the cut
    /// latches: the command becomes what the guard allows), then learns from the step.
    fn flush_plant(&mut self) {
        if self.pending_s <= 0.0 {
            return;
        }
        let start_s = self.time_s() - self.pending_s;
        for i in 0..self.display.channel_count() {
            let (Ok(channel), Some(guard)) = (self.display.channel_mut(i), self.guards.get_mut(i)) else {
                continue;
            };
            let (allowed_a, trip) = guard.gate(self.commanded_a[i], self.pending_s, channel.hot_side_reading_c());
            if let Some(trip) = trip {
                self.stats.guard_trips += 1;
                self.stats.last_guard_trip = Some(GuardTripAt {
                    time_s: start_s,
                    channel: i,
                    trip,
                    plate_c: channel.state().plate_c,
                });
            }
            self.commanded_a[i] = allowed_a;
            let state = *channel.step(self.pending_s, allowed_a);
            let hot_side_c = channel.hot_side_reading_c();
            guard.account(
                self.pending_s,
                state.time_s,
                state.applied_current_a,
                hot_side_c,
                self.config.sensor.sample(state.sensor),
            );
        }
        self.pending_s = 0.0;
        self.write_trace();
    }

    /// One trace row per channel for the step just taken, written at once.
    fn write_trace(&mut self) {
        let time_s = self.time_s();
        if let Some(trace) = self.trace.as_mut() {
            trace.step(time_s, &self.display);
        }
    }

    fn handle(&mut self, frame: Frame<HostMessage>, now_s: f64, out: &mut Vec<u8>) {
        self.last_valid_s = now_s;
        self.last_command_seq = frame.seq;
        match frame.message {
            HostMessage::Hello => self.send(DeviceMessage::Identify(self.identify), out),
            HostMessage::Heartbeat => {}
            HostMessage::Drive(drive) => self.drive(frame.seq, &drive, out),
            HostMessage::AllOff => {
                self.commanded_a = [0.0; MAX_CHANNELS];
                self.send(DeviceMessage::Ack { seq: frame.seq }, out);
            }
            HostMessage::ClearFault => {
                self.latch = None;
                for guard in &mut self.guards {
                    guard.release();
                }
                self.send(DeviceMessage::Ack { seq: frame.seq }, out);
            }
        }
    }

    fn drive(&mut self, seq: u16, drive: &DriveFrame, out: &mut Vec<u8>) {
        let first = drive.first_channel();
        let currents = drive.currents_ma();
        let code = if self.latch.is_some() {
            Some(NackCode::Latched)
        } else if first + currents.len() > self.display.channel_count() {
            Some(NackCode::BadChannel)
        } else {
            None
        };
        if let Some(code) = code {
            self.nack(seq, code, out);
            return;
        }
        for (slot, &ma) in self.commanded_a[first..].iter_mut().zip(currents) {
            *slot = f64::from(ma) * 1e-3;
        }
    }

    /// Answers a dropped frame that got far enough to name its sequence number.
    fn refuse(&mut self, error: &DecodeError, out: &mut Vec<u8>) {
        let code = match error {
            DecodeError::Version { .. } => NackCode::UnsupportedVersion,
            DecodeError::UnknownType { .. } => NackCode::UnknownType,
            DecodeError::Length { .. } | DecodeError::Value { .. } => NackCode::Malformed,
            DecodeError::Frame(_) | DecodeError::TooShort { .. } => return,
        };
        if let Some(seq) = error.seq() {
            self.nack(seq, code, out);
        }
    }

    fn nack(&mut self, seq: u16, code: NackCode, out: &mut Vec<u8>) {
        self.stats.nacks += 1;
        self.send(DeviceMessage::Nack { seq, code }, out);
    }

    fn send_report(&mut self, t_s: f64, out: &mut Vec<u8>) {
        let mut flags = ReportFlags::default();
        match self.latch {
            Some(Latch::PowerUp) => flags.0 |= ReportFlags::LATCHED,
            Some(Latch::Watchdog) => flags.0 |= ReportFlags::LATCHED | ReportFlags::WATCHDOG_EXPIRED,
            None => {}
        }
        let count = self.display.channel_count();
        let mut channels = [ChannelReport::default(); MAX_CHANNELS];
        for (i, slot) in channels.iter_mut().enumerate().take(count) {
            *slot = self.channel_report(i, t_s);
        }
        let device_time_ms = ((t_s * 1e3).round() as u64 & u64::from(u32::MAX)) as u32;
        let Ok(report) = SensorReport::new(device_time_ms, flags, self.last_command_seq, &channels[..count]) else {
            return;
        };
        self.stats.reports += 1;
        self.send(DeviceMessage::SensorReport(report), out);
    }

    fn channel_report(&self, index: usize, t_s: f64) -> ChannelReport {
        let Ok(channel) = self.display.channel(index) else {
            return ChannelReport::default();
        };
        let state = channel.state();
        let limit_a = channel.config().drive.current_limit_a;
        let commanded_a = self.commanded_a[index];
        let mut faults = 0u8;
        let sensor_c = self.config.sensor.reads_c(state.sensor.value_c);
        if sensor_c >= SENSOR_OPEN_THRESHOLD_C {
            faults |= ChannelFaults::SENSOR_OPEN;
        }
        if sensor_c <= SENSOR_SHORT_THRESHOLD_C {
            faults |= ChannelFaults::SENSOR_SHORT;
        }
        if (state.applied_current_a - commanded_a.clamp(-limit_a, limit_a)).abs() > 1e-9 {
            faults |= ChannelFaults::DRIVE_FAULT;
        }
        if commanded_a.abs() > limit_a {
            faults |= ChannelFaults::CURRENT_LIMITED;
        }
        if self.latch.is_some() {
            faults |= ChannelFaults::LATCHED_OFF;
        }
        let cuts = self.cuts(index);
        if cuts.heating {
            faults |= ChannelFaults::OVER_TEMPERATURE;
        }
        if cuts.cooling {
            faults |= ChannelFaults::UNDER_TEMPERATURE;
        }
        let age_ms = ((t_s - state.sensor.time_s) * 1e3)
            .round()
            .clamp(0.0, f64::from(u16::MAX));
        ChannelReport {
            sensor_milli_c: to_milli_c(sensor_c),
            hot_side_centi_c: to_centi_c(channel.hot_side_reading_c()),
            applied_ma: super::codec::to_milliamps(state.applied_current_a).unwrap_or(0),
            sample_seq: (state.sensor.seq & 0xFFFF) as u16,
            sample_age_ms: age_ms as u16,
            faults: ChannelFaults(faults),
        }
    }

    /// Sends one frame through the link faults.
    fn send(&mut self, message: DeviceMessage, out: &mut Vec<u8>) {
        if self.faults.mute {
            return;
        }
        let frame = Frame {
            seq: self.tx_seq,
            message,
        };
        self.tx_seq = self.tx_seq.wrapping_add(1);
        if let Some(log) = &self.log {
            log.push(frame);
        }
        if self.faults.drop_frame_rate > 0.0 && self.rng.gen::<f64>() < self.faults.drop_frame_rate {
            self.stats.frames_dropped += 1;
            return;
        }
        self.frame.clear();
        if encode_frame(frame.seq, &frame.message, &mut self.frame).is_err() {
            return;
        }
        if self.faults.corrupt_byte_rate > 0.0 {
            for byte in self.frame.iter_mut() {
                if self.rng.gen::<f64>() < self.faults.corrupt_byte_rate {
                    *byte ^= self.rng.gen_range(1..=255u8);
                    self.stats.bytes_corrupted += 1;
                }
            }
        }
        out.extend_from_slice(&self.frame);
        self.stats.frames_sent += 1;
    }
}

pub use crate::runner::TRACE_HEADER;

/// A snapshot of an emulator, published by the runner after every loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmulatorStatus {
    /// Emulator time \[s\].
    pub time_s: f64,
    /// Whether the drives are latched off.
    pub latched: bool,
    /// Emulator time of the last valid host frame \[s\].
    pub last_valid_s: f64,
    /// Number of channels.
    pub channel_count: usize,
    /// Commanded current per channel \[A\] (entries past `channel_count` are 0).
    pub commanded_a: [f64; MAX_CHANNELS],
    /// Current the drive delivered in the last plant step, per channel \[A\].
    pub applied_a: [f64; MAX_CHANNELS],
    /// True plate temperature per channel \[°C\] (NaN past `channel_count`).
    pub plate_c: [f64; MAX_CHANNELS],
    /// What each channel's plate guard has cut.
    pub cuts: [Cuts; MAX_CHANNELS],
    /// The link faults in force.
    pub link_faults: LinkFaults,
    /// The statistics.
    pub stats: EmulatorStats,
}

/// Controls a running emulator from another thread and reads its status ([`Control`]; its command is the link
/// faults).
pub type EmulatorControl = Control<EmulatorStatus, LinkFaults>;

impl Control<EmulatorStatus, LinkFaults> {
    /// Sets the link faults from the next loop on (validated there; invalid rates stop the emulator with an error).
    pub fn set_link_faults(&self, faults: LinkFaults) {
        self.send(faults);
    }
}

/// An emulator running in its own thread on a pseudo-terminal (Unix): the host opens [`PtyRunner::path`] as its
/// serial port. Dropping it stops the emulator and removes the pseudo-terminal.
#[cfg(unix)]
pub type PtyEmulator = PtyRunner<EmulatorStatus, LinkFaults>;

impl<F: PlateFinger + Send> Emulated for Emulator<F> {
    type Status = EmulatorStatus;
    type Command = LinkFaults;

    fn receive(&mut self, bytes: &[u8], now_s: f64, out: &mut Vec<u8>) {
        Emulator::receive(self, bytes, now_s, out);
    }

    fn advance_to(&mut self, now_s: f64, out: &mut Vec<u8>) {
        Emulator::advance_to(self, now_s, out);
    }

    fn tick_s(&self) -> f64 {
        self.config.tick_s
    }

    fn snapshot(&self) -> EmulatorStatus {
        self.status()
    }

    fn command(&mut self, faults: LinkFaults) -> Result<(), EmulatorError> {
        self.set_link_faults(faults)
    }

    fn write_stalled(&mut self) {
        self.stats.write_stalls += 1;
    }
}
