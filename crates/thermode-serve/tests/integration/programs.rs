//! Stimulus programs and responses through the daemon: the segment limit, one start tick for every channel (in the
//! recording), a response ending an `until: response` ramp within a tick of its reply with the return at its
//! rate, targets clipped to the display's range with `cutoff_c`, and the events subscribers get.

use serde_json::{json, Value};
use thermode_serve::{Daemon, DaemonConfig};

use crate::common::{self, ask, client_runtime, next_json, ws_connect, SpyDevice};

/// A daemon of `channels` simulated channels with the render pipelines at `rate_hz`, recording into `dir`, once
/// every channel has a first reading (a program starts from the display's temperature).
fn daemon(channels: usize, rate_hz: f64, dir: &std::path::Path) -> Daemon {
    daemon_with(channels, rate_hz, dir, common::test_config())
}

/// [`daemon`] from `config`.
fn daemon_with(channels: usize, rate_hz: f64, dir: &std::path::Path, mut config: DaemonConfig) -> Daemon {
    config.core.loop_config.rate_hz = rate_hz;
    config.core.record_dir = Some(dir.to_path_buf());
    let daemon = common::start(config, SpyDevice::new(channels), common::pipelines());
    let addr = daemon.http_addr();
    let measured = || {
        let status = common::get_json(addr, "/api/status");
        (0..channels).all(|i| status["channels"][i]["sensor_c"].is_number())
    };
    assert!(common::wait_until(10.0, measured), "no first reading within 10 s");
    daemon
}

/// A CSV file as its header's columns and rows of fields.
fn csv(path: &std::path::Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text
        .lines()
        .map(|l| l.split(',').map(str::to_string).collect::<Vec<_>>());
    (lines.next().expect("header"), lines.collect())
}

/// The field `name` of `row` under `header`.
fn field<'a>(header: &[String], row: &'a [String], name: &str) -> &'a str {
    let i = header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no {name}"));
    &row[i]
}

/// The recording's rows as (time \[s\], channel, display set-point \[°C\]).
fn recorded(path: &std::path::Path) -> Vec<(f64, usize, f64)> {
    let (header, rows) = csv(path);
    let number = |row: &[String], name: &str| field(&header, row, name).parse::<f64>().unwrap_or(f64::NAN);
    rows.iter()
        .map(|r| {
            (
                number(r, "time_s"),
                number(r, "channel") as usize,
                number(r, "display_setpoint_c"),
            )
        })
        .collect()
}

/// The session's program events (`<session>.events.csv`) as (tick, time \[s\], channel, event, segment).
fn recorded_events(session: &std::path::Path) -> Vec<(u64, f64, usize, String, String)> {
    let (header, rows) = csv(&thermode_serve::program_events::events_csv_path(session));
    assert_eq!(header.join(","), thermode_serve::program_events::EVENTS_CSV_HEADER);
    rows.iter()
        .map(|r| {
            let text = |name: &str| field(&header, r, name).to_string();
            let tick = text("tick").parse().expect("tick");
            let time_s = text("time_s").parse().expect("time_s");
            (
                tick,
                time_s,
                text("channel").parse().expect("channel"),
                text("event"),
                text("segment"),
            )
        })
        .collect()
}

/// Sends `text` and returns its reply, keeping the program events that arrive meanwhile in `events`.
async fn ask_keeping(ws: &mut common::Ws, text: &str, events: &mut Vec<Value>) -> Value {
    use futures_util::SinkExt;
    let id = serde_json::from_str::<Value>(text).expect("JSON")["id"].clone();
    ws.send(tokio_tungstenite::tungstenite::Message::Text(text.to_string().into()))
        .await
        .expect("send");
    loop {
        let message = next_json(ws).await;
        if message["type"] == "program_event" {
            events.push(message);
        } else if message["type"] != "telemetry" && message["id"] == id {
            return message;
        }
    }
}

/// A program message of one channel's `segments`.
fn program(id: u64, channel: usize, segments: Value) -> String {
    json!({"type": "program", "id": id, "channels": {channel.to_string(): segments}}).to_string()
}

#[test]
fn a_999_segment_program_is_accepted_and_a_1000_segment_one_refused_naming_the_limit() {
    let dir = tempfile::tempdir().expect("temp dir");
    let daemon = daemon(1, 100.0, dir.path());
    client_runtime().block_on(async {
        let mut ws = ws_connect(daemon.http_addr(), "").await;
        let segment = json!({"to_c": 31.5, "rate_c_s": 1.0, "until": "response"});
        let many = |n: usize| Value::Array(vec![segment.clone(); n]);
        let accepted = ask(&mut ws, &program(1, 0, many(999))).await;
        assert_eq!(accepted["type"], "ok", "999 segments: {accepted}");
        assert_eq!(accepted["request"], "program", "{accepted}");
        let refused = ask(&mut ws, &program(2, 0, many(1000))).await;
        assert_eq!(refused["type"], "error", "1000 segments: {refused}");
        assert_eq!(refused["code"], "bad_value", "{refused}");
        let message = refused["message"].as_str().unwrap_or_default();
        assert!(
            message.contains("999") && message.contains("1000"),
            "the limit is named: {message}"
        );
    });
}

#[test]
fn a_flood_of_long_programs_gets_a_reply_to_each_by_its_id_and_a_second_client_still_stops_all() {
    use futures_util::SinkExt;
    use tokio_tungstenite::tungstenite::Message;
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = common::test_config();
    // A bucket of 20 requests refilled at 1 per second: of 150 sent back to back, most are refused.
    (config.server.net.requests_per_s, config.server.net.burst) = (1.0, 20.0);
    let daemon = daemon_with(2, 100.0, dir.path(), config);
    client_runtime().block_on(async {
        let mut flood = ws_connect(daemon.http_addr(), "").await;
        // 999 holds on each channel: about 34 KB, read on the blocking pool (above the 16 KiB read inline).
        let holds = Value::Array(vec![json!({"hold_s": 0.01}); 999]);
        let n = 150u64;
        for id in 0..n {
            let text = json!({"type": "program", "id": id, "channels": {"0": holds, "1": holds}}).to_string();
            flood.send(Message::Text(text.into())).await.expect("send");
        }
        let mut stopper = ws_connect(daemon.http_addr(), "").await;
        let stopped = ask(&mut stopper, r#"{"type":"stop_all","id":"stop"}"#).await;
        assert_eq!(stopped["type"], "ok", "stop_all beside the flood: {stopped}");
        let (mut ids, mut limited) = (Vec::new(), 0);
        while (ids.len() as u64) < n {
            let reply = next_json(&mut flood).await;
            if reply["type"] == "program_event" || reply["type"] == "telemetry" {
                continue;
            }
            limited += usize::from(reply["code"] == "rate_limited");
            ids.push(
                reply["id"]
                    .as_u64()
                    .unwrap_or_else(|| panic!("a reply without the id: {reply}")),
            );
        }
        assert_eq!(
            ids,
            (0..n).collect::<Vec<_>>(),
            "one reply per program, in order, each with its id"
        );
        assert!(limited >= 100, "{limited} of {n} refused as rate_limited");
    });
}

#[test]
fn a_five_channel_program_changes_every_channel_s_set_point_first_on_one_tick_of_the_recording() {
    let dir = tempfile::tempdir().expect("temp dir");
    let daemon = daemon(5, 1000.0, dir.path());
    let path = daemon.recording_path().expect("recording");
    let addr = daemon.http_addr();
    // A program that arrives before a channel's first sample starts on its tick but cannot move a set-point until
    // the samples are there (no shaping without a measurement; the display samples at 100 Hz): wait for every
    // channel's readings over the first 0.1 s.
    let measured = (0..5000).any(|_| {
        let ready = daemon
            .snapshot()
            .is_some_and(|s| s.time_s >= 0.1 && s.channels.iter().all(|c| c.telemetry.sensor_c.is_finite()));
        if !ready {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        ready
    });
    assert!(measured, "no channel measured within 5000 polls of the snapshot");
    let reply = client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        // A grill-like pattern: alternate bars step to 20 and 40 °C (40 within the display), then hold.
        let channels: serde_json::Map<String, Value> = (0..5)
            .map(|c| {
                let to_c = if c % 2 == 0 { 20.0 } else { 40.0 };
                (c.to_string(), json!([{"to_c": to_c, "rate_c_s": 5.0}, {"hold_s": 0.2}]))
            })
            .collect();
        let text = json!({"type": "program", "id": 1, "channels": channels}).to_string();
        ask(&mut ws, &text).await
    });
    assert_eq!(reply["type"], "ok", "{reply}");
    assert_eq!(reply["channels"], json!([0, 1, 2, 3, 4]), "{reply}");
    std::thread::sleep(std::time::Duration::from_millis(1500));
    daemon.shutdown().expect("shutdown");
    let start_s = reply["start_time_s"].as_f64().expect("start_time_s");
    let rows = recorded(&path);
    for channel in 0..5 {
        // From the tick before the program on (in air before it, the set-point follows the plate's estimate as
        // the daemon starts).
        let mine: Vec<_> = rows
            .iter()
            .filter(|r| r.1 == channel && r.0 > start_s - 0.0015)
            .collect();
        let first = mine
            .windows(2)
            .find(|w| (w[1].2 - w[0].2).abs() > 1e-6)
            .map(|w| w[1])
            .unwrap_or_else(|| panic!("channel {channel}'s set-point never changed"));
        assert!(
            (first.0 - start_s).abs() < 5e-7,
            "channel {channel}: first set-point change at {} s, the program's start tick at {start_s} s",
            first.0
        );
    }
    let start_tick = reply["start_tick"].as_u64().expect("start_tick");
    let starts: Vec<_> = recorded_events(&path)
        .into_iter()
        .filter(|e| e.3 == "segment_start" && e.4 == "0")
        .collect();
    assert_eq!(starts.len(), 5, "one start of segment 0 per channel: {starts:?}");
    for (tick, time_s, channel, _, _) in starts {
        assert_eq!(
            tick, start_tick,
            "channel {channel}'s first segment starts on the reply's tick"
        );
        assert!(
            (time_s - start_s).abs() < 5e-7,
            "channel {channel}: {time_s} s against {start_s} s"
        );
    }
}

#[test]
fn a_response_ends_an_until_response_ramp_within_a_tick_of_its_reply_and_the_return_runs_at_its_rate() {
    let dir = tempfile::tempdir().expect("temp dir");
    let daemon = daemon(1, 1000.0, dir.path());
    let path = daemon.recording_path().expect("recording");
    let addr = daemon.http_addr();
    let (started, response, events) = client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let mut events = Vec::new();
        // The method of limits: towards 0 °C at 1 °C/s until the response, back to 32 °C at 1 °C/s.
        let segments = json!([{"to_c": 0, "rate_c_s": 1, "until": "response"}, {"to_c": 32, "rate_c_s": 1}]);
        let started = ask_keeping(&mut ws, &program(1, 0, segments), &mut events).await;
        tokio::time::sleep(std::time::Duration::from_millis(1500)).await;
        let text = r#"{"type":"response","id":2,"channel":0,"kind":"button"}"#;
        let response = ask_keeping(&mut ws, text, &mut events).await;
        while events.len() < 4 {
            let message = next_json(&mut ws).await;
            if message["type"] == "program_event" {
                events.push(message);
            }
        }
        (started, response, events)
    });
    std::thread::sleep(std::time::Duration::from_millis(500));
    daemon.shutdown().expect("shutdown");
    assert_eq!(started["type"], "ok", "{started}");
    assert_eq!(response["type"], "ok", "{response}");
    assert_eq!(response["ended_segment"], 0, "the response ended the ramp: {response}");
    let (tick, reply_s) = (
        response["tick"].as_u64().expect("tick"),
        response["time_s"].as_f64().expect("time"),
    );
    let kinds: Vec<&str> = events.iter().map(|e| e["event"].as_str().unwrap_or("?")).collect();
    assert_eq!(
        kinds,
        ["segment_start", "response", "segment_start", "program_end"],
        "{events:?}"
    );
    assert_eq!(events[1]["tick"], tick, "the response event is on the reply's tick");
    assert_eq!(events[2]["tick"], tick, "the return starts on the reply's tick");
    let rows = recorded(&path);
    let at = rows
        .iter()
        .position(|r| (r.0 - reply_s).abs() < 5e-7)
        .expect("the reply's tick is recorded");
    let setpoint = response["setpoint_c"].as_f64().expect("setpoint_c");
    assert!(
        (rows[at].2 - setpoint).abs() < 1e-4,
        "the reply's set-point {setpoint} is the row's {}",
        rows[at].2
    );
    assert!(
        response["sensor_c"].as_f64().is_some(),
        "the simulated plate is measured: {response}"
    );
    // The ramp falls up to the reply's tick and not after it: its last decrease is on or before that tick.
    let last_decrease = rows
        .windows(2)
        .rposition(|w| w[1].2 < w[0].2 - 1e-7)
        .expect("the ramp fell")
        + 1;
    assert!(
        last_decrease <= at,
        "last decrease at row {last_decrease}, the reply at row {at}"
    );
    assert!(
        rows[at - 1].2 < rows[at - 2].2 - 0.0009,
        "the ramp still ran on the tick before the reply: {:?}",
        &rows[at - 2..=at]
    );
    // The return: 1 °C/s measured over its first 0.3 s of rows.
    let (from, to) = (&rows[at], &rows[at + 300]);
    let rate = (to.2 - from.2) / (to.0 - from.0);
    assert!((rate - 1.0).abs() < 0.01, "return at {rate} °C/s, asked 1 °C/s");
    let at_reply: Vec<(String, String)> = recorded_events(&path)
        .into_iter()
        .filter(|e| e.0 == tick)
        .map(|e| (e.3, e.4))
        .collect();
    let want = [("response", "0"), ("segment_start", "1")].map(|(e, s)| (e.to_string(), s.to_string()));
    assert_eq!(at_reply, want, "the events file at the reply's tick");
}

#[test]
fn a_50_c_target_on_the_simulated_display_is_clipped_to_its_range_and_the_reply_says_so() {
    let dir = tempfile::tempdir().expect("temp dir");
    let daemon = daemon(2, 100.0, dir.path());
    let addr = daemon.http_addr();
    let display_max_c = common::get_json(addr, "/api/status")["limits"]["display_max_c"]
        .as_f64()
        .expect("display_max_c");
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let reply = ask(
            &mut ws,
            &program(1, 1, json!([{"to_c": 50, "rate_c_s": 2}, {"to_c": 32}])),
        )
        .await;
        assert_eq!(reply["type"], "ok", "{reply}");
        assert_eq!(reply["cutoff_c"].as_f64(), Some(display_max_c), "{reply}");
        assert!(
            display_max_c < 50.0,
            "the simulated display stops below 50 °C: {display_max_c}"
        );
        let cutoff = &reply["cutoffs"][0];
        assert_eq!(
            (&cutoff["channel"], &cutoff["segment"], &cutoff["requested_c"]),
            (&json!(1), &json!(0), &json!(50.0)),
            "{reply}"
        );
        assert_eq!(
            reply["cutoffs"].as_array().map(Vec::len),
            Some(1),
            "32 °C is not clipped: {reply}"
        );
    });
}

#[test]
fn bad_programs_and_responses_are_refused_with_typed_errors() {
    let dir = tempfile::tempdir().expect("temp dir");
    let daemon = daemon(2, 100.0, dir.path());
    client_runtime().block_on(async {
        let mut ws = ws_connect(daemon.http_addr(), "").await;
        let cases = [
            (program(1, 5, json!([{"hold_s": 1}])), "unknown_channel"),
            (program(2, 0, json!([])), "bad_value"),
            (program(3, 0, json!([{"to_c": 30, "until": "response"}])), "bad_value"),
            (program(4, 0, json!([{"to_c": 30, "hold_s": 1}])), "bad_value"),
            (program(5, 0, json!([{"to_c": 30, "rate_c_s": 1000}])), "bad_value"),
            (program(6, 0, json!([{"to_c": 30, "speed": 1}])), "unknown_field"),
            (
                r#"{"type":"response","id":7,"channel":0,"kind":"rating"}"#.into(),
                "missing_field",
            ),
            (
                r#"{"type":"response","id":8,"channel":0,"kind":"rating","value":101}"#.into(),
                "bad_value",
            ),
            (
                r#"{"type":"response","id":9,"channel":0,"kind":"button","value":3}"#.into(),
                "bad_value",
            ),
            (
                r#"{"type":"response","id":10,"channel":0,"kind":"tap"}"#.into(),
                "bad_value",
            ),
        ];
        for (text, code) in cases {
            let reply = ask(&mut ws, &text).await;
            assert_eq!(
                (reply["type"].as_str(), reply["code"].as_str()),
                (Some("error"), Some(code)),
                "{text} → {reply}"
            );
        }
        let rating = ask(
            &mut ws,
            r#"{"type":"response","id":11,"channel":1,"kind":"rating","value":55}"#,
        )
        .await;
        assert_eq!(
            (rating["type"].as_str(), rating["value"].as_f64()),
            (Some("ok"), Some(55.0)),
            "{rating}"
        );
        assert!(rating["ended_segment"].is_null(), "no program ran: {rating}");
        let stop = ask(&mut ws, r#"{"type":"program_stop","id":12,"channel":1}"#).await;
        assert_eq!(stop["type"], "ok", "{stop}");
    });
}

#[test]
fn program_stop_holds_the_set_point_where_the_program_left_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let daemon = daemon(1, 100.0, dir.path());
    let addr = daemon.http_addr();
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let started = ask(&mut ws, &program(1, 0, json!([{"to_c": 20, "rate_c_s": 2}]))).await;
        assert_eq!(started["type"], "ok", "{started}");
        tokio::time::sleep(std::time::Duration::from_millis(500)).await;
        let stopped = ask(&mut ws, r#"{"type":"program_stop","id":2,"channel":0}"#).await;
        assert_eq!(stopped["type"], "ok", "{stopped}");
        let setpoint = |s: &Value| s["channels"][0]["display_setpoint_c"].as_f64().unwrap_or(f64::NAN);
        let held_c = setpoint(&common::get_json(addr, "/api/status"));
        tokio::time::sleep(std::time::Duration::from_millis(500)).await;
        let later_c = setpoint(&common::get_json(addr, "/api/status"));
        assert!(held_c > 20.5, "the program was stopped on its way: {held_c}");
        assert!(
            (later_c - held_c).abs() < 0.03,
            "held at {held_c} °C, then {later_c} °C"
        );
    });
}

#[test]
fn osc_runs_a_program_and_its_responses_reach_the_events_file() {
    use thermode_serve::osc::{encode, OscArg};
    let dir = tempfile::tempdir().expect("temp dir");
    let daemon = daemon(2, 100.0, dir.path());
    let (addr, osc) = (daemon.http_addr(), daemon.osc_addr().expect("OSC"));
    let path = daemon.recording_path().expect("recording");
    let socket = std::net::UdpSocket::bind("127.0.0.1:0").expect("udp");
    let send = |address: &str, args: &[OscArg]| {
        socket.send_to(&encode(address, args), osc).expect("send");
    };
    let program = r#"{"1": [{"hold_s": 30, "until": "response"}, {"hold_s": 30, "until": "response"}, {"to_c": 31}]}"#;
    send("/thermode/program", &[OscArg::Str(program.into())]);
    let segment = || common::get_json(addr, "/api/status")["channels"][1]["program_segment"].as_u64();
    assert!(common::wait_until(5.0, || segment() == Some(0)), "the program started");
    send("/thermode/channel/1/response", &[OscArg::Float(1.0)]);
    assert!(
        common::wait_until(5.0, || segment() == Some(1)),
        "the button ended the first hold"
    );
    send("/thermode/channel/1/rating", &[OscArg::Float(40.0)]);
    assert!(
        common::wait_until(5.0, || segment().is_none()),
        "the rating ended the second hold, the step ran"
    );
    send("/thermode/channel/1/rating", &[OscArg::Float(140.0)]);
    send("/thermode/channel/0/program_stop", &[]);
    let osc_status = || common::get_json(addr, "/api/status")["osc"].clone();
    assert!(
        common::wait_until(5.0, || osc_status()["refused"] == 1),
        "{}",
        osc_status()
    );
    assert!(
        osc_status()["last_error"]
            .as_str()
            .is_some_and(|e| e.contains("rating") && e.contains("100")),
        "{}",
        osc_status()
    );
    daemon.shutdown().expect("shutdown");
    let (header, rows) = csv(&thermode_serve::program_events::events_csv_path(&path));
    let summary: Vec<String> = rows
        .iter()
        .map(|r| {
            let f = |name| field(&header, r, name);
            format!("{} {} {} {}", f("event"), f("segment"), f("kind"), f("value"))
        })
        .collect();
    let want = [
        "segment_start 0  ",
        "response 0 button ",
        "segment_start 1  ",
        "response 1 rating 40",
        "segment_start 2  ",
        "program_end   ",
    ];
    assert_eq!(summary, want, "the events file");
}

/// Issue 35, finding 7: a program kept its clock while its channel was faulted, and after `clear_fault` its
/// set-point jumped from 38.9 to 45 °C in 0.5 s (12 °C/s) where the program asked 2 °C/s. Now a channel that faults
/// (its cable pulled: reads fail until the sensor is stale) or that its device cuts stops its program on that tick,
/// says so in a `program_stopped` event with the reason (over the WebSocket and in the events file), renders air,
/// and once the cable is back and the fault cleared nothing of the program resumes: the set-point rose no faster
/// than the program's own 2 °C/s, and after the stop it renders air (below 40 °C), never the program's 45 °C.
#[test]
fn a_program_stops_with_its_reason_when_its_channel_faults_or_is_cut_and_never_resumes_faster() {
    let dir = tempfile::tempdir().expect("temp dir");
    let device = SpyDevice::new(2);
    let control = device.control.clone();
    let mut config = common::test_config();
    config.core.record_dir = Some(dir.path().to_path_buf());
    let daemon = common::start(config, device, common::pipelines());
    let addr = daemon.http_addr();
    let path = daemon.recording_path().expect("recording");
    let measured = || {
        let status = common::get_json(addr, "/api/status");
        (0..2).all(|i| status["channels"][i]["sensor_c"].is_number())
    };
    assert!(common::wait_until(10.0, measured), "no first reading within 10 s");
    let stopped: Vec<Value> = client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let mut events = Vec::new();
        let ramp = json!({"0": [{"to_c": 45, "rate_c_s": 2}], "1": [{"to_c": 45, "rate_c_s": 2}]});
        let started = ask_keeping(
            &mut ws,
            &json!({"type": "program", "id": 1, "channels": ramp}).to_string(),
            &mut events,
        )
        .await;
        assert_eq!(started["type"], "ok", "{started}");
        tokio::time::sleep(std::time::Duration::from_millis(1500)).await;
        {
            let mut c = control.lock().expect("spy control");
            c.failing_reads.push(0);
            c.cut_reads.push((1, thermode_device::DeviceCut::OverTemperature));
        }
        let stops = |events: &[Value]| events.iter().filter(|e| e["event"] == "program_stopped").count();
        while stops(&events) < 2 {
            let message = next_json(&mut ws).await;
            if message["type"] == "program_event" {
                events.push(message);
            }
        }
        {
            let mut c = control.lock().expect("spy control");
            c.failing_reads.clear();
            c.cut_reads.clear();
        }
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        let cleared = ask_keeping(&mut ws, r#"{"type":"clear_fault","id":2,"channel":0}"#, &mut events).await;
        assert_eq!(cleared["type"], "ok", "{cleared}");
        tokio::time::sleep(std::time::Duration::from_millis(1500)).await;
        events.into_iter().filter(|e| e["event"] == "program_stopped").collect()
    });
    let reasons: Vec<&str> = stopped.iter().filter_map(|e| e["reason"].as_str()).collect();
    println!("program_stopped reasons: {reasons:?}");
    assert!(
        reasons.iter().any(|r| r.contains("E104")) && reasons.iter().any(|r| r.contains("device cut")),
        "{stopped:?}"
    );
    let status = common::get_json(addr, "/api/status");
    for i in 0..2 {
        assert_eq!(
            status["channels"][i]["mode"], "air",
            "channel {i}: {}",
            status["channels"][i]
        );
    }
    daemon.shutdown().expect("shutdown");
    let events = recorded_events(&path);
    assert_eq!(
        events.iter().filter(|e| e.3 == "program_stopped").count(),
        2,
        "{events:?}"
    );
    for channel in 0..2 {
        let stop_s = events
            .iter()
            .find(|e| e.2 == channel && e.3 == "program_stopped")
            .map_or(f64::NAN, |e| e.1);
        let rows: Vec<(f64, f64)> = recorded(&path)
            .into_iter()
            .filter(|r| r.1 == channel && r.2.is_finite())
            .map(|r| (r.0, r.2))
            .collect();
        let split = rows.partition_point(|r| r.0 < stop_s);
        let (program, after) = rows.split_at(split);
        let steepest = program
            .windows(2)
            .filter(|w| w[1].1 > w[0].1)
            .map(|w| (w[1].1 - w[0].1) / (w[1].0 - w[0].0))
            .fold(0.0, f64::max);
        let at_stop_c = program.last().map_or(f64::NAN, |r| r.1);
        let highest_after_c = after.iter().map(|r| r.1).fold(f64::MIN, f64::max);
        println!(
            "channel {channel}: stopped at {stop_s:.2} s at {at_stop_c:.2} °C; steepest rise before {steepest:.3} °C/s, \
             highest after {highest_after_c:.2} °C"
        );
        assert!(
            steepest <= 2.0 + 1e-6,
            "channel {channel}: set-point rose at {steepest} °C/s"
        );
        // Air renders the resting finger (a finger model cooled by the cold plate is warmed back, up to about
        // 37 °C); a program resumed would have gone on to its 45 °C.
        assert!(
            highest_after_c < 40.0,
            "channel {channel}: after the stop at {at_stop_c} °C the set-point went to {highest_after_c} °C"
        );
    }
}
