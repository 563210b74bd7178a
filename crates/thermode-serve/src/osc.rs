//! OSC over UDP, for game engines (Unity, Unreal) and audio-visual tools: a small decoder of OSC 1.0 packets
//! (messages and bundles; argument types `s i f d h T F N`) and the listener that maps addresses to commands.
//!
//! Addresses (channels from 0):
//! - `/thermode/channel/<i>/touch s [f]` — touch the named material, optionally at an object temperature \[°C\];
//! - `/thermode/channel/<i>/setpoint f f` — direct mode: temperature \[°C\] and rate \[°C/s\];
//! - `/thermode/channel/<i>/release` — release (arguments ignored, so a button's `1.0` works);
//! - `/thermode/program s` — a stimulus program: the string is the `program` request's `channels` object as JSON
//!   (`{"0": [{"to_c": 25, "rate_c_s": 1, "until": "response"}, {"to_c": 32, "rate_c_s": 1}]}`; the whole packet
//!   at most [`MAX_PACKET_BYTES`], so longer programs go over the WebSocket);
//! - `/thermode/channel/<i>/response` — a participant's button response (arguments ignored, so a button's `1.0`
//!   works); `/thermode/channel/<i>/rating f` — a rating, 0 to 100;
//! - `/thermode/channel/<i>/program_stop` — end the channel's program, holding its set-point;
//! - `/thermode/stop` (or `/thermode/stop_all`) — stop all, on a path no budget can starve: it is queued on the loop's
//!   urgent lane before the rate limit is consulted, so a flood of other datagrams (a thousand a second, a
//!   subscription pointed at the daemon itself) cannot drop it;
//! - `/thermode/all/<action>` or `/thermode/channel/*/<action>` — `touch`, `setpoint` or `release` on every channel
//!   (validated for every channel before any is queued);
//! - `/thermode/subscribe f [i]` — telemetry at that rate \[Hz\] and fault events, to the sender or to the given
//!   port on its host, until `/thermode/unsubscribe [i]` or [`SUBSCRIPTION_TTL_S`] without a renewal; at most
//!   [`MAX_SUBSCRIBERS`], from loopback only. Sent by a task of the network runtime from the published snapshot,
//!   never by the loop: `/thermode/channel/<i>/telemetry f f f f f i` (target skin, skin, sensor, plate estimate
//!   \[°C\], current \[A\], fault code) and `/thermode/channel/<i>/fault i s` (code and description; 0 `cleared`).
//!   Refused (answered `/thermode/error s s` to the sender, counted as `subscriptions_refused`): the daemon's own
//!   ports (its OSC and HTTP ports, on any loopback address: a daemon flooding itself spent the OSC budget and
//!   dropped commands), and a port another address already subscribed (unless the request comes from that very
//!   port). Each subscriber gets at most `NetLimits::osc_subscriber_bytes_per_s`: a faster subscription is lowered
//!   to fit (the acknowledgement `/thermode/subscribed f f` says the rate granted and the time to live), and what
//!   would exceed the budget is not sent (counted as `throttled`).
//!
//! Same validation as the WebSocket API: a touch or set-point becomes the same [`Command`] through the same
//! [`protocol::stimulus_command`], so both refuse the same stimuli with the same message. OSC commands have no
//! replies (only a subscription is answered) and no authentication: malformed datagrams are ignored and counted;
//! every message is counted once the control loop has answered it, as applied or as refused (a refusal by the
//! validation, a full queue, or the loop itself: a faulted channel, a failed recording); the last reason is in
//! `/api/status`. OSC listens only on loopback, and when the daemon has a token not at all unless asked to
//! (`--osc-without-token`).

use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::net::UdpSocket;
use tokio::time::Instant;

use crate::api::limit::TokenBucket;
use crate::api::protocol::{self, ApiError, ErrorCode};
use crate::api::{App, OscCounters};
use thermode_protocol::program::{ProgramRequest, ResponseInput};
use thermode_protocol::ResponseKind;
use thermode_runtime::command::{Command, Owner};
use thermode_runtime::engine::Stimulus;
use thermode_runtime::snapshot::ChannelStatus;

/// Largest datagram read \[bytes\]; longer ones are truncated and so malformed.
pub const MAX_PACKET_BYTES: usize = 8192;
/// Deepest nesting of bundles accepted.
const MAX_BUNDLE_DEPTH: usize = 4;
/// Most messages taken from one datagram.
const MAX_MESSAGES_PER_PACKET: usize = 64;

/// One OSC argument.
#[derive(Debug, Clone, PartialEq)]
pub enum OscArg {
    /// `s` string (also `S` symbol).
    Str(String),
    /// `i` 32-bit integer.
    Int(i32),
    /// `h` 64-bit integer.
    Long(i64),
    /// `f` 32-bit float.
    Float(f32),
    /// `d` 64-bit float.
    Double(f64),
    /// `T`/`F` booleans and `N` nil.
    Other,
}

impl OscArg {
    /// The argument as a number, if it is one.
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            OscArg::Int(v) => Some(f64::from(v)),
            OscArg::Long(v) => Some(v as f64),
            OscArg::Float(v) => Some(f64::from(v)),
            OscArg::Double(v) => Some(v),
            OscArg::Str(_) | OscArg::Other => None,
        }
    }
}

/// One OSC message.
#[derive(Debug, Clone, PartialEq)]
pub struct OscMessage {
    /// The address pattern, e.g. `/thermode/stop`.
    pub address: String,
    /// The arguments.
    pub args: Vec<OscArg>,
}

/// Why a datagram is not OSC.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Malformed(pub &'static str);

/// Decodes a datagram into its messages (bundles flattened, time tags ignored: messages act at once).
pub fn decode(packet: &[u8]) -> Result<Vec<OscMessage>, Malformed> {
    let mut out = Vec::new();
    decode_into(packet, 0, &mut out)?;
    Ok(out)
}

fn decode_into(packet: &[u8], depth: usize, out: &mut Vec<OscMessage>) -> Result<(), Malformed> {
    if packet.starts_with(b"#bundle\0") {
        if depth >= MAX_BUNDLE_DEPTH {
            return Err(Malformed("bundles nested too deeply"));
        }
        let mut rest = packet.get(16..).ok_or(Malformed("bundle shorter than its header"))?;
        while !rest.is_empty() {
            let size = read_i32(&mut rest)?;
            let size = usize::try_from(size).map_err(|_| Malformed("negative bundle element size"))?;
            if size % 4 != 0 || size > rest.len() {
                return Err(Malformed("bad bundle element size"));
            }
            let (element, tail) = rest.split_at(size);
            decode_into(element, depth + 1, out)?;
            rest = tail;
        }
        return Ok(());
    }
    if out.len() >= MAX_MESSAGES_PER_PACKET {
        return Err(Malformed("too many messages in one datagram"));
    }
    out.push(decode_message(packet)?);
    Ok(())
}

fn decode_message(packet: &[u8]) -> Result<OscMessage, Malformed> {
    let mut rest = packet;
    let address = read_string(&mut rest)?;
    if !address.starts_with('/') {
        return Err(Malformed("address must start with '/'"));
    }
    if rest.is_empty() {
        return Ok(OscMessage { address, args: vec![] });
    }
    let tags = read_string(&mut rest)?;
    let tags = tags
        .strip_prefix(',')
        .ok_or(Malformed("type tags must start with ','"))?;
    let mut args = Vec::with_capacity(tags.len());
    for tag in tags.chars() {
        args.push(match tag {
            's' | 'S' => OscArg::Str(read_string(&mut rest)?),
            'i' => OscArg::Int(read_i32(&mut rest)?),
            'f' => OscArg::Float(f32::from_bits(read_i32(&mut rest)? as u32)),
            'h' => OscArg::Long(i64::from_be_bytes(take::<8>(&mut rest)?)),
            'd' => OscArg::Double(f64::from_be_bytes(take::<8>(&mut rest)?)),
            'T' | 'F' | 'N' | 'I' => OscArg::Other,
            _ => return Err(Malformed("unsupported argument type")),
        });
    }
    if !rest.is_empty() {
        return Err(Malformed("bytes after the last argument"));
    }
    Ok(OscMessage { address, args })
}

fn take<const N: usize>(rest: &mut &[u8]) -> Result<[u8; N], Malformed> {
    let (head, tail) = rest
        .split_at_checked(N)
        .ok_or(Malformed("packet ends inside an argument"))?;
    *rest = tail;
    head.try_into().map_err(|_| Malformed("packet ends inside an argument"))
}

fn read_i32(rest: &mut &[u8]) -> Result<i32, Malformed> {
    Ok(i32::from_be_bytes(take::<4>(rest)?))
}

/// A NUL-terminated string padded to a multiple of 4 bytes.
fn read_string(rest: &mut &[u8]) -> Result<String, Malformed> {
    let end = rest
        .iter()
        .position(|&b| b == 0)
        .ok_or(Malformed("unterminated string"))?;
    let padded = (end / 4 + 1) * 4;
    if padded > rest.len() {
        return Err(Malformed("string padding runs past the packet"));
    }
    let text = std::str::from_utf8(&rest[..end]).map_err(|_| Malformed("string is not UTF-8"))?;
    let text = text.to_string();
    *rest = &rest[padded..];
    Ok(text)
}

/// What an OSC message asks for: one command, or one per channel for the all-channels addresses
/// (`/thermode/channel/*/…` and `/thermode/all/…`).
fn to_commands(message: &OscMessage, app: &App) -> Result<Vec<Command>, ApiError> {
    let parts: Vec<&str> = message.address.split('/').collect();
    let every_channel = |action: &str| {
        (0..app.limits.channel_count)
            .map(|channel| channel_command(channel, action, &message.args, app))
            .collect::<Result<Vec<_>, _>>()
    };
    match parts.as_slice() {
        ["", "thermode", "stop" | "stop_all"] => Ok(vec![Command::StopAll]),
        ["", "thermode", "program"] => Ok(vec![program_command(&message.args, app)?]),
        ["", "thermode", "all", action] | ["", "thermode", "channel", "*", action] => every_channel(action),
        ["", "thermode", "channel", index, action] => {
            let index: i64 = index
                .parse()
                .map_err(|_| ApiError::new(ErrorCode::UnknownChannel, format!("channel {index:?} is not a number")))?;
            let channel = protocol::channel_index(index, app.limits.channel_count)?;
            Ok(vec![channel_command(channel, action, &message.args, app)?])
        }
        _ => Err(ApiError::new(
            ErrorCode::UnknownType,
            format!("unknown OSC address {:?}", message.address),
        )),
    }
}

fn channel_command(channel: usize, action: &str, args: &[OscArg], app: &App) -> Result<Command, ApiError> {
    let number = |i: usize, what: &str| {
        args.get(i)
            .and_then(OscArg::as_f64)
            .ok_or_else(|| ApiError::new(ErrorCode::BadValue, format!("argument {i} ({what}) must be a number")))
    };
    match action {
        "touch" => {
            let Some(OscArg::Str(name)) = args.first() else {
                return Err(ApiError::new(
                    ErrorCode::MissingField,
                    "touch needs the material name (s)",
                ));
            };
            let material = protocol::material_by_name(name)?;
            let object_c = match args.get(1) {
                None => app.limits.default_object_c,
                Some(_) => number(1, "object temperature")?,
            };
            protocol::stimulus_command(channel, Stimulus::Touch { material, object_c }, Owner::Osc, &app.limits)
        }
        "setpoint" => {
            let (temp_c, rate_c_per_s) = (number(0, "temperature")?, number(1, "rate")?);
            protocol::stimulus_command(
                channel,
                Stimulus::Direct { temp_c, rate_c_per_s },
                Owner::Osc,
                &app.limits,
            )
        }
        "release" => Ok(Command::Release { channel }),
        "program_stop" => Ok(Command::ProgramStop { channel }),
        "response" | "rating" => {
            let (kind, value) = match action {
                "rating" => (ResponseKind::Rating, Some(number(0, "rating")?)),
                _ => (ResponseKind::Button, None),
            };
            let response = ResponseInput {
                channel: channel as i64,
                kind,
                value,
            };
            protocol::response_command(response, &app.limits)
        }
        _ => Err(ApiError::new(
            ErrorCode::UnknownType,
            format!("unknown OSC action {action:?}"),
        )),
    }
}

/// `/thermode/program s`: the program whose `channels` object is the JSON string argument.
fn program_command(args: &[OscArg], app: &App) -> Result<Command, ApiError> {
    let Some(OscArg::Str(json)) = args.first() else {
        return Err(ApiError::new(
            ErrorCode::MissingField,
            "program needs the `channels` object as a JSON string (s)",
        ));
    };
    let channels = serde_json::from_str(json)
        .map_err(|e| ApiError::new(ErrorCode::BadValue, format!("program `channels`: {e}")))?;
    protocol::program_command(ProgramRequest { channels }, &app.limits, Owner::Osc)
}

/// How long a subscription lasts unless renewed \[s\] (the default of `NetLimits::osc_subscription_ttl_s`).
pub use crate::api::SUBSCRIPTION_TTL_S;

/// Most OSC subscribers at once; a further one is refused until one leaves or expires.
pub const MAX_SUBSCRIBERS: usize = 8;
/// Longest the sender sleeps between looks at the faults and the subscriptions' expiry \[s\].
const FAULT_POLL_S: f64 = 0.05;

/// One OSC client receiving telemetry and fault events.
#[derive(Debug)]
struct Subscriber {
    /// Where its datagrams go.
    to: SocketAddr,
    /// Who subscribed it (only it, or the port itself, may renew, change or end the subscription).
    owner: SocketAddr,
    /// Its byte budget (one token a byte).
    budget: TokenBucket,
    period: Duration,
    next_due: Instant,
    expires: Instant,
    /// The fault code last sent per channel (0: none); a change is sent as a fault event.
    faults_sent: Vec<u16>,
}

type Subscribers = Arc<Mutex<Vec<Subscriber>>>;

/// Subscribes (or renews) `from`, or the port its second argument names on the same host: the acknowledgement
/// and where it goes.
fn subscribe(
    message: &OscMessage,
    from: SocketAddr,
    app: &App,
    subscribers: &Subscribers,
) -> Result<(SocketAddr, Vec<u8>), ApiError> {
    if !from.ip().is_loopback() {
        return Err(ApiError::new(
            ErrorCode::BadValue,
            "OSC subscribers must be on loopback",
        ));
    }
    let rate_hz = message
        .args
        .first()
        .and_then(OscArg::as_f64)
        .ok_or_else(|| ApiError::new(ErrorCode::BadValue, "argument 0 (rate in Hz) must be a number"))?;
    let asked_hz = protocol::subscription_rate(rate_hz, &app.limits)?;
    let to = reply_address(message.args.get(1), from)?;
    refuse_own_port(to, &app.info)?;
    let bytes_per_s = app.net.osc_subscriber_bytes_per_s;
    let set_bytes = telemetry_set_bytes(app.limits.channel_count);
    let rate_hz = asked_hz.min(bytes_per_s / set_bytes as f64);
    let now = Instant::now();
    let ttl_s = app.net.osc_subscription_ttl_s;
    let expires = now + Duration::from_secs_f64(ttl_s);
    let period = Duration::from_secs_f64(1.0 / rate_hz);
    let mut list = subscribers.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let same_port = list.iter().position(|s| s.to.port() == to.port());
    if let Some(i) = same_port.filter(|&i| list[i].to != to || !may_change(&list[i], from)) {
        return Err(ApiError::new(
            ErrorCode::Busy,
            format!(
                "port {} is already subscribed by another address ({}); it renews or ends its own subscription",
                to.port(),
                list[i].owner
            ),
        ));
    }
    if let Some(known) = same_port.map(|i| &mut list[i]) {
        known.expires = expires;
        known.owner = from;
        if known.period != period {
            known.period = period;
            known.next_due = now;
        }
    } else if list.len() >= MAX_SUBSCRIBERS {
        return Err(ApiError::new(
            ErrorCode::Busy,
            format!("{MAX_SUBSCRIBERS} OSC subscribers already; unsubscribe one or let it expire"),
        ));
    } else {
        list.push(Subscriber {
            to,
            owner: from,
            budget: TokenBucket::new(bytes_per_s, byte_burst(bytes_per_s, set_bytes)),
            period,
            next_due: now,
            expires,
            faults_sent: vec![0; app.limits.channel_count],
        });
    }
    app.osc.subscribers.store(list.len(), Ordering::Relaxed);
    let ack = encode(
        "/thermode/subscribed",
        &[OscArg::Float(rate_hz as f32), OscArg::Float(ttl_s as f32)],
    );
    Ok((to, ack))
}

/// Whether a request from `from` may renew, change or end `sub`: its owner, or the subscribed port itself.
fn may_change(sub: &Subscriber, from: SocketAddr) -> bool {
    sub.owner == from || sub.to == from
}

/// Refuses the daemon's own OSC and HTTP ports on any loopback address: a subscription there made the daemon flood
/// itself.
fn refuse_own_port(to: SocketAddr, info: &crate::api::Info) -> Result<(), ApiError> {
    let own = [info.osc_port, Some(info.http_port)];
    if to.ip().is_loopback() && own.contains(&Some(to.port())) {
        return Err(ApiError::new(
            ErrorCode::BadValue,
            format!(
                "port {} is the daemon's own (OSC or HTTP): telemetry cannot be sent to the daemon itself",
                to.port()
            ),
        ));
    }
    Ok(())
}

/// Bytes of one round of telemetry (one message per channel).
fn telemetry_set_bytes(channel_count: usize) -> usize {
    (0..channel_count)
        .map(|channel| telemetry_packet(channel, [0.0; 5], 0).len())
        .sum()
}

/// A subscriber's burst \[bytes\]: a quarter second of its budget, or one round of telemetry and a fault event of
/// every channel, whichever is more (so that a round always fits a full budget).
fn byte_burst(bytes_per_s: f64, set_bytes: usize) -> f64 {
    (bytes_per_s / 4.0).max(2.0 * set_bytes as f64 + 256.0)
}

/// The sender's address, or the port `port` names on the sender's host.
fn reply_address(port: Option<&OscArg>, from: SocketAddr) -> Result<SocketAddr, ApiError> {
    let Some(port) = port else { return Ok(from) };
    port.as_f64()
        .filter(|p| p.fract() == 0.0 && (1.0..=65535.0).contains(p))
        .map(|p| SocketAddr::new(from.ip(), p as u16))
        .ok_or_else(|| {
            ApiError::new(
                ErrorCode::BadValue,
                "argument 1 (port) must be an integer from 1 to 65535",
            )
        })
}

fn unsubscribe(message: &OscMessage, from: SocketAddr, app: &App, subscribers: &Subscribers) -> Result<(), ApiError> {
    let to = reply_address(message.args.first(), from)?;
    let mut list = subscribers.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    if list.iter().any(|s| s.to == to && !may_change(s, from)) {
        return Err(ApiError::new(
            ErrorCode::Busy,
            format!(
                "port {} was subscribed by another address; only it can unsubscribe",
                to.port()
            ),
        ));
    }
    list.retain(|s| s.to != to);
    app.osc.subscribers.store(list.len(), Ordering::Relaxed);
    Ok(())
}

/// Sends telemetry and fault events to the subscribers, from the network runtime (the loop only publishes its
/// snapshot): at each subscriber's rate one `/thermode/channel/<i>/telemetry` per channel, and within
/// [`FAULT_POLL_S`] of a fault latching or clearing a `/thermode/channel/<i>/fault`, each within the subscriber's
/// byte budget (a fault event that does not fit waits for the next look; a round of telemetry that does not fit is
/// skipped whole and counted as throttled). Datagrams that cannot be sent at once are dropped, never waited for.
async fn send_to_subscribers(socket: Arc<UdpSocket>, app: Arc<App>, subscribers: Subscribers) {
    let poll = Duration::from_secs_f64(FAULT_POLL_S);
    let origin = Instant::now();
    loop {
        let wake = {
            let now = Instant::now();
            let Ok(mut list) = subscribers.lock() else { return };
            list.retain(|s| s.expires > now);
            app.osc.subscribers.store(list.len(), Ordering::Relaxed);
            list.iter().map(|s| s.next_due).fold(now + poll, Instant::min)
        };
        tokio::time::sleep_until(wake).await;
        let mut out: Vec<(SocketAddr, Vec<u8>)> = Vec::new();
        {
            let Ok(mut list) = subscribers.lock() else { return };
            if list.is_empty() {
                continue;
            }
            let snapshot = app.shared.snapshot();
            let now = Instant::now();
            let now_s = now.duration_since(origin).as_secs_f64();
            for sub in list.iter_mut() {
                for (status, sent) in snapshot.channels.iter().zip(sub.faults_sent.iter_mut()) {
                    let fault = status.telemetry.fault;
                    let code = fault.map_or(0, |f| f.code());
                    if code != *sent {
                        let description = fault.map_or("cleared", |f| f.description());
                        let address = format!("/thermode/channel/{}/fault", status.channel);
                        let args = [OscArg::Int(i32::from(code)), OscArg::Str(description.into())];
                        let packet = encode(&address, &args);
                        if sub.budget.take_many(packet.len() as f64, now_s) {
                            *sent = code;
                            out.push((sub.to, packet));
                        }
                    }
                }
                if now >= sub.next_due {
                    let round: Vec<Vec<u8>> = snapshot.channels.iter().map(telemetry_message).collect();
                    let bytes: usize = round.iter().map(Vec::len).sum();
                    if sub.budget.take_many(bytes as f64, now_s) {
                        out.extend(round.into_iter().map(|packet| (sub.to, packet)));
                    } else {
                        app.osc.throttled.fetch_add(round.len() as u64, Ordering::Relaxed);
                    }
                    sub.next_due += sub.period;
                    if sub.next_due < now {
                        sub.next_due = now + sub.period;
                    }
                }
            }
        }
        for (to, packet) in out {
            if socket.try_send_to(&packet, to).is_ok() {
                app.osc.sent.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// `/thermode/channel/<i>/telemetry f f f f f i`: target skin, skin, sensor, plate estimate \[°C\], current \[A\]
/// (floats, NaN where the JSON telemetry has null) and the latched fault code (0: none).
fn telemetry_message(status: &ChannelStatus) -> Vec<u8> {
    let t = &status.telemetry;
    let values = [t.target_skin_c, t.skin_c, t.sensor_c, t.plate_estimate_c, t.current_a];
    telemetry_packet(status.channel, values, i32::from(t.fault.map_or(0, |f| f.code())))
}

/// `/thermode/channel/<channel>/telemetry` with five floats and a fault code.
fn telemetry_packet(channel: usize, values: [f64; 5], fault: i32) -> Vec<u8> {
    let address = format!("/thermode/channel/{channel}/telemetry");
    let mut args: Vec<OscArg> = values.iter().map(|&v| OscArg::Float(v as f32)).collect();
    args.push(OscArg::Int(fault));
    encode(&address, &args)
}

/// Receives datagrams until the runtime stops (and runs the subscribers' sender beside it).
pub async fn serve(socket: UdpSocket, app: Arc<App>) {
    let socket = Arc::new(socket);
    let subscribers: Subscribers = Arc::default();
    tokio::spawn(send_to_subscribers(socket.clone(), app.clone(), subscribers.clone()));
    let mut buffer = vec![0u8; MAX_PACKET_BYTES];
    let mut bucket = TokenBucket::new(app.net.osc_messages_per_s, app.net.osc_burst);
    let origin = tokio::time::Instant::now();
    loop {
        let Ok((len, from)) = socket.recv_from(&mut buffer).await else {
            continue;
        };
        let counters = &app.osc;
        counters.packets.fetch_add(1, Ordering::Relaxed);
        let messages = match decode(&buffer[..len]) {
            Ok(messages) if len < MAX_PACKET_BYTES => messages,
            _ => {
                counters.malformed.fetch_add(1, Ordering::Relaxed);
                continue;
            }
        };
        for message in &messages {
            if is_stop(message) {
                queue(Command::StopAll, message, &app);
                continue;
            }
            if !bucket.take(origin.elapsed().as_secs_f64()) {
                counters.rate_limited.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            match message.address.as_str() {
                "/thermode/subscribe" => {
                    let (to, reply) = match subscribe(message, from, &app, &subscribers) {
                        Ok(ack) => {
                            count(counters, &message.address, Ok(()));
                            ack
                        }
                        Err(e) => {
                            let args = [OscArg::Str(e.code.as_str().into()), OscArg::Str(e.message.clone())];
                            counters.subscriptions_refused.fetch_add(1, Ordering::Relaxed);
                            count(counters, &message.address, Err(e));
                            (from, encode("/thermode/error", &args))
                        }
                    };
                    if socket.try_send_to(&reply, to).is_ok() {
                        counters.sent.fetch_add(1, Ordering::Relaxed);
                    }
                    continue;
                }
                "/thermode/unsubscribe" => {
                    count(
                        counters,
                        &message.address,
                        unsubscribe(message, from, &app, &subscribers),
                    );
                    continue;
                }
                _ => {}
            }
            let commands = match to_commands(message, &app) {
                Ok(commands) => commands,
                Err(e) => {
                    count(counters, &message.address, Err(e));
                    continue;
                }
            };
            for command in commands {
                queue(command, message, &app);
            }
        }
    }
}

/// `/thermode/stop` or `/thermode/stop_all`: taken before the rate limit.
fn is_stop(message: &OscMessage) -> bool {
    matches!(message.address.as_str(), "/thermode/stop" | "/thermode/stop_all")
}

/// Queues `command` (a stop-all on the loop's urgent lane) and counts the loop's answer when it comes (within the
/// reply wait; a withdrawn command is refused as busy); a full queue is counted as refused at once.
fn queue(command: Command, message: &OscMessage, app: &Arc<App>) {
    match app.commands.request(command).map_err(crate::api::execute::loop_error) {
        Ok(answer) => {
            let (counters, address, wait) = (app.osc.clone(), message.address.clone(), app.reply_wait);
            tokio::spawn(async move {
                let reply = crate::api::answer_within(answer, wait)
                    .await
                    .map_err(crate::api::execute::loop_error);
                count(&counters, &address, reply.map(|_| ()));
            });
        }
        Err(e) => count(&app.osc, &message.address, Err(e)),
    }
}

/// Counts one message's outcome (and keeps the last refusal's reason).
fn count(counters: &OscCounters, address: &str, outcome: Result<(), ApiError>) {
    match outcome {
        Ok(()) => {
            counters.applied.fetch_add(1, Ordering::Relaxed);
        }
        Err(e) => {
            if let Ok(mut last) = counters.last_error.lock() {
                *last = Some(format!("{address} {}: {}", e.code.as_str(), e.message));
            }
            counters.refused.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Encodes a message (for tests and examples): string, int and float arguments.
pub fn encode(address: &str, args: &[OscArg]) -> Vec<u8> {
    let mut out = Vec::new();
    push_string(&mut out, address);
    let mut tags = String::from(",");
    for arg in args {
        tags.push(match arg {
            OscArg::Str(_) => 's',
            OscArg::Int(_) => 'i',
            OscArg::Long(_) => 'h',
            OscArg::Float(_) => 'f',
            OscArg::Double(_) => 'd',
            OscArg::Other => 'N',
        });
    }
    push_string(&mut out, &tags);
    for arg in args {
        match arg {
            OscArg::Str(s) => push_string(&mut out, s),
            OscArg::Int(v) => out.extend_from_slice(&v.to_be_bytes()),
            OscArg::Long(v) => out.extend_from_slice(&v.to_be_bytes()),
            OscArg::Float(v) => out.extend_from_slice(&v.to_be_bytes()),
            OscArg::Double(v) => out.extend_from_slice(&v.to_be_bytes()),
            OscArg::Other => {}
        }
    }
    out
}

fn push_string(out: &mut Vec<u8>, text: &str) {
    out.extend_from_slice(text.as_bytes());
    let pad = 4 - text.len() % 4;
    out.extend(std::iter::repeat_n(0u8, pad));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_round_trip() {
        let args = vec![OscArg::Str("wood".into()), OscArg::Float(25.5), OscArg::Int(-3)];
        let packet = encode("/thermode/channel/2/touch", &args);
        assert_eq!(packet.len() % 4, 0);
        let decoded = decode(&packet).expect("valid");
        assert_eq!(
            decoded,
            vec![OscMessage {
                address: "/thermode/channel/2/touch".into(),
                args
            }]
        );
    }

    #[test]
    fn bundles_are_flattened() {
        let a = encode("/thermode/stop", &[]);
        let b = encode("/thermode/channel/0/release", &[OscArg::Float(1.0)]);
        let mut bundle = b"#bundle\0".to_vec();
        bundle.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 1]);
        for m in [&a, &b] {
            bundle.extend_from_slice(&(m.len() as i32).to_be_bytes());
            bundle.extend_from_slice(m);
        }
        let decoded = decode(&bundle).expect("valid bundle");
        assert_eq!(decoded.len(), 2);
        assert_eq!(decoded[1].address, "/thermode/channel/0/release");
    }

    #[test]
    fn garbage_is_malformed_not_a_panic() {
        let good = encode("/thermode/channel/1/touch", &[OscArg::Str("aluminium".into())]);
        for cut in 0..good.len() {
            let _ = decode(&good[..cut]);
        }
        let cases: [&[u8]; 7] = [
            b"",
            b"abc\0",
            b"/x",
            b"/x\0\0,q\0\0",
            b"/x\0\0,i\0\0\0\0",
            b"#bundle\0\0\0\0\0\0\0\0\0\xff\xff\xff\xff",
            b"/x\0\0,s\0\0\xff\xfe\0\0",
        ];
        for case in cases {
            assert!(decode(case).is_err(), "{case:?} decoded");
        }
        let mut deep = encode("/thermode/stop", &[]);
        for _ in 0..6 {
            let mut bundle = b"#bundle\0\0\0\0\0\0\0\0\0".to_vec();
            bundle.extend_from_slice(&(deep.len() as i32).to_be_bytes());
            bundle.extend_from_slice(&deep);
            deep = bundle;
        }
        assert_eq!(decode(&deep), Err(Malformed("bundles nested too deeply")));
    }
}
