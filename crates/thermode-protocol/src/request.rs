//! Requests: what a client sends on the WebSocket (`/api/ws`), one JSON object a message, `type` naming the
//! request and `id` echoed in its reply. [`Envelope`] is a whole message; [`Request`] its body.
//!
//! Every field a request does not have is refused (`unknown_field`), so a misspelt key never goes unnoticed. Numbers
//! are checked against their ranges by the daemon (the channel against the display, temperatures and rates against
//! the envelope the channel runs), which answers `bad_value`, `unknown_channel` or `unknown_material` with a
//! message naming the key.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::materials::MaterialProperties;
pub use crate::materials::MAX_NAME_CHARS;
use crate::program::{ProgramRequest, ResponseInput};

/// A request's `id`: a number or a string of at most [`MAX_ID_CHARS`] characters, echoed unchanged in the reply.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum RequestId {
    /// A number (echoed digit for digit).
    Number(serde_json::Number),
    /// A string of at most [`MAX_ID_CHARS`] characters.
    Text(#[schemars(length(max = 128))] String),
}

impl From<u64> for RequestId {
    fn from(id: u64) -> Self {
        RequestId::Number(id.into())
    }
}

/// Longest accepted `id` string \[characters\].
pub const MAX_ID_CHARS: usize = 128;
/// Longest client marker text \[characters\].
pub const MAX_MARKER_CHARS: usize = 1024;
/// Slowest telemetry subscription \[Hz\] (one message every 100 s).
pub const MIN_SUBSCRIBE_HZ: f64 = 0.01;

/// A whole request message: its `id` and its body (whose `type` names it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Envelope {
    /// Echoed in the reply.
    pub id: RequestId,
    /// The request.
    #[serde(flatten)]
    pub request: Request,
}

impl Envelope {
    /// The message as JSON text.
    pub fn to_text(&self) -> String {
        serde_json::to_string(self).expect("a request always serialises")
    }
}

/// A request body, tagged by `type`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Request {
    /// Touch a material on a channel: a library material by name, or one given by its properties.
    Touch(Touch),
    /// Release a channel: it renders air again.
    Release(OnChannel),
    /// Direct mode: the display set-point of a channel goes to `temp_c` at `rate_c_s`.
    Setpoint(Setpoint),
    /// Clear a channel's latched safety fault (refused while its cause persists).
    ClearFault(OnChannel),
    /// Release every channel and drive 0 A on each until its next command.
    StopAll(NoFields),
    /// Telemetry messages at `rate_hz`.
    Subscribe(Subscribe),
    /// No more telemetry.
    Unsubscribe(NoFields),
    /// The daemon's status (the `/api/status` body).
    Status(NoFields),
    /// An operator acknowledges a failed recording: stimuli are accepted again.
    AckRecording(NoFields),
    /// A client's event marker, stamped with the loop clock (and sent to the LSL marker stream under `--lsl`).
    Marker(Marker),
    /// A stimulus program: each of a set of channels gets a list of segments; all start on the same tick.
    Program(ProgramRequest),
    /// End a channel's program; its set-point holds where it is.
    ProgramStop(OnChannel),
    /// A participant's response on a channel (a button press or a rating), effective on the next tick.
    Response(ResponseInput),
}

/// `touch`: a library material by name, or one given by its properties.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Touch {
    /// The channel (from 0).
    pub channel: i64,
    /// A library material (case-insensitive, aliases as in `thermode materials`); give this or `properties`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<String>,
    /// A material given by its properties; give this or `material`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub properties: Option<MaterialProperties>,
    /// The object's temperature \[°C\]; default the daemon's (23, room temperature).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object_temp_c: Option<f64>,
}

/// A request about one channel (`release`, `clear_fault`, `program_stop`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OnChannel {
    /// The channel (from 0).
    pub channel: i64,
}

/// `setpoint`: direct mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Setpoint {
    /// The channel (from 0).
    pub channel: i64,
    /// The set-point \[°C\], within the display's range.
    pub temp_c: f64,
    /// The rate \[°C/s\], positive, at most the envelope's rate limit.
    #[serde(rename = "rate_c_s")]
    pub rate_c_per_s: f64,
}

/// `subscribe`: telemetry at a rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Subscribe {
    /// Messages per second \[Hz\], from 0.01 to the daemon's maximum (`limits.max_subscribe_hz`).
    pub rate_hz: f64,
}

/// `marker`: a client's event marker.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Marker {
    /// The text: at most 1024 characters, no NUL.
    pub text: String,
    /// The channel it concerns, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub channel: Option<i64>,
}

/// A request without fields of its own (`stop_all`, `unsubscribe`, `status`, `ack_recording`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoFields {}

impl Request {
    /// Every request `type`, in the order of the protocol's documentation.
    pub const TYPES: [&'static str; 13] = [
        "touch",
        "release",
        "setpoint",
        "clear_fault",
        "stop_all",
        "subscribe",
        "unsubscribe",
        "status",
        "ack_recording",
        "marker",
        "program",
        "program_stop",
        "response",
    ];

    /// The request's `type`.
    pub fn kind(&self) -> &'static str {
        match self {
            Request::Touch(_) => "touch",
            Request::Release(_) => "release",
            Request::Setpoint(_) => "setpoint",
            Request::ClearFault(_) => "clear_fault",
            Request::StopAll(_) => "stop_all",
            Request::Subscribe(_) => "subscribe",
            Request::Unsubscribe(_) => "unsubscribe",
            Request::Status(_) => "status",
            Request::AckRecording(_) => "ack_recording",
            Request::Marker(_) => "marker",
            Request::Program(_) => "program",
            Request::ProgramStop(_) => "program_stop",
            Request::Response(_) => "response",
        }
    }

    /// A touch of the library material `material` on `channel`, at the daemon's default object temperature.
    pub fn touch(channel: usize, material: &str) -> Request {
        Request::Touch(Touch {
            channel: channel as i64,
            material: Some(material.to_string()),
            properties: None,
            object_temp_c: None,
        })
    }

    /// This request with `id`: the message to send.
    pub fn with_id(self, id: impl Into<RequestId>) -> Envelope {
        Envelope {
            id: id.into(),
            request: self,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_request_kind_is_a_serde_tag_and_listed_once() {
        let examples = [
            Request::touch(1, "wood"),
            Request::Release(OnChannel { channel: 0 }),
            Request::Setpoint(Setpoint {
                channel: 0,
                temp_c: 30.0,
                rate_c_per_s: 1.0,
            }),
            Request::ClearFault(OnChannel { channel: 0 }),
            Request::StopAll(NoFields {}),
            Request::Subscribe(Subscribe { rate_hz: 10.0 }),
            Request::Unsubscribe(NoFields {}),
            Request::Status(NoFields {}),
            Request::AckRecording(NoFields {}),
            Request::Marker(Marker {
                text: "t".into(),
                channel: None,
            }),
            Request::Program(ProgramRequest {
                channels: [("0".to_string(), vec![crate::program::SegmentSpec::default()])].into(),
            }),
            Request::ProgramStop(OnChannel { channel: 0 }),
            Request::Response(ResponseInput {
                channel: 0,
                kind: crate::program::ResponseKind::Button,
                value: None,
            }),
        ];
        let kinds: Vec<&str> = examples.iter().map(Request::kind).collect();
        assert_eq!(
            kinds,
            Request::TYPES,
            "kind() and TYPES list the same requests in the same order"
        );
        for request in examples {
            let value = serde_json::to_value(request.clone().with_id(7)).expect("serialises");
            assert_eq!(value["type"], request.kind(), "{value}");
            assert_eq!(value["id"], 7, "{value}");
        }
    }
}
