//! Typed errors for parameters: material and skin files, physical values out of range, unknown names.

use thiserror::Error;

/// Why a set of parameters was refused. Every variant names what was wrong and where it came from (`origin` is the
/// file name, or `"built-in"`/`"command line"`), so the message can be shown to a user as it is.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ParamError {
    /// The text is not valid TOML, or a value has the wrong type.
    #[error("{origin}: {message}")]
    Syntax {
        /// Where the parameters came from (file name, `"built-in"`, `"command line"`).
        origin: String,
        /// What was wrong.
        message: String,
    },
    /// A key that the file format does not know.
    #[error("{origin}: unknown key `{key}`")]
    UnknownKey {
        /// Where the parameters came from (file name, `"built-in"`, `"command line"`).
        origin: String,
        /// The key.
        key: String,
    },
    /// A required key is absent.
    #[error("{origin}: missing key `{key}`")]
    MissingKey {
        /// Where the parameters came from (file name, `"built-in"`, `"command line"`).
        origin: String,
        /// The key.
        key: String,
    },
    /// Both the SI and the cgs spelling of one quantity were given.
    #[error("{origin}: both `{si_key}` and `{cgs_key}` given; give exactly one")]
    BothSpellings {
        /// Where the parameters came from (file name, `"built-in"`, `"command line"`).
        origin: String,
        /// The SI spelling given.
        si_key: String,
        /// The cgs spelling given.
        cgs_key: String,
    },
    /// A key holds a value of the wrong type (a string where a number belongs, …).
    #[error("{origin}: `{key}` must be {expected}, found {found}")]
    WrongType {
        /// Where the parameters came from (file name, `"built-in"`, `"command line"`).
        origin: String,
        /// The key.
        key: String,
        /// The type the key needs.
        expected: String,
        /// The type found.
        found: String,
    },
    /// A number that must be finite and inside a range is not.
    #[error("{origin}: `{key}` = {value} is invalid: {requirement}")]
    BadValue {
        /// Where the parameters came from (file name, `"built-in"`, `"command line"`).
        origin: String,
        /// The key.
        key: String,
        /// The offending value.
        value: f64,
        /// What the value must satisfy.
        requirement: String,
    },
    /// A structural problem (wrong number of layers, empty name, …).
    #[error("{origin}: {message}")]
    Invalid {
        /// Where the parameters came from (file name, `"built-in"`, `"command line"`).
        origin: String,
        /// What was wrong.
        message: String,
    },
    /// A material name that is not in the library; `close` lists the nearest known names.
    #[error("unknown material `{name}`{}", suggest(close))]
    UnknownMaterial {
        /// The name asked for.
        name: String,
        /// The nearest known names.
        close: Vec<String>,
    },
}

fn suggest(close: &[String]) -> String {
    if close.is_empty() {
        String::new()
    } else {
        format!("; did you mean {}?", close.join(", "))
    }
}

/// Checks that `value` is finite and strictly positive.
pub fn require_positive(origin: &str, key: &str, value: f64) -> Result<f64, ParamError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(ParamError::BadValue {
            origin: origin.to_string(),
            key: key.to_string(),
            value,
            requirement: "must be a finite number greater than zero".to_string(),
        })
    }
}

/// Checks that `value` is finite and not negative.
pub fn require_non_negative(origin: &str, key: &str, value: f64) -> Result<f64, ParamError> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(ParamError::BadValue {
            origin: origin.to_string(),
            key: key.to_string(),
            value,
            requirement: "must be a finite number not below zero".to_string(),
        })
    }
}

/// Checks that `value` is finite (any sign).
pub fn require_finite(origin: &str, key: &str, value: f64) -> Result<f64, ParamError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ParamError::BadValue {
            origin: origin.to_string(),
            key: key.to_string(),
            value,
            requirement: "must be a finite number".to_string(),
        })
    }
}
