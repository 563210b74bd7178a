//! QUEST+ (Watson 2017) with the keys and the arithmetic of the `questplus` Python package 2023.1
//! (`questplus/qp.py`, `questplus/psychometric_function.py`), so that for the same grid and responses the next
//! intensity is the package's and the posterior agrees to rounding:
//!
//! - The likelihood of the first outcome (`outcome_domain.response[0]`, "Yes") is the psychometric function p, of the
//!   second `1 − p`. `norm_cdf` (linear scale only): `p = γ + (1 − γ − δ) Φ((x − mean)/sd)`; `weibull`:
//!   `p = 1 − δ − (1 − γ − δ) exp(−z)` with `z = (x/t)^β` (linear), `10^(β(x − t))` (log10) or `10^(β(x − t)/20)`
//!   (dB); γ the lower asymptote, δ the lapse rate.
//! - The prior is uniform over the parameter grid (the package's default); after a response the posterior is
//!   multiplied by the likelihood of that stimulus and outcome and normalised to sum 1.
//! - `min_entropy`: for every stimulus and outcome, the unnormalised next posterior `post · L`, its total `p_k` and
//!   its entropy `H = −Σ q ln q` of `q = post · L / p_k` (terms with q = 0 or undefined count 0); the expected
//!   entropy is `Σ_k p_k H_k`, and the next stimulus is the first of the grid with the smallest one (NumPy's
//!   `argmin`).
//! - The estimate (`param_estimation_method`): `mean`, the posterior mean of each parameter; `mode`, the parameters
//!   of the first largest posterior cell.
//!
//! The parameter grid is ordered as the package orders it when `param_domain` lists the keys in this order:
//! `mean, sd, lower_asymptote, lapse_rate` (norm_cdf) or `threshold, slope, lower_asymptote, lapse_rate` (weibull),
//! the last index fastest. The stimulus value is the change from the baseline \[°C\] on a linear scale, its log10 on
//! `log10`, and 20·log10 of it on `dB`.

use serde::{Deserialize, Serialize};
use thermode_model::params::Rule;

use crate::plan::{Procedure, Response, TrialPlan};
use crate::stimulus::StimulusConfig;
use crate::ProcedureError;

/// A grid of values: a list, or `{ start, stop, step }` giving `start + i·step` for `i = 0, 1, …` below `stop`
/// (as `numpy.arange`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Grid {
    /// The values themselves.
    Values(Vec<f64>),
    /// `start + i·step` below `stop`.
    Range {
        /// First value.
        start: f64,
        /// Bound, excluded.
        stop: f64,
        /// Step, positive.
        step: f64,
    },
}

impl Grid {
    /// The grid's values; refuses an empty grid, a non-finite value or more than 100 000 values.
    pub fn values(&self, key: &str) -> Result<Vec<f64>, ProcedureError> {
        let values = match *self {
            Grid::Values(ref v) => v.clone(),
            Grid::Range { start, stop, step } => {
                if !(step > 0.0 && start.is_finite() && stop.is_finite()) || (stop - start) / step > 1e5 {
                    return Err(ProcedureError::invalid(
                        key,
                        format!("{self:?}"),
                        "a range with a positive step",
                    ));
                }
                let n = ((stop - start) / step).ceil().max(0.0) as usize;
                (0..n).map(|i| start + i as f64 * step).collect()
            }
        };
        if values.is_empty() || values.len() > 100_000 || values.iter().any(|v| !v.is_finite()) {
            return Err(ProcedureError::invalid(
                key,
                format!("{values:?}"),
                "1 to 100000 finite values",
            ));
        }
        Ok(values)
    }
}

/// `stim_domain`: the stimulus grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StimDomain {
    /// The intensities (on `stim_scale`).
    pub intensity: Grid,
}

/// `param_domain`: the grid of the psychometric function's parameters (those of `func`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ParamDomain {
    /// norm_cdf: the mean (the 50 % point without asymptotes) \[stimulus units\].
    pub mean: Option<Grid>,
    /// norm_cdf: the standard deviation \[stimulus units\].
    pub sd: Option<Grid>,
    /// weibull: the threshold \[stimulus units\].
    pub threshold: Option<Grid>,
    /// weibull: the slope β.
    pub slope: Option<Grid>,
    /// The lower asymptote γ (false-alarm rate in yes/no). Default `[0.01]` (the package's function default).
    pub lower_asymptote: Option<Grid>,
    /// The lapse rate δ. Default `[0.01]` (the package's function default).
    pub lapse_rate: Option<Grid>,
}

/// `outcome_domain`: the two responses, the first the one the function's p gives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutcomeDomain {
    /// The two responses. Default `["Yes", "No"]`.
    pub response: Vec<String>,
}

impl Default for OutcomeDomain {
    fn default() -> Self {
        OutcomeDomain {
            response: vec!["Yes".to_string(), "No".to_string()],
        }
    }
}

/// `func`: the psychometric function.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Func {
    /// The cumulative normal with asymptotes.
    NormCdf,
    /// The Weibull function with asymptotes.
    Weibull,
}

/// `stim_scale`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum StimScale {
    /// Intensities are changes \[°C\].
    #[default]
    #[serde(rename = "linear")]
    Linear,
    /// Intensities are log10 of the change.
    #[serde(rename = "log10")]
    Log10,
    /// Intensities are 20·log10 of the change.
    #[serde(rename = "dB")]
    Db,
}

/// `stim_selection_method`: only `min_entropy` is deterministic, and the only one supported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum StimSelection {
    /// The stimulus of least expected entropy.
    #[default]
    MinEntropy,
}

/// `param_estimation_method`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ParamEstimation {
    /// The posterior mean of each parameter.
    #[default]
    Mean,
    /// The parameters of the posterior's (first) peak.
    Mode,
}

/// The `[questplus]` table of an experiment file: the package's constructor keys, and the number of trials.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuestPlusConfig {
    /// The stimulus grid.
    pub stim_domain: StimDomain,
    /// The parameter grid.
    pub param_domain: ParamDomain,
    /// The responses. Default `{ response = ["Yes", "No"] }`.
    #[serde(default)]
    pub outcome_domain: OutcomeDomain,
    /// `norm_cdf` or `weibull`.
    pub func: Func,
    /// `linear` (default), `log10` or `dB`; norm_cdf takes only `linear`.
    #[serde(default)]
    pub stim_scale: StimScale,
    /// `min_entropy` (default).
    #[serde(default)]
    pub stim_selection_method: StimSelection,
    /// `mean` (default) or `mode`.
    #[serde(default)]
    pub param_estimation_method: ParamEstimation,
    /// Trials in the session. Default 30.
    #[serde(default = "default_trials")]
    pub trials: usize,
}

fn default_trials() -> usize {
    30
}

/// The grid, likelihoods and posterior of QUEST+.
#[derive(Debug, Clone, PartialEq)]
pub struct QuestPlus {
    func: Func,
    scale: StimScale,
    stim: Vec<f64>,
    params: [Vec<f64>; 4],
    /// p(first outcome) for each stimulus (outer) and parameter cell (inner, C order).
    likelihood: Vec<f64>,
    posterior: Vec<f64>,
    estimation: ParamEstimation,
}

/// Φ as `scipy.special.ndtr` computes it (Cephes): `0.5 + 0.5 erf(x/√2)` near 0, `erfc` in the tails.
fn ndtr(a: f64) -> f64 {
    let x = a * std::f64::consts::FRAC_1_SQRT_2;
    let z = x.abs();
    if z < std::f64::consts::FRAC_1_SQRT_2 {
        0.5 + 0.5 * libm::erf(x)
    } else {
        let y = 0.5 * libm::erfc(z);
        if x > 0.0 {
            1.0 - y
        } else {
            y
        }
    }
}

impl QuestPlus {
    /// The grid for `config`, with the uniform prior.
    pub fn new(config: &QuestPlusConfig) -> Result<Self, ProcedureError> {
        let stim = config.stim_domain.intensity.values("questplus.stim_domain.intensity")?;
        let params = param_grids(config)?;
        if config.outcome_domain.response.len() != 2 {
            return Err(ProcedureError::invalid(
                "questplus.outcome_domain.response",
                format!("{:?}", config.outcome_domain.response),
                "two responses (detected first)",
            ));
        }
        if config.func == Func::NormCdf && config.stim_scale != StimScale::Linear {
            return Err(ProcedureError::invalid(
                "questplus.stim_scale",
                format!("{:?}", config.stim_scale),
                "linear (the only scale of norm_cdf)",
            ));
        }
        let cells: usize = params.iter().map(Vec::len).product();
        let grid_cells = Rule::AtMost {
            max: 5e7,
            what: "the grid cells QUEST+ holds",
        };
        grid_cells.check("questplus (grid cells)", cells.saturating_mul(stim.len()) as f64)?;
        let mut qp = QuestPlus {
            func: config.func,
            scale: config.stim_scale,
            stim,
            params,
            likelihood: Vec::new(),
            posterior: vec![1.0 / cells as f64; cells],
            estimation: config.param_estimation_method,
        };
        qp.likelihood = qp
            .stim
            .iter()
            .flat_map(|&x| qp.cells().map(move |c| (x, c)))
            .map(|(x, c)| qp.p(x, c))
            .collect();
        if qp.likelihood.iter().any(|p| !p.is_finite()) {
            return Err(ProcedureError::invalid(
                "questplus.param_domain",
                "the grid",
                "parameters giving finite probabilities",
            ));
        }
        Ok(qp)
    }

    fn cells(&self) -> impl Iterator<Item = [f64; 4]> + '_ {
        let [a, b, c, d] = &self.params;
        a.iter().flat_map(move |&a| {
            b.iter()
                .flat_map(move |&b| c.iter().flat_map(move |&c| d.iter().map(move |&d| [a, b, c, d])))
        })
    }

    fn p(&self, x: f64, [a, b, gamma, delta]: [f64; 4]) -> f64 {
        match self.func {
            Func::NormCdf => gamma + (1.0 - gamma - delta) * ndtr((x - a) / b),
            Func::Weibull => {
                let z = match self.scale {
                    StimScale::Linear => (x / a).powf(b),
                    StimScale::Log10 => 10f64.powf(b * (x - a)),
                    StimScale::Db => 10f64.powf(b * (x - a) / 20.0),
                };
                1.0 - delta - (1.0 - gamma - delta) * (-z).exp()
            }
        }
    }

    /// The stimulus grid.
    pub fn stim_domain(&self) -> &[f64] {
        &self.stim
    }

    /// The posterior over the parameter grid (C order, the last parameter fastest).
    pub fn posterior(&self) -> &[f64] {
        &self.posterior
    }

    fn likelihood_row(&self, stim_index: usize) -> &[f64] {
        let n = self.posterior.len();
        &self.likelihood[stim_index * n..(stim_index + 1) * n]
    }

    /// The expected entropy after presenting each stimulus.
    pub fn expected_entropies(&self) -> Vec<f64> {
        (0..self.stim.len()).map(|s| self.expected_entropy(s)).collect()
    }

    fn expected_entropy(&self, stim_index: usize) -> f64 {
        let row = self.likelihood_row(stim_index);
        let mut total = 0.0;
        for outcome in 0..2 {
            let lik = |p: f64| if outcome == 0 { p } else { 1.0 - p };
            let joint = || self.posterior.iter().zip(row).map(|(post, p)| post * lik(*p));
            let pk: f64 = joint().sum();
            if pk.is_nan() || pk == 0.0 {
                continue;
            }
            let h: f64 = -joint()
                .map(|j| j / pk)
                .filter(|q| *q > 0.0)
                .map(|q| q * q.ln())
                .sum::<f64>();
            total += pk * h;
        }
        total
    }

    /// The index of the next stimulus: the first of least expected entropy.
    pub fn next_index(&self) -> usize {
        let entropies = self.expected_entropies();
        let mut best = 0;
        for (i, h) in entropies.iter().enumerate() {
            if *h < entropies[best] || entropies[best].is_nan() {
                best = i;
            }
        }
        best
    }

    /// Updates the posterior with outcome 0 (the first response) or 1 at stimulus `stim_index`.
    pub fn update(&mut self, stim_index: usize, outcome: usize) {
        let n = self.posterior.len();
        let row = &self.likelihood[stim_index * n..(stim_index + 1) * n];
        for (post, p) in self.posterior.iter_mut().zip(row) {
            *post *= if outcome == 0 { *p } else { 1.0 - *p };
        }
        let sum: f64 = self.posterior.iter().sum();
        self.posterior.iter_mut().for_each(|p| *p /= sum);
    }

    /// The parameter estimates, in the grid's order (`param_estimation_method`).
    pub fn param_estimate(&self) -> [f64; 4] {
        match self.estimation {
            ParamEstimation::Mean => {
                let mut mean = [0.0; 4];
                for (cell, post) in self.cells().zip(&self.posterior) {
                    for k in 0..4 {
                        mean[k] += post * cell[k];
                    }
                }
                mean
            }
            ParamEstimation::Mode => {
                let mut best = 0;
                for (i, p) in self.posterior.iter().enumerate() {
                    if *p > self.posterior[best] {
                        best = i;
                    }
                }
                self.cells().nth(best).unwrap_or([f64::NAN; 4])
            }
        }
    }

    /// A stimulus value as a change from the baseline \[°C\] (undoing `stim_scale`).
    pub fn to_change_c(&self, value: f64) -> f64 {
        match self.scale {
            StimScale::Linear => value,
            StimScale::Log10 => 10f64.powf(value),
            StimScale::Db => 10f64.powf(value / 20.0),
        }
    }
}

fn param_grids(config: &QuestPlusConfig) -> Result<[Vec<f64>; 4], ProcedureError> {
    let d = &config.param_domain;
    let (first, second, names) = match config.func {
        Func::NormCdf => (&d.mean, &d.sd, ["mean", "sd"]),
        Func::Weibull => (&d.threshold, &d.slope, ["threshold", "slope"]),
    };
    let unused = match config.func {
        Func::NormCdf => [("threshold", &d.threshold), ("slope", &d.slope)],
        Func::Weibull => [("mean", &d.mean), ("sd", &d.sd)],
    };
    if let Some((name, _)) = unused.iter().find(|(_, g)| g.is_some()) {
        return Err(ProcedureError::invalid(
            &format!("questplus.param_domain.{name}"),
            "given",
            &format!("absent: {:?} takes {} and {}", config.func, names[0], names[1]),
        ));
    }
    let required = |grid: &Option<Grid>, name: &str| -> Result<Vec<f64>, ProcedureError> {
        let key = format!("questplus.param_domain.{name}");
        grid.as_ref()
            .ok_or_else(|| ProcedureError::invalid(&key, "missing", "a grid"))?
            .values(&key)
    };
    let optional = |grid: &Option<Grid>, name: &str| match grid {
        Some(g) => g.values(&format!("questplus.param_domain.{name}")),
        None => Ok(vec![0.01]),
    };
    Ok([
        required(first, names[0])?,
        required(second, names[1])?,
        optional(&d.lower_asymptote, "lower_asymptote")?,
        optional(&d.lapse_rate, "lapse_rate")?,
    ])
}

/// QUEST+ as a procedure presenting trapezoids.
#[derive(Debug, Clone)]
pub struct QuestPlusProcedure {
    engine: QuestPlus,
    stimulus: StimulusConfig,
    trials: usize,
    presented: Vec<usize>,
    pending: Option<(usize, TrialPlan)>,
}

impl QuestPlusProcedure {
    /// The procedure for `config`, presenting trapezoids of `stimulus`.
    pub fn new(config: &QuestPlusConfig, stimulus: StimulusConfig) -> Result<Self, ProcedureError> {
        stimulus.validate()?;
        Rule::Within {
            min: 1.0,
            max: 10_000.0,
        }
        .check("questplus.trials", config.trials as f64)?;
        Ok(QuestPlusProcedure {
            engine: QuestPlus::new(config)?,
            stimulus,
            trials: config.trials,
            presented: Vec::new(),
            pending: None,
        })
    }

    /// The engine (grid, posterior).
    pub fn engine(&self) -> &QuestPlus {
        &self.engine
    }
}

impl Procedure for QuestPlusProcedure {
    fn next_trial(&mut self) -> Option<TrialPlan> {
        if self.pending.is_none() {
            if self.presented.len() >= self.trials {
                return None;
            }
            let index = self.engine.next_index();
            let change = self.engine.to_change_c(self.engine.stim[index]);
            let plan = self.stimulus.trial(self.presented.len(), "questplus", change);
            self.pending = Some((index, plan));
        }
        self.pending.as_ref().map(|(_, plan)| plan.clone())
    }

    fn record(&mut self, response: Response) -> Result<(), ProcedureError> {
        let (index, _) = self.pending.take().ok_or(ProcedureError::NoTrialPending)?;
        self.engine.update(index, if response.detected { 0 } else { 1 });
        self.presented.push(index);
        Ok(())
    }

    /// The estimate of the first parameter (norm_cdf's mean, weibull's threshold) as a change \[°C\].
    fn estimate_c(&self) -> Option<f64> {
        Some(self.engine.to_change_c(self.engine.param_estimate()[0]))
    }
}
