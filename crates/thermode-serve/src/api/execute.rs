//! What the WebSocket (`/api/ws`) and HTTP (`POST /api/command`) faces share: reading a request's text into the
//! request to run (or the error reply), running every request that needs no connection (a loop command, `status`,
//! `marker`, `ack_recording`), the rate-limit refusal, and telling the loop that a client is gone. Both faces answer
//! with the same replies and errors because both answer here.

use std::time::Duration;

use thermode_platform::to_clock_resolution;
use thermode_protocol::{Done, OkReply, RequestId, Response as Reply, StatusReply};

use super::protocol::{self, ApiError, ApiRequest, ErrorCode};
use super::{recording_status, status, App};
use thermode_runtime::command::{Command, CommandError, Owner};
use thermode_runtime::recorder::RecordState;

/// Messages longer than this \[bytes\] are read on the blocking pool, not on a network worker: a 999-segment
/// program takes milliseconds to read, and a few clients sending them back to back would otherwise hold both
/// workers while a `stop_all` waits behind them. 16384 (the soft message limit: only a `program` is longer).
pub(crate) const INLINE_READ_BYTES: usize = 16 * 1024;

/// Reads one request's text from `owner`: the request with its `id`, or the error reply to send.
pub(crate) async fn parsed(app: &App, text: &str, owner: Owner) -> Result<(RequestId, ApiRequest), Box<Reply>> {
    let read = if text.len() <= INLINE_READ_BYTES {
        protocol::parse(text, &app.limits, owner)
    } else {
        let (text, limits) = (text.to_owned(), app.limits.clone());
        match tokio::task::spawn_blocking(move || protocol::parse(&text, &limits, owner)).await {
            Ok(read) => read,
            Err(_) => (
                None,
                Err(ApiError::new(
                    ErrorCode::Busy,
                    "the request could not be read; nothing was done",
                )),
            ),
        }
    };
    match read {
        (Some(id), Ok(request)) => Ok((id, request)),
        (id, Err(e)) => Err(Box::new(e.reply(id))),
        // parse_request gives every request it accepts its id; answered as a missing one all the same.
        (None, Ok(_)) => Err(Box::new(
            ApiError::new(ErrorCode::MissingField, "every request needs an `id`").reply(None),
        )),
    }
}

/// The `rate_limited` reply to `text` (with its `id` when it has a readable one: only the id is read, so that a
/// refused flood costs little).
pub(crate) fn rate_limited(app: &App, text: &str) -> Reply {
    let message = format!(
        "more than {} requests per second (burst {}); slow down",
        app.net.requests_per_s, app.net.burst
    );
    ApiError::new(ErrorCode::RateLimited, message).reply(thermode_protocol::request_id_only(text))
}

/// Runs a request that needs no connection and gives its reply; a `subscribe` or `unsubscribe` (telemetry is
/// streamed on a connection) is refused with `unknown_type` saying where to go instead.
pub(crate) async fn execute(app: &App, request: ApiRequest, id: RequestId) -> Reply {
    let done = match request {
        ApiRequest::Command(command) => to_loop(app, command).await,
        ApiRequest::AckRecording => Ok(acknowledge(app)),
        ApiRequest::Marker { text, channel } => marker(app, text, channel),
        ApiRequest::Status => {
            let status = status(app);
            return Reply::Status(Box::new(StatusReply { id, status }));
        }
        ApiRequest::Subscribe { .. } | ApiRequest::Unsubscribe => Err(ApiError::new(
            ErrorCode::UnknownType,
            "`subscribe` and `unsubscribe` need a connection (telemetry is streamed): use the WebSocket /api/ws, \
             or poll `status` or GET /api/history",
        )),
    };
    match done {
        Ok(done) => Reply::Ok(OkReply { id, done }),
        Err(e) => e.reply(Some(id)),
    }
}

/// An operator acknowledges a failed recording (also under the policy `continue`, without an interlock: a
/// failed recording goes on in a new file).
fn acknowledge(app: &App) -> Done {
    let mut acknowledged = app.interlock.acknowledge();
    if let Some(recording) = &app.recording {
        acknowledged |= recording.state() == RecordState::Failed;
        if acknowledged {
            recording.request_resume();
        }
    }
    let recording = app.recording.as_ref().map(|r| recording_status(app, r));
    Done::AckRecording {
        acknowledged,
        recording,
    }
}

/// Tells the loop that `client` is gone since `at_s` (loop time \[s\]; `None`: now), retrying while the urgent lane
/// is full: its contacts must be released after the grace period.
pub(crate) async fn goodbye(app: &App, client: u64, at_s: Option<f64>) {
    let at_s = Some(at_s.unwrap_or_else(|| app.clock.now_s()));
    for _ in 0..1000 {
        match app.commands.send(Command::ClientGone { client, at_s }) {
            Err(CommandError::Busy) => tokio::time::sleep(Duration::from_millis(5)).await,
            _ => return,
        }
    }
}

/// A client marker: stamped with the loop clock now, forwarded to the LSL marker stream when there is one;
/// answered with the loop time (and the LSL time under `--lsl`).
fn marker(app: &App, text: String, channel: Option<usize>) -> Result<Done, ApiError> {
    let time_s = app.clock.now_s();
    let lsl_time_s = match &app.markers {
        Some(markers) => {
            let lsl_time_s = to_clock_resolution(markers.clock().lsl_time_s(time_s));
            if !markers.send(crate::lsl::ClientMarker { time_s, text, channel }) {
                return Err(ApiError::new(
                    ErrorCode::Busy,
                    "the LSL marker queue is full; nothing was sent",
                ));
            }
            Some(lsl_time_s)
        }
        None => None,
    };
    Ok(Done::Marker {
        channel,
        time_s: to_clock_resolution(time_s),
        lsl_time_s,
        lsl: lsl_time_s.is_some(),
    })
}

/// Sends `command` to the loop and waits (bounded) for its answer.
async fn to_loop(app: &App, command: Command) -> Result<Done, ApiError> {
    let answer = app.commands.request(command.clone()).map_err(loop_error)?;
    let applied = super::answer_within(answer, app.reply_wait).await.map_err(loop_error)?;
    Ok(protocol::done(&command, &applied))
}

/// The API error for a loop refusal.
pub(crate) fn loop_error(e: CommandError) -> ApiError {
    let code = match &e {
        CommandError::UnknownChannel { .. } => ErrorCode::UnknownChannel,
        CommandError::Faulted { .. } | CommandError::FaultPersists { .. } => ErrorCode::DeviceFault,
        CommandError::Rejected { .. } | CommandError::Program(_) => ErrorCode::BadValue,
        CommandError::NoStartTemperature { .. } => ErrorCode::Busy,
        CommandError::Busy | CommandError::Stopped => ErrorCode::Busy,
        CommandError::Cancelled => ErrorCode::Cancelled,
        CommandError::RecordingFailed => ErrorCode::RecordingFailed,
        CommandError::DoseNotRecorded => ErrorCode::DoseNotRecorded,
        CommandError::DoseBudgetSpent { .. } => ErrorCode::DoseBudgetSpent,
    };
    ApiError::new(code, e.to_string())
}
