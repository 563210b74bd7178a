//! End-to-end tests of the `thermode` binary: `materials` and `simulate`, run as a user would, with small helpers
//! that print what was expected and what came back; `serve` on `emulate` (killed, signalled) in
//! [`serve_on_emulator`].

use std::path::Path;
use std::process::{Command, Output};

// A module file, not a second test binary (Cargo builds every `tests/*.rs` as one).
#[cfg(unix)]
#[path = "cli/serve_on_emulator.rs"]
mod serve_on_emulator;
#[cfg(unix)]
#[path = "cli/service.rs"]
mod service;

fn thermode(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_thermode"))
        .args(args)
        .output()
        .expect("run thermode")
}

fn expect_success(args: &[&str]) -> String {
    let out = thermode(args);
    assert!(
        out.status.success(),
        "thermode {args:?} failed with {:?}\nstderr: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 stdout")
}

fn expect_error(args: &[&str], message_part: &str) {
    let out = thermode(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(2),
        "thermode {args:?}: want exit 2, got {:?}; stderr: {stderr}",
        out.status.code()
    );
    assert!(
        stderr.contains(message_part),
        "thermode {args:?}: stderr lacks `{message_part}`:\n{stderr}"
    );
}

/// Reads a CSV written by `simulate` into its header and rows of strings.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let mut reader = csv::Reader::from_path(path).expect("open csv");
    let header = reader.headers().expect("header").iter().map(str::to_string).collect();
    let rows = reader
        .records()
        .map(|r| r.expect("row").iter().map(str::to_string).collect())
        .collect();
    (header, rows)
}

fn column(header: &[String], rows: &[Vec<String>], name: &str) -> Vec<f64> {
    let index = header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"));
    rows.iter().map(|r| r[index].parse().expect("number")).collect()
}

#[test]
fn materials_json_lists_the_paper_materials_with_si_values_and_sources() {
    let text = expect_success(&["materials", "--format", "json"]);
    let list: serde_json::Value = serde_json::from_str(&text).expect("json");
    let list = list.as_array().expect("array");
    assert!(list.len() >= 20, "only {} materials", list.len());
    let aluminium = list
        .iter()
        .find(|m| m["name"] == "aluminium")
        .expect("aluminium listed");
    // Table 1: k = 0.526 cal/cm·s·°C → ×418.68; effusivity √(kρc) computed here independently.
    let k: f64 = 0.526 * 418.68;
    let (rho, c): (f64, f64) = (2.70 * 1000.0, 0.215 * 4186.8);
    let e = (k * rho * c).sqrt();
    for (key, want) in [
        ("conductivity_w_mk", k),
        ("density_kg_m3", rho),
        ("specific_heat_j_kgk", c),
        ("effusivity", e),
    ] {
        let got = aluminium[key].as_f64().unwrap_or(f64::NAN);
        assert!(
            (got - want).abs() < 1e-9 * want,
            "aluminium {key}: got {got}, want {want}"
        );
    }
    for m in list {
        assert!(
            m["source"].as_str().is_some_and(|s| !s.is_empty()),
            "no source for {}",
            m["name"]
        );
    }
}

#[test]
fn simulate_kron_writes_csv_whose_display_finger_follows_the_target() {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv_path = dir.path().join("al.csv");
    let svg_path = dir.path().join("al.svg");
    let csv = csv_path.to_str().expect("path");
    let svg = svg_path.to_str().expect("path");
    let stdout = expect_success(&[
        "simulate",
        "--material",
        "aluminium",
        "--duration",
        "10",
        "--out",
        csv,
        "--plot",
        svg,
    ]);
    assert!(stdout.contains("aluminium"), "summary lacks the material:\n{stdout}");
    let (header, rows) = read_csv(&csv_path);
    assert_eq!(rows.len(), 1001, "10 s at 0.01 s plus the row at t = 0");
    let time = column(&header, &rows, "time_s");
    let skin = column(&header, &rows, "skin_surface_c");
    let finger = column(&header, &rows, "display_finger_c");
    column(&header, &rows, "display_setpoint_c");
    assert_eq!((time[0], time[1000]), (0.0, 10.0));
    // The unlimited display inverse makes the finger on the display equal the target at every step.
    for (row, (s, f)) in skin.iter().zip(&finger).enumerate() {
        assert!((s - f).abs() < 1e-8, "row {row}: target {s}, finger on display {f}");
    }
    // Aluminium at 23 °C cools a 32 °C fingertip by several degrees within 10 s.
    assert!(skin[0] - skin[1000] > 4.0, "cooling {} → {}", skin[0], skin[1000]);
    let svg_text = std::fs::read_to_string(&svg_path).expect("svg written");
    assert!(
        svg_text.contains("<svg") && svg_text.contains("aluminium"),
        "SVG does not look like the plot"
    );
}

#[test]
fn simulate_semi_infinite_matches_the_interface_temperature() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("s.csv");
    let out = path.to_str().expect("path");
    expect_success(&[
        "simulate",
        "--material",
        "steel",
        "--model",
        "semi-infinite",
        "--duration",
        "2",
        "--dt",
        "0.5",
        "--initial",
        "uniform:33",
        "--out",
        out,
    ]);
    let (header, rows) = read_csv(&path);
    let skin = column(&header, &rows, "skin_surface_c");
    // Independent: default fingertip epidermis (k 0.21, ρ 1150, c 3600) and Table 1 steel, perfect contact.
    let e_skin = (0.21f64 * 1150.0 * 3600.0).sqrt();
    let e_steel = (0.110f64 * 418.68 * 7850.0 * 0.120 * 4186.8).sqrt();
    let want = (e_skin * 33.0 + e_steel * 23.0) / (e_skin + e_steel);
    assert_eq!(skin[0], 33.0, "resting surface");
    for (row, got) in skin.iter().enumerate().skip(1) {
        assert!(
            (got - want).abs() < 1e-9,
            "row {row}: got {got}, interface temperature {want}"
        );
    }
}

#[test]
fn several_materials_share_one_csv_and_all_paper_expands_to_five() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("all.csv");
    let out = path.to_str().expect("path");
    let stdout = expect_success(&[
        "simulate",
        "--material",
        "all-paper",
        "--duration",
        "1",
        "--dt",
        "0.1",
        "--out",
        out,
    ]);
    for name in ["aluminium", "steel", "stone", "wood", "rubber"] {
        assert!(stdout.contains(name), "summary lacks {name}:\n{stdout}");
    }
    let (header, rows) = read_csv(&path);
    assert_eq!(header.last().map(String::as_str), Some("material"));
    assert_eq!(rows.len(), 5 * 11);
}

#[test]
fn bad_input_gets_a_clear_message_and_exit_code_2() {
    expect_error(&["simulate", "--material", "alumnium"], "did you mean aluminium");
    expect_error(&["simulate", "--material", "wood", "--dt", "NaN"], "dt_s");
    expect_error(&["simulate", "--material", "wood", "--duration", "-1"], "duration_s");
    expect_error(&["simulate", "--material", "wood", "--initial", "warm"], "--initial");
    expect_error(
        &[
            "simulate",
            "--material",
            "wood",
            "--model",
            "kron",
            "--contact-resistance",
            "0.001",
        ],
        "contact resistance",
    );
    expect_error(
        &["simulate", "--material", "wood", "--out", "/nonexistent-dir/x.csv"],
        "cannot write",
    );
    expect_error(&["simulate", "--material", "wood", "--plot", "x.jpg"], ".svg or .png");
    expect_error(&["simulate", "--material-file", "/nonexistent/m.toml"], "cannot read");
    let dir = tempfile::tempdir().expect("tempdir");
    let material = dir.path().join("m.toml");
    std::fs::write(&material, "name = \"x\"\nconductivity_w_mk = 1.0\nconductivity_cal_cm_s_c = 0.002\ndensity_kg_m3 = 1000\nspecific_heat_j_kgk = 1000\n").expect("write");
    expect_error(
        &["simulate", "--material-file", material.to_str().expect("path")],
        "conductivity_cal_cm_s_c",
    );
}

#[test]
fn render_summary_json_reports_the_judged_metrics_and_the_csv_has_the_documented_columns() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("render.csv");
    let out = path.to_str().expect("path");
    let text = expect_success(&[
        "render",
        "--material",
        "stone",
        "--duration",
        "3",
        "--pre-contact",
        "1",
        "--summary",
        "--format",
        "json",
        "--out",
        out,
    ]);
    let summary: serde_json::Value = serde_json::from_str(&text).expect("json summary");
    let row = &summary[0];
    assert_eq!(row["material"], "stone");
    for key in [
        "rms_skin_0_5_c",
        "rms_truth_0_90_c",
        "rms_display_tracking_c",
        "overshoot_c",
        "lag_s",
        "actuator_limit_lag_s",
    ] {
        assert!(
            row[key].as_f64().is_some_and(f64::is_finite),
            "summary {key} = {}",
            row[key]
        );
    }
    // Physics: no controller beats the ideal one that drives the most useful current (one 10 ms tick of slack).
    let (lag, limit) = (
        row["lag_s"].as_f64().unwrap_or(f64::NAN),
        row["actuator_limit_lag_s"].as_f64().unwrap_or(f64::NAN),
    );
    assert!(lag >= limit - 0.011, "lag {lag} s beats the actuator limit {limit} s");
    let (header, rows) = read_csv(&path);
    for name in [
        "time_s",
        "truth_skin_c",
        "target_skin_c",
        "skin_c",
        "display_setpoint_c",
        "display_c",
        "sensor_c",
        "current_a",
        "hot_side_c",
        "fault",
    ] {
        assert!(header.iter().any(|h| h == name), "render CSV lacks {name}: {header:?}");
    }
    let time = column(&header, &rows, "time_s");
    assert!(
        time[0] < 0.0 && time.contains(&0.0),
        "time_s must be negative before contact and 0 at contact"
    );
    // Default finger and fv renderer: truth and target coincide.
    let truth = column(&header, &rows, "truth_skin_c");
    let target = column(&header, &rows, "target_skin_c");
    for (row, (a, b)) in truth.iter().zip(&target).enumerate() {
        assert!((a - b).abs() < 1e-9, "row {row}: truth {a}, target {b}");
    }
    expect_error(&["render", "--material", "unobtainium"], "unknown material");
}

#[test]
fn serve_refuses_a_network_bind_without_a_token() {
    expect_error(&["serve", "--bind", "0.0.0.0"], "--token");
}

#[test]
fn emulate_prints_the_pseudo_terminal_path_first() {
    use std::io::{BufRead, BufReader};
    let mut child = Command::new(env!("CARGO_BIN_EXE_thermode"))
        .args(["emulate", "--channels", "2"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("spawn emulate");
    let mut first = String::new();
    let read = BufReader::new(child.stdout.take().expect("stdout")).read_line(&mut first);
    let _ = child.kill();
    let _ = child.wait();
    read.expect("read first line");
    let path = first.trim();
    assert!(path.starts_with("/dev/"), "first line is not a device path: `{path}`");
}
