//! Experiment designs: the TOML file that describes a material-identification study (the paper's section 4.2).
//!
//! ```toml
//! name = "paper"                      # [A-Za-z0-9_-]+, used in session file names (required)
//! materials = ["aluminium", "steel"]  # library names, at least 2, no duplicates (required)
//! conditions = ["real", "simulated"]  # default both; the first listed gets the extra participant
//! participants = 15                   # count, 1..=10000 (required)
//! participant_ids = ["P01", "P02"]    # optional; default P01, P02, … (zero-padded to the count's width)
//! repetitions = 2                     # blocks of every material per condition, 1..=1000 (default 1)
//! presentation_s = 30.0               # seconds of contact before the answer, (0, 3600] (default 30)
//! response_options = ["steel", "aluminium"]  # default: the materials; must be the same set (order = key order)
//! exclusion_max_drift_c = 1.0         # °C a trial's finger start may differ from the session start (default 1)
//! seed = 42                           # 0..=2^63-1, seeds every random choice of the plan (required)
//! ```
//!
//! Material names are resolved with `thermode_model::materials::find` (any case, aliases such as `aluminum`) and
//! stored under their library names. The response options must be exactly the materials (in any order): the
//! analysis takes the presented materials as the options and the chance level as one over their number, so an option
//! that is never presented would make the data inconsistent with it. Unknown keys, wrong types, out-of-range
//! numbers, duplicate names and unknown materials are errors naming the file and the key. The file is read with
//! [`thermode_model::params::Table`], the reader of every parameter file.

use std::path::{Path, PathBuf};

use serde::Serialize;

use thermode_model::limits;
use thermode_model::materials::find;
use thermode_model::params::{self, Rule, Table};
use thermode_model::ParamError;
use thermode_platform::fs::{read_text_at_most, MAX_SETTINGS_BYTES};
use thiserror::Error;

/// Why an experiment file was refused. Every variant names the file.
#[derive(Debug, Error)]
pub enum DesignError {
    /// The file could not be read.
    #[error("{}: {error}", file.display())]
    Io {
        /// The experiment file.
        file: PathBuf,
        /// The operating-system error (part of the message, so not chained as a source).
        error: std::io::Error,
    },
    /// The text is not valid TOML, or a key is unknown, missing, of the wrong type or out of range (the error names
    /// the file and the key).
    #[error(transparent)]
    Param(#[from] ParamError),
}

/// Default presentation time \[s\] (the paper: "after 30 seconds of presentation").
pub const DEFAULT_PRESENTATION_S: f64 = 30.0;
/// Default exclusion threshold \[°C\] (the paper discarded data sets that differed by more than 1 °C).
pub const DEFAULT_EXCLUSION_MAX_DRIFT_C: f64 = 1.0;
/// Largest number of participants accepted.
pub const MAX_PARTICIPANTS: usize = 10_000;
/// Largest number of repetitions accepted.
pub const MAX_REPETITIONS: usize = 1_000;
/// Longest presentation accepted \[s\]: the top of the physical range of durations
/// ([`thermode_model::limits::DURATION`], one hour).
pub const MAX_PRESENTATION_S: f64 = limits::DURATION.max;

/// A validated experiment design.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiment {
    /// Name of the experiment, `[A-Za-z0-9_-]+`; part of every session file name.
    pub name: String,
    /// The presented materials as library names, in the file's order (≥ 2, distinct).
    pub materials: Vec<String>,
    /// The conditions, in the file's order (distinct; default real, simulated).
    pub conditions: Vec<Condition>,
    /// Participant identifiers, one per participant (default `P01`, `P02`, …).
    pub participant_ids: Vec<String>,
    /// Number of blocks of every material per condition and participant (default 1).
    pub repetitions: usize,
    /// Presentation time before the answer \[s\] (default 30).
    pub presentation_s: f64,
    /// The response options as library names, in the order of the answer keys 1..n (default: the materials).
    pub response_options: Vec<String>,
    /// Largest allowed difference between a trial's finger start temperature and the session's first one \[°C\]
    /// (default 1).
    pub exclusion_max_drift_c: f64,
    /// Seed of every random choice of the plan.
    pub seed: u64,
}

/// An experiment file as read: where it came from, its exact text and the design.
#[derive(Debug, Clone, PartialEq)]
pub struct ExperimentFile {
    /// The file.
    pub path: PathBuf,
    /// Its text, unchanged (recorded in every session's sidecar).
    pub text: String,
    /// The validated design.
    pub experiment: Experiment,
}

impl ExperimentFile {
    /// Reads and validates the experiment file at `path`.
    pub fn load(path: &Path) -> Result<ExperimentFile, DesignError> {
        let text = read_text_at_most(path, MAX_SETTINGS_BYTES).map_err(|error| DesignError::Io {
            file: path.to_path_buf(),
            error,
        })?;
        let experiment = Experiment::from_toml_str(&text, path)?;
        Ok(ExperimentFile {
            path: path.to_path_buf(),
            text,
            experiment,
        })
    }
}

impl Experiment {
    /// Parses and validates an experiment file's text; `file` names it in errors.
    pub fn from_toml_str(text: &str, file: &Path) -> Result<Experiment, DesignError> {
        let origin = file.display().to_string();
        let toml = params::parse(text, &origin)?;
        let keys = Table::new(&toml, &origin);
        let name = name(&keys)?;
        let materials = material_names(&keys, "materials")?.ok_or_else(|| keys.missing("materials"))?;
        if materials.len() < 2 {
            return Err(keys.invalid("materials", "needs at least 2 materials").into());
        }
        let participants = keys
            .count("participants", 1, MAX_PARTICIPANTS)?
            .ok_or_else(|| keys.missing("participants"))?;
        let response_options = match material_names(&keys, "response_options")? {
            Some(options) => check_options(&keys, options, &materials)?,
            None => materials.clone(),
        };
        let experiment = Experiment {
            name,
            conditions: conditions(&keys)?,
            participant_ids: participant_ids(&keys, participants)?,
            repetitions: keys.count("repetitions", 1, MAX_REPETITIONS)?.unwrap_or(1),
            presentation_s: positive_at_most(&keys, "presentation_s", MAX_PRESENTATION_S)?
                .unwrap_or(DEFAULT_PRESENTATION_S),
            exclusion_max_drift_c: positive_at_most(&keys, "exclusion_max_drift_c", f64::MAX)?
                .unwrap_or(DEFAULT_EXCLUSION_MAX_DRIFT_C),
            seed: seed(&keys)?,
            response_options,
            materials,
        };
        keys.finish()?;
        Ok(experiment)
    }

    /// Number of participants.
    pub fn participants(&self) -> usize {
        self.participant_ids.len()
    }

    /// Number of trials of every participant: conditions × repetitions × materials.
    pub fn trials_per_participant(&self) -> usize {
        self.conditions.len() * self.repetitions * self.materials.len()
    }

    /// Index of a participant identifier in [`Experiment::participant_ids`].
    pub fn participant_index(&self, id: &str) -> Option<usize> {
        self.participant_ids.iter().position(|p| p == id)
    }

    /// The keys whose values differ between `self` and `other`, as `key: self vs other` lines (empty if equal).
    pub fn differences(&self, other: &Experiment) -> Vec<String> {
        let mut out = Vec::new();
        let mut compare = |key: &str, a: String, b: String| {
            if a != b {
                out.push(format!("{key}: {a} vs {b}"));
            }
        };
        compare("name", self.name.clone(), other.name.clone());
        compare("materials", self.materials.join(","), other.materials.join(","));
        let conditions = |e: &Experiment| e.conditions.iter().map(|c| c.name()).collect::<Vec<_>>().join(",");
        compare("conditions", conditions(self), conditions(other));
        compare(
            "participant_ids",
            self.participant_ids.join(","),
            other.participant_ids.join(","),
        );
        compare(
            "repetitions",
            self.repetitions.to_string(),
            other.repetitions.to_string(),
        );
        compare(
            "presentation_s",
            self.presentation_s.to_string(),
            other.presentation_s.to_string(),
        );
        compare(
            "response_options",
            self.response_options.join(","),
            other.response_options.join(","),
        );
        compare(
            "exclusion_max_drift_c",
            self.exclusion_max_drift_c.to_string(),
            other.exclusion_max_drift_c.to_string(),
        );
        compare("seed", self.seed.to_string(), other.seed.to_string());
        out
    }
}

/// Checks that an identifier is non-empty, at most 64 characters, and only `[A-Za-z0-9_-]`.
pub fn is_valid_identifier(id: &str) -> bool {
    !id.is_empty() && id.len() <= 64 && id.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
}

/// The response options must be the materials, each once.
fn check_options(keys: &Table, options: Vec<String>, materials: &[String]) -> Result<Vec<String>, ParamError> {
    let mut a = options.clone();
    let mut b = materials.to_vec();
    a.sort();
    b.sort();
    if a != b {
        return Err(keys.invalid(
            "response_options",
            format!(
                "must list exactly the materials ({}) in any order: the analysis takes the presented materials \
                 as the response options",
                materials.join(", ")
            ),
        ));
    }
    Ok(options)
}

/// An array of distinct strings.
fn distinct_strings(keys: &Table, key: &str) -> Result<Option<Vec<String>>, ParamError> {
    let Some(strings) = keys.strings(key)? else {
        return Ok(None);
    };
    if let Some(dup) = first_duplicate(&strings) {
        return Err(keys.invalid(key, format!("`{dup}` appears more than once")));
    }
    Ok(Some(strings))
}

fn name(keys: &Table) -> Result<String, ParamError> {
    let name = keys.required_string("name")?;
    if !is_valid_identifier(&name) {
        return Err(keys.invalid(
            "name",
            format!("{name:?} must be 1 to 64 characters from A-Z, a-z, 0-9, `_` and `-` (it names files)"),
        ));
    }
    Ok(name)
}

/// A list of material names resolved to library names.
fn material_names(keys: &Table, key: &str) -> Result<Option<Vec<String>>, ParamError> {
    let Some(names) = distinct_strings(keys, key)? else {
        return Ok(None);
    };
    let resolved: Vec<String> = names
        .iter()
        .map(|n| find(n).map(|m| m.name).map_err(|e| keys.invalid(key, e)))
        .collect::<Result<_, _>>()?;
    if let Some(dup) = first_duplicate(&resolved) {
        return Err(keys.invalid(key, format!("`{dup}` appears more than once (after resolving aliases)")));
    }
    Ok(Some(resolved))
}

fn conditions(keys: &Table) -> Result<Vec<Condition>, ParamError> {
    let Some(names) = distinct_strings(keys, "conditions")? else {
        return Ok(Condition::ALL.to_vec());
    };
    if names.is_empty() {
        return Err(keys.invalid("conditions", "needs at least one of `real`, `simulated`"));
    }
    let parsed: Vec<Condition> = names
        .iter()
        .map(|n| {
            Condition::parse(n)
                .ok_or_else(|| keys.invalid("conditions", format!("`{n}` is neither `real` nor `simulated`")))
        })
        .collect::<Result<_, _>>()?;
    if parsed.len() == 2 && parsed[0] == parsed[1] {
        return Err(keys.invalid("conditions", "a condition appears more than once"));
    }
    Ok(parsed)
}

/// A finite number in (0, max]; integers are accepted.
fn positive_at_most(keys: &Table, key: &str, max: f64) -> Result<Option<f64>, ParamError> {
    let Some(value) = keys.number(key, Rule::Positive)? else {
        return Ok(None);
    };
    let rule = Rule::Within { min: 0.0, max };
    if rule.admits(value) {
        Ok(Some(value))
    } else {
        Err(keys.bad(key, value, rule))
    }
}

fn seed(keys: &Table) -> Result<u64, ParamError> {
    let seed = keys.integer("seed")?.ok_or_else(|| keys.missing("seed"))?;
    u64::try_from(seed).map_err(|_| keys.bad("seed", seed as f64, Rule::NonNegative))
}

fn participant_ids(keys: &Table, participants: usize) -> Result<Vec<String>, ParamError> {
    let Some(ids) = distinct_strings(keys, "participant_ids")? else {
        let width = participants.to_string().len().max(2);
        return Ok((1..=participants).map(|i| format!("P{i:0width$}")).collect());
    };
    if ids.len() != participants {
        return Err(keys.invalid(
            "participant_ids",
            format!("has {} identifiers for {participants} participants", ids.len()),
        ));
    }
    if let Some(bad) = ids.iter().find(|id| !is_valid_identifier(id)) {
        return Err(keys.invalid(
            "participant_ids",
            format!("{bad:?} must be 1 to 64 characters from A-Z, a-z, 0-9, `_` and `-`"),
        ));
    }
    Ok(ids)
}

fn first_duplicate(items: &[String]) -> Option<&String> {
    items
        .iter()
        .enumerate()
        .find(|(i, s)| items[..*i].contains(s))
        .map(|(_, s)| s)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = "name = \"t\"\nmaterials = [\"aluminium\", \"wood\"]\nparticipants = 3\nseed = 7\n";

    fn parse(text: &str) -> Result<Experiment, DesignError> {
        Experiment::from_toml_str(text, Path::new("exp.toml"))
    }

    fn error(text: &str) -> String {
        match parse(text) {
            Ok(e) => panic!("accepted {e:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn defaults_fill_the_optional_keys() {
        let e = parse(MINIMAL).expect("valid");
        assert_eq!(e.conditions, vec![Condition::Real, Condition::Simulated]);
        assert_eq!(e.participant_ids, vec!["P01", "P02", "P03"]);
        assert_eq!(e.repetitions, 1);
        assert_eq!(e.presentation_s, 30.0);
        assert_eq!(e.response_options, e.materials);
        assert_eq!(e.exclusion_max_drift_c, 1.0);
        assert_eq!(e.trials_per_participant(), 4);
    }

    #[test]
    fn aliases_resolve_to_library_names() {
        let e = parse(&MINIMAL.replace("\"aluminium\"", "\"Aluminum\"")).expect("valid");
        assert_eq!(e.materials, vec!["aluminium", "wood"]);
    }

    #[test]
    fn errors_name_the_file_and_key() {
        let cases = [
            (format!("{MINIMAL}colour = 1\n"), "unknown key `colour`"),
            (MINIMAL.replace("seed = 7\n", ""), "missing key `seed`"),
            (MINIMAL.replace("seed = 7", "seed = -1"), "`seed`"),
            (
                MINIMAL.replace("participants = 3", "participants = 0"),
                "`participants`",
            ),
            (
                MINIMAL.replace("participants = 3", "participants = \"3\""),
                "`participants`",
            ),
            (
                MINIMAL.replace("\"wood\"", "\"unobtainium\""),
                "`materials`: unknown material",
            ),
            (MINIMAL.replace("\"wood\"", "\"aluminum\""), "more than once"),
            (MINIMAL.replace("\"t\"", "\"a b\""), "`name`"),
            (format!("{MINIMAL}presentation_s = nan\n"), "`presentation_s`"),
            (format!("{MINIMAL}presentation_s = -3\n"), "`presentation_s`"),
            (
                format!("{MINIMAL}exclusion_max_drift_c = inf\n"),
                "`exclusion_max_drift_c`",
            ),
            (format!("{MINIMAL}conditions = [\"real\", \"fake\"]\n"), "`fake`"),
            (
                format!("{MINIMAL}conditions = [\"real\", \"Real\"]\n"),
                "more than once",
            ),
            (format!("{MINIMAL}conditions = []\n"), "`conditions`"),
            (
                format!("{MINIMAL}response_options = [\"wood\"]\n"),
                "`response_options`",
            ),
            (
                format!("{MINIMAL}participant_ids = [\"a\", \"b\"]\n"),
                "`participant_ids`",
            ),
            (
                format!("{MINIMAL}participant_ids = [\"a\", \"b\", \"c d\"]\n"),
                "`participant_ids`",
            ),
            ("name = \n".to_string(), "invalid TOML"),
        ];
        for (text, want) in cases {
            let got = error(&text);
            assert!(got.starts_with("exp.toml:"), "no file in {got:?}");
            assert!(got.contains(want), "{got:?} does not contain {want:?}");
        }
    }

    #[test]
    fn differences_name_the_keys() {
        let a = parse(MINIMAL).expect("valid");
        let b = parse(&MINIMAL.replace("seed = 7", "seed = 8")).expect("valid");
        assert!(a.differences(&a).is_empty());
        assert_eq!(a.differences(&b), vec!["seed: 7 vs 8"]);
    }

    #[test]
    fn identifiers() {
        assert!(is_valid_identifier("P-01_a"));
        assert!(!is_valid_identifier(""));
        assert!(!is_valid_identifier("a/b"));
        assert!(!is_valid_identifier("é"));
        assert!(!is_valid_identifier(&"x".repeat(65)));
    }
}

/// The two conditions of the paper's experiment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Condition {
    /// A real sample was touched.
    Real,
    /// The material was rendered by the thermal display.
    Simulated,
}

impl Condition {
    /// Both conditions, real first.
    pub const ALL: [Condition; 2] = [Condition::Real, Condition::Simulated];

    /// Parses `real` / `simulated` (trimmed, any case).
    pub fn parse(text: &str) -> Option<Condition> {
        match text.trim().to_ascii_lowercase().as_str() {
            "real" => Some(Condition::Real),
            "simulated" => Some(Condition::Simulated),
            _ => None,
        }
    }

    /// `real` or `simulated`.
    pub fn name(self) -> &'static str {
        match self {
            Condition::Real => "real",
            Condition::Simulated => "simulated",
        }
    }
}
