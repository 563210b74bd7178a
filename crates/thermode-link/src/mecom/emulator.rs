//! The device side of MeCom, emulated: a Meerstetter-style TEC controller of one address with one instance per
//! channel of a [`SimulatedDisplay`], answering frames byte for byte as the published protocol describes
//! ([`super`] lists the sources), so the MeCom host ([`super::host::MecomDevice`]) is tested without hardware.
//!
//! What it emulates, per instance (channel):
//! - the parameters thermode reads and writes ([`super::codec::payload::param`]): identity `?IF`, device type, status and
//!   error number, object (the plate's sensor reading) and sink (hot-side reading) temperature, target, actual
//!   current and voltage; input selection (static, live current, temperature controller), output stage enable
//!   (static off/on, live off/on), current and voltage limitation, positive-current sign, object temperature error
//!   thresholds, error auto-restart delay, the communication watchdog, and the volatile live parameters;
//! - the output stage: the selected current (static, live, or its own PI temperature controller on the object
//!   reading, towards the live or stored target) clamped to the current limitation, only while enabled and not in
//!   the error state;
//! - the error state (status 3, output disabled, latched): the object reading above the upper threshold (error
//!   138) or below the lower one (137), or no valid frame for longer than the watchdog timeout (183; every valid
//!   frame to its address feeds it, whichever client sends it, as on the device). It holds
//!   until `RS` resets the device (volatile parameters back to their reset state) or the auto-restart delay passes;
//! - answers: values, acknowledges (the set command's CRC in place of a payload and frame CRC), server errors (`+01` unknown command, `+04` format,
//!   `+05` unknown parameter, `+06` read only, `+07` out of range, `+08` no such instance). Frames with a bad CRC
//!   or for another address get no answer, as on the device.
//!
//! With [`MecomEmulatorConfig::old_firmware`] it answers as an older firmware without the newer commands
//! (`?VM` and three newer parameters refused as not available).
//!
//! **Flash.** The stored (non-live) parameters live in RAM and in a flash copy: while saving to flash is on (108 = 0,
//! the power-up state) every stored parameter set is also written to the copy (counted:
//! [`FirmwareStatus::stored_writes`]) and the flash status (109) reads 1 "pending" for 0.5 s after it, then 0 "all
//! saved"; with 108 = 1 the parameters are RAM only and 109 reads 2 "disabled". `RS` restarts the device as the real
//! one does: the stored parameters come back from the flash copy, saving to flash is on again, the live ones reset.
//!
//! Not emulated: error 139 (temperature changing too fast; the threshold is stored), the voltage limitation's
//! effect (stored), the bootloader, `?VB`/`VB` big data (answered `+01`).
//!
//! [`MecomBus`] puts several of them on one port at their own addresses (an RS-485 bus).
//!
//! Time runs in fixed ticks (default 1 ms) as in [`crate::own::emulator`]; answers leave as soon as their frame is read.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use thermode_device::{Device, DeviceError, PlateFinger, SimulatedDisplay, MAX_CHANNELS};
use thermode_model::peltier::PeltierModule;

use super::codec::frame::{encode_ack, encode_frame, FrameDecoder, DEVICE_CONTROL, HOST_CONTROL};
use super::codec::payload::{error_number, param, status, Request};
use crate::runner::EmulatorError;
use crate::runner::{merged_step_s, tick_at, Firmware, FirmwareStatus, SensorError, Trace};

/// How long the flash status reads "pending" after a stored parameter was set \[s\]: 0.5 (the controller saves
/// about 0.5 s after the last change).
const FLASH_SAVE_S: f64 = 0.5;

/// The identity the emulator answers to `?IF` (20 characters).
pub const EMULATOR_IDENTITY: &str = "thermode-TEC EMU G01";

/// Settings of the emulated controller.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MecomEmulatorConfig {
    /// Device address, 1 to 254 (frames to address 0 are answered too). Default 1.
    pub address: u8,
    /// Device type answered for parameter 100. Default 1122 (a two-channel TEC controller; the emulator has as many
    /// instances as the display has channels).
    pub device_type: i32,
    /// Tick of the device loop and the plant \[s\], 1e-4 to 0.01. Default 0.001.
    pub tick_s: f64,
    /// Proportional gain of the emulated temperature controller \[A/K\], positive. Default 0.4.
    pub kp_a_per_k: f64,
    /// Integral time of the emulated temperature controller \[s\], positive. Default 2.
    pub ti_s: f64,
    /// Behave like an older firmware without the newer commands: `?VM` (metadata) answered "command not available"
    /// (server error 1); the max object temperature change (4012), the live set voltage (50002) and the actual
    /// output voltage (1021) answered "parameter not available" (5). Default false.
    pub old_firmware: bool,
    /// The object temperature sensor's error: it reports `gain · T + offset_c` for a sensor at T, and the device
    /// regulates and compares its thresholds on that reading. Default none (gain 1, offset 0).
    pub sensor: SensorError,
}

impl Default for MecomEmulatorConfig {
    fn default() -> Self {
        MecomEmulatorConfig {
            address: 1,
            device_type: 1122,
            tick_s: 1e-3,
            kp_a_per_k: 0.4,
            ti_s: 2.0,
            old_firmware: false,
            sensor: SensorError::default(),
        }
    }
}

/// Whether an older firmware ([`MecomEmulatorConfig::old_firmware`]) lacks `request`.
fn lacks(request: &Request) -> bool {
    match *request {
        Request::Meta { .. } => true,
        Request::Read { id, .. } | Request::Set { id, .. } => matches!(
            id,
            param::MAX_TEMP_CHANGE | param::LIVE_SET_VOLTAGE | param::ACTUAL_OUTPUT_VOLTAGE
        ),
        Request::Identify | Request::Reset => false,
    }
}

/// One instance's parameters and controller state.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Instance {
    input_selection: i32,
    output_enable: i32,
    static_current_a: f32,
    current_limit_a: f32,
    voltage_limit_v: f32,
    positive_heats: i32,
    target_c: f32,
    lower_error_c: f32,
    upper_error_c: f32,
    max_change_c_per_s: f32,
    restart_delay_s: f32,
    live_enable: i32,
    live_current_a: f32,
    live_voltage_v: f32,
    target_source: i32,
    live_target_c: f32,
    /// Integral part of the PI controller \[A\] (heat-positive).
    integral_a: f64,
    /// Heat-positive current delivered in the last step \[A\].
    applied_a: f64,
    resistance_ohm: f64,
    hardware_limit_a: f64,
}

impl Instance {
    fn new(hardware_limit_a: f64, resistance_ohm: f64) -> Self {
        Instance {
            input_selection: 2,
            output_enable: 0,
            static_current_a: 0.0,
            current_limit_a: hardware_limit_a as f32,
            voltage_limit_v: 5.0,
            positive_heats: 1,
            target_c: 25.0,
            lower_error_c: -10.0,
            upper_error_c: 100.0,
            max_change_c_per_s: 100.0,
            restart_delay_s: 5.0,
            live_enable: 0,
            live_current_a: 0.0,
            live_voltage_v: 0.0,
            target_source: 0,
            live_target_c: 0.0,
            integral_a: 0.0,
            applied_a: 0.0,
            resistance_ohm,
            hardware_limit_a,
        }
    }

    /// The volatile parameters back to their reset state.
    fn reset_volatile(&mut self) {
        self.live_enable = 0;
        self.live_current_a = 0.0;
        self.live_voltage_v = 0.0;
        self.target_source = 0;
        self.live_target_c = 0.0;
        self.integral_a = 0.0;
    }

    fn enabled(&self) -> bool {
        match self.output_enable {
            1 => true,
            2 => self.live_enable == 1,
            _ => false,
        }
    }

    fn sign(&self) -> f64 {
        if self.positive_heats == 1 {
            1.0
        } else {
            -1.0
        }
    }

    fn active_target_c(&self) -> f64 {
        f64::from(if self.target_source == 1 {
            self.live_target_c
        } else {
            self.target_c
        })
    }
}

/// The emulated controller around a simulated display of fingers `F`.
#[derive(Debug)]
pub struct MecomEmulator<F> {
    display: SimulatedDisplay<F>,
    config: MecomEmulatorConfig,
    decoder: FrameDecoder,
    instances: Vec<Instance>,
    watchdog_s: f32,
    /// Parameter 108: 0 saving to flash on, 1 RAM only.
    save_to_flash: i32,
    /// The flash copy of the stored parameters (every instance's, and the watchdog).
    flash: (Vec<Instance>, f32),
    /// Device time until which the flash status reads "pending" \[s\].
    flash_pending_until_s: f64,
    /// Stored parameters written to the flash copy.
    stored_writes: u64,
    last_valid_s: f64,
    /// The error state: (error number, instance) and when it began.
    error: Option<(i32, u8, f64)>,
    tick: u64,
    frames_in: u64,
    frames_refused: u64,
    frames_out: u64,
    resets: u64,
    trace: Option<Trace>,
}

impl<F: PlateFinger> MecomEmulator<F> {
    /// The controller around `display`, at time 0, every output off.
    pub fn new(display: SimulatedDisplay<F>, config: MecomEmulatorConfig) -> Result<Self, EmulatorError> {
        let bad = |what: &'static str, value: f64, requirement: &'static str| EmulatorError::BadSetting {
            what,
            value,
            requirement,
        };
        if !(1e-4..=0.01).contains(&config.tick_s) {
            return Err(bad("tick_s", config.tick_s, "must be from 1e-4 to 0.01"));
        }
        if !(config.kp_a_per_k.is_finite() && config.kp_a_per_k > 0.0) {
            return Err(bad("kp_a_per_k", config.kp_a_per_k, "must be positive"));
        }
        if !(config.ti_s.is_finite() && config.ti_s > 0.0) {
            return Err(bad("ti_s", config.ti_s, "must be positive"));
        }
        config.sensor.check()?;
        if config.address == 0 || config.address == 255 {
            return Err(bad("address", f64::from(config.address), "must be from 1 to 254"));
        }
        let mut instances = Vec::with_capacity(display.channel_count());
        for i in 0..display.channel_count() {
            let channel = display.channel(i)?;
            let module = PeltierModule::from_datasheet(&channel.config().peltier).map_err(DeviceError::from)?;
            instances.push(Instance::new(
                channel.config().drive.current_limit_a,
                module.resistance_ohm,
            ));
        }
        Ok(MecomEmulator {
            display,
            config,
            decoder: FrameDecoder::new(HOST_CONTROL),
            flash: (instances.clone(), 0.0),
            instances,
            watchdog_s: 0.0,
            save_to_flash: 0,
            flash_pending_until_s: 0.0,
            stored_writes: 0,
            last_valid_s: 0.0,
            error: None,
            tick: 0,
            frames_in: 0,
            frames_refused: 0,
            frames_out: 0,
            resets: 0,
            trace: None,
        })
    }

    crate::runner::display_accessors!();
    crate::runner::trace_accessors!();

    /// The error state's number, if the device is in it.
    pub fn error_number(&self) -> Option<i32> {
        self.error.map(|(number, _, _)| number)
    }

    /// The communication watchdog timeout in force \[s\] (0: off).
    pub fn watchdog_s(&self) -> f64 {
        f64::from(self.watchdog_s)
    }

    /// How often `RS` reset the device.
    pub fn resets(&self) -> u64 {
        self.resets
    }

    /// Whether the output of `channel` is enabled (and the device not in its error state).
    pub fn output_on(&self, channel: usize) -> bool {
        self.error.is_none() && self.instances.get(channel).is_some_and(Instance::enabled)
    }

    /// Current limitation of `channel` \[A\] (parameter 2030).
    pub fn current_limit_a(&self, channel: usize) -> Option<f64> {
        self.instances.get(channel).map(|i| f64::from(i.current_limit_a))
    }

    /// Object temperature error thresholds of `channel` \[°C\], (lower, upper).
    pub fn error_thresholds_c(&self, channel: usize) -> Option<(f64, f64)> {
        self.instances
            .get(channel)
            .map(|i| (f64::from(i.lower_error_c), f64::from(i.upper_error_c)))
    }

    /// The error state's auto-restart delay of `channel` \[s\] (0: off).
    pub fn restart_delay_s(&self, channel: usize) -> Option<f64> {
        self.instances.get(channel).map(|i| f64::from(i.restart_delay_s))
    }

    fn step_plant(&mut self, dt_s: f64) {
        let now_s = self.time_s();
        // The device sees its sensor's reading, errors included.
        let sensor = self.config.sensor;
        for (i, inst) in self.instances.iter_mut().enumerate() {
            let Ok(channel) = self.display.channel_mut(i) else {
                continue;
            };
            let sensor_c = sensor.reads_c(channel.state().sensor.value_c);
            let limit_a = f64::from(inst.current_limit_a).min(inst.hardware_limit_a);
            let heat_a = if self.error.is_some() || !inst.enabled() {
                inst.integral_a = 0.0;
                0.0
            } else {
                match inst.input_selection {
                    0 => f64::from(inst.static_current_a) * inst.sign(),
                    1 => f64::from(inst.live_current_a) * inst.sign(),
                    2 => {
                        let error_c = inst.active_target_c() - sensor_c;
                        let p_a = self.config.kp_a_per_k * error_c;
                        let unclamped = p_a + inst.integral_a;
                        // Anti-windup: integrate only while the output is not pushed further into its limit.
                        if unclamped.abs() < limit_a || unclamped.signum() != error_c.signum() {
                            inst.integral_a += self.config.kp_a_per_k * error_c * dt_s / self.config.ti_s;
                            inst.integral_a = inst.integral_a.clamp(-limit_a, limit_a);
                        }
                        p_a + inst.integral_a
                    }
                    _ => 0.0,
                }
            };
            let heat_a = if heat_a.is_finite() {
                heat_a.clamp(-limit_a, limit_a)
            } else {
                0.0
            };
            let state = channel.step(dt_s, heat_a);
            inst.applied_a = state.applied_current_a;
            let reading_c = sensor.reads_c(state.sensor.value_c);
            if self.error.is_none() {
                if reading_c > f64::from(inst.upper_error_c) {
                    self.error = Some((error_number::OBJECT_TOO_HIGH, (i + 1) as u8, now_s));
                } else if reading_c < f64::from(inst.lower_error_c) {
                    self.error = Some((error_number::OBJECT_TOO_LOW, (i + 1) as u8, now_s));
                }
            }
        }
        if let Some(trace) = &mut self.trace {
            trace.step(now_s, &self.display);
        }
    }

    fn check_watchdog_and_restart(&mut self, now_s: f64) {
        if self.error.is_none() && self.watchdog_s > 0.0 && now_s - self.last_valid_s > f64::from(self.watchdog_s) {
            self.error = Some((error_number::WATCHDOG, 1, now_s));
        }
        if let Some((_, instance, since_s)) = self.error {
            let delay_s = self
                .instances
                .get(usize::from(instance).saturating_sub(1))
                .map_or(0.0, |i| f64::from(i.restart_delay_s));
            if delay_s > 0.0 && now_s - since_s > delay_s {
                self.error = None;
                self.last_valid_s = now_s;
            }
        }
    }

    fn handle(&mut self, address: u8, seq: u16, payload: &str, crc: u16, now_s: f64, out: &mut Vec<u8>) {
        self.frames_in += 1;
        self.last_valid_s = now_s;
        let answer = match Request::parse(payload) {
            Err(code) => format!("+{code:02X}"),
            Ok(request) if self.config.old_firmware && lacks(&request) => match request {
                Request::Meta { .. } => "+01".to_string(),
                _ => "+05".to_string(),
            },
            Ok(Request::Identify) => EMULATOR_IDENTITY.to_string(),
            Ok(Request::Reset) => {
                self.reset(now_s);
                String::new()
            }
            Ok(Request::Read { id, instance }) => match self.read(id, instance) {
                Ok(bits) => format!("{bits:08X}"),
                Err(code) => format!("+{code:02X}"),
            },
            Ok(Request::Meta { id, instance }) => match self.meta(id, instance) {
                Ok(text) => text,
                Err(code) => format!("+{code:02X}"),
            },
            Ok(Request::Set { id, instance, value }) => match self.set(id, instance, value) {
                Ok(()) => {
                    self.save_if_stored(id, now_s);
                    String::new()
                }
                Err(code) => format!("+{code:02X}"),
            },
        };
        if answer.is_empty() {
            // An acknowledge: the set command's CRC in place of a payload and frame CRC.
            encode_ack(address, seq, crc, out);
        } else {
            encode_frame(DEVICE_CONTROL, address, seq, &answer, out);
        }
        self.frames_out += 1;
    }

    /// After parameter `id` was set at `now_s` \[s\]: a stored parameter goes to the flash copy while saving is on.
    fn save_if_stored(&mut self, id: u16, now_s: f64) {
        let live = id == param::FLASH_SAVE_OFF || (50000..=50099).contains(&id);
        if live || self.save_to_flash != 0 {
            return;
        }
        self.flash = (self.instances.clone(), self.watchdog_s);
        self.stored_writes += 1;
        self.flash_pending_until_s = now_s + FLASH_SAVE_S;
    }

    /// `RS`: the device restarts: stored parameters from the flash copy, saving to flash on, live parameters reset.
    fn reset(&mut self, now_s: f64) {
        self.resets += 1;
        self.error = None;
        self.last_valid_s = now_s;
        let (stored, watchdog_s) = &self.flash;
        for (inst, saved) in self.instances.iter_mut().zip(stored) {
            *inst = Instance {
                applied_a: inst.applied_a,
                ..*saved
            };
            inst.reset_volatile();
        }
        self.watchdog_s = *watchdog_s;
        self.save_to_flash = 0;
    }

    /// Parameter 109: 0 all saved, 1 a save pending, 2 saving disabled.
    fn flash_status(&self) -> i32 {
        if self.save_to_flash != 0 {
            2
        } else if self.time_s() < self.flash_pending_until_s {
            1
        } else {
            0
        }
    }

    fn instance(&self, instance: u8) -> Result<&Instance, u8> {
        usize::from(instance)
            .checked_sub(1)
            .and_then(|i| self.instances.get(i))
            .ok_or(8)
    }

    fn instance_mut(&mut self, instance: u8) -> Result<&mut Instance, u8> {
        usize::from(instance)
            .checked_sub(1)
            .and_then(|i| self.instances.get_mut(i))
            .ok_or(8)
    }

    /// The 32 bits of parameter `id` of `instance`, or a server error code.
    fn read(&self, id: u16, instance: u8) -> Result<u32, u8> {
        let inst = *self.instance(instance)?;
        let channel = self.display.channel(usize::from(instance) - 1).map_err(|_| 8u8)?;
        let state = channel.state();
        let f = |v: f64| Ok((v as f32).to_bits());
        let i = |v: i32| Ok(v as u32);
        match id {
            param::DEVICE_TYPE => i(self.config.device_type),
            101 | 103 => i(100),
            param::SERIAL_NUMBER => i(4242),
            param::DEVICE_STATUS => i(if self.error.is_some() {
                status::ERROR
            } else if self.instances.iter().any(Instance::enabled) {
                status::RUN
            } else {
                status::READY
            }),
            param::ERROR_NUMBER => i(self.error.map_or(0, |(n, _, _)| n)),
            106 => i(self.error.map_or(0, |(_, inst, _)| i32::from(inst))),
            107 => i(0),
            param::FLASH_SAVE_OFF => i(self.save_to_flash),
            param::FLASH_STATUS => i(self.flash_status()),
            param::OBJECT_TEMPERATURE => f(self.config.sensor.reads_c(state.sensor.value_c)),
            param::SINK_TEMPERATURE => f(channel.hot_side_reading_c()),
            param::TARGET_OBJECT_TEMPERATURE => f(inst.active_target_c()),
            param::ACTUAL_OUTPUT_CURRENT => f(inst.applied_a * inst.sign()),
            param::ACTUAL_OUTPUT_VOLTAGE => {
                f(channel
                    .module()
                    .voltage_v(inst.applied_a, state.plate_c, state.hot_side_c)
                    * inst.sign())
            }
            param::INPUT_SELECTION => i(inst.input_selection),
            param::OUTPUT_STAGE_ENABLE => i(inst.output_enable),
            2020 => Ok(inst.static_current_a.to_bits()),
            param::CURRENT_LIMITATION => Ok(inst.current_limit_a.to_bits()),
            param::VOLTAGE_LIMITATION => Ok(inst.voltage_limit_v.to_bits()),
            param::WATCHDOG_TIMEOUT if instance == 1 => Ok(self.watchdog_s.to_bits()),
            3000 => Ok(inst.target_c.to_bits()),
            param::POSITIVE_CURRENT_IS => i(inst.positive_heats),
            param::LOWER_ERROR_THRESHOLD => Ok(inst.lower_error_c.to_bits()),
            param::UPPER_ERROR_THRESHOLD => Ok(inst.upper_error_c.to_bits()),
            param::MAX_TEMP_CHANGE => Ok(inst.max_change_c_per_s.to_bits()),
            param::ERROR_RESTART_DELAY => Ok(inst.restart_delay_s.to_bits()),
            param::LIVE_ENABLE => i(inst.live_enable),
            param::LIVE_SET_CURRENT => Ok(inst.live_current_a.to_bits()),
            param::LIVE_SET_VOLTAGE => Ok(inst.live_voltage_v.to_bits()),
            param::TARGET_SOURCE => i(inst.target_source),
            param::LIVE_TARGET => Ok(inst.live_target_c.to_bits()),
            param::WATCHDOG_TIMEOUT => Err(8),
            _ => Err(5),
        }
    }

    /// `?VM`: type, flags, instances, elements, min, max, actual (as in 5117C §3.2.3).
    fn meta(&self, id: u16, instance: u8) -> Result<String, u8> {
        let bits = self.read(id, instance)?;
        let int = matches!(
            id,
            100..=109
                | param::INPUT_SELECTION
                | param::OUTPUT_STAGE_ENABLE
                | param::POSITIVE_CURRENT_IS
                | param::LIVE_ENABLE
                | param::TARGET_SOURCE
        );
        let writable = !matches!(id, 100..=107 | 1000..=1099);
        let (min, max) = if int {
            (0x8000_0000u32, 0x7FFF_FFFFu32)
        } else {
            (0xFF80_0000, 0x7F80_0000)
        };
        let instances = if id == param::WATCHDOG_TIMEOUT || (100..=109).contains(&id) {
            1
        } else {
            self.instances.len()
        };
        // Type enumeration: FLOAT32 0, INT32 1; flags: bit 0 read, bit 1 write.
        Ok(format!(
            "{:02X}{:02X}{:02X}{:08X}{min:08X}{max:08X}{bits:08X}",
            u8::from(int),
            if writable { 3 } else { 1 },
            instances,
            1
        ))
    }

    /// Sets parameter `id` of `instance` from its 32 bits, or a server error code.
    fn set(&mut self, id: u16, instance: u8, value: u32) -> Result<(), u8> {
        let int = value as i32;
        let float = f32::from_bits(value);
        let in_range = |v: f32, min: f32, max: f32| {
            if v.is_finite() && v >= min && v <= max {
                Ok(v)
            } else {
                Err(7u8)
            }
        };
        let choice = |v: i32, max: i32| if (0..=max).contains(&v) { Ok(v) } else { Err(7u8) };
        match id {
            100..=107 | param::FLASH_STATUS | 1000..=1099 => {
                self.instance(instance)?;
                return Err(6);
            }
            param::FLASH_SAVE_OFF => {
                self.instance(instance)?;
                self.save_to_flash = choice(int, 1)?;
                return Ok(());
            }
            param::WATCHDOG_TIMEOUT => {
                if instance != 1 {
                    return Err(8);
                }
                if float != 0.0 {
                    in_range(float, 0.1, 600.0)?;
                }
                self.watchdog_s = float;
                return Ok(());
            }
            _ => {}
        }
        let inst = self.instance_mut(instance)?;
        let hardware_a = inst.hardware_limit_a as f32;
        match id {
            param::INPUT_SELECTION => inst.input_selection = choice(int, 2)?,
            param::OUTPUT_STAGE_ENABLE => inst.output_enable = choice(int, 3)?,
            2020 => inst.static_current_a = in_range(float, -hardware_a, hardware_a)?,
            param::CURRENT_LIMITATION => inst.current_limit_a = in_range(float, 0.0, hardware_a)?,
            param::VOLTAGE_LIMITATION => inst.voltage_limit_v = in_range(float, 0.0, 30.0)?,
            3000 => inst.target_c = in_range(float, -273.0, 1000.0)?,
            param::POSITIVE_CURRENT_IS => inst.positive_heats = choice(int, 1)?,
            param::LOWER_ERROR_THRESHOLD => inst.lower_error_c = in_range(float, -273.0, 1000.0)?,
            param::UPPER_ERROR_THRESHOLD => inst.upper_error_c = in_range(float, -273.0, 1000.0)?,
            param::MAX_TEMP_CHANGE => inst.max_change_c_per_s = in_range(float, 1.0, 200.0)?,
            param::ERROR_RESTART_DELAY => inst.restart_delay_s = in_range(float, 0.0, 86_400.0)?,
            param::LIVE_ENABLE => inst.live_enable = choice(int, 1)?,
            param::LIVE_SET_CURRENT => inst.live_current_a = in_range(float, -hardware_a, hardware_a)?,
            param::LIVE_SET_VOLTAGE => inst.live_voltage_v = in_range(float, 0.0, 30.0)?,
            param::TARGET_SOURCE => inst.target_source = choice(int, 1)?,
            param::LIVE_TARGET => inst.live_target_c = in_range(float, -273.0, 1000.0)?,
            _ => return Err(5),
        }
        Ok(())
    }
}

impl<F: PlateFinger + Send> Firmware for MecomEmulator<F> {
    fn receive(&mut self, bytes: &[u8], now_s: f64, out: &mut Vec<u8>) {
        self.advance_to(now_s, out);
        let now_s = self.time_s().max(now_s);
        for &byte in bytes {
            match self.decoder.push(byte) {
                Some(Ok(frame)) if frame.address == self.config.address || frame.address == 0 => {
                    self.handle(frame.address, frame.seq, &frame.payload, frame.crc, now_s, out);
                }
                // Another device's frame: not ours to answer, and no proof the host is alive for us.
                Some(Ok(_)) => {}
                Some(Err(_)) => self.frames_refused += 1,
                None => {}
            }
        }
    }

    fn advance_to(&mut self, now_s: f64, _out: &mut Vec<u8>) {
        let Some(target) = tick_at(now_s, self.config.tick_s) else {
            return;
        };
        // Beyond 0.1 s behind, the plant takes one merged step.
        if let Some(dt_s) = merged_step_s(self.tick, target, self.config.tick_s) {
            self.tick = target;
            self.check_watchdog_and_restart(self.time_s());
            self.step_plant(dt_s);
            return;
        }
        while self.tick < target {
            self.tick += 1;
            self.check_watchdog_and_restart(self.time_s());
            self.step_plant(self.config.tick_s);
        }
    }

    fn tick_s(&self) -> f64 {
        self.config.tick_s
    }

    fn status(&self) -> FirmwareStatus {
        let on = |inst: &Instance| self.error.is_none() && inst.enabled();
        let instance = |i: usize| {
            self.instances
                .get(i)
                .map_or((0.0, false), |inst| (inst.applied_a, on(inst)))
        };
        let mut status = FirmwareStatus::of_display(&self.display, self.instances.len(), self.time_s(), instance);
        status.frames_in = self.frames_in;
        status.frames_refused = self.frames_refused;
        status.frames_out = self.frames_out;
        status.error = self.error_number();
        status.stored_writes = self.stored_writes;
        status
    }
}

/// Several emulated controllers on one RS-485 bus (one port): every byte from the host reaches each, and the one at
/// the frame's address answers (as on a bus, where the others stay quiet). Each can be muted (it hears and answers
/// nothing, its time runs on: its watchdog trips), a device unplugged from the bus.
pub struct MecomBus {
    devices: Vec<(Box<dyn Firmware>, Arc<AtomicBool>)>,
}

impl MecomBus {
    /// A bus of `devices` (each at its own address); their channels follow one another in the status.
    pub fn new(devices: Vec<Box<dyn Firmware>>) -> Self {
        MecomBus {
            devices: devices
                .into_iter()
                .map(|d| (d, Arc::new(AtomicBool::new(false))))
                .collect(),
        }
    }

    /// The switch that mutes device `index` (true: unplugged), if there is one.
    pub fn mute(&self, index: usize) -> Option<Arc<AtomicBool>> {
        self.devices.get(index).map(|(_, muted)| Arc::clone(muted))
    }
}

impl Firmware for MecomBus {
    fn receive(&mut self, bytes: &[u8], now_s: f64, out: &mut Vec<u8>) {
        for (device, muted) in &mut self.devices {
            if muted.load(Ordering::SeqCst) {
                device.advance_to(now_s, &mut Vec::new());
            } else {
                device.receive(bytes, now_s, out);
            }
        }
    }

    fn advance_to(&mut self, now_s: f64, out: &mut Vec<u8>) {
        for (device, _) in &mut self.devices {
            device.advance_to(now_s, out);
        }
    }

    fn tick_s(&self) -> f64 {
        self.devices
            .iter()
            .map(|(d, _)| d.tick_s())
            .fold(f64::INFINITY, f64::min)
    }

    /// The devices' channels one after the other (as many as fit), their counters summed, the first error.
    fn status(&self) -> FirmwareStatus {
        let mut all = FirmwareStatus::new(0);
        for (device, _) in &self.devices {
            let one = device.status();
            all.time_s = one.time_s;
            for i in 0..one.channel_count {
                let Some(slot) = (all.channel_count < MAX_CHANNELS).then_some(all.channel_count) else {
                    break;
                };
                all.plate_c[slot] = one.plate_c[i];
                all.applied_a[slot] = one.applied_a[i];
                all.output_on[slot] = one.output_on[i];
                all.channel_count += 1;
            }
            all.frames_in += one.frames_in;
            all.frames_refused += one.frames_refused;
            all.frames_out += one.frames_out;
            all.error = all.error.or(one.error);
        }
        all
    }
}
