//! MeCom payloads (MeCom Protocol Specification 5117C §2–3) and the parameters thermode uses (TEC Controller
//! Communication Protocol 5136AL §3.3).
//!
//! Requests: `?IF` (firmware identity), `RS` (reset), `?VR` + id (4 hex) + instance (2 hex) (read a value),
//! `VS` + id + instance + value (8 hex) (set a value), `?VM` + id + instance (meta data, of which thermode uses the
//! number of instances). Values are 32 bits on the wire: FLOAT32 as its IEEE-754 bits, INT32 as two's complement.
//! Answers: the value (8 hex), an acknowledge (the set command's own CRC, 4 hex), the identity (20 characters), the
//! meta data, or a server error `+` and a code (2 hex).

use thermode_device::RequestFault;
use thiserror::Error;

use super::frame::{parse_hex, push_hex};

/// A MeCom parameter id and what it holds. See the module documentation for the sources.
pub mod param {
    /// Device type (INT32, e.g. 1089 for a TEC-1089).
    pub const DEVICE_TYPE: u16 = 100;
    /// Serial number (INT32), what tells one controller from another of its type.
    pub const SERIAL_NUMBER: u16 = 102;
    /// Device status (INT32): 0 init, 1 ready, 2 run, 3 error, 4 bootloader, 5 reset within 200 ms.
    pub const DEVICE_STATUS: u16 = 104;
    /// Error number (INT32; 0: none).
    pub const ERROR_NUMBER: u16 = 105;
    /// Saving to flash off (INT32): 0 every stored parameter set is saved to flash (about 0.5 s after the last
    /// change; the power-up state), 1 the parameters are RAM only until the device restarts.
    pub const FLASH_SAVE_OFF: u16 = 108;
    /// Flash status (INT32, read only): 0 every parameter saved, 1 a save pending or under way, 2 saving is off.
    pub const FLASH_STATUS: u16 = 109;
    /// Object (plate) temperature \[°C\] (FLOAT32, read only).
    pub const OBJECT_TEMPERATURE: u16 = 1000;
    /// Sink (hot-side) temperature \[°C\] (FLOAT32, read only).
    pub const SINK_TEMPERATURE: u16 = 1001;
    /// Target object temperature the controller follows \[°C\] (FLOAT32, read only).
    pub const TARGET_OBJECT_TEMPERATURE: u16 = 1010;
    /// Actual output current \[A\] (FLOAT32, read only).
    pub const ACTUAL_OUTPUT_CURRENT: u16 = 1020;
    /// Actual output voltage \[V\] (FLOAT32, read only).
    pub const ACTUAL_OUTPUT_VOLTAGE: u16 = 1021;
    /// Output stage input selection (INT32): 0 static current/voltage, 1 live current/voltage, 2 temperature
    /// controller.
    pub const INPUT_SELECTION: u16 = 2000;
    /// Output stage enable (INT32): 0 static off, 1 static on, 2 live off/on (by [`LIVE_ENABLE`]), 3 hardware enable.
    pub const OUTPUT_STAGE_ENABLE: u16 = 2010;
    /// Current limitation \[A\] (FLOAT32).
    pub const CURRENT_LIMITATION: u16 = 2030;
    /// Voltage limitation \[V\] (FLOAT32).
    pub const VOLTAGE_LIMITATION: u16 = 2031;
    /// Communication watchdog timeout \[s\] (FLOAT32, 0.1 to 600; 0 disables it). When no frame arrives for this
    /// long the device enters its error state (error 183) and its output stage is disabled.
    pub const WATCHDOG_TIMEOUT: u16 = 2060;
    /// Positive current is (INT32): 0 cooling, 1 heating.
    pub const POSITIVE_CURRENT_IS: u16 = 3034;
    /// Object temperature lower error threshold \[°C\] (FLOAT32): below it, error 137 and the output is disabled.
    pub const LOWER_ERROR_THRESHOLD: u16 = 4010;
    /// Object temperature upper error threshold \[°C\] (FLOAT32): above it, error 138 and the output is disabled.
    pub const UPPER_ERROR_THRESHOLD: u16 = 4011;
    /// Largest plausible object temperature change \[°C/s\] (FLOAT32, 1 to 200): faster, error 139.
    pub const MAX_TEMP_CHANGE: u16 = 4012;
    /// Error state auto-restart delay \[s\] (FLOAT32; 0: the error state holds until a reset).
    pub const ERROR_RESTART_DELAY: u16 = 6310;
    /// Live enable (INT32, volatile, 0 at reset): the output enable while [`OUTPUT_STAGE_ENABLE`] is 2.
    pub const LIVE_ENABLE: u16 = 50000;
    /// Live set current \[A\] (FLOAT32, volatile, 0 at reset): the output current while [`INPUT_SELECTION`] is 1.
    pub const LIVE_SET_CURRENT: u16 = 50001;
    /// Live set voltage \[V\] (FLOAT32, volatile, 0 at reset): the output voltage while [`INPUT_SELECTION`] is 1.
    pub const LIVE_SET_VOLTAGE: u16 = 50002;
    /// Object target temperature source (INT32, volatile, 0 at reset): 0 parameter 3000, 1 [`LIVE_TARGET`].
    pub const TARGET_SOURCE: u16 = 50011;
    /// Live object target temperature \[°C\] (FLOAT32, volatile, 0 at reset).
    pub const LIVE_TARGET: u16 = 50012;
}

/// Device status values of [`param::DEVICE_STATUS`].
pub mod status {
    /// Initialising.
    pub const INIT: i32 = 0;
    /// Ready: no error, output stage disabled.
    pub const READY: i32 = 1;
    /// Run: no error, output stage enabled.
    pub const RUN: i32 = 2;
    /// Error: output stage disabled until the error is cleared (a reset, or the auto-restart delay).
    pub const ERROR: i32 = 3;
}

/// Device error numbers thermode names (TEC-Family User Manual 5216G §8.2).
pub mod error_number {
    /// Object temperature below the lower error threshold.
    pub const OBJECT_TOO_LOW: i32 = 137;
    /// Object temperature above the upper error threshold.
    pub const OBJECT_TOO_HIGH: i32 = 138;
    /// Object temperature changing faster than the maximum change.
    pub const OBJECT_TOO_FAST: i32 = 139;
    /// No frame received within the communication watchdog timeout.
    pub const WATCHDOG: i32 = 183;
}

/// A short description of device error `number` (TEC-Family User Manual 5216G §8.2).
pub fn describe_error(number: i32) -> &'static str {
    match number {
        0 => "no error",
        30..=37 => "power supply out of range",
        50..=52 => "on-board flash failure",
        60 => "device running too hot",
        100..=105 => "output over-current or over-voltage",
        106..=111 => "output stage fault",
        error_number::OBJECT_TOO_LOW => "object temperature below the lower error threshold",
        error_number::OBJECT_TOO_HIGH => "object temperature above the upper error threshold",
        error_number::OBJECT_TOO_FAST => "object temperature changing too fast",
        142..=144 => "sink temperature out of range",
        150..=153 => "object temperature measurement circuit failure",
        error_number::WATCHDOG => "no frame within the communication watchdog timeout",
        _ => "see the device manual",
    }
}

/// A server error code of an answer (MeCom Protocol Specification 5117C §1.3.4).
pub fn describe_server_error(code: u8) -> &'static str {
    match code {
        1 => "command not available",
        2 => "device busy",
        3 => "general communication error",
        4 => "format error",
        5 => "parameter not available",
        6 => "parameter read only",
        7 => "value out of range",
        8 => "instance not available",
        9 => "parameter general failure",
        _ => "unknown server error",
    }
}

/// A request from the host.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Request {
    /// `?IF`: the 20-character firmware identity.
    Identify,
    /// `RS`: reset the device (acknowledged; the device resets within 200 ms).
    Reset,
    /// `?VR`: read parameter `id` of `instance`.
    Read {
        /// Parameter id.
        id: u16,
        /// Instance (channel), from 1.
        instance: u8,
    },
    /// `?VM`: the meta data of parameter `id` of `instance`.
    Meta {
        /// Parameter id.
        id: u16,
        /// Instance, from 1.
        instance: u8,
    },
    /// `VS`: set parameter `id` of `instance` to the 32 bits `value`.
    Set {
        /// Parameter id.
        id: u16,
        /// Instance, from 1.
        instance: u8,
        /// The value's 32 bits (FLOAT32 bits or INT32 two's complement).
        value: u32,
    },
}

impl Request {
    /// Sets FLOAT32 parameter `id` of `instance` to `value`.
    pub fn set_f32(id: u16, instance: u8, value: f32) -> Self {
        Request::Set {
            id,
            instance,
            value: value.to_bits(),
        }
    }

    /// Sets INT32 parameter `id` of `instance` to `value`.
    pub fn set_i32(id: u16, instance: u8, value: i32) -> Self {
        Request::Set {
            id,
            instance,
            value: value as u32,
        }
    }

    /// The request's command: `?IF`, `RS`, `?VR`, `?VM` or `VS`.
    pub fn command(&self) -> &'static str {
        match self {
            Request::Identify => "?IF",
            Request::Reset => "RS",
            Request::Read { .. } => "?VR",
            Request::Meta { .. } => "?VM",
            Request::Set { .. } => "VS",
        }
    }

    /// The payload text.
    pub fn payload(&self) -> String {
        let mut out = Vec::with_capacity(24);
        match *self {
            Request::Identify => out.extend_from_slice(b"?IF"),
            Request::Reset => out.extend_from_slice(b"RS"),
            Request::Read { id, instance } | Request::Meta { id, instance } => {
                out.extend_from_slice(if matches!(self, Request::Read { .. }) {
                    b"?VR"
                } else {
                    b"?VM"
                });
                push_hex(&mut out, u32::from(id), 4);
                push_hex(&mut out, u32::from(instance), 2);
            }
            Request::Set { id, instance, value } => {
                out.extend_from_slice(b"VS");
                push_hex(&mut out, u32::from(id), 4);
                push_hex(&mut out, u32::from(instance), 2);
                push_hex(&mut out, value, 8);
            }
        }
        String::from_utf8(out).unwrap_or_default()
    }

    /// Parses a host payload (the device side). `Err` carries the server error code to answer: 1 for an unknown
    /// command, 4 for a format error.
    pub fn parse(payload: &str) -> Result<Request, u8> {
        let bytes = payload.as_bytes();
        let id_instance = |rest: &[u8]| -> Result<(u16, u8), u8> {
            if rest.len() < 6 {
                return Err(4);
            }
            let id = parse_hex(&rest[..4]).ok_or(4u8)? as u16;
            let instance = parse_hex(&rest[4..6]).ok_or(4u8)? as u8;
            Ok((id, instance))
        };
        if payload == "?IF" {
            Ok(Request::Identify)
        } else if payload == "RS" {
            Ok(Request::Reset)
        } else if let Some(rest) = bytes.strip_prefix(b"?VR") {
            if rest.len() != 6 {
                return Err(4);
            }
            let (id, instance) = id_instance(rest)?;
            Ok(Request::Read { id, instance })
        } else if let Some(rest) = bytes.strip_prefix(b"?VM") {
            if rest.len() != 6 {
                return Err(4);
            }
            let (id, instance) = id_instance(rest)?;
            Ok(Request::Meta { id, instance })
        } else if let Some(rest) = bytes.strip_prefix(b"VS") {
            if rest.len() != 14 {
                return Err(4);
            }
            let (id, instance) = id_instance(rest)?;
            let value = parse_hex(&rest[6..14]).ok_or(4u8)?;
            Ok(Request::Set { id, instance, value })
        } else {
            Err(1)
        }
    }
}

/// Why an answer does not answer its request.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum AnswerError {
    /// The device answered with a server error.
    #[error("the device answered server error {code} ({})", describe_server_error(*code))]
    Server {
        /// The code.
        code: u8,
    },
    /// The answer has the wrong shape for the request.
    #[error("unexpected answer of {length} characters to {request}")]
    Unexpected {
        /// The answer's payload length \[characters\].
        length: usize,
        /// The request's command (`?IF`, `RS`, `?VR`, `?VM`, `VS`).
        request: &'static str,
    },
}

impl From<AnswerError> for RequestFault {
    fn from(error: AnswerError) -> Self {
        match error {
            AnswerError::Server { code } => RequestFault::Server {
                code,
                meaning: describe_server_error(code),
            },
            AnswerError::Unexpected { length, request } => RequestFault::Unexpected { length, request },
        }
    }
}

/// A server error in an answer's payload (`+` and 2 hex digits), if it is one.
pub fn server_error(payload: &str) -> Option<u8> {
    let rest = payload.strip_prefix('+')?;
    if rest.len() != 2 {
        return None;
    }
    parse_hex(rest.as_bytes()).map(|v| v as u8)
}

/// Checks an answer's payload against its request: a value (`Some` bits) for `?VR`, the max number of instances
/// for `?VM`, the identity text length for `?IF` (`None`), the set command's CRC for `VS` and `RS` (`None`).
pub fn check_answer(request: &Request, request_crc: u16, payload: &str) -> Result<Option<u32>, AnswerError> {
    if let Some(code) = server_error(payload) {
        return Err(AnswerError::Server { code });
    }
    let unexpected = || AnswerError::Unexpected {
        length: payload.len(),
        request: request.command(),
    };
    let bytes = payload.as_bytes();
    match request {
        Request::Identify => (payload.len() == 20).then_some(None).ok_or_else(unexpected),
        Request::Read { .. } => match bytes.len() {
            8 => parse_hex(bytes).map(Some).ok_or_else(unexpected),
            _ => Err(unexpected()),
        },
        Request::Meta { .. } => {
            // type (2), flags (2), max instances (2), max elements (8), min, max, actual (8 each).
            if bytes.len() != 38 {
                return Err(unexpected());
            }
            parse_hex(&bytes[4..6]).map(Some).ok_or_else(unexpected)
        }
        Request::Set { .. } | Request::Reset => (parse_hex(bytes) == Some(u32::from(request_crc)) && bytes.len() == 4)
            .then_some(None)
            .ok_or_else(unexpected),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payloads_round_trip() {
        let cases = [
            (Request::Identify, "?IF"),
            (Request::Reset, "RS"),
            (Request::Read { id: 1000, instance: 1 }, "?VR03E801"),
            (Request::Meta { id: 1000, instance: 1 }, "?VM03E801"),
            (Request::set_i32(2010, 1, 2), "VS07DA0100000002"),
            (Request::set_f32(3000, 1, 21.75), "VS0BB80141AE0000"),
            (Request::set_f32(50001, 2, -1.5), "VSC35102BFC00000"),
        ];
        for (request, text) in cases {
            assert_eq!(request.payload(), text, "{request:?}");
            assert_eq!(Request::parse(text), Ok(request), "{text}");
        }
        assert_eq!(Request::parse("XX"), Err(1));
        assert_eq!(Request::parse("?VR03E8"), Err(4));
        assert_eq!(Request::parse("VS07DA01000000G2"), Err(4));
    }

    #[test]
    fn answers_are_checked_against_their_request() {
        let read = Request::Read { id: 100, instance: 1 };
        assert_eq!(check_answer(&read, 0, "00000441"), Ok(Some(1089)));
        assert_eq!(check_answer(&read, 0, "+05"), Err(AnswerError::Server { code: 5 }));
        assert!(check_answer(&read, 0, "0441").is_err());
        let set = Request::set_i32(2010, 1, 2);
        assert_eq!(check_answer(&set, 0x8F97, "8F97"), Ok(None));
        assert!(check_answer(&set, 0x8F97, "8F98").is_err());
        assert_eq!(check_answer(&Request::Identify, 0, "8065-TEC SW G01     "), Ok(None));
        assert_eq!(server_error("+0G"), None);
    }
}
