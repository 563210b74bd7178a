//! The TCS II stimulator's side of its serial protocol, emulated over a [`SimulatedDisplay`] (one zone per
//! channel, 1 to 5), so the TCS II host ([`super::host::Tcs2Device`]) is tested without hardware.
//!
//! What it emulates: `?` (answers `TCS`), `N` neutral temperature, `S` zones, `C` stimulation temperatures
//! (limited to `Om`), `V`/`R` rise and return speeds, `D` durations (stored), `Om` maximum temperature, `Od` follow
//! mode (each zone's target ramps at its speed to its stimulation temperature and stays there), `A` (leave follow
//! mode: back to neutral at the return speed), `F` mute, `Oa`/`Ob` streams, `E` temperatures once, `Q` error state.
//! Each zone's plate is driven by the emulator's own PI controller on its sensor towards the ramped target, within
//! the display's current limit (its sensor may err, [`Tcs2EmulatorConfig::sensor`]: the stimulator then regulates,
//! clamps and reports on the wrong reading). Like the stimulator, it has **no communication watchdog**: with the host gone it
//! holds the last stimulation temperature for ever.
//!
//! Temperatures stream, unless muted, once a second outside follow mode and at 100 Hz in follow mode (the
//! stimulator's "between" and "during" stimulation rates); [`Tcs2EmulatorConfig::forced_stream_hz`] makes it stream
//! even when muted (a test of the host's separation of streamed lines from replies). Unknown bytes are skipped and
//! counted.

use thermode_device::{Device, PlateFinger, SimulatedDisplay};

use super::codec::{parse_command, Command, ParseStep, Temperatures, TCS2_ZONES};
use crate::runner::EmulatorError;
use crate::runner::{merged_step_s, tick_at, Firmware, FirmwareStatus, SensorError, Trace};

/// Settings of the emulated stimulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tcs2EmulatorConfig {
    /// Tick of the stimulator loop and the plant \[s\], 1e-4 to 0.01. Default 0.001.
    pub tick_s: f64,
    /// Stream temperature lines at this rate \[Hz\] even when muted (a test hook), or None. Default None.
    pub forced_stream_hz: Option<f64>,
    /// Proportional gain of the zone controllers \[A/K\]. Default 0.4.
    pub kp_a_per_k: f64,
    /// Integral time of the zone controllers \[s\]. Default 2.
    pub ti_s: f64,
    /// The zones' sensor error: each reads `gain · T + offset_c` at T, and the stimulator regulates, clamps and
    /// reports on that reading. Default none (gain 1, offset 0).
    pub sensor: SensorError,
}

impl Default for Tcs2EmulatorConfig {
    fn default() -> Self {
        Tcs2EmulatorConfig {
            tick_s: 1e-3,
            forced_stream_hz: None,
            kp_a_per_k: 0.4,
            ti_s: 2.0,
            sensor: SensorError::default(),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Zone {
    enabled: bool,
    /// Stimulation temperature \[°C\] (`C`, limited to `Om`).
    stimulation_c: f64,
    /// The ramped target the controller follows \[°C\].
    target_c: f64,
    rise_c_per_s: f64,
    return_c_per_s: f64,
    duration_ms: u32,
    integral_a: f64,
    applied_a: f64,
}

/// The emulated stimulator around a simulated display of fingers `F`.
#[derive(Debug)]
pub struct Tcs2Emulator<F> {
    display: SimulatedDisplay<F>,
    config: Tcs2EmulatorConfig,
    zones: Vec<Zone>,
    neutral_c: f64,
    max_c: f64,
    follow: bool,
    muted: bool,
    stream_between: bool,
    stream_during: bool,
    pending: Vec<u8>,
    tick: u64,
    last_stream_s: f64,
    commands: u64,
    skipped_bytes: u64,
    lines_out: u64,
    trace: Option<Trace>,
}

impl<F: PlateFinger> Tcs2Emulator<F> {
    /// The stimulator around `display` (1 to 5 channels), at time 0, neutral 32 °C, not in follow mode.
    pub fn new(display: SimulatedDisplay<F>, config: Tcs2EmulatorConfig) -> Result<Self, EmulatorError> {
        let bad = |what: &'static str, value: f64, requirement: &'static str| EmulatorError::BadSetting {
            what,
            value,
            requirement,
        };
        if display.channel_count() > TCS2_ZONES {
            return Err(bad(
                "channels",
                display.channel_count() as f64,
                "a TCS II probe has 1 to 5 zones",
            ));
        }
        if !(1e-4..=0.01).contains(&config.tick_s) {
            return Err(bad("tick_s", config.tick_s, "must be from 1e-4 to 0.01"));
        }
        config.sensor.check()?;
        if let Some(hz) = config.forced_stream_hz {
            if !(hz.is_finite() && hz > 0.0 && hz <= 1000.0) {
                return Err(bad("forced_stream_hz", hz, "must lie in (0, 1000]"));
            }
        }
        let neutral_c = 32.0;
        let zones = (0..display.channel_count())
            .map(|_| Zone {
                enabled: true,
                stimulation_c: neutral_c,
                target_c: neutral_c,
                rise_c_per_s: 20.0,
                return_c_per_s: 20.0,
                duration_ms: 1000,
                integral_a: 0.0,
                applied_a: 0.0,
            })
            .collect();
        Ok(Tcs2Emulator {
            display,
            config,
            zones,
            neutral_c,
            max_c: 60.0,
            follow: false,
            muted: false,
            stream_between: true,
            stream_during: true,
            pending: Vec::new(),
            tick: 0,
            last_stream_s: 0.0,
            commands: 0,
            skipped_bytes: 0,
            lines_out: 0,
            trace: None,
        })
    }

    crate::runner::display_accessors!();
    crate::runner::trace_accessors!();

    /// Whether it is in follow mode.
    pub fn following(&self) -> bool {
        self.follow
    }

    /// The maximum stimulation temperature (`Om`) \[°C\].
    pub fn max_c(&self) -> f64 {
        self.max_c
    }

    /// The neutral temperature (`N`) \[°C\].
    pub fn neutral_c(&self) -> f64 {
        self.neutral_c
    }

    /// The stimulation temperature of zone `index` (from 0) \[°C\].
    pub fn stimulation_c(&self, index: usize) -> Option<f64> {
        self.zones.get(index).map(|z| z.stimulation_c)
    }

    /// Rise and return speed of zone `index` \[°C/s\].
    pub fn speeds_c_per_s(&self, index: usize) -> Option<(f64, f64)> {
        self.zones.get(index).map(|z| (z.rise_c_per_s, z.return_c_per_s))
    }

    fn temperatures(&self) -> Temperatures {
        let mut zones_c = [f64::NAN; TCS2_ZONES];
        for (i, slot) in zones_c.iter_mut().enumerate().take(self.zones.len()) {
            if let Ok(channel) = self.display.channel(i) {
                *slot = self.config.sensor.reads_c(channel.state().sensor.value_c);
            }
        }
        let neutral_c = self
            .display
            .channel(0)
            .map_or(self.neutral_c, |c| c.hot_side_reading_c());
        Temperatures {
            neutral_c,
            zones_c,
            zone_count: TCS2_ZONES,
        }
        .with_zones(self.zones.len())
    }

    fn send_line(&mut self, text: &str, out: &mut Vec<u8>) {
        out.push(b'\r');
        out.extend_from_slice(text.as_bytes());
        self.lines_out += 1;
    }

    fn execute(&mut self, command: Command, out: &mut Vec<u8>) {
        self.commands += 1;
        let zones = |zone: u8, count: usize| -> std::ops::Range<usize> {
            match zone {
                0 => 0..count,
                z => {
                    let i = usize::from(z - 1).min(count);
                    i..(i + 1).min(count)
                }
            }
        };
        let count = self.zones.len();
        match command {
            Command::Identify => self.send_line("TCS", out),
            Command::Mute => self.muted = true,
            Command::StreamBetween => {
                self.muted = false;
                self.stream_between = true;
            }
            Command::StreamDuring => {
                self.muted = false;
                self.stream_during = true;
            }
            Command::Neutral(t) if (200..=400).contains(&t) => self.neutral_c = f64::from(t) / 10.0,
            Command::Zones(flags) => {
                for (zone, on) in self.zones.iter_mut().zip(flags) {
                    zone.enabled = on;
                }
            }
            Command::Target { zone, tenths } if (100..=600).contains(&tenths) => {
                let c = (f64::from(tenths) / 10.0).min(self.max_c);
                for i in zones(zone, count) {
                    self.zones[i].stimulation_c = c;
                }
            }
            Command::Speed { zone, tenths } if tenths >= 1 => {
                for i in zones(zone, count) {
                    self.zones[i].rise_c_per_s = f64::from(tenths) / 10.0;
                }
            }
            Command::ReturnSpeed { zone, tenths } if tenths >= 1 => {
                for i in zones(zone, count) {
                    self.zones[i].return_c_per_s = f64::from(tenths) / 10.0;
                }
            }
            Command::Duration { zone, ms } if ms >= 1 => {
                for i in zones(zone, count) {
                    self.zones[i].duration_ms = ms;
                }
            }
            Command::MaxTemperature(t) => {
                self.max_c = f64::from(t) / 10.0;
                for zone in &mut self.zones {
                    zone.stimulation_c = zone.stimulation_c.min(self.max_c);
                }
            }
            Command::Follow => self.follow = true,
            Command::Abort => self.follow = false,
            Command::Temperatures => {
                let line = self.temperatures().to_line();
                self.send_line(&line, out);
            }
            Command::ErrorState => {
                let mut codes = String::from("0");
                for i in 0..TCS2_ZONES {
                    let bad = self
                        .display
                        .channel(i)
                        .is_ok_and(|c| !(-20.0..=90.0).contains(&self.config.sensor.reads_c(c.state().sensor.value_c)));
                    codes.push(if bad { '1' } else { '0' });
                }
                self.send_line(&codes, out);
            }
            // Arguments out of the stimulator's ranges: ignored.
            _ => self.commands -= 1,
        }
    }

    fn step(&mut self, dt_s: f64) {
        let (follow, neutral_c, sensor) = (self.follow, self.neutral_c, self.config.sensor);
        for (i, zone) in self.zones.iter_mut().enumerate() {
            let Ok(channel) = self.display.channel_mut(i) else {
                continue;
            };
            let goal_c = if follow && zone.enabled {
                zone.stimulation_c
            } else {
                neutral_c
            };
            let away = (goal_c - neutral_c).abs() >= (zone.target_c - neutral_c).abs();
            let speed = if away { zone.rise_c_per_s } else { zone.return_c_per_s };
            let step_c = speed * dt_s;
            zone.target_c += (goal_c - zone.target_c).clamp(-step_c, step_c);
            let limit_a = channel.config().drive.current_limit_a;
            let error_c = zone.target_c - sensor.reads_c(channel.state().sensor.value_c);
            let p_a = self.config.kp_a_per_k * error_c;
            if (p_a + zone.integral_a).abs() < limit_a {
                zone.integral_a += self.config.kp_a_per_k * error_c * dt_s / self.config.ti_s;
            }
            let current_a = (p_a + zone.integral_a).clamp(-limit_a, limit_a);
            let current_a = if current_a.is_finite() { current_a } else { 0.0 };
            // The clamp: the zone stays between where its target was and where it goes. No heating at or above the
            // higher of the two, no cooling at or below the lower (the plate has no mass beyond its own node, so it
            // stops within a tick's rise), and the integral holds while clamped. The stimulator knows its plate only
            // through its sensor (without the lag: its clamp reads fast), errors included.
            let plate_c = sensor.reads_c(channel.state().plate_c);
            let clamped = (current_a > 0.0 && plate_c >= goal_c.max(zone.target_c))
                || (current_a < 0.0 && plate_c <= goal_c.min(zone.target_c));
            let current_a = if clamped {
                zone.integral_a -= self.config.kp_a_per_k * error_c * dt_s / self.config.ti_s;
                0.0
            } else {
                current_a
            };
            zone.applied_a = channel.step(dt_s, current_a).applied_current_a;
        }
        if let Some(trace) = &mut self.trace {
            trace.step(self.tick as f64 * self.config.tick_s, &self.display);
        }
    }

    fn stream(&mut self, now_s: f64, out: &mut Vec<u8>) {
        let hz = match self.config.forced_stream_hz {
            Some(hz) => hz,
            None if self.muted => return,
            None if self.follow && self.stream_during => 100.0,
            None if !self.follow && self.stream_between => 1.0,
            None => return,
        };
        if now_s - self.last_stream_s >= 1.0 / hz - 1e-9 {
            self.last_stream_s = now_s;
            let line = self.temperatures().to_line();
            self.send_line(&line, out);
        }
    }
}

impl Temperatures {
    fn with_zones(mut self, count: usize) -> Self {
        self.zone_count = count.clamp(1, TCS2_ZONES);
        self
    }
}

impl<F: PlateFinger + Send> Firmware for Tcs2Emulator<F> {
    fn receive(&mut self, bytes: &[u8], now_s: f64, out: &mut Vec<u8>) {
        self.advance_to(now_s, out);
        self.pending.extend_from_slice(bytes);
        let mut start = 0;
        loop {
            match parse_command(&self.pending[start..]) {
                ParseStep::Incomplete => break,
                ParseStep::Command(command, len) => {
                    start += len;
                    self.execute(command, out);
                }
                ParseStep::Skip(len) => {
                    start += len;
                    self.skipped_bytes += len as u64;
                }
            }
        }
        self.pending.drain(..start.min(self.pending.len()));
        // A stuck partial command cannot grow without bound.
        if self.pending.len() > 64 {
            self.skipped_bytes += self.pending.len() as u64;
            self.pending.clear();
        }
    }

    fn advance_to(&mut self, now_s: f64, out: &mut Vec<u8>) {
        let Some(target) = tick_at(now_s, self.config.tick_s) else {
            return;
        };
        if let Some(dt_s) = merged_step_s(self.tick, target, self.config.tick_s) {
            self.tick = target;
            self.step(dt_s);
        }
        while self.tick < target {
            self.tick += 1;
            self.step(self.config.tick_s);
        }
        self.stream(self.time_s(), out);
    }

    fn tick_s(&self) -> f64 {
        self.config.tick_s
    }

    fn status(&self) -> FirmwareStatus {
        let zone = |i: usize| self.zones.get(i).map_or((0.0, false), |zone| (zone.applied_a, true));
        let mut status = FirmwareStatus::of_display(&self.display, self.zones.len(), self.time_s(), zone);
        status.frames_in = self.commands;
        status.frames_refused = self.skipped_bytes;
        status.frames_out = self.lines_out;
        status
    }
}
