//! The procedures' typed error: a configuration that cannot run, or a response given out of turn.

use thiserror::Error;

/// Why a procedure, a participant, an experiment file or an analysis was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ProcedureError {
    /// A parameter is outside its range; the message names the key, the value and the range.
    #[error("{key} = {value}: {expected}")]
    BadValue {
        /// The parameter's key as written in an experiment file (e.g. `limits.rate_c_s`).
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
    /// A [`ProcedureError::BadValue`] for `key` = `value`, which must be `expected`.
    pub fn bad(key: &str, value: impl std::fmt::Display, expected: &str) -> Self {
        ProcedureError::BadValue {
            key: key.to_string(),
            value: value.to_string(),
            expected: expected.to_string(),
        }
    }
}

/// Checks that `value` is finite and within `[min, max]`; the error names `key` and the range.
pub fn check_range(key: &str, value: f64, min: f64, max: f64) -> Result<f64, ProcedureError> {
    if value.is_finite() && value >= min && value <= max {
        Ok(value)
    } else {
        Err(ProcedureError::bad(
            key,
            value,
            &format!("a number from {min} to {max}"),
        ))
    }
}

/// Checks that `value` is finite and strictly positive, at most `max`.
pub fn check_positive(key: &str, value: f64, max: f64) -> Result<f64, ProcedureError> {
    if value.is_finite() && value > 0.0 && value <= max {
        Ok(value)
    } else {
        Err(ProcedureError::bad(
            key,
            value,
            &format!("a number above 0, at most {max}"),
        ))
    }
}
