//! [`Tcs2Device`]: a QST.Lab TCS II stimulator behind a serial port (`tcs2:PATH`, 115200 8N1) in follow mode, as a
//! [`Device`] with one channel per zone (1 to 5).
//!
//! - **Connect**: `?` until the stimulator answers `TCS`; then `F` (mute: thermode asks for temperatures itself),
//!   `Om` the maximum stimulation temperature (the envelope's maximum: the stimulator refuses anything hotter),
//!   `N` the neutral temperature, `S` the zones, `V0`/`R0` rise and return speeds (the envelope's set-point rate
//!   limit, so the probe itself moves no faster than thermode allows), `D0` the longest duration, `C0` neutral,
//!   `Od` follow mode; `Q` must answer with no zone in error and `E` with temperatures.
//! - **Set-points**: the stimulator regulates its probe itself, so each zone is sent the envelope's shaped set-point
//!   of the gated command ([`DriveCommand::setpoint_c`]) as `C` (tenths of a degree) when it changes, **clamped to
//!   [`Tcs2Config::hold_max_c`]** (43 °C by default): the stimulator has no watchdog and holds its last set-point if
//!   the host disappears, so thermode streams only temperatures a finger can rest on indefinitely. A command
//!   without a set-point (off, a hold, a fault) sends the neutral temperature. [`Device::all_off`] sends `A` (leave
//!   follow mode, back to neutral); the next set-point enters follow mode again.
//! - **Readings**: `read` asks for temperatures (`E`) at most every [`Tcs2Config::poll_interval_s`] and for the
//!   error state (`Q`) every [`Tcs2Config::error_poll_interval_s`]; a reader thread classifies every line (streamed
//!   temperatures and the answers to `E` update the zones; `TCS` and `Q` answers are replies), so a stream
//!   interleaved with replies loses neither. Each temperature line is one sample of every zone (its time: arrival
//!   on the host clock). The neutral (probe) temperature reads as the hot side; the stimulator reports no current
//!   (0 A).
//! - **Errors** ([`DeviceError::Link`]): no temperature line for longer than [`Tcs2Config::link_timeout_s`], a port
//!   that fails, or a zone in error (`Q`).

use std::io::{Read, Write};
use std::sync::Arc;
use std::time::Duration;

use thermode_model::{BadValue, Rule};
use thermode_platform::Clock;
use thermode_safety::{DriveCommand, ABSOLUTE_MAX_C};

use super::codec::{
    tenths, Command, Line as TextLine, LineDecoder, TCS2_BAUD_RATE, TCS2_MAX_C, TCS2_MIN_C, TCS2_ZONES,
};
use crate::host::{self, Line, LineState, OnLine, ReaderSpec};
use thermode_device::{Awaited, Device, DeviceError, LinkFault, Measures, Reading, Silence};

/// The warmest set-point thermode streams to a TCS II in follow mode by default \[°C\]: 43 (the temperature a
/// finger can rest on indefinitely: IEC 60601-1 allows 43 °C for long skin contact, and 43 °C is CEM43's reference,
/// below which the thermal dose grows slowly).
pub const DEFAULT_HOLD_MAX_C: f64 = 43.0;

/// Settings of the TCS II host.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tcs2Config {
    /// Zones driven (channels), 1 to 5. Default 5.
    pub zones: usize,
    /// Neutral temperature \[°C\], 20 to 40: where the probe rests outside follow mode and what a command without a
    /// set-point sends. Default 32.
    pub neutral_c: f64,
    /// The warmest set-point streamed \[°C\], in \[neutral, 43\]: what the stimulator may hold when the host is gone.
    /// Default [`DEFAULT_HOLD_MAX_C`].
    pub hold_max_c: f64,
    /// The coolest set-point streamed \[°C\], in \[10, neutral\]. Default 15 (the envelope's minimum).
    pub hold_min_c: f64,
    /// The stimulator's own maximum (`Om`) \[°C\], in \[hold_max_c, 60\]. Default 48 (the envelope's maximum).
    pub max_c: f64,
    /// Rise and return speed of the probe \[°C/s\], 0.1 to 999.9. Default 10 (the envelope's set-point rate limit).
    pub speed_c_per_s: f64,
    /// Shortest interval between two temperature requests (`E`) \[s\], in \[0.001, 1\]. Default 0.01.
    pub poll_interval_s: f64,
    /// Interval between two error-state requests (`Q`) \[s\], in \[0.01, 10\]. Default 0.5.
    pub error_poll_interval_s: f64,
    /// Longest time without a temperature line before readings fail \[s\], in (0, 10]. Default 0.5.
    pub link_timeout_s: f64,
    /// Longest time for the connection \[s\], on the host clock, in (0, 60]. Default 3.
    pub handshake_timeout_s: f64,
}

impl Default for Tcs2Config {
    fn default() -> Self {
        Tcs2Config {
            zones: TCS2_ZONES,
            neutral_c: 32.0,
            hold_max_c: DEFAULT_HOLD_MAX_C,
            hold_min_c: 15.0,
            max_c: ABSOLUTE_MAX_C,
            speed_c_per_s: 10.0,
            poll_interval_s: 0.01,
            error_poll_interval_s: 0.5,
            link_timeout_s: 0.5,
            handshake_timeout_s: 3.0,
        }
    }
}

impl Tcs2Config {
    /// `Ok` if every setting is in its range.
    pub fn validate(&self) -> Result<(), DeviceError> {
        if !(1..=TCS2_ZONES).contains(&self.zones) {
            return Err(DeviceError::ChannelCount {
                count: self.zones,
                max: TCS2_ZONES,
            });
        }
        let checks = [
            ("tcs2 neutral_c [°C]", self.neutral_c, 20.0, 40.0),
            (
                "tcs2 hold_max_c [°C]",
                self.hold_max_c,
                self.neutral_c,
                DEFAULT_HOLD_MAX_C,
            ),
            ("tcs2 hold_min_c [°C]", self.hold_min_c, TCS2_MIN_C, self.neutral_c),
            ("tcs2 max_c [°C]", self.max_c, self.hold_max_c, TCS2_MAX_C),
            ("tcs2 speed_c_per_s [°C/s]", self.speed_c_per_s, 0.1, 999.9),
            ("tcs2 poll_interval_s [s]", self.poll_interval_s, 0.001, 1.0),
            ("tcs2 error_poll_interval_s [s]", self.error_poll_interval_s, 0.01, 10.0),
            ("tcs2 link_timeout_s [s]", self.link_timeout_s, 1e-9, 10.0),
            ("tcs2 handshake_timeout_s [s]", self.handshake_timeout_s, 1e-9, 60.0),
        ];
        for (name, value, min, max) in checks {
            Rule::Within { min, max }.check(name, value)?;
        }
        Ok(())
    }

    /// The set-point streamed for `command` \[°C\]: its set-point clamped to `[hold_min_c, hold_max_c]`, or neutral.
    pub fn streamed_c(&self, command: &DriveCommand) -> f64 {
        command
            .setpoint_c()
            .map_or(self.neutral_c, |c| c.clamp(self.hold_min_c, self.hold_max_c))
    }
}

/// What the host has seen and done on the link.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Tcs2Stats {
    /// Temperature lines taken (streamed and answers to `E`).
    pub temperature_lines: u64,
    /// `TCS` identity replies.
    pub identity_replies: u64,
    /// Error-state replies.
    pub error_replies: u64,
    /// Other lines.
    pub other_lines: u64,
    /// Lines dropped (too long, not ASCII).
    pub dropped_lines: u64,
    /// Temperature requests sent.
    pub polls: u64,
    /// Set-point commands sent.
    pub setpoints_sent: u64,
}

#[derive(Debug, Default)]
pub(crate) struct Shared {
    decoder: LineDecoder,
    identified: bool,
    sample_seq: u64,
    time_s: f64,
    zones_c: [f64; TCS2_ZONES],
    neutral_c: f64,
    last_line_s: Option<f64>,
    error_codes: Option<Vec<u8>>,
    stats: Tcs2Stats,
    error: Option<LinkFault>,
}

impl LineState for Shared {
    /// Splits what the stimulator sent into lines.
    fn take(&mut self, bytes: &[u8], now_s: f64) {
        let mut decoder = std::mem::take(&mut self.decoder);
        decoder.feed(bytes, |line| self.take_line(line, now_s));
        self.decoder = decoder;
    }

    fn port_fault(&self) -> Option<&LinkFault> {
        self.error.as_ref()
    }

    fn set_port_fault(&mut self, fault: LinkFault) {
        self.error = Some(fault);
    }
}

impl Shared {
    fn take_line(&mut self, line: Result<TextLine, super::codec::LineError>, now_s: f64) {
        match line {
            Ok(TextLine::Temperatures(t)) => {
                self.stats.temperature_lines += 1;
                self.sample_seq += 1;
                self.time_s = self.time_s.max(now_s);
                self.zones_c = [f64::NAN; TCS2_ZONES];
                self.zones_c[..t.zone_count].copy_from_slice(&t.zones_c[..t.zone_count]);
                self.neutral_c = t.neutral_c;
                self.last_line_s = Some(now_s);
            }
            Ok(TextLine::Identity) => {
                self.stats.identity_replies += 1;
                self.identified = true;
            }
            Ok(TextLine::ErrorState(codes)) => {
                self.stats.error_replies += 1;
                self.error_codes = Some(codes);
            }
            Ok(TextLine::Other(_)) => self.stats.other_lines += 1,
            Err(_) => self.stats.dropped_lines += 1,
        }
    }
}

/// The reader thread of a TCS II link.
const READER: ReaderSpec = ReaderSpec {
    thread: "thermode-tcs2-reader",
    buffer_len: 512,
};

/// A TCS II stimulator in follow mode. See the module documentation.
pub struct Tcs2Device {
    line: Line<Shared>,
    config: Tcs2Config,
    /// Tenths of a degree last sent per zone (None: not since follow mode was entered).
    sent: [Option<u16>; TCS2_ZONES],
    following: bool,
    last_poll_s: f64,
    last_error_poll_s: f64,
    out: Vec<u8>,
    polls: u64,
    setpoints_sent: u64,
}

impl std::fmt::Debug for Tcs2Device {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tcs2Device")
            .field("name", &self.line.name)
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

impl Tcs2Device {
    /// Opens the serial port `path` (115200 8N1), connects and enters follow mode.
    pub fn open(path: &str, config: &Tcs2Config, clock: Arc<dyn Clock>) -> Result<Self, DeviceError> {
        config.validate()?;
        let port = host::open_serial(
            path,
            TCS2_BAUD_RATE,
            Duration::from_millis(5),
            serialport::ClearBuffer::Input,
        )?;
        let streams = host::split(port, path, Duration::from_millis(50))?;
        Tcs2Device::start(
            Line::start(&format!("tcs2:{path}"), streams, clock, &READER, true)?,
            config,
        )
    }

    /// A stimulator over any byte streams, named `name` in messages (the reader should time out within a few
    /// milliseconds; it is not waited for when the device is dropped).
    pub fn from_streams(
        name: &str,
        reader: Box<dyn Read + Send>,
        writer: Box<dyn Write + Send>,
        config: &Tcs2Config,
        clock: Arc<dyn Clock>,
    ) -> Result<Self, DeviceError> {
        config.validate()?;
        Tcs2Device::start(Line::start(name, (reader, writer), clock, &READER, false)?, config)
    }

    /// The stimulator on `line`, connected and in follow mode.
    fn start(line: Line<Shared>, config: &Tcs2Config) -> Result<Self, DeviceError> {
        let mut device = Tcs2Device {
            line,
            config: *config,
            sent: [None; TCS2_ZONES],
            following: false,
            last_poll_s: f64::NEG_INFINITY,
            last_error_poll_s: f64::NEG_INFINITY,
            out: Vec::with_capacity(64),
            polls: 0,
            setpoints_sent: 0,
        };
        device.connect()?;
        Ok(device)
    }

    fn connect(&mut self) -> Result<(), DeviceError> {
        let deadline_s = self.line.deadline_s(self.config.handshake_timeout_s);
        self.wait_for(
            deadline_s,
            Command::Identify,
            |s| s.identified,
            Awaited::StimulatorIdentity,
        )?;
        let c = self.config;
        let t = |celsius: f64| tenths(celsius).unwrap_or(0);
        let speed = ((c.speed_c_per_s * 10.0).round() as u16).clamp(1, 9999);
        let mut zones = [false; TCS2_ZONES];
        zones[..c.zones].iter_mut().for_each(|z| *z = true);
        for command in [
            Command::Mute,
            Command::MaxTemperature(t(c.max_c)),
            Command::Neutral(t(c.neutral_c)),
            Command::Zones(zones),
            Command::Speed { zone: 0, tenths: speed },
            Command::ReturnSpeed { zone: 0, tenths: speed },
            Command::Duration { zone: 0, ms: 99_999 },
            Command::Target {
                zone: 0,
                tenths: t(c.neutral_c),
            },
        ] {
            self.send(command)?;
        }
        self.enter_follow()?;
        self.wait_for(
            deadline_s,
            Command::ErrorState,
            |s| s.error_codes.is_some(),
            Awaited::StimulatorErrorState,
        )?;
        let first = self.lock()?.sample_seq;
        self.wait_for(
            deadline_s,
            Command::Temperatures,
            |s| s.sample_seq > first,
            Awaited::StimulatorTemperatures,
        )?;
        if let Some(fault) = self.zone_error(None)? {
            return Err(self.line.error(fault));
        }
        Ok(())
    }

    /// Sends `command` every 0.1 s until `done` holds, or `deadline_s` on the clock.
    fn wait_for(
        &mut self,
        deadline_s: f64,
        command: Command,
        done: impl Fn(&Shared) -> bool,
        awaited: Awaited,
    ) -> Result<(), DeviceError> {
        let send = |device: &mut Tcs2Device| device.send(command);
        match host::retry_until(self, deadline_s, 0.1, send, |s| done(s).then_some(()))? {
            Some(()) => Ok(()),
            None => Err(self.line.error(LinkFault::Handshake {
                awaited,
                timeout_s: self.config.handshake_timeout_s,
                other_version: false,
            })),
        }
    }

    /// The settings.
    pub fn config(&self) -> &Tcs2Config {
        &self.config
    }

    /// What has been seen and done on the link so far.
    pub fn stats(&self) -> Tcs2Stats {
        let mut stats = self.lock().map(|s| s.stats).unwrap_or_default();
        stats.polls = self.polls;
        stats.setpoints_sent = self.setpoints_sent;
        stats
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, Shared>, DeviceError> {
        self.line.lock()
    }

    fn check_channel(&self, channel: usize) -> Result<(), DeviceError> {
        let count = self.config.zones;
        if channel < count {
            Ok(())
        } else {
            Err(DeviceError::NoSuchChannel { channel, count })
        }
    }

    fn send(&mut self, command: Command) -> Result<(), DeviceError> {
        self.line.check_failed()?;
        self.out.clear();
        command.encode(&mut self.out);
        let out = std::mem::take(&mut self.out);
        let result = self.line.write(&out);
        self.out = out;
        result
    }

    /// `Od`: follow mode.
    fn enter_follow(&mut self) -> Result<(), DeviceError> {
        self.send(Command::Follow)?;
        self.following = true;
        Ok(())
    }

    /// `E` and `Q` when due.
    fn keep_polling(&mut self) -> Result<(), DeviceError> {
        let now = self.line.clock.now_s();
        if now - self.last_poll_s >= self.config.poll_interval_s {
            self.last_poll_s = now;
            self.polls += 1;
            self.send(Command::Temperatures)?;
        }
        if now - self.last_error_poll_s >= self.config.error_poll_interval_s {
            self.last_error_poll_s = now;
            self.send(Command::ErrorState)?;
        }
        Ok(())
    }

    /// Why the neutral sensor or `channel`'s zone (all zones if None) is in error, from the last `Q` answer.
    fn zone_error(&self, channel: Option<usize>) -> Result<Option<LinkFault>, DeviceError> {
        let state = self.lock()?;
        let Some(codes) = &state.error_codes else {
            return Ok(None);
        };
        let zones = match channel {
            Some(ch) => ch..ch + 1,
            None => 0..self.config.zones,
        };
        let neutral = codes.first().copied().unwrap_or(0);
        let bad = zones
            .filter_map(|z| codes.get(z + 1).map(|&c| (z, c)))
            .find(|&(_, c)| c != 0);
        Ok(match (neutral, bad) {
            (0, None) => None,
            (code, _) if code != 0 => Some(LinkFault::Stimulator { zone: None, code }),
            (_, Some((z, code))) => Some(LinkFault::Stimulator {
                zone: Some(z + 1),
                code,
            }),
            _ => None,
        })
    }
}

impl OnLine for Tcs2Device {
    type State = Shared;

    fn line(&self) -> &Line<Shared> {
        &self.line
    }
}

impl Device for Tcs2Device {
    fn channel_count(&self) -> usize {
        self.config.zones
    }

    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        self.check_channel(channel)?;
        if let Some(setpoint_c) = command.setpoint_c() {
            Rule::Finite.check("drive set-point [°C]", setpoint_c)?;
        }
        let streamed_c = self.config.streamed_c(command);
        let t = tenths(streamed_c)
            .ok_or_else(|| BadValue::custom("TCS II set-point [°C]", streamed_c, "must be from 10 to 60"))?;
        if !self.following {
            if command.setpoint_c().is_none() {
                // Out of follow mode the probe already rests at neutral.
                return self.keep_polling();
            }
            // Every zone to neutral first: the stimulator keeps the stimulation temperatures of the last follow mode,
            // and `Od` would send every zone back to them.
            let neutral = tenths(self.config.neutral_c).unwrap_or(0);
            self.send(Command::Target {
                zone: 0,
                tenths: neutral,
            })?;
            self.sent = [Some(neutral); TCS2_ZONES];
            self.send(Command::Target {
                zone: channel as u8 + 1,
                tenths: t,
            })?;
            self.sent[channel] = Some(t);
            self.setpoints_sent += 2;
            self.enter_follow()?;
        } else if self.sent[channel] != Some(t) {
            self.send(Command::Target {
                zone: channel as u8 + 1,
                tenths: t,
            })?;
            self.sent[channel] = Some(t);
            self.setpoints_sent += 1;
        }
        self.keep_polling()
    }

    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        self.check_channel(channel)?;
        self.keep_polling()?;
        if let Some(fault) = self.zone_error(Some(channel))? {
            return Err(self.line.error(fault));
        }
        let now_s = self.line.clock.now_s();
        let state = self.lock()?;
        self.line.check_port(&state)?;
        let Some(last_s) = state.last_line_s else {
            return Err(self.line.error(LinkFault::NothingYet {
                silence: Silence::Temperatures,
            }));
        };
        let silent_s = now_s - last_s;
        if silent_s > self.config.link_timeout_s {
            return Err(self.line.error(LinkFault::Silent {
                silence: Silence::Temperatures,
                silent_s,
                timeout_s: self.config.link_timeout_s,
            }));
        }
        let sensor_c = state.zones_c[channel];
        if !sensor_c.is_finite() {
            return Err(self.line.error(LinkFault::NoZone { zone: channel + 1 }));
        }
        Ok(Reading {
            sensor_c,
            hot_side_c: state.neutral_c,
            time_s: state.time_s,
            sample_seq: state.sample_seq,
            // The stimulator sets its current itself and reports none.
            current_a: f64::NAN,
            voltage_v: f64::NAN,
            heating_limit_a: f64::INFINITY,
        })
    }

    /// A real stimulator runs in real time: nothing to do.
    fn poll(&mut self, _now_s: f64) {}

    /// The stimulator regulates its zones itself and reports no current and no hot side (the reading's hot side is
    /// its neutral temperature, a stand-in for the envelope's checks).
    fn measures(&self) -> Measures {
        Measures {
            drive_current: false,
            hot_side: false,
        }
    }

    /// `A`: leave follow mode, every zone back to neutral.
    fn all_off(&mut self) -> Result<(), DeviceError> {
        self.following = false;
        self.sent = [None; TCS2_ZONES];
        self.send(Command::Abort)
    }
}

impl Drop for Tcs2Device {
    /// `A` (back to neutral) unless the link failed; the reader ends with its field.
    fn drop(&mut self) {
        if self.line.failed.is_none() {
            let _ = self.send(Command::Abort);
        }
    }
}
