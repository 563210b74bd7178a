//! `lab export --bids` on a simulated paper design (`lab run --observer` for two participants) with a `serve
//! --record` recording assigned to one of them: the files, the events against the session CSVs, the gzip signals
//! against the recording, and the reference validator (`bids-validator` 1.15, from npm) reporting no error.
//!
//! The validator: `$THERMODE_BIDS_VALIDATOR`, else `bids-validator` on the PATH. Without it the validator step is
//! skipped with a message, unless `THERMODE_REQUIRE_BIDS_VALIDATOR=1` (CI), where its absence fails the test.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;

fn thermode(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_thermode"))
        .args(args)
        .output()
        .expect("run thermode");
    assert!(
        out.status.success(),
        "thermode {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn paper() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../thermode-lab/experiments/paper.toml")
        .to_string_lossy()
        .into_owned()
}

/// Two observer sessions of the paper design and a short `serve --record` recording of two channels.
fn lab_folder(root: &Path) -> (PathBuf, PathBuf) {
    let data = root.join("data");
    for participant in ["P01", "P02"] {
        observer_session(&data, participant);
    }
    let record = root.join("rec");
    short_recording(&record, &root.join("state"));
    let recording = std::fs::read_dir(&record)
        .expect("list recordings")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "csv"))
        .expect("a recording");
    (data, recording)
}

/// A simulated observer session of the paper design for `participant` in the data folder `data`.
pub(super) fn observer_session(data: &Path, participant: &str) {
    thermode(&[
        "lab",
        "run",
        "--simulate",
        "--experiment",
        &paper(),
        "--participant",
        participant,
        "--data-dir",
        data.to_str().expect("utf-8"),
        "--observer",
        "--time-scale",
        "0",
        "--stimulus",
        "model",
    ]);
}

/// A 0.5 s `serve --record record` of two channels (`record` a folder, or a `.arrow`/`.parquet` file).
pub(super) fn short_recording(record: &Path, state: &Path) {
    thermode(&[
        "serve",
        "--port",
        "0",
        "--no-osc",
        "--no-realtime",
        "--channels",
        "2",
        "--duration",
        "0.5",
        "--record",
        record.to_str().expect("utf-8"),
        "--state-dir",
        state.to_str().expect("utf-8"),
    ]);
}

fn beh(bids: &Path, subject: &str) -> PathBuf {
    let dir = bids.join(format!("sub-{subject}"));
    let session = std::fs::read_dir(&dir)
        .expect("subject folder")
        .next()
        .expect("a session")
        .expect("entry");
    session.path().join("beh")
}

fn gunzip(path: &Path) -> String {
    let mut text = String::new();
    flate2::read::GzDecoder::new(std::fs::File::open(path).expect("open gz"))
        .read_to_string(&mut text)
        .expect("valid gzip");
    text
}

#[test]
fn a_simulated_paper_design_exports_as_a_valid_bids_data_set() {
    let root = tempfile::tempdir().expect("temp dir");
    let (data, recording) = lab_folder(root.path());
    let bids = root.path().join("bids");
    let given = format!("P01={}", recording.display());
    let said = thermode(&[
        "lab",
        "export",
        "--bids",
        bids.to_str().expect("utf-8"),
        "--data-dir",
        data.to_str().expect("utf-8"),
        "--recording",
        &given,
    ]);
    assert!(
        said.contains("2 subject(s), 2 session(s), 40 trial(s), 2 continuous"),
        "{said}"
    );
    for file in [
        "dataset_description.json",
        "participants.tsv",
        "participants.json",
        "README",
    ] {
        assert!(bids.join(file).is_file(), "{file} missing");
    }
    check_events(&bids, &data);
    check_signals(&bids, &recording);
    validate(&bids);
    // A second export into the same folder is refused rather than mixed with the first.
    let again = Command::new(env!("CARGO_BIN_EXE_thermode"))
        .args([
            "lab",
            "export",
            "--bids",
            bids.to_str().expect("utf-8"),
            "--data-dir",
            data.to_str().expect("utf-8"),
        ])
        .output()
        .expect("run thermode");
    assert_eq!(again.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&again.stderr).contains("not empty"));
}

/// One events row per trial, the condition as trial_type, onsets not decreasing, the CSV's columns kept.
fn check_events(bids: &Path, data: &Path) {
    let dir = beh(bids, "P02");
    let events = std::fs::read_to_string(dir.join(first_with(&dir, "_events.tsv"))).expect("events");
    let lines: Vec<Vec<&str>> = events.lines().map(|l| l.split('\t').collect()).collect();
    assert_eq!(&lines[0][..3], ["onset", "duration", "trial_type"]);
    assert_eq!(lines.len(), 21, "header + 20 trials, got {}", lines.len());
    let csv_name = std::fs::read_dir(data)
        .expect("data")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().contains("P02") && p.extension().is_some_and(|e| e == "csv"))
        .expect("P02 csv");
    let csv = std::fs::read_to_string(csv_name).expect("csv");
    let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
    let (condition, presented) = (
        header.iter().position(|h| *h == "condition").expect("condition"),
        header.iter().position(|h| *h == "presented").expect("presented"),
    );
    let mut last_onset = f64::NEG_INFINITY;
    for (row, source) in lines[1..].iter().zip(csv.lines().skip(1)) {
        let source: Vec<&str> = source.split(',').collect();
        assert_eq!(row.len(), lines[0].len(), "ragged events row {row:?}");
        assert_eq!(row[2], source[condition], "trial_type vs condition");
        assert_eq!(row[3 + presented], source[presented], "presented column kept");
        let onset: f64 = row[0].parse().expect("numeric onset");
        assert!(onset >= last_onset, "onset {onset} before {last_onset}");
        last_onset = onset;
    }
}

/// The `_stim` file holds the recording's ch0 set-point column, sample for sample, at the loop rate.
fn check_signals(bids: &Path, recording: &Path) {
    let dir = beh(bids, "P01");
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(first_with(&dir, "_stim.json"))).expect("stim json"))
            .expect("stim json parses");
    let rate = sidecar["SamplingFrequency"].as_f64().expect("SamplingFrequency");
    assert!(
        (rate - 100.0).abs() < 1e-6,
        "SamplingFrequency {rate}, want the loop's 100 Hz"
    );
    let columns: Vec<&str> = sidecar["Columns"]
        .as_array()
        .expect("Columns")
        .iter()
        .filter_map(|c| c.as_str())
        .collect();
    let setpoint = columns
        .iter()
        .position(|c| *c == "ch0_display_setpoint_c")
        .expect("ch0 set-point column");
    let stim = gunzip(&dir.join(first_with(&dir, "_stim.tsv.gz")));
    let csv = std::fs::read_to_string(recording).expect("recording");
    let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
    let (channel, source) = (
        header.iter().position(|h| *h == "channel").expect("channel"),
        header
            .iter()
            .position(|h| *h == "display_setpoint_c")
            .expect("set-point"),
    );
    let expected: Vec<f64> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|f| f[channel] == "0")
        .map(|f| f[source].parse().expect("number"))
        .collect();
    let got: Vec<f64> = stim
        .lines()
        .map(|l| l.split('\t').nth(setpoint).expect("column").parse().expect("number"))
        .collect();
    assert_eq!(got.len(), expected.len(), "stim rows vs recorded ticks");
    for (i, (g, e)) in got.iter().zip(&expected).enumerate() {
        assert!((g - e).abs() < 1e-9, "row {i}: stim {g} vs recording {e}");
    }
}

fn first_with(dir: &Path, suffix: &str) -> PathBuf {
    std::fs::read_dir(dir)
        .expect("list")
        .filter_map(Result::ok)
        .map(|e| e.file_name().into())
        .find(|n: &PathBuf| n.to_string_lossy().ends_with(suffix))
        .unwrap_or_else(|| panic!("no *{suffix} in {}", dir.display()))
}

/// Runs the reference validator (JSON output) and asserts it reports no error.
pub(super) fn validate(bids: &Path) {
    let required = std::env::var("THERMODE_REQUIRE_BIDS_VALIDATOR").is_ok_and(|v| v == "1");
    let program = std::env::var("THERMODE_BIDS_VALIDATOR").unwrap_or_else(|_| "bids-validator".into());
    let out = match Command::new(&program).arg(bids).arg("--json").output() {
        Ok(out) => out,
        Err(e) => {
            assert!(
                !required,
                "THERMODE_REQUIRE_BIDS_VALIDATOR=1 but {program} cannot run: {e}"
            );
            println!("skipped the validator: {program} not found ({e}); `npm install bids-validator@1.15.0`");
            return;
        }
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let report: serde_json::Value = serde_json::from_str(&stdout).unwrap_or_else(|e| {
        panic!(
            "validator output is not JSON ({e}):\n{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    let errors = report["issues"]["errors"].as_array().cloned().unwrap_or_default();
    let warnings = report["issues"]["warnings"].as_array().map_or(0, Vec::len);
    println!("bids-validator: {} error(s), {warnings} warning(s)", errors.len());
    assert!(errors.is_empty(), "bids-validator errors: {errors:#?}");
    assert!(
        out.status.success(),
        "bids-validator exited with {:?}",
        out.status.code()
    );
}

/// A display session by hand (two trials whose curves carry the daemon's loop time, 0.1 s and 0.25 s) and a real
/// `serve --record` recording of that daemon: the export puts events and signals on one clock (onset 0 at the first
/// trial's start, the recording's StartTime its first loop time minus that start) and the validator accepts it.
#[test]
fn a_display_session_exports_on_one_clock_as_a_valid_bids_data_set() {
    let root = tempfile::tempdir().expect("temp dir");
    let (_, recording) = lab_folder(root.path());
    let data = root.path().join("display");
    let curves = data.join("P-01_paper_2026-11-23_curves");
    std::fs::create_dir_all(&curves).expect("curves folder");
    let sidecar = serde_json::json!({"format": "thermode-lab session 2", "participant": "P-01",
        "experiment": "paper", "session_date": "2026-11-23", "csv_file": "P-01_paper_2026-11-23.csv"});
    std::fs::write(data.join("P-01_paper_2026-11-23.json"), sidecar.to_string()).expect("sidecar");
    let mut csv = "participant,trial,condition,presented,response_time_s,presentation_s,curve_file\n".to_string();
    for (trial, start_s) in [(1, 0.1), (2, 0.25)] {
        let name = format!("trial-{trial:03}.csv");
        csv.push_str(&format!(
            "P-01,{trial},simulated,wood,1,0.1,P-01_paper_2026-11-23_curves/{name}\n"
        ));
        let mut curve = "trial,time_s,loop_time_s,target_skin_c,finger_c\n".to_string();
        for i in 0..10 {
            let t = f64::from(i) * 0.01;
            curve.push_str(&format!("{trial},{t},{:.6},31,30\n", start_s + t));
        }
        std::fs::write(curves.join(name), curve).expect("curve");
    }
    std::fs::write(data.join("P-01_paper_2026-11-23.csv"), csv).expect("csv");
    let bids = root.path().join("bids");
    let given = format!("P-01={}", recording.display());
    let data_s = data.to_str().expect("utf-8");
    thermode(&[
        "lab",
        "export",
        "--bids",
        bids.to_str().expect("utf-8"),
        "--data-dir",
        data_s,
        "--recording",
        &given,
    ]);
    let dir = beh(&bids, "P01");
    let events = std::fs::read_to_string(dir.join(first_with(&dir, "_events.tsv"))).expect("events");
    let onsets: Vec<&str> = events
        .lines()
        .skip(1)
        .map(|l| l.split('\t').next().unwrap_or_default())
        .collect();
    assert_eq!(onsets, ["0", "0.15"], "onsets on the loop clock: {events}");
    let first_s: f64 = std::fs::read_to_string(&recording)
        .expect("recording")
        .lines()
        .nth(1)
        .and_then(|l| l.split(',').next())
        .and_then(|t| t.parse().ok())
        .expect("first time_s");
    let stim_json = std::fs::read_dir(&dir)
        .expect("list")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().contains("_recording-session") && p.to_string_lossy().ends_with("_stim.json"))
        .unwrap_or_else(|| panic!("no recording stim sidecar in {}", dir.display()));
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(stim_json).expect("stim json")).expect("json");
    let start_s = sidecar["StartTime"].as_f64().expect("StartTime");
    assert!(
        (start_s - (first_s - 0.1)).abs() < 1e-9,
        "StartTime {start_s}, recording from {first_s} s, first trial at 0.1 s"
    );
    validate(&bids);
}
