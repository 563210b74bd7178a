//! The messages of the device protocol, host → device ([`HostMessage`]) and device → host ([`DeviceMessage`]),
//! with the fixed-point units they carry on the wire and the conversions to and from SI values.
//!
//! Every message is a plain value without heap storage (channel arrays are fixed at [`MAX_CHANNELS`]), so encoding
//! and decoding allocate nothing. Byte layouts are in [`super::layout`] and `docs/protocol.md`.

use thiserror::Error;

use thermode_device::MAX_CHANNELS;

/// Why a message could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum MessageError {
    /// A channel range outside `0..MAX_CHANNELS`, or an empty one.
    #[error("{count} channel(s) from channel {first} on: a message carries 1 to {max} channels, numbered from 0")]
    Channels {
        /// First channel of the range.
        first: usize,
        /// Number of channels.
        count: usize,
        /// Most channels a message carries.
        max: usize,
    },
}

/// Drive currents for a contiguous range of channels, in mA (positive heats the display).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DriveFrame {
    first_channel: u8,
    count: u8,
    currents_ma: [i16; MAX_CHANNELS],
}

impl DriveFrame {
    /// Currents `currents_ma` \[mA\] for channels `first_channel..first_channel + currents_ma.len()`; the range must
    /// be non-empty and lie within `0..MAX_CHANNELS`.
    pub fn new(first_channel: usize, currents_ma: &[i16]) -> Result<Self, MessageError> {
        let count = currents_ma.len();
        if count == 0 || first_channel + count > MAX_CHANNELS {
            return Err(MessageError::Channels {
                first: first_channel,
                count,
                max: MAX_CHANNELS,
            });
        }
        let mut all = [0; MAX_CHANNELS];
        all[..count].copy_from_slice(currents_ma);
        Ok(DriveFrame {
            first_channel: first_channel as u8,
            count: count as u8,
            currents_ma: all,
        })
    }

    /// The first channel the currents are for.
    pub fn first_channel(&self) -> usize {
        self.first_channel as usize
    }

    /// The currents \[mA\], one per channel from [`DriveFrame::first_channel`] on.
    pub fn currents_ma(&self) -> &[i16] {
        &self.currents_ma[..self.count as usize]
    }
}

/// A message from the host to the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HostMessage {
    /// Asks the device to identify itself; answered by [`DeviceMessage::Identify`].
    Hello,
    /// Keeps the watchdog fed; not answered (the next report's `last_command_seq` confirms it).
    Heartbeat,
    /// Sets the drive currents of a range of channels; they hold until the next command. Not answered when applied
    /// (confirmed by `last_command_seq`); refused with a [`NackCode`] otherwise.
    Drive(DriveFrame),
    /// Switches every drive off at once; answered by [`DeviceMessage::Ack`].
    AllOff,
    /// Releases the latch (after power-up or an expired watchdog) so that drive commands apply again; the drives
    /// stay off until the next drive command. Answered by [`DeviceMessage::Ack`].
    ClearFault,
}

/// Firmware version of the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FirmwareVersion {
    /// Major version.
    pub major: u8,
    /// Minor version.
    pub minor: u8,
    /// Patch version.
    pub patch: u8,
}

/// The device's answer to [`HostMessage::Hello`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identify {
    /// Number of channels, 1 to [`MAX_CHANNELS`].
    pub channel_count: u8,
    /// Firmware version.
    pub firmware: FirmwareVersion,
    /// Largest current magnitude a drive delivers \[mA\]; larger commands are clamped and flagged.
    pub current_limit_ma: u16,
    /// Watchdog period \[ms\]: without a valid host frame for longer, every drive is switched off and latched.
    pub watchdog_ms: u16,
    /// Interval between sensor reports \[ms\].
    pub report_interval_ms: u16,
}

/// Device-wide status bits of a [`SensorReport`]. Reserved bits are sent as 0 and ignored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReportFlags(pub u8);

impl ReportFlags {
    /// Bit 0: drives are latched off (after power-up, or after the watchdog expired) until [`HostMessage::ClearFault`].
    pub const LATCHED: u8 = 0x01;
    /// Bit 1: the latch was set by an expired watchdog (not by power-up).
    pub const WATCHDOG_EXPIRED: u8 = 0x02;

    /// Whether the drives are latched off.
    pub fn latched(self) -> bool {
        self.0 & Self::LATCHED != 0
    }

    /// Whether the latch comes from an expired watchdog.
    pub fn watchdog_expired(self) -> bool {
        self.0 & Self::WATCHDOG_EXPIRED != 0
    }
}

/// Per-channel fault bits of a [`ChannelReport`]. Reserved bits are sent as 0 and ignored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ChannelFaults(pub u8);

impl ChannelFaults {
    /// Bit 0: the display sensor reads open (at or above [`SENSOR_OPEN_THRESHOLD_C`]).
    pub const SENSOR_OPEN: u8 = 0x01;
    /// Bit 1: the display sensor reads shorted (at or below [`SENSOR_SHORT_THRESHOLD_C`]).
    pub const SENSOR_SHORT: u8 = 0x02;
    /// Bit 2: the drive does not deliver what it was told (a stuck or failed driver stage).
    pub const DRIVE_FAULT: u8 = 0x04;
    /// Bit 3: the last command exceeded the current limit and was clamped to it.
    pub const CURRENT_LIMITED: u8 = 0x08;
    /// Bit 4: the drive is latched off (see [`ReportFlags::LATCHED`]).
    pub const LATCHED_OFF: u8 = 0x10;
    /// Bit 5: the device's own cut latched this channel's heating off: its bound on the plate reached the upper
    /// line (48 °C). Released by [`HostMessage::ClearFault`] once the plate is back inside (`docs/protocol.md` §6).
    pub const OVER_TEMPERATURE: u8 = 0x20;
    /// Bit 6: the device's own cut latched this channel's cooling off: its bound on the plate reached the lower
    /// line (10 °C). Released like [`ChannelFaults::OVER_TEMPERATURE`].
    pub const UNDER_TEMPERATURE: u8 = 0x40;

    /// Whether `bit` (one of the constants) is set.
    pub fn has(self, bit: u8) -> bool {
        self.0 & bit != 0
    }
}

/// A device reports its sensor open at or above this reading \[°C\] (an open PT-100 reads far above any
/// temperature a display reaches).
pub const SENSOR_OPEN_THRESHOLD_C: f64 = 400.0;

/// A device reports its sensor shorted at or below this reading \[°C\] (a shorted PT-100 reads about −242 °C).
pub const SENSOR_SHORT_THRESHOLD_C: f64 = -200.0;

/// One channel of a [`SensorReport`], in the wire's fixed-point units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ChannelReport {
    /// Display (PT-100) reading \[m°C\]; `i32::MIN` stands for "no valid number".
    pub sensor_milli_c: i32,
    /// Hot-side (box) reading \[c°C, hundredths of a degree\]; `i16::MIN` stands for "no valid number"; readings
    /// beyond ±327.67 °C saturate.
    pub hot_side_centi_c: i16,
    /// Current the drive delivers (its own measurement) \[mA\].
    pub applied_ma: i16,
    /// Sequence number of the display sample, modulo 2¹⁶; it advances with every new sample and stops when the
    /// sensor stops delivering.
    pub sample_seq: u16,
    /// Age of the display sample at the report's `device_time_ms` \[ms\], saturating at 65535.
    pub sample_age_ms: u16,
    /// Fault bits.
    pub faults: ChannelFaults,
}

/// Readings are divided by their power of ten, not multiplied by its inverse: the division is correctly rounded, so
/// 23281 m°C reads as 23.281 °C (times 1e-3 gives 23.281000000000002): the sensor's resolution, no more digits.
impl ChannelReport {
    /// The display reading \[°C\] (NaN for the "no valid number" code).
    pub fn sensor_c(&self) -> f64 {
        match self.sensor_milli_c {
            i32::MIN => f64::NAN,
            v => f64::from(v) / 1000.0,
        }
    }

    /// The hot-side reading \[°C\] (NaN for the "no valid number" code).
    pub fn hot_side_c(&self) -> f64 {
        match self.hot_side_centi_c {
            i16::MIN => f64::NAN,
            v => f64::from(v) / 100.0,
        }
    }

    /// The delivered current \[A\].
    pub fn applied_a(&self) -> f64 {
        f64::from(self.applied_ma) / 1000.0
    }
}

/// `value_c` \[°C\] in m°C, rounded; saturates at ±2 147 483.647 °C; NaN becomes the "no valid number" code.
pub fn to_milli_c(value_c: f64) -> i32 {
    if value_c.is_nan() {
        return i32::MIN;
    }
    (value_c * 1e3)
        .round()
        .clamp(f64::from(i32::MIN + 1), f64::from(i32::MAX)) as i32
}

/// `value_c` \[°C\] in c°C, rounded; saturates at ±327.67 °C; NaN becomes the "no valid number" code.
pub fn to_centi_c(value_c: f64) -> i16 {
    if value_c.is_nan() {
        return i16::MIN;
    }
    (value_c * 1e2)
        .round()
        .clamp(f64::from(i16::MIN + 1), f64::from(i16::MAX)) as i16
}

/// `current_a` \[A\] in mA, rounded, if it is finite and within ±32.767 A.
pub fn to_milliamps(current_a: f64) -> Option<i16> {
    let ma = (current_a * 1e3).round();
    (ma.is_finite() && ma.abs() <= f64::from(i16::MAX)).then_some(ma as i16)
}

/// The device's periodic report of every channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SensorReport {
    /// Device clock at the report \[ms\] since power-up, modulo 2³².
    pub device_time_ms: u32,
    /// Device-wide status.
    pub flags: ReportFlags,
    /// Sequence number of the last valid host frame the device took (0 before any).
    pub last_command_seq: u16,
    count: u8,
    channels: [ChannelReport; MAX_CHANNELS],
}

impl SensorReport {
    /// A report of `channels` (1 to [`MAX_CHANNELS`], channel 0 first).
    pub fn new(
        device_time_ms: u32,
        flags: ReportFlags,
        last_command_seq: u16,
        channels: &[ChannelReport],
    ) -> Result<Self, MessageError> {
        let count = channels.len();
        if count == 0 || count > MAX_CHANNELS {
            return Err(MessageError::Channels {
                first: 0,
                count,
                max: MAX_CHANNELS,
            });
        }
        let mut all = [ChannelReport::default(); MAX_CHANNELS];
        all[..count].copy_from_slice(channels);
        Ok(SensorReport {
            device_time_ms,
            flags,
            last_command_seq,
            count: count as u8,
            channels: all,
        })
    }

    /// The channels, channel 0 first.
    pub fn channels(&self) -> &[ChannelReport] {
        &self.channels[..self.count as usize]
    }
}

/// Why the device refused a frame whose CRC was good.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NackCode {
    /// 1: the body's length or a field does not fit the message type.
    Malformed,
    /// 2: the message type is unknown.
    UnknownType,
    /// 3: a channel does not exist on this device.
    BadChannel,
    /// 4: drives are latched off; send [`HostMessage::ClearFault`] first.
    Latched,
    /// 5: the protocol version is not the device's.
    UnsupportedVersion,
}

impl NackCode {
    /// Every code, in code order.
    pub const ALL: [NackCode; 5] = [
        NackCode::Malformed,
        NackCode::UnknownType,
        NackCode::BadChannel,
        NackCode::Latched,
        NackCode::UnsupportedVersion,
    ];

    /// The code's byte on the wire.
    pub fn code(self) -> u8 {
        match self {
            NackCode::Malformed => 1,
            NackCode::UnknownType => 2,
            NackCode::BadChannel => 3,
            NackCode::Latched => 4,
            NackCode::UnsupportedVersion => 5,
        }
    }

    /// The code with byte `code`, if any.
    pub fn from_code(code: u8) -> Option<NackCode> {
        NackCode::ALL.into_iter().find(|c| c.code() == code)
    }
}

/// A message from the device to the host.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceMessage {
    /// The answer to [`HostMessage::Hello`].
    Identify(Identify),
    /// The periodic report of every channel.
    SensorReport(SensorReport),
    /// A host frame (its sequence number) was carried out.
    Ack {
        /// Sequence number of the host frame.
        seq: u16,
    },
    /// A host frame (its sequence number) was refused.
    Nack {
        /// Sequence number of the host frame.
        seq: u16,
        /// Why.
        code: NackCode,
    },
}

/// A message with the sender's sequence number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<M> {
    /// Sequence number: each end counts its own frames, modulo 2¹⁶, from 0.
    pub seq: u16,
    /// The message.
    pub message: M,
}
