//! Framing of the device protocol: COBS (Consistent Overhead Byte Stuffing) with a 0x00 delimiter and a CRC-32
//! over the payload.
//!
//! On the wire a frame is `COBS(payload ‖ CRC-32(payload) as 4 bytes little-endian)` followed by one 0x00 byte.
//! COBS removes every 0x00 from the stuffed bytes, so 0x00 only ever ends a frame: a receiver that lost track
//! (noise, a frame cut short, a reset) is back in step at the next 0x00. The CRC is CRC-32/ISO-HDLC (the CRC of
//! Ethernet and zlib: polynomial 0x04C11DB7 reflected, initial value and final XOR 0xFFFFFFFF, check value
//! 0xCBF43926 for the ASCII bytes `123456789`).
//!
//! [`FrameDecoder`] takes the received bytes one at a time and hands out each CRC-checked payload, or the reason a
//! frame was refused; it never panics and never keeps more than [`MAX_ENCODED_LEN`] bytes.

use crc::{Crc, CRC_32_ISO_HDLC};
use thiserror::Error;

/// The byte that ends every frame.
pub const DELIMITER: u8 = 0x00;

/// Length of the CRC that follows the payload \[bytes\].
pub const CRC_LEN: usize = 4;

/// Longest payload of one frame \[bytes\] (before the CRC and before stuffing): 251, so that payload and CRC fit
/// in 255 bytes.
pub const MAX_PAYLOAD_LEN: usize = 251;

/// Longest frame before stuffing: payload and CRC \[bytes\].
pub const MAX_FRAME_LEN: usize = MAX_PAYLOAD_LEN + CRC_LEN;

/// Longest stuffed frame without its delimiter \[bytes\]: COBS adds one code byte per started block of 254 bytes,
/// and one more at the start.
pub const MAX_ENCODED_LEN: usize = MAX_FRAME_LEN + MAX_FRAME_LEN / 254 + 1;

/// The CRC-32/ISO-HDLC engine.
const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Why a frame was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum FrameError {
    /// More than [`MAX_ENCODED_LEN`] bytes arrived without a delimiter (or a payload to send is longer than
    /// [`MAX_PAYLOAD_LEN`]).
    #[error("frame longer than {max} bytes")]
    Oversized {
        /// The longest allowed \[bytes\].
        max: usize,
    },
    /// The stuffed bytes are not valid COBS: a code byte points past the end of the frame.
    #[error("invalid COBS stuffing")]
    Cobs,
    /// The unstuffed frame is too short to hold a CRC and a header.
    #[error("frame of {len} bytes is too short")]
    TooShort {
        /// Its length after unstuffing \[bytes\].
        len: usize,
    },
    /// The CRC does not match the payload.
    #[error("CRC mismatch: computed {computed:#010x}, received {received:#010x}")]
    Crc {
        /// CRC-32 of the received payload.
        computed: u32,
        /// CRC-32 carried by the frame.
        received: u32,
    },
}

/// The CRC-32/ISO-HDLC of `bytes`.
pub fn crc32(bytes: &[u8]) -> u32 {
    CRC32.checksum(bytes)
}

/// Appends the COBS stuffing of `src` to `out` (without a delimiter). The output has no 0x00 byte and is at most
/// `src.len() + src.len() / 254 + 1` bytes long.
pub fn cobs_encode(src: &[u8], out: &mut Vec<u8>) {
    let mut code_at = out.len();
    out.push(0); // placeholder for the first code byte
    let mut code: u8 = 1;
    for (i, &byte) in src.iter().enumerate() {
        if byte != 0 {
            out.push(byte);
            code += 1;
        }
        // A zero ends the block; so does a full block (254 data bytes) that more bytes follow.
        if byte == 0 || (code == 0xFF && i + 1 < src.len()) {
            out[code_at] = code;
            code_at = out.len();
            out.push(0);
            code = 1;
        }
    }
    out[code_at] = code;
}

/// Appends the bytes stuffed in `src` (one frame, without its delimiter) to `out`. Fails on a 0x00 in `src` or a
/// code byte that points past the end.
pub fn cobs_decode(src: &[u8], out: &mut Vec<u8>) -> Result<(), FrameError> {
    let mut i = 0;
    while i < src.len() {
        let code = src[i] as usize;
        if code == 0 || i + code > src.len() {
            return Err(FrameError::Cobs);
        }
        let block = &src[i + 1..i + code];
        if block.contains(&0) {
            return Err(FrameError::Cobs);
        }
        out.extend_from_slice(block);
        i += code;
        // A block shorter than 254 data bytes stands for a 0x00 after it, except at the very end.
        if code < 0xFF && i < src.len() {
            out.push(0);
        }
    }
    Ok(())
}

/// Appends one complete frame carrying `payload` to `out`: stuffed payload and CRC, then the delimiter. Refuses a
/// payload longer than [`MAX_PAYLOAD_LEN`]. Does not allocate once `out` has grown to hold a frame.
pub fn write_frame(payload: &[u8], out: &mut Vec<u8>) -> Result<(), FrameError> {
    if payload.len() > MAX_PAYLOAD_LEN {
        return Err(FrameError::Oversized { max: MAX_PAYLOAD_LEN });
    }
    let mut frame = [0u8; MAX_FRAME_LEN];
    frame[..payload.len()].copy_from_slice(payload);
    frame[payload.len()..payload.len() + CRC_LEN].copy_from_slice(&crc32(payload).to_le_bytes());
    cobs_encode(&frame[..payload.len() + CRC_LEN], out);
    out.push(DELIMITER);
    Ok(())
}

/// Splits a byte stream into frames and checks each one. Holds at most [`MAX_ENCODED_LEN`] bytes; allocates only
/// when created.
#[derive(Debug, Clone)]
pub struct FrameDecoder {
    encoded: Vec<u8>,
    decoded: Vec<u8>,
    /// True once the current frame has overflowed; its bytes are discarded up to the next delimiter.
    overflow: bool,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        FrameDecoder::new()
    }
}

impl FrameDecoder {
    /// A decoder waiting for the start of a frame.
    pub fn new() -> Self {
        FrameDecoder {
            encoded: Vec::with_capacity(MAX_ENCODED_LEN),
            decoded: Vec::with_capacity(MAX_ENCODED_LEN),
            overflow: false,
        }
    }

    /// Takes one received byte. At a delimiter returns the frame that it ended: `Some(Ok(payload))` (the CRC
    /// checked and removed) or `Some(Err(why))`. Empty frames (two delimiters in a row) are not frames: `None`.
    pub fn push(&mut self, byte: u8) -> Option<Result<&[u8], FrameError>> {
        if byte != DELIMITER {
            if self.encoded.len() < MAX_ENCODED_LEN {
                self.encoded.push(byte);
            } else {
                self.overflow = true;
            }
            return None;
        }
        let overflow = std::mem::take(&mut self.overflow);
        if overflow {
            self.encoded.clear();
            return Some(Err(FrameError::Oversized { max: MAX_ENCODED_LEN }));
        }
        if self.encoded.is_empty() {
            return None;
        }
        self.decoded.clear();
        let unstuffed = cobs_decode(&self.encoded, &mut self.decoded);
        self.encoded.clear();
        Some(unstuffed.and_then(|()| check_crc(&self.decoded)))
    }

    /// Forgets a partly received frame.
    pub fn reset(&mut self) {
        self.encoded.clear();
        self.overflow = false;
    }
}

/// The payload of an unstuffed frame whose CRC matches.
fn check_crc(frame: &[u8]) -> Result<&[u8], FrameError> {
    if frame.len() <= CRC_LEN {
        return Err(FrameError::TooShort { len: frame.len() });
    }
    if frame.len() > MAX_FRAME_LEN {
        return Err(FrameError::Oversized { max: MAX_ENCODED_LEN });
    }
    let (payload, tail) = frame.split_at(frame.len() - CRC_LEN);
    let received = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
    let computed = crc32(payload);
    if computed != received {
        return Err(FrameError::Crc { computed, received });
    }
    Ok(payload)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stuff(src: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        cobs_encode(src, &mut out);
        out
    }

    /// The examples of Cheshire & Baker's COBS paper (as tabulated in its common descriptions).
    #[test]
    fn cobs_matches_published_examples() {
        assert_eq!(stuff(&[0x00]), [0x01, 0x01]);
        assert_eq!(stuff(&[0x00, 0x00]), [0x01, 0x01, 0x01]);
        assert_eq!(stuff(&[0x00, 0x11, 0x00]), [0x01, 0x02, 0x11, 0x01]);
        assert_eq!(stuff(&[0x11, 0x22, 0x00, 0x33]), [0x03, 0x11, 0x22, 0x02, 0x33]);
        assert_eq!(stuff(&[0x11, 0x22, 0x33, 0x44]), [0x05, 0x11, 0x22, 0x33, 0x44]);
        assert_eq!(stuff(&[0x11, 0x00, 0x00, 0x00]), [0x02, 0x11, 0x01, 0x01, 0x01]);
        assert_eq!(stuff(&[]), [0x01]);
    }

    #[test]
    fn cobs_long_runs() {
        // 254 non-zero bytes: one full block (code 0xFF), nothing after it.
        let run: Vec<u8> = (1..=254).map(|i| i as u8).collect();
        let enc = stuff(&run);
        assert_eq!(enc.len(), 255, "254-byte run");
        assert_eq!(enc[0], 0xFF);
        assert_eq!(&enc[1..], &run[..]);
        // 254 non-zero bytes and a zero: the full block, then an empty block for the zero and the final one.
        let mut with_zero = run.clone();
        with_zero.push(0);
        let enc = stuff(&with_zero);
        assert_eq!(enc.len(), 257);
        assert_eq!((enc[0], enc[255], enc[256]), (0xFF, 0x01, 0x01));
        // A zero then 254 non-zero bytes.
        let mut lead_zero = vec![0u8];
        lead_zero.extend_from_slice(&run);
        let enc = stuff(&lead_zero);
        assert_eq!((enc.len(), enc[0], enc[1]), (256, 0x01, 0xFF));
        // 255 non-zero bytes: a full block and a block of one byte.
        let run: Vec<u8> = (0..255).map(|i| (i % 255 + 1) as u8).collect();
        let enc = stuff(&run);
        assert_eq!(enc.len(), 257);
        assert_eq!((enc[0], enc[255], enc[256]), (0xFF, 0x02, run[254]));
        let mut back = Vec::new();
        cobs_decode(&enc, &mut back).expect("decodes");
        assert_eq!(back, run);
    }

    #[test]
    fn cobs_refuses_bad_codes() {
        let mut out = Vec::new();
        assert_eq!(cobs_decode(&[0x05, 0x11, 0x22], &mut out), Err(FrameError::Cobs));
        assert_eq!(cobs_decode(&[0x00, 0x11], &mut out), Err(FrameError::Cobs));
        assert_eq!(cobs_decode(&[0x03, 0x00, 0x11], &mut out), Err(FrameError::Cobs));
    }

    /// The standard check value of CRC-32/ISO-HDLC.
    #[test]
    fn crc_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }
}
