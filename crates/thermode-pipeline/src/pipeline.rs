//! One display channel's pipeline: renderer → display inverse → safety envelope → controller → safety envelope →
//! drive, as one allocation-free tick that cannot panic.
//!
//! # One tick at time `now_s` over the interval [now, now + dt]
//! 1. `envelope.observe(reading)`: fault checks and thermal dose on the newest measurement.
//! 2. The renderer (the controller's finger model touching the virtual world) steps to now + dt; its receptor is
//!    the target. In direct mode the renderer idles in air and the requested set-point is the direct ramp instead.
//! 3. The display inverse gives the display set-point that, held over the request horizon
//!    H = max(dt, 1/sensor sample rate) ([`ChannelPipeline::request_horizon_s`]), brings the finger model on the
//!    display to the target (unlimited). The finger model itself still advances by dt (step 7): the request is
//!    recomputed every tick from the model's present state, a receding horizon of which only the first dt is used.
//!    Why not one tick: at a high tick rate a one-tick request is a steep set-point that asks the receptor to
//!    close its whole error in 1 ms and overshoots (figures in `docs/design-choices.md`); the sensor delivers
//!    nothing new faster than its sample period. At the default 100 Hz (tick = sample period) nothing changes.
//!    3a. If the controller reports a plate estimate (an observer), the request is limited to a band of
//!    [`FEASIBLE_BAND_C`] around the plate temperature it expects now, so the envelope's rate limiter never winds up
//!    far from a plate that cannot follow (the paper's PID has no estimate and gets the request unchanged).
//! 4. `envelope.shape_setpoint`: clamp into the display limits and rate limit.
//! 5. `controller.update` on the shaped set-point, with the finger model's receptor temperature and its
//!    conductance to the plate (receptor conductance × contact area); the set-point's rate is given as 0 while the
//!    band of 3a holds the request and the set-point moves away from it (it then only follows the estimate).
//! 6. `envelope.gate_drive`: the only way to a [`DriveCommand`], with the plate guard's forecast of the true
//!    plate ([`crate::guard::PlateGuard`], updated at the start of this step), so the envelope bounds the plate and
//!    not only the lagging reading, whatever the controller.
//! 7. The finger model on the display advances with what the finger really receives: the controller's plate
//!    estimate if it has one (an observer), else the shaped set-point (the paper's way).
//!
//! While the channel is held off ([`ChannelPipeline::hold`], stop all) steps 3a–6 are replaced by the envelope's
//! hold: 0 A, faults still checked, the controller not asked and restarted when the hold ends.
//!
//! Before the first touch, while the display renders air, the controller's learned unknown heat is averaged; at
//! the first touch it calibrates the finger models to the real finger ([`PipelineConfig::calibrate_finger_at_touch`]).
//!
//! A time step that is not finite and positive skips steps 2–5 and requests NaN from the envelope, which latches
//! [`thermode_safety::FaultCode::NonFiniteCommand`] (as for any controller error) and switches the drive off.
//! Every other broken number (NaN from a model, a sensor fault) latches its fault in the envelope as well.

use thermode_control::{ControlInput, Controller, Finger};
use thermode_device::{DeviceConfig, Reading};
use thermode_model::fv::{FvConfig, FvModel, ModalStepping};
use thermode_model::kron::calibrate_to_surface;
use thermode_model::limits::CONTACT_RESISTANCE;
use thermode_model::peltier::PeltierModule;
use thermode_model::{Material, Rule, Skin};
use thermode_safety::{
    DoseLedger, DriveCommand, EnvelopeConfig, FaultCode, MeasuredOnly, SafetyEnvelope, SetpointDecision,
};

use crate::controllers::{build_controller, plant_model, ControllerKind};
use crate::display::DisplayFinger;
use crate::error::PipelineError;
use crate::guard::PlateGuard;
use crate::renderer::{fv_config, Renderer, RendererKind, LIGHT_TOUCH_RESISTANCE_M2K_W};
use crate::self_test::{SelfTest, SelfTestReport, SelfTestRun};
use crate::stimulus::Stimulus;

/// The ambient temperature a pipeline accepts: the one physical range of air temperatures,
/// [`thermode_model::limits::AMBIENT_TEMPERATURE`] (−30 to 50 °C).
pub use thermode_model::limits::AMBIENT_TEMPERATURE;

/// How much higher than its set-point rate limit a rendering envelope puts its plausibility bound on the measured
/// plate rate (`max_measured_rate_c_per_s`): 2.5 times, and never below the envelope's default (50 °C/s). The
/// default display renders at 20 °C/s, where this is exactly the default 50 °C/s; a display that renders faster
/// keeps the same margin for a plate that follows its set-point with sensor noise on top.
pub const MEASURED_RATE_PER_SETPOINT_RATE: f64 = 2.5;

/// The safety envelope of a pipeline that renders on `device` with the set-point rate limit `max_rate_c_per_s`
/// \[°C/s\]: [`EnvelopeConfig::default`] with that limit, the measured-rate plausibility bound raised to
/// [`MEASURED_RATE_PER_SETPOINT_RATE`] times it where that exceeds the default, and the device's sensor time
/// constant (the thermal dose is counted at the plate reconstructed from the sensor). The limit is checked when
/// the envelope is validated (at most the compiled-in [`thermode_safety::ABSOLUTE_MAX_RATE_C_PER_S`]).
pub fn render_envelope_with_rate(device: &DeviceConfig, max_rate_c_per_s: f64) -> EnvelopeConfig {
    let default = EnvelopeConfig::default();
    EnvelopeConfig {
        max_setpoint_rate_c_per_s: max_rate_c_per_s,
        sensor_time_constant_s: device.sensor.time_constant_s,
        max_measured_rate_c_per_s: default
            .max_measured_rate_c_per_s
            .max(MEASURED_RATE_PER_SETPOINT_RATE * max_rate_c_per_s),
        ..default
    }
}

/// The safety envelope of a pipeline rendering on `device`: [`render_envelope_with_rate`] with the device file's
/// rendering rate (`render.max_setpoint_rate_c_per_s`, 20 °C/s for the default display) instead of the envelope's
/// general default of 10.
///
/// Why a per-device rate: rendering a touch must let the Peltier cool as fast as it physically can (the paper's
/// first flaw is that limit); the default module cools the resting plate at about 13 °C/s at full current, so at
/// 10 °C/s the envelope and not the actuator would limit the initial drop (figures in `docs/design-choices.md`),
/// and a display with a stronger module needs a higher limit for the same reason.
pub fn render_envelope(device: &DeviceConfig) -> EnvelopeConfig {
    render_envelope_with_rate(device, device.render.max_setpoint_rate_c_per_s)
}

/// The fastest an idle temperature-commanded channel (rendering air) moves its set-point \[°C/s\]: 1 (see
/// [`ChannelPipeline::tick`]; the paper's displays changed at 0.1–2 °C/s, where a change from rest is barely felt).
pub const IDLE_RATE_C_PER_S: f64 = 1.0;

/// Half width of the band around the controller's plate estimate that a requested set-point is limited to \[°C\]:
/// 1 (see the module documentation, step 3a). A model controller asks for its full current about 0.3 °C beyond
/// the plate at 100 Hz; 1 °C leaves margin.
pub const FEASIBLE_BAND_C: f64 = 1.0;

/// Everything a channel pipeline is built from.
#[derive(Debug, Clone, PartialEq)]
pub struct PipelineConfig {
    /// The display (device file): drive limit, finger contact conductance and area, and for `model` every plant
    /// number. Default [`DeviceConfig::default`].
    pub device: DeviceConfig,
    /// The renderer, and with it the finger model of the display inverse. Default [`RendererKind::Fv`].
    pub renderer: RendererKind,
    /// The controller. No default here: see [`crate::controllers::gains_for_device`] for the tuned PID gains.
    pub controller: ControllerKind,
    /// The safety envelope. Default [`render_envelope`] of the device (15–48 °C, the device's rendering rate: 20
    /// °C/s for the default display) with the device file's sensor time constant (the thermal dose is counted at the
    /// plate reconstructed from the sensor); its `sensor_time_constant_s` must not be shorter than the device's.
    pub envelope: EnvelopeConfig,
    /// The controller's model of the finger (renderer and display inverse). Default [`Skin::fingertip`].
    pub skin: Skin,
    /// Air temperature \[°C\], in [`AMBIENT_TEMPERATURE`]. Default 23 (the paper's room).
    pub ambient_c: f64,
    /// Contact resistance between skin and virtual object of the fv renderer [m²K/W], in
    /// [`thermode_model::limits::CONTACT_RESISTANCE`]. Default
    /// [`LIGHT_TOUCH_RESISTANCE_M2K_W`] (1e-3, light touch). The kron renderer has none.
    pub contact_resistance_m2k_w: f64,
    /// Whether a touch from air calibrates the finger models (renderer and display inverse) to the resting surface
    /// temperature of the real finger, as the controller's learned unknown heat tells it
    /// ([`ChannelPipeline::set_stimulus`]). Default true; without a controller that learns an unknown heat
    /// ([`Controller::unknown_heat_w`], e.g. the paper's PID) nothing is calibrated.
    pub calibrate_finger_at_touch: bool,
    /// How the fv renderer and the fv display finger step: on the modal fast path
    /// ([`ModalFv`](thermode_model::fv::ModalFv), selected where the grid allows it) with
    /// [`ModalStepping::Exact`] (default: exact in time for the finite-volume equations, within 0.005 °C of the full
    /// model converged in time) or [`ModalStepping::Scheme`] (the full model's TR-BDF2 step per tick reproduced to
    /// rounding), or `None`: the full model, one TR-BDF2 step per tick, as before the fast path (for comparisons
    /// and benchmarks).
    pub fv_fast_path: Option<ModalStepping>,
    /// Whether the channel tests its display against the device file before its first stimulus
    /// ([`crate::self_test`]): for its first [`SelfTest::record_s`] the drive is the self-test's pulse through the
    /// envelope and every stimulus but air is refused; a display off its file is then refused (fault E106). Default
    /// false (a simulated display built from its own file is that file); a daemon on real hardware driven by
    /// current sets it.
    pub self_test_at_start: bool,
    /// Whether the device regulates its plate to the set-point itself (a TCS II; a MeCom controller in temperature
    /// mode): thermode's current does not reach the plate. The controller is then not asked (a model controller
    /// would integrate a current the plate never gets and wind its estimate, and with it the set-point, up: an
    /// idle MeCom channel reached 48 °C in 2 s), no feasible band is drawn around its estimate, the finger model
    /// on the display follows the shaped set-point (what the device regulates to), the plate guard takes the current
    /// the device reports delivering (none reported: 0 A) and runs no innovation check, and nothing counts as a
    /// drive stuck at its limit. Default false (thermode drives the current).
    pub temperature_commanded: bool,
}

impl PipelineConfig {
    /// The defaults above for `device` and `controller`.
    pub fn new(device: DeviceConfig, controller: ControllerKind) -> Self {
        PipelineConfig {
            device,
            renderer: RendererKind::Fv,
            controller,
            envelope: render_envelope(&device),
            skin: Skin::fingertip(),
            ambient_c: 23.0,
            contact_resistance_m2k_w: LIGHT_TOUCH_RESISTANCE_M2K_W,
            calibrate_finger_at_touch: true,
            fv_fast_path: Some(ModalStepping::Exact),
            self_test_at_start: false,
            temperature_commanded: false,
        }
    }

    /// Checks the numbers the pipeline itself adds (the models, device, envelope and controller check theirs when
    /// the pipeline is built).
    pub fn validate(&self) -> Result<(), PipelineError> {
        AMBIENT_TEMPERATURE.check(self.ambient_c)?;
        CONTACT_RESISTANCE.check(self.contact_resistance_m2k_w)?;
        self.device.validate("device config")?;
        self.envelope.validate()?;
        Rule::AtMost {
            max: self.envelope.sensor_time_constant_s,
            what: "the envelope's sensor_time_constant_s [s] (a shorter assumed lag under-counts the thermal dose)",
        }
        .check("device sensor time constant [s]", self.device.sensor.time_constant_s)?;
        Ok(())
    }
}

/// What one tick did, for logs and plots. Temperatures in °C, currents in A.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Telemetry {
    /// The tick's time `now_s` \[s\].
    pub time_s: f64,
    /// Whether the rendered finger touches a virtual object (false in air and in direct mode).
    pub contact: bool,
    /// The renderer's receptor temperature at the end of the tick (now + dt): the target. NaN in direct mode
    /// (nothing is rendered) and on a refused time step.
    pub target_skin_c: f64,
    /// The receptor of the finger model on the display at the end of the tick: what the pipeline believes the
    /// finger feels.
    pub skin_c: f64,
    /// The display set-point the inverse (or the direct ramp) asked for, before the envelope; NaN on a refused
    /// time step.
    pub requested_setpoint_c: f64,
    /// The display set-point after the envelope (clamped, rate limited), held over the tick.
    pub display_setpoint_c: f64,
    /// The display sensor reading the tick used.
    pub sensor_c: f64,
    /// The hot-side reading the tick used.
    pub hot_side_c: f64,
    /// The controller's request (NaN if it refused its input).
    pub requested_current_a: f64,
    /// The current the envelope let through (0 when faulted or held off).
    pub current_a: f64,
    /// The safety envelope's estimate of the true plate (its own model of the display, whatever the controller);
    /// NaN before the first reading.
    pub plate_estimate_c: f64,
    /// The real finger's receptor temperature as the plate's heat balance measures it \[°C\]: the controller's finger
    /// model plus the heat the real finger gives the plate beyond the model's (the observer's unknown heat d) over
    /// the receptor-to-plate conductance G, `T_model + d/G` (the same measure the touch calibration uses). Per tick
    /// it carries the observer's noise: average it over a rest (`thermode lab run` does). NaN for a controller
    /// without an observer (pid), while held off and on a refused time step.
    pub finger_c: f64,
    /// The latched fault, if any.
    pub fault: Option<FaultCode>,
}

/// What drives the requested set-point.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    /// The renderer and the display inverse.
    Render,
    /// A direct ramp to `temp_c` at `rate_c_per_s`; `ramp_c` is where the ramp stands (`None` before its first tick).
    Direct {
        temp_c: f64,
        rate_c_per_s: f64,
        ramp_c: Option<f64>,
    },
}

/// The set-point stage of a tick (steps 2, 3 and 7 of the module documentation): the renderer and the finger model
/// on the display with its inverse, or the direct ramp. It turns the virtual world into a requested display
/// set-point and follows what the finger really receives.
#[derive(Debug, Clone)]
pub struct SetpointStage {
    renderer: Renderer,
    display: DisplayFinger,
    mode: Mode,
    /// Shortest request horizon \[s\]: one sensor sample period (see the module documentation, step 3).
    min_request_horizon_s: f64,
}

/// The drive stage of a tick (steps 1, 3a, 4, 5 and 6): safety envelope and controller. It turns a requested
/// set-point and the newest reading into a gated drive.
pub struct DriveStage {
    controller: Box<dyn Controller>,
    envelope: SafetyEnvelope,
    /// The envelope's own model of the plate (whatever the controller).
    guard: PlateGuard,
    /// The current the envelope let through on the previous tick \[A\].
    applied_current_a: f64,
    /// The device regulates its plate itself ([`PipelineConfig::temperature_commanded`]).
    temperature_commanded: bool,
}

/// What the drive stage did in one tick.
#[derive(Debug, PartialEq)]
pub struct DriveOutcome {
    /// The set-point after the envelope.
    pub decision: SetpointDecision,
    /// The controller's request \[A\] (NaN if it refused its input).
    pub requested_current_a: f64,
    /// The gated drive.
    pub drive: DriveCommand,
}

/// One display channel: renderer, display inverse, controller and safety envelope. See the module documentation.
pub struct ChannelPipeline {
    setpoint: SetpointStage,
    /// The set-point stage as built, at rest in air: what a cleared fault restarts the finger models from.
    setpoint_at_rest: Box<SetpointStage>,
    drive: DriveStage,
    /// Receptor-to-plate conductance of the finger model over the contact area [W/K].
    finger_conductance_w_k: f64,
    /// The last shaped set-point [°C].
    last_setpoint_c: Option<f64>,
    /// What the finger models are built from, for the calibration at the first touch (`None`: no calibration, or
    /// done).
    calibration: Option<FingerModels>,
    /// The controller's unknown heat averaged over the rest before the first touch.
    rest_heat: RestHeat,
    /// The module the device file describes and the relative uncertainty of its parameters
    /// ([`thermode_device::RenderConfig::peltier_uncertainty`]), for the calibration.
    peltier: (PeltierModule, f64),
    /// How much warmer the calibrated display finger model is than the one the controller's unknown heat was
    /// learned against \[°C\]; subtracted from the receptor temperature given to the controller (0 uncalibrated).
    receptor_offset_c: f64,
    /// Held off (stop all) until the next stimulus.
    held: bool,
    /// The start-up self-test under way (`None`: none, or done).
    self_test: Option<Box<SelfTestRun>>,
    /// A fresh run of the start-up self-test, for a retest once an inconclusive one's fault is cleared (`None`:
    /// the channel runs none).
    retest: Option<Box<SelfTestRun>>,
    /// Where the start-up self-test stands.
    self_test_state: SelfTestState,
}

/// Where a channel's start-up self-test of its display stands ([`PipelineConfig::self_test_at_start`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SelfTestState {
    /// None was asked for.
    NotRun,
    /// Under way: the pulse is driven and every stimulus but air is refused.
    Running,
    /// Done: what it measured (a display off its file is refused, fault E106; an inconclusive test holds the
    /// channel off, fault E108, until `clear_fault` tests it again).
    Done(SelfTestReport),
    /// Stopped before its end (stop all): the display is held off, untested (fault E108), until `clear_fault`
    /// tests it again.
    Interrupted,
}

/// Time the finger must rest on the display before the controller's unknown heat is averaged \[s\]: 1, longer than
/// the model controller's observer needs to settle from its start (figures in `docs/design-choices.md`).
pub const REST_SETTLE_S: f64 = 1.0;

/// Time constant of the average of the unknown heat over the rest \[s\]: 1. The average halves the observer's tick
/// to tick fluctuation and still follows a real finger, which settles on the display within seconds (figures in
/// `docs/design-choices.md`).
pub const REST_AVERAGE_S: f64 = 1.0;

/// The controller's unknown heat averaged over the rest before the first touch: exponentially weighted mean and
/// variance with time constant [`REST_AVERAGE_S`], from [`REST_SETTLE_S`] of rest on, and the average of the part
/// of it that the device file's uncertain Peltier parameters could explain.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct RestHeat {
    /// Rest so far \[s\].
    rested_s: f64,
    /// Weighted mean \[W\] and variance \[W²\] (`None` before the first averaged sample).
    moments: Option<(f64, f64)>,
    /// Weighted mean of the heat the module's uncertainty could explain \[W\].
    explained_w: f64,
}

impl RestHeat {
    /// Adds one tick of `dt_s` \[s\] with the controller's unknown heat `heat_w` \[W\] (none or non-finite: nothing)
    /// and the heat `explained_w` \[W\] that errors of the module's parameters could produce at this tick.
    fn add(&mut self, dt_s: f64, heat_w: Option<f64>, explained_w: f64) {
        self.rested_s += dt_s;
        let Some(d) = heat_w.filter(|d| d.is_finite() && explained_w.is_finite()) else {
            return;
        };
        if self.rested_s < REST_SETTLE_S {
            return;
        }
        let alpha = 1.0 - (-dt_s / REST_AVERAGE_S).exp();
        self.moments = Some(match self.moments {
            None => {
                self.explained_w = explained_w;
                (d, 0.0)
            }
            Some((mean, var)) => {
                self.explained_w += alpha * (explained_w - self.explained_w);
                let delta = d - mean;
                (mean + alpha * delta, (1.0 - alpha) * (var + alpha * delta * delta))
            }
        });
    }

    /// The part of the mean \[W\] beyond what the module's uncertainty explains, if the mean differs from zero by
    /// more than twice the fluctuation of the samples (standard deviation) and by more than that explained heat,
    /// and at least one average time was averaged; else `None`.
    fn significant_w(&self) -> Option<f64> {
        let (mean, var) = self.moments?;
        let beyond_w = mean.abs() - self.explained_w;
        (self.rested_s >= REST_SETTLE_S + REST_AVERAGE_S && mean.abs() > 2.0 * var.sqrt() && beyond_w > 0.0)
            .then_some(beyond_w.copysign(mean))
    }
}

/// What the renderer and the display finger are built from.
#[derive(Debug, Clone)]
struct FingerModels {
    kind: RendererKind,
    skin: Skin,
    ambient_c: f64,
    contact_w_m2k: f64,
    grid: FvConfig,
    fast_path: Option<ModalStepping>,
}

impl std::fmt::Debug for ChannelPipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChannelPipeline")
            .field("renderer", &self.setpoint.renderer.kind())
            .field("controller", &self.drive.controller.name())
            .field("mode", &self.setpoint.mode)
            .field("fault", &self.drive.envelope.fault())
            .finish_non_exhaustive()
    }
}

impl std::fmt::Debug for DriveStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DriveStage")
            .field("controller", &self.controller.name())
            .field("fault", &self.envelope.fault())
            .finish_non_exhaustive()
    }
}

impl SetpointStage {
    /// The renderer and display finger of `config` at rest in air, rendering air.
    pub fn new(config: &PipelineConfig) -> Result<Self, PipelineError> {
        let grid = fv_config(config.contact_resistance_m2k_w);
        let contact_w_m2k = config.device.plate.contact_conductance_w_m2k;
        let mut renderer = Renderer::new(config.renderer, &config.skin, config.ambient_c, &grid)?;
        let mut display = DisplayFinger::new(config.renderer, &config.skin, config.ambient_c, contact_w_m2k, &grid)?;
        renderer.set_fv_fast_path(config.fv_fast_path);
        display.set_fv_fast_path(config.fv_fast_path);
        Ok(SetpointStage {
            renderer,
            display,
            mode: Mode::Render,
            min_request_horizon_s: 1.0 / config.device.sensor.sample_rate_hz,
        })
    }

    /// Steps the renderer (or the direct ramp) by `dt_s` \[s\]: (target \[°C\], requested set-point \[°C\]). The
    /// request holds over [`SetpointStage::request_horizon_s`] (step 3).
    pub fn request(&mut self, dt_s: f64) -> (f64, f64) {
        self.renderer.step(dt_s);
        let horizon_s = self.request_horizon_s(dt_s);
        match &mut self.mode {
            Mode::Render => {
                let target_c = self.renderer.receptor_c();
                (target_c, self.display.setpoint_c(target_c, horizon_s))
            }
            Mode::Direct {
                temp_c,
                rate_c_per_s,
                ramp_c,
            } => {
                let from_c = ramp_c.unwrap_or(*temp_c);
                let max_step_c = *rate_c_per_s * dt_s;
                let next_c = from_c + (*temp_c - from_c).clamp(-max_step_c, max_step_c);
                *ramp_c = Some(next_c);
                (f64::NAN, next_c)
            }
        }
    }

    /// The horizon over which the display inverse computes the request for a tick of `dt_s` \[s\]:
    /// max(dt, 1/sensor sample rate) \[s\] (see the module documentation, step 3).
    pub fn request_horizon_s(&self, dt_s: f64) -> f64 {
        dt_s.max(self.min_request_horizon_s)
    }

    /// Step 7: the finger model on the display advances by `dt_s` \[s\] with the plate at `plate_c` \[°C\].
    pub fn follow(&mut self, dt_s: f64, plate_c: f64) {
        self.display.advance(dt_s, plate_c);
    }

    /// The finger model's receptor \[°C\].
    pub fn receptor_c(&self) -> f64 {
        self.display.receptor_c()
    }

    /// Whether the renderer is in contact with a virtual object (false in air and in direct mode).
    pub fn in_contact(&self) -> bool {
        self.mode == Mode::Render && self.renderer.in_contact()
    }

    /// The renderer touches `material` at `object_c` \[°C\] (render mode).
    pub fn touch(&mut self, material: &Material, object_c: f64) -> Result<(), PipelineError> {
        self.renderer.touch(material, object_c)?;
        self.mode = Mode::Render;
        Ok(())
    }

    /// The renderer renders air (render mode).
    pub fn release(&mut self) {
        self.renderer.release();
        self.mode = Mode::Render;
    }

    /// Direct mode: a ramp to `temp_c` \[°C\] at `rate_c_per_s` \[°C/s\], continuing from where the display stands (the
    /// ramp's position, or `last_setpoint_c` \[°C\] when coming from render mode).
    fn direct(&mut self, temp_c: f64, rate_c_per_s: f64, last_setpoint_c: Option<f64>) {
        let ramp_c = match self.mode {
            Mode::Direct { ramp_c, .. } => ramp_c,
            Mode::Render => last_setpoint_c,
        };
        self.renderer.release();
        self.mode = Mode::Direct {
            temp_c,
            rate_c_per_s,
            ramp_c,
        };
    }
}

/// The shaped set-point's rate `shaped_rate_c_per_s` \[°C/s\] as the controller is told it: 0 while the feasible
/// band holds the request (`requested_c` beyond the band, so the band gave `feasible_c`) and the set-point moves away
/// from it. The set-point then moves only because the band follows the plate estimate, not because the request
/// turned back, and a controller that never drives the plate against the set-point's motion
/// ([`thermode_control::ModelController`]) must not take an estimate's tick-to-tick wobble for the request's return:
/// on a module 30 % weaker in S than its file, a 6 m°C rise of the estimate during the saturated drop stopped
/// the cooling for 0.09 s (the plate then waited for a set-point that only followed it up).
fn requested_motion_c_per_s(requested_c: f64, feasible_c: f64, shaped_rate_c_per_s: f64) -> f64 {
    let held_below = requested_c < feasible_c && shaped_rate_c_per_s > 0.0;
    let held_above = requested_c > feasible_c && shaped_rate_c_per_s < 0.0;
    if held_below || held_above {
        0.0
    } else {
        shaped_rate_c_per_s
    }
}

impl DriveStage {
    /// The envelope of `config` around `controller`, nothing observed yet.
    pub fn new(config: &PipelineConfig, controller: Box<dyn Controller>) -> Result<Self, PipelineError> {
        let guard = PlateGuard::new(
            plant_model(&config.device)?,
            config.device.render.sensor_lag_uncertainty,
        )?;
        Ok(DriveStage {
            controller,
            envelope: SafetyEnvelope::new(config.envelope, config.device.drive.current_limit_a)?,
            guard: match config.temperature_commanded {
                true => guard.for_regulating_device()?,
                false => guard,
            },
            applied_current_a: 0.0,
            temperature_commanded: config.temperature_commanded,
        })
    }

    /// The current the plate guard is told the envelope gated \[A\]: none on a temperature-commanded device (it
    /// takes the current the device reports delivering, if any).
    fn gated_for_guard_a(&self) -> f64 {
        if self.temperature_commanded {
            0.0
        } else {
            self.applied_current_a
        }
    }

    /// Step 1: the envelope observes the newest reading (fault checks, thermal dose).
    pub fn observe(&mut self, reading: &Reading) {
        self.envelope.observe(&reading.measurement());
    }

    /// Steps 3a–6 at `now_s` for a tick of `dt_s` \[s\]: the request limited to the feasible band, shaped by the
    /// envelope, the controller's request on the shaped set-point with `finger` and `reading`, and the gated drive.
    pub fn drive(
        &mut self,
        now_s: f64,
        dt_s: f64,
        reading: &Reading,
        requested_c: f64,
        finger: Finger,
    ) -> DriveOutcome {
        let fresh_sample = self.guard.update(now_s, reading, self.gated_for_guard_a(), finger);
        self.act_on_reading_check(now_s);
        self.envelope.check_estimate(now_s, self.guard.plate_estimate_c());
        let feasible_c = match self.temperature_commanded {
            true => requested_c,
            false => self.feasible(requested_c, dt_s),
        };
        let decision = self.envelope.shape_setpoint(now_s, feasible_c);
        if self.temperature_commanded {
            // The device regulates to the set-point; no current of thermode's reaches the plate.
            let forecast = self.guard.forecast(dt_s, finger);
            let drive = self.envelope.gate_drive(now_s, 0.0, &forecast);
            return DriveOutcome {
                decision,
                requested_current_a: f64::NAN,
                drive,
            };
        }
        let input = ControlInput {
            time_s: now_s,
            dt_s,
            setpoint_c: decision.setpoint_c,
            setpoint_rate_c_per_s: requested_motion_c_per_s(requested_c, feasible_c, decision.rate_c_per_s),
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
            applied_current_a: self.applied_current_a,
            finger_receptor_c: Some(finger.receptor_c),
            finger_conductance_w_k: finger.conductance_w_k,
            measured_current_a: reading.current_a,
            voltage_v: reading.voltage_v,
            fresh_sample,
        };
        let requested_current_a = within_device_limit(self.controller.update(&input).unwrap_or(f64::NAN), reading);
        let forecast = self.guard.forecast(dt_s, finger);
        let drive = self.envelope.gate_drive(now_s, requested_current_a, &forecast);
        self.applied_current_a = drive.current_a();
        DriveOutcome {
            decision,
            requested_current_a,
            drive,
        }
    }

    /// A tick at `now_s` \[s\] whose time step is not usable: the envelope gets a NaN request, latches
    /// [`FaultCode::NonFiniteCommand`] and switches the drive off.
    pub fn refuse(&mut self, now_s: f64) -> DriveCommand {
        let drive = self.envelope.gate_drive(now_s, f64::NAN, &MeasuredOnly);
        self.applied_current_a = drive.current_a();
        drive
    }

    /// A tick at `now_s` \[s\] while the channel is held off (stop all): the plate guard follows the plate at 0 A
    /// with `finger`, the envelope checks faults with the drive off ([`SafetyEnvelope::hold`]), and the controller
    /// is not asked (it restarts when the hold ends, [`DriveStage::end_hold`]).
    pub fn hold(&mut self, now_s: f64, reading: &Reading, finger: Finger) -> DriveCommand {
        self.guard.update(now_s, reading, self.gated_for_guard_a(), finger);
        self.act_on_reading_check(now_s);
        self.applied_current_a = 0.0;
        self.envelope.hold(now_s)
    }

    /// A tick of the start-up self-test at `now_s` \[s\], `dt_s` \[s\] long: `pulse_a` \[A\] gated by the envelope
    /// with the plate guard's forecast (no finger on the display); the controller is not asked.
    pub fn pulse(&mut self, now_s: f64, dt_s: f64, reading: &Reading, pulse_a: f64) -> DriveCommand {
        self.guard.update(now_s, reading, self.applied_current_a, Finger::NONE);
        self.act_on_reading_check(now_s);
        let forecast = self.guard.forecast(dt_s, Finger::NONE);
        let drive = self
            .envelope
            .gate_drive(now_s, within_device_limit(pulse_a, reading), &forecast);
        self.applied_current_a = drive.current_a();
        drive
    }

    /// Gives the envelope the plate guard's innovation check at `now_s` \[s\] (after the guard took the tick): a
    /// reading found disagreeing with the plate model is distrusted from the disagreement's start (a fault, the
    /// dose counted at the model's plate), and from then on every tick renews the plate the dose counts at.
    fn act_on_reading_check(&mut self, now_s: f64) {
        let Some(disagreement) = self.guard.reading_disagreement() else {
            return;
        };
        if self.envelope.reading_distrusted() {
            self.envelope.set_distrusted_plate_c(self.guard.distrusted_plate_c());
        } else {
            let hottest_c = disagreement.hottest_plate_c + crate::reading_check::DISTRUST_MARGIN_C;
            self.envelope.distrust_reading(now_s, disagreement.since_s, hottest_c);
        }
    }

    /// Ends a hold: the controller restarts from the present readings, as on a fresh channel.
    pub fn end_hold(&mut self) {
        self.controller.reset();
        self.applied_current_a = 0.0;
    }

    /// The plate guard's estimate of the true plate \[°C\] (NaN before the first reading).
    pub fn plate_estimate_c(&self) -> f64 {
        self.guard.plate_estimate_c()
    }

    /// The request limited to [`FEASIBLE_BAND_C`] (or two ticks of the envelope's rate limit, if more) around the
    /// plate temperature the controller expects now, when it has an estimate. Without the band a set-point the
    /// plate cannot follow runs away from it inside the envelope's rate limiter (which shapes from its own last
    /// value), and when the request turns back the shaped set-point needs time to return to the plate: the
    /// controller keeps driving past the target (figures in `docs/design-choices.md`). The band is wide enough for
    /// the controller to drive its full current towards a set-point beyond it. NaN passes unchanged (the envelope latches it).
    fn feasible(&self, requested_c: f64, dt_s: f64) -> f64 {
        match self.controller.plate_estimate_c() {
            Some(plate_c) if plate_c.is_finite() && requested_c.is_finite() => {
                let band_c = FEASIBLE_BAND_C.max(2.0 * self.envelope.config().max_setpoint_rate_c_per_s * dt_s);
                requested_c.clamp(plate_c - band_c, plate_c + band_c)
            }
            _ => requested_c,
        }
    }

    /// Where step 7 puts the plate \[°C\]: the controller's estimate if it has one (an observer), else (and on a
    /// temperature-commanded device) the shaped set-point (the paper's way).
    pub fn plate_for_finger_c(&self, decision: &SetpointDecision) -> f64 {
        if self.temperature_commanded {
            return decision.setpoint_c;
        }
        self.controller
            .plate_estimate_c()
            .filter(|p| p.is_finite())
            .unwrap_or(decision.setpoint_c)
    }

    /// The safety envelope.
    pub fn envelope(&self) -> &SafetyEnvelope {
        &self.envelope
    }

    /// The controller.
    pub fn controller(&self) -> &dyn Controller {
        self.controller.as_ref()
    }
}

/// `current_a` \[A\] with its heating bounded by the device's own present limit ([`Reading::heating_limit_a`]), so
/// that the models integrate the current the plate receives; NaN stays NaN (the envelope latches it).
fn within_device_limit(current_a: f64, reading: &Reading) -> f64 {
    if current_a > reading.heating_limit_a {
        reading.heating_limit_a.max(0.0)
    } else {
        current_a
    }
}

/// The start-up self-test of `config`'s display ([`PipelineConfig::self_test_at_start`]): the default pulse,
/// recorded for as long as the file's sensor needs ([`SelfTest::for_sensor`]).
fn self_test_run(config: &PipelineConfig) -> Result<Box<SelfTestRun>, PipelineError> {
    let plant = plant_model(&config.device)?;
    let test = SelfTest::for_sensor(plant.sensor_time_constant_s);
    let uncertainty = config.device.render.sensor_lag_uncertainty;
    Ok(Box::new(SelfTestRun::new(test, plant, uncertainty)))
}

impl ChannelPipeline {
    /// Builds the pipeline of `config`: the controller it names, everything at rest (the finger in air, the display
    /// rendering air).
    pub fn new(config: &PipelineConfig) -> Result<Self, PipelineError> {
        config.validate()?;
        let controller = build_controller(&config.controller, &config.device)?;
        ChannelPipeline::with_controller(config, controller)
    }

    /// As [`ChannelPipeline::new`] with a controller of the caller's (`config.controller` is not used). The
    /// controller's output should respect the device's drive limit; the envelope enforces it anyway.
    pub fn with_controller(config: &PipelineConfig, controller: Box<dyn Controller>) -> Result<Self, PipelineError> {
        config.validate()?;
        let setpoint = SetpointStage::new(config)?;
        let drive = DriveStage::new(config, controller)?;
        let finger_conductance_w_k = setpoint.display.receptor_conductance_w_m2k() * config.device.plate.area_m2;
        Ok(ChannelPipeline {
            setpoint_at_rest: Box::new(setpoint.clone()),
            setpoint,
            drive,
            finger_conductance_w_k,
            last_setpoint_c: None,
            calibration: config.calibrate_finger_at_touch.then(|| FingerModels {
                kind: config.renderer,
                skin: config.skin.clone(),
                ambient_c: config.ambient_c,
                contact_w_m2k: config.device.plate.contact_conductance_w_m2k,
                grid: fv_config(config.contact_resistance_m2k_w),
                fast_path: config.fv_fast_path,
            }),
            rest_heat: RestHeat::default(),
            peltier: (config.device.module()?, config.device.render.peltier_uncertainty),
            receptor_offset_c: 0.0,
            held: false,
            self_test: config.self_test_at_start.then(|| self_test_run(config)).transpose()?,
            retest: config.self_test_at_start.then(|| self_test_run(config)).transpose()?,
            self_test_state: if config.self_test_at_start {
                SelfTestState::Running
            } else {
                SelfTestState::NotRun
            },
        })
    }

    /// Changes what the channel displays, at any time: air (release), a touch of a fresh object (also a change of
    /// material during contact), or a direct temperature. Validated first ([`Stimulus::validate`]); an error
    /// leaves the pipeline unchanged. Not a per-tick operation: a new material may allocate its grid.
    pub fn set_stimulus(&mut self, stimulus: Stimulus) -> Result<(), PipelineError> {
        stimulus.validate()?;
        if self.self_test.is_some() && stimulus != Stimulus::Air {
            return Err(PipelineError::SelfTestRunning);
        }
        if self.held {
            self.held = false;
            self.drive.end_hold();
        }
        match stimulus {
            Stimulus::Air => self.setpoint.release(),
            Stimulus::Touch { material, object_c } => self.touch(&material, object_c)?,
            Stimulus::Direct { temp_c, rate_c_per_s } => {
                // After a hold there is no set-point to continue from: the ramp starts where the plate stands.
                let plate_c = Some(self.drive.plate_estimate_c()).filter(|p| p.is_finite());
                self.setpoint
                    .direct(temp_c, rate_c_per_s, self.last_setpoint_c.or(plate_c))
            }
        }
        Ok(())
    }

    /// Holds the drive off until the next stimulus (stop all): the display renders air, the envelope keeps
    /// checking faults with the drive at 0 A, the controller is not asked, and the next stimulus starts it afresh,
    /// as on a fresh channel.
    pub fn hold(&mut self) {
        self.setpoint.release();
        self.last_setpoint_c = None;
        self.held = true;
        if self.self_test.take().is_some() {
            self.self_test_state = SelfTestState::Interrupted;
            let now_s = self.drive.envelope.last_measurement().map_or(0.0, |m| m.time_s);
            self.drive.envelope.hold_untested(now_s);
        }
    }

    fn touch(&mut self, material: &Material, object_c: f64) -> Result<(), PipelineError> {
        if self.setpoint.mode == Mode::Render && !self.setpoint.renderer.in_contact() {
            self.calibrate();
        }
        self.calibration = None;
        self.setpoint.touch(material, object_c)
    }

    /// Calibrates the finger models to the real finger's resting surface at its first touch from air (once; see
    /// [`PipelineConfig::calibrate_finger_at_touch`]). The controller's learned unknown heat d, averaged over the
    /// rest ([`RestHeat`]), is the heat the real finger gives the plate beyond the finger model's,
    /// G·(T_real − T_model) with G the receptor-to-plate conductance over the contact area, so the real receptor
    /// rests at T_model + d/G. The skin's perfusion is scaled so that its steady state in air has that receptor
    /// temperature (the paper measured each participant's resting finger; `calibrate_to_surface`), and renderer and
    /// display finger restart from that steady state, so the target is computed for this finger. The controller's
    /// unknown heat already holds d, so the receptor given to the controller is lowered by the calibration's shift:
    /// the heat it expects from the finger stays continuous. Nothing changes when the average is not
    /// distinguishable from its own fluctuation ([`RestHeat::significant_w`]: a finger that matches the model
    /// keeps the model), or when no perfusion reaches the surface temperature.
    fn calibrate(&mut self) {
        let (Some(models), Some(heat_w)) = (&self.calibration, self.rest_heat.significant_w()) else {
            return;
        };
        let model_c = self.setpoint.receptor_c();
        let real_c = model_c + heat_w / self.finger_conductance_w_k;
        let Some((renderer, display)) = models.calibrated(real_c) else {
            return;
        };
        self.receptor_offset_c = display.receptor_c() - model_c;
        self.setpoint.renderer = renderer;
        self.setpoint.display = display;
    }

    /// One tick at `now_s` \[s\] (the envelope's clock: the same clock as the readings' `time_s`) for the interval
    /// `dt_s` \[s\] until the next tick, with the newest `reading`. Returns the gated drive to apply until the next
    /// tick and what happened. Never allocates, never panics.
    pub fn tick(&mut self, now_s: f64, dt_s: f64, reading: &Reading) -> (DriveCommand, Telemetry) {
        self.drive.observe(reading);
        if !(dt_s.is_finite() && dt_s > 0.0) {
            let drive = self.drive.refuse(now_s);
            let telemetry = self.refused_tick(now_s, reading, &drive);
            return (drive, telemetry);
        }
        let (target_c, requested_c) = self.setpoint.request(dt_s);
        let finger = Finger {
            receptor_c: self.setpoint.receptor_c() - self.receptor_offset_c,
            conductance_w_k: self.finger_conductance_w_k,
        };
        if self.held {
            return self.held_tick(now_s, dt_s, reading, finger, (target_c, requested_c));
        }
        if let Some(mut run) = self.self_test.take() {
            let (drive, mut telemetry) = self.self_test_tick(&mut run, now_s, dt_s, reading, (target_c, requested_c));
            if run.finished(now_s) {
                self.finish_self_test(&run, now_s);
                // A refusal shows from this tick on.
                telemetry.fault = self.drive.envelope.fault();
            } else {
                self.self_test = Some(run);
            }
            return (drive, telemetry);
        }
        let requested_c = self.idle_request_c((target_c, requested_c), reading, dt_s);
        let outcome = self.drive.drive(now_s, dt_s, reading, requested_c, finger);
        self.last_setpoint_c = Some(outcome.decision.setpoint_c);
        if self.calibration.is_some() && self.setpoint.mode == Mode::Render && !self.setpoint.renderer.in_contact() {
            let (module, uncertainty) = self.peltier;
            let plate_c = Some(self.drive.plate_estimate_c())
                .filter(|c| c.is_finite())
                .unwrap_or(reading.sensor_c);
            let explained_w = uncertainty * module.display_heat_terms_w(reading.current_a, plate_c, reading.hot_side_c);
            self.rest_heat
                .add(dt_s, self.drive.controller.unknown_heat_w(), explained_w);
        }
        let plate_c = self.drive.plate_for_finger_c(&outcome.decision);
        self.setpoint.follow(dt_s, plate_c);
        // From the next tick on: a finger model that left the band drives nothing.
        self.drive.envelope.check_estimate(now_s, self.setpoint.receptor_c());
        let drive = outcome.drive;
        let telemetry = Telemetry {
            time_s: now_s,
            contact: self.setpoint.in_contact(),
            target_skin_c: target_c,
            skin_c: self.setpoint.receptor_c(),
            requested_setpoint_c: requested_c,
            display_setpoint_c: outcome.decision.setpoint_c,
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
            requested_current_a: outcome.requested_current_a,
            current_a: drive.current_a(),
            plate_estimate_c: self.drive.plate_estimate_c(),
            finger_c: match self.drive.temperature_commanded {
                true => f64::NAN,
                false => self
                    .drive
                    .controller
                    .unknown_heat_w()
                    .map_or(f64::NAN, |heat_w| finger.receptor_c + heat_w / finger.conductance_w_k),
            },
            fault: drive.fault(),
        };
        (drive, telemetry)
    }

    /// The request of an idle temperature-commanded channel (rendering air): the rendered skin temperature
    /// `target_c` \[°C\] itself, reached from the last set-point (the reading, before the first) at no more than
    /// [`IDLE_RATE_C_PER_S`] over `dt_s` \[s\]. The display inverse would warm a finger model cooled by a plate that
    /// started cold past the skin (33.3 °C on an emulated MeCom controller), and a device's own regulation overshoots
    /// a fast set-point (3.6 °C on a 20 °C/s approach from 24.5 to 32 °C); at rest nothing needs either. Every other
    /// request (`requested_c`) passes unchanged.
    fn idle_request_c(&self, (target_c, requested_c): (f64, f64), reading: &Reading, dt_s: f64) -> f64 {
        let idle =
            self.drive.temperature_commanded && self.setpoint.mode == Mode::Render && !self.setpoint.in_contact();
        let from_c = self.last_setpoint_c.unwrap_or(reading.sensor_c);
        if !(idle && from_c.is_finite() && target_c.is_finite()) {
            return requested_c;
        }
        let step_c = IDLE_RATE_C_PER_S * dt_s;
        target_c.clamp(from_c - step_c, from_c + step_c)
    }

    /// A tick while held off: 0 A; the finger model on the display follows the estimated plate.
    /// A tick of the start-up self-test: the pulse's current through the envelope (no finger on the display), the
    /// reading taken into the record.
    fn self_test_tick(
        &mut self,
        run: &mut SelfTestRun,
        now_s: f64,
        dt_s: f64,
        reading: &Reading,
        (target_c, requested_c): (f64, f64),
    ) -> (DriveCommand, Telemetry) {
        let pulse_a = run.tick(now_s, dt_s, self.drive.applied_current_a, reading);
        let drive = self.drive.pulse(now_s, dt_s, reading, pulse_a);
        let plate_c = self.drive.plate_estimate_c();
        self.setpoint
            .follow(dt_s, if plate_c.is_finite() { plate_c } else { reading.sensor_c });
        let telemetry = Telemetry {
            requested_current_a: pulse_a,
            current_a: drive.current_a(),
            ..self.unrendered_telemetry(now_s, reading, (target_c, requested_c), &drive)
        };
        (drive, telemetry)
    }

    /// Ends the start-up self-test at `now_s` \[s\]: its report taken ([`ChannelPipeline::take_self_test`]) and
    /// kept, the controller restarted from the present readings.
    fn finish_self_test(&mut self, run: &SelfTestRun, now_s: f64) {
        let report = run.report();
        self.take_self_test(&report, now_s);
        self.self_test_state = SelfTestState::Done(report);
        self.drive.controller.reset();
    }

    /// Where the start-up self-test stands.
    pub fn self_test_state(&self) -> SelfTestState {
        self.self_test_state
    }

    fn held_tick(
        &mut self,
        now_s: f64,
        dt_s: f64,
        reading: &Reading,
        finger: Finger,
        (target_c, requested_c): (f64, f64),
    ) -> (DriveCommand, Telemetry) {
        let drive = self.drive.hold(now_s, reading, finger);
        let plate_c = self.drive.plate_estimate_c();
        self.setpoint
            .follow(dt_s, if plate_c.is_finite() { plate_c } else { reading.sensor_c });
        let telemetry = self.unrendered_telemetry(now_s, reading, (target_c, requested_c), &drive);
        (drive, telemetry)
    }

    /// The telemetry of a tick whose drive is not the controller's (held off, or the self-test's pulse): no
    /// contact, no set-point, no current asked for.
    fn unrendered_telemetry(
        &self,
        now_s: f64,
        reading: &Reading,
        (target_c, requested_c): (f64, f64),
        drive: &DriveCommand,
    ) -> Telemetry {
        Telemetry {
            time_s: now_s,
            contact: false,
            target_skin_c: target_c,
            skin_c: self.setpoint.receptor_c(),
            requested_setpoint_c: requested_c,
            display_setpoint_c: f64::NAN,
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
            requested_current_a: 0.0,
            current_a: 0.0,
            plate_estimate_c: self.drive.plate_estimate_c(),
            finger_c: f64::NAN,
            fault: drive.fault(),
        }
    }

    /// The horizon over which the display inverse computes the request for a tick of `dt_s` \[s\] (see
    /// [`SetpointStage::request_horizon_s`]).
    pub fn request_horizon_s(&self, dt_s: f64) -> f64 {
        self.setpoint.request_horizon_s(dt_s)
    }

    fn refused_tick(&self, now_s: f64, reading: &Reading, drive: &DriveCommand) -> Telemetry {
        Telemetry {
            time_s: now_s,
            contact: self.setpoint.in_contact(),
            target_skin_c: f64::NAN,
            skin_c: self.setpoint.receptor_c(),
            requested_setpoint_c: f64::NAN,
            display_setpoint_c: self.last_setpoint_c.unwrap_or(f64::NAN),
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
            requested_current_a: f64::NAN,
            current_a: drive.current_a(),
            plate_estimate_c: self.drive.plate_estimate_c(),
            finger_c: f64::NAN,
            fault: drive.fault(),
        }
    }

    /// Clears the envelope's latched fault at `now_s` (see [`SafetyEnvelope::clear_fault`]) and resets the
    /// controller and the plate guard's estimate, so both restart from the present readings; a finger model on the
    /// display outside the plausible band restarts from rest in air. Returns the cleared fault.
    /// A channel whose start-up self-test was inconclusive or interrupted is tested again from here (stimuli but
    /// air refused meanwhile); one whose display was refused stays refused (E106 latched again, should another
    /// fault have been latched first).
    pub fn clear_fault(&mut self, now_s: f64) -> Result<Option<FaultCode>, PipelineError> {
        let cleared = self.drive.envelope.clear_fault(now_s)?;
        if cleared.is_some() {
            self.drive.controller.reset();
            self.drive.guard.restart();
            self.drive.applied_current_a = 0.0;
            let plausible = self.drive.envelope.config().plausible_min_c..=self.drive.envelope.config().plausible_max_c;
            if !plausible.contains(&self.setpoint.receptor_c()) {
                // The finger model followed a plate the faulted readings made up (an open sensor's 850 °C): it starts
                // again from rest in air, rendering what it rendered.
                let mode = self.setpoint.mode;
                let renderer = self.setpoint.renderer.clone();
                self.setpoint = (*self.setpoint_at_rest).clone();
                (self.setpoint.mode, self.setpoint.renderer) = (mode, renderer);
                self.receptor_offset_c = 0.0;
                self.last_setpoint_c = None;
            }
            self.after_cleared(now_s);
        }
        Ok(cleared)
    }

    /// What the start-up self-test asks of a channel whose fault was just cleared at `now_s` \[s\]: a refused
    /// display refused again, an untested one (inconclusive, interrupted) tested again.
    fn after_cleared(&mut self, now_s: f64) {
        let untested = match self.self_test_state {
            SelfTestState::Done(report) if report.off_file().is_some() => {
                self.drive.envelope.refuse_display(now_s);
                return;
            }
            SelfTestState::Done(report) => report.inconclusive.is_some(),
            SelfTestState::Interrupted => true,
            SelfTestState::NotRun | SelfTestState::Running => false,
        };
        if let (true, Some(fresh)) = (untested, &self.retest) {
            self.self_test = Some(fresh.clone());
            self.self_test_state = SelfTestState::Running;
        }
    }

    /// The safety envelope (fault, thermal dose, limits).
    pub fn envelope(&self) -> &SafetyEnvelope {
        self.drive.envelope()
    }

    /// Restores a saved thermal dose into the envelope (before the first tick; see
    /// [`SafetyEnvelope::restore_dose`]: a restore never lowers the dose).
    pub fn restore_dose(&mut self, saved: &DoseLedger) -> Result<(), PipelineError> {
        Ok(self.drive.envelope.restore_dose(saved)?)
    }

    /// The controller.
    pub fn controller(&self) -> &dyn Controller {
        self.drive.controller()
    }

    /// The renderer.
    pub fn renderer(&self) -> &Renderer {
        &self.setpoint.renderer
    }

    /// Takes the display's self-test at `now_s` \[s\]: a display unlike the device file this pipeline was built
    /// for is refused ([`SafetyEnvelope::refuse_display`]: 0 A from now on, a fault that cannot be cleared); one the
    /// test could not judge is held off ([`SafetyEnvelope::hold_untested`], until `clear_fault` tests it again); one
    /// within it has its plate bounded with the sensor lag measured ([`crate::self_test::LAG_MARGIN`]) where that
    /// is longer than the file's allowance.
    pub fn take_self_test(&mut self, report: &crate::self_test::SelfTestReport, now_s: f64) {
        match report.verdict() {
            crate::self_test::Verdict::NotAsFiled(_) => self.drive.envelope.refuse_display(now_s),
            crate::self_test::Verdict::Inconclusive(_) => self.drive.envelope.hold_untested(now_s),
            crate::self_test::Verdict::Matches => self.drive.guard.allow_sensor_lag(report.guard_lag_s()),
        }
    }

    /// The finger model on the display and its inverse.
    pub fn display_finger(&self) -> &DisplayFinger {
        &self.setpoint.display
    }

    /// The finger model's receptor-to-plate conductance over the contact area [W/K], as given to the controller.
    pub fn finger_conductance_w_k(&self) -> f64 {
        self.finger_conductance_w_k
    }

    /// The shift of the finger model's receptor by the last calibration \[°C\] (0 if never calibrated); see
    /// [`PipelineConfig::calibrate_finger_at_touch`].
    pub fn calibration_shift_c(&self) -> f64 {
        self.receptor_offset_c
    }

    /// Whether the channel is in direct mode.
    pub fn is_direct(&self) -> bool {
        matches!(self.setpoint.mode, Mode::Direct { .. })
    }
}

impl FingerModels {
    /// Renderer and display finger at rest in air, with the skin's perfusion scaled so that the receptor rests at
    /// `receptor_c` \[°C\]; `None` if no perfusion reaches it or the models refuse it.
    fn calibrated(&self, receptor_c: f64) -> Option<(Renderer, DisplayFinger)> {
        if !receptor_c.is_finite() {
            return None;
        }
        let skin = match self.kind {
            RendererKind::Kron => calibrate_to_surface(&self.skin, self.ambient_c, receptor_c).ok()?,
            RendererKind::Fv => {
                let mut model = FvModel::new(&self.skin, None, &self.grid).ok()?;
                let scale = model.calibrate_to_surface(self.ambient_c, receptor_c).ok()?;
                self.skin.with_perfusion_scaled(scale)
            }
        };
        let mut renderer = Renderer::new(self.kind, &skin, self.ambient_c, &self.grid).ok()?;
        let mut display = DisplayFinger::new(self.kind, &skin, self.ambient_c, self.contact_w_m2k, &self.grid).ok()?;
        renderer.set_fv_fast_path(self.fast_path);
        display.set_fv_fast_path(self.fast_path);
        Some((renderer, display))
    }
}

#[cfg(test)]
mod tests {
    use super::requested_motion_c_per_s;

    /// The controller hears the set-point's own rate unless the band holds the request and the set-point moves away
    /// from it: a request far below a rising set-point (the band following a rising estimate) and far above a falling
    /// one give 0; a request that has turned back inside the band, or a set-point moving towards the request, keep
    /// their rate.
    #[test]
    fn the_band_following_the_estimate_is_not_a_set_point_turning_back() {
        for (requested_c, feasible_c, rate, want) in [
            (16.6, 29.8, 0.6, 0.0),
            (600.0, 46.9, -0.6, 0.0),
            (29.8, 29.8, 0.6, 0.6),
            (16.6, 29.8, -20.0, -20.0),
            (600.0, 46.9, 20.0, 20.0),
        ] {
            let got = requested_motion_c_per_s(requested_c, feasible_c, rate);
            assert_eq!(got, want, "request {requested_c}, band {feasible_c}, rate {rate}");
        }
    }
}
