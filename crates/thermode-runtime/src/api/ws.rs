//! The WebSocket endpoint `/api/ws`: one task per connection that reads requests, answers each with the same
//! `id`, streams telemetry to subscribers, pings, and on disconnect tells the loop, which releases the client's
//! contacts after the grace period.
//!
//! Limits: messages above the soft size limit get `too_large`; frames above the hard limit close the connection;
//! each connection has a token-bucket rate limit (`rate_limited`); a client that sends nothing for the idle timeout
//! or does not take our messages within the send timeout is disconnected.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::Response;
use serde_json::{json, Value};
use tokio::time::{interval, timeout, Instant, Interval, MissedTickBehavior};

use super::protocol::{self, ApiError, ApiRequest, ErrorCode};
use super::{error_response, status_json, App};
use crate::command::{Command, CommandError, Owner};

/// Counts a connection for as long as it lives.
struct ConnectionSlot(Arc<App>);

impl Drop for ConnectionSlot {
    fn drop(&mut self) {
        self.0.clients.fetch_sub(1, Ordering::Relaxed);
    }
}

/// `GET /api/ws`: upgrades, unless the connection limit is reached.
pub async fn upgrade(State(app): State<Arc<App>>, ws: WebSocketUpgrade) -> Response {
    let previous = app.clients.fetch_add(1, Ordering::Relaxed);
    let slot = ConnectionSlot(app.clone());
    if previous >= app.net.max_connections {
        let e = ApiError::new(
            ErrorCode::TooManyConnections,
            format!("at most {} WebSocket connections", app.net.max_connections),
        );
        return error_response(StatusCode::SERVICE_UNAVAILABLE, &e);
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
}

impl Connection {
    fn new(app: Arc<App>, socket: WebSocket, client: u64) -> Self {
        let bucket = super::limit::TokenBucket::new(app.net.requests_per_s, app.net.burst);
        let now = Instant::now();
        Connection {
            app,
            socket,
            client,
            bucket,
            subscription: None,
            origin: now,
            last_heard: now,
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
            };
            if !open {
                break;
            }
        }
        let (app, client) = (self.app.clone(), self.client);
        drop(self);
        goodbye(&app, client).await;
    }

    /// Handles one received item; false when the connection is over.
    async fn on_message(&mut self, message: Option<Result<Message, axum::Error>>) -> bool {
        let Some(Ok(message)) = message else {
            return false;
        };
        self.last_heard = Instant::now();
        match message {
            Message::Text(text) => {
                let reply = self.answer(text.as_str()).await;
                self.send(reply).await
            }
            Message::Binary(_) => {
                let e = ApiError::new(ErrorCode::BadJson, "binary frames are not supported; send JSON text");
                self.send(e.to_json(&Value::Null)).await
            }
            Message::Ping(_) | Message::Pong(_) => true,
            Message::Close(_) => false,
        }
    }

    /// The reply to one text message.
    async fn answer(&mut self, text: &str) -> Value {
        let owner = Owner::Client(self.client);
        let now_s = self.origin.elapsed().as_secs_f64();
        if !self.bucket.take(now_s) {
            let (id, _) = protocol::parse(text, &self.app.limits, owner);
            let message = format!(
                "more than {} requests per second (burst {}); slow down",
                self.app.net.requests_per_s, self.app.net.burst
            );
            return ApiError::new(ErrorCode::RateLimited, message).to_json(&id);
        }
        let (id, request) = protocol::parse(text, &self.app.limits, owner);
        match request {
            Ok(request) => self.execute(request, &id).await.unwrap_or_else(|e| e.to_json(&id)),
            Err(e) => e.to_json(&id),
        }
    }

    async fn execute(&mut self, request: ApiRequest, id: &Value) -> Result<Value, ApiError> {
        match request {
            ApiRequest::Command(command) => to_loop(&self.app, command, id).await,
            ApiRequest::Subscribe { rate_hz } => {
                let mut every = interval(Duration::from_secs_f64(1.0 / rate_hz));
                every.set_missed_tick_behavior(MissedTickBehavior::Skip);
                self.subscription = Some(every);
                Ok(protocol::ok_reply(id, "subscribe", json!({"rate_hz": rate_hz})))
            }
            ApiRequest::Unsubscribe => {
                self.subscription = None;
                Ok(protocol::ok_reply(id, "unsubscribe", json!({})))
            }
            ApiRequest::Status => {
                let mut status = status_json(&self.app);
                if let Value::Object(map) = &mut status {
                    map.insert("type".into(), json!("status"));
                    map.insert("id".into(), id.clone());
                }
                Ok(status)
            }
        }
    }

    async fn send_telemetry(&mut self) -> bool {
        let snapshot = self.app.shared.snapshot();
        self.send(protocol::telemetry_message(&snapshot)).await
    }

    async fn ping(&mut self) -> bool {
        if self.last_heard.elapsed().as_secs_f64() > self.app.net.idle_timeout_s {
            return false;
        }
        self.send_message(Message::Ping(Vec::new().into())).await
    }

    async fn send(&mut self, value: Value) -> bool {
        self.send_message(Message::Text(value.to_string().into())).await
    }

    async fn send_message(&mut self, message: Message) -> bool {
        let wait = Duration::from_secs_f64(self.app.net.send_timeout_s);
        matches!(timeout(wait, self.socket.send(message)).await, Ok(Ok(())))
    }
}

/// Tells the loop a client is gone (retrying while the queue is full: its contacts must be released).
async fn goodbye(app: &App, client: u64) {
    for _ in 0..1000 {
        match app.commands.send(Command::ClientGone { client }) {
            Err(CommandError::Busy) => tokio::time::sleep(Duration::from_millis(5)).await,
            _ => return,
        }
    }
}

/// Sends `command` to the loop and waits (bounded) for its answer.
async fn to_loop(app: &App, command: Command, id: &Value) -> Result<Value, ApiError> {
    let (name, extra) = (command.name(), protocol::command_reply_fields(&command));
    let answer = app.commands.request(command).map_err(loop_error)?;
    let wait = Duration::from_secs_f64(app.net.reply_timeout_s);
    let applied = match timeout(wait, answer).await {
        Ok(Ok(reply)) => reply.map_err(loop_error)?,
        Ok(Err(_)) => return Err(loop_error(CommandError::Stopped)),
        Err(_) => {
            return Err(ApiError::new(
                ErrorCode::Busy,
                "the control loop did not answer in time; the command may still be applied",
            ))
        }
    };
    let mut reply = protocol::ok_reply(id, name, extra);
    if let Value::Object(map) = &mut reply {
        map.insert("tick".into(), json!(applied.tick));
        map.insert("time_s".into(), json!(applied.time_s));
    }
    Ok(reply)
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

/// The API error for a loop refusal.
fn loop_error(e: CommandError) -> ApiError {
    let code = match &e {
        CommandError::UnknownChannel { .. } => ErrorCode::UnknownChannel,
        CommandError::Faulted { .. } | CommandError::FaultPersists { .. } => ErrorCode::DeviceFault,
        CommandError::Rejected { .. } => ErrorCode::BadValue,
        CommandError::Busy | CommandError::Stopped => ErrorCode::Busy,
    };
    ApiError::new(code, e.to_string())
}
