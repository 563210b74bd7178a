//! Contact runs: a finger resting in air touches an object at t = 0; one run on one grid ([`simulate_contact`]) or
//! refined until the answer no longer depends on the grid ([`simulate_contact_converged`]).

use super::adaptive::{self, RowAt, StepCounts};
use super::model::StepEnds;
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
    /// Interval between output rows \[s\]. Default 0.01. With fixed steps every interval is split into equal
    /// steps no longer than [`FvConfig::max_step_s`]; adaptive steps ignore it (rows are interpolated).
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
        limits::check_touch_temperatures(ORIGIN, self.ambient_c, self.object_c)?;
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
    /// Internal steps taken and rejected (none rejected with fixed steps).
    pub steps: StepCounts,
    /// Eliminations (factorisations) of the step matrix during the contact ([`FvModel::factorisations`]).
    pub factorisations: usize,
}

impl ContactRun {
    /// Records the row `at` in the last step from the step's end values `ends`.
    fn record_interpolated(&mut self, model: &FvModel, ends: &StepEnds, at: RowAt) {
        let (theta, step_s, time_s) = (at.theta, at.step_s, at.time_s);
        let (skin0, object0) = (ends.skin0.at(theta, step_s), ends.object0.at(theta, step_s));
        let (surface_c, face_c, flux_w_m2) = model.contact_observables(skin0, object0);
        self.time_s.push(time_s);
        self.surface_c.push(surface_c);
        self.object_face_c.push(face_c);
        self.heat_flux_w_m2.push(flux_w_m2);
        let means = ends
            .layer_heat
            .iter()
            .zip(&ends.layer_capacity)
            .map(|(heat, capacity)| heat.at(theta, step_s) / capacity)
            .collect();
        self.layer_mean_c.push(means);
    }

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
        steps: StepCounts::default(),
        factorisations: 0,
    };
    run.record(&model, 0.0, spec.object_c);
    model.touch(spec.object_c)?;
    let before = model.factorisations();
    match config.tolerance_c {
        Some(tolerance_c) => run_adaptive(&mut model, spec, tolerance_c, &mut run)?,
        None => run_fixed(&mut model, spec, config.max_step_s, &mut run),
    }
    run.factorisations = model.factorisations() - before;
    Ok(run)
}

/// The output time of row `k` (k ≥ 1) \[s\]: `k·output_dt_s`, the last one exactly the duration.
fn row_time_s(spec: &ContactSpec, k: usize, intervals: usize) -> f64 {
    if k == intervals {
        spec.duration_s
    } else {
        k as f64 * spec.output_dt_s
    }
}

/// Fixed steps: every output interval split into equal steps of at most `max_step_s`. Every full interval has the
/// same step, bit for bit (computed from the output interval, not from a difference of output times), so the
/// cached elimination is reused; only a shorter last interval changes it.
fn run_fixed(model: &mut FvModel, spec: &ContactSpec, max_step_s: f64, run: &mut ContactRun) {
    let intervals = spec.intervals();
    let mut previous_s = 0.0;
    for k in 1..=intervals {
        let time_s = row_time_s(spec, k, intervals);
        let interval_s = interval_length_s(spec, k, intervals, previous_s);
        let steps = (interval_s / max_step_s - 1e-9).ceil().max(1.0) as usize;
        let h = interval_s / steps as f64;
        run.step_s = run.step_s.max(h);
        for _ in 0..steps {
            model.step(h, FvEnvironment::Object);
        }
        run.steps.accepted += steps;
        let face = model.object_face_c().unwrap_or(spec.object_c);
        run.record(model, time_s, face);
        previous_s = time_s;
    }
}

/// The length of output interval `k` of `intervals` \[s\], starting at `previous_s`: the output interval itself,
/// bit for bit, unless it is the last one and the duration is not a whole number of output intervals (to 1e-9
/// relative), when it is what is left of the duration.
fn interval_length_s(spec: &ContactSpec, k: usize, intervals: usize, previous_s: f64) -> f64 {
    let left_s = spec.duration_s - previous_s;
    if k < intervals || (left_s - spec.output_dt_s).abs() <= 1e-9 * spec.output_dt_s {
        spec.output_dt_s
    } else {
        left_s
    }
}

/// Adaptive steps ([`super::adaptive`]), rows interpolated between them. Every recorded quantity is linear in the
/// state, so the rows interpolate the quantities themselves (cubic Hermite from their values and rates at both ends
/// of the step, [`FvModel::last_step_ends`], gathered once per step): O(layers) per row, O(cells) per step.
fn run_adaptive(
    model: &mut FvModel,
    spec: &ContactSpec,
    tolerance_c: f64,
    run: &mut ContactRun,
) -> Result<(), ParamError> {
    let intervals = spec.intervals();
    let mut times = (1..=intervals).map(|k| row_time_s(spec, k, intervals));
    let mut ends = StepEnds::new(model.layer_count());
    let mut gathered_step = 0;
    let mut record = |model: &FvModel, at: RowAt| {
        if at.step != gathered_step {
            model.last_step_ends(&mut ends);
            gathered_step = at.step;
        }
        run.record_interpolated(model, &ends, at);
    };
    let (counts, largest_s) = adaptive::integrate(
        model,
        FvEnvironment::Object,
        (0.0, spec.duration_s),
        tolerance_c,
        &mut times,
        &mut record,
    )?;
    run.steps = counts;
    run.step_s = largest_s;
    Ok(())
}

/// When [`simulate_contact_converged`] stops refining.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refinement {
    /// Largest change of the surface temperature trajectory between two successive refinements that counts as
    /// converged \[°C\]. Default 0.005.
    pub tolerance_c: f64,
    /// Most refinements after the first run (each doubles the cells, so with adaptive steps costs about twice the
    /// previous run; with fixed steps it also halves the step, about four times). Default 5.
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

/// Runs [`simulate_contact`] on `config` and refined once (×2 cells), then on finer pairs of neighbouring levels
/// until the largest change of the surface temperature trajectory between the two finest runs is below
/// `refinement.tolerance_c` or `refinement.max_refinements` is reached. Returns the finest run and the resolution
/// used; check [`Resolution::converged`].
///
/// Levels that cannot converge are not run: the change falls by a factor per level (observed from the last two
/// changes, else 4 for the second-order grid, held to between 2 and 16), so when that predicts that the next level
/// still misses the tolerance the refinement jumps ahead to the predicted pair of neighbouring levels, skipping the
/// levels in between (each level costs about twice the one before, so this saves most of the work of a sequential
/// search when the start is coarse).
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
    let run_at = |level: u32| simulate_contact(skin, object, &config.refined(level), spec);
    let mut previous = run_at(0)?;
    let mut level = 1;
    let mut last_change: Option<f64> = None;
    loop {
        let run = run_at(level)?;
        let change = max_difference(&previous.surface_c, &run.surface_c);
        let converged = change < refinement.tolerance_c;
        if converged || level == refinement.max_refinements {
            let resolution = Resolution {
                refinements: level,
                skin_cells: run.skin_cells,
                object_cells: run.object_cells,
                surface_cell_m: config.refined(level).surface_cell_m,
                step_s: run.step_s,
                max_change_c: change,
                converged,
            };
            return Ok((run, resolution));
        }
        let ahead = levels_ahead(change, last_change, refinement.tolerance_c);
        let next = (level + ahead).min(refinement.max_refinements);
        // At most two runs are held at once (what `SimulationSpec::result_bytes` budgets for).
        if next == level + 1 {
            previous = run;
        } else {
            drop(run);
            previous = run_at(next - 1)?;
        }
        last_change = if next == level + 1 { Some(change) } else { None };
        level = next;
    }
}

/// How many levels finer the next convergence check should be, from the change between the last two levels
/// \[°C\], the change before it (if the levels were neighbours) and the tolerance \[°C\]: the smallest number of
/// levels after which the change, falling by the observed (or second-order) ratio per level, is predicted below
/// the tolerance; at least 1. A NaN change gives 1.
fn levels_ahead(change: f64, last_change: Option<f64>, tolerance_c: f64) -> u32 {
    let ratio = last_change.map_or(4.0, |last| (last / change).clamp(2.0, 16.0));
    let ratio = if ratio.is_nan() { 4.0 } else { ratio };
    let needed = ((change / tolerance_c).ln() / ratio.ln()).ceil();
    if needed.is_finite() && needed > 1.0 {
        needed.min(8.0) as u32
    } else {
        1
    }
}

/// Largest absolute difference of two equally long series (NaN anywhere gives NaN, never "converged").
fn max_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, |m, d| if d.is_nan() || m.is_nan() { f64::NAN } else { m.max(d) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_ahead_jumps_only_when_the_next_level_cannot_converge() {
        // Change 0.004 < 4 × 0.005: the next level is predicted to converge.
        assert_eq!(levels_ahead(0.016, None, 0.005), 1);
        // 0.32 needs 64× less: three levels at the second-order ratio 4.
        assert_eq!(levels_ahead(0.32, None, 0.005), 3);
        // An observed ratio of 2 (first order) needs six.
        assert_eq!(levels_ahead(0.32, Some(0.64), 0.005), 6);
        assert_eq!(levels_ahead(f64::NAN, Some(0.1), 0.005), 1);
        assert_eq!(levels_ahead(1e9, None, 0.005), 8, "capped");
    }

    #[test]
    fn last_interval_is_the_output_interval_unless_the_duration_is_not_a_multiple() {
        let spec = ContactSpec {
            duration_s: 0.5,
            output_dt_s: 0.01,
            ..ContactSpec::default()
        };
        let intervals = spec.intervals();
        assert_eq!(intervals, 50);
        let previous_s = 49.0 * 0.01;
        assert_eq!(
            interval_length_s(&spec, intervals, intervals, previous_s).to_bits(),
            0.01f64.to_bits()
        );
        let spec = ContactSpec {
            duration_s: 0.505,
            ..spec
        };
        let last = interval_length_s(&spec, spec.intervals(), spec.intervals(), 0.5);
        assert!((last - 0.005).abs() < 1e-12, "last interval {last}");
    }
}
