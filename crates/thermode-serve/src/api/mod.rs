//! The network side: HTTP routes (`/` dashboard, `/api/status`, `/api/materials`, `/api/history`, `/api/ws`,
//! `POST /api/command`), the access check in front of every route, and the state the handlers share. It talks to
//! the control loop only through the bounded command queue and the published snapshot.

pub mod access;
pub mod command;
pub(crate) mod execute;
pub mod history;
pub mod limit;
pub mod protocol;
pub mod server;
pub mod ws;

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::extract::{Request, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use thermode_platform::to_clock_resolution;
use thermode_protocol::finite;
use thermode_protocol::status::{
    Auth, Commands, Contact, DeviceCutEntry, DeviceStatus, DoseLedgerStatus, EarlierFile, FaultEntry, HttpStatus,
    InterlockStatus, LinkStatus, LoopStatus, LslStatus, OscStatus, RealtimeStatus, Recording, Status,
};

use access::Access;
use protocol::{ApiError, ErrorCode, RequestLimits};
use thermode_model::params::Rule;
use thermode_platform::Clock;

use crate::error::ServeError;
use thermode_runtime::command::{Answer, CommandSender, Reply};
use thermode_runtime::interlock::Interlock;
use thermode_runtime::ledger::WriterStatus;
use thermode_runtime::recorder::{RecordErrorPolicy, RecordState, RecordStatus};
use thermode_runtime::snapshot::{Mode, Shared, Snapshot};

/// The dashboard page (one static file, inline script, hand-drawn canvas plots).
pub const DASHBOARD_HTML: &str = include_str!("../dashboard.html");

/// How long an OSC subscription lasts unless renewed (by sending `/thermode/subscribe` again) \[s\]: the default of
/// [`NetLimits::osc_subscription_ttl_s`].
pub const SUBSCRIPTION_TTL_S: f64 = 10.0;

/// Limits of the network side.
#[derive(Debug, Clone, PartialEq)]
pub struct NetLimits {
    /// Frames or messages larger than this close the connection (the protocol's hard limit) \[bytes\]. Default
    /// 196608 (192 KiB: a `program` of 999 segments fits). Messages up to it but above
    /// [`RequestLimits::max_message_bytes`] get a `too_large` error, unless they are a `program`.
    pub hard_message_bytes: usize,
    /// Sustained requests per second per WebSocket connection. Default 50.
    pub requests_per_s: f64,
    /// Requests a connection may send at once. Default 100.
    pub burst: f64,
    /// Most simultaneous WebSocket connections. Default 32.
    pub max_connections: usize,
    /// Most simultaneous HTTP connections, WebSockets included \[connections\]. Default 128; lowered at start-up
    /// to the open-files limit less 64 (see [`server`]). At the cap a new connection replaces the oldest idle one.
    pub max_http_connections: usize,
    /// A request head must be complete within this time of the connection's start, or of the first byte of a later
    /// request \[s\]. Default 5; at most 10.
    pub header_timeout_s: f64,
    /// A kept-alive HTTP connection with no request for this long is closed \[s\]. Default 10.
    pub http_idle_timeout_s: f64,
    /// Longest wait for the control loop's answer \[s\]. Default 1.
    pub reply_timeout_s: f64,
    /// The lease of `POST /api/command`'s virtual connection: when no HTTP command arrives for this long, the
    /// contacts made over HTTP are released after the grace period, as a disconnected WebSocket client's are
    /// ([`command`]) \[s\]. Default 30 (a method-of-limits ramp of 17 °C at 1 °C/s with its response fits).
    pub command_lease_s: f64,
    /// A connection from which nothing (not even a pong) arrives for this long is closed \[s\]. Default 20.
    pub idle_timeout_s: f64,
    /// Interval of the server's pings \[s\]. Default 1.
    pub ping_interval_s: f64,
    /// A client that stopped reading is closed: a send that cannot complete for this long, or a ping left
    /// unanswered for this long \[s\]. Default 5 (so a client that stops reading is closed within 5 s plus one ping
    /// interval).
    pub send_timeout_s: f64,
    /// Sustained OSC messages per second (all senders together). Default 200.
    pub osc_messages_per_s: f64,
    /// OSC burst. Default 400.
    pub osc_burst: f64,
    /// An OSC telemetry subscription not renewed for this long ends \[s\]. Default 10
    /// ([`SUBSCRIPTION_TTL_S`]).
    pub osc_subscription_ttl_s: f64,
    /// Most OSC bytes sent to one subscriber per second (telemetry and fault events; the datagrams' payload)
    /// \[B/s\]. Default 16384: five channels at 50 Hz (64 bytes a channel's telemetry); a faster
    /// subscription is lowered to fit (the acknowledgement says the rate granted), and whatever would exceed the
    /// budget is not sent (counted as `throttled`). At least 1024.
    pub osc_subscriber_bytes_per_s: f64,
}

impl Default for NetLimits {
    fn default() -> Self {
        NetLimits {
            hard_message_bytes: 192 * 1024,
            requests_per_s: 50.0,
            burst: 100.0,
            max_connections: 32,
            max_http_connections: 128,
            header_timeout_s: 5.0,
            http_idle_timeout_s: 10.0,
            reply_timeout_s: 1.0,
            command_lease_s: 30.0,
            idle_timeout_s: 20.0,
            ping_interval_s: 1.0,
            send_timeout_s: 5.0,
            osc_messages_per_s: 200.0,
            osc_burst: 400.0,
            osc_subscription_ttl_s: SUBSCRIPTION_TTL_S,
            osc_subscriber_bytes_per_s: 16_384.0,
        }
    }
}

impl NetLimits {
    /// Every duration in (0, 86400] s (the header timeout in (0, 10] s), every rate and burst at least 1, at
    /// least one WebSocket connection, a hard message limit of at least 1 KiB and more HTTP connections than
    /// WebSockets: each refused number is a `BadValue` naming its key.
    pub fn validate(&self) -> Result<(), ServeError> {
        let day = Rule::AtMost {
            max: 86_400.0,
            what: "a day [s]",
        };
        let durations = [
            ("reply_timeout_s", self.reply_timeout_s),
            ("command_lease_s", self.command_lease_s),
            ("idle_timeout_s", self.idle_timeout_s),
            ("ping_interval_s", self.ping_interval_s),
            ("send_timeout_s", self.send_timeout_s),
            ("http_idle_timeout_s", self.http_idle_timeout_s),
            ("osc_subscription_ttl_s", self.osc_subscription_ttl_s),
        ];
        for (name, value) in durations {
            Rule::Positive.check(name, value)?;
            day.check(name, value)?;
        }
        let at_least_one = Rule::AtLeast { min: 1.0 };
        for (name, value) in [
            ("requests_per_s", self.requests_per_s),
            ("burst", self.burst),
            ("osc_messages_per_s", self.osc_messages_per_s),
            ("osc_burst", self.osc_burst),
            ("max_connections", self.max_connections as f64),
        ] {
            at_least_one.check(name, value)?;
        }
        Rule::AtLeast { min: 1024.0 }.check("hard_message_bytes", self.hard_message_bytes as f64)?;
        Rule::AtLeast { min: 1024.0 }.check("osc_subscriber_bytes_per_s", self.osc_subscriber_bytes_per_s)?;
        let above_websockets = Rule::AtLeast {
            min: self.max_connections as f64 + 1.0,
        };
        above_websockets.check("max_http_connections", self.max_http_connections as f64)?;
        Rule::Positive.check("header_timeout_s", self.header_timeout_s)?;
        let header = Rule::AtMost {
            max: 10.0,
            what: "the longest header timeout [s]",
        };
        header.check("header_timeout_s", self.header_timeout_s)?;
        Ok(())
    }
}

/// Counters of the OSC listener.
#[derive(Debug, Default)]
pub struct OscCounters {
    /// Datagrams received.
    pub packets: AtomicU64,
    /// Messages the control loop applied (counted when the loop answers).
    pub applied: AtomicU64,
    /// Datagrams that are not valid OSC (ignored).
    pub malformed: AtomicU64,
    /// Valid OSC messages refused: by the validation (unknown address, channel or material, bad value), by a full
    /// queue, or by the control loop (a faulted channel, a failed recording…).
    pub refused: AtomicU64,
    /// Messages dropped by the rate limit.
    pub rate_limited: AtomicU64,
    /// OSC telemetry subscribers now (expired ones leave within a fraction of a second).
    pub subscribers: AtomicUsize,
    /// OSC datagrams sent to subscribers (telemetry, fault events, acknowledgements).
    pub sent: AtomicU64,
    /// Subscriptions refused (a daemon's own port, a port another address subscribed, the cap, a bad rate…).
    pub subscriptions_refused: AtomicU64,
    /// Datagrams not sent to a subscriber because its byte budget
    /// ([`NetLimits::osc_subscriber_bytes_per_s`]) was spent.
    pub throttled: AtomicU64,
    /// The last refusal, for the status page.
    pub last_error: Mutex<Option<String>>,
}

/// Facts about the daemon shown by `/api/status`.
#[derive(Debug, Clone, PartialEq)]
pub struct Info {
    /// The device, e.g. `sim` or `serial:/dev/ttyACM0`.
    pub device: String,
    /// A name per channel (e.g. the fingers), or empty.
    pub channel_names: Vec<String>,
    /// What each channel's device file is (channels past the list: its last entry; none: `datasheet`).
    pub device_files: Vec<thermode_protocol::status::DeviceFileKind>,
    /// The OSC port, when OSC listens.
    pub osc_port: Option<u16>,
    /// The HTTP port (an OSC subscription to it is refused, as to the OSC port).
    pub http_port: u16,
    /// The session recording, if any.
    pub recording: Option<String>,
}

/// State shared by the handlers.
pub struct App {
    pub(crate) commands: CommandSender,
    pub(crate) shared: Arc<Shared>,
    pub(crate) limits: RequestLimits,
    pub(crate) net: NetLimits,
    pub(crate) access: Access,
    pub(crate) info: Info,
    pub(crate) osc: Arc<OscCounters>,
    /// The dose ledger of the state directory, if any.
    pub(crate) dose_ledger: Option<Arc<WriterStatus>>,
    /// The recording, if any.
    pub(crate) recording: Option<Arc<RecordStatus>>,
    /// The recording's event counts, fed by its event port ([`RecordStatus::listen`]), if recording.
    pub(crate) record_events: Option<tokio::sync::watch::Receiver<thermode_runtime::recorder::RecordEvents>>,
    /// What a failed recording does.
    pub(crate) record_policy: RecordErrorPolicy,
    /// The interlock the loop obeys (tripped by a failed recording under the policy `stop`).
    pub(crate) interlock: Arc<Interlock>,
    /// The loop's clock (disconnect times are on it).
    pub(crate) clock: Arc<dyn Clock>,
    /// Longest wait for the loop's answer: the configured reply timeout, at least two loop periods.
    pub(crate) reply_wait: Duration,
    pub(crate) clients: AtomicUsize,
    pub(crate) next_client: AtomicU64,
    /// The rate limit and lease of `POST /api/command`.
    pub(crate) command_lease: command::CommandLease,
    /// What the HTTP server did.
    pub(crate) http: Arc<server::HttpCounters>,
    /// The HTTP connection cap in force (fitted to the open-files limit).
    pub(crate) http_cap: usize,
    /// The device's link, if it has one.
    pub(crate) link: Option<Arc<thermode_device::LinkHealth>>,
    /// The devices the display is made of, each with its channels and link.
    pub(crate) parts: Vec<thermode_device::DevicePart>,
    /// What real-time treatment the loop obtained.
    pub(crate) realtime: thermode_platform::rt::Realtime,
    /// The last seconds of telemetry (`/api/history`), filled off the loop thread.
    pub(crate) history: Arc<history::History>,
    /// Program events (segment starts, responses, ends) as WebSocket messages, for telemetry subscribers.
    pub(crate) program_events: tokio::sync::broadcast::Sender<Arc<str>>,
    /// Where client markers go (`serve --lsl`), or `None`.
    pub(crate) markers: Option<crate::lsl::MarkerSender>,
    /// The LSL streams, for `/api/status`.
    pub(crate) lsl: Option<crate::lsl::LslInfo>,
}

impl std::fmt::Debug for App {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("App")
            .field("limits", &self.limits)
            .field("net", &self.net)
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

/// Waits up to `wait` for the loop's answer to a request (the loop core's [`Answer::wait_until`] on a tokio timer):
/// `Err(Busy)` means nothing was applied and nothing will be.
pub async fn answer_within(answer: Answer, wait: Duration) -> Reply {
    answer.wait_until(tokio::time::sleep(wait)).await
}

/// The recording's event counts as a watch channel, fed by the recorder's event port.
pub(crate) fn record_events(
    recording: &RecordStatus,
) -> tokio::sync::watch::Receiver<thermode_runtime::recorder::RecordEvents> {
    let (sender, receiver) = tokio::sync::watch::channel(recording.events());
    recording.listen(Box::new(move |events| {
        sender.send_replace(events);
    }));
    receiver
}

/// The router with every route behind the access check.
pub fn router(app: Arc<App>) -> Router {
    Router::new()
        .route("/", get(dashboard))
        .route("/api/status", get(status_route))
        .route("/api/materials", get(materials))
        .route("/api/history", get(history_route))
        .route("/api/ws", get(ws::upgrade))
        .route("/api/command", post(command::post).fallback(command::other_method))
        .fallback(not_found)
        .layer(middleware::from_fn_with_state(app.clone(), check_access))
        .with_state(app)
}

/// An error as an HTTP response with a JSON body.
pub(crate) fn error_response(status: StatusCode, error: &ApiError) -> Response {
    (status, Json(error.reply(None))).into_response()
}

async fn check_access(State(app): State<Arc<App>>, request: Request, next: Next) -> Response {
    if request.headers().get_all(header::HOST).iter().count() > 1 {
        let e = ApiError::new(ErrorCode::BadValue, "a request must have exactly one Host header");
        return error_response(StatusCode::BAD_REQUEST, &e);
    }
    match app.access.check(request.headers(), request.uri().query()) {
        Ok(()) => next.run(request).await,
        Err(e) if e.code == ErrorCode::Unauthorized => {
            let mut response = error_response(StatusCode::UNAUTHORIZED, &e);
            response
                .headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
            response
        }
        Err(e) => error_response(StatusCode::FORBIDDEN, &e),
    }
}

async fn dashboard() -> Response {
    let mut response = Html(DASHBOARD_HTML).into_response();
    let headers = response.headers_mut();
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    headers.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    headers.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; connect-src 'self'; \
             img-src 'self' data:; frame-ancestors 'none'",
        ),
    );
    response
}

async fn status_route(State(app): State<Arc<App>>) -> Json<Status> {
    Json(status(&app))
}

async fn history_route(State(app): State<Arc<App>>) -> Json<thermode_protocol::reply::History> {
    Json(app.history.to_history())
}

async fn materials() -> Json<Vec<thermode_protocol::MaterialInfo>> {
    Json(thermode_protocol::materials::library_info())
}

async fn not_found() -> Response {
    let e = ApiError::new(
        ErrorCode::UnknownType,
        "no such route; see /, /api/status, /api/materials, /api/history, /api/ws, /api/command (POST)",
    );
    error_response(StatusCode::NOT_FOUND, &e)
}

/// The daemon's status (the `/api/status` body and the WebSocket `status` reply without `type` and `id`).
pub fn status(app: &App) -> Status {
    let snapshot = app.shared.snapshot();
    let name = |i: usize| app.info.channel_names.get(i).map(String::as_str);
    let count = |a: &AtomicU64| a.load(Ordering::Relaxed);
    Status {
        version: env!("CARGO_PKG_VERSION").to_string(),
        device: app.info.device.clone(),
        running: snapshot.running,
        time_s: to_clock_resolution(snapshot.time_s),
        tick: snapshot.tick,
        channel_count: snapshot.channels.len(),
        channels: snapshot
            .channels
            .iter()
            .map(|c| protocol::channel_status(c, name(c.channel)))
            .collect(),
        contacts: contacts(&snapshot),
        faults: faults(&snapshot),
        device_cuts: device_cuts(&snapshot),
        loop_stats: loop_status(app, &snapshot),
        commands: Commands {
            applied: snapshot.commands_applied,
            refused: snapshot.commands_refused,
            withdrawn: snapshot.commands_withdrawn,
        },
        device_errors: snapshot.device_errors,
        clients: app.clients.load(Ordering::Relaxed),
        http: HttpStatus {
            open: count(&app.http.open),
            max_connections: app.http_cap,
            header_timeout_s: app.net.header_timeout_s,
            idle_timeout_s: app.net.http_idle_timeout_s,
            accepted: count(&app.http.accepted),
            evicted: count(&app.http.evicted),
            timed_out: count(&app.http.timed_out),
            refused: count(&app.http.refused),
            accept_errors: count(&app.http.accept_errors),
            commands: count(&app.http.commands),
            command_lease_s: app.net.command_lease_s,
            command_client: app.command_lease.client(),
        },
        auth: Auth {
            token_required: app.access.token_required(),
        },
        limits: protocol::limits_status(&app.limits, app.net.requests_per_s, app.net.burst),
        osc: osc_status(app),
        recording: app.recording.as_ref().map(|r| recording_status(app, r)),
        lsl: app.lsl.as_ref().map(|l| LslStatus {
            library: l.library.clone(),
            lsl_offset_s: to_clock_resolution(l.clock.offset_s),
            lsl_clock_at_start_s: to_clock_resolution(l.clock.lsl_at_start_s),
            samples: count(&l.counters.samples),
            markers: count(&l.counters.markers),
            failed: count(&l.counters.failed),
        }),
        link: app
            .link
            .as_ref()
            .map(|l| link_status(l))
            .or_else(|| links_together(&app.parts)),
        devices: app
            .parts
            .iter()
            .map(|part| DeviceStatus {
                device: match part.label.is_empty() {
                    true => app.info.device.clone(),
                    false => part.label.clone(),
                },
                channels: part.channels().collect(),
                link: part.health.as_deref().map(link_status),
                command_set: part.health.as_ref().and_then(|h| h.command_set()),
            })
            .collect(),
        channel_devices: (0..snapshot.channels.len())
            .map(|channel| {
                app.parts
                    .iter()
                    .position(|p| p.channels().contains(&channel))
                    .unwrap_or(0)
            })
            .collect(),
        channel_device_files: (0..snapshot.channels.len())
            .map(|c| {
                let files = &app.info.device_files;
                files.get(c).or(files.last()).copied().unwrap_or_default()
            })
            .collect(),
        dose_ledger: app.dose_ledger.as_ref().map(|w| DoseLedgerStatus {
            path: w.path.display().to_string(),
            writes: count(&w.writes),
            errors: count(&w.errors),
            last_error: w.last_error.lock().map(|e| e.clone()).unwrap_or(None),
            stimuli_refused: app.interlock.dose_held(),
        }),
        interlock: InterlockStatus {
            engaged: app.interlock.engaged(),
            trips: app.interlock.trips(),
            reason: app.interlock.reason(),
        },
    }
}

/// The status of one link.
fn link_status(l: &thermode_device::LinkHealth) -> LinkStatus {
    LinkStatus {
        state: if l.is_up() { "up" } else { "down" }.to_string(),
        reconnects: l.reconnects(),
        failures: l.failures(),
        attempts: l.attempts(),
        error: l.error(),
    }
}

/// The links of a display of several devices together: `up` only when every one is up, the counts summed, the
/// error of the first link that is down (else the last one's); None when no part has a link.
fn links_together(parts: &[thermode_device::DevicePart]) -> Option<LinkStatus> {
    let links: Vec<LinkStatus> = parts
        .iter()
        .filter_map(|p| p.health.as_deref().map(link_status))
        .collect();
    let down = links.iter().find(|l| l.state == "down");
    let error = down.map_or_else(|| links.iter().rev().find_map(|l| l.error.clone()), |l| l.error.clone());
    (!links.is_empty()).then(|| LinkStatus {
        state: if down.is_some() { "down" } else { "up" }.to_string(),
        reconnects: links.iter().map(|l| l.reconnects).sum(),
        failures: links.iter().map(|l| l.failures).sum(),
        attempts: links.iter().map(|l| l.attempts).sum(),
        error,
    })
}

fn contacts(snapshot: &Snapshot) -> Vec<Contact> {
    let shown = snapshot.channels.iter().filter(|c| c.mode != Mode::Air);
    shown
        .map(|c| Contact {
            channel: c.channel,
            material: c.label.to_string(),
            mode: crate::wire::mode(c.mode),
            owner: crate::wire::owner(c.owner),
        })
        .collect()
}

fn faults(snapshot: &Snapshot) -> Vec<FaultEntry> {
    let faulted = snapshot
        .channels
        .iter()
        .filter_map(|c| c.telemetry.fault.map(|f| (c.channel, f)));
    faulted
        .map(|(channel, f)| FaultEntry {
            channel,
            fault: f.code(),
            description: f.description().to_string(),
        })
        .collect()
}

fn device_cuts(snapshot: &Snapshot) -> Vec<DeviceCutEntry> {
    let cut = snapshot
        .channels
        .iter()
        .filter_map(|c| c.device_cut.map(|cut| (c.channel, cut)));
    cut.map(|(channel, cut)| DeviceCutEntry {
        channel,
        cut: cut.name().to_string(),
        description: cut.to_string(),
    })
    .collect()
}

fn loop_status(app: &App, snapshot: &Snapshot) -> LoopStatus {
    let (s, rt) = (&snapshot.stats, &app.realtime);
    LoopStatus {
        rate_hz: s.rate_hz,
        period_s: s.period_s,
        period_p50_s: finite(s.period.p50_s).map(to_clock_resolution),
        period_p99_s: finite(s.period.p99_s).map(to_clock_resolution),
        period_max_s: finite(s.period.max_s).map(to_clock_resolution),
        work_p50_s: finite(s.work.p50_s).map(to_clock_resolution),
        work_p99_s: finite(s.work.p99_s).map(to_clock_resolution),
        work_max_s: finite(s.work.max_s).map(to_clock_resolution),
        window_ticks: s.period.count,
        missed_deadlines: s.missed_deadlines,
        ticks: s.ticks,
        skipped_publishes: app.shared.skipped_publishes(),
        realtime: RealtimeStatus {
            scheduling: if rt.fifo_priority.is_some() {
                "SCHED_FIFO"
            } else {
                "normal"
            }
            .to_string(),
            priority: rt.fifo_priority,
            scheduling_error: rt.scheduling_error.clone(),
            memory_locked: rt.memory_locked,
            memory_error: rt.memory_error.clone(),
            cpu: rt.cpu,
        },
    }
}

fn osc_status(app: &App) -> OscStatus {
    let (osc, count) = (&app.osc, |a: &AtomicU64| a.load(Ordering::Relaxed));
    OscStatus {
        enabled: app.info.osc_port.is_some(),
        port: app.info.osc_port,
        packets: count(&osc.packets),
        applied: count(&osc.applied),
        malformed: count(&osc.malformed),
        refused: count(&osc.refused),
        rate_limited: count(&osc.rate_limited),
        subscribers: osc.subscribers.load(Ordering::Relaxed),
        sent: count(&osc.sent),
        subscriptions_refused: count(&osc.subscriptions_refused),
        throttled: count(&osc.throttled),
        subscriber_bytes_per_s: app.net.osc_subscriber_bytes_per_s,
        last_error: osc.last_error.lock().map(|e| e.clone()).unwrap_or(None),
    }
}

/// `/api/status` `recording`: the file, `state` (`ok` or `failed`), the `error`, the rows in the file, and what the
/// policy does.
pub fn recording_status(app: &App, r: &RecordStatus) -> Recording {
    let state = match r.state() {
        RecordState::Ok => "ok",
        RecordState::Failed => "failed",
    };
    let earlier = r.earlier_files().into_iter().map(|(path, rows)| EarlierFile {
        path: path.display().to_string(),
        rows_written: rows,
    });
    Recording {
        path: r.path().display().to_string(),
        segment: r.segment(),
        earlier_files: earlier.collect(),
        state: state.to_string(),
        error: r.error(),
        rows_written: r.rows_written(),
        rows: r.rows_written(),
        bytes_written: r.bytes_written(),
        rows_lost: r.rows_lost(),
        dropped_ticks: app.shared.dropped_records(),
        on_error: app.record_policy.name().to_string(),
        stimuli_refused: r.state() == RecordState::Failed && app.interlock.engaged(),
    }
}
