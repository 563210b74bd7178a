//! The finger resting on the plate: which skin model plays it, and how the physical contact conductance maps to
//! the conductance between that model's receptor node and the plate.
//!
//! [`PlateCoupled`] models exchange heat with the plate as `G·(receptor − plate)` per area. Where the receptor node
//! is the skin surface (the finite-volume finger: its receptor is the surface face temperature) G is the physical
//! skin-to-plate contact conductance h_c = 1/R_c of the device file. Where it is the centre of the epidermis (the
//! three-layer Kron model: T1) the outer half of the epidermis lies in series, as in Kron's own contact
//! conductance 2/(Δx₁/k₁ + Δx_env/k_env): G = 1/(Δx₁/(2k₁) + 1/h_c). [`PlateFinger`] gives that mapping, so both
//! models feel the same physical contact.

use thermode_model::fv::{FvConfig, FvModel, ModalFv};
use thermode_model::inverse::PlateCoupled;
use thermode_model::kron::{KronModel, DEFAULT_AMBIENT_C};
use thermode_model::{ParamError, Skin};

/// The finger of the simulated display by default: the finite-volume finger (the reference physics). To make the
/// paper's three-layer finger the default, change this one line to `pub type DefaultFinger = KronModel;`.
pub type DefaultFinger = FvModel;

/// The default finger: [`DefaultFinger`] for the default fingertip ([`Skin::fingertip`]).
pub fn default_finger() -> Result<DefaultFinger, ParamError> {
    DefaultFinger::fingertip()
}

/// A skin model that can rest on the display plate.
pub trait PlateFinger: PlateCoupled {
    /// The conductance between this model's receptor node and the plate [W/(m²·K)] for a physical skin-surface to
    /// plate contact conductance `surface_contact_w_m2k` [W/(m²·K)].
    fn receptor_conductance_w_m2k(&self, surface_contact_w_m2k: f64) -> f64;

    /// The skin temperature at `depth_m` \[m\] below the skin surface \[°C\], for comparing this finger with a
    /// model whose receptor lies at another depth (the Kron renderer's T1 at the epidermis centre). Default: the
    /// receptor temperature whatever the depth (a model with a single node per layer has no finer read-out); the
    /// finite-volume finger interpolates its cells ([`FvModel::skin_temperature_at_depth_c`]).
    fn temperature_at_depth_c(&self, depth_m: f64) -> f64 {
        let _ = depth_m;
        self.receptor_c()
    }

    /// This model for the default fingertip ([`Skin::fingertip`]), at its steady state in still air at 23 °C.
    fn fingertip() -> Result<Self, ParamError>
    where
        Self: Sized;
}

impl PlateFinger for KronModel {
    fn receptor_conductance_w_m2k(&self, surface_contact_w_m2k: f64) -> f64 {
        let epidermis = &self.skin().layers[0];
        1.0 / (epidermis.thickness_m / (2.0 * epidermis.conductivity_w_mk) + 1.0 / surface_contact_w_m2k)
    }

    /// [`KronModel::new`]: the steady state in still air at 23 °C.
    fn fingertip() -> Result<Self, ParamError> {
        KronModel::new(&Skin::fingertip())
    }
}

impl PlateFinger for FvModel {
    fn receptor_conductance_w_m2k(&self, surface_contact_w_m2k: f64) -> f64 {
        surface_contact_w_m2k
    }

    /// [`FvModel::skin_temperature_at_depth_c`]: the surface at depth 0, linear between cell centres.
    fn temperature_at_depth_c(&self, depth_m: f64) -> f64 {
        self.skin_temperature_at_depth_c(depth_m)
    }

    /// Default grid and scheme, at the steady state in still air at the paper's 23 °C (as the Kron model starts).
    fn fingertip() -> Result<Self, ParamError> {
        let mut finger = FvModel::new(&Skin::fingertip(), None, &FvConfig::default())?;
        finger.set_steady_in_air(DEFAULT_AMBIENT_C)?;
        Ok(finger)
    }
}

impl PlateFinger for ModalFv {
    fn receptor_conductance_w_m2k(&self, surface_contact_w_m2k: f64) -> f64 {
        surface_contact_w_m2k
    }

    /// [`ModalFv::skin_temperature_at_depth_c`] (reconstructs the cells after fast steps).
    fn temperature_at_depth_c(&self, depth_m: f64) -> f64 {
        self.skin_temperature_at_depth_c(depth_m)
    }

    /// The [`FvModel`] fingertip on the modal fast path.
    fn fingertip() -> Result<Self, ParamError> {
        Ok(ModalFv::new(<FvModel as PlateFinger>::fingertip()?))
    }
}

/// No finger: the bare plate, as `thermode identify` measures a display (only the Peltier, the plate, the hot side
/// and the water exchange heat). It couples with zero conductance and has no receptor (NaN).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NoFinger;

impl PlateCoupled for NoFinger {
    fn receptor_affine(&self, _dt_s: f64, _conductance_w_m2k: f64) -> (f64, f64) {
        (0.0, 0.0)
    }

    fn step_on_plate(&mut self, _dt_s: f64, _conductance_w_m2k: f64, _plate_c: f64) {}

    fn receptor_c(&self) -> f64 {
        f64::NAN
    }
}

impl PlateFinger for NoFinger {
    fn receptor_conductance_w_m2k(&self, _surface_contact_w_m2k: f64) -> f64 {
        0.0
    }

    fn fingertip() -> Result<Self, ParamError> {
        Ok(NoFinger)
    }
}
