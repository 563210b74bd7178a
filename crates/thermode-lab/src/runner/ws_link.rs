//! [`WsLink`]: one channel of a running `thermode serve`, over its WebSocket API (`docs/api.md`), for
//! [`super::live::LiveStimulus`]. Blocking (the runner is sequential): requests are answered in order, telemetry
//! that arrives while a reply is awaited is kept for [`DisplayLink::next_sample`]. A daemon that sends nothing for
//! longer than the link's [`SilenceLimit`] is a lost link: an error, never a hang; the daemon then releases this
//! client's contacts itself (its grace period, `serve --release-after`). The limit is sized from the silences
//! measured on the link (a loaded machine pauses; a 3 s limit once lost a session to a pause of about 3 s): four
//! times the longest so far, at least [`MIN_SILENT_LINK_S`] (beyond the daemon's own keep-alive window: a ping every
//! second, a client closed after 5 s without an answer) and at most [`MAX_SILENT_LINK_S`].

use std::collections::VecDeque;
use std::net::{TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

use serde_json::{json, Value};
use thermode_model::materials::Material;
use thermode_protocol::request::{Marker, NoFields, OnChannel, Subscribe};
use thermode_protocol::status::Status;
use thermode_protocol::{Done, Request, Response, Telemetry};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

use super::live::{DisplayLink, DisplaySample};
use super::stimulus::StimulusError;

/// Shortest silence of the daemon that counts as a lost link \[s\]: 10 (its keep-alive window is 1 s of ping
/// interval plus 5 s of send timeout; a two-core machine under load was seen to pause for about 3 s).
pub const MIN_SILENT_LINK_S: f64 = 10.0;
/// Longest silence limit \[s\]: 60 (a link that was once that silent still counts as lost after a minute).
pub const MAX_SILENT_LINK_S: f64 = 60.0;
/// The silence limit is this many times the longest silence measured on the link: 4.
pub const SILENCE_FACTOR: f64 = 4.0;

/// How long the daemon may stay silent before the link counts as lost, sized from the silences measured on the
/// link: [`SILENCE_FACTOR`] times the longest so far, within [`MIN_SILENT_LINK_S`] and [`MAX_SILENT_LINK_S`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SilenceLimit {
    longest_s: f64,
}

impl SilenceLimit {
    /// The limit now \[s\].
    pub fn limit_s(&self) -> f64 {
        (SILENCE_FACTOR * self.longest_s).clamp(MIN_SILENT_LINK_S, MAX_SILENT_LINK_S)
    }

    /// The longest silence measured so far \[s\].
    pub fn longest_s(&self) -> f64 {
        self.longest_s
    }

    /// Records a wait of `silent_s` \[s\] for the daemon's next message (a non-finite or negative wait is ignored).
    pub fn measured(&mut self, silent_s: f64) {
        if silent_s.is_finite() && silent_s > self.longest_s {
            self.longest_s = silent_s;
        }
    }
}

/// Telemetry rate asked of the daemon \[Hz\] (at most its loop rate).
pub const TELEMETRY_HZ: f64 = 100.0;

/// One channel of a running daemon.
pub struct WsLink {
    socket: WebSocket<TcpStream>,
    url: String,
    channel: usize,
    next_id: u64,
    pending: VecDeque<DisplaySample>,
    /// Telemetry and program events that arrived while a reply was awaited, kept for a procedure's
    /// [`WsLink::next_message`] once [`WsLink::keep_messages`] was called.
    messages: Option<VecDeque<Response>>,
    status: Option<Status>,
    /// The wall-clock time of the daemon's loop time zero \[s since 1970, UTC\], from the status at connect.
    loop_time_zero_unix_s: f64,
    /// Half the status request's round trip: the uncertainty of that zero \[s\].
    loop_time_zero_uncertainty_s: f64,
    /// The silences measured on the link and the limit they give.
    silence: SilenceLimit,
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
        let silence = Some(Duration::from_secs_f64(SilenceLimit::default().limit_s()));
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
            messages: None,
            status: None,
            loop_time_zero_unix_s: f64::NAN,
            loop_time_zero_uncertainty_s: f64::NAN,
            silence: SilenceLimit::default(),
        };
        let sent_unix_s = unix_now_s();
        let Response::Status(reply) = link.request(Request::Status(NoFields {}))? else {
            return Err(device(format!("{url} answered `status` with another message")));
        };
        let status = reply.status;
        let received_unix_s = unix_now_s();
        link.loop_time_zero_unix_s = 0.5 * (sent_unix_s + received_unix_s) - status.time_s;
        link.loop_time_zero_uncertainty_s = 0.5 * (received_unix_s - sent_unix_s);
        let count = status.channel_count;
        if channel >= count {
            return Err(device(format!(
                "{url} has {count} channel(s); channel {channel} does not exist"
            )));
        }
        let rate_hz = status.loop_stats.rate_hz.min(TELEMETRY_HZ);
        link.status = Some(status);
        link.request(Request::Subscribe(Subscribe { rate_hz }))?;
        Ok(link)
    }

    /// The daemon's status at connect (`GET /api/status`).
    pub fn status(&self) -> Option<&Status> {
        self.status.as_ref()
    }

    /// The next message the daemon sends (one this runner does not know, from a newer daemon, is passed over); a
    /// silent or closed link is an error.
    fn read(&mut self) -> Result<Response, StimulusError> {
        loop {
            let limit_s = self.silence.limit_s();
            // The timeout of the stream under the WebSocket: the current limit (it only grows).
            let _ = self
                .socket
                .get_ref()
                .set_read_timeout(Some(Duration::from_secs_f64(limit_s)));
            let waited = Instant::now();
            let message = self.socket.read().map_err(|e| {
                device(match e {
                    tungstenite::Error::Io(io)
                        if matches!(io.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) =>
                    {
                        format!(
                            "the display at {} sent nothing for {limit_s:.0} s (the longest silence before: {:.2} s): \
                             the link is lost",
                            self.url,
                            self.silence.longest_s()
                        )
                    }
                    other => format!("the link to the display at {} failed: {other}", self.url),
                })
            })?;
            self.silence.measured(waited.elapsed().as_secs_f64());
            let Message::Text(text) = message else { continue };
            let value: Value = serde_json::from_str(text.as_str())
                .map_err(|e| device(format!("the display sent a malformed message: {e}")))?;
            let known = ["ok", "error", "status", "telemetry", "event", "program_event"];
            if !known.iter().any(|kind| value["type"] == *kind) {
                continue;
            }
            return serde_json::from_value(value)
                .map_err(|e| device(format!("the display sent a malformed message: {e}")));
        }
    }

    /// Sends `request` with a fresh id and waits for its reply (keeping telemetry that arrives meanwhile).
    fn request(&mut self, request: Request) -> Result<Response, StimulusError> {
        self.next_id += 1;
        let kind = request.kind();
        let id = thermode_protocol::RequestId::from(self.next_id);
        let text = request.with_id(id.clone()).to_text();
        self.socket
            .send(Message::text(text))
            .map_err(|e| device(format!("the link to the display at {} failed: {e}", self.url)))?;
        loop {
            let reply = match self.read()? {
                Response::Telemetry(telemetry) => {
                    self.pending.extend(self.sample_of(&telemetry));
                    if let Some(messages) = self.messages.as_mut() {
                        messages.push_back(Response::Telemetry(telemetry));
                    }
                    continue;
                }
                Response::ProgramEvent(event) => {
                    if let Some(messages) = self.messages.as_mut() {
                        messages.push_back(Response::ProgramEvent(event));
                    }
                    continue;
                }
                Response::Event(_) => continue,
                reply => reply,
            };
            let reply_id = match &reply {
                Response::Ok(ok) => Some(&ok.id),
                Response::Status(status) => Some(&status.id),
                Response::Error(error) => error.id.as_ref(),
                Response::Telemetry(_) | Response::Event(_) | Response::ProgramEvent(_) => None,
            };
            if reply_id != Some(&id) {
                continue;
            }
            if let Response::Error(error) = reply {
                return Err(device(format!(
                    "the display refused `{kind}`: {} ({})",
                    error.message,
                    error.code.as_str()
                )));
            }
            return Ok(reply);
        }
    }

    /// From now on, telemetry and program events are kept for [`WsLink::next_message`] (a procedure's program
    /// display), and the single-channel samples are no longer queued.
    pub(crate) fn keep_messages(&mut self) {
        self.messages.get_or_insert_with(VecDeque::new);
        self.pending.clear();
    }

    /// The next telemetry or program event (kept ones first; see [`WsLink::keep_messages`]).
    pub(crate) fn next_message(&mut self) -> Result<Response, StimulusError> {
        loop {
            if let Some(message) = self.messages.as_mut().and_then(VecDeque::pop_front) {
                self.pending.clear();
                return Ok(message);
            }
            match self.read()? {
                message @ (Response::Telemetry(_) | Response::ProgramEvent(_)) => return Ok(message),
                _ => continue,
            }
        }
    }

    /// The daemon's channel count (from its status at connect).
    pub(crate) fn channel_count(&self) -> usize {
        self.status.as_ref().map_or(0, |s| s.channel_count)
    }

    /// What a request did (an `ok` reply), or an error for any other answer.
    pub(crate) fn done(&mut self, request: Request) -> Result<Done, StimulusError> {
        match self.request(request)? {
            Response::Ok(ok) => Ok(ok.done),
            _ => Err(device("the display answered with a message that is not an `ok`")),
        }
    }

    /// This channel's sample in a telemetry message.
    fn sample_of(&self, telemetry: &Telemetry) -> Option<DisplaySample> {
        let channel = telemetry.channels.iter().find(|c| c.channel == self.channel)?;
        let number = |value: Option<f64>| value.unwrap_or(f64::NAN);
        Some(DisplaySample {
            loop_time_s: telemetry.time_s,
            target_skin_c: number(channel.target_skin_c),
            skin_c: number(channel.skin_c),
            finger_c: number(channel.finger_c),
            sensor_c: number(channel.sensor_c),
            display_setpoint_c: number(channel.display_setpoint_c),
            current_a: number(channel.current_a),
            fault: channel.fault,
            contact: channel.contact,
        })
    }

    /// The loop time at which a command was applied \[s\].
    fn applied_time_s(done: Done) -> Result<f64, StimulusError> {
        match done {
            Done::Touch { applied, .. } | Done::Release { applied, .. } => Ok(applied.time_s),
            _ => Err(device("the display's reply has no loop time")),
        }
    }
}

impl DisplayLink for WsLink {
    fn touch(&mut self, material: &Material) -> Result<f64, StimulusError> {
        let done = self.done(Request::touch(self.channel, &material.name))?;
        Self::applied_time_s(done)
    }

    fn release(&mut self) -> Result<f64, StimulusError> {
        let done = self.done(Request::Release(OnChannel {
            channel: self.channel as i64,
        }))?;
        Self::applied_time_s(done)
    }

    fn marker(&mut self, text: &str) -> Result<Option<f64>, StimulusError> {
        let marker = Request::Marker(Marker {
            text: text.to_string(),
            channel: Some(self.channel as i64),
        });
        match self.done(marker)? {
            Done::Marker { time_s, lsl_time_s, .. } => Ok(lsl_time_s.map(|lsl_s| lsl_s - time_s)),
            _ => Err(device("the display answered `marker` with another reply")),
        }
    }

    fn next_sample(&mut self) -> Result<DisplaySample, StimulusError> {
        loop {
            if let Some(sample) = self.pending.pop_front() {
                return Ok(sample);
            }
            if let Response::Telemetry(telemetry) = self.read()? {
                if let Some(sample) = self.sample_of(&telemetry) {
                    return Ok(sample);
                }
            }
        }
    }

    fn describe(&self) -> Value {
        let status = self.status.as_ref();
        json!({
            "url": self.url,
            "channel": self.channel,
            "daemon_version": status.map(|s| &s.version),
            "device": status.map(|s| &s.device),
            "loop_rate_hz": status.map(|s| s.loop_stats.rate_hz),
            "limits": status.map(|s| &s.limits),
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
        let release = Request::Release(OnChannel {
            channel: self.channel as i64,
        });
        let _ = self.socket.send(Message::text(release.with_id(0).to_text()));
        let _ = self.socket.close(None);
        let _ = self.socket.flush();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_silence_limit_grows_with_the_silences_measured_within_its_bounds() {
        let mut silence = SilenceLimit::default();
        assert_eq!(silence.limit_s(), MIN_SILENT_LINK_S, "before any measurement");
        // Telemetry every 10 ms, then a loaded machine's pause of 3.2 s (which a 3 s limit called a lost link).
        for waited_s in [0.01, 0.012, 3.2, 0.01] {
            silence.measured(waited_s);
        }
        assert_eq!(silence.longest_s(), 3.2);
        assert!(
            (silence.limit_s() - 4.0 * 3.2).abs() < 1e-12,
            "limit {}",
            silence.limit_s()
        );
        silence.measured(f64::NAN);
        silence.measured(40.0);
        assert_eq!(silence.limit_s(), MAX_SILENT_LINK_S, "bounded above");
    }
}
