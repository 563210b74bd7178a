//! `POST /api/command` end to end on a running daemon (real clock, simulated five-finger display): the WebSocket's
//! replies and errors for the same requests, the token, malformed and oversize bodies, the rate cap shared by every
//! HTTP command, a request that needs a connection, and the lease that releases an HTTP client's contacts once it
//! stops sending commands.

use crate::common;

use std::net::SocketAddr;
use std::time::Instant;

use common::{
    ask, channel, client_runtime, get_json, http_post, http_request, pipelines, start, test_config, ws_connect,
    SpyDevice,
};
use serde_json::Value;

/// POSTs `body` to `/api/command` with `headers`: (HTTP status, the reply as JSON).
fn command_with(addr: SocketAddr, headers: &[(&str, &str)], body: &[u8]) -> (u16, Value) {
    let (status, text) = http_post(addr, "/api/command", headers, body);
    let reply = serde_json::from_str(&text).unwrap_or_else(|e| panic!("reply to POST is not JSON ({e}): {text:?}"));
    (status, reply)
}

fn command(addr: SocketAddr, body: &str) -> (u16, Value) {
    command_with(addr, &[("Content-Type", "application/json")], body.as_bytes())
}

/// The object's keys, sorted.
fn keys(value: &Value) -> Vec<String> {
    let mut keys: Vec<String> = value
        .as_object()
        .map(|o| o.keys().cloned().collect())
        .unwrap_or_default();
    keys.sort();
    keys
}

#[test]
fn a_touch_over_http_then_status_gives_the_websockets_replies() {
    let daemon = start(test_config(), SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let (code, touch) = command(addr, r#"{"type":"touch","id":"t1","channel":1,"material":"aluminium"}"#);
    assert_eq!(code, 200, "{touch}");
    let fields = (touch["type"].as_str(), touch["id"].as_str(), touch["request"].as_str());
    assert_eq!(fields, (Some("ok"), Some("t1"), Some("touch")), "{touch}");
    assert_eq!(
        (touch["channel"].as_u64(), touch["material"].as_str()),
        (Some(1), Some("aluminium"))
    );
    let (code, status) = command(addr, r#"{"type":"status","id":2}"#);
    assert_eq!(
        (code, status["type"].as_str(), status["id"].as_i64()),
        (200, Some("status"), Some(2))
    );
    let c = channel(&status, 1);
    assert_eq!(common::shows(c), "aluminium", "the HTTP touch is shown: {c}");
    let http_client = status["http"]["command_client"].as_u64().expect("a lease runs");
    assert_eq!(c["owner"]["kind"], "client", "{c}");
    assert_eq!(
        c["owner"]["id"].as_u64(),
        Some(http_client),
        "owned by the HTTP lease: {c}"
    );
    assert!(status["http"]["commands"].as_u64() >= Some(2), "{}", status["http"]);

    // The same requests over the WebSocket: the same reply (up to the tick and time), the same errors exactly.
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let ws_touch = ask(
            &mut ws,
            r#"{"type":"touch","id":"t1","channel":1,"material":"aluminium"}"#,
        )
        .await;
        assert_eq!(
            keys(&ws_touch),
            keys(&touch),
            "WebSocket {ws_touch} against HTTP {touch}"
        );
        for request in [
            r#"{"type":"touch","id":5,"channel":1,"material":"unobtainium"}"#,
            r#"{"type":"touch","id":6,"channel":9,"material":"wood"}"#,
            r#"{"type":"setpoint","id":7,"channel":0,"temp_c":60,"rate_c_s":1}"#,
            r#"{"type":"release","id":8,"channel":0,"colour":"red"}"#,
            r#"{"type":"fly","id":9}"#,
        ] {
            let over_ws = ask(&mut ws, request).await;
            let (code, over_http) = command(addr, request);
            assert_eq!(over_http, over_ws, "{request}: HTTP {code} against the WebSocket's");
            assert_eq!(code, 400, "{request}: {over_http}");
        }
    });
    let foreign = [("Origin", "http://evil.example"), ("Content-Type", "text/plain")];
    let (code, refused) = command_with(addr, &foreign, br#"{"type":"release","id":11,"channel":1}"#);
    assert_eq!(
        (code, refused["code"].as_str()),
        (403, Some("forbidden")),
        "a cross-site POST: {refused}"
    );
    let s = get_json(addr, "/api/status");
    assert_eq!(
        common::shows(channel(&s, 1)),
        "aluminium",
        "the cross-site POST changed nothing"
    );
    let (code, release) = command(addr, r#"{"type":"release","id":10,"channel":1}"#);
    assert_eq!((code, release["request"].as_str()), (200, Some("release")), "{release}");
    let s = get_json(addr, "/api/status");
    assert_eq!(common::shows(channel(&s, 1)), "air");
}

#[test]
fn without_the_token_or_with_a_wrong_one_a_command_is_refused_with_401() {
    let mut config = test_config();
    config.server.token = Some("s3cret-t0ken".into());
    let daemon = start(config, SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let touch = br#"{"type":"touch","id":1,"channel":0,"material":"wood"}"#;
    for headers in [vec![], vec![("Authorization", "Bearer wrong-token")]] {
        let (code, reply) = command_with(addr, &headers, touch);
        assert_eq!(code, 401, "{headers:?}: {reply}");
        assert_eq!(
            (reply["type"].as_str(), reply["code"].as_str()),
            (Some("error"), Some("unauthorized"))
        );
        assert!(reply["id"].is_null(), "{reply}");
    }
    let s = get_json(addr, "/api/status?token=s3cret-t0ken");
    assert_eq!(
        common::shows(channel(&s, 0)),
        "air",
        "a refused command changed nothing"
    );
    let (code, reply) = command_with(addr, &[("Authorization", "Bearer s3cret-t0ken")], touch);
    assert_eq!((code, reply["type"].as_str()), (200, Some("ok")), "{reply}");
    let (status, text) = http_post(
        addr,
        "/api/command?token=s3cret-t0ken",
        &[],
        br#"{"type":"status","id":2}"#,
    );
    assert_eq!(status, 200, "the token in the query, as for every route: {text}");
}

#[test]
fn malformed_bodies_and_requests_that_need_a_connection_are_refused_with_the_websockets_codes() {
    let daemon = start(test_config(), SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let cases: [(&[u8], u16, &str); 6] = [
        (b"{", 400, "bad_json"),
        (b"", 400, "bad_json"),
        (b"[1,2]", 400, "bad_json"),
        (b"{\"type\":\"status\",\"id\":1,\"x\":\"\xff\"}", 400, "bad_json"),
        (
            br#"{"type":"touch","channel":0,"material":"wood"}"#,
            400,
            "missing_field",
        ),
        (br#"{"type":"subscribe","id":3,"rate_hz":10}"#, 400, "unknown_type"),
    ];
    for (body, want_status, want_code) in cases {
        let (code, reply) = command_with(addr, &[], body);
        let shown = String::from_utf8_lossy(body);
        assert_eq!(
            (code, reply["code"].as_str()),
            (want_status, Some(want_code)),
            "{shown}: {reply}"
        );
        assert_eq!(reply["type"], "error", "{shown}: {reply}");
    }
    let (_, subscribe) = command(addr, r#"{"type":"unsubscribe","id":"u"}"#);
    let message = subscribe["message"].as_str().unwrap_or_default();
    assert!(message.contains("/api/ws"), "says where telemetry is: {message}");
    assert_eq!(subscribe["id"], "u", "the id is echoed: {subscribe}");
    let (code, text) = http_request(addr, "GET", "/api/command", &[], None);
    assert_eq!(code, 405, "GET: {text}");
    let reply: Value = serde_json::from_str(&text).expect("JSON");
    assert_eq!(reply["code"], "bad_value", "{reply}");
}

#[test]
fn oversize_bodies_get_too_large_and_a_long_program_fits_as_over_the_websocket() {
    let daemon = start(test_config(), SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let soft = format!(r#"{{"type":"status","id":4,"pad":"{}"}}"#, "x".repeat(20_000));
    let (code, reply) = command(addr, &soft);
    assert_eq!((code, reply["code"].as_str()), (413, Some("too_large")), "{reply}");
    assert!(
        reply["message"].as_str().unwrap_or_default().contains("16384"),
        "names the limit: {reply}"
    );
    let hard = format!(r#"{{"type":"program","id":5,"pad":"{}"}}"#, "x".repeat(200 * 1024));
    let (code, reply) = command(addr, &hard);
    assert_eq!((code, reply["code"].as_str()), (413, Some("too_large")), "{reply}");
    assert!(
        reply["message"].as_str().unwrap_or_default().contains("196608"),
        "names the limit: {reply}"
    );
    // 999 holds are above the 16 KiB of other requests and within the 192 KiB of a program.
    let holds = vec![r#"{"hold_s": 0.01}"#; 999].join(", ");
    let program = format!(r#"{{"type":"program","id":6,"channels":{{"2":[{holds}]}}}}"#);
    assert!(program.len() > 16 * 1024, "{} bytes", program.len());
    let mut reply = Value::Null;
    let started = common::wait_until(10.0, || {
        // The program needs the channel's first reading to start from: `busy` until then.
        reply = command(addr, &program).1;
        reply["code"] != "busy"
    });
    assert!(started, "{reply}");
    assert_eq!(
        (reply["type"].as_str(), reply["request"].as_str()),
        (Some("ok"), Some("program")),
        "{reply}"
    );
}

#[test]
fn every_http_command_together_has_one_connections_rate_cap() {
    let mut config = test_config();
    config.server.net.requests_per_s = 1.0;
    config.server.net.burst = 10.0;
    let daemon = start(config, SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let started = Instant::now();
    let replies: Vec<(u16, Value)> = (0..20)
        .map(|i| command(addr, &format!(r#"{{"type":"marker","id":{i},"text":"m{i}"}}"#)))
        .collect();
    let refill = started.elapsed().as_secs_f64().floor() as usize;
    let granted = replies.iter().filter(|(code, _)| *code == 200).count();
    assert!(
        (10..=10 + refill).contains(&granted),
        "burst 10 (+{refill} refilled at 1/s) granted, got {granted}: {replies:?}"
    );
    for (code, reply) in replies.iter().filter(|(code, _)| *code != 200) {
        assert_eq!((*code, reply["code"].as_str()), (429, Some("rate_limited")), "{reply}");
        assert!(reply["id"].is_i64(), "the id is echoed: {reply}");
    }
}

#[test]
fn an_http_clients_contacts_last_while_it_sends_commands_and_are_released_after_lease_and_grace() {
    let (lease_s, grace_s) = (1.0, 0.5);
    let mut config = test_config();
    config.server.net.command_lease_s = lease_s;
    config.core.loop_config.release_after_disconnect_s = grace_s;
    let daemon = start(config, SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let (code, reply) = command(addr, r#"{"type":"touch","id":1,"channel":3,"material":"steel"}"#);
    assert_eq!(code, 200, "{reply}");
    // Renewed every 0.3 s for 2.5 s (over twice lease + grace): the contact stays.
    let renewing = Instant::now();
    let mut last = Instant::now();
    while renewing.elapsed().as_secs_f64() < 2.5 {
        std::thread::sleep(std::time::Duration::from_millis(300));
        let (code, status) = command(addr, r#"{"type":"status","id":2}"#);
        last = Instant::now();
        assert_eq!(
            (code, common::shows(channel(&status, 3))),
            (200, "steel".to_string()),
            "renewed"
        );
    }
    let released = common::wait_until(lease_s + grace_s + 3.0, || {
        common::shows(channel(&get_json(addr, "/api/status"), 3)) == "air"
    });
    let after_s = last.elapsed().as_secs_f64();
    assert!(released, "released once the commands stopped");
    assert!(
        after_s >= lease_s + grace_s - 0.1,
        "released {after_s:.2} s after the last command, before the lease ({lease_s} s) and grace ({grace_s} s)"
    );
    let status = get_json(addr, "/api/status");
    assert!(
        status["http"]["command_client"].is_null(),
        "the lease ended: {}",
        status["http"]
    );
    // The next command opens a new lease under a new client number.
    let (_, reply) = command(addr, r#"{"type":"touch","id":3,"channel":3,"material":"wood"}"#);
    assert_eq!(reply["type"], "ok", "{reply}");
    let (_, status) = command(addr, r#"{"type":"status","id":4}"#);
    assert_eq!(common::shows(channel(&status, 3)), "wood");
}
