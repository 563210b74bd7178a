//! The JSON Schema (draft 2020-12) of the wire protocol, generated from the serde types: `$defs` holds every type,
//! and the root accepts any message of either direction. A client validates what it sends against
//! `#/$defs/ClientMessage`, what it receives against `#/$defs/Response`, `/api/status` against `#/$defs/Status`,
//! `/api/materials` against `#/$defs/MaterialList` and `/api/history` against `#/$defs/History`. `POST
//! /api/command` takes a `ClientMessage` as its body and answers with a `Response`.
//!
//! The checked-in copy is `docs/protocol.schema.json`; a test fails when it is stale (`THERMODE_WRITE_SCHEMA=1
//! cargo test -p thermode-protocol` rewrites it).

use schemars::generate::SchemaSettings;
use serde_json::{json, Map, Value};

use crate::materials::MaterialInfo;
use crate::reply::{History, Response};
use crate::request::{Request, RequestId};
use crate::status::Status;

/// The schema document.
pub fn protocol_schema() -> Value {
    let mut generator = SchemaSettings::draft2020_12().into_generator();
    generator.subschema_for::<Request>();
    generator.subschema_for::<RequestId>();
    generator.subschema_for::<Response>();
    generator.subschema_for::<Status>();
    generator.subschema_for::<Vec<MaterialInfo>>();
    generator.subschema_for::<History>();
    let mut defs: Map<String, Value> = generator.take_definitions(true);
    defs.values_mut().for_each(plain_descriptions);
    defs.insert("ClientMessage".into(), client_message(&defs));
    defs.insert(
        "MaterialList".into(),
        json!({"type": "array", "items": {"$ref": "#/$defs/MaterialInfo"}}),
    );
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "thermode wire protocol",
        "description": "Every message of thermode's WebSocket API (/api/ws) and the bodies of its HTTP routes \
            (POST /api/command takes a ClientMessage and answers with a Response), generated from the serde types \
            of the thermode-protocol crate. docs/api.md is the prose.",
        "oneOf": [{"$ref": "#/$defs/ClientMessage"}, {"$ref": "#/$defs/Response"}],
        "$defs": Value::Object(defs),
    })
}

/// A request message: each variant of `Request` with the `id` every message carries (the daemon reads the `id`
/// before the body, so the body's type has none).
fn client_message(defs: &Map<String, Value>) -> Value {
    let mut message = defs.get("Request").cloned().unwrap_or(Value::Null);
    if let Some(variants) = message.get_mut("oneOf").and_then(Value::as_array_mut) {
        for variant in variants {
            if let Some(properties) = variant.get_mut("properties").and_then(Value::as_object_mut) {
                properties.insert("id".into(), json!({"$ref": "#/$defs/RequestId"}));
            }
            if let Some(required) = variant.get_mut("required").and_then(Value::as_array_mut) {
                required.push(json!("id"));
            }
        }
    }
    message
}

/// Descriptions come from doc comments, whose brackets are escaped for rustdoc (`\[°C\]`): plain text here.
fn plain_descriptions(value: &mut Value) {
    match value {
        Value::Object(map) => {
            if let Some(Value::String(text)) = map.get_mut("description") {
                *text = text.replace("\\[", "[").replace("\\]", "]");
            }
            map.values_mut().for_each(plain_descriptions);
        }
        Value::Array(items) => items.iter_mut().for_each(plain_descriptions),
        _ => {}
    }
}

/// The schema as the checked-in file holds it: pretty JSON and a final newline.
pub fn protocol_schema_text() -> String {
    format!("{:#}\n", protocol_schema())
}
