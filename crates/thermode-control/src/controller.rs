//! The controller interface every display controller implements, and the paper's controller behind it.
//!
//! A [`Controller`] turns one tick's [`ControlInput`] into a requested drive current (A, positive heats the
//! display). The request is *not* a drive: it must pass `thermode_safety::SafetyEnvelope::gate_drive`, which is the only
//! way to a `thermode_safety::DriveCommand`. The trait is object safe (`Box<dyn Controller>`), so the runtime can pick
//! `pid` or the model-based controller at run time.
//!
//! [`PidController`] is the paper's structure (section 3.2, Figure 2): a first-order low-pass filter on the sensor,
//! then a PID on the filtered value.

use crate::error::ControlError;
use crate::filter::LowPass;
use crate::pid::{Pid, PidGains, PidTerms};
use thermode_model::Rule;

/// Everything a controller may use on one tick. Temperatures in °C, current in A (positive heats the display).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlInput {
    /// Time of this tick, s (same clock as the envelope; informative, controllers integrate with `dt_s`).
    pub time_s: f64,
    /// Time since the previous tick, s (> 0).
    pub dt_s: f64,
    /// The display set-point as shaped by the safety envelope, °C.
    pub setpoint_c: f64,
    /// Rate of change of the shaped set-point over the last interval, °C/s (for feed-forward).
    pub setpoint_rate_c_per_s: f64,
    /// The newest display sensor reading (raw, unfiltered), °C.
    pub sensor_c: f64,
    /// The newest hot-side (reference side) temperature, °C.
    pub hot_side_c: f64,
    /// The current the envelope actually let through on the previous tick, A (0 at start). Observers and
    /// anti-windup schemes should use this rather than their own previous request.
    pub applied_current_a: f64,
    /// The receptor temperature of the finger model resting on the display (the display inverse's model), °C;
    /// `None` when no finger model runs (direct set-point mode on real hardware without a model).
    pub finger_receptor_c: Option<f64>,
    /// Conductance from that receptor node to the plate over the contact area, W/K (receptor conductance per area
    /// times the contact area), so the heat the finger gives the plate is
    /// `finger_conductance_w_k · (finger_receptor_c − T_plate)`. 0 when unknown.
    pub finger_conductance_w_k: f64,
    /// The drive's own measurement with this tick's reading: the current it delivers, A, and the module's terminal
    /// voltage, V; NaN when the device does not report them. The model controller fits its module to them.
    pub measured_current_a: f64,
    /// See `measured_current_a`.
    pub voltage_v: f64,
    /// Whether `sensor_c` is a fresh PT-100 sample (false: the sample of an earlier tick, held). The model
    /// controller's observer corrects on fresh samples and coasts between them; true when the caller cannot tell.
    pub fresh_sample: bool,
}

/// A display temperature controller: one requested current per tick.
pub trait Controller {
    /// A short stable name for logs and the CLI (`"pid"`, `"model"`).
    fn name(&self) -> &'static str;

    /// Computes the requested drive current in A (positive heats) for this tick. An invalid input (non-finite
    /// value, `dt_s` ≤ 0) is an error and must leave the controller's state untouched; the caller then requests
    /// `f64::NAN` from the envelope, which latches a fault and switches the channel off.
    fn update(&mut self, input: &ControlInput) -> Result<f64, ControlError>;

    /// Forgets all internal state (filters, integrators, observers), as after a restart.
    fn reset(&mut self);

    /// The controller's best estimate of the true display (plate) temperature after its last update, °C, if it
    /// has one (an observer). The pipeline advances the display inverse's finger model with this value — what the
    /// finger really receives — instead of the set-point; `None` (the paper's way) advances it with the set-point.
    fn plate_estimate_c(&self) -> Option<f64> {
        None
    }

    /// The heat into the plate that the controller has learned its model misses, W (positive warms the plate),
    /// after its last update, if it learns one (an observer's unknown-heat state); `None` (the default) otherwise.
    /// With the display rendering air before a touch, it tells how much more heat the real finger gives the plate
    /// than the finger model does, which the pipeline can use to calibrate its finger model to this finger.
    fn unknown_heat_w(&self) -> Option<f64> {
        None
    }
}

/// The paper's controller: sensor → first-order low-pass → PID (derivative on the filtered measurement).
#[derive(Debug, Clone, PartialEq)]
pub struct PidController {
    filter: LowPass,
    pid: Pid,
}

impl PidController {
    /// Builds the filter from `gains.filter_cutoff_hz` and the PID with output limits `±current_limit_a`.
    pub fn new(gains: PidGains, current_limit_a: f64) -> Result<Self, ControlError> {
        Ok(Self {
            filter: LowPass::new(gains.filter_cutoff_hz)?,
            pid: Pid::new(gains, current_limit_a)?,
        })
    }

    /// The PID inside (gains, limits).
    pub fn pid(&self) -> &Pid {
        &self.pid
    }

    /// The last P, I, D terms and output, for logging.
    pub fn terms(&self) -> PidTerms {
        self.pid.terms()
    }

    /// The last filtered sensor value, °C (`None` before the first tick).
    pub fn filtered_c(&self) -> Option<f64> {
        self.filter.value()
    }
}

impl Controller for PidController {
    fn name(&self) -> &'static str {
        "pid"
    }

    fn update(&mut self, input: &ControlInput) -> Result<f64, ControlError> {
        // Validate everything the PID uses before touching the filter, so a refused tick changes nothing.
        Rule::Finite.check("setpoint_c", input.setpoint_c)?;
        Rule::Finite.check("sensor_c", input.sensor_c)?;
        Rule::Positive.check("dt_s", input.dt_s)?;
        let filtered_c = self.filter.update(input.sensor_c, input.dt_s)?;
        self.pid.update(input.setpoint_c, filtered_c, input.dt_s)
    }

    fn reset(&mut self) {
        self.filter.reset();
        self.pid.reset();
    }
}
