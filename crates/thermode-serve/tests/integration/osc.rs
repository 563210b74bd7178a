//! OSC both ways on a running daemon (real clock): a subscriber receives telemetry at about its rate and fault events
//! (latched and cleared), stops receiving after unsubscribing or when its subscription expires; the subscriber cap;
//! the all-channels addresses; subscriptions to the daemon's own ports or to a port another address holds are
//! refused; the bytes sent to a subscriber stay within its budget.

use crate::common;

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use common::{ask, client_runtime, get_json, pipelines, start, test_config, ws_connect, SpyDevice};
use thermode_device::Fault;
use thermode_safety::FaultCode;
use thermode_serve::osc::{decode, encode, OscArg, OscMessage, MAX_SUBSCRIBERS};

/// A loopback client socket that gives up a read after 100 ms.
fn client() -> UdpSocket {
    let socket = UdpSocket::bind("127.0.0.1:0").expect("udp");
    socket
        .set_read_timeout(Some(Duration::from_millis(100)))
        .expect("timeout");
    socket
}

/// Every message received for `window_s`.
fn receive_for(socket: &UdpSocket, window_s: f64) -> Vec<OscMessage> {
    let end = Instant::now() + Duration::from_secs_f64(window_s);
    let mut buffer = [0u8; 2048];
    let mut out = Vec::new();
    while Instant::now() < end {
        if let Ok((len, _)) = socket.recv_from(&mut buffer) {
            out.extend(decode(&buffer[..len]).expect("the daemon sends valid OSC"));
        }
    }
    out
}

/// Receives until a message satisfies `wanted` (or `limit_s` passes).
fn receive_until(socket: &UdpSocket, limit_s: f64, wanted: impl Fn(&OscMessage) -> bool) -> Option<OscMessage> {
    let end = Instant::now() + Duration::from_secs_f64(limit_s);
    let mut buffer = [0u8; 2048];
    while Instant::now() < end {
        if let Ok((len, _)) = socket.recv_from(&mut buffer) {
            if let Some(m) = decode(&buffer[..len]).expect("valid OSC").into_iter().find(&wanted) {
                return Some(m);
            }
        }
    }
    None
}

fn count(messages: &[OscMessage], address: &str) -> usize {
    messages.iter().filter(|m| m.address == address).count()
}

fn subscribe(socket: &UdpSocket, osc: SocketAddr, args: &[OscArg]) {
    socket.send_to(&encode("/thermode/subscribe", args), osc).expect("send");
}

#[test]
fn a_subscriber_receives_telemetry_at_its_rate_and_fault_events_until_it_unsubscribes() {
    let device = SpyDevice::new(3);
    let control = device.control.clone();
    let daemon = start(test_config(), device, pipelines());
    let osc = daemon.osc_addr().expect("OSC listens on loopback");
    let socket = client();
    let rate_hz = 20.0_f32;
    subscribe(&socket, osc, &[OscArg::Float(rate_hz)]);
    let ack = receive_until(&socket, 5.0, |m| m.address == "/thermode/subscribed").expect("acknowledged");
    assert_eq!(ack.args[0], OscArg::Float(rate_hz), "{ack:?}");

    let window_s = 2.0;
    let messages = receive_for(&socket, window_s);
    let per_channel: Vec<usize> = (0..3)
        .map(|i| count(&messages, &format!("/thermode/channel/{i}/telemetry")))
        .collect();
    let received_hz = per_channel[0] as f32 / window_s as f32;
    println!(
        "OSC telemetry: asked {rate_hz} Hz, received {received_hz} Hz (per channel {per_channel:?} in {window_s} s)"
    );
    assert!(
        (0.5 * rate_hz..=1.5 * rate_hz).contains(&received_hz),
        "asked {rate_hz} Hz, received {received_hz} Hz"
    );
    assert!(
        per_channel.iter().all(|&n| n.abs_diff(per_channel[0]) <= 1),
        "every channel at each tick: {per_channel:?}"
    );
    let sample = messages
        .iter()
        .find(|m| m.address == "/thermode/channel/1/telemetry")
        .expect("a telemetry message");
    let kinds: Vec<bool> = sample.args.iter().map(|a| matches!(a, OscArg::Float(_))).collect();
    assert_eq!(kinds, [true, true, true, true, true, false], "{sample:?}");
    assert_eq!(sample.args[5], OscArg::Int(0), "no fault: {sample:?}");

    control.lock().expect("control").inject.push((1, Fault::SensorOpen));
    let fault = receive_until(&socket, 5.0, |m| m.address == "/thermode/channel/1/fault").expect("a fault event");
    let code = i32::from(FaultCode::SensorOpen.code());
    assert_eq!(fault.args.first(), Some(&OscArg::Int(code)), "{fault:?}");
    assert!(
        matches!(fault.args.get(1), Some(OscArg::Str(d)) if !d.is_empty()),
        "{fault:?}"
    );
    let faulted = receive_until(&socket, 5.0, |m| m.address == "/thermode/channel/1/telemetry").expect("telemetry");
    assert_eq!(faulted.args[5], OscArg::Int(code), "{faulted:?}");

    control.lock().expect("control").clear.push(1);
    let last_reply = client_runtime().block_on(async {
        let mut ws = ws_connect(daemon.http_addr(), "").await;
        let mut reply = serde_json::Value::Null;
        for id in 0..50 {
            reply = ask(&mut ws, &format!(r#"{{"type":"clear_fault","id":{id},"channel":1}}"#)).await;
            if reply["type"] == "ok" {
                break;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        reply
    });
    assert_eq!(
        last_reply["type"], "ok",
        "the fault clears once the sensor is back: {last_reply}"
    );
    let event = receive_until(&socket, 5.0, |m| m.address == "/thermode/channel/1/fault").expect("a clear event");
    assert_eq!(event.args, [OscArg::Int(0), OscArg::Str("cleared".into())], "{event:?}");

    socket
        .send_to(&encode("/thermode/unsubscribe", &[]), osc)
        .expect("send");
    receive_for(&socket, 0.3);
    let after = receive_for(&socket, 1.0);
    assert!(
        after.is_empty(),
        "after unsubscribing: {} messages, first {:?}",
        after.len(),
        after.first()
    );
    assert_eq!(get_json(daemon.http_addr(), "/api/status")["osc"]["subscribers"], 0);
}

#[test]
fn subscriptions_expire_unless_renewed_go_to_the_given_port_and_are_capped() {
    let mut config = test_config();
    config.server.net.osc_subscription_ttl_s = 1.0;
    let daemon = start(config, SpyDevice::new(2), pipelines());
    let osc = daemon.osc_addr().expect("OSC listens on loopback");
    let (sender, listener) = (client(), client());
    let port = listener.local_addr().expect("addr").port();
    subscribe(&sender, osc, &[OscArg::Float(10.0), OscArg::Int(i32::from(port))]);
    let ack = receive_until(&listener, 5.0, |m| m.address == "/thermode/subscribed");
    assert!(ack.is_some(), "the acknowledgement goes to the given port");
    let got = receive_until(&listener, 5.0, |m| m.address == "/thermode/channel/0/telemetry");
    assert!(got.is_some(), "telemetry goes to the given port");
    assert!(receive_for(&sender, 0.3).is_empty(), "nothing to the sender's own port");
    // Not renewed: within the 1 s TTL (and a generous margin) nothing more arrives.
    receive_for(&listener, 2.0);
    let after = receive_for(&listener, 1.0);
    assert!(after.is_empty(), "after expiry: {} messages", after.len());

    let clients: Vec<UdpSocket> = (0..MAX_SUBSCRIBERS).map(|_| client()).collect();
    for c in &clients {
        subscribe(c, osc, &[OscArg::Float(1.0)]);
        assert!(receive_until(c, 5.0, |m| m.address == "/thermode/subscribed").is_some());
    }
    let one_more = client();
    subscribe(&one_more, osc, &[OscArg::Float(1.0)]);
    let refused = receive_until(&one_more, 5.0, |m| m.address == "/thermode/error").expect("refused");
    assert_eq!(refused.args[0], OscArg::Str("busy".into()), "{refused:?}");
    let too_fast = client();
    subscribe(&too_fast, osc, &[OscArg::Float(1.0e6)]);
    let refused = receive_until(&too_fast, 5.0, |m| m.address == "/thermode/error").expect("refused");
    assert_eq!(refused.args[0], OscArg::Str("bad_value".into()), "{refused:?}");
}

#[test]
fn the_all_channels_addresses_apply_to_every_channel() {
    let daemon = start(test_config(), SpyDevice::new(4), pipelines());
    let addr = daemon.http_addr();
    let osc = daemon.osc_addr().expect("OSC listens on loopback");
    let socket = client();
    let shows = || -> Vec<String> {
        let status = get_json(addr, "/api/status");
        (0..4).map(|i| common::shows(&status["channels"][i])).collect()
    };
    socket
        .send_to(&encode("/thermode/channel/*/touch", &[OscArg::Str("wood".into())]), osc)
        .expect("send");
    assert!(
        common::wait_until(5.0, || shows().iter().all(|s| s == "wood")),
        "{:?}",
        shows()
    );
    socket
        .send_to(&encode("/thermode/all/release", &[OscArg::Float(1.0)]), osc)
        .expect("send");
    assert!(
        common::wait_until(5.0, || shows().iter().all(|s| s == "air")),
        "{:?}",
        shows()
    );
    socket
        .send_to(
            &encode("/thermode/all/setpoint", &[OscArg::Float(34.0), OscArg::Float(2.0)]),
            osc,
        )
        .expect("send");
    let direct = || {
        let status = get_json(addr, "/api/status");
        (0..4).all(|i| status["channels"][i]["mode"] == "direct")
    };
    assert!(
        common::wait_until(5.0, direct),
        "{}",
        get_json(addr, "/api/status")["channels"]
    );
}

/// The self-subscription: `/thermode/subscribe 100 <the daemon's OSC port>` made the daemon flood its own port, spend
/// the OSC budget and drop commands. Refused now for the OSC and the HTTP port, on any loopback address, answered to
/// the sender and counted; so is a port another address already subscribed (the port itself may still renew).
#[test]
fn subscriptions_to_the_daemons_own_ports_or_to_a_port_another_address_holds_are_refused() {
    let daemon = start(test_config(), SpyDevice::new(2), pipelines());
    let osc = daemon.osc_addr().expect("OSC listens on loopback");
    let http_port = daemon.http_addr().port();
    let sender = client();
    for port in [osc.port(), http_port] {
        subscribe(&sender, osc, &[OscArg::Float(100.0), OscArg::Int(i32::from(port))]);
        let refused = receive_until(&sender, 5.0, |m| m.address == "/thermode/error").expect("refused");
        assert_eq!(
            refused.args[0],
            OscArg::Str("bad_value".into()),
            "port {port}: {refused:?}"
        );
        assert!(
            matches!(&refused.args[1], OscArg::Str(m) if m.contains("the daemon's own")),
            "port {port}: {refused:?}"
        );
    }
    // From another loopback address (127.0.0.2): the reply goes to the same host's port, so it is refused too.
    if let Ok(other) = UdpSocket::bind("127.0.0.2:0") {
        other
            .set_read_timeout(Some(Duration::from_millis(100)))
            .expect("timeout");
        subscribe(&other, osc, &[OscArg::Float(100.0), OscArg::Int(i32::from(osc.port()))]);
        let refused = receive_until(&other, 5.0, |m| m.address == "/thermode/error").expect("refused");
        assert_eq!(refused.args[0], OscArg::Str("bad_value".into()), "{refused:?}");
    }
    let status = get_json(daemon.http_addr(), "/api/status");
    let osc_status = &status["osc"];
    assert_eq!(osc_status["subscribers"], 0, "{osc_status}");
    assert!(osc_status["subscriptions_refused"].as_u64() >= Some(2), "{osc_status}");
    assert!(
        osc_status["last_error"].as_str().is_some_and(|e| e.contains("own")),
        "{osc_status}"
    );
    assert_eq!(osc_status["rate_limited"], 0, "no flood: {osc_status}");

    // A listener's port subscribed by one client: another client cannot take it over, the listener itself can.
    let (owner, intruder, listener) = (client(), client(), client());
    let port = i32::from(listener.local_addr().expect("addr").port());
    subscribe(&owner, osc, &[OscArg::Float(1.0), OscArg::Int(port)]);
    assert!(receive_until(&listener, 5.0, |m| m.address == "/thermode/subscribed").is_some());
    subscribe(&intruder, osc, &[OscArg::Float(100.0), OscArg::Int(port)]);
    let refused = receive_until(&intruder, 5.0, |m| m.address == "/thermode/error").expect("refused");
    assert_eq!(refused.args[0], OscArg::Str("busy".into()), "{refused:?}");
    assert!(
        matches!(&refused.args[1], OscArg::Str(m) if m.contains("already subscribed by another address")),
        "{refused:?}"
    );
    intruder
        .send_to(&encode("/thermode/unsubscribe", &[OscArg::Int(port)]), osc)
        .expect("send");
    subscribe(&listener, osc, &[OscArg::Float(2.0)]);
    let ack = receive_until(&listener, 5.0, |m| m.address == "/thermode/subscribed").expect("the port renews");
    assert_eq!(ack.args[0], OscArg::Float(2.0), "{ack:?}");
    assert_eq!(get_json(daemon.http_addr(), "/api/status")["osc"]["subscribers"], 1);
}

/// One 32-byte datagram yielded 20,000 times its size in telemetry. Now a subscriber gets at most
/// `osc_subscriber_bytes_per_s`: asked for 100 Hz of five channels (320 bytes a round, 32 kB/s) under a 4096 B/s
/// budget, the acknowledgement grants 12.8 Hz and the bytes received over 3 s stay within the budget plus its
/// quarter-second burst, while telemetry still flows.
#[test]
fn the_bytes_sent_to_a_subscriber_stay_within_its_budget() {
    let mut config = test_config();
    config.server.net.osc_subscriber_bytes_per_s = 4096.0;
    let daemon = start(config, SpyDevice::new(5), pipelines());
    let osc = daemon.osc_addr().expect("OSC listens on loopback");
    let socket = client();
    subscribe(&socket, osc, &[OscArg::Float(100.0)]);
    let ack = receive_until(&socket, 5.0, |m| m.address == "/thermode/subscribed").expect("acknowledged");
    let granted_hz = ack.args[0].as_f64().unwrap_or(f64::NAN);
    assert!((granted_hz - 12.8).abs() < 0.01, "granted {granted_hz} Hz: {ack:?}");
    receive_until(&socket, 5.0, |m| m.address == "/thermode/channel/4/telemetry").expect("telemetry");
    let window_s = 3.0;
    let end = Instant::now() + Duration::from_secs_f64(window_s);
    let (mut bytes, mut datagrams) = (0usize, 0usize);
    let mut buffer = [0u8; 2048];
    while Instant::now() < end {
        if let Ok((len, _)) = socket.recv_from(&mut buffer) {
            bytes += len;
            datagrams += 1;
        }
    }
    let cap = 4096.0 * window_s + 4096.0 / 4.0;
    println!("OSC byte cap: {bytes} bytes in {datagrams} datagrams over {window_s} s (cap 4096 B/s, bound {cap})");
    assert!((bytes as f64) <= cap, "{bytes} bytes in {window_s} s, more than {cap}");
    assert!(
        (bytes as f64) >= 0.5 * 4096.0 * window_s,
        "{bytes} bytes in {window_s} s: telemetry should still flow near the budget"
    );
}

/// The subscriber byte budget is a checked setting: below 1024 B/s (or not a number) is refused, naming the key; the
/// default is reported in `/api/status`.
#[test]
fn the_subscriber_byte_budget_is_checked_and_reported() {
    use thermode_serve::api::NetLimits;
    for bad in [100.0, f64::NAN, -1.0] {
        let limits = NetLimits {
            osc_subscriber_bytes_per_s: bad,
            ..NetLimits::default()
        };
        let message = limits.validate().map_err(|e| e.to_string());
        assert!(
            message
                .as_ref()
                .is_err_and(|m| m.contains("osc_subscriber_bytes_per_s")),
            "{bad}: {message:?}"
        );
    }
    let daemon = start(test_config(), SpyDevice::new(1), pipelines());
    let status = get_json(daemon.http_addr(), "/api/status");
    assert_eq!(
        status["osc"]["subscriber_bytes_per_s"].as_f64(),
        Some(NetLimits::default().osc_subscriber_bytes_per_s),
        "{}",
        status["osc"]
    );
}
