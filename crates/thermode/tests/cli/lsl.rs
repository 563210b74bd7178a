//! `serve --lsl` from the command line: a missing liblsl is a clear error before anything listens, and with liblsl
//! (the `pylsl` package's copy) a recording gets its `.lsl.json` sidecar with the LSL clock at the start. The streams
//! themselves are judged by a pylsl inlet in `python/lsl/test_lsl.py` (run by [`super::python_packages`]).

use std::path::PathBuf;
use std::process::Command;

fn serve(extra: &[&str], envs: &[(&str, &str)], state: &std::path::Path) -> std::process::Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_thermode"));
    command
        .args(["serve", "--port", "0", "--no-osc", "--no-realtime", "--state-dir"])
        .arg(state)
        .args(extra);
    for (key, value) in envs {
        command.env(key, value);
    }
    command.output().expect("run thermode serve")
}

#[test]
fn serve_lsl_without_liblsl_refuses_to_start_and_says_what_to_do() {
    let state = tempfile::tempdir().expect("temp dir");
    let out = serve(
        &["--lsl", "--duration", "1"],
        &[("THERMODE_LIBLSL", "/nonexistent/liblsl.so")],
        state.path(),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "serve --lsl started without liblsl: {stderr}");
    for part in [
        "liblsl",
        "/nonexistent/liblsl.so",
        "THERMODE_LIBLSL",
        "pip install pylsl",
    ] {
        assert!(stderr.contains(part), "stderr lacks `{part}`:\n{stderr}");
    }
    assert!(
        !String::from_utf8_lossy(&out.stdout).contains("ws://"),
        "it listened before failing"
    );
}

#[test]
fn serve_without_lsl_never_loads_liblsl() {
    let state = tempfile::tempdir().expect("temp dir");
    let out = serve(
        &["--duration", "0.3"],
        &[("THERMODE_LIBLSL", "/nonexistent/liblsl.so")],
        state.path(),
    );
    assert!(
        out.status.success(),
        "serve failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The `pylsl` package's liblsl, if Python has one.
fn pylsl_library() -> Option<PathBuf> {
    let script =
        "import importlib.util as u; s = u.find_spec('pylsl'); print(s.submodule_search_locations[0] if s else '')";
    let out = Command::new("python3").args(["-c", script]).output().ok()?;
    let dir = String::from_utf8_lossy(&out.stdout).trim().to_string();
    let lib = PathBuf::from(dir).join("lib").join("liblsl.so");
    lib.is_file().then_some(lib)
}

#[test]
fn a_recording_with_lsl_notes_the_lsl_clock_at_its_start() {
    let Some(lib) = pylsl_library() else {
        let required = std::env::var("THERMODE_REQUIRE_PYTHON_TESTS").is_ok_and(|v| v == "1");
        assert!(
            !required,
            "THERMODE_REQUIRE_PYTHON_TESTS=1 but python3 has no pylsl (with its liblsl)"
        );
        println!("skipped: `python3 -m pip install pylsl` to test serve --lsl --record");
        return;
    };
    let (state, record) = (tempfile::tempdir().expect("temp"), tempfile::tempdir().expect("temp"));
    // liblsl kept on this machine (machine scope, no IPv6, loopback peer only).
    let config = state.path().join("lsl_api.cfg");
    std::fs::write(
        &config,
        "[ports]\nIPv6 = disable\n[multicast]\nResolveScope = machine\n[lab]\nKnownPeers = {127.0.0.1}\nSessionID = thermode-cli-test\n",
    )
    .expect("write lsl config");
    let record_dir = record.path().to_str().expect("utf-8 path");
    let out = serve(
        &[
            "--lsl",
            "--lsl-name",
            "thermode-cli-test",
            "--record",
            record_dir,
            "--duration",
            "0.5",
        ],
        &[
            ("THERMODE_LIBLSL", lib.to_str().expect("utf-8 path")),
            ("LSLAPICFG", config.to_str().expect("utf-8 path")),
        ],
        state.path(),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "serve --lsl failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("thermode-cli-test telemetry"),
        "banner lacks the streams:\n{stdout}"
    );
    let sidecar = std::fs::read_dir(record.path())
        .expect("list recordings")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().ends_with(".lsl.json"))
        .expect("a .lsl.json sidecar beside the recording");
    let text = std::fs::read_to_string(&sidecar).expect("read sidecar");
    let value: serde_json::Value = serde_json::from_str(&text).expect("sidecar is JSON");
    let (lsl, loop_s, offset) = (
        value["lsl_clock_at_start_s"].as_f64().expect("lsl_clock_at_start_s"),
        value["loop_time_at_start_s"].as_f64().expect("loop_time_at_start_s"),
        value["lsl_offset_s"].as_f64().expect("lsl_offset_s"),
    );
    assert!(
        (lsl - (loop_s + offset)).abs() < 1e-9,
        "lsl {lsl} != loop {loop_s} + offset {offset}"
    );
    let csv = sidecar.to_string_lossy().replace(".lsl.json", ".csv");
    assert!(PathBuf::from(&csv).is_file(), "{csv} missing beside its sidecar");
}
