//! End-to-end tests of the `thermode` binary: `materials` and `simulate`, run as a user would, with small helpers
//! that print what was expected and what came back; `serve` on `emulate` (killed, signalled) in
//! [`serve_on_emulator`].

use std::path::Path;
use std::process::{Command, Output};

// A module file, not a second test binary (Cargo builds every `tests/*.rs` as one).
#[cfg(unix)]
#[path = "cli/python_packages.rs"]
mod python_packages;
// clients/js and examples/webxr with Node's test runner (and headless Chromium).
#[cfg(unix)]
#[path = "cli/node_packages.rs"]
mod node_packages;
// The MATLAB/Octave client under octave-cli.
#[cfg(unix)]
#[path = "cli/matlab_client.rs"]
mod matlab_client;
// `lab export --bids`, checked by the reference validator.
#[cfg(unix)]
#[path = "cli/bids.rs"]
mod bids;
// `serve --lsl` (the streams themselves: python/lsl with pylsl).
#[cfg(unix)]
#[path = "cli/lsl.rs"]
mod lsl;
#[path = "cli/serve_on_emulator.rs"]
mod serve_on_emulator;
// `simulate` and `render` to Arrow IPC and Parquet.
#[path = "cli/columnar.rs"]
mod columnar;
#[cfg(unix)]
#[path = "cli/service.rs"]
mod service;

// `lab run --simulate --seed/--renderer` and the new `lab analyze` outputs.
#[path = "cli/lab_simulate.rs"]
mod lab_simulate;

// Procedure files run by `lab run`, analysed and exported.
#[cfg(unix)]
#[path = "cli/procedures.rs"]
mod procedures;

// A device file's calibration on every backend's own lines, judged by the emulators' true plate.
#[cfg(unix)]
#[path = "cli/calibrated_lines.rs"]
mod calibrated_lines;

// MeCom and TCS II emulators with `bench` on them.
#[cfg(unix)]
#[path = "cli/hardware.rs"]
mod hardware;

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

/// `serve` on a one-channel simulated display with the state directory `dir`, stopping at once (free port, no OSC).
fn serve_once_on(dir: &str) -> [&str; 10] {
    [
        "serve",
        "--state-dir",
        dir,
        "--port",
        "0",
        "--no-osc",
        "--channels",
        "1",
        "--duration",
        "0",
    ]
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
fn simulate_precision_rounds_every_quantity_and_keeps_time_exact() {
    let dir = tempfile::tempdir().expect("tempdir");
    let exact_path = dir.path().join("exact.csv");
    let rounded_path = dir.path().join("rounded.csv");
    let base = [
        "simulate",
        "--material",
        "steel",
        "--duration",
        "2",
        "--dt",
        "0.001",
        "--out",
    ];
    let run = |path: &Path, extra: &[&str]| {
        let mut args = base.to_vec();
        args.push(path.to_str().expect("path"));
        args.extend_from_slice(extra);
        expect_success(&args);
    };
    run(&exact_path, &[]);
    run(&rounded_path, &["--precision", "3"]);
    let (header, exact) = read_csv(&exact_path);
    let (rounded_header, rounded) = read_csv(&rounded_path);
    assert_eq!((&header, exact.len()), (&rounded_header, rounded.len()));
    for (row, (e, r)) in exact.iter().zip(&rounded).enumerate() {
        assert_eq!(e[0], r[0], "row {row}: time_s is written exact");
        for (name, (e, r)) in header.iter().zip(e.iter().zip(r)).skip(1) {
            let Ok(exact_value) = e.parse::<f64>() else {
                assert_eq!(e, r, "row {row} {name}");
                continue;
            };
            let decimals = r.split_once('.').map_or(0, |(_, fraction)| fraction.len());
            let value: f64 = r.parse().expect("number");
            assert!(
                decimals == 3 && (value - exact_value).abs() <= 5.0005e-4,
                "row {row} {name}: {r} written for {e}"
            );
        }
    }
    expect_error(&["simulate", "--material", "steel", "--precision", "13"], "--precision");
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
        &["simulate", "--material", "wood", "--out", "/dev/null/x.csv"],
        "cannot write",
    );
    expect_error(&["simulate", "--material", "wood", "--plot", "x.jpg"], ".svg or .png");
    expect_error(&["simulate", "--material-file", "/nonexistent/m.toml"], "cannot read");
    // An endless file given for a settings file is refused at 16 MiB, not read until the memory is gone.
    for option in ["--material-file", "--skin"] {
        let mut args = vec!["simulate", option, "/dev/zero"];
        if option == "--skin" {
            args.extend(["--material", "wood"]);
        }
        expect_error(&args, "cannot read /dev/zero: larger than 16 MiB");
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let material = dir.path().join("m.toml");
    std::fs::write(&material, "name = \"x\"\nconductivity_w_mk = 1.0\nconductivity_cal_cm_s_c = 0.002\ndensity_kg_m3 = 1000\nspecific_heat_j_kgk = 1000\n").expect("write");
    expect_error(
        &["simulate", "--material-file", material.to_str().expect("path")],
        "conductivity_cal_cm_s_c",
    );
}

#[test]
fn simulate_fv_level_runs_one_grid_and_bad_levels_or_tolerances_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("fv.csv");
    let out = csv.to_str().expect("path");
    let base = ["simulate", "--model", "fv", "--material", "wood", "--duration", "2"];
    fn with<'a>(base: &[&'a str], extra: &[&'a str]) -> Vec<&'a str> {
        base.iter().chain(extra).copied().collect()
    }
    let run = thermode(&with(
        &base,
        &["--fv-level", "1", "--fv-tolerance", "1e-4", "--out", out],
    ));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(
        stderr.contains("62 skin + 81 object cells") && stderr.contains("convergence not checked"),
        "level 1 of the default grid: {stderr}"
    );
    let (header, rows) = read_csv(&csv);
    assert_eq!(rows.len(), 201, "rows every 10 ms over 2 s");
    let surface = column(&header, &rows, "skin_surface_c");
    assert!(surface.iter().all(|c| (20.0..37.0).contains(c)), "{surface:?}");
    expect_error(&with(&base, &["--fv-level", "7"]), "fv_level");
    expect_error(&with(&base, &["--fv-tolerance", "0"]), "fv_tolerance_c");
    expect_error(&with(&base, &["--fv-tolerance", "nan"]), "fv_tolerance_c");
    expect_error(&["simulate", "--material", "wood", "--fv-level", "2"], "--model fv");
}

#[test]
fn unphysical_input_is_refused_with_its_range_and_writes_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("out.csv");
    let out = csv.to_str().expect("path");
    let simulate = |extra: &[&'static str]| -> Vec<&str> {
        let mut args = vec!["simulate", "--duration", "1", "--out", out];
        args.extend_from_slice(extra);
        args
    };
    // An oven for air, colder than absolute zero, an unheard-of skin: each named with its range.
    expect_error(
        &simulate(&["--material", "wood", "--ambient", "1000"]),
        "`ambient_c` = 1000 is invalid: must be a finite number from -30 to 50",
    );
    expect_error(
        &simulate(&["--material", "wood", "--object-temp", "-300"]),
        "`object_c` = -300 is invalid: must be a finite number from -50 to 150",
    );
    expect_error(
        &simulate(&["--material", "wood", "--initial", "uniform:80"]),
        "must be a finite number from 0 to 50",
    );
    // A material with k = 1e300 (fv gave NaN curves, kron a table of nonsense, both with exit 0).
    let material = dir.path().join("hyper.toml");
    std::fs::write(
        &material,
        "name = \"hyper\"\nconductivity_w_mk = 1e300\ndensity_kg_m3 = 1000\nspecific_heat_j_kgk = 1000\n",
    )
    .expect("write");
    let path = material.to_str().expect("path");
    for model in ["fv", "kron", "semi-infinite"] {
        let mut args = simulate(&["--model", model]);
        args.extend(["--material-file", path]);
        expect_error(
            &args,
            "`conductivity_w_mk` = 1e300 is invalid: must be a finite number from 0.01 to 2500",
        );
    }
    let mut args = simulate(&[]);
    args.extend(["--material-file", path]);
    let stderr = String::from_utf8_lossy(&thermode(&args).stderr).to_string();
    assert_eq!(stderr.matches("is invalid").count(), 1, "said once: {stderr}");
    expect_error(
        &["render", "--material", "wood", "--object-temp", "-300", "--out", out],
        "object temperature [°C]` = -300",
    );
    expect_error(
        &["render", "--material", "wood", "--max-rate", "301", "--out", out],
        "max_setpoint_rate",
    );
    assert!(!csv.exists(), "a refused run left {}", csv.display());
}

#[test]
fn work_too_large_for_memory_is_refused_before_it_starts() {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("big.csv");
    let out = csv.to_str().expect("path");
    // 3000 s at 100 kHz: 3e8 rows, about 46 GB; aborted on a failed allocation before.
    let args = [
        "render",
        "--material",
        "wood",
        "--duration",
        "3000",
        "--rate",
        "100000",
        "--out",
        out,
    ];
    let started = std::time::Instant::now();
    expect_error(&args, "more than the 1074 MB one command may use");
    expect_error(&args, "use a lower tick rate, a shorter duration or fewer runs");
    // Refused up front, not after rendering (a generous bound: the run itself would take hours).
    assert!(started.elapsed().as_secs() < 60, "took {:?}", started.elapsed());
    // The issue's case (an hour at 100 kHz, 3.6e8 rows): refused for its memory, not aborted.
    expect_error(
        &[
            "render",
            "--material",
            "wood",
            "--duration",
            "3599",
            "--rate",
            "100000",
            "--out",
            out,
        ],
        "more than the 1074 MB one command may use",
    );
    // Over the one-hour duration range the duration is refused first.
    expect_error(
        &["render", "--material", "wood", "--duration", "3601", "--out", out],
        "duration [s]` = 3601",
    );
    // Ten runs that each fit but not together.
    expect_error(
        &[
            "render",
            "--material",
            "all-paper",
            "--controller",
            "both",
            "--duration",
            "3500",
            "--rate",
            "1000",
            "--out",
            out,
        ],
        "10 run(s)",
    );
    // fv keeps two refinement levels of every row: an hour at 0.4 ms is about 2.4 GB.
    expect_error(
        &[
            "simulate",
            "--material",
            "wood",
            "--model",
            "fv",
            "--duration",
            "3600",
            "--dt",
            "0.0004",
            "--out",
            out,
        ],
        "more than the 1074 MB",
    );
    assert!(!csv.exists(), "a refused run left {}", csv.display());
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
        "rms_truth_0_3_c",
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
    // A 3 s run is summarised over 0–3 s, and its keys say so.
    assert!(
        row.get("rms_skin_0_90_c").is_none() && row["window_end_s"] == 3.0,
        "{row}"
    );
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
    // Default finger and fv renderer: the truth (converged fv) and the target (the renderer's coarse fv, one step
    // per tick) are the same physics and differ only by the renderer's discretisation, a few hundredths of a °C.
    let truth = column(&header, &rows, "truth_skin_c");
    let target = column(&header, &rows, "target_skin_c");
    for (row, (a, b)) in truth.iter().zip(&target).enumerate() {
        assert!((a - b).abs() < 0.15, "row {row}: truth {a}, target {b}");
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

/// The state directory's ledger as JSON (panics if it cannot be read).
fn ledger_json(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("dose-ledger.json")).expect("read the ledger");
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("ledger: {e}: {text}"))
}

#[test]
fn dose_show_and_reset_and_a_corrupt_ledger_is_refused_never_reset() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().to_str().expect("utf-8 path");
    let out = expect_success(&["dose", "show", "--state-dir", dir]);
    assert!(out.contains("no dose recorded"), "{out}");
    // A ledger with a locked channel, as `serve` writes it.
    let ledger = r#"{"format": "thermode-dose-ledger", "version": 1, "channels": [
        {"channel": 2, "cem43_min": 1.0125, "time_at_or_above_43_s": 3.5, "lockout": true,
         "updated_utc": "2025-01-31T12:00:00Z"}]}"#;
    std::fs::write(tmp.path().join("dose-ledger.json"), ledger).expect("write");
    let out = expect_success(&["dose", "show", "--state-dir", dir]);
    assert!(
        out.contains("1.012500") && out.contains("yes") && out.contains("2025-01-31T12:00:00Z"),
        "{out}"
    );
    let json: serde_json::Value = serde_json::from_str(&expect_success(&[
        "dose",
        "show",
        "--state-dir",
        dir,
        "--format",
        "json",
    ]))
    .expect("json");
    assert_eq!(json["channels"][0]["channel"], 2);
    // A reset needs a reason and a channel (or --all).
    expect_error(
        &["dose", "reset", "--channel", "2", "--reason", "  ", "--state-dir", dir],
        "reason",
    );
    let out = thermode(&["dose", "reset", "--reason", "x", "--state-dir", dir]);
    assert_eq!(out.status.code(), Some(2), "reset without --channel or --all");
    let out = expect_success(&[
        "dose",
        "reset",
        "--channel",
        "2",
        "--reason",
        "new participant P07",
        "--state-dir",
        dir,
    ]);
    assert!(
        out.contains("dose reset channel 2: cem43_min 1.0125") && out.contains("new participant P07"),
        "{out}"
    );
    let log = std::fs::read_to_string(tmp.path().join("dose-reset.log")).expect("log");
    assert_eq!(log.lines().count(), 1, "{log}");
    assert!(
        log.starts_with("20") && log.contains("Z dose reset channel 2"),
        "UTC time first: {log}"
    );
    assert_eq!(ledger_json(tmp.path())["channels"].as_array().map(Vec::len), Some(0));
    // Corrupt: serve, show and a channel reset refuse (exit 2) and leave the file as it is; reset --all sets it aside.
    let corrupt = "{\"format\": \"thermode-dose-ledger\", \"version\": 1, \"channels\": [{\"channel\": 0,";
    std::fs::write(tmp.path().join("dose-ledger.json"), corrupt).expect("write");
    let serve = serve_once_on(dir);
    expect_error(&serve, "corrupt");
    expect_error(&["dose", "show", "--state-dir", dir], "corrupt");
    expect_error(
        &["dose", "reset", "--channel", "0", "--reason", "x", "--state-dir", dir],
        "corrupt",
    );
    let kept = std::fs::read_to_string(tmp.path().join("dose-ledger.json")).expect("read");
    assert_eq!(kept, corrupt, "the corrupt ledger is left as it is");
    let out = expect_success(&["dose", "reset", "--all", "--reason", "disk error", "--state-dir", dir]);
    assert!(out.contains("set aside as"), "{out}");
    let out = expect_success(&["dose", "show", "--state-dir", dir]);
    assert!(out.contains("no dose recorded"), "{out}");
    assert_eq!(
        std::fs::read_to_string(tmp.path().join("dose-reset.log"))
            .expect("log")
            .lines()
            .count(),
        2
    );
}

/// `thermode args`, killed and failed if it runs for 60 s (a FIFO ledger blocked `serve` for ever).
fn thermode_within_60_s(args: &[&str]) -> Output {
    with_env_within_60_s(args, &[])
}

/// The output of `child` (thermode with `args`), killed and a panic if it still runs after 60 s.
fn wait_within_60_s(mut child: std::process::Child, args: &[&str]) -> Output {
    let start = std::time::Instant::now();
    while child.try_wait().expect("wait").is_none() {
        if start.elapsed().as_secs_f64() > 60.0 {
            let _ = child.kill();
            let _ = child.wait();
            panic!("thermode {args:?} still runs after 60 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.wait_with_output().expect("output")
}

/// Hostile ledgers: a link to `/dev/zero` (grew `serve` to 3.3 GB in 6 s), a FIFO (blocked it for ever), a dose
/// of 1e308, an entry for channel 99, NaN. `serve` and `dose show` refuse each at once with exit 2 and a message
/// naming what is wrong.
#[cfg(unix)]
#[test]
fn hostile_ledgers_are_refused_at_once_naming_what_is_wrong() {
    let entry = |channel: &str, cem43: &str| {
        format!(
            "{{\"format\": \"thermode-dose-ledger\", \"version\": 1, \"channels\": [{{\"channel\": {channel}, \
             \"cem43_min\": {cem43}, \"time_at_or_above_43_s\": 0, \"lockout\": false, \
             \"updated_utc\": \"2025-01-31T12:00:00Z\"}}]}}"
        )
    };
    let cases: [(&str, Option<String>, &str); 5] = [
        ("/dev/zero link", None, "a device, not a regular file"),
        ("FIFO", None, "a FIFO, not a regular file"),
        ("1e308", Some(entry("0", "1e308")), "`cem43_min` = 1e308"),
        ("channel 99", Some(entry("99", "0.5")), "`channel` = 99"),
        ("NaN", Some(entry("0", "NaN")), "corrupt"),
    ];
    for (what, text, message) in cases {
        let tmp = tempfile::tempdir().expect("temp dir");
        let dir = tmp.path().to_str().expect("utf-8 path");
        let path = tmp.path().join("dose-ledger.json");
        match (&text, what) {
            (Some(text), _) => std::fs::write(&path, text).expect("write"),
            (None, "FIFO") => {
                let made = Command::new("mkfifo").arg(&path).status().expect("mkfifo");
                assert!(made.success(), "mkfifo");
            }
            (None, _) => std::os::unix::fs::symlink("/dev/zero", &path).expect("symlink"),
        }
        let serve = serve_once_on(dir);
        for args in [&serve[..], &["dose", "show", "--state-dir", dir][..]] {
            let out = thermode_within_60_s(args);
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{what}: thermode {args:?}: {stderr}");
            assert!(
                stderr.contains(message),
                "{what}: thermode {args:?}: stderr lacks `{message}`: {stderr}"
            );
        }
    }
}

/// Special files where `serve` would wait for ever (issue 35, finding 9): `--record X.arrow` with X a FIFO (written
/// when serve stops, after the drives are off: it blocked there, deaf to SIGINT), or its clock sidecar a FIFO, and
/// `--lsl` with a FIFO as the library (the loader waited for a writer at start). Each is refused at start, exit 2,
/// one line naming the file and what it is, before anything listens.
#[cfg(unix)]
#[test]
fn serve_refuses_special_files_it_would_wait_on_for_ever() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let state = tmp.path().join("state");
    let state = state.to_str().expect("utf-8 path");
    let mkfifo = |path: &std::path::Path| {
        let made = Command::new("mkfifo").arg(path).status().expect("mkfifo");
        assert!(made.success(), "mkfifo {}", path.display());
        path.to_str().expect("utf-8 path").to_string()
    };
    let arrow = mkfifo(&tmp.path().join("session.arrow"));
    let sidecar_of = tmp.path().join("other.arrow");
    mkfifo(&sidecar_of.with_extension("clock.json"));
    let library = mkfifo(&tmp.path().join("liblsl.so"));
    let sidecar_of = sidecar_of.to_str().expect("utf-8 path");
    let serve = serve_once_on(state);
    let cases: [(&str, Vec<&str>, Option<&str>, &str); 3] = [
        ("--record FIFO", vec!["--record", &arrow], None, &arrow),
        (
            "--record, sidecar FIFO",
            vec!["--record", sidecar_of],
            None,
            "other.clock.json",
        ),
        ("--lsl, library FIFO", vec!["--lsl"], Some(&library), &library),
    ];
    for (what, extra, liblsl, names) in cases {
        let mut args = serve.to_vec();
        args.extend(extra);
        let out = match liblsl {
            Some(library) => with_env_within_60_s(&args, &[("THERMODE_LIBLSL", library)]),
            None => thermode_within_60_s(&args),
        };
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{what}: {stderr}");
        let errors: Vec<&str> = stderr.lines().filter(|l| l.contains("error")).collect();
        assert!(
            errors.len() == 1 && errors[0].contains("a FIFO, not a regular file") && errors[0].contains(names),
            "{what}: {stderr}"
        );
        assert!(
            !String::from_utf8_lossy(&out.stdout).contains("ws://"),
            "{what}: it listened before refusing"
        );
    }
}

/// A Python that hangs when asked where `pylsl` lives held `serve --lsl` at start for ever (issue 35, finding 9): the
/// probe is now killed at its time-out and named among what was tried (where the system has no liblsl of its own;
/// with one, serve starts before asking Python).
#[cfg(unix)]
#[test]
fn serve_lsl_with_a_hanging_python_probe_ends_and_names_it() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let python = tmp.path().join("python3");
    std::fs::write(&python, "#!/bin/sh\nexec sleep 600\n").expect("write the hanging python");
    let made = Command::new("chmod").arg("+x").arg(&python).status().expect("chmod");
    assert!(made.success(), "chmod");
    let state = tmp.path().join("state");
    let mut args = serve_once_on(state.to_str().expect("utf-8 path")).to_vec();
    args.push("--lsl");
    let out = with_env_within_60_s(&args, &[("THERMODE_PYTHON", python.to_str().expect("utf-8 path"))]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    if out.status.success() {
        println!("skipped: this system has a liblsl of its own, found before Python is asked");
        return;
    }
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("asked of") && stderr.contains("no answer within 5 s: killed"),
        "{stderr}"
    );
}

/// [`thermode_within_60_s`] with `envs` set.
fn with_env_within_60_s(args: &[&str], envs: &[(&str, &str)]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_thermode"));
    command
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    for (key, value) in envs {
        command.env(key, value);
    }
    wait_within_60_s(command.spawn().expect("run thermode"), args)
}

/// An OSC message `/thermode/channel/<channel>/setpoint f f`.
fn osc_setpoint(channel: usize, temp_c: f32, rate_c_per_s: f32) -> Vec<u8> {
    fn padded(text: &str) -> Vec<u8> {
        let mut bytes = text.as_bytes().to_vec();
        bytes.push(0);
        while !bytes.len().is_multiple_of(4) {
            bytes.push(0);
        }
        bytes
    }
    let mut message = padded(&format!("/thermode/channel/{channel}/setpoint"));
    message.extend(padded(",ff"));
    message.extend(temp_c.to_be_bytes());
    message.extend(rate_c_per_s.to_be_bytes());
    message
}

/// `GET /api/status` of the daemon at `addr` as JSON.
fn status(addr: &str) -> serde_json::Value {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(std::time::Duration::from_secs(10)))
        .expect("timeout");
    write!(
        stream,
        "GET /api/status HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .expect("send");
    let mut response = String::new();
    stream.read_to_string(&mut response).expect("read");
    let body = response.split_once("\r\n\r\n").map_or("", |(_, b)| b);
    serde_json::from_str(body).unwrap_or_else(|e| panic!("status: {e}: {response}"))
}

/// `serve` heating one channel at 48 °C is killed with SIGKILL: the ledger it leaves is whole and holds at least
/// the dose the daemon reported before its last write; while it ran, a reset was refused (the state directory is
/// locked); after the kill the lock is gone and a reset works.
#[test]
fn a_sigkilled_serve_leaves_a_whole_ledger_with_the_dose_it_reported() {
    use std::io::{BufRead, BufReader};
    use std::time::{Duration, Instant};
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().to_str().expect("utf-8 path");
    let mut child = Command::new(env!("CARGO_BIN_EXE_thermode"))
        .args([
            "serve",
            "--state-dir",
            dir,
            "--port",
            "0",
            "--osc-port",
            "0",
            "--channels",
            "1",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("spawn serve");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    let (mut http, mut osc, mut ledger_line) = (None, None, None);
    while http.is_none() || osc.is_none() || ledger_line.is_none() {
        let line = lines.next().expect("banner line").expect("utf-8");
        let word = |prefix: &str| line.trim().strip_prefix(prefix).map(|rest| rest.trim().to_string());
        if let Some(url) = word("dashboard") {
            http = url.strip_prefix("http://").map(|u| u.trim_end_matches('/').to_string());
        } else if let Some(url) = word("OSC") {
            osc = url.strip_prefix("udp://").map(str::to_string);
        } else if let Some(path) = word("dose") {
            ledger_line = Some(path);
        }
    }
    let (http, osc) = (http.expect("http"), osc.expect("osc"));
    assert_eq!(ledger_line.as_deref(), tmp.path().join("dose-ledger.json").to_str());
    let socket = std::net::UdpSocket::bind("127.0.0.1:0").expect("udp");
    socket.send_to(&osc_setpoint(0, 48.0, 20.0), &osc).expect("send osc");
    // Wait for dose to accumulate (the loop runs in real time; 48 °C spends 0.53 CEM43-min per second).
    let start = Instant::now();
    let reported = loop {
        let s = status(&http);
        let dose = s["channels"][0]["cem43_min"].as_f64().expect("cem43_min");
        if dose >= 0.2 {
            break dose;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "no dose after 60 s: {s}");
        std::thread::sleep(Duration::from_millis(50));
    };
    expect_error(
        &["dose", "reset", "--channel", "0", "--reason", "x", "--state-dir", dir],
        "in use",
    );
    // The writer (every 0.25 s) catches up with what was reported; then the daemon is killed.
    let written_at = Instant::now();
    let written = loop {
        let written = ledger_json(tmp.path())["channels"][0]["cem43_min"]
            .as_f64()
            .unwrap_or(0.0);
        if written >= reported {
            break written;
        }
        assert!(
            written_at.elapsed() < Duration::from_secs(10),
            "ledger {written} never reached {reported}"
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    println!(
        "reported {reported} CEM43-min; the ledger held {written} {:.3} s later",
        written_at.elapsed().as_secs_f64()
    );
    child.kill().expect("SIGKILL");
    let _ = child.wait();
    let after = ledger_json(tmp.path());
    let saved = after["channels"][0]["cem43_min"].as_f64().expect("a whole ledger");
    assert!(saved >= reported, "ledger {saved} < reported {reported}");
    let out = expect_success(&[
        "dose",
        "reset",
        "--channel",
        "0",
        "--reason",
        "test",
        "--state-dir",
        dir,
    ]);
    assert!(out.contains("dose reset channel 0"), "{out}");
}

#[test]
fn dash_is_standard_output_and_a_bad_second_output_leaves_nothing_behind() {
    let out = thermode(&["simulate", "--material", "wood", "--duration", "1", "--out", "-"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let csv = String::from_utf8_lossy(&out.stdout);
    assert!(
        csv.starts_with("time_s,"),
        "standard output is not the CSV: {}",
        &csv[..80.min(csv.len())]
    );
    assert!(!Path::new("-").exists(), "a file named `-` was written");
    let dir = tempfile::tempdir().expect("tempdir");
    let csv_path = dir.path().join("x.csv");
    let csv_arg = csv_path.to_str().expect("utf-8");
    expect_error(
        &[
            "simulate",
            "--material",
            "wood",
            "--out",
            csv_arg,
            "--plot",
            "/dev/null/p.png",
        ],
        "--plot /dev/null/p.png: cannot write in /dev/null",
    );
    assert!(!csv_path.exists(), "the CSV was left behind");
    // Commands that work for minutes before they write check their output first.
    expect_error(
        &["tune", "--out", "/dev/null/gains.toml"],
        "--out /dev/null/gains.toml: cannot write in /dev/null",
    );
    let refused = thermode(&["render", "--material", "wood", "--plot", "figure.jpg"]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(2), "{stderr}");
    assert_eq!(
        stderr.trim(),
        "thermode: error: --plot figure.jpg: plots are written as .svg or .png"
    );
}

#[test]
fn serve_checks_its_options_before_opening_ports_and_says_who_holds_a_port() {
    let state = tempfile::tempdir().expect("tempdir");
    let state_arg = state.path().to_str().expect("utf-8");
    let out = thermode(&[
        "serve",
        "--duration=-1",
        "--port",
        "0",
        "--no-osc",
        "--state-dir",
        state_arg,
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        !stdout.contains("dashboard") && !stdout.contains("running"),
        "banner before the refusal: {stdout}"
    );
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("a port");
    let port = taken.local_addr().expect("address").port().to_string();
    // A state directory and a recording folder not made yet: a start that fails on its port leaves neither.
    let (fresh_state, fresh_record) = (state.path().join("fresh-state"), state.path().join("fresh-record"));
    let out = thermode(&[
        "serve",
        "--port",
        &port,
        "--no-osc",
        "--duration",
        "0",
        "--state-dir",
        fresh_state.to_str().expect("utf-8"),
        "--record",
        fresh_record.to_str().expect("utf-8"),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        !fresh_state.exists() && !fresh_record.exists(),
        "a failed start left files: state {}, record {}",
        fresh_state.exists(),
        fresh_record.exists()
    );
    assert!(
        stderr.contains("another `thermode serve` or `thermode demo`"),
        "{stderr}"
    );
    assert_eq!(
        stderr.matches("os error").count(),
        1,
        "the cause is printed once: {stderr}"
    );
}

/// Every file of `dir`, by name, with its text, less the sidecars' wall-clock start (`started_utc`: the one thing
/// that differs between two runs of the same simulation).
fn files_of(dir: &Path) -> Vec<(String, String)> {
    let mut files: Vec<(String, String)> = std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| {
            let path = e.expect("entry").path();
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default();
            let text = std::fs::read_to_string(&path).expect("read file");
            let kept: Vec<&str> = text.lines().filter(|l| !l.contains("\"started_utc\"")).collect();
            (name, kept.join("\n"))
        })
        .collect();
    files.sort();
    files
}

#[test]
fn lab_run_batches_participants_with_output_independent_of_the_thread_count() {
    let experiment = concat!(env!("CARGO_MANIFEST_DIR"), "/../thermode-lab/experiments/paper.toml");
    let tmp = tempfile::tempdir().expect("temp dir");
    let base = |dir: &Path| -> Vec<String> {
        [
            "lab",
            "run",
            "--simulate",
            "--experiment",
            experiment,
            "--observer",
            "--time-scale",
            "0",
            "--data-dir",
        ]
        .iter()
        .map(|s| s.to_string())
        .chain([dir.display().to_string()])
        .collect()
    };
    let run = |dir: &Path, extra: &[&str]| -> String {
        let mut args = base(dir);
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        expect_success(&args).replace(&dir.display().to_string(), "DIR")
    };
    let who = ["--participant", "P01", "--participant", "P02", "--participant", "P03"];
    let (one, three, single) = (
        tmp.path().join("one"),
        tmp.path().join("three"),
        tmp.path().join("single"),
    );
    let out_one = run(&one, &[&who[..], &["--jobs", "1"]].concat());
    let out_three = run(&three, &[&who[..], &["--jobs", "3"]].concat());
    assert_eq!(
        out_one, out_three,
        "the printed output does not depend on the thread count"
    );
    assert!(
        out_one.contains("== P03") && out_one.contains("session complete"),
        "{out_one}"
    );
    assert_eq!(files_of(&one), files_of(&three), "nor do the session files");
    for p in ["P01", "P02", "P03"] {
        run(&single, &["--participant", p]);
    }
    assert_eq!(
        files_of(&single),
        files_of(&one),
        "a batch writes what single runs write"
    );
    assert_eq!(files_of(&one).len(), 6, "a CSV and a sidecar per participant");
    let keyboard = [
        "lab",
        "run",
        "--simulate",
        "--experiment",
        experiment,
        "--participant",
        "P01",
        "--participant",
        "P02",
    ];
    expect_error(&keyboard, "only with --simulated-participant");
    let mut zero = base(tmp.path());
    zero.extend(["--all-participants", "--jobs", "0"].map(String::from));
    let zero: Vec<&str> = zero.iter().map(String::as_str).collect();
    expect_error(&zero, "--jobs 0");
}

/// `lab run` on a display (`--device sim`: the simulated display run as `serve` runs it, in real time, through the
/// daemon's WebSocket API): the finger is measured on the plate at rest, the measurements go in the `finger_*`
/// columns (none in `model_finger_*`), each trial's curve is kept beside the session CSV and `lab analyze --curves`
/// reads it; the same command after the end finds the session complete. The plant's finger is the fv fingertip,
/// whose receptor rests at 32.13 °C in 23 °C air (README: fv surface at rest); the display renders air for it.
#[test]
fn lab_run_on_a_display_measures_the_finger_on_it_and_keeps_each_trials_curve() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let experiment = tmp.path().join("mini.toml");
    std::fs::write(
        &experiment,
        "name = \"mini\"\nmaterials = [\"aluminium\", \"wood\"]\nconditions = [\"simulated\", \"real\"]\n\
         participants = 1\nrepetitions = 1\npresentation_s = 2.0\nresponse_options = [\"aluminium\", \"wood\"]\n\
         exclusion_max_drift_c = 1.0\nseed = 7\n",
    )
    .expect("write experiment");
    let data = tmp.path().join("data");
    let (experiment, data_dir, state) = (
        experiment.display().to_string(),
        data.display().to_string(),
        tmp.path().join("state").display().to_string(),
    );
    let args = [
        "lab",
        "run",
        "--experiment",
        &experiment,
        "--participant",
        "P01",
        "--device",
        "sim",
        "--state-dir",
        &state,
        "--simulated-participant",
        "--data-dir",
        &data_dir,
    ];
    let out = expect_success(&args);
    assert!(out.contains("session complete: 4 trials"), "{out}");
    let session = std::fs::read_dir(&data)
        .expect("data folder")
        .map(|e| e.expect("entry").path())
        .find(|p| p.extension().is_some_and(|e| e == "csv"))
        .expect("a session CSV");
    let csv = std::fs::read_to_string(&session).expect("session CSV");
    let mut reader = csv::Reader::from_reader(csv.as_bytes());
    let header = reader.headers().expect("header").clone();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no {name}"))
    };
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.expect("row")).collect();
    assert_eq!(rows.len(), 4, "{csv}");
    let baseline_c: f64 = rows[0][column("finger_start_c")].parse().expect("a measured start");
    assert!(
        (baseline_c - 32.13).abs() < 0.3,
        "finger measured at rest before the first trial {baseline_c} °C vs the plant's 32.13 °C"
    );
    for row in &rows {
        let number = |name: &str| -> f64 { row[column(name)].parse().unwrap_or_else(|_| panic!("{name}: {row:?}")) };
        let (start_c, end_c) = (number("finger_start_c"), number("finger_end_c"));
        assert!(
            row[column("model_finger_start_c")].is_empty(),
            "nothing simulated in a measured session"
        );
        if &row[column("condition")] == "simulated" {
            // Aluminium and wood at 23 °C both draw heat: the finger comes back to the plate cooler (by 0.2–1 °C
            // after 2 s of contact and a rest, depending on how far it had recovered before).
            assert!(
                end_c < start_c,
                "a cold touch cooled the finger: {start_c} -> {end_c} °C"
            );
        }
        let presentation_s: f64 = row[column("presentation_s")].parse().expect("presentation");
        assert!(
            (presentation_s - 2.0).abs() < 0.02,
            "the contact lasted {presentation_s} s of 2"
        );
        let curve = std::fs::read_to_string(data.join(&row[column("curve_file")])).expect("the trial's curve");
        // Telemetry is best effort (a loaded machine skips publications): at least half of the 10 ms ticks, and
        // the curve spans the presentation.
        let times: Vec<f64> = curve
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(3).and_then(|t| t.parse().ok()).expect("time_s"))
            .collect();
        assert!(
            (100..=202).contains(&times.len()) && times[0] < 0.1 && times[times.len() - 1] >= 2.0,
            "{} samples from {} to {} s: a sample per 10 ms tick over 2 s, at least half of them",
            times.len(),
            times[0],
            times[times.len() - 1]
        );
    }
    let simulated = rows
        .iter()
        .find(|r| &r[column("condition")] == "simulated")
        .expect("a simulated trial");
    let curves = data.join(&simulated[column("curve_file")]).display().to_string();
    let session = session.display().to_string();
    let analysis = expect_success(&["lab", "analyze", &session, "--curves", &curves, "--format", "json"]);
    assert!(
        analysis.contains("\"finger_c\""),
        "the curve's temperature is the measured finger: {analysis}"
    );
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(Path::new(&session).with_extension("json")).expect("sidecar"))
            .expect("JSON sidecar");
    let started = sidecar["started_utc"].as_str().unwrap_or_default();
    assert!(
        started.len() == 24 && started.ends_with('Z'),
        "UTC ISO 8601 start with ms: {started}"
    );
    let display = &sidecar["device"]["stimulus"]["display"];
    assert!(
        display["loop_time_zero_unix_s"].as_f64().is_some_and(f64::is_finite),
        "{display}"
    );
    let again = expect_success(&args);
    assert!(again.contains("session already complete"), "{again}");
}

#[test]
fn lab_run_needs_a_display_or_an_explicit_simulation() {
    let experiment = concat!(env!("CARGO_MANIFEST_DIR"), "/../thermode-lab/experiments/paper.toml");
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().display().to_string();
    let base = [
        "lab",
        "run",
        "--experiment",
        experiment,
        "--participant",
        "P01",
        "--data-dir",
        &dir,
    ];
    expect_error(&base, "--simulate (the offline simulation)");
    expect_error(
        &[&base[..], &["--display", "ws://127.0.0.1:1"]].concat(),
        "cannot reach the display at ws://127.0.0.1:1",
    );
    expect_error(&[&base[..], &["--display", "http://x"]].concat(), "ws://HOST:PORT");
}

/// `thermode identify` writes a device file that `render` reads, and refuses a display that reports no voltage or
/// an output it could not write, before it starts.
#[test]
fn identify_writes_a_device_file_render_reads_and_refuses_a_display_without_voltage() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let out = tmp.path().join("identified.toml");
    let out_arg = out.display().to_string();
    expect_success(&["identify", "--out", &out_arg]);
    let text = std::fs::read_to_string(&out).expect("identified file");
    assert!(text.starts_with("# Identified by `thermode identify`"), "{text}");
    let summary = expect_success(&["render", "--material", "wood", "--device-file", &out_arg, "--summary"]);
    assert!(summary.contains("wood"), "{summary}");
    expect_error(&["identify", "--device", "serial:/dev/null"], "Peltier voltage");
    // A folder that cannot take the file is refused before the excitation, not after it.
    let refused = thermode(&["identify", "--out", "/dev/null/identified.toml"]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("cannot write in /dev/null"), "{stderr}");
    assert!(!stderr.contains("excitation"), "started the excitation first: {stderr}");
}

/// The path policy (README): every output folder is created, with its parents, by the command that writes into it;
/// a command refused before its work leaves no folder; a folder that cannot be created is refused first.
#[test]
fn every_output_folder_is_created_and_a_refused_command_leaves_none() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = |rel: &str| dir.path().join(rel).to_string_lossy().into_owned();
    let experiment = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../thermode-lab/experiments/paper.toml")
        .to_string_lossy()
        .into_owned();
    for args in [
        vec![
            "simulate",
            "--material",
            "wood",
            "--duration",
            "1",
            "--out",
            &path("a/b/sim.csv"),
        ],
        vec![
            "simulate",
            "--material",
            "wood",
            "--duration",
            "1",
            "--plot",
            &path("c/d/sim.svg"),
        ],
        vec![
            "lab",
            "plan",
            "--experiment",
            &experiment,
            "--out",
            &path("e/f/plan.csv"),
        ],
    ] {
        let out = thermode(&args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    for file in ["a/b/sim.csv", "c/d/sim.svg", "e/f/plan.csv"] {
        assert!(dir.path().join(file).is_file(), "{file} not written");
    }
    // Refused before the work: nothing created.
    expect_error(
        &[
            "simulate",
            "--material",
            "wood",
            "--ambient",
            "1000",
            "--out",
            &path("g/sim.csv"),
        ],
        "ambient_c",
    );
    expect_error(
        &[
            "lab",
            "plan",
            "--experiment",
            &path("missing.toml"),
            "--out",
            &path("h/plan.csv"),
        ],
        "missing.toml",
    );
    for folder in ["g", "h"] {
        assert!(
            !dir.path().join(folder).exists(),
            "a refused command left {folder}/ behind"
        );
    }
}

/// `serve` (and `demo`, through the same stop) ended by `--duration` says how it stopped, as after a signal.
#[test]
fn serve_ended_by_its_duration_prints_a_summary() {
    let dir = tempfile::tempdir().expect("tempdir");
    let state = dir.path().join("state").to_string_lossy().into_owned();
    let args = [
        "serve",
        "--port",
        "0",
        "--no-osc",
        "--no-realtime",
        "--duration",
        "0.3",
        "--state-dir",
        &state,
    ];
    let out = thermode(&args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let summary = stderr
        .lines()
        .find(|l| l.starts_with("thermode: --duration passed: stopped at loop time "))
        .unwrap_or_else(|| panic!("no summary line: {stderr}"));
    assert!(summary.ends_with(" s, every drive set to 0 A"), "{summary}");
}
