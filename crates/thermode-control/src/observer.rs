//! The display's plant model ([`PlantModel`], filled from the device file) and a Kalman filter on it
//! ([`PlateObserver`]) that estimates the true plate temperature from the lagging, noisy, quantised PT-100.
//!
//! # Model (the simulated display's node equations, `model.md` §5)
//! With the plate at T_p, the hot side at T_h, the PT-100 element at T_s, the current I (positive heats the plate),
//! the finger model's receptor at T_r with conductance G_f to the plate, and an unknown heat d into the plate:
//! - `C_p dT_p/dt = q_d(I, T_p, T_h) + G_f (T_r − T_p) + d`
//! - `C_h dT_h/dt = q_h(I, T_p, T_h) − G_w (T_h − T_w)`
//! - `τ dT_s/dt = T_p − T_s` (τ includes the mean age of the held sample, see below)
//! - `dd/dt = w` (a random walk: the finger's heat the finger model gets wrong, and any other mismatch)
//! - θ constant: the plate's response to heat relative to the file's capacity, `C_file/C_p − 1` (see below)
//!
//! q_d and q_h are the Peltier flows of [`PeltierModule`]; the plate has no other losses (as in the simulated
//! device: its free edges lose under 0.3 mW/K to air). d makes the observer offset-free: whatever heat the model
//! misses (a finger 20 % off the model, a wrong contact conductance) shows up as a persistent difference between
//! predicted and measured sensor and is learnt, so the estimate converges to the true plate temperature.
//!
//! # Discretisation (matches the plant)
//! At a fixed current the Peltier flows are affine in (T_p, T_h), so plate and hot side are advanced together by
//! backward Euler with end-of-step finger receptor, hot-side coupling and current — the scheme of the simulated
//! plant (identical to it when a tick is one plant substep; the first-order difference over a 10 ms tick is far
//! below the sensor noise, the plate's slowest time constant being seconds). The PT-100 is advanced with the exact
//! first-order-lag response to a plate temperature that changes linearly over the step.
//! The plate's change over the step is then scaled by 1 + θ: `T_p1 = T̃_p1 + θ (T̃_p1 − T_p0)` with `T̃_p1` the
//! file's step (exactly the file's at θ = 0). The result is a map `x₁ = F x₀ + c` of the state
//! `x = [T_p, T_h, T_s, d, θ]`, linear but for the product θ·(T̃_p1 − T_p0), which F linearises (an extended
//! Kalman filter); the filter propagates its covariance `P₁ = F P₀ Fᵀ + Q`.
//!
//! # The plate's response θ
//! The file's plate capacity is an estimate; a plate 30 % lighter falls 43 % faster at full current, and the
//! finger, whose model follows the estimate, overshoots at the end of a drop. θ starts at 0 with the standard
//! deviation [`ObserverDesign::plate_response_uncertainty`] (the device file's `render.plate_uncertainty`), has no
//! process noise (a property of the plant), is learnt while heat flows (its Jacobian column is the plate's change
//! over the step) and is kept within −0.5 and 1. With an uncertainty of 0 it stays 0 and the filter is the
//! four-state filter on the file's capacity.
//!
//! # Measurements
//! The PT-100 reading `y_s = T_s + v_s` with variance `σ² + Δ²/12` (noise plus uniform quantisation error) and the
//! hot-side reading `y_h = T_h + v_h` with variance `Δ²/12`, both processed each tick as sequential scalar updates.
//! The PT-100 is sampled at `f_s` and held between samples; when the controller runs faster than that, the same
//! sample is seen `1/(f_s dt)` times, so its variance is scaled by that factor (the information per sample period
//! is then that of one sample). The hold delays the reading by the sample's mean age, `(T_sample − dt)/2` when the
//! controller ticks faster than the sensor samples (0 at the sample rate), which is added to the sensor's time
//! constant.
//!
//! # Noise intensities (derived from the device, no tuning per display)
//! [`ObserverDesign`] holds three dimensionless fractions, the same for every display; the heat they scale is
//! `Q_ref`, the module's cooling capacity at the drive limit with both faces at the water temperature.
//! - Unknown heat d: a random walk of intensity `(drift · Q_ref)²` W²/s; starting variance `(initial · Q_ref)²`.
//! - Plate and hot-side heat: white noise of `heat_noise · Q_ref` RMS over one sample period (the finger's heat
//!   varies within a step; the linear model is exact otherwise).
//!
//! - The hot side's response: while a hot-side reading lies beyond [`HOT_SIDE_GATE_SD`] standard deviations of its
//!   prediction, `(u · ΔT_h)²` more variance on the hot side per step, u the file's uncertainty of its hot side
//!   ([`ObserverDesign::hot_side_response_uncertainty`]), ΔT_h the modelled change: the filter then follows the
//!   hot-side reading, whose innovations would otherwise reach the plate through the states' correlation.
//!
//! The filter is time-varying (the current changes F every tick) and costs a few hundred flops per tick; it never
//! allocates.

use thermode_model::peltier::PeltierModule;

use crate::error::ControlError;
use thermode_model::{BadValue, Rule};

/// Number of observer states: plate, hot side, sensor element, unknown heat, plate response scale.
pub const OBSERVER_STATES: usize = 5;

/// The observer's noise model as dimensionless fractions of the module's reference heat flow
/// ([`PlantModel::reference_heat_w`]), the same for every display (no tuning per display), and how uncertain the
/// device file says the plate's heat capacity is (from the file, not tuned). Defaults in the field docs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverDesign {
    /// Random-walk intensity of the unknown plate heat d, as a fraction of the reference heat per √s. Default 0.003
    /// (10 mW/√s for the default module). A finger off the model misses about 0.1 W during a contact transient,
    /// which builds up over a second or more. The default trades a little speed after a grossly wrong contact for a
    /// steady estimate (figures in `docs/design-choices.md`).
    pub disturbance_drift_per_sqrt_s: f64,
    /// Standard deviation of the unknown heat at start, as a fraction of the reference heat. Default 0.1.
    pub disturbance_initial_fraction: f64,
    /// RMS of the white heat noise on the plate and hot-side nodes over one sensor sample period, as a fraction of
    /// the reference heat. Default 0.002 (7 mW for the default module).
    pub plant_heat_noise_fraction: f64,
    /// Relative standard deviation of the plate's response to heat (its heat capacity as the file states it) at
    /// start; the observer then estimates the response's scale. Default 0 (the file's capacity, not estimated).
    pub plate_response_uncertainty: f64,
    /// Relative uncertainty of the hot side's modelled change over a step (its heat capacity and water conductance as
    /// the file states them): while the last hot-side reading lay beyond [`HOT_SIDE_GATE_SD`] standard deviations of
    /// its prediction (the file's hot side running off the display's), `(u · ΔT_h)²` is added to the hot side's
    /// variance at every prediction, so the filter follows the hot-side reading, and the reading's innovations are
    /// not carried into the plate through the states' correlation. A hot side that agrees with its file changes
    /// nothing. Default 0 (the file's hot side taken as exact).
    pub hot_side_response_uncertainty: f64,
}

impl Default for ObserverDesign {
    fn default() -> Self {
        Self {
            disturbance_drift_per_sqrt_s: 0.003,
            disturbance_initial_fraction: 0.1,
            plant_heat_noise_fraction: 0.002,
            plate_response_uncertainty: 0.0,
            hot_side_response_uncertainty: 0.0,
        }
    }
}

impl ObserverDesign {
    /// Checks that every fraction is finite and ≥ 0.
    pub fn validate(&self) -> Result<(), ControlError> {
        Rule::NonNegative.check("disturbance_drift_per_sqrt_s", self.disturbance_drift_per_sqrt_s)?;
        Rule::NonNegative.check("disturbance_initial_fraction", self.disturbance_initial_fraction)?;
        Rule::NonNegative.check("plant_heat_noise_fraction", self.plant_heat_noise_fraction)?;
        Rule::NonNegative.check("plate_response_uncertainty", self.plate_response_uncertainty)?;
        Rule::NonNegative.check("hot_side_response_uncertainty", self.hot_side_response_uncertainty)?;
        Ok(())
    }
}

/// A hot-side reading further than this many standard deviations from its prediction shows the file's hot side
/// running off the display's: 3 (see [`ObserverDesign::hot_side_response_uncertainty`]).
pub const HOT_SIDE_GATE_SD: f64 = 3.0;

/// Smallest standard deviation assigned to a reading, °C: 1e-4 (keeps the filter well posed for a noiseless,
/// unquantised sensor).
pub const READING_FLOOR_C: f64 = 1e-4;

/// Standard deviation of the plate estimate at start, °C: 0.5 (the plate may not be in equilibrium with the
/// sensor when the controller starts).
pub const INITIAL_PLATE_SD_C: f64 = 0.5;

const TP: usize = 0;
const TH: usize = 1;
const TS: usize = 2;
const DIST: usize = 3;
const SCALE: usize = 4;

/// The plate response scale's estimate is kept within these bounds (a plate responding half or twice as fast as
/// its file says).
const SCALE_BOUNDS: (f64, f64) = (-0.5, 1.0);

type Matrix = [[f64; OBSERVER_STATES]; OBSERVER_STATES];
type Vector = [f64; OBSERVER_STATES];

/// What the model-based controller knows about the display: the device file's numbers. All temperatures in °C.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantModel {
    /// The Peltier module (S, R, K) from the datasheet (`DeviceConfig::module`). Default module: 6.37 mV/K,
    /// 0.515 Ω, 28.0 mW/K.
    pub module: PeltierModule,
    /// Heat capacity of the display node (plate, cold ceramic, half the legs), J/K (> 0). Device default 0.28.
    pub plate_heat_capacity_j_k: f64,
    /// Heat capacity of the hot node (hot ceramic, half the legs, box and water in it), J/K (> 0). Device
    /// default 1.7.
    pub hot_heat_capacity_j_k: f64,
    /// Conductance from the hot node to the cooling water, W/K (≥ 0). Device default 0.3.
    pub water_conductance_w_k: f64,
    /// Temperature of the cooling water, °C. Device default 23.
    pub water_c: f64,
    /// First-order lag of the PT-100 behind the plate, s (≥ 0; 0 = none). Device default 0.3.
    pub sensor_time_constant_s: f64,
    /// Standard deviation of the PT-100's noise, °C (≥ 0). Device default 0.02.
    pub sensor_noise_c: f64,
    /// Quantisation step of the PT-100 and hot-side readings, °C (≥ 0; 0 = none). Device default 0.01.
    pub sensor_resolution_c: f64,
    /// Sampling rate of the PT-100, Hz (> 0); the reading is held between samples. Device default 100.
    pub sensor_sample_rate_hz: f64,
    /// Largest current magnitude of the drive, A (> 0). Device default 2.8.
    pub current_limit_a: f64,
}

impl PlantModel {
    /// Checks every number: finite; capacities, module parameters, sample rate and current limit > 0; water
    /// conductance, sensor lag, noise and resolution ≥ 0; the water between −50 and 100 °C.
    pub fn validate(&self) -> Result<(), ControlError> {
        Rule::Positive.check("module.seebeck_v_k", self.module.seebeck_v_k)?;
        Rule::Positive.check("module.resistance_ohm", self.module.resistance_ohm)?;
        Rule::Positive.check("module.conductance_w_k", self.module.conductance_w_k)?;
        Rule::Positive.check("plate_heat_capacity_j_k", self.plate_heat_capacity_j_k)?;
        Rule::Positive.check("hot_heat_capacity_j_k", self.hot_heat_capacity_j_k)?;
        Rule::NonNegative.check("water_conductance_w_k", self.water_conductance_w_k)?;
        Rule::Within { min: -50.0, max: 100.0 }.check("water_c", self.water_c)?;
        Rule::NonNegative.check("sensor_time_constant_s", self.sensor_time_constant_s)?;
        Rule::NonNegative.check("sensor_noise_c", self.sensor_noise_c)?;
        Rule::NonNegative.check("sensor_resolution_c", self.sensor_resolution_c)?;
        Rule::Positive.check("sensor_sample_rate_hz", self.sensor_sample_rate_hz)?;
        Rule::Positive.check("current_limit_a", self.current_limit_a)?;
        Ok(())
    }

    /// The sensor's sample period, s.
    pub fn sample_period_s(&self) -> f64 {
        1.0 / self.sensor_sample_rate_hz
    }

    /// The lag the observer gives the sensor for ticks of `dt_s`, s: its time constant plus the mean age of the
    /// held sample, `max(0, T_sample − dt)/2` (a controller ticking at the sample rate reads each sample as it is
    /// taken; one ticking n times faster reads it at ages 0, dt, …, T_sample − dt).
    pub fn effective_sensor_lag_s(&self, dt_s: f64) -> f64 {
        self.sensor_time_constant_s + 0.5 * (self.sample_period_s() - dt_s).max(0.0)
    }

    /// Variance of one PT-100 reading, °C²: noise² + resolution²/12 + floor².
    pub fn sensor_variance_c2(&self) -> f64 {
        self.sensor_noise_c.powi(2) + self.sensor_resolution_c.powi(2) / 12.0 + READING_FLOOR_C.powi(2)
    }

    /// Variance of one hot-side reading, °C²: resolution²/12 + floor².
    pub fn hot_side_variance_c2(&self) -> f64 {
        self.sensor_resolution_c.powi(2) / 12.0 + READING_FLOOR_C.powi(2)
    }

    /// The reference heat flow of the noise model, W: the module's cooling capacity at the drive limit with both
    /// faces at the water temperature (3.4 W for the default display); at least 1 mW.
    pub fn reference_heat_w(&self) -> f64 {
        self.module
            .max_cooling_w(self.current_limit_a, self.water_c, self.water_c)
            .max(1e-3)
    }

    /// The most useful cooling current at a plate temperature, A (negative): the optimum cooling current of the
    /// module or the drive limit, whichever is smaller in magnitude. More cooling current than this warms the plate
    /// or is not available.
    pub fn most_useful_cooling_a(&self, plate_c: f64) -> f64 {
        // Never positive (an absurd plate estimate, e.g. from a broken sensor, must not turn "cooling" into heating)
        // and never NaN-poisoned into a panic: max/min instead of clamp.
        self.module
            .optimum_cooling_current_a(plate_c)
            .max(-self.current_limit_a)
            .min(0.0)
    }

    /// Plate and hot side \[°C\] after one backward-Euler step of `dt_s` \[s\] from `start` (plate, hot side)
    /// at `current_a` \[A\] with `finger` on the plate: the model's own step, for open-loop simulations of it (the
    /// start-up self-test).
    pub fn nodes_after(&self, dt_s: f64, current_a: f64, start: [f64; 2], finger: Finger) -> [f64; 2] {
        self.plate_hot_step(dt_s, current_a, start, finger, 0.0).end
    }

    /// Plate and hot side after one backward-Euler step of `dt_s` from (`plate_c`, `hot_c`) at `current_a`, with the
    /// finger heat `g_f (receptor_c − T_p)` and the extra heat `extra_w` into the plate. Returns the end temperatures
    /// and the 2×2 map M⁻¹·diag(C/dt) of the start temperatures into them (for the observer's Jacobian) and M⁻¹e₁
    /// (the end temperatures' sensitivity to `extra_w`).
    fn plate_hot_step(&self, dt_s: f64, current_a: f64, start: [f64; 2], finger: Finger, extra_w: f64) -> NodeStep {
        let qd = self.module.display_heat_affine(current_a);
        let qh = self.module.hot_heat_affine(current_a);
        let cp = self.plate_heat_capacity_j_k / dt_s;
        let ch = self.hot_heat_capacity_j_k / dt_s;
        let gw = self.water_conductance_w_k;
        let (a11, a12) = (cp - qd.display_w_k + finger.conductance_w_k, -qd.hot_w_k);
        let (a21, a22) = (-qh.display_w_k, ch - qh.hot_w_k + gw);
        let r1 = cp * start[0] + qd.constant_w + finger.conductance_w_k * finger.receptor_c + extra_w;
        let r2 = ch * start[1] + qh.constant_w + gw * self.water_c;
        let det = a11 * a22 - a12 * a21;
        let inv = [[a22 / det, -a12 / det], [-a21 / det, a11 / det]];
        NodeStep {
            end: [inv[0][0] * r1 + inv[0][1] * r2, inv[1][0] * r1 + inv[1][1] * r2],
            start_map: [[inv[0][0] * cp, inv[0][1] * ch], [inv[1][0] * cp, inv[1][1] * ch]],
            heat_map: [inv[0][0], inv[1][0]],
        }
    }
}

/// The finger as the plate sees it: heat `conductance_w_k · (receptor_c − T_p)` into the plate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Finger {
    /// The finger model's receptor temperature, °C.
    pub receptor_c: f64,
    /// Conductance from the receptor to the plate, W/K (≥ 0; 0 = no finger or unknown).
    pub conductance_w_k: f64,
}

impl Finger {
    /// No finger (or none known): no heat.
    pub const NONE: Finger = Finger {
        receptor_c: 0.0,
        conductance_w_k: 0.0,
    };
}

/// One backward-Euler step of the plate and hot-side nodes.
struct NodeStep {
    end: [f64; 2],
    start_map: [[f64; 2]; 2],
    heat_map: [f64; 2],
}

/// The observer's estimate after an update. Temperatures in °C.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateEstimate {
    /// True plate (display) temperature, °C.
    pub plate_c: f64,
    /// Hot-side temperature, °C.
    pub hot_side_c: f64,
    /// Temperature of the PT-100 element (the lagged plate), °C.
    pub sensor_element_c: f64,
    /// Unknown heat into the plate the model misses, W.
    pub disturbance_w: f64,
    /// Standard deviation of the plate estimate, °C.
    pub plate_sd_c: f64,
    /// The plate's response to heat relative to its file (1 + θ: 1.3 is a plate 30 % faster, a heat capacity 1/1.3
    /// of the file's).
    pub plate_response_scale: f64,
}

/// One tick's data for the observer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverTick {
    /// Time since the previous tick, s (> 0).
    pub dt_s: f64,
    /// Current applied over that interval, A (positive heats).
    pub applied_current_a: f64,
    /// The finger at the end of the interval.
    pub finger: Finger,
    /// The PT-100 reading now, °C.
    pub sensor_c: f64,
    /// The hot-side reading now, °C.
    pub hot_side_c: f64,
}

impl ObserverTick {
    fn validate(&self) -> Result<(), ControlError> {
        Rule::Positive.check("dt_s", self.dt_s)?;
        Rule::Finite.check("applied_current_a", self.applied_current_a)?;
        Rule::Finite.check("finger_receptor_c", self.finger.receptor_c)?;
        Rule::NonNegative.check("finger_conductance_w_k", self.finger.conductance_w_k)?;
        Rule::Finite.check("sensor_c", self.sensor_c)?;
        Rule::Finite.check("hot_side_c", self.hot_side_c)?;
        Ok(())
    }
}

/// Kalman filter on `[T_p, T_h, T_s, d]`; see the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct PlateObserver {
    plant: PlantModel,
    design: ObserverDesign,
    x: Vector,
    p: Matrix,
    started: bool,
    /// Multi-rate use ([`PlateObserver::coast`]): the ticks coasted since the last correction.
    coasted: Coasted,
    /// Whether the last hot-side reading lay beyond [`HOT_SIDE_GATE_SD`] standard deviations of its prediction
    /// (the file's hot side then runs off the display's; see [`ObserverDesign::hot_side_response_uncertainty`]).
    hot_side_off: bool,
}

/// The ticks an observer coasted through since its last correction ([`PlateObserver::coast`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Coasted {
    /// Their total length, s.
    duration_s: f64,
    /// The charge they applied, A·s (their mean current is `charge_a_s / duration_s`).
    charge_a_s: f64,
    /// The state at the last correction (where the interval's Jacobian is taken).
    from_x: Vector,
    /// The sensor's decay over the last coasted tick's length: (length \[s\], e^(−dt/τ), β) — renewed only when the
    /// length changes (a loop's ticks are mostly equal).
    decay: (f64, f64, f64),
}

impl PlateObserver {
    /// An observer of `plant` (validated here) with the default [`ObserverDesign`]. It starts on its first
    /// [`PlateObserver::update`].
    pub fn new(plant: PlantModel) -> Result<Self, ControlError> {
        Self::with_design(plant, ObserverDesign::default())
    }

    /// An observer of `plant` with the noise model `design` (both validated here).
    pub fn with_design(plant: PlantModel, design: ObserverDesign) -> Result<Self, ControlError> {
        plant.validate()?;
        design.validate()?;
        Ok(Self {
            plant,
            design,
            x: [0.0; OBSERVER_STATES],
            p: [[0.0; OBSERVER_STATES]; OBSERVER_STATES],
            started: false,
            coasted: Coasted::default(),
            hot_side_off: false,
        })
    }

    /// The plant model.
    pub fn plant(&self) -> &PlantModel {
        &self.plant
    }

    /// Replaces the plant model's Peltier module (a live estimate of it); the state and its covariance are kept.
    pub fn set_module(&mut self, module: PeltierModule) {
        self.plant.module = module;
    }

    /// The noise model.
    pub fn design(&self) -> &ObserverDesign {
        &self.design
    }

    /// Forgets everything; the next update starts afresh.
    pub fn reset(&mut self) {
        self.x = [0.0; OBSERVER_STATES];
        self.p = [[0.0; OBSERVER_STATES]; OBSERVER_STATES];
        self.started = false;
        self.coasted = Coasted::default();
        self.hot_side_off = false;
    }

    /// The estimate (`None` before the first update).
    pub fn estimate(&self) -> Option<PlateEstimate> {
        self.started.then(|| PlateEstimate {
            plate_c: self.x[TP],
            hot_side_c: self.x[TH],
            sensor_element_c: self.x[TS],
            disturbance_w: self.x[DIST],
            plate_sd_c: self.p[TP][TP].max(0.0).sqrt(),
            plate_response_scale: 1.0 + self.x[SCALE],
        })
    }

    /// One tick: predicts over `tick.dt_s` with the applied current and the finger, then corrects with both
    /// readings. The first call initialises the estimate from the readings (plate = sensor, no unknown heat).
    /// Invalid input (non-finite, `dt_s` ≤ 0, negative conductance) is an error and changes nothing.
    pub fn update(&mut self, tick: &ObserverTick) -> Result<PlateEstimate, ControlError> {
        tick.validate()?;
        if self.started {
            self.predict(tick);
            self.correct(TS, tick.sensor_c, self.plant.sensor_variance_c2(), tick.dt_s);
            self.correct(TH, tick.hot_side_c, self.plant.hot_side_variance_c2(), tick.dt_s);
        } else {
            self.start(tick.sensor_c, tick.hot_side_c);
        }
        self.estimate().ok_or(ControlError::BadValue(BadValue::custom(
            "observer state",
            f64::NAN,
            "must stay finite",
        )))
    }

    /// Multi-rate use, for a loop that ticks faster than its PT-100 samples (the plate guard): advances the estimate
    /// over one tick of `dt_s` \[s\] at `current_a` \[A\] with `finger` without a fresh reading — the mean only, with
    /// the sensor's own time constant (a held sample is not seen again) — and keeps the interval for the next
    /// [`PlateObserver::update_fresh`], which propagates the covariance over it at once. Does nothing before the
    /// first update or for a `dt_s` that is not positive and finite, or non-finite inputs.
    pub fn coast(&mut self, dt_s: f64, current_a: f64, finger: Finger) {
        let inputs_ok = current_a.is_finite() && finger.receptor_c.is_finite() && finger.conductance_w_k >= 0.0;
        if !(self.started && dt_s.is_finite() && dt_s > 0.0 && inputs_ok) {
            return;
        }
        let step = self
            .plant
            .plate_hot_step(dt_s, current_a, [self.x[TP], self.x[TH]], finger, self.x[DIST]);
        let plate_c = step.end[0] + self.x[SCALE] * (step.end[0] - self.x[TP]);
        let (decay, w1, w0) = self.coasted_sensor_weights(dt_s);
        self.x[TS] = decay * self.x[TS] + w1 * plate_c + w0 * self.x[TP];
        self.x[TP] = plate_c;
        self.x[TH] = step.end[1];
        self.coasted.duration_s += dt_s;
        self.coasted.charge_a_s += current_a * dt_s;
    }

    /// Multi-rate use: the tick of a fresh PT-100 sample. Coasts over `tick` ([`PlateObserver::coast`]), then
    /// propagates the covariance over every tick coasted since the last correction at once (the Jacobian taken at
    /// that correction's state with the interval's mean current, the process noise of the whole interval) and
    /// corrects with both readings, each counted as one sample (or as the part of one that the interval is, when
    /// samples come faster than the file's rate). The first call initialises the estimate from the
    /// readings. Invalid input is an error and changes nothing.
    pub fn update_fresh(&mut self, tick: &ObserverTick) -> Result<PlateEstimate, ControlError> {
        tick.validate()?;
        if self.started {
            self.coast(tick.dt_s, tick.applied_current_a, tick.finger);
            let duration_s = self.coasted.duration_s;
            let interval = ObserverTick {
                dt_s: duration_s,
                applied_current_a: self.coasted.charge_a_s / duration_s,
                ..*tick
            };
            let lag_s = self.plant.sensor_time_constant_s;
            let (f, _) = self.transition_from(&self.coasted.from_x, &interval, lag_s);
            self.propagate_covariance(&f, duration_s);
            self.add_hot_side_response_noise(self.x[TH] - self.coasted.from_x[TH]);
            self.correct(TS, tick.sensor_c, self.plant.sensor_variance_c2(), duration_s);
            self.correct(TH, tick.hot_side_c, self.plant.hot_side_variance_c2(), duration_s);
        } else {
            self.start(tick.sensor_c, tick.hot_side_c);
        }
        self.coasted = Coasted {
            from_x: self.x,
            ..Coasted::default()
        };
        self.estimate().ok_or(ControlError::BadValue(BadValue::custom(
            "observer state",
            f64::NAN,
            "must stay finite",
        )))
    }

    /// The sensor's first-order weights over a coasted tick of `dt_s`: (e^(−dt/τ), 1 − β, β − e^(−dt/τ)) with
    /// τ the sensor's own time constant (see [`PlateObserver::transition_from`]), kept while the length is the same.
    fn coasted_sensor_weights(&mut self, dt_s: f64) -> (f64, f64, f64) {
        if self.coasted.decay.0 != dt_s {
            let (decay, beta) = sensor_decay(dt_s, self.plant.sensor_time_constant_s);
            self.coasted.decay = (dt_s, decay, beta);
        }
        let (_, decay, beta) = self.coasted.decay;
        (decay, 1.0 - beta, beta - decay)
    }

    /// The plate temperature one step of `dt_s` ahead at `current_a` with `finger`, from the current estimate, °C
    /// (`None` before the first update). Does not change the state.
    pub fn predict_plate_c(&self, dt_s: f64, current_a: f64, finger: Finger) -> Option<f64> {
        self.started.then(|| {
            let step = self
                .plant
                .plate_hot_step(dt_s, current_a, [self.x[TP], self.x[TH]], finger, self.x[DIST]);
            step.end[0] + self.x[SCALE] * (step.end[0] - self.x[TP])
        })
    }

    fn start(&mut self, sensor_c: f64, hot_side_c: f64) {
        let q_ref = self.plant.reference_heat_w();
        self.x = [sensor_c, hot_side_c, sensor_c, 0.0, 0.0];
        self.p = [[0.0; OBSERVER_STATES]; OBSERVER_STATES];
        self.p[TP][TP] = INITIAL_PLATE_SD_C.powi(2);
        self.p[TH][TH] = self.plant.hot_side_variance_c2();
        self.p[TS][TS] = self.plant.sensor_variance_c2();
        self.p[DIST][DIST] = (self.design.disturbance_initial_fraction * q_ref).powi(2);
        self.p[SCALE][SCALE] = self.design.plate_response_uncertainty.powi(2);
        self.started = true;
    }

    /// The linear one-step map `x₁ = F x₀ + c` from `x` over the tick (returned as F and x₁) at the tick's current
    /// and finger, the sensor lagging by `lag_s` \[s\].
    fn transition_from(&self, x: &Vector, tick: &ObserverTick, lag_s: f64) -> (Matrix, Vector) {
        let dt = tick.dt_s;
        let step = self
            .plant
            .plate_hot_step(dt, tick.applied_current_a, [x[TP], x[TH]], tick.finger, x[DIST]);
        // Exact lag for an input linear over the step: T_s1 = e T_s0 + (1 − β) T_p1 + (β − e) T_p0.
        let (decay, beta) = sensor_decay(dt, lag_s);
        let (w1, w0) = (1.0 - beta, beta - decay);
        let mut f = [[0.0; OBSERVER_STATES]; OBSERVER_STATES];
        for (row, node) in [(TP, 0), (TH, 1)] {
            f[row][TP] = step.start_map[node][0];
            f[row][TH] = step.start_map[node][1];
            f[row][DIST] = step.heat_map[node];
        }
        // The plate's change scaled by 1 + θ: T_p1 = end + θ (end − T_p0).
        let scale = x[SCALE];
        let change_c = step.end[0] - x[TP];
        let plate_c = step.end[0] + scale * change_c;
        for col in [TP, TH, DIST] {
            f[TP][col] *= 1.0 + scale;
        }
        f[TP][TP] -= scale;
        f[TP][SCALE] = change_c;
        for col in [TP, TH, DIST, SCALE] {
            f[TS][col] = w1 * f[TP][col];
        }
        f[TS][TP] += w0;
        f[TS][TS] = decay;
        f[DIST][DIST] = 1.0;
        f[SCALE][SCALE] = 1.0;
        let sensor = decay * x[TS] + w1 * plate_c + w0 * x[TP];
        (f, [plate_c, step.end[1], sensor, x[DIST], scale])
    }

    fn predict(&mut self, tick: &ObserverTick) {
        let lag_s = self.plant.effective_sensor_lag_s(tick.dt_s);
        let (f, x1) = self.transition_from(&self.x, tick, lag_s);
        self.propagate_covariance(&f, tick.dt_s);
        self.add_hot_side_response_noise(x1[TH] - self.x[TH]);
        self.x = x1;
    }

    /// Adds `(u · change)²` to the hot side's variance for its modelled `change_c` \[°C\] over a step, u the
    /// design's [`ObserverDesign::hot_side_response_uncertainty`], while the last hot-side reading was off its
    /// prediction (nothing otherwise, or when u is 0).
    fn add_hot_side_response_noise(&mut self, change_c: f64) {
        let u = self.design.hot_side_response_uncertainty;
        if u > 0.0 && self.hot_side_off {
            self.p[TH][TH] += (u * change_c).powi(2);
        }
    }

    /// `P ← F P Fᵀ + Q` over `dt_s` \[s\].
    fn propagate_covariance(&mut self, f: &Matrix, dt_s: f64) {
        self.p = times_transposed(&times(f, &self.p), f);
        let q = self.process_noise(dt_s);
        for (i, qi) in q.iter().enumerate() {
            self.p[i][i] += qi;
        }
    }

    /// Diagonal process noise over a step of `dt_s`: heat noise on plate and hot side, random walk of d (the
    /// plate's response scale is a constant).
    fn process_noise(&self, dt_s: f64) -> Vector {
        let q_ref = self.plant.reference_heat_w();
        // White heat of RMS a over one sample period has intensity a²·T_sample [W²·s]; over dt it adds
        // a²·T_sample·dt / C² to a node's variance.
        let heat = (self.design.plant_heat_noise_fraction * q_ref).powi(2) * self.plant.sample_period_s() * dt_s;
        [
            heat / self.plant.plate_heat_capacity_j_k.powi(2),
            heat / self.plant.hot_heat_capacity_j_k.powi(2),
            0.0,
            (self.design.disturbance_drift_per_sqrt_s * q_ref).powi(2) * dt_s,
            0.0,
        ]
    }

    /// Scalar Kalman update with a reading of state `index` of variance `variance` per sample; a reading held
    /// over several ticks counts as one sample per sample period.
    fn correct(&mut self, index: usize, reading: f64, variance: f64, dt_s: f64) {
        let repeats = (self.plant.sample_period_s() / dt_s).max(1.0);
        let r = variance * repeats;
        let s = self.p[index][index] + r;
        let gain: Vector = std::array::from_fn(|i| self.p[i][index] / s);
        let innovation = reading - self.x[index];
        if index == TH {
            self.hot_side_off = innovation * innovation > HOT_SIDE_GATE_SD * HOT_SIDE_GATE_SD * s;
        }
        for (x, k) in self.x.iter_mut().zip(gain) {
            *x += k * innovation;
        }
        self.x[SCALE] = self.x[SCALE].clamp(SCALE_BOUNDS.0, SCALE_BOUNDS.1);
        let row = self.p[index];
        for (i, k) in gain.iter().enumerate() {
            for (j, pj) in row.iter().enumerate() {
                self.p[i][j] -= k * pj;
            }
        }
        // Keep P symmetric against rounding.
        for i in 0..OBSERVER_STATES {
            for j in (i + 1)..OBSERVER_STATES {
                let m = 0.5 * (self.p[i][j] + self.p[j][i]);
                self.p[i][j] = m;
                self.p[j][i] = m;
            }
        }
    }
}

/// A first-order sensor of time constant `lag_s` \[s\] over `dt_s` \[s\]: (e^(−dt/τ), β = τ/dt (1 − e^(−dt/τ))).
fn sensor_decay(dt_s: f64, lag_s: f64) -> (f64, f64) {
    let decay = (-dt_s / lag_s).exp();
    (decay, lag_s / dt_s * (1.0 - decay))
}

/// `F·P` for the covariance's prediction, skipping the terms where `F` is zero (most of its entries: the unknown heat
/// and the plate's response map onto themselves), which leaves every sum as it was.
fn times(f: &Matrix, p: &Matrix) -> Matrix {
    let mut out = [[0.0; OBSERVER_STATES]; OBSERVER_STATES];
    for (out_row, f_row) in out.iter_mut().zip(f) {
        for (&f_ik, p_row) in f_row.iter().zip(p) {
            if f_ik != 0.0 {
                for (o, &p_kj) in out_row.iter_mut().zip(p_row) {
                    *o += f_ik * p_kj;
                }
            }
        }
    }
    out
}

/// `A·Fᵀ`, skipping the terms where `F` is zero (see [`times`]).
fn times_transposed(a: &Matrix, f: &Matrix) -> Matrix {
    let mut out = [[0.0; OBSERVER_STATES]; OBSERVER_STATES];
    for (j, f_row) in f.iter().enumerate() {
        for (k, &f_jk) in f_row.iter().enumerate() {
            if f_jk != 0.0 {
                for (out_row, a_row) in out.iter_mut().zip(a) {
                    out_row[j] += a_row[k] * f_jk;
                }
            }
        }
    }
    out
}
