//! The files of a procedure session, written durably in the data folder:
//!
//! - `<participant>_<experiment>_<date>.csv`: one row per completed trial ([`PROCEDURE_COLUMNS`]): what was asked
//!   (`intensity_c`, the change from the baseline; `target_c`; the display's `cutoff_c` when it clipped the target),
//!   what was delivered (`delivered_c`: the plate at the response's tick, at the plateau, or where the ramp ended),
//!   the response and its tick and loop time, the program's start tick and time, and the trial's trace file.
//! - `<same stem>_events.csv`: every program event of the session (segment starts, responses, program ends) with
//!   its tick and loop time, a trial's events appended before its row.
//! - `<same stem>_traces/trial-NNN.csv`: each trial's plate trace (`loop_time_s`, then per channel the set-point,
//!   sensor and plate), written before its row.
//! - `<same stem>.json`: the sidecar (format [`PROCEDURE_SIDECAR_FORMAT`]): the experiment file's text, the display
//!   and who answered, the columns, each resume.
//!
//! A row is appended with one write and `sync_all` before the next trial starts. On a resume (same participant and
//! experiment in the folder) a torn last line is cut, the experiment text must be the same, the rows are replayed
//! into the procedure (which is deterministic given its answers), and events of a trial that has no row are dropped.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thermode_platform::fs::{read_text_at_most, MAX_DATA_BYTES, MAX_SETTINGS_BYTES};
use thermode_platform::write_bytes_atomically;

use crate::session::{io, session_stem, SessionError};

/// The sidecar format of a procedure session (a `thermode-lab session …` format, found by `lab export`).
pub const PROCEDURE_SIDECAR_FORMAT: &str = "thermode-lab session procedure/1";

/// Columns of a procedure session CSV, in order.
pub const PROCEDURE_COLUMNS: [&str; 24] = [
    "participant",
    "expName",
    "session_date",
    "seed",
    "software_version",
    "trial",
    "label",
    "run",
    "channel",
    "baseline_c",
    "intensity_c",
    "target_c",
    "cutoff_c",
    "rate_c_s",
    "delivered_c",
    "response",
    "rating",
    "paradoxical_heat",
    "response_tick",
    "response_time_s",
    "start_tick",
    "start_time_s",
    "estimate_c",
    "curve_file",
];

/// Columns of the events file.
pub const EVENT_COLUMNS: [&str; 10] = [
    "trial", "event", "channel", "segment", "tick", "time_s", "to_c", "cutoff_c", "kind", "value",
];

/// One completed trial's row. Unknown numbers are NaN (an empty field).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ProcedureRow {
    /// 1-based trial number.
    pub trial: usize,
    /// What the trial measures (`CDT`, `levels`, a stimulus' name, …).
    pub label: String,
    /// 1-based run or repetition.
    pub run: usize,
    /// The channel (the first of a multi-zone program).
    pub channel: usize,
    /// The baseline \[°C\].
    pub baseline_c: f64,
    /// The requested intensity: change of the plate from the baseline \[°C\], signed (NaN for a multi-zone program).
    pub intensity_c: f64,
    /// The requested target \[°C\].
    pub target_c: f64,
    /// The display's limit the target was clipped to \[°C\] (NaN: not clipped).
    pub cutoff_c: f64,
    /// The ramp's rate \[°C/s\].
    pub rate_c_per_s: f64,
    /// The delivered intensity's plate temperature \[°C\].
    pub delivered_c: f64,
    /// `press`, `none`, `yes`, `no`, `rating`.
    pub response: String,
    /// The rating 0–100 (NaN: none).
    pub rating: f64,
    /// A paradoxical heat sensation was reported.
    pub paradoxical_heat: bool,
    /// The tick the response took effect on (None: no response on the display).
    pub response_tick: Option<u64>,
    /// Loop time of that tick \[s\].
    pub response_time_s: f64,
    /// The program's first tick.
    pub start_tick: u64,
    /// Loop time of that tick \[s\].
    pub start_time_s: f64,
    /// The procedure's threshold estimate after this trial \[°C, magnitude\] (NaN: none).
    pub estimate_c: f64,
    /// The trace file, relative to the data folder.
    pub curve_file: String,
}

/// A number as the CSV writes it: rounded to 1e-9 (the shortest decimal that reads back to it), empty when unknown.
pub fn number(value: f64) -> String {
    if value.is_finite() {
        let rounded = (value * 1e9).round() / 1e9;
        format!("{}", if rounded == 0.0 { 0.0 } else { rounded })
    } else {
        String::new()
    }
}

impl ProcedureRow {
    fn fields(&self, sidecar: &ProcedureSidecar) -> Vec<String> {
        PROCEDURE_COLUMNS
            .iter()
            .map(|column| match *column {
                "participant" => sidecar.participant.clone(),
                "expName" => sidecar.experiment.clone(),
                "session_date" => sidecar.session_date.clone(),
                "seed" => sidecar.seed.to_string(),
                "software_version" => env!("CARGO_PKG_VERSION").to_string(),
                "trial" => self.trial.to_string(),
                "label" => self.label.clone(),
                "run" => self.run.to_string(),
                "channel" => self.channel.to_string(),
                "baseline_c" => number(self.baseline_c),
                "intensity_c" => number(self.intensity_c),
                "target_c" => number(self.target_c),
                "cutoff_c" => number(self.cutoff_c),
                "rate_c_s" => number(self.rate_c_per_s),
                "delivered_c" => number(self.delivered_c),
                "response" => self.response.clone(),
                "rating" => number(self.rating),
                "paradoxical_heat" => self.paradoxical_heat.to_string(),
                "response_tick" => self.response_tick.map(|t| t.to_string()).unwrap_or_default(),
                "response_time_s" => number(self.response_time_s),
                "start_tick" => self.start_tick.to_string(),
                "start_time_s" => number(self.start_time_s),
                "estimate_c" => number(self.estimate_c),
                _ => self.curve_file.clone(),
            })
            .collect()
    }

    /// The row of a CSV record with `header` (`line` names it in errors).
    pub fn parse(header: &[String], record: &csv::StringRecord, line: u64, file: &Path) -> Result<Self, SessionError> {
        let bad = |message: String| SessionError::Corrupt {
            file: file.to_path_buf(),
            line,
            message,
        };
        let field = |name: &str| -> Result<&str, SessionError> {
            header
                .iter()
                .position(|h| h == name)
                .and_then(|i| record.get(i))
                .ok_or_else(|| bad(format!("no `{name}` field")))
        };
        let float = |name: &str| -> Result<f64, SessionError> {
            let text = field(name)?;
            if text.is_empty() {
                return Ok(f64::NAN);
            }
            text.parse::<f64>()
                .map_err(|_| bad(format!("`{name}` is `{text}`, not a number")))
        };
        let integer = |name: &str| -> Result<u64, SessionError> {
            field(name)?
                .parse::<u64>()
                .map_err(|_| bad(format!("`{name}` is not a whole number")))
        };
        Ok(ProcedureRow {
            trial: integer("trial")? as usize,
            label: field("label")?.to_string(),
            run: integer("run")? as usize,
            channel: integer("channel")? as usize,
            baseline_c: float("baseline_c")?,
            intensity_c: float("intensity_c")?,
            target_c: float("target_c")?,
            cutoff_c: float("cutoff_c")?,
            rate_c_per_s: float("rate_c_s")?,
            delivered_c: float("delivered_c")?,
            response: field("response")?.to_string(),
            rating: float("rating")?,
            paradoxical_heat: field("paradoxical_heat")? == "true",
            response_tick: field("response_tick")?.parse::<u64>().ok(),
            response_time_s: float("response_time_s")?,
            start_tick: integer("start_tick")?,
            start_time_s: float("start_time_s")?,
            estimate_c: float("estimate_c")?,
            curve_file: field("curve_file")?.to_string(),
        })
    }
}

/// One program event of a trial, for the events file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EventRow {
    /// 1-based trial.
    pub trial: usize,
    /// `segment_start`, `response`, `program_end`.
    pub event: String,
    /// The channel.
    pub channel: usize,
    /// The segment, if any.
    pub segment: Option<usize>,
    /// The tick.
    pub tick: u64,
    /// Loop time \[s\].
    pub time_s: f64,
    /// A started segment's target \[°C\] (NaN: none).
    pub to_c: f64,
    /// Its cut-off \[°C\] (NaN: none).
    pub cutoff_c: f64,
    /// A response's kind (`button`, `rating`).
    pub kind: String,
    /// A rating (NaN: none).
    pub value: f64,
}

impl EventRow {
    fn fields(&self) -> [String; 10] {
        [
            self.trial.to_string(),
            self.event.clone(),
            self.channel.to_string(),
            self.segment.map(|s| s.to_string()).unwrap_or_default(),
            self.tick.to_string(),
            number(self.time_s),
            number(self.to_c),
            number(self.cutoff_c),
            self.kind.clone(),
            number(self.value),
        ]
    }
}

/// A resume of the session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProcedureResume {
    /// When (UTC, ISO 8601 with milliseconds).
    pub started_utc: String,
    /// Trials already recorded.
    pub completed_trials: usize,
    /// The display of the resumed part.
    pub display: serde_json::Value,
}

/// The sidecar of a procedure session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProcedureSidecar {
    /// Always [`PROCEDURE_SIDECAR_FORMAT`].
    pub format: String,
    /// Participant identifier.
    pub participant: String,
    /// Experiment name.
    pub experiment: String,
    /// The procedure (`limits`, `levels`, `staircase`, `questplus`, `program`).
    pub procedure: String,
    /// Date the session started (`YYYY-MM-DD`).
    pub session_date: String,
    /// When it started (UTC, ISO 8601 with milliseconds).
    pub started_utc: String,
    /// The experiment's seed.
    pub seed: u64,
    /// Software name.
    pub software: String,
    /// Software version that started the session.
    pub software_version: String,
    /// The experiment file's path as given.
    pub experiment_file: String,
    /// The experiment file's whole text.
    pub experiment_toml: String,
    /// The display (and, for a daemon, its loop clock's wall-clock zero `loop_time_zero_unix_s`).
    pub device: serde_json::Value,
    /// Who answered.
    pub answers: String,
    /// The session CSV's file name.
    pub csv_file: String,
    /// The events file's name.
    pub events_file: String,
    /// The CSV's columns.
    pub columns: Vec<String>,
    /// Every resume.
    #[serde(default)]
    pub resumes: Vec<ProcedureResume>,
}

/// What opens a procedure session.
#[derive(Debug, Clone)]
pub struct ProcedureSessionSpec<'a> {
    /// Participant identifier (letters, digits, `_`, `-`).
    pub participant: &'a str,
    /// Experiment name.
    pub experiment: &'a str,
    /// The procedure's name.
    pub procedure: &'a str,
    /// The experiment's seed.
    pub seed: u64,
    /// The experiment file's path and text.
    pub experiment_file: (&'a Path, &'a str),
    /// The data folder (created if missing).
    pub data_dir: &'a Path,
    /// Today (`YYYY-MM-DD`), for a new session.
    pub today: &'a str,
    /// Now (UTC, ISO 8601 with milliseconds).
    pub now_utc: &'a str,
    /// The display's description.
    pub device: serde_json::Value,
    /// Who answers.
    pub answers: String,
}

/// An open procedure session.
#[derive(Debug)]
pub struct ProcedureSession {
    data_dir: PathBuf,
    stem: String,
    sidecar: ProcedureSidecar,
    rows: Vec<ProcedureRow>,
    csv: File,
    events: File,
}

fn csv_line(fields: &[String]) -> Vec<u8> {
    let mut writer = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    // Writing to memory cannot fail; the fields hold no line ends.
    let _ = writer.write_record(fields);
    writer.into_inner().unwrap_or_default()
}

fn atomically(path: &Path, bytes: &[u8]) -> Result<(), SessionError> {
    write_bytes_atomically(path, bytes).map_err(io(path))
}

fn append(path: &Path) -> Result<File, SessionError> {
    OpenOptions::new().append(true).open(path).map_err(io(path))
}

impl ProcedureSession {
    /// Opens the session of `spec`: the existing one of this participant and experiment (resumed), else a new one.
    pub fn open(spec: &ProcedureSessionSpec) -> Result<ProcedureSession, SessionError> {
        std::fs::create_dir_all(spec.data_dir).map_err(io(spec.data_dir))?;
        match Self::find(spec)? {
            Some(sidecar) => Self::resume(spec, sidecar),
            None => Self::create(spec),
        }
    }

    fn find(spec: &ProcedureSessionSpec) -> Result<Option<ProcedureSidecar>, SessionError> {
        let prefix = format!("{}_{}_", spec.participant, spec.experiment);
        let mut found: Option<ProcedureSidecar> = None;
        for entry in std::fs::read_dir(spec.data_dir).map_err(io(spec.data_dir))? {
            let path = entry.map_err(io(spec.data_dir))?.path();
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            if !(name.starts_with(&prefix) && name.ends_with(".json")) {
                continue;
            }
            let text = read_text_at_most(&path, MAX_SETTINGS_BYTES).map_err(io(&path))?;
            let Ok(sidecar) = serde_json::from_str::<ProcedureSidecar>(&text) else {
                continue;
            };
            let ours = sidecar.format == PROCEDURE_SIDECAR_FORMAT
                && sidecar.participant == spec.participant
                && sidecar.experiment == spec.experiment;
            if ours && found.as_ref().is_none_or(|f| f.session_date < sidecar.session_date) {
                found = Some(sidecar);
            }
        }
        Ok(found)
    }

    fn create(spec: &ProcedureSessionSpec) -> Result<ProcedureSession, SessionError> {
        let stem = session_stem(spec.participant, spec.experiment, spec.today);
        let sidecar = ProcedureSidecar {
            format: PROCEDURE_SIDECAR_FORMAT.to_string(),
            participant: spec.participant.to_string(),
            experiment: spec.experiment.to_string(),
            procedure: spec.procedure.to_string(),
            session_date: spec.today.to_string(),
            started_utc: spec.now_utc.to_string(),
            seed: spec.seed,
            software: "thermode".to_string(),
            software_version: env!("CARGO_PKG_VERSION").to_string(),
            experiment_file: spec.experiment_file.0.display().to_string(),
            experiment_toml: spec.experiment_file.1.to_string(),
            device: spec.device.clone(),
            answers: spec.answers.clone(),
            csv_file: format!("{stem}.csv"),
            events_file: format!("{stem}_events.csv"),
            columns: PROCEDURE_COLUMNS.iter().map(|c| c.to_string()).collect(),
            resumes: Vec::new(),
        };
        let csv_path = spec.data_dir.join(&sidecar.csv_file);
        if csv_path.exists() {
            return Err(SessionError::Collision { file: csv_path });
        }
        let events_path = spec.data_dir.join(&sidecar.events_file);
        let sidecar_path = spec.data_dir.join(format!("{stem}.json"));
        atomically(&sidecar_path, &sidecar_bytes(&sidecar))?;
        let header: Vec<String> = sidecar.columns.clone();
        atomically(&csv_path, &csv_line(&header))?;
        let event_header: Vec<String> = EVENT_COLUMNS.iter().map(|c| c.to_string()).collect();
        atomically(&events_path, &csv_line(&event_header))?;
        Ok(ProcedureSession {
            data_dir: spec.data_dir.to_path_buf(),
            stem,
            rows: Vec::new(),
            csv: append(&csv_path)?,
            events: append(&events_path)?,
            sidecar,
        })
    }

    fn resume(spec: &ProcedureSessionSpec, mut sidecar: ProcedureSidecar) -> Result<ProcedureSession, SessionError> {
        let stem = session_stem(&sidecar.participant, &sidecar.experiment, &sidecar.session_date);
        let sidecar_path = spec.data_dir.join(format!("{stem}.json"));
        if sidecar.experiment_toml != spec.experiment_file.1 {
            return Err(SessionError::Mismatch {
                file: sidecar_path,
                message: "the session was recorded with a different experiment file; name the experiment anew \
                          or move the session away"
                    .into(),
            });
        }
        let csv_path = spec.data_dir.join(&sidecar.csv_file);
        let rows = read_rows(&csv_path)?;
        let events_path = spec.data_dir.join(&sidecar.events_file);
        keep_events_of(&events_path, rows.len())?;
        sidecar.resumes.push(ProcedureResume {
            started_utc: spec.now_utc.to_string(),
            completed_trials: rows.len(),
            display: spec.device.clone(),
        });
        atomically(&sidecar_path, &sidecar_bytes(&sidecar))?;
        Ok(ProcedureSession {
            data_dir: spec.data_dir.to_path_buf(),
            stem,
            rows,
            csv: append(&csv_path)?,
            events: append(&events_path)?,
            sidecar,
        })
    }

    /// The completed trials.
    pub fn rows(&self) -> &[ProcedureRow] {
        &self.rows
    }

    /// The sidecar.
    pub fn sidecar(&self) -> &ProcedureSidecar {
        &self.sidecar
    }

    /// The session CSV.
    pub fn csv_path(&self) -> PathBuf {
        self.data_dir.join(&self.sidecar.csv_file)
    }

    /// Whether this session continues an earlier one.
    pub fn resumed(&self) -> bool {
        !self.sidecar.resumes.is_empty()
    }

    /// Writes trial `trial`'s trace atomically and returns its path relative to the data folder.
    pub fn write_trace(&self, trial: usize, csv_text: &str) -> Result<String, SessionError> {
        let folder = format!("{}_traces", self.stem);
        let dir = self.data_dir.join(&folder);
        std::fs::create_dir_all(&dir).map_err(io(&dir))?;
        let name = format!("trial-{trial:03}.csv");
        atomically(&dir.join(&name), csv_text.as_bytes())?;
        Ok(format!("{folder}/{name}"))
    }

    /// Appends a trial's events, then its row, each synced to disk.
    pub fn append(&mut self, row: ProcedureRow, events: &[EventRow]) -> Result<(), SessionError> {
        let expected = self.rows.len() + 1;
        if row.trial != expected {
            return Err(SessionError::Mismatch {
                file: self.csv_path(),
                message: format!("trial {} given where trial {expected} is next", row.trial),
            });
        }
        let bytes: Vec<u8> = events.iter().flat_map(|e| csv_line(&e.fields())).collect();
        let events_path = self.data_dir.join(&self.sidecar.events_file);
        self.events.write_all(&bytes).map_err(io(&events_path))?;
        self.events.sync_all().map_err(io(&events_path))?;
        let path = self.csv_path();
        self.csv
            .write_all(&csv_line(&row.fields(&self.sidecar)))
            .map_err(io(&path))?;
        self.csv.sync_all().map_err(io(&path))?;
        self.rows.push(row);
        Ok(())
    }
}

fn sidecar_bytes(sidecar: &ProcedureSidecar) -> Vec<u8> {
    let mut text = serde_json::to_string_pretty(sidecar).unwrap_or_default();
    text.push('\n');
    text.into_bytes()
}

/// The complete rows of a session CSV; a torn last line (no line end: a kill mid-write) is cut off.
pub fn read_rows(path: &Path) -> Result<Vec<ProcedureRow>, SessionError> {
    let mut text = read_text_at_most(path, MAX_DATA_BYTES).map_err(io(path))?;
    if !text.ends_with('\n') {
        let keep = text.rfind('\n').map_or(0, |i| i + 1);
        text.truncate(keep);
        atomically(path, text.as_bytes())?;
    }
    let mut reader = csv::ReaderBuilder::new().from_reader(text.as_bytes());
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| corrupt(path, 1, e.to_string()))?
        .iter()
        .map(str::to_string)
        .collect();
    let mut rows = Vec::new();
    for (index, record) in reader.records().enumerate() {
        let line = index as u64 + 2;
        let record = record.map_err(|e| corrupt(path, line, e.to_string()))?;
        let row = ProcedureRow::parse(&header, &record, line, path)?;
        if row.trial != rows.len() + 1 {
            return Err(corrupt(
                path,
                line,
                format!("trial {} where {} is next", row.trial, rows.len() + 1),
            ));
        }
        rows.push(row);
    }
    Ok(rows)
}

fn corrupt(path: &Path, line: u64, message: String) -> SessionError {
    SessionError::Corrupt {
        file: path.to_path_buf(),
        line,
        message,
    }
}

/// Drops from the events file the events of trials after `completed` (a trial cut short before its row).
fn keep_events_of(path: &Path, completed: usize) -> Result<(), SessionError> {
    let text = read_text_at_most(path, MAX_DATA_BYTES).map_err(io(path))?;
    let mut kept = String::with_capacity(text.len());
    for (index, line) in text.lines().enumerate() {
        let trial = line.split(',').next().and_then(|t| t.parse::<usize>().ok());
        if index == 0 || trial.is_some_and(|t| t <= completed) {
            kept.push_str(line);
            kept.push('\n');
        }
    }
    if kept != text {
        atomically(path, kept.as_bytes())?;
    }
    Ok(())
}
