//! The binary protocol between the host (thermode) and a display's microcontroller, which drives the Peltier
//! elements and reads the sensors. `docs/protocol.md` is its full description; in short:
//!
//! - **Framing** ([`frame`]): each frame is COBS-stuffed `payload ‖ CRC-32` ending in a 0x00 delimiter; at most
//!   [`MAX_PAYLOAD_LEN`] payload bytes. Bytes that do not make a valid frame (bad stuffing, bad CRC, too short,
//!   too long) are dropped and counted, and the receiver is back in step at the next 0x00.
//! - **Messages** ([`message`], [`layout`]): a 4-byte header (version [`PROTOCOL_VERSION`], type, sequence number)
//!   and a little-endian body. Host → device: `Hello`, `Heartbeat`, `Drive` (currents in mA for a range of
//!   channels), `AllOff`, `ClearFault`. Device → host: `Identify`, `SensorReport` (every channel: sensor in m°C,
//!   hot side in c°C, delivered current in mA, sample sequence and age, fault bits), `Ack`, `Nack`.
//! - **Watchdog**: the device switches every drive off and latches them off when no valid host frame arrives
//!   within its watchdog period ([`DEFAULT_WATCHDOG_MS`] by default, announced in `Identify`); the host must send a
//!   frame at least every third of that period. A device also starts latched after power-up; `ClearFault`
//!   releases the latch.
//! - **Time**: both ends run on an injected monotonic `thermode_platform::Clock`.

pub mod frame;
pub mod layout;
pub mod message;

pub use frame::{
    cobs_decode, cobs_encode, crc32, write_frame, FrameDecoder, FrameError, DELIMITER, MAX_ENCODED_LEN, MAX_FRAME_LEN,
    MAX_PAYLOAD_LEN,
};
pub use layout::{
    decode_payload, encode_frame, DecodeError, LinkCounters, StreamDecoder, WireMessage, HEADER_LEN, PROTOCOL_VERSION,
};
pub use message::{
    to_centi_c, to_milli_c, to_milliamps, ChannelFaults, ChannelReport, DeviceMessage, DriveFrame, FirmwareVersion,
    Frame, HostMessage, Identify, MessageError, NackCode, ReportFlags, SensorReport, SENSOR_OPEN_THRESHOLD_C,
    SENSOR_SHORT_THRESHOLD_C,
};

/// Default watchdog period of a device \[ms\]: 250. Without a valid host frame for longer, every drive is switched
/// off and latched; the host sends at least every [`DEFAULT_WATCHDOG_MS`] / 3 ≈ 83 ms.
pub const DEFAULT_WATCHDOG_MS: u16 = 250;

/// Default interval between a device's sensor reports \[ms\]: 10 (100 Hz, the PT-100's default sample rate).
pub const DEFAULT_REPORT_INTERVAL_MS: u16 = 10;

/// Default baud rate of a serial link \[bit/s\]: 115200 (enough for five channels at 100 reports/s; USB CDC and
/// pseudo-terminals ignore it).
pub const DEFAULT_BAUD_RATE: u32 = 115_200;
