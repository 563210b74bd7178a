//! First-order low-pass filter with exact discretisation, as used on the sensor signal in the paper's controller
//! (section 3.2, Figure 2: "a low pass filter was integrated" against sensor noise).
//!
//! Continuous model: `τ dy/dt = x − y` with `τ = 1 / (2π f_c)`. With the input held constant over a step of length
//! `dt` (zero-order hold) the exact update is `y ← y + α (x − y)`, `α = 1 − exp(−2π f_c dt)`, so a unit step is
//! followed exactly by `1 − exp(−t/τ)` for any (also varying) step length.

use std::f64::consts::TAU;

use thermode_model::{BadValue, Rule};

use crate::error::ControlError;

/// First-order low-pass filter. The first sample after construction or [`LowPass::reset`] initialises the output
/// to that sample (no start-up transient); [`LowPass::reset_to`] presets it.
#[derive(Debug, Clone, PartialEq)]
pub struct LowPass {
    cutoff_hz: f64,
    state: Option<f64>,
}

impl LowPass {
    /// A filter with corner frequency `cutoff_hz` (Hz, > 0). `f64::INFINITY` is allowed and means "no filtering"
    /// (α = 1). NaN, zero or negative cut-offs are errors.
    pub fn new(cutoff_hz: f64) -> Result<Self, ControlError> {
        // Not `Rule::Positive`: an infinite cut-off is allowed.
        if cutoff_hz.is_nan() || cutoff_hz <= 0.0 {
            return Err(ControlError::BadValue(BadValue::custom(
                "filter_cutoff_hz",
                cutoff_hz,
                "must be > 0 (use inf for no filtering)",
            )));
        }
        Ok(Self { cutoff_hz, state: None })
    }

    /// The corner frequency in Hz.
    pub fn cutoff_hz(&self) -> f64 {
        self.cutoff_hz
    }

    /// The time constant `τ = 1/(2π f_c)` in s (0 for an infinite cut-off).
    pub fn time_constant_s(&self) -> f64 {
        1.0 / (TAU * self.cutoff_hz)
    }

    /// The smoothing factor `α = 1 − exp(−2π f_c dt)` for a step of `dt_s` seconds.
    pub fn alpha(&self, dt_s: f64) -> f64 {
        -(-TAU * self.cutoff_hz * dt_s).exp_m1()
    }

    /// Feeds one sample `x` (held over the last `dt_s` seconds) and returns the filtered value. `x` must be finite
    /// and `dt_s` finite and > 0; otherwise the state is left untouched and an error returned.
    pub fn update(&mut self, x: f64, dt_s: f64) -> Result<f64, ControlError> {
        Rule::Finite.check("sample", x)?;
        Rule::Positive.check("dt_s", dt_s)?;
        let y = match self.state {
            None => x,
            Some(y) => y + self.alpha(dt_s) * (x - y),
        };
        self.state = Some(y);
        Ok(y)
    }

    /// The last filtered value (`None` before the first sample).
    pub fn value(&self) -> Option<f64> {
        self.state
    }

    /// Forgets the state: the next sample initialises the output.
    pub fn reset(&mut self) {
        self.state = None;
    }

    /// Presets the output to `value` (must be finite), e.g. to start a step response from a known state.
    pub fn reset_to(&mut self, value: f64) -> Result<(), ControlError> {
        Rule::Finite.check("reset value", value)?;
        self.state = Some(value);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit step from 0: after n steps the output must equal the analytic `1 − exp(−t/τ)` to 1e-12, with a fixed
    /// and with an irregular step length.
    #[test]
    fn step_response_matches_analytic_exponential() {
        let mut f = LowPass::new(2.0).unwrap();
        let tau = f.time_constant_s();
        assert!((tau - 1.0 / (4.0 * std::f64::consts::PI)).abs() < 1e-15, "tau {tau}");
        f.reset_to(0.0).unwrap();
        let mut t = 0.0;
        for k in 0..2000 {
            // irregular steps between 0.5 ms and 3.5 ms
            let dt = 0.5e-3 + 3e-3 * ((k * 7919) % 13) as f64 / 13.0;
            t += dt;
            let got = f.update(1.0, dt).unwrap();
            let want = 1.0 - (-t / tau).exp();
            assert!((got - want).abs() < 1e-12, "t = {t}: filter {got} vs analytic {want}");
        }
    }

    #[test]
    fn first_sample_initialises_and_infinite_cutoff_passes_through() {
        let mut f = LowPass::new(1.0).unwrap();
        assert_eq!(f.value(), None);
        assert_eq!(f.update(33.0, 1e-3).unwrap(), 33.0);
        let mut pass = LowPass::new(f64::INFINITY).unwrap();
        pass.update(1.0, 1e-3).unwrap();
        assert_eq!(pass.update(5.0, 1e-3).unwrap(), 5.0);
    }

    #[test]
    fn bad_parameters_and_inputs_are_errors_and_leave_state() {
        for bad in [0.0, -1.0, f64::NAN] {
            assert!(
                matches!(LowPass::new(bad), Err(ControlError::BadValue(ref e)) if e.name == "filter_cutoff_hz"),
                "{bad}"
            );
        }
        let mut f = LowPass::new(1.0).unwrap();
        f.update(20.0, 0.01).unwrap();
        assert!(f.update(f64::NAN, 0.01).is_err());
        assert!(f.update(1.0, 0.0).is_err());
        assert!(f.update(1.0, -0.01).is_err());
        assert!(f.update(1.0, f64::INFINITY).is_err());
        assert_eq!(f.value(), Some(20.0));
    }
}
