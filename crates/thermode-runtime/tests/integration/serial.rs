//! The real hardware path end to end without hardware: the daemon drives the emulated firmware (the simulated
//! display behind the device protocol) over a pseudo-terminal. A touch over the WebSocket cools the emulated plate;
//! when the port vanishes, every channel faults (stale sensor), its drive is off, touches are refused with
//! `device_fault`, and the daemon keeps answering.

use crate::common;

use std::sync::Arc;
use std::time::Duration;

use common::{ask, channel, client_runtime, get_json, pipelines, test_config, ws_connect};
use thermode_device::{DefaultFinger, DeviceConfig, SimulatedDisplay};
use thermode_link::emulator::{Emulator, EmulatorConfig, PtyEmulator};
use thermode_link::serial::{SerialConfig, SerialDevice};
use thermode_platform::{Clock, MonotonicClock};
use thermode_runtime::Daemon;

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
    std::thread::sleep(Duration::from_millis(700));
    let rest = get_json(addr, "/api/status");
    let rest_c = channel(&rest, 1)["sensor_c"]
        .as_f64()
        .expect("a sensor reading over the link");
    assert!((28.0..36.0).contains(&rest_c), "resting display {rest_c} °C");
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
