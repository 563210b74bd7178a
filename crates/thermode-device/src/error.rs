//! Typed errors of the device layer: bad channel numbers, bad values handed to a device, bad faults, bad
//! configuration, link failures of real devices, a device whose watchdog is too slow, a channel that a device's
//! own protection cut ([`DeviceCut`]), and a calibration a device's own lines cannot follow
//! ([`CalibrationRefusal`]).

use std::path::PathBuf;

use thermode_model::{BadValue, ParamError};
use thiserror::Error;

use crate::link_error::LinkError;

/// Why a device operation was refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DeviceError {
    /// A channel index outside `0..count`.
    #[error("channel {channel} does not exist (the device has {count} channels)")]
    NoSuchChannel {
        /// The index asked for.
        channel: usize,
        /// How many channels the device has.
        count: usize,
    },
    /// A display must have between 1 and [`crate::MAX_CHANNELS`] channels.
    #[error("a display has 1 to {max} channels, not {count}")]
    ChannelCount {
        /// The number asked for.
        count: usize,
        /// The most allowed.
        max: usize,
    },
    /// A number handed to the device is not finite or out of its range.
    #[error(transparent)]
    BadValue(#[from] BadValue),
    /// The device configuration was refused.
    #[error(transparent)]
    Config(#[from] ParamError),
    /// A real device could not be reached or answered wrongly.
    #[error("device link: {0}")]
    Link(#[from] LinkError),
    /// A real device announced a watchdog period longer than the host accepts: after the host's last frame its
    /// drives would stay on for longer than `max_ms`.
    #[error(
        "{}: the device's watchdog is {device_ms} ms, longer than the {max_ms} ms this host accepts (its drives \
         must go off within {max_ms} ms of the host's last frame); set the device's watchdog to at most {max_ms} ms",
        device.display()
    )]
    WatchdogTooLong {
        /// The device (e.g. its port's path).
        device: PathBuf,
        /// The period it announced \[ms\].
        device_ms: u16,
        /// The longest period the host accepts \[ms\].
        max_ms: u16,
    },
    /// The device file's calibration asks more of a device's own line than the device can follow.
    #[error(transparent)]
    Calibration(#[from] CalibrationRefusal),
    /// The device's own protection latched part of a channel's drive off; the channel takes no drive until the
    /// device releases the cut.
    #[error("channel {channel}: {cut}")]
    Cut {
        /// The channel.
        channel: usize,
        /// What the device cut.
        cut: DeviceCut,
        /// The channel's newest reading, where the device goes on measuring while cut (a MeCom controller in its
        /// error state, thermode's own firmware): the plate is still seen, so its thermal dose is counted from it
        /// and not at a bound on unseen time.
        reading: Option<crate::reading::Reading>,
    },
}

/// A device file's calibration (`[calibration]`, `thermode calibrate`) that a device's own line cannot follow: the
/// device compares only its own reading, and where it does not let the host move its line, a calibration that says
/// the reading errs outward there by more than the line's margin would let the true plate pass it.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum CalibrationRefusal {
    /// A cut fixed in the device's firmware (thermode's own protocol: 48 °C and 10 °C on its own reading), which
    /// the calibration would move beyond its margin on the true scale.
    #[error(
        "the device file's calibration (gain {gain}, offset {offset_c} °C) says the plate sensor reads {error_c:+.2} \
         °C off at {line_c} °C, so the device's own cut, fixed in its firmware at {line_c} °C on its own reading (the \
         host cannot move it), would come at a true {true_c:.2} °C, more than {margin_c} K beyond {line_c} °C: \
         refused; check the sensor's mount and the reference thermometer, and calibrate again"
    )]
    BeyondFixedCut {
        /// The calibration's gain \[-\].
        gain: f64,
        /// The calibration's offset \[°C\].
        offset_c: f64,
        /// The firmware's line \[°C\] (on its reading).
        line_c: f64,
        /// What the sensor reads less the truth at the line, as the calibration has it \[K\].
        error_c: f64,
        /// The true plate at which the cut would come \[°C\].
        true_c: f64,
        /// How far beyond its line the cut may come on the true scale \[K\].
        margin_c: f64,
    },
    /// A stimulator's neutral temperature (where its probe rests, and stays when the host is gone) above the
    /// warmest set-point it may hold, once that is put on the zone's own reading through the calibration.
    #[error(
        "the neutral temperature {neutral_c} °C is above the warmest the probe may hold, {hold_max_c:.2} °C on the \
         zone's own reading under the device file's calibration (the probe rests at neutral when the host is gone): \
         use a lower neutral= or check the calibration"
    )]
    NeutralAboveHold {
        /// The neutral temperature \[°C\].
        neutral_c: f64,
        /// The warmest set-point on the zone's reading \[°C\].
        hold_max_c: f64,
    },
}

/// What a device's own protection cut on a channel (its firmware's over- or under-temperature cut, independent of
/// the host's safety envelope).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum DeviceCut {
    /// Heating latched off: the device's bound on its plate reached its upper line.
    #[error(
        "the device's own over-temperature cut latched heating off (its plate could pass its upper line); it is \
         released once the plate is back inside"
    )]
    OverTemperature,
    /// Cooling latched off: the device's bound on its plate reached its lower line.
    #[error(
        "the device's own under-temperature cut latched cooling off (its plate could pass its lower line); it is \
         released once the plate is back inside"
    )]
    UnderTemperature,
    /// Heating and cooling latched off: the device cannot bound its plate (its sensor reading is not valid).
    #[error("the device latched heating and cooling off: it cannot bound its plate (sensor reading not valid)")]
    Both,
}

impl DeviceCut {
    /// A short stable name: `over_temperature`, `under_temperature` or `both`.
    pub fn name(self) -> &'static str {
        match self {
            DeviceCut::OverTemperature => "over_temperature",
            DeviceCut::UnderTemperature => "under_temperature",
            DeviceCut::Both => "both",
        }
    }

    /// The cut from the two latches (None when neither is set).
    pub fn from_latches(heating: bool, cooling: bool) -> Option<DeviceCut> {
        match (heating, cooling) {
            (true, true) => Some(DeviceCut::Both),
            (true, false) => Some(DeviceCut::OverTemperature),
            (false, true) => Some(DeviceCut::UnderTemperature),
            (false, false) => None,
        }
    }
}
