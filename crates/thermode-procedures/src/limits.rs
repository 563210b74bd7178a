//! The method of limits: the DFNS thermal tests (Rolke et al., Eur J Pain 10 (2006) 77–88). From a baseline
//! (32 °C) the plate ramps (1 °C/s) toward a cut-off (0 or 50 °C) until the participant presses; it then returns to
//! the baseline at 1 °C/s after a detection and 5 °C/s after a pain threshold. Each test is run `runs` times (3)
//! and averaged by the analysis (`crate::analysis`).
//!
//! - CDT, WDT: cold and warm detection thresholds (cooling, warming ramps).
//! - TSL: the thermal sensory limen, alternating warm and cold ramps, each starting where the previous one was
//!   stopped (no return between them); a run is one warm and one cold ramp, its limen their difference. A cold ramp
//!   felt as warm or hot is a paradoxical heat sensation (PHS), counted.
//! - CPT, HPT: cold and heat pain thresholds (cooling, warming ramps, pain asked for, fast return).

use serde::{Deserialize, Serialize};
use thermode_model::params::Rule;

use crate::plan::{Direction, Procedure, Response, TrialPlan, RAMP_RATE};
use crate::ProcedureError;

/// A DFNS thermal test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum LimitsTest {
    /// Cold detection threshold.
    #[serde(rename = "CDT")]
    Cdt,
    /// Warm detection threshold.
    #[serde(rename = "WDT")]
    Wdt,
    /// Thermal sensory limen (with the paradoxical heat sensations).
    #[serde(rename = "TSL")]
    Tsl,
    /// Cold pain threshold.
    #[serde(rename = "CPT")]
    Cpt,
    /// Heat pain threshold.
    #[serde(rename = "HPT")]
    Hpt,
}

impl LimitsTest {
    /// The DFNS abbreviation (`CDT`, `WDT`, `TSL`, `CPT`, `HPT`).
    pub fn name(self) -> &'static str {
        match self {
            LimitsTest::Cdt => "CDT",
            LimitsTest::Wdt => "WDT",
            LimitsTest::Tsl => "TSL",
            LimitsTest::Cpt => "CPT",
            LimitsTest::Hpt => "HPT",
        }
    }

    /// A test from its abbreviation (case-insensitive).
    pub fn from_name(name: &str) -> Option<Self> {
        [Self::Cdt, Self::Wdt, Self::Tsl, Self::Cpt, Self::Hpt]
            .into_iter()
            .find(|t| t.name().eq_ignore_ascii_case(name.trim()))
    }

    /// Whether the participant is asked for pain (CPT, HPT).
    pub fn is_pain(self) -> bool {
        matches!(self, LimitsTest::Cpt | LimitsTest::Hpt)
    }
}

/// The `[limits]` table of an experiment file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LimitsConfig {
    /// The tests, in order. Default `["CDT", "WDT", "TSL", "CPT", "HPT"]` (the DFNS order).
    pub tests: Vec<LimitsTest>,
    /// The baseline every ramp starts from \[°C\]. Default 32.
    pub baseline_c: f64,
    /// The ramps' rate \[°C/s\]. Default 1.
    #[serde(rename = "rate_c_s")]
    pub rate_c_per_s: f64,
    /// The return rate after a detection (CDT, WDT, TSL) \[°C/s\]. Default 1.
    #[serde(rename = "detection_return_rate_c_s")]
    pub detection_return_rate_c_per_s: f64,
    /// The return rate after a pain threshold (CPT, HPT) \[°C/s\]. Default 5.
    #[serde(rename = "pain_return_rate_c_s")]
    pub pain_return_rate_c_per_s: f64,
    /// The cooling ramps' cut-off \[°C\]. Default 0 (a display with a narrower range cuts off at its own limit).
    pub cold_cutoff_c: f64,
    /// The warming ramps' cut-off \[°C\]. Default 50 (likewise).
    pub heat_cutoff_c: f64,
    /// Runs of each test (TSL: warm–cold pairs). Default 3.
    pub runs: usize,
    /// The pause at the baseline after each returned ramp \[s\]. Default 10.
    pub isi_s: f64,
    /// The thermal sensory limen's first ramp. Default `warm`.
    pub tsl_first: Direction,
}

impl Default for LimitsConfig {
    fn default() -> Self {
        LimitsConfig {
            tests: vec![
                LimitsTest::Cdt,
                LimitsTest::Wdt,
                LimitsTest::Tsl,
                LimitsTest::Cpt,
                LimitsTest::Hpt,
            ],
            baseline_c: 32.0,
            rate_c_per_s: 1.0,
            detection_return_rate_c_per_s: 1.0,
            pain_return_rate_c_per_s: 5.0,
            cold_cutoff_c: 0.0,
            heat_cutoff_c: 50.0,
            runs: 3,
            isi_s: 10.0,
            tsl_first: Direction::Warm,
        }
    }
}

impl LimitsConfig {
    /// Checks every value (key names as in the experiment file).
    pub fn validate(&self) -> Result<(), ProcedureError> {
        if self.tests.is_empty() {
            return Err(ProcedureError::invalid(
                "limits.tests",
                "[]",
                "at least one of CDT, WDT, TSL, CPT, HPT",
            ));
        }
        Rule::Within { min: 20.0, max: 40.0 }.check("limits.baseline_c", self.baseline_c)?;
        RAMP_RATE.check("limits.rate_c_s", self.rate_c_per_s)?;
        RAMP_RATE.check("limits.detection_return_rate_c_s", self.detection_return_rate_c_per_s)?;
        RAMP_RATE.check("limits.pain_return_rate_c_s", self.pain_return_rate_c_per_s)?;
        Rule::Within {
            min: -10.0,
            max: self.baseline_c - 0.1,
        }
        .check("limits.cold_cutoff_c", self.cold_cutoff_c)?;
        Rule::Within {
            min: self.baseline_c + 0.1,
            max: 60.0,
        }
        .check("limits.heat_cutoff_c", self.heat_cutoff_c)?;
        Rule::Within { min: 0.0, max: 3600.0 }.check("limits.isi_s", self.isi_s)?;
        Rule::Within { min: 1.0, max: 100.0 }.check("limits.runs", self.runs as f64)?;
        Ok(())
    }
}

/// One recorded ramp of the method of limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LimitsRun {
    /// The test.
    pub test: LimitsTest,
    /// 1-based run.
    pub run: usize,
    /// The ramp's direction.
    pub direction: Direction,
    /// Where the ramp started \[°C\].
    pub start_c: f64,
    /// The session's baseline \[°C\].
    pub baseline_c: f64,
    /// The plate at the response \[°C\], or where the ramp ended without one (its cut-off, or the display's limit
    /// when that is narrower).
    pub delivered_c: f64,
    /// The ramp reached its cut-off without a response.
    pub cutoff_reached: bool,
    /// A paradoxical heat sensation was reported (TSL cold ramps).
    pub paradoxical_heat: bool,
}

/// One ramp still to present.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Step {
    test: LimitsTest,
    run: usize,
    direction: Direction,
    /// The last ramp of a TSL block returns to the baseline; earlier ones do not.
    tsl_last: bool,
}

/// The method of limits as a state machine over the configured tests and runs.
#[derive(Debug, Clone)]
pub struct LimitsProcedure {
    config: LimitsConfig,
    steps: Vec<Step>,
    next: usize,
    pending: Option<TrialPlan>,
    runs: Vec<LimitsRun>,
}

impl LimitsProcedure {
    /// The procedure for `config` (validated).
    pub fn new(config: LimitsConfig) -> Result<Self, ProcedureError> {
        config.validate()?;
        let mut steps = Vec::new();
        for &test in &config.tests {
            for run in 1..=config.runs {
                match test {
                    LimitsTest::Tsl => {
                        let first = config.tsl_first;
                        for (k, direction) in [first, first.opposite()].into_iter().enumerate() {
                            let tsl_last = run == config.runs && k == 1;
                            steps.push(Step {
                                test,
                                run,
                                direction,
                                tsl_last,
                            });
                        }
                    }
                    LimitsTest::Cdt | LimitsTest::Cpt => steps.push(Step {
                        test,
                        run,
                        direction: Direction::Cold,
                        tsl_last: false,
                    }),
                    LimitsTest::Wdt | LimitsTest::Hpt => steps.push(Step {
                        test,
                        run,
                        direction: Direction::Warm,
                        tsl_last: false,
                    }),
                }
            }
        }
        Ok(LimitsProcedure {
            config,
            steps,
            next: 0,
            pending: None,
            runs: Vec::new(),
        })
    }

    /// The recorded ramps so far.
    pub fn runs(&self) -> &[LimitsRun] {
        &self.runs
    }

    /// The configuration.
    pub fn config(&self) -> &LimitsConfig {
        &self.config
    }

    fn cutoff_c(&self, direction: Direction) -> f64 {
        match direction {
            Direction::Cold => self.config.cold_cutoff_c,
            Direction::Warm => self.config.heat_cutoff_c,
        }
    }

    fn plan(&self, step: Step) -> TrialPlan {
        let c = &self.config;
        let continues = step.test == LimitsTest::Tsl && self.runs.last().is_some_and(|r| r.test == LimitsTest::Tsl);
        let start_c = match self.runs.last() {
            Some(last) if continues => last.delivered_c,
            _ => c.baseline_c,
        };
        let returns = step.test != LimitsTest::Tsl || step.tsl_last;
        let return_rate_c_per_s = if step.test.is_pain() {
            c.pain_return_rate_c_per_s
        } else {
            c.detection_return_rate_c_per_s
        };
        TrialPlan {
            index: self.next,
            label: step.test.name().to_string(),
            run: step.run,
            baseline_c: start_c,
            intensity_c: self.cutoff_c(step.direction) - start_c,
            rate_c_per_s: c.rate_c_per_s,
            until_response: true,
            plateau_s: 0.0,
            return_c: returns.then_some(c.baseline_c),
            return_rate_c_per_s,
            isi_s: if returns { c.isi_s } else { 0.0 },
            pain: step.test.is_pain(),
            continues_previous: continues,
        }
    }
}

impl Procedure for LimitsProcedure {
    fn next_trial(&mut self) -> Option<TrialPlan> {
        if self.pending.is_none() {
            let step = *self.steps.get(self.next)?;
            self.pending = Some(self.plan(step));
        }
        self.pending.clone()
    }

    fn record(&mut self, response: Response) -> Result<(), ProcedureError> {
        let plan = self.pending.take().ok_or(ProcedureError::NoTrialPending)?;
        let step = self.steps[self.next];
        self.next += 1;
        self.runs.push(LimitsRun {
            test: step.test,
            run: step.run,
            direction: step.direction,
            start_c: plan.baseline_c,
            baseline_c: self.config.baseline_c,
            delivered_c: if response.delivered_c.is_finite() {
                response.delivered_c
            } else {
                plan.target_c()
            },
            cutoff_reached: !response.detected,
            paradoxical_heat: response.paradoxical_heat,
        });
        Ok(())
    }

    /// The mean of the recorded runs' changes from the baseline of the last recorded test (a magnitude \[°C\]).
    fn estimate_c(&self) -> Option<f64> {
        let test = self.runs.last()?.test;
        let changes: Vec<f64> = self
            .runs
            .iter()
            .filter(|r| r.test == test)
            .map(|r| (r.delivered_c - r.baseline_c).abs())
            .collect();
        Some(changes.iter().sum::<f64>() / changes.len() as f64)
    }
}
