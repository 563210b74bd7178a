//! The PID tuner behind `thermode tune`: the gains (k_p, k_i, k_d) and the sensor filter's cut-off of the paper's
//! structure (low-pass filtered sensor → PID) that minimise the mean RMS skin error (skin − target over the 90 s
//! after contact) over the paper's five materials on one display.
//!
//! # What makes it fast
//! - For `pid` the display inverse is advanced with the shaped set-point (the paper's way), so renderer, inverse and
//!   set-point shaping do not depend on the gains: [`prepare`] runs them once per material and stores the target,
//!   the requested set-point, the shaped set-point and the finger model's receptor for every tick. The shaping
//!   depends on the measurements only through the first one (the envelope anchors its first set-point there),
//!   and through the thermal-dose lockout, which the cold paper materials never reach; every evaluation checks
//!   that its envelope shapes exactly the stored set-points and refuses the gains otherwise.
//! - An evaluation ([`evaluate`]) then runs only the pipeline's drive stage (`DriveStage`: envelope and PID) and
//!   the plant; the set-point stage (`SetpointStage`) ran once in [`prepare`]. Both are the stages
//!   `ChannelPipeline::tick` is composed of, so the order of operations is written once: the RMS equals
//!   [`crate::run::render`]'s bit for bit (same plant start, same seed; tested).
//! - The five materials run in parallel threads (`std::thread::scope`).
//!
//! # Search
//! In log-gain space x = ln(k_p, k_i, k_d, f_c), deterministic:
//! 1. the SIMC start point (below) is evaluated — the "before" of the report;
//! 2. 24 screening points around the plant's scales ([`PlantScales::screening`]): the objective has several basins
//!    (a smooth SIMC-like loop, and high-gain loops that saturate the drive on any real error, with a derivative
//!    lead against the sensor lag), and a local search from one start point can end in the worse one (figures in
//!    `docs/design-choices.md`);
//! 3. Nelder–Mead ([`crate::nelder_mead`]) from each of the two best screening points, restarted from its best
//!    point until a restart no longer improves, half of the remaining budget each.
//!
//! Bounds ([`BOUNDS`]) are enforced by projection with a penalty growing with the distance outside; the result
//! reports any parameter that ends at a bound.
//!
//! # Start point (from the plant, SIMC rules for a first-order plant with dead time; Skogestad, J. Process Control
//! 13 (2003) 291–309)
//! Plate capacity C [J/K]; Peltier gain b = S·T at the resting plate temperature [W/A]; loss conductance
//! G = K + G_f (module plus finger receptor-to-plate conductance over the area) [W/K]; dead time θ = sensor lag +
//! half a sample period \[s\]. The plate is `k/(τ₁ s + 1)` with k = b/G, τ₁ = C/G. With the closed-loop time
//! constant τ_c = θ: k_p = τ₁/(k (τ_c + θ)) = C/(2 b θ), τ_I = min(τ₁, 4 (τ_c + θ)), k_i = k_p/τ_I,
//! k_d = k_p θ/3, and the filter cut-off f_c = 5/(2π θ) (a filter five times faster than the dead time).

use std::thread;

use thermode_control::{PidController, PidGains};
use thermode_device::{Device, DeviceConfig};
use thermode_model::materials::paper_materials;
use thermode_model::peltier::KELVIN_OFFSET;
use thermode_model::Material;
use thermode_safety::{EnvelopeConfig, SafetyEnvelope};

use crate::error::RenderError;
use crate::nelder_mead::{minimise_with_restarts, Minimum, NelderMead};
use crate::run::{resting_plant, Plant, RenderSpec};
use crate::summary::FULL_WINDOW_S;
use thermode_control::Finger;
use thermode_pipeline::controllers::ControllerKind;
use thermode_pipeline::pipeline::{render_envelope, DriveStage, PipelineConfig, SetpointStage};
use thermode_pipeline::renderer::RendererKind;
use thermode_pipeline::ChannelPipeline;

/// Search bounds of (k_p [A/°C], k_i [A/(°C·s)], k_d [A·s/°C], f_c \[Hz\]); f_c is further capped at half the tick
/// rate (a filter beyond the Nyquist frequency of the loop filters nothing).
pub const BOUNDS: [(f64, f64); 4] = [(1e-3, 1e2), (1e-4, 1e2), (1e-6, 10.0), (0.01, 1e3)];

/// Names of the tuned parameters, in the order of [`BOUNDS`].
pub const PARAMETER_NAMES: [&str; 4] = ["kp_a_per_c", "ki_a_per_c_s", "kd_a_s_per_c", "filter_cutoff_hz"];

/// Default largest number of objective evaluations (start, screening and both searches): 180 (45–50 s on two
/// lightly loaded cores for each shipped display; on the default display the objective is within 0.02 % of a
/// 500-evaluation search).
pub const DEFAULT_MAX_EVALUATIONS: usize = 180;

/// A parameter counts as at its bound when within this distance in log space (1 %).
const AT_BOUND_LOG: f64 = 0.01;

/// What to tune for.
#[derive(Debug, Clone, PartialEq)]
pub struct TuneSpec {
    /// The display.
    pub device: DeviceConfig,
    /// The renderer (and display-inverse model). Default fv.
    pub renderer: RendererKind,
    /// The safety envelope. Default [`render_envelope`] of the device (as `thermode render`).
    pub envelope: EnvelopeConfig,
    /// The materials. Default the paper's five.
    pub materials: Vec<Material>,
    /// Sensor noise seed. Default [`crate::run::DEFAULT_SEED`] (as `thermode render`).
    pub seed: u64,
    /// Largest number of objective evaluations over all restarts. Default [`DEFAULT_MAX_EVALUATIONS`].
    pub max_evaluations: usize,
}

impl TuneSpec {
    /// The defaults above for `device`.
    pub fn new(device: DeviceConfig) -> Self {
        TuneSpec {
            device,
            renderer: RendererKind::Fv,
            envelope: render_envelope(&device),
            materials: paper_materials(),
            seed: crate::run::DEFAULT_SEED,
            max_evaluations: DEFAULT_MAX_EVALUATIONS,
        }
    }

    /// The render spec of one material with `gains`, exactly as `thermode render` runs it.
    pub fn render_spec(&self, material: &Material, gains: PidGains) -> RenderSpec {
        let mut pipeline = PipelineConfig::new(self.device, ControllerKind::Pid(gains));
        pipeline.renderer = self.renderer;
        pipeline.envelope = self.envelope;
        let mut spec = RenderSpec::new(pipeline, material.clone());
        spec.duration_s = FULL_WINDOW_S;
        spec.seed = self.seed;
        spec
    }
}

/// Everything about one material that does not depend on the gains.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The plant at rest before the first tick.
    pub plant: Plant,
    /// The per-tick sequences (shared by the evaluation threads).
    pub ticks: Ticks,
}

/// The gain-independent per-tick sequences of one material.
#[derive(Debug, Clone, PartialEq)]
pub struct Ticks {
    /// The render spec (its gains are placeholders).
    pub spec: RenderSpec,
    /// Per tick: the renderer's target at the end of the tick \[°C\].
    pub target_c: Vec<f64>,
    /// Per tick: the set-point the inverse asked for \[°C\].
    pub requested_c: Vec<f64>,
    /// Per tick: the set-point after the envelope \[°C\].
    pub shaped_c: Vec<f64>,
    /// Per tick: the finger model's receptor at the start of the tick \[°C\] (the controller's input).
    pub receptor_c: Vec<f64>,
    /// The finger model's receptor-to-plate conductance over the area [W/K].
    pub finger_conductance_w_k: f64,
    /// Ticks before the touch.
    pub pre_ticks: usize,
}

/// Runs renderer, display inverse and set-point shaping of `spec` once (see the module documentation).
pub fn prepare(spec: &RenderSpec) -> Result<Prepared, RenderError> {
    spec.validate()?;
    let cfg = &spec.pipeline;
    let mut stage = SetpointStage::new(cfg)?;
    let mut shaper = SafetyEnvelope::new(cfg.envelope, cfg.device.drive.current_limit_a)?;
    let mut plant = resting_plant(spec)?;
    shaper.observe(&plant.read(0)?.measurement());
    let (pre, contact_ticks, release) = spec.tick_counts();
    let ticks = pre + contact_ticks;
    let dt = spec.tick_s();
    let start_s = plant.time_s();
    let mut prepared = Ticks {
        spec: spec.clone(),
        target_c: Vec::with_capacity(ticks),
        requested_c: Vec::with_capacity(ticks),
        shaped_c: Vec::with_capacity(ticks),
        receptor_c: Vec::with_capacity(ticks),
        finger_conductance_w_k: ChannelPipeline::new(cfg)?.finger_conductance_w_k(),
        pre_ticks: pre,
    };
    for k in 0..ticks {
        if k == pre {
            stage.touch(&spec.material, spec.object_temperature_c())?;
        }
        if release.is_some_and(|r| k == pre + r) {
            stage.release();
        }
        let (target_c, requested_c) = stage.request(dt);
        let shaped_c = shaper.shape_setpoint(start_s + k as f64 * dt, requested_c).setpoint_c;
        prepared.receptor_c.push(stage.receptor_c());
        stage.follow(dt, shaped_c);
        prepared.target_c.push(target_c);
        prepared.requested_c.push(requested_c);
        prepared.shaped_c.push(shaped_c);
    }
    Ok(Prepared { plant, ticks: prepared })
}

/// The RMS skin error (skin − target over 0 < t ≤ 90 s) of `prepared` with `gains`: envelope, PID and plant only,
/// operation for operation as [`crate::run::render`]. Errors if the gains are invalid, or if the envelope shapes a
/// set-point other than the stored one (then the shortcut does not hold for these gains).
pub fn evaluate(prepared: &Prepared, gains: &PidGains) -> Result<f64, RenderError> {
    evaluate_ticks(&prepared.ticks, prepared.plant.clone(), gains)
}

fn evaluate_ticks(prepared: &Ticks, mut plant: Plant, gains: &PidGains) -> Result<f64, RenderError> {
    let spec = &prepared.spec;
    // The skin is read where the renderer's receptor sits (kron: the epidermis centre), as `render` does.
    let depth_m = spec.receptor_depth_m();
    let cfg = &spec.pipeline;
    let limit_a = cfg.device.drive.current_limit_a;
    let controller = PidController::new(*gains, limit_a)?;
    let mut stage = DriveStage::new(cfg, Box::new(controller))?;
    let dt = spec.tick_s();
    let substeps = spec.substeps();
    let h = dt / substeps as f64;
    let start_s = plant.time_s();
    let (mut sum, mut count) = (0.0, 0usize);
    for k in 0..prepared.target_c.len() {
        let now_s = start_s + k as f64 * dt;
        let reading = plant.read(0)?;
        stage.observe(&reading);
        let finger = Finger {
            receptor_c: prepared.receptor_c[k],
            conductance_w_k: prepared.finger_conductance_w_k,
        };
        let outcome = stage.drive(now_s, dt, &reading, prepared.requested_c[k], finger);
        if outcome.decision.setpoint_c.to_bits() != prepared.shaped_c[k].to_bits() {
            return Err(RenderError::Invalid(format!(
                "tuner: the envelope shaped {} °C where {} °C was prepared (tick {k}); the gain-independent \
                 shortcut does not hold",
                outcome.decision.setpoint_c, prepared.shaped_c[k]
            )));
        }
        plant.apply(0, &outcome.drive)?;
        for _ in 0..substeps {
            plant.advance(h);
        }
        let time_s = (k + 1) as f64 * dt - prepared.pre_ticks as f64 * dt;
        if time_s > 1e-9 && time_s <= FULL_WINDOW_S + 1e-9 {
            let error_c = crate::run::finger_at_depth_c(plant.channel(0)?, depth_m) - prepared.target_c[k];
            sum += error_c * error_c;
            count += 1;
        }
    }
    if count == 0 {
        return Err(RenderError::Invalid("tuner: no rows after the touch".into()));
    }
    Ok((sum / count as f64).sqrt())
}

/// [`evaluate`] for every material in parallel threads; in the order of `prepared`.
pub fn evaluate_all(prepared: &[Prepared], gains: &PidGains) -> Vec<Result<f64, RenderError>> {
    thread::scope(|scope| {
        let handles: Vec<_> = prepared
            .iter()
            .map(|p| {
                let (ticks, plant) = (&p.ticks, p.plant.clone());
                scope.spawn(move || evaluate_ticks(ticks, plant, gains))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(RenderError::Invalid("tuner: an evaluation thread panicked".into())))
            })
            .collect()
    })
}

/// The mean of the materials' RMS skin errors with `gains` [°C]; +∞ if any evaluation fails.
pub fn objective(prepared: &[Prepared], gains: &PidGains) -> f64 {
    let results = evaluate_all(prepared, gains);
    let mut sum = 0.0;
    for r in &results {
        match r {
            Ok(v) if v.is_finite() => sum += v,
            _ => return f64::INFINITY,
        }
    }
    sum / results.len().max(1) as f64
}

/// The plant's scales the start points are built from (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantScales {
    /// Plate heat capacity C [J/K].
    pub capacity_j_k: f64,
    /// Peltier gain b = S·T at the resting plate temperature [W/A].
    pub peltier_w_per_a: f64,
    /// Loss conductance G = K + finger conductance [W/K].
    pub loss_w_k: f64,
    /// Dead time θ = sensor lag + half a sample period \[s\].
    pub dead_time_s: f64,
    /// The drive limit \[A\].
    pub current_limit_a: f64,
}

impl PlantScales {
    /// The scales of `device` with the finger's receptor-to-plate conductance `finger_conductance_w_k` [W/K] and
    /// the plate at `resting_plate_c` \[°C\].
    pub fn new(device: &DeviceConfig, finger_conductance_w_k: f64, resting_plate_c: f64) -> Result<Self, RenderError> {
        let module = device.module()?;
        Ok(PlantScales {
            capacity_j_k: device.plate.heat_capacity_j_k,
            peltier_w_per_a: module.seebeck_v_k * (resting_plate_c + KELVIN_OFFSET),
            loss_w_k: module.conductance_w_k + finger_conductance_w_k,
            dead_time_s: device.sensor.time_constant_s + 0.5 / device.sensor.sample_rate_hz,
            current_limit_a: device.drive.current_limit_a,
        })
    }

    /// The SIMC start point (see the module documentation).
    pub fn simc(&self) -> PidGains {
        let theta = self.dead_time_s;
        let kp = self.capacity_j_k / (2.0 * self.peltier_w_per_a * theta);
        let tau_i = (self.capacity_j_k / self.loss_w_k).min(8.0 * theta);
        PidGains {
            kp_a_per_c: kp,
            ki_a_per_c_s: kp / tau_i,
            kd_a_s_per_c: kp * theta / 3.0,
            filter_cutoff_hz: 5.0 / (std::f64::consts::TAU * theta),
            derivative_filter_s: None,
        }
    }

    /// The 24 screening points: k_p from the SIMC value to the gain that saturates the drive at
    /// [`SATURATION_ERROR_C`] of error and their geometric mean; derivative time k_d/k_p of θ/3 (SIMC) or θ; filter
    /// time constant θ/5 (SIMC) or θ/20; integral time SIMC's or a hundred times longer.
    pub fn screening(&self) -> Vec<PidGains> {
        let simc = self.simc();
        let theta = self.dead_time_s;
        let kp_sat = self.current_limit_a / SATURATION_ERROR_C;
        let kps = [simc.kp_a_per_c, (simc.kp_a_per_c * kp_sat).sqrt(), kp_sat];
        let tau_i = simc.kp_a_per_c / simc.ki_a_per_c_s;
        let mut points = Vec::with_capacity(24);
        for kp in kps {
            for td in [theta / 3.0, theta] {
                for tf in [theta / 5.0, theta / 20.0] {
                    for ti in [tau_i, 100.0 * tau_i] {
                        points.push(PidGains {
                            kp_a_per_c: kp,
                            ki_a_per_c_s: kp / ti,
                            kd_a_s_per_c: kp * td,
                            filter_cutoff_hz: 1.0 / (std::f64::consts::TAU * tf),
                            derivative_filter_s: None,
                        });
                    }
                }
            }
        }
        points
    }
}

/// Error at which the most aggressive screening gain saturates the drive \[°C\]: 0.5 (fifty sensor resolution
/// steps; a thermal display is expected to hold the plate well within that).
pub const SATURATION_ERROR_C: f64 = 0.5;

/// The result of a tuning run.
#[derive(Debug, Clone, PartialEq)]
pub struct TuneResult {
    /// The start point.
    pub start: PidGains,
    /// The objective there [°C].
    pub start_objective_c: f64,
    /// The best gains found.
    pub gains: PidGains,
    /// The objective there [°C].
    pub objective_c: f64,
    /// Each material's RMS skin error at the best gains [°C].
    pub per_material_c: Vec<(String, f64)>,
    /// Objective evaluations spent.
    pub evaluations: usize,
    /// Parameters that ended at a search bound (names from [`PARAMETER_NAMES`]); empty when the optimum is inside.
    pub at_bound: Vec<&'static str>,
}

/// The search bounds in log space for a tick rate of `rate_hz`.
fn log_bounds(rate_hz: f64) -> [(f64, f64); 4] {
    let mut bounds = BOUNDS.map(|(lo, hi)| (lo.ln(), hi.ln()));
    bounds[3].1 = bounds[3].1.min((0.5 * rate_hz).ln());
    bounds
}

fn gains_at(x: &[f64], bounds: &[(f64, f64); 4]) -> (PidGains, f64) {
    let mut outside = 0.0;
    let p: Vec<f64> = x
        .iter()
        .zip(bounds)
        .map(|(v, (lo, hi))| {
            let clamped = v.clamp(*lo, *hi);
            outside += (v - clamped) * (v - clamped);
            clamped.exp()
        })
        .collect();
    let gains = PidGains {
        kp_a_per_c: p[0],
        ki_a_per_c_s: p[1],
        kd_a_s_per_c: p[2],
        filter_cutoff_hz: p[3],
        derivative_filter_s: None,
    };
    (gains, outside)
}

/// Tunes the PID of `spec` (see the module documentation).
pub fn tune(spec: &TuneSpec) -> Result<TuneResult, RenderError> {
    tune_with_progress(spec, &mut |_, _, _| {})
}

/// As [`tune`], calling `progress(evaluations, best objective so far [°C], best gains so far)` whenever the best
/// objective improves.
pub fn tune_with_progress(
    spec: &TuneSpec,
    progress: &mut dyn FnMut(usize, f64, &PidGains),
) -> Result<TuneResult, RenderError> {
    if spec.materials.is_empty() {
        return Err(RenderError::Invalid("tuner: no materials".into()));
    }
    // Any valid gains: the prepared sequences do not depend on them.
    let placeholder = PidGains {
        kp_a_per_c: 1.0,
        ki_a_per_c_s: 0.0,
        kd_a_s_per_c: 0.0,
        filter_cutoff_hz: 1.0,
        derivative_filter_s: None,
    };
    let prepared = spec
        .materials
        .iter()
        .map(|m| prepare(&spec.render_spec(m, placeholder)))
        .collect::<Result<Vec<_>, _>>()?;
    let resting_plate_c = prepared[0].plant.channel(0)?.state().plate_c;
    let scales = PlantScales::new(&spec.device, prepared[0].ticks.finger_conductance_w_k, resting_plate_c)?;
    let start = scales.simc();
    start.validate()?;
    let bounds = log_bounds(prepared[0].ticks.spec.rate_hz);
    let (mut evaluations, mut best_so_far) = (0usize, f64::INFINITY);
    let mut f = |x: &[f64]| {
        let (gains, outside) = gains_at(x, &bounds);
        let value = objective(&prepared, &gains) * (1.0 + outside);
        evaluations += 1;
        if value < best_so_far {
            best_so_far = value;
            progress(evaluations, value, &gains);
        }
        value
    };
    let to_x = |g: &PidGains| -> Vec<f64> {
        [g.kp_a_per_c, g.ki_a_per_c_s, g.kd_a_s_per_c, g.filter_cutoff_hz]
            .iter()
            .zip(&bounds)
            .map(|(v, (lo, hi))| v.ln().clamp(*lo, *hi))
            .collect()
    };
    let start_objective_c = f(&to_x(&start));
    let mut screened: Vec<(Vec<f64>, f64)> = scales
        .screening()
        .iter()
        .map(|g| {
            let x = to_x(g);
            let value = f(&x);
            (x, value)
        })
        .collect();
    screened.sort_by(|a, b| a.1.total_cmp(&b.1));
    let spent = 1 + screened.len();
    let remaining = spec.max_evaluations.saturating_sub(spent);
    let mut best = Minimum {
        x: screened[0].0.clone(),
        value: screened[0].1,
        evaluations: spent,
    };
    // Two searches from the two best screening points, half the remaining budget each.
    for (index, share) in [(0, remaining / 2), (1, remaining - remaining / 2)] {
        let options = NelderMead {
            initial_step: 0.7,
            max_evaluations: share,
            f_tolerance: 1e-4,
            x_tolerance: 0.02,
        };
        if share < 10 {
            continue;
        }
        let found = minimise_with_restarts(&mut f, &screened[index].0, &options, 4);
        let evaluations = best.evaluations + found.evaluations;
        if found.value < best.value {
            best = found;
        }
        best.evaluations = evaluations;
    }
    let (gains, _) = gains_at(&best.x, &bounds);
    let per_material_c = spec
        .materials
        .iter()
        .zip(evaluate_all(&prepared, &gains))
        .map(|(m, r)| r.map(|v| (m.name.clone(), v)))
        .collect::<Result<Vec<_>, _>>()?;
    let objective_c = per_material_c.iter().map(|(_, v)| v).sum::<f64>() / per_material_c.len() as f64;
    let at_bound = best
        .x
        .iter()
        .zip(&bounds)
        .zip(PARAMETER_NAMES)
        .filter(|((v, (lo, hi)), _)| **v <= lo + AT_BOUND_LOG || **v >= hi - AT_BOUND_LOG)
        .map(|(_, name)| name)
        .collect();
    Ok(TuneResult {
        start,
        start_objective_c,
        gains,
        objective_c,
        per_material_c,
        evaluations: best.evaluations + 1,
        at_bound,
    })
}
