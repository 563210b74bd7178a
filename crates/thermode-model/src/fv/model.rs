//! [`FvModel`]: the finite-volume finger (and optional object) with its state, stepping, steady states,
//! calibration, energy bookkeeping and the display-inverse interface.
//!
//! The display inverse uses that a step on a plate is linear: the next skin state is
//! `M⁻¹(C·T + h·b₀) + T_d·s`, where the sensitivity `s` (every cell's response to a unit plate temperature) depends
//! only on the step, the conductance, the scheme and the grid. `s` is cached per (step, conductance), so
//! [`PlateCoupled::receptor_affine`] costs one step (the offset, plate at 0 °C), and a
//! [`PlateCoupled::step_on_plate`] right after it with the same step and conductance costs no solve at all.

use std::cell::RefCell;

use super::chain::{Arm, Bodies, Side, StepFlows, Work};
use super::grid::{centres_m, stack_cells, SizeRule, MAX_CELLS};
use super::{DeepBoundary, FarSide, FvConfig, FvEnvironment, TimeScheme, ORIGIN};
use crate::error::{At, ParamError};
use crate::inverse::PlateCoupled;
use crate::limits;
use crate::materials::Material;
use crate::params::Rule;
use crate::skin::Skin;

/// Heat that crossed each boundary since the model was built or the ledger reset [J/m²], integrated consistently
/// with the time-stepping scheme, so that
/// `Δ skin energy = perfusion + metabolic + deep_in − skin_surface_out` and
/// `Δ object energy = object_contact_in + object_far_side_in` hold to rounding.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EnergyLedger {
    /// Heat brought by perfusion, Σ ω ρ_b c_b Δx (T_art − T) integrated [J/m²] (negative when tissue is above T_art).
    pub perfusion_j_m2: f64,
    /// Metabolic heat, Σ q_m Δx integrated [J/m²].
    pub metabolic_j_m2: f64,
    /// Heat into the skin through the deep boundary [J/m²] (0 when insulated).
    pub deep_in_j_m2: f64,
    /// Heat out of the skin through its surface, to air, plate or object [J/m²].
    pub skin_surface_out_j_m2: f64,
    /// Heat into the object through its contact face [J/m²].
    pub object_contact_in_j_m2: f64,
    /// Heat into the object through its far side [J/m²] (0 when insulated).
    pub object_far_side_in_j_m2: f64,
}

impl EnergyLedger {
    fn record(&mut self, flows: StepFlows) {
        self.perfusion_j_m2 += flows.skin.perfusion;
        self.metabolic_j_m2 += flows.skin.metabolic;
        self.deep_in_j_m2 += flows.skin.end_in;
        self.skin_surface_out_j_m2 -= flows.skin.side_in;
        self.object_contact_in_j_m2 += flows.object.side_in;
        self.object_far_side_in_j_m2 += flows.object.end_in;
    }
}

/// A scalar's values \[unit\] and rates \[unit/s\] at both ends of a step, for cubic Hermite interpolation.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Ends {
    pub start: f64,
    pub end: f64,
    pub start_rate: f64,
    pub end_rate: f64,
}

impl Ends {
    fn constant(value: f64) -> Self {
        Ends {
            start: value,
            end: value,
            start_rate: 0.0,
            end_rate: 0.0,
        }
    }

    /// The cubic Hermite interpolant at `theta` ∈ \[0, 1\] of a step of `step_s` \[s\].
    pub fn at(&self, theta: f64, step_s: f64) -> f64 {
        let [h00, h10, h01, h11] = hermite_weights(theta, step_s);
        h00 * self.start + h01 * self.end + h10 * self.start_rate + h11 * self.end_rate
    }
}

/// The cubic Hermite weights of (start value, start rate, end value, end rate) at `theta` of a step of `step_s`
/// \[s\] (the rate weights include the step).
fn hermite_weights(theta: f64, step_s: f64) -> [f64; 4] {
    let (t2, t3) = (theta * theta, theta * theta * theta);
    [
        2.0 * t3 - 3.0 * t2 + 1.0,
        (t3 - 2.0 * t2 + theta) * step_s,
        -2.0 * t3 + 3.0 * t2,
        (t3 - t2) * step_s,
    ]
}

/// What a contact run records, at both ends of the last adaptive step (see [`FvModel::last_step_ends`]).
#[derive(Debug, Clone)]
pub(super) struct StepEnds {
    /// Temperature of the skin's surface cell \[°C\].
    pub skin0: Ends,
    /// Temperature of the object's contact cell \[°C\].
    pub object0: Ends,
    /// Heat Σ C·T of every skin layer \[J/m²\].
    pub layer_heat: Vec<Ends>,
    /// Capacity Σ C of every skin layer \[J/(m²·K)\].
    pub layer_capacity: Vec<f64>,
}

impl StepEnds {
    pub fn new(layers: usize) -> Self {
        StepEnds {
            skin0: Ends::default(),
            object0: Ends::default(),
            layer_heat: vec![Ends::default(); layers],
            layer_capacity: vec![0.0; layers],
        }
    }
}

/// The finite-volume finger, optionally with a touched object. See the [module documentation](super).
///
/// A new model is uniform at the arterial temperature, in air at that temperature; set an initial state with
/// [`set_steady`](Self::set_steady), [`set_steady_in_air`](Self::set_steady_in_air),
/// [`set_skin_uniform`](Self::set_skin_uniform) or [`calibrate_to_surface`](Self::calibrate_to_surface).
#[derive(Debug, Clone)]
pub struct FvModel {
    skin: Arm,
    object: Option<Arm>,
    contact_resistance_m2k_w: f64,
    air_convection_w_m2k: f64,
    scheme: TimeScheme,
    skin_t: Vec<f64>,
    object_t: Vec<f64>,
    env: FvEnvironment,
    ledger: EnergyLedger,
    perfusion_scale: f64,
    layer_count: usize,
    work: RefCell<Work>,
    plate: RefCell<PlateCache>,
}

/// The display-inverse cache: the plate sensitivity for one (step, conductance) and the offset step from the current
/// state. Preallocated; refilling it never allocates.
#[derive(Debug, Clone)]
struct PlateCache {
    /// (`dt_s`, `conductance_w_m2k`) as bits, that the sensitivity belongs to; `None` when nothing is cached.
    key: Option<[u64; 2]>,
    /// Response of every skin cell to a unit plate temperature over one step [K/K].
    sensitivity: Vec<f64>,
    /// Heat flows of the step per degree of plate temperature [J/(m²·K)].
    flow_slope: StepFlows,
    /// Receptor weights: `surface = cell_weight · T₀(next) + plate_weight · T_d` [1].
    cell_weight: f64,
    plate_weight: f64,
    /// The step from the current state with the plate at 0 °C \[°C\], valid while `offset_key == key`.
    offset: Vec<f64>,
    /// Heat flows of that offset step [J/m²].
    offset_flows: StepFlows,
    /// The key the offset step was made with; `None` when the state or the matrix changed since.
    offset_key: Option<[u64; 2]>,
    /// All zeros: the state the sensitivity is measured from.
    zeros: Vec<f64>,
}

impl PlateCache {
    fn new(skin_cells: usize) -> Self {
        PlateCache {
            key: None,
            sensitivity: vec![0.0; skin_cells],
            flow_slope: StepFlows::default(),
            cell_weight: 0.0,
            plate_weight: 0.0,
            offset: vec![0.0; skin_cells],
            offset_flows: StepFlows::default(),
            offset_key: None,
            zeros: vec![0.0; skin_cells],
        }
    }

    /// Forgets everything (after a change of the matrix).
    fn invalidate(&mut self) {
        self.key = None;
        self.offset_key = None;
    }

    /// Forgets the offset step (after a change of the state).
    fn forget_offset(&mut self) {
        self.offset_key = None;
    }
}

/// The display-inverse cache key of a step of `dt_s` on a plate through `conductance_w_m2k`.
fn plate_key(dt_s: f64, conductance_w_m2k: f64) -> [u64; 2] {
    [dt_s.to_bits(), conductance_w_m2k.to_bits()]
}

impl FvModel {
    /// Builds the grid for `skin` and, if given, the touched `object` (its `thickness_m` is the slab thickness).
    /// Errors if `skin`, `object` or `config` fail their `validate` (non-finite or out-of-range numbers) or the grid
    /// would have more than [`MAX_CELLS`] cells.
    pub fn new(skin: &Skin, object: Option<&Material>, config: &FvConfig) -> Result<Self, ParamError> {
        config.validate()?;
        skin.validate("skin")?;
        if let Some(material) = object {
            material.validate(&format!("material `{}`", material.name))?;
        }
        let rule = SizeRule {
            surface_m: config.surface_cell_m,
            growth: config.growth,
            max_m: config.max_cell_m,
        };
        let skin_arm = skin_arm(skin, rule, config.deep_boundary)?;
        let object_arm = match object {
            Some(material) => Some(object_arm(material, rule, config.far_side, MAX_CELLS - skin_arm.len())?),
            None => None,
        };
        let arterial_c = skin.blood.arterial_c;
        let object_cells = object_arm.as_ref().map_or(0, Arm::len);
        Ok(FvModel {
            skin_t: vec![arterial_c; skin_arm.len()],
            object_t: vec![arterial_c; object_cells],
            work: RefCell::new(Work::new(skin_arm.len(), object_cells)),
            plate: RefCell::new(PlateCache::new(skin_arm.len())),
            skin: skin_arm,
            object: object_arm,
            contact_resistance_m2k_w: config.contact_resistance_m2k_w,
            air_convection_w_m2k: skin.air_convection_w_m2k,
            scheme: config.scheme,
            env: FvEnvironment::Air { ambient_c: arterial_c },
            ledger: EnergyLedger::default(),
            perfusion_scale: 1.0,
            layer_count: skin.layers.len(),
        })
    }

    // ----- grid -----

    /// Number of skin cells.
    pub fn skin_cells(&self) -> usize {
        self.skin.len()
    }

    /// Number of object cells (0 without an object).
    pub fn object_cells(&self) -> usize {
        self.object.as_ref().map_or(0, Arm::len)
    }

    /// Depth of every skin cell centre below the skin surface \[m\], surface cell first.
    pub fn skin_cell_centres_m(&self) -> &[f64] {
        &self.skin.centre_m
    }

    /// Width of every skin cell \[m\], surface cell first.
    pub fn skin_cell_widths_m(&self) -> &[f64] {
        &self.skin.width_m
    }

    /// Index of the skin layer every skin cell belongs to (0 = outermost), surface cell first.
    pub fn skin_cell_layers(&self) -> &[usize] {
        &self.skin.layer
    }

    /// Width of every object cell \[m\], contact cell first (empty without object).
    pub fn object_cell_widths_m(&self) -> &[f64] {
        self.object.as_ref().map_or(&[], |o| &o.width_m)
    }

    /// Distance of every object cell centre from the contact face \[m\], contact cell first (empty without object).
    pub fn object_cell_centres_m(&self) -> &[f64] {
        self.object.as_ref().map_or(&[], |o| &o.centre_m)
    }

    // ----- state -----

    /// Temperature of every skin cell \[°C\], surface cell first.
    pub fn skin_temperatures_c(&self) -> &[f64] {
        &self.skin_t
    }

    /// Temperature of every object cell \[°C\], contact cell first (empty without object).
    pub fn object_temperatures_c(&self) -> &[f64] {
        &self.object_t
    }

    /// The environment of the last step (or the one set by an initialiser or [`Self::set_environment`]).
    pub fn environment(&self) -> FvEnvironment {
        self.env
    }

    /// Declares what the surface is connected to without stepping; it decides [`Self::surface_c`] and the fluxes.
    pub fn set_environment(&mut self, env: FvEnvironment) -> Result<(), ParamError> {
        env.validate()?;
        self.env = env;
        Ok(())
    }

    /// The factor applied to every layer's perfusion (1 unless calibrated or set).
    pub fn perfusion_scale(&self) -> f64 {
        self.perfusion_scale
    }

    /// Multiplies every layer's `perfusion_per_s` by `scale` (≥ 0), as `Skin::with_perfusion_scaled` would.
    pub fn set_perfusion_scale(&mut self, scale: f64) -> Result<(), ParamError> {
        Rule::NonNegative.check("perfusion_scale", scale).at(ORIGIN)?;
        self.perfusion_scale = scale;
        self.skin.set_perfusion_scale(scale);
        self.work.get_mut().invalidate();
        self.plate.get_mut().invalidate();
        Ok(())
    }

    /// Sets every skin cell to `temperature_c` \[°C\].
    pub fn set_skin_uniform(&mut self, temperature_c: f64) -> Result<(), ParamError> {
        Rule::Finite.check("temperature_c", temperature_c).at(ORIGIN)?;
        self.skin_t.iter_mut().for_each(|t| *t = temperature_c);
        self.plate.get_mut().forget_offset();
        Ok(())
    }

    /// Touches the object: it becomes uniform at `object_c` \[°C\] and the environment becomes
    /// [`FvEnvironment::Object`]. Errors if the model has no object or `object_c` is outside
    /// [`limits::OBJECT_TEMPERATURE`].
    pub fn touch(&mut self, object_c: f64) -> Result<(), ParamError> {
        limits::OBJECT_TEMPERATURE
            .rule()
            .check("object_c", object_c)
            .at(ORIGIN)?;
        if self.object.is_none() {
            return Err(ParamError::Invalid {
                origin: ORIGIN.to_string(),
                message: "cannot touch: the model was built without an object".to_string(),
            });
        }
        self.object_t.iter_mut().for_each(|t| *t = object_c);
        self.env = FvEnvironment::Object;
        Ok(())
    }

    /// Replaces the touched object by `object` (or removes it with `None`) while keeping the skin — its grid, its
    /// temperatures, perfusion scale and environment — as it is: the finger that lets go of one object and touches
    /// another keeps its own temperature field (a renderer whose virtual material changes during contact).
    ///
    /// The new object is built as [`FvModel::new`] would build it from `config`: its cells follow `config`'s
    /// cell-width rule, its far side is `config.far_side`, and `config.contact_resistance_m2k_w` becomes the
    /// contact resistance. The skin-side settings of `config` (deep boundary, scheme) are not used. The new object
    /// starts uniform at the arterial temperature; call [`FvModel::touch`] to set its temperature. The energy
    /// ledger keeps its totals, so its object terms no longer balance the new object's energy: reset it if you
    /// check balances across a replacement. Allocates (this is not a per-step operation). Errors, leaving the
    /// model unchanged, if `config` or the material fail their `validate` or the grid would exceed [`MAX_CELLS`].
    pub fn replace_object(&mut self, object: Option<&Material>, config: &FvConfig) -> Result<(), ParamError> {
        config.validate()?;
        let arm = match object {
            Some(material) => {
                material.validate(&format!("material `{}`", material.name))?;
                let rule = SizeRule {
                    surface_m: config.surface_cell_m,
                    growth: config.growth,
                    max_m: config.max_cell_m,
                };
                Some(object_arm(
                    material,
                    rule,
                    config.far_side,
                    MAX_CELLS - self.skin.len(),
                )?)
            }
            None => None,
        };
        let object_cells = arm.as_ref().map_or(0, Arm::len);
        self.object = arm;
        self.object_t = vec![self.skin.arterial_c; object_cells];
        self.contact_resistance_m2k_w = config.contact_resistance_m2k_w;
        self.work = RefCell::new(Work::new(self.skin.len(), object_cells));
        self.plate.get_mut().invalidate();
        Ok(())
    }

    /// Advances the state by `dt_s` \[s\] with the surface in `env`. Never fails and never allocates.
    ///
    /// `dt_s` must be finite and positive and `env` valid ([`FvEnvironment::validate`]); other values give
    /// meaningless (possibly non-finite) temperatures. In [`FvEnvironment::Object`] skin and object are advanced
    /// together; otherwise the object is left as it is.
    pub fn step(&mut self, dt_s: f64, env: FvEnvironment) {
        let scheme = self.scheme;
        self.try_step(env, |bodies, state, next, work| {
            (Some(bodies.advance(scheme, dt_s, state, next, work)), ())
        });
    }

    /// Computes one step in `env` into the work space's next-state buffers with `compute`, and takes it if
    /// `compute` says so. `compute` gets the bodies in `env`, the present (skin, object) state, the (skin, object)
    /// buffers of the next state and the work space; it returns the step's energy flows if the step is to be taken
    /// (`None` leaves the model unchanged) and the value this returns. Never allocates: the buffers go back to the
    /// work space.
    fn try_step<R>(
        &mut self,
        env: FvEnvironment,
        compute: impl FnOnce(&Bodies, (&[f64], &[f64]), (&mut [f64], &mut [f64]), &mut Work) -> (Option<StepFlows>, R),
    ) -> R {
        let side = self.side(env);
        let bodies = Bodies::new(&self.skin, self.object.as_ref(), side);
        let contact = matches!(side, Side::Contact { .. });
        let work = self.work.get_mut();
        let mut next_skin = std::mem::take(&mut work.next_skin);
        let mut next_object = std::mem::take(&mut work.next_object);
        let state = (self.skin_t.as_slice(), self.object_t.as_slice());
        let (flows, result) = compute(&bodies, state, (&mut next_skin, &mut next_object), work);
        if let Some(flows) = flows {
            self.accept(&mut next_skin, &mut next_object, contact, flows, env);
        }
        let work = self.work.get_mut();
        work.next_skin = next_skin;
        work.next_object = next_object;
        result
    }

    /// Takes a computed step: its end state (swapped in; the object's only in contact), energy flows and
    /// environment.
    fn accept(
        &mut self,
        next_skin: &mut Vec<f64>,
        next_object: &mut Vec<f64>,
        contact: bool,
        flows: StepFlows,
        env: FvEnvironment,
    ) {
        std::mem::swap(&mut self.skin_t, next_skin);
        if contact {
            std::mem::swap(&mut self.object_t, next_object);
        }
        self.ledger.record(flows);
        self.env = env;
        self.plate.get_mut().forget_offset();
    }

    /// Attempts one TR-BDF2 step of `dt_s` \[s\] in `env` with the Hosea & Shampine (1996) embedded estimate of
    /// its local error, whatever [`TimeScheme`] the model was built with. The step is taken (state, environment and
    /// energy ledger advance, as with [`Self::step`]) only if the estimate is at most `tolerance_c` \[K\];
    /// otherwise the model is left unchanged. Returns the estimate: the largest over all cells of the filtered
    /// error `(C − d·h·J)⁻¹·h·Σ(b − b̂)ᵢF(Tᵢ)` \[K\]. Never allocates; reuses the cached elimination while the step
    /// and the environment stay bit-identical. `dt_s` and `env` must be valid as for [`Self::step`].
    pub fn step_with_error(&mut self, dt_s: f64, env: FvEnvironment, tolerance_c: f64) -> f64 {
        self.try_step(env, |bodies, state, (next_skin, next_object), work| {
            let next = (&mut *next_skin, &mut *next_object);
            let flows = bodies.advance(TimeScheme::TrBdf2, dt_s, state, next, work);
            let error_c = bodies.tr_bdf2_error(dt_s, state, (next_skin, next_object), work);
            ((error_c <= tolerance_c).then_some(flows), error_c)
        })
    }

    /// Sets `probe`'s state to the cubic Hermite interpolant at `theta` ∈ \[0, 1\] of the last step of `dt_s`
    /// \[s\] taken by [`Self::step_with_error`] (its start state and F(T₀), its end state and F(T₁)): fourth-order
    /// accurate in the step, one order above the step's local error. `probe` must be a clone of this model (same
    /// grid); its environment becomes this model's.
    pub(super) fn interpolate_last_step(&self, theta: f64, dt_s: f64, probe: &mut FvModel) {
        let work = self.work.borrow();
        let [h00, h10, h01, h11] = hermite_weights(theta, dt_s);
        let hermite = |out: &mut [f64], start: &[f64], end: &[f64], f0: &[f64], f1: &[f64], capacity: &[f64]| {
            for i in 0..out.len() {
                out[i] = h00 * start[i] + h01 * end[i] + (h10 * f0[i] + h11 * f1[i]) / capacity[i];
            }
        };
        hermite(
            &mut probe.skin_t,
            &work.next_skin,
            &self.skin_t,
            &work.flux_start_skin,
            &work.flux_end_skin,
            &self.skin.capacity,
        );
        if let (FvEnvironment::Object, Some(object)) = (self.env, self.object.as_ref()) {
            hermite(
                &mut probe.object_t,
                &work.next_object,
                &self.object_t,
                &work.flux_start_object,
                &work.flux_end_object,
                &object.capacity,
            );
        }
        probe.env = self.env;
        probe.plate.get_mut().forget_offset();
    }

    /// Number of eliminations (factorisations) of the step matrix since the model was built: a step whose length,
    /// scheme stage and environment equal the previous one's, bit for bit, reuses the cached elimination and adds
    /// none. A diagnostic of step-length hygiene (see [`FvConfig::tolerance_c`](super::FvConfig::tolerance_c)).
    pub fn factorisations(&self) -> usize {
        self.work.borrow().eliminations
    }

    /// Number of skin layers.
    pub(super) fn layer_count(&self) -> usize {
        self.layer_count
    }

    /// The values and rates at both ends of the last step taken by [`Self::step_with_error`] of what a contact run
    /// records: the surface cells of skin and object and the heat Σ C·T of every skin layer.
    pub(super) fn last_step_ends(&self, out: &mut StepEnds) {
        let work = self.work.borrow();
        let capacity = &self.skin.capacity;
        out.skin0 = Ends {
            start: work.next_skin[0],
            end: self.skin_t[0],
            start_rate: work.flux_start_skin[0] / capacity[0],
            end_rate: work.flux_end_skin[0] / capacity[0],
        };
        out.object0 = match (self.env, self.object.as_ref()) {
            (FvEnvironment::Object, Some(object)) => Ends {
                start: work.next_object[0],
                end: self.object_t[0],
                start_rate: work.flux_start_object[0] / object.capacity[0],
                end_rate: work.flux_end_object[0] / object.capacity[0],
            },
            _ => Ends::constant(self.object_t.first().copied().unwrap_or(0.0)),
        };
        out.layer_heat.iter_mut().for_each(|e| *e = Ends::default());
        out.layer_capacity.iter_mut().for_each(|c| *c = 0.0);
        for (i, &layer) in self.skin.layer.iter().enumerate() {
            let heat = &mut out.layer_heat[layer];
            heat.start += capacity[i] * work.next_skin[i];
            heat.end += capacity[i] * self.skin_t[i];
            heat.start_rate += work.flux_start_skin[i];
            heat.end_rate += work.flux_end_skin[i];
            out.layer_capacity[layer] += capacity[i];
        }
    }

    /// Skin surface temperature \[°C\], object face temperature \[°C\] and heat flux out of the skin \[W/m²\]
    /// in the current environment for given temperatures of the surface cells of skin and object \[°C\] (as
    /// [`Self::surface_c`], [`Self::object_face_c`] and [`Self::surface_heat_flux_w_m2`] compute them from the
    /// state).
    pub(super) fn contact_observables(&self, skin0_c: f64, object0_c: f64) -> (f64, f64, f64) {
        let (flux_w_m2, face_c) = match (self.side(self.env), self.object.as_ref()) {
            (Side::Contact { g }, Some(object)) => {
                let q = g * (skin0_c - object0_c);
                (q, object0_c + q * object.half_resistance())
            }
            (Side::Contact { g }, None) => (g * (skin0_c - object0_c), object0_c),
            (Side::Fixed { g, temp_c }, _) => (g * (skin0_c - temp_c), object0_c),
        };
        (skin0_c - flux_w_m2 * self.skin.half_resistance(), face_c, flux_w_m2)
    }

    /// Sets the steady state in `env` (solving the steady tridiagonal system directly). In
    /// [`FvEnvironment::Object`] skin and object are solved together. Errors if `env` is invalid, there is no object
    /// to touch, or no steady state exists (nothing holds the temperature: no perfusion, insulated deep boundary, and
    /// no heat exchange at the surface with a held temperature).
    pub fn set_steady(&mut self, env: FvEnvironment) -> Result<(), ParamError> {
        env.validate()?;
        if env == FvEnvironment::Object && self.object.is_none() {
            return Err(ParamError::Invalid {
                origin: ORIGIN.to_string(),
                message: "no steady state in contact: the model was built without an object".to_string(),
            });
        }
        let side = self.side(env);
        if !self.grounded(side) {
            return Err(ParamError::Invalid {
                origin: ORIGIN.to_string(),
                message: "no steady state: no perfusion, no held deep or far-side temperature and no heat exchange \
                          at the surface"
                    .to_string(),
            });
        }
        let bodies = Bodies::new(&self.skin, self.object.as_ref(), side);
        let object_len = if matches!(side, Side::Contact { .. }) {
            self.object_t.len()
        } else {
            0
        };
        bodies.steady(
            (&mut self.skin_t, &mut self.object_t[..object_len]),
            self.work.get_mut(),
        );
        self.env = env;
        self.plate.get_mut().forget_offset();
        Ok(())
    }

    /// Sets the steady state in air at `ambient_c` \[°C\] (the default initial state of a contact).
    pub fn set_steady_in_air(&mut self, ambient_c: f64) -> Result<(), ParamError> {
        self.set_steady(FvEnvironment::Air { ambient_c })
    }

    /// Calibrates the resting finger: finds the perfusion scale (a factor on every layer's perfusion, bisection to
    /// 1e-9 °C) whose steady state in air at `ambient_c` has the skin surface at `surface_c` \[°C\], and leaves the
    /// model in that state. Returns the scale. Errors, leaving the model unchanged, if the surface temperature cannot
    /// be reached with a scale between 0 and 1e6.
    pub fn calibrate_to_surface(&mut self, ambient_c: f64, surface_c: f64) -> Result<f64, ParamError> {
        limits::check_resting_temperatures(ORIGIN, ambient_c, surface_c)?;
        let saved = (
            self.skin_t.clone(),
            self.object_t.clone(),
            self.env,
            self.perfusion_scale,
        );
        let result = self.bisect_perfusion(ambient_c, surface_c);
        if result.is_err() {
            let (skin_t, object_t, env, scale) = saved;
            self.skin_t = skin_t;
            self.object_t = object_t;
            self.env = env;
            self.plate.get_mut().forget_offset();
            self.set_perfusion_scale(scale)?;
        }
        result
    }

    fn bisect_perfusion(&mut self, ambient_c: f64, target_c: f64) -> Result<f64, ParamError> {
        const MAX_SCALE: f64 = 1e6;
        let at = |model: &mut Self, scale: f64| -> Result<f64, ParamError> {
            model.set_perfusion_scale(scale)?;
            model.set_steady_in_air(ambient_c)?;
            Ok(model.surface_c() - target_c)
        };
        let low_miss = at(self, 0.0)?;
        if low_miss == 0.0 {
            return Ok(0.0);
        }
        let (mut lo, mut hi) = (0.0, 1.0);
        let mut high_miss = at(self, hi)?;
        while high_miss != 0.0 && high_miss.signum() == low_miss.signum() {
            if hi >= MAX_SCALE {
                // Between the surface without perfusion and with the largest perfusion scale, in this air.
                let reachable = Rule::Between {
                    min: low_miss + target_c,
                    max: high_miss + target_c,
                };
                return reachable.check("surface_c", target_c).at(ORIGIN).map(|_| 0.0);
            }
            lo = hi;
            hi *= 2.0;
            high_miss = at(self, hi)?;
        }
        if high_miss == 0.0 {
            return Ok(hi);
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            let miss = at(self, mid)?;
            if miss.abs() < 1e-9 || hi - lo <= 1e-15 * hi {
                return Ok(mid);
            }
            if miss.signum() == high_miss.signum() {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let mid = 0.5 * (lo + hi);
        at(self, mid)?;
        Ok(mid)
    }

    // ----- observables -----

    /// Skin surface temperature \[°C\] — the temperature the receptors see: the face temperature from flux continuity
    /// through the surface half cell (and the contact resistance, air film or plate contact) in the current
    /// environment.
    pub fn surface_c(&self) -> f64 {
        let t0 = self.skin_t[0];
        t0 - self.surface_heat_flux_w_m2() * self.skin.half_resistance()
    }

    /// Skin temperature at `depth_m` \[m\] below the surface \[°C\]: the surface face value ([`Self::surface_c`]) at
    /// depth 0, linear between the surface and the centre of the surface cell and between neighbouring cell centres,
    /// and from the centre of the deepest cell to the bottom face (the held core temperature with
    /// [`DeepBoundary::Core`](super::DeepBoundary::Core), the deepest cell's own temperature when insulated).
    /// Between two centres the line follows the flux: the gradient in each half is the heat flux between the two
    /// cells over that cell's conductivity, so across a layer boundary the profile kinks as steady conduction does;
    /// inside a layer it is plain linear interpolation. Its job includes clamping: a depth below 0 reads the
    /// surface, one beyond the skin's thickness the bottom face. A NaN depth gives NaN. Never allocates.
    pub fn skin_temperature_at_depth_c(&self, depth_m: f64) -> f64 {
        if depth_m.is_nan() {
            return f64::NAN;
        }
        let centres = &self.skin.centre_m;
        let last = centres.len() - 1;
        let thickness_m = centres[last] + 0.5 * self.skin.width_m[last];
        let depth_m = depth_m.clamp(0.0, thickness_m);
        if depth_m <= centres[0] {
            let surface_c = self.surface_c();
            return surface_c + (self.skin_t[0] - surface_c) * depth_m / centres[0];
        }
        if depth_m >= centres[last] {
            let bottom_c = if self.skin.end_g > 0.0 {
                self.skin.end_c
            } else {
                self.skin_t[last]
            };
            let half_m = thickness_m - centres[last];
            return self.skin_t[last] + (bottom_c - self.skin_t[last]) * (depth_m - centres[last]) / half_m;
        }
        // The cell pair whose centres enclose the depth: i = number of centres at or above it, minus one.
        let i = centres.partition_point(|c| *c <= depth_m) - 1;
        let flux_w_m2 = self.skin.link[i] * (self.skin_t[i] - self.skin_t[i + 1]);
        let face_m = centres[i] + 0.5 * self.skin.width_m[i];
        if depth_m <= face_m {
            self.skin_t[i] - flux_w_m2 * (depth_m - centres[i]) / self.skin.conductivity[i]
        } else {
            self.skin_t[i + 1] + flux_w_m2 * (centres[i + 1] - depth_m) / self.skin.conductivity[i + 1]
        }
    }

    /// Temperature of the object's contact face \[°C\] (the object side of the contact resistance), if there is an
    /// object.
    pub fn object_face_c(&self) -> Option<f64> {
        let object = self.object.as_ref()?;
        let q = match self.env {
            FvEnvironment::Object => self.surface_heat_flux_w_m2(),
            _ => 0.0,
        };
        Some(self.object_t[0] + q * object.half_resistance())
    }

    /// Heat flux out of the skin through its surface at the current state [W/m²] (positive when the skin loses heat).
    pub fn surface_heat_flux_w_m2(&self) -> f64 {
        match self.side(self.env) {
            Side::Fixed { g, temp_c } => g * (self.skin_t[0] - temp_c),
            Side::Contact { g } => g * (self.skin_t[0] - self.object_t[0]),
        }
    }

    /// Heat flux into the object through its contact face at the current state [W/m²] (0 when not in contact).
    pub fn object_heat_flux_w_m2(&self) -> f64 {
        match self.side(self.env) {
            Side::Contact { g } => g * (self.skin_t[0] - self.object_t[0]),
            Side::Fixed { .. } => 0.0,
        }
    }

    /// Heat stored in the skin, Σ ρ c Δx T [J/m²] (relative to 0 °C).
    pub fn skin_energy_j_m2(&self) -> f64 {
        self.skin.energy(&self.skin_t)
    }

    /// Heat stored in the object, Σ ρ c Δx T [J/m²] (relative to 0 °C; 0 without object).
    pub fn object_energy_j_m2(&self) -> f64 {
        self.object.as_ref().map_or(0.0, |o| o.energy(&self.object_t))
    }

    /// Heat that crossed each boundary since the model was built or the ledger was reset.
    pub fn energy_ledger(&self) -> EnergyLedger {
        self.ledger
    }

    /// Zeroes the [`EnergyLedger`].
    pub fn reset_energy_ledger(&mut self) {
        self.ledger = EnergyLedger::default();
    }

    /// Capacity-weighted mean temperature of every skin layer \[°C\], outermost first.
    pub fn layer_means_c(&self) -> Vec<f64> {
        let mut heat = vec![0.0; self.layer_count];
        let mut capacity = vec![0.0; self.layer_count];
        for ((layer, c), t) in self.skin.layer.iter().zip(&self.skin.capacity).zip(&self.skin_t) {
            heat[*layer] += c * t;
            capacity[*layer] += c;
        }
        heat.iter().zip(&capacity).map(|(h, c)| h / c).collect()
    }

    // ----- internals -----

    /// The solver's view of an environment: a conductance from the centre of the surface cell.
    fn side(&self, env: FvEnvironment) -> Side {
        let r_half = self.skin.half_resistance();
        match env {
            FvEnvironment::Air { ambient_c } => Side::Fixed {
                g: series(r_half, self.air_convection_w_m2k),
                temp_c: ambient_c,
            },
            FvEnvironment::Plate {
                conductance_w_m2k,
                temperature_c,
            } => Side::Fixed {
                g: series(r_half, conductance_w_m2k),
                temp_c: temperature_c,
            },
            FvEnvironment::Object => match &self.object {
                Some(o) => Side::Contact {
                    g: 1.0 / (r_half + self.contact_resistance_m2k_w + o.half_resistance()),
                },
                None => Side::Fixed { g: 0.0, temp_c: 0.0 },
            },
        }
    }

    /// Whether the steady system is non-singular: some path to a held temperature or perfusion.
    fn grounded(&self, side: Side) -> bool {
        let skin = self.skin.end_g > 0.0 || self.skin.perfusion.iter().any(|p| *p > 0.0);
        let surface = match side {
            Side::Fixed { g, .. } => g > 0.0,
            Side::Contact { .. } => self.object.as_ref().is_some_and(|o| o.end_g > 0.0),
        };
        skin || surface
    }

    /// Makes the display-inverse cache hold the sensitivity for (`dt_s`, `conductance_w_m2k`) and the offset step
    /// from the current state; returns the receptor temperature after one step as `(offset_c, slope)`.
    fn plate_offset(&self, dt_s: f64, conductance_w_m2k: f64) -> (f64, f64) {
        let key = plate_key(dt_s, conductance_w_m2k);
        let mut work = self.work.borrow_mut();
        let cache = &mut *self.plate.borrow_mut();
        let g = series(self.skin.half_resistance(), conductance_w_m2k);
        let on_plate = |plate_c: f64| Bodies::new(&self.skin, None, Side::Fixed { g, temp_c: plate_c });
        if cache.key != Some(key) {
            self.fill_sensitivity(cache, g, dt_s, &mut work);
            cache.key = Some(key);
        }
        if cache.offset_key != Some(key) {
            let (state, offset) = (&self.skin_t, &mut cache.offset);
            cache.offset_flows = on_plate(0.0).advance(self.scheme, dt_s, (state, &[]), (offset, &mut []), &mut work);
            cache.offset_key = Some(key);
        }
        (
            cache.cell_weight * cache.offset[0],
            cache.cell_weight * cache.sensitivity[0] + cache.plate_weight,
        )
    }

    /// The response to a unit plate temperature, as the difference of two steps from the zero state (plate at 1 °C
    /// and at 0 °C: the sources cancel, and from zero the two steps are small, so the difference keeps full
    /// precision), and the receptor weights. Uses the offset buffer as scratch (the caller invalidates it).
    fn fill_sensitivity(&self, cache: &mut PlateCache, g: f64, dt_s: f64, work: &mut Work) {
        let step = |plate_c: f64, out: &mut [f64], work: &mut Work| {
            let bodies = Bodies::new(&self.skin, None, Side::Fixed { g, temp_c: plate_c });
            bodies.advance(self.scheme, dt_s, (&cache.zeros, &[]), (out, &mut []), work)
        };
        let mut flow_slope = step(1.0, &mut cache.sensitivity, work);
        flow_slope.add_scaled(step(0.0, &mut cache.offset, work), -1.0);
        for (s, base) in cache.sensitivity.iter_mut().zip(&cache.offset) {
            *s -= base;
        }
        cache.flow_slope = flow_slope;
        cache.offset_key = None;
        // surface = T₀ − g (T₀ − T_d) r_half (flux continuity through the surface half cell).
        let plate_weight = g * self.skin.half_resistance();
        cache.cell_weight = 1.0 - plate_weight;
        cache.plate_weight = plate_weight;
    }
}

impl PlateCoupled for FvModel {
    /// Exact: the step is linear in the plate temperature. The sensitivity to the plate temperature is cached per
    /// (`dt_s`, `conductance_w_m2k`), so this costs one step on scratch buffers (the offset, plate at 0 °C), which a
    /// following [`step_on_plate`](PlateCoupled::step_on_plate) with the same step and conductance reuses.
    fn receptor_affine(&self, dt_s: f64, conductance_w_m2k: f64) -> (f64, f64) {
        self.plate_offset(dt_s, conductance_w_m2k)
    }

    /// Equal to [`FvModel::step`] in [`FvEnvironment::Plate`] to rounding (state and energy ledger). Right after
    /// [`receptor_affine`](PlateCoupled::receptor_affine) with the same step and conductance (and no change of state
    /// in between) it is the cached offset step plus `plate_c` times the cached sensitivity, without solving;
    /// otherwise it is that plain step (so a caller whose inverse horizon differs from its step, as a renderer
    /// requesting over the sensor period, costs two steps per tick and never refills the cache).
    fn step_on_plate(&mut self, dt_s: f64, conductance_w_m2k: f64, plate_c: f64) {
        let env = FvEnvironment::Plate {
            conductance_w_m2k,
            temperature_c: plate_c,
        };
        let cache = self.plate.get_mut();
        if cache.offset_key != Some(plate_key(dt_s, conductance_w_m2k)) {
            self.step(dt_s, env);
            return;
        }
        let response = cache.offset.iter().zip(&cache.sensitivity);
        for (t, (offset, sensitivity)) in self.skin_t.iter_mut().zip(response) {
            *t = offset + plate_c * sensitivity;
        }
        let mut flows = cache.offset_flows;
        flows.add_scaled(cache.flow_slope, plate_c);
        cache.forget_offset();
        self.ledger.record(flows);
        self.env = env;
    }

    fn receptor_c(&self) -> f64 {
        self.surface_c()
    }
}

/// Conductance of a half cell of resistance `r_half` in series with a conductance `g` [W/(m²·K)] (0 stays 0).
fn series(r_half: f64, g: f64) -> f64 {
    if g > 0.0 {
        1.0 / (r_half + 1.0 / g)
    } else {
        0.0
    }
}

fn skin_arm(skin: &Skin, rule: SizeRule, deep: DeepBoundary) -> Result<Arm, ParamError> {
    let thicknesses: Vec<f64> = skin.layers.iter().map(|l| l.thickness_m).collect();
    let (widths, layer) = stack_cells(rule, &thicknesses, MAX_CELLS)?;
    let blood = skin.blood.density_kg_m3 * skin.blood.specific_heat_j_kgk;
    let props = |f: &dyn Fn(&crate::skin::SkinLayer) -> f64| -> Vec<f64> {
        layer.iter().map(|l| f(&skin.layers[*l])).collect()
    };
    let conductivity = props(&|l| l.conductivity_w_mk);
    let volumetric = props(&|l| l.density_kg_m3 * l.specific_heat_j_kgk);
    let perfusion = props(&|l| l.perfusion_per_s * blood);
    let metabolic = props(&|l| l.metabolic_w_m3);
    let end = match deep {
        DeepBoundary::Insulated => None,
        DeepBoundary::Core { temperature_c } => Some(temperature_c),
    };
    Ok(build_arm(
        widths,
        layer,
        &conductivity,
        &volumetric,
        &perfusion,
        &metabolic,
        skin.blood.arterial_c,
        end,
    ))
}

fn object_arm(material: &Material, rule: SizeRule, far: FarSide, budget: usize) -> Result<Arm, ParamError> {
    let (widths, layer) = stack_cells(rule, &[material.thickness_m], budget)?;
    let n = widths.len();
    let volumetric = material.density_kg_m3 * material.specific_heat_j_kgk;
    let end = match far {
        FarSide::Insulated => None,
        FarSide::Held { temperature_c } => Some(temperature_c),
    };
    let zeros = vec![0.0; n];
    Ok(build_arm(
        widths,
        layer,
        &vec![material.conductivity_w_mk; n],
        &vec![volumetric; n],
        &zeros,
        &zeros,
        0.0,
        end,
    ))
}

/// Assembles an arm from per-cell properties: conductivity [W/(m·K)], ρc [J/(m³·K)], ω ρ_b c_b [W/(m³·K)] and
/// q_m [W/m³]; `end_c` is the held far-end temperature, if any.
#[allow(clippy::too_many_arguments)]
fn build_arm(
    width_m: Vec<f64>,
    layer: Vec<usize>,
    conductivity: &[f64],
    volumetric: &[f64],
    perfusion: &[f64],
    metabolic: &[f64],
    arterial_c: f64,
    end_c: Option<f64>,
) -> Arm {
    let n = width_m.len();
    let per_area = |v: &[f64]| -> Vec<f64> { v.iter().zip(&width_m).map(|(v, w)| v * w).collect() };
    let link = (0..n.saturating_sub(1))
        .map(|i| 1.0 / (0.5 * width_m[i] / conductivity[i] + 0.5 * width_m[i + 1] / conductivity[i + 1]))
        .collect();
    let end_g = end_c.map_or(0.0, |_| 2.0 * conductivity[n - 1] / width_m[n - 1]);
    let mut arm = Arm {
        centre_m: centres_m(&width_m),
        capacity: per_area(volumetric),
        perfusion_base: per_area(perfusion),
        perfusion: vec![0.0; n],
        metabolic: per_area(metabolic),
        source: vec![0.0; n],
        conductivity: conductivity.to_vec(),
        link,
        layer,
        width_m,
        arterial_c,
        end_g,
        end_c: end_c.unwrap_or(0.0),
    };
    arm.set_perfusion_scale(1.0);
    arm
}

/// Access for the modal fast path ([`super::modal`]), kept apart from the stepping code.
impl FvModel {
    /// The skin arm and the object arm (if any).
    pub(crate) fn arms(&self) -> (&Arm, Option<&Arm>) {
        (&self.skin, self.object.as_ref())
    }

    /// The solver's view of `env` (see `side`).
    pub(crate) fn solver_side(&self, env: FvEnvironment) -> Side {
        self.side(env)
    }

    /// The time-stepping scheme.
    pub(crate) fn time_scheme(&self) -> TimeScheme {
        self.scheme
    }

    /// Sets the cell temperatures (the object's only if `object_c` is not empty) and the environment, as a step
    /// would leave them (the energy ledger is not touched).
    pub(crate) fn load_state(&mut self, skin_c: &[f64], object_c: &[f64], env: FvEnvironment) {
        self.skin_t.copy_from_slice(skin_c);
        if !object_c.is_empty() {
            self.object_t.copy_from_slice(object_c);
        }
        self.env = env;
        self.plate.get_mut().forget_offset();
    }
}

#[cfg(test)]
mod plate_cache_tests {
    //! The cached display-inverse step against the plain step in a plate environment (the computation before
    //! caching), and the invalidation of the cache.

    use super::*;

    /// A fingertip with perfusion and metabolic heat in every layer, held at a core temperature below, in its steady
    /// state in air: every source term of the step is active.
    fn busy_finger(scheme: TimeScheme) -> FvModel {
        let mut skin = Skin::fingertip();
        for (i, layer) in skin.layers.iter_mut().enumerate() {
            layer.perfusion_per_s = 0.001 * (i + 1) as f64;
            layer.metabolic_w_m3 = 400.0 * (i + 1) as f64;
        }
        let config = FvConfig {
            deep_boundary: DeepBoundary::Core { temperature_c: 36.0 },
            scheme,
            ..FvConfig::default()
        };
        let mut model = FvModel::new(&skin, None, &config).unwrap();
        model.set_steady_in_air(23.0).unwrap();
        model
    }

    fn plate(conductance_w_m2k: f64, temperature_c: f64) -> FvEnvironment {
        FvEnvironment::Plate {
            conductance_w_m2k,
            temperature_c,
        }
    }

    /// Largest difference over all skin cells [K].
    fn max_cell_difference(a: &FvModel, b: &FvModel) -> f64 {
        let pairs = a.skin_temperatures_c().iter().zip(b.skin_temperatures_c());
        pairs.map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
    }

    /// Largest difference of the ledger entries relative to the largest entry.
    fn ledger_difference(a: EnergyLedger, b: EnergyLedger) -> f64 {
        let fields = |l: EnergyLedger| {
            [
                l.perfusion_j_m2,
                l.metabolic_j_m2,
                l.deep_in_j_m2,
                l.skin_surface_out_j_m2,
            ]
        };
        let (fa, fb) = (fields(a), fields(b));
        let scale = fb.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        fa.iter().zip(&fb).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max) / scale
    }

    /// Runs 200 display-inverse ticks (affine, then the step) beside plain plate steps, with the plate temperature,
    /// and per `schedule` the step and conductance, changing every tick; returns the worst cell and ledger difference
    /// and the worst miss of the affine prediction of the receptor temperature.
    fn run_beside(scheme: TimeScheme, schedule: impl Fn(usize) -> (f64, f64)) -> (f64, f64, f64) {
        let mut cached = busy_finger(scheme);
        let mut plain = cached.clone();
        let (mut cells, mut ledger, mut predicted) = (0.0f64, 0.0f64, 0.0f64);
        for tick in 0..200 {
            let (dt_s, conductance) = schedule(tick);
            let plate_c = 30.0 + 12.0 * (tick as f64 * 0.37).sin();
            let (offset, slope) = cached.receptor_affine(dt_s, conductance);
            cached.step_on_plate(dt_s, conductance, plate_c);
            plain.step(dt_s, plate(conductance, plate_c));
            cells = cells.max(max_cell_difference(&cached, &plain));
            ledger = ledger.max(ledger_difference(cached.energy_ledger(), plain.energy_ledger()));
            predicted = predicted.max((offset + slope * plate_c - plain.surface_c()).abs());
            assert_eq!(cached.environment(), plain.environment());
        }
        (cells, ledger, predicted)
    }

    /// Runs [`run_beside`] for both schemes with `schedule` (tick → (dt, conductance)) and requires the cached path
    /// to equal the plain one to 1e-12 in the cells, the ledger and the affine prediction.
    fn assert_cached_equals_plain(schedule: impl Fn(usize) -> (f64, f64) + Copy) {
        for scheme in [TimeScheme::TrBdf2, TimeScheme::BackwardEuler] {
            let (cells, ledger, predicted) = run_beside(scheme, schedule);
            println!("{scheme:?}: cells {cells:.1e} K, ledger {ledger:.1e} relative, prediction {predicted:.1e} K");
            assert!(
                cells <= 1e-12,
                "{scheme:?}: cached vs plain cell temperatures differ by {cells} K"
            );
            assert!(
                ledger <= 1e-12,
                "{scheme:?}: cached vs plain ledger differs by {ledger} (relative)"
            );
            assert!(
                predicted <= 1e-12,
                "{scheme:?}: affine prediction vs plain step {predicted} K"
            );
        }
    }

    #[test]
    fn cached_plate_steps_equal_plain_plate_steps() {
        assert_cached_equals_plain(|_| (0.01, 2000.0));
    }

    #[test]
    fn changing_step_or_conductance_recomputes_the_sensitivity() {
        // The step and the conductance change often enough that a stale sensitivity (its effect is of the order of
        // the plate temperature times the change of the response, ≫ 1e-12 K) would show.
        let schedule = |tick: usize| {
            let dt_s = if (tick / 3).is_multiple_of(2) { 0.01 } else { 0.025 };
            let conductance = if (tick / 5).is_multiple_of(2) { 2000.0 } else { 800.0 };
            (dt_s, conductance)
        };
        assert_cached_equals_plain(schedule);
    }

    #[test]
    fn cache_keys_follow_step_and_conductance() {
        let mut model = busy_finger(TimeScheme::TrBdf2);
        model.receptor_affine(0.01, 2000.0);
        let key = |m: &FvModel| (m.plate.borrow().key, m.plate.borrow().offset_key);
        assert_eq!(
            key(&model),
            (Some(plate_key(0.01, 2000.0)), Some(plate_key(0.01, 2000.0)))
        );
        let slope_at = |m: &FvModel, dt_s: f64, g: f64| m.receptor_affine(dt_s, g).1;
        let first = slope_at(&model, 0.01, 2000.0);
        let other_step = slope_at(&model, 0.02, 2000.0);
        assert_eq!(key(&model).0, Some(plate_key(0.02, 2000.0)));
        let other_conductance = slope_at(&model, 0.02, 800.0);
        assert_eq!(key(&model).0, Some(plate_key(0.02, 800.0)));
        assert!(
            other_step > first && other_conductance < other_step,
            "slopes: {first} at 0.01 s, {other_step} at 0.02 s, {other_conductance} at 0.02 s and 800 W/(m²K)"
        );
        model.step_on_plate(0.02, 800.0, 30.0);
        assert_eq!(
            key(&model),
            (Some(plate_key(0.02, 800.0)), None),
            "the step used up the offset"
        );
        // An inverse over a longer horizon than the step (a renderer requesting over the sensor period): the step
        // is a plain step and leaves the sensitivity of the horizon cached.
        model.receptor_affine(0.02, 800.0);
        let mut plain = model.clone();
        model.step_on_plate(0.001, 800.0, 30.0);
        plain.step(0.001, plate(800.0, 30.0));
        assert_eq!(key(&model), (Some(plate_key(0.02, 800.0)), None));
        assert_eq!(model.skin_temperatures_c(), plain.skin_temperatures_c());
    }

    #[test]
    fn changes_of_state_or_matrix_between_affine_and_step_are_seen() {
        type Change = fn(&mut FvModel);
        let changes: [(&str, Change); 4] = [
            ("set_skin_uniform", |m| m.set_skin_uniform(31.0).unwrap()),
            ("set_perfusion_scale", |m| m.set_perfusion_scale(3.0).unwrap()),
            ("set_steady", |m| m.set_steady(plate(1500.0, 28.0)).unwrap()),
            ("step", |m| m.step(0.01, plate(2000.0, 40.0))),
        ];
        for (name, change) in changes {
            let mut cached = busy_finger(TimeScheme::TrBdf2);
            cached.receptor_affine(0.01, 2000.0);
            change(&mut cached);
            let mut plain = cached.clone();
            cached.step_on_plate(0.01, 2000.0, 20.0);
            plain.step(0.01, plate(2000.0, 20.0));
            let difference = max_cell_difference(&cached, &plain);
            assert!(
                difference <= 1e-12,
                "{name}: cached vs plain step differ by {difference} K"
            );
        }
    }
}
