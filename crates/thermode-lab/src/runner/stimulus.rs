//! The stimulus seam: what happens while the finger touches a material, real or rendered.
//!
//! The runner asks a [`Stimulus`] to present one material in one condition for the presentation time and gets back
//! a [`TrialMeasurement`]: the finger temperature at the start and at the end and, if the stimulus has it, the skin
//! temperature curve. A lab with a display implements [`Stimulus`] over its device (the display/runtime pipeline:
//! render the material on the Peltier element for a simulated trial, read the finger sensor for a real one).
//!
//! Two stimuli without hardware ship here:
//! - [`DisplayStimulus`] (the default of `thermode lab run`): every material is rendered offline on the simulated
//!   display of `thermode_render::run` (renderer → display inverse → controller → safety envelope → Peltier plant
//!   with a simulated finger resting on it). A `real` trial is that finger touching the real material (the render's
//!   ground truth); a `simulated` trial is the same finger on the display rendering the material. The two differ
//!   where the display cannot follow (it lags at the touch, the paper's first flaw).
//! - [`ModelStimulus`] stands in for both conditions with real contact under the finite-volume model of finger and
//!   object ([`FvContact`], the physically true curve of `thermode_model::fv`). Real and simulated trials give the
//!   same curve; the name says so.

use std::collections::HashMap;

use serde_json::json;
use thermode_model::fv::{simulate_contact, ContactSpec, FvConfig, FvModel, InitialState};
use thermode_model::materials::Material;
use thermode_model::params::{BadValue, Rule};
use thermode_model::skin::Skin;
use thermode_model::ParamError;
use thiserror::Error;

use thermode_pipeline::{ControllerKind, PipelineConfig};
use thermode_render::run::{render, render_all, RenderRun, DEFAULT_PRE_CONTACT_S, DEFAULT_RATE_HZ};
use thermode_render::{RenderError, RenderSpec};

use super::trace::TrialTrace;
use crate::design::Condition;
use crate::random::{standard_normal, trial_rng};

/// Why a stimulus could not be presented or measured.
#[derive(Debug, Error)]
pub enum StimulusError {
    /// The thermal model refused its parameters.
    #[error("stimulus model: {0}")]
    Model(#[from] ParamError),
    /// The simulated display refused its settings or could not render.
    #[error("stimulus display: {0}")]
    Render(#[from] RenderError),
    /// The device failed (message from the device layer).
    #[error("stimulus device: {0}")]
    Device(String),
    /// The measurement is unusable (non-finite temperature, malformed curve, …).
    #[error("stimulus measurement: {0}")]
    BadMeasurement(String),
    /// A stimulus setting is out of range (the one `BadValue` of `thermode_model::params`, naming the key).
    #[error("stimulus setting {0}")]
    BadSetting(#[from] BadValue),
}

/// A skin surface temperature curve: `skin_c[i]` at `time_s[i]` seconds after the touch.
#[derive(Debug, Clone, PartialEq)]
pub struct SkinCurve {
    /// Time since the touch \[s\], starting at 0, strictly increasing.
    pub time_s: Vec<f64>,
    /// Skin surface temperature \[°C\].
    pub skin_c: Vec<f64>,
}

impl SkinCurve {
    /// Checks: at least two samples, equal lengths, finite values, times strictly increasing from 0.
    pub fn validate(&self) -> Result<(), StimulusError> {
        let bad = |m: &str| Err(StimulusError::BadMeasurement(format!("skin curve: {m}")));
        if self.time_s.len() != self.skin_c.len() {
            return bad("time and temperature columns differ in length");
        }
        if self.time_s.len() < 2 {
            return bad("fewer than two samples");
        }
        if self.time_s.iter().chain(&self.skin_c).any(|v| !v.is_finite()) {
            return bad("a value is not finite");
        }
        if self.time_s[0] != 0.0 || self.time_s.windows(2).any(|w| w[1] <= w[0]) {
            return bad("times must start at 0 and increase");
        }
        Ok(())
    }

    /// The temperature at `t_s` by linear interpolation (clamped to the curve's ends). Call on a validated curve.
    pub fn at(&self, t_s: f64) -> f64 {
        let i = self.time_s.partition_point(|&t| t <= t_s);
        if i == 0 {
            return self.skin_c[0];
        }
        if i >= self.time_s.len() {
            return self.skin_c[self.skin_c.len() - 1];
        }
        let (t0, t1) = (self.time_s[i - 1], self.time_s[i]);
        let w = (t_s - t0) / (t1 - t0);
        self.skin_c[i - 1] + w * (self.skin_c[i] - self.skin_c[i - 1])
    }
}

/// What a stimulus reports about one presentation.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialMeasurement {
    /// Finger (skin surface) temperature just before the touch \[°C\].
    pub finger_start_c: f64,
    /// Finger temperature at the end of the presentation \[°C\].
    pub finger_end_c: f64,
    /// The skin temperature curve of the presentation, if the stimulus records one.
    pub curve: Option<SkinCurve>,
    /// Whether the finger temperatures were measured on a display (true) or come from a model (false: a
    /// simulation); the session keeps them in different columns.
    pub measured: bool,
    /// The trial's curve on a real display (kept beside the session CSV), if the stimulus records one.
    pub trace: Option<TrialTrace>,
}

impl TrialMeasurement {
    /// A simulation's measurement of a trial: the finger at the first and the last point of `curve` (which must not
    /// be empty), with the curve, no trace.
    pub fn modelled(curve: SkinCurve) -> Self {
        TrialMeasurement {
            finger_start_c: curve.skin_c[0],
            finger_end_c: curve.skin_c[curve.skin_c.len() - 1],
            curve: Some(curve),
            measured: false,
            trace: None,
        }
    }

    /// Checks that the temperatures are finite and the curve (if any) is valid.
    pub fn validate(&self) -> Result<(), StimulusError> {
        if !(self.finger_start_c.is_finite() && self.finger_end_c.is_finite()) {
            return Err(StimulusError::BadMeasurement(format!(
                "finger temperatures {} / {} °C are not finite",
                self.finger_start_c, self.finger_end_c
            )));
        }
        self.curve.as_ref().map_or(Ok(()), SkinCurve::validate)
    }
}

/// One presentation asked of a [`Stimulus`].
#[derive(Debug, Clone, Copy)]
pub struct StimulusRequest<'a> {
    /// The material to present.
    pub material: &'a Material,
    /// Real (the experimenter placed the sample) or simulated (render it on the display).
    pub condition: Condition,
    /// Presentation time \[s\].
    pub duration_s: f64,
    /// 0-based index of the participant in the design.
    pub participant_index: usize,
    /// 1-based trial number.
    pub trial: usize,
}

/// Presents a material to the finger and measures it. Implementations may take the presentation time themselves
/// (a device running in real time); the runner waits for whatever remains of it.
pub trait Stimulus {
    /// Presents `request.material` in `request.condition` and returns the measurement.
    fn present(&mut self, request: &StimulusRequest) -> Result<TrialMeasurement, StimulusError>;

    /// Notes for the operator gathered since the last call (an unsettled measurement, …); none by default.
    fn take_notes(&mut self) -> Vec<String> {
        Vec::new()
    }

    /// Measures the finger at rest now \[°C\] with how long the measurement took \[s\], where the stimulus measures
    /// a finger (a display); `None` by default (a simulation has no finger to wait for).
    fn finger_at_rest(&mut self) -> Option<Result<(f64, f64), StimulusError>> {
        None
    }
}

/// Real contact of the finger with a material under the finite-volume model (`thermode_model::fv`).
#[derive(Debug, Clone, PartialEq)]
pub struct FvContact {
    /// The finger. Default [`Skin::fingertip`].
    pub skin: Skin,
    /// Grid and boundaries. Default [`FvConfig::default`] (perfect contact; its surface curve changes by less than
    /// 0.005 °C when the grid is refined, for the paper's materials over 30 s).
    pub config: FvConfig,
    /// Room temperature, which the resting finger is in steady state with \[°C\]. Default 23 (the paper's room).
    pub ambient_c: f64,
    /// Temperature of the sample at the touch \[°C\]. Default 23 (samples at room temperature).
    pub object_c: f64,
    /// Interval between curve samples \[s\]. Default 0.05.
    pub output_dt_s: f64,
}

impl Default for FvContact {
    fn default() -> Self {
        FvContact {
            skin: Skin::fingertip(),
            config: FvConfig::default(),
            ambient_c: 23.0,
            object_c: 23.0,
            output_dt_s: 0.05,
        }
    }
}

impl FvContact {
    /// The skin surface curve of touching `material` for `duration_s`, the finger resting at `finger_start_c`
    /// (perfusion calibrated to it) or, with `None`, in its steady state in air.
    pub fn curve(
        &self,
        material: &Material,
        finger_start_c: Option<f64>,
        duration_s: f64,
    ) -> Result<SkinCurve, ParamError> {
        let initial = match finger_start_c {
            None => InitialState::SteadyInAir,
            Some(surface_c) => InitialState::RestingSurface { surface_c },
        };
        let spec = ContactSpec {
            ambient_c: self.ambient_c,
            object_c: self.object_c,
            initial,
            duration_s,
            output_dt_s: self.output_dt_s,
        };
        let run = simulate_contact(&self.skin, material, &self.config, &spec)?;
        Ok(SkinCurve {
            time_s: run.time_s,
            skin_c: run.surface_c,
        })
    }

    /// The resting finger's skin surface temperature: steady state in air at `ambient_c` \[°C\].
    pub fn resting_surface_c(&self) -> Result<f64, ParamError> {
        let mut model = FvModel::new(&self.skin, None, &self.config)?;
        model.set_steady_in_air(self.ambient_c)?;
        Ok(model.surface_c())
    }
}

/// Seed salt of the finger drift of [`ModelStimulus`] (so that it never shares a random stream with the simulated participant).
const DRIFT_SALT: u64 = 0x6472_6966_7400_0001;

/// The stand-in stimulus: both conditions are real contact under the fv model ([`FvContact`]).
///
/// The finger starts each trial at its resting temperature plus, if `finger_drift_sd_c` > 0, a Gaussian offset
/// drawn per (participant, trial) from a ChaCha8 stream of `seed` — so a resumed session sees the same fingers.
/// Curves are cached per (material, start temperature, duration).
#[derive(Debug, Clone)]
pub struct ModelStimulus {
    contact: FvContact,
    finger_drift_sd_c: f64,
    seed: u64,
    resting_c: f64,
    cache: HashMap<(String, u64, u64), SkinCurve>,
}

impl ModelStimulus {
    /// A model stimulus; `finger_drift_sd_c` \[°C\] (≥ 0, default choice 0) is the standard deviation of the
    /// finger's start temperature around its resting value from trial to trial.
    pub fn new(contact: FvContact, finger_drift_sd_c: f64, seed: u64) -> Result<ModelStimulus, StimulusError> {
        check_drift_sd(finger_drift_sd_c)?;
        let resting_c = contact.resting_surface_c()?;
        Ok(ModelStimulus {
            contact,
            finger_drift_sd_c,
            seed,
            resting_c,
            cache: HashMap::new(),
        })
    }

    /// The finger's resting surface temperature \[°C\].
    pub fn resting_c(&self) -> f64 {
        self.resting_c
    }

    /// A description for the session sidecar's device configuration.
    pub fn describe(&self) -> serde_json::Value {
        json!({
            "stimulus": "ModelStimulus",
            "note": "no display hardware: real and simulated trials are both real contact under the \
                     finite-volume model (thermode_model::fv); finger temperatures are the model's",
            "ambient_c": self.contact.ambient_c,
            "object_c": self.contact.object_c,
            "resting_finger_c": self.resting_c,
            "finger_drift_sd_c": self.finger_drift_sd_c,
            "contact_resistance_m2k_w": self.contact.config.contact_resistance_m2k_w,
            "skin_layers": self.contact.skin.layers.iter().map(|l| l.name.clone()).collect::<Vec<_>>(),
        })
    }

    fn start_c(&self, participant_index: usize, trial: usize) -> Option<f64> {
        if self.finger_drift_sd_c == 0.0 {
            return None;
        }
        Some(self.resting_c + trial_drift_c(self.finger_drift_sd_c, self.seed ^ DRIFT_SALT, participant_index, trial))
    }
}

impl Stimulus for ModelStimulus {
    fn present(&mut self, request: &StimulusRequest) -> Result<TrialMeasurement, StimulusError> {
        let start = self.start_c(request.participant_index, request.trial);
        let key = (
            request.material.name.clone(),
            start.unwrap_or(f64::NAN).to_bits(),
            request.duration_s.to_bits(),
        );
        let curve = match self.cache.get(&key) {
            Some(curve) => curve.clone(),
            None => {
                let curve = self.contact.curve(request.material, start, request.duration_s)?;
                self.cache.insert(key, curve.clone());
                curve
            }
        };
        Ok(TrialMeasurement::modelled(curve))
    }
}

/// Seed salt of the finger drift of [`DisplayStimulus`] (its own stream, apart from the simulated participant's and the sensor's).
const DISPLAY_DRIFT_SALT: u64 = 0x6472_6966_7400_0002;

/// How [`DisplayStimulus`] renders: the display's pipeline and the timing of the offline render.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplaySetup {
    /// The display's pipeline: device file, controller (`model` or `pid`), renderer, safety envelope, the
    /// controller's finger model and the room temperature. Default: see [`PipelineConfig::new`] (fv renderer,
    /// fingertip, 23 °C, the rendering envelope).
    pub pipeline: PipelineConfig,
    /// Time the finger rests on the display rendering air before the touch \[s\], at least one tick. Default
    /// [`DEFAULT_PRE_CONTACT_S`] (5).
    pub pre_contact_s: f64,
    /// Tick rate of the pipeline \[Hz\]. Default [`DEFAULT_RATE_HZ`] (100, the PT-100's sample rate).
    pub rate_hz: f64,
}

impl DisplaySetup {
    /// The defaults above for the display `pipeline`.
    pub fn new(pipeline: PipelineConfig) -> DisplaySetup {
        DisplaySetup {
            pipeline,
            pre_contact_s: DEFAULT_PRE_CONTACT_S,
            rate_hz: DEFAULT_RATE_HZ,
        }
    }

    /// The default display (built-in device file) with `controller`.
    pub fn default_display(controller: ControllerKind) -> DisplaySetup {
        DisplaySetup::new(PipelineConfig::new(
            thermode_device::DeviceConfig::default(),
            controller,
        ))
    }

    /// The render of touching `material` for `duration_s`, sensor noise seeded by `seed` (and the material's name).
    pub fn spec(&self, material: &Material, duration_s: f64, seed: u64) -> RenderSpec {
        let mut spec = RenderSpec::new(self.pipeline.clone(), material.clone());
        spec.duration_s = duration_s;
        spec.pre_contact_s = self.pre_contact_s;
        spec.rate_hz = self.rate_hz;
        spec.seed = seed;
        spec
    }

    fn validate(&self) -> Result<(), StimulusError> {
        self.pipeline.validate().map_err(RenderError::from)?;
        let ticks = self.pre_contact_s * self.rate_hz;
        if !(ticks.is_finite() && ticks.round() >= 1.0) {
            let requirement = "must last at least one tick of the pipeline (the curve starts at the touch)";
            return Err(BadValue::custom("pre_contact_s", self.pre_contact_s, requirement).into());
        }
        Ok(())
    }
}

/// Both curves of one material from one render: `real` is the finger touching the real material (the render's
/// ground truth `truth_skin_c`), `simulated` the finger on the display (`skin_c`). Time 0 is the touch; the first
/// sample is the finger just before it.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayCurves {
    /// The finger touching the real material.
    pub real: SkinCurve,
    /// The finger on the display rendering the material.
    pub simulated: SkinCurve,
}

impl DisplayCurves {
    /// The curve of `condition`.
    pub fn of(&self, condition: Condition) -> &SkinCurve {
        match condition {
            Condition::Real => &self.real,
            Condition::Simulated => &self.simulated,
        }
    }

    /// The curves of a render: its rows from the touch on. A display fault is an error (the drive was switched
    /// off; the finger did not feel the material).
    pub fn from_run(run: &RenderRun) -> Result<DisplayCurves, StimulusError> {
        if let Some(fault) = &run.summary.first_fault {
            return Err(StimulusError::Device(format!(
                "the simulated display faulted rendering {}: {fault} at t = {:.2} s (drive switched off)",
                run.spec.material.name,
                run.summary.first_fault_time_s.unwrap_or(f64::NAN)
            )));
        }
        let t = &run.trajectory;
        let half_tick_s = 0.5 / run.spec.rate_hz;
        let first = t.time_s.iter().position(|&time| time > -half_tick_s).ok_or_else(|| {
            StimulusError::BadMeasurement(format!(
                "the render of {} has no row after the touch",
                run.spec.material.name
            ))
        })?;
        if first == 0 {
            return Err(StimulusError::BadMeasurement(format!(
                "the render of {} has no row before the touch",
                run.spec.material.name
            )));
        }
        let t0 = t.time_s[first];
        let time_s: Vec<f64> = t.time_s[first..].iter().map(|&time| time - t0).collect();
        let curves = DisplayCurves {
            real: SkinCurve {
                time_s: time_s.clone(),
                skin_c: t.truth_skin_c[first..].to_vec(),
            },
            simulated: SkinCurve {
                time_s,
                skin_c: t.skin_c[first..].to_vec(),
            },
        };
        curves.real.validate()?;
        curves.simulated.validate()?;
        Ok(curves)
    }
}

/// The display stimulus: every material rendered offline on the simulated display (`thermode_render::run`), see the
/// module documentation. A `real` trial gives [`DisplayCurves::real`], a `simulated` trial
/// [`DisplayCurves::simulated`].
///
/// Deterministic: the only randomness of a render is the display's sensor noise, seeded by `seed` and the
/// material's name. A curve does not depend on the trial, so one render per (material, presentation time) serves
/// both conditions and is cached.
///
/// **Finger drift.** With `finger_drift_sd_c` > 0 each trial's finger is offset from its resting curve by a
/// Gaussian amount drawn per (participant, trial) from a ChaCha8 stream of `seed` (a resumed session sees the same
/// fingers); the whole curve is shifted by it. This is a first-order model: a finger δ warmer would also drop by
/// about δ / (T_finger − T_object) more (≈ 5 % for δ = 0.5 °C), which is not rendered. The offset moves the finger
/// start temperature, which is what the exclusion rule looks at.
#[derive(Debug, Clone)]
pub struct DisplayStimulus {
    setup: DisplaySetup,
    finger_drift_sd_c: f64,
    seed: u64,
    drift_seed: u64,
    cache: HashMap<(String, u64), DisplayCurves>,
}

impl DisplayStimulus {
    /// A display stimulus; `finger_drift_sd_c` \[°C\] (≥ 0; 0 = every trial starts at rest) as for
    /// [`ModelStimulus`]; `seed` seeds the sensor noise and the drift.
    pub fn new(setup: DisplaySetup, finger_drift_sd_c: f64, seed: u64) -> Result<DisplayStimulus, StimulusError> {
        check_drift_sd(finger_drift_sd_c)?;
        setup.validate()?;
        Ok(DisplayStimulus {
            setup,
            finger_drift_sd_c,
            seed,
            drift_seed: seed,
            cache: HashMap::new(),
        })
    }

    /// The same stimulus with the finger drift drawn from the streams of `drift_seed` instead of the seed given to
    /// [`new`](Self::new), which keeps seeding the sensor noise (`lab run --seed`: the participants' noise apart
    /// from the design's seed).
    pub fn with_drift_seed(mut self, drift_seed: u64) -> DisplayStimulus {
        self.drift_seed = drift_seed;
        self
    }

    /// The setup.
    pub fn setup(&self) -> &DisplaySetup {
        &self.setup
    }

    /// Renders every material of `materials` not yet cached for `duration_s` \[s\], in parallel (one thread each).
    pub fn prepare(&mut self, materials: &[Material], duration_s: f64) -> Result<(), StimulusError> {
        let mut missing: Vec<&Material> = Vec::new();
        for m in materials {
            if !self.cache.contains_key(&key(m, duration_s)) && !missing.iter().any(|x| x.name == m.name) {
                missing.push(m);
            }
        }
        let specs: Vec<RenderSpec> = missing
            .iter()
            .map(|m| self.setup.spec(m, duration_s, self.seed))
            .collect();
        for run in render_all(&specs)? {
            let curves = DisplayCurves::from_run(&run)?;
            self.cache.insert(key(&run.spec.material, duration_s), curves);
        }
        Ok(())
    }

    /// Both curves of touching `material` for `duration_s` \[s\] (rendered once, then cached).
    pub fn curves(&mut self, material: &Material, duration_s: f64) -> Result<&DisplayCurves, StimulusError> {
        let k = key(material, duration_s);
        if !self.cache.contains_key(&k) {
            let run = render(&self.setup.spec(material, duration_s, self.seed))?;
            self.cache.insert(k.clone(), DisplayCurves::from_run(&run)?);
        }
        self.cache
            .get(&k)
            .ok_or_else(|| StimulusError::BadMeasurement("the rendered curve was not cached".to_string()))
    }

    /// A description for the session sidecar's device configuration: the device file (TOML), the controller, the
    /// renderer and every setting of the render.
    pub fn describe(&self) -> serde_json::Value {
        let p = &self.setup.pipeline;
        let pid_gains = match &p.controller {
            ControllerKind::Pid(gains) => serde_json::to_value(gains).unwrap_or(serde_json::Value::Null),
            ControllerKind::Model => serde_json::Value::Null,
        };
        json!({
            "stimulus": "DisplayStimulus",
            "note": "no display hardware: each material is rendered offline on the simulated display \
                     (thermode_render::run); a real trial is the simulated finger touching the real material \
                     (the render's ground truth), a simulated trial the same finger on the display",
            "controller": p.controller.name(),
            "pid_gains": pid_gains,
            "renderer": p.renderer.name(),
            "ambient_c": p.ambient_c,
            "contact_resistance_m2k_w": p.contact_resistance_m2k_w,
            "envelope": format!("{:?}", p.envelope),
            "skin_layers": p.skin.layers.iter().map(|l| l.name.clone()).collect::<Vec<_>>(),
            "pre_contact_s": self.setup.pre_contact_s,
            "rate_hz": self.setup.rate_hz,
            "sensor_noise_seed": self.seed,
            "finger_drift_sd_c": self.finger_drift_sd_c,
            "device_toml": p.device.to_toml_string(),
        })
    }

    fn drift_c(&self, participant_index: usize, trial: usize) -> f64 {
        if self.finger_drift_sd_c == 0.0 {
            return 0.0;
        }
        trial_drift_c(
            self.finger_drift_sd_c,
            self.drift_seed ^ DISPLAY_DRIFT_SALT,
            participant_index,
            trial,
        )
    }
}

/// The cache key of a render: material name and presentation time.
fn key(material: &Material, duration_s: f64) -> (String, u64) {
    (material.name.clone(), duration_s.to_bits())
}

impl Stimulus for DisplayStimulus {
    fn present(&mut self, request: &StimulusRequest) -> Result<TrialMeasurement, StimulusError> {
        let drift_c = self.drift_c(request.participant_index, request.trial);
        let base = self.curves(request.material, request.duration_s)?.of(request.condition);
        let curve = SkinCurve {
            time_s: base.time_s.clone(),
            skin_c: base.skin_c.iter().map(|c| c + drift_c).collect(),
        };
        Ok(TrialMeasurement::modelled(curve))
    }
}

/// `Ok` if `finger_drift_sd_c` \[°C\] is a valid standard deviation of the finger's start temperature (finite, at
/// least 0).
fn check_drift_sd(finger_drift_sd_c: f64) -> Result<(), StimulusError> {
    Rule::NonNegative.check("finger_drift_sd_c", finger_drift_sd_c)?;
    Ok(())
}

/// The finger's offset from rest in one trial \[°C\]: `sd_c` \[°C\] times a standard normal number from the trial's
/// stream of `seed` ([`trial_rng`]).
fn trial_drift_c(sd_c: f64, seed: u64, participant_index: usize, trial: usize) -> f64 {
    let mut rng = trial_rng(seed, participant_index, trial);
    sd_c * standard_normal(&mut rng)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_is_linear_and_clamped() {
        let curve = SkinCurve {
            time_s: vec![0.0, 1.0, 3.0],
            skin_c: vec![30.0, 28.0, 27.0],
        };
        curve.validate().expect("valid");
        assert_eq!(curve.at(-1.0), 30.0);
        assert_eq!(curve.at(0.5), 29.0);
        assert_eq!(curve.at(2.0), 27.5);
        assert_eq!(curve.at(9.0), 27.0);
    }

    #[test]
    fn malformed_curves_are_refused() {
        let bad = [
            (vec![0.0], vec![30.0]),
            (vec![0.0, 1.0], vec![30.0]),
            (vec![0.0, 0.0], vec![30.0, 29.0]),
            (vec![0.5, 1.0], vec![30.0, 29.0]),
            (vec![0.0, 1.0], vec![30.0, f64::NAN]),
        ];
        for (time_s, skin_c) in bad {
            let curve = SkinCurve { time_s, skin_c };
            assert!(curve.validate().is_err(), "accepted {curve:?}");
        }
    }

    #[test]
    fn drift_must_be_finite_and_not_negative() {
        for v in [-0.1, f64::NAN, f64::INFINITY] {
            assert!(ModelStimulus::new(FvContact::default(), v, 1).is_err(), "accepted {v}");
        }
    }
}
