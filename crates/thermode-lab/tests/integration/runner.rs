//! Integration tests of the runner, the session files and the simulated participant: scripted and interactive
//! sessions with a fake clock, the CSV and sidecar contents, resume after a failure and after a torn row, refusal of
//! a different plan, the exclusion rule, bad input, the simulated participant's calibration against the paper's 66 %, and a full
//! simulated-participant run of the paper's design read back by the analysis.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use thermode_lab::analysis;
use thermode_lab::design::Condition;
use thermode_lab::design::ExperimentFile;
use thermode_lab::participant::{
    CurveFeatures, SimulatedParticipant, PAPER_CALIBRATED_NOISE_SD, PAPER_REAL_IDENTIFICATION_RATE,
};
use thermode_lab::plan::make_plan;
use thermode_lab::runner::{
    Console, FvContact, InteractiveResponder, ModelStimulus, QuietConsole, RunError, Runner, ScriptedResponses,
    SessionSummary, Stimulus, StimulusError, StimulusRequest, TerminalConsole, TrialMeasurement,
};
use thermode_lab::session::{SessionError, SESSION_COLUMNS, SESSION_COLUMNS_V1, SOFTWARE_VERSION, TIMING_COLUMNS};
use thermode_model::materials::find;
use thermode_platform::{parse_iso_date, ManualClock};

/// A jumping manual clock (every wait passes at once) whose wall clock starts on `date` (`YYYY-MM-DD`).
fn dated_clock(date: &str) -> ManualClock {
    ManualClock::jumping().with_unix_origin_s(parse_iso_date(date).expect("a valid date"))
}

const DATE: &str = "2024-05-01";

fn paper() -> ExperimentFile {
    ExperimentFile::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/paper.toml")).expect("valid")
}

/// A small design written to `dir`: 3 materials, 2 participants, 1 repetition (6 trials each).
fn small(dir: &Path, seed: u64) -> ExperimentFile {
    let path = dir.join("small.toml");
    let text = format!(
        "name = \"small\"\nmaterials = [\"aluminium\", \"steel\", \"wood\"]\nparticipants = 2\nseed = {seed}\n\
         presentation_s = 10\n"
    );
    std::fs::write(&path, text).expect("write design");
    ExperimentFile::load(&path).expect("valid")
}

/// Answers "presented" for every trial of `participant`, as a responses text.
fn perfect_answers(experiment: &ExperimentFile, participant: &str) -> String {
    let plan = make_plan(&experiment.experiment);
    let p = plan.participant(participant).expect("planned");
    p.trials.iter().map(|t| format!("{}\n", t.presented)).collect()
}

/// A stimulus with given finger start temperatures per trial (no curve); fails at `fail_at` if set.
struct TableStimulus {
    starts_c: Vec<f64>,
    fail_at: Option<usize>,
}

impl Stimulus for TableStimulus {
    fn present(&mut self, request: &StimulusRequest) -> Result<TrialMeasurement, StimulusError> {
        if self.fail_at == Some(request.trial) {
            return Err(StimulusError::Device("display unplugged".to_string()));
        }
        let start = self.starts_c[(request.trial - 1) % self.starts_c.len()];
        Ok(TrialMeasurement {
            finger_start_c: start,
            finger_end_c: start - 3.0,
            curve: None,
            measured: false,
            trace: None,
        })
    }
}

fn steady() -> TableStimulus {
    TableStimulus {
        starts_c: vec![32.0],
        fail_at: None,
    }
}

/// Answers for the six trials of [`small`].
const SIX_ANSWERS: &str = "1\n2\n3\n1\n2\n3\n";

/// P01's session of `exp` in `dir`, stopped by a display that fails at trial `fail_at`; its CSV.
fn interrupted_at(exp: &ExperimentFile, dir: &Path, fail_at: usize) -> PathBuf {
    let mut failing = TableStimulus {
        starts_c: vec![32.0],
        fail_at: Some(fail_at),
    };
    run_scripted(exp, "P01", dir, &mut failing, SIX_ANSWERS, DATE).expect_err("the display fails");
    dir.join("P01_small_2024-05-01.csv")
}

fn run_scripted(
    experiment: &ExperimentFile,
    participant: &str,
    dir: &Path,
    stimulus: &mut dyn Stimulus,
    answers: &str,
    date: &str,
) -> Result<SessionSummary, RunError> {
    let options = &experiment.experiment.response_options;
    let trials = experiment.experiment.trials_per_participant();
    let mut responder = ScriptedResponses::from_text(answers, Path::new("answers.txt"), options, trials)?;
    Runner {
        experiment,
        participant,
        data_dir: dir,
        device: serde_json::json!({"device": "test"}),
        stimulus,
        responder: &mut responder,
        clock: &dated_clock(date),
        time_scale: 1.0,
        console: &mut QuietConsole,
        interactive: false,
    }
    .run()
}

/// The rows of a session CSV as (column, value) lists, header checked.
fn rows(path: &Path) -> Vec<Vec<(String, String)>> {
    let mut reader = csv::Reader::from_path(path).expect("readable session");
    let header: Vec<String> = reader.headers().expect("header").iter().map(str::to_string).collect();
    assert_eq!(header, SESSION_COLUMNS, "session columns");
    reader
        .records()
        .map(|r| {
            let r = r.expect("row parses");
            header.iter().cloned().zip(r.iter().map(str::to_string)).collect()
        })
        .collect()
}

fn field<'a>(row: &'a [(String, String)], name: &str) -> &'a str {
    row.iter()
        .find(|(k, _)| k == name)
        .map(|(_, v)| v.as_str())
        .expect("column present")
}

fn without_timing(rows: Vec<Vec<(String, String)>>) -> Vec<Vec<(String, String)>> {
    rows.into_iter()
        .map(|r| {
            r.into_iter()
                .filter(|(k, _)| !TIMING_COLUMNS.contains(&k.as_str()))
                .collect()
        })
        .collect()
}

#[test]
fn a_scripted_session_writes_the_planned_trials_with_session_fields_on_every_row() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = paper();
    let answers = perfect_answers(&exp, "P02");
    let mut stimulus = ModelStimulus::new(FvContact::default(), 0.0, 1).expect("model");
    let summary = run_scripted(&exp, "P02", dir.path(), &mut stimulus, &answers, DATE).expect("session runs");
    assert_eq!(summary.csv_path, dir.path().join("P02_paper_2024-05-01.csv"));
    assert_eq!(summary.sidecar_path, dir.path().join("P02_paper_2024-05-01.json"));
    assert_eq!(
        (summary.planned_trials, summary.recorded_before, summary.recorded_now),
        (20, 0, 20)
    );
    let plan = make_plan(&exp.experiment);
    let planned = &plan.participant("P02").expect("planned").trials;
    let rows = rows(&summary.csv_path);
    assert_eq!(rows.len(), 20);
    for (row, t) in rows.iter().zip(planned) {
        assert_eq!(field(row, "participant"), "P02");
        assert_eq!(field(row, "expName"), "paper");
        assert_eq!(
            field(row, "trials.thisN"),
            (t.trial - 1).to_string(),
            "PsychoPy's 0-based counter"
        );
        assert_eq!(
            field(row, "key_resp.rt"),
            "",
            "a responses file is not a person: no response time"
        );
        assert_eq!(field(row, "session_date"), DATE);
        assert_eq!(field(row, "seed"), "2008");
        assert_eq!(field(row, "software_version"), SOFTWARE_VERSION);
        assert_eq!(field(row, "trial"), t.trial.to_string());
        assert_eq!(field(row, "condition"), t.condition.name());
        assert_eq!(field(row, "presented"), t.presented);
        assert_eq!(field(row, "identified"), t.presented);
        assert_eq!(
            field(row, "presentation_s"),
            "30.000",
            "the fake clock's presentation time"
        );
        assert_eq!(field(row, "excluded"), "false");
        assert_eq!(
            field(row, "finger_start_c"),
            "",
            "a model's finger is not a measurement"
        );
        let start: f64 = field(row, "model_finger_start_c").parse().expect("number");
        let end: f64 = field(row, "model_finger_end_c").parse().expect("number");
        assert!(start > 31.0 && start < 34.0, "resting finger {start} °C");
        assert!(
            end < start && end > 23.0,
            "after 30 s on {} the finger is at {end} °C",
            t.presented
        );
    }
    // P02 is the second participant: simulated first.
    assert_eq!(field(&rows[0], "condition"), "simulated");
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary.sidecar_path).expect("sidecar")).expect("JSON");
    assert_eq!(sidecar["experiment_toml"], serde_json::Value::String(exp.text.clone()));
    assert_eq!(sidecar["seed"], 2008);
    assert_eq!(sidecar["software_version"], SOFTWARE_VERSION);
    assert_eq!(sidecar["device"]["device"], "test");
    assert_eq!(sidecar["condition_order"], serde_json::json!(["simulated", "real"]));
    // The analysis reads the session as it is.
    let result = analysis::analyze(std::slice::from_ref(&summary.csv_path)).expect("analysable");
    assert_eq!(result.trials, 20);
    assert_eq!(result.rates.real.rate, Some(1.0));
}

#[test]
fn resuming_after_a_failure_continues_at_the_first_missing_trial() {
    let dir = tempfile::tempdir().expect("temp dir");
    let reference_dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    let answers = "1\n2\n3\nwood\nsteel\naluminium\n";
    let whole = run_scripted(&exp, "P01", reference_dir.path(), &mut steady(), answers, DATE).expect("runs");
    let mut failing = TableStimulus {
        starts_c: vec![32.0],
        fail_at: Some(4),
    };
    let err = run_scripted(&exp, "P01", dir.path(), &mut failing, answers, DATE).expect_err("device fails");
    assert!(err.to_string().contains("display unplugged"), "{err}");
    let csv = dir.path().join("P01_small_2024-05-01.csv");
    assert_eq!(rows(&csv).len(), 3, "trials 1-3 are saved");
    // Resumed on a later day: same file, same session date.
    let resumed = run_scripted(&exp, "P01", dir.path(), &mut steady(), answers, "2024-05-02").expect("resumes");
    assert!(resumed.resumed);
    assert_eq!((resumed.recorded_before, resumed.recorded_now), (3, 3));
    assert_eq!(resumed.csv_path, csv);
    assert_eq!(without_timing(rows(&csv)), without_timing(rows(&whole.csv_path)));
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&resumed.sidecar_path).expect("sidecar")).expect("JSON");
    assert_eq!(sidecar["resumes"][0]["date"], "2024-05-02");
    assert_eq!(sidecar["resumes"][0]["recorded_trials"], 3);
    // A complete session is left alone.
    let again = run_scripted(&exp, "P01", dir.path(), &mut steady(), answers, DATE).expect("complete");
    assert_eq!((again.recorded_before, again.recorded_now), (6, 0));
    assert_eq!(rows(&csv).len(), 6);
}

#[test]
fn a_torn_last_row_is_cut_off_and_the_trial_redone() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    let answers = SIX_ANSWERS;
    let csv = interrupted_at(&exp, dir.path(), 3);
    let before = std::fs::read_to_string(&csv).expect("read");
    let second_row = before.lines().nth(2).expect("row 2").to_string();
    // Simulate a kill in the middle of writing trial 3's row: a prefix of a row without its line end.
    let torn = second_row.replacen(",2,", ",3,", 1);
    std::fs::write(&csv, format!("{before}{}", &torn[..torn.len() / 2])).expect("tear");
    let summary = run_scripted(&exp, "P01", dir.path(), &mut steady(), answers, DATE).expect("resumes");
    assert!(summary.removed_torn_row);
    assert_eq!((summary.recorded_before, summary.recorded_now), (2, 4));
    let rows = rows(&csv);
    let trials: Vec<&str> = rows.iter().map(|r| field(r, "trial")).collect();
    assert_eq!(trials, ["1", "2", "3", "4", "5", "6"]);
}

#[test]
fn a_complete_row_that_contradicts_the_plan_is_reported_not_dropped() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    let answers = SIX_ANSWERS;
    let csv = interrupted_at(&exp, dir.path(), 3);
    let text = std::fs::read_to_string(&csv).expect("read");
    let planned = &make_plan(&exp.experiment).participants[0].trials[1];
    let other = ["aluminium", "steel", "wood"]
        .into_iter()
        .find(|m| *m != planned.presented)
        .expect("other");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    lines[2] = lines[2].replacen(&format!(",{},", planned.presented), &format!(",{other},"), 1);
    std::fs::write(&csv, lines.join("\n") + "\n").expect("edit");
    let err = run_scripted(&exp, "P01", dir.path(), &mut steady(), answers, DATE).expect_err("corrupt");
    assert!(
        matches!(err, RunError::Session(SessionError::Corrupt { line: 3, .. })),
        "{err}"
    );
    assert!(err.to_string().contains("presented"), "{err}");
}

#[test]
fn a_session_of_a_different_plan_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    let answers = SIX_ANSWERS;
    let csv = interrupted_at(&exp, dir.path(), 2);
    let before = std::fs::read(&csv).expect("read");
    let reseeded = small(dir.path(), 6);
    let err = run_scripted(&reseeded, "P01", dir.path(), &mut steady(), answers, DATE).expect_err("mismatch");
    assert!(matches!(err, RunError::Session(SessionError::Mismatch { .. })), "{err}");
    assert!(err.to_string().contains("seed: 5 vs 6"), "{err}");
    assert_eq!(
        std::fs::read(&csv).expect("read"),
        before,
        "a refused resume changes nothing"
    );
}

#[test]
fn the_exclusion_rule_marks_trials_beyond_one_degree_from_the_session_start() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    let mut stimulus = TableStimulus {
        starts_c: vec![32.0, 33.2, 31.0, 30.95, 32.5, 32.0],
        fail_at: None,
    };
    let summary = run_scripted(&exp, "P01", dir.path(), &mut stimulus, "1\n1\n1\n1\n1\n1\n", DATE).expect("runs");
    let rows = rows(&summary.csv_path);
    let excluded: Vec<&str> = rows.iter().map(|r| field(r, "excluded")).collect();
    assert_eq!(excluded, ["false", "true", "false", "true", "false", "false"]);
    assert!(rows.iter().all(|r| field(r, "model_finger_baseline_c") == "32.0000"));
    let reason = field(&rows[1], "exclusion_reason");
    assert!(reason.contains("1.20 °C") && reason.contains("limit 1 °C"), "{reason}");
    assert_eq!(field(&rows[0], "exclusion_reason"), "");
    assert_eq!(summary.excluded, 2);
    let result = analysis::analyze(&[summary.csv_path]).expect("analysable");
    assert_eq!((result.trials, result.excluded_trials), (4, 2));
}

#[test]
fn bad_participants_and_unwritable_folders_are_clear_errors() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    let answers = "1\n1\n1\n1\n1\n1\n";
    let err = run_scripted(&exp, "P 01", dir.path(), &mut steady(), answers, DATE).expect_err("format");
    assert!(matches!(err, RunError::BadParticipant(_)), "{err}");
    let err = run_scripted(&exp, "P09", dir.path(), &mut steady(), answers, DATE).expect_err("not planned");
    assert!(err.to_string().contains("P01 … P02"), "{err}");
    let blocker = dir.path().join("not-a-folder");
    std::fs::write(&blocker, "x").expect("write");
    let err = run_scripted(&exp, "P01", &blocker, &mut steady(), answers, DATE).expect_err("unwritable");
    assert!(err.to_string().contains("not-a-folder"), "{err}");
    let options = &exp.experiment.response_options;
    let err = ScriptedResponses::from_text("1\n", Path::new("r.txt"), options, 6).expect_err("too few");
    assert!(err.to_string().contains("1 answers for 6 trials"), "{err}");
}

#[test]
fn interactive_sessions_prompt_and_ask_again_after_a_bad_answer() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    let plan = make_plan(&exp.experiment);
    let trials = &plan.participant("P01").expect("planned").trials;
    // Real trials need an Enter first; the first answer is wrong twice.
    let mut input = String::new();
    for (i, t) in trials.iter().enumerate() {
        if t.condition == Condition::Real {
            input.push('\n');
        }
        if i == 0 {
            input.push_str("9\nglass\n");
        }
        input.push_str(&format!("{}\n", t.presented.to_uppercase()));
    }
    let mut console = TerminalConsole::new(Cursor::new(input), Vec::new());
    let summary = Runner {
        experiment: &exp,
        participant: "P01",
        data_dir: dir.path(),
        device: serde_json::Value::Null,
        stimulus: &mut steady(),
        responder: &mut InteractiveResponder,
        clock: &dated_clock(DATE),
        time_scale: 1.0,
        console: &mut console,
        interactive: true,
    }
    .run()
    .expect("session runs");
    let output = String::from_utf8(console.into_output()).expect("UTF-8");
    assert!(output.contains("trial 1/6, real, present: "), "{output}");
    assert!(output.contains("place the"), "{output}");
    assert!(
        output.contains("`9` is not an option") && output.contains("`glass` is not an option"),
        "{output}"
    );
    let rows = rows(&summary.csv_path);
    assert!(rows.iter().all(|r| field(r, "identified") == field(r, "presented")));
}

#[test]
fn an_interactive_session_whose_input_ends_keeps_the_completed_trials() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    let mut console = TerminalConsole::new(Cursor::new("\n1\n\n2\n"), Vec::new());
    let err = Runner {
        experiment: &exp,
        participant: "P01",
        data_dir: dir.path(),
        device: serde_json::Value::Null,
        stimulus: &mut steady(),
        responder: &mut InteractiveResponder,
        clock: &dated_clock(DATE),
        time_scale: 1.0,
        console: &mut console,
        interactive: true,
    }
    .run()
    .expect_err("input ends");
    assert!(matches!(err, RunError::InputClosed), "{err}");
    assert_eq!(rows(&dir.path().join("P01_small_2024-05-01.csv")).len(), 2);
}

fn paper_options() -> Vec<String> {
    paper().experiment.response_options
}

#[test]
fn the_calibrated_simulated_participant_identifies_real_contact_as_often_as_the_papers_participants() {
    let options = paper_options();
    let contact = FvContact::default();
    let mut simulated = SimulatedParticipant::from_model(&options, &contact, 30.0, 3).expect("references");
    let calibration = simulated
        .calibrate(PAPER_REAL_IDENTIFICATION_RATE, 4000, 1)
        .expect("reachable");
    assert!(
        (calibration.noise_sd - PAPER_CALIBRATED_NOISE_SD).abs() < 0.0005,
        "calibrated σ {} vs documented {PAPER_CALIBRATED_NOISE_SD}",
        calibration.noise_sd
    );
    assert!(
        (calibration.rate - 0.66).abs() < 0.005,
        "calibration-sample rate {}",
        calibration.rate
    );
    // Fresh trials: real-contact curves recomputed by the stimulus, noise from the per-trial streams.
    let mut stimulus = ModelStimulus::new(contact, 0.0, 1).expect("model");
    let mut confusion = vec![vec![0usize; options.len()]; options.len()];
    let per_material = 2000;
    for (i, name) in options.iter().enumerate() {
        let material = find(name).expect("library");
        let m = stimulus
            .present(&StimulusRequest {
                material: &material,
                condition: Condition::Real,
                duration_s: 30.0,
                participant_index: 0,
                trial: 1,
            })
            .expect("curve");
        let curve = m.curve.expect("the model stimulus records curves");
        for k in 0..per_material {
            let answer = simulated.identify_trial(&curve, 1000 + k, i + 1).expect("features");
            confusion[i][answer] += 1;
        }
    }
    let correct: usize = (0..options.len()).map(|i| confusion[i][i]).sum();
    let rate = correct as f64 / (per_material * options.len()) as f64;
    eprintln!(
        "calibrated noise {} (calibration-sample rate {}); fresh-trial rate {rate}; confusion {confusion:?}",
        calibration.noise_sd, calibration.rate
    );
    assert!(
        (rate - 0.66).abs() <= 0.05,
        "real identification rate {rate} vs the paper's 0.66 ± 0.05"
    );
    // The mistakes are the physically similar pairs: aluminium/steel and wood/rubber.
    let idx = |n: &str| options.iter().position(|o| o == n).expect("option");
    let similar = confusion[idx("aluminium")][idx("steel")]
        + confusion[idx("steel")][idx("aluminium")]
        + confusion[idx("wood")][idx("rubber")]
        + confusion[idx("rubber")][idx("wood")];
    let mistakes = per_material * options.len() - correct;
    assert!(
        similar as f64 > 0.8 * mistakes as f64,
        "{similar} of {mistakes} mistakes are Al/steel or wood/rubber: {confusion:?}"
    );
}

#[test]
fn simulated_participant_limits_noise_free_and_very_noisy() {
    let options = paper_options();
    let mut simulated = SimulatedParticipant::from_model(&options, &FvContact::default(), 30.0, 3).expect("references");
    // No noise: every reference is identified as itself.
    for (i, reference) in simulated.references().iter().enumerate() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
        assert_eq!(simulated.identify(reference, &mut rng), i, "{}", options[i]);
    }
    // Wood and rubber: almost the same effusivity, so almost the same curve (a few hundredths of a degree).
    let f: Vec<&CurveFeatures> = simulated.references().iter().collect();
    assert!(
        (f[3].end_drop_c - f[4].end_drop_c).abs() < 0.1,
        "{:?} vs {:?}",
        f[3],
        f[4]
    );
    // Huge noise: chance level, 1/5.
    simulated.set_noise_sd(100.0).expect("valid");
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(2);
    let n = 4000;
    let correct = (0..n)
        .map(|k| k % 5)
        .filter(|&i| simulated.identify(&simulated.references()[i].clone(), &mut rng) == i)
        .count();
    let rate = correct as f64 / n as f64;
    assert!((rate - 0.2).abs() < 0.03, "rate {rate} vs chance 0.2");
}

/// The paper's design run with the calibrated simulated for every participant (the demo of the issue).
#[test]
fn a_simulated_participant_run_of_the_paper_design_analyses_like_the_paper() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = paper();
    let contact = FvContact::default();
    let mut stimulus = ModelStimulus::new(contact.clone(), 0.0, exp.experiment.seed).expect("model");
    let options = &exp.experiment.response_options;
    let mut simulated = SimulatedParticipant::from_model(options, &contact, 30.0, exp.experiment.seed).expect("refs");
    simulated
        .calibrate(PAPER_REAL_IDENTIFICATION_RATE, 4000, 1)
        .expect("reachable");
    let mut files: Vec<PathBuf> = Vec::new();
    for id in &exp.experiment.participant_ids {
        let summary = Runner {
            experiment: &exp,
            participant: id,
            data_dir: dir.path(),
            device: stimulus.describe(),
            stimulus: &mut stimulus,
            responder: &mut simulated,
            clock: &dated_clock(DATE),
            time_scale: 1.0,
            console: &mut QuietConsole,
            interactive: false,
        }
        .run()
        .expect("session runs");
        files.push(summary.csv_path);
    }
    let result = analysis::analyze(&files).expect("analysable");
    assert_eq!(
        (result.participants, result.trials, result.excluded_trials),
        (15, 300, 0)
    );
    let real = result.rates.real.rate.expect("rate");
    let simulated_rate = result.rates.simulated.rate.expect("rate");
    // 150 trials per condition: standard error √(0.66·0.34/150) ≈ 0.039; 3 standard errors.
    assert!((real - 0.66).abs() < 0.12, "real rate {real}");
    assert!((simulated_rate - 0.66).abs() < 0.12, "simulated rate {simulated_rate}");
    // Re-running the same design gives the same data (simulated and stimulus are seeded per trial).
    let again = tempfile::tempdir().expect("temp dir");
    let summary = Runner {
        experiment: &exp,
        participant: "P07",
        data_dir: again.path(),
        device: stimulus.describe(),
        stimulus: &mut stimulus,
        responder: &mut simulated,
        clock: &dated_clock(DATE),
        time_scale: 1.0,
        console: &mut QuietConsole,
        interactive: false,
    }
    .run()
    .expect("session runs");
    let first = std::fs::read(dir.path().join("P07_paper_2024-05-01.csv")).expect("read");
    assert_eq!(std::fs::read(summary.csv_path).expect("read"), first);
}

#[test]
fn the_model_stimulus_curves_are_grid_converged() {
    // The default grid against one refinement (twice the cells, half the step): the documented 0.005 °C.
    let coarse = FvContact::default();
    let fine = FvContact {
        config: coarse.config.refined(1),
        ..coarse.clone()
    };
    for name in paper_options() {
        let material = find(&name).expect("library");
        let a = coarse.curve(&material, None, 30.0).expect("curve");
        let b = fine.curve(&material, None, 30.0).expect("curve");
        assert_eq!(a.time_s, b.time_s);
        let change = a
            .skin_c
            .iter()
            .zip(&b.skin_c)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(change < 0.005, "{name}: default vs refined grid differ by {change} °C");
    }
}

#[test]
fn the_model_fingers_drift_reproducibly_with_the_asked_spread() {
    let sd_c = 0.4;
    let mut stimulus = ModelStimulus::new(FvContact::default(), sd_c, 17).expect("model");
    let rest = stimulus.resting_c();
    let wood = find("wood").expect("library");
    let mut start = |participant_index: usize, trial: usize| {
        stimulus
            .present(&StimulusRequest {
                material: &wood,
                condition: Condition::Simulated,
                duration_s: 5.0,
                participant_index,
                trial,
            })
            .expect("curve")
            .finger_start_c
    };
    let n = 60;
    let starts: Vec<f64> = (1..=n).map(|t| start(0, t)).collect();
    assert_eq!(start(0, 7), starts[6], "the same trial gives the same finger");
    assert_ne!(start(1, 7), starts[6], "another participant gives another finger");
    let mean = starts.iter().sum::<f64>() / n as f64;
    let sd = (starts.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    // 60 draws: the mean is within 4 standard errors (4 · 0.4/√60 = 0.21 °C) of the resting temperature and the
    // sample sd within ±35 % of 0.4 °C (a χ² interval far beyond 99.9 %).
    assert!((mean - rest).abs() < 0.21, "mean start {mean} vs resting {rest}");
    assert!((sd / sd_c - 1.0).abs() < 0.35, "sample sd {sd} vs {sd_c}");
}

#[test]
fn sessions_whose_names_collide_are_told_apart_and_never_overwritten() {
    // Participant `a` of experiment `b_c` and participant `a_b` of experiment `c` share the file name a_b_c_<date>.
    let dir = tempfile::tempdir().expect("temp dir");
    let design = |name: &str, id: &str| {
        let path = dir.path().join(format!("{name}.toml"));
        let text = format!(
            "name = \"{name}\"\nmaterials = [\"aluminium\", \"wood\"]\nparticipants = 1\n\
             participant_ids = [\"{id}\"]\nseed = 3\npresentation_s = 5\n"
        );
        std::fs::write(&path, text).expect("write design");
        ExperimentFile::load(&path).expect("valid")
    };
    let (first, second) = (design("b_c", "a"), design("c", "a_b"));
    let data = dir.path().join("data");
    let one = run_scripted(&first, "a", &data, &mut steady(), "1\n1\n1\n1\n", DATE).expect("runs");
    let before = std::fs::read(&one.csv_path).expect("read");
    let err = run_scripted(&second, "a_b", &data, &mut steady(), "2\n2\n2\n2\n", DATE).expect_err("collides");
    assert!(
        matches!(err, RunError::Session(SessionError::Collision { .. })),
        "{err}"
    );
    assert_eq!(
        std::fs::read(&one.csv_path).expect("read"),
        before,
        "the first session is untouched"
    );
    // The first session is still found as its own (complete) session.
    let again = run_scripted(&first, "a", &data, &mut steady(), "1\n1\n1\n1\n", DATE).expect("complete");
    assert_eq!((again.recorded_before, again.recorded_now), (4, 0));
}

/// A session started by thermode before PsychoPy's column names (format 1) resumes in its own columns: the rows
/// already there are read, the new ones are written under the same header, and nothing moves to the new names.
#[test]
fn a_format_1_session_resumes_in_its_own_columns() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    let answers = SIX_ANSWERS;
    let csv = interrupted_at(&exp, dir.path(), 3);
    let json = csv.with_extension("json");
    // Rewrite the two rows and the sidecar as format 1 wrote them.
    let mut reader = csv::Reader::from_path(&csv).expect("session");
    let header: Vec<String> = reader.headers().expect("header").iter().map(str::to_string).collect();
    let v1_of = |name: &str| match name {
        "experiment" => "expName".to_string(),
        "response_key" => "key_resp.keys".to_string(),
        "response_time_s" => "key_resp.rt".to_string(),
        "finger_baseline_c" | "finger_start_c" | "finger_end_c" => format!("model_{name}"),
        other => other.to_string(),
    };
    let mut text = format!("{}\n", SESSION_COLUMNS_V1.join(","));
    for row in reader.records() {
        let row = row.expect("row");
        let cells: Vec<String> = SESSION_COLUMNS_V1
            .iter()
            .map(|c| {
                let i = header.iter().position(|h| *h == v1_of(c)).expect("mapped column");
                match (c, &row[i]) {
                    (&"response_time_s", "") => "0.000".to_string(),
                    (_, value) => value.to_string(),
                }
            })
            .collect();
        text.push_str(&format!("{}\n", cells.join(",")));
    }
    std::fs::write(&csv, &text).expect("format-1 CSV");
    let mut sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("sidecar")).expect("json");
    sidecar["format"] = "thermode-lab session 1".into();
    sidecar["columns"] = serde_json::json!(SESSION_COLUMNS_V1);
    std::fs::write(&json, sidecar.to_string()).expect("format-1 sidecar");
    let summary = run_scripted(&exp, "P01", dir.path(), &mut steady(), answers, DATE).expect("resumes");
    assert_eq!((summary.recorded_before, summary.recorded_now), (2, 4));
    let after = std::fs::read_to_string(&csv).expect("read");
    assert!(
        after.starts_with(&text),
        "the format-1 rows are kept as they were:\n{after}"
    );
    let mut reader = csv::Reader::from_path(&csv).expect("session");
    assert_eq!(
        reader.headers().expect("header").iter().collect::<Vec<_>>(),
        SESSION_COLUMNS_V1
    );
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.expect("row")).collect();
    assert_eq!(rows.len(), 6);
    assert!(rows
        .iter()
        .all(|r| r.len() == SESSION_COLUMNS_V1.len() && &r[1] == "small" && &r[16] == "32.0000"));
}

/// A display whose finger, at rest, reads each of `rests_c` in turn (10 s per measurement), then its last.
struct RecoveringFinger {
    trials: TableStimulus,
    rests_c: Vec<f64>,
    measured: usize,
}

impl Stimulus for RecoveringFinger {
    fn present(&mut self, request: &StimulusRequest) -> Result<TrialMeasurement, StimulusError> {
        self.trials.present(request)
    }

    fn finger_at_rest(&mut self) -> Option<Result<(f64, f64), StimulusError>> {
        let index = self.measured.min(self.rests_c.len() - 1);
        self.measured += 1;
        Some(Ok((self.rests_c[index], 10.0)))
    }
}

/// Lines the runner says.
#[derive(Default)]
struct Said(Vec<String>);

impl Console for Said {
    fn say(&mut self, line: &str) -> std::io::Result<()> {
        self.0.push(line.to_string());
        Ok(())
    }

    fn ask(&mut self, _prompt: &str) -> std::io::Result<Option<String>> {
        Ok(None)
    }
}

/// Resumes P01's session of `exp` in `dir` on `finger`; what the runner said.
fn resume_on(exp: &ExperimentFile, dir: &Path, finger: &mut RecoveringFinger) -> Vec<String> {
    let options = &exp.experiment.response_options;
    let trials = exp.experiment.trials_per_participant();
    let mut responder =
        ScriptedResponses::from_text(SIX_ANSWERS, Path::new("answers.txt"), options, trials).expect("answers");
    let mut said = Said::default();
    Runner {
        experiment: exp,
        participant: "P01",
        data_dir: dir,
        device: serde_json::json!({"device": "test"}),
        stimulus: finger,
        responder: &mut responder,
        clock: &dated_clock(DATE),
        time_scale: 0.0,
        console: &mut said,
        interactive: false,
    }
    .run()
    .expect("resumes");
    said.0
}

#[test]
fn a_resumed_session_waits_for_the_finger_to_come_back_to_its_baseline() {
    // The session's baseline is 32 °C (its first trial); the interrupted trial left the finger at 30.72 °C.
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    interrupted_at(&exp, dir.path(), 4);
    let mut finger = RecoveringFinger {
        trials: steady(),
        rests_c: vec![30.72, 30.9, 31.4],
        measured: 0,
    };
    let said = resume_on(&exp, dir.path(), &mut finger);
    let resume: Vec<&String> = said.iter().filter(|l| l.starts_with("resume: ")).collect();
    assert_eq!(finger.measured, 3, "measured until within 1 °C: {resume:?}");
    assert_eq!(resume.len(), 3, "{said:?}");
    assert!(
        resume[0].contains("finger at rest 30.72 °C, 1.28 °C from the session's baseline 32.00 °C"),
        "{resume:?}"
    );
    assert!(
        resume[0].ends_with("waiting for the finger to recover (10 s so far)"),
        "{resume:?}"
    );
    assert!(
        resume[2].contains("0.60 °C from") && resume[2].ends_with("the trials go on"),
        "{resume:?}"
    );
    let first_trial = said
        .iter()
        .position(|l| l.starts_with("trial 4/"))
        .expect("trial 4 runs");
    let last_resume = said
        .iter()
        .rposition(|l| l.starts_with("resume: "))
        .expect("resume lines");
    assert!(last_resume < first_trial, "the wait comes before any trial: {said:?}");
}

#[test]
fn a_resumed_session_says_plainly_when_the_finger_does_not_recover() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exp = small(dir.path(), 5);
    interrupted_at(&exp, dir.path(), 4);
    let mut finger = RecoveringFinger {
        trials: steady(),
        rests_c: vec![30.5],
        measured: 0,
    };
    let said = resume_on(&exp, dir.path(), &mut finger);
    let warning = said
        .iter()
        .find(|l| l.contains("WARNING"))
        .unwrap_or_else(|| panic!("no warning: {said:?}"));
    let rests = (thermode_lab::runner::RECOVERY_WAIT_S / 10.0).ceil() as usize;
    assert_eq!(finger.measured, rests, "{said:?}");
    assert!(
        warning.contains("1.50 °C from the session's baseline 32.00 °C")
            && warning.contains("the finger has not recovered"),
        "{warning}"
    );
}
