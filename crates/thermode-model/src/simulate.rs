//! One complete contact simulation, as `thermode simulate` runs it: a finger rests in air until t = 0, then touches
//! an object; the chosen model gives the skin temperature the receptors see, and (for kron and fv) the display
//! inverse gives the display set-point that would make a finger resting on the display feel the same.
//!
//! - `kron`: the paper's three-layer model; the receptor temperature is T1 (epidermis centre). Backward Euler with
//!   the step `dt_s`.
//! - `fv`: the finite-volume reference, refined automatically until the surface trajectory changes by less than
//!   0.005 °C; the receptor temperature is the skin surface. Default contact resistance 1e-3 m²K/W (light touch).
//! - `semi-infinite`: the paper's model (a), analytic. The skin is homogeneous with the properties of the skin's
//!   outermost layer; its initial temperature is the resting surface temperature of the finite-volume finger (or the
//!   given one). Default contact resistance 0 (perfect contact, as model (a) assumes).
//!
//! The display set-point is unlimited here (no safety envelope acts in a pure simulation): it is eq. 7 as it is.

use std::str::FromStr;

use crate::error::{At, ParamError};
use crate::fv::{self, FvConfig, FvEnvironment, FvModel, InitialState};
use crate::inverse::{DisplayInverse, DEFAULT_DISPLAY_CONDUCTANCE_W_M2K};
use crate::kron::{self, KronEnvironment, KronModel};
use crate::limits;
use crate::materials::Material;
use crate::params::Rule;
use crate::semi_infinite;
use crate::skin::Skin;

const ORIGIN: &str = "simulation";

/// Default contact resistance of the fv model [m²K/W]: a light touch (`model.md` §3; the paper's participants
/// touched "without exerting pressure").
pub const FV_DEFAULT_CONTACT_RESISTANCE_M2K_W: f64 = 1e-3;

/// Which skin model runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelKind {
    /// The paper's three-layer model (Kron).
    Kron,
    /// The finite-volume reference model.
    Fv,
    /// Two semi-infinite bodies (the paper's model (a)), analytic.
    SemiInfinite,
}

impl ModelKind {
    /// The contact resistance used when none is given [m²K/W]: 1e-3 for fv, 0 for the others (kron has none).
    pub fn default_contact_resistance_m2k_w(self) -> f64 {
        match self {
            ModelKind::Fv => FV_DEFAULT_CONTACT_RESISTANCE_M2K_W,
            ModelKind::Kron | ModelKind::SemiInfinite => 0.0,
        }
    }
}

/// The finger's state at the moment of contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Initial {
    /// The steady state in air at the ambient temperature (default).
    Steady,
    /// Every layer at this temperature \[°C\].
    Uniform(f64),
    /// The steady state in air with the perfusion scaled so that the resting surface (receptor) temperature is this
    /// \[°C\]: the per-participant calibration (the paper measured each subject's finger temperature).
    Surface(f64),
}

impl FromStr for Initial {
    type Err = ParamError;

    /// Parses `steady`, `uniform:C` or `surface:C`.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let bad = |message: &str| ParamError::Invalid {
            origin: "--initial".into(),
            message: format!("`{text}`: {message}; expected steady, uniform:C or surface:C"),
        };
        let number = |value: &str| {
            value
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| bad("not a finite temperature"))
        };
        match text.trim().split_once(':') {
            None if text.trim() == "steady" => Ok(Initial::Steady),
            Some(("uniform", value)) => number(value).map(Initial::Uniform),
            Some(("surface", value)) => number(value).map(Initial::Surface),
            _ => Err(bad("unknown initial state")),
        }
    }
}

/// Everything one simulation needs. Temperatures in °C, times in s.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationSpec {
    /// The model. Default kron.
    pub model: ModelKind,
    /// The finger. Default [`Skin::fingertip`].
    pub skin: Skin,
    /// The touched object (its thickness is used).
    pub material: Material,
    /// Contact duration \[s\]. Default 90 (the paper's recordings).
    pub duration_s: f64,
    /// Output interval and kron time step \[s\]. Default 0.01.
    pub dt_s: f64,
    /// Air temperature \[°C\]. Default 23 (the paper's room).
    pub ambient_c: f64,
    /// Object temperature \[°C\]. Default: the ambient temperature.
    pub object_c: f64,
    /// The finger at the moment of contact. Default [`Initial::Steady`].
    pub initial: Initial,
    /// Contact resistance [m²K/W]; `None` takes [`ModelKind::default_contact_resistance_m2k_w`]. Kron has none and
    /// refuses a non-zero value.
    pub contact_resistance_m2k_w: Option<f64>,
    /// Finger–display contact conductance G_d of the display inverse [W/(m²·K)]. Default 800.
    pub display_conductance_w_m2k: f64,
    /// fv only: the grid, as refinements of the default grid ([`fv::FvConfig::refined`]), at most
    /// [`MAX_FV_LEVEL`]; `None` (default) refines until converged ([`fv::simulate_contact_converged`]), `Some(L)`
    /// runs level L alone, without a convergence check (for benchmarks and convergence studies).
    pub fv_level: Option<u32>,
    /// fv only: local error tolerance of the adaptive time steps \[K\] ([`fv::FvConfig::tolerance_c`]). Default
    /// [`fv::DEFAULT_TOLERANCE_C`].
    pub fv_tolerance_c: f64,
}

/// The finest fv grid level [`SimulationSpec::fv_level`] accepts (about 2 300 cells with the default fingertip and
/// a 1 cm object).
pub const MAX_FV_LEVEL: u32 = 6;

impl SimulationSpec {
    /// The defaults above for `material`.
    pub fn new(model: ModelKind, material: Material) -> Self {
        SimulationSpec {
            model,
            skin: Skin::fingertip(),
            material,
            duration_s: 90.0,
            dt_s: 0.01,
            ambient_c: 23.0,
            object_c: 23.0,
            initial: Initial::Steady,
            contact_resistance_m2k_w: None,
            display_conductance_w_m2k: DEFAULT_DISPLAY_CONDUCTANCE_W_M2K,
            fv_level: None,
            fv_tolerance_c: fv::DEFAULT_TOLERANCE_C,
        }
    }

    /// Checks every number against its physical range ([`crate::limits`]: duration, time step, ambient and
    /// object temperature, the initial skin temperature, contact resistance and display conductance, the skin and
    /// the material), the combination of model and options, and that the results fit in memory
    /// ([`SimulationSpec::result_bytes`] at most [`limits::MAX_RESULT_BYTES`]).
    pub fn validate(&self) -> Result<(), ParamError> {
        Rule::Positive.check("duration_s", self.duration_s).at(ORIGIN)?;
        limits::DURATION
            .rule()
            .check("duration_s", self.duration_s)
            .at(ORIGIN)?;
        limits::TIME_STEP.rule().check("dt_s", self.dt_s).at(ORIGIN)?;
        if self.dt_s > self.duration_s {
            return Err(invalid(format!(
                "dt_s = {} is longer than duration_s = {}",
                self.dt_s, self.duration_s
            )));
        }
        if self.duration_s / self.dt_s > 1e7 {
            return Err(invalid(
                "more than 1e7 steps: use a longer dt_s or a shorter duration_s".into(),
            ));
        }
        limits::check_result_bytes(self.result_bytes()).map_err(|message| ParamError::TooLarge {
            origin: ORIGIN.into(),
            message: format!("{message}: use a longer dt_s or a shorter duration_s"),
        })?;
        limits::check_touch_temperatures(ORIGIN, self.ambient_c, self.object_c)?;
        match self.initial {
            Initial::Steady => {}
            Initial::Uniform(c) => {
                limits::SKIN_TEMPERATURE
                    .rule()
                    .check("initial uniform_c", c)
                    .at(ORIGIN)?;
            }
            Initial::Surface(c) => {
                limits::SKIN_TEMPERATURE
                    .rule()
                    .check("initial surface_c", c)
                    .at(ORIGIN)?;
            }
        }
        limits::CONTACT_CONDUCTANCE
            .rule()
            .check("display_conductance_w_m2k", self.display_conductance_w_m2k)
            .at(ORIGIN)?;
        if let Some(r) = self.contact_resistance_m2k_w {
            limits::CONTACT_RESISTANCE
                .rule()
                .check("contact_resistance_m2k_w", r)
                .at(ORIGIN)?;
            if self.model == ModelKind::Kron && r != 0.0 {
                return Err(invalid(
                    "the kron model has no contact resistance; use --model fv".into(),
                ));
            }
        }
        self.validate_fv_options()?;
        self.skin.validate(ORIGIN)?;
        self.material.validate(ORIGIN)
    }

    /// The fv grid level (at most [`MAX_FV_LEVEL`]) and tolerance (positive), and neither set for another model.
    fn validate_fv_options(&self) -> Result<(), ParamError> {
        Rule::Positive.check("fv_tolerance_c", self.fv_tolerance_c).at(ORIGIN)?;
        if let Some(level) = self.fv_level {
            Rule::AtMost {
                max: f64::from(MAX_FV_LEVEL),
                what: "the finest fv grid level",
            }
            .check("fv_level", f64::from(level))
            .at(ORIGIN)?;
        }
        let default_tolerance = self.fv_tolerance_c == fv::DEFAULT_TOLERANCE_C;
        if self.model != ModelKind::Fv && (self.fv_level.is_some() || !default_tolerance) {
            return Err(invalid(
                "the fv grid level and tolerance apply to the fv model only; use --model fv".into(),
            ));
        }
        Ok(())
    }

    /// Number of output rows: one per output time (see [`Trace::time_s`]). Meaningful for a spec whose duration
    /// and time step are finite and positive.
    pub fn rows(&self) -> usize {
        let intervals = (self.duration_s / self.dt_s - 1e-9).ceil().max(1.0);
        // Saturates for absurd ratios; `validate` refuses those by the step count first.
        intervals as usize + 1
    }

    /// Estimated memory of the result \[bytes\]: rows × bytes per row. A row holds the time and every column as
    /// `f64`: kron 5 + layers, semi-infinite 3 columns; fv 7 + layers, plus the two finite-volume runs its grid
    /// refinement holds at once (4 numbers and a per-layer row of its own, with its allocation, each).
    pub fn result_bytes(&self) -> u64 {
        let layers = self.skin.layers.len() as u64;
        let per_row = match self.model {
            ModelKind::Kron => 8 * (5 + layers),
            ModelKind::SemiInfinite => 8 * 3,
            ModelKind::Fv => 8 * (7 + layers) + 2 * (8 * 4 + 24 + 8 * layers + 16),
        };
        (self.rows() as u64).saturating_mul(per_row)
    }

    fn contact_resistance(&self) -> f64 {
        self.contact_resistance_m2k_w
            .unwrap_or_else(|| self.model.default_contact_resistance_m2k_w())
    }

    /// Output times: 0, dt, 2dt, … with the last row exactly at the duration.
    fn times_s(&self) -> Vec<f64> {
        let intervals = self.rows() - 1;
        (0..=intervals)
            .map(|k| (k as f64 * self.dt_s).min(self.duration_s))
            .collect()
    }
}

fn invalid(message: String) -> ParamError {
    ParamError::Invalid {
        origin: ORIGIN.into(),
        message,
    }
}

/// A simulated trajectory: `time_s` and named columns of equal length, `skin_surface_c` first.
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    /// Time since contact \[s\]; the first row (t = 0) is the resting finger just before the touch.
    pub time_s: Vec<f64>,
    /// Named columns, units in the names; the first is `skin_surface_c`.
    pub columns: Vec<(String, Vec<f64>)>,
    /// A line describing the numerical resolution used (grid, step), for the log.
    pub resolution: String,
}

impl Trace {
    /// The column called `name`, if present.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_slice())
    }

    /// `Ok` if every number of the trace is finite, else a [`ParamError::NonFinite`] naming the first column (in
    /// column order) that is not, with its first such value and time.
    pub fn check_finite(&self) -> Result<(), ParamError> {
        let columns = self.columns.iter().map(|(name, values)| (name.as_str(), values));
        for (name, values) in std::iter::once(("time_s", &self.time_s)).chain(columns) {
            if let Some(row) = values.iter().position(|v| !v.is_finite()) {
                return Err(ParamError::NonFinite {
                    origin: ORIGIN.into(),
                    quantity: name.to_string(),
                    value: values[row],
                    time_s: self.time_s.get(row).copied().unwrap_or(f64::NAN),
                });
            }
        }
        Ok(())
    }

    /// The receptor temperature (`skin_surface_c`) at `time_s`, linearly interpolated; `None` outside the run.
    pub fn skin_surface_at(&self, time_s: f64) -> Option<f64> {
        let surface = self.column("skin_surface_c")?;
        let upper = self.time_s.iter().position(|&t| t >= time_s)?;
        if upper == 0 {
            return (self.time_s[0] == time_s).then_some(surface[0]);
        }
        let (t0, t1) = (self.time_s[upper - 1], self.time_s[upper]);
        let w = (time_s - t0) / (t1 - t0);
        Some(surface[upper - 1] + w * (surface[upper] - surface[upper - 1]))
    }
}

/// Runs the simulation described by `spec`. A result with a number that is not finite is refused
/// ([`ParamError::NonFinite`] naming the first such column and time), never returned.
pub fn simulate(spec: &SimulationSpec) -> Result<Trace, ParamError> {
    spec.validate()?;
    let trace = match spec.model {
        ModelKind::Kron => simulate_kron(spec),
        ModelKind::Fv => simulate_fv(spec),
        ModelKind::SemiInfinite => simulate_semi_infinite(spec),
    }?;
    trace.check_finite()?;
    Ok(trace)
}

/// The skin the model runs with: calibrated by perfusion when a resting surface temperature is requested.
fn kron_initial(spec: &SimulationSpec) -> Result<KronModel, ParamError> {
    let air = KronEnvironment::Air {
        ambient_c: spec.ambient_c,
    };
    let mut model = match spec.initial {
        Initial::Surface(surface_c) => {
            KronModel::new(&kron::calibrate_to_surface(&spec.skin, spec.ambient_c, surface_c)?)?
        }
        _ => KronModel::new(&spec.skin)?,
    };
    match spec.initial {
        Initial::Uniform(c) => model.set_temperatures_c([c; 3]),
        Initial::Steady | Initial::Surface(_) => model.settle(&air),
    }
    Ok(model)
}

fn simulate_kron(spec: &SimulationSpec) -> Result<Trace, ParamError> {
    let mut columns = KronColumns::new(spec)?;
    simulate_kron_into(spec, &mut columns, usize::MAX, &mut |_| {})?;
    Ok(columns.into_trace(spec))
}

/// A kron run's numbers, allocated at their full length before it starts so that a caller can read the rows
/// already computed while later ones are being filled ([`simulate_kron_into`]): the output times and the columns of
/// the run's [`Trace`], in order.
#[derive(Debug, Clone, PartialEq)]
pub struct KronColumns {
    /// Time since contact \[s\] ([`Trace::time_s`]).
    pub time_s: Vec<f64>,
    /// The columns' names, units in the names: `skin_surface_c` (the receptor, epidermis centre), the three
    /// layers, `heat_flux_w_m2`, `display_setpoint_c`, `display_finger_c`.
    pub names: Vec<String>,
    /// The columns' values, each as long as `time_s` (zero until computed).
    pub values: Vec<Vec<f64>>,
}

impl KronColumns {
    /// Blank columns for the kron run of `spec`, which is validated first (and must be a kron run).
    pub fn new(spec: &SimulationSpec) -> Result<Self, ParamError> {
        spec.validate()?;
        if spec.model != ModelKind::Kron {
            return Err(invalid(format!("{:?} is not the kron model", spec.model)));
        }
        let mut names = vec!["skin_surface_c".to_string()];
        names.extend(spec.skin.layers.iter().map(|l| format!("{}_c", column_name(&l.name))));
        names.extend(["heat_flux_w_m2", "display_setpoint_c", "display_finger_c"].map(String::from));
        let time_s = spec.times_s();
        let values = names.iter().map(|_| vec![0.0; time_s.len()]).collect();
        Ok(KronColumns { time_s, names, values })
    }

    /// The filled columns as the run's [`Trace`].
    pub fn into_trace(self, spec: &SimulationSpec) -> Trace {
        Trace {
            time_s: self.time_s,
            columns: self.names.into_iter().zip(self.values).collect(),
            resolution: format!("kron, backward Euler, step {} s", spec.dt_s),
        }
    }
}

/// Rows of a kron run just computed, borrowed for as long as the run's [`KronColumns`] are.
#[derive(Debug, Clone)]
pub struct KronRows<'a> {
    /// Index of the first of them in the run.
    pub first_row: usize,
    /// Their output times \[s\].
    pub time_s: &'a [f64],
    /// Their values, one slice per column of [`KronColumns::names`].
    pub values: Vec<&'a [f64]>,
}

/// Runs the kron simulation of `spec` into `columns` (from [`KronColumns::new`] for the same spec) and hands
/// every `rows_per_call` rows (at least 1; the last piece shorter) to `on_rows` as soon as they are computed and
/// found finite, so that a caller writes them while the run goes on: the rows stay borrowed, never copied, for as
/// long as `columns` is (a thread of the caller's scope may read them). A number that is not finite ends the run
/// with [`ParamError::NonFinite`] (the first such column and time) before its rows are handed on.
pub fn simulate_kron_into<'a>(
    spec: &SimulationSpec,
    columns: &'a mut KronColumns,
    rows_per_call: usize,
    on_rows: &mut dyn FnMut(KronRows<'a>),
) -> Result<(), ParamError> {
    let mut run = KronRun::new(spec)?;
    if columns.time_s.len() != spec.rows() || columns.values.len() != KRON_COLUMNS {
        return Err(invalid("the columns were not made for this run".into()));
    }
    let KronColumns { time_s, names, values } = columns;
    let (time_s, names): (&'a [f64], &'a [String]) = (time_s, names);
    let mut unfilled: Vec<&'a mut [f64]> = values.iter_mut().map(Vec::as_mut_slice).collect();
    let mut first = 0;
    while first < time_s.len() {
        let rows = first..(first + rows_per_call.max(1)).min(time_s.len());
        let mut piece: Vec<&'a mut [f64]> = unfilled.iter_mut().map(|rest| split_off(rest, rows.len())).collect();
        for (i, row) in rows.clone().enumerate() {
            for (column, value) in piece.iter_mut().zip(run.row(row, time_s)) {
                column[i] = value;
            }
        }
        let piece: Vec<&'a [f64]> = piece.into_iter().map(shared).collect();
        let times = &time_s[rows.clone()];
        check_finite_rows(names, times, &piece)?;
        on_rows(KronRows {
            first_row: first,
            time_s: times,
            values: piece,
        });
        first = rows.end;
    }
    Ok(())
}

/// A kron contact being run: the finger, the display inverse and the two environments (air before the touch).
struct KronRun<'s> {
    spec: &'s SimulationSpec,
    finger: KronModel,
    display: DisplayInverse<KronModel>,
    object: KronEnvironment,
    air: KronEnvironment,
}

/// Numbers of a kron row: the receptor (epidermis centre) as the skin surface, the three layers, the heat flux, the
/// display set-point and the finger on the display.
const KRON_COLUMNS: usize = 7;

impl<'s> KronRun<'s> {
    fn new(spec: &'s SimulationSpec) -> Result<Self, ParamError> {
        let finger = kron_initial(spec)?;
        let object = KronEnvironment::touching(&spec.material, spec.object_c);
        object.validate(ORIGIN)?;
        Ok(KronRun {
            spec,
            display: DisplayInverse::new(finger.clone(), spec.display_conductance_w_m2k)?,
            finger,
            object,
            air: KronEnvironment::Air {
                ambient_c: spec.ambient_c,
            },
        })
    }

    /// The numbers of `row` (0: the resting finger before the touch; later rows step from the one before, so rows
    /// come in order) at the output times `time_s`.
    fn row(&mut self, row: usize, time_s: &[f64]) -> [f64; KRON_COLUMNS] {
        let (env, setpoint_c) = if row == 0 {
            let receptor_c = self.finger.temperatures_c()[0];
            let flux_w_m2 = self.finger.heat_flux_to_env_w_m2(&self.air);
            (&self.air, resting_display_c(receptor_c, flux_w_m2, self.spec))
        } else {
            let h = time_s[row] - time_s[row - 1];
            self.finger.step(h, &self.object);
            let setpoint_c = self.display.setpoint_c(self.finger.temperatures_c()[0], h);
            self.display.advance(h, setpoint_c);
            (&self.object, setpoint_c)
        };
        let [t1, t2, t3] = self.finger.temperatures_c();
        let flux_w_m2 = self.finger.heat_flux_to_env_w_m2(env);
        [t1, t1, t2, t3, flux_w_m2, setpoint_c, self.display.receptor_c()]
    }
}

/// The first `count` numbers of `rest`, which keeps the others.
fn split_off<'a>(rest: &mut &'a mut [f64], count: usize) -> &'a mut [f64] {
    let (piece, later) = std::mem::take(rest).split_at_mut(count);
    *rest = later;
    piece
}

/// `Ok` if every number of the rows `columns` (named `names`, at the times `time_s`) is finite, else a
/// [`ParamError::NonFinite`] naming the first column that is not, with its first such value and time.
fn check_finite_rows(names: &[String], time_s: &[f64], columns: &[&[f64]]) -> Result<(), ParamError> {
    for (name, column) in names.iter().zip(columns) {
        if let Some(i) = column.iter().position(|v| !v.is_finite()) {
            return Err(ParamError::NonFinite {
                origin: ORIGIN.into(),
                quantity: name.clone(),
                value: column[i],
                time_s: time_s[i],
            });
        }
    }
    Ok(())
}

/// A slice filled, from now on only read.
fn shared(slice: &mut [f64]) -> &[f64] {
    slice
}

/// The plate temperature that draws the resting heat flux `flux_w_m2` from a finger whose receptor is at
/// `receptor_c`: the display rendering air.
fn resting_display_c(receptor_c: f64, flux_w_m2: f64, spec: &SimulationSpec) -> f64 {
    receptor_c - flux_w_m2 / spec.display_conductance_w_m2k
}

fn fv_initial(spec: &SimulationSpec) -> InitialState {
    match spec.initial {
        Initial::Steady => InitialState::SteadyInAir,
        Initial::Uniform(temperature_c) => InitialState::Uniform { temperature_c },
        Initial::Surface(surface_c) => InitialState::RestingSurface { surface_c },
    }
}

/// The finite-volume finger alone (no object), prepared as the simulation's finger is before contact.
fn fv_resting_finger(spec: &SimulationSpec, config: &FvConfig) -> Result<FvModel, ParamError> {
    let mut finger = FvModel::new(&spec.skin, None, config)?;
    match spec.initial {
        Initial::Steady => finger.set_steady_in_air(spec.ambient_c)?,
        Initial::Uniform(c) => {
            finger.set_skin_uniform(c)?;
            finger.set_environment(FvEnvironment::Air {
                ambient_c: spec.ambient_c,
            })?;
        }
        Initial::Surface(surface_c) => {
            finger.calibrate_to_surface(spec.ambient_c, surface_c)?;
        }
    }
    Ok(finger)
}

fn simulate_fv(spec: &SimulationSpec) -> Result<Trace, ParamError> {
    let base = FvConfig {
        contact_resistance_m2k_w: spec.contact_resistance(),
        tolerance_c: Some(spec.fv_tolerance_c),
        ..FvConfig::default()
    };
    let contact = fv::ContactSpec {
        ambient_c: spec.ambient_c,
        object_c: spec.object_c,
        initial: fv_initial(spec),
        duration_s: spec.duration_s,
        output_dt_s: spec.dt_s,
    };
    let (run, resolution) = match spec.fv_level {
        None => {
            fv::simulate_contact_converged(&spec.skin, &spec.material, &base, &contact, &fv::Refinement::default())?
        }
        Some(level) => fv_at_level(spec, &base, &contact, level)?,
    };
    let config = base.refined(resolution.refinements);
    let mut display = DisplayInverse::new(fv_resting_finger(spec, &config)?, spec.display_conductance_w_m2k)?;
    let mut setpoint = Vec::with_capacity(run.time_s.len());
    let mut display_finger = Vec::with_capacity(run.time_s.len());
    setpoint.push(resting_display_c(run.surface_c[0], run.heat_flux_w_m2[0], spec));
    display_finger.push(display.receptor_c());
    for (k, pair) in run.time_s.windows(2).enumerate() {
        // The output interval itself, bit for bit, unless it is a shorter last one: equal steps keep the display
        // inverse's cached plate sensitivity (a difference of output times varies in the last bit).
        let difference = pair[1] - pair[0];
        let h = if (difference - spec.dt_s).abs() <= 1e-9 * spec.dt_s {
            spec.dt_s
        } else {
            difference
        };
        let setpoint_c = display.setpoint_c(run.surface_c[k + 1], h);
        display.advance(h, setpoint_c);
        setpoint.push(setpoint_c);
        display_finger.push(display.receptor_c());
    }
    let mut columns = vec![("skin_surface_c".to_string(), run.surface_c.clone())];
    for (i, layer) in spec.skin.layers.iter().enumerate() {
        let mean = run.layer_mean_c.iter().map(|row| row[i]).collect();
        columns.push((format!("{}_mean_c", column_name(&layer.name)), mean));
    }
    columns.push(("object_face_c".into(), run.object_face_c.clone()));
    columns.push(("heat_flux_w_m2".into(), run.heat_flux_w_m2.clone()));
    columns.push(("display_setpoint_c".into(), setpoint));
    columns.push(("display_finger_c".into(), display_finger));
    let resolution = format!(
        "fv, {} skin + {} object cells, first cell {:.1} µm, {} adaptive steps (longest {:.4} ms), {} refinements, \
         last change {:.4} °C{}",
        resolution.skin_cells,
        resolution.object_cells,
        resolution.surface_cell_m * 1e6,
        run.steps.accepted,
        resolution.step_s * 1e3,
        resolution.refinements,
        resolution.max_change_c,
        match (spec.fv_level, resolution.converged) {
            (Some(_), _) => " (fixed grid level: convergence not checked)",
            (None, true) => "",
            (None, false) => " (NOT converged)",
        }
    );
    Ok(Trace {
        time_s: run.time_s,
        columns,
        resolution,
    })
}

/// One fv run on the default grid refined `level` times, with its resolution (no convergence check: the change
/// is reported as NaN and `converged` as false).
fn fv_at_level(
    spec: &SimulationSpec,
    base: &FvConfig,
    contact: &fv::ContactSpec,
    level: u32,
) -> Result<(fv::ContactRun, fv::Resolution), ParamError> {
    let config = base.refined(level);
    let run = fv::simulate_contact(&spec.skin, &spec.material, &config, contact)?;
    let resolution = fv::Resolution {
        refinements: level,
        skin_cells: run.skin_cells,
        object_cells: run.object_cells,
        surface_cell_m: config.surface_cell_m,
        step_s: run.step_s,
        max_change_c: f64::NAN,
        converged: false,
    };
    Ok((run, resolution))
}

fn simulate_semi_infinite(spec: &SimulationSpec) -> Result<Trace, ParamError> {
    let outer = &spec.skin.layers[0];
    let skin_e = crate::units::effusivity(outer.conductivity_w_mk, outer.density_kg_m3, outer.specific_heat_j_kgk);
    let object_e = spec.material.effusivity();
    let skin_c = match spec.initial {
        Initial::Uniform(c) | Initial::Surface(c) => c,
        Initial::Steady => fv_resting_finger(spec, &FvConfig::default())?.surface_c(),
    };
    let resting_flux = spec.skin.air_convection_w_m2k * (skin_c - spec.ambient_c);
    let r_c = spec.contact_resistance();
    let times = spec.times_s();
    let surface: Vec<f64> = times
        .iter()
        .map(|&t| semi_infinite::surface_temperature_c(skin_e, skin_c, object_e, spec.object_c, r_c, t))
        .collect();
    let flux = times
        .iter()
        .map(|&t| {
            if t <= 0.0 {
                resting_flux
            } else {
                semi_infinite::surface_heat_flux_w_m2(skin_e, skin_c, object_e, spec.object_c, r_c, t)
            }
        })
        .collect();
    let columns = vec![("skin_surface_c".to_string(), surface), ("heat_flux_w_m2".into(), flux)];
    Ok(Trace {
        time_s: times,
        columns,
        resolution: format!("semi-infinite, analytic, skin effusivity {skin_e:.0} (outermost layer), R_c {r_c} m²K/W"),
    })
}

/// A layer name as a CSV column stem: lower case, anything but letters and digits as `_`.
fn column_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::materials::find;

    fn spec(model: ModelKind, name: &str) -> SimulationSpec {
        SimulationSpec::new(model, find(name).unwrap_or_else(|e| panic!("{e}")))
    }

    #[test]
    fn initial_states_parse_and_bad_ones_are_refused() {
        assert_eq!("steady".parse::<Initial>(), Ok(Initial::Steady));
        assert_eq!("uniform:30.5".parse::<Initial>(), Ok(Initial::Uniform(30.5)));
        assert_eq!("surface:31".parse::<Initial>(), Ok(Initial::Surface(31.0)));
        for bad in ["warm", "uniform:", "uniform:NaN", "surface:inf", "steady:3", ""] {
            assert!(bad.parse::<Initial>().is_err(), "`{bad}` was accepted");
        }
    }

    #[test]
    fn kron_rows_are_handed_on_in_order_in_pieces_and_are_the_traces_numbers() {
        let mut s = spec(ModelKind::Kron, "aluminium");
        s.duration_s = 1.0;
        s.dt_s = 0.001;
        let whole = simulate(&s).unwrap_or_else(|e| panic!("{e}"));
        let mut columns = KronColumns::new(&s).unwrap_or_else(|e| panic!("{e}"));
        let mut pieces = Vec::new();
        simulate_kron_into(&s, &mut columns, 300, &mut |rows| {
            let values: Vec<Vec<f64>> = rows.values.iter().map(|v| v.to_vec()).collect();
            pieces.push((rows.first_row, rows.time_s.to_vec(), values));
        })
        .unwrap_or_else(|e| panic!("{e}"));
        let sizes: Vec<usize> = pieces.iter().map(|(_, time, _)| time.len()).collect();
        assert_eq!(sizes, [300, 300, 300, 101], "piece sizes of 1001 rows by 300");
        let mut next = 0;
        for (first, time, values) in &pieces {
            assert_eq!(*first, next, "pieces in order, none missing");
            let rows = *first..first + time.len();
            assert_eq!(time.as_slice(), &whole.time_s[rows.clone()]);
            for ((name, column), piece) in whole.columns.iter().zip(values) {
                let same = column[rows.clone()]
                    .iter()
                    .zip(piece)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(
                    same,
                    "{name}, rows {rows:?}: the piece handed on differs from the trace"
                );
            }
            next = rows.end;
        }
        assert_eq!(columns.into_trace(&s), whole, "the filled columns are the trace");
    }

    #[test]
    fn the_last_row_is_exactly_the_duration() {
        let mut s = spec(ModelKind::Kron, "wood");
        s.duration_s = 1.0;
        s.dt_s = 0.3;
        let trace = simulate(&s).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(trace.time_s, vec![0.0, 0.3, 0.6, 0.8999999999999999, 1.0]);
        for (name, values) in &trace.columns {
            assert_eq!(values.len(), trace.time_s.len(), "column {name}");
        }
    }

    #[test]
    fn surface_calibration_starts_every_model_at_the_requested_temperature() {
        for model in [ModelKind::Kron, ModelKind::Fv, ModelKind::SemiInfinite] {
            let mut s = spec(model, "stone");
            s.duration_s = 0.05;
            s.initial = Initial::Surface(30.0);
            let trace = simulate(&s).unwrap_or_else(|e| panic!("{model:?}: {e}"));
            let start = trace.skin_surface_at(0.0).unwrap_or(f64::NAN);
            assert!(
                (start - 30.0).abs() < 1e-5,
                "{model:?}: resting surface {start}, requested 30"
            );
        }
    }

    #[test]
    fn kron_trace_equals_stepping_the_model_by_hand() {
        let mut s = spec(ModelKind::Kron, "steel");
        s.duration_s = 2.0;
        s.dt_s = 0.05;
        let trace = simulate(&s).unwrap_or_else(|e| panic!("{e}"));
        let mut model = KronModel::new(&Skin::fingertip()).unwrap_or_else(|e| panic!("{e}"));
        model.settle(&KronEnvironment::Air { ambient_c: 23.0 });
        let env = KronEnvironment::touching(&s.material, 23.0);
        for _ in 0..40 {
            model.step(0.05, &env);
        }
        let got = *trace
            .column("skin_surface_c")
            .and_then(|c| c.last())
            .unwrap_or(&f64::NAN);
        let want = model.temperatures_c()[0];
        assert!((got - want).abs() < 1e-12, "trace {got}, by hand {want}");
    }

    #[test]
    fn invalid_specs_are_errors() {
        let mut s = spec(ModelKind::Fv, "cork");
        s.dt_s = 0.0;
        assert!(simulate(&s).is_err());
        let mut s = spec(ModelKind::Fv, "cork");
        s.contact_resistance_m2k_w = Some(-1e-3);
        assert!(simulate(&s).is_err());
        let mut s = spec(ModelKind::Kron, "cork");
        s.ambient_c = f64::INFINITY;
        assert!(simulate(&s).is_err());
        let mut s = spec(ModelKind::Kron, "cork");
        s.dt_s = 2.0;
        s.duration_s = 1.0;
        assert!(simulate(&s).is_err());
    }

    #[test]
    fn fv_grid_level_and_tolerance_are_checked_and_used() {
        let refused = |change: &dyn Fn(&mut SimulationSpec), model: ModelKind, what: &str| {
            let mut s = spec(model, "wood");
            s.duration_s = 1.0;
            change(&mut s);
            let err = simulate(&s).err().map(|e| e.to_string());
            assert!(err.as_deref().is_some_and(|e| e.contains(what)), "{what}: {err:?}");
        };
        refused(&|s| s.fv_level = Some(MAX_FV_LEVEL + 1), ModelKind::Fv, "fv_level");
        refused(&|s| s.fv_tolerance_c = 0.0, ModelKind::Fv, "fv_tolerance_c");
        refused(&|s| s.fv_tolerance_c = f64::NAN, ModelKind::Fv, "fv_tolerance_c");
        refused(&|s| s.fv_level = Some(1), ModelKind::Kron, "fv model only");
        refused(&|s| s.fv_tolerance_c = 1e-4, ModelKind::SemiInfinite, "fv model only");
        // A fixed level runs that level: its cell count is the level's, whatever convergence would pick.
        let mut s = spec(ModelKind::Fv, "wood");
        s.duration_s = 1.0;
        s.fv_level = Some(0);
        let coarse = simulate(&s).unwrap();
        s.fv_level = Some(2);
        let fine = simulate(&s).unwrap();
        assert!(
            coarse.resolution.contains("31 skin + 41 object"),
            "{}",
            coarse.resolution
        );
        assert!(fine.resolution.contains("2 refinements"), "{}", fine.resolution);
        assert!(fine.resolution.contains("not checked"), "{}", fine.resolution);
    }

    #[test]
    fn unphysical_inputs_are_refused_with_their_range() {
        let refused = |change: &dyn Fn(&mut SimulationSpec), key: &str| {
            for model in [ModelKind::Kron, ModelKind::Fv, ModelKind::SemiInfinite] {
                let mut s = spec(model, "wood");
                s.duration_s = 1.0;
                change(&mut s);
                match simulate(&s) {
                    Err(ParamError::BadValue { source, .. }) => assert_eq!(source.name, key, "{model:?}"),
                    other => panic!("{model:?}, {key}: expected a refused value, got {other:?}"),
                }
            }
        };
        refused(&|s| s.ambient_c = 1000.0, "ambient_c");
        refused(&|s| s.object_c = -300.0, "object_c");
        refused(&|s| s.material.conductivity_w_mk = 1e300, "conductivity_w_mk");
        refused(&|s| s.initial = Initial::Uniform(80.0), "initial uniform_c");
        refused(&|s| s.display_conductance_w_m2k = 1e9, "display_conductance_w_m2k");
        refused(&|s| s.duration_s = 4000.0, "duration_s");
    }

    #[test]
    fn work_beyond_the_memory_cap_is_refused_before_it_runs() {
        let mut s = spec(ModelKind::Fv, "wood");
        s.duration_s = 3600.0;
        s.dt_s = 3600.0 / 9e6;
        let bytes = s.result_bytes();
        assert!(bytes > limits::MAX_RESULT_BYTES, "estimate {bytes} B");
        assert!(
            matches!(simulate(&s), Err(ParamError::TooLarge { .. })),
            "9e6 fv rows accepted"
        );
        s.model = ModelKind::SemiInfinite;
        assert!(s.result_bytes() <= limits::MAX_RESULT_BYTES, "{} B", s.result_bytes());
    }

    #[test]
    fn every_model_stays_finite_at_the_corners_of_the_ranges() {
        // The most extreme objects the ranges admit: the best conductor, thinnest and lightest or thickest and
        // heaviest, at the coldest and hottest object and ambient temperatures.
        for (k, rho, c, thickness) in [
            (
                limits::CONDUCTIVITY.max,
                limits::DENSITY.min,
                limits::SPECIFIC_HEAT.min,
                limits::OBJECT_THICKNESS.min,
            ),
            (
                limits::CONDUCTIVITY.max,
                limits::DENSITY.max,
                limits::SPECIFIC_HEAT.max,
                limits::OBJECT_THICKNESS.max,
            ),
            (
                limits::CONDUCTIVITY.min,
                limits::DENSITY.min,
                limits::SPECIFIC_HEAT.min,
                limits::OBJECT_THICKNESS.min,
            ),
            (
                limits::CONDUCTIVITY.min,
                limits::DENSITY.max,
                limits::SPECIFIC_HEAT.max,
                limits::OBJECT_THICKNESS.max,
            ),
        ] {
            for (ambient_c, object_c) in [
                (limits::AMBIENT_TEMPERATURE.min, limits::OBJECT_TEMPERATURE.max),
                (limits::AMBIENT_TEMPERATURE.max, limits::OBJECT_TEMPERATURE.min),
            ] {
                for model in [ModelKind::Kron, ModelKind::Fv, ModelKind::SemiInfinite] {
                    let mut s = spec(model, "wood");
                    s.material = Material {
                        name: "corner".into(),
                        conductivity_w_mk: k,
                        density_kg_m3: rho,
                        specific_heat_j_kgk: c,
                        thickness_m: thickness,
                        source: "test".into(),
                    };
                    // Short: a 1 m object needs 65 000 fv cells (a second or two per corner).
                    s.duration_s = 0.2;
                    s.dt_s = 0.01;
                    s.ambient_c = ambient_c;
                    s.object_c = object_c;
                    if let Err(e) = simulate(&s) {
                        panic!("{model:?} k {k} ρ {rho} c {c} d {thickness} air {ambient_c} object {object_c}: {e}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_non_finite_result_names_its_column_and_time() {
        let trace = Trace {
            time_s: vec![0.0, 0.5, 1.0],
            columns: vec![
                ("skin_surface_c".into(), vec![32.0, 31.0, 30.0]),
                ("heat_flux_w_m2".into(), vec![90.0, f64::NAN, f64::INFINITY]),
            ],
            resolution: String::new(),
        };
        match trace.check_finite() {
            Err(ParamError::NonFinite { quantity, time_s, .. }) => {
                assert_eq!((quantity.as_str(), time_s), ("heat_flux_w_m2", 0.5))
            }
            other => panic!("expected NonFinite, got {other:?}"),
        }
    }
}
