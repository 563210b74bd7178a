//! The `[stimulus]` table shared by the yes/no procedures (levels, staircase, QUEST+): a trapezoid from the
//! baseline, whose amplitude the procedure chooses.

use serde::{Deserialize, Serialize};
use thermode_model::params::Rule;

use crate::plan::{Direction, TrialPlan, RAMP_RATE};
use crate::ProcedureError;

/// A trapezoidal stimulus of chosen amplitude: ramp, plateau, return, pause.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StimulusConfig {
    /// The baseline \[°C\]. Default 32.
    pub baseline_c: f64,
    /// Cooling or warming. Default `cold`.
    pub direction: Direction,
    /// The ramp's rate \[°C/s\] (the safety envelope's rate limit by default). Default 10.
    #[serde(rename = "rate_c_s")]
    pub rate_c_per_s: f64,
    /// The plateau \[s\]. Default 1.
    pub plateau_s: f64,
    /// The return ramp's rate \[°C/s\]. Default 10.
    #[serde(rename = "return_rate_c_s")]
    pub return_rate_c_per_s: f64,
    /// The pause after the trial, while the participant answers \[s\]. Default 5.
    pub isi_s: f64,
    /// The largest amplitude a procedure may ask for \[°C\]. Default 10.
    pub max_amplitude_c: f64,
}

impl Default for StimulusConfig {
    fn default() -> Self {
        StimulusConfig {
            baseline_c: 32.0,
            direction: Direction::Cold,
            rate_c_per_s: 10.0,
            plateau_s: 1.0,
            return_rate_c_per_s: 10.0,
            isi_s: 5.0,
            max_amplitude_c: 10.0,
        }
    }
}

impl StimulusConfig {
    /// Checks every value (key names as in the experiment file).
    pub fn validate(&self) -> Result<(), ProcedureError> {
        Rule::Within { min: 20.0, max: 40.0 }.check("stimulus.baseline_c", self.baseline_c)?;
        RAMP_RATE.check("stimulus.rate_c_s", self.rate_c_per_s)?;
        Rule::Within { min: 0.0, max: 600.0 }.check("stimulus.plateau_s", self.plateau_s)?;
        RAMP_RATE.check("stimulus.return_rate_c_s", self.return_rate_c_per_s)?;
        Rule::Within { min: 0.0, max: 3600.0 }.check("stimulus.isi_s", self.isi_s)?;
        Rule::PositiveUpTo { max: 30.0 }.check("stimulus.max_amplitude_c", self.max_amplitude_c)?;
        Ok(())
    }

    /// The trial plan of a trapezoid of amplitude `amplitude_c` \[°C, a magnitude, clamped to 0–`max_amplitude_c`\].
    pub fn trial(&self, index: usize, label: &str, amplitude_c: f64) -> TrialPlan {
        let amplitude = amplitude_c.clamp(0.0, self.max_amplitude_c);
        TrialPlan {
            index,
            label: label.to_string(),
            run: index + 1,
            baseline_c: self.baseline_c,
            intensity_c: self.direction.sign() * amplitude,
            rate_c_per_s: self.rate_c_per_s,
            until_response: false,
            plateau_s: self.plateau_s,
            return_c: Some(self.baseline_c),
            return_rate_c_per_s: self.return_rate_c_per_s,
            isi_s: self.isi_s,
            pain: false,
            continues_previous: false,
        }
    }
}
