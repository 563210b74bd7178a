//! One display channel's pipeline: renderer → display inverse → safety envelope → controller → safety envelope →
//! drive, as one allocation-free tick that cannot panic.
//!
//! # One tick at time `now_s` over the interval [now, now + dt]
//! 1. `envelope.observe(reading)`: fault checks and thermal dose on the newest measurement.
//! 2. The renderer (the controller's finger model touching the virtual world) steps to now + dt; its receptor is
//!    the target. In direct mode the renderer idles in air and the requested set-point is the direct ramp instead.
//! 3. The display inverse gives the display set-point that brings the finger model on the display to the target at
//!    now + dt (unlimited).
//!    3a. If the controller reports a plate estimate (an observer), the request is limited to a band of
//!    [`FEASIBLE_BAND_C`] around the plate temperature it expects now, so the envelope's rate limiter never winds up
//!    far from a plate that cannot follow (the paper's PID has no estimate and gets the request unchanged).
//! 4. `envelope.shape_setpoint`: clamp into the display limits and rate limit.
//! 5. `controller.update` on the shaped set-point, with the finger model's receptor temperature and its
//!    conductance to the plate (receptor conductance × contact area).
//! 6. `envelope.gate_drive`: the only way to a [`DriveCommand`].
//! 7. The finger model on the display advances with what the finger really receives: the controller's plate
//!    estimate if it has one (an observer), else the shaped set-point (the paper's way).
//!
//! A time step that is not finite and positive skips steps 2–5 and requests NaN from the envelope, which latches
//! [`thermode_control::FaultCode::NonFiniteCommand`] (as for any controller error) and switches the drive off.
//! Every other broken number (NaN from a model, a sensor fault) latches its fault in the envelope as well.

use thermode_control::{
    ControlInput, Controller, DriveCommand, EnvelopeConfig, FaultCode, SafetyEnvelope, SetpointDecision,
    ABSOLUTE_MAX_RATE_C_PER_S,
};
use thermode_device::{DeviceConfig, Reading};
use thermode_model::{Material, Skin};

use crate::controllers::{build_controller, ControllerKind};
use crate::display::DisplayFinger;
use crate::error::{require_in, RenderError};
use crate::renderer::{fv_config, Renderer, RendererKind, LIGHT_TOUCH_RESISTANCE_M2K_W};
use crate::stimulus::Stimulus;

/// Lowest ambient (air) temperature a pipeline accepts \[°C\]: −30.
pub const MIN_AMBIENT_C: f64 = -30.0;
/// Highest ambient (air) temperature a pipeline accepts \[°C\]: 50 (above it the resting finger has no steady state
/// below the arterial temperature worth rendering).
pub const MAX_AMBIENT_C: f64 = 50.0;

/// The set-point rate limit of a rendering pipeline \[°C/s\]: 20, the compiled-in absolute maximum
/// ([`ABSOLUTE_MAX_RATE_C_PER_S`]), instead of the envelope's general default of 10.
///
/// Why: rendering a touch must let the Peltier cool as fast as it physically can (the paper's first flaw is that
/// limit). The default module cools the resting plate at about 13 °C/s at full current (3.4 W into 0.28 J/K with
/// the hot side near the water temperature) — faster than 10 °C/s, so at 10 °C/s the envelope and not the actuator
/// limits the initial drop. Measured on the default display, model controller, fv renderer, aluminium: lag at half
/// drop 0.580 s at 10 °C/s against 0.477 s at 20 °C/s, where the actuator limit is 0.477 s. A real touch changes
/// the skin surface at well over 100 °C/s, so 20 °C/s shows nothing a real contact would not; the display limits
/// and the thermal dose are untouched.
pub const RENDER_MAX_RATE_C_PER_S: f64 = ABSOLUTE_MAX_RATE_C_PER_S;

/// The safety envelope of a rendering pipeline: [`EnvelopeConfig::default`] with the set-point rate limit
/// [`RENDER_MAX_RATE_C_PER_S`].
pub fn render_envelope() -> EnvelopeConfig {
    EnvelopeConfig {
        max_setpoint_rate_c_per_s: RENDER_MAX_RATE_C_PER_S,
        ..EnvelopeConfig::default()
    }
}

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
    /// The safety envelope. Default [`render_envelope`] (15–48 °C, 20 °C/s).
    pub envelope: EnvelopeConfig,
    /// The controller's model of the finger (renderer and display inverse). Default [`Skin::fingertip`].
    pub skin: Skin,
    /// Air temperature \[°C\], in [[`MIN_AMBIENT_C`], [`MAX_AMBIENT_C`]]. Default 23 (the paper's room).
    pub ambient_c: f64,
    /// Contact resistance between skin and virtual object of the fv renderer [m²K/W], ≥ 0. Default
    /// [`LIGHT_TOUCH_RESISTANCE_M2K_W`] (1e-3, light touch). The kron renderer has none.
    pub contact_resistance_m2k_w: f64,
}

impl PipelineConfig {
    /// The defaults above for `device` and `controller`.
    pub fn new(device: DeviceConfig, controller: ControllerKind) -> Self {
        PipelineConfig {
            device,
            renderer: RendererKind::Fv,
            controller,
            envelope: render_envelope(),
            skin: Skin::fingertip(),
            ambient_c: 23.0,
            contact_resistance_m2k_w: LIGHT_TOUCH_RESISTANCE_M2K_W,
        }
    }

    /// Checks the numbers the pipeline itself adds (the models, device, envelope and controller check theirs when
    /// the pipeline is built).
    pub fn validate(&self) -> Result<(), RenderError> {
        require_in("ambient temperature [°C]", self.ambient_c, MIN_AMBIENT_C, MAX_AMBIENT_C)?;
        require_in(
            "contact resistance [m²K/W]",
            self.contact_resistance_m2k_w,
            0.0,
            f64::MAX,
        )?;
        self.device.validate("device config")?;
        self.envelope.validate()?;
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
    /// The current the envelope let through (0 when faulted).
    pub current_a: f64,
    /// The latched fault, if any.
    pub fault: Option<FaultCode>,
}

/// What drives the requested set-point.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    /// The renderer and the display inverse.
    Render,
    /// A direct ramp to `temp_c` at `rate_c_s`; `ramp_c` is where the ramp stands (`None` before its first tick).
    Direct {
        temp_c: f64,
        rate_c_s: f64,
        ramp_c: Option<f64>,
    },
}

/// One display channel: renderer, display inverse, controller and safety envelope. See the module documentation.
pub struct ChannelPipeline {
    renderer: Renderer,
    display: DisplayFinger,
    controller: Box<dyn Controller>,
    envelope: SafetyEnvelope,
    mode: Mode,
    /// Receptor-to-plate conductance of the finger model over the contact area [W/K].
    finger_conductance_w_k: f64,
    /// The current the envelope let through on the previous tick \[A\].
    applied_current_a: f64,
    /// The last shaped set-point [°C].
    last_setpoint_c: Option<f64>,
}

impl std::fmt::Debug for ChannelPipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChannelPipeline")
            .field("renderer", &self.renderer.kind())
            .field("controller", &self.controller.name())
            .field("mode", &self.mode)
            .field("fault", &self.envelope.fault())
            .finish_non_exhaustive()
    }
}

impl ChannelPipeline {
    /// Builds the pipeline of `config`: the controller it names, everything at rest (the finger in air, the display
    /// rendering air).
    pub fn new(config: &PipelineConfig) -> Result<Self, RenderError> {
        config.validate()?;
        let controller = build_controller(&config.controller, &config.device)?;
        ChannelPipeline::with_controller(config, controller)
    }

    /// As [`ChannelPipeline::new`] with a controller of the caller's (`config.controller` is not used). The
    /// controller's output should respect the device's drive limit; the envelope enforces it anyway.
    pub fn with_controller(config: &PipelineConfig, controller: Box<dyn Controller>) -> Result<Self, RenderError> {
        config.validate()?;
        let grid = fv_config(config.contact_resistance_m2k_w);
        let renderer = Renderer::new(config.renderer, &config.skin, config.ambient_c, &grid)?;
        let contact_w_m2k = config.device.plate.contact_conductance_w_m2k;
        let display = DisplayFinger::new(config.renderer, &config.skin, config.ambient_c, contact_w_m2k, &grid)?;
        let envelope = SafetyEnvelope::new(config.envelope, config.device.drive.current_limit_a)?;
        let finger_conductance_w_k = display.receptor_conductance_w_m2k() * config.device.plate.area_m2;
        Ok(ChannelPipeline {
            renderer,
            display,
            controller,
            envelope,
            mode: Mode::Render,
            finger_conductance_w_k,
            applied_current_a: 0.0,
            last_setpoint_c: None,
        })
    }

    /// Changes what the channel displays, at any time: air (release), a touch of a fresh object (also a change of
    /// material during contact), or a direct temperature. Validated first ([`Stimulus::validate`]); an error
    /// leaves the pipeline unchanged. Not a per-tick operation: a new material may allocate its grid.
    pub fn set_stimulus(&mut self, stimulus: Stimulus) -> Result<(), RenderError> {
        stimulus.validate()?;
        match stimulus {
            Stimulus::Air => {
                self.renderer.release();
                self.mode = Mode::Render;
            }
            Stimulus::Touch { material, object_c } => {
                self.touch(&material, object_c)?;
            }
            Stimulus::Direct { temp_c, rate_c_s } => {
                let ramp_c = match self.mode {
                    Mode::Direct { ramp_c, .. } => ramp_c,
                    Mode::Render => self.last_setpoint_c,
                };
                self.renderer.release();
                self.mode = Mode::Direct {
                    temp_c,
                    rate_c_s,
                    ramp_c,
                };
            }
        }
        Ok(())
    }

    fn touch(&mut self, material: &Material, object_c: f64) -> Result<(), RenderError> {
        self.renderer.touch(material, object_c)?;
        self.mode = Mode::Render;
        Ok(())
    }

    /// One tick at `now_s` \[s\] (the envelope's clock: the same clock as the readings' `time_s`) for the interval
    /// `dt_s` \[s\] until the next tick, with the newest `reading`. Returns the gated drive to apply until the next
    /// tick and what happened. Never allocates, never panics.
    pub fn tick(&mut self, now_s: f64, dt_s: f64, reading: &Reading) -> (DriveCommand, Telemetry) {
        self.envelope.observe(&reading.measurement());
        if !(dt_s.is_finite() && dt_s > 0.0) {
            let drive = self.envelope.gate_drive(now_s, f64::NAN);
            let telemetry = self.refused_tick(now_s, reading, &drive);
            return (drive, telemetry);
        }
        let (target_c, requested_c) = self.request(dt_s);
        let decision = self.envelope.shape_setpoint(now_s, self.feasible(requested_c, dt_s));
        self.last_setpoint_c = Some(decision.setpoint_c);
        let request_a = self.control(now_s, dt_s, reading, &decision);
        let drive = self.envelope.gate_drive(now_s, request_a);
        self.applied_current_a = drive.current_a();
        let plate_c = self
            .controller
            .plate_estimate_c()
            .filter(|p| p.is_finite())
            .unwrap_or(decision.setpoint_c);
        self.display.advance(dt_s, plate_c);
        let telemetry = Telemetry {
            time_s: now_s,
            contact: self.mode == Mode::Render && self.renderer.in_contact(),
            target_skin_c: target_c,
            skin_c: self.display.receptor_c(),
            requested_setpoint_c: requested_c,
            display_setpoint_c: decision.setpoint_c,
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
            requested_current_a: request_a,
            current_a: drive.current_a(),
            fault: drive.fault(),
        };
        (drive, telemetry)
    }

    /// Steps the renderer (or the direct ramp) by `dt_s`: (target, requested set-point).
    fn request(&mut self, dt_s: f64) -> (f64, f64) {
        self.renderer.step(dt_s);
        match &mut self.mode {
            Mode::Render => {
                let target_c = self.renderer.receptor_c();
                (target_c, self.display.setpoint_c(target_c, dt_s))
            }
            Mode::Direct {
                temp_c,
                rate_c_s,
                ramp_c,
            } => {
                let from_c = ramp_c.unwrap_or(*temp_c);
                let max_step_c = *rate_c_s * dt_s;
                let next_c = from_c + (*temp_c - from_c).clamp(-max_step_c, max_step_c);
                *ramp_c = Some(next_c);
                (f64::NAN, next_c)
            }
        }
    }

    /// The request limited to [`FEASIBLE_BAND_C`] (or two ticks of the envelope's rate limit, if more) around the
    /// plate temperature the controller expects now, when it has an estimate. Without the band a set-point the
    /// plate cannot follow runs away from it inside the envelope's rate limiter (which shapes from its own last
    /// value), and when the request turns back the shaped set-point needs time to return to the plate: the
    /// controller keeps driving past the target (measured on the default display, model controller, aluminium,
    /// 20 °C/s: overshoot 0.27 °C without the band). The band is wide enough for the controller to drive its
    /// full current towards a set-point beyond it. NaN passes unchanged (the envelope latches it).
    fn feasible(&self, requested_c: f64, dt_s: f64) -> f64 {
        match self.controller.plate_estimate_c() {
            Some(plate_c) if plate_c.is_finite() && requested_c.is_finite() => {
                let band_c = FEASIBLE_BAND_C.max(2.0 * self.envelope.config().max_setpoint_rate_c_per_s * dt_s);
                requested_c.clamp(plate_c - band_c, plate_c + band_c)
            }
            _ => requested_c,
        }
    }

    /// The controller's request for this tick (NaN if it refused its input).
    fn control(&mut self, now_s: f64, dt_s: f64, reading: &Reading, decision: &SetpointDecision) -> f64 {
        let input = ControlInput {
            time_s: now_s,
            dt_s,
            setpoint_c: decision.setpoint_c,
            setpoint_rate_c_per_s: decision.rate_c_per_s,
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
            applied_current_a: self.applied_current_a,
            finger_receptor_c: Some(self.display.receptor_c()),
            finger_conductance_w_k: self.finger_conductance_w_k,
        };
        self.controller.update(&input).unwrap_or(f64::NAN)
    }

    fn refused_tick(&mut self, now_s: f64, reading: &Reading, drive: &DriveCommand) -> Telemetry {
        self.applied_current_a = drive.current_a();
        Telemetry {
            time_s: now_s,
            contact: self.mode == Mode::Render && self.renderer.in_contact(),
            target_skin_c: f64::NAN,
            skin_c: self.display.receptor_c(),
            requested_setpoint_c: f64::NAN,
            display_setpoint_c: self.last_setpoint_c.unwrap_or(f64::NAN),
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
            requested_current_a: f64::NAN,
            current_a: drive.current_a(),
            fault: drive.fault(),
        }
    }

    /// Clears the envelope's latched fault at `now_s` (see [`SafetyEnvelope::clear_fault`]) and resets the
    /// controller, so it restarts from the present readings. Returns the cleared fault.
    pub fn clear_fault(&mut self, now_s: f64) -> Result<Option<FaultCode>, RenderError> {
        let cleared = self.envelope.clear_fault(now_s)?;
        if cleared.is_some() {
            self.controller.reset();
            self.applied_current_a = 0.0;
        }
        Ok(cleared)
    }

    /// The safety envelope (fault, thermal dose, limits).
    pub fn envelope(&self) -> &SafetyEnvelope {
        &self.envelope
    }

    /// The controller.
    pub fn controller(&self) -> &dyn Controller {
        self.controller.as_ref()
    }

    /// The renderer.
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// The finger model on the display and its inverse.
    pub fn display_finger(&self) -> &DisplayFinger {
        &self.display
    }

    /// The finger model's receptor-to-plate conductance over the contact area [W/K], as given to the controller.
    pub fn finger_conductance_w_k(&self) -> f64 {
        self.finger_conductance_w_k
    }

    /// Whether the channel is in direct mode.
    pub fn is_direct(&self) -> bool {
        matches!(self.mode, Mode::Direct { .. })
    }
}
