//! What one offline render is ([`RenderSpec`]): the run's settings with their defaults and physical ranges, and
//! the memory its results take ([`check_result_bytes`]). The run itself is [`crate::run`]; the ground truth
//! [`crate::truth`] and the metrics [`crate::summary`] read the same spec.

use thermode_device::DeviceConfig;
use thermode_model::limits::{self, CONTACT_CONDUCTANCE, DURATION, OBJECT_TEMPERATURE, TICK_RATE};
use thermode_model::{BadValue, Material, Rule, Skin};
use thermode_pipeline::pipeline::PipelineConfig;
#[cfg(doc)]
use thermode_pipeline::renderer::RendererKind;
use thermode_safety::FaultCode;

use crate::error::RenderError;

/// Default largest plant substep \[s\]: 2 ms (see the module documentation for the measured effect).
pub const PLANT_SUBSTEP_S: f64 = 0.002;
/// Default tick rate \[Hz\]: 100, the PT-100's sample rate (a faster tick sees the same held sample again).
pub const DEFAULT_RATE_HZ: f64 = 100.0;
/// Default contact duration \[s\]: 90, the paper's recordings (section 4.1).
pub const DEFAULT_DURATION_S: f64 = 90.0;
/// Default time the finger rests on the display rendering air before the touch \[s\]: 5.
pub const DEFAULT_PRE_CONTACT_S: f64 = 5.0;
/// Default seed of the sensor noise.
pub const DEFAULT_SEED: u64 = 1;
/// Longest run accepted (pre-contact plus contact) \[s\]: two hours, so that an hour of contact (the thermal-dose
/// check `--duration 3600`) fits with any pre-contact of up to an hour.
pub const MAX_RUN_S: f64 = 7200.0;
/// Estimated memory of one row of a run \[bytes\]: the [`Trajectory`](crate::trajectory::Trajectory) row (twelve numbers, the contact flag and
/// the fault) plus a figure's copy of up to four of its curves as (time, value) pairs (`--plot`).
pub const BYTES_PER_ROW: u64 = (12 * std::mem::size_of::<f64>()
    + std::mem::size_of::<bool>()
    + std::mem::size_of::<Option<FaultCode>>()
    + 4 * 2 * std::mem::size_of::<f64>()) as u64;

/// Everything one offline render needs.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderSpec {
    /// The channel pipeline (device, renderer, controller, envelope, the controller's finger model, ambient).
    pub pipeline: PipelineConfig,
    /// The simulated finger's own skin. Default [`Skin::fingertip`] (then it matches the controller's model).
    pub finger_skin: Skin,
    /// The simulated finger's skin-to-plate contact conductance [W/(m²·K)]; `None` = the device file's.
    pub finger_contact_w_m2k: Option<f64>,
    /// The simulated hardware, when it differs from the device file the pipeline believes (`pipeline.device`):
    /// real displays differ from their datasheets. Default `None`: the plant is the pipeline's device.
    pub hardware: Option<DeviceConfig>,
    /// The touched material.
    pub material: Material,
    /// Object temperature at the touch \[°C\]; `None` = the ambient temperature (the paper's objects lay in the room).
    pub object_c: Option<f64>,
    /// Recorded time after the touch \[s\]. Default [`DEFAULT_DURATION_S`].
    pub duration_s: f64,
    /// Time the finger rests on the display rendering air before the touch \[s\] (≥ 0). Default
    /// [`DEFAULT_PRE_CONTACT_S`].
    pub pre_contact_s: f64,
    /// Time after the touch at which the finger lets go \[s\]; `None` = never.
    pub release_at_s: Option<f64>,
    /// Tick rate of the pipeline \[Hz\]. Default [`DEFAULT_RATE_HZ`].
    pub rate_hz: f64,
    /// Largest plant substep \[s\]. Default [`PLANT_SUBSTEP_S`].
    pub plant_substep_s: f64,
    /// Seed of the sensor noise (combined with the material's name, see [`noise_seed`]). Default [`DEFAULT_SEED`].
    pub seed: u64,
}

impl RenderSpec {
    /// The defaults above for `pipeline` and `material`.
    pub fn new(pipeline: PipelineConfig, material: Material) -> Self {
        RenderSpec {
            pipeline,
            finger_skin: Skin::fingertip(),
            finger_contact_w_m2k: None,
            hardware: None,
            material,
            object_c: None,
            duration_s: DEFAULT_DURATION_S,
            pre_contact_s: DEFAULT_PRE_CONTACT_S,
            release_at_s: None,
            rate_hz: DEFAULT_RATE_HZ,
            plant_substep_s: PLANT_SUBSTEP_S,
            seed: DEFAULT_SEED,
        }
    }

    /// Checks every number of the run against its physical range ([`thermode_model::limits`]: object
    /// temperature, contact conductance, duration with the pre-contact time, tick rate; the pipeline, models and
    /// device check their own when built), and that the run's results fit in memory ([`RenderSpec::result_bytes`]
    /// at most [`limits::MAX_RESULT_BYTES`]), before anything is allocated.
    pub fn validate(&self) -> Result<(), RenderError> {
        self.pipeline.validate()?;
        self.finger_skin.validate("finger skin")?;
        self.material.validate(&format!("material `{}`", self.material.name))?;
        if let Some(g) = self.finger_contact_w_m2k {
            CONTACT_CONDUCTANCE
                .rule()
                .check("finger contact conductance [W/(m²·K)]", g)?;
        }
        if let Some(c) = self.object_c {
            OBJECT_TEMPERATURE.check(c)?;
        }
        Rule::Positive.check("duration [s]", self.duration_s)?;
        DURATION.check(self.duration_s)?;
        DURATION.rule().check("pre-contact time [s]", self.pre_contact_s)?;
        Rule::AtMost {
            max: MAX_RUN_S,
            what: "the longest run [s]",
        }
        .check(
            "duration [s] (with the pre-contact time)",
            self.duration_s + self.pre_contact_s,
        )?;
        if let Some(r) = self.release_at_s {
            Rule::Within {
                min: 0.0,
                max: self.duration_s,
            }
            .check("release time [s]", r)?;
        }
        TICK_RATE.check(self.rate_hz)?;
        Rule::Within { min: 1e-6, max: 0.01 }.check("plant substep [s]", self.plant_substep_s)?;
        if (self.duration_s * self.rate_hz).round() < 1.0 {
            return Err(BadValue::custom("duration [s]", self.duration_s, "must last at least one tick").into());
        }
        check_result_bytes(std::slice::from_ref(self))
    }

    /// Number of rows the run records: one per tick, before and after the touch. Meaningful for a spec whose
    /// times and tick rate are finite (saturates otherwise).
    pub fn rows(&self) -> u64 {
        let ticks = |s: f64| (s * self.rate_hz).round().max(0.0) as u64;
        ticks(self.pre_contact_s).saturating_add(ticks(self.duration_s).max(1))
    }

    /// Estimated memory of the run's results \[bytes\]: [`RenderSpec::rows`] × [`BYTES_PER_ROW`].
    pub fn result_bytes(&self) -> u64 {
        self.rows().saturating_mul(BYTES_PER_ROW)
    }

    /// The tick length \[s\].
    pub fn tick_s(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// The object temperature at the touch \[°C\].
    pub fn object_temperature_c(&self) -> f64 {
        self.object_c.unwrap_or(self.pipeline.ambient_c)
    }

    /// Ticks before the touch, ticks of contact, and the tick of the release (if any).
    pub(crate) fn tick_counts(&self) -> (usize, usize, Option<usize>) {
        let ticks = |s: f64| (s * self.rate_hz).round() as usize;
        let release = self.release_at_s.map(|r| ticks(r).max(1));
        (ticks(self.pre_contact_s), ticks(self.duration_s).max(1), release)
    }

    /// Plant substeps per tick.
    pub(crate) fn substeps(&self) -> usize {
        ((self.tick_s() / self.plant_substep_s) - 1e-9).ceil().max(1.0) as usize
    }

    /// Depth below the skin surface at which the simulated finger (`skin_c`) and the truth (`truth_skin_c`) are
    /// read \[m\]: the renderer's receptor depth in the simulated finger's own skin
    /// ([`RendererKind::receptor_depth_m`] of [`RenderSpec::finger_skin`]): half its epidermis (Kron's T1) for the
    /// kron renderer, 0 (the surface) for the fv renderer. See the module documentation.
    pub fn receptor_depth_m(&self) -> f64 {
        self.pipeline.renderer.receptor_depth_m(&self.finger_skin)
    }

    /// The pipeline as the controller believes it: [`RenderSpec::pipeline`], whose device file is exact
    /// ([`DeviceConfig::exact_for_its_simulation`]) when the plant is built from it (no [`RenderSpec::hardware`]).
    pub fn believed_pipeline(&self) -> PipelineConfig {
        let mut config = self.pipeline.clone();
        if self.hardware.is_none() {
            config.device = config.device.exact_for_its_simulation();
        }
        config
    }

    /// The device as the plant sees it: the hardware (default: the pipeline's device file) with the simulated
    /// finger's contact conductance.
    pub fn plant_device(&self) -> DeviceConfig {
        let mut device = self.hardware.unwrap_or(self.pipeline.device);
        if let Some(g) = self.finger_contact_w_m2k {
            device.plate.contact_conductance_w_m2k = g;
        }
        device
    }
}

/// `Ok` if the results of all `specs` together fit in [`limits::MAX_RESULT_BYTES`] (the sum of their
/// [`RenderSpec::result_bytes`]), else [`RenderError::TooLarge`].
pub fn check_result_bytes(specs: &[RenderSpec]) -> Result<(), RenderError> {
    let total = specs
        .iter()
        .fold(0u64, |sum, spec| sum.saturating_add(spec.result_bytes()));
    limits::check_result_bytes(total).map_err(|message| {
        let rows = specs.iter().fold(0u64, |sum, spec| sum.saturating_add(spec.rows()));
        RenderError::TooLarge(format!(
            "{} run(s) of {rows} rows in all at {BYTES_PER_ROW} bytes per row: {message}",
            specs.len()
        ))
    })
}

/// The seed of a run's sensor noise: `seed` XOR the 64-bit FNV-1a hash of the material's name. Each material gets
/// its own noise realisation (five materials rendered with one seed are five independent draws, so a tuner cannot
/// profit from one lucky realisation shared by all), and a material's run is the same alone or among others.
pub fn noise_seed(seed: u64, material: &str) -> u64 {
    let hash = material.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    });
    seed ^ hash
}
