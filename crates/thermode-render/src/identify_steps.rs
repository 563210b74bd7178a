//! `thermode identify` on a temperature-commanded device (a TCS II, a MeCom controller in temperature mode): the
//! device regulates its plate itself and reports neither the current it drives nor the Peltier voltage, so the
//! module's parameters cannot be identified (`crate::identify` needs both). What the sensor alone tells, with the
//! bare plate stepped through the device's own regulation ([`StepExcitation`]), is identified here:
//!
//! - **The sensor's lag** (a first-order PT-100 of time constant τ_s, the value the safety envelope's plate estimate
//!   rests on: the plate guard's bound, the observer's sensor model, the thermal dose's plate reconstruction).
//!   Inside the device's own loop it is **not** identifiable from set-point steps: the reading's closed-loop
//!   response r → s is fully measured, but the plate p = s + τ_s ṡ differs from it by a term any τ_s fits, given a
//!   suitable (unknown) device controller. It is identified from responses in which the plate moves on its own:
//!   - [`StepMethod::Relaxation`] (a device that can switch its output off: MeCom): the plate is held until the
//!     reading settles, then the output goes off and the bare plate relaxes towards its heat sink. With p = s at
//!     that instant, the reading is `A + B (e^{−u/τ_p} − (τ_s/τ_p) e^{−u/τ_s})` with u the time since the output
//!     went off (a dead time d fitted too): the plate's passive relaxation (τ_p, seconds: the plate's heat capacity
//!     over the module's conductance) and the sensor's lag. The two time constants enter symmetrically but for the
//!     settled start; the faster is taken as the sensor's (a Peltier plate relaxes in seconds, a mounted PT-100 lags
//!     0.1–1.5 s). The passive relaxation is a single exponential here, where the plate and the hot side make two:
//!     over the 4 s window the fitted τ_p absorbs the second.
//!   - [`StepMethod::Tail`] (a device that always regulates: the TCS II): after a set-point step the reading's tail
//!     `A + B e^{−t/τ}` decays with the slower of the sensor's lag and the closed loop's own approach. So τ is an
//!     **upper bound** of the sensor's lag (exactly it when the device holds the plate at its set-point once there,
//!     as the TCS II emulator does). An upper bound is the cautious side of the guard's bound (the plate is taken
//!     further ahead of the reading); the dose reconstruction counts a cooling plate somewhat colder.
//! - **The closed-loop plate response** ([`PlateResponse`], per step): the plate reconstructed from the reading with
//!   the identified lag (`s + τ_s ṡ`), its overshoot beyond the set-point and the time it takes to come within 10 %
//!   of the step. Reported with the file; the envelope does not act on it (it shapes the set-point the device
//!   follows and clamps it into the display's limits).
//!
//! Not identifiable from the sensor alone, and left at the believed file's values: the module (S, R, K), the heat
//! capacities, the water conductance, the hot side.

use thermode_control::linear::inverse_diagonal;
use thermode_device::config::SELF_TEST_LAG_ERROR;
use thermode_device::{DeviceConfig, Reading};
use thermode_pipeline::{ChannelPipeline, ControllerKind, PipelineConfig, Stimulus};
use thermode_safety::DriveCommand;

use crate::error::RenderError;
use crate::nelder_mead::{minimise_with_restarts, NelderMead};

/// How the sensor's lag is identified (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepMethod {
    /// The output switched off after each plateau: the plate relaxes on its own (MeCom).
    Relaxation,
    /// The tails of the regulated steps: an upper bound (TCS II).
    Tail,
}

/// The phases of [`StepMethod::Relaxation`]: two relaxations from 35 °C (the plate then relaxes at about 1.3 °C/s,
/// which the sensor's lag bends visibly; a plate relaxing from below the heat sink's temperature moves too little
/// to tell much) and one from 17 °C (the down step), all inside a MeCom controller's own error thresholds on the
/// default display (14.3–38.7 °C) with room for its regulation's overshoot.
pub const RELAXATION_PLAN: [Phase; 6] = [
    Phase::Hold(35.0),
    Phase::Off,
    Phase::Hold(35.0),
    Phase::Off,
    Phase::Hold(17.0),
    Phase::Off,
];
/// The set points of [`StepMethod::Tail`] \[°C\]: up from rest (32 °C), down, and back to rest.
pub const TAIL_SETPOINTS_C: [f64; 3] = [40.0, 24.0, 32.0];
/// Rate of the set-point steps of [`StepMethod::Tail`] \[°C/s\]: 20 (the default display's rendering limit: the
/// plate's approach ends soon, and the tail is the sensor's).
const TAIL_RATE_C_PER_S: f64 = 20.0;
/// Rate of the approach to a plateau of [`StepMethod::Relaxation`] \[°C/s\]: 2 (what follows the plateau is
/// measured, not the approach; a MeCom controller's own regulation overshot a 20 °C/s step past its own error
/// threshold on the emulator).
const RELAXATION_RATE_C_PER_S: f64 = 2.0;
/// Shortest hold at a set point \[s\]: 6.
const MIN_HOLD_S: f64 = 6.0;
/// Longest hold at a set point \[s\]: 60 (then identification stops: the device does not settle).
pub const MAX_HOLD_S: f64 = 60.0;
/// The reading has settled when the means of the four quarters of this window lie within [`SETTLED_SPREAD_C`] of
/// each other \[s\]: 2 (four quarters, not two halves: a reading that peaks mid-window has equal halves).
const SETTLED_WINDOW_S: f64 = 2.0;
/// Largest spread of the quarter means of a settled reading \[°C\]: 0.015 (the plate then moves at about 0.01 °C/s
/// at most, a hundredth of the relaxation's rate; the noise of a quarter's mean at 100 Hz is 0.003 °C).
const SETTLED_SPREAD_C: f64 = 0.015;
/// Length of each relaxation with the output off \[s\]: 4.
pub const RELAX_S: f64 = 4.0;
/// Longest dead time fitted between the command that switches the output off and the plate's first motion \[s\].
const MAX_DEAD_TIME_S: f64 = 0.25;
/// The tail of a step is fitted from where the reading is within this fraction of the step of its end: 0.15.
const TAIL_FROM_FRACTION: f64 = 0.15;
/// Half-width of the derivative used for the plate's reconstruction \[samples\]: 10 (±0.1 s at 100 Hz).
const DERIVATIVE_HALF_WIDTH: usize = 10;

/// One fresh sensor sample of the record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepSample {
    /// When it was taken \[s\] (the readings' clock).
    pub time_s: f64,
    /// The reading \[°C\].
    pub sensor_c: f64,
}

/// A phase of the excitation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Phase {
    /// The device regulates to this set point \[°C\] until its reading settles.
    Hold(f64),
    /// The output is off (the plate relaxes).
    Off,
}

/// What was recorded: the fresh samples and when each phase began.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepRecord {
    /// The fresh sensor samples, in time order.
    pub samples: Vec<StepSample>,
    /// `(start time [s], phase)` of every phase, in order.
    pub phases: Vec<(f64, Phase)>,
}

/// The excitation tick by tick: the phases of [`RELAXATION_PLAN`] or the holds at [`TAIL_SETPOINTS_C`] through the pipeline of the believed file
/// (direct mode, every command through the safety envelope, which carries the shaped set-point the device follows);
/// an output-off phase lasts [`RELAX_S`].
pub struct StepExcitation {
    pipeline: ChannelPipeline,
    method: StepMethod,
    plan: Vec<Phase>,
    next: usize,
    record: StepRecord,
    last_seq: Option<u64>,
}

impl StepExcitation {
    /// The excitation for `method` on a fresh temperature-commanded pipeline of `believed`.
    pub fn new(believed: &DeviceConfig, method: StepMethod) -> Result<Self, RenderError> {
        let plan = match method {
            StepMethod::Relaxation => RELAXATION_PLAN.to_vec(),
            StepMethod::Tail => TAIL_SETPOINTS_C.iter().map(|&c| Phase::Hold(c)).collect(),
        };
        // The device regulates its plate itself: no current reaches the guard's model, which must not judge the
        // reading against a drive the device never applied.
        let mut config = PipelineConfig::new(*believed, ControllerKind::Model);
        config.temperature_commanded = true;
        Ok(StepExcitation {
            pipeline: ChannelPipeline::new(&config)?,
            method,
            plan,
            next: 0,
            record: StepRecord::default(),
            last_seq: None,
        })
    }

    /// Whether every phase has run.
    pub fn done(&self) -> bool {
        self.next > self.plan.len()
    }

    /// The record so far.
    pub fn record(&self) -> &StepRecord {
        &self.record
    }

    /// The record, taken.
    pub fn into_record(self) -> StepRecord {
        self.record
    }

    /// The command for the tick at `now_s` \[s\] of `dt_s` \[s\] with `reading`: the envelope's gated command while
    /// a set point is held, [`DriveCommand::off`] while the output is off or once done. A fault of the envelope, or
    /// a set point the reading does not settle at within [`MAX_HOLD_S`], is an error (the drive is then off).
    pub fn tick(&mut self, now_s: f64, dt_s: f64, reading: &Reading) -> Result<DriveCommand, RenderError> {
        if self.last_seq != Some(reading.sample_seq) {
            self.last_seq = Some(reading.sample_seq);
            self.record.samples.push(StepSample {
                time_s: reading.time_s,
                sensor_c: reading.sensor_c,
            });
        }
        let holding = matches!(self.record.phases.last(), Some((_, Phase::Hold(_)))) && !self.done();
        let (drive, _) = self.pipeline.tick(now_s, dt_s, reading);
        if let Some(fault) = drive.fault() {
            return Err(RenderError::Invalid(format!(
                "identification: the display faulted at {now_s:.2} s: {fault}"
            )));
        }
        // A phase starts after the pipeline's tick (the first once it has a reading: a set point's ramp starts from
        // the plate, not from nowhere) and acts from the next tick on.
        if self.phase_over(now_s)? {
            self.start_next(now_s)?;
        }
        Ok(if holding { drive } else { DriveCommand::off() })
    }

    /// Starts the next phase at `now_s` (past the last: done).
    fn start_next(&mut self, now_s: f64) -> Result<(), RenderError> {
        if let Some(&phase) = self.plan.get(self.next) {
            if let Phase::Hold(temp_c) = phase {
                let rate_c_per_s = match self.method {
                    StepMethod::Relaxation => RELAXATION_RATE_C_PER_S,
                    StepMethod::Tail => TAIL_RATE_C_PER_S,
                };
                self.pipeline.set_stimulus(Stimulus::Direct { temp_c, rate_c_per_s })?;
            }
            self.record.phases.push((now_s, phase));
        }
        self.next += 1;
        Ok(())
    }

    /// Whether the current phase is over at `now_s`: a hold once the reading settled (at least [`MIN_HOLD_S`]), an
    /// output-off phase after [`RELAX_S`].
    fn phase_over(&self, now_s: f64) -> Result<bool, RenderError> {
        let Some(&(start_s, phase)) = self.record.phases.last() else {
            return Ok(true);
        };
        let held_s = now_s - start_s;
        match phase {
            _ if self.done() => Ok(false),
            Phase::Off => Ok(held_s >= RELAX_S),
            Phase::Hold(_) if held_s < MIN_HOLD_S => Ok(false),
            Phase::Hold(setpoint_c) => {
                let window: Vec<f64> = self
                    .record
                    .samples
                    .iter()
                    .filter(|s| s.time_s >= now_s - SETTLED_WINDOW_S)
                    .map(|s| s.sensor_c)
                    .collect();
                let quarter = (window.len() / 4).max(1);
                let means: Vec<f64> = window
                    .chunks(quarter)
                    .map(|part| part.iter().sum::<f64>() / part.len() as f64)
                    .collect();
                let spread_c = means.iter().fold(f64::NEG_INFINITY, |m, &c| m.max(c))
                    - means.iter().fold(f64::INFINITY, |m, &c| m.min(c));
                if spread_c <= SETTLED_SPREAD_C {
                    return Ok(true);
                }
                if held_s > MAX_HOLD_S {
                    return Err(RenderError::Invalid(format!(
                        "identification: the reading did not settle at {setpoint_c} °C within {MAX_HOLD_S} s \
                         (its means over the quarters of the last {SETTLED_WINDOW_S} s spread {spread_c:.3} °C): is \
                         something on the plate?"
                    )));
                }
                Ok(false)
            }
        }
    }

    /// The method this excitation was made for.
    pub fn method(&self) -> StepMethod {
        self.method
    }
}

/// A fitted time constant with its standard deviation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LagFit {
    /// The sensor's time constant \[s\] (an upper bound for [`StepMethod::Tail`]).
    pub time_constant_s: f64,
    /// Its standard deviation \[s\].
    pub sd_s: f64,
    /// The plate's passive relaxation time constant \[s\] ([`StepMethod::Relaxation`]; NaN for a tail).
    pub plate_time_constant_s: f64,
    /// RMS residual of the fit \[°C\].
    pub rms_c: f64,
}

/// The closed-loop response of the plate to one set-point step, reconstructed with the identified lag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateResponse {
    /// The set point \[°C\].
    pub setpoint_c: f64,
    /// The step's size from the reading at its start \[°C\] (signed).
    pub step_c: f64,
    /// The plate's largest excursion beyond the set point in the step's direction \[°C\] (0 when it never passed).
    pub overshoot_c: f64,
    /// Time from the step's start until the plate first came within 10 % of the step of the set point \[s\].
    pub rise_s: f64,
}

/// What the steps identified.
#[derive(Debug, Clone, PartialEq)]
pub struct StepIdentification {
    /// How the lag was identified.
    pub method: StepMethod,
    /// Each window's fit.
    pub windows: Vec<LagFit>,
    /// The windows combined: the inverse-variance mean, its standard deviation at least half the windows' spread.
    pub lag: LagFit,
    /// The plate's closed-loop response per held step.
    pub responses: Vec<PlateResponse>,
}

/// The windows of `record` the lag is fitted on: `(times from the window's zero [s], readings [°C])`. Relaxation:
/// each output-off phase from its start (zero: the command). Tail: each hold from where the reading came within [`TAIL_FROM_FRACTION`] of the step of its end.
fn windows(record: &StepRecord, method: StepMethod) -> Vec<(Vec<f64>, Vec<f64>)> {
    let mut out = Vec::new();
    for (k, &(start_s, phase)) in record.phases.iter().enumerate() {
        let end_s = record.phases.get(k + 1).map_or(f64::INFINITY, |p| p.0);
        let inside: Vec<StepSample> = record
            .samples
            .iter()
            .filter(|s| s.time_s >= start_s && s.time_s < end_s)
            .copied()
            .collect();
        let (Some(first), Some(last)) = (inside.first(), inside.last()) else {
            continue;
        };
        match (method, phase) {
            (StepMethod::Relaxation, Phase::Off) => {
                out.push(inside.iter().map(|s| (s.time_s - start_s, s.sensor_c)).unzip());
            }
            (StepMethod::Tail, Phase::Hold(_)) => {
                let step_c = last.sensor_c - first.sensor_c;
                let from = inside
                    .iter()
                    .position(|s| (last.sensor_c - s.sensor_c).abs() <= TAIL_FROM_FRACTION * step_c.abs())
                    .unwrap_or(0);
                let zero_s = inside[from].time_s;
                out.push(inside[from..].iter().map(|s| (s.time_s - zero_s, s.sensor_c)).unzip());
            }
            _ => {}
        }
    }
    out
}

/// Least squares of `y ≈ a + b·g` \[(a, b, sum of squared residuals)\].
fn affine_fit(g: &[f64], y: &[f64]) -> (f64, f64, f64) {
    let n = g.len() as f64;
    let (mg, my) = (g.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut sgg, mut sgy) = (0.0, 0.0);
    for (gi, yi) in g.iter().zip(y) {
        sgg += (gi - mg) * (gi - mg);
        sgy += (gi - mg) * (yi - my);
    }
    let b = if sgg > 0.0 { sgy / sgg } else { 0.0 };
    let a = my - b * mg;
    let ssr = g.iter().zip(y).map(|(gi, yi)| (yi - a - b * gi).powi(2)).sum();
    (a, b, ssr)
}

/// The relaxation's shape at `t` \[s\] for (τ_p, τ_s, d): `e^{−u/τ_p} − (τ_s/τ_p) e^{−u/τ_s}`, u = max(t − d, 0).
fn relaxation_shape(t: f64, tau_p: f64, tau_s: f64, dead_s: f64) -> f64 {
    let u = (t - dead_s).max(0.0);
    (-u / tau_p).exp() - tau_s / tau_p * (-u / tau_s).exp()
}

/// The tail's shape at `t` \[s\] for τ: `e^{−t/τ}`.
fn tail_shape(t: f64, tau: f64) -> f64 {
    (-t / tau).exp()
}

/// The model's shape at `t` for the nonlinear parameters `x` of `method` (relaxation: τ_p, τ_s, d; tail: τ).
fn shape(method: StepMethod, t: f64, x: &[f64]) -> f64 {
    match method {
        StepMethod::Relaxation => relaxation_shape(t, x[0], x[1], x[2]),
        StepMethod::Tail => tail_shape(t, x[0]),
    }
}

/// The nonlinear parameters of `method` from the minimiser's coordinates `z` (time constants as logarithms, the
/// dead time squashed into `[0, MAX_DEAD_TIME_S]`), or `None` outside what is physical (τ_s ≥ τ_p).
fn parameters(method: StepMethod, z: &[f64]) -> Option<Vec<f64>> {
    match method {
        StepMethod::Relaxation => {
            let (tau_p, tau_s) = (z[0].exp(), z[1].exp());
            let dead_s = MAX_DEAD_TIME_S * 0.5 * (1.0 + z[2].tanh());
            (tau_s < tau_p).then(|| vec![tau_p, tau_s, dead_s])
        }
        StepMethod::Tail => Some(vec![z[0].exp()]),
    }
}

/// The sum of squared residuals of the best affine fit of `y` on the shape of `x`.
fn ssr_at(method: StepMethod, t: &[f64], y: &[f64], x: &[f64]) -> f64 {
    let g: Vec<f64> = t.iter().map(|&ti| shape(method, ti, x)).collect();
    affine_fit(&g, y).2
}

/// Fits one window `(t, y)` with `method`, starting from the sensor lag `lag_guess_s` \[s\]; `None` when the window
/// is too short or the fit is not finite.
pub fn fit_window(method: StepMethod, t: &[f64], y: &[f64], lag_guess_s: f64) -> Option<LagFit> {
    if t.len() < 20 || t.len() != y.len() {
        return None;
    }
    let start = match method {
        StepMethod::Relaxation => vec![(10.0 * lag_guess_s).max(3.0).ln(), lag_guess_s.ln(), -1.0],
        StepMethod::Tail => vec![lag_guess_s.ln()],
    };
    let options = NelderMead {
        initial_step: 0.4,
        max_evaluations: 600,
        f_tolerance: 1e-10,
        x_tolerance: 1e-6,
    };
    let mut objective = |z: &[f64]| parameters(method, z).map_or(f64::INFINITY, |x| ssr_at(method, t, y, &x));
    let best = minimise_with_restarts(&mut objective, &start, &options, 3);
    let x = parameters(method, &best.x)?;
    let dof = (t.len() - x.len() - 2) as f64;
    let variance = best.value / dof;
    let sd_s = lag_sd(method, t, y, &x, variance);
    let (tau_s, tau_p) = match method {
        StepMethod::Relaxation => (x[1], x[0]),
        StepMethod::Tail => (x[0], f64::NAN),
    };
    let fit = LagFit {
        time_constant_s: tau_s,
        sd_s,
        plate_time_constant_s: tau_p,
        rms_c: (best.value / t.len() as f64).sqrt(),
    };
    (fit.time_constant_s.is_finite() && fit.sd_s.is_finite()).then_some(fit)
}

/// The standard deviation of the sensor lag \[s\] at the fit `x` (the amplitudes refitted): the linearised
/// covariance `σ² (JᵀJ)⁻¹` of all parameters (the two amplitudes and `x`), with a central-difference Jacobian.
fn lag_sd(method: StepMethod, t: &[f64], y: &[f64], x: &[f64], variance: f64) -> f64 {
    let g: Vec<f64> = t.iter().map(|&ti| shape(method, ti, x)).collect();
    let (a, b, _) = affine_fit(&g, y);
    let model = |p: &[f64], ti: f64| p[0] + p[1] * shape(method, ti, &p[2..]);
    let mut p = vec![a, b];
    p.extend_from_slice(x);
    let columns: Vec<Vec<f64>> = (0..p.len())
        .map(|k| {
            let h = 1e-6 * p[k].abs().max(1e-3);
            let (mut up, mut down) = (p.clone(), p.clone());
            up[k] += h;
            down[k] -= h;
            t.iter()
                .map(|&ti| (model(&up, ti) - model(&down, ti)) / (2.0 * h))
                .collect()
        })
        .collect();
    let jtj_entry = |i: usize, j: usize| -> f64 { columns[i].iter().zip(&columns[j]).map(|(u, v)| u * v).sum() };
    // The lag is the last parameter of the tail's (a, b, τ) and the fourth of the relaxation's (a, b, τ_p, τ_s, d).
    let lag_variance = match method {
        StepMethod::Relaxation => inverse_diagonal(normal_matrix::<5>(jtj_entry), 3),
        StepMethod::Tail => inverse_diagonal(normal_matrix::<3>(jtj_entry), 2),
    };
    lag_variance.map_or(f64::NAN, |v| (variance * v).sqrt())
}

/// The N × N matrix of `entry(i, j)` (JᵀJ of an N-parameter fit).
fn normal_matrix<const N: usize>(entry: impl Fn(usize, usize) -> f64) -> [[f64; N]; N] {
    std::array::from_fn(|i| std::array::from_fn(|j| entry(i, j)))
}

/// The windows' fits combined: the inverse-variance mean; its standard deviation the mean's, scaled up by the
/// Birge ratio (√ of the reduced χ² of the windows about the mean) when the windows disagree beyond their noise (the
/// model is then not exact).
fn combine(fits: &[LagFit]) -> Option<LagFit> {
    let weights: Vec<f64> = fits.iter().map(|f| 1.0 / (f.sd_s * f.sd_s).max(1e-18)).collect();
    let total: f64 = weights.iter().sum();
    if fits.is_empty() || !total.is_finite() {
        return None;
    }
    let mean = |value: fn(&LagFit) -> f64| fits.iter().zip(&weights).map(|(f, w)| w * value(f)).sum::<f64>() / total;
    let tau_s = mean(|f| f.time_constant_s);
    let chi2: f64 = fits
        .iter()
        .zip(&weights)
        .map(|(f, w)| w * (f.time_constant_s - tau_s).powi(2))
        .sum();
    let birge = match fits.len() {
        1 => 1.0,
        n => (chi2 / (n - 1) as f64).sqrt().max(1.0),
    };
    Some(LagFit {
        time_constant_s: tau_s,
        sd_s: birge / total.sqrt(),
        plate_time_constant_s: mean(|f| f.plate_time_constant_s),
        rms_c: (fits.iter().map(|f| f.rms_c * f.rms_c).sum::<f64>() / fits.len() as f64).sqrt(),
    })
}

/// The plate's closed-loop response to each held step of `record`, reconstructed with the lag `tau_s` \[s\].
fn plate_responses(record: &StepRecord, tau_s: f64) -> Vec<PlateResponse> {
    let samples = &record.samples;
    let w = DERIVATIVE_HALF_WIDTH;
    let plate_c = |i: usize| {
        let (a, b) = (&samples[i - w], &samples[i + w]);
        samples[i].sensor_c + tau_s * (b.sensor_c - a.sensor_c) / (b.time_s - a.time_s)
    };
    let mut out = Vec::new();
    for (k, &(start_s, phase)) in record.phases.iter().enumerate() {
        let Phase::Hold(setpoint_c) = phase else {
            continue;
        };
        let end_s = record.phases.get(k + 1).map_or(f64::INFINITY, |p| p.0);
        let inside: Vec<usize> = (w..samples.len().saturating_sub(w))
            .filter(|&i| samples[i].time_s >= start_s && samples[i].time_s < end_s)
            .collect();
        let Some(&first) = inside.first() else {
            continue;
        };
        let step_c = setpoint_c - samples[first].sensor_c;
        let sign = step_c.signum();
        let overshoot_c = inside
            .iter()
            .map(|&i| sign * (plate_c(i) - setpoint_c))
            .fold(0.0, f64::max);
        let rise_s = inside
            .iter()
            .find(|&&i| sign * (setpoint_c - plate_c(i)) <= 0.1 * step_c.abs())
            .map_or(f64::NAN, |&i| samples[i].time_s - start_s);
        out.push(PlateResponse {
            setpoint_c,
            step_c,
            overshoot_c,
            rise_s,
        });
    }
    out
}

/// Identifies the sensor's lag and the plate's closed-loop response from `record` with `method`, starting from the
/// lag of `believed`.
pub fn identify_steps(
    record: &StepRecord,
    method: StepMethod,
    believed: &DeviceConfig,
) -> Result<StepIdentification, RenderError> {
    let guess_s = believed.sensor.time_constant_s.max(0.05);
    let fits: Vec<LagFit> = windows(record, method)
        .iter()
        .filter_map(|(t, y)| fit_window(method, t, y, guess_s))
        .collect();
    let lag = combine(&fits).ok_or_else(|| {
        RenderError::Invalid("identification: no step of the record could be fitted (too few samples?)".into())
    })?;
    Ok(StepIdentification {
        method,
        responses: plate_responses(record, lag.time_constant_s),
        windows: fits,
        lag,
    })
}

/// The device file identified from `believed`: the sensor's time constant the fitted one, its uncertainty
/// (`render.sensor_lag_uncertainty`) three of its relative standard deviations, at least the self-test's own error
/// ([`SELF_TEST_LAG_ERROR`], 0.15),
/// at most 1; everything else the believed file's (module, capacities, water: not identifiable from the sensor).
pub fn identified_device(believed: &DeviceConfig, lag: &LagFit) -> Result<DeviceConfig, RenderError> {
    let mut device = *believed;
    device.sensor.time_constant_s = lag.time_constant_s;
    device.render.sensor_lag_uncertainty = (3.0 * lag.sd_s / lag.time_constant_s).clamp(SELF_TEST_LAG_ERROR, 1.0);
    device
        .validate("the identified device file")
        .map_err(|e| RenderError::Invalid(e.to_string()))?;
    Ok(device)
}

#[cfg(test)]
mod tests {
    use super::*;
    use thermode_device::{Device, NoFinger, SimulatedDisplay};

    /// A display of `plant` whose true plate is held at `hold_c` by a stiff regulator on the true plate for `hold_s`
    /// (the sensor settles), then (`relax`) left at 0 A or (not `relax`) stepped to `to_c` and held there; sampled
    /// at 100 Hz from the switch for `after_s`: (times from the switch [s], readings [°C]).
    fn simulated_window(plant: &DeviceConfig, hold_c: f64, to_c: f64, relax: bool) -> (Vec<f64>, Vec<f64>) {
        let mut display = SimulatedDisplay::<NoFinger>::fingertips(plant, 1, 7).unwrap();
        let dt_s = 1e-3;
        let regulate = |display: &mut SimulatedDisplay<NoFinger>, goal_c: f64| {
            let channel = display.channel_mut(0).unwrap();
            let error_c = goal_c - channel.state().plate_c;
            channel.step(dt_s, (3.0 * error_c).clamp(-2.8, 2.8));
        };
        for _ in 0..15_000 {
            regulate(&mut display, hold_c);
        }
        let (mut t, mut y) = (Vec::new(), Vec::new());
        for k in 0..4_000 {
            if relax {
                display.channel_mut(0).unwrap().step(dt_s, 0.0);
            } else {
                regulate(&mut display, to_c);
            }
            if k % 10 == 9 {
                t.push((k + 1) as f64 * dt_s);
                y.push(display.read(0).unwrap().sensor_c);
            }
        }
        (t, y)
    }

    fn with_lag(lag_s: f64) -> DeviceConfig {
        let mut plant = DeviceConfig::default();
        plant.sensor.time_constant_s = lag_s;
        plant
    }

    #[test]
    fn a_relaxation_recovers_the_sensor_lag_of_the_plant() {
        for lag_s in [0.3, 0.39, 0.8] {
            for (hold_c, to_c) in [(36.0, 0.0), (16.0, 0.0)] {
                let (t, y) = simulated_window(&with_lag(lag_s), hold_c, to_c, true);
                let fit = fit_window(StepMethod::Relaxation, &t, &y, 0.3).unwrap();
                let error = (fit.time_constant_s - lag_s).abs();
                assert!(
                    error < 0.1 * lag_s && error < 3.0 * fit.sd_s,
                    "relaxation from {hold_c} °C: identified {:.4} ± {:.4} s, true {lag_s} s",
                    fit.time_constant_s,
                    fit.sd_s
                );
            }
        }
    }

    #[test]
    fn a_tail_after_the_plate_stops_recovers_the_sensor_lag() {
        for lag_s in [0.3, 0.39] {
            let (t, y) = simulated_window(&with_lag(lag_s), 32.0, 40.0, false);
            let last = *y.last().unwrap();
            let from = y.iter().position(|c| (last - c).abs() <= 0.15 * 8.0).unwrap();
            let (t, y): (Vec<f64>, Vec<f64>) = t[from..].iter().map(|s| s - t[from]).zip(y[from..].to_vec()).unzip();
            let fit = fit_window(StepMethod::Tail, &t, &y, 0.3).unwrap();
            assert!(
                (fit.time_constant_s - lag_s).abs() < 0.05 * lag_s,
                "tail: identified {:.4} ± {:.4} s, true {lag_s} s",
                fit.time_constant_s,
                fit.sd_s
            );
        }
    }

    #[test]
    fn the_plate_is_reconstructed_from_the_lagging_reading() {
        // A reading that is the first-order lag (τ 0.4 s) of a plate stepping from 30 to 40 °C at t = 1 s: the plate
        // rebuilt with the right τ rises within 10 % of the step at once, and does not overshoot.
        let tau_s = 0.4;
        let samples: Vec<StepSample> = (0..800)
            .map(|k| {
                let t = k as f64 * 0.01;
                let u = (t - 1.0).max(0.0);
                StepSample {
                    time_s: t,
                    sensor_c: 40.0 - 10.0 * (-u / tau_s).exp(),
                }
            })
            .collect();
        let record = StepRecord {
            samples,
            phases: vec![(0.5, Phase::Hold(40.0))],
        };
        let response = plate_responses(&record, tau_s)[0];
        assert!(response.overshoot_c < 0.3, "overshoot {} °C", response.overshoot_c);
        assert!(
            (response.rise_s - 0.5).abs() < 0.15,
            "rise {} s after the step's start, the plate at 1.0 s",
            response.rise_s
        );
        // With no lag assumed the reading itself takes ln(10)·τ = 0.92 s longer.
        let unlagged = plate_responses(&record, 0.0)[0];
        assert!(
            (unlagged.rise_s - 0.5 - 0.92).abs() < 0.05,
            "rise without lag {} s",
            unlagged.rise_s
        );
    }
}
