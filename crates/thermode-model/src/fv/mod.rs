//! The finite-volume reference contact model (`model.md` §3, beyond the paper).
//!
//! A 1-D model of finger and touched object, per unit area, SI units, temperatures in °C:
//!
//! - **Skin**: the layers of a [`Skin`](crate::Skin) (any number ≥ 1), each split into cells. Per cell: conduction,
//!   capacity ρcΔx, Pennes perfusion ω ρ_b c_b (T_art − T) and the metabolic heat q_m of its layer. Below the last
//!   layer a [`DeepBoundary`]: insulated (default, as in the three-layer model) or a held core temperature.
//! - **Contact**: a resistance R_c ≥ 0 [m²K/W] between skin surface and object (0 = perfect contact).
//! - **Object**: a [`Material`](crate::Material) slab of its thickness, split into cells, starting uniform at the
//!   object temperature at the moment of touch; its far side is a [`FarSide`]: insulated (default) or held.
//! - **Surface environments** ([`FvEnvironment`]): air (convection α from the skin's `air_convection_w_m2k` to an
//!   ambient temperature), the object, or a plate at a temperature through a contact conductance (the finger on the
//!   display; [`FvModel`] implements [`PlateCoupled`](crate::inverse::PlateCoupled)).
//!
//! Cells are fine at the skin surface and at the object's contact face and grow geometrically away from it, never
//! straddling a layer boundary (see [`FvConfig`]). Conductance between neighbouring cells is the series (harmonic)
//! combination of their half cells, so steady conduction through slabs in series is exact. The skin surface
//! temperature — what the receptors see — is the face temperature given by flux continuity through the surface half
//! cell and whatever the surface is connected to: with a flux q leaving the surface cell (centre temperature T₀,
//! width Δx₀, conductivity k₀), `T_surface = T₀ − q·Δx₀/(2k₀)`.
//!
//! Time stepping is implicit, O(cells) per step with a tridiagonal (Thomas) solve and no allocation. The default
//! scheme is TR-BDF2 (a trapezoidal stage to t + γh, γ = 2 − √2, then a BDF2 stage): second order, L-stable — so the
//! jump at the moment of touch is damped as by backward Euler, but the time error falls four-fold when the step is
//! halved — and both stages share one matrix. Backward Euler is available as [`TimeScheme::BackwardEuler`].
//! Both conserve energy exactly: every step reports the heat that crossed each boundary, consistent with the
//! scheme, in an [`EnergyLedger`].
//!
//! Error-controlled adaptive stepping ([`FvModel::step_with_error`], [`FvModel::advance_adaptive`], the default of
//! [`simulate_contact`] through [`FvConfig::tolerance_c`]): every TR-BDF2 step is held to the Hosea & Shampine
//! (1996) embedded estimate of its local error, filtered by the step's own matrix; rows between steps come from the
//! step's cubic Hermite interpolant; step lengths are quantised so that equal steps are equal in bits and reuse
//! the cached elimination (see `adaptive.rs`).
//!
//! [`simulate_contact`] runs one contact on one grid; [`simulate_contact_converged`] refines the grid (and the fixed
//! step, if fixed) until the surface temperature trajectory no longer changes by more than a tolerance, skipping
//! levels that cannot converge.

mod adaptive;
mod chain;
mod grid;
mod modal;
mod model;
mod run;
#[cfg(test)]
mod tests;
mod tridiagonal;

pub use adaptive::StepCounts;
pub use grid::MAX_CELLS;
pub use modal::{ModalFv, ModalStepping, MAX_BASES, MAX_STEP_TABLES, MODAL_MAX_CELLS};
pub use model::{EnergyLedger, FvModel};
pub use run::{
    simulate_contact, simulate_contact_converged, ContactRun, ContactSpec, InitialState, Refinement, Resolution,
};

use crate::error::{At, ParamError};
use crate::limits;
use crate::params::{BadValue, Rule};

const ORIGIN: &str = "fv model";

/// Default local error tolerance of adaptive stepping \[K\] ([`FvConfig::tolerance_c`]).
pub const DEFAULT_TOLERANCE_C: f64 = 2e-5;

/// What lies below the deepest skin layer.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum DeepBoundary {
    /// No heat crosses it (default; consistent with the three-layer model, which has no conduction below layer 3).
    #[default]
    Insulated,
    /// Held at a core temperature \[°C\] (the bottom face of the deepest layer).
    Core {
        /// Core temperature \[°C\].
        temperature_c: f64,
    },
}

/// What lies at the far side of the object (the face away from the finger).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum FarSide {
    /// No heat crosses it (default; an object resting on an insulating support).
    #[default]
    Insulated,
    /// Held at a temperature \[°C\] (e.g. ambient, for an object on a large heat sink).
    Held {
        /// Held temperature \[°C\].
        temperature_c: f64,
    },
}

/// The implicit time-stepping scheme.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum TimeScheme {
    /// TR-BDF2 (default): second order in time, L-stable, two tridiagonal solves per step with one matrix.
    #[default]
    TrBdf2,
    /// Backward Euler: first order in time, L-stable, one tridiagonal solve per step (the scheme of `model.md` §1).
    BackwardEuler,
}

/// What the skin surface is connected to during a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FvEnvironment {
    /// Still air: convection and radiation with the skin's `air_convection_w_m2k` to `ambient_c` \[°C\].
    Air {
        /// Air temperature \[°C\].
        ambient_c: f64,
    },
    /// The object, through the contact resistance (call [`FvModel::touch`] first to set its temperature). A model
    /// built without an object has an insulated surface in this environment.
    Object,
    /// A plate held at `temperature_c` \[°C\] through a contact conductance `conductance_w_m2k` [W/(m²·K)] (the
    /// finger resting on the display).
    Plate {
        /// Finger–plate contact conductance G_d [W/(m²·K)], ≥ 0 (0 = no contact).
        conductance_w_m2k: f64,
        /// Plate temperature \[°C\].
        temperature_c: f64,
    },
}

impl FvEnvironment {
    /// Checks that the numbers are finite, the air in [`limits::AMBIENT_TEMPERATURE`] and the conductance not
    /// negative.
    pub fn validate(&self) -> Result<(), ParamError> {
        match *self {
            FvEnvironment::Air { ambient_c } => limits::AMBIENT_TEMPERATURE
                .rule()
                .check("ambient_c", ambient_c)
                .at(ORIGIN)
                .map(|_| ()),
            FvEnvironment::Object => Ok(()),
            FvEnvironment::Plate {
                conductance_w_m2k,
                temperature_c,
            } => {
                Rule::NonNegative
                    .check("conductance_w_m2k", conductance_w_m2k)
                    .at(ORIGIN)?;
                Rule::Finite
                    .check("temperature_c", temperature_c)
                    .at(ORIGIN)
                    .map(|_| ())
            }
        }
    }
}

/// Grid, boundaries and contact of the finite-volume model.
///
/// With the defaults, the default fingertip (0.5 + 1.5 + 3 mm) gets 31 skin cells and a 1 cm object 41 cells; the
/// first cells are about 10 µm wide.
#[derive(Debug, Clone, PartialEq)]
pub struct FvConfig {
    /// Width of the cells at the skin surface and at the object's contact face \[m\]. Default 1e-5 (10 µm; the early
    /// transient in the skin is only a few tens of µm deep).
    pub surface_cell_m: f64,
    /// Ratio of neighbouring cell widths away from the contact face \[-\], ≥ 1. Default 1.15.
    pub growth: f64,
    /// Largest cell width \[m\], ≥ `surface_cell_m`. Default 5e-4 (0.5 mm).
    pub max_cell_m: f64,
    /// Largest internal time step of [`simulate_contact`] with fixed steps (`tolerance_c` = `None`) \[s\]; an output
    /// interval is split into equal steps no longer than this. Default 0.01 s. ([`FvModel::step`] takes its step
    /// directly.)
    pub max_step_s: f64,
    /// Local error tolerance of the adaptive time stepping of [`simulate_contact`] \[K\]: every TR-BDF2 step is
    /// held to a Hosea–Shampine error estimate (largest over all cells) of at most this, and the output rows are
    /// interpolated between steps. `None` = fixed steps of `max_step_s` (with the chosen `scheme`). Default
    /// `Some(`[`DEFAULT_TOLERANCE_C`]`)`; not changed by [`FvConfig::refined`] (it bounds the time error, which does
    /// not depend on the grid). Adaptive stepping is always TR-BDF2, whatever `scheme` says.
    pub tolerance_c: Option<f64>,
    /// Boundary below the deepest skin layer. Default [`DeepBoundary::Insulated`].
    pub deep_boundary: DeepBoundary,
    /// Boundary at the object's far side. Default [`FarSide::Insulated`].
    pub far_side: FarSide,
    /// Contact resistance R_c between skin surface and object [m²K/W], ≥ 0. Default 0 (perfect contact); about
    /// 1e-3 for a light touch.
    pub contact_resistance_m2k_w: f64,
    /// Time-stepping scheme. Default [`TimeScheme::TrBdf2`].
    pub scheme: TimeScheme,
}

impl Default for FvConfig {
    fn default() -> Self {
        FvConfig {
            surface_cell_m: 1e-5,
            growth: 1.15,
            max_cell_m: 5e-4,
            max_step_s: 0.01,
            tolerance_c: Some(DEFAULT_TOLERANCE_C),
            deep_boundary: DeepBoundary::Insulated,
            far_side: FarSide::Insulated,
            contact_resistance_m2k_w: 0.0,
            scheme: TimeScheme::TrBdf2,
        }
    }
}

impl FvConfig {
    /// The configuration refined `levels` times: each level halves the cell-width rule everywhere (surface width,
    /// growth excess g − 1 and maximum width, so about twice the cells) and halves the largest fixed time step
    /// (`max_step_s`). The adaptive tolerance (`tolerance_c`) is kept: it bounds the time error, which does not
    /// depend on the grid.
    pub fn refined(&self, levels: u32) -> FvConfig {
        let factor = 0.5f64.powi(levels as i32);
        FvConfig {
            surface_cell_m: self.surface_cell_m * factor,
            growth: 1.0 + (self.growth - 1.0) * factor,
            max_cell_m: self.max_cell_m * factor,
            max_step_s: self.max_step_s * factor,
            ..self.clone()
        }
    }

    /// Checks every number: widths and step finite and positive, growth ≥ 1, maximum width ≥ surface width,
    /// contact resistance ≥ 0, held temperatures finite.
    pub fn validate(&self) -> Result<(), ParamError> {
        Rule::Positive.check("surface_cell_m", self.surface_cell_m).at(ORIGIN)?;
        Rule::Positive.check("max_cell_m", self.max_cell_m).at(ORIGIN)?;
        Rule::Positive.check("max_step_s", self.max_step_s).at(ORIGIN)?;
        if let Some(tolerance_c) = self.tolerance_c {
            Rule::Positive.check("tolerance_c", tolerance_c).at(ORIGIN)?;
        }
        Rule::NonNegative
            .check("contact_resistance_m2k_w", self.contact_resistance_m2k_w)
            .at(ORIGIN)?;
        if !(self.growth.is_finite() && self.growth >= 1.0) {
            return Err(bad("growth", self.growth, "must be a finite number of at least 1"));
        }
        if self.max_cell_m < self.surface_cell_m {
            return Err(bad(
                "max_cell_m",
                self.max_cell_m,
                "must not be smaller than surface_cell_m",
            ));
        }
        if let DeepBoundary::Core { temperature_c } = self.deep_boundary {
            Rule::Finite
                .check("deep_boundary.temperature_c", temperature_c)
                .at(ORIGIN)?;
        }
        if let FarSide::Held { temperature_c } = self.far_side {
            Rule::Finite.check("far_side.temperature_c", temperature_c).at(ORIGIN)?;
        }
        Ok(())
    }
}

fn bad(key: &'static str, value: f64, requirement: &'static str) -> ParamError {
    ParamError::bad_value(ORIGIN, BadValue::custom(key, value, requirement))
}
