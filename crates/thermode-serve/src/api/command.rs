//! `POST /api/command`: any WebSocket request as the JSON body of one HTTP request, for clients without a
//! WebSocket library (MATLAB, Octave, shell scripts). The body is answered with the WebSocket's own reply (the same
//! JSON, the same errors; an error's code also sets the HTTP status, [`http_status`]), under the same limits: the
//! message sizes, and one token bucket for every HTTP command together (the rate limit of one WebSocket
//! connection). The access check in front of every route (token, Host, Origin) applies as to any route.
//!
//! **The lease.** HTTP has no connection whose end could release a client's contacts, so the HTTP commands act as
//! one virtual connection: its first command opens it (a client number like a WebSocket's, the `owner` of what it
//! touches), every command renews it, and when no command arrives for [`NetLimits::command_lease_s`] it ends as a
//! WebSocket disconnect does: its contacts (touches, set-points, programs) are released after the grace period
//! (`--release-after`) unless another client took them over. The next command opens a new one. A contact made over
//! HTTP therefore lasts at most the lease plus the grace period after the client's last command, however the
//! client ended. `subscribe` and `unsubscribe` need a connection and are refused (`unknown_type`).
//!
//! [`NetLimits::command_lease_s`]: super::NetLimits::command_lease_s

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::body::Body;
use axum::extract::State;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use thermode_protocol::Response as Reply;
use tokio::time::Instant;

use super::execute;
use super::limit::TokenBucket;
use super::protocol::{ApiError, ErrorCode};
use super::App;
use thermode_runtime::command::Owner;

/// The state of the HTTP commands: their rate limit and their lease.
#[derive(Debug)]
pub struct CommandLease {
    state: Mutex<LeaseState>,
}

#[derive(Debug)]
struct LeaseState {
    /// Every HTTP command together: the rate limit of one WebSocket connection.
    bucket: TokenBucket,
    /// Origin of the bucket's time.
    origin: Instant,
    /// The virtual connection, while its lease runs.
    current: Option<Lease>,
}

/// One virtual connection of the HTTP commands.
#[derive(Debug, Clone, Copy)]
struct Lease {
    /// Its client number (the `owner` of its contacts).
    client: u64,
    /// When its last command arrived.
    renewed: Instant,
    /// The same moment on the loop's clock \[s\].
    renewed_loop_s: f64,
}

/// What taking the lease for a command did.
struct Taken {
    /// The client number the command runs as.
    client: u64,
    /// A new virtual connection was opened: its expiry is to be watched.
    opened: bool,
    /// An expired one found on the way: (its client number, the loop time its lease ended \[s\]).
    expired: Option<(u64, f64)>,
}

impl CommandLease {
    /// A full bucket of `requests_per_s` \[1/s\] sustained and `burst` requests, and no lease yet.
    pub fn new(requests_per_s: f64, burst: f64) -> Self {
        CommandLease {
            state: Mutex::new(LeaseState {
                bucket: TokenBucket::new(requests_per_s, burst),
                origin: Instant::now(),
                current: None,
            }),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, LeaseState> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Takes a token from the bucket; false when the HTTP commands go faster than the rate limit.
    fn admit(&self) -> bool {
        let mut state = self.lock();
        let now_s = state.origin.elapsed().as_secs_f64();
        state.bucket.take(now_s)
    }

    /// The client number a command runs as, renewing the lease (or opening a new one, retiring an expired one).
    fn take(&self, app: &App) -> Taken {
        let lease = Duration::from_secs_f64(app.net.command_lease_s);
        let mut state = self.lock();
        let expired = state
            .current
            .filter(|l| l.renewed.elapsed() >= lease)
            .map(|l| (l.client, l.renewed_loop_s + app.net.command_lease_s));
        if expired.is_some() {
            state.current = None;
        }
        let opened = state.current.is_none();
        let client = match state.current {
            Some(l) => l.client,
            None => app.next_client.fetch_add(1, Ordering::Relaxed),
        };
        state.current = Some(Lease {
            client,
            renewed: Instant::now(),
            renewed_loop_s: app.clock.now_s(),
        });
        Taken {
            client,
            opened,
            expired,
        }
    }

    /// Ends the lease of `client` if it expired: the time to wait before looking again, or the loop time its lease
    /// ended \[s\] (`Ok`) once it is over (`None`: another command already retired it).
    fn expire(&self, client: u64, lease_s: f64) -> Result<Option<f64>, Duration> {
        let lease = Duration::from_secs_f64(lease_s);
        let mut state = self.lock();
        match state.current {
            Some(l) if l.client == client => {
                let age = l.renewed.elapsed();
                if age < lease {
                    return Err(lease - age);
                }
                state.current = None;
                Ok(Some(l.renewed_loop_s + lease_s))
            }
            _ => Ok(None),
        }
    }

    /// The client number of the HTTP commands' virtual connection while its lease runs.
    pub fn client(&self) -> Option<u64> {
        self.lock().current.map(|l| l.client)
    }
}

/// Watches the lease of `client` and, once it runs out, tells the loop the client is gone (as a WebSocket
/// disconnect does, at the moment the lease ended).
async fn watch_lease(app: Arc<App>, client: u64) {
    loop {
        match app.command_lease.expire(client, app.net.command_lease_s) {
            Err(wait) => tokio::time::sleep(wait).await,
            Ok(Some(ended_s)) => return execute::goodbye(&app, client, Some(ended_s)).await,
            Ok(None) => return,
        }
    }
}

/// `POST /api/command`: one request in, its reply out.
pub async fn post(State(app): State<Arc<App>>, body: Body) -> Response {
    let text = match read_body(&app, body).await {
        Ok(text) => text,
        Err((status, e)) => return reply_response(status, &e.reply(None)),
    };
    app.http.commands.fetch_add(1, Ordering::Relaxed);
    if !app.command_lease.admit() {
        return respond(&execute::rate_limited(&app, &text));
    }
    let taken = app.command_lease.take(&app);
    if let Some((client, ended_s)) = taken.expired {
        execute::goodbye(&app, client, Some(ended_s)).await;
    }
    if taken.opened {
        tokio::spawn(watch_lease(app.clone(), taken.client));
    }
    let reply = match execute::parsed(&app, &text, Owner::Client(taken.client)).await {
        Ok((id, request)) => execute::execute(&app, request, id).await,
        Err(reply) => *reply,
    };
    respond(&reply)
}

/// Any other method on `/api/command`: 405 with the error JSON.
pub async fn other_method() -> Response {
    let e = ApiError::new(
        ErrorCode::BadValue,
        "/api/command takes POST with a request's JSON as the body",
    );
    let mut response = reply_response(StatusCode::METHOD_NOT_ALLOWED, &e.reply(None));
    response
        .headers_mut()
        .insert(header::ALLOW, HeaderValue::from_static("POST"));
    response
}

/// The body as text: at most the network's hard message limit (else `too_large`, 413), complete within the
/// header-read timeout (else `bad_json`, 408, so that a slow body cannot hold a connection), UTF-8 (else
/// `bad_json`, 400).
async fn read_body(app: &App, body: Body) -> Result<String, (StatusCode, ApiError)> {
    let hard = app.net.hard_message_bytes;
    let wait = Duration::from_secs_f64(app.net.header_timeout_s);
    let bytes = match tokio::time::timeout(wait, axum::body::to_bytes(body, hard)).await {
        Err(_) => {
            let message = format!("the body did not arrive within {} s", app.net.header_timeout_s);
            return Err((StatusCode::REQUEST_TIMEOUT, ApiError::new(ErrorCode::BadJson, message)));
        }
        Ok(Err(_)) => {
            let message = format!(
                "a request body may be at most {hard} bytes (a `program`; other requests {} bytes)",
                app.limits.max_message_bytes
            );
            return Err((
                StatusCode::PAYLOAD_TOO_LARGE,
                ApiError::new(ErrorCode::TooLarge, message),
            ));
        }
        Ok(Ok(bytes)) => bytes,
    };
    String::from_utf8(bytes.to_vec()).map_err(|_| {
        (
            StatusCode::BAD_REQUEST,
            ApiError::new(ErrorCode::BadJson, "the body must be UTF-8 JSON"),
        )
    })
}

/// The reply with the HTTP status its error code calls for (200 for every other reply).
fn respond(reply: &Reply) -> Response {
    let status = match reply {
        Reply::Error(e) => http_status(e.code),
        _ => StatusCode::OK,
    };
    reply_response(status, reply)
}

fn reply_response(status: StatusCode, reply: &Reply) -> Response {
    let mut response = (status, reply.to_text()).into_response();
    response
        .headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static("application/json"));
    response
}

/// The HTTP status of an error reply: 400 for a request that is wrong, 413 too large, 429 too fast, 409 for a
/// request the display's state refuses, 503 when the loop is busy (retry), and the access check's own.
pub fn http_status(code: ErrorCode) -> StatusCode {
    match code {
        ErrorCode::BadJson
        | ErrorCode::UnknownType
        | ErrorCode::MissingField
        | ErrorCode::UnknownField
        | ErrorCode::BadValue
        | ErrorCode::UnknownChannel
        | ErrorCode::UnknownMaterial => StatusCode::BAD_REQUEST,
        ErrorCode::TooLarge => StatusCode::PAYLOAD_TOO_LARGE,
        ErrorCode::RateLimited => StatusCode::TOO_MANY_REQUESTS,
        ErrorCode::Unauthorized => StatusCode::UNAUTHORIZED,
        ErrorCode::Forbidden => StatusCode::FORBIDDEN,
        ErrorCode::DeviceFault
        | ErrorCode::Cancelled
        | ErrorCode::RecordingFailed
        | ErrorCode::DoseNotRecorded
        | ErrorCode::DoseBudgetSpent => StatusCode::CONFLICT,
        ErrorCode::Busy | ErrorCode::TooManyConnections => StatusCode::SERVICE_UNAVAILABLE,
    }
}
