//! The one parameter vocabulary of thermode: what a number must satisfy ([`Rule`], [`Range`]) and the one error for
//! a refused number ([`BadValue`]). Every crate checks its numbers with these (skin, material, device, envelope,
//! controller, pipeline, run, experiment and API inputs), so a refused number reads the same everywhere: what it is
//! (with its unit), the value, and the rule it breaks. Parameter files (skin, material, device, gains, experiment)
//! are read with the one TOML reader, [`Table`], whose getters apply a [`Rule`] to every number.
//!
//! Nothing here allocates when the name is a `&'static str`, so checks may run on the per-tick path.

use std::borrow::Cow;
use std::fmt;

use thiserror::Error;

use crate::numbers::Significant;

mod table;

pub use table::{parse, Spellings, Table, CONDUCTIVITY, DENSITY, SPECIFIC_HEAT};

/// What a number must satisfy. Every rule requires a finite number (NaN and ±∞ are always refused).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rule {
    /// Any finite number.
    Finite,
    /// A finite number greater than zero.
    Positive,
    /// A finite number not below zero.
    NonNegative,
    /// A finite number not below `min` (a count of at least one, a size of at least a kibibyte).
    AtLeast {
        /// Smallest allowed value.
        min: f64,
    },
    /// A finite number in `[min, max]` (both inclusive).
    Within {
        /// Smallest allowed value.
        min: f64,
        /// Largest allowed value.
        max: f64,
    },
    /// A finite number above zero and not above `max` (a rate of at most 300 °C/s, a hold of at most an hour).
    PositiveUpTo {
        /// Largest allowed value.
        max: f64,
    },
    /// A requirement the other rules cannot say, in words (`"must last at least one tick"`); checked by the caller.
    Custom(&'static str),
    /// A finite number strictly between `min` and `max` (both excluded).
    Between {
        /// The value must be greater than this.
        min: f64,
        /// The value must be smaller than this.
        max: f64,
    },
    /// A finite number not above another quantity's value (`drive.current_limit_a` at most the module's I_max).
    AtMost {
        /// The largest allowed value.
        max: f64,
        /// What the bound is, with its unit (`"the module's I_max [A]"`).
        what: &'static str,
    },
    /// A finite number below another quantity's value (ΔT_max below the hot-side temperature).
    Below {
        /// The value must be smaller than this.
        max: f64,
        /// What the bound is, with its unit (`"the hot-side temperature [K]"`).
        what: &'static str,
    },
    /// A finite number within a relative tolerance of another quantity's value: |value − target| ≤ relative·|target|.
    Near {
        /// The value the number should be close to.
        target: f64,
        /// The allowed relative difference (0.3 = 30 %).
        relative: f64,
        /// What the target is, with its unit (`"the Q_max that I_max, V_max and ΔT_max imply [W]"`).
        what: &'static str,
    },
}

impl Rule {
    /// Whether `value` satisfies the rule (a [`Rule::Custom`] only checks finiteness).
    pub fn admits(self, value: f64) -> bool {
        value.is_finite()
            && match self {
                Rule::Finite | Rule::Custom(_) => true,
                Rule::Positive => value > 0.0,
                Rule::NonNegative => value >= 0.0,
                Rule::AtLeast { min } => value >= min,
                Rule::Within { min, max } => value >= min && value <= max,
                Rule::PositiveUpTo { max } => value > 0.0 && value <= max,
                Rule::Between { min, max } => value > min && value < max,
                Rule::AtMost { max, .. } => value <= max,
                Rule::Below { max, .. } => value < max,
                Rule::Near { target, relative, .. } => (value - target).abs() <= relative * target.abs(),
            }
    }

    /// `Ok(value)` if `value` satisfies the rule, else a [`BadValue`] naming `name`.
    pub fn check(self, name: impl Into<Cow<'static, str>>, value: f64) -> Result<f64, BadValue> {
        if self.admits(value) {
            Ok(value)
        } else {
            Err(BadValue {
                name: name.into(),
                value,
                rule: self,
            })
        }
    }
}

impl fmt::Display for Rule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Rule::Finite => f.write_str("must be a finite number"),
            Rule::Positive => f.write_str("must be a finite number greater than zero"),
            Rule::NonNegative => f.write_str("must be a finite number not below zero"),
            Rule::AtLeast { min } => write!(f, "must be a finite number not below {}", Significant(*min)),
            Rule::Within { min, max } => write!(
                f,
                "must be a finite number from {} to {}",
                Significant(*min),
                Significant(*max)
            ),
            Rule::PositiveUpTo { max } => {
                write!(f, "must be a finite number above zero, at most {}", Significant(*max))
            }
            Rule::Custom(text) => f.write_str(text),
            Rule::Between { min, max } => write!(
                f,
                "must be a finite number strictly between {} and {}",
                Significant(*min),
                Significant(*max)
            ),
            Rule::AtMost { max, what } => write!(f, "must be a finite number not above {what} = {}", Significant(*max)),
            Rule::Below { max, what } => write!(f, "must be a finite number below {what} = {}", Significant(*max)),
            Rule::Near { target, relative, what } => write!(
                f,
                "must be a finite number within {:.0} % of {what} = {target:.4}",
                100.0 * relative
            ),
        }
    }
}

/// A named physical range: one quantity's name with its unit and the interval it must lie in. Ranges that several
/// commands share are written once, as constants, so every input path enforces the same numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// What the quantity is, with its unit in brackets (`"object temperature [°C]"`).
    pub name: &'static str,
    /// Smallest allowed value.
    pub min: f64,
    /// Largest allowed value.
    pub max: f64,
}

impl Range {
    /// The range as a [`Rule`].
    pub const fn rule(self) -> Rule {
        Rule::Within {
            min: self.min,
            max: self.max,
        }
    }

    /// `Ok(value)` if `value` is finite and inside the range, else a [`BadValue`] with the range's name.
    pub fn check(self, value: f64) -> Result<f64, BadValue> {
        self.rule().check(self.name, value)
    }
}

/// A refused number: what it is (a key or a description, with its unit), the value, and the rule it breaks.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("`{name}` = {} is invalid: {rule}", Shown(*value))]
pub struct BadValue {
    /// What the number is: a file key (`conductivity_w_mk`) or a description with its unit.
    pub name: Cow<'static, str>,
    /// The refused value.
    pub value: f64,
    /// The rule it breaks.
    pub rule: Rule,
}

/// A number as an error message shows it: as Rust writes it, except that very large and very small magnitudes
/// (from 1e15, below 1e-6) are written in exponent form (`1e300`, not three hundred digits).
struct Shown(f64);

impl fmt::Display for Shown {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let magnitude = self.0.abs();
        if magnitude.is_finite() && (magnitude >= 1e15 || (magnitude > 0.0 && magnitude < 1e-6)) {
            write!(f, "{:e}", self.0)
        } else {
            write!(f, "{}", self.0)
        }
    }
}

impl BadValue {
    /// A value that breaks a requirement in words (see [`Rule::Custom`]).
    pub fn custom(name: impl Into<Cow<'static, str>>, value: f64, requirement: &'static str) -> Self {
        BadValue {
            name: name.into(),
            value,
            rule: Rule::Custom(requirement),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_rule_refuses_non_finite_numbers_and_says_why() {
        for rule in [
            Rule::Finite,
            Rule::Positive,
            Rule::NonNegative,
            Rule::Within {
                min: -1e300,
                max: 1e300,
            },
            Rule::Custom("any"),
            Rule::Between {
                min: -1e300,
                max: 1e300,
            },
            Rule::AtMost { max: 1e300, what: "x" },
            Rule::Below { max: 1e300, what: "x" },
            Rule::PositiveUpTo { max: 1e300 },
        ] {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                assert!(!rule.admits(bad), "{rule:?} admitted {bad}");
            }
        }
        assert_eq!(
            Rule::Positive.check("dt [s]", 0.0).map_err(|e| e.to_string()),
            Err("`dt [s]` = 0 is invalid: must be a finite number greater than zero".to_string())
        );
        assert_eq!(Rule::NonNegative.check("noise [°C]", 0.0), Ok(0.0));
        let between = Rule::Between { min: 0.0, max: 100.0 };
        assert!(!between.admits(0.0) && !between.admits(100.0) && between.admits(50.0));
        let at_most = Rule::AtMost {
            max: 2.8,
            what: "the module's I_max [A]",
        };
        assert!(at_most.admits(2.8) && !at_most.admits(2.9));
        assert_eq!(
            at_most.check("drive.current_limit_a", 3.0).map_err(|e| e.to_string()),
            Err("`drive.current_limit_a` = 3 is invalid: must be a finite number not above the module's I_max [A] = 2.8"
                .to_string())
        );
        let below = Rule::Below { max: 1.0, what: "one" };
        assert!(below.admits(0.5) && !below.admits(1.0));
        let up_to = Rule::PositiveUpTo { max: 300.0 };
        assert!(up_to.admits(300.0) && up_to.admits(1e-9) && !up_to.admits(0.0) && !up_to.admits(300.5));
        assert_eq!(
            up_to.check("limits.rate_c_s", 400.0).map_err(|e| e.to_string()),
            Err("`limits.rate_c_s` = 400 is invalid: must be a finite number above zero, at most 300".to_string())
        );
    }

    #[test]
    fn a_range_is_inclusive_and_names_its_quantity() {
        let range = Range {
            name: "object temperature [°C]",
            min: 0.0,
            max: 70.0,
        };
        assert_eq!(range.check(0.0), Ok(0.0));
        assert_eq!(range.check(70.0), Ok(70.0));
        let error = range.check(70.5).expect_err("above the range");
        assert_eq!(
            error.to_string(),
            "`object temperature [°C]` = 70.5 is invalid: must be a finite number from 0 to 70"
        );
    }
}
