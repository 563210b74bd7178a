//! Session files: one CSV per session and participant, PsychoPy-style, written durably, and its JSON sidecar.
//!
//! - `<participant>_<experiment>_<YYYY-MM-DD>.csv`: a header ([`SESSION_COLUMNS`]) and one row per completed trial;
//!   the session fields (participant, experiment, session date, seed, software version) are repeated on every row.
//!   The analysis (`thermode lab analyze`) reads it as it is (`participant, condition, presented, identified,
//!   excluded`; the other columns are kept).
//! - `<same stem>.json`: the sidecar — the experiment file's whole text, seed, software version, device
//!   configuration, the participant's condition order and, for each resume, when and with what it was resumed.
//!
//! **Durability.** The sidecar and then the CSV header are written atomically (temporary file, `sync_all`, rename,
//! directory sync). Each trial row is appended with one write and `sync_all`ed before [`SessionFile::append`]
//! returns, so the runner never starts a trial before the previous one is on disk.
//!
//! **Resume.** [`SessionFile::open`] looks in the data folder for a session of the same participant and experiment
//! (any date; identified by its sidecar, which names both, so underscores in names cannot mix sessions up; a new
//! session whose file name is taken by another session is refused, never written over). It
//! refuses, with the differing keys, a session recorded with a different design (seed, materials, …). A last line
//! without its line end is a row torn by a kill mid-write: it is cut off (the file is truncated to the last complete
//! row). Every complete row must parse and match the planned trial of its position, else the file is reported as
//! corrupt with its line — a complete row is never dropped silently. The runner then continues at the first missing
//! trial.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thermode_platform::{parse_iso_date, utc_iso8601_ms, write_bytes_atomically};
use thiserror::Error;

use crate::design::{Experiment, ExperimentFile};
use crate::plan::{ParticipantPlan, PlannedTrial};

/// Columns of a session CSV (format 2), in order. Where a column means what one of PsychoPy's data files means, it
/// has PsychoPy's name (`participant`, `expName`, `trials.thisN`, `key_resp.keys`, `key_resp.rt`); `docs/lab.md`
/// lists them and says why the others differ. Finger temperatures measured on a display and those of a simulation
/// are never in the same column: `finger_*` hold measurements, `model_finger_*` a simulation's (the other set is
/// empty).
pub const SESSION_COLUMNS: [&str; 25] = columns(&[
    &[
        "participant",
        "expName",
        "session_date",
        "seed",
        "software_version",
        "trials.thisN",
    ],
    &PLAN_COLUMNS,
    &["key_resp.keys", "key_resp.rt", "presentation_s"],
    &FINGER_COLUMNS,
    &["model_finger_baseline_c", "model_finger_start_c", "model_finger_end_c"],
    &EXCLUSION_COLUMNS,
    &["curve_file"],
]);

/// The columns of format 1 (thermode 0.1 before PsychoPy's names), still read and continued on a resume.
pub const SESSION_COLUMNS_V1: [&str; 20] = columns(&[
    &["participant", "experiment", "session_date", "seed", "software_version"],
    &PLAN_COLUMNS,
    &["response_key", "response_time_s", "presentation_s"],
    &FINGER_COLUMNS,
    &EXCLUSION_COLUMNS,
]);

/// The columns of a trial's place in the plan and its answer, the same in both formats.
const PLAN_COLUMNS: [&str; 7] = [
    "trial",
    "block",
    "repetition",
    "condition",
    "position",
    "presented",
    "identified",
];
/// The finger temperatures measured on a display, the same in both formats.
const FINGER_COLUMNS: [&str; 3] = ["finger_baseline_c", "finger_start_c", "finger_end_c"];
/// The exclusion rule's verdict, the same in both formats.
const EXCLUSION_COLUMNS: [&str; 2] = ["excluded", "exclusion_reason"];

/// The column names of `parts`, one after the other; `N` must be their number (checked when compiled).
const fn columns<const N: usize>(parts: &[&[&'static str]]) -> [&'static str; N] {
    let mut out = [""; N];
    let (mut part, mut n) = (0, 0);
    while part < parts.len() {
        let mut i = 0;
        while i < parts[part].len() {
            out[n] = parts[part][i];
            (i, n) = (i + 1, n + 1);
        }
        part += 1;
    }
    assert!(n == N, "the column count differs from the parts' total");
    out
}

/// Format-1 names of the columns that format 2 renamed to PsychoPy's: (format 2, format 1).
const RENAMED: [(&str, &str); 3] = [
    ("expName", "experiment"),
    ("key_resp.keys", "response_key"),
    ("key_resp.rt", "response_time_s"),
];

/// The columns that hold measured durations (they differ between two runs of the same plan on a person or a
/// display in real time; a simulation at time scale 0 writes them identically).
pub const TIMING_COLUMNS: [&str; 2] = ["key_resp.rt", "presentation_s"];

/// The software version written into every row and sidecar.
pub const SOFTWARE_VERSION: &str = env!("CARGO_PKG_VERSION");

/// The `format` field of a sidecar.
pub const SIDECAR_FORMAT: &str = "thermode-lab session 2";

/// The `format` of a format-1 sidecar (its CSV has [`SESSION_COLUMNS_V1`]).
pub const SIDECAR_FORMAT_V1: &str = "thermode-lab session 1";

/// Why a session file could not be created, resumed or written.
#[derive(Debug, Error)]
pub enum SessionError {
    /// A file or folder could not be read or written.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The operating-system error (part of the message, so not chained as a source).
        error: std::io::Error,
    },
    /// A sidecar is not valid JSON of the expected shape.
    #[error("{}: invalid session sidecar: {message}", path.display())]
    Sidecar {
        /// The sidecar.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The existing session belongs to a different plan.
    #[error("{}: refusing to resume: {message}", file.display())]
    Mismatch {
        /// The session file.
        file: PathBuf,
        /// What differs.
        message: String,
    },
    /// A complete row does not parse or does not match the plan.
    #[error("{}:{line}: {message}", file.display())]
    Corrupt {
        /// The session CSV.
        file: PathBuf,
        /// 1-based line.
        line: u64,
        /// What is wrong.
        message: String,
    },
    /// More than one session of the same participant and experiment.
    #[error(
        "several sessions of this participant and experiment: {}; move all but one away",
        list(files)
    )]
    Ambiguous {
        /// Their CSV files.
        files: Vec<PathBuf>,
    },
    /// A new session's file name is taken by another session (e.g. participant `a_b` of experiment `c` and
    /// participant `a` of experiment `b_c` on the same day).
    #[error("{}: already exists and belongs to another session; use another data folder", file.display())]
    Collision {
        /// The existing file.
        file: PathBuf,
    },
    /// A session CSV without its sidecar, so it cannot be checked against the plan.
    #[error("{}: session file without its sidecar {}; cannot check it against the plan", csv.display(), sidecar.display())]
    MissingSidecar {
        /// The CSV.
        csv: PathBuf,
        /// The sidecar expected beside it.
        sidecar: PathBuf,
    },
}

fn list(files: &[PathBuf]) -> String {
    files
        .iter()
        .map(|f| f.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

pub(crate) fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SessionError + '_ {
    move |error| SessionError::Io {
        path: path.to_path_buf(),
        error,
    }
}

/// One completed trial.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialRecord {
    /// The planned trial.
    pub trial: PlannedTrial,
    /// Library name of the answer.
    pub identified: String,
    /// The answer as option number, 1-based.
    pub response_key: usize,
    /// Time from the end of the presentation to the answer \[s\], measured when a person answered; `None` (an empty
    /// cell, as PsychoPy leaves a missing `rt`) for a responses file or the simulated participant.
    pub response_time_s: Option<f64>,
    /// Duration of the presentation in experiment seconds \[s\]: the clock's seconds divided by the time scale; at
    /// time scale 0 (a simulation without waiting) the presentation the stimulus covered.
    pub presentation_s: f64,
    /// Whether the finger temperatures below were measured on a display (`finger_*` columns) or simulated
    /// (`model_finger_*` columns).
    pub finger_measured: bool,
    /// The session's finger baseline: the start temperature of its first trial \[°C\].
    pub finger_baseline_c: f64,
    /// Finger temperature just before the touch \[°C\].
    pub finger_start_c: f64,
    /// Finger temperature at the end of the presentation \[°C\].
    pub finger_end_c: f64,
    /// Whether the exclusion rule discarded the trial.
    pub excluded: bool,
    /// Why (empty when not excluded).
    pub exclusion_reason: String,
    /// Software version that recorded the row.
    pub software_version: String,
    /// The trial's curve file beside the session CSV (empty when the stimulus records none).
    pub curve_file: String,
}

/// A resume of a session, as noted in its sidecar.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResumeNote {
    /// Date of the resume (`YYYY-MM-DD`).
    pub date: String,
    /// Trials already recorded at the resume.
    pub recorded_trials: usize,
    /// Whether a torn last row was cut off.
    pub removed_torn_row: bool,
    /// Software version that resumed.
    pub software_version: String,
    /// Device configuration at the resume.
    pub device: serde_json::Value,
    /// When the resume started (UTC, ISO 8601 with milliseconds).
    #[serde(default)]
    pub started_utc: String,
}

/// The sidecar JSON of a session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sidecar {
    /// Always [`SIDECAR_FORMAT`].
    pub format: String,
    /// Participant identifier.
    pub participant: String,
    /// 0-based index of the participant in the design.
    pub participant_index: usize,
    /// Experiment name.
    pub experiment: String,
    /// Date the session started (`YYYY-MM-DD`).
    pub session_date: String,
    /// When the session started (UTC, ISO 8601 with milliseconds; empty in format 1).
    #[serde(default)]
    pub started_utc: String,
    /// The design's seed.
    pub seed: u64,
    /// Software name.
    pub software: String,
    /// Software version that started the session.
    pub software_version: String,
    /// Path of the experiment file as given.
    pub experiment_file: String,
    /// The experiment file's whole text.
    pub experiment_toml: String,
    /// Device configuration (as passed by the caller).
    pub device: serde_json::Value,
    /// File name of the session CSV.
    pub csv_file: String,
    /// The CSV's columns.
    pub columns: Vec<String>,
    /// The conditions in this participant's order.
    pub condition_order: Vec<String>,
    /// Number of planned trials.
    pub planned_trials: usize,
    /// Every resume, in order.
    #[serde(default)]
    pub resumes: Vec<ResumeNote>,
}

/// What identifies a session: the experiment, the participant's plan and where the data go.
#[derive(Debug, Clone, Copy)]
pub struct SessionSpec<'a> {
    /// The experiment file.
    pub experiment: &'a ExperimentFile,
    /// The participant's plan.
    pub plan: &'a ParticipantPlan,
    /// The data folder (created if missing).
    pub data_dir: &'a Path,
    /// Today's date (`YYYY-MM-DD`), used for a new session and noted on a resume.
    pub today: &'a str,
    /// The wall-clock time now (s since 1970, UTC), noted as the start of a new session or a resume.
    pub now_unix_s: f64,
    /// Device configuration for the sidecar.
    pub device: &'a serde_json::Value,
}

/// An open session: its files, the completed trials, and the CSV open for appending.
#[derive(Debug)]
pub struct SessionFile {
    csv_path: PathBuf,
    sidecar_path: PathBuf,
    sidecar: Sidecar,
    records: Vec<TrialRecord>,
    planned: usize,
    options: Vec<String>,
    appender: File,
    resumed: bool,
    removed_torn_row: bool,
}

/// The file stem of a session: `<participant>_<experiment>_<date>`.
pub fn session_stem(participant: &str, experiment: &str, date: &str) -> String {
    format!("{participant}_{experiment}_{date}")
}

impl SessionFile {
    /// Opens the session of `spec` — resuming the existing one of this participant and experiment if there is one
    /// (see the module documentation), creating it dated `spec.today` otherwise.
    pub fn open(spec: &SessionSpec) -> Result<SessionFile, SessionError> {
        std::fs::create_dir_all(spec.data_dir).map_err(io(spec.data_dir))?;
        let design = &spec.experiment.experiment;
        match find_session(spec.data_dir, &spec.plan.id, &design.name)? {
            Some((sidecar_path, sidecar)) => Self::resume(spec, sidecar_path, sidecar),
            None => Self::create(spec),
        }
    }

    fn create(spec: &SessionSpec) -> Result<SessionFile, SessionError> {
        let design = &spec.experiment.experiment;
        let stem = session_stem(&spec.plan.id, &design.name, spec.today);
        let sidecar = Sidecar {
            format: SIDECAR_FORMAT.to_string(),
            participant: spec.plan.id.clone(),
            participant_index: spec.plan.index,
            experiment: design.name.clone(),
            session_date: spec.today.to_string(),
            started_utc: utc_iso8601_ms(spec.now_unix_s),
            seed: design.seed,
            software: "thermode-lab".to_string(),
            software_version: SOFTWARE_VERSION.to_string(),
            experiment_file: spec.experiment.path.display().to_string(),
            experiment_toml: spec.experiment.text.clone(),
            device: spec.device.clone(),
            csv_file: format!("{stem}.csv"),
            columns: SESSION_COLUMNS.iter().map(|c| c.to_string()).collect(),
            condition_order: spec.plan.condition_order.iter().map(|c| c.name().to_string()).collect(),
            planned_trials: spec.plan.trials.len(),
            resumes: Vec::new(),
        };
        let sidecar_path = spec.data_dir.join(format!("{stem}.json"));
        for taken in [&sidecar_path, &spec.data_dir.join(&sidecar.csv_file)] {
            if taken.exists() {
                return Err(SessionError::Collision { file: taken.clone() });
            }
        }
        write_sidecar(&sidecar_path, &sidecar)?;
        Self::finish_open(spec, sidecar_path, sidecar, false)
    }

    fn resume(spec: &SessionSpec, sidecar_path: PathBuf, mut sidecar: Sidecar) -> Result<SessionFile, SessionError> {
        check_same_design(&sidecar_path, &sidecar, &spec.experiment.experiment)?;
        let mut session = Self::finish_open(spec, sidecar_path, sidecar.clone(), true)?;
        if !session.is_complete() {
            sidecar.resumes.push(ResumeNote {
                date: spec.today.to_string(),
                recorded_trials: session.records.len(),
                removed_torn_row: session.removed_torn_row,
                software_version: SOFTWARE_VERSION.to_string(),
                device: spec.device.clone(),
                started_utc: utc_iso8601_ms(spec.now_unix_s),
            });
            write_sidecar(&session.sidecar_path, &sidecar)?;
            session.sidecar = sidecar;
        }
        Ok(session)
    }

    /// Creates the CSV with its header if it is missing, reads and repairs it otherwise, and opens it for appending.
    fn finish_open(
        spec: &SessionSpec,
        sidecar_path: PathBuf,
        sidecar: Sidecar,
        resumed: bool,
    ) -> Result<SessionFile, SessionError> {
        let csv_path = sidecar_path.with_file_name(&sidecar.csv_file);
        let known = match sidecar.format.as_str() {
            SIDECAR_FORMAT => &SESSION_COLUMNS[..],
            SIDECAR_FORMAT_V1 => &SESSION_COLUMNS_V1[..],
            other => {
                return Err(SessionError::Mismatch {
                    file: sidecar_path,
                    message: format!("session format `{other}` is not one this version of thermode reads"),
                })
            }
        };
        if sidecar.columns != known {
            return Err(SessionError::Mismatch {
                file: sidecar_path,
                message: format!("its columns are not those of `{}`", sidecar.format),
            });
        }
        let header = format!("{}\n", sidecar.columns.join(","));
        if !csv_path.exists() {
            write_atomically(&csv_path, header.as_bytes())?;
        }
        let mut session = SessionFile {
            appender: OpenOptions::new().append(true).open(&csv_path).map_err(io(&csv_path))?,
            csv_path,
            sidecar_path,
            sidecar,
            records: Vec::new(),
            planned: spec.plan.trials.len(),
            options: spec.experiment.experiment.response_options.clone(),
            resumed,
            removed_torn_row: false,
        };
        session.read_existing(spec.plan, &header)?;
        Ok(session)
    }

    /// Reads the completed rows, cutting off a torn last line, and checks every row against the plan.
    fn read_existing(&mut self, plan: &ParticipantPlan, header: &str) -> Result<(), SessionError> {
        let path = self.csv_path.clone();
        let bytes = std::fs::read(&path).map_err(io(&path))?;
        if !bytes.starts_with(header.as_bytes()) {
            return Err(SessionError::Mismatch {
                file: path,
                message: "its header is not the session header of this version of thermode".to_string(),
            });
        }
        let complete = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        if complete < bytes.len() {
            truncate(&path, complete as u64)?;
            self.removed_torn_row = true;
        }
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(true)
            .from_reader(&bytes[..complete]);
        for (k, record) in reader.records().enumerate() {
            let line = k as u64 + 2;
            let corrupt = |message: String| SessionError::Corrupt {
                file: path.clone(),
                line,
                message,
            };
            let record = record.map_err(|e| corrupt(e.to_string()))?;
            let planned = plan
                .trials
                .get(k)
                .ok_or_else(|| corrupt(format!("more rows than the {} planned trials", plan.trials.len())))?;
            let parsed = self.parse_row(&record, planned).map_err(corrupt)?;
            if let Some(first) = self.records.first() {
                if parsed.finger_baseline_c != first.finger_baseline_c {
                    return Err(corrupt("`finger_baseline_c` differs from the first row's".to_string()));
                }
            }
            self.records.push(parsed);
        }
        Ok(())
    }

    /// Parses one row and checks it against the session and the planned trial.
    fn parse_row(&self, record: &csv::StringRecord, planned: &PlannedTrial) -> Result<TrialRecord, String> {
        let columns = &self.sidecar.columns;
        if record.len() != columns.len() {
            return Err(format!("{} fields, the header has {}", record.len(), columns.len()));
        }
        let field = |name: &str| record.get(column(columns, name)).unwrap_or_default();
        let expect = |name: &str, want: &str| {
            let got = field(name);
            if got == want {
                Ok(())
            } else {
                Err(format!(
                    "column `{name}` is `{got}`, expected `{want}` (the session and its plan)"
                ))
            }
        };
        let s = &self.sidecar;
        expect("participant", &s.participant)?;
        expect("expName", &s.experiment)?;
        expect("session_date", &s.session_date)?;
        expect("seed", &s.seed.to_string())?;
        expect("trial", &planned.trial.to_string())?;
        expect("block", &planned.block.to_string())?;
        expect("repetition", &planned.repetition.to_string())?;
        expect("condition", planned.condition.name())?;
        expect("position", &planned.position.to_string())?;
        expect("presented", &planned.presented)?;
        let identified = field("identified").to_string();
        let key = self.options.iter().position(|o| *o == identified).map(|i| i + 1);
        let Some(response_key) = key else {
            return Err(format!("`identified` = `{identified}` is not a response option"));
        };
        expect("key_resp.keys", &response_key.to_string())?;
        let excluded = match field("excluded") {
            "true" => true,
            "false" => false,
            other => return Err(format!("`excluded` = `{other}`: expected true or false")),
        };
        // Format 1 kept every finger temperature in `finger_*`, and they were all simulated (no display could run
        // the lab then); format 2 keeps a simulation's in `model_finger_*`.
        let v1 = self.sidecar.format == SIDECAR_FORMAT_V1;
        let finger_measured = !v1 && !field("finger_start_c").is_empty();
        let prefix = if finger_measured || v1 { "" } else { "model_" };
        let number = |name: &str| -> Result<f64, String> {
            let text = field(name);
            text.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("`{name}` = `{text}` is not a finite number"))
        };
        Ok(TrialRecord {
            trial: planned.clone(),
            identified,
            response_key,
            response_time_s: match field("key_resp.rt") {
                "" => None,
                _ => Some(number("key_resp.rt")?),
            },
            presentation_s: number("presentation_s")?,
            finger_measured,
            finger_baseline_c: number(&format!("{prefix}finger_baseline_c"))?,
            finger_start_c: number(&format!("{prefix}finger_start_c"))?,
            finger_end_c: number(&format!("{prefix}finger_end_c"))?,
            excluded,
            exclusion_reason: field("exclusion_reason").to_string(),
            software_version: field("software_version").to_string(),
            curve_file: field("curve_file").to_string(),
        })
    }

    /// Appends the next trial's row and syncs it to disk. `record.trial` must be the next planned trial.
    pub fn append(&mut self, record: &TrialRecord) -> Result<(), SessionError> {
        let next = self.records.len() + 1;
        if record.trial.trial != next {
            return Err(SessionError::Mismatch {
                file: self.csv_path.clone(),
                message: format!("trial {} given where trial {next} is next", record.trial.trial),
            });
        }
        let bytes = self.row_bytes(record);
        let path = self.csv_path.clone();
        self.appender.write_all(&bytes).map_err(io(&path))?;
        self.appender.sync_all().map_err(io(&path))?;
        self.records.push(record.clone());
        Ok(())
    }

    fn row_bytes(&self, r: &TrialRecord) -> Vec<u8> {
        let s = &self.sidecar;
        let fingers = [r.finger_baseline_c, r.finger_start_c, r.finger_end_c].map(|c| format!("{c:.4}"));
        let v1 = s.format == SIDECAR_FORMAT_V1;
        // Format 1 has only `finger_*`; format 2 puts a simulation's in `model_finger_*`.
        let (measured, model): ([String; 3], [String; 3]) = if r.finger_measured || v1 {
            (fingers, Default::default())
        } else {
            (Default::default(), fingers)
        };
        let value = |name: &str| -> String {
            match name {
                "participant" => s.participant.clone(),
                "expName" => s.experiment.clone(),
                "session_date" => s.session_date.clone(),
                "seed" => s.seed.to_string(),
                "software_version" => r.software_version.clone(),
                "trials.thisN" => (r.trial.trial - 1).to_string(),
                "trial" => r.trial.trial.to_string(),
                "block" => r.trial.block.to_string(),
                "repetition" => r.trial.repetition.to_string(),
                "condition" => r.trial.condition.name().to_string(),
                "position" => r.trial.position.to_string(),
                "presented" => r.trial.presented.clone(),
                "identified" => r.identified.clone(),
                "key_resp.keys" => r.response_key.to_string(),
                "key_resp.rt" => r.response_time_s.map(|t| format!("{t:.3}")).unwrap_or_default(),
                "presentation_s" => format!("{:.3}", r.presentation_s),
                "finger_baseline_c" => measured[0].clone(),
                "finger_start_c" => measured[1].clone(),
                "finger_end_c" => measured[2].clone(),
                "model_finger_baseline_c" => model[0].clone(),
                "model_finger_start_c" => model[1].clone(),
                "model_finger_end_c" => model[2].clone(),
                "excluded" => r.excluded.to_string(),
                "exclusion_reason" => r.exclusion_reason.clone(),
                "curve_file" => r.curve_file.clone(),
                _ => String::new(),
            }
        };
        let fields: Vec<String> = s.columns.iter().map(|c| value(canonical(c))).collect();
        let mut writer = csv::WriterBuilder::new()
            .terminator(csv::Terminator::Any(b'\n'))
            .from_writer(Vec::new());
        // Writing to memory cannot fail; the fields hold no line ends.
        let _ = writer.write_record(&fields);
        writer.into_inner().unwrap_or_default()
    }

    /// Writes trial `trial`'s curve in the session's curve folder beside its CSV, atomically
    /// (`<stem>_curves/trial-<NNN>.csv`; a trial repeated after a crash writes it anew), and returns its path
    /// relative to the data folder for the row's `curve_file`. Call it before [`SessionFile::append`], so that a
    /// row never names a file that is not there. `lab export --bids` exports the folder's curves.
    pub fn write_curve(&self, trial: usize, csv_text: &str) -> Result<String, SessionError> {
        let folder = format!("{}_curves", self.sidecar.csv_file.trim_end_matches(".csv"));
        let dir = self.csv_path.with_file_name(&folder);
        std::fs::create_dir_all(&dir).map_err(io(&dir))?;
        let name = format!("trial-{trial:03}.csv");
        write_atomically(&dir.join(&name), csv_text.as_bytes())?;
        Ok(format!("{folder}/{name}"))
    }

    /// The session CSV.
    pub fn csv_path(&self) -> &Path {
        &self.csv_path
    }

    /// The sidecar JSON.
    pub fn sidecar_path(&self) -> &Path {
        &self.sidecar_path
    }

    /// The sidecar as written.
    pub fn sidecar(&self) -> &Sidecar {
        &self.sidecar
    }

    /// The completed trials, in order.
    pub fn records(&self) -> &[TrialRecord] {
        &self.records
    }

    /// Number of planned trials.
    pub fn planned_trials(&self) -> usize {
        self.planned
    }

    /// Whether every planned trial is recorded.
    pub fn is_complete(&self) -> bool {
        self.records.len() >= self.planned
    }

    /// Whether an existing session was opened.
    pub fn resumed(&self) -> bool {
        self.resumed
    }

    /// Whether a torn last row was cut off on opening.
    pub fn removed_torn_row(&self) -> bool {
        self.removed_torn_row
    }

    /// The session's finger baseline (the first trial's start temperature), once there is a first trial.
    pub fn baseline_c(&self) -> Option<f64> {
        self.records.first().map(|r| r.finger_baseline_c)
    }
}

/// The format-2 name of a column (a format-1 name that format 2 renamed becomes PsychoPy's).
fn canonical(name: &str) -> &str {
    RENAMED.iter().find(|(_, v1)| *v1 == name).map_or(name, |(v2, _)| v2)
}

/// The index of the column whose format-2 name is `name` in `columns` (format 1 or 2).
fn column(columns: &[String], name: &str) -> usize {
    columns.iter().position(|c| canonical(c) == name).unwrap_or(usize::MAX)
}

/// Refuses a session whose sidecar records a different design.
fn check_same_design(sidecar_path: &Path, sidecar: &Sidecar, design: &Experiment) -> Result<(), SessionError> {
    let mismatch = |message: String| SessionError::Mismatch {
        file: sidecar_path.to_path_buf(),
        message,
    };
    if sidecar.format != SIDECAR_FORMAT && sidecar.format != SIDECAR_FORMAT_V1 {
        return Err(mismatch(format!(
            "sidecar format `{}`, expected `{SIDECAR_FORMAT}` or `{SIDECAR_FORMAT_V1}`",
            sidecar.format
        )));
    }
    let recorded = Experiment::from_toml_str(&sidecar.experiment_toml, sidecar_path)
        .map_err(|e| mismatch(format!("its recorded experiment file is invalid: {e}")))?;
    let differences = recorded.differences(design);
    if !differences.is_empty() {
        return Err(mismatch(format!(
            "it was recorded with a different design (recorded vs now): {}",
            differences.join("; ")
        )));
    }
    Ok(())
}

/// The existing session of `participant` in `experiment` in `data_dir`, if any: (sidecar path, sidecar).
fn find_session(
    data_dir: &Path,
    participant: &str,
    experiment: &str,
) -> Result<Option<(PathBuf, Sidecar)>, SessionError> {
    let prefix = format!("{participant}_{experiment}_");
    let mut dates: Vec<String> = Vec::new();
    for entry in std::fs::read_dir(data_dir).map_err(io(data_dir))? {
        let name = entry.map_err(io(data_dir))?.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(&prefix)) else {
            continue;
        };
        let date = rest.strip_suffix(".csv").or_else(|| rest.strip_suffix(".json"));
        if let Some(date) = date.filter(|d| parse_iso_date(d).is_some()) {
            if !dates.iter().any(|d| d == date) {
                dates.push(date.to_string());
            }
        }
    }
    dates.sort();
    let mut found = Vec::new();
    for date in dates {
        let stem = session_stem(participant, experiment, &date);
        let sidecar_path = data_dir.join(format!("{stem}.json"));
        if !sidecar_path.exists() {
            return Err(SessionError::MissingSidecar {
                csv: data_dir.join(format!("{stem}.csv")),
                sidecar: sidecar_path,
            });
        }
        let sidecar = read_sidecar(&sidecar_path)?;
        if sidecar.participant == participant && sidecar.experiment == experiment {
            if sidecar.session_date != date || sidecar.csv_file != format!("{stem}.csv") {
                return Err(SessionError::Mismatch {
                    file: sidecar_path,
                    message: format!("its session date or CSV name does not match its file name {stem}"),
                });
            }
            found.push((sidecar_path, sidecar));
        }
    }
    if found.len() > 1 {
        let files = found.iter().map(|(p, s)| p.with_file_name(&s.csv_file)).collect();
        return Err(SessionError::Ambiguous { files });
    }
    Ok(found.pop())
}

fn read_sidecar(path: &Path) -> Result<Sidecar, SessionError> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    serde_json::from_str(&text).map_err(|e| SessionError::Sidecar {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

fn write_sidecar(path: &Path, sidecar: &Sidecar) -> Result<(), SessionError> {
    let text = serde_json::to_string_pretty(sidecar).map_err(|e| SessionError::Sidecar {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    write_atomically(path, format!("{text}\n").as_bytes())
}

/// Writes `bytes` to `path` atomically (`thermode_platform::write_bytes_atomically`).
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), SessionError> {
    write_bytes_atomically(path, bytes).map_err(io(path))
}

fn truncate(path: &Path, len: u64) -> Result<(), SessionError> {
    let file = OpenOptions::new().write(true).open(path).map_err(io(path))?;
    file.set_len(len).map_err(io(path))?;
    file.sync_all().map_err(io(path))
}
