//! The checked-in JSON Schema of the protocol (`docs/protocol.schema.json`) is the one the types generate, and real
//! messages of every kind are instances of it.

use std::path::PathBuf;

use thermode_protocol::schema::protocol_schema_text;

fn checked_in_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/protocol.schema.json")
}

#[test]
fn the_checked_in_schema_is_the_one_the_types_generate() {
    let generated = protocol_schema_text();
    let path = checked_in_path();
    if std::env::var_os("THERMODE_WRITE_SCHEMA").is_some() {
        std::fs::write(&path, &generated).expect("write docs/protocol.schema.json");
    }
    let checked_in = std::fs::read_to_string(&path).unwrap_or_default();
    if checked_in != generated {
        let line = checked_in
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(checked_in.lines().count().min(generated.lines().count()));
        panic!(
            "docs/protocol.schema.json is stale (first difference at line {}: checked in {:?}, generated {:?}); \
             rewrite it with `THERMODE_WRITE_SCHEMA=1 cargo test -p thermode-protocol --test schema`",
            line + 1,
            checked_in.lines().nth(line),
            generated.lines().nth(line)
        );
    }
}
