//! Configuration of the per-channel safety envelope ([`EnvelopeConfig`]) and the compiled-in absolute limits no
//! configuration may widen. A configuration outside the absolute limits is an [`EnvelopeError`], never clamped.
//!
//! Sources of the figures (see also `shared/design/model.md` §6):
//! - Paper, section 2a and 3: operating range 15–48 °C; pain below 15 °C and above 48 °C; display rate 2 °C/s;
//!   Jones & Berris recommend 10 °C/s.
//! - IEC 60601-1 (Table 24, applied parts in contact with the patient): 48 °C for 1–10 min contact, 43 °C for
//!   ≥ 10 min. Hence the absolute maximum of 48 °C and the 10-minute budget at ≥ 43 °C.
//! - ISO 13732-3 contact criteria: numbness at about 7 °C skin temperature. The absolute minimum of 10 °C keeps a
//!   3 K margin above it (a display colder than the skin it touches means the skin stays warmer still).
//! - CEM43 thermal dose (Sapareto & Dewey 1984). Damage thresholds for skin are tens of CEM43-minutes
//!   (Yarmolenko et al. 2011); van Rhoon et al. 2013 (Eur. Radiol. 23:2215) propose limits of a few CEM43-minutes
//!   for routine, uncontrolled exposure. The default budget of 1 CEM43-minute stays below that proposal.

use serde::Serialize;

use thermode_model::limits;
use thermode_model::params::{self, Rule, Table};
use thermode_model::ParamError;

use crate::dose::CEM43_REFERENCE_C;
use crate::error::EnvelopeError;

/// Lowest display temperature any configuration may allow, °C (3 K above the 7 °C numbness criterion behind
/// ISO 13732-3).
pub const ABSOLUTE_MIN_C: f64 = 10.0;
/// Highest display temperature any configuration may allow, °C (IEC 60601-1 applied-part limit for 1–10 min
/// contact; the paper's pain threshold).
pub const ABSOLUTE_MAX_C: f64 = 48.0;
/// Highest set-point rate any configuration may allow, °C/s: 300, the upper bound of the physical range of
/// set-point rates ([`limits::SETPOINT_RATE`], written there once). It is not what protects the skin — the
/// temperature limits and the thermal dose do, whatever the rate; commercial stimulators ramp at 70–300 °C/s
/// inside the same temperature bounds (e.g. QST.Lab TCS II, up to 300 °C/s) — but a cap on how fast a display may
/// follow. A display's rendering rate is a per-device setting (its device file's
/// `render.max_setpoint_rate_c_per_s`, default 20); the envelope's general default stays 10 (Jones & Berris).
pub const ABSOLUTE_MAX_RATE_C_PER_S: f64 = limits::SETPOINT_RATE.max;
/// Highest plausibility bound on the measured plate rate any configuration may set, °C/s: 1000, so that it can
/// always stay above the set-point rate limit (`max_setpoint_rate_c_per_s < max_measured_rate_c_per_s`), with
/// margin for a plate that follows a 300 °C/s ramp with sensor noise.
pub const ABSOLUTE_MAX_MEASURED_RATE_C_PER_S: f64 = 1000.0;
// Any allowed set-point rate leaves room for a measured-rate bound above it.
const _: () = assert!(ABSOLUTE_MAX_MEASURED_RATE_C_PER_S > ABSOLUTE_MAX_RATE_C_PER_S);
/// Longest cumulative time at or above 43 °C any configuration may allow, s (IEC 60601-1: 43 °C for ≥ 10 min).
pub const ABSOLUTE_MAX_TIME_AT_OR_ABOVE_43_S: f64 = 600.0;
/// Largest CEM43 budget any configuration may allow, CEM43-minutes (= 10 min at 43 °C, the IEC long-contact case).
pub const ABSOLUTE_MAX_CEM43_BUDGET_MIN: f64 = 10.0;
/// Longest continuous time at or above [`ABSOLUTE_MAX_C`] any configuration may tolerate before a fault, s.
pub const ABSOLUTE_MAX_TIME_AT_OR_ABOVE_48_S: f64 = 10.0;
/// Highest hot-side limit any configuration may set, °C: the water-cooled box is worn on the phalanx (paper 3.1),
/// so it is held to the same 48 °C contact limit as the display.
pub const ABSOLUTE_MAX_HOT_SIDE_C: f64 = 48.0;
/// Longest stale-sensor timeout any configuration may set, s.
pub const ABSOLUTE_MAX_STALE_TIMEOUT_S: f64 = 1.0;
/// Display set-point used when nothing else is known (no measurement, no valid request yet), °C: the middle of
/// the 30–36 °C indifference zone (paper 2a), clamped into the configured range.
pub const NEUTRAL_SETPOINT_C: f64 = 33.0;

/// Safety envelope settings of one channel. Every field has a default (`EnvelopeConfig::default()`), so a TOML
/// table may give only some keys; unknown keys are refused ([`EnvelopeConfig::from_toml_str`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EnvelopeConfig {
    /// Lowest display set-point, °C. Default 15 (paper: cold pain below 15 °C). Range [10, 48).
    pub min_display_c: f64,
    /// Highest display set-point, °C. Default 48 (paper: heat pain above 48 °C; IEC 60601-1). Range (min, 48].
    pub max_display_c: f64,
    /// Largest rate of change of the shaped set-point, °C/s. Default 10 (Jones & Berris; the paper used 2).
    /// Range [0.01, 300] ([`limits::SETPOINT_RATE`]; at most [`ABSOLUTE_MAX_RATE_C_PER_S`]); must stay below
    /// `max_measured_rate_c_per_s`.
    pub max_setpoint_rate_c_per_s: f64,
    /// Cumulative time at or above 43 °C (measured) after which the maximum drops below 43 °C, s. Default 600
    /// (IEC 60601-1: 43 °C for ≥ 10 min). Range [0, 600].
    pub max_time_at_or_above_43_s: f64,
    /// CEM43 budget after which the maximum drops below 43 °C, CEM43-minutes. Default 1 (below the few
    /// CEM43-minutes proposed for routine exposure by van Rhoon et al. 2013). Range [0, 10].
    pub cem43_budget_min: f64,
    /// After the dose lockout the maximum is `43 − dose_lockout_margin_c`, °C. Default 0.5 (≈ the tolerance of a
    /// class-B PT-100 at 43 °C, 0.3 + 0.005·43 = 0.52 °C). Range [0.1, 5].
    pub dose_lockout_margin_c: f64,
    /// After the dose lockout engages, time the measured display has to fall below 43 °C before any reading at
    /// or above 43 °C is a fault, s. Default 5 (cooling 48 → 43 °C at the 10 °C/s rate limit takes 0.5 s).
    /// Range [0, 60].
    pub dose_lockout_grace_s: f64,
    /// Continuous time the measured display may stay at or above 48 °C before a fault ("never sustained"), s.
    /// Default 1 (heating is refused at the maximum, so a display that stays there is heated by something the
    /// envelope does not command). Range [0, 10].
    pub max_time_at_or_above_48_s: f64,
    /// Margin beyond the display limits at which the measured display is a fault, °C. Default 1.
    /// Range [0.1, 5].
    pub limit_margin_c: f64,
    /// Reading at or above which the display sensor is open, °C. Default 150 (an open PT-100 reads as an
    /// unbounded resistance, far beyond 150 °C). Must exceed `plausible_max_c`; at most 1000.
    pub sensor_open_c: f64,
    /// Reading at or below which the display sensor is shorted, °C. Default −50 (a shorted PT-100 reads ≈ 0 Ω,
    /// about −242 °C). Must be below `plausible_min_c`; at least −300.
    pub sensor_short_c: f64,
    /// Lowest plausible display reading, °C. Default 0 (the water loop runs at room temperature; a display on a
    /// finger cannot reach freezing within the 10 °C absolute minimum). Must be below `min_display_c −
    /// limit_margin_c`.
    pub plausible_min_c: f64,
    /// Highest plausible display reading, °C. Default 70. Must exceed `max_display_c + limit_margin_c`.
    pub plausible_max_c: f64,
    /// Longest time without a fresh display sample before a fault, s. Default 0.2 (≥ 10 conversions of a
    /// 50–60 Hz PT-100 converter; the set-point moves at most 2 °C at the default rate limit). Range [0.001, 1].
    pub stale_timeout_s: f64,
    /// Largest plausible rate of change of the measured display, °C/s. Default 50 (a bare 0.2 J/K plate heated
    /// by the 8×8 mm module at full current warms at about 35 °C/s). Must exceed `max_setpoint_rate_c_per_s` (a
    /// plate that follows its set-point at the rate limit must not look implausible); at most
    /// [`ABSOLUTE_MAX_MEASURED_RATE_C_PER_S`] (1000), which stays above any allowed set-point rate.
    pub max_measured_rate_c_per_s: f64,
    /// Shortest time span over which the measured rate is evaluated, s (suppresses noise/quantisation between
    /// close samples: a jump of `max_measured_rate_c_per_s · rate_window_s` = 2.5 °C is implausible). Default
    /// 0.05. Range [0.001, 1].
    pub rate_window_s: f64,
    /// Hot-side temperature above which the cooling has failed, °C. Default 45 (3 K below the 48 °C contact
    /// limit of the worn box; with water at ≈ 23 °C and 0.3 W/K, 45 °C means > 6 W of rejected heat, beyond
    /// normal rendering). Range (hot_side_min_c, 48].
    pub hot_side_max_c: f64,
    /// Hot-side reading below which its sensor is implausible (shorted), °C. Default 0. Range [−50, hot_side_max_c).
    pub hot_side_min_c: f64,
    /// Fraction of the current limit at which the drive counts as "at its limit". Default 0.98. Range [0.5, 1].
    pub stuck_current_fraction: f64,
    /// Longest continuous time at the current limit before a fault, s. Default 10 (the rate-limited set-point
    /// crosses the whole 15–48 °C range in 3.3 s; a plate that needs full current for longer is not following
    /// the model). Range [0.1, 60].
    pub stuck_at_limit_s: f64,
    /// First-order time constant of the display sensor behind the plate, s: the thermal dose is counted at the
    /// plate temperature reconstructed from the reading (`crate::dose`, "The plate, not the sensor"). Default 0.3
    /// (the default display's PT-100; a rendering pipeline requires at least its device file's). Larger than the
    /// real one over-counts the dose (safe); smaller under-counts it. Range [0, 10].
    pub sensor_time_constant_s: f64,
}

impl Default for EnvelopeConfig {
    fn default() -> Self {
        Self {
            min_display_c: 15.0,
            max_display_c: ABSOLUTE_MAX_C,
            max_setpoint_rate_c_per_s: 10.0,
            max_time_at_or_above_43_s: ABSOLUTE_MAX_TIME_AT_OR_ABOVE_43_S,
            cem43_budget_min: 1.0,
            dose_lockout_margin_c: 0.5,
            dose_lockout_grace_s: 5.0,
            max_time_at_or_above_48_s: 1.0,
            limit_margin_c: 1.0,
            sensor_open_c: 150.0,
            sensor_short_c: -50.0,
            plausible_min_c: 0.0,
            plausible_max_c: 70.0,
            stale_timeout_s: 0.2,
            max_measured_rate_c_per_s: 50.0,
            rate_window_s: 0.05,
            hot_side_max_c: 45.0,
            hot_side_min_c: 0.0,
            stuck_current_fraction: 0.98,
            stuck_at_limit_s: 10.0,
            sensor_time_constant_s: 0.3,
        }
    }
}

/// `Ok` if `holds`, else [`EnvelopeError::Inconsistent`].
fn require(holds: bool, requirement: &'static str) -> Result<(), EnvelopeError> {
    if holds {
        Ok(())
    } else {
        Err(EnvelopeError::Inconsistent { requirement })
    }
}

impl EnvelopeConfig {
    /// The maximum display set-point once the thermal-dose lockout has engaged, °C.
    pub fn dose_lockout_max_c(&self) -> f64 {
        CEM43_REFERENCE_C - self.dose_lockout_margin_c
    }

    /// Checks every field against its range and the relations between fields.
    pub fn validate(&self) -> Result<(), EnvelopeError> {
        self.validate_ranges()?;
        self.validate_relations()
    }

    /// Every field with its key (units are in the names) and its range `[min, max]`, in declaration order.
    fn fields(&mut self) -> [(&'static str, &mut f64, f64, f64); 21] {
        [
            ("min_display_c", &mut self.min_display_c, ABSOLUTE_MIN_C, ABSOLUTE_MAX_C),
            ("max_display_c", &mut self.max_display_c, ABSOLUTE_MIN_C, ABSOLUTE_MAX_C),
            (
                "max_setpoint_rate_c_per_s",
                &mut self.max_setpoint_rate_c_per_s,
                limits::SETPOINT_RATE.min,
                ABSOLUTE_MAX_RATE_C_PER_S,
            ),
            (
                "max_time_at_or_above_43_s",
                &mut self.max_time_at_or_above_43_s,
                0.0,
                ABSOLUTE_MAX_TIME_AT_OR_ABOVE_43_S,
            ),
            (
                "cem43_budget_min",
                &mut self.cem43_budget_min,
                0.0,
                ABSOLUTE_MAX_CEM43_BUDGET_MIN,
            ),
            ("dose_lockout_margin_c", &mut self.dose_lockout_margin_c, 0.1, 5.0),
            ("dose_lockout_grace_s", &mut self.dose_lockout_grace_s, 0.0, 60.0),
            (
                "max_time_at_or_above_48_s",
                &mut self.max_time_at_or_above_48_s,
                0.0,
                ABSOLUTE_MAX_TIME_AT_OR_ABOVE_48_S,
            ),
            ("limit_margin_c", &mut self.limit_margin_c, 0.1, 5.0),
            ("sensor_open_c", &mut self.sensor_open_c, -300.0, 1000.0),
            ("sensor_short_c", &mut self.sensor_short_c, -300.0, 1000.0),
            ("plausible_min_c", &mut self.plausible_min_c, -300.0, 1000.0),
            ("plausible_max_c", &mut self.plausible_max_c, -300.0, 1000.0),
            (
                "stale_timeout_s",
                &mut self.stale_timeout_s,
                0.001,
                ABSOLUTE_MAX_STALE_TIMEOUT_S,
            ),
            (
                "max_measured_rate_c_per_s",
                &mut self.max_measured_rate_c_per_s,
                limits::SETPOINT_RATE.min,
                ABSOLUTE_MAX_MEASURED_RATE_C_PER_S,
            ),
            ("rate_window_s", &mut self.rate_window_s, 0.001, 1.0),
            (
                "hot_side_max_c",
                &mut self.hot_side_max_c,
                -50.0,
                ABSOLUTE_MAX_HOT_SIDE_C,
            ),
            (
                "hot_side_min_c",
                &mut self.hot_side_min_c,
                -50.0,
                ABSOLUTE_MAX_HOT_SIDE_C,
            ),
            ("stuck_current_fraction", &mut self.stuck_current_fraction, 0.5, 1.0),
            ("stuck_at_limit_s", &mut self.stuck_at_limit_s, 0.1, 60.0),
            (
                "sensor_time_constant_s",
                &mut self.sensor_time_constant_s,
                limits::SENSOR_LAG.min,
                limits::SENSOR_LAG.max,
            ),
        ]
    }

    fn validate_ranges(&self) -> Result<(), EnvelopeError> {
        let mut copy = *self;
        for (field, value, min, max) in copy.fields() {
            Rule::Within { min, max }.check(field, *value)?;
        }
        Ok(())
    }

    /// Reads an envelope table (TOML) with [`Table`]: every key optional (missing keys keep their defaults),
    /// unknown keys and values of the wrong type refused, and the result validated (see
    /// [`EnvelopeConfig::validate`]). `origin` (usually the file name) appears in every error.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<EnvelopeConfig, ParamError> {
        let toml = params::parse(text, origin)?;
        let file = Table::new(&toml, origin);
        let mut config = EnvelopeConfig::default();
        for (key, value, min, max) in config.fields() {
            if let Some(read) = file.number(key, Rule::Within { min, max })? {
                *value = read;
            }
        }
        file.finish()?;
        config.validate().map_err(|error| match error {
            EnvelopeError::BadValue(refused) => ParamError::bad_value(origin, refused),
            other => ParamError::Invalid {
                origin: origin.to_string(),
                message: other.to_string(),
            },
        })?;
        Ok(config)
    }

    fn validate_relations(&self) -> Result<(), EnvelopeError> {
        require(self.min_display_c < self.max_display_c, "min_display_c < max_display_c")?;
        require(
            self.min_display_c < self.dose_lockout_max_c(),
            "min_display_c < 43 - dose_lockout_margin_c (the maximum after a dose lockout)",
        )?;
        require(
            self.sensor_short_c < self.plausible_min_c,
            "sensor_short_c < plausible_min_c",
        )?;
        require(
            self.plausible_min_c < self.min_display_c - self.limit_margin_c,
            "plausible_min_c < min_display_c - limit_margin_c",
        )?;
        require(
            self.max_display_c + self.limit_margin_c < self.plausible_max_c,
            "max_display_c + limit_margin_c < plausible_max_c",
        )?;
        require(
            self.plausible_max_c < self.sensor_open_c,
            "plausible_max_c < sensor_open_c",
        )?;
        require(
            self.max_setpoint_rate_c_per_s < self.max_measured_rate_c_per_s,
            "max_setpoint_rate_c_per_s < max_measured_rate_c_per_s",
        )?;
        require(
            self.hot_side_min_c < self.hot_side_max_c,
            "hot_side_min_c < hot_side_max_c",
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid_and_matches_the_sources() {
        let c = EnvelopeConfig::default();
        c.validate().unwrap();
        assert_eq!((c.min_display_c, c.max_display_c), (15.0, 48.0));
        assert_eq!(c.max_setpoint_rate_c_per_s, 10.0);
        assert_eq!(c.max_time_at_or_above_43_s, 600.0);
        assert_eq!(c.dose_lockout_max_c(), 42.5);
    }

    #[test]
    fn wider_than_absolute_is_an_error_not_a_clamp() {
        let hot = EnvelopeConfig {
            max_display_c: 48.5,
            ..Default::default()
        };
        assert!(matches!(
            hot.validate(),
            Err(EnvelopeError::BadValue(ref e)) if e.name == "max_display_c"
        ));
        let cold = EnvelopeConfig {
            min_display_c: 9.0,
            ..Default::default()
        };
        assert!(matches!(
            cold.validate(),
            Err(EnvelopeError::BadValue(ref e)) if e.name == "min_display_c"
        ));
        let fast = EnvelopeConfig {
            max_setpoint_rate_c_per_s: 301.0,
            max_measured_rate_c_per_s: 900.0,
            ..Default::default()
        };
        assert!(matches!(fast.validate(), Err(EnvelopeError::BadValue(_))));
        // Up to 300 °C/s is allowed, as long as the measured-rate plausibility bound stays above it.
        let quick = EnvelopeConfig {
            max_setpoint_rate_c_per_s: ABSOLUTE_MAX_RATE_C_PER_S,
            max_measured_rate_c_per_s: ABSOLUTE_MAX_MEASURED_RATE_C_PER_S,
            ..Default::default()
        };
        quick.validate().unwrap();
        let implausible = EnvelopeConfig {
            max_setpoint_rate_c_per_s: 60.0,
            ..Default::default()
        };
        assert!(matches!(
            implausible.validate(),
            Err(EnvelopeError::Inconsistent { requirement }) if requirement.contains("max_measured_rate")
        ));
        let long = EnvelopeConfig {
            max_time_at_or_above_43_s: 601.0,
            ..Default::default()
        };
        assert!(matches!(long.validate(), Err(EnvelopeError::BadValue(_))));
        let nan = EnvelopeConfig {
            cem43_budget_min: f64::NAN,
            ..Default::default()
        };
        assert!(matches!(nan.validate(), Err(EnvelopeError::BadValue(_))));
        let swapped = EnvelopeConfig {
            min_display_c: 40.0,
            max_display_c: 30.0,
            ..Default::default()
        };
        assert!(matches!(swapped.validate(), Err(EnvelopeError::Inconsistent { .. })));
        let narrower = EnvelopeConfig {
            min_display_c: 20.0,
            max_display_c: 40.0,
            ..Default::default()
        };
        narrower.validate().unwrap();
    }

    #[test]
    fn partial_toml_keeps_defaults_and_unknown_keys_are_refused() {
        let c = EnvelopeConfig::from_toml_str("max_display_c = 42.0\nstale_timeout_s = 0.1\n", "e.toml").unwrap();
        assert_eq!(c.max_display_c, 42.0);
        assert_eq!(c.stale_timeout_s, 0.1);
        assert_eq!(c.min_display_c, 15.0);
        assert!(matches!(
            EnvelopeConfig::from_toml_str("max_display = 42.0\n", "e.toml"),
            Err(ParamError::UnknownKey { key, .. }) if key == "max_display"
        ));
        let hot = EnvelopeConfig::from_toml_str("max_display_c = 49\n", "e.toml")
            .map(|_| ())
            .unwrap_err();
        assert_eq!(hot.bad_key(), Some("max_display_c"));
        assert!(hot.to_string().starts_with("e.toml: `max_display_c` = 49"), "{hot}");
        let swapped = EnvelopeConfig::from_toml_str("min_display_c = 40\nmax_display_c = 30\n", "e.toml");
        assert!(matches!(swapped, Err(ParamError::Invalid { .. })), "{swapped:?}");
        let back = EnvelopeConfig::from_toml_str(&toml::to_string(&c).unwrap(), "back.toml").unwrap();
        assert_eq!(back, c);
    }
}
