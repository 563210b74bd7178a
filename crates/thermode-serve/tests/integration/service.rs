//! The daemon against hostile clients and its own limits (docs/security.md §"Starvation", docs/api.md
//! "Connections"): slow and silent HTTP connections cannot starve `/api/status` or the WebSocket handshake (STOP
//! ALL) and are closed by the header-read timeout; OSC cannot bypass the token; WebSocket and HTTP conformance (a
//! reader that stops reading is closed, 1007 on a text frame that is not UTF-8, a malformed key and a second Host
//! header are refused); OSC counts the loop's refusals as refusals; OSC STOP ALL is applied under a 1000 datagrams/s
//! flood.

use crate::common;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::time::Duration;

use common::{client_runtime, get_json, http_get, start, test_config, trackers, SpyDevice};
use thermode_serve::api::NetLimits;
use thermode_serve::osc::{encode, OscArg};

/// A raw HTTP exchange: sends `request`, returns what arrives until the server closes or `limit_s` passes.
fn raw_exchange(addr: SocketAddr, request: &str, limit_s: f64) -> String {
    let mut stream = TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs_f64(limit_s)))
        .expect("timeout");
    stream.write_all(request.as_bytes()).expect("send");
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    while let Ok(n) = stream.read(&mut buf) {
        if n == 0 {
            break;
        }
        out.extend_from_slice(&buf[..n]);
        if out.windows(4).any(|w| w == b"\r\n\r\n") && !request.contains("Upgrade") {
            break;
        }
        if request.contains("Upgrade") && out.windows(4).any(|w| w == b"\r\n\r\n") {
            break;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Whether the server has closed `stream` (a read returns 0 or fails), waiting at most `limit_s`.
fn closed_within(stream: &mut TcpStream, limit_s: f64) -> bool {
    stream
        .set_read_timeout(Some(Duration::from_secs_f64(limit_s)))
        .expect("timeout");
    let mut buf = [0u8; 1024];
    loop {
        match stream.read(&mut buf) {
            Ok(0) => return true,
            Ok(_) => continue,
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                return false
            }
            Err(_) => return true,
        }
    }
}

#[test]
fn slow_and_silent_connections_cannot_starve_status_or_stop_all_and_are_closed_by_the_header_timeout() {
    let mut config = test_config();
    config.server.net = NetLimits {
        max_http_connections: 48,
        header_timeout_s: 2.0,
        ..NetLimits::default()
    };
    let daemon = start(config, SpyDevice::new(2), trackers());
    let addr = daemon.http_addr();
    // 300 slowloris connections (six times the cap): half send a partial request head, half nothing at all.
    let mut held: Vec<TcpStream> = (0..300)
        .map(|i| {
            let mut s = TcpStream::connect(addr).expect("connect");
            if i % 2 == 0 {
                s.write_all(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
                    .expect("partial head");
            }
            s
        })
        .collect();
    for _ in 0..3 {
        let (code, body) = http_get(addr, "/api/status", &[]);
        assert_eq!(code, 200, "status under 300 slow connections: {body}");
    }
    client_runtime().block_on(async {
        let mut ws = common::ws_connect(addr, "").await;
        let r = common::ask(&mut ws, r#"{"type":"touch","id":1,"channel":0,"material":"wood"}"#).await;
        assert_eq!(r["type"], "ok", "{r}");
        let r = common::ask(&mut ws, r#"{"type":"stop_all","id":2}"#).await;
        assert_eq!(r["type"], "ok", "STOP ALL through the exhausted server: {r}");
    });
    let status = get_json(addr, "/api/status");
    let http = &status["http"];
    assert!(
        http["evicted"].as_u64().unwrap_or(0) >= 200,
        "idle connections made room: {http}"
    );
    assert_eq!(http["max_connections"], 48, "{http}");
    // Every connection still open is closed by the header-read timeout (2 s here) — generous liveness bound.
    let survivors: Vec<usize> = held
        .iter_mut()
        .enumerate()
        .filter_map(|(i, s)| (!closed_within(s, 10.0)).then_some(i))
        .collect();
    assert!(survivors.is_empty(), "connections still open: {survivors:?}");
    let http = &get_json(addr, "/api/status")["http"];
    assert!(http["timed_out"].as_u64().unwrap_or(0) > 0, "{http}");
}

#[test]
fn a_second_host_header_and_a_malformed_websocket_key_are_refused() {
    let daemon = start(test_config(), SpyDevice::new(1), trackers());
    let addr = daemon.http_addr();
    let reply = raw_exchange(
        addr,
        &format!("GET /api/status HTTP/1.1\r\nHost: {addr}\r\nHost: evil.example\r\nConnection: close\r\n\r\n"),
        5.0,
    );
    assert!(reply.starts_with("HTTP/1.1 400"), "two Host headers: {reply}");
    let upgrade = |key: &str| {
        format!(
            "GET /api/ws HTTP/1.1\r\nHost: {addr}\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n\
             Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: {key}\r\n\r\n"
        )
    };
    for key in ["", "abc", "dGhlIHNhbXBsZSBub25jZQ=", "dGhlIHNhbXBsZSBub25jZR=="] {
        let reply = raw_exchange(addr, &upgrade(key), 5.0);
        assert!(reply.starts_with("HTTP/1.1 400"), "key {key:?}: {reply}");
    }
    let reply = raw_exchange(addr, &upgrade("dGhlIHNhbXBsZSBub25jZQ=="), 5.0);
    assert!(reply.starts_with("HTTP/1.1 101"), "the RFC 6455 sample key: {reply}");
}

#[test]
fn a_text_frame_that_is_not_utf8_is_closed_with_1007() {
    let daemon = start(test_config(), SpyDevice::new(1), trackers());
    let addr = daemon.http_addr();
    let mut stream = TcpStream::connect(addr).expect("connect");
    stream.set_read_timeout(Some(Duration::from_secs(10))).expect("timeout");
    let handshake = format!(
        "GET /api/ws HTTP/1.1\r\nHost: {addr}\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n\
         Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n"
    );
    stream.write_all(handshake.as_bytes()).expect("handshake");
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        stream.read_exact(&mut byte).expect("101 head");
        head.push(byte[0]);
    }
    assert!(head.starts_with(b"HTTP/1.1 101"), "{}", String::from_utf8_lossy(&head));
    // A masked text frame (FIN, opcode 1) holding 0xFF 0xFE: not UTF-8.
    let mask = [1u8, 2, 3, 4];
    let payload = [0xFFu8, 0xFE];
    let mut frame = vec![0x81, 0x80 | payload.len() as u8];
    frame.extend_from_slice(&mask);
    frame.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
    stream.write_all(&frame).expect("frame");
    let mut received = Vec::new();
    let mut buf = [0u8; 256];
    loop {
        match stream.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => received.extend_from_slice(&buf[..n]),
        }
    }
    // Skip ping frames (opcode 9) to the close frame (opcode 8) and read its code.
    let mut at = 0;
    let mut code = None;
    while at + 2 <= received.len() {
        let (opcode, len) = (received[at] & 0x0F, usize::from(received[at + 1] & 0x7F));
        if opcode == 8 && len >= 2 && at + 4 <= received.len() {
            code = Some(u16::from_be_bytes([received[at + 2], received[at + 3]]));
            break;
        }
        at += 2 + len;
    }
    assert_eq!(code, Some(1007), "close code; received {received:?}");
}

#[test]
fn a_subscriber_that_never_reads_is_closed_by_the_send_timeout() {
    let mut config = test_config();
    config.server.net = NetLimits {
        send_timeout_s: 1.0,
        ping_interval_s: 0.2,
        ..NetLimits::default()
    };
    let daemon = start(config, SpyDevice::new(5), trackers());
    let addr = daemon.http_addr();
    client_runtime().block_on(async {
        let mut ws = common::ws_connect(addr, "").await;
        let r = common::ask(&mut ws, r#"{"type":"subscribe","id":1,"rate_hz":100}"#).await;
        assert_eq!(r["type"], "ok", "{r}");
        assert_eq!(get_json(addr, "/api/status")["clients"], 1);
        // From here on the client reads nothing (it keeps its socket open).
        let closed = common::wait_until(10.0, || get_json(addr, "/api/status")["clients"] == 0);
        assert!(closed, "a subscriber that stopped reading is still connected");
        // The idle timeout (20 s) is not what closed it: the send timeout (1 s here) and its ping were.
        assert!(NetLimits::default().idle_timeout_s > 10.0);
        drop(ws);
    });
}

#[test]
fn with_a_token_osc_is_off_unless_asked_for_and_then_on_loopback_only() {
    let mut config = test_config();
    config.server.token = Some("s3cret-t0ken".into());
    let daemon = start(config, SpyDevice::new(3), trackers());
    assert_eq!(daemon.osc_addr(), None, "a token turns OSC off: OSC cannot carry it");
    let status = get_json(daemon.http_addr(), "/api/status?token=s3cret-t0ken");
    assert_eq!(status["osc"]["enabled"], false, "{}", status["osc"]);
    drop(daemon);

    let mut config = test_config();
    config.server.token = Some("s3cret-t0ken".into());
    config.server.bind = "0.0.0.0".parse().expect("address");
    config.server.osc_without_token = true;
    assert!(config.server.osc_unauthenticated());
    let daemon = start(config, SpyDevice::new(3), trackers());
    let osc = daemon.osc_addr().expect("asked for: OSC listens");
    assert!(
        osc.ip().is_loopback(),
        "OSC without a token listens on loopback only, not {osc}"
    );
}

#[test]
fn an_osc_touch_the_loop_refuses_is_counted_as_refused() {
    let device = SpyDevice::new(2);
    let control = device.control.clone();
    let daemon = start(test_config(), device, trackers());
    let addr = daemon.http_addr();
    let osc = daemon.osc_addr().expect("OSC");
    // Channel 1's reads fail: its envelope latches a stale-sensor fault.
    control.lock().expect("control").failing_reads.push(1);
    assert!(
        common::wait_until(10.0, || get_json(addr, "/api/status")["channels"][1]["fault"] != 0
            && !get_json(addr, "/api/status")["channels"][1]["fault"].is_null()),
        "channel 1 faults"
    );
    let socket = UdpSocket::bind("127.0.0.1:0").expect("udp");
    let before = get_json(addr, "/api/status")["osc"].clone();
    socket
        .send_to(&encode("/thermode/channel/1/touch", &[OscArg::Str("wood".into())]), osc)
        .expect("send");
    let counted = common::wait_until(10.0, || {
        get_json(addr, "/api/status")["osc"]["refused"].as_u64() > before["refused"].as_u64()
    });
    let after = get_json(addr, "/api/status")["osc"].clone();
    assert!(counted, "refusal counted: {after}");
    assert_eq!(after["applied"], before["applied"], "not counted as applied: {after}");
    assert!(
        after["last_error"].as_str().is_some_and(|e| e.contains("device_fault")),
        "{after}"
    );
    socket
        .send_to(&encode("/thermode/channel/0/touch", &[OscArg::Str("wood".into())]), osc)
        .expect("send");
    assert!(common::wait_until(10.0, || {
        get_json(addr, "/api/status")["osc"]["applied"].as_u64() > before["applied"].as_u64()
    }));
}

#[test]
fn the_status_says_what_real_time_treatment_the_loop_got_and_the_http_limits() {
    let daemon = start(test_config(), SpyDevice::new(1), trackers());
    let status = get_json(daemon.http_addr(), "/api/status");
    let rt = &status["loop"]["realtime"];
    assert_eq!(
        rt["scheduling"], "normal",
        "not asked for by default in the library: {rt}"
    );
    assert_eq!(rt["memory_locked"], false, "{rt}");
    assert_eq!(rt["scheduling_error"], "not requested", "{rt}");
    let http = &status["http"];
    let defaults = NetLimits::default();
    assert_eq!(http["header_timeout_s"], defaults.header_timeout_s, "{http}");
    assert_eq!(http["idle_timeout_s"], defaults.http_idle_timeout_s, "{http}");
    assert!(defaults.header_timeout_s <= 10.0);
    let cap = http["max_connections"].as_u64().unwrap_or(0);
    assert!(cap > 0 && cap <= defaults.max_http_connections as u64, "{http}");
}

/// STOP ALL over OSC is answered (applied, counted) while 1000 datagrams per second arrive: a bounded flood from the
/// test (loopback only, 4000 telemetry-like datagrams, as a daemon subscribed to itself sent, then it stops by itself)
/// spends the OSC budget (200/s, burst 400), yet `/thermode/stop` is queued on the urgent lane before the rate
/// limit: every channel is released and the stop is counted as applied before the flood ends. Before, the stop was
/// dropped with the flood (3 of 3 in one run; this test then fails: 'STOP ALL not counted as applied').
#[test]
fn stop_all_over_osc_is_answered_while_1000_datagrams_per_second_arrive() {
    let daemon = start(test_config(), SpyDevice::new(2), trackers());
    let addr = daemon.http_addr();
    let osc = daemon.osc_addr().expect("OSC");
    let commander = UdpSocket::bind("127.0.0.1:0").expect("udp");
    for channel in 0..2 {
        let touch = encode(
            &format!("/thermode/channel/{channel}/touch"),
            &[OscArg::Str("wood".into())],
        );
        commander.send_to(&touch, osc).expect("send");
    }
    let touching = || get_json(addr, "/api/status")["contacts"].as_array().map_or(0, Vec::len);
    assert!(common::wait_until(10.0, || touching() == 2), "both channels touch wood");
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flood_done = done.clone();
    let flood = std::thread::spawn(move || {
        let socket = UdpSocket::bind("127.0.0.1:0").expect("udp");
        let datagram = encode(
            "/thermode/channel/0/telemetry",
            &[
                OscArg::Float(32.0),
                OscArg::Float(32.0),
                OscArg::Float(32.0),
                OscArg::Float(32.0),
                OscArg::Float(0.0),
                OscArg::Int(0),
            ],
        );
        // 1000 per second: 10 every 10 ms, 4000 in all.
        for _ in 0..400 {
            for _ in 0..10 {
                let _ = socket.send_to(&datagram, osc);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        flood_done.store(true, std::sync::atomic::Ordering::SeqCst);
    });
    let limited = || {
        get_json(addr, "/api/status")["osc"]["rate_limited"]
            .as_u64()
            .unwrap_or(0)
    };
    assert!(
        common::wait_until(10.0, || limited() > 0),
        "the flood spends the OSC budget"
    );
    let before = get_json(addr, "/api/status")["osc"].clone();
    commander.send_to(&encode("/thermode/stop", &[]), osc).expect("send");
    let applied = || get_json(addr, "/api/status")["osc"]["applied"].as_u64().unwrap_or(0);
    let answered = common::wait_until(10.0, || applied() > before["applied"].as_u64().unwrap_or(0));
    let released = touching() == 0;
    let during_the_flood = !done.load(std::sync::atomic::Ordering::SeqCst);
    flood.join().expect("flood");
    let after = get_json(addr, "/api/status")["osc"].clone();
    println!("OSC under a 1000/s flood: before the stop {before}, after {after}");
    assert!(
        answered,
        "STOP ALL not counted as applied: before {before}, after {after}"
    );
    assert!(
        released,
        "channels still touching after STOP ALL: {}",
        get_json(addr, "/api/status")["contacts"]
    );
    assert!(
        during_the_flood,
        "the flood had ended before the stop was answered: {after}"
    );
    assert!(
        after["rate_limited"].as_u64() > before["rate_limited"].as_u64(),
        "the flood went on being rate limited: before {before}, after {after}"
    );
}
