//! [`WsLink`]: one channel of a running `thermode serve`, over its WebSocket API (`docs/api.md`), for
//! [`super::live::LiveStimulus`]. Blocking (the runner is sequential): requests are answered in order, telemetry
//! that arrives while a reply is awaited is kept for [`DisplayLink::next_sample`]. A daemon that sends nothing for
//! [`SILENT_LINK_S`] is a lost link: an error, never a hang; the daemon then releases this client's contacts
//! itself (its grace period, `serve --release-after`).

use std::collections::VecDeque;
use std::net::{TcpStream, ToSocketAddrs};
use std::time::Duration;

use serde_json::{json, Value};
use thermode_model::materials::Material;
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

use super::live::{DisplayLink, DisplaySample};
use super::stimulus::StimulusError;

/// Seconds without any message from the daemon after which the link counts as lost \[s\].
pub const SILENT_LINK_S: f64 = 3.0;

/// Telemetry rate asked of the daemon \[Hz\] (at most its loop rate).
pub const TELEMETRY_HZ: f64 = 100.0;

/// One channel of a running daemon.
pub struct WsLink {
    socket: WebSocket<TcpStream>,
    url: String,
    channel: usize,
    next_id: u64,
    pending: VecDeque<DisplaySample>,
    status: Value,
    /// The wall-clock time of the daemon's loop time zero \[s since 1970, UTC\], from the status at connect.
    loop_time_zero_unix_s: f64,
    /// Half the status request's round trip: the uncertainty of that zero \[s\].
    loop_time_zero_uncertainty_s: f64,
}

/// The system's wall clock \[s since 1970, UTC\].
fn unix_now_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

fn device(message: impl Into<String>) -> StimulusError {
    StimulusError::Device(message.into())
}

impl WsLink {
    /// Connects to `url` (`ws://HOST:PORT`, the path defaulting to `/api/ws`) with `token` (if the daemon wants
    /// one), checks that `channel` exists and subscribes to its telemetry.
    pub fn connect(url: &str, token: Option<&str>, channel: usize) -> Result<WsLink, StimulusError> {
        let full = match url.strip_prefix("ws://") {
            Some(rest) if !rest.contains('/') => format!("{url}/api/ws"),
            Some(_) => url.to_string(),
            None => return Err(device(format!("{url}: the display must be a ws://HOST:PORT address"))),
        };
        let mut request = full
            .as_str()
            .into_client_request()
            .map_err(|e| device(format!("{url}: {e}")))?;
        if let Some(token) = token {
            let value = format!("Bearer {token}")
                .parse()
                .map_err(|_| device("the token holds characters a header cannot carry"))?;
            request.headers_mut().insert("Authorization", value);
        }
        let authority = request.uri().authority().map(|a| a.to_string()).unwrap_or_default();
        let address = authority
            .to_socket_addrs()
            .map_err(|e| device(format!("{url}: {e}")))?
            .next()
            .ok_or_else(|| device(format!("{url}: no address")))?;
        let stream = TcpStream::connect_timeout(&address, Duration::from_secs(5))
            .map_err(|e| device(format!("cannot reach the display at {url}: {e}")))?;
        let silence = Some(Duration::from_secs_f64(SILENT_LINK_S));
        stream
            .set_read_timeout(silence)
            .and_then(|()| stream.set_write_timeout(silence))
            .map_err(|e| device(format!("{url}: {e}")))?;
        let (socket, _) = tungstenite::client(request, stream).map_err(|e| {
            device(format!(
                "{url}: the WebSocket handshake failed: {e} (a daemon with --token needs --token)"
            ))
        })?;
        let mut link = WsLink {
            socket,
            url: url.to_string(),
            channel,
            next_id: 0,
            pending: VecDeque::new(),
            status: Value::Null,
            loop_time_zero_unix_s: f64::NAN,
            loop_time_zero_uncertainty_s: f64::NAN,
        };
        let sent_unix_s = unix_now_s();
        link.status = link.request(json!({"type": "status"}))?;
        let received_unix_s = unix_now_s();
        if let Some(loop_s) = link.status["time_s"].as_f64() {
            link.loop_time_zero_unix_s = 0.5 * (sent_unix_s + received_unix_s) - loop_s;
            link.loop_time_zero_uncertainty_s = 0.5 * (received_unix_s - sent_unix_s);
        }
        let count = link.status["channel_count"].as_u64().unwrap_or(0) as usize;
        if channel >= count {
            return Err(device(format!(
                "{url} has {count} channel(s); channel {channel} does not exist"
            )));
        }
        let rate_hz = link.status["loop"]["rate_hz"]
            .as_f64()
            .unwrap_or(TELEMETRY_HZ)
            .min(TELEMETRY_HZ);
        link.request(json!({"type": "subscribe", "rate_hz": rate_hz}))?;
        Ok(link)
    }

    /// The daemon's status at connect (`GET /api/status`).
    pub fn status(&self) -> &Value {
        &self.status
    }

    /// The next message as JSON; a silent or closed link is an error.
    fn read(&mut self) -> Result<Value, StimulusError> {
        loop {
            let message = self.socket.read().map_err(|e| {
                device(match e {
                    tungstenite::Error::Io(io)
                        if matches!(io.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) =>
                    {
                        format!(
                            "the display at {} sent nothing for {SILENT_LINK_S} s: the link is lost",
                            self.url
                        )
                    }
                    other => format!("the link to the display at {} failed: {other}", self.url),
                })
            })?;
            if let Message::Text(text) = message {
                return serde_json::from_str(text.as_str())
                    .map_err(|e| device(format!("the display sent a malformed message: {e}")));
            }
        }
    }

    /// Sends `body` with a fresh id and waits for its reply (keeping telemetry that arrives meanwhile).
    fn request(&mut self, mut body: Value) -> Result<Value, StimulusError> {
        self.next_id += 1;
        let id = self.next_id;
        body["id"] = json!(id);
        self.socket
            .send(Message::text(body.to_string()))
            .map_err(|e| device(format!("the link to the display at {} failed: {e}", self.url)))?;
        loop {
            let message = self.read()?;
            if message["type"] == "telemetry" {
                if let Some(sample) = self.sample_of(&message) {
                    self.pending.push_back(sample);
                }
                continue;
            }
            if message["id"] != json!(id) {
                continue;
            }
            if message["type"] == "error" {
                return Err(device(format!(
                    "the display refused `{}`: {} ({})",
                    body["type"].as_str().unwrap_or("?"),
                    message["message"].as_str().unwrap_or(""),
                    message["code"].as_str().unwrap_or("?")
                )));
            }
            return Ok(message);
        }
    }

    /// This channel's sample in a telemetry message.
    fn sample_of(&self, telemetry: &Value) -> Option<DisplaySample> {
        let channel = telemetry["channels"]
            .as_array()?
            .iter()
            .find(|c| c["channel"].as_u64() == Some(self.channel as u64))?;
        let number = |key: &str| channel[key].as_f64().unwrap_or(f64::NAN);
        Some(DisplaySample {
            loop_time_s: telemetry["time_s"].as_f64()?,
            target_skin_c: number("target_skin_c"),
            skin_c: number("skin_c"),
            finger_c: number("finger_c"),
            sensor_c: number("sensor_c"),
            display_setpoint_c: number("display_setpoint_c"),
            current_a: number("current_a"),
            fault: channel["fault"].as_u64().unwrap_or(0).min(u16::MAX as u64) as u16,
            contact: channel["contact"].as_bool().unwrap_or(false),
        })
    }

    /// The loop time of a reply \[s\].
    fn time_of(reply: &Value) -> Result<f64, StimulusError> {
        reply["time_s"]
            .as_f64()
            .ok_or_else(|| device("the display's reply has no loop time"))
    }
}

impl DisplayLink for WsLink {
    fn touch(&mut self, material: &Material) -> Result<f64, StimulusError> {
        let reply = self.request(json!({"type": "touch", "channel": self.channel, "material": material.name}))?;
        Self::time_of(&reply)
    }

    fn release(&mut self) -> Result<f64, StimulusError> {
        let reply = self.request(json!({"type": "release", "channel": self.channel}))?;
        Self::time_of(&reply)
    }

    fn marker(&mut self, text: &str) -> Result<Option<f64>, StimulusError> {
        let reply = self.request(json!({"type": "marker", "text": text, "channel": self.channel}))?;
        Ok(reply["lsl_time_s"]
            .as_f64()
            .zip(reply["time_s"].as_f64())
            .map(|(lsl_s, loop_s)| lsl_s - loop_s))
    }

    fn next_sample(&mut self) -> Result<DisplaySample, StimulusError> {
        loop {
            if let Some(sample) = self.pending.pop_front() {
                return Ok(sample);
            }
            let message = self.read()?;
            if message["type"] == "telemetry" {
                if let Some(sample) = self.sample_of(&message) {
                    return Ok(sample);
                }
            }
        }
    }

    fn describe(&self) -> Value {
        json!({
            "url": self.url,
            "channel": self.channel,
            "daemon_version": self.status["version"],
            "device": self.status["device"],
            "loop_rate_hz": self.status["loop"]["rate_hz"],
            "limits": self.status["limits"],
            "loop_time_zero_utc": thermode_platform::utc_iso8601_ms(self.loop_time_zero_unix_s),
            "loop_time_zero_unix_s": self.loop_time_zero_unix_s,
            "loop_time_zero_uncertainty_s": self.loop_time_zero_uncertainty_s,
            "alignment": "unix_time_s = loop_time_zero_unix_s + loop_time_s (the trial curves' column)",
        })
    }
}

impl Drop for WsLink {
    /// Releases the channel and closes the connection (best effort: the daemon releases a gone client's contacts
    /// after its grace period anyway).
    fn drop(&mut self) {
        let release = json!({"type": "release", "id": 0, "channel": self.channel});
        let _ = self.socket.send(Message::text(release.to_string()));
        let _ = self.socket.close(None);
        let _ = self.socket.flush();
    }
}
