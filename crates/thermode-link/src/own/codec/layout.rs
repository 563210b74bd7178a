//! Byte layouts of the messages and the stream decoder that turns received bytes into checked messages while it
//! counts everything it drops.
//!
//! Every payload starts with a 4-byte header, then the message body; all fields are little-endian:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 1 | protocol version, [`PROTOCOL_VERSION`] |
//! | 1 | 1 | message type (host → device 0x01–0x05, device → host 0x81–0x84) |
//! | 2 | 2 | sequence number, u16 |
//!
//! The first four bytes keep this layout in every future version, so a device can refuse another version with a
//! [`NackCode::UnsupportedVersion`] that names the frame. The bodies are documented on each type code below and in
//! `docs/protocol.md`.

use std::marker::PhantomData;

use thiserror::Error;

use super::frame::{write_frame, FrameDecoder, FrameError, MAX_PAYLOAD_LEN};
use super::message::{
    ChannelFaults, ChannelReport, DeviceMessage, DriveFrame, FirmwareVersion, Frame, HostMessage, Identify, NackCode,
    ReportFlags, SensorReport,
};
use thermode_device::MAX_CHANNELS;

/// The protocol version this crate speaks.
pub const PROTOCOL_VERSION: u8 = 1;

/// Length of the header before every body \[bytes\].
pub const HEADER_LEN: usize = 4;

/// Type 0x01, [`HostMessage::Hello`]: empty body.
pub const TYPE_HELLO: u8 = 0x01;
/// Type 0x02, [`HostMessage::Heartbeat`]: empty body.
pub const TYPE_HEARTBEAT: u8 = 0x02;
/// Type 0x03, [`HostMessage::Drive`]: first channel u8, count n u8 (1–10), n × current i16 \[mA\].
pub const TYPE_DRIVE: u8 = 0x03;
/// Type 0x04, [`HostMessage::AllOff`]: empty body.
pub const TYPE_ALL_OFF: u8 = 0x04;
/// Type 0x05, [`HostMessage::ClearFault`]: empty body.
pub const TYPE_CLEAR_FAULT: u8 = 0x05;
/// Type 0x81, [`DeviceMessage::Identify`]: channel count u8, firmware major u8, minor u8, patch u8, current limit
/// u16 \[mA\], watchdog u16 \[ms\], report interval u16 \[ms\] (10 bytes).
pub const TYPE_IDENTIFY: u8 = 0x81;
/// Type 0x82, [`DeviceMessage::SensorReport`]: device time u32 \[ms\], flags u8, last command seq u16, count n u8
/// (1–10), then n × [`CHANNEL_REPORT_LEN`] bytes: sensor i32 \[m°C\], hot side i16 \[c°C\], applied current i16
/// \[mA\], sample seq u16, sample age u16 \[ms\], faults u8.
pub const TYPE_SENSOR_REPORT: u8 = 0x82;
/// Type 0x83, [`DeviceMessage::Ack`]: acknowledged seq u16.
pub const TYPE_ACK: u8 = 0x83;
/// Type 0x84, [`DeviceMessage::Nack`]: refused seq u16, code u8.
pub const TYPE_NACK: u8 = 0x84;

/// Bytes per channel in a sensor report.
pub const CHANNEL_REPORT_LEN: usize = 13;

/// Why received bytes did not make a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum DecodeError {
    /// The frame itself was refused (stuffing, length, CRC).
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// The payload is shorter than the header.
    #[error("payload of {len} bytes is shorter than the {HEADER_LEN}-byte header")]
    TooShort {
        /// Payload length \[bytes\].
        len: usize,
    },
    /// Another protocol version.
    #[error("protocol version {got} (this end speaks {PROTOCOL_VERSION})")]
    Version {
        /// Sequence number of the frame.
        seq: u16,
        /// Its version byte.
        got: u8,
    },
    /// A message type this direction does not have.
    #[error("unknown message type {code:#04x}")]
    UnknownType {
        /// Sequence number of the frame.
        seq: u16,
        /// Its type byte.
        code: u8,
    },
    /// The body length does not fit the message type.
    #[error("message type {code:#04x} with a {got}-byte body (expected {expected})")]
    Length {
        /// Sequence number of the frame.
        seq: u16,
        /// Its type byte.
        code: u8,
        /// Expected body length \[bytes\].
        expected: usize,
        /// Received body length \[bytes\].
        got: usize,
    },
    /// A field is out of its range.
    #[error("invalid {what}")]
    Value {
        /// Sequence number of the frame.
        seq: u16,
        /// Which field.
        what: &'static str,
    },
}

impl DecodeError {
    /// The sequence number of the refused frame, where the frame got far enough to tell it.
    pub fn seq(&self) -> Option<u16> {
        match *self {
            DecodeError::Frame(_) | DecodeError::TooShort { .. } => None,
            DecodeError::Version { seq, .. }
            | DecodeError::UnknownType { seq, .. }
            | DecodeError::Length { seq, .. }
            | DecodeError::Value { seq, .. } => Some(seq),
        }
    }
}

/// A message type of one direction of the link.
pub trait WireMessage: Sized + Copy {
    /// The type byte.
    fn type_code(&self) -> u8;
    /// Writes the body into `out` and returns its length \[bytes\] (`out` holds at least [`MAX_PAYLOAD_LEN`]
    /// − [`HEADER_LEN`] bytes).
    fn encode_body(&self, out: &mut [u8]) -> usize;
    /// The message of type `code` with body `body`; `seq` names the frame in errors.
    fn decode_body(seq: u16, code: u8, body: &[u8]) -> Result<Self, DecodeError>;
}

/// Appends `message` as one complete frame with sequence number `seq` to `out`. Allocates nothing once `out` has
/// room for a frame.
pub fn encode_frame<M: WireMessage>(seq: u16, message: &M, out: &mut Vec<u8>) -> Result<(), FrameError> {
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    payload[0] = PROTOCOL_VERSION;
    payload[1] = message.type_code();
    payload[2..4].copy_from_slice(&seq.to_le_bytes());
    let len = message.encode_body(&mut payload[HEADER_LEN..]);
    write_frame(&payload[..HEADER_LEN + len], out)
}

/// The message in a CRC-checked `payload`.
pub fn decode_payload<M: WireMessage>(payload: &[u8]) -> Result<Frame<M>, DecodeError> {
    if payload.len() < HEADER_LEN {
        return Err(DecodeError::TooShort { len: payload.len() });
    }
    let seq = u16::from_le_bytes([payload[2], payload[3]]);
    if payload[0] != PROTOCOL_VERSION {
        return Err(DecodeError::Version { seq, got: payload[0] });
    }
    let message = M::decode_body(seq, payload[1], &payload[HEADER_LEN..])?;
    Ok(Frame { seq, message })
}

/// Refuses a body whose length is not `expected`.
fn expect_len(seq: u16, code: u8, body: &[u8], expected: usize) -> Result<(), DecodeError> {
    if body.len() == expected {
        Ok(())
    } else {
        Err(DecodeError::Length {
            seq,
            code,
            expected,
            got: body.len(),
        })
    }
}

/// Little-endian field reader over a body whose length was checked.
struct Fields<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Fields<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Fields { bytes, at: 0 }
    }

    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        out.copy_from_slice(&self.bytes[self.at..self.at + N]);
        self.at += N;
        out
    }

    fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }

    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }

    fn i16(&mut self) -> i16 {
        i16::from_le_bytes(self.take())
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }

    fn i32(&mut self) -> i32 {
        i32::from_le_bytes(self.take())
    }
}

/// Little-endian field writer.
struct Writer<'a> {
    out: &'a mut [u8],
    at: usize,
}

impl<'a> Writer<'a> {
    fn new(out: &'a mut [u8]) -> Self {
        Writer { out, at: 0 }
    }

    fn put(&mut self, bytes: &[u8]) -> &mut Self {
        self.out[self.at..self.at + bytes.len()].copy_from_slice(bytes);
        self.at += bytes.len();
        self
    }
}

impl WireMessage for HostMessage {
    fn type_code(&self) -> u8 {
        match self {
            HostMessage::Hello => TYPE_HELLO,
            HostMessage::Heartbeat => TYPE_HEARTBEAT,
            HostMessage::Drive(_) => TYPE_DRIVE,
            HostMessage::AllOff => TYPE_ALL_OFF,
            HostMessage::ClearFault => TYPE_CLEAR_FAULT,
        }
    }

    fn encode_body(&self, out: &mut [u8]) -> usize {
        let HostMessage::Drive(drive) = self else {
            return 0;
        };
        let mut w = Writer::new(out);
        let currents = drive.currents_ma();
        w.put(&[drive.first_channel() as u8, currents.len() as u8]);
        for current in currents {
            w.put(&current.to_le_bytes());
        }
        w.at
    }

    fn decode_body(seq: u16, code: u8, body: &[u8]) -> Result<Self, DecodeError> {
        let message = match code {
            TYPE_HELLO => HostMessage::Hello,
            TYPE_HEARTBEAT => HostMessage::Heartbeat,
            TYPE_ALL_OFF => HostMessage::AllOff,
            TYPE_CLEAR_FAULT => HostMessage::ClearFault,
            TYPE_DRIVE => return decode_drive(seq, body),
            _ => return Err(DecodeError::UnknownType { seq, code }),
        };
        expect_len(seq, code, body, 0)?;
        Ok(message)
    }
}

fn decode_drive(seq: u16, body: &[u8]) -> Result<HostMessage, DecodeError> {
    if body.len() < 2 {
        return Err(DecodeError::Length {
            seq,
            code: TYPE_DRIVE,
            expected: 2,
            got: body.len(),
        });
    }
    let (first, count) = (body[0] as usize, body[1] as usize);
    expect_len(seq, TYPE_DRIVE, body, 2 + 2 * count)?;
    let mut fields = Fields::new(&body[2..]);
    let mut currents = [0i16; MAX_CHANNELS];
    let slots = currents.get_mut(..count).ok_or(DecodeError::Value {
        seq,
        what: "drive channel count",
    })?;
    for slot in slots.iter_mut() {
        *slot = fields.i16();
    }
    let drive = DriveFrame::new(first, slots).map_err(|_| DecodeError::Value {
        seq,
        what: "drive channel range",
    })?;
    Ok(HostMessage::Drive(drive))
}

impl WireMessage for DeviceMessage {
    fn type_code(&self) -> u8 {
        match self {
            DeviceMessage::Identify(_) => TYPE_IDENTIFY,
            DeviceMessage::SensorReport(_) => TYPE_SENSOR_REPORT,
            DeviceMessage::Ack { .. } => TYPE_ACK,
            DeviceMessage::Nack { .. } => TYPE_NACK,
        }
    }

    fn encode_body(&self, out: &mut [u8]) -> usize {
        let mut w = Writer::new(out);
        match self {
            DeviceMessage::Identify(id) => {
                let fw = id.firmware;
                w.put(&[id.channel_count, fw.major, fw.minor, fw.patch])
                    .put(&id.current_limit_ma.to_le_bytes())
                    .put(&id.watchdog_ms.to_le_bytes())
                    .put(&id.report_interval_ms.to_le_bytes());
            }
            DeviceMessage::SensorReport(report) => encode_report(report, &mut w),
            DeviceMessage::Ack { seq } => {
                w.put(&seq.to_le_bytes());
            }
            DeviceMessage::Nack { seq, code } => {
                w.put(&seq.to_le_bytes()).put(&[code.code()]);
            }
        }
        w.at
    }

    fn decode_body(seq: u16, code: u8, body: &[u8]) -> Result<Self, DecodeError> {
        match code {
            TYPE_IDENTIFY => decode_identify(seq, body),
            TYPE_SENSOR_REPORT => decode_report(seq, body),
            TYPE_ACK => {
                expect_len(seq, code, body, 2)?;
                Ok(DeviceMessage::Ack {
                    seq: Fields::new(body).u16(),
                })
            }
            TYPE_NACK => {
                expect_len(seq, code, body, 3)?;
                let mut f = Fields::new(body);
                let refused = f.u16();
                let nack = NackCode::from_code(f.u8()).ok_or(DecodeError::Value { seq, what: "nack code" })?;
                Ok(DeviceMessage::Nack {
                    seq: refused,
                    code: nack,
                })
            }
            _ => Err(DecodeError::UnknownType { seq, code }),
        }
    }
}

fn encode_report(report: &SensorReport, w: &mut Writer<'_>) {
    let channels = report.channels();
    w.put(&report.device_time_ms.to_le_bytes())
        .put(&[report.flags.0])
        .put(&report.last_command_seq.to_le_bytes())
        .put(&[channels.len() as u8]);
    for ch in channels {
        w.put(&ch.sensor_milli_c.to_le_bytes())
            .put(&ch.hot_side_centi_c.to_le_bytes())
            .put(&ch.applied_ma.to_le_bytes())
            .put(&ch.sample_seq.to_le_bytes())
            .put(&ch.sample_age_ms.to_le_bytes())
            .put(&[ch.faults.0]);
    }
}

fn decode_identify(seq: u16, body: &[u8]) -> Result<DeviceMessage, DecodeError> {
    expect_len(seq, TYPE_IDENTIFY, body, 10)?;
    let mut f = Fields::new(body);
    let channel_count = f.u8();
    if channel_count == 0 || channel_count as usize > MAX_CHANNELS {
        return Err(DecodeError::Value {
            seq,
            what: "identify channel count",
        });
    }
    let firmware = FirmwareVersion {
        major: f.u8(),
        minor: f.u8(),
        patch: f.u8(),
    };
    Ok(DeviceMessage::Identify(Identify {
        channel_count,
        firmware,
        current_limit_ma: f.u16(),
        watchdog_ms: f.u16(),
        report_interval_ms: f.u16(),
    }))
}

fn decode_report(seq: u16, body: &[u8]) -> Result<DeviceMessage, DecodeError> {
    const FIXED: usize = 8;
    if body.len() < FIXED {
        return Err(DecodeError::Length {
            seq,
            code: TYPE_SENSOR_REPORT,
            expected: FIXED,
            got: body.len(),
        });
    }
    let count = body[FIXED - 1] as usize;
    expect_len(seq, TYPE_SENSOR_REPORT, body, FIXED + CHANNEL_REPORT_LEN * count)?;
    let mut f = Fields::new(body);
    let (device_time_ms, flags, last_command_seq, _) = (f.u32(), ReportFlags(f.u8()), f.u16(), f.u8());
    let mut channels = [ChannelReport::default(); MAX_CHANNELS];
    let slots = channels.get_mut(..count).ok_or(DecodeError::Value {
        seq,
        what: "report channel count",
    })?;
    for slot in slots.iter_mut() {
        *slot = ChannelReport {
            sensor_milli_c: f.i32(),
            hot_side_centi_c: f.i16(),
            applied_ma: f.i16(),
            sample_seq: f.u16(),
            sample_age_ms: f.u16(),
            faults: ChannelFaults(f.u8()),
        };
    }
    let report = SensorReport::new(device_time_ms, flags, last_command_seq, slots).map_err(|_| DecodeError::Value {
        seq,
        what: "report channel count",
    })?;
    Ok(DeviceMessage::SensorReport(report))
}

/// What a receiver has seen of the link. Every dropped frame is counted in exactly one of the error counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkCounters {
    /// Bytes received.
    pub bytes: u64,
    /// Frames decoded into messages.
    pub frames: u64,
    /// Frames refused for invalid COBS stuffing.
    pub cobs_errors: u64,
    /// Frames refused for being longer than the maximum.
    pub oversized: u64,
    /// Frames too short for a CRC and a header.
    pub too_short: u64,
    /// Frames refused for a wrong CRC.
    pub crc_errors: u64,
    /// CRC-valid frames of another protocol version.
    pub bad_version: u64,
    /// CRC-valid frames of an unknown message type.
    pub unknown_type: u64,
    /// CRC-valid frames whose body does not fit their type.
    pub malformed: u64,
    /// Frames missing by the sender's sequence numbers (sum of the forward gaps).
    pub lost: u64,
    /// Times the sender's sequence number went backwards or jumped by half the range or more (a restart).
    pub sequence_restarts: u64,
}

impl LinkCounters {
    /// Frames dropped for any reason on this end (all error counters; `lost` is not included).
    pub fn errors(&self) -> u64 {
        self.cobs_errors
            + self.oversized
            + self.too_short
            + self.crc_errors
            + self.bad_version
            + self.unknown_type
            + self.malformed
    }

    fn count(&mut self, error: &DecodeError) {
        let counter = match error {
            DecodeError::Frame(FrameError::Cobs) => &mut self.cobs_errors,
            DecodeError::Frame(FrameError::Oversized { .. }) => &mut self.oversized,
            DecodeError::Frame(FrameError::TooShort { .. }) | DecodeError::TooShort { .. } => &mut self.too_short,
            DecodeError::Frame(FrameError::Crc { .. }) => &mut self.crc_errors,
            DecodeError::Version { .. } => &mut self.bad_version,
            DecodeError::UnknownType { .. } => &mut self.unknown_type,
            DecodeError::Length { .. } | DecodeError::Value { .. } => &mut self.malformed,
        };
        *counter += 1;
    }
}

/// Turns a received byte stream into messages of type `M`, counting what it drops and the sender's sequence gaps.
/// Never panics on any input and holds a bounded amount of memory.
#[derive(Debug, Clone)]
pub struct StreamDecoder<M> {
    frames: FrameDecoder,
    counters: LinkCounters,
    last_seq: Option<u16>,
    _message: PhantomData<fn() -> M>,
}

impl<M: WireMessage> Default for StreamDecoder<M> {
    fn default() -> Self {
        StreamDecoder::new()
    }
}

impl<M: WireMessage> StreamDecoder<M> {
    /// A decoder at the start of the stream.
    pub fn new() -> Self {
        StreamDecoder {
            frames: FrameDecoder::new(),
            counters: LinkCounters::default(),
            last_seq: None,
            _message: PhantomData,
        }
    }

    /// Takes one byte; at the end of a frame returns its message or why it was dropped (already counted).
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame<M>, DecodeError>> {
        self.counters.bytes += 1;
        let result = match self.frames.push(byte)? {
            Ok(payload) => decode_payload::<M>(payload),
            Err(error) => Err(DecodeError::Frame(error)),
        };
        match &result {
            Ok(frame) => self.accept(frame.seq),
            Err(error) => self.counters.count(error),
        }
        Some(result)
    }

    /// Takes `bytes`, calling `on_frame` for every frame that ends in them.
    pub fn feed(&mut self, bytes: &[u8], mut on_frame: impl FnMut(Result<Frame<M>, DecodeError>)) {
        for &byte in bytes {
            if let Some(result) = self.push(byte) {
                on_frame(result);
            }
        }
    }

    /// The counters so far.
    pub fn counters(&self) -> &LinkCounters {
        &self.counters
    }

    fn accept(&mut self, seq: u16) {
        self.counters.frames += 1;
        if let Some(last) = self.last_seq {
            let gap = seq.wrapping_sub(last).wrapping_sub(1);
            if gap < 0x8000 {
                self.counters.lost += u64::from(gap);
            } else {
                self.counters.sequence_restarts += 1;
            }
        }
        self.last_seq = Some(seq);
    }
}
