//! The procedures' typed error: a configuration that cannot run, or a response given out of turn.

use thermode_model::params::BadValue;
use thiserror::Error;

/// Why a procedure, a participant, an experiment file or an analysis was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ProcedureError {
    /// A number outside its range; the message names the key (as written in an experiment file, e.g.
    /// `limits.rate_c_s`), the value and the rule.
    #[error(transparent)]
    BadValue(#[from] BadValue),
    /// A setting that is not a number (a list, a name, a combination of keys) and is not what it must be.
    #[error("{key} = {value}: {expected}")]
    Invalid {
        /// The setting's key as written in an experiment file (e.g. `limits.tests`).
        key: String,
        /// The value given, as text.
        value: String,
        /// What the value must be.
        expected: String,
    },
    /// A response was recorded while no trial was pending (`record` before `next_trial`, or twice).
    #[error("a response was recorded but no trial is pending")]
    NoTrialPending,
    /// The experiment file could not be parsed.
    #[error("experiment file: {0}")]
    Parse(String),
    /// The experiment file names a procedure but lacks its table.
    #[error("experiment file: procedure `{procedure}` needs a [{table}] table")]
    MissingTable {
        /// The procedure named by `procedure`.
        procedure: String,
        /// The table it needs.
        table: String,
    },
    /// The reference table could not be read (line numbers are 1-based, the header is line 1).
    #[error("reference table, line {line}: {message}")]
    Reference {
        /// 1-based line of the problem.
        line: u64,
        /// What is wrong.
        message: String,
    },
    /// The skin model refused its parameters.
    #[error("skin model: {0}")]
    Skin(String),
}

impl ProcedureError {
    /// A [`ProcedureError::Invalid`] for `key` = `value`, which must be `expected`.
    pub fn invalid(key: &str, value: impl std::fmt::Display, expected: &str) -> Self {
        ProcedureError::Invalid {
            key: key.to_string(),
            value: value.to_string(),
            expected: expected.to_string(),
        }
    }
}
