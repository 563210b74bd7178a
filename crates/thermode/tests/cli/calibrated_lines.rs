//! A device file's calibration on every backend's own lines (issue 35, finding 2), judged by the emulators' true
//! plate (`--trace`), each emulator's sensor erring by `--sensor-offset-c` as a mounted sensor may:
//! - MeCom in temperature mode, a sensor reading 5 °C low honestly calibrated (and an honest sensor under a
//!   calibration that lies by +5 °C): 48 °C asked at 20 °C/s, the true plate peaks at most at 48.5 °C (the
//!   controller's object threshold on its reading moved by the calibration; before, on the raw reading: 50.8 °C);
//! - TCS II, the same two calibrations: 48 °C asked, then the host SIGKILLed (the stimulator has no watchdog and
//!   holds its last set-point): the true plate stays at most 43.5 °C (before: a true 48 °C held);
//! - thermode's own firmware, whose cut is fixed at 48 °C on its reading: `serve` refuses a file calibrated 5 °C off
//!   (exit 2, one line naming the fixed cut, no current delivered); calibrated 0.4 °C off honestly, a host killed
//!   while heating to 48 °C leaves the true plate at most 48.5 °C;
//! - `thermode calibrate` against a MeCom sensor 5 °C off: refused without `--accept-offset-c` (exit 2, one line,
//!   nothing written), written with `--accept-offset-c -5.0`, and it says what the envelope acts on.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use thermode_device::config::CalibrationConfig;
use thermode_device::DeviceConfig;

use super::serve_on_emulator::{
    binary, emulate_with, poll_mecom_as_a_second_client, read_trace, serve_device, setpoint, status, Process, Tail,
    LIVENESS_S,
};

/// The line the true plate must not pass where the device's own line is 48 °C \[°C\].
const JUDGED_MAX_PLATE_C: f64 = 48.5;
/// The line the true plate must not pass on a TCS II, whose held maximum is 43 °C \[°C\].
const JUDGED_TCS2_HOLD_C: f64 = 43.5;

/// A default device file calibrated to a sensor offset of `offset_c` \[°C\] (gain 1), written into `dir`.
fn calibrated_file(dir: &Path, offset_c: f64) -> PathBuf {
    let file = DeviceConfig {
        calibration: CalibrationConfig {
            sensor_offset_c: offset_c,
            ..CalibrationConfig::default()
        },
        ..DeviceConfig::default()
    };
    let path = dir.join(format!("calibrated{offset_c}.toml"));
    std::fs::write(&path, file.to_toml_string()).unwrap_or_else(|e| panic!("write {}: {e}", path.display()));
    path
}

/// The highest true plate in `trace` from `since_s` on (emulator time) \[°C\], and the last row's time \[s\].
fn peak_since(trace: &Path, since_s: f64) -> (f64, f64) {
    let rows = read_trace(trace);
    let peak = rows
        .iter()
        .filter(|r| r.time_s >= since_s)
        .map(|r| r.plate_c)
        .fold(f64::NEG_INFINITY, f64::max);
    (peak, rows.last().map_or(0.0, |r| r.time_s))
}

/// Follows `tail` for `watch_s` \[s\]; the newest row's time \[s\].
fn follow(tail: &mut Tail, watch_s: f64) -> f64 {
    let started = Instant::now();
    let mut last_s = 0.0;
    while started.elapsed().as_secs_f64() < watch_s {
        if let Some(r) = tail.rows().last() {
            last_s = r.time_s;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    last_s
}

/// The sensor's offset in the emulator and in the device file, for the two cases of finding 2: an honest calibration
/// of a sensor that reads 5 °C low, and a calibration that lies by +5 °C about an honest sensor.
const CASES: [(&str, f64, f64); 2] = [
    ("honest calibration, sensor 5 °C low", -5.0, -5.0),
    ("lying calibration +5 °C, honest sensor", 0.0, 5.0),
];

/// MeCom in temperature mode: 48 °C asked at 20 °C/s on a calibrated sensor; then the host killed while another
/// client polls (feeding the watchdog). The true plate's peak over the run.
#[test]
fn a_calibrated_mecom_in_temperature_mode_keeps_the_true_plate_at_its_line() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("tempdir: {e}"));
    for (case, sensor_offset_c, file_offset_c) in CASES {
        let trace = dir.path().join("mecom.csv");
        let offset = format!("--sensor-offset-c={sensor_offset_c}");
        let (emulator, address) = emulate_with(
            1,
            None,
            &trace,
            &["--protocol", "mecom", "--tcp", "127.0.0.1:0", &offset],
        );
        let file = calibrated_file(dir.path(), file_offset_c);
        let mut host = serve_device(&format!("mecom-tcp:{address}?mode=temperature"), Some(&file), None);
        let mut tail = Tail::open(&trace);
        setpoint(host.osc_port, 0, 48.0, 20.0);
        let killed_s = follow(&mut tail, 6.0);
        host.process.0.kill().unwrap_or_else(|e| panic!("SIGKILL serve: {e}"));
        let _ = host.process.0.wait();
        let answered = poll_mecom_as_a_second_client(&address, 3.0);
        drop(emulator);
        let (peak_c, _) = peak_since(&trace, 0.0);
        let (after_c, last_s) = peak_since(&trace, killed_s);
        println!(
            "MeCom temperature mode, {case}: 48 °C at 20 °C/s: true plate peak {peak_c:.2} °C; after SIGKILL at \
             {killed_s:.1} s with a second client ({answered} answers): {after_c:.2} °C until {last_s:.1} s"
        );
        assert!(answered > 50, "{case}: the second client got {answered} answers");
        assert!(
            peak_c <= JUDGED_MAX_PLATE_C,
            "{case}: the true plate peaked at {peak_c:.2} °C, above {JUDGED_MAX_PLATE_C} °C"
        );
    }
}

/// TCS II: 48 °C asked on a calibrated zone for 8 s, then the host killed; the stimulator holds its last set-point
/// for ever, which must be a true 43 °C at most on either calibration.
#[test]
fn a_calibrated_tcs2_holds_at_most_a_true_43_c_after_a_host_kill() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("tempdir: {e}"));
    for (case, sensor_offset_c, file_offset_c) in CASES {
        let trace = dir.path().join("tcs2.csv");
        let offset = format!("--sensor-offset-c={sensor_offset_c}");
        let (emulator, pty) = emulate_with(1, None, &trace, &["--protocol", "tcs2", &offset]);
        let file = calibrated_file(dir.path(), file_offset_c);
        let mut host = serve_device(&format!("tcs2:{pty}"), Some(&file), None);
        let mut tail = Tail::open(&trace);
        setpoint(host.osc_port, 0, 48.0, 10.0);
        let killed_s = follow(&mut tail, 8.0);
        let channel = status(host.http_port)["channels"][0].clone();
        host.process.0.kill().unwrap_or_else(|e| panic!("SIGKILL serve: {e}"));
        let _ = host.process.0.wait();
        follow(&mut tail, 5.0);
        drop(emulator);
        let (peak_c, _) = peak_since(&trace, 0.0);
        let (held_c, last_s) = peak_since(&trace, killed_s);
        println!(
            "TCS II, {case}: 48 °C asked: true plate peak {peak_c:.2} °C; after SIGKILL at {killed_s:.1} s held at most \
             {held_c:.2} °C until {last_s:.1} s"
        );
        assert!(
            peak_c <= JUDGED_TCS2_HOLD_C && held_c <= JUDGED_TCS2_HOLD_C,
            "{case}: the true plate reached {peak_c:.2} °C ({held_c:.2} °C after the kill), above {JUDGED_TCS2_HOLD_C} °C"
        );
        assert!(
            held_c > 40.0,
            "{case}: the zone never heated ({held_c:.2} °C); before the kill: {channel}"
        );
    }
}

/// Thermode's own firmware: a file calibrated 5 °C off is refused at once (its cut is fixed on its own reading),
/// with one line and exit 2, and the emulator never delivered a current.
#[test]
fn serve_refuses_a_calibration_the_own_firmware_cannot_follow() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("tempdir: {e}"));
    let trace = dir.path().join("own.csv");
    let (emulator, pty) = emulate_with(1, None, &trace, &["--sensor-offset-c=-5"]);
    let file = calibrated_file(dir.path(), -5.0);
    let out = Command::new(binary())
        .args([
            "serve",
            "--device",
            &format!("serial:{pty}"),
            "--port",
            "0",
            "--no-osc",
            "--state-dir",
        ])
        .arg(dir.path())
        .arg("--device-file")
        .arg(&file)
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("run serve: {e}"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stderr}");
    drop(emulator);
    assert_eq!(out.status.code(), Some(2), "serve: {stderr}");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.contains("error")).collect();
    assert!(
        errors.len() == 1 && errors[0].contains("fixed in its firmware") && errors[0].contains("53.00 °C"),
        "{stderr}"
    );
    let delivered = read_trace(&trace).iter().filter(|r| r.current_a != 0.0).count();
    assert_eq!(delivered, 0, "the emulator delivered a current in {delivered} ticks");
}

/// Thermode's own firmware, a sensor 0.4 °C low honestly calibrated (inside the cut's margin): a host killed while
/// heating to 48 °C at 20 °C/s, once the true plate reached 47.5 °C or the device cut: the true plate peaks at most
/// at 48.5 °C.
#[test]
fn an_own_display_calibrated_within_its_cuts_margin_survives_a_host_kill() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("tempdir: {e}"));
    let trace = dir.path().join("own.csv");
    let (emulator, pty) = emulate_with(1, None, &trace, &["--sensor-offset-c=-0.4"]);
    let file = calibrated_file(dir.path(), -0.4);
    let mut host = serve_device(&format!("serial:{pty}"), Some(&file), None);
    let mut tail = Tail::open(&trace);
    setpoint(host.osc_port, 0, 48.0, 20.0);
    let started = Instant::now();
    let mut at_kill_c = f64::NAN;
    'watch: while started.elapsed().as_secs_f64() < LIVENESS_S {
        for r in tail.rows() {
            if r.plate_c >= 47.5 || (r.plate_c > 40.0 && r.current_a == 0.0) {
                at_kill_c = r.plate_c;
                break 'watch;
            }
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    host.process.0.kill().unwrap_or_else(|e| panic!("SIGKILL serve: {e}"));
    let _ = host.process.0.wait();
    std::thread::sleep(Duration::from_millis(1500));
    drop(emulator);
    let (peak_c, _) = peak_since(&trace, 0.0);
    println!(
        "own firmware, sensor 0.4 °C low calibrated: SIGKILL at plate {at_kill_c:.2} °C: true peak {peak_c:.2} °C"
    );
    assert!(
        at_kill_c.is_finite(),
        "the plate never heated past 40 °C (peak {peak_c:.2} °C)"
    );
    assert!(peak_c <= JUDGED_MAX_PLATE_C, "the true plate peaked at {peak_c:.2} °C");
}

/// `thermode calibrate` on `device` with `reference`, writing `out`, plus `extra`; its output.
fn calibrate(device: &str, reference: &str, out: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(binary())
        .args([
            "calibrate",
            "--device",
            device,
            "--reference",
            &format!("serial:{reference}"),
        ])
        .args(["--setpoints", "25,35", "--out"])
        .arg(out)
        .args(extra)
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("run calibrate: {e}"))
}

/// `thermode calibrate` against a MeCom sensor 5 °C low (its reference the true plate): refused without the
/// operator's confirmation, written with `--accept-offset-c -5.0`.
#[test]
fn calibrate_refuses_an_offset_of_5_c_unless_its_figure_is_confirmed() {
    let mut child = Command::new(binary())
        .args([
            "emulate",
            "--protocol",
            "mecom",
            "--channels",
            "1",
            "--no-finger",
            "--sensor-offset-c=-5",
        ])
        .args(["--reference-channel", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("spawn emulate: {e}"));
    let stdout = child.stdout.take().unwrap_or_else(|| panic!("emulate stdout"));
    let _emulator = Process(child);
    let lines: Vec<String> = BufReader::new(stdout)
        .lines()
        .take(2)
        .map(|l| l.unwrap_or_else(|e| panic!("emulate stdout: {e}")).trim().to_string())
        .collect();
    let [pty, reference] = <[String; 2]>::try_from(lines).unwrap_or_else(|l| panic!("two lines: {l:?}"));
    let device = format!("mecom:{pty}");
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("tempdir: {e}"));
    let out = dir.path().join("display.toml");
    let refused = calibrate(&device, &reference, &out, &[]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    println!("{stderr}");
    assert_eq!(refused.status.code(), Some(2), "{stderr}");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.contains("error")).collect();
    assert!(
        errors.len() == 1 && errors[0].contains("--accept-offset-c -5.0") && errors[0].contains("nothing written"),
        "{stderr}"
    );
    assert!(!out.exists(), "{} was written", out.display());
    let accepted = calibrate(&device, &reference, &out, &["--accept-offset-c", "-5.0"]);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&accepted.stdout),
        String::from_utf8_lossy(&accepted.stderr),
    );
    println!("{stderr}{stdout}");
    assert!(accepted.status.success(), "{stderr}");
    assert!(
        stdout.contains("act on the calibrated plate") && stdout.contains("object thresholds"),
        "{stdout}"
    );
    let text = std::fs::read_to_string(&out).unwrap_or_else(|e| panic!("read {}: {e}", out.display()));
    let file = DeviceConfig::from_toml_str(&text, "calibrated").unwrap_or_else(|e| panic!("{e}"));
    let offset_c = file.calibration.sensor_offset_c;
    assert!(
        (offset_c + 5.0).abs() < 0.05,
        "fitted offset {offset_c} °C for an injected −5 °C"
    );
}
