//! `thermode lab export --bids DIR`: the lab's sessions and recordings as a BIDS data set (Brain Imaging Data
//! Structure, behavioural data type).
//!
//! What is written ([`export_bids`]):
//! - `dataset_description.json`, `README`, `participants.tsv` and `participants.json`;
//! - per session (a session sidecar `*.json` of format `thermode-lab session …` in the data folder, with its CSV):
//!   `sub-<participant>/ses-<date>/beh/sub-…_ses-…_task-<experiment>_events.tsv` — one row per trial: `onset`,
//!   `duration` (the presentation), `trial_type` (the condition), then every column of the session CSV as it is —
//!   and its JSON sidecar describing each column;
//! - continuous signals: every curve CSV in a folder beside the session CSV whose name starts with the session's
//!   stem (per-trial measured curves), and every recording assigned to a participant with
//!   [`BidsOptions::recordings`] (`serve --record` files), as `…_recording-<name>_stim.tsv.gz` (what the display
//!   was asked to show: target and set-point columns) and `…_recording-<name>_physio.tsv.gz` (what the plate and
//!   finger did: sensor, skin, current, …), each with its JSON sidecar (`SamplingFrequency`, `StartTime`,
//!   `Columns`). A recording in long form (a `channel` column, one row per tick per channel) is made wide
//!   (`ch<c>_<column>`);
//! - `sourcedata/thermode/`: the original session CSVs and sidecars, unchanged (BIDS validators ignore it).
//!
//! Labels: BIDS labels are letters and digits only, so `P-01` becomes `P01`; two participants (or experiments)
//! whose labels collide are refused. The session label is the session date without dashes (`20261123`).
//!
//! One clock: a session that ran on a display (its trial curves carry the daemon's `loop_time_s`) puts its events
//! and signals on that loop clock, onset 0 at the first trial's start: a trial's `onset` is its curve's first
//! sample, a trial curve's `StartTime` its first `loop_time_s`, and a `serve --record` file's `StartTime` its first
//! `time_s` (the loop time of the daemon that wrote it; a recording of another daemon is shifted by the difference
//! of the wall-clock zeros in its `.clock.json` and the session sidecar), all relative to that start. A session
//! without such curves (a simulation) has no clock: a trial's `onset` is then the sum of the previous trials'
//! presentation and response times (the time on task, without the breaks between trials), or the CSV's own clock
//! column ([`ONSET_COLUMNS`], e.g. monotonic seconds at each trial's start) relative to the first trial, and each
//! signal keeps its own time base.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use flate2::write::GzEncoder;
use flate2::Compression;
use serde_json::{json, Map, Value};
use thermode_platform::fs::{open_at_most, read_text_at_most, MAX_DATA_BYTES, MAX_SETTINGS_BYTES};
use thiserror::Error;

mod clock;

use clock::{SessionClock, LOOP_TIME_COLUMN};

/// The BIDS version the export follows.
pub const BIDS_VERSION: &str = "1.9.0";
/// Columns of a curve that go to `_stim` (what the display was asked to show); the others go to `_physio`.
pub const STIM_COLUMNS: [&str; 5] = [
    "target_skin_c",
    "target_c",
    "display_setpoint_c",
    "setpoint_c",
    "requested_setpoint_c",
];
/// Session CSV columns that give a trial's onset \[s\] on a clock of the session, in order of preference; the
/// first present is used, relative to its first row.
pub const ONSET_COLUMNS: [&str; 4] = [
    "onset_s",
    "trial_onset_s",
    "stimulus_onset_s",
    "trial_start_monotonic_s",
];
/// Session CSV columns of the response time \[s\], in order of preference (thermode's and PsychoPy's names).
pub const RESPONSE_TIME_COLUMNS: [&str; 2] = ["response_time_s", "key_resp.rt"];
/// Names of a curve's time column \[s\], in order of preference.
pub const TIME_COLUMNS: [&str; 3] = ["time_s", "t_s", "time"];

/// Why the export failed.
#[derive(Debug, Error)]
pub enum ExportError {
    /// A file or folder could not be read or written.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The operating system's error.
        error: std::io::Error,
    },
    /// A CSV or JSON file cannot be read as what it should be.
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Two names map to the same BIDS label, or a name has no letter or digit.
    #[error("BIDS label: {0}")]
    Label(String),
    /// The output folder exists and is not empty.
    #[error("{}: the output folder is not empty; give a new or empty folder", .0.display())]
    NotEmpty(PathBuf),
    /// A recording is assigned to a participant without a session.
    #[error("recording {}: participant {participant:?} has no session in the data folder", path.display())]
    UnknownParticipant {
        /// The recording.
        path: PathBuf,
        /// The participant named.
        participant: String,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ExportError + '_ {
    move |error| ExportError::Io {
        path: path.to_path_buf(),
        error,
    }
}

fn invalid(path: &Path, message: impl Into<String>) -> ExportError {
    ExportError::Invalid {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// What to export and where.
#[derive(Debug, Clone, PartialEq)]
pub struct BidsOptions {
    /// The lab's data folder (session CSVs and sidecars, as `lab run` writes them).
    pub data_dir: PathBuf,
    /// The BIDS folder to write (created; must be new or empty).
    pub out_dir: PathBuf,
    /// Recordings (`serve --record` CSVs) and the participant each belongs to (added to that participant's first
    /// session). Default none.
    pub recordings: Vec<(String, PathBuf)>,
}

/// What was written.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BidsSummary {
    /// Subjects.
    pub subjects: usize,
    /// Sessions (events files).
    pub sessions: usize,
    /// Trials (events rows).
    pub trials: usize,
    /// Continuous signal files (`_stim` and `_physio`).
    pub signals: usize,
}

/// One session found in the data folder.
#[derive(Debug, Clone)]
struct Session {
    participant: String,
    experiment: String,
    date: String,
    csv: PathBuf,
    sidecar: PathBuf,
    meta: Value,
}

impl Session {
    fn subject(&self) -> Result<String, ExportError> {
        label(&self.participant)
    }

    fn label(&self) -> String {
        self.date.chars().filter(char::is_ascii_alphanumeric).collect()
    }

    /// `sub-X_ses-Y_task-Z`.
    fn prefix(&self) -> Result<String, ExportError> {
        Ok(format!(
            "sub-{}_ses-{}_task-{}",
            self.subject()?,
            self.label(),
            label(&self.experiment)?
        ))
    }

    fn beh_dir(&self, root: &Path) -> Result<PathBuf, ExportError> {
        Ok(root
            .join(format!("sub-{}", self.subject()?))
            .join(format!("ses-{}", self.label()))
            .join("beh"))
    }
}

/// A BIDS label of `name`: its letters and digits.
pub fn label(name: &str) -> Result<String, ExportError> {
    let label: String = name.chars().filter(char::is_ascii_alphanumeric).collect();
    if label.is_empty() {
        return Err(ExportError::Label(format!("{name:?} has no letter or digit")));
    }
    Ok(label)
}

/// Writes the BIDS data set of `options` (module documentation).
pub fn export_bids(options: &BidsOptions) -> Result<BidsSummary, ExportError> {
    let sessions = find_sessions(&options.data_dir)?;
    if sessions.is_empty() {
        return Err(invalid(
            &options.data_dir,
            "no lab session (a `*.json` session sidecar with its CSV) here",
        ));
    }
    check_labels(&sessions)?;
    prepare_out(&options.out_dir)?;
    let root = options.out_dir.as_path();
    write_dataset_files(root, &sessions)?;
    let mut summary = BidsSummary {
        subjects: sessions
            .iter()
            .map(|s| s.participant.clone())
            .collect::<BTreeSet<_>>()
            .len(),
        ..BidsSummary::default()
    };
    let mut clocks = Vec::with_capacity(sessions.len());
    for session in &sessions {
        let (header, rows) = read_csv(&session.csv)?;
        let clock = SessionClock::of(&session.csv, &session.meta, &header, &rows)?;
        summary.trials += match session.meta.get("events_file").and_then(Value::as_str) {
            Some(events) => write_procedure_events(root, session, &session.csv.with_file_name(events), clock.as_ref())?,
            None => write_events(root, session, clock.as_ref())?,
        };
        summary.sessions += 1;
        for curve in session_curves(session)? {
            let placement = clock.as_ref().map_or(Placement::Own, Placement::Trial);
            summary.signals += write_signals(root, session, &curve, placement)?;
        }
        copy_source(root, session)?;
        clocks.push(clock);
    }
    for (participant, path) in &options.recordings {
        let index = sessions
            .iter()
            .position(|s| s.participant == *participant)
            .ok_or_else(|| ExportError::UnknownParticipant {
                path: path.clone(),
                participant: participant.clone(),
            })?;
        let placement = clocks[index].as_ref().map_or(Placement::Own, Placement::Recording);
        summary.signals += write_signals(root, &sessions[index], path, placement)?;
    }
    Ok(summary)
}

/// Every session (sidecar + CSV) in `dir`, sorted by participant, date and experiment.
fn find_sessions(dir: &Path) -> Result<Vec<Session>, ExportError> {
    let mut sessions = Vec::new();
    for entry in fs::read_dir(dir).map_err(io(dir))? {
        let path = entry.map_err(io(dir))?.path();
        if path.extension().is_some_and(|e| e == "json") {
            if let Some(session) = read_session(&path)? {
                sessions.push(session);
            }
        }
    }
    sessions.sort_by(|a, b| (&a.participant, &a.date, &a.experiment).cmp(&(&b.participant, &b.date, &b.experiment)));
    Ok(sessions)
}

/// The session of a sidecar, or `None` for a JSON file that is not a session sidecar.
fn read_session(path: &Path) -> Result<Option<Session>, ExportError> {
    let text = read_text_at_most(path, MAX_SETTINGS_BYTES).map_err(io(path))?;
    let Ok(meta) = serde_json::from_str::<Value>(&text) else {
        return Ok(None);
    };
    let format = meta.get("format").and_then(Value::as_str).unwrap_or_default();
    if !format.starts_with("thermode-lab session") {
        return Ok(None);
    }
    let field = |key: &str| {
        meta.get(key)
            .and_then(Value::as_str)
            .map(str::to_string)
            .ok_or_else(|| invalid(path, format!("session sidecar without `{key}`")))
    };
    let csv_name = field("csv_file")?;
    let csv = path.with_file_name(&csv_name);
    if !csv.is_file() {
        return Err(invalid(path, format!("its session CSV {csv_name} is missing")));
    }
    Ok(Some(Session {
        participant: field("participant")?,
        experiment: field("experiment")?,
        date: field("session_date")?,
        csv,
        sidecar: path.to_path_buf(),
        meta,
    }))
}

/// Refuses two participants (or experiments) with one label, and two sessions with one file name.
fn check_labels(sessions: &[Session]) -> Result<(), ExportError> {
    let mut seen: BTreeMap<String, String> = BTreeMap::new();
    for name in sessions.iter().flat_map(|s| [&s.participant, &s.experiment]) {
        let label = label(name)?;
        if let Some(other) = seen.insert(label.clone(), name.clone()) {
            if other != *name {
                return Err(ExportError::Label(format!(
                    "{other:?} and {name:?} both become {label:?}"
                )));
            }
        }
    }
    let mut prefixes = BTreeSet::new();
    for session in sessions {
        if !prefixes.insert(session.prefix()?) {
            return Err(ExportError::Label(format!(
                "two sessions of {} on {} in {}",
                session.participant, session.date, session.experiment
            )));
        }
    }
    Ok(())
}

fn prepare_out(dir: &Path) -> Result<(), ExportError> {
    if dir.exists() && fs::read_dir(dir).map_err(io(dir))?.next().is_some() {
        return Err(ExportError::NotEmpty(dir.to_path_buf()));
    }
    fs::create_dir_all(dir).map_err(io(dir))
}

fn write_text(path: &Path, text: &str) -> Result<(), ExportError> {
    if let Some(parent) = path.parent() {
        fs::create_dir_all(parent).map_err(io(parent))?;
    }
    fs::write(path, text).map_err(io(path))
}

fn write_json(path: &Path, value: &Value) -> Result<(), ExportError> {
    write_text(path, &format!("{value:#}\n"))
}

/// `dataset_description.json`, `README`, `participants.tsv` and `.json`.
fn write_dataset_files(root: &Path, sessions: &[Session]) -> Result<(), ExportError> {
    let experiments: BTreeSet<&str> = sessions.iter().map(|s| s.experiment.as_str()).collect();
    let names: Vec<&str> = experiments.into_iter().collect();
    let description = json!({
        "Name": format!("thermode lab: {}", names.join(", ")),
        "BIDSVersion": BIDS_VERSION,
        "DatasetType": "raw",
        "GeneratedBy": [{"Name": "thermode", "Version": env!("CARGO_PKG_VERSION"),
                         "Description": "thermode lab export --bids"}],
    });
    write_json(&root.join("dataset_description.json"), &description)?;
    write_text(&root.join("README"), &readme(sessions, &names))?;
    write_participants(root, sessions)
}

fn readme(sessions: &[Session], experiments: &[&str]) -> String {
    format!(
        "thermode lab data set\n=====================\n\nMaterial-identification sessions with a thermal display \
         (experiments: {}), {} session(s), exported by `thermode lab export --bids` (thermode {}).\n\n\
         Each session is `sub-<participant>/ses-<date>/beh/*_events.tsv`: one row per trial, `onset` in seconds of \
         time on task (the sum of the previous trials' presentation and response times; the breaks between trials \
         are not counted), `duration` the presentation, `trial_type` the condition (real contact or the display), \
         and every column of thermode's session CSV. Continuous signals, where recorded, are `*_stim.tsv.gz` (what \
         the display was asked to show) and `*_physio.tsv.gz` (what the plate and finger did). The original files \
         are in `sourcedata/thermode/`.\n",
        experiments.join(", "),
        sessions.len(),
        env!("CARGO_PKG_VERSION")
    )
}

fn write_participants(root: &Path, sessions: &[Session]) -> Result<(), ExportError> {
    let mut rows = BTreeMap::new();
    for session in sessions {
        let order = session
            .meta
            .get("condition_order")
            .and_then(Value::as_array)
            .map(|a| a.iter().filter_map(Value::as_str).collect::<Vec<_>>().join("-"))
            .filter(|o| !o.is_empty())
            .unwrap_or_else(|| "n/a".into());
        rows.entry(session.subject()?)
            .or_insert((session.participant.clone(), order));
    }
    let mut tsv = String::from("participant_id\tsource_id\tcondition_order\n");
    for (subject, (source, order)) in &rows {
        tsv.push_str(&format!("sub-{subject}\t{}\t{}\n", tsv_field(source), tsv_field(order)));
    }
    write_text(&root.join("participants.tsv"), &tsv)?;
    let sidecar = json!({
        "participant_id": {"Description": "BIDS label of the participant (the lab's identifier without punctuation)"},
        "source_id": {"Description": "The participant's identifier in thermode's session files"},
        "condition_order": {"Description": "The order of the conditions for this participant (counterbalanced)"},
    });
    write_json(&root.join("participants.json"), &sidecar)
}

/// A value as a TSV field: empty is `n/a`, tabs and line ends become spaces.
fn tsv_field(value: &str) -> String {
    let value = value.trim();
    if value.is_empty() {
        return "n/a".into();
    }
    value.replace(['\t', '\n', '\r'], " ")
}

/// A CSV as its header and rows; an Arrow IPC (`.arrow`, `.feather`) or Parquet (`.parquet`) file of the same
/// table (`serve --record FILE.arrow`, `render --out FILE.parquet`) as the fields its CSV holds.
fn read_csv(path: &Path) -> Result<(Vec<String>, Vec<Vec<String>>), ExportError> {
    if thermode_table::Format::of(path).is_columnar() {
        return thermode_table::read_fields(path, MAX_DATA_BYTES).map_err(|e| invalid(path, e.to_string()));
    }
    let file = open_at_most(path, MAX_DATA_BYTES).map_err(|e| invalid(path, e.to_string()))?;
    let mut reader = csv::ReaderBuilder::new().comment(Some(b'#')).from_reader(file);
    let header = reader
        .headers()
        .map_err(|e| invalid(path, e.to_string()))?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| invalid(path, e.to_string()))?;
        rows.push(record.iter().map(str::to_string).collect());
    }
    Ok((header, rows))
}

/// Writes a session's `_events.tsv` and `.json`; returns its trials.
fn write_events(root: &Path, session: &Session, clock: Option<&SessionClock>) -> Result<usize, ExportError> {
    let (header, rows) = read_csv(&session.csv)?;
    let column = |name: &str| header.iter().position(|h| h == name);
    let number = |row: &[String], name: &str| {
        column(name)
            .and_then(|i| row.get(i))
            .and_then(|v| v.parse::<f64>().ok())
    };
    let presentation_s = session
        .meta
        .pointer("/experiment_toml")
        .and_then(Value::as_str)
        .and_then(presentation_of);
    let kept: Vec<&String> = header
        .iter()
        .filter(|h| !matches!(h.as_str(), "onset" | "duration" | "trial_type"))
        .collect();
    let mut tsv = String::from("onset\tduration\ttrial_type");
    for name in &kept {
        tsv.push('\t');
        tsv.push_str(name);
    }
    tsv.push('\n');
    let onset_column = ONSET_COLUMNS.iter().find(|c| column(c).is_some());
    let first_onset_s = onset_column.and_then(|c| rows.first().and_then(|r| number(r, c)));
    let mut elapsed_s = 0.0;
    for (index, row) in rows.iter().enumerate() {
        let duration = number(row, "presentation_s").or(presentation_s);
        let clocked = onset_column
            .and_then(|c| number(row, c))
            .zip(first_onset_s)
            .map(|(t, t0)| t - t0);
        let onset = clock.and_then(|c| c.onset_s(index)).or(clocked).unwrap_or(elapsed_s);
        let response_s = RESPONSE_TIME_COLUMNS.iter().find_map(|c| number(row, c)).unwrap_or(0.0);
        elapsed_s = onset + duration.unwrap_or(0.0) + response_s;
        let kind = column("condition")
            .and_then(|i| row.get(i))
            .map_or("trial".into(), |v| tsv_field(v));
        let duration = duration.map_or("n/a".into(), |d| format!("{d}"));
        tsv.push_str(&format!("{onset}\t{duration}\t{kind}"));
        for name in &kept {
            let value = header.iter().position(|h| h == *name).and_then(|i| row.get(i));
            tsv.push('\t');
            tsv.push_str(&tsv_field(value.map_or("", String::as_str)));
        }
        tsv.push('\n');
    }
    let dir = session.beh_dir(root)?;
    let prefix = session.prefix()?;
    write_text(&dir.join(format!("{prefix}_events.tsv")), &tsv)?;
    write_json(
        &dir.join(format!("{prefix}_events.json")),
        &events_sidecar(&kept, clock.is_some()),
    )?;
    Ok(rows.len())
}

/// The columns of a procedure session's events file that the export keeps (after `onset`, `duration`,
/// `trial_type`), and the session CSV's columns it adds to each event of a trial.
const PROCEDURE_EVENT_COLUMNS: [&str; 9] = [
    "trial", "channel", "segment", "tick", "to_c", "cutoff_c", "kind", "value", "time_s",
];
const PROCEDURE_TRIAL_COLUMNS: [&str; 6] = ["label", "run", "intensity_c", "delivered_c", "response", "rating"];

/// Writes a procedure session's `_events.tsv` and `.json` from its events file: one row per program event
/// (`segment_start`, `response`, `program_end` as `trial_type`), onset on the session's clock (the display's loop
/// clock, 0 at the first trial's start), with the trial's label, run, intensity, delivered temperature and response
/// from the session CSV; returns the session's trials.
fn write_procedure_events(
    root: &Path,
    session: &Session,
    events: &Path,
    clock: Option<&SessionClock>,
) -> Result<usize, ExportError> {
    let (header, rows) = read_csv(&session.csv)?;
    let (event_header, event_rows) = read_csv(events)?;
    let column = |names: &[String], name: &str| names.iter().position(|h| h == name);
    let field =
        |row: &[String], index: Option<usize>| index.and_then(|i| row.get(i)).map_or(String::new(), |v| v.clone());
    let time_of = |row: &[String]| field(row, column(&event_header, "time_s")).parse::<f64>().ok();
    let first_s = event_rows.iter().find_map(|r| time_of(r)).unwrap_or(0.0);
    let mut tsv = String::from("onset\tduration\ttrial_type");
    for name in PROCEDURE_EVENT_COLUMNS.iter().chain(&PROCEDURE_TRIAL_COLUMNS) {
        tsv.push('\t');
        tsv.push_str(name);
    }
    tsv.push('\n');
    for event in &event_rows {
        let Some(time_s) = time_of(event) else { continue };
        let onset = clock.map_or(time_s - first_s, |c| c.session_time_s(time_s));
        let kind = field(event, column(&event_header, "event"));
        tsv.push_str(&format!("{onset}\t0\t{}", tsv_field(&kind)));
        for name in PROCEDURE_EVENT_COLUMNS {
            tsv.push('\t');
            tsv.push_str(&tsv_field(&field(event, column(&event_header, name))));
        }
        let trial = field(event, column(&event_header, "trial"));
        let row = rows.iter().find(|r| field(r, column(&header, "trial")) == trial);
        for name in PROCEDURE_TRIAL_COLUMNS {
            tsv.push('\t');
            tsv.push_str(&tsv_field(
                &row.map(|r| field(r, column(&header, name))).unwrap_or_default(),
            ));
        }
        tsv.push('\n');
    }
    let dir = session.beh_dir(root)?;
    let prefix = session.prefix()?;
    write_text(&dir.join(format!("{prefix}_events.tsv")), &tsv)?;
    let mut sidecar = Map::new();
    sidecar.insert(
        "onset".into(),
        json!({"Description": "The event's tick on the display's loop clock, seconds since the first trial's start", "Units": "s"}),
    );
    sidecar.insert(
        "duration".into(),
        json!({"Description": "Events are instants", "Units": "s"}),
    );
    sidecar.insert(
        "trial_type".into(),
        json!({"Description": "What happened", "Levels": {
            "segment_start": "A program segment started (its first set-point is this tick's)",
            "response": "A participant's response took effect on this tick",
            "program_end": "The channel's program ended; its set-point holds"}}),
    );
    for name in PROCEDURE_EVENT_COLUMNS.iter().chain(&PROCEDURE_TRIAL_COLUMNS) {
        sidecar.insert((*name).to_string(), column_description(name));
    }
    write_json(&dir.join(format!("{prefix}_events.json")), &Value::Object(sidecar))?;
    Ok(rows.len())
}

/// The experiment file's `presentation_s`, if it has one.
fn presentation_of(toml_text: &str) -> Option<f64> {
    let value: toml::Value = toml::from_str(toml_text).ok()?;
    value.get("presentation_s")?.as_float()
}

fn events_sidecar(columns: &[&String], on_loop_clock: bool) -> Value {
    let mut map = Map::new();
    let onset = if on_loop_clock {
        "Start of the presentation on the display's loop clock (the first sample of the trial's curve), seconds \
         since the first trial's start; the session's signals share this time axis (their StartTime)"
    } else {
        "Start of the presentation: seconds of time on task from the session start (the previous trials' \
         presentation and response times; breaks not counted), or the session CSV's own trial clock relative to \
         the first trial where it has one"
    };
    map.insert("onset".into(), json!({"Description": onset, "Units": "s"}));
    map.insert(
        "duration".into(),
        json!({"Description": "Duration of the presentation", "Units": "s"}),
    );
    map.insert(
        "trial_type".into(),
        json!({"Description": "The condition", "Levels": {
            "real": "The participant touched the real material",
            "simulated": "The thermal display rendered the material"}}),
    );
    for name in columns {
        map.insert((*name).clone(), column_description(name));
    }
    map.insert(
        "StimulusPresentation".into(),
        json!({"SoftwareName": "thermode", "SoftwareVersion": env!("CARGO_PKG_VERSION")}),
    );
    Value::Object(map)
}

/// The description of a session CSV column (units from the name's suffix).
fn column_description(name: &str) -> Value {
    let known = match name {
        "participant" => "Participant identifier in thermode's files",
        "experiment" | "expName" => "Experiment name",
        "trials.thisN" => "Trial index from 0 (PsychoPy's loop counter)",
        "curve_file" => "The trial's curve on the display, relative to the data folder",
        "model_finger_baseline_c" => "Simulated finger temperature before the session's first trial",
        "model_finger_start_c" => "Simulated finger temperature before the touch",
        "model_finger_end_c" => "Simulated finger temperature at the end of the presentation",
        "session_date" => "Date the session started",
        "seed" => "The design's seed",
        "software_version" => "thermode version that recorded the row",
        "trial" => "Trial number within the session",
        "block" => "Block (condition) number",
        "repetition" => "Repetition of the material within the block",
        "condition" => "real (touch the material) or simulated (the display renders it)",
        "position" => "Position within the block",
        "presented" => "The material presented",
        "identified" => "The material the participant named",
        "response_key" | "key_resp.keys" => "The answer as option number (1-based)",
        "response_time_s" | "key_resp.rt" => "Time from the end of the presentation to a person's answer",
        "presentation_s" => "Measured duration of the presentation",
        "finger_baseline_c" => "The session's finger baseline temperature, measured on the display",
        "finger_start_c" => "Finger temperature measured on the display at rest before the trial",
        "finger_end_c" => "Finger temperature measured on the display at rest after the trial",
        "excluded" => "Whether the exclusion rule discarded the trial",
        "exclusion_reason" => "Why the trial was excluded",
        "label" => "What the trial measures (a DFNS test, the procedure, or a multi-zone stimulus)",
        "run" => "Run (repetition) of the test or stimulus",
        "channel" => "Display channel",
        "segment" => "Program segment (from 0)",
        "tick" => "The display loop's tick",
        "time_s" => "The display loop's time of the tick",
        "to_c" => "A started segment's target temperature (after the display's cut-off)",
        "cutoff_c" => "The display's limit a target was clipped to",
        "kind" => "A response's kind: button or rating",
        "value" => "A rating, 0 to 100",
        "intensity_c" => "Requested change of the plate from the baseline",
        "delivered_c" => "The plate at the response's tick, at the plateau, or where the ramp ended",
        "response" => "press, none (method of limits); yes, no; rating",
        "rating" => "The participant's rating, 0 to 100",
        _ => "Column of thermode's session CSV (see thermode's documentation)",
    };
    let units = if name.ends_with("_s") || name == "key_resp.rt" {
        Some("s")
    } else if name.ends_with("_c") {
        Some("degC")
    } else {
        None
    };
    match units {
        Some(units) => json!({"Description": known, "Units": units}),
        None => json!({"Description": known}),
    }
}

/// Curve CSVs (or Arrow and Parquet files) in folders beside the session CSV named after its stem.
fn session_curves(session: &Session) -> Result<Vec<PathBuf>, ExportError> {
    let Some(stem) = session.csv.file_stem().map(|s| s.to_string_lossy().into_owned()) else {
        return Ok(Vec::new());
    };
    let dir = session.csv.parent().unwrap_or(Path::new("."));
    let mut curves = Vec::new();
    for entry in fs::read_dir(dir).map_err(io(dir))? {
        let path = entry.map_err(io(dir))?.path();
        let named = path.file_name().is_some_and(|n| n.to_string_lossy().starts_with(&stem));
        if path.is_dir() && named {
            for inner in fs::read_dir(&path).map_err(io(&path))? {
                let file = inner.map_err(io(&path))?.path();
                let columnar = thermode_table::Format::of(&file).is_columnar();
                if columnar || file.extension().is_some_and(|e| e == "csv") {
                    curves.push(file);
                }
            }
        }
    }
    curves.sort();
    Ok(curves)
}

/// A curve as wide numeric columns on one time base.
#[derive(Debug, Clone, PartialEq)]
struct Curve {
    times_s: Vec<f64>,
    columns: Vec<String>,
    rows: Vec<Vec<Option<f64>>>,
}

/// Reads a curve CSV: its time column (`loop_time` if given and present, else the first of [`TIME_COLUMNS`]),
/// every numeric column but the time columns; long form (`channel`) made wide.
fn read_curve(path: &Path, loop_time: Option<&str>) -> Result<Curve, ExportError> {
    let (header, rows) = read_csv(path)?;
    let position = |name: &str| header.iter().position(|h| h == name);
    let time = loop_time
        .and_then(position)
        .or_else(|| TIME_COLUMNS.iter().find_map(|t| position(t)))
        .ok_or_else(|| invalid(path, format!("no time column ({})", TIME_COLUMNS.join(", "))))?;
    let on_loop_clock = loop_time.is_some_and(|name| header[time] == name);
    let is_time = |i: usize| i == time || (on_loop_clock && TIME_COLUMNS.contains(&header[i].as_str()));
    let channel = position("channel");
    let numeric: Vec<usize> = (0..header.len())
        .filter(|&i| !is_time(i) && Some(i) != channel)
        .filter(|&i| rows.iter().any(|r| r.get(i).is_some_and(|v| v.parse::<f64>().is_ok())))
        .filter(|&i| {
            rows.iter()
                .all(|r| r.get(i).is_none_or(|v| v.is_empty() || v.parse::<f64>().is_ok()))
        })
        .collect();
    let mut by_time: BTreeMap<u64, BTreeMap<String, Option<f64>>> = BTreeMap::new();
    let mut columns = BTreeSet::new();
    for row in &rows {
        let t: f64 = row[time]
            .parse()
            .map_err(|_| invalid(path, format!("time {:?} is not a number", row[time])))?;
        let prefix = channel.map_or(String::new(), |c| format!("ch{}_", row[c]));
        let slot = by_time.entry(t.to_bits()).or_default();
        for &i in &numeric {
            let name = format!("{prefix}{}", header[i]);
            columns.insert(name.clone());
            slot.insert(name, row.get(i).and_then(|v| v.parse::<f64>().ok()));
        }
    }
    let columns: Vec<String> = columns.into_iter().collect();
    let mut times: Vec<(f64, BTreeMap<String, Option<f64>>)> =
        by_time.into_iter().map(|(bits, v)| (f64::from_bits(bits), v)).collect();
    times.sort_by(|a, b| a.0.total_cmp(&b.0));
    let rows = times
        .iter()
        .map(|(_, values)| columns.iter().map(|c| values.get(c).copied().flatten()).collect())
        .collect();
    Ok(Curve {
        times_s: times.iter().map(|(t, _)| *t).collect(),
        columns,
        rows,
    })
}

/// The sampling rate of `times_s` \[Hz\]: one over the median step.
fn sampling_hz(times_s: &[f64]) -> Option<f64> {
    let mut steps: Vec<f64> = times_s.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    if steps.is_empty() {
        return None;
    }
    steps.sort_by(f64::total_cmp);
    // Rounded to a microhertz: the steps of printed times carry rounding noise (0.01 s steps give 99.99999… Hz).
    Some((1e6 / steps[steps.len() / 2]).round() / 1e6)
}

/// Where a signal's time axis goes.
#[derive(Debug, Clone, Copy)]
enum Placement<'a> {
    /// Its own time base (a session without a loop clock).
    Own,
    /// A trial curve of a session with a loop clock: its `loop_time_s` on the session's axis.
    Trial(&'a SessionClock),
    /// A `serve --record` file given for a session with a loop clock: its `time_s` on the session's axis.
    Recording(&'a SessionClock),
}

impl Placement<'_> {
    /// The signal's first sample on its export axis \[s\]: `first_s` of its own time base moved to the session's.
    fn start_s(self, path: &Path, first_s: f64) -> f64 {
        match self {
            Placement::Own => first_s,
            Placement::Trial(clock) => clock.session_time_s(first_s),
            Placement::Recording(clock) => clock.session_time_s(first_s + clock.recording_offset_s(path)),
        }
    }

    fn description(self) -> &'static str {
        match self {
            Placement::Own => {
                "thermode curve; StartTime is the source's own time base (loop time of the daemon for a serve \
                 recording, time from the touch for a trial curve), not the events' onsets"
            }
            Placement::Trial(_) | Placement::Recording(_) => {
                "thermode curve on the session's one clock: StartTime is its first sample on the display's loop \
                 clock, seconds since the first trial's start, the time axis of the events' onsets"
            }
        }
    }
}

/// Writes a curve as `_stim` and `_physio` files of `session`; returns the files written.
fn write_signals(root: &Path, session: &Session, path: &Path, placement: Placement) -> Result<usize, ExportError> {
    let loop_time = matches!(placement, Placement::Trial(_)).then_some(LOOP_TIME_COLUMN);
    let curve = read_curve(path, loop_time)?;
    let rate_hz = sampling_hz(&curve.times_s).ok_or_else(|| invalid(path, "fewer than two time points"))?;
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let recording = label(&name)?;
    let dir = session.beh_dir(root)?;
    let prefix = format!("{}_recording-{recording}", session.prefix()?);
    let is_stim = |c: &String| STIM_COLUMNS.iter().any(|s| c == s || c.ends_with(&format!("_{s}")));
    let mut written = 0;
    for (suffix, stim) in [("stim", true), ("physio", false)] {
        let chosen: Vec<usize> = (0..curve.columns.len())
            .filter(|&i| is_stim(&curve.columns[i]) == stim)
            .collect();
        if chosen.is_empty() {
            continue;
        }
        let file = dir.join(format!("{prefix}_{suffix}.tsv.gz"));
        write_gzip_tsv(&file, &curve, &chosen)?;
        let columns: Vec<&str> = chosen.iter().map(|&i| curve.columns[i].as_str()).collect();
        let sidecar = json!({
            "SamplingFrequency": rate_hz,
            "StartTime": placement.start_s(path, curve.times_s[0]),
            "Columns": columns,
            "Source": path.file_name().map(|n| n.to_string_lossy().into_owned()),
            "Description": placement.description(),
        });
        write_json(&dir.join(format!("{prefix}_{suffix}.json")), &sidecar)?;
        written += 1;
    }
    Ok(written)
}

/// The chosen columns, tab-separated, no header, gzip (no name or time in the gzip header: same data, same bytes).
fn write_gzip_tsv(path: &Path, curve: &Curve, chosen: &[usize]) -> Result<(), ExportError> {
    if let Some(parent) = path.parent() {
        fs::create_dir_all(parent).map_err(io(parent))?;
    }
    let file = fs::File::create(path).map_err(io(path))?;
    let mut gz = GzEncoder::new(std::io::BufWriter::new(file), Compression::default());
    for row in &curve.rows {
        let line: Vec<String> = chosen
            .iter()
            .map(|&i| {
                row[i]
                    .filter(|v| v.is_finite())
                    .map_or("n/a".into(), |v| format!("{v}"))
            })
            .collect();
        writeln!(gz, "{}", line.join("\t")).map_err(io(path))?;
    }
    let mut out = gz.finish().map_err(io(path))?;
    out.flush().map_err(io(path))
}

/// Copies the session's CSV and sidecar to `sourcedata/thermode/`.
fn copy_source(root: &Path, session: &Session) -> Result<(), ExportError> {
    let dir = root.join("sourcedata").join("thermode");
    fs::create_dir_all(&dir).map_err(io(&dir))?;
    for file in [&session.csv, &session.sidecar] {
        if let Some(name) = file.file_name() {
            fs::copy(file, dir.join(name)).map_err(io(file))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_keep_letters_and_digits_only() {
        assert_eq!(label("P-01_a").unwrap(), "P01a");
        assert!(label("--").is_err());
    }

    #[test]
    fn the_sampling_rate_is_one_over_the_median_step() {
        let times: Vec<f64> = (0..101).map(|i| f64::from(i) * 0.01).collect();
        let rate = sampling_hz(&times).unwrap();
        assert!((rate - 100.0).abs() < 1e-6, "rate {rate} Hz, want 100 Hz");
        assert_eq!(sampling_hz(&[1.0]), None);
    }

    /// A data folder with one session of three 30 s trials answered after 2 s, and a 50 Hz trial curve beside it.
    fn data_folder(dir: &Path) {
        let sidecar = json!({"format": "thermode-lab session 1", "participant": "P-01", "experiment": "paper",
                             "session_date": "2026-11-23", "csv_file": "P-01_paper_2026-11-23.csv",
                             "condition_order": ["real", "simulated"]});
        fs::write(dir.join("P-01_paper_2026-11-23.json"), sidecar.to_string()).unwrap();
        let mut csv = String::from("participant,trial,condition,presented,response_time_s,presentation_s\n");
        for (trial, condition) in [(1, "real"), (2, "real"), (3, "simulated")] {
            csv.push_str(&format!("P-01,{trial},{condition},wood,2.0,30.0\n"));
        }
        fs::write(dir.join("P-01_paper_2026-11-23.csv"), csv).unwrap();
        let curves = dir.join("P-01_paper_2026-11-23_curves");
        fs::create_dir(&curves).unwrap();
        let mut curve = String::from("time_s,target_skin_c,sensor_c,material\n");
        for i in 0..100 {
            curve.push_str(&format!(
                "{},{},{},wood\n",
                f64::from(i) * 0.02,
                32.0 - f64::from(i) * 0.01,
                30.0
            ));
        }
        fs::write(curves.join("trial001.csv"), curve).unwrap();
    }

    fn export_into(data: &Path, out: &Path) -> BidsSummary {
        export_bids(&BidsOptions {
            data_dir: data.to_path_buf(),
            out_dir: out.to_path_buf(),
            recordings: Vec::new(),
        })
        .unwrap()
    }

    #[test]
    fn onsets_are_time_on_task_and_curves_split_into_stim_and_physio() {
        let root = tempfile::tempdir().unwrap();
        data_folder(root.path());
        let out = root.path().join("bids");
        let summary = export_into(root.path(), &out);
        assert_eq!(
            (summary.subjects, summary.sessions, summary.trials, summary.signals),
            (1, 1, 3, 2)
        );
        let beh = out.join("sub-P01/ses-20261123/beh");
        let events = fs::read_to_string(beh.join("sub-P01_ses-20261123_task-paper_events.tsv")).unwrap();
        let onsets: Vec<f64> = events
            .lines()
            .skip(1)
            .map(|l| l.split('\t').next().unwrap().parse().unwrap())
            .collect();
        // Each trial: 30 s of presentation, then 2 s to answer.
        assert_eq!(onsets, [0.0, 32.0, 64.0], "onsets");
        assert!(
            events.lines().nth(3).unwrap().starts_with("64\t30\tsimulated\t"),
            "{events}"
        );
        let stim: Value = serde_json::from_str(
            &fs::read_to_string(beh.join("sub-P01_ses-20261123_task-paper_recording-trial001_stim.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(stim["Columns"], json!(["target_skin_c"]));
        assert!(
            (stim["SamplingFrequency"].as_f64().unwrap() - 50.0).abs() < 1e-9,
            "{stim}"
        );
        let physio = beh.join("sub-P01_ses-20261123_task-paper_recording-trial001_physio.json");
        assert_eq!(
            serde_json::from_str::<Value>(&fs::read_to_string(physio).unwrap()).unwrap()["Columns"],
            json!(["sensor_c"])
        );
    }

    /// Trial starts on the daemon's loop clock in the clocked data folder \[s\].
    const TRIAL_STARTS_S: [f64; 3] = [100.0, 140.5, 181.25];

    /// A display session: three trials whose curves carry the daemon's loop time (100 Hz, 30 s from each start),
    /// and a `serve --record` file of the same daemon from loop time 90 s to 215 s whose `contact` turns 1 at each
    /// trial's start (the marker).
    fn clocked_data_folder(dir: &Path) -> PathBuf {
        let sidecar = json!({"format": "thermode-lab session 2", "participant": "P-01", "experiment": "paper",
                             "session_date": "2026-11-23", "csv_file": "P-01_paper_2026-11-23.csv",
                             "device": {"loop_time_zero_unix_s": 1.8e9}});
        fs::write(dir.join("P-01_paper_2026-11-23.json"), sidecar.to_string()).unwrap();
        let mut csv = String::from("participant,trial,condition,presented,response_time_s,presentation_s,curve_file\n");
        let curves = dir.join("P-01_paper_2026-11-23_curves");
        fs::create_dir(&curves).unwrap();
        for (index, start_s) in TRIAL_STARTS_S.iter().enumerate() {
            let trial = index + 1;
            let name = format!("trial-{trial:03}.csv");
            csv.push_str(&format!(
                "P-01,{trial},simulated,wood,2.5,30.0,P-01_paper_2026-11-23_curves/{name}\n"
            ));
            let mut curve = String::from("trial,time_s,loop_time_s,target_skin_c,finger_c\n");
            for i in 0..3000 {
                let t = f64::from(i) * 0.01;
                curve.push_str(&format!("{trial},{t},{:.6},{},30\n", start_s + t, 32.0 - t / 30.0));
            }
            fs::write(curves.join(name), curve).unwrap();
        }
        fs::write(dir.join("P-01_paper_2026-11-23.csv"), csv).unwrap();
        let mut record = String::from("time_s,channel,contact,material,target_skin_c,sensor_c\n");
        for i in 0..12_500u32 {
            let t = 90.0 + f64::from(i) * 0.01;
            let touching = TRIAL_STARTS_S.iter().any(|s| t >= s - 1e-9 && t < s + 30.0 - 1e-9);
            let (contact, material) = if touching { (1, "wood") } else { (0, "") };
            record.push_str(&format!("{t:.6},0,{contact},{material},32,30\n"));
        }
        let recording = dir.join("session_20261123-101500.csv");
        fs::write(&recording, record).unwrap();
        // The same daemon: its zero as the recorder wrote it, within a round trip of the session's estimate.
        let clock = json!({"loop_time_zero_unix_s": 1.8e9 + 0.0004});
        fs::write(dir.join("session_20261123-101500.clock.json"), clock.to_string()).unwrap();
        recording
    }

    fn gunzip_rows(path: &Path) -> Vec<Vec<String>> {
        let mut text = String::new();
        std::io::Read::read_to_string(
            &mut flate2::read::GzDecoder::new(fs::File::open(path).unwrap()),
            &mut text,
        )
        .unwrap();
        text.lines()
            .map(|l| l.split('\t').map(str::to_string).collect())
            .collect()
    }

    #[test]
    fn a_markers_event_onset_lands_on_the_signal_sample_where_it_was_recorded() {
        let root = tempfile::tempdir().unwrap();
        let recording = clocked_data_folder(root.path());
        let out = root.path().join("bids");
        export_bids(&BidsOptions {
            data_dir: root.path().to_path_buf(),
            out_dir: out.clone(),
            recordings: vec![("P-01".into(), recording)],
        })
        .unwrap();
        let beh = out.join("sub-P01/ses-20261123/beh");
        let prefix = "sub-P01_ses-20261123_task-paper";
        let events = fs::read_to_string(beh.join(format!("{prefix}_events.tsv"))).unwrap();
        let onsets: Vec<f64> = events
            .lines()
            .skip(1)
            .map(|l| l.split('\t').next().unwrap().parse().unwrap())
            .collect();
        // On the loop clock from the first trial's start (time on task would say 0, 32.5, 65).
        assert_eq!(onsets, [0.0, 40.5, 81.25], "{events}");
        let sidecar = |name: &str| -> Value {
            serde_json::from_str(&fs::read_to_string(beh.join(format!("{prefix}_recording-{name}.json"))).unwrap())
                .unwrap()
        };
        let physio = sidecar("session20261123101500_physio");
        let (start_s, rate_hz) = (
            physio["StartTime"].as_f64().unwrap(),
            physio["SamplingFrequency"].as_f64().unwrap(),
        );
        assert_eq!((start_s, rate_hz), (-10.0, 100.0), "{physio}");
        let columns: Vec<&str> = physio["Columns"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_str().unwrap())
            .collect();
        let contact = columns.iter().position(|c| *c == "ch0_contact").expect("ch0_contact");
        let rows = gunzip_rows(&beh.join(format!("{prefix}_recording-session20261123101500_physio.tsv.gz")));
        for onset in onsets {
            let sample = ((onset - start_s) * rate_hz).round() as usize;
            assert_eq!(
                (rows[sample - 1][contact].as_str(), rows[sample][contact].as_str()),
                ("0", "1"),
                "event at {onset} s: sample {sample} is not where the touch was recorded"
            );
        }
        // Each trial's own curve starts at its event's onset.
        for (trial, onset) in [(1, 0.0), (2, 40.5), (3, 81.25)] {
            let stim = sidecar(&format!("trial{trial:03}_stim"));
            assert_eq!(stim["StartTime"].as_f64(), Some(onset), "trial {trial}: {stim}");
        }
    }

    #[test]
    fn the_same_data_export_to_the_same_bytes_and_a_used_folder_is_refused() {
        let root = tempfile::tempdir().unwrap();
        data_folder(root.path());
        let (a, b) = (root.path().join("a"), root.path().join("b"));
        export_into(root.path(), &a);
        export_into(root.path(), &b);
        let gz = "sub-P01/ses-20261123/beh/sub-P01_ses-20261123_task-paper_recording-trial001_stim.tsv.gz";
        assert_eq!(fs::read(a.join(gz)).unwrap(), fs::read(b.join(gz)).unwrap());
        let again = export_bids(&BidsOptions {
            data_dir: root.path().to_path_buf(),
            out_dir: a.clone(),
            recordings: Vec::new(),
        });
        assert!(matches!(again, Err(ExportError::NotEmpty(_))), "{again:?}");
    }

    #[test]
    fn tsv_fields_are_never_empty_and_never_split() {
        assert_eq!(tsv_field(""), "n/a");
        assert_eq!(tsv_field("a\tb\nc"), "a b c");
    }
}
