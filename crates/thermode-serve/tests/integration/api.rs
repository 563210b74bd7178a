//! The contact API end to end on a running daemon (real clock, simulated five-finger display, the render
//! pipelines): every WebSocket request and its reply, every error code, HTTP status and materials, limits, OSC,
//! and release of a vanished client's contacts.

use crate::common;

use std::net::UdpSocket;
use std::time::Duration;

use common::{
    ask, channel, client_runtime, get_json, http_get, next_json, pipelines, start, test_config, ws_connect, SpyDevice,
};
use futures_util::SinkExt;
use serde_json::{json, Value};
use thermode_serve::osc::{encode, OscArg};
use tokio_tungstenite::tungstenite::Message;

fn status_of(addr: std::net::SocketAddr) -> Value {
    get_json(addr, "/api/status")
}

#[test]
fn every_request_type_gets_its_reply_with_the_same_id() {
    let daemon = start(test_config(), SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let r = ask(&mut ws, r#"{"type":"touch","id":1,"channel":1,"material":"aluminium"}"#).await;
        assert_eq!((r["type"].as_str(), r["id"].as_i64(), r["request"].as_str()), (Some("ok"), Some(1), Some("touch")));
        assert_eq!((r["channel"].as_u64(), r["material"].as_str(), r["object_temp_c"].as_f64()), (Some(1), Some("aluminium"), Some(23.0)));
        assert!(r["tick"].is_u64() && r["time_s"].is_f64(), "{r}");
        let r = ask(
            &mut ws,
            r#"{"type":"touch","id":"custom","channel":2,"object_temp_c":30,
                "properties":{"name":"my-foam","conductivity_w_mk":0.03,"density_kg_m3":30,"specific_heat_j_kgk":1400}}"#,
        )
        .await;
        assert_eq!((r["id"].as_str(), r["material"].as_str()), (Some("custom"), Some("my-foam")), "{r}");
        let r = ask(&mut ws, r#"{"type":"setpoint","id":3,"channel":3,"temp_c":30,"rate_c_s":2}"#).await;
        assert_eq!((r["type"].as_str(), r["request"].as_str()), (Some("ok"), Some("setpoint")), "{r}");
        let status = ask(&mut ws, r#"{"type":"status","id":4}"#).await;
        assert_eq!(status["type"], "status");
        let contacts: Vec<String> = (0..5).map(|i| common::shows(channel(&status, i))).collect();
        assert_eq!(contacts, ["air", "aluminium", "my-foam", "direct", "air"]);
        assert_eq!(channel(&status, 3)["direct_temp_c"], 30.0);
        let r = ask(&mut ws, r#"{"type":"release","id":5,"channel":1}"#).await;
        assert_eq!((r["type"].as_str(), r["channel"].as_u64()), (Some("ok"), Some(1)), "{r}");
        let r = ask(&mut ws, r#"{"type":"clear_fault","id":6,"channel":0}"#).await;
        assert_eq!(r["type"], "ok", "clearing a channel without a fault is fine: {r}");
        let r = ask(&mut ws, r#"{"type":"subscribe","id":7,"rate_hz":20}"#).await;
        assert_eq!((r["type"].as_str(), r["rate_hz"].as_f64()), (Some("ok"), Some(20.0)), "{r}");
        let mut times = Vec::new();
        while times.len() < 4 {
            let m = next_json(&mut ws).await;
            if m["type"] == "telemetry" {
                check_telemetry(&m, 5);
                times.push(m["time_s"].as_f64().unwrap_or(f64::NAN));
            }
        }
        assert!(times.windows(2).all(|w| w[1] > w[0]), "telemetry times increase: {times:?}");
        let r = ask(&mut ws, r#"{"type":"unsubscribe","id":8}"#).await;
        assert_eq!(r["request"], "unsubscribe");
        let quiet = tokio::time::timeout(Duration::from_millis(400), next_json(&mut ws)).await;
        assert!(quiet.is_err(), "telemetry after unsubscribe: {quiet:?}");
        let r = ask(&mut ws, r#"{"type":"stop_all","id":9}"#).await;
        assert_eq!(r["request"], "stop_all");
    });
    let status = status_of(addr);
    for i in 0..5 {
        let c = channel(&status, i);
        assert_eq!(
            (common::shows(c).as_str(), c["held_off"].as_bool()),
            ("air", Some(true)),
            "{c}"
        );
    }
}

fn check_telemetry(m: &Value, channels: usize) {
    let list = m["channels"].as_array().expect("channels array");
    assert_eq!(list.len(), channels);
    for (i, c) in list.iter().enumerate() {
        assert_eq!(c["channel"], i);
        for key in [
            "target_skin_c",
            "skin_c",
            "display_setpoint_c",
            "sensor_c",
            "current_a",
            "hot_side_c",
        ] {
            assert!(c[key].is_number() || c[key].is_null(), "{key} in {c}");
        }
        assert!(
            c["contact"].is_boolean() && c["mode"].is_string() && c["fault"].is_u64(),
            "{c}"
        );
        assert_eq!(c["contact"], c["mode"] == "touch", "{c}");
        // The thermal dose: a number from the first tick on (restored or zero), never negative.
        for key in ["cem43_min", "time_at_or_above_43_s"] {
            assert!(c[key].as_f64().is_some_and(|v| v >= 0.0), "{key} in {c}");
        }
        assert!(c["dose_lockout"].is_boolean(), "{c}");
    }
    let skin = list[0]["skin_c"].as_f64().expect("a rendered skin temperature");
    assert!((20.0..40.0).contains(&skin), "skin {skin} °C");
}

#[test]
fn touching_cools_the_rendered_skin_and_the_sensor_follows() {
    let daemon = start(test_config(), SpyDevice::new(2), pipelines());
    let addr = daemon.http_addr();
    std::thread::sleep(Duration::from_millis(500));
    let before = status_of(addr);
    let rest_c = channel(&before, 0)["sensor_c"].as_f64().expect("sensor");
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let r = ask(&mut ws, r#"{"type":"touch","id":1,"channel":0,"material":"aluminium"}"#).await;
        assert_eq!(r["type"], "ok", "{r}");
        tokio::time::sleep(Duration::from_millis(2500)).await;
        let s = ask(&mut ws, r#"{"type":"status","id":2}"#).await;
        let (touched, idle) = (channel(&s, 0), channel(&s, 1));
        let cooled = touched["sensor_c"].as_f64().expect("sensor");
        let target = touched["target_skin_c"].as_f64().expect("target");
        assert!(
            cooled < rest_c - 1.0,
            "display after 2.5 s on aluminium {cooled} °C vs at rest {rest_c} °C"
        );
        assert!(
            target < idle["target_skin_c"].as_f64().expect("idle target") - 1.0,
            "{touched} vs {idle}"
        );
        assert_eq!(
            s["contacts"],
            json!([{"channel": 0, "material": "aluminium", "mode": "touch",
            "owner": {"kind": "client", "id": s["contacts"][0]["owner"]["id"]}}])
        );
    });
}

#[test]
fn bad_input_of_every_kind_gets_its_error_code_and_changes_nothing() {
    let daemon = start(test_config(), SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let status = client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let cases: &[(&str, &str, Value)] = &[
            ("{not json", "bad_json", Value::Null),
            ("[1,2,3]", "bad_json", Value::Null),
            (r#"{"type":"touch","id":1,"channel":0,"material":"wood","object_temp_c":NaN}"#, "bad_json", Value::Null),
            (r#"{"type":"touch","channel":0,"material":"wood"}"#, "missing_field", Value::Null),
            (r#"{"type":"teleport","id":"t"}"#, "unknown_type", json!("t")),
            (r#"{"id":2}"#, "missing_field", json!(2)),
            (r#"{"type":"touch","id":3,"channel":0}"#, "missing_field", json!(3)),
            (r#"{"type":"touch","id":4,"channel":0,"material":"wood","force_n":3}"#, "unknown_field", json!(4)),
            (r#"{"type":"touch","id":5,"channel":5,"material":"wood"}"#, "unknown_channel", json!(5)),
            (r#"{"type":"touch","id":6,"channel":-1,"material":"wood"}"#, "unknown_channel", json!(6)),
            (r#"{"type":"touch","id":7,"channel":1e300,"material":"wood"}"#, "bad_value", json!(7)),
            (r#"{"type":"touch","id":8,"channel":0,"material":"kryptonite"}"#, "unknown_material", json!(8)),
            (r#"{"type":"touch","id":9,"channel":0,"material":"wood","object_temp_c":1e308}"#, "bad_value", json!(9)),
            (r#"{"type":"touch","id":10,"channel":0,"material":"wood","object_temp_c":-400}"#, "bad_value", json!(10)),
            (r#"{"type":"touch","id":11,"channel":0,"properties":{"conductivity_w_mk":1e30,"density_kg_m3":1,"specific_heat_j_kgk":1}}"#, "bad_value", json!(11)),
            (r#"{"type":"touch","id":12,"channel":0,"properties":{"conductivity_w_mk":0,"density_kg_m3":1,"specific_heat_j_kgk":1}}"#, "bad_value", json!(12)),
            (r#"{"type":"setpoint","id":13,"channel":0,"temp_c":49,"rate_c_s":1}"#, "bad_value", json!(13)),
            (r#"{"type":"setpoint","id":14,"channel":0,"temp_c":30,"rate_c_s":-1}"#, "bad_value", json!(14)),
            (r#"{"type":"setpoint","id":15,"channel":0,"temp_c":"hot","rate_c_s":1}"#, "bad_value", json!(15)),
            (r#"{"type":"subscribe","id":16,"rate_hz":0}"#, "bad_value", json!(16)),
            (r#"{"type":"release","id":17}"#, "missing_field", json!(17)),
            (r#"{"type":"release","id":[1],"channel":0}"#, "bad_value", Value::Null),
        ];
        for (text, code, id) in cases {
            let sent: Value = serde_json::from_str(text).unwrap_or(Value::Null);
            ws.send(Message::Text(text.to_string().into())).await.expect("send");
            let reply = next_json(&mut ws).await;
            let _ = sent;
            assert_eq!(reply["type"], "error", "{text} → {reply}");
            assert_eq!(reply["code"], *code, "{text} → {reply}");
            assert_eq!(reply["id"], *id, "{text} → {reply}");
            assert!(reply["message"].as_str().is_some_and(|m| !m.is_empty()), "{reply}");
        }
        let big = format!(r#"{{"type":"status","id":99,"pad":"{}"}}"#, "x".repeat(20_000));
        ws.send(Message::Text(big.into())).await.expect("send");
        assert_eq!(next_json(&mut ws).await["code"], "too_large");
        ws.send(Message::Binary(vec![1, 2, 3].into())).await.expect("send");
        assert_eq!(next_json(&mut ws).await["code"], "bad_json");
        let r = ask(&mut ws, r#"{"type":"status","id":100}"#).await;
        assert_eq!(r["type"], "status", "the connection survives all of it");
        // Read while the connection is open: its close queues a (counted) client-gone command.
        status_of(addr)
    });
    assert_eq!(status["contacts"], json!([]), "nothing changed");
    assert!(status["channels"]
        .as_array()
        .expect("channels")
        .iter()
        .all(|c| c["held_off"] == false));
    assert_eq!(status["commands"]["applied"], 0, "no command reached the loop");
}

#[test]
fn a_flood_is_rate_limited_and_the_connection_recovers() {
    let daemon = start(test_config(), SpyDevice::new(2), common::trackers());
    client_runtime().block_on(async {
        let mut ws = ws_connect(daemon.http_addr(), "").await;
        let n = 400;
        let started = std::time::Instant::now();
        for i in 0..n {
            let text = format!(r#"{{"type":"status","id":{i}}}"#);
            ws.send(Message::Text(text.into())).await.expect("send");
        }
        let mut codes = std::collections::BTreeMap::new();
        for _ in 0..n {
            let reply = next_json(&mut ws).await;
            let key = reply["code"]
                .as_str()
                .unwrap_or(reply["type"].as_str().unwrap_or("?"))
                .to_string();
            *codes.entry(key).or_insert(0) += 1;
        }
        let elapsed_s = started.elapsed().as_secs_f64();
        let answered = codes.get("status").copied().unwrap_or(0);
        let limited = codes.get("rate_limited").copied().unwrap_or(0);
        // Token bucket: the burst of 100 plus 50 per second of the flood's duration.
        let most = 100.0 + 50.0 * elapsed_s;
        assert_eq!(answered + limited, n, "{codes:?}");
        assert!(
            answered >= 100 && answered as f64 <= most + 1.0,
            "{codes:?} over {elapsed_s} s (at most {most})"
        );
        tokio::time::sleep(Duration::from_millis(1100)).await;
        let r = ask(&mut ws, r#"{"type":"release","id":"after","channel":0}"#).await;
        assert_eq!(r["type"], "ok", "tokens refill: {r}");
    });
}

#[test]
fn frames_beyond_the_hard_limit_close_the_connection_without_harm() {
    let daemon = start(test_config(), SpyDevice::new(2), common::trackers());
    let addr = daemon.http_addr();
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let huge = "x".repeat(200_000);
        let _ = ws.send(Message::Text(huge.into())).await;
        let closed = async {
            loop {
                match futures_util::StreamExt::next(&mut ws).await {
                    Some(Ok(Message::Ping(_) | Message::Pong(_))) => continue,
                    None | Some(Err(_)) | Some(Ok(Message::Close(_))) => return true,
                    Some(Ok(other)) => panic!("expected the connection to close, got {other:?}"),
                }
            }
        };
        let closed = tokio::time::timeout(Duration::from_secs(10), closed).await;
        assert_eq!(closed, Ok(true), "the connection closes within 10 s");
        let mut again = ws_connect(addr, "").await;
        assert_eq!(ask(&mut again, r#"{"type":"status","id":1}"#).await["type"], "status");
    });
}

#[test]
fn http_status_and_materials() {
    let daemon = start(test_config(), SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    assert!(common::wait_until(5.0, || status_of(addr)["loop"]["window_ticks"]
        .as_u64()
        .unwrap_or(0)
        > 50));
    let s = status_of(addr);
    assert_eq!(
        (
            s["channel_count"].as_u64(),
            s["device"].as_str(),
            s["running"].as_bool()
        ),
        (Some(5), Some("sim"), Some(true))
    );
    let l = &s["loop"];
    assert_eq!(l["rate_hz"], 100.0);
    let (p50, p99, max) = (
        l["period_p50_s"].as_f64(),
        l["period_p99_s"].as_f64(),
        l["period_max_s"].as_f64(),
    );
    let (p50, p99, max) = (p50.expect("p50"), p99.expect("p99"), max.expect("max"));
    assert!(
        p50 > 0.0 && p50 <= p99 && p99 <= max,
        "p50 {p50} ≤ p99 {p99} ≤ max {max}"
    );
    assert!((p50 - 0.01).abs() < 0.005, "median period {p50} s at 100 Hz");
    assert!(
        l["missed_deadlines"].is_u64() && l["ticks"].as_u64().unwrap_or(0) > 50,
        "{l}"
    );
    assert_eq!(s["auth"]["token_required"], false);
    assert_eq!(s["faults"], json!([]));
    let materials = get_json(addr, "/api/materials");
    let list = materials.as_array().expect("array");
    let library = thermode_model::materials::library();
    assert_eq!(list.len(), library.len());
    for (m, want) in list.iter().zip(&library) {
        assert_eq!(m["name"], want.name.as_str());
        // JSON text round trips to within the last bit of a double
        let close = |key: &str, value: f64| {
            let got = m[key].as_f64().unwrap_or(f64::NAN);
            assert!(
                (got - value).abs() <= 1e-12 * value.abs(),
                "{} {key}: {got} vs {value}",
                want.name
            );
        };
        close("conductivity_w_mk", want.conductivity_w_mk);
        close("density_kg_m3", want.density_kg_m3);
        close("specific_heat_j_kgk", want.specific_heat_j_kgk);
        close("thickness_m", want.thickness_m);
        close("effusivity", want.effusivity());
    }
    let (code, body) = http_get(addr, "/", &[]);
    assert_eq!(code, 200);
    assert!(body.contains("STOP ALL") && body.contains("/api/ws"), "dashboard page");
    let (code, body) = http_get(addr, "/nope", &[]);
    assert_eq!(code, 404);
    assert!(body.contains("\"type\":\"error\""), "{body}");
}

#[test]
fn osc_touch_release_stop_and_malformed_packets() {
    let daemon = start(test_config(), SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let osc = daemon.osc_addr().expect("OSC listens on loopback");
    let socket = UdpSocket::bind("127.0.0.1:0").expect("udp");
    let send = |packet: &[u8]| {
        socket.send_to(packet, osc).expect("send");
    };
    let contact = |i: usize| common::shows(&status_of(addr)["channels"][i]);
    send(&encode("/thermode/channel/3/touch", &[OscArg::Str("steel".into())]));
    assert!(
        common::wait_until(5.0, || contact(3) == "steel"),
        "OSC touch: {}",
        contact(3)
    );
    send(&encode(
        "/thermode/channel/4/touch",
        &[OscArg::Str("wood".into()), OscArg::Float(30.0)],
    ));
    assert!(common::wait_until(5.0, || contact(4) == "wood"));
    assert_eq!(status_of(addr)["channels"][4]["object_temp_c"], 30.0);
    send(&encode("/thermode/channel/3/release", &[OscArg::Float(1.0)]));
    assert!(common::wait_until(5.0, || contact(3) == "air"), "OSC release");
    let before = status_of(addr)["osc"].clone();
    send(b"\xff\x00garbage");
    send(&encode("/thermode/channel/9/touch", &[OscArg::Str("wood".into())]));
    send(&encode(
        "/thermode/channel/0/touch",
        &[OscArg::Str("kryptonite".into())],
    ));
    send(&encode(
        "/thermode/channel/0/touch",
        &[OscArg::Str("wood".into()), OscArg::Float(f32::NAN)],
    ));
    let settled = common::wait_until(5.0, || {
        let o = &status_of(addr)["osc"];
        o["malformed"].as_u64() > before["malformed"].as_u64()
            && o["refused"].as_u64() >= Some(before["refused"].as_u64().unwrap_or(0) + 3)
    });
    assert!(settled, "{}", status_of(addr)["osc"]);
    assert_eq!(contact(0), "air", "refused OSC changed nothing");
    send(&encode("/thermode/stop", &[]));
    assert!(common::wait_until(5.0, || contact(4) == "air"
        && status_of(addr)["channels"][4]["held_off"] == true));
}

#[test]
fn a_vanished_clients_contacts_are_released_after_the_grace_period() {
    let mut config = test_config();
    config.core.loop_config.release_after_disconnect_s = 1.0;
    let daemon = start(config, SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let rt = client_runtime();
    rt.block_on(async {
        let mut ws = ws_connect(addr, "").await;
        assert_eq!(
            ask(&mut ws, r#"{"type":"touch","id":1,"channel":2,"material":"aluminium"}"#).await["type"],
            "ok"
        );
        let mut other = ws_connect(addr, "").await;
        assert_eq!(
            ask(&mut other, r#"{"type":"touch","id":1,"channel":3,"material":"wood"}"#).await["type"],
            "ok"
        );
        drop(ws); // the TCP connection closes without a WebSocket close frame, as when a client is killed
        let pending = common::wait_until(5.0, || !status_of(addr)["channels"][2]["release_at_s"].is_null());
        assert!(pending, "a release is scheduled");
        let s = status_of(addr);
        let c = channel(&s, 2);
        assert_eq!(
            common::shows(c),
            "aluminium",
            "still touching during the grace period: {c}"
        );
        let released = common::wait_until(10.0, || common::shows(&status_of(addr)["channels"][2]) == "air");
        assert!(released, "released after the grace period");
        let s = status_of(addr);
        assert_eq!(
            common::shows(channel(&s, 3)),
            "wood",
            "the connected client's contact stays"
        );
        drop(other);
    });
}

/// The `bad_value` message of a refused WebSocket request, and the OSC refusal of the same stimulus (its
/// `last_error`), once the OSC listener has counted it.
fn refusals(
    daemon: &thermode_serve::Daemon,
    ws_request: &str,
    osc_address: &str,
    osc_args: &[OscArg],
) -> (String, String) {
    let addr = daemon.http_addr();
    let reply = client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        ask(&mut ws, ws_request).await
    });
    assert_eq!(
        (reply["type"].as_str(), reply["code"].as_str()),
        (Some("error"), Some("bad_value")),
        "{reply}"
    );
    let refused_before = status_of(addr)["osc"]["refused"].as_u64().unwrap_or(0);
    let socket = UdpSocket::bind("127.0.0.1:0").expect("udp");
    let osc = daemon.osc_addr().expect("OSC listens on loopback");
    socket.send_to(&encode(osc_address, osc_args), osc).expect("send");
    assert!(common::wait_until(5.0, || status_of(addr)["osc"]["refused"].as_u64()
        > Some(refused_before)));
    let osc_error = status_of(addr)["osc"]["last_error"].as_str().unwrap_or("").to_string();
    let ws_error = format!("{osc_address} bad_value: {}", reply["message"].as_str().unwrap_or(""));
    (ws_error, osc_error)
}

#[test]
fn a_stimulus_beyond_the_channels_limits_is_refused_identically_over_websocket_and_osc() {
    let daemon = start(test_config(), SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    let envelope = thermode_pipeline::pipeline::render_envelope(&thermode_device::DeviceConfig::default());
    let too_fast = envelope.max_setpoint_rate_c_per_s + 5.0;
    let (ws, osc) = refusals(
        &daemon,
        &format!(r#"{{"type":"setpoint","id":1,"channel":0,"temp_c":30,"rate_c_s":{too_fast}}}"#),
        "/thermode/channel/0/setpoint",
        &[OscArg::Float(30.0), OscArg::Float(too_fast as f32)],
    );
    assert_eq!(ws, osc, "a too fast ramp");
    assert!(ws.contains("set-point rate"), "{ws}");
    let too_hot = thermode_pipeline::stimulus::OBJECT_TEMPERATURE.max + 1.0;
    let (ws, osc) = refusals(
        &daemon,
        &format!(r#"{{"type":"touch","id":2,"channel":1,"material":"wood","object_temp_c":{too_hot}}}"#),
        "/thermode/channel/1/touch",
        &[OscArg::Str("wood".into()), OscArg::Float(too_hot as f32)],
    );
    assert_eq!(ws, osc, "a too hot object");
    let (ws, osc) = refusals(
        &daemon,
        r#"{"type":"setpoint","id":3,"channel":2,"temp_c":49,"rate_c_s":1}"#,
        "/thermode/channel/2/setpoint",
        &[OscArg::Float(49.0), OscArg::Float(1.0)],
    );
    assert_eq!(ws, osc, "a display temperature above the envelope's maximum");
    let contacts = status_of(addr)["contacts"].clone();
    assert_eq!(contacts, json!([]), "nothing refused reached a channel");
    // The channels run the render envelope (20 °C/s), so a ramp faster than the envelope's general default
    // (10 °C/s) but within the channel's limit is accepted: the API enforces what the channels enforce.
    let fast = client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        ask(
            &mut ws,
            r#"{"type":"setpoint","id":4,"channel":3,"temp_c":30,"rate_c_s":15}"#,
        )
        .await
    });
    assert_eq!(fast["type"], "ok", "{fast}");
}

#[test]
fn the_status_limits_are_those_of_the_envelope_the_channels_run() {
    use thermode_device::DeviceConfig;
    use thermode_pipeline::{ControllerKind, PipelineConfig};
    let mut pipeline = PipelineConfig::new(DeviceConfig::default(), ControllerKind::Model);
    pipeline.envelope.min_display_c = 18.0;
    pipeline.envelope.max_display_c = 44.0;
    pipeline.envelope.max_setpoint_rate_c_per_s = 7.0;
    let envelope = pipeline.envelope;
    let engines = thermode_runtime::engine::pipeline_engines(pipeline);
    let daemon = start(test_config(), SpyDevice::new(2), engines);
    let addr = daemon.http_addr();
    let limits = status_of(addr)["limits"].clone();
    let published = |key: &str| limits[key].as_f64().unwrap_or(f64::NAN);
    assert_eq!(
        [
            published("display_min_c"),
            published("display_max_c"),
            published("max_rate_c_s")
        ],
        [
            envelope.min_display_c,
            envelope.max_display_c,
            envelope.max_setpoint_rate_c_per_s
        ],
        "{limits}"
    );
    assert_eq!(
        [published("object_temp_min_c"), published("object_temp_max_c")],
        [
            thermode_pipeline::stimulus::OBJECT_TEMPERATURE.min,
            thermode_pipeline::stimulus::OBJECT_TEMPERATURE.max
        ],
        "{limits}"
    );
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let edge = r#"{"type":"setpoint","id":1,"channel":0,"temp_c":18,"rate_c_s":7}"#;
        assert_eq!(
            ask(&mut ws, edge).await["type"],
            "ok",
            "the published limits are accepted"
        );
        for (i, (temp_c, rate_c_per_s)) in [(17.9, 1.0), (44.1, 1.0), (30.0, 7.1)].into_iter().enumerate() {
            let text =
                format!(r#"{{"type":"setpoint","id":{i},"channel":1,"temp_c":{temp_c},"rate_c_s":{rate_c_per_s}}}"#);
            assert_eq!(ask(&mut ws, &text).await["code"], "bad_value", "{text}");
        }
    });
}

#[test]
fn the_status_reports_the_rendering_rate_of_the_device_file() {
    use thermode_device::DeviceConfig;
    use thermode_pipeline::{ControllerKind, PipelineConfig};
    // A display with a stronger module renders at 60 °C/s (its device file's render.max_setpoint_rate_c_per_s):
    // that is the rate its channels enforce, so it is what /api/status publishes and what a ramp may ask for.
    let device = DeviceConfig::from_toml_str("[render]\nmax_setpoint_rate_c_per_s = 60\n", "fast.toml")
        .unwrap_or_else(|e| panic!("{e}"));
    let pipeline = PipelineConfig::new(device, ControllerKind::Model);
    assert_eq!(pipeline.envelope.max_setpoint_rate_c_per_s, 60.0);
    let engines = thermode_runtime::engine::pipeline_engines(pipeline);
    let daemon = start(test_config(), SpyDevice::new(1), engines);
    let addr = daemon.http_addr();
    let published = status_of(addr)["limits"]["max_rate_c_s"].as_f64().unwrap_or(f64::NAN);
    assert_eq!(published, 60.0, "published rate limit");
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let fast = r#"{"type":"setpoint","id":1,"channel":0,"temp_c":30,"rate_c_s":55}"#;
        let reply = ask(&mut ws, fast).await;
        assert_eq!(reply["type"], "ok", "{reply}");
        let too_fast = r#"{"type":"setpoint","id":2,"channel":0,"temp_c":30,"rate_c_s":61}"#;
        let reply = ask(&mut ws, too_fast).await;
        assert_eq!(reply["code"], "bad_value", "{reply}");
    });
}

#[test]
fn a_marker_without_lsl_is_acknowledged_with_the_loop_time_between_two_ticks() {
    let daemon = start(test_config(), SpyDevice::new(2), pipelines());
    let addr = daemon.http_addr();
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let before = ask(&mut ws, r#"{"type":"release","id":1,"channel":0}"#).await;
        let r = ask(
            &mut ws,
            r#"{"type":"marker","id":2,"text":"trial 1 start","channel":1}"#,
        )
        .await;
        assert_eq!(
            (r["type"].as_str(), r["request"].as_str(), r["channel"].as_u64()),
            (Some("ok"), Some("marker"), Some(1)),
            "{r}"
        );
        assert_eq!(
            (r["lsl"].as_bool(), r["lsl_time_s"].is_null()),
            (Some(false), true),
            "{r}"
        );
        let after = ask(&mut ws, r#"{"type":"release","id":3,"channel":0}"#).await;
        let (t0, t, t1) = (
            before["time_s"].as_f64().unwrap(),
            r["time_s"].as_f64().unwrap(),
            after["time_s"].as_f64().unwrap(),
        );
        // The marker's loop time lies between the ticks that applied the requests sent before and after it (one
        // period of slack on each side: a reply's time is its tick's deadline, the marker's the clock when received).
        let period = 0.01;
        assert!(
            t0 - period <= t && t <= t1 + period,
            "marker at {t} s, outside [{t0}, {t1}] s"
        );
        let r = ask(&mut ws, r#"{"type":"marker","id":4,"text":"x","channel":7}"#).await;
        assert_eq!(r["code"], "unknown_channel", "{r}");
    });
    let status = get_json(addr, "/api/status");
    assert!(status["lsl"].is_null(), "no LSL without --lsl: {}", status["lsl"]);
}

/// A temperature-commanded device without a hot-side sensor (as a TCS II): its status and telemetry give the current,
/// the model's finger estimate and the hot side as null, never the controller's or the model's numbers; the plate
/// reading and the set-point stay numbers. The same daemon on a device that measures everything gives numbers.
/// Decimals of `value` as JSON writes it (0 for an integer).
fn decimals(value: &Value) -> usize {
    let text = value.to_string();
    text.split_once('.').map_or(0, |(_, fraction)| {
        fraction.trim_end_matches(|c: char| !c.is_ascii_digit()).len()
    })
}

#[test]
fn times_in_replies_and_status_are_whole_nanoseconds() {
    let daemon = start(test_config(), SpyDevice::new(2), pipelines());
    let addr = daemon.http_addr();
    let mut times = Vec::new();
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        for id in 1..=20 {
            let r = ask(
                &mut ws,
                &format!(r#"{{"type":"touch","id":{id},"channel":0,"material":"wood"}}"#),
            )
            .await;
            assert_eq!(r["type"], "ok", "{r}");
            times.push(r["time_s"].clone());
            tokio::time::sleep(Duration::from_millis(7)).await;
        }
    });
    let status = status_of(addr);
    times.push(status["time_s"].clone());
    for key in [
        "period_p50_s",
        "period_p99_s",
        "period_max_s",
        "work_p50_s",
        "work_p99_s",
        "work_max_s",
    ] {
        // Null until the loop has its statistics window.
        times.extend(Some(status["loop_stats"][key].clone()).filter(|v| !v.is_null()));
    }
    for time in &times {
        assert!(
            time.is_f64() && decimals(time) <= 9,
            "time {time}: more decimals than the clock's nanosecond"
        );
    }
    daemon.shutdown().expect("shutdown");
}

#[test]
fn numbers_a_device_does_not_measure_are_null() {
    let fields = ["current_a", "finger_c", "hot_side_c"];
    for (measures, null) in [
        (
            thermode_device::Measures {
                drive_current: false,
                hot_side: false,
            },
            true,
        ),
        (thermode_device::Measures::ALL, false),
    ] {
        let mut device = SpyDevice::new(2);
        device.measures = measures;
        let daemon = start(test_config(), device, pipelines());
        let addr = daemon.http_addr();
        client_runtime().block_on(async {
            let mut ws = ws_connect(addr, "").await;
            let r = ask(&mut ws, r#"{"type":"touch","id":1,"channel":0,"material":"aluminium"}"#).await;
            assert_eq!(r["type"], "ok", "{r}");
            tokio::time::sleep(Duration::from_millis(300)).await;
        });
        let status = status_of(addr);
        let c = channel(&status, 0);
        for field in fields {
            assert_eq!(c[field].is_null(), null, "{field} with {measures:?}: {c}");
        }
        assert!(c["sensor_c"].is_f64() && c["display_setpoint_c"].is_f64(), "{c}");
        daemon.shutdown().expect("shutdown");
    }
}
