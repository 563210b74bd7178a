//! The contact API's messages: parsing and validating a request into an [`ApiRequest`] (a loop [`Command`], or one
//! of the requests only the connection handles), the stable error codes, and the JSON of replies, telemetry and
//! status. Every check happens here, before anything reaches the control loop; a stimulus is checked by
//! [`stimulus_command`] against the limits the channels enforce (shared with OSC), every other number with
//! `thermode_model::params`.
//!
//! A request is a JSON object with `type` and `id` (a string of at most 128 characters or a number; replies
//! carry it back unchanged). Unknown fields are refused (`unknown_field`), so a misspelt key never goes unnoticed,
//! and so is a key given twice in one object (`bad_json`): JSON readers differ on which of the two counts, so a
//! proxy that checked the first `type` must not see thermode act on the second.

use std::collections::HashSet;
use std::fmt;

use serde::de::{self, Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};
use serde_json::{json, Map, Value};
use thermode_model::limits;
use thermode_model::materials::{self, Material, DEFAULT_THICKNESS_M};
use thermode_model::params::{BadValue, Range};

use thermode_runtime::command::{Command, Owner};
use thermode_runtime::engine::Stimulus;
use thermode_runtime::limits::StimulusLimits;
use thermode_runtime::snapshot::{ChannelStatus, Mode, Snapshot};

/// Stable error codes of the API (they never change meaning).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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
        }
    }
}

/// An error reply's code and message.
#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    /// The stable code.
    pub code: ErrorCode,
    /// A human-readable explanation.
    pub message: String,
}

impl From<BadValue> for ApiError {
    fn from(e: BadValue) -> Self {
        ApiError::bad_value(&e)
    }
}

impl ApiError {
    /// An error with `code` and `message`.
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        ApiError {
            code,
            message: message.into(),
        }
    }

    /// A refused number (`bad_value`).
    pub fn bad_value(e: &impl std::fmt::Display) -> Self {
        ApiError::new(ErrorCode::BadValue, e.to_string())
    }

    /// The error as a message: `{"type": "error", "id", "code", "message"}`.
    pub fn to_json(&self, id: &Value) -> Value {
        json!({"type": "error", "id": id, "code": self.code.as_str(), "message": self.message})
    }
}

/// Limits every request is checked against.
#[derive(Debug, Clone, PartialEq)]
pub struct RequestLimits {
    /// Number of channels.
    pub channel_count: usize,
    /// Largest accepted message \[bytes\]. Default 16384.
    pub max_message_bytes: usize,
    /// What every channel accepts as a stimulus: the limits its engine enforces (object temperature, the
    /// envelope's display range and rate limit), as reported by the loop.
    pub stimulus: StimulusLimits,
    /// Fastest telemetry subscription \[Hz\] (at most the loop rate; default 100).
    pub max_subscribe_hz: f64,
    /// Object temperature when a touch gives none \[°C\] (default 23, room temperature).
    pub default_object_c: f64,
}

/// Slowest telemetry subscription \[Hz\] (one message every 100 s).
pub const MIN_SUBSCRIBE_HZ: f64 = 0.01;
/// Longest accepted `id` string \[characters\].
pub const MAX_ID_CHARS: usize = 128;
/// Longest accepted name (material or custom label) \[characters\].
pub const MAX_NAME_CHARS: usize = 64;

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
        /// The text (at most [`crate::lsl::MAX_MARKER_CHARS`] characters, no NUL).
        text: String,
        /// The channel it concerns, if any.
        channel: Option<usize>,
    },
}

/// Parses and validates one text message from `owner`. Returns the `id` to answer with (null when there is none or
/// it is invalid) and the request or the error.
pub fn parse(text: &str, limits: &RequestLimits, owner: Owner) -> (Value, Result<ApiRequest, ApiError>) {
    if text.len() > limits.max_message_bytes {
        let message = format!(
            "message of {} bytes exceeds the limit of {} bytes",
            text.len(),
            limits.max_message_bytes
        );
        return (Value::Null, Err(ApiError::new(ErrorCode::TooLarge, message)));
    }
    if let Err(e) = serde_json::from_str::<UniqueKeys>(text) {
        return (
            Value::Null,
            Err(ApiError::new(ErrorCode::BadJson, format!("not valid JSON: {e}"))),
        );
    }
    let value: Value = match serde_json::from_str(text) {
        Ok(value) => value,
        Err(e) => {
            return (
                Value::Null,
                Err(ApiError::new(ErrorCode::BadJson, format!("not valid JSON: {e}"))),
            )
        }
    };
    let Value::Object(map) = value else {
        return (
            Value::Null,
            Err(ApiError::new(ErrorCode::BadJson, "a message must be a JSON object")),
        );
    };
    let id = match request_id(&map) {
        Ok(id) => id,
        Err(e) => return (Value::Null, Err(e)),
    };
    let request = parse_object(&map, limits, owner);
    (id, request)
}

/// A JSON text read only to check that no object in it names a key twice (`serde_json::Value` keeps the last).
struct UniqueKeys;

impl<'de> Deserialize<'de> for UniqueKeys {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_any(UniqueKeysVisitor)
    }
}

struct UniqueKeysVisitor;

impl<'de> Visitor<'de> for UniqueKeysVisitor {
    type Value = UniqueKeys;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any JSON value")
    }

    fn visit_bool<E: de::Error>(self, _: bool) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_i64<E: de::Error>(self, _: i64) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_u64<E: de::Error>(self, _: u64) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_f64<E: de::Error>(self, _: f64) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_str<E: de::Error>(self, _: &str) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_unit<E: de::Error>(self) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut items: A) -> Result<UniqueKeys, A::Error> {
        while items.next_element::<UniqueKeys>()?.is_some() {}
        Ok(UniqueKeys)
    }

    fn visit_map<A: MapAccess<'de>>(self, mut entries: A) -> Result<UniqueKeys, A::Error> {
        let mut keys = HashSet::new();
        while let Some(key) = entries.next_key::<String>()? {
            if keys.contains(&key) {
                return Err(de::Error::custom(format!("the key `{key}` is given twice")));
            }
            entries.next_value::<UniqueKeys>()?;
            keys.insert(key);
        }
        Ok(UniqueKeys)
    }
}

fn request_id(map: &Map<String, Value>) -> Result<Value, ApiError> {
    match map.get("id") {
        None => Err(ApiError::new(ErrorCode::MissingField, "every request needs an `id`")),
        Some(Value::String(s)) if s.chars().count() <= MAX_ID_CHARS => Ok(Value::String(s.clone())),
        Some(Value::Number(n)) => Ok(Value::Number(n.clone())),
        Some(_) => Err(ApiError::new(
            ErrorCode::BadValue,
            format!("`id` must be a number or a string of at most {MAX_ID_CHARS} characters"),
        )),
    }
}

fn parse_object(map: &Map<String, Value>, limits: &RequestLimits, owner: Owner) -> Result<ApiRequest, ApiError> {
    let fields = Fields { map };
    let kind = fields.string("type")?;
    let command = match kind {
        "touch" => parse_touch(&fields, limits, owner)?,
        "release" => {
            fields.only(&["channel"])?;
            Command::Release {
                channel: fields.channel(limits.channel_count)?,
            }
        }
        "setpoint" => parse_setpoint(&fields, limits, owner)?,
        "clear_fault" => {
            fields.only(&["channel"])?;
            Command::ClearFault {
                channel: fields.channel(limits.channel_count)?,
            }
        }
        "stop_all" => fields.only(&[]).map(|()| Command::StopAll)?,
        "subscribe" => {
            fields.only(&["rate_hz"])?;
            let rate = Range {
                name: "rate_hz",
                min: MIN_SUBSCRIBE_HZ,
                max: limits.max_subscribe_hz,
            };
            let rate_hz = rate.check(fields.number("rate_hz")?)?;
            return Ok(ApiRequest::Subscribe { rate_hz });
        }
        "unsubscribe" => return fields.only(&[]).map(|()| ApiRequest::Unsubscribe),
        "status" => return fields.only(&[]).map(|()| ApiRequest::Status),
        "ack_recording" => return fields.only(&[]).map(|()| ApiRequest::AckRecording),
        "marker" => return parse_marker(&fields, limits),
        other => Err(ApiError::new(
            ErrorCode::UnknownType,
            format!(
                "unknown request type {:?}; known: touch, release, setpoint, clear_fault, stop_all, subscribe, unsubscribe, \
                 status, ack_recording, marker",
                truncate(other)
            ),
        ))?,
    };
    Ok(ApiRequest::Command(command))
}

fn parse_marker(fields: &Fields, limits: &RequestLimits) -> Result<ApiRequest, ApiError> {
    fields.only(&["text", "channel"])?;
    let text = fields.string("text")?;
    let max = crate::lsl::MAX_MARKER_CHARS;
    if text.chars().count() > max || text.contains('\0') {
        return Err(ApiError::new(
            ErrorCode::BadValue,
            format!("`text` must be at most {max} characters without NUL"),
        ));
    }
    let channel = match fields.map.get("channel") {
        None => None,
        Some(_) => Some(fields.channel(limits.channel_count)?),
    };
    Ok(ApiRequest::Marker {
        text: text.to_string(),
        channel,
    })
}

fn parse_touch(fields: &Fields, limits: &RequestLimits, owner: Owner) -> Result<Command, ApiError> {
    fields.only(&["channel", "material", "properties", "object_temp_c"])?;
    let channel = fields.channel(limits.channel_count)?;
    let material = match (fields.map.get("material"), fields.map.get("properties")) {
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
        (Some(_), None) => material_by_name(fields.string("material")?)?,
        (None, Some(properties)) => material_from_properties(properties)?,
    };
    let object_c = match fields.map.get("object_temp_c") {
        None => limits.default_object_c,
        Some(_) => fields.number("object_temp_c")?,
    };
    stimulus_command(channel, Stimulus::Touch { material, object_c }, owner, limits)
}

fn parse_setpoint(fields: &Fields, limits: &RequestLimits, owner: Owner) -> Result<Command, ApiError> {
    fields.only(&["channel", "temp_c", "rate_c_s"])?;
    let channel = fields.channel(limits.channel_count)?;
    let temp_c = fields.number("temp_c")?;
    let rate_c_s = fields.number("rate_c_s")?;
    stimulus_command(channel, Stimulus::Direct { temp_c, rate_c_s }, owner, limits)
}

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

/// The reply's fields for a command the loop applied (the request's name is [`Command::name`]) (`touch`: channel, material and object
/// temperature; `setpoint`: channel, temperature and rate; `release`, `clear_fault`: channel).
pub fn command_reply_fields(command: &Command) -> Value {
    match command {
        Command::Stimulate {
            channel,
            stimulus,
            label,
            ..
        } => match stimulus {
            Stimulus::Touch { object_c, .. } => {
                json!({"channel": channel, "material": &**label, "object_temp_c": object_c})
            }
            Stimulus::Direct { temp_c, rate_c_s } => {
                json!({"channel": channel, "temp_c": temp_c, "rate_c_s": rate_c_s})
            }
            Stimulus::Air => json!({"channel": channel}),
        },
        Command::Release { channel } | Command::ClearFault { channel } => json!({"channel": channel}),
        Command::StopAll | Command::ClientGone { .. } => json!({}),
    }
}

/// The stimulus limits as published in `/api/status` (`limits`): what the API and the loop enforce.
pub fn limits_json(limits: &StimulusLimits) -> Value {
    json!({
        "display_min_c": limits.display_c.min,
        "display_max_c": limits.display_c.max,
        "max_rate_c_s": limits.max_rate_c_s,
        "object_temp_min_c": limits.object_c.min,
        "object_temp_max_c": limits.object_c.max,
    })
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

fn material_from_properties(value: &Value) -> Result<Material, ApiError> {
    let Value::Object(map) = value else {
        return Err(ApiError::new(ErrorCode::BadValue, "`properties` must be an object"));
    };
    let fields = Fields { map };
    fields.only(&[
        "name",
        "conductivity_w_mk",
        "density_kg_m3",
        "specific_heat_j_kgk",
        "thickness_m",
    ])?;
    let name = match map.get("name") {
        None => "custom".to_string(),
        Some(_) => label(fields.string("name")?)?,
    };
    // The physical ranges of material properties (docs/ranges.md), as for material files.
    let property = |key: &'static str, range: Range| -> Result<f64, ApiError> {
        Ok(range.rule().check(key, fields.number(key)?)?)
    };
    let thickness_m = match map.get("thickness_m") {
        None => DEFAULT_THICKNESS_M,
        Some(_) => property("thickness_m", limits::OBJECT_THICKNESS)?,
    };
    let material = Material {
        name,
        conductivity_w_mk: property("conductivity_w_mk", limits::CONDUCTIVITY)?,
        density_kg_m3: property("density_kg_m3", limits::DENSITY)?,
        specific_heat_j_kgk: property("specific_heat_j_kgk", limits::SPECIFIC_HEAT)?,
        thickness_m,
        source: "contact API properties".to_string(),
    };
    material.validate("properties").map_err(|e| ApiError::bad_value(&e))?;
    Ok(material)
}

/// A custom material's label: 1 to 64 of `A–Z a–z 0–9 _ - .`.
fn label(name: &str) -> Result<String, ApiError> {
    let ok = !name.is_empty()
        && name.chars().count() <= MAX_NAME_CHARS
        && name.chars().all(|c| c.is_ascii_alphanumeric() || "_-.".contains(c));
    if ok {
        Ok(name.to_string())
    } else {
        Err(ApiError::new(
            ErrorCode::BadValue,
            format!("`name` must be 1 to {MAX_NAME_CHARS} of A-Z a-z 0-9 _ - ."),
        ))
    }
}

/// At most 40 characters of a client's string, for messages.
fn truncate(text: &str) -> String {
    text.chars().take(40).collect()
}

/// Typed access to a request's fields.
struct Fields<'a> {
    map: &'a Map<String, Value>,
}

impl Fields<'_> {
    /// Refuses fields other than `type`, `id` and `allowed`.
    fn only(&self, allowed: &[&str]) -> Result<(), ApiError> {
        let unknown = self
            .map
            .keys()
            .find(|k| !matches!(k.as_str(), "type" | "id") && !allowed.contains(&k.as_str()));
        match unknown {
            Some(key) => Err(ApiError::new(
                ErrorCode::UnknownField,
                format!("unknown field {:?}", truncate(key)),
            )),
            None => Ok(()),
        }
    }

    fn get(&self, key: &str) -> Result<&Value, ApiError> {
        self.map
            .get(key)
            .ok_or_else(|| ApiError::new(ErrorCode::MissingField, format!("missing field `{key}`")))
    }

    fn string(&self, key: &str) -> Result<&str, ApiError> {
        self.get(key)?
            .as_str()
            .ok_or_else(|| ApiError::new(ErrorCode::BadValue, format!("`{key}` must be a string")))
    }

    fn number(&self, key: &str) -> Result<f64, ApiError> {
        self.get(key)?
            .as_f64()
            .filter(|v| v.is_finite())
            .ok_or_else(|| ApiError::new(ErrorCode::BadValue, format!("`{key}` must be a finite number")))
    }

    fn channel(&self, count: usize) -> Result<usize, ApiError> {
        let value = self.get("channel")?;
        let channel = value.as_i64().ok_or_else(|| {
            ApiError::new(
                ErrorCode::BadValue,
                format!("`channel` must be an integer, not {value}"),
            )
        })?;
        channel_index(channel, count)
    }
}

/// A successful reply: `{"type": "ok", "id", "request": <type>, ...extra}`.
pub fn ok_reply(id: &Value, request: &str, extra: Value) -> Value {
    merged(json!({"type": "ok", "id": id, "request": request}), extra)
}

/// `base` with the fields of `extra` added (both objects; otherwise `base` unchanged).
pub fn merged(mut base: Value, extra: Value) -> Value {
    if let (Value::Object(base), Value::Object(extra)) = (&mut base, extra) {
        base.extend(extra);
    }
    base
}

/// The fault of a channel as a number: the stable code, 0 for none.
fn fault_code(status: &ChannelStatus) -> u16 {
    status.telemetry.fault.map_or(0, |f| f.code())
}

/// One channel's telemetry object (the `render` CSV names).
pub fn channel_telemetry(status: &ChannelStatus) -> Value {
    let t = &status.telemetry;
    json!({
        "channel": status.channel,
        "contact": status.mode == Mode::Touch,
        "material": (status.mode == Mode::Touch).then_some(&*status.label),
        "mode": status.mode,
        "target_skin_c": finite(t.target_skin_c),
        "skin_c": finite(t.skin_c),
        "display_setpoint_c": finite(t.display_setpoint_c),
        "sensor_c": finite(t.sensor_c),
        "plate_estimate_c": finite(t.plate_estimate_c),
        "finger_c": finite(t.finger_c),
        "current_a": finite(t.current_a),
        "hot_side_c": finite(t.hot_side_c),
        "fault": fault_code(status),
        "cem43_min": finite(status.dose.cem43_min),
        "time_at_or_above_43_s": finite(status.dose.time_at_or_above_43_s),
        "dose_lockout": status.dose.lockout,
    })
}

/// A number, or null when it is not finite (JSON has no NaN).
fn finite(value: f64) -> Value {
    if value.is_finite() {
        json!(value)
    } else {
        Value::Null
    }
}

/// A telemetry message.
pub fn telemetry_message(snapshot: &Snapshot) -> Value {
    let channels: Vec<Value> = snapshot.channels.iter().map(channel_telemetry).collect();
    json!({"type": "telemetry", "time_s": snapshot.time_s, "tick": snapshot.tick, "channels": channels})
}

/// One channel's status: its telemetry plus mode, fault text, owner and pending release.
pub fn channel_status(status: &ChannelStatus, name: Option<&str>) -> Value {
    let extra = json!({
        "name": name,
        "fault_description": status.telemetry.fault.map(|f| f.description()),
        "object_temp_c": status.object_c,
        "direct_temp_c": status.direct.map(|d| d.0),
        "direct_rate_c_s": status.direct.map(|d| d.1),
        "held_off": status.held_off,
        "owner": status.owner,
        "release_at_s": status.release_at_s,
        "link_ok": status.link_ok,
        "device_cut": status.device_cut.map(|c| c.name()),
        "device_cut_description": status.device_cut.map(|c| c.to_string()),
        "engine_failed": status.engine_failed,
    });
    merged(channel_telemetry(status), extra)
}

/// The library as JSON: the fields of `thermode materials --format json`.
pub fn materials_json() -> Value {
    let rows: Vec<Value> = materials::library()
        .iter()
        .map(|m| {
            json!({
                "name": m.name,
                "conductivity_w_mk": m.conductivity_w_mk,
                "density_kg_m3": m.density_kg_m3,
                "specific_heat_j_kgk": m.specific_heat_j_kgk,
                "effusivity": m.effusivity(),
                "diffusivity_m2_s": m.diffusivity_m2_s(),
                "thickness_m": m.thickness_m,
                "source": m.source,
            })
        })
        .collect();
    Value::Array(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> RequestLimits {
        RequestLimits {
            channel_count: 5,
            max_message_bytes: 16 * 1024,
            stimulus: StimulusLimits::of_envelope(&thermode_safety::EnvelopeConfig::default()),
            max_subscribe_hz: 100.0,
            default_object_c: 23.0,
        }
    }

    fn parse_text(text: &str) -> (Value, Result<ApiRequest, ApiError>) {
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
            "a".repeat(crate::lsl::MAX_MARKER_CHARS + 1)
        );
        assert_eq!(code_of(&long), Some("bad_value"));
    }

    #[test]
    fn a_touch_by_name_and_by_properties() {
        let (id, touch) = parse_text(r#"{"type":"touch","id":7,"channel":1,"material":"Aluminum","object_temp_c":30}"#);
        assert_eq!(id, json!(7));
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
                assert_eq!((material.thickness_m, &*label), (DEFAULT_THICKNESS_M, "custom"));
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
        assert_eq!(id, json!("abc"));
        assert!(result.is_err());
    }
}
