//! thermode-protocol: the wire vocabulary of thermode, one type per message, used by the daemon
//! (`thermode-serve`), by the lab's live runner (`thermode-lab`) and by tests, so that no side spells a message
//! again. The JSON Schema of every message (`docs/protocol.schema.json`) is generated from these types
//! ([`schema::protocol_schema`]); clients in other languages are tested against it.
//!
//! - [`request`]: what clients send ([`Envelope`]: an `id` and a [`Request`] tagged by `type`);
//! - [`parse`]: reading a request message, with the stable error codes ([`ApiError`]);
//! - [`reply`]: what the daemon sends ([`Response`]: replies, errors, the status, telemetry, events);
//! - [`telemetry`], [`status`]: the numbers and states those carry;
//! - [`program`]: stimulus programs and participants' responses (requests, cut-offs, events);
//! - [`materials`]: a material given by its properties, and the library as listed.
//!
//! The prose of the protocol (what each request does, the limits, the security rules) is `docs/api.md`.

pub mod materials;
pub mod parse;
pub mod program;
pub mod reply;
pub mod request;
pub mod schema;
pub mod status;
pub mod telemetry;

pub use materials::{MaterialInfo, MaterialProperties};
pub use parse::{parse_request, parse_request_sized, request_id_only, ApiError};
pub use program::{ProgramCutoff, ProgramEvent, ProgramEventKind, ResponseKind};
pub use reply::{AppliedAt, Done, ErrorCode, ErrorReply, Event, OkReply, RecordingEvent, Response, StatusReply};
pub use request::{Envelope, Request, RequestId};
pub use telemetry::{finite, ChannelState, ChannelTelemetry, Mode, OffReason, Owner, Telemetry};
