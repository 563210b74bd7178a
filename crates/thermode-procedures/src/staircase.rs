//! The n-up/m-down staircase, with exactly the rules of PsychoPy's `StairHandler` (psychopy/data/staircase.py),
//! so that for the same responses it presents the same sequence of intensities:
//!
//! - A response counts in a signed run counter: a "yes" (1) after a "yes" adds 1, else sets it to 1; a "no" (0)
//!   after a "no" subtracts 1, else sets it to −1 (the previous *response*, not the previous trial's step, decides).
//! - Until the first reversal, with `apply_initial_rule` (default true), the rule is 1-up/1-down: a yes goes down, a
//!   no goes up; a change of direction is a reversal, and the trial that makes the first reversal still steps by
//!   this rule.
//! - Afterwards the counter at `n_down` or more goes down, at `-n_up` or less goes up; otherwise the intensity stays.
//!   A direction change (from up to down or back; the start counts as neither) is a reversal.
//! - Every step (up or down) resets the counter to 0.
//! - A reversal records the trial index and its intensity; with several `step_sizes` the step becomes
//!   `step_sizes[number of reversals]`, the last one once the list is exhausted.
//! - Steps: `lin` adds or subtracts the step; `db` multiplies or divides by 10^(step/20); `log` by 10^step. Going up
//!   is clipped to `max_val`, going down to `min_val`.
//! - `n_reversals` defaults to the number of step sizes and is raised to it when smaller. The staircase has finished
//!   when it has at least `n_reversals` reversals and at least `n_trials` trials.
//!
//! Not in PsychoPy: `max_trials` ends a staircase that would otherwise run for ever; the estimate is the mean of the
//! last `estimate_reversals` reversal intensities (what PsychoPy's demos compute).

use serde::{Deserialize, Serialize};
use thermode_model::params::Rule;

use crate::plan::{Procedure, Response, TrialPlan};
use crate::stimulus::StimulusConfig;
use crate::ProcedureError;

/// How a staircase step changes the intensity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StepType {
    /// Add or subtract the step \[°C\].
    Lin,
    /// Multiply or divide by 10^(step/20).
    Db,
    /// Multiply or divide by 10^step.
    Log,
}

/// The `[staircase]` table of an experiment file (PsychoPy's `StairHandler` arguments, in snake case).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StaircaseConfig {
    /// The first intensity \[°C of change from the baseline\] (`startVal`). Default 2.
    pub start_val: f64,
    /// The step sizes, one per reversal, the last repeated (`stepSizes`). Default `[0.4, 0.2, 0.1, 0.05]`.
    pub step_sizes: Vec<f64>,
    /// `lin`, `db` or `log` (`stepType`). Default `lin`.
    pub step_type: StepType,
    /// "No" responses in a run before going up (`nUp`). Default 1.
    pub n_up: u32,
    /// "Yes" responses in a run before going down (`nDown`). Default 1.
    pub n_down: u32,
    /// Minimum number of reversals (`nReversals`); default the number of step sizes.
    pub n_reversals: Option<usize>,
    /// Minimum number of trials (`nTrials`). Default 30.
    pub n_trials: usize,
    /// 1-up/1-down until the first reversal (`applyInitialRule`). Default true.
    pub apply_initial_rule: bool,
    /// The smallest intensity (`minVal`) \[°C\]. Default 0.01.
    pub min_val: Option<f64>,
    /// The largest intensity (`maxVal`) \[°C\]. Default 10.
    pub max_val: Option<f64>,
    /// Not PsychoPy's: the staircase ends after this many trials whatever its reversals. Default 200.
    pub max_trials: usize,
    /// Not PsychoPy's: the estimate is the mean of this many last reversal intensities. Default 6.
    pub estimate_reversals: usize,
}

impl Default for StaircaseConfig {
    fn default() -> Self {
        StaircaseConfig {
            start_val: 2.0,
            step_sizes: vec![0.4, 0.2, 0.1, 0.05],
            step_type: StepType::Lin,
            n_up: 1,
            n_down: 1,
            n_reversals: None,
            n_trials: 30,
            apply_initial_rule: true,
            min_val: Some(0.01),
            max_val: Some(10.0),
            max_trials: 200,
            estimate_reversals: 6,
        }
    }
}

impl StaircaseConfig {
    /// Checks every value (key names as in the experiment file).
    pub fn validate(&self) -> Result<(), ProcedureError> {
        Rule::Finite.check("staircase.start_val", self.start_val)?;
        if self.step_sizes.is_empty() || self.step_sizes.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(ProcedureError::invalid(
                "staircase.step_sizes",
                format!("{:?}", self.step_sizes),
                "a non-empty list of positive numbers",
            ));
        }
        let count = Rule::AtLeast { min: 1.0 };
        count.check("staircase.n_up", self.n_up as f64)?;
        count.check("staircase.n_down", self.n_down as f64)?;
        count.check("staircase.max_trials", self.max_trials as f64)?;
        count.check("staircase.estimate_reversals", self.estimate_reversals as f64)?;
        Ok(())
    }
}

/// Where the staircase last went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Heading {
    Start,
    Up,
    Down,
}

/// The staircase's state, mirroring `StairHandler`'s attributes.
#[derive(Debug, Clone)]
pub struct Staircase {
    config: StaircaseConfig,
    stimulus: StimulusConfig,
    n_reversals: usize,
    step_current: f64,
    next_intensity: f64,
    intensities: Vec<f64>,
    data: Vec<bool>,
    reversal_points: Vec<usize>,
    reversal_intensities: Vec<f64>,
    heading: Heading,
    correct_counter: i64,
    initial_rule: bool,
    finished: bool,
    pending: Option<TrialPlan>,
}

impl Staircase {
    /// A staircase for `config` presenting trapezoids of `stimulus`.
    pub fn new(config: StaircaseConfig, stimulus: StimulusConfig) -> Result<Self, ProcedureError> {
        config.validate()?;
        stimulus.validate()?;
        let n_reversals = config.n_reversals.unwrap_or(0).max(config.step_sizes.len());
        Ok(Staircase {
            n_reversals,
            step_current: config.step_sizes[0],
            next_intensity: config.start_val,
            config,
            stimulus,
            intensities: Vec::new(),
            data: Vec::new(),
            reversal_points: Vec::new(),
            reversal_intensities: Vec::new(),
            heading: Heading::Start,
            correct_counter: 0,
            initial_rule: false,
            finished: false,
            pending: None,
        })
    }

    /// The intensities presented so far (`intensities`).
    pub fn intensities(&self) -> &[f64] {
        &self.intensities
    }

    /// The trials (0-based) at which the staircase reversed (`reversalPoints`).
    pub fn reversal_points(&self) -> &[usize] {
        &self.reversal_points
    }

    /// The intensities at the reversals (`reversalIntensities`).
    pub fn reversal_intensities(&self) -> &[f64] {
        &self.reversal_intensities
    }

    /// Whether the staircase has finished (`finished`, or `max_trials` reached).
    pub fn finished(&self) -> bool {
        self.finished || self.intensities.len() >= self.config.max_trials
    }

    /// Presents the next intensity (`__next__`): `None` once finished.
    pub fn next_intensity(&mut self) -> Option<f64> {
        if self.finished() {
            return None;
        }
        self.intensities.push(self.next_intensity);
        Some(self.next_intensity)
    }

    /// Records a yes (1) or no (0) for the last presented intensity (`addResponse`).
    pub fn add_response(&mut self, yes: bool) {
        let same_as_previous = self.data.last() == Some(&yes);
        self.data.push(yes);
        self.correct_counter = match (yes, same_as_previous) {
            (true, true) => self.correct_counter + 1,
            (true, false) => 1,
            (false, true) => self.correct_counter - 1,
            (false, false) => -1,
        };
        self.calculate_next_intensity(yes);
    }

    fn calculate_next_intensity(&mut self, yes: bool) {
        let initial_phase = self.reversal_intensities.is_empty() && self.config.apply_initial_rule;
        let going = if initial_phase {
            Some(if yes { Heading::Down } else { Heading::Up })
        } else if self.correct_counter >= i64::from(self.config.n_down) {
            Some(Heading::Down)
        } else if self.correct_counter <= -i64::from(self.config.n_up) {
            Some(Heading::Up)
        } else {
            None
        };
        let reversal = match going {
            Some(to) => {
                let reversed = self.heading != Heading::Start && self.heading != to;
                self.heading = to;
                reversed
            }
            None => false,
        };
        if reversal {
            self.reversal_points.push(self.intensities.len() - 1);
            if self.reversal_intensities.is_empty() && self.config.apply_initial_rule {
                self.initial_rule = true;
            }
            let last = *self.intensities.last().unwrap_or(&self.next_intensity);
            self.reversal_intensities.push(last);
        }
        if self.reversal_intensities.len() >= self.n_reversals && self.intensities.len() >= self.config.n_trials {
            self.finished = true;
        }
        if reversal && self.config.step_sizes.len() > 1 {
            let n = self.reversal_intensities.len().min(self.config.step_sizes.len() - 1);
            self.step_current = self.config.step_sizes[n];
        }
        self.apply_step(yes);
    }

    fn apply_step(&mut self, yes: bool) {
        if (self.reversal_intensities.is_empty() || self.initial_rule) && self.config.apply_initial_rule {
            self.initial_rule = false;
            if yes {
                self.step_down();
            } else {
                self.step_up();
            }
        } else if self.correct_counter >= i64::from(self.config.n_down) {
            self.step_down();
        } else if self.correct_counter <= -i64::from(self.config.n_up) {
            self.step_up();
        }
    }

    fn factor(&self) -> f64 {
        match self.config.step_type {
            StepType::Lin => 0.0,
            StepType::Db => 10f64.powf(self.step_current / 20.0),
            StepType::Log => 10f64.powf(self.step_current),
        }
    }

    fn step_up(&mut self) {
        self.next_intensity = match self.config.step_type {
            StepType::Lin => self.next_intensity + self.step_current,
            _ => self.next_intensity * self.factor(),
        };
        if let Some(max) = self.config.max_val {
            if self.next_intensity > max {
                self.next_intensity = max;
            }
        }
        self.correct_counter = 0;
    }

    fn step_down(&mut self) {
        self.next_intensity = match self.config.step_type {
            StepType::Lin => self.next_intensity - self.step_current,
            _ => self.next_intensity / self.factor(),
        };
        self.correct_counter = 0;
        if let Some(min) = self.config.min_val {
            if self.next_intensity < min {
                self.next_intensity = min;
            }
        }
    }
}

impl Procedure for Staircase {
    fn next_trial(&mut self) -> Option<TrialPlan> {
        if self.pending.is_none() {
            let intensity = self.next_intensity()?;
            let index = self.intensities.len() - 1;
            self.pending = Some(self.stimulus.trial(index, "staircase", intensity));
        }
        self.pending.clone()
    }

    fn record(&mut self, response: Response) -> Result<(), ProcedureError> {
        self.pending.take().ok_or(ProcedureError::NoTrialPending)?;
        self.add_response(response.detected);
        Ok(())
    }

    /// The mean of the last `estimate_reversals` reversal intensities.
    fn estimate_c(&self) -> Option<f64> {
        let n = self.reversal_intensities.len().min(self.config.estimate_reversals);
        if n == 0 {
            return None;
        }
        let last = &self.reversal_intensities[self.reversal_intensities.len() - n..];
        Some(last.iter().sum::<f64>() / n as f64)
    }
}
