//! The Python example client (`examples/touch_aluminium.py`, standard library only) against a running daemon:
//! it touches aluminium, prints the cooling finger, and releases. Skipped loudly without `python3` (fails on CI).

use crate::common;

use std::path::PathBuf;
use std::process::Command;

use common::{pipelines, start, test_config, SpyDevice};

#[test]
fn the_python_example_touches_and_releases() {
    let python = Command::new("python3").arg("--version").output();
    if python.is_err() {
        assert!(std::env::var_os("CI").is_none(), "python3 is missing on CI");
        eprintln!("\n*** SKIPPED the Python example test: python3 is not installed ***\n");
        return;
    }
    let mut config = test_config();
    config.server.token = Some("example-token".into());
    let daemon = start(config, SpyDevice::new(5), pipelines());
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/touch_aluminium.py");
    let url = format!("ws://{}/api/ws", daemon.http_addr());
    let output = Command::new("python3")
        .arg(&script)
        .args([
            "--url",
            &url,
            "--token",
            "example-token",
            "--channel",
            "2",
            "--hold",
            "1.5",
        ])
        .output()
        .expect("python3 runs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "exit {:?}\n{stdout}\n{stderr}", output.status);
    assert!(stdout.contains("ok touch: channel 2 touches aluminium"), "{stdout}");
    assert!(stdout.contains("ok release: channel 2"), "{stdout}");
    let samples = stdout
        .lines()
        .filter(|l| l.contains("aluminium") && l.contains("target"))
        .count();
    assert!(samples >= 3, "telemetry lines while touching: {stdout}");
    let (code, body) = common::http_get(daemon.http_addr(), "/api/status?token=example-token", &[]);
    assert_eq!(code, 200, "{body}");
    let status: serde_json::Value = serde_json::from_str(&body).expect("status JSON");
    assert_eq!(common::shows(&status["channels"][2]), "air", "released");
}
