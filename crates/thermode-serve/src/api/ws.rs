//! The WebSocket endpoint `/api/ws`: one task per connection that reads requests, answers each with the same
//! `id`, streams telemetry to subscribers, sends events (a failed recording), pings, and on disconnect tells the
//! loop, which releases the client's contacts after the grace period.
//!
//! Limits: messages above the soft size limit get `too_large`; frames above the hard limit close the connection;
//! each connection has a token-bucket rate limit (`rate_limited`); a client that sends nothing for the idle timeout
//! is disconnected; so is a client that stops reading: a send that cannot complete within the send timeout, or a
//! ping (one every ping interval) not answered within the send timeout. A text frame that is not UTF-8 is
//! answered with the close code 1007. The handshake needs a well-formed `Sec-WebSocket-Key` (16 bytes in base64).

use std::collections::VecDeque;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
use axum::Extension;
use thermode_protocol::{Done, Event, OkReply, RecordingEvent, Response as Reply};
use tokio::sync::{broadcast, watch};
use tokio::time::{interval, timeout, Instant, Interval, MissedTickBehavior};

use super::execute;
use super::protocol::{self, ApiError, ApiRequest, ErrorCode};
use super::{error_response, recording_status, App};
use thermode_runtime::command::{Command, Owner};
use thermode_runtime::recorder::RecordEvents;

/// The close code for a text frame that is not UTF-8 (RFC 6455 §7.4.1: invalid frame payload data).
pub const CLOSE_INVALID_PAYLOAD: u16 = 1007;

/// Counts a connection for as long as it lives.
struct ConnectionSlot(Arc<App>);

impl Drop for ConnectionSlot {
    fn drop(&mut self) {
        self.0.clients.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Whether `key` is a valid `Sec-WebSocket-Key`: the base64 of 16 bytes (24 characters, ending in `==`).
pub fn valid_websocket_key(key: &[u8]) -> bool {
    let b64 = |c: &u8| c.is_ascii_alphanumeric() || *c == b'+' || *c == b'/';
    key.len() == 24 && key[..22].iter().all(b64) && key.ends_with(b"==") && b"AQgw".contains(&key[21])
}

/// `GET /api/ws`: upgrades, unless the key is malformed or the connection limit is reached.
pub async fn upgrade(
    State(app): State<Arc<App>>,
    connection: Option<Extension<Arc<super::server::Slot>>>,
    headers: HeaderMap,
    ws: WebSocketUpgrade,
) -> Response {
    let keys: Vec<&[u8]> = headers
        .get_all("sec-websocket-key")
        .iter()
        .map(|v| v.as_bytes())
        .collect();
    if keys.len() != 1 || !valid_websocket_key(keys[0]) {
        let e = ApiError::new(
            ErrorCode::BadValue,
            "Sec-WebSocket-Key must be one header holding 16 bytes in base64",
        );
        return error_response(StatusCode::BAD_REQUEST, &e);
    }
    let previous = app.clients.fetch_add(1, Ordering::Relaxed);
    let slot = ConnectionSlot(app.clone());
    if previous >= app.net.max_connections {
        let e = ApiError::new(
            ErrorCode::TooManyConnections,
            format!("at most {} WebSocket connections", app.net.max_connections),
        );
        return error_response(StatusCode::SERVICE_UNAVAILABLE, &e);
    }
    if let Some(Extension(connection)) = connection {
        connection.upgraded();
    }
    let hard = app.net.hard_message_bytes;
    ws.max_message_size(hard)
        .max_frame_size(hard)
        .on_upgrade(move |socket| async move {
            let client = slot.0.next_client.fetch_add(1, Ordering::Relaxed);
            Connection::new(slot.0.clone(), socket, client).run().await;
            drop(slot);
        })
}

/// One WebSocket connection.
struct Connection {
    app: Arc<App>,
    socket: WebSocket,
    client: u64,
    bucket: super::limit::TokenBucket,
    subscription: Option<Interval>,
    origin: Instant,
    last_heard: Instant,
    /// Pings sent and not yet answered: (sequence number, when sent).
    pings: VecDeque<(u64, Instant)>,
    next_ping: u64,
    /// The recording's event counts as last told to this client.
    recording: Option<watch::Receiver<RecordEvents>>,
    /// Program events, sent while the client subscribes to telemetry or once it sent a program or response.
    program_events: Option<broadcast::Receiver<Arc<str>>>,
    /// The client sent a program or a response: it gets program events even without a subscription.
    follows_programs: bool,
}

impl Connection {
    fn new(app: Arc<App>, socket: WebSocket, client: u64) -> Self {
        let bucket = super::limit::TokenBucket::new(app.net.requests_per_s, app.net.burst);
        let now = Instant::now();
        let recording = app.record_events.clone();
        let program_events = Some(app.program_events.subscribe());
        Connection {
            app,
            socket,
            client,
            bucket,
            subscription: None,
            origin: now,
            last_heard: now,
            pings: VecDeque::new(),
            next_ping: 0,
            recording,
            program_events,
            follows_programs: false,
        }
    }

    async fn run(mut self) {
        let mut ping = interval(Duration::from_secs_f64(self.app.net.ping_interval_s));
        ping.set_missed_tick_behavior(MissedTickBehavior::Delay);
        loop {
            let open = tokio::select! {
                message = self.socket.recv() => self.on_message(message).await,
                _ = tick(&mut self.subscription) => self.send_telemetry().await,
                _ = ping.tick() => self.ping().await,
                event = changed(&mut self.recording) => self.send_event(event).await,
                event = next_program_event(&mut self.program_events) => self.send_program_event(event).await,
            };
            if !open {
                break;
            }
        }
        let (app, client) = (self.app.clone(), self.client);
        drop(self);
        execute::goodbye(&app, client, None).await;
    }

    /// Handles one received item; false when the connection is over.
    async fn on_message(&mut self, message: Option<Result<Message, axum::Error>>) -> bool {
        let message = match message {
            Some(Ok(message)) => message,
            Some(Err(e)) => {
                if is_invalid_utf8(e) {
                    let frame = CloseFrame {
                        code: CLOSE_INVALID_PAYLOAD,
                        reason: "a text frame must be UTF-8".into(),
                    };
                    let _ = self.send_message(Message::Close(Some(frame))).await;
                }
                return false;
            }
            None => return false,
        };
        self.last_heard = Instant::now();
        match message {
            Message::Text(text) => {
                let reply = self.answer(text.as_str()).await;
                self.send(&reply).await
            }
            Message::Binary(_) => {
                let e = ApiError::new(ErrorCode::BadJson, "binary frames are not supported; send JSON text");
                self.send(&e.reply(None)).await
            }
            Message::Pong(payload) => {
                if let Ok(bytes) = <[u8; 8]>::try_from(payload.as_ref()) {
                    let answered = u64::from_be_bytes(bytes);
                    while self.pings.front().is_some_and(|(seq, _)| *seq <= answered) {
                        self.pings.pop_front();
                    }
                }
                true
            }
            Message::Ping(_) => true,
            Message::Close(_) => false,
        }
    }

    /// The reply to one text message.
    async fn answer(&mut self, text: &str) -> Reply {
        let owner = Owner::Client(self.client);
        let now_s = self.origin.elapsed().as_secs_f64();
        if !self.bucket.take(now_s) {
            return execute::rate_limited(&self.app, text);
        }
        let (id, request) = match execute::parsed(&self.app, text, owner).await {
            Ok(parsed) => parsed,
            Err(reply) => return *reply,
        };
        match request {
            ApiRequest::Subscribe { rate_hz } => {
                let mut every = interval(Duration::from_secs_f64(1.0 / rate_hz));
                every.set_missed_tick_behavior(MissedTickBehavior::Skip);
                self.subscription = Some(every);
                Reply::Ok(OkReply {
                    id,
                    done: Done::Subscribe { rate_hz },
                })
            }
            ApiRequest::Unsubscribe => {
                self.subscription = None;
                Reply::Ok(OkReply {
                    id,
                    done: Done::Unsubscribe {},
                })
            }
            request => {
                if let ApiRequest::Command(Command::Program { .. } | Command::Response { .. }) = &request {
                    self.follows_programs = true;
                }
                execute::execute(&self.app, request, id).await
            }
        }
    }

    async fn send_telemetry(&mut self) -> bool {
        let snapshot = self.app.shared.snapshot();
        self.send(&Reply::Telemetry(protocol::telemetry_message(&snapshot)))
            .await
    }

    /// Closes a connection that sent nothing for the idle timeout, or left a ping unanswered for the send timeout
    /// (it stopped reading); else pings.
    async fn ping(&mut self) -> bool {
        if self.last_heard.elapsed().as_secs_f64() > self.app.net.idle_timeout_s {
            return false;
        }
        let unanswered = self.pings.front().map(|(_, sent)| sent.elapsed().as_secs_f64());
        if unanswered.is_some_and(|s| s > self.app.net.send_timeout_s) {
            return false;
        }
        let seq = self.next_ping;
        self.next_ping += 1;
        self.pings.push_back((seq, Instant::now()));
        self.send_message(Message::Ping(seq.to_be_bytes().to_vec().into()))
            .await
    }

    /// Tells the client the recording failed, or that an operator acknowledged the failure.
    async fn send_event(&mut self, event: Option<RecordingEvent>) -> bool {
        let (Some(event), Some(recording)) = (event, self.app.recording.clone()) else {
            // The recorder is gone (the daemon is stopping): no more events.
            self.recording = None;
            return true;
        };
        let recording = recording_status(&self.app, &recording);
        self.send(&Reply::Event(Event { event, recording })).await
    }

    /// Sends a program event to a telemetry subscriber or a client that sent a program or response (others do not
    /// get them); a client too slow for the events misses the oldest ones.
    async fn send_program_event(&mut self, event: Result<Arc<str>, broadcast::error::RecvError>) -> bool {
        match event {
            Ok(text) if self.subscription.is_some() || self.follows_programs => {
                self.send_message(Message::Text(text.as_ref().into())).await
            }
            Ok(_) | Err(broadcast::error::RecvError::Lagged(_)) => true,
            // The daemon is stopping: no more events, the connection stays until it closes.
            Err(broadcast::error::RecvError::Closed) => {
                self.program_events = None;
                true
            }
        }
    }

    async fn send(&mut self, reply: &Reply) -> bool {
        self.send_message(Message::Text(reply.to_text().into())).await
    }

    async fn send_message(&mut self, message: Message) -> bool {
        let wait = Duration::from_secs_f64(self.app.net.send_timeout_s);
        matches!(timeout(wait, self.socket.send(message)).await, Ok(Ok(())))
    }
}

/// Waits for the subscription's next tick, or forever without one.
async fn tick(subscription: &mut Option<Interval>) {
    match subscription {
        Some(every) => {
            every.tick().await;
        }
        None => std::future::pending().await,
    }
}

/// Waits for the recording's next change: `recording_failed` or `recording_acknowledged`; forever without a
/// recording; `None` once the recorder is gone.
async fn changed(recording: &mut Option<watch::Receiver<RecordEvents>>) -> Option<RecordingEvent> {
    let Some(receiver) = recording else {
        return std::future::pending().await;
    };
    let before = *receiver.borrow_and_update();
    receiver.changed().await.ok()?;
    let after = *receiver.borrow_and_update();
    Some(if after.failures != before.failures {
        RecordingEvent::RecordingFailed
    } else if after.resumptions != before.resumptions {
        RecordingEvent::RecordingResumed
    } else {
        RecordingEvent::RecordingAcknowledged
    })
}

/// The next program event; forever once there are none left to come.
async fn next_program_event(
    events: &mut Option<broadcast::Receiver<Arc<str>>>,
) -> Result<Arc<str>, broadcast::error::RecvError> {
    match events {
        Some(receiver) => receiver.recv().await,
        None => std::future::pending().await,
    }
}

/// Whether a receive error is a text frame that is not UTF-8.
fn is_invalid_utf8(e: axum::Error) -> bool {
    let inner = e.into_inner();
    matches!(
        inner.downcast_ref::<tokio_tungstenite::tungstenite::Error>(),
        Some(tokio_tungstenite::tungstenite::Error::Utf8(_))
    )
}
