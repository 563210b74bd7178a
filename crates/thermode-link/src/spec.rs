//! The `--device` spellings of real displays and opening the device one names ([`open_hardware`]):
//!
//! | spelling | device |
//! | --- | --- |
//! | `serial:PATH` | thermode's own protocol ([`crate::own::host::SerialDevice`]) |
//! | `mecom:PATH[@ADDR][?OPTIONS]` | Meerstetter TEC controller(s) over a serial port ([`crate::mecom::host::MecomDevice`]); `@ADDR`: the instances of the device at RS-485 address ADDR (as `address=ADDR`) |
//! | `mecom-tcp:HOST:PORT[?OPTIONS]` | the same over TCP |
//! | `tcs2:PATH[?OPTIONS]` | QST.Lab TCS II in follow mode ([`crate::tcs2::host::Tcs2Device`]) |
//!
//! OPTIONS are `key=value` pairs joined by `&`. MeCom: `mode=current|temperature` (default current),
//! `channels=ADDRESS:INSTANCE,…` (default: every instance of address 0), `baud=N` (default 57600), `watchdog=S`
//! (the device's communication watchdog, 0.1 to 0.25 s; default 0.25). TCS II: `zones=N` (1 to 5; default 5),
//! `hold_max=C` (the warmest set-point streamed, at most 43 °C; default 43), `neutral=C` (20 to 40 °C; default 32).
//! Everything else follows the device file and the envelope ([`HardwareContext`]).
//!
//! A display of several devices ([`open_display`], `--device` given several times) is a
//! [`thermode_device::CompositeDevice`] of their channels in order; `mecom:PATH@ADDR` spellings of one PATH are one
//! bus: one MeCom host owns the port and asks every address in turn (requests one at a time, answers matched by
//! address and sequence number), the channels of each address in the order the spellings come.

use std::ops::Range;
use std::sync::Arc;

use thermode_device::{CalibrationRefusal, CompositeDevice, Device, DeviceConfig, DeviceError, LinkError, SpecFault};
use thermode_platform::Clock;
use thermode_safety::EnvelopeConfig;

use crate::mecom::host::{
    lower_error_threshold_c, upper_error_threshold_c, MecomChannel, MecomConfig, MecomDevice, MecomMode,
};
use crate::mecom::line::HeatingLine;
use crate::own::guard::own_cut_allows;
use crate::own::host::{SerialConfig, SerialDevice, SERIAL_PREFIX};
use crate::tcs2::codec::TCS2_MIN_C;
use crate::tcs2::host::{Tcs2Config, Tcs2Device, DEFAULT_HOLD_MAX_C};

/// Prefix of a MeCom serial device: `mecom:`.
pub const MECOM_PREFIX: &str = "mecom:";
/// Prefix of a MeCom TCP device: `mecom-tcp:`.
pub const MECOM_TCP_PREFIX: &str = "mecom-tcp:";
/// Prefix of a TCS II device: `tcs2:`.
pub const TCS2_PREFIX: &str = "tcs2:";

/// What thermode knows of the display besides the device's spelling: the device file (current limit, module
/// voltage) and the safety envelope (limits the device's own protection is set to).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HardwareContext {
    /// The device file.
    pub device: DeviceConfig,
    /// The envelope every channel runs.
    pub envelope: EnvelopeConfig,
}

/// Whether `spec` names a real display (any spelling of the table above).
pub fn is_hardware(spec: &str) -> bool {
    [SERIAL_PREFIX, MECOM_PREFIX, MECOM_TCP_PREFIX, TCS2_PREFIX]
        .iter()
        .any(|p| spec.starts_with(p))
}

fn bad_spec(spec: &str, fault: SpecFault) -> DeviceError {
    LinkError::Spec {
        spec: spec.into(),
        fault,
    }
    .into()
}

/// The byte range of `part`, a slice of `spec`, in `spec`.
fn span(spec: &str, part: &str) -> Range<usize> {
    let start = (part.as_ptr() as usize)
        .saturating_sub(spec.as_ptr() as usize)
        .min(spec.len());
    start..(start + part.len()).min(spec.len())
}

/// The spelling's option `key` has the value `value` (a slice of `spec`), which is wrong as `requirement` says.
fn bad_value(spec: &str, key: &'static str, value: &str, requirement: &'static str) -> DeviceError {
    let value = span(spec, value);
    bad_spec(
        spec,
        SpecFault::BadValue {
            key,
            value,
            requirement,
        },
    )
}

/// `key=value` options, in order.
type Options<'a> = Vec<(&'a str, &'a str)>;

/// Splits `rest` into the target and its `key=value` options.
fn split_options<'a>(spec: &str, rest: &'a str) -> Result<(&'a str, Options<'a>), DeviceError> {
    let (target, options) = rest.split_once('?').unwrap_or((rest, ""));
    if target.is_empty() {
        return Err(bad_spec(spec, SpecFault::NoTarget));
    }
    let mut pairs = Vec::new();
    for pair in options.split('&').filter(|p| !p.is_empty()) {
        let (key, value) = pair.split_once('=').ok_or_else(|| {
            bad_spec(
                spec,
                SpecFault::NotKeyValue {
                    option: span(spec, pair),
                },
            )
        })?;
        pairs.push((key, value));
    }
    Ok((target, pairs))
}

fn number(spec: &str, key: &'static str, value: &str) -> Result<f64, DeviceError> {
    value
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| bad_value(spec, key, value, " is not a number"))
}

/// The lower and upper object temperature error thresholds \[°C\] a MeCom controller of the device file `device`
/// is set to, on its own reading: [`lower_error_threshold_c`] and [`upper_error_threshold_c`] through the file's
/// calibration, the more cautious of both scales.
pub fn mecom_thresholds_on_reading_c(device: &DeviceConfig) -> Result<(f64, f64), DeviceError> {
    let calibration = &device.calibration;
    Ok((
        calibration.lower_line_on_reading_c(lower_error_threshold_c(device)?),
        calibration.upper_line_on_reading_c(upper_error_threshold_c(device)?),
    ))
}

/// The MeCom settings of `spec`'s options over the defaults of `context`. The device compares only its own
/// reading, so each of its lines (object thresholds, largest change, temperature mode's target range) is put on
/// that reading's scale through the device file's calibration, the more cautious of both scales
/// ([`thermode_device::config::CalibrationConfig::upper_line_on_reading_c`]).
pub fn mecom_config(
    spec: &str,
    options: &[(&str, &str)],
    context: &HardwareContext,
) -> Result<MecomConfig, DeviceError> {
    let (calibration, envelope) = (&context.device.calibration, &context.envelope);
    let (lower_error_c, upper_error_c) = mecom_thresholds_on_reading_c(&context.device)?;
    let mut config = MecomConfig {
        current_limit_a: context.device.drive.current_limit_a,
        voltage_limit_v: context.device.peltier.vmax_v,
        lower_error_c,
        upper_error_c,
        max_change_c_per_s: calibration
            .rate_on_reading_c_per_s(envelope.max_measured_rate_c_per_s)
            .clamp(1.0, 200.0),
        target_min_c: calibration.lower_line_on_reading_c(envelope.min_display_c),
        target_max_c: calibration.upper_line_on_reading_c(envelope.max_display_c),
        // The dynamic line works on the device's raw reading against the true plate's limit: with a calibration
        // the static thresholds (on the more cautious of both scales) are the line.
        heating_line: match calibration.is_set() {
            true => None,
            false => Some(HeatingLine::new(&context.device).map_err(DeviceError::from)?),
        },
        ..MecomConfig::default()
    };
    for &(key, value) in options {
        match key {
            "mode" => {
                config.mode = match value {
                    "current" => MecomMode::Current,
                    "temperature" => MecomMode::Temperature,
                    _ => return Err(bad_value(spec, "mode", value, ": use current or temperature")),
                }
            }
            "channels" => {
                config.channels = value
                    .split(',')
                    .map(|pair| {
                        let parsed = pair
                            .split_once(':')
                            .and_then(|(a, i)| Some((a.parse::<u8>().ok()?, i.parse::<u8>().ok()?)));
                        parsed
                            .map(|(address, instance)| MecomChannel { address, instance })
                            .ok_or_else(|| {
                                bad_spec(
                                    spec,
                                    SpecFault::NotAChannel {
                                        channel: span(spec, pair),
                                    },
                                )
                            })
                    })
                    .collect::<Result<_, _>>()?;
            }
            "baud" => {
                config.baud_rate = value
                    .parse()
                    .map_err(|_| bad_value(spec, "baud", value, " is not a whole number"))?;
            }
            "watchdog" => config.watchdog_s = number(spec, "watchdog", value)?,
            "address" => {
                config.discover_address = value
                    .parse()
                    .map_err(|_| bad_value(spec, "address", value, " is not 0 to 254"))?;
            }
            _ => {
                return Err(bad_spec(
                    spec,
                    SpecFault::UnknownOption {
                        protocol: "MeCom",
                        key: span(spec, key),
                    },
                ))
            }
        }
    }
    config.validate()?;
    Ok(config)
}

/// The path and settings of the MeCom serial spelling `spec` (`rest`: after the prefix): `PATH[@ADDR][?OPTIONS]`.
fn mecom_serial<'a>(
    spec: &str,
    rest: &'a str,
    context: &HardwareContext,
) -> Result<(&'a str, MecomConfig), DeviceError> {
    let (target, options) = split_options(spec, rest)?;
    let (path, address) = match target.rsplit_once('@') {
        Some((path, address)) if !path.is_empty() => (path, Some(address)),
        _ => (target, None),
    };
    let mut config = mecom_config(spec, &options, context)?;
    if let Some(address) = address {
        config.discover_address = address
            .parse()
            .ok()
            .filter(|a| (1..=254).contains(a))
            .ok_or_else(|| bad_value(spec, "@", address, " is not an address from 1 to 254"))?;
    }
    Ok((path, config))
}

/// Opens the display the spellings `specs` name (each as [`open_hardware`] takes it): one device as it opens it;
/// several as one [`CompositeDevice`] of their channels in order, named by their spellings. The `mecom:PATH@ADDR`
/// spellings of one PATH (same options but the address) are one bus device whose channels are each address's
/// instances, where the first of them stands.
pub fn open_display(
    specs: &[String],
    context: &HardwareContext,
    clock: Arc<dyn Clock>,
) -> Result<Box<dyn Device + Send>, DeviceError> {
    if let [spec] = specs {
        return open_hardware(spec, context, clock);
    }
    let mut members: Vec<(String, Box<dyn Device + Send>)> = Vec::new();
    for (index, spec) in specs.iter().enumerate() {
        if let Some(bus) = bus_of(specs, index, context)? {
            let (label, config, path) = bus;
            members.push((
                label,
                Box::new(MecomDevice::open_serial(&path, &config, Arc::clone(&clock))?),
            ));
        } else if !joins_earlier_bus(specs, index, context) {
            members.push((spec.clone(), open_hardware(spec, context, Arc::clone(&clock))?));
        }
    }
    Ok(Box::new(CompositeDevice::new(members)?))
}

/// A MeCom serial spelling's path and settings (None for any other spelling).
fn as_mecom(spec: &str, context: &HardwareContext) -> Result<Option<(String, MecomConfig)>, DeviceError> {
    match spec.strip_prefix(MECOM_PREFIX) {
        Some(rest) => mecom_serial(spec, rest, context).map(|(p, c)| Some((p.to_string(), c))),
        None => Ok(None),
    }
}

/// The bus that starts at `specs[index]`: its label, settings and path, when that spelling is the first of two or
/// more MeCom spellings on its path (None otherwise).
fn bus_of(
    specs: &[String],
    index: usize,
    context: &HardwareContext,
) -> Result<Option<(String, MecomConfig, String)>, DeviceError> {
    let Some((path, mut config)) = as_mecom(&specs[index], context)? else {
        return Ok(None);
    };
    if joins_earlier_bus(specs, index, context) {
        return Ok(None);
    }
    let mut labels = vec![specs[index].clone()];
    for spec in &specs[index + 1..] {
        if let Some((other, more)) = as_mecom(spec, context)? {
            if other == path {
                if !more.channels.is_empty() || !config.channels.is_empty() {
                    return Err(bad_spec(spec, SpecFault::BusWithChannels));
                }
                config.bus_addresses.push(more.discover_address);
                labels.push(spec.clone());
            }
        }
    }
    Ok((labels.len() > 1).then(|| (labels.join(" + "), config, path)))
}

/// Whether `specs[index]` is a MeCom spelling on the path of an earlier one (it joined that one's bus).
fn joins_earlier_bus(specs: &[String], index: usize, context: &HardwareContext) -> bool {
    let path_of = |spec: &String| as_mecom(spec, context).ok().flatten().map(|(path, _)| path);
    let Some(path) = path_of(&specs[index]) else {
        return false;
    };
    specs[..index]
        .iter()
        .any(|earlier| path_of(earlier).as_ref() == Some(&path))
}

/// The TCS II settings of `spec`'s options over the defaults of `context`. The stimulator regulates and clamps on its
/// own reading, so its lines (the warmest and coolest set-points streamed, `Om`) are put on that reading's scale
/// through the device file's calibration, the more cautious of both scales
/// ([`thermode_device::config::CalibrationConfig::upper_line_on_reading_c`]): a zone that reads 5 °C low,
/// honestly calibrated, holds at most a true 43 °C when the host is gone, and so does an honest zone under a
/// calibration that lies.
pub fn tcs2_config(spec: &str, options: &[(&str, &str)], context: &HardwareContext) -> Result<Tcs2Config, DeviceError> {
    let envelope = &context.envelope;
    let mut config = Tcs2Config {
        speed_c_per_s: envelope.max_setpoint_rate_c_per_s.clamp(0.1, 999.9),
        ..Tcs2Config::default()
    };
    for &(key, value) in options {
        match key {
            "zones" => {
                config.zones = value
                    .parse()
                    .map_err(|_| bad_value(spec, "zones", value, " is not 1 to 5"))?;
            }
            "hold_max" => config.hold_max_c = number(spec, "hold_max", value)?,
            "neutral" => config.neutral_c = number(spec, "neutral", value)?,
            _ => {
                return Err(bad_spec(
                    spec,
                    SpecFault::UnknownOption {
                        protocol: "TCS II",
                        key: span(spec, key),
                    },
                ))
            }
        }
    }
    let calibration = &context.device.calibration;
    let hold_max_c = config.hold_max_c.min(DEFAULT_HOLD_MAX_C).min(envelope.max_display_c);
    config.hold_max_c = calibration.upper_line_on_reading_c(hold_max_c);
    config.max_c = calibration.upper_line_on_reading_c(envelope.max_display_c.max(hold_max_c));
    config.hold_min_c = calibration
        .lower_line_on_reading_c(envelope.min_display_c.max(TCS2_MIN_C))
        .min(config.neutral_c);
    if config.hold_max_c < config.neutral_c {
        return Err(CalibrationRefusal::NeutralAboveHold {
            neutral_c: config.neutral_c,
            hold_max_c: config.hold_max_c,
        }
        .into());
    }
    config.validate()?;
    Ok(config)
}

/// Opens the real display `spec` names (see the module documentation), with its readings on `clock`.
pub fn open_hardware(
    spec: &str,
    context: &HardwareContext,
    clock: Arc<dyn Clock>,
) -> Result<Box<dyn Device + Send>, DeviceError> {
    if let Some(rest) = spec.strip_prefix(SERIAL_PREFIX) {
        if rest.is_empty() {
            return Err(bad_spec(spec, SpecFault::NoPath));
        }
        own_cut_allows(&context.device.calibration)?;
        return Ok(Box::new(SerialDevice::open(rest, &SerialConfig::default(), clock)?));
    }
    if let Some(rest) = spec.strip_prefix(MECOM_TCP_PREFIX) {
        let (address, options) = split_options(spec, rest)?;
        let config = mecom_config(spec, &options, context)?;
        return Ok(Box::new(MecomDevice::open_tcp(address, &config, clock)?));
    }
    if let Some(rest) = spec.strip_prefix(MECOM_PREFIX) {
        let (path, config) = mecom_serial(spec, rest, context)?;
        return Ok(Box::new(MecomDevice::open_serial(path, &config, clock)?));
    }
    if let Some(rest) = spec.strip_prefix(TCS2_PREFIX) {
        let (path, options) = split_options(spec, rest)?;
        let config = tcs2_config(spec, &options, context)?;
        return Ok(Box::new(Tcs2Device::open(path, &config, clock)?));
    }
    Err(bad_spec(spec, SpecFault::NotHardware))
}
