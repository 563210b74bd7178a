//! Offline rendering against the simulated display, as `thermode render` runs it: one channel pipeline drives a
//! [`SimulatedDisplay`] with a simulated finger resting on it, next to the ground truth (that finger touching the
//! real material), and every tick is recorded.
//!
//! # The run
//! - The simulated finger ([`RenderSpec::finger_skin`], default the fingertip) is the finite-volume finger — the
//!   reference physics — resting on the plate; its contact conductance is the device file's unless
//!   [`RenderSpec::finger_contact_w_m2k`] overrides it (real fingers press differently than the model assumes).
//! - Before the run the finger is at its steady state in still air and the plate at the temperature that draws
//!   exactly the heat still air would (`receptor − q_air/G`): the display has been rendering air when the finger is
//!   put on it. The hot side starts at the water temperature. The plant is then stepped one sensor sample period at
//!   0 A so that the first reading is a fresh sample of that state (otherwise the envelope would see the plate jump
//!   from the water temperature, an implausible rate).
//! - The display renders air for [`RenderSpec::pre_contact_s`], the finger touches the object at t = 0 and lets go
//!   at [`RenderSpec::release_at_s`] if given. One tick every 1/[`RenderSpec::rate_hz`] s.
//! - After each tick the plant is advanced by the tick in equal substeps of at most [`RenderSpec::plant_substep_s`]
//!   (default [`PLANT_SUBSTEP_S`]), the gated drive held. The plant's backward Euler is first order; 2 ms keeps its
//!   error below half the sensor's 0.01 °C resolution (test `plant_substep_convergence` in
//!   `tests/integration/run.rs`; figures in `docs/design-choices.md`).
//! - Truth: the simulated finger touching the real material under the reference fv physics, converged in grid and
//!   time to 0.005 °C at every row, its contact resistance 1/G with G the simulated finger's contact conductance
//!   (see [`crate::truth`]). The renderer's target is the same physics on the renderer's coarse grid, one step per
//!   tick, with the light-touch resistance [`LIGHT_TOUCH_RESISTANCE_M2K_W`]: with the default finger and display
//!   they differ only by the renderer's discretisation (a few hundredths of a °C at the first rows after a touch;
//!   the pipeline's calibration at the touch, [`PipelineConfig::calibrate_finger_at_touch`], leaves a finger that
//!   matches the model as it is; a different finger gets a target computed for it, while the truth is that
//!   finger's own contact).
//! - Receptor depth: the target is the renderer's receptor — the skin surface for the fv renderer, the epidermis
//!   centre T1 (depth Δx₁/2) for the kron renderer — so the simulated finger on the display (`skin_c`) and the
//!   truth (`truth_skin_c`) are read at that same depth ([`RenderSpec::receptor_depth_m`]): at the surface for fv
//!   (the finger's receptor, bit for bit as before), and for kron at half the first layer of the *simulated
//!   finger's* skin ([`RenderSpec::finger_skin`]), interpolated between its finite-volume cells
//!   ([`FvModel::skin_temperature_at_depth_c`]). It is that skin's because the receptor is a place in the real
//!   finger (its own epidermis centre), and the truth is the same finger; with the default finger it is the
//!   renderer's own Δx₁/2. Comparing Kron's T1 with a surface temperature would count the gradient across half
//!   the epidermis as error (on aluminium several °C at the touch). The kron target remains Kron's model: what is
//!   left of truth − target is its known limit (an object held at its temperature, without heat capacity).
//! - Rows are recorded after each tick and plant step: `time_s` is the end of the tick's interval relative to the
//!   contact (0 at contact, negative before); temperatures are those at that time; current and set-point are those
//!   held over the interval.
//!
//! Deterministic: the only randomness is the sensor noise, seeded by [`RenderSpec::seed`] and the material's name
//! ([`noise_seed`]).

use std::io::Write;

use thermode_device::{Device, DeviceConfig, PlateFinger, SimulatedChannel, SimulatedDisplay};
use thermode_model::fv::{FvConfig, FvModel};
use thermode_model::{BadValue, Material, Skin};
pub use thermode_platform::csv_text::Precision;
use thermode_platform::csv_text::{self, CsvText};
use thermode_safety::FaultCode;

use thermode_model::limits::{self, CONTACT_CONDUCTANCE, DURATION, OBJECT_TEMPERATURE, TICK_RATE};
use thermode_model::Rule;

use crate::error::RenderError;
use crate::summary::{actuator_limit, summarise, Summary};
use crate::truth::truth_skin_c;
use thermode_pipeline::pipeline::{ChannelPipeline, PipelineConfig, Telemetry};
use thermode_pipeline::renderer::{fv_config, Renderer, RendererKind, LIGHT_TOUCH_RESISTANCE_M2K_W};
use thermode_pipeline::stimulus::Stimulus;

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
/// Estimated memory of one row of a run \[bytes\]: the [`Trajectory`] row (twelve numbers, the contact flag and
/// the fault) plus a figure's copy of up to four of its curves as (time, value) pairs (`--plot`).
pub const BYTES_PER_ROW: u64 = (12 * std::mem::size_of::<f64>()
    + std::mem::size_of::<bool>()
    + std::mem::size_of::<Option<FaultCode>>()
    + 4 * 2 * std::mem::size_of::<f64>()) as u64;

/// The simulated display of a run: one channel with the finite-volume finger.
pub type Plant = SimulatedDisplay<FvModel>;

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

/// One column per recorded quantity, one row per tick.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trajectory {
    /// Time since the touch at the end of the tick \[s\] (0 at contact, negative before).
    pub time_s: Vec<f64>,
    /// Ground truth: the simulated finger touching the real material, at the receptor depth
    /// ([`RenderSpec::receptor_depth_m`]: surface for fv, epidermis centre for kron) \[°C\].
    pub truth_skin_c: Vec<f64>,
    /// The renderer's target: its receptor (fv: the skin surface; kron: T1, the epidermis centre) \[°C\].
    pub target_skin_c: Vec<f64>,
    /// The simulated finger on the display at the receptor depth ([`RenderSpec::receptor_depth_m`]: surface for
    /// fv, epidermis centre for kron) \[°C\].
    pub skin_c: Vec<f64>,
    /// The pipeline's finger model on the display (what it believes the finger feels) \[°C\].
    pub model_skin_c: Vec<f64>,
    /// The set-point the inverse asked for, before the envelope \[°C\].
    pub requested_setpoint_c: Vec<f64>,
    /// The set-point after the envelope \[°C\].
    pub display_setpoint_c: Vec<f64>,
    /// The true plate temperature \[°C\].
    pub display_c: Vec<f64>,
    /// The PT-100 reading \[°C\].
    pub sensor_c: Vec<f64>,
    /// The safety envelope's estimate of the true plate (`display_c`) from the reading \[°C\].
    pub plate_estimate_c: Vec<f64>,
    /// The gated drive current \[A\].
    pub current_a: Vec<f64>,
    /// The true hot-side temperature \[°C\].
    pub hot_side_c: Vec<f64>,
    /// Whether the rendered finger touched the object.
    pub contact: Vec<bool>,
    /// The latched fault, if any.
    pub fault: Vec<Option<FaultCode>>,
}

impl Trajectory {
    fn with_capacity(rows: usize) -> Self {
        let v = || Vec::with_capacity(rows);
        Trajectory {
            time_s: v(),
            truth_skin_c: v(),
            target_skin_c: v(),
            skin_c: v(),
            model_skin_c: v(),
            requested_setpoint_c: v(),
            display_setpoint_c: v(),
            display_c: v(),
            sensor_c: v(),
            plate_estimate_c: v(),
            current_a: v(),
            hot_side_c: v(),
            contact: Vec::with_capacity(rows),
            fault: Vec::with_capacity(rows),
        }
    }

    /// The numeric columns with their CSV names, in CSV order.
    pub fn numbers(&self) -> impl Iterator<Item = (&'static str, &[f64])> {
        [
            ("time_s", &self.time_s),
            ("truth_skin_c", &self.truth_skin_c),
            ("target_skin_c", &self.target_skin_c),
            ("skin_c", &self.skin_c),
            ("model_skin_c", &self.model_skin_c),
            ("display_setpoint_c", &self.display_setpoint_c),
            ("requested_setpoint_c", &self.requested_setpoint_c),
            ("display_c", &self.display_c),
            ("sensor_c", &self.sensor_c),
            ("plate_estimate_c", &self.plate_estimate_c),
            ("current_a", &self.current_a),
            ("hot_side_c", &self.hot_side_c),
        ]
        .into_iter()
        .map(|(name, column)| (name, column.as_slice()))
    }

    /// The first numeric column (in CSV order) holding a number that is not finite, with the row of its first
    /// such number; `None` if every number is finite.
    pub fn first_non_finite(&self) -> Option<(&'static str, usize)> {
        self.numbers()
            .find_map(|(name, column)| column.iter().position(|v| !v.is_finite()).map(|row| (name, row)))
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    fn record(&mut self, time_s: f64, truth_c: f64, telemetry: &Telemetry, plant: &Plant, depth_m: f64) {
        let Ok(channel) = plant.channel(0) else {
            return;
        };
        let state = channel.state();
        self.time_s.push(time_s);
        self.truth_skin_c.push(truth_c);
        self.target_skin_c.push(telemetry.target_skin_c);
        self.skin_c.push(finger_at_depth_c(channel, depth_m));
        self.model_skin_c.push(telemetry.skin_c);
        self.requested_setpoint_c.push(telemetry.requested_setpoint_c);
        self.display_setpoint_c.push(telemetry.display_setpoint_c);
        self.display_c.push(state.plate_c);
        self.sensor_c.push(state.sensor.value_c);
        self.plate_estimate_c.push(telemetry.plate_estimate_c);
        self.current_a.push(state.applied_current_a);
        self.hot_side_c.push(state.hot_side_c);
        self.contact.push(telemetry.contact);
        self.fault.push(telemetry.fault);
    }
}

/// The state at the moment of touch.
#[derive(Debug, Clone)]
pub struct ContactState {
    /// The renderer's target at the touch \[°C\] (T0 of the lag).
    pub target_c: f64,
    /// The simulated finger at the receptor depth at the touch \[°C\] ([`RenderSpec::receptor_depth_m`]).
    pub skin_c: f64,
    /// The plant at the touch (for the actuator-limit run).
    pub plant: Plant,
}

/// One offline render: its spec, its trajectory and its summary.
#[derive(Debug, Clone)]
pub struct RenderRun {
    /// What was run.
    pub spec: RenderSpec,
    /// Every tick.
    pub trajectory: Trajectory,
    /// The metrics of the paper's Figure 3.
    pub summary: Summary,
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

/// The simulated display of `spec` at rest: the finger steady in air, the plate at the air-rendering temperature,
/// the hot side at the water temperature, one sample period stepped at 0 A (see the module documentation).
pub fn resting_plant(spec: &RenderSpec) -> Result<Plant, RenderError> {
    let device = spec.plant_device();
    let mut finger = FvModel::new(&spec.finger_skin, None, &FvConfig::default())?;
    finger.set_steady_in_air(spec.pipeline.ambient_c)?;
    let contact = device.plate.contact_conductance_w_m2k;
    let plate_c = finger.surface_c() - finger.surface_heat_flux_w_m2() / contact;
    let mut plant = SimulatedDisplay::new(&device, vec![finger], noise_seed(spec.seed, &spec.material.name))?;
    plant
        .channel_mut(0)?
        .set_temperatures(plate_c, device.ambient.water_c)?;
    plant.advance(1.0 / device.sensor.sample_rate_hz);
    Ok(plant)
}

/// A live fv renderer of the simulated finger's skin with the light-touch contact resistance on the default grid,
/// at rest in air: the ground truth before it was converged (stepped once per tick on the coarse grid, 0.02–0.09 °C
/// off at the first rows after a touch). Runs now use [`truth_skin_c`].
pub fn truth_renderer(spec: &RenderSpec) -> Result<Renderer, RenderError> {
    let grid = fv_config(LIGHT_TOUCH_RESISTANCE_M2K_W);
    Ok(Renderer::new(
        RendererKind::Fv,
        &spec.finger_skin,
        spec.pipeline.ambient_c,
        &grid,
    )?)
}

/// Runs `spec` with the controller its pipeline names.
pub fn render(spec: &RenderSpec) -> Result<RenderRun, RenderError> {
    spec.validate()?;
    let pipeline = ChannelPipeline::new(&spec.believed_pipeline())?;
    render_with(spec, pipeline)
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

/// Runs every spec, in parallel threads (one per spec); results in the order of `specs`. The first error is
/// returned. Work whose results would not fit in memory together ([`check_result_bytes`]) is refused before any
/// run starts.
pub fn render_all(specs: &[RenderSpec]) -> Result<Vec<RenderRun>, RenderError> {
    check_result_bytes(specs)?;
    std::thread::scope(|scope| {
        let handles: Vec<_> = specs.iter().map(|spec| scope.spawn(move || render(spec))).collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(RenderError::Invalid("a render thread panicked".into())))
            })
            .collect()
    })
}

/// Runs `spec` with a pipeline of the caller's (e.g. with a custom controller). A run that records a number that
/// is not finite is refused ([`RenderError::NonFinite`], see [`Trajectory::first_non_finite`]).
pub fn render_with(spec: &RenderSpec, mut pipeline: ChannelPipeline) -> Result<RenderRun, RenderError> {
    spec.validate()?;
    let mut plant = resting_plant(spec)?;
    let (truth, _) = truth_skin_c(spec)?;
    let (pre, contact_ticks, release) = spec.tick_counts();
    let dt = spec.tick_s();
    let depth_m = spec.receptor_depth_m();
    let start_s = plant.time_s();
    let mut trajectory = Trajectory::with_capacity(pre + contact_ticks);
    let mut at_contact = None;
    let touch = Stimulus::Touch {
        material: spec.material.clone(),
        object_c: spec.object_temperature_c(),
    };
    for (k, &truth_c) in truth.iter().enumerate().take(pre + contact_ticks) {
        if k == pre {
            pipeline.set_stimulus(touch.clone())?;
            at_contact = Some(ContactState {
                target_c: pipeline.renderer().receptor_c(),
                skin_c: finger_at_depth_c(plant.channel(0)?, depth_m),
                plant: plant.clone(),
            });
        }
        if release.is_some_and(|r| k == pre + r) {
            pipeline.set_stimulus(Stimulus::Air)?;
        }
        let telemetry = tick(&mut pipeline, &mut plant, start_s + k as f64 * dt, dt, spec.substeps())?;
        let time_s = (k + 1) as f64 * dt - pre as f64 * dt;
        trajectory.record(time_s, truth_c, &telemetry, &plant, depth_m);
    }
    let contact = at_contact.ok_or_else(|| RenderError::Invalid("the run never reached the touch".into()))?;
    if let Some((quantity, row)) = trajectory.first_non_finite() {
        let column = trajectory.numbers().find(|(name, _)| *name == quantity).map(|(_, c)| c);
        return Err(RenderError::NonFinite {
            material: spec.material.name.clone(),
            controller: pipeline.controller().name().to_string(),
            quantity,
            value: column.map_or(f64::NAN, |c| c[row]),
            time_s: trajectory.time_s[row],
        });
    }
    let limit = actuator_limit(spec, &trajectory, &contact)?;
    let summary = summarise(spec, pipeline.controller().name(), &trajectory, &contact, limit);
    Ok(RenderRun {
        spec: spec.clone(),
        trajectory,
        summary,
    })
}

/// The simulated finger's skin at `depth_m` \[m\] below its surface \[°C\]: its receptor (the surface) at depth 0
/// — exactly the channel state's `receptor_c` — otherwise [`PlateFinger::temperature_at_depth_c`].
pub fn finger_at_depth_c(channel: &SimulatedChannel<FvModel>, depth_m: f64) -> f64 {
    if depth_m == 0.0 {
        channel.state().receptor_c
    } else {
        channel.finger().temperature_at_depth_c(depth_m)
    }
}

/// One tick of the pipeline on the plant's newest reading, then the plant advanced by `dt` in `substeps` equal
/// substeps with the gated drive.
pub fn tick(
    pipeline: &mut ChannelPipeline,
    plant: &mut Plant,
    now_s: f64,
    dt: f64,
    substeps: usize,
) -> Result<Telemetry, RenderError> {
    let reading = plant.read(0)?;
    let (drive, telemetry) = pipeline.tick(now_s, dt, &reading);
    plant.apply(0, &drive)?;
    let h = dt / substeps as f64;
    for _ in 0..substeps {
        plant.advance(h);
    }
    Ok(telemetry)
}

/// The CSV columns, in order.
pub const CSV_HEADER: [&str; 18] = [
    "time_s",
    "truth_skin_c",
    "target_skin_c",
    "skin_c",
    "model_skin_c",
    "display_setpoint_c",
    "requested_setpoint_c",
    "display_c",
    "sensor_c",
    "plate_estimate_c",
    "current_a",
    "hot_side_c",
    "contact",
    "fault",
    "material",
    "controller",
    "renderer",
    "fault_description",
];

/// Writes the runs as one CSV (header first, then every run's rows in order). `time_s` in Rust's shortest
/// round-trip form, the other numbers as `precision` says; `fault` is the numeric fault code (empty without fault); `contact` is 0 or 1.
/// The columns are the [`Trajectory`] fields of the same names. `target_skin_c` is the renderer's receptor, and
/// `skin_c` (the simulated finger on the display) and `truth_skin_c` (that finger touching the real material) are
/// read at the same depth: the skin surface with `renderer` = `fv`, the centre of the finger's epidermis (Kron's
/// T1, depth Δx₁/2) with `renderer` = `kron` ([`RenderSpec::receptor_depth_m`]). `model_skin_c` is the
/// pipeline's own display-finger model at its receptor (the same node as the target).
pub fn write_csv(runs: &[RenderRun], precision: Precision, sink: &mut dyn Write) -> Result<(), csv::Error> {
    sink.write_all(format!("{}\n", CSV_HEADER.join(",")).as_bytes())?;
    for run in runs {
        let t = &run.trajectory;
        let mut run_fields = CsvText::new();
        for text in [
            run.spec.material.name.as_str(),
            run.summary.controller.as_str(),
            run.spec.pipeline.renderer.name(),
        ] {
            run_fields.push_byte(b',');
            run_fields.push_field(text);
        }
        run_fields.push_byte(b',');
        csv_text::write_rows(sink, t.len(), |rows, out| {
            for row in rows {
                out.push_f64(t.time_s[row]);
                out.push_byte(b',');
                for column in [
                    &t.truth_skin_c,
                    &t.target_skin_c,
                    &t.skin_c,
                    &t.model_skin_c,
                    &t.display_setpoint_c,
                    &t.requested_setpoint_c,
                    &t.display_c,
                    &t.sensor_c,
                    &t.plate_estimate_c,
                    &t.current_a,
                    &t.hot_side_c,
                ] {
                    out.push_number(column[row], precision);
                    out.push_byte(b',');
                }
                out.push_byte(if t.contact[row] { b'1' } else { b'0' });
                out.push_byte(b',');
                if let Some(fault) = t.fault[row] {
                    out.push_bytes(fault.code().to_string().as_bytes());
                }
                out.push_bytes(run_fields.as_bytes());
                if let Some(fault) = t.fault[row] {
                    out.push_field(fault.description());
                }
                out.push_byte(b'\n');
            }
        })?;
    }
    sink.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_non_finite_number_is_found_in_csv_order() {
        let mut t = Trajectory::with_capacity(3);
        for (k, time_s) in [-0.01, 0.0, 0.01].into_iter().enumerate() {
            t.time_s.push(time_s);
            for column in [
                &mut t.truth_skin_c,
                &mut t.target_skin_c,
                &mut t.skin_c,
                &mut t.model_skin_c,
                &mut t.requested_setpoint_c,
                &mut t.display_setpoint_c,
                &mut t.display_c,
                &mut t.sensor_c,
                &mut t.plate_estimate_c,
                &mut t.current_a,
                &mut t.hot_side_c,
            ] {
                column.push(30.0 + k as f64);
            }
            t.contact.push(k > 0);
            t.fault.push(None);
        }
        assert_eq!(t.first_non_finite(), None);
        t.hot_side_c[1] = f64::INFINITY;
        t.skin_c[2] = f64::NAN;
        assert_eq!(t.first_non_finite(), Some(("skin_c", 2)));
        let names: Vec<&str> = t.numbers().map(|(name, _)| name).collect();
        assert_eq!(names, CSV_HEADER[..12].to_vec(), "numeric columns in CSV order");
    }
}
