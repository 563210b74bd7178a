//! Typed errors of the device layer: bad channel numbers, bad values handed to a device, bad faults, bad
//! configuration, and link failures of real devices.

use thermode_model::{BadValue, ParamError};
use thiserror::Error;

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
    Link(String),
}
