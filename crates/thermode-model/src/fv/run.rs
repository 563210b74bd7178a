//! Contact runs: a finger resting in air touches an object at t = 0; one run on one grid ([`simulate_contact`]) or
//! refined until the answer no longer depends on the grid ([`simulate_contact_converged`]).

use super::{bad, FvConfig, FvEnvironment, FvModel};
use crate::error::{At, ParamError};
use crate::limits;
use crate::materials::Material;
use crate::params::Rule;
use crate::skin::Skin;

/// How the finger is prepared before it touches the object.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum InitialState {
    /// The steady state in air at the ambient temperature (default).
    #[default]
    SteadyInAir,
    /// Every skin cell at this temperature \[°C\].
    Uniform {
        /// Skin temperature \[°C\].
        temperature_c: f64,
    },
    /// The steady state in air at the ambient temperature with the perfusion scaled so that the resting skin surface
    /// is at `surface_c` \[°C\] (see [`FvModel::calibrate_to_surface`]).
    RestingSurface {
        /// Resting skin surface temperature \[°C\] (measured per subject in the paper).
        surface_c: f64,
    },
}

/// A contact experiment: the finger rests in air until t = 0, then touches the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactSpec {
    /// Air temperature before contact \[°C\]. Default 23 (the paper's room).
    pub ambient_c: f64,
    /// Object temperature at the moment of touch \[°C\]. Default 23.
    pub object_c: f64,
    /// The finger before contact. Default [`InitialState::SteadyInAir`].
    pub initial: InitialState,
    /// Contact duration \[s\]. Default 10.
    pub duration_s: f64,
    /// Interval between output rows \[s\]. Default 0.01. Internal steps are no longer than
    /// [`FvConfig::max_step_s`].
    pub output_dt_s: f64,
}

impl Default for ContactSpec {
    fn default() -> Self {
        ContactSpec {
            ambient_c: 23.0,
            object_c: 23.0,
            initial: InitialState::SteadyInAir,
            duration_s: 10.0,
            output_dt_s: 0.01,
        }
    }
}

impl ContactSpec {
    /// Checks the numbers against their physical ranges ([`crate::limits`]: ambient, object and initial skin
    /// temperature, duration), the output interval positive, at most 10⁷ output rows.
    pub fn validate(&self) -> Result<(), ParamError> {
        const ORIGIN: &str = "fv contact";
        limits::AMBIENT_TEMPERATURE
            .rule()
            .check("ambient_c", self.ambient_c)
            .at(ORIGIN)?;
        limits::OBJECT_TEMPERATURE
            .rule()
            .check("object_c", self.object_c)
            .at(ORIGIN)?;
        Rule::Positive.check("duration_s", self.duration_s).at(ORIGIN)?;
        limits::DURATION
            .rule()
            .check("duration_s", self.duration_s)
            .at(ORIGIN)?;
        Rule::Positive.check("output_dt_s", self.output_dt_s).at(ORIGIN)?;
        let skin = limits::SKIN_TEMPERATURE.rule();
        match self.initial {
            InitialState::SteadyInAir => {}
            InitialState::Uniform { temperature_c } => {
                skin.check("initial temperature_c", temperature_c).at(ORIGIN)?;
            }
            InitialState::RestingSurface { surface_c } => {
                skin.check("initial surface_c", surface_c).at(ORIGIN)?;
            }
        }
        if self.duration_s / self.output_dt_s > 1e7 {
            return Err(bad(
                "output_dt_s",
                self.output_dt_s,
                "gives more than 1e7 output rows for the duration",
            ));
        }
        Ok(())
    }

    /// Number of output intervals: the last one ends exactly at the duration (and may be shorter).
    fn intervals(&self) -> usize {
        (self.duration_s / self.output_dt_s - 1e-9).ceil().max(1.0) as usize
    }
}

/// The trajectory of a contact run, one row per output time (the first row is t = 0, just before the touch).
#[derive(Debug, Clone, PartialEq)]
pub struct ContactRun {
    /// Time since the touch \[s\].
    pub time_s: Vec<f64>,
    /// Skin surface temperature, what the receptors see \[°C\].
    pub surface_c: Vec<f64>,
    /// Temperature of the object's contact face \[°C\] (the object side of the contact resistance; the untouched
    /// object temperature in the row t = 0).
    pub object_face_c: Vec<f64>,
    /// Heat flux out of the skin surface [W/m²] (to the air in the row t = 0, then to the object).
    pub heat_flux_w_m2: Vec<f64>,
    /// Capacity-weighted mean temperature of every skin layer \[°C\]: `layer_mean_c[row][layer]`.
    pub layer_mean_c: Vec<Vec<f64>>,
    /// The perfusion scale used (1 unless calibrated to a resting surface temperature).
    pub perfusion_scale: f64,
    /// Number of skin cells.
    pub skin_cells: usize,
    /// Number of object cells.
    pub object_cells: usize,
    /// Largest internal time step \[s\].
    pub step_s: f64,
}

impl ContactRun {
    fn record(&mut self, model: &FvModel, time_s: f64, object_face_c: f64) {
        self.time_s.push(time_s);
        self.surface_c.push(model.surface_c());
        self.object_face_c.push(object_face_c);
        self.heat_flux_w_m2.push(model.surface_heat_flux_w_m2());
        self.layer_mean_c.push(model.layer_means_c());
    }
}

/// Runs one contact on the grid and time step of `config`: the finger prepared as `spec.initial` in air at
/// `spec.ambient_c`, then touching `object` (a slab of its `thickness_m`, starting at `spec.object_c`) for
/// `spec.duration_s`.
pub fn simulate_contact(
    skin: &Skin,
    object: &Material,
    config: &FvConfig,
    spec: &ContactSpec,
) -> Result<ContactRun, ParamError> {
    spec.validate()?;
    let mut model = FvModel::new(skin, Some(object), config)?;
    let air = FvEnvironment::Air {
        ambient_c: spec.ambient_c,
    };
    match spec.initial {
        InitialState::SteadyInAir => model.set_steady(air)?,
        InitialState::Uniform { temperature_c } => {
            model.set_skin_uniform(temperature_c)?;
            model.set_environment(air)?;
        }
        InitialState::RestingSurface { surface_c } => {
            model.calibrate_to_surface(spec.ambient_c, surface_c)?;
        }
    }
    let intervals = spec.intervals();
    let mut run = ContactRun {
        time_s: Vec::with_capacity(intervals + 1),
        surface_c: Vec::with_capacity(intervals + 1),
        object_face_c: Vec::with_capacity(intervals + 1),
        heat_flux_w_m2: Vec::with_capacity(intervals + 1),
        layer_mean_c: Vec::with_capacity(intervals + 1),
        perfusion_scale: model.perfusion_scale(),
        skin_cells: model.skin_cells(),
        object_cells: model.object_cells(),
        step_s: 0.0,
    };
    run.record(&model, 0.0, spec.object_c);
    model.touch(spec.object_c)?;
    let mut previous_s = 0.0;
    for k in 1..=intervals {
        let time_s = (k as f64 * spec.output_dt_s).min(spec.duration_s);
        let interval_s = time_s - previous_s;
        let steps = (interval_s / config.max_step_s - 1e-9).ceil().max(1.0) as usize;
        let h = interval_s / steps as f64;
        run.step_s = run.step_s.max(h);
        for _ in 0..steps {
            model.step(h, FvEnvironment::Object);
        }
        let face = model.object_face_c().unwrap_or(spec.object_c);
        run.record(&model, time_s, face);
        previous_s = time_s;
    }
    Ok(run)
}

/// When [`simulate_contact_converged`] stops refining.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refinement {
    /// Largest change of the surface temperature trajectory between two successive refinements that counts as
    /// converged \[°C\]. Default 0.005.
    pub tolerance_c: f64,
    /// Most refinements after the first run (each doubles the cells and halves the step, so costs about four times
    /// the previous run). Default 5.
    pub max_refinements: u32,
}

impl Default for Refinement {
    fn default() -> Self {
        Refinement {
            tolerance_c: 0.005,
            max_refinements: 5,
        }
    }
}

/// The resolution a converged run used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resolution {
    /// Number of refinements of the starting configuration ([`FvConfig::refined`]).
    pub refinements: u32,
    /// Number of skin cells.
    pub skin_cells: usize,
    /// Number of object cells.
    pub object_cells: usize,
    /// Width of the surface cells \[m\].
    pub surface_cell_m: f64,
    /// Largest internal time step \[s\].
    pub step_s: f64,
    /// Largest change of the surface temperature trajectory against the previous, coarser run \[°C\].
    pub max_change_c: f64,
    /// Whether `max_change_c` is below the tolerance (false when the refinement cap was reached first).
    pub converged: bool,
}

/// Runs [`simulate_contact`] on `config`, then again refined (×2 cells, ½ step) until the largest change of the
/// surface temperature trajectory is below `refinement.tolerance_c` or `refinement.max_refinements` is reached.
/// Returns the finest run and the resolution used; check [`Resolution::converged`].
pub fn simulate_contact_converged(
    skin: &Skin,
    object: &Material,
    config: &FvConfig,
    spec: &ContactSpec,
    refinement: &Refinement,
) -> Result<(ContactRun, Resolution), ParamError> {
    Rule::Positive
        .check("tolerance_c", refinement.tolerance_c)
        .at("fv refinement")?;
    if refinement.max_refinements == 0 {
        return Err(bad("max_refinements", 0.0, "must be at least 1"));
    }
    let mut previous = simulate_contact(skin, object, config, spec)?;
    let mut level = 1;
    loop {
        let finer_config = config.refined(level);
        let run = simulate_contact(skin, object, &finer_config, spec)?;
        let change = max_difference(&previous.surface_c, &run.surface_c);
        let converged = change < refinement.tolerance_c;
        if converged || level == refinement.max_refinements {
            let resolution = Resolution {
                refinements: level,
                skin_cells: run.skin_cells,
                object_cells: run.object_cells,
                surface_cell_m: finer_config.surface_cell_m,
                step_s: run.step_s,
                max_change_c: change,
                converged,
            };
            return Ok((run, resolution));
        }
        previous = run;
        level += 1;
    }
}

/// Largest absolute difference of two equally long series (NaN anywhere gives NaN, never "converged").
fn max_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, |m, d| if d.is_nan() || m.is_nan() { f64::NAN } else { m.max(d) })
}
