//! The real hardware path end to end without hardware: the daemon drives the emulated firmware (the simulated
//! display behind the device protocol) over a pseudo-terminal. A touch over the WebSocket cools the emulated plate;
//! when the port vanishes, every channel faults (stale sensor), its drive is off, touches are refused with
//! `device_fault`, and the daemon keeps answering. A device that falls silent during a hot set-point has its unseen
//! time counted at the envelope's bound on the plate, until the dose budget is spent, then not at all.

use crate::common;

use std::sync::Arc;
use std::time::Duration;

use common::{ask, channel, client_runtime, get_json, pipelines, test_config, ws_connect};
use thermode_device::{DefaultFinger, DeviceConfig, SimulatedDisplay};
use thermode_link::own::emulator::{Emulator, EmulatorConfig, PtyEmulator};
use thermode_link::own::host::{SerialConfig, SerialDevice};
use thermode_platform::{Clock, MonotonicClock};
use thermode_serve::Daemon;

#[test]
fn the_daemon_renders_through_the_serial_protocol_and_survives_a_vanished_port() {
    let display = SimulatedDisplay::<DefaultFinger>::fingertips(&DeviceConfig::default(), 3, 11).expect("display");
    let emulator = Emulator::new(display, EmulatorConfig::default()).expect("emulator");
    let device_clock = Arc::new(MonotonicClock::new());
    let pty = PtyEmulator::spawn(emulator, device_clock).expect("pseudo-terminal");
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let serial =
        SerialDevice::open(pty.path(), &SerialConfig::default(), clock.clone()).expect("handshake with the emulator");
    let mut config = test_config();
    config.device_label = format!("serial:{}", pty.path());
    let daemon = Daemon::start(config, Box::new(serial), pipelines(), clock).expect("daemon");
    let addr = daemon.http_addr();
    // The emulated plate warms towards the resting finger from the start (about 0.7 s to 28 °C); on a loaded
    // machine that takes longer, so the reading is polled, not taken once after a fixed sleep.
    let resting = |status: &serde_json::Value| {
        channel(status, 1)["sensor_c"]
            .as_f64()
            .filter(|c| (28.0..36.0).contains(c))
    };
    common::wait_until(10.0, || resting(&get_json(addr, "/api/status")).is_some());
    let rest = get_json(addr, "/api/status");
    let rest_c = channel(&rest, 1)["sensor_c"]
        .as_f64()
        .expect("a sensor reading over the link");
    assert!(resting(&rest).is_some(), "resting display {rest_c} °C");
    assert_eq!(rest["faults"], serde_json::json!([]), "{}", rest["faults"]);
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let r = ask(&mut ws, r#"{"type":"touch","id":1,"channel":1,"material":"aluminium"}"#).await;
        assert_eq!(r["type"], "ok", "{r}");
        tokio::time::sleep(Duration::from_millis(2000)).await;
        let s = ask(&mut ws, r#"{"type":"status","id":2}"#).await;
        let cooled = channel(&s, 1)["sensor_c"].as_f64().expect("sensor");
        assert!(
            cooled < rest_c - 1.0,
            "emulated plate after 2 s of aluminium {cooled} °C vs {rest_c} °C"
        );
        pty.control().close_port();
        let faulted = async {
            for _ in 0..200 {
                let s = ask(&mut ws, r#"{"type":"status","id":3}"#).await;
                let all = (0..3).all(|i| channel(&s, i)["fault"] != 0 && channel(&s, i)["current_a"] == 0.0);
                if all {
                    return Some(s);
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            None
        };
        let s = faulted
            .await
            .expect("every channel faults with its drive off after the port vanished");
        assert!(s["device_errors"].as_u64().unwrap_or(0) > 0, "{}", s["device_errors"]);
        let r = ask(&mut ws, r#"{"type":"touch","id":4,"channel":0,"material":"wood"}"#).await;
        assert_eq!(
            (r["type"].as_str(), r["code"].as_str()),
            (Some("error"), Some("device_fault")),
            "{r}"
        );
    });
    assert!(
        get_json(addr, "/api/status")["running"].as_bool().unwrap_or(false),
        "the daemon keeps running"
    );
    daemon.shutdown().expect("clean shutdown");
}

/// A running emulator of `channels` channels on a pseudo-terminal.
fn emulator(channels: usize, seed: u64) -> PtyEmulator {
    let display =
        SimulatedDisplay::<DefaultFinger>::fingertips(&DeviceConfig::default(), channels, seed).expect("display");
    let emulator = Emulator::new(display, EmulatorConfig::default()).expect("emulator");
    PtyEmulator::spawn(emulator, Arc::new(MonotonicClock::new())).expect("pseudo-terminal")
}

/// Points the symbolic link `link` at `target` (atomically, as `thermode emulate --link` does).
fn point(link: &std::path::Path, target: &str) {
    let tmp = link.with_extension("new");
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(target, &tmp).expect("symlink");
    std::fs::rename(&tmp, link).expect("rename");
}

/// Clears every channel's fault, then asks channel 0 for a direct set-point and returns its sensor after 1.5 s.
async fn clear_and_render(ws: &mut common::Ws, channels: usize, id: &mut u64) -> (f64, f64) {
    for channel in 0..channels {
        let mut cleared = false;
        for _ in 0..100 {
            *id += 1;
            let r = ask(
                ws,
                &format!(r#"{{"type":"clear_fault","id":{id},"channel":{channel}}}"#),
            )
            .await;
            if r["type"] == "ok" {
                cleared = true;
                break;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        assert!(cleared, "clear_fault on channel {channel} never succeeded");
    }
    *id += 1;
    let s = ask(ws, &format!(r#"{{"type":"status","id":{id}}}"#)).await;
    let before = channel(&s, 0)["sensor_c"].as_f64().expect("sensor");
    *id += 1;
    let r = ask(
        ws,
        &format!(r#"{{"type":"setpoint","id":{id},"channel":0,"temp_c":38,"rate_c_s":5}}"#),
    )
    .await;
    assert_eq!(r["type"], "ok", "{r}");
    tokio::time::sleep(Duration::from_millis(1500)).await;
    *id += 1;
    let s = ask(ws, &format!(r#"{{"type":"status","id":{id}}}"#)).await;
    let after = channel(&s, 0)["sensor_c"].as_f64().expect("sensor");
    *id += 1;
    let r = ask(ws, &format!(r#"{{"type":"release","id":{id},"channel":0}}"#)).await;
    assert_eq!(r["type"], "ok", "{r}");
    (before, after)
}

#[test]
fn the_link_recovers_from_a_silent_device_and_from_an_emulator_restarted_on_the_same_path() {
    use thermode_link::own::emulator::LinkFaults;
    let dir = tempfile::tempdir().expect("temp dir");
    let link = dir.path().join("thermode-port");
    let first = emulator(2, 3);
    point(&link, first.path());
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let serial =
        SerialDevice::open(link.to_str().expect("path"), &SerialConfig::default(), clock.clone()).expect("handshake");
    let mut config = test_config();
    config.device_label = format!("serial:{}", link.display());
    let daemon = Daemon::start(config, Box::new(serial), pipelines(), clock).expect("daemon");
    let addr = daemon.http_addr();
    let link_state = || get_json(addr, "/api/status")["link"].clone();
    assert_eq!(link_state()["state"], "up", "{}", link_state());
    client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        let mut id = 0;
        // 1. The device falls silent for 2.5 s (as a stopped emulator does), then answers again.
        first.control().set_link_faults(LinkFaults {
            mute: true,
            ..LinkFaults::default()
        });
        assert!(
            common::wait_until(10.0, || link_state()["state"] == "down"),
            "{}",
            link_state()
        );
        let s = get_json(addr, "/api/status");
        assert!(
            (0..2).all(|i| channel(&s, i)["current_a"] == 0.0 && channel(&s, i)["link_ok"] == false),
            "every drive off while the link is down: {}",
            s["channels"]
        );
        tokio::time::sleep(Duration::from_millis(1500)).await;
        first.control().set_link_faults(LinkFaults::default());
        assert!(
            common::wait_until(20.0, || link_state()["state"] == "up"
                && link_state()["reconnects"] == 1),
            "{}",
            link_state()
        );
        let s = get_json(addr, "/api/status");
        assert!(
            (0..2).all(|i| channel(&s, i)["fault"] != 0 && !channel(&s, i)["fault"].is_null()),
            "channels stay faulted until cleared: {}",
            s["channels"]
        );
        let (before, after) = clear_and_render(&mut ws, 2, &mut id).await;
        assert!(
            after > before + 0.5,
            "renders again after the reconnection: {before} → {after} °C"
        );
        // 2. The emulator ends; a new one starts on the same path.
        first.control().close_port();
        drop(first);
        assert!(
            common::wait_until(10.0, || link_state()["state"] == "down"),
            "{}",
            link_state()
        );
        let second = emulator(2, 4);
        point(&link, second.path());
        assert!(
            common::wait_until(20.0, || link_state()["state"] == "up"
                && link_state()["reconnects"] == 2),
            "{}",
            link_state()
        );
        let (before, after) = clear_and_render(&mut ws, 2, &mut id).await;
        assert!(
            after > before + 0.5,
            "renders on the new emulator: {before} → {after} °C"
        );
        let notices = daemon.take_notices();
        assert!(
            notices.iter().filter(|l| l.contains("link DOWN")).count() == 1
                && notices.iter().any(|l| l.contains("back up")),
            "{notices:?}"
        );
        drop(second);
    });
    daemon.shutdown().expect("clean shutdown");
}

/// The true plate's CEM43 \[min\] in an emulator trace (`time_s,channel,plate_c,…`) of channel 0: each step at the
/// hotter of its ends.
fn traced_dose_min(trace: &str) -> f64 {
    let plate: Vec<(f64, f64)> = trace
        .lines()
        .skip(1)
        .filter_map(|line| {
            let mut f = line.split(',');
            let time_s = f.next()?.parse::<f64>().ok()?;
            let channel = f.next()?;
            let plate_c = f.next()?.parse::<f64>().ok()?;
            (channel == "0").then_some((time_s, plate_c))
        })
        .collect();
    plate
        .windows(2)
        .map(|w| thermode_safety::dose::cem43_increment_min(w[0].1.max(w[1].1), w[1].0 - w[0].0))
        .sum()
}

/// The own protocol's emulator falls silent (LinkFaults mute) during a hot set-point (47 °C): the envelope counts
/// the unseen time at its bound on the plate until the budget is spent, then nothing — the dose 3 s and 6 s into the
/// outage is the same, within the bound, and at least the emulated plate's true dose (from its trace) — and after
/// the link is back the channel is off: `off_reason` `dose_budget_spent` once its fault is cleared.
#[test]
fn a_silent_device_during_a_hot_set_point_spends_the_budget_at_the_bound_not_at_the_held_reading() {
    use thermode_link::own::emulator::LinkFaults;
    let tmp = tempfile::tempdir().expect("temp dir");
    let trace_path = tmp.path().join("trace.csv");
    let display = SimulatedDisplay::<DefaultFinger>::fingertips(&DeviceConfig::default(), 1, 5).expect("display");
    let mut emulator = Emulator::new(display, EmulatorConfig::default()).expect("emulator");
    emulator.trace_to(Box::new(std::fs::File::create(&trace_path).expect("trace file")));
    let pty = PtyEmulator::spawn(emulator, Arc::new(MonotonicClock::new())).expect("pseudo-terminal");
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let serial = SerialDevice::open(pty.path(), &SerialConfig::default(), clock.clone()).expect("handshake");
    let mut config = test_config();
    config.device_label = format!("serial:{}", pty.path());
    let daemon = Daemon::start(config, Box::new(serial), pipelines(), clock).expect("daemon");
    let addr = daemon.http_addr();
    let dose = || {
        get_json(addr, "/api/status")["channels"][0]["cem43_min"]
            .as_f64()
            .unwrap_or(f64::NAN)
    };
    // A script's set-point: it stays when no client is connected.
    let answer = daemon
        .commands()
        .expect("commands")
        .request(thermode_runtime::Command::direct(
            0,
            47.0,
            20.0,
            thermode_runtime::Owner::Script,
        ))
        .expect("queued");
    answer.blocking_recv().expect("answered").expect("applied");
    let hot = common::wait_until(20.0, || {
        channel(&get_json(addr, "/api/status"), 0)["sensor_c"]
            .as_f64()
            .is_some_and(|c| c >= 46.5)
    });
    assert!(
        hot,
        "the plate never reached 46.5 °C: {}",
        channel(&get_json(addr, "/api/status"), 0)
    );
    std::thread::sleep(Duration::from_millis(500));
    let before = dose();
    pty.control().set_link_faults(LinkFaults {
        mute: true,
        ..LinkFaults::default()
    });
    std::thread::sleep(Duration::from_secs(3));
    let at_3_s = dose();
    std::thread::sleep(Duration::from_secs(3));
    let at_6_s = dose();
    pty.control().set_link_faults(LinkFaults::default());
    let link_state = || get_json(addr, "/api/status")["link"]["state"].clone();
    assert!(common::wait_until(20.0, || link_state() == "up"), "{}", link_state());
    std::thread::sleep(Duration::from_secs(1));
    let cleared = client_runtime().block_on(async {
        let mut ws = ws_connect(addr, "").await;
        for id in 10..110 {
            let r = ask(&mut ws, &format!(r#"{{"type":"clear_fault","id":{id},"channel":0}}"#)).await;
            if r["type"] == "ok" {
                return true;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        false
    });
    assert!(cleared, "the fault never cleared");
    std::thread::sleep(Duration::from_millis(300));
    let status = get_json(addr, "/api/status");
    let ch = channel(&status, 0).clone();
    let end = ch["cem43_min"].as_f64().unwrap_or(f64::NAN);
    daemon.shutdown().expect("clean shutdown");
    drop(pty);
    let truth = traced_dose_min(&std::fs::read_to_string(&trace_path).expect("trace"));
    let envelope = thermode_safety::EnvelopeConfig::default();
    let spent_at = envelope.cem43_budget_min * (1.0 + thermode_safety::dose::DOSE_ESTIMATE_ALLOWANCE);
    let bound = spent_at + thermode_safety::dose::cem43_increment_min(49.0, envelope.stale_timeout_s + 0.01);
    println!(
        "own protocol, silent for 6 s at 47 °C: dose {before:.4} before, {at_3_s:.4} after 3 s, {at_6_s:.4} after 6 s, \
         {end:.4} at the end (bound [{spent_at:.4}, {bound:.4}]); the emulated plate's true dose {truth:.4}; the held \
         reading would have added {:.4} per 6 s",
        thermode_safety::dose::cem43_increment_min(47.0, 6.0)
    );
    assert!(
        at_3_s >= spent_at && at_3_s <= bound,
        "3 s into the outage: {at_3_s} CEM43-min, want within [{spent_at}, {bound}]"
    );
    assert_eq!(at_6_s, at_3_s, "the count grew after the budget was spent");
    assert!(end - at_6_s < 1e-3, "the return added {}", end - at_6_s);
    assert!(end >= truth, "counted {end} CEM43-min, the emulated plate {truth}");
    assert_eq!(ch["off_reason"], "dose_budget_spent", "{ch}");
}
