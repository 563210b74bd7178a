//! Experiment files of the procedures (TOML, the family of `crates/thermode-lab/experiments/paper.toml`): a `name`,
//! the `procedure` (`limits`, `levels`, `staircase`, `questplus` or `program`), its table, the `[stimulus]` of the
//! yes/no procedures, a `seed`, and the optional `[simulated_participant]`.

use serde::{Deserialize, Serialize};
use thermode_model::params::Rule;

use crate::levels::{Levels, LevelsConfig};
use crate::limits::{LimitsConfig, LimitsProcedure};
use crate::participant::ParticipantConfig;
use crate::plan::Procedure;
use crate::program::ProgramConfig;
use crate::questplus::{QuestPlusConfig, QuestPlusProcedure};
use crate::staircase::{Staircase, StaircaseConfig};
use crate::stimulus::StimulusConfig;
use crate::ProcedureError;

/// Which procedure an experiment runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProcedureKind {
    /// The method of limits (`[limits]`).
    Limits,
    /// The method of levels (`[levels]`, `[stimulus]`).
    Levels,
    /// A PsychoPy-compatible staircase (`[staircase]`, `[stimulus]`).
    Staircase,
    /// QUEST+ (`[questplus]`, `[stimulus]`).
    Questplus,
    /// A multi-zone program (`[program]`).
    Program,
}

impl ProcedureKind {
    /// The name an experiment file gives it (`limits`, `levels`, `staircase`, `questplus`, `program`).
    pub fn name(self) -> &'static str {
        match self {
            ProcedureKind::Limits => "limits",
            ProcedureKind::Levels => "levels",
            ProcedureKind::Staircase => "staircase",
            ProcedureKind::Questplus => "questplus",
            ProcedureKind::Program => "program",
        }
    }
}

/// An experiment file of a procedure: one with a `procedure` key (the identification design of `thermode-lab` has
/// none; [`ProcedureFile::declares_procedure`] tells them apart).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProcedureFile {
    /// The experiment's name.
    pub name: String,
    /// The procedure.
    pub procedure: ProcedureKind,
    /// Participants planned (`P01`, `P02`, …). Default 1.
    #[serde(default = "default_participants")]
    pub participants: usize,
    /// The seed of the simulated participants' random streams. Default 0.
    #[serde(default)]
    pub seed: u64,
    /// The pause at the baseline before the first trial (and before a trial whose baseline the plate is not at),
    /// while the finger adapts \[s\]. Default 10.
    #[serde(default = "default_adaptation_s")]
    pub adaptation_s: f64,
    /// The method of limits' table.
    pub limits: Option<LimitsConfig>,
    /// The method of levels' table.
    pub levels: Option<LevelsConfig>,
    /// The staircase's table.
    pub staircase: Option<StaircaseConfig>,
    /// QUEST+'s table.
    pub questplus: Option<QuestPlusConfig>,
    /// The multi-zone program's table.
    pub program: Option<ProgramConfig>,
    /// The yes/no procedures' stimulus; default [`StimulusConfig::default`].
    pub stimulus: Option<StimulusConfig>,
    /// The simulated participant (`--simulated-participant`); default [`ParticipantConfig::default`].
    pub simulated_participant: Option<ParticipantConfig>,
}

fn default_participants() -> usize {
    1
}

fn default_adaptation_s() -> f64 {
    10.0
}

fn missing(procedure: &str, table: &str) -> ProcedureError {
    ProcedureError::MissingTable {
        procedure: procedure.to_string(),
        table: table.to_string(),
    }
}

impl ProcedureFile {
    /// Whether a TOML text has a top-level `procedure` key (so it is a procedure file, not an identification
    /// design). A text that is not TOML has none.
    pub fn declares_procedure(text: &str) -> bool {
        toml::from_str::<toml::Table>(text).is_ok_and(|t| t.contains_key("procedure"))
    }

    /// Parses and validates an experiment file's text.
    pub fn from_toml_str(text: &str) -> Result<Self, ProcedureError> {
        let file: ProcedureFile = toml::from_str(text).map_err(|e| ProcedureError::Parse(e.to_string()))?;
        file.validate()?;
        Ok(file)
    }

    /// Checks that the procedure's table is present and every table valid (building the procedure once).
    pub fn validate(&self) -> Result<(), ProcedureError> {
        Rule::Within {
            min: 1.0,
            max: 10_000.0,
        }
        .check("participants", self.participants as f64)?;
        Rule::Within { min: 0.0, max: 600.0 }.check("adaptation_s", self.adaptation_s)?;
        if let Some(p) = &self.simulated_participant {
            p.validate()?;
        }
        match self.procedure {
            ProcedureKind::Program => self
                .program
                .as_ref()
                .ok_or_else(|| missing("program", "program"))?
                .validate(),
            _ => self.build().map(drop),
        }
    }

    /// The yes/no procedures' stimulus (the default when the file has none).
    pub fn stimulus(&self) -> StimulusConfig {
        self.stimulus.unwrap_or_default()
    }

    /// The simulated participant (the default when the file has none).
    pub fn participant(&self) -> ParticipantConfig {
        self.simulated_participant.unwrap_or_default()
    }

    /// A fresh state machine of the single-channel procedure (`None` for a multi-zone program: see
    /// [`ProgramConfig::trials`]).
    pub fn procedure(&self) -> Result<Option<Box<dyn Procedure + Send>>, ProcedureError> {
        match self.procedure {
            ProcedureKind::Program => Ok(None),
            _ => self.build().map(Some),
        }
    }

    fn build(&self) -> Result<Box<dyn Procedure + Send>, ProcedureError> {
        let stimulus = self.stimulus();
        Ok(match self.procedure {
            ProcedureKind::Limits => Box::new(LimitsProcedure::new(
                self.limits.clone().ok_or_else(|| missing("limits", "limits"))?,
            )?),
            ProcedureKind::Levels => Box::new(Levels::new(
                self.levels.ok_or_else(|| missing("levels", "levels"))?,
                stimulus,
            )?),
            ProcedureKind::Staircase => Box::new(Staircase::new(
                self.staircase
                    .clone()
                    .ok_or_else(|| missing("staircase", "staircase"))?,
                stimulus,
            )?),
            ProcedureKind::Questplus => Box::new(QuestPlusProcedure::new(
                self.questplus
                    .as_ref()
                    .ok_or_else(|| missing("questplus", "questplus"))?,
                stimulus,
            )?),
            ProcedureKind::Program => return Err(missing("program", "a single-channel procedure")),
        })
    }
}
