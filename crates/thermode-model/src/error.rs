//! Typed errors for parameters: material, skin, device and experiment files, refused numbers (the one
//! [`BadValue`] with the file it came from), unknown names.

use thiserror::Error;

use crate::params::BadValue;

/// Why a set of parameters was refused. Every variant names what was wrong and where it came from (`origin` is the
/// file name, or `"built-in"`/`"command line"`), so the message can be shown to a user as it is.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ParamError {
    /// The text is not valid TOML.
    #[error("{origin}: invalid TOML: {message}")]
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
    /// A number that breaks its [`Rule`](crate::params::Rule): the one [`BadValue`], with where it came from.
    #[error("{origin}: {source}")]
    BadValue {
        /// Where the parameters came from (file name, `"built-in"`, `"command line"`).
        origin: String,
        /// The refused number: its key (with the section path), value and rule.
        source: BadValue,
    },
    /// A structural problem (wrong number of layers, empty name, …).
    #[error("{origin}: {message}")]
    Invalid {
        /// Where the parameters came from (file name, `"built-in"`, `"command line"`).
        origin: String,
        /// What was wrong.
        message: String,
    },
    /// A computation from accepted inputs gave a number that is not finite (NaN or ±∞): the result is refused,
    /// never written.
    #[error("{origin}: the result is not finite: `{quantity}` = {value} at t = {time_s} s")]
    NonFinite {
        /// What computed it (`"simulation"`, …).
        origin: String,
        /// The quantity (a column name, with its unit).
        quantity: String,
        /// The non-finite value.
        value: f64,
        /// When \[s\].
        time_s: f64,
    },
    /// Work whose results would not fit in the memory thermode allows one command
    /// ([`crate::limits::MAX_RESULT_BYTES`]); refused before anything is allocated.
    #[error("{origin}: {message}")]
    TooLarge {
        /// What was asked for (`"simulation"`, …).
        origin: String,
        /// The estimate, the limit and how to make the work smaller.
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

impl ParamError {
    /// A [`ParamError::BadValue`]: `source` refused, from `origin`.
    pub fn bad_value(origin: &str, source: BadValue) -> Self {
        ParamError::BadValue {
            origin: origin.to_string(),
            source,
        }
    }

    /// The key (or description) of a refused number, if this is a [`ParamError::BadValue`].
    pub fn bad_key(&self) -> Option<&str> {
        match self {
            ParamError::BadValue { source, .. } => Some(&source.name),
            _ => None,
        }
    }
}

/// Attaches where a refused number came from: `Rule::Positive.check("dt_s", dt).at(origin)?`.
pub trait At<T> {
    /// The result with a [`BadValue`] turned into a [`ParamError::BadValue`] from `origin`.
    fn at(self, origin: &str) -> Result<T, ParamError>;
}

impl<T> At<T> for Result<T, BadValue> {
    fn at(self, origin: &str) -> Result<T, ParamError> {
        self.map_err(|source| ParamError::bad_value(origin, source))
    }
}
