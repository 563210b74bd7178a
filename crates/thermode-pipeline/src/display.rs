//! The display inverse of one channel (paper eq. 7, `model.md` §2) over the finger model that matches the renderer:
//! the three-layer model for the kron renderer, the finite-volume finger for the fv renderer.
//!
//! The device file's `contact_conductance_w_m2k` is the physical skin-surface-to-plate conductance. The fv finger's
//! receptor is the skin surface, so it sees that value itself; the Kron finger's receptor is the epidermis centre T1,
//! so the outer half of the epidermis lies in series ([`PlateFinger::receptor_conductance_w_m2k`]).

use thermode_device::PlateFinger;
use thermode_model::fv::{FvConfig, FvEnvironment, FvModel, ModalFv, ModalStepping};
use thermode_model::inverse::DisplayInverse;
use thermode_model::kron::{KronEnvironment, KronModel};
use thermode_model::{ParamError, Skin};

use crate::renderer::RendererKind;

/// The finger-on-display model and its display inverse.
#[derive(Debug, Clone)]
// One per channel, stepped every tick: the size difference costs nothing, a box would cost an indirection.
#[allow(clippy::large_enum_variant)]
pub enum DisplayFinger {
    /// The three-layer finger (kron renderer).
    Kron(DisplayInverse<KronModel>),
    /// The finite-volume finger (fv renderer), on the modal fast path where it applies ([`ModalFv`]).
    Fv(DisplayInverse<ModalFv>),
}

impl DisplayFinger {
    /// The finger model matching `kind` for `skin`, at rest in still air at `ambient_c` \[°C\] (the finger was in air
    /// before it was put on the display), coupled to the plate through the physical skin-to-plate contact
    /// conductance `surface_contact_w_m2k` [W/(m²·K)]. The fv finger uses the grid of `config` (no object).
    pub fn new(
        kind: RendererKind,
        skin: &Skin,
        ambient_c: f64,
        surface_contact_w_m2k: f64,
        config: &FvConfig,
    ) -> Result<Self, ParamError> {
        match kind {
            RendererKind::Kron => {
                let mut model = KronModel::new(skin)?;
                let air = KronEnvironment::Air { ambient_c };
                air.validate("display finger")?;
                model.settle(&air);
                let g = model.receptor_conductance_w_m2k(surface_contact_w_m2k);
                Ok(DisplayFinger::Kron(DisplayInverse::new(model, g)?))
            }
            RendererKind::Fv => {
                let mut model = FvModel::new(skin, None, config)?;
                model.set_steady_in_air(ambient_c)?;
                let g = model.receptor_conductance_w_m2k(surface_contact_w_m2k);
                let mut model = ModalFv::new(model);
                model.prepare(FvEnvironment::Plate {
                    conductance_w_m2k: g,
                    temperature_c: ambient_c,
                });
                Ok(DisplayFinger::Fv(DisplayInverse::new(model, g)?))
            }
        }
    }

    /// Puts the fv finger on the modal fast path with `stepping` (where the grid allows it; the default is
    /// [`ModalStepping::Exact`]) or, with `None`, off it (the full model steps every tick). No effect on the Kron
    /// finger.
    pub fn set_fv_fast_path(&mut self, stepping: Option<ModalStepping>) {
        if let DisplayFinger::Fv(inverse) = self {
            let (fast, current) = (inverse.model().fast_path(), inverse.model().stepping());
            if fast != stepping.is_some() || (fast && Some(current) != stepping) {
                let mut model = inverse.model().clone();
                model.set_stepping(stepping.unwrap_or_default());
                model.set_fast_path(stepping.is_some());
                model.prepare(FvEnvironment::Plate {
                    conductance_w_m2k: inverse.conductance_w_m2k(),
                    temperature_c: model.surface_c(),
                });
                if let Ok(switched) = DisplayInverse::new(model, inverse.conductance_w_m2k()) {
                    *inverse = switched;
                }
            }
        }
    }

    /// The display set-point \[°C\] that brings the receptor to `target_c` \[°C\] at the end of a step of `dt_s` \[s\]
    /// (unlimited; NaN for a step that is not finite and positive).
    pub fn setpoint_c(&self, target_c: f64, dt_s: f64) -> f64 {
        match self {
            DisplayFinger::Kron(inverse) => inverse.setpoint_c(target_c, dt_s),
            DisplayFinger::Fv(inverse) => inverse.setpoint_c(target_c, dt_s),
        }
    }

    /// Advances the finger by `dt_s` \[s\] with the plate at `plate_c` \[°C\] (what the finger really receives).
    pub fn advance(&mut self, dt_s: f64, plate_c: f64) {
        match self {
            DisplayFinger::Kron(inverse) => inverse.advance(dt_s, plate_c),
            DisplayFinger::Fv(inverse) => inverse.advance(dt_s, plate_c),
        }
    }

    /// The receptor temperature of the finger on the display now \[°C\].
    pub fn receptor_c(&self) -> f64 {
        match self {
            DisplayFinger::Kron(inverse) => inverse.receptor_c(),
            DisplayFinger::Fv(inverse) => inverse.receptor_c(),
        }
    }

    /// Conductance between the receptor node and the plate per area [W/(m²·K)].
    pub fn receptor_conductance_w_m2k(&self) -> f64 {
        match self {
            DisplayFinger::Kron(inverse) => inverse.conductance_w_m2k(),
            DisplayFinger::Fv(inverse) => inverse.conductance_w_m2k(),
        }
    }
}
