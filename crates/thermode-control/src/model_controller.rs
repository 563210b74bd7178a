//! thermode's own display controller, `model`: a Kalman observer of the true plate temperature
//! ([`crate::observer::PlateObserver`]) and an inversion of the plate's heat balance through the Peltier equations,
//! with every number taken from the device file ([`PlantModel`]). It removes the two flaws the paper saw with its
//! PID on a low-pass-filtered sensor (section 4.1, Figure 3):
//!
//! 1. *The slow initial drop* (the Peltier's cooling capacity). A set-point the plate cannot follow asks for more
//!    heat than the module can pump; the controller then drives the **most useful cooling current** (the drive
//!    limit or the module's optimum current `−S T_p / R`, whichever is smaller in magnitude; beyond the optimum
//!    more current warms the plate) at once, with no filter or integrator delaying it.
//! 2. *The colder end* (controller inertia). There is no integrator to wind up: offset-freedom comes from the
//!    observer's unknown-heat state, which is driven by the current actually applied, so saturation cannot wind
//!    anything up. The controller reports the plate temperature it expects at the end of the tick
//!    ([`Controller::plate_estimate_c`]), and the pipeline advances the display inverse's finger model with it:
//!    when the plate lags the set-point, the finger model knows it, and the next set-point already accounts for the
//!    lag instead of driving the finger past its target.
//!
//! # Control law (one tick of length h)
//! With the observer's estimate `T̂_p, T̂_h, d̂` after this tick's readings, the shaped set-point s and its rate ṡ,
//! and the finger model (receptor T_r, conductance G_f):
//! - Reference for the end of the tick: the error to the set-point decays with the closed-loop time constant τ_c,
//!   and a ramping set-point is followed without lag:
//!   `T_p* = s + λ (T̂_p − s + ṡ h)`, `λ = exp(−h/τ_c)`;
//!   but the plate is never driven against the set-point's motion: while the set-point rises, `T_p* ≥ T̂_p`,
//!   while it falls, `T_p* ≤ T̂_p`. This matters when a set-point the plate could not follow turns back towards
//!   it (the finger has reached its target, and the rate-limited set-point returns from beyond the plate): the plate
//!   then waits for the set-point instead of running on to meet it and having to turn back, which would carry the
//!   finger past its target. The bound acts only when the plate is ahead of a moving set-point by more than
//!   `λ/(1 − λ)` ticks of its motion (1.5 at the default tick), so it never touches a plate following a ramp.
//! - Heat the plate needs for that (backward Euler, as the plant integrates), with the plate's capacity as the
//!   observer has learnt it (the file's C_p over its response scale 1 + θ̂, [`PlateEstimate::plate_response_scale`]):
//!   `q* = C_p/(1 + θ̂) (T_p* − T̂_p)/h − G_f (T_r − T_p*) − d̂`.
//! - Current: the root of `q_d(I, T_p*, T̂_h) = q*` on the efficient branch
//!   ([`thermode_model::peltier::PeltierModule::current_for_heat_into_display`]), limited to
//!   `[most useful cooling current, +drive limit]`; if more cooling is asked than the module can pump at any
//!   current, the most useful cooling current.
//! - τ_c = [`ModelDesign::closed_loop_sample_periods`] sensor sample periods (at least the tick): the feedback
//!   acts on the observer's estimate, which is model-based and nearly noise-free, so the loop can be as fast as the
//!   sensor delivers information.
//!
//! When the device reports the module's voltage ([`ControlInput::voltage_v`]), the observer's Peltier module is
//! fitted to it live ([`ModuleFit`]: S and R from the voltage, K as [`ModelDesign::module_conductance`] says), so a
//! module that is not its datasheet does not leave a current-dependent error in the observer's unknown heat.
//!
//! No control error is integrated anywhere, so there is nothing to wind up: the only integrating state is the
//! observer's unknown heat, an estimate of a physical heat flow driven by the current really applied, which stays
//! right while the drive is saturated.
//!
//! Invalid input (non-finite values, `dt_s` ≤ 0, a negative finger conductance) is an error and leaves the state
//! untouched. No allocation per tick; deterministic.
//!
//! ```
//! use thermode_control::{ControlInput, Controller, ModelController, PlantModel};
//! use thermode_model::peltier::{PeltierDatasheet, PeltierModule};
//! // The default display's device file.
//! let plant = PlantModel {
//!     module: PeltierModule::from_datasheet(&PeltierDatasheet::default())?,
//!     plate_heat_capacity_j_k: 0.28,
//!     hot_heat_capacity_j_k: 1.7,
//!     water_conductance_w_k: 0.3,
//!     water_c: 23.0,
//!     sensor_time_constant_s: 0.3,
//!     sensor_noise_c: 0.02,
//!     sensor_resolution_c: 0.01,
//!     sensor_sample_rate_hz: 100.0,
//!     current_limit_a: 2.8,
//! };
//! let mut controller = ModelController::new(plant)?;
//! // A plate resting at 32 °C asked to be at 20 °C: far out of reach in one tick, so full cooling.
//! let input = ControlInput { time_s: 0.0, dt_s: 0.01, setpoint_c: 20.0, setpoint_rate_c_per_s: 0.0,
//!     sensor_c: 32.0, hot_side_c: 23.0, applied_current_a: 0.0, finger_receptor_c: Some(32.1),
//!     finger_conductance_w_k: 0.064, measured_current_a: f64::NAN, voltage_v: f64::NAN, fresh_sample: true };
//! assert_eq!(controller.update(&input)?, -2.8);
//! assert!(controller.plate_estimate_c().is_some_and(|p| p < 32.0));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::controller::{ControlInput, Controller};
use crate::error::ControlError;
use crate::module_fit::{ConductanceRule, ModuleFit};
use crate::observer::{Finger, ObserverDesign, ObserverTick, PlantModel, PlateEstimate, PlateObserver};
use thermode_model::Rule;

/// The controller's design constants, the same for every display (everything display-specific comes from the
/// [`PlantModel`]). Defaults in the field docs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelDesign {
    /// The observer's noise model. Default [`ObserverDesign::default`].
    pub observer: ObserverDesign,
    /// Relative standard deviation of the device file's S and R with which the live fit to the module's voltage
    /// starts ([`ModuleFit`]), > 0; `None`: no fit (the file's module throughout). Default `Some(0.3)` (datasheet
    /// values); the pipeline gives the device file's `render.peltier_uncertainty`, and `None` when that is 0.
    pub module_fit_relative_sd: Option<f64>,
    /// What the fitted S and R say of the module's conductance K ([`ConductanceRule`]). Default
    /// [`ConductanceRule::ErrorSources`] (a module's S, R and K may each be off its file on its own).
    pub module_conductance: ConductanceRule,
    /// Closed-loop time constant of the plate, in sensor sample periods (> 0). Default 2 (20 ms for the default
    /// 100 Hz PT-100).
    pub closed_loop_sample_periods: f64,
}

impl Default for ModelDesign {
    fn default() -> Self {
        Self {
            observer: ObserverDesign::default(),
            module_fit_relative_sd: Some(0.3),
            module_conductance: ConductanceRule::default(),
            closed_loop_sample_periods: 2.0,
        }
    }
}

/// What the controller did on its last tick, for logging and tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelTerms {
    /// The observer's estimate after this tick's readings.
    pub estimate: PlateEstimate,
    /// Plate temperature aimed at for the end of the tick, °C.
    pub reference_c: f64,
    /// Heat into the plate needed for that, W (negative = cooling).
    pub heat_needed_w: f64,
    /// The requested current, A (positive heats).
    pub current_a: f64,
    /// Whether the request was limited (drive limit, most useful cooling current, or infeasible heat).
    pub saturated: bool,
    /// Plate temperature expected at the end of the tick with the requested current, °C.
    pub predicted_plate_c: f64,
}

/// The model-based controller; see the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelController {
    observer: PlateObserver,
    closed_loop_sample_periods: f64,
    terms: Option<ModelTerms>,
    /// The live fit of the module to its voltage (`None`: off), as it started, and as it is.
    module_fit_start: Option<ModuleFit>,
    module_fit: Option<ModuleFit>,
}

impl ModelController {
    /// A controller for the display described by `plant` (validated here), with the default [`ModelDesign`].
    pub fn new(plant: PlantModel) -> Result<Self, ControlError> {
        Self::with_design(plant, ModelDesign::default())
    }

    /// A controller for `plant` with the design constants `design` (both validated here).
    pub fn with_design(plant: PlantModel, design: ModelDesign) -> Result<Self, ControlError> {
        let periods = design.closed_loop_sample_periods;
        Rule::Positive.check("closed_loop_sample_periods [-]", periods)?;
        if let Some(sd) = design.module_fit_relative_sd {
            Rule::Positive.check("module_fit_relative_sd [-]", sd)?;
        }
        let module_fit = design
            .module_fit_relative_sd
            .map(|sd| ModuleFit::with_conductance(plant.module, sd, design.module_conductance));
        Ok(Self {
            observer: PlateObserver::with_design(plant, design.observer)?,
            closed_loop_sample_periods: periods,
            terms: None,
            module_fit_start: module_fit,
            module_fit,
        })
    }

    /// The plant model in use.
    pub fn plant(&self) -> &PlantModel {
        self.observer.plant()
    }

    /// The observer.
    pub fn observer(&self) -> &PlateObserver {
        &self.observer
    }

    /// What the last tick did (`None` before the first tick or after a reset).
    pub fn terms(&self) -> Option<ModelTerms> {
        self.terms
    }

    /// The closed-loop time constant for a tick of `dt_s`, s.
    pub fn closed_loop_time_constant_s(&self, dt_s: f64) -> f64 {
        self.closed_loop_sample_periods * self.plant().sample_period_s().max(dt_s)
    }

    fn validate(input: &ControlInput) -> Result<Finger, ControlError> {
        Rule::Finite.check("time_s", input.time_s)?;
        Rule::Finite.check("setpoint_c", input.setpoint_c)?;
        Rule::Finite.check("setpoint_rate_c_per_s", input.setpoint_rate_c_per_s)?;
        Rule::Finite.check("sensor_c", input.sensor_c)?;
        Rule::Finite.check("hot_side_c", input.hot_side_c)?;
        Rule::Finite.check("applied_current_a", input.applied_current_a)?;
        Rule::Positive.check("dt_s", input.dt_s)?;
        Rule::NonNegative.check("finger_conductance_w_k", input.finger_conductance_w_k)?;
        match input.finger_receptor_c {
            Some(receptor_c) => {
                Rule::Finite.check("finger_receptor_c", receptor_c)?;
                Ok(Finger {
                    receptor_c,
                    conductance_w_k: input.finger_conductance_w_k,
                })
            }
            None => Ok(Finger::NONE),
        }
    }

    /// Where the plate should be at the end of the tick (see the module documentation): the error to the set-point
    /// decays by `lambda`, a ramp is followed without lag, and the plate is never driven against the direction in
    /// which the set-point moves.
    fn reference_c(plate_c: f64, input: &ControlInput, lambda: f64) -> f64 {
        let (s, rate) = (input.setpoint_c, input.setpoint_rate_c_per_s);
        let reference_c = s + lambda * (plate_c - s + rate * input.dt_s);
        if rate > 0.0 {
            reference_c.max(plate_c)
        } else if rate < 0.0 {
            reference_c.min(plate_c)
        } else {
            reference_c
        }
    }

    /// The control law on an estimate; see the module documentation.
    fn control(
        &self,
        observer: &PlateObserver,
        est: &PlateEstimate,
        input: &ControlInput,
        finger: Finger,
    ) -> ModelTerms {
        let plant = observer.plant();
        let h = input.dt_s;
        let lambda = (-h / self.closed_loop_time_constant_s(h)).exp();
        let reference_c = Self::reference_c(est.plate_c, input, lambda);
        let heat_needed_w = plant.plate_heat_capacity_j_k / est.plate_response_scale * (reference_c - est.plate_c) / h
            - finger.conductance_w_k * (finger.receptor_c - reference_c)
            - est.disturbance_w;
        let lowest_a = plant.most_useful_cooling_a(est.plate_c);
        let unlimited = plant
            .module
            .current_for_heat_into_display(heat_needed_w, reference_c, est.hot_side_c);
        let current_a = unlimited.unwrap_or(lowest_a).max(lowest_a).min(plant.current_limit_a);
        let saturated = unlimited != Some(current_a);
        let predicted_plate_c = observer.predict_plate_c(h, current_a, finger).unwrap_or(est.plate_c);
        ModelTerms {
            estimate: *est,
            reference_c,
            heat_needed_w,
            current_a,
            saturated,
            predicted_plate_c,
        }
    }
}

impl Controller for ModelController {
    fn name(&self) -> &'static str {
        "model"
    }

    fn update(&mut self, input: &ControlInput) -> Result<f64, ControlError> {
        let finger = Self::validate(input)?;
        let mut observer = self.observer.clone();
        let tick = ObserverTick {
            dt_s: input.dt_s,
            applied_current_a: input.applied_current_a,
            finger,
            sensor_c: input.sensor_c,
            hot_side_c: input.hot_side_c,
        };
        // Corrected on a fresh PT-100 sample, coasting through the ticks that see a held one (a started observer).
        let estimate = match observer.estimate() {
            Some(before) if !input.fresh_sample => {
                observer.coast(tick.dt_s, tick.applied_current_a, tick.finger);
                observer.estimate().unwrap_or(before)
            }
            _ => observer.update_fresh(&tick)?,
        };
        let mut module_fit = self.module_fit;
        if let Some(fit) = &mut module_fit {
            let (current_a, voltage_v) = (input.measured_current_a, input.voltage_v);
            if let Some(module) = fit.update(voltage_v, current_a, estimate.plate_c, input.hot_side_c, input.dt_s) {
                observer.set_module(module);
            }
        }
        let terms = self.control(&observer, &estimate, input, finger);
        Rule::Finite.check("requested current", terms.current_a)?;
        Rule::Finite.check("predicted plate temperature", terms.predicted_plate_c)?;
        self.observer = observer;
        self.module_fit = module_fit;
        self.terms = Some(terms);
        Ok(terms.current_a)
    }

    fn reset(&mut self) {
        self.observer.reset();
        if let Some(start) = self.module_fit_start {
            self.observer.set_module(start.file_module());
        }
        self.module_fit = self.module_fit_start;
        self.terms = None;
    }

    /// The plate temperature expected at the end of the coming tick with the requested current, °C (what the finger
    /// will receive over that tick, as the plant integrates it); `None` before the first tick.
    fn plate_estimate_c(&self) -> Option<f64> {
        self.terms.map(|t| t.predicted_plate_c)
    }

    /// The observer's unknown heat after the last update, W ([`PlateEstimate::disturbance_w`]); `None` before the
    /// first tick.
    fn unknown_heat_w(&self) -> Option<f64> {
        self.terms.map(|t| t.estimate.disturbance_w)
    }
}
