//! What the daemon sends on the WebSocket: replies to requests ([`OkReply`], [`ErrorReply`], the status), telemetry
//! and events, all tagged by `type` ([`Response`]); the stable error codes ([`ErrorCode`]); and the `/api/history`
//! body ([`History`]).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::program::{ProgramCutoff, ProgramEvent, ResponseKind};
use crate::request::RequestId;
use crate::status::{Recording, Status};
use crate::telemetry::Telemetry;

/// Stable error codes of the API (they never change meaning).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ErrorCode {
    /// The message is not valid JSON, not an object, or a binary frame.
    BadJson,
    /// `type` names no request.
    UnknownType,
    /// A required field is missing.
    MissingField,
    /// A field the request does not have.
    UnknownField,
    /// A field has the wrong type or a value out of range (NaN, huge, negative…).
    BadValue,
    /// The channel does not exist.
    UnknownChannel,
    /// The material is not in the library.
    UnknownMaterial,
    /// The message exceeds the size limit.
    TooLarge,
    /// The connection sends faster than its rate limit.
    RateLimited,
    /// Missing or wrong token.
    Unauthorized,
    /// The request's Host or Origin is not allowed (another web site, DNS rebinding).
    Forbidden,
    /// The channel has a latched safety fault; its drive is off.
    DeviceFault,
    /// The control loop is overloaded or did not answer in time; nothing changed.
    Busy,
    /// Too many WebSocket connections.
    TooManyConnections,
    /// A `stop_all` sent after this request was applied first; nothing changed.
    Cancelled,
    /// The recording failed and the policy is `stop`: stimuli are refused until `ack_recording`.
    RecordingFailed,
    /// The dose ledger cannot be written: stimuli are refused until a write succeeds again.
    DoseNotRecorded,
    /// The channel's thermal-dose budget is spent: its drive is off (0 A) and it accepts nothing but a release
    /// until the dose ledger is reset (`thermode dose reset`).
    DoseBudgetSpent,
}

impl ErrorCode {
    /// The code as it appears in messages.
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorCode::BadJson => "bad_json",
            ErrorCode::UnknownType => "unknown_type",
            ErrorCode::MissingField => "missing_field",
            ErrorCode::UnknownField => "unknown_field",
            ErrorCode::BadValue => "bad_value",
            ErrorCode::UnknownChannel => "unknown_channel",
            ErrorCode::UnknownMaterial => "unknown_material",
            ErrorCode::TooLarge => "too_large",
            ErrorCode::RateLimited => "rate_limited",
            ErrorCode::Unauthorized => "unauthorized",
            ErrorCode::Forbidden => "forbidden",
            ErrorCode::DeviceFault => "device_fault",
            ErrorCode::Busy => "busy",
            ErrorCode::TooManyConnections => "too_many_connections",
            ErrorCode::Cancelled => "cancelled",
            ErrorCode::RecordingFailed => "recording_failed",
            ErrorCode::DoseNotRecorded => "dose_not_recorded",
            ErrorCode::DoseBudgetSpent => "dose_budget_spent",
        }
    }
}

/// A refused request (also the body of an HTTP error).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ErrorReply {
    /// The request's `id`; null when it had none or an invalid one.
    pub id: Option<RequestId>,
    /// The stable code.
    pub code: ErrorCode,
    /// A human-readable explanation.
    pub message: String,
}

/// When the loop applied a command.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct AppliedAt {
    /// Index of the tick that applied it (its drive command is the first to see it).
    pub tick: u64,
    /// Loop time of that tick \[s\].
    pub time_s: f64,
}

/// A request that succeeded, tagged by the `request` it answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "request", rename_all = "snake_case")]
pub enum Done {
    /// The touch is shown from `tick` on.
    Touch {
        /// The channel.
        channel: usize,
        /// The material's name (`custom` for properties without one).
        material: String,
        /// The object temperature \[°C\].
        object_temp_c: f64,
        /// When.
        #[serde(flatten)]
        applied: AppliedAt,
    },
    /// The set-point ramp starts at `tick`.
    Setpoint {
        /// The channel.
        channel: usize,
        /// The set-point \[°C\].
        temp_c: f64,
        /// The rate \[°C/s\].
        #[serde(rename = "rate_c_s")]
        rate_c_per_s: f64,
        /// When.
        #[serde(flatten)]
        applied: AppliedAt,
    },
    /// The channel renders air from `tick` on.
    Release {
        /// The channel.
        channel: usize,
        /// When.
        #[serde(flatten)]
        applied: AppliedAt,
    },
    /// The fault is cleared.
    ClearFault {
        /// The channel.
        channel: usize,
        /// When.
        #[serde(flatten)]
        applied: AppliedAt,
    },
    /// Every channel released, 0 A until its next command.
    StopAll {
        /// When.
        #[serde(flatten)]
        applied: AppliedAt,
    },
    /// Telemetry follows at `rate_hz`.
    Subscribe {
        /// Messages per second \[Hz\].
        rate_hz: f64,
    },
    /// No more telemetry.
    Unsubscribe {},
    /// The acknowledgement of a failed recording.
    AckRecording {
        /// Something was acknowledged (the interlock, or a failed recording).
        acknowledged: bool,
        /// The recording, if any.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        recording: Option<Recording>,
    },
    /// The marker is stamped.
    Marker {
        /// The channel it concerns, if any.
        channel: Option<usize>,
        /// Loop time of the marker \[s\].
        time_s: f64,
        /// Its LSL time \[s\], under `--lsl`.
        lsl_time_s: Option<f64>,
        /// The marker went to the LSL marker stream.
        lsl: bool,
    },
    /// The program runs: every channel's first set-point is that of `start_tick`.
    Program {
        /// The channels, in order.
        channels: Vec<usize>,
        /// The tick whose set-point is every channel's first of the program.
        start_tick: u64,
        /// Loop time of that tick \[s\].
        start_time_s: f64,
        /// The display's limit a target was clipped to \[°C\] (the first clipped one's), if any was: the
        /// display's cut-off, never applied silently.
        cutoff_c: Option<f64>,
        /// Every clipped target.
        cutoffs: Vec<ProgramCutoff>,
        /// When (the same tick).
        #[serde(flatten)]
        applied: AppliedAt,
    },
    /// The channel's program ended; its set-point holds.
    ProgramStop {
        /// The channel.
        channel: usize,
        /// When.
        #[serde(flatten)]
        applied: AppliedAt,
    },
    /// The response took effect on `tick`: the plate and set-point at that tick.
    Response {
        /// The channel.
        channel: usize,
        /// `button` or `rating`.
        kind: ResponseKind,
        /// The rating (ratings only).
        value: Option<f64>,
        /// The plate sensor at the response's tick \[°C\] (null where the device cannot measure).
        sensor_c: Option<f64>,
        /// The plate estimate at that tick \[°C\] (null where the device cannot measure).
        plate_estimate_c: Option<f64>,
        /// The display set-point of that tick \[°C\].
        setpoint_c: Option<f64>,
        /// The `until: response` segment the response ended, if it ended one.
        ended_segment: Option<usize>,
        /// When: the tick the response took effect on.
        #[serde(flatten)]
        applied: AppliedAt,
    },
}

/// A successful reply.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct OkReply {
    /// The request's `id`.
    pub id: RequestId,
    /// What was done.
    #[serde(flatten)]
    pub done: Done,
}

/// The reply to `status`: the status with the request's `id`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct StatusReply {
    /// The request's `id`.
    pub id: RequestId,
    /// The status.
    #[serde(flatten)]
    pub status: Status,
}

/// What happened to the recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RecordingEvent {
    /// A write failed.
    RecordingFailed,
    /// An operator acknowledged the failure.
    RecordingAcknowledged,
    /// The recording goes on in a new file.
    RecordingResumed,
}

/// An event every client is told of.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Event {
    /// What happened.
    pub event: RecordingEvent,
    /// The recording as it now stands.
    pub recording: Recording,
}

/// Every message the daemon sends on the WebSocket, tagged by `type`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Response {
    /// A request succeeded.
    Ok(OkReply),
    /// A request was refused.
    Error(ErrorReply),
    /// The reply to `status`.
    // Boxed: it is far larger than the other messages.
    Status(Box<StatusReply>),
    /// Telemetry of a subscription.
    Telemetry(Telemetry),
    /// An event.
    Event(Event),
    /// A program's event (a segment's start, a response, the program's end), to telemetry subscribers.
    ProgramEvent(ProgramEvent),
}

impl Response {
    /// The message as JSON text.
    pub fn to_text(&self) -> String {
        serde_json::to_string(self).expect("a response always serialises")
    }
}

/// The `/api/history` body: per channel, parallel arrays over the kept samples (null where not finite).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct History {
    /// Samples per second \[Hz\].
    pub rate_hz: f64,
    /// The window kept \[s\].
    pub window_s: f64,
    /// Loop time of each sample \[s\].
    pub time_s: Vec<f64>,
    /// Every channel.
    pub channels: Vec<ChannelHistory>,
}

/// One channel's columns of [`History`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ChannelHistory {
    /// The channel.
    pub channel: usize,
    /// Target skin temperature \[°C\].
    pub target_skin_c: Vec<Option<f64>>,
    /// Rendered skin temperature \[°C\].
    pub skin_c: Vec<Option<f64>>,
    /// Plate sensor \[°C\].
    pub sensor_c: Vec<Option<f64>>,
    /// Display set-point \[°C\].
    pub display_setpoint_c: Vec<Option<f64>>,
    /// Drive current \[A\].
    pub current_a: Vec<Option<f64>>,
}
