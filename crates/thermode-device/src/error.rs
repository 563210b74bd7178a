//! Typed errors of the device layer: bad channel numbers, bad values handed to a device, bad faults, bad
//! configuration, link failures of real devices, a device whose watchdog is too slow, and a channel that a device's
//! own protection cut ([`DeviceCut`]).

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
