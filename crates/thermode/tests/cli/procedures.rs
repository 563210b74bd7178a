//! `thermode lab run`, `lab analyze` and `lab export --bids` on procedure files, run as a lab would: the method of
//! limits on the simulated display against the analytic line at three rates, a QUEST+ session replayed through the
//! `questplus` package, a multi-zone program starting every channel on one tick, a scripted limits run on the TCS II
//! emulator (a temperature-commanded device), a procedure session's BIDS events, and `lab plan` refusing what `lab
//! run` refuses.

use std::path::{Path, PathBuf};
use std::process::Command;

use thermode_model::skin::Skin;
use thermode_procedures::participant::ParticipantConfig;
use thermode_procedures::skin_response::SkinResponse;

use super::{expect_success, read_csv, thermode};

fn experiment(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../thermode-lab/experiments")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

fn column(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
}

/// The one session CSV of `data`.
fn session_csv(data: &Path) -> PathBuf {
    let mut found: Vec<PathBuf> = std::fs::read_dir(data)
        .expect("data folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv") && !p.to_string_lossy().ends_with("_events.csv"))
        .collect();
    assert_eq!(found.len(), 1, "one session CSV in {}: {found:?}", data.display());
    found.remove(0)
}

/// `lab run` of `file` for P01 on the simulated display, answered by the simulated participant, into `data`.
fn simulated_run_args<'a>(file: &'a Path, data: &'a Path) -> [&'a str; 10] {
    [
        "lab",
        "run",
        "--experiment",
        file.to_str().expect("utf-8"),
        "--participant",
        "P01",
        "--simulate",
        "--simulated-participant",
        "--data-dir",
        data.to_str().expect("utf-8"),
    ]
}

fn run_simulated(file: &Path, data: &Path) -> String {
    expect_success(&simulated_run_args(file, data))
}

#[test]
fn the_method_of_limits_run_by_lab_follows_the_analytic_line_at_three_rates() {
    let participant = ParticipantConfig::default();
    let skin = SkinResponse::new(&Skin::fingertip(), participant.contact_conductance_w_m2k).expect("skin response");
    for rate_c_per_s in [1.0, 2.0, 4.0] {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("limits.toml");
        std::fs::write(
            &file,
            format!(
                "name = \"limits\"\nprocedure = \"limits\"\nseed = 3\nadaptation_s = 5.0\n[limits]\n\
                 tests = [\"CDT\", \"WDT\"]\nrate_c_s = {rate_c_per_s}\nruns = 3\nisi_s = 4.0\n\
                 [simulated_participant]\nthreshold_c = 0.5\nreaction_time_s = 0.4\nnoise_c = 0.0\nlapse = 0.0\n"
            ),
        )
        .expect("write experiment");
        let data = dir.path().join("data");
        run_simulated(&file, &data);
        let expected_c = skin
            .limits_estimate_c(0.5, rate_c_per_s, 0.4)
            .expect("the skin reaches the threshold");
        let (header, rows) = read_csv(&session_csv(&data));
        let (delivered, baseline, response) = (
            column(&header, "delivered_c"),
            column(&header, "baseline_c"),
            column(&header, "response"),
        );
        assert_eq!(rows.len(), 6, "CDT and WDT, three runs each");
        for row in &rows {
            assert_eq!(row[response], "press", "{row:?}");
            let change_c = (row[delivered].parse::<f64>().expect("delivered")
                - row[baseline].parse::<f64>().expect("baseline"))
            .abs();
            assert!(
                (change_c - expected_c).abs() <= 0.05,
                "at {rate_c_per_s} °C/s the display's plate at the press moved {change_c:.4} °C; the analytic line \
                 θ + r·(reaction time + skin lag) gives {expected_c:.4} °C"
            );
        }
    }
}

#[test]
fn a_multi_zone_program_starts_every_channel_on_one_tick_and_is_rated() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    run_simulated(Path::new(&experiment("thermal-grill.toml")), &data);
    let csv = session_csv(&data);
    let (header, rows) = read_csv(&csv);
    assert_eq!(rows.len(), 6, "three stimuli, two repetitions");
    let rating = column(&header, "rating");
    assert!(
        rows.iter()
            .all(|r| r[rating].parse::<f64>().is_ok_and(|v| (0.0..=100.0).contains(&v))),
        "{rows:?}"
    );
    let events = csv.with_file_name(
        csv.file_name()
            .expect("name")
            .to_string_lossy()
            .replace(".csv", "_events.csv"),
    );
    let (header, events) = read_csv(&events);
    let (trial, event, segment, channel, tick) = (
        column(&header, "trial"),
        column(&header, "event"),
        column(&header, "segment"),
        column(&header, "channel"),
        column(&header, "tick"),
    );
    for number in 1..=6 {
        let firsts: Vec<(String, String)> = events
            .iter()
            .filter(|e| e[trial] == number.to_string() && e[event] == "segment_start" && e[segment] == "0")
            .map(|e| (e[channel].clone(), e[tick].clone()))
            .collect();
        assert_eq!(firsts.len(), 5, "trial {number}: five channels start: {firsts:?}");
        assert!(
            firsts.iter().all(|(_, t)| *t == firsts[0].1),
            "trial {number}: one start tick: {firsts:?}"
        );
    }
}

/// Replays the session CSV's trials through the `questplus` package (the experiment's `[questplus]` table): each
/// trial's intensity must be the package's next one.
const REPLAY: &str = r#"
import csv, sys, tomllib
import numpy as np
import questplus
assert questplus.__version__ == "2023.1", questplus.__version__
config = tomllib.load(open(sys.argv[1], "rb"))["questplus"]
def domain(spec):
    if isinstance(spec, dict):
        return np.arange(spec["start"], spec["stop"], spec["step"])
    return spec
qp = questplus.QuestPlus(
    stim_domain={k: domain(v) for k, v in config["stim_domain"].items()},
    param_domain={k: domain(v) for k, v in config["param_domain"].items()},
    outcome_domain=config["outcome_domain"],
    func=config["func"],
    stim_scale=config["stim_scale"],
    stim_selection_method=config["stim_selection_method"],
    param_estimation_method=config["param_estimation_method"],
)
rows = list(csv.DictReader(open(sys.argv[2])))
assert len(rows) == config["trials"], len(rows)
for row in rows:
    want = qp.next_stim["intensity"]
    got = abs(float(row["intensity_c"]))
    assert abs(got - want) <= 1e-9 * max(1.0, abs(want)), (row["trial"], got, want)
    qp.update(stim={"intensity": want}, outcome={"response": "Yes" if row["response"] == "yes" else "No"})
print("replayed", len(rows), "trials")
"#;

#[test]
fn a_quest_plus_session_of_lab_run_replays_through_the_questplus_package() {
    let required = std::env::var("THERMODE_REQUIRE_PYTHON_TESTS").is_ok_and(|v| v == "1");
    let ready = Command::new("python3")
        .args(["-c", "import questplus; assert questplus.__version__ == '2023.1'"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ready {
        assert!(
            !required,
            "THERMODE_REQUIRE_PYTHON_TESTS=1 but python3 lacks questplus 2023.1"
        );
        println!("skipped: `python3 -m pip install questplus==2023.1` to replay the session through the package");
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    let file = experiment("questplus.toml");
    run_simulated(Path::new(&file), &data);
    let out = Command::new("python3")
        .args(["-c", REPLAY, &file, session_csv(&data).to_str().expect("utf-8")])
        .output()
        .expect("run python3");
    assert!(
        out.status.success(),
        "the questplus package disagrees with the session:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_procedure_session_is_analysed_with_z_scores_and_exported_with_its_events() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("dfns.toml");
    let text = std::fs::read_to_string(experiment("dfns-thermal.toml")).expect("dfns file");
    std::fs::write(
        &file,
        text.replace("runs = 3", "runs = 2")
            .replace("isi_s = 10.0", "isi_s = 2.0"),
    )
    .expect("write");
    let data = dir.path().join("data");
    run_simulated(&file, &data);
    let reference = dir.path().join("reference.csv");
    // CDT on the hand, log10 of the magnitude: a mean of 0.25 (1.78 °C) with sd 0.2.
    std::fs::write(
        &reference,
        "test,site,sex,age_band,mean,sd\nCDT,hand,female,20-40,0.25,0.2\n",
    )
    .expect("write");
    let out = dir.path().join("report");
    let csv = session_csv(&data);
    let s = |p: &Path| p.to_str().expect("utf-8").to_string();
    // The README's glob (`P01_dfns-thermal_*.csv`) also matches the session's events file: it is read with its
    // session, not refused.
    let events = csv.with_file_name(format!(
        "{}_events.csv",
        csv.file_stem().expect("stem").to_string_lossy()
    ));
    assert!(events.exists(), "{} beside the session", events.display());
    let args = [
        "lab",
        "analyze",
        &s(&csv),
        &s(&events),
        "--format",
        "json",
        "--out",
        &s(&out),
        "--reference",
        &s(&reference),
        "--site",
        "hand",
        "--sex",
        "female",
        "--age-band",
        "20-40",
    ];
    let analysis: serde_json::Value = serde_json::from_str(&expect_success(&args)).expect("analysis JSON");
    let session = &analysis[0];
    let cdt = session["thresholds"]
        .as_array()
        .and_then(|t| t.iter().find(|t| t["test"] == "CDT"))
        .expect("a CDT threshold");
    let value_c = cdt["value_c"].as_f64().expect("CDT value");
    let z = session["z_scores"][0]["z"].as_f64().expect("a CDT z-score");
    let expected_z = -(value_c.abs().log10() - 0.25) / 0.2;
    assert!(
        (z - expected_z).abs() < 1e-9,
        "z {z}, expected {expected_z} from CDT {value_c} °C"
    );
    let figures = session["figures"].as_array().map_or(0, Vec::len);
    assert_eq!(
        figures,
        session["trials"].as_u64().unwrap_or(0) as usize,
        "a trace figure per trial"
    );
    // Named by the session's file, so another session of P01 analysed with it keeps its own figures.
    let stem = csv.file_stem().expect("stem").to_string_lossy().into_owned();
    let svg = std::fs::read_to_string(out.join(format!("figures/{stem}_trial-001.svg"))).expect("first trace figure");
    assert!(svg.contains("response"), "the response is marked in the trace figure");

    let bids = dir.path().join("bids");
    expect_success(&["lab", "export", "--bids", &s(&bids), "--data-dir", &s(&data)]);
    let beh = bids.join("sub-P01/ses-").to_string_lossy().into_owned();
    let events = std::fs::read_dir(bids.join("sub-P01"))
        .expect("subject")
        .flat_map(|ses| std::fs::read_dir(ses.expect("ses").path().join("beh")).expect("beh"))
        .map(|e| e.expect("entry").path())
        .find(|p| p.to_string_lossy().ends_with("_events.tsv"))
        .unwrap_or_else(|| panic!("no events.tsv under {beh}"));
    let text = std::fs::read_to_string(&events).expect("events");
    let header: Vec<&str> = text.lines().next().unwrap_or("").split('\t').collect();
    assert_eq!(&header[..3], ["onset", "duration", "trial_type"]);
    let kinds: Vec<&str> = text.lines().skip(1).filter_map(|l| l.split('\t').nth(2)).collect();
    assert!(kinds.contains(&"segment_start") && kinds.contains(&"response") && kinds.contains(&"program_end"));
    let first_onset: f64 = text
        .lines()
        .nth(1)
        .and_then(|l| l.split('\t').next())
        .and_then(|v| v.parse().ok())
        .expect("onset");
    assert_eq!(first_onset, 0.0, "onset 0 at the first trial's start on the loop clock");
    super::bids::validate(&bids);
}

#[test]
fn the_space_bar_stops_a_ramp_on_the_simulated_display_in_real_time() {
    use std::io::{BufRead, BufReader, Write};
    use std::process::Stdio;
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("cdt.toml");
    std::fs::write(
        &file,
        "name = \"cdt\"\nprocedure = \"limits\"\nadaptation_s = 0.5\n[limits]\ntests = [\"CDT\"]\nruns = 1\nisi_s = 0.5\n",
    )
    .expect("write");
    let data = dir.path().join("data");
    let mut child = Command::new(env!("CARGO_BIN_EXE_thermode"))
        .args([
            "lab",
            "run",
            "--experiment",
            file.to_str().expect("utf-8"),
            "--participant",
            "P01",
        ])
        .args(["--simulate", "--data-dir", data.to_str().expect("utf-8")])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn lab run");
    let mut stdin = child.stdin.take().expect("stdin");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    let mut printed = Vec::new();
    for line in lines.by_ref() {
        let line = line.expect("line");
        let asked = line.contains("press SPACE");
        printed.push(line);
        if asked {
            break;
        }
    }
    // The participant feels the ramp a second in and presses the space bar (a USB button types one too).
    std::thread::sleep(std::time::Duration::from_secs(1));
    stdin.write_all(b" ").expect("press");
    stdin.flush().expect("flush");
    printed.extend(lines.map_while(Result::ok));
    let status = child.wait().expect("wait");
    assert!(status.success(), "lab run failed: {printed:?}");
    let (header, rows) = read_csv(&session_csv(&data));
    let row = &rows[0];
    assert_eq!(row[column(&header, "response")], "press", "{printed:?}");
    let delivered_c: f64 = row[column(&header, "delivered_c")].parse().expect("delivered");
    // A press about 1 s into a 1 °C/s ramp from 32 °C (the plate lags its set-point a little).
    assert!(
        (29.8..=31.7).contains(&delivered_c),
        "plate at the press {delivered_c} °C; {printed:?}"
    );
}

#[test]
fn lab_plan_refuses_a_ramp_the_display_refuses_as_lab_run_does() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("fast.toml");
    let write = |rate_c_per_s: f64| {
        std::fs::write(
            &file,
            format!(
                "name = \"fast\"\nprocedure = \"limits\"\nadaptation_s = 1.0\n[limits]\ntests = [\"CDT\"]\n\
                 runs = 1\nrate_c_s = {rate_c_per_s}\nisi_s = 1.0\n"
            ),
        )
        .expect("write experiment")
    };
    let path = file.to_str().expect("utf-8");
    write(50.0);
    let plan = thermode(&["lab", "plan", "--experiment", path]);
    let run = thermode(&simulated_run_args(&file, &dir.path().join("data")));
    let limit = "`rate_c_s [°C/s]` = 50 is invalid: must be a finite number from 0.01 to 20";
    for (what, out) in [("lab plan", &plan), ("lab run", &run)] {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(limit),
            "{what} of a 50 °C/s ramp: expected a refusal naming `{limit}`, got {:?}: {stderr}",
            out.status.code()
        );
    }
    assert!(
        plan.stdout.is_empty(),
        "no plan printed: {}",
        String::from_utf8_lossy(&plan.stdout)
    );
    write(20.0);
    expect_success(&["lab", "plan", "--experiment", path]);
}
