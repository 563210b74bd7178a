//! What the control loop drives per channel: the [`ChannelEngine`] trait (stimulus in; reading in, gated drive
//! command and telemetry out), implemented by the render pipeline (`thermode_pipeline::ChannelPipeline`: renderer →
//! display inverse → controller → safety envelope) and by [`TrackingEngine`], a deliberately simple engine for
//! tests of the runtime (it is not a thermal renderer). [`Stimulus`] and [`Telemetry`] are the pipeline's.
//! Refusals are typed end to end ([`EngineError`]: the limit, pipeline or envelope error itself).
//!
//! Every drive an engine returns is a `thermode_safety::DriveCommand`, which only a safety envelope can make, so an
//! engine cannot bypass the envelope.

use thermode_device::Reading;
use thermode_model::params::Rule;
use thermode_pipeline::ChannelPipeline;
use thermode_safety::{DoseLedger, DriveCommand, EnvelopeConfig, FaultCode, MeasuredOnly, SafetyEnvelope};

use crate::limits::StimulusLimits;

pub use crate::limits::EngineError;
pub use thermode_pipeline::{SelfTestState, Stimulus, Telemetry};

/// One channel's renderer + controller + safety envelope, as the loop sees it.
pub trait ChannelEngine {
    /// What this channel accepts as a stimulus: its envelope's display range and rate limit, the pipeline's object
    /// range. The loop refuses any stimulus outside them before [`ChannelEngine::set_stimulus`] is called.
    fn limits(&self) -> StimulusLimits;

    /// Changes what the channel renders from the next tick on. Invalid stimuli are refused and change nothing.
    fn set_stimulus(&mut self, stimulus: Stimulus) -> Result<(), EngineError>;

    /// One tick at loop time `now_s` \[s\], `dt_s` \[s\] after the previous one, with the channel's newest reading:
    /// the gated drive command to apply and the telemetry of this tick. Never fails: bad numbers latch a fault and
    /// give a 0 A command.
    fn tick(&mut self, now_s: f64, dt_s: f64, reading: &Reading) -> (DriveCommand, Telemetry);

    /// Clears the latched safety fault at `now_s` \[s\] if its cause is gone; returns the cleared fault (`None`
    /// if none was latched). Refused while the cause persists.
    fn clear_fault(&mut self, now_s: f64) -> Result<Option<FaultCode>, EngineError>;

    /// Holds the drive off until the next stimulus (stop all): the channel renders air, its envelope keeps
    /// checking faults with the drive at 0 A, and the next stimulus starts the controller afresh.
    fn hold(&mut self);
    /// The channel's thermal dose as its safety envelope counts it (`SafetyEnvelope::dose_ledger`). Called by the
    /// loop after every tick (it publishes it and the daemon saves it): cheap, no allocation.
    fn dose(&self) -> DoseLedger;

    /// Whether the channel's dose budget is spent (`SafetyEnvelope::dose_budget_spent`): its drive is then off and
    /// the loop refuses every stimulus but air. Called by the loop after every tick: cheap, no allocation.
    fn dose_budget_spent(&self) -> bool;

    /// Restores a saved thermal dose into the channel's safety envelope (`SafetyEnvelope::restore_dose`: never
    /// lowers the dose). The daemon calls it before the first tick.
    fn restore_dose(&mut self, saved: &DoseLedger) -> Result<(), EngineError>;

    /// Where the channel's start-up self-test of its display stands (`ChannelPipeline::self_test_state`); the loop
    /// ticks before it answers any command while one is [`SelfTestState::Running`]. Default: none is run.
    fn self_test_state(&self) -> SelfTestState {
        SelfTestState::NotRun
    }
}

/// A boxed engine is an engine (the daemon's loop holds whichever engines its factory built as these).
impl<E: ChannelEngine + ?Sized> ChannelEngine for Box<E> {
    fn limits(&self) -> StimulusLimits {
        (**self).limits()
    }
    fn set_stimulus(&mut self, stimulus: Stimulus) -> Result<(), EngineError> {
        (**self).set_stimulus(stimulus)
    }
    fn tick(&mut self, now_s: f64, dt_s: f64, reading: &Reading) -> (DriveCommand, Telemetry) {
        (**self).tick(now_s, dt_s, reading)
    }
    fn clear_fault(&mut self, now_s: f64) -> Result<Option<FaultCode>, EngineError> {
        (**self).clear_fault(now_s)
    }
    fn hold(&mut self) {
        (**self).hold();
    }
    fn dose(&self) -> DoseLedger {
        (**self).dose()
    }
    fn dose_budget_spent(&self) -> bool {
        (**self).dose_budget_spent()
    }
    fn restore_dose(&mut self, saved: &DoseLedger) -> Result<(), EngineError> {
        (**self).restore_dose(saved)
    }
    fn self_test_state(&self) -> SelfTestState {
        (**self).self_test_state()
    }
}

/// Builds a channel's engines on the loop thread (engines need not be `Send`): called once with the device's
/// channel count, it returns one engine per channel.
pub type EngineFactory = Box<dyn FnOnce(usize) -> Result<Vec<Box<dyn ChannelEngine>>, EngineError> + Send>;

impl ChannelEngine for ChannelPipeline {
    fn limits(&self) -> StimulusLimits {
        StimulusLimits::of_envelope(self.envelope().config())
    }

    fn set_stimulus(&mut self, stimulus: Stimulus) -> Result<(), EngineError> {
        Ok(ChannelPipeline::set_stimulus(self, stimulus)?)
    }

    fn tick(&mut self, now_s: f64, dt_s: f64, reading: &Reading) -> (DriveCommand, Telemetry) {
        ChannelPipeline::tick(self, now_s, dt_s, reading)
    }

    fn clear_fault(&mut self, now_s: f64) -> Result<Option<FaultCode>, EngineError> {
        Ok(ChannelPipeline::clear_fault(self, now_s)?)
    }

    fn hold(&mut self) {
        ChannelPipeline::hold(self);
    }

    fn dose(&self) -> DoseLedger {
        self.envelope().dose_ledger()
    }

    fn dose_budget_spent(&self) -> bool {
        self.envelope().dose_budget_spent()
    }

    fn restore_dose(&mut self, saved: &DoseLedger) -> Result<(), EngineError> {
        Ok(ChannelPipeline::restore_dose(self, saved)?)
    }

    fn self_test_state(&self) -> SelfTestState {
        ChannelPipeline::self_test_state(self)
    }
}

/// Skin effusivity used by [`TrackingEngine`]'s contact temperature \[W·s^½/(m²·K)\] (a typical fingertip value).
const TRACKING_SKIN_EFFUSIVITY: f64 = 1100.0;

/// A test engine: the target is the contact temperature of two semi-infinite bodies (skin at `rest_c`, object at
/// its temperature), the set-point equals the target (or ramps in direct mode), and a proportional controller
/// behind a real [`SafetyEnvelope`] drives the display.
#[derive(Debug, Clone)]
pub struct TrackingEngine {
    rest_c: f64,
    gain_a_per_c: f64,
    stimulus: Stimulus,
    direct_c: Option<f64>,
    envelope: SafetyEnvelope,
    /// Held off (stop all) until the next stimulus.
    held: bool,
}

impl TrackingEngine {
    /// A test engine: resting skin `rest_c` \[°C\] (default use 32), proportional gain `gain_a_per_c` \[A/°C\],
    /// drive limit `current_limit_a` \[A\], default envelope.
    pub fn new(rest_c: f64, gain_a_per_c: f64, current_limit_a: f64) -> Result<Self, EngineError> {
        Rule::Finite.check("tracking engine rest temperature [°C]", rest_c)?;
        Rule::NonNegative.check("tracking engine gain [A/°C]", gain_a_per_c)?;
        let envelope = SafetyEnvelope::new(EnvelopeConfig::default(), current_limit_a)?;
        Ok(TrackingEngine {
            rest_c,
            gain_a_per_c,
            stimulus: Stimulus::Air,
            direct_c: None,
            envelope,
            held: false,
        })
    }

    fn target_c(&self) -> f64 {
        match &self.stimulus {
            Stimulus::Air => self.rest_c,
            Stimulus::Touch { material, object_c } => {
                let e_object = material.effusivity();
                (TRACKING_SKIN_EFFUSIVITY * self.rest_c + e_object * object_c) / (TRACKING_SKIN_EFFUSIVITY + e_object)
            }
            Stimulus::Direct { temp_c, .. } => *temp_c,
        }
    }

    fn requested_setpoint_c(&mut self, dt_s: f64) -> f64 {
        let Stimulus::Direct { temp_c, rate_c_per_s } = self.stimulus else {
            self.direct_c = None;
            return self.target_c();
        };
        let from_c = self.direct_c.unwrap_or(self.rest_c);
        let step_c = rate_c_per_s * dt_s.max(0.0);
        let next_c = from_c + (temp_c - from_c).clamp(-step_c, step_c);
        self.direct_c = Some(next_c);
        next_c
    }
}

impl ChannelEngine for TrackingEngine {
    fn limits(&self) -> StimulusLimits {
        StimulusLimits::of_envelope(self.envelope.config())
    }

    fn set_stimulus(&mut self, stimulus: Stimulus) -> Result<(), EngineError> {
        stimulus.validate()?;
        self.stimulus = stimulus;
        self.held = false;
        Ok(())
    }

    fn tick(&mut self, now_s: f64, dt_s: f64, reading: &Reading) -> (DriveCommand, Telemetry) {
        self.envelope.observe(&reading.measurement());
        let requested_c = self.requested_setpoint_c(dt_s);
        let shaped = self.envelope.shape_setpoint(now_s, requested_c);
        let request_a = self.gain_a_per_c * (shaped.setpoint_c - reading.sensor_c);
        let command = if self.held {
            self.envelope.hold(now_s)
        } else {
            self.envelope.gate_drive(now_s, request_a, &MeasuredOnly)
        };
        let telemetry = Telemetry {
            time_s: now_s,
            contact: matches!(self.stimulus, Stimulus::Touch { .. }),
            target_skin_c: self.target_c(),
            skin_c: reading.sensor_c,
            requested_setpoint_c: requested_c,
            display_setpoint_c: shaped.setpoint_c,
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
            requested_current_a: request_a,
            current_a: command.current_a(),
            plate_estimate_c: f64::NAN,
            finger_c: f64::NAN,
            fault: command.fault(),
        };
        (command, telemetry)
    }

    fn clear_fault(&mut self, now_s: f64) -> Result<Option<FaultCode>, EngineError> {
        Ok(self.envelope.clear_fault(now_s)?)
    }

    fn hold(&mut self) {
        self.stimulus = Stimulus::Air;
        self.held = true;
    }

    fn dose(&self) -> DoseLedger {
        self.envelope.dose_ledger()
    }

    fn dose_budget_spent(&self) -> bool {
        self.envelope.dose_budget_spent()
    }

    fn restore_dose(&mut self, saved: &DoseLedger) -> Result<(), EngineError> {
        Ok(self.envelope.restore_dose(saved)?)
    }
}

/// An [`EngineFactory`] of one render pipeline per channel, all built from `config`.
pub fn pipeline_engines(config: thermode_pipeline::PipelineConfig) -> EngineFactory {
    Box::new(move |count| {
        (0..count)
            .map(|_| {
                ChannelPipeline::new(&config)
                    .map(|p| Box::new(p) as Box<dyn ChannelEngine>)
                    .map_err(EngineError::from)
            })
            .collect()
    })
}

/// An [`EngineFactory`] of one render pipeline per channel, channel `i` built from `configs[i]` (a display of
/// several devices, each on its own device file); channels past the list take its last entry.
pub fn pipeline_engines_per_channel(configs: Vec<thermode_pipeline::PipelineConfig>) -> EngineFactory {
    Box::new(move |count| {
        (0..count)
            .map(|channel| {
                let config = configs.get(channel).or(configs.last()).ok_or_else(|| {
                    EngineError::BadValue(thermode_model::BadValue::custom(
                        "pipeline configurations",
                        0.0,
                        "need at least one",
                    ))
                })?;
                ChannelPipeline::new(config)
                    .map(|p| Box::new(p) as Box<dyn ChannelEngine>)
                    .map_err(EngineError::from)
            })
            .collect()
    })
}

/// `engines` with each channel's saved dose restored (`saved(channel)`) before the factory returns, i.e. before
/// the loop's first tick. A refused restore (a bad number) fails the start.
pub fn with_restored_doses(
    engines: EngineFactory,
    saved: impl Fn(usize) -> DoseLedger + Send + 'static,
) -> EngineFactory {
    Box::new(move |count| {
        let mut built = engines(count)?;
        for (channel, engine) in built.iter_mut().enumerate() {
            engine.restore_dose(&saved(channel))?;
        }
        Ok(built)
    })
}

/// An [`EngineFactory`] of [`TrackingEngine`]s (tests): resting skin `rest_c` \[°C\], gain \[A/°C\], drive limit \[A\].
pub fn tracking_engines(rest_c: f64, gain_a_per_c: f64, current_limit_a: f64) -> EngineFactory {
    Box::new(move |count| {
        (0..count)
            .map(|_| {
                TrackingEngine::new(rest_c, gain_a_per_c, current_limit_a)
                    .map(|e| Box::new(e) as Box<dyn ChannelEngine>)
            })
            .collect()
    })
}
