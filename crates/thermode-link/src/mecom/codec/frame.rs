//! The MeCom frame: the ASCII link layer of Meerstetter devices (MeCom Protocol Specification 5117C, §1.2).
//!
//! A frame is a control character (`#` from the host, `!` from the device), the device address (2 hex digits), a
//! sequence number (4 hex digits, echoed by the device), the payload (ASCII), a CRC-16/XMODEM (polynomial 0x1021,
//! initial value 0, not reflected, no final XOR) over every character before it as 4 hex digits, and a carriage
//! return. Hex digits are upper case on the wire; the decoder also takes lower case.
//!
//! The one exception is the device's acknowledge of a set command (5117C §1.3.1): `!`, address, sequence number and
//! the **set command's own CRC** in place of a payload and frame CRC (`!0015AE8F97` acknowledges
//! `#0015AEVS07DA01000000028F97`). A device frame of exactly [`FRAME_OVERHEAD`] characters is such an acknowledge:
//! its CRC field is not checked against its own characters but handed out as its payload, and the host compares it
//! with the CRC of the request it answers ([`super::payload::check_answer`]).
//!
//! [`FrameDecoder`] takes bytes as they arrive and returns whole frames or a typed [`FrameError`]: it synchronises on
//! the control character it expects, drops a frame longer than [`MAX_FRAME_LEN`], and never panics whatever the
//! bytes.

use crc::{Crc, CRC_16_XMODEM};
use thiserror::Error;

/// Control character of a host frame: `#`.
pub const HOST_CONTROL: u8 = b'#';
/// Control character of a device frame: `!`.
pub const DEVICE_CONTROL: u8 = b'!';
/// End of every frame: carriage return.
pub const END_OF_FRAME: u8 = b'\r';
/// Longest frame the decoder accepts \[bytes\], from the control character to the CRC: 512 (the longest payload
/// thermode uses is a 20-character identity string; the specification's big-data answers stay near 256 elements).
pub const MAX_FRAME_LEN: usize = 512;
/// Characters of a frame around its payload: control 1, address 2, sequence 4, CRC 4.
pub const FRAME_OVERHEAD: usize = 11;

const CRC16: Crc<u16> = Crc::<u16>::new(&CRC_16_XMODEM);

/// CRC-16/XMODEM of `bytes` (the MeCom frame check).
pub fn crc16(bytes: &[u8]) -> u16 {
    CRC16.checksum(bytes)
}

/// Why a received frame was dropped.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameError {
    /// More than [`MAX_FRAME_LEN`] characters without a carriage return.
    #[error("MeCom frame longer than {MAX_FRAME_LEN} characters (no carriage return)")]
    TooLong,
    /// Fewer characters than a frame's fixed fields.
    #[error("MeCom frame of {len} characters is shorter than its {FRAME_OVERHEAD} fixed characters")]
    TooShort {
        /// Characters received.
        len: usize,
    },
    /// A character that is not a hex digit where one must be.
    #[error("MeCom frame: {field} is not hexadecimal")]
    NotHex {
        /// Which field.
        field: &'static str,
    },
    /// A payload character outside printable ASCII.
    #[error("MeCom frame: the payload has a byte 0x{byte:02X} outside printable ASCII")]
    NotAscii {
        /// The byte.
        byte: u8,
    },
    /// The CRC does not match.
    #[error("MeCom frame CRC mismatch: received {received:04X}, computed {computed:04X}")]
    Crc {
        /// CRC in the frame.
        received: u16,
        /// CRC of the characters received.
        computed: u16,
    },
}

/// A decoded frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// `#` (host) or `!` (device).
    pub control: u8,
    /// Device address, 0 to 255.
    pub address: u8,
    /// Sequence number.
    pub seq: u16,
    /// Payload (printable ASCII).
    pub payload: String,
    /// The frame's CRC (a set command's acknowledge echoes it).
    pub crc: u16,
}

/// Appends the frame `control`, `address`, `seq`, `payload` with its CRC and carriage return to `out`; returns the
/// CRC.
pub fn encode_frame(control: u8, address: u8, seq: u16, payload: &str, out: &mut Vec<u8>) -> u16 {
    let start = out.len();
    out.push(control);
    push_hex(out, u32::from(address), 2);
    push_hex(out, u32::from(seq), 4);
    out.extend_from_slice(payload.as_bytes());
    let crc = crc16(&out[start..]);
    push_hex(out, u32::from(crc), 4);
    out.push(END_OF_FRAME);
    crc
}

/// Appends the device's acknowledge of the set command with CRC `set_crc` (no frame CRC of its own) to `out`.
pub fn encode_ack(address: u8, seq: u16, set_crc: u16, out: &mut Vec<u8>) {
    out.push(DEVICE_CONTROL);
    push_hex(out, u32::from(address), 2);
    push_hex(out, u32::from(seq), 4);
    push_hex(out, u32::from(set_crc), 4);
    out.push(END_OF_FRAME);
}

/// Appends `value` as `digits` upper-case hex digits (the low `4 × digits` bits).
pub fn push_hex(out: &mut Vec<u8>, value: u32, digits: usize) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    for i in (0..digits).rev() {
        out.push(HEX[((value >> (4 * i)) & 0xF) as usize]);
    }
}

/// The value of hex digits `text` (1 to 8 digits), or None.
pub fn parse_hex(text: &[u8]) -> Option<u32> {
    if text.is_empty() || text.len() > 8 {
        return None;
    }
    text.iter().try_fold(0u32, |acc, &c| {
        let digit = (c as char).to_digit(16)?;
        Some((acc << 4) | digit)
    })
}

/// Parses one frame without its carriage return: `text` starts with the control character.
pub fn parse_frame(text: &[u8]) -> Result<Frame, FrameError> {
    if text.len() < FRAME_OVERHEAD {
        return Err(FrameError::TooShort { len: text.len() });
    }
    let body_end = text.len() - 4;
    let received = parse_hex(&text[body_end..]).ok_or(FrameError::NotHex { field: "CRC" })? as u16;
    let acknowledge = text[0] == DEVICE_CONTROL && text.len() == FRAME_OVERHEAD;
    let computed = crc16(&text[..body_end]);
    if received != computed && !acknowledge {
        return Err(FrameError::Crc { received, computed });
    }
    let address = parse_hex(&text[1..3]).ok_or(FrameError::NotHex { field: "address" })? as u8;
    let seq = parse_hex(&text[3..7]).ok_or(FrameError::NotHex {
        field: "sequence number",
    })? as u16;
    // An acknowledge's payload is the CRC it echoes.
    let payload = if acknowledge {
        &text[body_end..]
    } else {
        &text[7..body_end]
    };
    if let Some(&byte) = payload.iter().find(|b| !(0x20..0x7F).contains(*b)) {
        return Err(FrameError::NotAscii { byte });
    }
    Ok(Frame {
        control: text[0],
        address,
        seq,
        // Printable ASCII is UTF-8.
        payload: String::from_utf8_lossy(payload).into_owned(),
        crc: received,
    })
}

/// Counts of what a decoder has seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameCounters {
    /// Bytes taken.
    pub bytes: u64,
    /// Frames decoded.
    pub frames: u64,
    /// Frames dropped for their CRC.
    pub crc_errors: u64,
    /// Frames dropped for any other reason (too long, too short, not hex, not ASCII).
    pub malformed: u64,
    /// Bytes skipped while looking for a control character.
    pub skipped_bytes: u64,
}

/// Cuts a byte stream into frames that start with one control character. See the module documentation.
#[derive(Debug, Clone)]
pub struct FrameDecoder {
    control: u8,
    buf: Vec<u8>,
    in_frame: bool,
    overflow: bool,
    counters: FrameCounters,
}

impl FrameDecoder {
    /// A decoder of frames starting with `control` ([`DEVICE_CONTROL`] on the host, [`HOST_CONTROL`] on a device).
    pub fn new(control: u8) -> Self {
        FrameDecoder {
            control,
            buf: Vec::with_capacity(64),
            in_frame: false,
            overflow: false,
            counters: FrameCounters::default(),
        }
    }

    /// What the decoder has seen so far.
    pub fn counters(&self) -> &FrameCounters {
        &self.counters
    }

    /// Takes one byte; returns a frame (or why one was dropped) when the byte ends one.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame, FrameError>> {
        self.counters.bytes += 1;
        if byte == self.control {
            // A control character always starts a frame: a frame cut short by a lost carriage return is dropped.
            if self.in_frame && !self.buf.is_empty() {
                self.counters.malformed += 1;
            }
            self.buf.clear();
            self.buf.push(byte);
            self.in_frame = true;
            self.overflow = false;
            return None;
        }
        if !self.in_frame {
            if byte != END_OF_FRAME && byte != b'\n' {
                self.counters.skipped_bytes += 1;
            }
            return None;
        }
        if byte == END_OF_FRAME {
            self.in_frame = false;
            if std::mem::take(&mut self.overflow) {
                self.buf.clear();
                self.counters.malformed += 1;
                return Some(Err(FrameError::TooLong));
            }
            let result = parse_frame(&self.buf);
            self.buf.clear();
            match &result {
                Ok(_) => self.counters.frames += 1,
                Err(FrameError::Crc { .. }) => self.counters.crc_errors += 1,
                Err(_) => self.counters.malformed += 1,
            }
            return Some(result);
        }
        if self.buf.len() >= MAX_FRAME_LEN {
            self.overflow = true;
        } else {
            self.buf.push(byte);
        }
        None
    }

    /// Takes `bytes`, handing every result to `each`.
    pub fn feed(&mut self, bytes: &[u8], mut each: impl FnMut(Result<Frame, FrameError>)) {
        for &byte in bytes {
            if let Some(result) = self.push(byte) {
                each(result);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(control: u8, address: u8, seq: u16, payload: &str) -> String {
        let mut out = Vec::new();
        encode_frame(control, address, seq, payload, &mut out);
        String::from_utf8(out).unwrap_or_default()
    }

    /// The published examples (MeCom Protocol Specification 5117C §1.3; TEC Controller Communication Protocol
    /// 5136AL §5), carriage return added.
    #[test]
    fn published_frames_are_reproduced() {
        // One published frame per line: the table is data.
        #[rustfmt::skip]
        let cases = [
            (HOST_CONTROL, 0x00, 0x15AA, "?IF", "#0015AA?IF62AE\r"),
            (HOST_CONTROL, 0x01, 0x15AA, "?IF", "#0115AA?IF257D\r"),
            (HOST_CONTROL, 0x00, 0xBDE2, "RS", "#00BDE2RS9780\r"),
            (DEVICE_CONTROL, 0x01, 0x15AC, "+05", "!0115AC+057509\r"),
            (HOST_CONTROL, 0x00, 0x15AB, "?VR006401", "#0015AB?VR0064018000\r"),
            (DEVICE_CONTROL, 0x00, 0x15AB, "00000441", "!0015AB000004411DBD\r"),
            (HOST_CONTROL, 0x00, 0x15AE, "VS07DA0100000002", "#0015AEVS07DA01000000028F97\r"),
            (HOST_CONTROL, 0x00, 0x15AB, "?VR03E801", "#0015AB?VR03E801C21A\r"),
            (DEVICE_CONTROL, 0x00, 0x15AB, "41CD2F28", "!0015AB41CD2F28D5C2\r"),
            (HOST_CONTROL, 0x00, 0x15B0, "VS0BB80141AE0000", "#0015B0VS0BB80141AE0000C482\r"),
            (DEVICE_CONTROL, 0x00, 0x15AC, "+05", "!0015AC+0532DA\r"),
        ];
        for (control, address, seq, payload, expected) in cases {
            let got = frame(control, address, seq, payload);
            assert_eq!(
                got, expected,
                "frame of {payload:?}: got {got:?}, published {expected:?}"
            );
        }
        assert_eq!(crc16(b"#0015AA?IF"), 0x62AE, "CRC of the identity query");
        // Acknowledges echo the set command's CRC instead of a frame CRC of their own.
        for (seq, set_crc, expected) in [(0x15AE, 0x8F97, "!0015AE8F97\r"), (0xBDE2, 0x9780, "!00BDE29780\r")] {
            let mut out = Vec::new();
            encode_ack(0, seq, set_crc, &mut out);
            assert_eq!(String::from_utf8_lossy(&out), expected);
            let mut decoder = FrameDecoder::new(DEVICE_CONTROL);
            let mut got = Vec::new();
            decoder.feed(&out, |r| got.push(r));
            assert!(got[0].as_ref().is_ok_and(|f| f.payload == expected[7..11]), "{got:?}");
        }
    }

    #[test]
    fn the_decoder_reads_published_answers_and_drops_bad_ones() {
        let mut decoder = FrameDecoder::new(DEVICE_CONTROL);
        let mut got = Vec::new();
        decoder.feed(b"noise!0015AB41CD2F28D5C2\r!0015AB41CD2F28D5C3\r!00\r", |r| got.push(r));
        assert_eq!(got.len(), 3, "{got:?}");
        let first = got[0].clone().unwrap_or_else(|e| panic!("first frame: {e}"));
        assert_eq!(
            (first.address, first.seq, first.payload.as_str()),
            (0, 0x15AB, "41CD2F28")
        );
        assert_eq!(f32::from_bits(0x41CD2F28), 25.648026);
        assert!(
            matches!(
                got[1],
                Err(FrameError::Crc {
                    received: 0xD5C3,
                    computed: 0xD5C2
                })
            ),
            "{:?}",
            got[1]
        );
        assert!(matches!(got[2], Err(FrameError::TooShort { len: 3 })), "{:?}", got[2]);
        let c = decoder.counters();
        assert_eq!(
            (c.frames, c.crc_errors, c.malformed, c.skipped_bytes),
            (1, 1, 1, 5),
            "{c:?}"
        );
    }

    #[test]
    fn an_endless_frame_is_dropped_and_the_next_one_read() {
        let mut decoder = FrameDecoder::new(DEVICE_CONTROL);
        let mut got = Vec::new();
        let mut bytes = vec![DEVICE_CONTROL];
        bytes.extend(std::iter::repeat_n(b'A', 2 * MAX_FRAME_LEN));
        bytes.push(END_OF_FRAME);
        bytes.extend_from_slice(b"!0015AE8F97\r");
        decoder.feed(&bytes, |r| got.push(r));
        assert_eq!(got.len(), 2, "{got:?}");
        assert_eq!(got[0], Err(FrameError::TooLong));
        assert!(got[1].as_ref().is_ok_and(|f| f.payload == "8F97"), "{:?}", got[1]);
    }
}
