//! Stimulus programs and participants' responses on the wire: the `program`, `program_stop` and `response`
//! requests' bodies ([`ProgramRequest`], [`SegmentSpec`], [`ResponseInput`]), what their replies add
//! ([`ProgramCutoff`]), and the events a program sends to subscribers ([`ProgramEvent`]).
//!
//! A segment is written as the lab writes it: `{"to_c": T, "rate_c_s": R}` is a ramp, `{"to_c": T}` a step (as
//! fast as the envelope allows), `{"hold_s": D}` a hold; a ramp or hold may add `"until": "response"`. The daemon
//! decides which one a segment is and refuses any other combination (`bad_value`, naming the segment).

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// `program`: each channel's list of segments (at most 999 a channel), keyed by the channel number as a string.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ProgramRequest {
    /// Per channel (`"0"`, `"3"`, …): its segments, run in order. All channels start on the same tick.
    pub channels: BTreeMap<String, Vec<SegmentSpec>>,
}

/// One segment: a ramp (`to_c` and `rate_c_s`), a step (`to_c` alone) or a hold (`hold_s` alone).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SegmentSpec {
    /// Target \[°C\] of a ramp or step; beyond the display's range it is clipped there (reported as `cutoff_c`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub to_c: Option<f64>,
    /// Rate of a ramp \[°C/s\], positive, at most the envelope's rate limit.
    #[serde(default, rename = "rate_c_s", skip_serializing_if = "Option::is_none")]
    pub rate_c_per_s: Option<f64>,
    /// Duration of a hold \[s\], 0 to 3600 (with `until`, the longest wait for the response).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_s: Option<f64>,
    /// `"response"`: a response on the channel ends this ramp or hold early; the program goes on with the next.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub until: Option<Until>,
}

/// What ends a segment early.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Until {
    /// A response on the segment's channel.
    Response,
}

/// The kind of a participant's response.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ResponseKind {
    /// A button press (a USB button is a keyboard key).
    Button,
    /// A rating on an electronic visual analogue scale, `value` 0 to 100.
    Rating,
}

/// `response`: a participant's response on a channel, taking effect on the loop's next tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ResponseInput {
    /// The channel (from 0).
    pub channel: i64,
    /// `button` or `rating`.
    pub kind: ResponseKind,
    /// The rating, 0 to 100 (ratings only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
}

/// A target clipped to the display's range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ProgramCutoff {
    /// The channel.
    pub channel: usize,
    /// The segment (from 0).
    pub segment: usize,
    /// The target asked for \[°C\].
    pub requested_c: f64,
    /// The target used: the display's limit \[°C\].
    pub cutoff_c: f64,
}

/// What happened in a program.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ProgramEventKind {
    /// A segment started (its first set-point is this tick's).
    SegmentStart,
    /// A response arrived (it took effect on this tick).
    Response,
    /// The program's last segment is over; the set-point holds.
    ProgramEnd,
    /// The program stopped before its end (`reason`: the channel faulted, or its device cut it); the channel
    /// renders air and nothing of the program resumes.
    ProgramStopped,
}

/// A program's event, sent to the WebSocket clients that follow programs (telemetry subscribers and clients that
/// sent a program or response), written beside a `--record` session (`<session>.events.csv`) and pushed to the LSL
/// marker stream under `serve --lsl`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ProgramEvent {
    /// What happened.
    pub event: ProgramEventKind,
    /// The channel.
    pub channel: usize,
    /// The tick it happened on.
    pub tick: u64,
    /// Loop time of that tick \[s\].
    pub time_s: f64,
    /// The segment that started (`segment_start`), or that ran at the response.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segment: Option<usize>,
    /// The started segment's target \[°C\] (ramps and steps; clipped).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub to_c: Option<f64>,
    /// The display's limit the started segment's target was clipped to \[°C\], if it was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cutoff_c: Option<f64>,
    /// The response's kind (`response`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<ResponseKind>,
    /// The rating (`response` of kind `rating`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    /// The display set-point of that tick \[°C\].
    pub setpoint_c: Option<f64>,
    /// The plate sensor at that tick \[°C\] (null where the device cannot measure).
    pub sensor_c: Option<f64>,
    /// Why the program stopped (`program_stopped`), e.g. `the channel faulted: E107 …`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}
