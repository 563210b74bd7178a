//! The modal fast path of the finite-volume model: [`ModalFv`], the same finger (and object) advanced exactly by
//! precomputed discrete-time updates between contact events.
//!
//! Between events (touch, release, a change of conductance or object) the model is linear and time-invariant:
//! `C dT/dt = −K T + s + b u`, with `C` the diagonal of cell capacities [J/(m²·K)], `K` the symmetric tridiagonal
//! conductance matrix of the chain skin-deep … skin-surface | object-face … object-far [W/(m²·K)], `s` the constant
//! sources (perfusion, metabolic heat, held far ends) and `u` the temperature the surface is connected to (air or
//! plate; none in contact). With `y = C^½ T` the matrix `A = C^−½ K C^−½` is symmetric tridiagonal; its eigen
//! decomposition `A = Q Λ Qᵀ` ([`super::tridiagonal`], implicit QL) gives modal coordinates `z = Qᵀ C^½ T` in which
//! every mode advances on its own and, with `u` held over the step (zero-order hold), exactly:
//! `z_j ← e^{−λ_j h} z_j + (1 − e^{−λ_j h})/λ_j · (f_j + β_j u)`. The receptor (the skin surface face temperature) is
//! a fixed linear combination of the modes. A step costs about 3 flops per cell and never allocates.
//!
//! The decomposition is computed once per configuration (surface conductance, or contact with the current object)
//! and cached ([`MAX_BASES`] configurations), so a finger that touches and releases the same object switches between
//! two cached bases; a switch projects the state (O(cells²)). The per-step factors are cached per step length
//! ([`MAX_STEP_TABLES`] per configuration), so a display inverse requesting over one horizon and stepping another
//! costs no exponentials per tick. No mode is truncated: all are kept (at these sizes a mode costs less than the
//! bookkeeping of dropping it), so the only error is rounding.
//!
//! **Accuracy.** The fast path is the exact solution of the finite-volume model's ODE (its space discretisation)
//! with the surface input held over each step, whereas [`FvModel::step`] approximates it with its implicit scheme.
//! Stated bound: within 0.005 °C of the full model on the same grid converged in time, over touch/release
//! sequences and plate step inputs (tested for the paper's five materials and contact resistances 0, 1e-3 and
//! 1e-2 m²K/W: at most 2.5e-5 °C against the full model at 64 steps per 10 ms tick, and that difference is the full
//! model's own time error: it falls 16-fold when the full model's step is divided by 4). Steady states are reached to
//! 1e-10 °C and a closed system keeps its energy to 1e-12 (relative). Against the full model stepped once per
//! tick the difference is that model's time error (TR-BDF2, largest in the first step after a touch: 0.043 °C at a
//! 10 ms tick on wood); figures in `docs/performance.md`.
//!
//! **Where it applies.** [`ModalFv::new`] selects the fast path automatically when the grid has at most
//! [`MODAL_MAX_CELLS`] cells (above that the O(cells³) decomposition and O(cells²) switches cost more than they save)
//! and the decomposition succeeds; otherwise every call goes to the wrapped [`FvModel`] unchanged. The wrapped
//! model's [`EnergyLedger`](super::EnergyLedger) counts only steps taken by the full model (none on the fast path);
//! energy and balances of the fast path are checked from the state ([`FvModel::skin_energy_j_m2`]) in the tests.

use std::cell::{Ref, RefCell};

use super::chain::{Arm, Side};
use super::model::FvModel;
use super::tridiagonal::symmetric_tridiagonal_eigen;
use super::{FvConfig, FvEnvironment, TimeScheme};
use crate::error::ParamError;
use crate::inverse::PlateCoupled;
use crate::materials::Material;

/// Largest grid (skin + object cells) for which [`ModalFv`] takes the fast path: 256.
pub const MODAL_MAX_CELLS: usize = 256;
/// Configurations whose decomposition is cached at once (air, plate, contact, and one more): 4.
pub const MAX_BASES: usize = 4;
/// Step lengths whose factors are cached per configuration: 4.
pub const MAX_STEP_TABLES: usize = 4;
/// Relative difference below which two step lengths share their factors: 1e-7 (see `same_step`).
const SAME_STEP_RELATIVE: f64 = 1e-7;

/// How [`ModalFv`] advances each mode over a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ModalStepping {
    /// Exactly, with the surface input held over the step: `e^{−λh}`, the solution of the finite-volume equations
    /// (default; what the pipeline uses).
    #[default]
    Exact,
    /// With the full model's own time scheme (TR-BDF2 or backward Euler) applied to each mode: reproduces
    /// [`FvModel::step`] with one step per call to rounding (about 1e-12 °C), at the fast path's cost. For a caller
    /// that must keep the full model's per-step results.
    Scheme,
}

/// TR-BDF2's constants, as the full model's solver defines them: γ = 2 − √2, d = γ/2, and the BDF2 stage
/// T₁ = A·T_γ − B·T₀ + d·h·F(T₁).
const GAMMA: f64 = 2.0 - std::f64::consts::SQRT_2;
const TR_D: f64 = GAMMA / 2.0;
const TR_A: f64 = 1.0 / (GAMMA * (2.0 - GAMMA));
const TR_B: f64 = (1.0 - GAMMA) * (1.0 - GAMMA) / (GAMMA * (2.0 - GAMMA));

/// A mode's factors over a step of `h` \[s\] at rate `rate_per_s`: (decay, φ) in `z ← decay·z + φ·(f + β u)`.
fn mode_factors(stepping: ModalStepping, scheme: TimeScheme, rate_per_s: f64, h: f64) -> (f64, f64) {
    let l = rate_per_s;
    match (stepping, scheme) {
        (ModalStepping::Exact, _) => {
            let phi = if l == 0.0 { h } else { -(-l * h).exp_m1() / l };
            ((-l * h).exp(), phi)
        }
        (ModalStepping::Scheme, TimeScheme::BackwardEuler) => {
            let m = 1.0 + h * l;
            (1.0 / m, h / m)
        }
        (ModalStepping::Scheme, TimeScheme::TrBdf2) => {
            // Trapezoid to γh: (1 + dhλ) y_γ = (1 − dhλ) y₀ + 2dh g; BDF2: (1 + dhλ) y₁ = A y_γ − B y₀ + dh g.
            let dh = TR_D * h;
            let m = 1.0 + dh * l;
            let (stage_decay, stage_phi) = ((1.0 - dh * l) / m, 2.0 * dh / m);
            ((TR_A * stage_decay - TR_B) / m, (TR_A * stage_phi + dh) / m)
        }
    }
}

/// What a configuration's matrix depends on: contact or not, the surface conductance (bits), the perfusion scale
/// (bits) and, in contact, the object's generation (bumped when it is replaced).
type BasisKey = (bool, u64, u64, u64);

/// The modal decomposition of one configuration.
#[derive(Debug, Clone)]
struct Basis {
    key: BasisKey,
    /// Cells of the system: the skin's, plus the object's in contact.
    cells: usize,
    /// λ_j of `C^−½ K C^−½` [1/s], ascending.
    rate_per_s: Vec<f64>,
    /// `C^−½ Q`, row-major cells × modes: cell temperature = Σ_j to_cell[k][j] z_j. Skin cells first (surface
    /// first), then object cells (contact face first).
    to_cell: Vec<f64>,
    /// `Qᵀ C^½`, row-major modes × cells: z_j = Σ_k to_mode[j][k] T_k.
    to_mode: Vec<f64>,
    /// Constant modal forcing `Qᵀ C^−½ s`.
    forcing: Vec<f64>,
    /// Modal forcing per degree of the surface input `Qᵀ C^−½ b` (zero in contact).
    input: Vec<f64>,
    /// Receptor (surface face temperature) = surface_row · z + surface_input · u.
    surface_row: Vec<f64>,
    surface_input: f64,
    /// How the modes advance, and the full model's scheme (for [`ModalStepping::Scheme`]).
    stepping: ModalStepping,
    scheme: TimeScheme,
    /// Per-step factors: [`MAX_STEP_TABLES`] slots with their storage allocated when the basis is built (a slot
    /// not yet used has a NaN step length), refilled round-robin.
    steps: Vec<StepTable>,
    /// The slot the next new step length goes to.
    next_slot: usize,
}

/// The factors of one step length `h` in one configuration.
#[derive(Debug, Clone, Default)]
struct StepTable {
    /// The step length \[s\].
    h_s: f64,
    /// e^{−λ_j h}.
    decay: Vec<f64>,
    /// φ_j f_j and φ_j β_j with φ_j = (1 − e^{−λ_j h})/λ_j (h when λ_j = 0).
    drive: Vec<f64>,
    drive_input: Vec<f64>,
    /// surface_row ∘ decay, and the receptor after the step from z = 0: out_const + out_input · u.
    row_decay: Vec<f64>,
    out_const: f64,
    out_input: f64,
}

/// The finite-volume model with the modal fast path (see `docs/performance.md` for the method and its bound).
///
/// Wraps an [`FvModel`] (grid, parameters, and the state whenever the full model is read) and mirrors the parts of
/// its interface that a renderer or a finger on a display steps every tick. Cloning copies the cached bases.
#[derive(Debug, Clone)]
pub struct ModalFv {
    core: RefCell<Core>,
}

#[derive(Debug, Clone)]
struct Core {
    /// The full model. Its cell temperatures are the state while `synced`; otherwise the modal state is.
    full: FvModel,
    /// Whether the fast path is used at all.
    enabled: bool,
    /// How the modes advance.
    stepping: ModalStepping,
    bases: Vec<Basis>,
    /// Index of the basis `z` belongs to.
    active: Option<usize>,
    /// The modal state (length of the active basis).
    z: Vec<f64>,
    /// Whether `full`'s cells hold the current state.
    synced: bool,
    /// The environment of the last step.
    env: FvEnvironment,
    /// Receptor temperature now \[°C\].
    surface_c: f64,
    /// Bumped whenever the object is replaced (part of the contact key).
    generation: u64,
    /// Scratch for projections.
    cells: Vec<f64>,
}

impl ModalFv {
    /// Wraps `model` in its current state and environment. The fast path is selected when the grid has at most
    /// [`MODAL_MAX_CELLS`] cells; otherwise this behaves exactly as `model`.
    pub fn new(model: FvModel) -> Self {
        let enabled = model.skin_cells() + model.object_cells() <= MODAL_MAX_CELLS;
        Self::with_fast_path(model, enabled)
    }

    /// As [`ModalFv::new`], with the fast path forced on or off (`false`: every call goes to the full model; for
    /// comparisons and benchmarks).
    pub fn with_fast_path(model: FvModel, enabled: bool) -> Self {
        let cells = vec![0.0; model.skin_cells() + model.object_cells()];
        let core = Core {
            env: model.environment(),
            surface_c: model.surface_c(),
            full: model,
            enabled,
            stepping: ModalStepping::Exact,
            bases: Vec::new(),
            active: None,
            z: Vec::new(),
            synced: true,
            generation: 0,
            cells,
        };
        let mut core = core;
        core.prepare(core.env);
        ModalFv {
            core: RefCell::new(core),
        }
    }

    /// Makes the configuration of `env` ready (decomposed and the state projected onto it) without stepping, so
    /// that the first step in it does not allocate: a display finger prepares its plate configuration when it is
    /// built. Does nothing off the fast path.
    pub fn prepare(&mut self, env: FvEnvironment) {
        self.core.get_mut().prepare(env);
    }

    /// Switches the fast path on (where the grid allows it: at most [`MODAL_MAX_CELLS`] cells) or off (every call
    /// goes to the full model). The state is kept.
    pub fn set_fast_path(&mut self, enabled: bool) {
        let core = self.core.get_mut();
        core.sync();
        core.active = None;
        core.enabled = enabled && core.cells.len() <= MODAL_MAX_CELLS;
        let env = core.env;
        core.prepare(env);
    }

    /// Sets how the modes advance ([`ModalStepping::Exact`] unless set); forgets the cached step factors.
    pub fn set_stepping(&mut self, stepping: ModalStepping) {
        let core = self.core.get_mut();
        if core.stepping != stepping {
            core.sync();
            core.active = None;
            core.bases.clear();
            core.stepping = stepping;
            let env = core.env;
            core.prepare(env);
        }
    }

    /// How the modes advance.
    pub fn stepping(&self) -> ModalStepping {
        self.core.borrow().stepping
    }

    /// Whether the fast path is in use.
    pub fn fast_path(&self) -> bool {
        self.core.borrow().enabled
    }

    /// The full model with the current state (the modal state is written into its cells first; O(cells²) after
    /// fast steps). Several guards may be held at once (only a step, which needs `&mut self`, makes the cells stale).
    pub fn model(&self) -> Ref<'_, FvModel> {
        if !self.core.borrow().synced {
            self.core.borrow_mut().sync();
        }
        Ref::map(self.core.borrow(), |core| &core.full)
    }

    /// The full model with the current state.
    pub fn into_model(self) -> FvModel {
        let mut core = self.core.into_inner();
        core.sync();
        core.full
    }

    /// Skin surface temperature \[°C\] ([`FvModel::surface_c`]) without reconstructing the cells.
    pub fn surface_c(&self) -> f64 {
        self.core.borrow().surface_c
    }

    /// The environment of the last step.
    pub fn environment(&self) -> FvEnvironment {
        self.core.borrow().env
    }

    /// Advances by `dt_s` \[s\] in `env`, as [`FvModel::step`] (same contract: `dt_s` finite and positive, `env`
    /// valid), exactly on the fast path. Never allocates once the configuration and step length are cached.
    pub fn step(&mut self, dt_s: f64, env: FvEnvironment) {
        self.core.get_mut().step(dt_s, env);
    }

    /// Skin temperature at `depth_m` \[m\] below the surface \[°C\] ([`FvModel::skin_temperature_at_depth_c`]);
    /// reconstructs the cells (O(cells²)) after fast steps.
    pub fn skin_temperature_at_depth_c(&self, depth_m: f64) -> f64 {
        self.model().skin_temperature_at_depth_c(depth_m)
    }

    /// [`FvModel::touch`]: the object becomes uniform at `object_c` \[°C\] and the environment the object. On the
    /// fast path the contact configuration is made ready here (decomposed on the first touch of an object, with the
    /// factors of the step lengths in use), so the steps that follow do not allocate.
    pub fn touch(&mut self, object_c: f64) -> Result<(), ParamError> {
        let core = self.core.get_mut();
        core.change_state(|m| m.touch(object_c))?;
        core.prepare(FvEnvironment::Object);
        Ok(())
    }

    /// [`FvModel::set_steady_in_air`].
    pub fn set_steady_in_air(&mut self, ambient_c: f64) -> Result<(), ParamError> {
        self.core.get_mut().change_state(|m| m.set_steady_in_air(ambient_c))
    }

    /// [`FvModel::set_steady`].
    pub fn set_steady(&mut self, env: FvEnvironment) -> Result<(), ParamError> {
        self.core.get_mut().change_state(|m| m.set_steady(env))
    }

    /// [`FvModel::set_skin_uniform`].
    pub fn set_skin_uniform(&mut self, temperature_c: f64) -> Result<(), ParamError> {
        self.core.get_mut().change_state(|m| m.set_skin_uniform(temperature_c))
    }

    /// [`FvModel::replace_object`]; the cached contact configurations no longer apply (those in air or on a plate
    /// do).
    pub fn replace_object(&mut self, object: Option<&Material>, config: &FvConfig) -> Result<(), ParamError> {
        let core = self.core.get_mut();
        core.change_state(|m| m.replace_object(object, config))?;
        core.generation += 1;
        core.cells = vec![0.0; core.full.skin_cells() + core.full.object_cells()];
        core.enabled &= core.cells.len() <= MODAL_MAX_CELLS;
        Ok(())
    }

    /// [`FvModel::set_perfusion_scale`]; forgets every cached configuration.
    pub fn set_perfusion_scale(&mut self, scale: f64) -> Result<(), ParamError> {
        self.core.get_mut().change_matrix(|m| m.set_perfusion_scale(scale))
    }

    /// [`FvModel::calibrate_to_surface`]; forgets every cached configuration.
    pub fn calibrate_to_surface(&mut self, ambient_c: f64, surface_c: f64) -> Result<f64, ParamError> {
        self.core
            .get_mut()
            .change_matrix(|m| m.calibrate_to_surface(ambient_c, surface_c))
    }
}

impl PlateCoupled for ModalFv {
    /// Exact for the model's ODE with the plate held over `dt_s`: one dot product over the skin cells once the
    /// plate configuration and the step length are cached.
    fn receptor_affine(&self, dt_s: f64, conductance_w_m2k: f64) -> (f64, f64) {
        let env = FvEnvironment::Plate {
            conductance_w_m2k,
            temperature_c: 0.0,
        };
        let Ok(mut core) = self.core.try_borrow_mut() else {
            // A guard from `model()` is held: the full model is in sync and answers.
            return self.core.borrow().full.receptor_affine(dt_s, conductance_w_m2k);
        };
        if !core.enabled {
            return core.full.receptor_affine(dt_s, conductance_w_m2k);
        }
        let Some(b) = core.activate(env) else {
            return core.full_affine(dt_s, conductance_w_m2k);
        };
        let t = core.step_table(b, dt_s);
        let basis = &core.bases[b];
        let table = &basis.steps[t];
        let offset = dot(&table.row_decay, &core.z) + table.out_const;
        (offset, table.out_input)
    }

    fn step_on_plate(&mut self, dt_s: f64, conductance_w_m2k: f64, plate_c: f64) {
        let env = FvEnvironment::Plate {
            conductance_w_m2k,
            temperature_c: plate_c,
        };
        let core = self.core.get_mut();
        if !core.enabled {
            core.full.step_on_plate(dt_s, conductance_w_m2k, plate_c);
            core.after_full_step(env);
            return;
        }
        core.step(dt_s, env);
    }

    fn receptor_c(&self) -> f64 {
        self.surface_c()
    }
}

impl Core {
    /// Makes `env`'s configuration active ahead of a step (on the fast path).
    fn prepare(&mut self, env: FvEnvironment) {
        if self.enabled {
            let _ = self.activate(env);
        }
    }

    /// The step: on the fast path the modal update in `env`'s configuration, else the full model's.
    fn step(&mut self, dt_s: f64, env: FvEnvironment) {
        let active = if self.enabled { self.activate(env) } else { None };
        let Some(b) = active else {
            self.sync();
            self.full.step(dt_s, env);
            self.after_full_step(env);
            return;
        };
        let input_c = surface_input_c(env);
        let t = self.step_table(b, dt_s);
        let basis = &self.bases[b];
        let table = &basis.steps[t];
        let mut surface_c = basis.surface_input * input_c;
        for (j, z) in self.z.iter_mut().enumerate() {
            *z = table.decay[j] * *z + table.drive[j] + table.drive_input[j] * input_c;
            surface_c += basis.surface_row[j] * *z;
        }
        self.surface_c = surface_c;
        self.env = env;
        self.synced = false;
    }

    /// After a step of the full model: its state is the state.
    fn after_full_step(&mut self, env: FvEnvironment) {
        self.env = env;
        self.active = None;
        self.synced = true;
        self.surface_c = self.full.surface_c();
    }

    /// The affine receptor map from the full model (when no basis can be had).
    fn full_affine(&mut self, dt_s: f64, conductance_w_m2k: f64) -> (f64, f64) {
        self.sync();
        self.active = None;
        self.full.receptor_affine(dt_s, conductance_w_m2k)
    }

    /// Writes the modal state into the full model's cells (and its environment), if it is not there yet.
    fn sync(&mut self) {
        if self.synced {
            return;
        }
        let Some(b) = self.active else {
            self.synced = true;
            return;
        };
        let basis = &self.bases[b];
        let cells = &mut self.cells[..basis.cells];
        for (k, t) in cells.iter_mut().enumerate() {
            *t = dot(&basis.to_cell[k * basis.cells..(k + 1) * basis.cells], &self.z);
        }
        let skin = self.full.skin_cells();
        self.full.load_state(&cells[..skin], &cells[skin..], self.env);
        self.synced = true;
    }

    /// Applies a change of state to the full model (the configuration is kept).
    fn change_state<R>(&mut self, change: impl FnOnce(&mut FvModel) -> Result<R, ParamError>) -> Result<R, ParamError> {
        self.sync();
        let result = change(&mut self.full);
        self.active = None;
        self.env = self.full.environment();
        self.surface_c = self.full.surface_c();
        result
    }

    /// Applies a change of the matrices to the full model and forgets every cached configuration.
    fn change_matrix<R>(
        &mut self,
        change: impl FnOnce(&mut FvModel) -> Result<R, ParamError>,
    ) -> Result<R, ParamError> {
        let result = self.change_state(change);
        self.bases.clear();
        result
    }

    /// Makes the modal state belong to `env`'s configuration (building or reusing its basis, projecting the state);
    /// returns its index, or `None` when no decomposition can be had (the caller uses the full model).
    fn activate(&mut self, env: FvEnvironment) -> Option<usize> {
        let side = self.full.solver_side(env);
        let contact = matches!(side, Side::Contact { .. });
        let g = match side {
            Side::Fixed { g, .. } | Side::Contact { g } => g,
        };
        let generation = if contact { self.generation } else { 0 };
        let key = (contact, g.to_bits(), self.full.perfusion_scale().to_bits(), generation);
        if let Some(b) = self.active.filter(|&b| self.bases[b].key == key) {
            return Some(b);
        }
        self.sync();
        let found = self.bases.iter().position(|basis| basis.key == key);
        let Some(b) = found.or_else(|| self.build_basis(key, side)) else {
            // The decomposition failed (non-finite coefficients): the full model from now on, rather than a failed
            // O(cells³) attempt every step.
            self.enabled = false;
            return None;
        };
        self.project(b);
        Some(b)
    }

    /// Decomposes the configuration and caches it (replacing the oldest beyond [`MAX_BASES`]), with the factors of
    /// the step lengths the other configurations have (the steps that will most likely follow).
    fn build_basis(&mut self, key: BasisKey, side: Side) -> Option<usize> {
        let (skin, object) = self.full.arms();
        let object = if key.0 { object } else { None };
        let mut basis = Basis::new(key, (skin, object), side, self.stepping, self.full.time_scheme())?;
        let known = self.bases.iter().rev().flat_map(|b| b.steps.iter().map(|t| t.h_s));
        for h_s in known.filter(|h| h.is_finite()) {
            let filled = basis.steps.iter().filter(|t| t.h_s.is_finite()).count();
            if filled < MAX_STEP_TABLES && !basis.steps.iter().any(|t| same_step(t.h_s, h_s)) {
                basis.fill_slot(h_s);
            }
        }
        if self.bases.len() >= MAX_BASES {
            self.bases.remove(0);
        }
        self.bases.push(basis);
        self.active = None;
        Some(self.bases.len() - 1)
    }

    /// Projects the full model's state (synced) onto basis `b` and makes it active (the environment is the step's
    /// business: the display inverse projects onto the plate configuration without stepping).
    fn project(&mut self, b: usize) {
        let basis = &self.bases[b];
        let n = basis.cells;
        let skin = self.full.skin_cells();
        self.cells[..skin].copy_from_slice(self.full.skin_temperatures_c());
        if n > skin {
            self.cells[skin..n].copy_from_slice(self.full.object_temperatures_c());
        }
        self.z.resize(n, 0.0);
        for (j, z) in self.z.iter_mut().enumerate() {
            *z = dot(&basis.to_mode[j * n..(j + 1) * n], &self.cells[..n]);
        }
        self.active = Some(b);
        self.synced = true;
    }

    /// The index of the step table of `dt_s` in basis `b`, filling a slot if needed (round-robin, in the storage
    /// allocated with the basis).
    fn step_table(&mut self, b: usize, dt_s: f64) -> usize {
        let basis = &mut self.bases[b];
        if let Some(t) = basis.steps.iter().position(|t| same_step(t.h_s, dt_s)) {
            return t;
        }
        basis.fill_slot(dt_s)
    }
}

/// Whether a step of `a` \[s\] may use the factors of a step of `b` \[s\]: equal to [`SAME_STEP_RELATIVE`]. Tick
/// lengths computed as differences of clock times differ in their last bits (at 1 kHz after 125 h of loop time by
/// up to 1e-7 of the tick); using the factors of `b` for `a` changes a step's result by at most that fraction of the
/// step's change (below 1e-7 °C here, far below the stated bound) and keeps a jittering tick from refilling its
/// factors every tick.
fn same_step(a: f64, b: f64) -> bool {
    (a - b).abs() <= SAME_STEP_RELATIVE * b.abs()
}

impl Basis {
    /// The decomposition of the skin (and, in contact, the object) connected as `side`; `None` if the eigen solver
    /// does not converge.
    fn new(
        key: BasisKey,
        (skin, object): (&Arm, Option<&Arm>),
        side: Side,
        stepping: ModalStepping,
        scheme: TimeScheme,
    ) -> Option<Basis> {
        let chain = Chain::new(skin, object, side);
        let n = chain.capacity.len();
        let scaled_diag: Vec<f64> = (0..n).map(|i| chain.diagonal[i] / chain.capacity[i]).collect();
        let scaled_off: Vec<f64> = (0..n - 1)
            .map(|i| chain.off_diagonal[i] / (chain.capacity[i] * chain.capacity[i + 1]).sqrt())
            .collect();
        let eigen = symmetric_tridiagonal_eigen(&scaled_diag, &scaled_off).ok()?;
        let q = |chain_index: usize, j: usize| eigen.vectors[chain_index * n + j];
        // Cell k of the model (skin surface first, then object face first) is chain index chain.index[k].
        let mut to_cell = vec![0.0; n * n];
        let mut to_mode = vec![0.0; n * n];
        for k in 0..n {
            let ci = chain.index[k];
            let root_c = chain.capacity[ci].sqrt();
            for j in 0..n {
                to_cell[k * n + j] = q(ci, j) / root_c;
                to_mode[j * n + k] = q(ci, j) * root_c;
            }
        }
        let project = |v: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|j| (0..n).map(|ci| q(ci, j) * v[ci] / chain.capacity[ci].sqrt()).sum())
                .collect()
        };
        let forcing = project(&chain.source);
        let input = project(&chain.input);
        let (surface_row, surface_input) = surface_read_out(skin, object, side, &to_cell, n);
        Some(Basis {
            key,
            cells: n,
            rate_per_s: eigen.values,
            to_cell,
            to_mode,
            forcing,
            input,
            surface_row,
            surface_input,
            stepping,
            scheme,
            steps: (0..MAX_STEP_TABLES).map(|_| StepTable::empty(n)).collect(),
            next_slot: 0,
        })
    }

    /// Fills the next slot with the factors of a step of `h` \[s\]; returns its index.
    fn fill_slot(&mut self, h: f64) -> usize {
        let slot = self.next_slot;
        self.next_slot = (slot + 1) % MAX_STEP_TABLES;
        let mut table = std::mem::take(&mut self.steps[slot]);
        self.fill_step_table(h, &mut table);
        self.steps[slot] = table;
        slot
    }

    /// Fills `table` with the exact zero-order-hold factors of a step of `h` \[s\] (no allocation when `table`
    /// already has room for this basis).
    fn fill_step_table(&self, h: f64, table: &mut StepTable) {
        let refill = |v: &mut Vec<f64>, values: &mut dyn Iterator<Item = f64>| {
            v.clear();
            v.extend(values);
        };
        let rates = &self.rate_per_s;
        let factors = |l: f64| mode_factors(self.stepping, self.scheme, l, h);
        refill(&mut table.decay, &mut rates.iter().map(|&l| factors(l).0));
        let phi = |l: f64| factors(l).1;
        refill(
            &mut table.drive,
            &mut rates.iter().zip(&self.forcing).map(|(&l, f)| phi(l) * f),
        );
        refill(
            &mut table.drive_input,
            &mut rates.iter().zip(&self.input).map(|(&l, b)| phi(l) * b),
        );
        table.row_decay.clear();
        table
            .row_decay
            .extend(self.surface_row.iter().zip(&table.decay).map(|(r, a)| r * a));
        table.h_s = h;
        table.out_const = dot(&self.surface_row, &table.drive);
        table.out_input = dot(&self.surface_row, &table.drive_input) + self.surface_input;
    }
}

impl StepTable {
    /// An unused slot with room for `n` modes.
    fn empty(n: usize) -> StepTable {
        let room = || Vec::with_capacity(n);
        StepTable {
            h_s: f64::NAN,
            decay: room(),
            drive: room(),
            drive_input: room(),
            row_decay: room(),
            out_const: 0.0,
            out_input: 0.0,
        }
    }
}

/// The system matrices in chain order: skin deepest cell first … skin surface, then object face … far side.
struct Chain {
    /// C [J/(m²·K)].
    capacity: Vec<f64>,
    /// Diagonal of K [W/(m²·K)].
    diagonal: Vec<f64>,
    /// Off-diagonal of K (negative) [W/(m²·K)].
    off_diagonal: Vec<f64>,
    /// Constant sources s [W/m²].
    source: Vec<f64>,
    /// b: heat per degree of surface input [W/(m²·K)].
    input: Vec<f64>,
    /// Chain index of model cell k (skin surface first, then object face first).
    index: Vec<usize>,
}

impl Chain {
    fn new(skin: &Arm, object: Option<&Arm>, side: Side) -> Chain {
        let ns = skin.len();
        let mut chain = Chain {
            capacity: Vec::new(),
            diagonal: Vec::new(),
            off_diagonal: Vec::new(),
            source: Vec::new(),
            input: Vec::new(),
            index: (0..ns).map(|k| ns - 1 - k).collect(),
        };
        let (side_g, input_g) = match side {
            Side::Fixed { g, .. } => (g, g),
            Side::Contact { g } => (g, 0.0),
        };
        chain.push_arm(skin, side_g, true);
        chain.input[ns - 1] = input_g;
        if let Some(o) = object {
            chain.off_diagonal.push(-side_g);
            chain.push_arm(o, side_g, false);
            chain.index.extend(ns..ns + o.len());
        }
        chain
    }

    /// Appends an arm: reversed (far end first) for the skin, in order for the object.
    fn push_arm(&mut self, arm: &Arm, side_g: f64, reversed: bool) {
        let n = arm.len();
        let cells: Vec<usize> = if reversed {
            (0..n).rev().collect()
        } else {
            (0..n).collect()
        };
        for (pos, &i) in cells.iter().enumerate() {
            let inward = if i + 1 < n { arm.link[i] } else { arm.end_g };
            let outward = if i > 0 { arm.link[i - 1] } else { side_g };
            self.capacity.push(arm.capacity[i]);
            self.diagonal.push(inward + outward + arm.perfusion[i]);
            self.source.push(arm.source[i]);
            self.input.push(0.0);
            if pos + 1 < n {
                let between = if reversed { arm.link[i - 1] } else { arm.link[i] };
                self.off_diagonal.push(-between);
            }
        }
    }
}

/// The receptor read-out: surface = T₀ − q r_half with q the flux out through the surface, as
/// [`FvModel::surface_c`]; returned as (row over the modes, weight of the surface input).
fn surface_read_out(skin: &Arm, object: Option<&Arm>, side: Side, to_cell: &[f64], n: usize) -> (Vec<f64>, f64) {
    let r_half = skin.half_resistance();
    let skin0 = &to_cell[..n];
    match (side, object) {
        (Side::Contact { g }, Some(_)) => {
            let object0 = &to_cell[skin.len() * n..(skin.len() + 1) * n];
            let w = g * r_half;
            let row = skin0.iter().zip(object0).map(|(s, o)| (1.0 - w) * s + w * o).collect();
            (row, 0.0)
        }
        (Side::Fixed { g, .. }, _) | (Side::Contact { g }, None) => {
            let w = g * r_half;
            (skin0.iter().map(|s| (1.0 - w) * s).collect(), w)
        }
    }
}

/// The temperature the surface is connected to in `env` (0 in contact: no input).
fn surface_input_c(env: FvEnvironment) -> f64 {
    match env {
        FvEnvironment::Air { ambient_c } => ambient_c,
        FvEnvironment::Plate { temperature_c, .. } => temperature_c,
        FvEnvironment::Object => 0.0,
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    //! The caches: configurations reused across touch and release, step factors shared by jittering tick lengths,
    //! and the forced-off path.

    use super::*;
    use crate::materials;
    use crate::skin::Skin;

    fn touching_wood() -> ModalFv {
        let wood = materials::find("wood").unwrap();
        let mut model = FvModel::new(&Skin::fingertip(), Some(&wood), &FvConfig::default()).unwrap();
        model.set_steady_in_air(23.0).unwrap();
        ModalFv::new(model)
    }

    fn air() -> FvEnvironment {
        FvEnvironment::Air { ambient_c: 23.0 }
    }

    #[test]
    fn touch_and_release_reuse_two_configurations() {
        let mut fast = touching_wood();
        for _ in 0..5 {
            fast.touch(30.0).unwrap();
            fast.step(0.01, FvEnvironment::Object);
            fast.step(0.01, air());
        }
        let core = fast.core.borrow();
        assert_eq!(core.bases.len(), 2, "air and contact, built once each");
        let used = |b: &Basis| b.steps.iter().filter(|t| t.h_s.is_finite()).count();
        assert!(core.bases.iter().all(|b| used(b) == 1), "one step length in each");
    }

    #[test]
    fn jittering_step_lengths_share_their_factors() {
        // Tick lengths computed as differences of clock times: 0.01 ± a few ulps.
        let mut fast = touching_wood();
        let mut jittered = fast.clone();
        for k in 1..200u32 {
            let dt_s = f64::from(k + 1) * 0.01 - f64::from(k) * 0.01;
            jittered.step(dt_s, air());
            fast.step(0.01, air());
        }
        let used = jittered.core.borrow().bases[0]
            .steps
            .iter()
            .filter(|t| t.h_s.is_finite())
            .count();
        assert_eq!(used, 1, "jittered steps filled {used} step tables");
        let difference = (jittered.surface_c() - fast.surface_c()).abs();
        assert!(difference < 1e-12, "jittered vs exact steps differ by {difference} °C");
    }

    #[test]
    fn forced_off_never_builds_a_configuration() {
        let mut fast = touching_wood();
        fast.set_fast_path(false);
        fast.touch(30.0).unwrap();
        fast.step(0.01, FvEnvironment::Object);
        let _ = fast.receptor_affine(0.01, 800.0);
        fast.step_on_plate(0.01, 800.0, 35.0);
        assert!(!fast.fast_path());
        assert!(fast.core.borrow().active.is_none());
    }
}
