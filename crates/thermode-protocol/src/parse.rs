//! Reading a request message: everything that holds for every request, whatever the display (the size, JSON, one
//! object whose keys are each given once, an `id`, a known `type`, the request's fields with their types). The
//! daemon then checks what depends on it (channels, materials, the envelope's ranges).
//!
//! A key given twice in one object is `bad_json`: JSON readers differ on which of the two counts, so a proxy that
//! checked the first `type` must not see thermode act on the second.

use std::collections::HashSet;
use std::fmt;

use serde::de::{self, Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};
use serde_json::{Map, Value};
use thermode_model::params::BadValue;

use crate::reply::{ErrorCode, ErrorReply, Response};
use crate::request::{Request, RequestId, MAX_ID_CHARS};

/// An error reply's code and message.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
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
    pub fn bad_value(e: &impl fmt::Display) -> Self {
        ApiError::new(ErrorCode::BadValue, e.to_string())
    }

    /// The error as the reply to the request `id`.
    pub fn reply(&self, id: Option<RequestId>) -> Response {
        Response::Error(ErrorReply {
            id,
            code: self.code,
            message: self.message.clone(),
        })
    }
}

/// Whether `text` is a JSON object whose `type` is `program`.
fn is_program(text: &str) -> bool {
    #[derive(serde::Deserialize)]
    struct Kind {
        #[serde(rename = "type")]
        kind: Option<String>,
    }
    serde_json::from_str::<Kind>(text).is_ok_and(|k| k.kind.as_deref() == Some("program"))
}

/// Reads one text message of at most `max_message_bytes`: the `id` to answer with (`None` when there is none or it
/// is invalid) and the request or the error.
pub fn parse_request(text: &str, max_message_bytes: usize) -> (Option<RequestId>, Result<Request, ApiError>) {
    parse_request_sized(text, max_message_bytes, max_message_bytes)
}

/// [`parse_request`] with a larger limit for `program` requests, `max_program_bytes` (a long program needs more
/// room than any other request): a message above `max_message_bytes` is read only if it is at most
/// `max_program_bytes` and a `program`.
pub fn parse_request_sized(
    text: &str,
    max_message_bytes: usize,
    max_program_bytes: usize,
) -> (Option<RequestId>, Result<Request, ApiError>) {
    let limit = if text.len() > max_message_bytes && text.len() <= max_program_bytes && is_program(text) {
        max_program_bytes
    } else {
        max_message_bytes
    };
    if text.len() > limit {
        let max_message_bytes = limit;
        let message = format!(
            "message of {} bytes exceeds the limit of {max_message_bytes} bytes",
            text.len()
        );
        return (None, Err(ApiError::new(ErrorCode::TooLarge, message)));
    }
    let bad_json = |e: serde_json::Error| ApiError::new(ErrorCode::BadJson, format!("not valid JSON: {e}"));
    if let Err(e) = serde_json::from_str::<UniqueKeys>(text) {
        return (None, Err(bad_json(e)));
    }
    let mut map = match serde_json::from_str(text) {
        Ok(Value::Object(map)) => map,
        Ok(_) => {
            let e = ApiError::new(ErrorCode::BadJson, "a message must be a JSON object");
            return (None, Err(e));
        }
        Err(e) => return (None, Err(bad_json(e))),
    };
    let id = match request_id(map.remove("id")) {
        Ok(id) => id,
        Err(e) => return (None, Err(e)),
    };
    (Some(id), request_of(map))
}

/// Only the `id` of a message (`None` when it has no readable one), read without building the rest: the cheap
/// read for a message refused before it is parsed (`rate_limited`), so that a flood of large programs costs a
/// tokenizer pass each, not a parse. A duplicated `id` key, or text that is not a JSON object, gives `None`.
pub fn request_id_only(text: &str) -> Option<RequestId> {
    #[derive(serde::Deserialize)]
    struct IdOnly {
        id: Option<Value>,
    }
    // serde reads a struct from an array as well: only an object has an `id`.
    if !text.trim_start().starts_with('{') {
        return None;
    }
    let id = serde_json::from_str::<IdOnly>(text).ok()?.id;
    request_id(id).ok()
}

fn request_id(id: Option<Value>) -> Result<RequestId, ApiError> {
    match id {
        None => Err(ApiError::new(ErrorCode::MissingField, "every request needs an `id`")),
        Some(Value::String(s)) if s.chars().count() <= MAX_ID_CHARS => Ok(RequestId::Text(s)),
        Some(Value::Number(n)) => Ok(RequestId::Number(n)),
        Some(_) => Err(ApiError::new(
            ErrorCode::BadValue,
            format!("`id` must be a number or a string of at most {MAX_ID_CHARS} characters"),
        )),
    }
}

/// The typed request of an object without its `id`.
fn request_of(mut map: Map<String, Value>) -> Result<Request, ApiError> {
    let kind = match map.remove("type") {
        None => return Err(ApiError::new(ErrorCode::MissingField, "missing field `type`")),
        Some(Value::String(kind)) => kind,
        Some(_) => return Err(ApiError::new(ErrorCode::BadValue, "`type` must be a string")),
    };
    let fields = Value::Object(map);
    Ok(match kind.as_str() {
        "touch" => Request::Touch(fields_of(fields)?),
        "release" => Request::Release(fields_of(fields)?),
        "setpoint" => Request::Setpoint(fields_of(fields)?),
        "clear_fault" => Request::ClearFault(fields_of(fields)?),
        "stop_all" => Request::StopAll(fields_of(fields)?),
        "subscribe" => Request::Subscribe(fields_of(fields)?),
        "unsubscribe" => Request::Unsubscribe(fields_of(fields)?),
        "status" => Request::Status(fields_of(fields)?),
        "ack_recording" => Request::AckRecording(fields_of(fields)?),
        "marker" => Request::Marker(fields_of(fields)?),
        "program" => Request::Program(fields_of(fields)?),
        "program_stop" => Request::ProgramStop(fields_of(fields)?),
        "response" => Request::Response(fields_of(fields)?),
        other => {
            return Err(ApiError::new(
                ErrorCode::UnknownType,
                format!(
                    "unknown request type {:?}; known: {}",
                    truncate(other),
                    Request::TYPES.join(", ")
                ),
            ))
        }
    })
}

/// A request's fields as their type (`serde_path_to_error` keeps the key of a refused value).
fn fields_of<T: serde::de::DeserializeOwned>(fields: Value) -> Result<T, ApiError> {
    serde_path_to_error::deserialize(fields).map_err(|e| field_error(&e))
}

/// The code and message of a request whose fields serde refused: the key is named.
fn field_error(e: &serde_path_to_error::Error<serde_json::Error>) -> ApiError {
    let inner = e.inner().to_string();
    let quoted = inner.split('`').nth(1).unwrap_or_default();
    if inner.starts_with("missing field") {
        ApiError::new(ErrorCode::MissingField, format!("missing field `{quoted}`"))
    } else if inner.starts_with("unknown field") {
        ApiError::new(ErrorCode::UnknownField, format!("unknown field {:?}", truncate(quoted)))
    } else {
        ApiError::new(ErrorCode::BadValue, format!("`{}`: {inner}", e.path()))
    }
}

/// At most 40 characters of a client's string, for messages.
pub fn truncate(text: &str) -> String {
    text.chars().take(40).collect()
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

#[cfg(test)]
mod tests {
    use super::*;

    fn code_of(text: &str) -> Option<&'static str> {
        parse_request(text, 16 * 1024).1.err().map(|e| e.code.as_str())
    }

    #[test]
    fn every_kind_of_malformed_message_has_its_code_and_names_its_key() {
        let cases = [
            (r#"{"id":1}"#, "missing_field"),
            (r#"{"type":"touch"}"#, "missing_field"),
            ("[1,2]", "bad_json"),
            (r#"{"type":"touch","type":"release","id":1,"channel":0}"#, "bad_json"),
            ("{", "bad_json"),
            (r#"{"type":7,"id":1}"#, "bad_value"),
            (r#"{"type":"fly","id":1}"#, "unknown_type"),
            (r#"{"type":"touch","id":1,"material":"wood"}"#, "missing_field"),
            (
                r#"{"type":"touch","id":1,"channel":0.5,"material":"wood"}"#,
                "bad_value",
            ),
            (
                r#"{"type":"touch","id":1,"channel":"0","material":"wood"}"#,
                "bad_value",
            ),
            (
                r#"{"type":"touch","id":1,"channel":0,"material":"wood","extra":1}"#,
                "unknown_field",
            ),
            (r#"{"type":"stop_all","id":1,"extra":1}"#, "unknown_field"),
            (r#"{"type":"release","id":{"x":1},"channel":0}"#, "bad_value"),
        ];
        for (text, want) in cases {
            assert_eq!(code_of(text), Some(want), "{text}");
        }
        let (_, refused) = parse_request(
            r#"{"type":"setpoint","id":1,"channel":0,"temp_c":"hot","rate_c_s":1}"#,
            1024,
        );
        let message = refused.unwrap_err().message;
        assert!(message.starts_with("`temp_c`"), "the message names the key: {message}");
        let (_, refused) = parse_request(r#"{"type":"touch","id":1,"channel":0,"properties":{"k":1}}"#, 1024);
        assert_eq!(refused.unwrap_err().message, "unknown field \"k\"");
        let big = format!(r#"{{"type":"status","id":1,"pad":"{}"}}"#, "x".repeat(2000));
        assert_eq!(parse_request(&big, 1024).1.unwrap_err().code, ErrorCode::TooLarge);
    }

    #[test]
    fn a_valid_message_is_its_typed_request_and_its_id_is_echoed_exactly() {
        let (id, request) = parse_request(
            r#"{"type":"touch","id":18446744073709551615,"channel":1,"material":"Aluminum"}"#,
            1024,
        );
        assert_eq!(serde_json::to_string(&id).unwrap(), "18446744073709551615");
        assert_eq!(request, Ok(Request::touch(1, "Aluminum")));
        let (id, _) = parse_request(r#"{"type":"fly","id":"abc"}"#, 1024);
        assert_eq!(
            id,
            Some(RequestId::Text("abc".into())),
            "ids are echoed even with errors"
        );
    }

    #[test]
    fn the_id_alone_is_the_id_the_full_read_finds() {
        let messages = [
            r#"{"type":"touch","id":18446744073709551615,"channel":1,"material":"Aluminum"}"#,
            r#"{"channels":{"0":[{"hold_s":1}]},"type":"program","id":"p-1"}"#,
            r#"{"type":"fly","id":"abc"}"#,
            r#"{"type":"status","id":[1]}"#,
            r#"{"type":"status"}"#,
        ];
        for text in messages {
            assert_eq!(request_id_only(text), parse_request(text, 1024).0, "{text}");
        }
        for text in [r#"{"id":1,"id":2}"#, "[1]", "{", r#""id""#] {
            assert_eq!(request_id_only(text), None, "{text}");
        }
    }
}
