//! Procedure sessions on the simulated display in virtual time: bit-identical runs, a session cut short by its
//! answers resumed where it stopped (the procedure replayed from the rows), a torn last row cut, rows that are not
//! the procedure's trials refused, rows whose delivery or estimate the trial cannot have given refused, and the
//! display's cut-off reported per trial.

use std::path::Path;

use thermode_lab::procedure::{
    ProcedureRunError, ProcedureRunner, ProcedureSession, ProcedureSessionSpec, ScriptedAnswers,
    SimulatedProgramDisplay,
};
use thermode_pipeline::{ControllerKind, PipelineConfig};
use thermode_procedures::ProcedureFile;

const LIMITS: &str =
    "name = \"cdt\"\nprocedure = \"limits\"\nadaptation_s = 1.0\n[limits]\ntests = [\"CDT\", \"WDT\"]\n\
                      runs = 2\nrate_c_s = 2.0\nisi_s = 1.0\n";
/// A press 1.5 s into each of the four ramps.
const FOUR_PRESSES: &str = "press 1.5\npress 1.5\npress 1.5\npress 1.5\n";

fn run(data: &Path, script: &str) -> Result<usize, ProcedureRunError> {
    let file = ProcedureFile::from_toml_str(LIMITS)?;
    let config = PipelineConfig::new(thermode_device::DeviceConfig::default(), ControllerKind::Model);
    let mut display = SimulatedProgramDisplay::new(&config, 1, 7, 1.0)?;
    let mut session = ProcedureSession::open(&ProcedureSessionSpec {
        participant: "P01",
        experiment: "cdt",
        procedure: "limits",
        seed: 0,
        experiment_file: (Path::new("cdt.toml"), LIMITS),
        data_dir: data,
        today: "2026-11-27",
        now_utc: "2026-11-27T12:00:00.000Z",
        device: serde_json::json!({}),
        answers: "script".into(),
    })?;
    let mut answers = ScriptedAnswers::from_text(script, "script")?;
    answers.skip(session.rows().len());
    let mut out = Vec::new();
    let summary = ProcedureRunner {
        file: &file,
        display: &mut display,
        responder: &mut answers,
        session: &mut session,
        channel: 0,
        out: &mut out,
    }
    .run()?;
    Ok(summary.trials)
}

/// The error of a run that must fail (empty if it succeeded).
fn refusal(data: &Path, script: &str) -> String {
    run(data, script).err().map(|e| e.to_string()).unwrap_or_default()
}

fn csv(data: &Path) -> String {
    std::fs::read_to_string(data.join("P01_cdt_2026-11-27.csv")).unwrap_or_else(|e| panic!("session CSV: {e}"))
}

#[test]
fn a_simulated_procedure_session_is_bit_identical_run_after_run() {
    let (a, b) = (tempfile::tempdir().expect("dir"), tempfile::tempdir().expect("dir"));
    assert_eq!(run(a.path(), FOUR_PRESSES).expect("first run"), 4);
    assert_eq!(run(b.path(), FOUR_PRESSES).expect("second run"), 4);
    assert_eq!(csv(a.path()), csv(b.path()));
    let trace = |d: &Path| std::fs::read(d.join("P01_cdt_2026-11-27_traces/trial-003.csv")).expect("trace");
    assert_eq!(trace(a.path()), trace(b.path()));
}

#[test]
fn a_session_cut_short_resumes_at_its_first_missing_trial() {
    let dir = tempfile::tempdir().expect("dir");
    let error = refusal(dir.path(), "press 1.5\npress 1.5\n");
    assert!(error.contains("no answer for trial 3"), "{error}");
    let rows = |d: &Path| csv(d).lines().count() - 1;
    assert_eq!(rows(dir.path()), 2, "the two answered trials are on disk");
    // A kill mid-write leaves a torn row: it is cut, and the trial runs again.
    let path = dir.path().join("P01_cdt_2026-11-27.csv");
    let mut text = csv(dir.path());
    text.push_str("P01,cdt,2026-11-27,0,0.1.0,3,WDT");
    std::fs::write(&path, text).expect("tear");
    assert_eq!(run(dir.path(), FOUR_PRESSES).expect("resume"), 4);
    let labels: Vec<String> = csv(dir.path())
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(6).unwrap_or("").to_string())
        .collect();
    assert_eq!(labels, ["CDT", "CDT", "WDT", "WDT"]);
    let events = std::fs::read_to_string(dir.path().join("P01_cdt_2026-11-27_events.csv")).expect("events");
    let responses = events.lines().filter(|l| l.contains(",response,")).count();
    assert_eq!(responses, 4, "one response event per trial, none twice:\n{events}");
}

#[test]
fn rows_that_are_not_the_procedures_trials_are_refused_on_resume() {
    let dir = tempfile::tempdir().expect("dir");
    run(dir.path(), FOUR_PRESSES).expect("run");
    let path = dir.path().join("P01_cdt_2026-11-27.csv");
    let text = csv(dir.path());
    let lines: Vec<&str> = text.lines().take(3).collect();
    let changed = format!(
        "{}\n{}\n{}\n",
        lines[0],
        lines[1],
        lines[2].replace(",CDT,2,", ",WDT,2,")
    );
    std::fs::write(&path, changed).expect("write");
    let error = refusal(dir.path(), FOUR_PRESSES);
    assert!(error.contains("trial 2") && error.contains("WDT run 2"), "{error}");
}

/// The session CSV with `column` of data row `row` (1-based) set to `value`.
fn with_field(text: &str, row: usize, column: &str, value: &str) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let at = lines[0].split(',').position(|h| h == column).expect("column");
    let mut fields: Vec<String> = lines[row].split(',').map(str::to_string).collect();
    fields[at] = value.to_string();
    lines[row] = fields.join(",");
    lines.iter().map(|l| format!("{l}\n")).collect()
}

#[test]
fn a_resumed_row_whose_delivery_or_estimate_the_trial_cannot_have_given_is_refused() {
    let dir = tempfile::tempdir().expect("dir");
    run(dir.path(), FOUR_PRESSES).expect("run");
    let path = dir.path().join("P01_cdt_2026-11-27.csv");
    let recorded = csv(dir.path());
    let first: Vec<String> = recorded.lines().take(2).map(str::to_string).collect();
    let estimate_at = first[0].split(',').position(|h| h == "estimate_c").expect("column");
    let recorded_estimate = first[1].split(',').nth(estimate_at).unwrap_or("").to_string();
    let edited_estimate = match recorded_estimate.is_empty() {
        true => "31.5".to_string(),
        false => String::new(),
    };
    let cases = [
        ("delivered_c", "99", "`delivered_c` = 99"),
        ("delivered_c", "", "`delivered_c` = empty"),
        ("response", "maybe", "`maybe`"),
        ("estimate_c", edited_estimate.as_str(), "`estimate_c`"),
    ];
    for (column, value, expected) in cases {
        std::fs::write(&path, with_field(&recorded, 1, column, value)).expect("edit");
        let error = refusal(dir.path(), FOUR_PRESSES);
        assert!(
            error.contains("trial 1") && error.contains(expected),
            "{column} = `{value}`: expected a refusal naming {expected}, got: {error}"
        );
    }
    std::fs::write(&path, &recorded).expect("restore");
    assert_eq!(run(dir.path(), FOUR_PRESSES).expect("the unedited session resumes"), 4);
}

#[test]
fn a_target_beyond_the_display_is_its_cut_off_in_the_row() {
    let dir = tempfile::tempdir().expect("dir");
    run(dir.path(), "none\nnone\nnone\nnone\n").expect("run");
    let text = csv(dir.path());
    let mut reader = csv::Reader::from_reader(text.as_bytes());
    let header = reader.headers().expect("header").clone();
    let at = |name: &str| header.iter().position(|h| h == name).expect("column");
    let device = thermode_device::DeviceConfig::default();
    let limits = thermode_pipeline::pipeline::render_envelope(&device);
    for row in reader.records().map(|r| r.expect("row")) {
        let cutoff_c: f64 = row[at("cutoff_c")].parse().expect("a cut-off");
        let delivered_c: f64 = row[at("delivered_c")].parse().expect("delivered");
        let expected = if row[at("label")] == *"CDT" {
            limits.min_display_c
        } else {
            limits.max_display_c
        };
        assert_eq!(cutoff_c, expected, "the display's limit, not the DFNS 0/50 °C");
        assert_eq!(
            delivered_c, cutoff_c,
            "no press: the ramp ended at the display's cut-off"
        );
        assert_eq!(&row[at("response")], "none");
    }
}
