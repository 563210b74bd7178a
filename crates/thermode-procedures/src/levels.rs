//! The method of levels (Yarnitsky & Ochoa 1990): trapezoids of fixed amplitude, a yes/no answer after each, and
//! a bisection of the amplitude. The amplitude goes down after a "yes" and up after a "no" by the current step; the
//! step is halved whenever the answer changes (a reversal), down to `min_step_c`. The participant's reaction time
//! does not enter (the answer comes after the stimulus), which removes the method of limits' rate artefact.
//!
//! The estimate is the mean amplitude of the last `average_last` trials (default 20; the bisection has by then narrowed to the
//! threshold and oscillates around it at the smallest step).

use serde::{Deserialize, Serialize};
use thermode_model::params::Rule;

use crate::plan::{Procedure, Response, TrialPlan};
use crate::stimulus::StimulusConfig;
use crate::ProcedureError;

/// The `[levels]` table of an experiment file.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LevelsConfig {
    /// The first amplitude \[°C of change from the baseline\]. Default 1.
    pub start_c: f64,
    /// The first step \[°C\]. Default 1.
    pub step_c: f64,
    /// The smallest step \[°C\]. Default 0.05.
    pub min_step_c: f64,
    /// Trials in the session. Default 30.
    pub trials: usize,
    /// The estimate averages this many last amplitudes. Default 20.
    pub average_last: usize,
}

impl Default for LevelsConfig {
    fn default() -> Self {
        LevelsConfig {
            start_c: 1.0,
            step_c: 1.0,
            min_step_c: 0.05,
            trials: 30,
            average_last: 20,
        }
    }
}

impl LevelsConfig {
    /// Checks every value (key names as in the experiment file).
    pub fn validate(&self) -> Result<(), ProcedureError> {
        Rule::PositiveUpTo { max: 30.0 }.check("levels.start_c", self.start_c)?;
        Rule::PositiveUpTo { max: 30.0 }.check("levels.step_c", self.step_c)?;
        Rule::Within {
            min: 1e-4,
            max: self.step_c,
        }
        .check("levels.min_step_c", self.min_step_c)?;
        Rule::Within {
            min: 1.0,
            max: 10_000.0,
        }
        .check("levels.trials", self.trials as f64)?;
        let up_to_trials = Rule::Within {
            min: 1.0,
            max: self.trials as f64,
        };
        up_to_trials.check("levels.average_last", self.average_last as f64)?;
        Ok(())
    }
}

/// The method of levels as a state machine.
#[derive(Debug, Clone)]
pub struct Levels {
    config: LevelsConfig,
    stimulus: StimulusConfig,
    amplitude_c: f64,
    step_c: f64,
    amplitudes: Vec<f64>,
    answers: Vec<bool>,
    pending: Option<TrialPlan>,
}

impl Levels {
    /// The procedure for `config`, presenting trapezoids of `stimulus`.
    pub fn new(config: LevelsConfig, stimulus: StimulusConfig) -> Result<Self, ProcedureError> {
        config.validate()?;
        stimulus.validate()?;
        Ok(Levels {
            amplitude_c: config.start_c,
            step_c: config.step_c,
            config,
            stimulus,
            amplitudes: Vec::new(),
            answers: Vec::new(),
            pending: None,
        })
    }

    /// The amplitudes presented so far \[°C\].
    pub fn amplitudes(&self) -> &[f64] {
        &self.amplitudes
    }
}

impl Procedure for Levels {
    fn next_trial(&mut self) -> Option<TrialPlan> {
        if self.pending.is_none() {
            if self.amplitudes.len() >= self.config.trials {
                return None;
            }
            let index = self.amplitudes.len();
            self.pending = Some(self.stimulus.trial(index, "levels", self.amplitude_c));
        }
        self.pending.clone()
    }

    fn record(&mut self, response: Response) -> Result<(), ProcedureError> {
        self.pending.take().ok_or(ProcedureError::NoTrialPending)?;
        let yes = response.detected;
        if self.answers.last().is_some_and(|&last| last != yes) {
            self.step_c = (0.5 * self.step_c).max(self.config.min_step_c);
        }
        self.amplitudes.push(self.amplitude_c);
        self.answers.push(yes);
        let next = if yes {
            self.amplitude_c - self.step_c
        } else {
            self.amplitude_c + self.step_c
        };
        self.amplitude_c = next.clamp(self.config.min_step_c, self.stimulus.max_amplitude_c);
        Ok(())
    }

    fn estimate_c(&self) -> Option<f64> {
        let n = self.amplitudes.len().min(self.config.average_last);
        if n == 0 {
            return None;
        }
        let last = &self.amplitudes[self.amplitudes.len() - n..];
        Some(last.iter().sum::<f64>() / n as f64)
    }
}
