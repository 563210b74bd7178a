//! The daemon's side of the wire vocabulary (`thermode_protocol`): a request, read and typed by
//! `thermode_protocol::parse_request`, is checked against what this daemon offers (its channels, the library, the
//! limits its channels enforce) and becomes an [`ApiRequest`] (a loop [`Command`], or one of the requests only the
//! connection handles); the loop's snapshot becomes the protocol's telemetry and channel states. Every check happens
//! here, before anything reaches the control loop; a stimulus is checked by [`stimulus_command`] against the limits
//! the channels enforce (shared with OSC), every other number with `thermode_model::params`.

use thermode_model::materials::{self, Material};
use thermode_model::params::Range;
use thermode_platform::to_clock_resolution;
use thermode_protocol::program::{ProgramRequest, ResponseInput, SegmentSpec, Until};
use thermode_protocol::request::{Marker, Setpoint, Touch};
pub use thermode_protocol::request::{MAX_MARKER_CHARS, MAX_NAME_CHARS, MIN_SUBSCRIBE_HZ};
use thermode_protocol::status::Limits;
use thermode_protocol::{
    finite, AppliedAt, ChannelState, ChannelTelemetry, Done, OffReason, ProgramCutoff, Request, RequestId,
    ResponseKind, Telemetry,
};
pub use thermode_protocol::{ApiError, ErrorCode};
use thermode_runtime::command::{Applied, Command, Owner};
use thermode_runtime::engine::Stimulus;
use thermode_runtime::limits::StimulusLimits;
use thermode_runtime::program::{Program, ProgramError, Segment, MAX_SEGMENTS};
use thermode_runtime::snapshot::{ChannelStatus, Mode, Snapshot};

/// Limits every request is checked against.
#[derive(Debug, Clone, PartialEq)]
pub struct RequestLimits {
    /// Number of channels.
    pub channel_count: usize,
    /// Largest accepted message \[bytes\]. Default 16384.
    pub max_message_bytes: usize,
    /// Largest accepted `program` message \[bytes\]: the network's hard limit (default 196608), so that 999
    /// segments fit.
    pub max_program_bytes: usize,
    /// What every channel accepts as a stimulus: the limits its engine enforces (object temperature, the
    /// envelope's display range and rate limit), as reported by the loop.
    pub stimulus: StimulusLimits,
    /// Fastest telemetry subscription \[Hz\] (at most the loop rate; default 100).
    pub max_subscribe_hz: f64,
    /// Object temperature when a touch gives none \[°C\] (default 23, room temperature).
    pub default_object_c: f64,
}

/// A validated request: a command for the control loop, or one the connection answers itself.
#[derive(Debug, Clone)]
pub enum ApiRequest {
    /// `touch`, `setpoint`, `release`, `clear_fault` or `stop_all`: the loop's [`Command`].
    Command(Command),
    /// Telemetry at `rate_hz`.
    Subscribe {
        /// Messages per second \[Hz\].
        rate_hz: f64,
    },
    /// No more telemetry.
    Unsubscribe,
    /// The daemon's status.
    Status,
    /// An operator acknowledges a failed recording: stimuli are accepted again.
    AckRecording,
    /// A client's event marker (forwarded to the LSL marker stream under `serve --lsl`).
    Marker {
        /// The text (at most [`MAX_MARKER_CHARS`] characters, no NUL).
        text: String,
        /// The channel it concerns, if any.
        channel: Option<usize>,
    },
}

/// Reads and validates one text message from `owner`: the `id` to answer with (`None` when there is none or it is
/// invalid) and the request or the error.
pub fn parse(text: &str, limits: &RequestLimits, owner: Owner) -> (Option<RequestId>, Result<ApiRequest, ApiError>) {
    let (id, request) =
        thermode_protocol::parse_request_sized(text, limits.max_message_bytes, limits.max_program_bytes);
    (id, request.and_then(|request| validate(request, limits, owner)))
}

/// What this daemon does with a well-formed request, once its numbers pass this daemon's limits.
fn validate(request: Request, limits: &RequestLimits, owner: Owner) -> Result<ApiRequest, ApiError> {
    let channel = |channel: i64| channel_index(channel, limits.channel_count);
    let command = match request {
        Request::Touch(touch) => touch_command(touch, limits, owner)?,
        Request::Release(on) => Command::Release {
            channel: channel(on.channel)?,
        },
        Request::Setpoint(Setpoint {
            channel: c,
            temp_c,
            rate_c_per_s,
        }) => stimulus_command(channel(c)?, Stimulus::Direct { temp_c, rate_c_per_s }, owner, limits)?,
        Request::ClearFault(on) => Command::ClearFault {
            channel: channel(on.channel)?,
        },
        Request::StopAll(_) => Command::StopAll,
        Request::Subscribe(subscribe) => {
            let rate_hz = subscription_rate(subscribe.rate_hz, limits)?;
            return Ok(ApiRequest::Subscribe { rate_hz });
        }
        Request::Unsubscribe(_) => return Ok(ApiRequest::Unsubscribe),
        Request::Status(_) => return Ok(ApiRequest::Status),
        Request::AckRecording(_) => return Ok(ApiRequest::AckRecording),
        Request::Marker(marker) => return marker_request(marker, limits),
        Request::Program(program) => program_command(program, limits, owner)?,
        Request::ProgramStop(on) => Command::ProgramStop {
            channel: channel(on.channel)?,
        },
        Request::Response(response) => response_command(response, limits)?,
    };
    Ok(ApiRequest::Command(command))
}

/// A telemetry subscription's rate \[Hz\], from [`MIN_SUBSCRIBE_HZ`] to the daemon's maximum (WebSocket and OSC).
pub fn subscription_rate(rate_hz: f64, limits: &RequestLimits) -> Result<f64, ApiError> {
    let rate = Range {
        name: "rate_hz",
        min: MIN_SUBSCRIBE_HZ,
        max: limits.max_subscribe_hz,
    };
    Ok(rate.check(rate_hz)?)
}

fn marker_request(marker: Marker, limits: &RequestLimits) -> Result<ApiRequest, ApiError> {
    if marker.text.chars().count() > MAX_MARKER_CHARS || marker.text.contains('\0') {
        return Err(ApiError::new(
            ErrorCode::BadValue,
            format!("`text` must be at most {MAX_MARKER_CHARS} characters without NUL"),
        ));
    }
    let channel = marker
        .channel
        .map(|c| channel_index(c, limits.channel_count))
        .transpose()?;
    Ok(ApiRequest::Marker {
        text: marker.text,
        channel,
    })
}

fn touch_command(touch: Touch, limits: &RequestLimits, owner: Owner) -> Result<Command, ApiError> {
    let channel = channel_index(touch.channel, limits.channel_count)?;
    let material = match (touch.material, touch.properties) {
        (Some(_), Some(_)) => {
            return Err(ApiError::new(
                ErrorCode::BadValue,
                "give either `material` or `properties`, not both",
            ))
        }
        (None, None) => {
            return Err(ApiError::new(
                ErrorCode::MissingField,
                "touch needs `material` (a library name) or `properties`",
            ))
        }
        (Some(name), None) => material_by_name(&name)?,
        (None, Some(properties)) => properties.to_material().map_err(|e| ApiError::bad_value(&e))?,
    };
    let object_c = touch.object_temp_c.unwrap_or(limits.default_object_c);
    stimulus_command(channel, Stimulus::Touch { material, object_c }, owner, limits)
}

/// The command running `request`'s programs: every channel key a channel of this daemon (each once), every
/// channel's segments a [`Program`] within the limits every channel enforces (targets clipped to the display's
/// range, reported as cut-offs). WebSocket and OSC both build programs here.
pub fn program_command(request: ProgramRequest, limits: &RequestLimits, owner: Owner) -> Result<Command, ApiError> {
    if request.channels.is_empty() {
        return Err(ApiError::new(
            ErrorCode::BadValue,
            "`channels` is empty: a program needs at least one channel",
        ));
    }
    let mut programs: Vec<(usize, Program)> = Vec::with_capacity(request.channels.len());
    for (key, specs) in request.channels {
        let number = key.trim().parse::<i64>().map_err(|_| {
            ApiError::new(
                ErrorCode::UnknownChannel,
                format!("channel key {key:?} is not a channel number"),
            )
        })?;
        let channel = channel_index(number, limits.channel_count)?;
        if programs.iter().any(|(c, _)| *c == channel) {
            return Err(ApiError::new(
                ErrorCode::BadValue,
                format!("channel {channel} is given twice"),
            ));
        }
        if specs.len() > MAX_SEGMENTS {
            let e = ProgramError::TooManySegments {
                channel,
                count: specs.len(),
                max: MAX_SEGMENTS,
            };
            return Err(ApiError::bad_value(&e));
        }
        let segments = specs
            .iter()
            .enumerate()
            .map(|(index, spec)| segment(channel, index, spec))
            .collect::<Result<Vec<_>, _>>()?;
        let program = Program::new(channel, segments, &limits.stimulus).map_err(|e| ApiError::bad_value(&e))?;
        programs.push((channel, program));
    }
    Ok(Command::Program { programs, owner })
}

/// Which segment `spec` is: `to_c` and `rate_c_s` a ramp, `to_c` alone a step, `hold_s` alone a hold.
fn segment(channel: usize, index: usize, spec: &SegmentSpec) -> Result<Segment, ApiError> {
    let until_response = spec.until == Some(Until::Response);
    let refuse = |what: &str| {
        ApiError::new(
            ErrorCode::BadValue,
            format!("channel {channel}, segment {index}: {what}"),
        )
    };
    match (spec.to_c, spec.rate_c_per_s, spec.hold_s) {
        (Some(to_c), Some(rate_c_per_s), None) => Ok(Segment::Ramp {
            to_c,
            rate_c_per_s,
            until_response,
        }),
        (Some(_), None, None) if until_response => Err(refuse(
            "a step cannot wait for a response (give `rate_c_s` to make it a ramp)",
        )),
        (Some(to_c), None, None) => Ok(Segment::Step { to_c }),
        (None, None, Some(hold_s)) => Ok(Segment::Hold { hold_s, until_response }),
        _ => Err(refuse(
            "give `to_c` and `rate_c_s` (a ramp), `to_c` alone (a step) or `hold_s` alone (a hold)",
        )),
    }
}

/// The command of a participant's response: a button press has no `value`, a rating a `value` from 0 to 100.
pub fn response_command(response: ResponseInput, limits: &RequestLimits) -> Result<Command, ApiError> {
    let channel = channel_index(response.channel, limits.channel_count)?;
    let value = match (response.kind, response.value) {
        (ResponseKind::Button, None) => None,
        (ResponseKind::Button, Some(_)) => {
            return Err(ApiError::new(ErrorCode::BadValue, "a button response has no `value`"))
        }
        (ResponseKind::Rating, None) => {
            return Err(ApiError::new(
                ErrorCode::MissingField,
                "a rating needs its `value` (0 to 100)",
            ))
        }
        (ResponseKind::Rating, Some(value)) => Some(RATING.check(value)?),
    };
    Ok(Command::Response {
        channel,
        kind: crate::wire::loop_response_kind(response.kind),
        value,
    })
}

/// A rating's range: an electronic visual analogue scale.
pub const RATING: Range = Range {
    name: "value (rating)",
    min: 0.0,
    max: 100.0,
};

/// The command showing `stimulus` on `channel` (already a valid channel) for `owner`, once the stimulus passes the
/// limits every channel enforces ([`StimulusLimits::check`], `bad_value` otherwise). The WebSocket API and OSC
/// both build their touch and set-point commands here, so both refuse the same stimuli with the same message.
pub fn stimulus_command(
    channel: usize,
    stimulus: Stimulus,
    owner: Owner,
    limits: &RequestLimits,
) -> Result<Command, ApiError> {
    limits.stimulus.check(&stimulus).map_err(|e| ApiError::bad_value(&e))?;
    Ok(Command::stimulate(channel, stimulus, owner))
}

/// What the reply says of a command the loop applied at `applied`.
pub fn done(command: &Command, applied: &Applied) -> Done {
    let at = AppliedAt {
        tick: applied.tick,
        time_s: to_clock_resolution(applied.time_s),
    };
    match command {
        Command::Program { programs, .. } => program_done(programs, at),
        Command::ProgramStop { channel } => Done::ProgramStop {
            channel: *channel,
            applied: at,
        },
        Command::Response { channel, kind, value } => {
            let reading = applied.at_response;
            Done::Response {
                channel: *channel,
                kind: crate::wire::response_kind(*kind),
                value: *value,
                sensor_c: reading.and_then(|r| finite(r.sensor_c)),
                plate_estimate_c: reading.and_then(|r| finite(r.plate_estimate_c)),
                setpoint_c: reading.and_then(|r| finite(r.setpoint_c)),
                ended_segment: reading.and_then(|r| r.ended_segment),
                applied: at,
            }
        }
        other => stimulus_done(other, at),
    }
}

/// The reply to a program the loop started at `at`: its channels and every clipped target.
fn program_done(programs: &[(usize, Program)], at: AppliedAt) -> Done {
    let cutoffs: Vec<ProgramCutoff> = programs
        .iter()
        .flat_map(|(channel, program)| {
            program.cutoffs().map(|c| ProgramCutoff {
                channel: *channel,
                segment: c.segment,
                requested_c: c.requested_c,
                cutoff_c: c.cutoff_c,
            })
        })
        .collect();
    Done::Program {
        channels: programs.iter().map(|(channel, _)| *channel).collect(),
        start_tick: at.tick,
        start_time_s: at.time_s,
        cutoff_c: cutoffs.first().map(|c| c.cutoff_c),
        cutoffs,
        applied: at,
    }
}

/// What the reply says of a stimulus, release, fault clearing or stop.
fn stimulus_done(command: &Command, applied: AppliedAt) -> Done {
    match command {
        Command::Stimulate {
            channel,
            stimulus,
            label,
            ..
        } => match stimulus {
            Stimulus::Touch { object_c, .. } => Done::Touch {
                channel: *channel,
                material: label.to_string(),
                object_temp_c: *object_c,
                applied,
            },
            Stimulus::Direct { temp_c, rate_c_per_s } => Done::Setpoint {
                channel: *channel,
                temp_c: *temp_c,
                rate_c_per_s: *rate_c_per_s,
                applied,
            },
            Stimulus::Air => Done::Release {
                channel: *channel,
                applied,
            },
        },
        Command::Release { channel } => Done::Release {
            channel: *channel,
            applied,
        },
        Command::ClearFault { channel } => Done::ClearFault {
            channel: *channel,
            applied,
        },
        Command::StopAll
        | Command::ClientGone { .. }
        | Command::Program { .. }
        | Command::ProgramStop { .. }
        | Command::Response { .. } => Done::StopAll { applied },
    }
}

/// The limits as published in `/api/status` (`limits`): what the API and the loop enforce.
pub fn limits_status(limits: &RequestLimits, requests_per_s: f64, burst: f64) -> Limits {
    let stimulus = &limits.stimulus;
    Limits {
        max_message_bytes: limits.max_message_bytes,
        requests_per_s,
        burst,
        max_subscribe_hz: limits.max_subscribe_hz,
        display_min_c: stimulus.display_c.min,
        display_max_c: stimulus.display_c.max,
        max_rate_c_per_s: stimulus.max_rate_c_per_s,
        object_temp_min_c: stimulus.object_c.min,
        object_temp_max_c: stimulus.object_c.max,
    }
}

/// A library material by name (case-insensitive, aliases as in `thermode materials`).
pub fn material_by_name(name: &str) -> Result<Material, ApiError> {
    if name.chars().count() > MAX_NAME_CHARS {
        return Err(ApiError::new(
            ErrorCode::UnknownMaterial,
            format!("material name longer than {MAX_NAME_CHARS} characters"),
        ));
    }
    materials::find(name).map_err(|e| ApiError::new(ErrorCode::UnknownMaterial, e.to_string()))
}

/// A channel number from a signed integer: `unknown_channel` outside `0..count`.
pub fn channel_index(channel: i64, count: usize) -> Result<usize, ApiError> {
    match usize::try_from(channel) {
        Ok(c) if c < count => Ok(c),
        _ => Err(ApiError::new(
            ErrorCode::UnknownChannel,
            format!(
                "channel {channel} does not exist (channels 0 to {})",
                count.saturating_sub(1)
            ),
        )),
    }
}

/// One channel's telemetry (the `render` CSV names).
pub fn channel_telemetry(status: &ChannelStatus) -> ChannelTelemetry {
    let t = &status.telemetry;
    let touch = status.mode == Mode::Touch;
    ChannelTelemetry {
        channel: status.channel,
        contact: touch,
        material: touch.then(|| status.label.to_string()),
        mode: crate::wire::mode(status.mode),
        target_skin_c: finite(t.target_skin_c),
        skin_c: finite(t.skin_c),
        display_setpoint_c: finite(t.display_setpoint_c),
        sensor_c: finite(t.sensor_c),
        plate_estimate_c: finite(t.plate_estimate_c),
        finger_c: finite(t.finger_c),
        current_a: finite(t.current_a),
        hot_side_c: finite(t.hot_side_c),
        fault: t.fault.map_or(0, |f| f.code()),
        cem43_min: finite(status.dose.cem43_min),
        time_at_or_above_43_s: finite(status.dose.time_at_or_above_43_s),
        dose_lockout: status.dose.lockout,
    }
}

/// A telemetry message.
pub fn telemetry_message(snapshot: &Snapshot) -> Telemetry {
    Telemetry {
        time_s: to_clock_resolution(snapshot.time_s),
        tick: snapshot.tick,
        channels: snapshot.channels.iter().map(channel_telemetry).collect(),
    }
}

/// One channel's status: its telemetry plus mode, fault text, owner and pending release.
pub fn channel_status(status: &ChannelStatus, name: Option<&str>) -> ChannelState {
    ChannelState {
        telemetry: channel_telemetry(status),
        name: name.map(str::to_string),
        program_segment: status.program.segment,
        fault_description: status.telemetry.fault.map(|f| f.description().to_string()),
        object_temp_c: status.object_c,
        direct_temp_c: status.direct.map(|d| d.0),
        direct_rate_c_per_s: status.direct.map(|d| d.1),
        held_off: status.held_off,
        owner: crate::wire::owner(status.owner),
        release_at_s: status.release_at_s.map(to_clock_resolution),
        link_ok: status.link_ok,
        device_cut: status.device_cut.map(|c| c.name().to_string()),
        device_cut_description: status.device_cut.map(|c| c.to_string()),
        engine_failed: status.engine_failed,
        dose_budget_spent: status.dose_budget_spent,
        off_reason: off_reason(status),
    }
}

/// Why the channel's drive is off whatever is asked (the first that applies, in [`OffReason`]'s order), if it is.
pub fn off_reason(status: &ChannelStatus) -> Option<OffReason> {
    if status.engine_failed {
        Some(OffReason::EngineFailed)
    } else if status.telemetry.fault.is_some() {
        Some(OffReason::Fault)
    } else if status.device_cut.is_some() {
        Some(OffReason::DeviceCut)
    } else if !status.link_ok {
        Some(OffReason::LinkDown)
    } else if status.dose_budget_spent {
        Some(OffReason::DoseBudgetSpent)
    } else if status.held_off {
        Some(OffReason::HeldOff)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every reason a channel is off has its words on the dashboard (`OFF_WORDS` in `dashboard.html`).
    #[test]
    fn the_dashboard_says_every_off_reason_in_words() {
        let every = [
            OffReason::EngineFailed,
            OffReason::Fault,
            OffReason::DeviceCut,
            OffReason::LinkDown,
            OffReason::DoseBudgetSpent,
            OffReason::HeldOff,
        ];
        // A new reason must be added to the list above (and to the dashboard): this match has no wildcard.
        for reason in every {
            match reason {
                OffReason::EngineFailed
                | OffReason::Fault
                | OffReason::DeviceCut
                | OffReason::LinkDown
                | OffReason::DoseBudgetSpent
                | OffReason::HeldOff => {}
            }
            let name = serde_json::to_value(reason).expect("serialize");
            let key = format!("  {}: \"", name.as_str().expect("a string"));
            assert!(
                crate::api::DASHBOARD_HTML.contains(&key),
                "the dashboard has no words for {name} (looked for {key:?})"
            );
        }
    }

    fn limits() -> RequestLimits {
        RequestLimits {
            channel_count: 5,
            max_message_bytes: 16 * 1024,
            max_program_bytes: 192 * 1024,
            stimulus: StimulusLimits::of_envelope(&thermode_safety::EnvelopeConfig::default()),
            max_subscribe_hz: 100.0,
            default_object_c: 23.0,
        }
    }

    fn parse_text(text: &str) -> (Option<RequestId>, Result<ApiRequest, ApiError>) {
        parse(text, &limits(), Owner::Client(1))
    }

    fn code_of(text: &str) -> Option<&'static str> {
        parse_text(text).1.err().map(|e| e.code.as_str())
    }

    #[test]
    fn a_marker_with_and_without_channel_and_its_refusals() {
        match parse_text(r#"{"type":"marker","id":1,"text":"trial 3 start","channel":2}"#).1 {
            Ok(ApiRequest::Marker { text, channel }) => {
                assert_eq!((text.as_str(), channel), ("trial 3 start", Some(2)))
            }
            other => panic!("expected a marker, got {other:?}"),
        }
        assert!(matches!(
            parse_text(r#"{"type":"marker","id":1,"text":"x"}"#).1,
            Ok(ApiRequest::Marker { channel: None, .. })
        ));
        assert_eq!(code_of(r#"{"type":"marker","id":1}"#), Some("missing_field"));
        assert_eq!(
            code_of(r#"{"type":"marker","id":1,"text":"x","channel":9}"#),
            Some("unknown_channel")
        );
        assert_eq!(code_of(r#"{"type":"marker","id":1,"text":7}"#), Some("bad_value"));
        assert_eq!(
            code_of(r#"{"type":"marker","id":1,"text":"x","colour":1}"#),
            Some("unknown_field")
        );
        let long = format!(
            r#"{{"type":"marker","id":1,"text":"{}"}}"#,
            "a".repeat(MAX_MARKER_CHARS + 1)
        );
        assert_eq!(code_of(&long), Some("bad_value"));
    }

    #[test]
    fn a_touch_by_name_and_by_properties() {
        let (id, touch) = parse_text(r#"{"type":"touch","id":7,"channel":1,"material":"Aluminum","object_temp_c":30}"#);
        assert_eq!(id, Some(RequestId::from(7)));
        match touch {
            Ok(ApiRequest::Command(Command::Stimulate {
                channel: 1,
                stimulus: Stimulus::Touch { material, object_c },
                owner: Owner::Client(1),
                ..
            })) => {
                assert_eq!(material.name, "aluminium");
                assert_eq!(object_c, 30.0);
            }
            other => panic!("got {other:?}"),
        }
        let (_, custom) = parse_text(
            r#"{"type":"touch","id":"a","channel":0,"properties":{"conductivity_w_mk":0.2,
                "density_kg_m3":1200,"specific_heat_j_kgk":1500}}"#,
        );
        match custom {
            Ok(ApiRequest::Command(Command::Stimulate {
                stimulus: Stimulus::Touch { material, .. },
                label,
                ..
            })) => {
                assert_eq!(
                    (material.thickness_m, &*label),
                    (materials::DEFAULT_THICKNESS_M, "custom")
                );
            }
            other => panic!("got {other:?}"),
        }
    }

    #[test]
    fn every_kind_of_bad_input_has_its_code() {
        let cases = [
            ("{", "bad_json"),
            ("[1,2]", "bad_json"),
            (r#"{"type":"touch","type":"release","id":1,"channel":0}"#, "bad_json"),
            (
                r#"{"type":"touch","id":1,"channel":0,"properties":{"density_kg_m3":1,"density_kg_m3":2}}"#,
                "bad_json",
            ),
            (r#"{"type":"touch"}"#, "missing_field"),
            (r#"{"type":"fly","id":1}"#, "unknown_type"),
            (r#"{"type":"touch","id":1,"channel":0}"#, "missing_field"),
            (
                r#"{"type":"touch","id":1,"channel":5,"material":"wood"}"#,
                "unknown_channel",
            ),
            (
                r#"{"type":"touch","id":1,"channel":-1,"material":"wood"}"#,
                "unknown_channel",
            ),
            (
                r#"{"type":"touch","id":1,"channel":0.5,"material":"wood"}"#,
                "bad_value",
            ),
            (
                r#"{"type":"touch","id":1,"channel":"0","material":"wood"}"#,
                "bad_value",
            ),
            (
                r#"{"type":"touch","id":1,"channel":0,"material":"unobtainium"}"#,
                "unknown_material",
            ),
            (
                r#"{"type":"touch","id":1,"channel":0,"material":"wood","object_temp_c":1e300}"#,
                "bad_value",
            ),
            (
                r#"{"type":"touch","id":1,"channel":0,"material":"wood","object_temp_c":1e999}"#,
                "bad_json",
            ),
            (
                r#"{"type":"touch","id":1,"channel":0,"material":"wood","extra":1}"#,
                "unknown_field",
            ),
            (
                r#"{"type":"setpoint","id":1,"channel":0,"temp_c":60,"rate_c_s":1}"#,
                "bad_value",
            ),
            (
                r#"{"type":"setpoint","id":1,"channel":0,"temp_c":30,"rate_c_s":0}"#,
                "bad_value",
            ),
            (r#"{"type":"subscribe","id":1,"rate_hz":1000}"#, "bad_value"),
            (r#"{"type":"subscribe","id":1,"rate_hz":1e-300}"#, "bad_value"),
            (r#"{"type":"release","id":{"x":1},"channel":0}"#, "bad_value"),
        ];
        for (text, want) in cases {
            assert_eq!(code_of(text), Some(want), "{text}");
        }
        let big = format!(r#"{{"type":"status","id":1,"pad":"{}"}}"#, "x".repeat(20_000));
        assert_eq!(code_of(&big), Some("too_large"));
        let props = r#"{"type":"touch","id":1,"channel":0,"properties":{"conductivity_w_mk":-1,
            "density_kg_m3":1,"specific_heat_j_kgk":1}}"#;
        assert_eq!(code_of(props), Some("bad_value"));
        let (_, twice) = parse_text(r#"{"type":"touch","type":"release","id":1,"channel":0}"#);
        let message = twice.map(drop).unwrap_err().message;
        assert!(message.contains("the key `type` is given twice"), "{message}");
    }

    #[test]
    fn ids_are_echoed_even_with_errors() {
        let (id, result) = parse_text(r#"{"type":"fly","id":"abc"}"#);
        assert_eq!(id, Some(RequestId::Text("abc".into())));
        assert!(result.is_err());
    }
}
