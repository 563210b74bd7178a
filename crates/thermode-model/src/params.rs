//! The one parameter vocabulary of thermode: what a number must satisfy ([`Rule`], [`Range`]) and the one error for
//! a refused number ([`BadValue`]). Every crate checks its numbers with these (skin, material, device, envelope,
//! controller, pipeline, run, experiment and API inputs), so a refused number reads the same everywhere: what it is
//! (with its unit), the value, and the rule it breaks.
//!
//! Nothing here allocates when the name is a `&'static str`, so checks may run on the per-tick path.

use std::borrow::Cow;
use std::fmt;

use thiserror::Error;

/// What a number must satisfy. Every rule requires a finite number (NaN and ±∞ are always refused).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rule {
    /// Any finite number.
    Finite,
    /// A finite number greater than zero.
    Positive,
    /// A finite number not below zero.
    NonNegative,
    /// A finite number in `[min, max]` (both inclusive).
    Within {
        /// Smallest allowed value.
        min: f64,
        /// Largest allowed value.
        max: f64,
    },
    /// A requirement the other rules cannot say, in words (`"must last at least one tick"`); checked by the caller.
    Custom(&'static str),
}

impl Rule {
    /// Whether `value` satisfies the rule (a [`Rule::Custom`] only checks finiteness).
    pub fn admits(self, value: f64) -> bool {
        value.is_finite()
            && match self {
                Rule::Finite | Rule::Custom(_) => true,
                Rule::Positive => value > 0.0,
                Rule::NonNegative => value >= 0.0,
                Rule::Within { min, max } => value >= min && value <= max,
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
            Rule::Within { min, max } => write!(f, "must be a finite number in [{min}, {max}]"),
            Rule::Custom(text) => f.write_str(text),
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
#[error("`{name}` = {value} is invalid: {rule}")]
pub struct BadValue {
    /// What the number is: a file key (`conductivity_w_mk`) or a description with its unit.
    pub name: Cow<'static, str>,
    /// The refused value.
    pub value: f64,
    /// The rule it breaks.
    pub rule: Rule,
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
            "`object temperature [°C]` = 70.5 is invalid: must be a finite number in [0, 70]"
        );
    }
}
