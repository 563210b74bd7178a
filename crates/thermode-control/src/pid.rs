//! The paper's controller: a PID acting on the (low-pass filtered) display sensor (section 3.2, Figure 2).
//!
//! Sign convention of the whole crate: a **positive current heats the display**. The error is
//! `e = setpoint − measured`, so a display colder than its set-point (e > 0) gets a heating (positive) current.
//!
//! - P acts on the error, I integrates the error, D acts on the **measurement** only (`D = −K_d dy/dt`), so a
//!   set-point step causes no derivative kick. The derivative can be smoothed by a first-order filter of time
//!   constant `derivative_filter_s` (exact discretisation).
//! - The integral is stored as a current (A), so changing `K_i` between ticks does not bump the output.
//! - Output limits `±output_limit_a`.
//! - Anti-windup by **conditional integration** (clamping): the integral is not advanced on a tick where the
//!   unsaturated output already exceeds a limit and the error would push it further out; in addition the integral
//!   term itself is bounded to `±output_limit_a`. [`AntiWindup::Off`] exists only to demonstrate the difference.
//! - [`Pid::reset`] forgets everything; [`Pid::reset_bumpless`] preloads the integral so that the next output
//!   continues from a given current (bumpless transfer, e.g. after a fault is cleared or a controller switch).
//! - The last P, I and D terms are kept for logging ([`Pid::terms`]).

use serde::Serialize;

use crate::error::ControlError;
use thermode_model::params::{self, Rule, Table};
use thermode_model::ParamError;

/// PID gains and the sensor filter cut-off, as saved to / loaded from a gains TOML file. Units: current in A,
/// temperature in °C (kelvin-sized), time in s. Read with [`PidGains::from_toml_str`] (unknown keys are refused);
/// written with serde.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PidGains {
    /// Proportional gain, A/°C (≥ 0). No default: tuned per display (`thermode tune`).
    pub kp_a_per_c: f64,
    /// Integral gain, A/(°C·s) (≥ 0). No default: tuned per display.
    pub ki_a_per_c_s: f64,
    /// Derivative gain, A·s/°C (≥ 0), applied to the measurement. No default: tuned per display.
    pub kd_a_s_per_c: f64,
    /// Corner frequency of the sensor low-pass filter in front of the PID, Hz (> 0; `inf` = no filter).
    /// No default: tuned per display.
    pub filter_cutoff_hz: f64,
    /// Optional time constant of an extra first-order filter on the derivative term, s (≥ 0; absent or 0 = none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub derivative_filter_s: Option<f64>,
}

impl PidGains {
    /// Reads a gains file (TOML, the keys of [`PidGains`]; `derivative_filter_s` optional, every other key
    /// required) with [`Table`] and validates it ([`PidGains::validate`]); `origin` (the file name) appears in
    /// every error, a refused number as a [`ParamError::BadValue`].
    pub fn from_toml_str(text: &str, origin: &str) -> Result<PidGains, ParamError> {
        let toml = params::parse(text, origin)?;
        let file = Table::new(&toml, origin);
        let gains = PidGains {
            kp_a_per_c: file.required_number("kp_a_per_c", Rule::NonNegative)?,
            ki_a_per_c_s: file.required_number("ki_a_per_c_s", Rule::NonNegative)?,
            kd_a_s_per_c: file.required_number("kd_a_s_per_c", Rule::NonNegative)?,
            // Not range-checked here: `inf` (no filter) is allowed; `validate` checks it.
            filter_cutoff_hz: file
                .unchecked_number("filter_cutoff_hz")?
                .ok_or_else(|| file.missing("filter_cutoff_hz"))?,
            derivative_filter_s: file.number("derivative_filter_s", Rule::NonNegative)?,
        };
        file.finish()?;
        let ControlError::BadValue(refused) = match gains.validate() {
            Ok(()) => return Ok(gains),
            Err(e) => e,
        };
        Err(ParamError::bad_value(origin, refused))
    }

    /// Checks every gain: finite and ≥ 0; the cut-off > 0 (may be `inf`); the derivative filter finite and ≥ 0.
    pub fn validate(&self) -> Result<(), ControlError> {
        Rule::NonNegative.check("kp_a_per_c", self.kp_a_per_c)?;
        Rule::NonNegative.check("ki_a_per_c_s", self.ki_a_per_c_s)?;
        Rule::NonNegative.check("kd_a_s_per_c", self.kd_a_s_per_c)?;
        if let Some(tf) = self.derivative_filter_s {
            Rule::NonNegative.check("derivative_filter_s", tf)?;
        }
        crate::filter::LowPass::new(self.filter_cutoff_hz).map(|_| ())
    }
}

/// Which anti-windup scheme the PID uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AntiWindup {
    /// Conditional integration plus a bound of the integral term to the output limits (the default).
    #[default]
    ConditionalIntegration,
    /// No anti-windup at all: the integral grows without bound under saturation. For comparison only.
    Off,
}

/// The terms of the last PID update, for logging. All in A.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PidTerms {
    /// Proportional term `K_p e`, A.
    pub p_a: f64,
    /// Integral term (after this tick's integration), A.
    pub i_a: f64,
    /// Derivative term `−K_d dy/dt` (filtered), A.
    pub d_a: f64,
    /// Output after limiting, A.
    pub output_a: f64,
    /// Whether the output was limited on this tick.
    pub saturated: bool,
}

/// A PID controller with derivative on measurement, output limits and anti-windup. See the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct Pid {
    gains: PidGains,
    output_limit_a: f64,
    anti_windup: AntiWindup,
    integral_a: f64,
    prev_measured_c: Option<f64>,
    derivative_a: f64,
    /// The derivative filter's weight for the last tick length: (dt \[s\], 1 − e^(−dt/T_f)), renewed only when the
    /// length changes (a loop's ticks are mostly equal; (0, 0) before the first filtered tick).
    filter_weight: (f64, f64),
    terms: PidTerms,
}

impl Pid {
    /// A PID with the given gains and output limits `±output_limit_a` (A, finite, > 0).
    pub fn new(gains: PidGains, output_limit_a: f64) -> Result<Self, ControlError> {
        gains.validate()?;
        Rule::Positive.check("output_limit_a", output_limit_a)?;
        Ok(Self {
            gains,
            output_limit_a,
            anti_windup: AntiWindup::default(),
            integral_a: 0.0,
            prev_measured_c: None,
            derivative_a: 0.0,
            filter_weight: (0.0, 0.0),
            terms: PidTerms::default(),
        })
    }

    /// The same PID with another anti-windup scheme.
    pub fn with_anti_windup(mut self, anti_windup: AntiWindup) -> Self {
        self.anti_windup = anti_windup;
        self
    }

    /// The gains in use.
    pub fn gains(&self) -> &PidGains {
        &self.gains
    }

    /// Replaces the gains without a bump (the integral is kept as a current).
    pub fn set_gains(&mut self, gains: PidGains) -> Result<(), ControlError> {
        gains.validate()?;
        self.gains = gains;
        self.filter_weight = (0.0, 0.0);
        Ok(())
    }

    /// The output limit in A (the output lies in `[−limit, +limit]`).
    pub fn output_limit_a(&self) -> f64 {
        self.output_limit_a
    }

    /// The terms of the last update (all zero before the first).
    pub fn terms(&self) -> PidTerms {
        self.terms
    }

    /// One controller step: `setpoint_c` and `measured_c` in °C, `dt_s` > 0 the time since the last step. Returns
    /// the current in A (positive heats), within the output limits. Non-finite inputs or a non-positive step are
    /// errors and leave the state untouched.
    pub fn update(&mut self, setpoint_c: f64, measured_c: f64, dt_s: f64) -> Result<f64, ControlError> {
        Rule::Finite.check("setpoint_c", setpoint_c)?;
        Rule::Finite.check("measured_c", measured_c)?;
        Rule::Positive.check("dt_s", dt_s)?;
        let limit = self.output_limit_a;
        let error_c = setpoint_c - measured_c;
        let p_a = self.gains.kp_a_per_c * error_c;
        let d_a = self.derivative(measured_c, dt_s);
        let step_a = self.gains.ki_a_per_c_s * error_c * dt_s;
        let mut i_a = self.integral_a + step_a;
        if self.anti_windup == AntiWindup::ConditionalIntegration {
            let unsaturated = p_a + i_a + d_a;
            let winding_up = (unsaturated > limit && step_a > 0.0) || (unsaturated < -limit && step_a < 0.0);
            if winding_up {
                i_a = self.integral_a;
            }
            i_a = i_a.clamp(-limit, limit);
        }
        let raw = p_a + i_a + d_a;
        let output_a = raw.clamp(-limit, limit);
        self.integral_a = i_a;
        self.prev_measured_c = Some(measured_c);
        self.terms = PidTerms {
            p_a,
            i_a,
            d_a,
            output_a,
            saturated: output_a != raw,
        };
        Ok(output_a)
    }

    /// Derivative term on the measurement, optionally filtered; zero on the first sample after a reset.
    fn derivative(&mut self, measured_c: f64, dt_s: f64) -> f64 {
        let raw_a = match self.prev_measured_c {
            None => 0.0,
            Some(prev) => -self.gains.kd_a_s_per_c * (measured_c - prev) / dt_s,
        };
        self.derivative_a = match self.gains.derivative_filter_s {
            Some(tf) if tf > 0.0 && self.prev_measured_c.is_some() => {
                if self.filter_weight.0 != dt_s {
                    self.filter_weight = (dt_s, -(-dt_s / tf).exp_m1());
                }
                self.derivative_a + self.filter_weight.1 * (raw_a - self.derivative_a)
            }
            _ => raw_a,
        };
        self.derivative_a
    }

    /// Forgets all state: integral 0, no derivative memory (the next sample gives no derivative kick).
    pub fn reset(&mut self) {
        self.integral_a = 0.0;
        self.prev_measured_c = None;
        self.derivative_a = 0.0;
        self.terms = PidTerms::default();
    }

    /// Bumpless reset: preloads the integral so that, for the same set-point and measurement, the next output is
    /// `output_a` (clamped to the limits), and sets the derivative memory to `measured_c`. Inputs must be finite.
    pub fn reset_bumpless(&mut self, setpoint_c: f64, measured_c: f64, output_a: f64) -> Result<(), ControlError> {
        Rule::Finite.check("setpoint_c", setpoint_c)?;
        Rule::Finite.check("measured_c", measured_c)?;
        Rule::Finite.check("output_a", output_a)?;
        let limit = self.output_limit_a;
        let p_a = self.gains.kp_a_per_c * (setpoint_c - measured_c);
        self.integral_a = (output_a.clamp(-limit, limit) - p_a).clamp(-limit, limit);
        self.prev_measured_c = Some(measured_c);
        self.derivative_a = 0.0;
        Ok(())
    }
}
