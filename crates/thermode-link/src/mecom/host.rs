//! [`MecomDevice`]: Meerstetter TEC controllers over MeCom, on a serial port (`mecom:PATH`) or TCP
//! (`mecom-tcp:HOST:PORT`), as a [`Device`] with one channel per TEC instance (address and instance).
//!
//! - **Connect** ([`MecomDevice::open`]): `?IF` until each address answers; without a channel list, `?VM` on the
//!   object temperature of the first address gives the number of instances. A device in its error state is reset
//!   (`RS`) first ([`MecomConfig::reset_on_error`]). Then, per channel, the output goes off (output stage enable
//!   0, live enable 0) before anything else, and the device's own protection is set as a second line: current and
//!   voltage limitation, object temperature error thresholds (10 °C plus and 48 °C less what the sensor's lag hides
//!   at the fastest cooling and heating, [`lower_error_threshold_c`], [`upper_error_threshold_c`]: beyond them the device disables its output by itself, whoever else
//!   talks to it), the largest plausible temperature change, no automatic
//!   restart from the error state (6310 = 0), and the communication watchdog (2060, default 0.25 s: with no frame
//!   for that long the device disables its output, error 183). A device that refuses any of these is refused. Then
//!   the mode's input selection and the output stage enable "live off/on", so the output runs only while thermode
//!   sets live enable.
//! - **Modes** ([`MecomMode`]): *current-commanded* — the live set current (50001) carries the gated command's
//!   current every cycle (sign per the device's "positive current is" 3034), so thermode's controller and envelope
//!   drive the Peltier and the device's limits are the second line; live enable follows whether the current is
//!   non-zero. *Temperature-commanded* — the device's own controller follows the live target (50012), which
//!   carries the envelope's shaped set-point of the gated command ([`DriveCommand::setpoint_c`]), clamped to
//!   [`MecomConfig::target_min_c`]–[`MecomConfig::target_max_c`] (the envelope's range on the device's own reading:
//!   what it regulates to if the host dies while another client feeds its watchdog); a command without one (off, a
//!   hold, a fault) disables the output. Every device-side line (the thresholds, the rate, the target range) is set
//!   on the more cautious of the calibrated and the raw scale when the device file has a `[calibration]`
//!   ([`crate::spec::mecom_config`]), so neither an honest calibration of a sensor that errs nor a lying calibration
//!   of an honest sensor moves a line outward.
//! - **Cycle**: a worker thread owns the port and, at most every [`MecomConfig::cycle_interval_s`], per channel
//!   writes the drive and reads object temperature (1000), sink temperature (1001), actual current (1020), actual
//!   voltage (1021, which `thermode identify` needs), device
//!   status (104) and error number (105). Every request waits for its answer (the sequence number matches), and is
//!   sent once more with the same sequence number after [`MecomConfig::answer_timeout_s`]. [`Device::read`] only
//!   copies the newest values.
//! - **Errors**: no good answer for longer than [`MecomConfig::link_timeout_s`], or a port that fails, makes
//!   [`Device::read`] fail with [`DeviceError::Link`]; the device's error state reads as [`DeviceError::Cut`] for
//!   its object temperature thresholds (137, 138) and [`DeviceError::Link`] naming the error otherwise. Malformed
//!   and CRC-bad answers are counted and dropped.
//! - **Reconnection** (a port opened by [`MecomDevice::open_serial`] or [`MecomDevice::open_tcp`]): a port that
//!   fails, or no answer for [`MecomConfig::reconnect_after_silence_s`], takes the link down (the worker stops, the
//!   readings fail) and the shared [`crate::host`] reconnector connects and configures the device again with
//!   back-off; the new link is adopted at the next [`Device::read`] or [`Device::apply`], every output off, sample
//!   numbers still rising. A serial port is held exclusively.
//! - **Stopping**: [`Device::all_off`] disables every output and waits for the device's acknowledges; dropping the
//!   device does the same before the worker ends.

use std::io;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use thermode_model::{BadValue, Rule};
use thermode_platform::Clock;
use thermode_safety::{DriveCommand, ABSOLUTE_MAX_C, ABSOLUTE_MIN_C};

use super::codec::frame::{encode_frame, FrameCounters, FrameDecoder, DEVICE_CONTROL, HOST_CONTROL};
use super::codec::payload::{check_answer, describe_error, error_number, param, status, Request};
use super::line::{HeatingLine, LineState};
pub use crate::host::Port;
use crate::host::{self, read_step, start_thread, ReadStep, Reconnector, Recovering};
use crate::own::guard::{sensor_lag_cooling_margin_c, sensor_lag_margin_c, RELEASE_HYSTERESIS_C};
use thermode_device::{
    Device, DeviceConfig, DeviceCut, DeviceError, DevicePart, DownReason, LinkError, LinkFault, LinkHealth, Measures,
    MecomSetup, OsError, Reading, RequestFault, MAX_CHANNELS,
};

/// Default baud rate of a MeCom serial port \[bit/s\]: 57600 (the TEC family's default and the rate its service
/// software always listens on).
pub const DEFAULT_MECOM_BAUD_RATE: u32 = 57_600;

/// The longest communication watchdog thermode sets \[s\]: 0.25, as for its own protocol
/// ([`crate::own::host::MAX_DEVICE_WATCHDOG_MS`]); the device's range starts at 0.1.
pub const MAX_MECOM_WATCHDOG_S: f64 = 0.25;

/// What the device regulates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MecomMode {
    /// Live current control: thermode's controller and envelope set the current.
    #[default]
    Current,
    /// The device's own temperature controller follows the envelope's shaped set-point.
    Temperature,
}

impl MecomMode {
    /// `current` or `temperature`.
    pub fn name(self) -> &'static str {
        match self {
            MecomMode::Current => "current",
            MecomMode::Temperature => "temperature",
        }
    }
}

/// One channel: a TEC instance of a device address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MecomChannel {
    /// Device address, 0 to 254 (0: whichever device is on the line answers).
    pub address: u8,
    /// Instance (output channel of that device), from 1.
    pub instance: u8,
}

/// Settings of the MeCom host.
#[derive(Debug, Clone, PartialEq)]
pub struct MecomConfig {
    /// What the device regulates. Default [`MecomMode::Current`].
    pub mode: MecomMode,
    /// The channels in order; empty: every instance of [`MecomConfig::discover_address`] (found with `?VM`).
    /// Default empty.
    pub channels: Vec<MecomChannel>,
    /// Address whose instances become the channels when none are listed. Default 0 (the one device on the line).
    pub discover_address: u8,
    /// Further addresses on the same port (an RS-485 bus, `mecom:PATH@ADDR` given several times) whose instances
    /// follow those of [`MecomConfig::discover_address`] when no channels are listed, in this order. Default empty.
    pub bus_addresses: Vec<u8>,
    /// Serial baud rate \[bit/s\]. Default [`DEFAULT_MECOM_BAUD_RATE`].
    pub baud_rate: u32,
    /// Longest wait for an answer before the request is sent once more \[s\], in (0, 1]. Default 0.05 (a request and
    /// its answer take about 7 ms at 57600 baud).
    pub answer_timeout_s: f64,
    /// Longest time for the connection and the configuration \[s\], on the host clock, in (0, 60]. Default 3.
    pub handshake_timeout_s: f64,
    /// Longest time without a good answer from a channel before its readings fail \[s\], in (0, 10]. Default 0.5.
    pub link_timeout_s: f64,
    /// Shortest interval between the starts of two cycles \[s\], in \[0, 1\]. Default 0.01 (100 Hz, the control loop's
    /// default rate; a cycle takes longer on a slow line: about 42 ms per channel at 57600 baud).
    pub cycle_interval_s: f64,
    /// The device's communication watchdog \[s\], in \[0.1, [`MAX_MECOM_WATCHDOG_S`]\]. Default 0.25.
    pub watchdog_s: f64,
    /// Current limitation set on every channel \[A\] (2030), positive. Default 2.8 (the default display's drive).
    pub current_limit_a: f64,
    /// Voltage limitation set on every channel \[V\] (2031), positive. Default 4.0.
    pub voltage_limit_v: f64,
    /// Lower object temperature error threshold \[°C\] (4010). Default [`lower_error_threshold_c`] of the default
    /// display: the envelope's absolute minimum (10) plus what the sensor's lag can hide at the fastest cooling
    /// (3.2 K), 13.2 °C; `--device mecom:…` sets it from the device file.
    pub lower_error_c: f64,
    /// Upper object temperature error threshold \[°C\] (4011). Default [`upper_error_threshold_c`] of the default
    /// display: the envelope's absolute maximum (48) less what the sensor's lag can hide at full current (8.3 K),
    /// 39.7 °C; `--device mecom:…` sets it from the device file.
    pub upper_error_c: f64,
    /// Largest plausible object temperature change \[°C/s\] (4012), in \[1, 200\]. Default 50 (the envelope's
    /// implausible-rate check).
    pub max_change_c_per_s: f64,
    /// Temperature mode: the coolest live target (50012) sent \[°C\], on the device's own reading. Default 15 (the
    /// envelope's minimum); `--device mecom:…` sets it from the envelope and the device file's calibration (the
    /// more cautious of both scales, [`thermode_device::config::CalibrationConfig::lower_line_on_reading_c`]).
    pub target_min_c: f64,
    /// Temperature mode: the warmest live target (50012) sent \[°C\], on the device's own reading: what the device
    /// regulates to when the host is gone and another client feeds its watchdog. Default 48 (the envelope's
    /// maximum); `--device mecom:…` sets it as [`MecomConfig::target_min_c`].
    pub target_max_c: f64,
    /// The dynamic second line on heating ([`super::line`]): once the configuration is saved to flash, saving is
    /// switched off (108 = 1) and the host keeps rewriting each channel's current limitation (2030) and upper
    /// threshold (4011) as the plate warms, so the plate can reach 48 °C while a dead host leaves it below
    /// [`super::line::LINE_PLATE_MAX_C`]. `None`: the static thresholds above only. Default the default display's
    /// line; `--device mecom:…` makes it from the device file. A device that cannot switch saving off keeps the
    /// static line (said in [`MecomCommandSet`]).
    pub heating_line: Option<HeatingLine>,
    /// Reset (`RS`) a device found in its error state at connect (e.g. after the watchdog of an earlier session
    /// tripped) instead of refusing it. Default true.
    pub reset_on_error: bool,
    /// No answer from any channel for this long takes the link down and starts a reconnection (a port opened by
    /// path or address) \[s\], in (0, 60]. Default 1.0, as thermode's own serial link.
    pub reconnect_after_silence_s: f64,
    /// Longest wait between two reconnection attempts \[s\] (the wait starts at [`host::FIRST_BACKOFF_S`] and
    /// doubles), in \[0.5, 60\]. Default 5.
    pub reconnect_backoff_max_s: f64,
}

impl Default for MecomConfig {
    fn default() -> Self {
        MecomConfig {
            mode: MecomMode::Current,
            channels: Vec::new(),
            discover_address: 0,
            bus_addresses: Vec::new(),
            baud_rate: DEFAULT_MECOM_BAUD_RATE,
            answer_timeout_s: 0.05,
            handshake_timeout_s: 3.0,
            link_timeout_s: 0.5,
            cycle_interval_s: 0.01,
            watchdog_s: MAX_MECOM_WATCHDOG_S,
            current_limit_a: 2.8,
            voltage_limit_v: 4.0,
            // As the upper threshold: a valid default file, else 48 °C, which `validate` refuses.
            lower_error_c: lower_error_threshold_c(&DeviceConfig::default()).unwrap_or(ABSOLUTE_MAX_C),
            // The default display's file is valid; were it not, 10 °C makes `validate` refuse the configuration.
            upper_error_c: upper_error_threshold_c(&DeviceConfig::default()).unwrap_or(ABSOLUTE_MIN_C),
            max_change_c_per_s: 50.0,
            target_min_c: 15.0,
            target_max_c: ABSOLUTE_MAX_C,
            heating_line: HeatingLine::new(&DeviceConfig::default()).ok(),
            reset_on_error: true,
            reconnect_after_silence_s: 1.0,
            reconnect_backoff_max_s: 5.0,
        }
    }
}

/// The upper object temperature error threshold \[°C\] thermode sets on a display of the device file `device`: the
/// envelope's absolute maximum less what the plate sensor's lag can hide at the display's fastest heating
/// ([`sensor_lag_margin_c`]: τ · r_max). The controller compares only its *reading* with the threshold; a plate that
/// rises at r_max is r_max·τ ahead of its sensor, so with the output left on (a host killed while another client
/// feeds the communication watchdog) the plate stops at about 48 °C instead of 48 °C plus the lag.
pub fn upper_error_threshold_c(device: &DeviceConfig) -> Result<f64, DeviceError> {
    let margin_c = sensor_lag_margin_c(device).map_err(DeviceError::from)?;
    Ok(ABSOLUTE_MAX_C - margin_c)
}

/// The lower object temperature error threshold \[°C\] thermode sets on a display of the device file `device`: the
/// envelope's absolute minimum plus what the plate sensor's lag can hide at the display's fastest cooling
/// ([`sensor_lag_cooling_margin_c`]), the mirror of [`upper_error_threshold_c`].
pub fn lower_error_threshold_c(device: &DeviceConfig) -> Result<f64, DeviceError> {
    let margin_c = sensor_lag_cooling_margin_c(device).map_err(DeviceError::from)?;
    Ok(ABSOLUTE_MIN_C + margin_c)
}

impl MecomConfig {
    /// `Ok` if every setting is in its range.
    pub fn validate(&self) -> Result<(), DeviceError> {
        let checks = [
            ("mecom answer_timeout_s [s]", self.answer_timeout_s, 1e-9, 1.0),
            ("mecom handshake_timeout_s [s]", self.handshake_timeout_s, 1e-9, 60.0),
            ("mecom link_timeout_s [s]", self.link_timeout_s, 1e-9, 10.0),
            ("mecom cycle_interval_s [s]", self.cycle_interval_s, 0.0, 1.0),
            ("mecom watchdog_s [s]", self.watchdog_s, 0.1, MAX_MECOM_WATCHDOG_S),
            ("mecom current_limit_a [A]", self.current_limit_a, 1e-9, 100.0),
            ("mecom voltage_limit_v [V]", self.voltage_limit_v, 1e-9, 100.0),
            ("mecom lower_error_c [°C]", self.lower_error_c, -273.0, 1000.0),
            ("mecom upper_error_c [°C]", self.upper_error_c, -273.0, 1000.0),
            ("mecom max_change_c_per_s [°C/s]", self.max_change_c_per_s, 1.0, 200.0),
            (
                "mecom target_min_c [°C]",
                self.target_min_c,
                ABSOLUTE_MIN_C,
                ABSOLUTE_MAX_C,
            ),
            (
                "mecom target_max_c [°C]",
                self.target_max_c,
                self.target_min_c,
                ABSOLUTE_MAX_C,
            ),
            (
                "mecom reconnect_after_silence_s [s]",
                self.reconnect_after_silence_s,
                1e-9,
                60.0,
            ),
            (
                "mecom reconnect_backoff_max_s [s]",
                self.reconnect_backoff_max_s,
                host::FIRST_BACKOFF_S,
                60.0,
            ),
        ];
        for (name, value, min, max) in checks {
            Rule::Within { min, max }.check(name, value)?;
        }
        if self.lower_error_c >= self.upper_error_c {
            return Err(BadValue::custom(
                "mecom lower_error_c [°C]",
                self.lower_error_c,
                "must lie below upper_error_c",
            )
            .into());
        }
        Rule::Positive.check("mecom baud_rate [bit/s]", f64::from(self.baud_rate))?;
        if self.channels.len() > MAX_CHANNELS {
            return Err(DeviceError::ChannelCount {
                count: self.channels.len(),
                max: MAX_CHANNELS,
            });
        }
        if !self.bus_addresses.is_empty() && self.discover_address == 0 {
            let why = "must be 1 to 254 on a bus (address 0 is answered by every device on it)";
            return Err(BadValue::custom("mecom bus address", 0.0, why).into());
        }
        let mut bus = vec![self.discover_address];
        for &address in &self.bus_addresses {
            if address == 0 || address == 255 || bus.contains(&address) {
                let why = "must be 1 to 254, each address once";
                return Err(BadValue::custom("mecom bus address", f64::from(address), why).into());
            }
            bus.push(address);
        }
        if let Some(c) = self.channels.iter().find(|c| c.instance == 0 || c.address == 255) {
            return Err(LinkError::BadChannel {
                address: c.address,
                instance: c.instance,
            }
            .into());
        }
        Ok(())
    }
}

/// What the host has seen and done on the link.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MecomStats {
    /// Frames received, dropped by CRC or shape, bytes skipped.
    pub rx: FrameCounters,
    /// Requests sent (repeats included).
    pub requests: u64,
    /// Requests sent again after no answer.
    pub repeats: u64,
    /// Requests that got no answer even when repeated.
    pub timeouts: u64,
    /// Answers that were a server error or had the wrong shape.
    pub bad_answers: u64,
    /// Answers to an earlier request (late), skipped.
    pub stale_answers: u64,
    /// Whole cycles (every channel written and read).
    pub cycles: u64,
    /// Duration of the last cycle \[s\].
    pub last_cycle_s: f64,
    /// Longest cycle so far \[s\].
    pub max_cycle_s: f64,
    /// Mean time from a request to its answer \[s\] (answered requests).
    pub mean_round_trip_s: f64,
    /// The device's error number found and cleared by a reset at connect, if any.
    pub reset_at_connect: Option<i32>,
}

/// Which MeCom commands a device is driven with: every firmware has `?IF`, `?VR`, `VS` and `RS` and the
/// parameters thermode's safety rests on; older firmware answers the metadata request `?VM` and some newer
/// parameters with a server error "command not available" (1) or "parameter not available" (5). Such a device is
/// driven without them: its instances counted by probing (or taken from `channels=`), the optional settings left
/// as they are, the voltage it does not report unknown.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MecomCommandSet {
    /// The instances were counted by reading the object temperature of instance 1, 2, … until one is refused
    /// (`?VM` not available).
    pub probed_instances: bool,
    /// The optional commands the device refused as not available, in words.
    pub missing: Vec<&'static str>,
    /// Why the dynamic second line on heating is not in force, when it is not (no `heating_line`, or the device
    /// cannot switch saving to flash off): the static upper threshold holds.
    pub static_line: Option<&'static str>,
}

impl MecomCommandSet {
    /// The command set in one line, as `/api/status` and the start-up log show it.
    pub fn describe(&self) -> String {
        let line = match self.static_line {
            Some(why) => format!("; the static upper threshold only ({why})"),
            None => String::new(),
        };
        if self.missing.is_empty() && !self.probed_instances {
            return format!("MeCom: the full command set{line}");
        }
        let counted = match self.probed_instances {
            true => "instances counted by probing the object temperature (1000); ",
            false => "",
        };
        format!(
            "MeCom: the commands every firmware has; {counted}not available: {}{line}",
            self.missing.join(", ")
        )
    }

    fn lacks(&mut self, what: &'static str) {
        if !self.missing.contains(&what) {
            self.missing.push(what);
        }
    }
}

/// Whether `fault` is the device saying it lacks the command or parameter (server error 1 "command not available"
/// or 5 "parameter not available").
fn not_available(fault: &RequestFault) -> bool {
    matches!(fault, RequestFault::Server { code: 1 | 5, .. })
}

/// What the metadata request `?VM` stands for, when the device lacks it.
const MISSING_META: &str = "metadata (?VM)";
/// The optional settings: (what, the parameter).
const OPTIONAL_SETTINGS: [(&str, u16); 2] = [
    ("max object temperature change (4012)", param::MAX_TEMP_CHANGE),
    ("live set voltage (50002)", param::LIVE_SET_VOLTAGE),
];
/// The actual output voltage, when the device lacks it (its readings then carry NaN).
const MISSING_VOLTAGE: &str = "actual output voltage (1021)";

/// The newest values of one channel.
#[derive(Debug, Clone, Default)]
struct Track {
    sample_seq: u64,
    time_s: f64,
    object_c: f64,
    sink_c: f64,
    current_a: f64,
    /// Actual output voltage \[V\] (1021), in thermode's sign convention.
    voltage_v: f64,
    device_status: i32,
    error_number: i32,
    /// Host clock time of the last good answer from this channel \[s\].
    last_answer_s: Option<f64>,
    /// Why the last request failed, if it did.
    last_failure: Option<RequestFault>,
}

/// What the device holds for one channel, as commanded.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Command {
    current_a: f64,
    setpoint_c: Option<f64>,
}

/// State shared by the worker and the device.
#[derive(Debug, Default)]
struct Shared {
    tracks: Vec<Track>,
    commands: [Command; MAX_CHANNELS],
    /// The largest heating current each channel's device delivers now \[A\] ([`Reading::heating_limit_a`]).
    heating_limits_a: [f64; MAX_CHANNELS],
    /// All-off requests made and carried out.
    off_requested: u64,
    off_done: u64,
    stats: MecomStats,
    /// Set when the port failed; permanent.
    error: Option<LinkFault>,
    /// Why the worker found the dynamic line unavailable, if it did (the device's command set says so).
    static_line: Option<&'static str>,
}

/// The port and the request/answer machinery (used by the connecting thread, then by the worker).
struct Link {
    name: PathBuf,
    port: Box<dyn Port>,
    decoder: FrameDecoder,
    seq: u16,
    clock: Arc<dyn Clock>,
    /// How long a request waits for its answer \[s\].
    answer_timeout_s: f64,
    out: Vec<u8>,
    buf: [u8; 256],
    stats: MecomStats,
    answered: u64,
    round_trip_total_s: f64,
}

impl Link {
    /// The link error `fault` of this device.
    fn error(&self, fault: LinkFault) -> DeviceError {
        LinkError::device(&self.name, fault).into()
    }

    /// Sends `request` to `address` and waits for its answer (once more with the same sequence number after the
    /// answer timeout).
    fn transact(&mut self, address: u8, request: &Request) -> Result<Option<u32>, RequestFault> {
        self.seq = self.seq.wrapping_add(1);
        let payload = request.payload();
        self.out.clear();
        let crc = encode_frame(HOST_CONTROL, address, self.seq, &payload, &mut self.out);
        for attempt in 0..2 {
            if attempt > 0 {
                self.stats.repeats += 1;
            }
            let sent_s = self.clock.now_s();
            self.port
                .write_all(&self.out)
                .and_then(|()| self.port.flush())
                .map_err(|e| RequestFault::Port {
                    error: OsError::from(e),
                })?;
            self.stats.requests += 1;
            if let Some(answer) = self.await_answer(address, sent_s)? {
                self.answered += 1;
                self.round_trip_total_s += self.clock.now_s() - sent_s;
                self.stats.mean_round_trip_s = self.round_trip_total_s / self.answered as f64;
                return check_answer(request, crc, &answer).map_err(|e| {
                    self.stats.bad_answers += 1;
                    RequestFault::from(e)
                });
            }
        }
        self.stats.timeouts += 1;
        Err(RequestFault::NoAnswer)
    }

    /// Reads until the answer with the current sequence number from `address` arrives, or the answer timeout.
    fn await_answer(&mut self, address: u8, sent_s: f64) -> Result<Option<String>, RequestFault> {
        while self.clock.now_s() - sent_s < self.answer_timeout_s {
            let n = match read_step(self.port.as_mut(), &mut self.buf) {
                ReadStep::Data(n) => n,
                ReadStep::Retry => continue,
                ReadStep::Idle => {
                    std::thread::sleep(Duration::from_micros(200));
                    continue;
                }
                ReadStep::Closed => {
                    return Err(RequestFault::Port {
                        error: OsError::from(io::ErrorKind::UnexpectedEof),
                    })
                }
                ReadStep::Failed(error) => return Err(RequestFault::Port { error }),
            };
            let mut found = None;
            let (seq, stats) = (self.seq, &mut self.stats);
            for &byte in &self.buf[..n] {
                if let Some(Ok(frame)) = self.decoder.push(byte) {
                    if frame.seq == seq && (frame.address == address || address == 0) && found.is_none() {
                        found = Some(frame.payload);
                    } else {
                        stats.stale_answers += 1;
                    }
                }
            }
            self.stats.rx = *self.decoder.counters();
            if found.is_some() {
                return Ok(found);
            }
        }
        self.stats.rx = *self.decoder.counters();
        Ok(None)
    }

    /// The 32 bits of parameter `id` of `channel` (`?VR`; 0 if the answer carries none).
    fn read_bits(&mut self, channel: MecomChannel, id: u16) -> Result<u32, RequestFault> {
        let instance = channel.instance;
        let bits = self.transact(channel.address, &Request::Read { id, instance })?;
        Ok(bits.unwrap_or(0))
    }

    fn read_i32(&mut self, channel: MecomChannel, id: u16) -> Result<i32, RequestFault> {
        Ok(self.read_bits(channel, id)? as i32)
    }

    /// A float parameter, as the decimal the controller's `f32` stands for (23.28, not 23.280000686645508).
    fn read_f32(&mut self, channel: MecomChannel, id: u16) -> Result<f64, RequestFault> {
        let value = f32::from_bits(self.read_bits(channel, id)?);
        Ok(thermode_model::numbers::f32_as_decimal(value))
    }

    fn set(&mut self, channel: MecomChannel, request: Request) -> Result<(), RequestFault> {
        self.transact(channel.address, &request).map(|_| ())
    }
}

/// How the device maps thermode's current (positive heats) to its own.
#[derive(Debug, Clone, Copy)]
struct ChannelSetup {
    channel: MecomChannel,
    /// +1 if the device's positive current heats, −1 if it cools.
    sign: f64,
}

/// A Meerstetter TEC controller (or several on one bus) over MeCom. See the module documentation.
pub struct MecomDevice {
    name: PathBuf,
    config: MecomConfig,
    channels: Vec<ChannelSetup>,
    identity: Vec<(u8, String)>,
    /// Each address's serial number (parameter 102), where it answered it.
    serials: Vec<(u8, i32)>,
    /// The commands it is driven with, found at connect.
    commands: MecomCommandSet,
    shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
    worker: Option<JoinHandle<()>>,
    clock: Arc<dyn Clock>,
    /// Re-opening the port after a failure or a silence (only for a port opened by path or address).
    recovery: Option<Reconnector<MecomDevice>>,
    /// Added to a link's sample numbers, so they keep rising across reconnections (each link counts from 0).
    seq_base: [u64; MAX_CHANNELS],
    /// The last sample number handed out per channel.
    seq_seen: [u64; MAX_CHANNELS],
    health: Arc<LinkHealth>,
    /// On a bus ([`MecomConfig::bus_addresses`]): each address's own link state, down while none of its channels
    /// answered within [`MecomConfig::link_timeout_s`] (empty otherwise).
    address_health: Vec<(u8, Arc<LinkHealth>)>,
}

impl std::fmt::Debug for MecomDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MecomDevice")
            .field("name", &self.name)
            .field("mode", &self.config.mode)
            .field("channels", &self.channels.len())
            .finish_non_exhaustive()
    }
}

impl MecomDevice {
    /// Opens the serial port `path` (raw, 8N1, [`MecomConfig::baud_rate`], exclusively: no other process opens it
    /// while thermode holds it), connects and configures the device. A failed or silent link is re-opened on the
    /// same path ([`MecomConfig::reconnect_after_silence_s`]).
    pub fn open_serial(path: &str, config: &MecomConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        let (owned, reopen) = (path.to_string(), config.clone());
        MecomDevice::with_recovery(
            MecomDevice::open_serial_once(path, config, Arc::clone(&clock))?,
            clock,
            move |c| MecomDevice::open_serial_once(&owned, &reopen, c),
        )
    }

    fn open_serial_once(path: &str, config: &MecomConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        config.validate()?;
        let port = host::open_serial(
            path,
            config.baud_rate,
            Duration::from_millis(2),
            serialport::ClearBuffer::Input,
        )?;
        MecomDevice::open(&format!("mecom:{path}"), Box::new(port), config, clock)
    }

    /// Connects to `address` (`HOST:PORT`) over TCP, then connects and configures the device. A dropped or silent
    /// connection is made again to the same address ([`MecomConfig::reconnect_after_silence_s`]).
    pub fn open_tcp(address: &str, config: &MecomConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        let (owned, reopen) = (address.to_string(), config.clone());
        MecomDevice::with_recovery(
            MecomDevice::open_tcp_once(address, config, Arc::clone(&clock))?,
            clock,
            move |c| MecomDevice::open_tcp_once(&owned, &reopen, c),
        )
    }

    fn open_tcp_once(address: &str, config: &MecomConfig, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        config.validate()?;
        let stream = host::open_tcp(
            address,
            Duration::from_secs_f64(config.handshake_timeout_s),
            Duration::from_millis(2),
            Duration::from_millis(100),
        )?;
        MecomDevice::open(&format!("mecom-tcp:{address}"), Box::new(stream), config, clock)
    }

    /// `device` with a reconnector that makes new links with `open` on `clock`.
    fn with_recovery(
        mut device: MecomDevice,
        clock: Arc<dyn Clock>,
        open: impl Fn(Arc<dyn Clock>) -> Result<MecomDevice, DeviceError> + Send + 'static,
    ) -> Result<Self, DeviceError> {
        let reopen_clock = Arc::clone(&clock);
        device.recovery = Some(Reconnector::spawn(
            &device.name.to_string_lossy(),
            device.config.reconnect_backoff_max_s,
            clock,
            Arc::clone(&device.health),
            move || open(Arc::clone(&reopen_clock)),
        )?);
        Ok(device)
    }

    /// Connects over any port (reads should time out within a few milliseconds), named `name` in messages:
    /// identifies the device(s), finds the channels, configures them (see the module documentation) and starts the
    /// worker. Reading times are on `clock`.
    pub fn open(
        name: &str,
        port: Box<dyn Port>,
        config: &MecomConfig,
        clock: Arc<dyn Clock>,
    ) -> Result<Self, DeviceError> {
        config.validate()?;
        let mut link = Link {
            name: PathBuf::from(name),
            port,
            decoder: FrameDecoder::new(DEVICE_CONTROL),
            // The specification recommends a random start; the time is random enough and keeps tests deterministic
            // in what matters (answers are matched by sequence number, whatever it starts at).
            seq: (clock.now_s() * 1e6) as u64 as u16,
            clock: Arc::clone(&clock),
            answer_timeout_s: config.answer_timeout_s,
            out: Vec::with_capacity(64),
            buf: [0; 256],
            stats: MecomStats::default(),
            answered: 0,
            round_trip_total_s: 0.0,
        };
        let deadline_s = clock.now_s() + config.handshake_timeout_s;
        let Connected {
            channels,
            identity,
            serials,
            mut commands,
        } = connect(&mut link, config, deadline_s).map_err(|e| link.error(e))?;
        if config.heating_line.is_none() {
            commands.static_line = Some("no dynamic line configured");
        }
        let health = Arc::new(LinkHealth::new());
        health.set_command_set(commands.describe());
        let shared = Arc::new(Mutex::new(Shared {
            tracks: vec![Track::default(); MAX_CHANNELS],
            heating_limits_a: [config.current_limit_a; MAX_CHANNELS],
            ..Shared::default()
        }));
        let mut device = MecomDevice {
            name: PathBuf::from(name),
            config: config.clone(),
            channels,
            identity,
            serials,
            commands: commands.clone(),
            shared: Arc::clone(&shared),
            stop: Arc::new(AtomicBool::new(false)),
            worker: None,
            clock: Arc::clone(&clock),
            recovery: None,
            seq_base: [0; MAX_CHANNELS],
            seq_seen: [0; MAX_CHANNELS],
            health,
            address_health: Vec::new(),
        };
        if !config.bus_addresses.is_empty() {
            for setup in &device.channels {
                let address = setup.channel.address;
                if !device.address_health.iter().any(|(a, _)| *a == address) {
                    device.address_health.push((address, Arc::new(LinkHealth::new())));
                }
            }
        }
        // One cycle here, so the first read after open has values.
        let mut worker = Worker {
            link,
            config: config.clone(),
            channels: device.channels.clone(),
            shared,
            clock,
            enabled: vec![false; device.channels.len()],
            voltage: vec![true; device.channels.len()],
            set_up: vec![true; device.channels.len()],
            silent_since: vec![None; device.channels.len()],
            line: vec![LineState::default(); device.channels.len()],
            written: vec![(config.current_limit_a, config.upper_error_c); device.channels.len()],
            heating_a: vec![0.0; device.channels.len()],
            last: vec![Track::default(); device.channels.len()],
            flash: Vec::new(),
        };
        worker.flash_saving_from(worker.clock.now_s());
        worker.cycle();
        let stop = Arc::clone(&device.stop);
        let thread = start_thread(&device.name, "thermode-mecom", move || worker.run(&stop))?;
        device.worker = Some(thread);
        Ok(device)
    }

    /// The settings.
    pub fn config(&self) -> &MecomConfig {
        &self.config
    }

    /// The channels (address, instance) in order.
    pub fn channels(&self) -> Vec<MecomChannel> {
        self.channels.iter().map(|c| c.channel).collect()
    }

    /// Which commands the device is driven with (found at connect; older firmware lacks some).
    pub fn command_set(&self) -> &MecomCommandSet {
        &self.commands
    }

    /// Each address's answer to `?IF`.
    pub fn identity(&self) -> &[(u8, String)] {
        &self.identity
    }

    /// What tells the controller at `address` apart: its serial number as `SN<number>` (parameter 102), else its
    /// `?IF` identity text, else `None`.
    pub fn identity_of(&self, address: u8) -> Option<String> {
        if let Some((_, serial)) = self.serials.iter().find(|(a, _)| *a == address) {
            return Some(format!("SN{serial}"));
        }
        self.identity
            .iter()
            .find(|(a, text)| *a == address && !text.trim().is_empty())
            .map(|(_, text)| text.trim().to_string())
    }

    /// What has been seen and done on the link so far.
    pub fn stats(&self) -> MecomStats {
        self.lock().map(|s| s.stats).unwrap_or_default()
    }

    /// The device status (104) and error number (105) last read from `channel`.
    pub fn device_status(&self, channel: usize) -> Result<(i32, i32), DeviceError> {
        self.check_channel(channel)?;
        let state = self.lock()?;
        let track = state.tracks.get(channel).cloned().unwrap_or_default();
        Ok((track.device_status, track.error_number))
    }

    fn lock(&self) -> Result<MutexGuard<'_, Shared>, DeviceError> {
        self.shared.lock().map_err(|_| self.error(LinkFault::ReaderFailed))
    }

    /// The link error `fault` of this device.
    fn error(&self, fault: LinkFault) -> DeviceError {
        LinkError::device(&self.name, fault).into()
    }

    /// The link state of `address`: its own on a bus, the port's otherwise.
    fn link_of(&self, address: u8) -> Arc<LinkHealth> {
        let own = self.address_health.iter().find(|(a, _)| *a == address);
        Arc::clone(own.map_or(&self.health, |(_, health)| health))
    }

    /// On a bus: takes an address's link state down when none of its channels answered within the link timeout,
    /// and up again (a reconnection) when one does.
    fn watch_addresses(&mut self) {
        let now_s = self.clock.now_s();
        let Ok(state) = self.shared.lock() else {
            return;
        };
        for (address, health) in &self.address_health {
            let last_s = self
                .channels
                .iter()
                .zip(&state.tracks)
                .filter(|(setup, _)| setup.channel.address == *address)
                .filter_map(|(_, track)| track.last_answer_s)
                .fold(f64::NEG_INFINITY, f64::max);
            let silent_s = now_s - last_s;
            let answering = silent_s <= self.config.link_timeout_s;
            if health.is_up() && !answering {
                let name = self.name.display();
                health.down(format!("{name}@{address}: no answer for {silent_s:.2} s"));
            } else if !health.is_up() && answering {
                health.reconnected();
            }
        }
    }

    /// The command set says so once the worker found the dynamic line unavailable.
    fn note_static_line(&mut self) {
        let found = self.shared.lock().ok().and_then(|s| s.static_line);
        if found.is_some() && self.commands.static_line.is_none() {
            self.commands.static_line = found;
            self.health.set_command_set(self.commands.describe());
        }
    }

    fn check_channel(&self, channel: usize) -> Result<(), DeviceError> {
        let count = self.channels.len();
        if channel < count {
            Ok(())
        } else {
            Err(DeviceError::NoSuchChannel { channel, count })
        }
    }
}

/// What connecting found.
struct Connected {
    /// The configured channels.
    channels: Vec<ChannelSetup>,
    /// Each address's `?IF` identity text.
    identity: Vec<(u8, String)>,
    /// Each address's serial number (parameter 102), where it answered it.
    serials: Vec<(u8, i32)>,
    /// The commands the device is driven with.
    commands: MecomCommandSet,
}

/// Identifies the device(s), finds the channels and configures them, before `deadline_s` on the link's clock.
/// Returns the channels and identities.
fn connect(link: &mut Link, config: &MecomConfig, deadline_s: f64) -> Result<Connected, LinkFault> {
    let fail = |setup: MecomSetup| LinkFault::Setup(setup);
    let mut addresses: Vec<u8> = config.channels.iter().map(|c| c.address).collect();
    if addresses.is_empty() {
        addresses.push(config.discover_address);
        addresses.extend(&config.bus_addresses);
    }
    addresses.dedup();
    let mut identity = Vec::new();
    let mut serials = Vec::new();
    for &address in &addresses {
        identity.push((address, identify(link, address, deadline_s)?));
        // Optional: a device that does not answer it is told apart by its `?IF` text.
        if let Ok(serial) = link.read_i32(MecomChannel { address, instance: 1 }, param::SERIAL_NUMBER) {
            serials.push((address, serial));
        }
    }
    let mut commands = MecomCommandSet::default();
    let channels = if config.channels.is_empty() {
        let mut all = Vec::new();
        for &address in &addresses {
            all.extend(discover(link, address, &mut commands)?);
        }
        if all.len() > MAX_CHANNELS {
            return Err(LinkFault::Setup(MecomSetup::InstanceCount {
                count: all.len(),
                max: MAX_CHANNELS,
            }));
        }
        all
    } else {
        config.channels.clone()
    };
    // A device in its error state (its output is off) is reset first, or refused.
    for &address in &addresses {
        let probe = MecomChannel { address, instance: 1 };
        let device_status = link
            .read_i32(probe, param::DEVICE_STATUS)
            .map_err(|why| fail(MecomSetup::ReadStatus { address, why }))?;
        if device_status == status::ERROR {
            let number = link.read_i32(probe, param::ERROR_NUMBER).unwrap_or(-1);
            if !config.reset_on_error {
                return Err(fail(MecomSetup::InErrorState {
                    address,
                    number,
                    meaning: describe_error(number),
                }));
            }
            link.set(probe, Request::Reset)
                .map_err(|why| fail(MecomSetup::Reset { address, number, why }))?;
            link.stats.reset_at_connect = Some(number);
            // No pause: the device restarts within 200 ms, and `?IF` until it answers also keeps a stored watchdog
            // fed from its first moment.
            identify(link, address, deadline_s)?;
        }
    }
    let mut setups = Vec::with_capacity(channels.len());
    for &channel in &channels {
        configure(link, config, channel, &mut commands).map_err(fail)?;
        let sign = match link.read_i32(channel, param::POSITIVE_CURRENT_IS) {
            Ok(0) => -1.0,
            Ok(_) => 1.0,
            Err(why) => return Err(fail(MecomSetup::ReadSign(why))),
        };
        setups.push(ChannelSetup { channel, sign });
    }
    for &address in &addresses {
        let probe = MecomChannel { address, instance: 1 };
        link.set(
            probe,
            Request::set_f32(param::WATCHDOG_TIMEOUT, 1, config.watchdog_s as f32),
        )
        .map_err(|why| {
            fail(MecomSetup::Watchdog {
                address,
                watchdog_s: config.watchdog_s,
                why,
            })
        })?;
    }
    for setup in &setups {
        let (device_status, number) = (
            link.read_i32(setup.channel, param::DEVICE_STATUS),
            link.read_i32(setup.channel, param::ERROR_NUMBER),
        );
        if let (Ok(status::ERROR), Ok(number)) = (device_status, number) {
            return Err(fail(MecomSetup::ErrorWhileConfiguring {
                address: setup.channel.address,
                number,
                meaning: describe_error(number),
            }));
        }
    }
    for &address in &addresses {
        let probe = MecomChannel { address, instance: 1 };
        // Any other failure is the link's, and the worker's cycle meets it.
        if link
            .read_f32(probe, param::ACTUAL_OUTPUT_VOLTAGE)
            .is_err_and(|why| not_available(&why))
        {
            commands.lacks(MISSING_VOLTAGE);
        }
    }
    Ok(Connected {
        channels: setups,
        identity,
        serials,
        commands,
    })
}

/// Every instance of `address`: counted with `?VM` on its object temperature, or, on a firmware without `?VM`,
/// by reading the object temperature of instance 1, 2, … until one is refused.
fn discover(link: &mut Link, address: u8, commands: &mut MecomCommandSet) -> Result<Vec<MecomChannel>, LinkFault> {
    let meta = link.transact(
        address,
        &Request::Meta {
            id: param::OBJECT_TEMPERATURE,
            instance: 1,
        },
    );
    let count = match meta {
        Ok(count) => count.unwrap_or(0) as usize,
        Err(why) if not_available(&why) => {
            commands.lacks(MISSING_META);
            commands.probed_instances = true;
            probe_instances(link, address)?
        }
        Err(why) => return Err(LinkFault::Setup(MecomSetup::CountInstances(why))),
    };
    if count == 0 || count > MAX_CHANNELS {
        return Err(LinkFault::Setup(MecomSetup::InstanceCount {
            count,
            max: MAX_CHANNELS,
        }));
    }
    Ok((1..=count as u8)
        .map(|instance| MecomChannel { address, instance })
        .collect())
}

/// The number of instances of `address`, found by reading the object temperature of instance 1, 2, … up to
/// [`MAX_CHANNELS`] + 1 until the device refuses one with a server error.
fn probe_instances(link: &mut Link, address: u8) -> Result<usize, LinkFault> {
    for instance in 1..=(MAX_CHANNELS as u8 + 1) {
        match link.read_f32(MecomChannel { address, instance }, param::OBJECT_TEMPERATURE) {
            Ok(_) => {}
            Err(RequestFault::Server { .. }) => return Ok(usize::from(instance) - 1),
            Err(why) => return Err(LinkFault::Setup(MecomSetup::CountInstances(why))),
        }
    }
    Ok(MAX_CHANNELS + 1)
}

/// `?IF` to `address` until it answers or `deadline_s` on the link's clock.
fn identify(link: &mut Link, address: u8, deadline_s: f64) -> Result<String, LinkFault> {
    let mut last = RequestFault::NoAnswer;
    while link.clock.now_s() < deadline_s {
        link.seq = link.seq.wrapping_add(1);
        match link.transact(address, &Request::Identify) {
            Ok(_) => {
                // The identity text itself: ask once more and keep the payload (check_answer only checks its length).
                return Ok(identity_text(link, address).unwrap_or_default());
            }
            Err(port @ RequestFault::Port { .. }) => return Err(LinkFault::Request(port)),
            Err(e) => last = e,
        }
    }
    Err(LinkFault::Setup(MecomSetup::NoIdentity { address, last }))
}

/// The identity string of `address` (one more `?IF`, keeping the payload).
fn identity_text(link: &mut Link, address: u8) -> Option<String> {
    link.seq = link.seq.wrapping_add(1);
    link.out.clear();
    encode_frame(HOST_CONTROL, address, link.seq, "?IF", &mut link.out);
    link.port.write_all(&link.out).ok()?;
    link.port.flush().ok()?;
    let sent_s = link.clock.now_s();
    link.await_answer(address, sent_s)
        .ok()
        .flatten()
        .map(|s| s.trim_end().to_string())
}

/// The per-channel configuration: output off first, then the device's own limits, then the mode.
fn configure(
    link: &mut Link,
    config: &MecomConfig,
    channel: MecomChannel,
    commands: &mut MecomCommandSet,
) -> Result<(), MecomSetup> {
    let i = channel.instance;
    let mut steps: Vec<(&'static str, Request)> = vec![
        (
            "output stage enable off (2010 = 0)",
            Request::set_i32(param::OUTPUT_STAGE_ENABLE, i, 0),
        ),
        (
            "live enable off (50000 = 0)",
            Request::set_i32(param::LIVE_ENABLE, i, 0),
        ),
        (
            "live set current 0 A (50001)",
            Request::set_f32(param::LIVE_SET_CURRENT, i, 0.0),
        ),
        (
            "current limitation (2030)",
            Request::set_f32(param::CURRENT_LIMITATION, i, config.current_limit_a as f32),
        ),
        (
            "voltage limitation (2031)",
            Request::set_f32(param::VOLTAGE_LIMITATION, i, config.voltage_limit_v as f32),
        ),
        (
            "lower object error threshold (4010)",
            Request::set_f32(param::LOWER_ERROR_THRESHOLD, i, config.lower_error_c as f32),
        ),
        (
            "upper object error threshold (4011)",
            Request::set_f32(param::UPPER_ERROR_THRESHOLD, i, config.upper_error_c as f32),
        ),
        (
            "max object temperature change (4012)",
            Request::set_f32(param::MAX_TEMP_CHANGE, i, config.max_change_c_per_s as f32),
        ),
        (
            "no restart from the error state (6310 = 0)",
            Request::set_f32(param::ERROR_RESTART_DELAY, i, 0.0),
        ),
    ];
    match config.mode {
        MecomMode::Current => {
            steps.push((
                "live set voltage at the limitation (50002)",
                Request::set_f32(param::LIVE_SET_VOLTAGE, i, config.voltage_limit_v as f32),
            ));
            steps.push((
                "input selection live current (2000 = 1)",
                Request::set_i32(param::INPUT_SELECTION, i, 1),
            ));
        }
        MecomMode::Temperature => {
            let object_c = link
                .read_f32(channel, param::OBJECT_TEMPERATURE)
                .map_err(MecomSetup::ReadObject)?;
            steps.push((
                "live target at the plate (50012)",
                Request::set_f32(param::LIVE_TARGET, i, object_c as f32),
            ));
            steps.push((
                "live target source (50011 = 1)",
                Request::set_i32(param::TARGET_SOURCE, i, 1),
            ));
            steps.push((
                "input selection temperature controller (2000 = 2)",
                Request::set_i32(param::INPUT_SELECTION, i, 2),
            ));
        }
    }
    steps.push((
        "output stage enable live off/on (2010 = 2)",
        Request::set_i32(param::OUTPUT_STAGE_ENABLE, i, 2),
    ));
    for (step, request) in steps {
        let optional = match request {
            Request::Set { id, .. } => OPTIONAL_SETTINGS.iter().find(|(_, p)| *p == id).map(|(what, _)| *what),
            _ => None,
        };
        match (link.set(channel, request), optional) {
            (Ok(()), _) => {}
            // A firmware without this setting: the device's own default stays.
            (Err(why), Some(what)) if not_available(&why) => commands.lacks(what),
            (Err(why), _) => {
                return Err(MecomSetup::Refused {
                    address: channel.address,
                    instance: i,
                    step,
                    why,
                })
            }
        }
    }
    Ok(())
}

/// The worker: owns the port after the connection.
struct Worker {
    link: Link,
    config: MecomConfig,
    channels: Vec<ChannelSetup>,
    shared: Arc<Mutex<Shared>>,
    clock: Arc<dyn Clock>,
    /// Whether live enable is set on each channel, as last acknowledged.
    enabled: Vec<bool>,
    /// Per channel: whether its device reports the actual output voltage (1021; an older firmware may not).
    voltage: Vec<bool>,
    /// Whether each channel is configured (false once its address was silent for longer than the link timeout).
    set_up: Vec<bool>,
    /// Per channel: since when \[s\] its address has not answered, if it has not.
    silent_since: Vec<Option<f64>>,
    /// Per channel: the dynamic second line's state ([`super::line`]).
    line: Vec<LineState>,
    /// Per channel: the line's pair in force, (heating limit \[A\], upper threshold \[°C\]); the limit is the
    /// current limitation (2030) in temperature mode and the host's own bound on the live current in current mode.
    written: Vec<(f64, f64)>,
    /// Per channel: the heating current the device may deliver until the next cycle \[A\], heat-positive: the live
    /// current written (current mode) or the one measured at the last sample (temperature mode).
    heating_a: Vec<f64>,
    /// Per channel: the last sample taken (object and sink temperature, current, status).
    last: Vec<Track>,
    /// Per address: whether saving to flash is off, so the line's writes stay in RAM.
    flash: Vec<(u8, Flash)>,
}

/// Where an address stands with saving to flash (parameter 108), which the dynamic second line needs off.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Flash {
    /// The configuration is being saved (flash status 109 pending) since this host time \[s\].
    Saving { since_s: f64 },
    /// Saving is off: the line's writes are RAM only.
    Off,
    /// The device cannot switch saving off (why): the static threshold holds.
    Unavailable(&'static str),
}

/// Longest wait for the configuration to be saved before the line gives up and the static threshold holds \[s\]: 3
/// (the controller saves about 0.5 s after the last change).
const FLASH_SAVE_LIMIT_S: f64 = 3.0;
/// The line's heating limit is lowered in steps of at least this \[A\] and raised in steps of five (0.05 A), so a
/// plate at rest costs no writes.
const LIMIT_STEP_A: f64 = 0.01;
/// The line's upper threshold is raised in steps of at least this \[°C\] (lowered at once).
const UPPER_STEP_C: f64 = 0.1;

/// `x` rounded down to a multiple of `step`.
fn floor_to(x: f64, step: f64) -> f64 {
    (x / step).floor() * step
}

impl Worker {
    fn run(mut self, stop: &AtomicBool) {
        let interval_s = self.config.cycle_interval_s;
        while !stop.load(Ordering::SeqCst) {
            let start_s = self.clock.now_s();
            if !self.cycle() {
                return;
            }
            let rest_s = interval_s - (self.clock.now_s() - start_s);
            if rest_s >= 0.0 {
                std::thread::sleep(Duration::from_secs_f64(rest_s));
            }
        }
        // Dropped: every output off before the worker ends, and the static line back in RAM.
        self.switch_all_off();
        self.restore_static_line();
    }

    /// One cycle over every channel; false when the port failed.
    fn cycle(&mut self) -> bool {
        let start_s = self.clock.now_s();
        let (commands, off_requested) = match self.shared.lock() {
            Ok(state) => (state.commands, state.off_requested),
            Err(_) => return false,
        };
        let off_done = self.shared.lock().map(|s| s.off_done).unwrap_or(0);
        if off_requested > off_done {
            let done = self.switch_all_off();
            if let Ok(mut state) = self.shared.lock() {
                if done {
                    state.off_done = off_requested;
                }
            }
        }
        // On a bus, an address that did not answer is asked nothing more this cycle, so one silent device costs the
        // others one answer timeout per cycle, not one per request.
        self.release_cuts(&commands);
        let first_address = self.channels.first().map(|c| c.channel.address);
        let bus = self.channels.iter().any(|c| Some(c.channel.address) != first_address);
        let mut silent: Vec<u8> = Vec::new();
        for (index, command) in commands.into_iter().enumerate().take(self.channels.len()) {
            let address = self.channels[index].channel.address;
            if silent.contains(&address) {
                continue;
            }
            let now_s = self.clock.now_s();
            if self.silent_since[index].is_some_and(|t| now_s - t > self.config.link_timeout_s) {
                self.set_up[index] = false;
            }
            let driven = self
                .set_up_again(index)
                .and_then(|()| self.keep_line(index))
                .and_then(|()| self.drive(index, command));
            let result = match driven {
                Err(fault @ RequestFault::Port { .. }) => Err(fault),
                Err(RequestFault::NoAnswer) if bus => Err(RequestFault::NoAnswer),
                // One device: read it all the same (a lost answer to the drive must not cost a sample).
                driven => self.sample(index).and(driven),
            };
            match result {
                Err(port @ RequestFault::Port { .. }) => return self.port_failed(port),
                Err(RequestFault::NoAnswer) => {
                    if bus {
                        silent.push(address);
                    }
                    self.mark_silent(address, now_s);
                }
                Ok(()) => self.silent_since[index] = None,
                Err(_) => {}
            }
        }
        let elapsed_s = self.clock.now_s() - start_s;
        self.link.stats.cycles += 1;
        self.link.stats.last_cycle_s = elapsed_s;
        self.link.stats.max_cycle_s = self.link.stats.max_cycle_s.max(elapsed_s);
        if let Ok(mut state) = self.shared.lock() {
            state.stats = self.link.stats;
        }
        true
    }

    /// The channels of `address` did not answer at `now_s` \[s\]: silent since then, unless already.
    fn mark_silent(&mut self, address: u8, now_s: f64) {
        for (index, setup) in self.channels.iter().enumerate() {
            if setup.channel.address == address {
                self.silent_since[index].get_or_insert(now_s);
            }
        }
    }

    /// Sets channel `index` up again (output off first, then its limits, mode and the watchdog of its address) when
    /// its address answers after a silence longer than [`MecomConfig::link_timeout_s`] (its readings failed
    /// meanwhile): a device that restarted lost its live settings. A device found in its error state (its
    /// watchdog tripped while the host could not reach it) is reset first, and set up at a later cycle, once it
    /// answers again.
    fn set_up_again(&mut self, index: usize) -> Result<(), RequestFault> {
        if self.set_up[index] {
            return Ok(());
        }
        self.enabled[index] = false;
        let channel = self.channels[index].channel;
        let probe = MecomChannel {
            address: channel.address,
            instance: 1,
        };
        if self.link.read_i32(probe, param::DEVICE_STATUS)? == status::ERROR {
            self.link.set(probe, Request::Reset)?;
            return Err(RequestFault::NoAnswer);
        }
        let mut commands = MecomCommandSet::default();
        configure(&mut self.link, &self.config, channel, &mut commands).map_err(|setup| match setup {
            MecomSetup::Refused { why, .. } | MecomSetup::ReadObject(why) => why,
            _ => RequestFault::NoAnswer,
        })?;
        let watchdog = Request::set_f32(param::WATCHDOG_TIMEOUT, 1, self.config.watchdog_s as f32);
        self.link.set(probe, watchdog)?;
        self.set_up[index] = true;
        // Configured anew: the static pair is in force and being saved; the line starts again once it is.
        self.line[index] = LineState::default();
        self.set_written(index, (self.config.current_limit_a, self.config.upper_error_c));
        let now_s = self.clock.now_s();
        if let Some((_, flash)) = self.flash.iter_mut().find(|(a, _)| *a == channel.address) {
            if !matches!(flash, Flash::Unavailable(_)) {
                *flash = Flash::Saving { since_s: now_s };
            }
        }
        Ok(())
    }

    /// Every address of the channels starts saving its configuration at `now_s` \[s\] (the line waits for it), or,
    /// without a line, keeps the static threshold.
    fn flash_saving_from(&mut self, now_s: f64) {
        let start = match self.config.heating_line {
            Some(_) => Flash::Saving { since_s: now_s },
            None => Flash::Unavailable("no dynamic line configured"),
        };
        for setup in &self.channels {
            let address = setup.channel.address;
            if !self.flash.iter().any(|(a, _)| *a == address) {
                self.flash.push((address, start));
            }
        }
    }

    /// Whether saving to flash is off at `address` (the line may write), switching it off once the configuration
    /// is saved (flash status 109 reads 0, or 2: already off). A device that refuses either parameter, or whose save
    /// stays pending for [`FLASH_SAVE_LIMIT_S`], keeps its static threshold.
    fn flash_off(&mut self, address: u8) -> Result<bool, RequestFault> {
        let Some(index) = self.flash.iter().position(|(a, _)| *a == address) else {
            return Ok(false);
        };
        let since_s = match self.flash[index].1 {
            Flash::Off => return Ok(true),
            Flash::Unavailable(_) => return Ok(false),
            Flash::Saving { since_s } => since_s,
        };
        let probe = MecomChannel { address, instance: 1 };
        let stage = match self.link.read_i32(probe, param::FLASH_STATUS) {
            Err(why) if not_available(&why) => Flash::Unavailable("the device has no flash status (109)"),
            Err(why) => return Err(why),
            Ok(0 | 2) => match self.link.set(probe, Request::set_i32(param::FLASH_SAVE_OFF, 1, 1)) {
                Ok(()) => Flash::Off,
                Err(RequestFault::Server { .. }) => {
                    Flash::Unavailable("the device refused to switch saving to flash off (108)")
                }
                Err(why) => return Err(why),
            },
            Ok(_) if self.clock.now_s() - since_s > FLASH_SAVE_LIMIT_S => {
                Flash::Unavailable("its configuration was not saved to flash within 3 s")
            }
            Ok(_) => Flash::Saving { since_s },
        };
        self.flash[index].1 = stage;
        if let (Flash::Unavailable(why), Ok(mut state)) = (stage, self.shared.lock()) {
            state.static_line = Some(why);
        }
        Ok(stage == Flash::Off)
    }

    /// The dynamic second line of channel `index` before its drive ([`super::line`]): the gap bound accounted with
    /// the heating current in force since the last cycle, then the pair rewritten where it must change — a
    /// threshold that is no longer safe lowered, the limit lowered, a higher limit only after the threshold that is
    /// safe with it, and the threshold raised as far as the limit in force allows. Each write leaves a safe pair.
    fn keep_line(&mut self, index: usize) -> Result<(), RequestFault> {
        let Some(line) = self.config.heating_line else {
            return Ok(());
        };
        let last = self.last[index].clone();
        if last.last_answer_s.is_none() || last.device_status == status::ERROR {
            return Ok(());
        }
        if !self.flash_off(self.channels[index].channel.address)? {
            return Ok(());
        }
        let (reading_c, hot_c) = (last.object_c, last.sink_c);
        let heating_a = self.heating_a[index].max(last.current_a);
        if self.config.mode == MecomMode::Temperature {
            // The device's own loop sets its current: the last one measured is the best known till the next sample.
            self.heating_a[index] = last.current_a.max(0.0);
        }
        let now_s = self.clock.now_s();
        self.line[index].account(&line, now_s, heating_a, reading_c, hot_c);
        let state = self.line[index];
        let upper = |limit_a: f64| floor_to(state.upper_c(&line, limit_a, reading_c, hot_c), 0.01);
        let want_a = floor_to(state.limit_a(&line, reading_c, hot_c), LIMIT_STEP_A);
        let (have_a, have_c) = self.written[index];
        let safe_c = upper(have_a);
        if !safe_c.is_finite() {
            // Nothing can be judged: no heating until it can.
            return self.write_limit(index, 0.0);
        }
        if safe_c < have_c {
            self.write_upper(index, safe_c)?;
        }
        if want_a < have_a - LIMIT_STEP_A || (want_a == 0.0 && have_a > 0.0) {
            self.write_limit(index, want_a)?;
        }
        let (have_a, have_c) = self.written[index];
        if want_a > have_a + 5.0 * LIMIT_STEP_A || (want_a > have_a && want_a >= line.current_limit_a()) {
            let with_c = upper(want_a);
            if with_c < have_c {
                self.write_upper(index, with_c)?;
            }
            self.write_limit(index, want_a)?;
        }
        let (have_a, have_c) = self.written[index];
        let room_c = upper(have_a);
        if room_c >= have_c + UPPER_STEP_C {
            self.write_upper(index, room_c)?;
        }
        Ok(())
    }

    /// The line's heating limit of channel `index` set to `limit_a` \[A\]: the current limitation (2030) in
    /// temperature mode (the device's own loop sets the current), the host's bound on the live current in current
    /// mode (the device holds the last live current after a host death).
    fn write_limit(&mut self, index: usize, limit_a: f64) -> Result<(), RequestFault> {
        if self.config.mode == MecomMode::Temperature {
            let channel = self.channels[index].channel;
            let request = Request::set_f32(param::CURRENT_LIMITATION, channel.instance, limit_a as f32);
            if let Err(why) = self.link.set(channel, request) {
                self.note_failure(index, &why);
                return Err(why);
            }
        }
        let (_, upper_c) = self.written[index];
        self.set_written(index, (limit_a, upper_c));
        Ok(())
    }

    /// Channel `index`'s upper object threshold (4011) set to `upper_c` \[°C\].
    fn write_upper(&mut self, index: usize, upper_c: f64) -> Result<(), RequestFault> {
        let channel = self.channels[index].channel;
        let request = Request::set_f32(param::UPPER_ERROR_THRESHOLD, channel.instance, upper_c as f32);
        if let Err(why) = self.link.set(channel, request) {
            self.note_failure(index, &why);
            return Err(why);
        }
        let (limit_a, _) = self.written[index];
        self.set_written(index, (limit_a, upper_c));
        Ok(())
    }

    /// The pair in force on channel `index`, also as the readings' heating limit.
    fn set_written(&mut self, index: usize, pair: (f64, f64)) {
        self.written[index] = pair;
        if let Ok(mut state) = self.shared.lock() {
            if let Some(limit) = state.heating_limits_a.get_mut(index) {
                *limit = pair.0.min(self.config.current_limit_a);
            }
        }
    }

    /// Releases the device's own over- or under-temperature cut (its error state, errors 137 and 138) the way the
    /// own protocol's `ClearFault` does: once every channel of its address is commanded off (`commands`: their
    /// envelopes have faulted) and each reading is back inside the static thresholds by [`RELEASE_HYSTERESIS_C`]
    /// (after the reset the static pair is in force until the line starts again), the address is reset (`RS`) and
    /// configured again ([`Worker::set_up_again`]). The channels stay off until their faults are cleared.
    fn release_cuts(&mut self, commands: &[Command; MAX_CHANNELS]) {
        let (lower_c, upper_c) = (
            self.config.lower_error_c + RELEASE_HYSTERESIS_C,
            self.config.upper_error_c - RELEASE_HYSTERESIS_C,
        );
        let cut = |t: &Track| {
            t.device_status == status::ERROR
                && matches!(
                    t.error_number,
                    error_number::OBJECT_TOO_HIGH | error_number::OBJECT_TOO_LOW
                )
        };
        for index in 0..self.channels.len() {
            if !(self.set_up[index] && cut(&self.last[index])) {
                continue;
            }
            let address = self.channels[index].channel.address;
            let of_address: Vec<usize> = (0..self.channels.len())
                .filter(|&k| self.channels[k].channel.address == address)
                .collect();
            let released = of_address.iter().all(|&k| {
                let inside = (lower_c..=upper_c).contains(&self.last[k].object_c);
                commands[k] == Command::default() && inside
            });
            if released {
                for k in of_address {
                    self.set_up[k] = false;
                }
            }
        }
    }

    /// The static pair back on every channel whose line wrote one (the worker ends; saving to flash stays off until
    /// the device restarts, so its flash keeps the configuration's static pair).
    fn restore_static_line(&mut self) {
        let static_pair = (self.config.current_limit_a, self.config.upper_error_c);
        for index in 0..self.channels.len() {
            let (limit_a, upper_c) = self.written[index];
            if upper_c > static_pair.1 {
                let _ = self.write_upper(index, static_pair.1);
            }
            if limit_a < static_pair.0 {
                let _ = self.write_limit(index, static_pair.0);
            }
        }
    }

    fn port_failed(&mut self, fault: RequestFault) -> bool {
        if let Ok(mut state) = self.shared.lock() {
            state.error = Some(LinkFault::Request(fault));
            state.stats = self.link.stats;
        }
        false
    }

    /// Writes channel `index`'s command: the live current or target, and live enable when it changes.
    fn drive(&mut self, index: usize, command: Command) -> Result<(), RequestFault> {
        let ChannelSetup { channel, sign } = self.channels[index];
        let i = channel.instance;
        let (enable, value) = match self.config.mode {
            MecomMode::Current => {
                let limit_a = self.config.current_limit_a;
                // The dynamic line bounds heating (its limit is the host's own in current mode).
                let heating_a = limit_a.min(self.written[index].0);
                let current_a = command.current_a.clamp(-limit_a, heating_a);
                // In force from now to the next cycle (the device holds it): the line accounts it then (the larger
                // of it and the one before, should the write fail).
                self.heating_a[index] = self.heating_a[index].max(current_a);
                (
                    current_a != 0.0,
                    Request::set_f32(param::LIVE_SET_CURRENT, i, (current_a * sign) as f32),
                )
            }
            MecomMode::Temperature => match command.setpoint_c {
                Some(setpoint_c) => {
                    let target_c = setpoint_c.clamp(self.config.target_min_c, self.config.target_max_c);
                    (true, Request::set_f32(param::LIVE_TARGET, i, target_c as f32))
                }
                None => (false, Request::set_i32(param::LIVE_ENABLE, i, 0)),
            },
        };
        let result = if enable {
            self.link.set(channel, value).and_then(|()| {
                if self.enabled[index] {
                    Ok(())
                } else {
                    self.link.set(channel, Request::set_i32(param::LIVE_ENABLE, i, 1))
                }
            })
        } else {
            // Off: the enable first, then (current mode) the current to 0.
            self.link
                .set(channel, Request::set_i32(param::LIVE_ENABLE, i, 0))
                .and_then(|()| match self.config.mode {
                    MecomMode::Current => self
                        .link
                        .set(channel, Request::set_f32(param::LIVE_SET_CURRENT, i, 0.0)),
                    MecomMode::Temperature => Ok(()),
                })
        };
        match &result {
            Ok(()) => {
                self.enabled[index] = enable;
                if self.config.mode == MecomMode::Current {
                    let live_a = if enable { command.current_a } else { 0.0 };
                    self.heating_a[index] = live_a.clamp(0.0, self.written[index].0);
                }
            }
            Err(e) => self.note_failure(index, e),
        }
        result
    }

    /// Reads channel `index`'s object and sink temperature, current, voltage, status and error number.
    fn sample(&mut self, index: usize) -> Result<(), RequestFault> {
        let ChannelSetup { channel, sign } = self.channels[index];
        let read = (|| -> Result<Track, RequestFault> {
            let object_c = self.link.read_f32(channel, param::OBJECT_TEMPERATURE)?;
            Ok(Track {
                time_s: self.clock.now_s(),
                object_c,
                sink_c: self.link.read_f32(channel, param::SINK_TEMPERATURE)?,
                current_a: self.link.read_f32(channel, param::ACTUAL_OUTPUT_CURRENT)? * sign,
                voltage_v: self.voltage(index)? * sign,
                device_status: self.link.read_i32(channel, param::DEVICE_STATUS)?,
                error_number: self.link.read_i32(channel, param::ERROR_NUMBER)?,
                ..Track::default()
            })
        })();
        match read {
            Ok(new) => {
                if new.device_status == status::ERROR {
                    // The device disabled its output by itself; it stays off until thermode enables it again.
                    self.enabled[index] = false;
                }
                // The current and voltage measured now are the drive written at this cycle's start, in force from
                // now on; over the interval that ends at this sample the previous cycle's were (a reading reports
                // the current over the interval before its sample, as the simulated display does).
                let previous = &self.last[index];
                let (current_a, voltage_v) = match previous.last_answer_s {
                    Some(_) => (previous.current_a, previous.voltage_v),
                    None => (new.current_a, new.voltage_v),
                };
                self.last[index] = Track {
                    last_answer_s: Some(new.time_s),
                    ..new.clone()
                };
                if let Some(track) = self.shared.lock().ok().as_mut().and_then(|s| s.tracks.get_mut(index)) {
                    *track = Track {
                        sample_seq: track.sample_seq + 1,
                        time_s: track.time_s.max(new.time_s),
                        last_answer_s: Some(self.clock.now_s()),
                        last_failure: None,
                        current_a,
                        voltage_v,
                        ..new
                    };
                }
                Ok(())
            }
            Err(e) => {
                self.note_failure(index, &e);
                Err(e)
            }
        }
    }

    /// Channel `index`'s actual output voltage \[V\] (1021, the device's sign), or NaN once its device answered that
    /// it lacks it (an older firmware).
    fn voltage(&mut self, index: usize) -> Result<f64, RequestFault> {
        if !self.voltage[index] {
            return Ok(f64::NAN);
        }
        match self
            .link
            .read_f32(self.channels[index].channel, param::ACTUAL_OUTPUT_VOLTAGE)
        {
            Err(why) if not_available(&why) => {
                self.voltage[index] = false;
                Ok(f64::NAN)
            }
            read => read,
        }
    }

    fn note_failure(&mut self, index: usize, failure: &RequestFault) {
        if let Some(track) = self.shared.lock().ok().as_mut().and_then(|s| s.tracks.get_mut(index)) {
            track.last_failure = Some(*failure);
        }
    }

    /// Live enable 0 (and, current mode, 0 A) on every channel; true when every write was acknowledged.
    fn switch_all_off(&mut self) -> bool {
        let mut all = true;
        for index in 0..self.channels.len() {
            let ok = self.drive(index, Command::default()).is_ok();
            all &= ok;
        }
        all
    }
}

impl Recovering for MecomDevice {
    fn recovery(&mut self) -> Option<&mut Reconnector<Self>> {
        self.recovery.as_mut()
    }

    /// Why the link must go down: it failed, or fell silent for longer than the configured limit.
    fn down_reason(&mut self) -> Option<DownReason> {
        let now_s = self.clock.now_s();
        let limit_s = self.config.reconnect_after_silence_s;
        self.shared.lock().ok().and_then(|state| {
            if let Some(error) = &state.error {
                return Some(DownReason::Failed(Box::new(error.clone())));
            }
            let last_s = state
                .tracks
                .iter()
                .filter_map(|t| t.last_answer_s)
                .fold(f64::NEG_INFINITY, f64::max);
            let silent_s = now_s - last_s;
            (silent_s > limit_s).then_some(DownReason::Silent { silent_s, limit_s })
        })
    }

    /// Stops the worker (not waited for: it ends within a cycle and closes the port) and asks for a new link; the
    /// reason goes to the link's health.
    fn take_down(&mut self, reason: DownReason) {
        let fault = LinkFault::Down { reason };
        self.health
            .down(LinkError::device(&self.name, fault.clone()).to_string());
        // The readings go on failing with what took the link down (the port's failure, or no answer).
        if let Ok(mut state) = self.shared.lock() {
            state.commands = [Command::default(); MAX_CHANNELS];
        }
        self.stop.store(true, Ordering::SeqCst);
        drop(self.worker.take());
        if let Some(recovery) = &mut self.recovery {
            recovery.request();
        }
    }

    /// Takes over a freshly connected and configured link: its worker, its state, its channels' sample numbers
    /// going on from where the old link's stopped. Every command starts off; the envelopes keep their faults until
    /// the operator clears them.
    fn adopt(&mut self, mut fresh: MecomDevice) {
        if fresh.channels.len() != self.channels.len() {
            let fault = LinkFault::ChannelsChanged {
                now: fresh.channels.len(),
                before: self.channels.len(),
            };
            self.health.set_error(LinkError::device(&self.name, fault).to_string());
            if let Some(recovery) = &mut self.recovery {
                recovery.request();
            }
            return;
        }
        std::mem::swap(&mut self.shared, &mut fresh.shared);
        std::mem::swap(&mut self.stop, &mut fresh.stop);
        std::mem::swap(&mut self.worker, &mut fresh.worker);
        self.channels = fresh.channels.clone();
        self.identity = fresh.identity.clone();
        self.serials = fresh.serials.clone();
        self.commands = fresh.commands.clone();
        self.health.set_command_set(self.commands.describe());
        for (base, seen) in self.seq_base.iter_mut().zip(self.seq_seen) {
            *base = seen + 1;
        }
        // `fresh` now holds the old link's stopped worker: let it go without waiting.
        drop(fresh.worker.take());
        drop(fresh);
        if let Some(recovery) = &mut self.recovery {
            recovery.down = false;
        }
        self.health.reconnected();
    }
}

impl Device for MecomDevice {
    fn channel_count(&self) -> usize {
        self.channels.len()
    }

    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        self.supervise();
        self.check_channel(channel)?;
        let current_a = command.current_a();
        Rule::Finite.check("drive current [A]", current_a)?;
        if let Some(setpoint_c) = command.setpoint_c() {
            Rule::Finite.check("drive set-point [°C]", setpoint_c)?;
        }
        let mut state = self.lock()?;
        if let Some(error) = &state.error {
            return Err(self.error(error.clone()));
        }
        state.commands[channel] = Command {
            current_a,
            setpoint_c: command.setpoint_c(),
        };
        Ok(())
    }

    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        self.supervise();
        self.watch_addresses();
        self.note_static_line();
        self.check_channel(channel)?;
        let now_s = self.clock.now_s();
        let seq_base = self.seq_base[channel];
        let state = self.lock()?;
        if let Some(error) = &state.error {
            return Err(self.error(error.clone()));
        }
        let Some(track) = state.tracks.get(channel) else {
            return Err(DeviceError::NoSuchChannel {
                channel,
                count: self.channels.len(),
            });
        };
        let Some(last_s) = track.last_answer_s else {
            return Err(self.error(LinkFault::NoReading { channel }));
        };
        let silent_s = now_s - last_s;
        if silent_s > self.config.link_timeout_s {
            return Err(self.error(LinkFault::NotAnswered {
                channel,
                silent_s,
                timeout_s: self.config.link_timeout_s,
                why: track.last_failure.unwrap_or(RequestFault::NoAnswer),
            }));
        }
        let reading = Reading {
            sensor_c: track.object_c,
            hot_side_c: track.sink_c,
            time_s: track.time_s,
            sample_seq: seq_base + track.sample_seq,
            current_a: track.current_a,
            voltage_v: track.voltage_v,
            heating_limit_a: state.heating_limits_a[channel],
        };
        let in_error = track.device_status == status::ERROR;
        let error_number = track.error_number;
        drop(state);
        self.seq_seen[channel] = reading.sample_seq;
        if !in_error {
            return Ok(reading);
        }
        // In its error state the controller still measures its object: the cut carries the reading.
        let cut = |cut| DeviceError::Cut {
            channel,
            cut,
            reading: Some(reading),
        };
        Err(match error_number {
            error_number::OBJECT_TOO_HIGH => cut(DeviceCut::OverTemperature),
            error_number::OBJECT_TOO_LOW => cut(DeviceCut::UnderTemperature),
            number => self.error(LinkFault::ErrorState {
                number,
                meaning: describe_error(number),
            }),
        })
    }

    fn link_health(&self) -> Option<Arc<LinkHealth>> {
        Some(Arc::clone(&self.health))
    }

    /// The first address's serial number or `?IF` text ([`MecomDevice::identity_of`]); on a bus of several
    /// addresses, each part has its own.
    fn identity(&self) -> Option<String> {
        self.identity_of(self.channels.first()?.channel.address)
    }

    /// In temperature mode the controller sets the current itself (thermode's current does not reach the plate);
    /// the object and sink temperatures are measured in both modes.
    fn measures(&self) -> Measures {
        Measures {
            drive_current: self.config.mode == MecomMode::Current,
            hot_side: true,
        }
    }

    /// The worker runs in real time: nothing to do.
    fn poll(&mut self, _now_s: f64) {}

    /// One part per address on a bus (`mecom:PATH@ADDR` given several times: each address's channels, named
    /// `mecom:PATH@ADDR`, with the address's own link state); one unnamed part otherwise.
    fn parts(&self) -> Vec<DevicePart> {
        let mut parts: Vec<DevicePart> = Vec::new();
        for (index, setup) in self.channels.iter().enumerate() {
            let label = format!("{}@{}", self.name.display(), setup.channel.address);
            match parts.last_mut() {
                Some(last) if last.label == label => last.channel_count += 1,
                _ => parts.push(DevicePart {
                    label,
                    first_channel: index,
                    channel_count: 1,
                    health: Some(self.link_of(setup.channel.address)),
                    identity: self.identity_of(setup.channel.address),
                }),
            }
        }
        let mut labels: Vec<&str> = parts.iter().map(|p| p.label.as_str()).collect();
        labels.sort_unstable();
        labels.dedup();
        if self.config.bus_addresses.is_empty() || labels.len() != parts.len() {
            return vec![DevicePart {
                label: String::new(),
                first_channel: 0,
                channel_count: self.channels.len(),
                health: Some(Arc::clone(&self.health)),
                identity: Device::identity(self),
            }];
        }
        parts
    }

    /// Every output disabled (live enable 0, and 0 A in current mode); waits for the acknowledges (at most two
    /// answer timeouts per write and channel, plus a cycle).
    fn all_off(&mut self) -> Result<(), DeviceError> {
        let wanted = {
            let mut state = self.lock()?;
            state.commands = [Command::default(); MAX_CHANNELS];
            state.off_requested += 1;
            state.off_requested
        };
        let wait_s = self.config.cycle_interval_s
            + 2.0 * (1.0 + self.channels.len() as f64) * 4.0 * self.config.answer_timeout_s;
        let deadline_s = self.clock.now_s() + wait_s;
        while self.clock.now_s() < deadline_s {
            {
                let state = self.lock()?;
                if state.off_done >= wanted {
                    return Ok(());
                }
                if let Some(error) = &state.error {
                    return Err(self.error(error.clone()));
                }
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        Err(self.error(LinkFault::OffNotAcknowledged { wait_s }))
    }
}

impl Drop for MecomDevice {
    fn drop(&mut self) {
        if let Ok(mut state) = self.shared.lock() {
            state.commands = [Command::default(); MAX_CHANNELS];
        }
        self.stop.store(true, Ordering::SeqCst);
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
    }
}
