//! The TCS II serial protocol as far as the public record shows it (115200 baud 8N1, ASCII): the host's commands
//! are a letter and fixed-width decimal arguments with no terminator ([`Command`]); the stimulator answers in
//! lines that begin with a carriage return, interleaving command replies with the temperatures it streams
//! ([`LineDecoder`], [`Line`]).
//!
//! Temperature lines carry the neutral (probe) temperature and the five zones in tenths of a degree: three digits,
//! then a sign and three digits per zone (`320+321+320+319+320+320`). The decoder classifies every line, never
//! panics, drops lines longer than [`MAX_LINE_LEN`] and resynchronises at the next carriage return or line feed.

use thiserror::Error;

/// Zones (stimulation areas) of a TCS II probe: 5.
pub const TCS2_ZONES: usize = 5;
/// Baud rate of the stimulator's serial port \[bit/s\]: 115200.
pub const TCS2_BAUD_RATE: u32 = 115_200;
/// Longest line the decoder keeps \[bytes\]: 128 (a temperature line has 23 characters; the longest reply
/// thermode reads is shorter).
pub const MAX_LINE_LEN: usize = 128;
/// Lowest stimulation temperature the stimulator takes \[°C\]: 10.0 (`C` argument 100).
pub const TCS2_MIN_C: f64 = 10.0;
/// Highest stimulation temperature the stimulator takes \[°C\]: 60.0 (`C` argument 600).
pub const TCS2_MAX_C: f64 = 60.0;
/// Neutral temperature range \[°C\]: 20.0 to 40.0 (`N` argument 200 to 400).
pub const TCS2_NEUTRAL_RANGE_C: (f64, f64) = (20.0, 40.0);

/// A host command. Temperatures in tenths of a degree, speeds in tenths of a degree per second; `zone` 0 means
/// every zone, 1 to 5 one zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// `?`: the stimulator answers `TCS`.
    Identify,
    /// `F`: mute mode (no temperatures streamed between and during stimulations).
    Mute,
    /// `Oa`: stream temperatures between stimulations (1 Hz).
    StreamBetween,
    /// `Ob`: stream temperatures during stimulations (100 Hz).
    StreamDuring,
    /// `Nxxx`: neutral temperature, 200 to 400.
    Neutral(u16),
    /// `Sxxxxx`: enable (true) or disable each zone.
    Zones([bool; TCS2_ZONES]),
    /// `Csxxx`: stimulation temperature of `zone`, 100 to 600.
    Target {
        /// 0 (all) or 1 to 5.
        zone: u8,
        /// Tenths of a degree.
        tenths: u16,
    },
    /// `Vsxxxx`: stimulation (rise) speed of `zone`, 1 to 9999.
    Speed {
        /// 0 (all) or 1 to 5.
        zone: u8,
        /// Tenths of a degree per second.
        tenths: u16,
    },
    /// `Rsxxxx`: return speed of `zone`, 1 to 9999.
    ReturnSpeed {
        /// 0 (all) or 1 to 5.
        zone: u8,
        /// Tenths of a degree per second.
        tenths: u16,
    },
    /// `Dsxxxxx`: stimulation duration of `zone` \[ms\], 1 to 99999.
    Duration {
        /// 0 (all) or 1 to 5.
        zone: u8,
        /// Milliseconds.
        ms: u32,
    },
    /// `Omxxx`: the maximum stimulation temperature; `C` is limited to it.
    MaxTemperature(u16),
    /// `Od`: follow mode — each zone goes to its stimulation temperature and stays there while it does not
    /// change.
    Follow,
    /// `A`: abort the stimulation or leave follow mode, back to neutral.
    Abort,
    /// `E`: the current temperatures, once (a temperature line).
    Temperatures,
    /// `Q`: the error state (six digits, neutral and zones; 0 OK).
    ErrorState,
}

impl Command {
    /// Appends the command's bytes to `out`.
    pub fn encode(&self, out: &mut Vec<u8>) {
        let text = match *self {
            Command::Identify => "?".to_string(),
            Command::Mute => "F".to_string(),
            Command::StreamBetween => "Oa".to_string(),
            Command::StreamDuring => "Ob".to_string(),
            Command::Neutral(t) => format!("N{:03}", t.min(999)),
            Command::Zones(zones) => {
                let flags: String = zones.iter().map(|&on| if on { '1' } else { '0' }).collect();
                format!("S{flags}")
            }
            Command::Target { zone, tenths } => format!("C{}{:03}", zone.min(9), tenths.min(999)),
            Command::Speed { zone, tenths } => format!("V{}{:04}", zone.min(9), tenths.min(9999)),
            Command::ReturnSpeed { zone, tenths } => format!("R{}{:04}", zone.min(9), tenths.min(9999)),
            Command::Duration { zone, ms } => format!("D{}{:05}", zone.min(9), ms.min(99_999)),
            Command::MaxTemperature(t) => format!("Om{:03}", t.min(999)),
            Command::Follow => "Od".to_string(),
            Command::Abort => "A".to_string(),
            Command::Temperatures => "E".to_string(),
            Command::ErrorState => "Q".to_string(),
        };
        out.extend_from_slice(text.as_bytes());
    }
}

/// Tenths of a degree of `celsius`, rounded (None if not finite or outside 0 to 999.9).
pub fn tenths(celsius: f64) -> Option<u16> {
    let t = (celsius * 10.0).round();
    (t.is_finite() && (0.0..=999.0).contains(&t)).then_some(t as u16)
}

/// The temperatures of one temperature line \[°C\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Temperatures {
    /// Neutral (probe) temperature \[°C\].
    pub neutral_c: f64,
    /// Zone temperatures \[°C\] (the first `zone_count` are valid).
    pub zones_c: [f64; TCS2_ZONES],
    /// Zones on the line, 1 to 5.
    pub zone_count: usize,
}

impl Temperatures {
    /// The line text (without the leading carriage return): `NNN` then `±ZZZ` per zone, tenths of a degree.
    pub fn to_line(&self) -> String {
        let mut line = format!("{:03}", (self.neutral_c * 10.0).round().clamp(0.0, 999.0) as u16);
        for &zone_c in &self.zones_c[..self.zone_count.min(TCS2_ZONES)] {
            let t = (zone_c * 10.0).round().clamp(-999.0, 999.0) as i32;
            line.push_str(&format!("{}{:03}", if t < 0 { '-' } else { '+' }, t.abs()));
        }
        line
    }
}

/// One line from the stimulator, classified.
#[derive(Debug, Clone, PartialEq)]
pub enum Line {
    /// Temperatures (streamed, or the answer to `E`).
    Temperatures(Temperatures),
    /// The answer to `?`.
    Identity,
    /// The answer to `Q`: one code per neutral and zone (0 OK).
    ErrorState(Vec<u8>),
    /// Any other text: a reply thermode does not interpret (kept for diagnostics).
    Other(String),
}

/// Why a line was dropped.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum LineError {
    /// More than [`MAX_LINE_LEN`] bytes without an end of line.
    #[error("TCS II line longer than {MAX_LINE_LEN} bytes")]
    TooLong,
    /// A byte outside printable ASCII.
    #[error("TCS II line has a byte 0x{byte:02X} outside printable ASCII")]
    NotAscii {
        /// The byte.
        byte: u8,
    },
}

/// Classifies one line's text (no line ends).
pub fn classify(text: &str) -> Line {
    if text == "TCS" {
        return Line::Identity;
    }
    let bytes = text.as_bytes();
    if bytes.len() == 1 + TCS2_ZONES && bytes.iter().all(u8::is_ascii_digit) {
        return Line::ErrorState(bytes.iter().map(|b| b - b'0').collect());
    }
    if let Some(t) = parse_temperatures(bytes) {
        return Line::Temperatures(t);
    }
    Line::Other(text.to_string())
}

/// `NNN` then 1 to 5 groups `±ZZZ`, all digits.
fn parse_temperatures(bytes: &[u8]) -> Option<Temperatures> {
    let digits = |b: &[u8]| -> Option<f64> {
        (b.len() == 3 && b.iter().all(u8::is_ascii_digit))
            .then(|| f64::from((b[0] - b'0') as u16 * 100 + (b[1] - b'0') as u16 * 10 + (b[2] - b'0') as u16) / 10.0)
    };
    if bytes.len() < 7 || !(bytes.len() - 3).is_multiple_of(4) {
        return None;
    }
    let zone_count = (bytes.len() - 3) / 4;
    if zone_count > TCS2_ZONES {
        return None;
    }
    let neutral_c = digits(&bytes[..3])?;
    let mut zones_c = [f64::NAN; TCS2_ZONES];
    for (z, group) in bytes[3..].chunks(4).enumerate() {
        let sign = match group[0] {
            b'+' => 1.0,
            b'-' => -1.0,
            _ => return None,
        };
        zones_c[z] = sign * digits(&group[1..])?;
    }
    Some(Temperatures {
        neutral_c,
        zones_c,
        zone_count,
    })
}

/// Cuts the stimulator's byte stream into classified lines. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct LineDecoder {
    buf: Vec<u8>,
    overflow: bool,
    bad_byte: Option<u8>,
    /// Lines decoded.
    pub lines: u64,
    /// Lines dropped.
    pub dropped: u64,
}

impl LineDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        LineDecoder::default()
    }

    /// Takes one byte; returns a line (or why one was dropped) when the byte ends a non-empty one.
    pub fn push(&mut self, byte: u8) -> Option<Result<Line, LineError>> {
        if byte == b'\r' || byte == b'\n' {
            let overflow = std::mem::take(&mut self.overflow);
            let bad = self.bad_byte.take();
            if self.buf.is_empty() && !overflow && bad.is_none() {
                return None;
            }
            let result = if overflow {
                Err(LineError::TooLong)
            } else if let Some(byte) = bad {
                Err(LineError::NotAscii { byte })
            } else {
                // Printable ASCII is UTF-8.
                Ok(classify(&String::from_utf8_lossy(&self.buf)))
            };
            self.buf.clear();
            match result {
                Ok(_) => self.lines += 1,
                Err(_) => self.dropped += 1,
            }
            return Some(result);
        }
        if !(0x20..0x7F).contains(&byte) {
            self.bad_byte.get_or_insert(byte);
        } else if self.buf.len() >= MAX_LINE_LEN {
            self.overflow = true;
        } else {
            self.buf.push(byte);
        }
        None
    }

    /// Takes `bytes`, handing every result to `each`.
    pub fn feed(&mut self, bytes: &[u8], mut each: impl FnMut(Result<Line, LineError>)) {
        for &byte in bytes {
            if let Some(result) = self.push(byte) {
                each(result);
            }
        }
    }
}

/// Why a command from the host was not taken (the emulator's side).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParseStep {
    /// Not enough bytes yet.
    Incomplete,
    /// A command of this many bytes.
    Command(Command, usize),
    /// The first byte starts no known command (or its arguments are not digits): skip this many bytes.
    Skip(usize),
}

/// Parses the command at the start of `bytes` (the emulator's side).
pub fn parse_command(bytes: &[u8]) -> ParseStep {
    let Some(&first) = bytes.first() else {
        return ParseStep::Incomplete;
    };
    let number = |from: usize, len: usize| -> Option<Option<u32>> {
        if bytes.len() < from + len {
            return Some(None);
        }
        let field = &bytes[from..from + len];
        field
            .iter()
            .all(u8::is_ascii_digit)
            .then(|| Some(field.iter().fold(0u32, |acc, b| acc * 10 + u32::from(b - b'0'))))
    };
    let zone_number = |len: usize, make: fn(u8, u32) -> Command| -> ParseStep {
        match (number(1, 1), number(2, len)) {
            (Some(Some(zone)), Some(Some(value))) if zone <= 5 => ParseStep::Command(make(zone as u8, value), 2 + len),
            (Some(None), _) | (_, Some(None)) => ParseStep::Incomplete,
            _ => ParseStep::Skip(1),
        }
    };
    match first {
        b'?' => ParseStep::Command(Command::Identify, 1),
        b'F' => ParseStep::Command(Command::Mute, 1),
        b'A' => ParseStep::Command(Command::Abort, 1),
        b'E' => ParseStep::Command(Command::Temperatures, 1),
        b'Q' => ParseStep::Command(Command::ErrorState, 1),
        b'N' => match number(1, 3) {
            Some(Some(t)) => ParseStep::Command(Command::Neutral(t as u16), 4),
            Some(None) => ParseStep::Incomplete,
            None => ParseStep::Skip(1),
        },
        b'S' => {
            if bytes.len() < 1 + TCS2_ZONES {
                return ParseStep::Incomplete;
            }
            let flags = &bytes[1..=TCS2_ZONES];
            if flags.iter().all(|b| *b == b'0' || *b == b'1') {
                let mut zones = [false; TCS2_ZONES];
                for (z, f) in zones.iter_mut().zip(flags) {
                    *z = *f == b'1';
                }
                ParseStep::Command(Command::Zones(zones), 1 + TCS2_ZONES)
            } else {
                ParseStep::Skip(1)
            }
        }
        b'C' => zone_number(3, |zone, v| Command::Target { zone, tenths: v as u16 }),
        b'V' => zone_number(4, |zone, v| Command::Speed { zone, tenths: v as u16 }),
        b'R' => zone_number(4, |zone, v| Command::ReturnSpeed { zone, tenths: v as u16 }),
        b'D' => zone_number(5, |zone, ms| Command::Duration { zone, ms }),
        b'O' => match bytes.get(1) {
            None => ParseStep::Incomplete,
            Some(b'a') => ParseStep::Command(Command::StreamBetween, 2),
            Some(b'b') => ParseStep::Command(Command::StreamDuring, 2),
            Some(b'd') => ParseStep::Command(Command::Follow, 2),
            Some(b'm') => match number(2, 3) {
                Some(Some(t)) => ParseStep::Command(Command::MaxTemperature(t as u16), 5),
                Some(None) => ParseStep::Incomplete,
                None => ParseStep::Skip(1),
            },
            Some(_) => ParseStep::Skip(2),
        },
        _ => ParseStep::Skip(1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_have_the_published_spelling_and_parse_back() {
        let cases = [
            (Command::Neutral(320), "N320"),
            (Command::Target { zone: 0, tenths: 450 }, "C0450"),
            (Command::Target { zone: 3, tenths: 100 }, "C3100"),
            (Command::Speed { zone: 0, tenths: 200 }, "V00200"),
            (Command::ReturnSpeed { zone: 1, tenths: 9999 }, "R19999"),
            (Command::Duration { zone: 0, ms: 99_999 }, "D099999"),
            (Command::MaxTemperature(480), "Om480"),
            (Command::Zones([true, true, false, false, true]), "S11001"),
            (Command::Follow, "Od"),
            (Command::Mute, "F"),
            (Command::Abort, "A"),
            (Command::Temperatures, "E"),
            (Command::ErrorState, "Q"),
            (Command::Identify, "?"),
        ];
        for (command, text) in cases {
            let mut out = Vec::new();
            command.encode(&mut out);
            assert_eq!(String::from_utf8_lossy(&out), text, "{command:?}");
            assert_eq!(
                parse_command(text.as_bytes()),
                ParseStep::Command(command, text.len()),
                "{text}"
            );
        }
        assert_eq!(parse_command(b"C04"), ParseStep::Incomplete);
        assert_eq!(parse_command(b"C0x50"), ParseStep::Skip(1));
        assert_eq!(parse_command(b"Z"), ParseStep::Skip(1));
    }

    #[test]
    fn lines_are_classified() {
        let mut decoder = LineDecoder::new();
        let mut got = Vec::new();
        decoder.feed(b"\r320+321+320-005+320+320\rTCS\r000000\r\rhello\r\n", |l| got.push(l));
        assert_eq!(got.len(), 4, "{got:?}");
        let Ok(Line::Temperatures(t)) = &got[0] else {
            panic!("not temperatures: {:?}", got[0]);
        };
        assert_eq!(
            (t.neutral_c, t.zones_c[0], t.zones_c[2], t.zone_count),
            (32.0, 32.1, -0.5, 5)
        );
        assert_eq!(t.to_line(), "320+321+320-005+320+320");
        assert_eq!(got[1], Ok(Line::Identity));
        assert_eq!(got[2], Ok(Line::ErrorState(vec![0; 6])));
        assert_eq!(got[3], Ok(Line::Other("hello".to_string())));
    }
}
