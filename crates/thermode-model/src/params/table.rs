//! The one TOML table reader of thermode: skin, material, device and experiment files are read with [`Table`].
//!
//! A [`Table`] wraps one TOML table with the file it came from (`origin`) and its path inside the file (`plate.`,
//! `layer[2].`). Its typed getters check every number with a [`Rule`] and name the file and the full key in every
//! error; quantities that material files may give in SI or in the paper's cgs units are read with [`Spellings`].
//! [`Table::finish`] refuses every key that no getter asked for, so a misspelt key is an error, never ignored.

use std::cell::RefCell;

use super::{BadValue, Rule};
use crate::error::ParamError;
use crate::units;

/// Parses TOML text into a table; a syntax error is a [`ParamError::Syntax`] naming `origin`.
pub fn parse(text: &str, origin: &str) -> Result<toml::Table, ParamError> {
    text.parse::<toml::Table>().map_err(|e| ParamError::Syntax {
        origin: origin.to_string(),
        message: e.to_string().trim().to_string(),
    })
}

/// The two spellings of one quantity: the SI key and the cgs-calorie key, with the conversion of the cgs value.
#[derive(Debug, Clone, Copy)]
pub struct Spellings {
    /// The SI key (`conductivity_w_mk`).
    pub si: &'static str,
    /// The cgs key (`conductivity_cal_cm_s_c`).
    pub cgs: &'static str,
    /// cgs value → SI value.
    pub to_si: fn(f64) -> f64,
}

impl Spellings {
    /// `rule`, a rule on the SI value, as a rule on the cgs value: the bounds of [`Rule::Within`] and
    /// [`Rule::Between`] divided by the conversion factor (the conversions are proportional); other rules hold in
    /// either unit as they are.
    pub fn cgs_rule(self, rule: Rule) -> Rule {
        let factor = (self.to_si)(1.0);
        match rule {
            Rule::Within { min, max } => Rule::Within {
                min: min / factor,
                max: max / factor,
            },
            Rule::Between { min, max } => Rule::Between {
                min: min / factor,
                max: max / factor,
            },
            other => other,
        }
    }
}

/// Thermal conductivity: `conductivity_w_mk` [W/(m·K)] or `conductivity_cal_cm_s_c` [cal/(cm·s·°C)].
pub const CONDUCTIVITY: Spellings = Spellings {
    si: "conductivity_w_mk",
    cgs: "conductivity_cal_cm_s_c",
    to_si: units::conductivity_to_si,
};

/// Density: `density_kg_m3` [kg/m³] or `density_g_cm3` [g/cm³].
pub const DENSITY: Spellings = Spellings {
    si: "density_kg_m3",
    cgs: "density_g_cm3",
    to_si: units::density_to_si,
};

/// Specific heat: `specific_heat_j_kgk` [J/(kg·K)] or `specific_heat_cal_g_c` [cal/(g·°C)].
pub const SPECIFIC_HEAT: Spellings = Spellings {
    si: "specific_heat_j_kgk",
    cgs: "specific_heat_cal_g_c",
    to_si: units::specific_heat_to_si,
};

/// One TOML table of a parameter file, with the file it came from and its path in the file, for error messages.
/// Every getter marks its key as known; [`Table::finish`] refuses the keys no getter asked for.
#[derive(Debug)]
pub struct Table<'a> {
    table: &'a toml::Table,
    origin: &'a str,
    prefix: String,
    asked: RefCell<Vec<String>>,
}

impl<'a> Table<'a> {
    /// The top-level table of the file `origin` (usually the file name; it appears in every error).
    pub fn new(table: &'a toml::Table, origin: &'a str) -> Self {
        Self::nested(table, origin, String::new())
    }

    fn nested(table: &'a toml::Table, origin: &'a str, prefix: String) -> Self {
        Table {
            table,
            origin,
            prefix,
            asked: RefCell::new(Vec::new()),
        }
    }

    /// Where the table came from (the file name).
    pub fn origin(&self) -> &'a str {
        self.origin
    }

    /// The full name of `key` as errors show it: the section path and the key (`plate.area_m2`, `layer[2].name`).
    pub fn key(&self, key: &str) -> String {
        format!("{}{}", self.prefix, key)
    }

    fn get(&self, key: &str) -> Option<&'a toml::Value> {
        let mut asked = self.asked.borrow_mut();
        if !asked.iter().any(|k| k == key) {
            asked.push(key.to_string());
        }
        self.table.get(key)
    }

    /// A [`ParamError::MissingKey`] for `key`.
    pub fn missing(&self, key: &str) -> ParamError {
        ParamError::MissingKey {
            origin: self.origin.to_string(),
            key: self.key(key),
        }
    }

    /// A [`ParamError::Invalid`] for `key`: "`key`: message".
    pub fn invalid(&self, key: &str, message: impl std::fmt::Display) -> ParamError {
        ParamError::Invalid {
            origin: self.origin.to_string(),
            message: format!("`{}`: {message}", self.key(key)),
        }
    }

    /// A [`ParamError::BadValue`] for `value` of `key`, which breaks `rule`.
    pub fn bad(&self, key: &str, value: f64, rule: Rule) -> ParamError {
        ParamError::bad_value(
            self.origin,
            BadValue {
                name: self.key(key).into(),
                value,
                rule,
            },
        )
    }

    fn wrong_type(&self, key: &str, expected: &str, found: &toml::Value) -> ParamError {
        ParamError::WrongType {
            origin: self.origin.to_string(),
            key: self.key(key),
            expected: expected.to_string(),
            found: format!("{} {}", found.type_str(), found),
        }
    }

    /// Refuses every key that no getter asked for ([`ParamError::UnknownKey`] naming the first, in file order).
    pub fn finish(&self) -> Result<(), ParamError> {
        let asked = self.asked.borrow();
        match self.table.keys().find(|k| !asked.contains(k)) {
            Some(k) => Err(ParamError::UnknownKey {
                origin: self.origin.to_string(),
                key: self.key(k),
            }),
            None => Ok(()),
        }
    }

    /// A number (TOML float or integer) if present, checked with `rule`; any other type is an error.
    pub fn number(&self, key: &str, rule: Rule) -> Result<Option<f64>, ParamError> {
        let Some(value) = self.unchecked_number(key)? else {
            return Ok(None);
        };
        if rule.admits(value) {
            Ok(Some(value))
        } else {
            Err(self.bad(key, value, rule))
        }
    }

    /// A number (TOML float or integer) if present, not range-checked: for the few numbers where ±∞ means
    /// something (a filter cut-off of `inf` = no filter); the caller checks it.
    pub fn unchecked_number(&self, key: &str) -> Result<Option<f64>, ParamError> {
        match self.get(key) {
            None => Ok(None),
            Some(toml::Value::Float(v)) => Ok(Some(*v)),
            // Integers in parameter files are small; the conversion is exact below 2^53.
            Some(toml::Value::Integer(v)) => Ok(Some(*v as f64)),
            Some(other) => Err(self.wrong_type(key, "a number", other)),
        }
    }

    /// A number that must be present, checked with `rule`.
    pub fn required_number(&self, key: &str, rule: Rule) -> Result<f64, ParamError> {
        self.number(key, rule)?.ok_or_else(|| self.missing(key))
    }

    /// A quantity given in exactly one of its two [`Spellings`] (the cgs value converted to SI), checked with
    /// `rule`, a rule on the SI value: a cgs value is checked against the same bounds converted to its unit, so
    /// the error shows the number as written with bounds in that unit. Neither spelling is `None`; both are a
    /// [`ParamError::BothSpellings`].
    pub fn either(&self, spellings: Spellings, rule: Rule) -> Result<Option<f64>, ParamError> {
        match (
            self.number(spellings.si, rule)?,
            self.number(spellings.cgs, spellings.cgs_rule(rule))?,
        ) {
            (Some(v), None) => Ok(Some(v)),
            (None, Some(v)) => Ok(Some((spellings.to_si)(v))),
            (Some(_), Some(_)) => Err(ParamError::BothSpellings {
                origin: self.origin.to_string(),
                si_key: self.key(spellings.si),
                cgs_key: self.key(spellings.cgs),
            }),
            (None, None) => Ok(None),
        }
    }

    /// As [`Table::either`], but one spelling must be given (a missing quantity names its SI key).
    pub fn required_either(&self, spellings: Spellings, rule: Rule) -> Result<f64, ParamError> {
        self.either(spellings, rule)?.ok_or_else(|| self.missing(spellings.si))
    }

    /// A TOML integer if present; any other type is an error.
    pub fn integer(&self, key: &str) -> Result<Option<i64>, ParamError> {
        match self.get(key) {
            None => Ok(None),
            Some(toml::Value::Integer(i)) => Ok(Some(*i)),
            Some(other) => Err(self.wrong_type(key, "an integer", other)),
        }
    }

    /// A count (an integer) in `[min, max]` if present.
    pub fn count(&self, key: &str, min: usize, max: usize) -> Result<Option<usize>, ParamError> {
        let Some(i) = self.integer(key)? else {
            return Ok(None);
        };
        match usize::try_from(i) {
            Ok(n) if (min..=max).contains(&n) => Ok(Some(n)),
            _ => Err(self.bad(
                key,
                i as f64,
                Rule::Within {
                    min: min as f64,
                    max: max as f64,
                },
            )),
        }
    }

    /// A string if present; any other type is an error.
    pub fn string(&self, key: &str) -> Result<Option<String>, ParamError> {
        match self.get(key) {
            None => Ok(None),
            Some(toml::Value::String(s)) => Ok(Some(s.clone())),
            Some(other) => Err(self.wrong_type(key, "a string", other)),
        }
    }

    /// A string that must be present.
    pub fn required_string(&self, key: &str) -> Result<String, ParamError> {
        self.string(key)?.ok_or_else(|| self.missing(key))
    }

    /// An array of strings if present; any other type (or an element that is not a string) is an error.
    pub fn strings(&self, key: &str) -> Result<Option<Vec<String>>, ParamError> {
        let Some(value) = self.get(key) else {
            return Ok(None);
        };
        let wrong = || self.wrong_type(key, "an array of strings", value);
        let items = value.as_array().ok_or_else(wrong)?;
        let strings: Option<Vec<String>> = items.iter().map(|v| v.as_str().map(str::to_string)).collect();
        strings.map(Some).ok_or_else(wrong)
    }

    /// The section `[key]` if present, as a table whose errors name its keys `key.…`.
    pub fn section(&self, key: &str) -> Result<Option<Table<'a>>, ParamError> {
        match self.get(key) {
            None => Ok(None),
            Some(toml::Value::Table(t)) => Ok(Some(Table::nested(t, self.origin, format!("{}.", self.key(key))))),
            Some(other) => Err(self.wrong_type(key, "a table", other)),
        }
    }

    /// The array of tables `[[key]]` if present, each a table whose errors name its keys `key[1].…`, `key[2].…`
    /// (counted from 1).
    pub fn sections(&self, key: &str) -> Result<Option<Vec<Table<'a>>>, ParamError> {
        let items = match self.get(key) {
            None => return Ok(None),
            Some(toml::Value::Array(items)) => items,
            Some(other) => return Err(self.wrong_type(key, "an array of tables", other)),
        };
        items
            .iter()
            .enumerate()
            .map(|(i, item)| {
                let name = format!("{}[{}]", self.key(key), i + 1);
                match item {
                    toml::Value::Table(t) => Ok(Table::nested(t, self.origin, format!("{name}."))),
                    other => Err(ParamError::WrongType {
                        origin: self.origin.to_string(),
                        key: name,
                        expected: format!("a table ([[{key}]])"),
                        found: other.type_str().to_string(),
                    }),
                }
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn getters_check_rules_and_name_file_section_and_key() {
        let toml = parse("a = 1\n[s]\nx = -2.5\ny = \"text\"\nk_cal = 1\n", "f.toml").expect("valid");
        let top = Table::new(&toml, "f.toml");
        assert_eq!(top.number("a", Rule::Positive), Ok(Some(1.0)));
        let s = top.section("s").expect("a table").expect("present");
        let error = s.number("x", Rule::NonNegative).expect_err("negative");
        assert_eq!(error.bad_key(), Some("s.x"));
        assert_eq!(
            error.to_string(),
            "f.toml: `s.x` = -2.5 is invalid: must be a finite number not below zero"
        );
        assert!(matches!(s.number("y", Rule::Finite), Err(ParamError::WrongType { key, .. }) if key == "s.y"));
        assert_eq!(
            s.finish(),
            Err(ParamError::UnknownKey {
                origin: "f.toml".into(),
                key: "s.k_cal".into()
            })
        );
        assert_eq!(top.finish(), Ok(()));
        assert!(matches!(parse("a = ", "g.toml"), Err(ParamError::Syntax { origin, .. }) if origin == "g.toml"));
    }

    #[test]
    fn a_range_applies_to_the_cgs_spelling_in_its_own_unit() {
        let within = Rule::Within { min: 0.01, max: 2500.0 };
        // 0.526 cal/(cm·s·°C) is 220 W/(m·K): inside, although 0.526 would be "inside" either way; 10 cal/(cm·s·°C)
        // is 4187 W/(m·K): beyond diamond, refused with the bound in cal/(cm·s·°C).
        let toml = parse("conductivity_cal_cm_s_c = 0.526\n", "m.toml").expect("valid");
        let got = Table::new(&toml, "m.toml").required_either(CONDUCTIVITY, within);
        assert!(got.as_ref().is_ok_and(|k| (k - 220.22).abs() < 0.01), "{got:?}");
        let toml = parse("conductivity_cal_cm_s_c = 10\n", "m.toml").expect("valid");
        let error = Table::new(&toml, "m.toml")
            .required_either(CONDUCTIVITY, within)
            .expect_err("4187 W/(m·K)");
        assert_eq!(error.bad_key(), Some("conductivity_cal_cm_s_c"));
        // The bounds 0.01 / 418.68 = 2.388458…e-5 and 2500 / 418.68 = 5.971147… to six significant digits (issue 25:
        // bounds as people write them, not 0.000023884589662749594 and 5.9711474156873985).
        assert!(error.to_string().contains("from 2.38846e-5 to 5.97115"), "{error}");
        assert_eq!(CONDUCTIVITY.cgs_rule(Rule::Positive), Rule::Positive);
    }

    #[test]
    fn spellings_convert_cgs_and_refuse_both() {
        let toml = parse("density_g_cm3 = 2.7\n", "m.toml").expect("valid");
        let t = Table::new(&toml, "m.toml");
        assert_eq!(t.required_either(DENSITY, Rule::Positive), Ok(2700.0));
        assert!(matches!(
            t.required_either(CONDUCTIVITY, Rule::Positive),
            Err(ParamError::MissingKey { .. })
        ));
        let toml = parse("density_g_cm3 = 2.7\ndensity_kg_m3 = 2700\n", "m.toml").expect("valid");
        let t = Table::new(&toml, "m.toml");
        assert!(matches!(
            t.either(DENSITY, Rule::Positive),
            Err(ParamError::BothSpellings { .. })
        ));
    }
}
