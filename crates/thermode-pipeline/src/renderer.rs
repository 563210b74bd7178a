//! The renderer: the controller's model of the finger touching the virtual world, stepped live, whose receptor
//! temperature is the target the display must make the real finger feel.
//!
//! - [`RendererKind::Fv`] (default): the finite-volume finger and object (`model.md` §3) with a light-touch contact
//!   resistance (default [`LIGHT_TOUCH_RESISTANCE_M2K_W`]); the object has its heat capacity, so effusivity counts.
//!   The receptor is the skin surface. Stepped on the modal fast path ([`ModalFv`]: exact in time for the model's
//!   equations, selected automatically for grids of at most `MODAL_MAX_CELLS` cells).
//! - [`RendererKind::Kron`]: the paper's three-layer model (eq. 1–6); the object is held at its temperature and only
//!   its conductivity and thickness count. The receptor is the epidermis centre T1.
//!
//! The finger starts at its steady state in still air at the ambient temperature. A touch puts it on a fresh object
//! (uniform at the object temperature) and keeps the finger's own temperature field; a release returns it to air;
//! a change of material during contact is a new touch of the new material. Stepping never allocates.

use thermode_model::fv::{FvConfig, FvEnvironment, FvModel, ModalFv, ModalStepping};
use thermode_model::kron::{KronEnvironment, KronModel};
use thermode_model::{Material, ParamError, Skin};

/// Contact resistance between skin and a touched object for a light touch [m²K/W]: 1e-3 (`model.md` §3; the
/// paper's participants touched "without exerting pressure").
pub const LIGHT_TOUCH_RESISTANCE_M2K_W: f64 = 1e-3;

/// Which finger model renders (and, through the display inverse, which model runs on the display).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RendererKind {
    /// The paper's three-layer model (Kron).
    Kron,
    /// The finite-volume reference (default; physics-true).
    #[default]
    Fv,
}

impl RendererKind {
    /// The name used on the command line and in files: `kron` or `fv`.
    pub fn name(self) -> &'static str {
        match self {
            RendererKind::Kron => "kron",
            RendererKind::Fv => "fv",
        }
    }

    /// Where this kind's receptor lies below the skin surface of `skin` \[m\]: half the first layer's
    /// thickness for the kron renderer (T1, the centre of the epidermis, Δx₁/2), 0 (the surface) for the fv
    /// renderer. Fingers compared with this kind's target are read at this depth.
    pub fn receptor_depth_m(self, skin: &Skin) -> f64 {
        match self {
            RendererKind::Kron => skin.layers.first().map_or(0.0, |epidermis| 0.5 * epidermis.thickness_m),
            RendererKind::Fv => 0.0,
        }
    }
}

/// The finite-volume grid of renderer and display inverse: [`FvConfig::default`] with the light-touch contact
/// resistance `contact_resistance_m2k_w` [m²K/W].
pub fn fv_config(contact_resistance_m2k_w: f64) -> FvConfig {
    FvConfig {
        contact_resistance_m2k_w,
        ..FvConfig::default()
    }
}

/// A finger model touching the virtual world, stepped live.
#[derive(Debug, Clone)]
// One per channel, stepped every tick: the size difference costs nothing, a box would cost an indirection.
#[allow(clippy::large_enum_variant)]
pub enum Renderer {
    /// The three-layer model and what its epidermis exchanges heat with.
    Kron {
        /// The model.
        model: KronModel,
        /// Air or the touched object.
        env: KronEnvironment,
        /// Air temperature \[°C\].
        ambient_c: f64,
    },
    /// The finite-volume finger (with the touched object once touched).
    Fv {
        /// The model, on the modal fast path where it applies.
        model: ModalFv,
        /// Air or the object.
        env: FvEnvironment,
        /// The grid and contact resistance used for every touched object.
        config: FvConfig,
        /// Air temperature \[°C\].
        ambient_c: f64,
        /// The material of the object the model holds now (`None` before the first touch).
        material: Option<Material>,
    },
}

impl Renderer {
    /// A renderer of `kind` for `skin`, at rest in still air at `ambient_c` \[°C\]; the fv renderer uses `config`
    /// (grid, contact resistance) for every object it touches.
    pub fn new(kind: RendererKind, skin: &Skin, ambient_c: f64, config: &FvConfig) -> Result<Self, ParamError> {
        let air_kron = KronEnvironment::Air { ambient_c };
        air_kron.validate("renderer")?;
        match kind {
            RendererKind::Kron => {
                let mut model = KronModel::new(skin)?;
                model.settle(&air_kron);
                Ok(Renderer::Kron {
                    model,
                    env: air_kron,
                    ambient_c,
                })
            }
            RendererKind::Fv => {
                let mut model = FvModel::new(skin, None, config)?;
                model.set_steady_in_air(ambient_c)?;
                Ok(Renderer::Fv {
                    model: ModalFv::new(model),
                    env: FvEnvironment::Air { ambient_c },
                    config: config.clone(),
                    ambient_c,
                    material: None,
                })
            }
        }
    }

    /// The finger lets go: from now on it is in still air at the ambient temperature.
    pub fn release(&mut self) {
        match self {
            Renderer::Kron { env, ambient_c, .. } => *env = KronEnvironment::Air { ambient_c: *ambient_c },
            Renderer::Fv { env, ambient_c, .. } => *env = FvEnvironment::Air { ambient_c: *ambient_c },
        }
    }

    /// The finger touches a fresh object of `material` at `object_c` \[°C\], keeping its own temperature field.
    /// Errors leave the renderer unchanged (a material the model refuses, an object grid that is too large).
    pub fn touch(&mut self, material: &Material, object_c: f64) -> Result<(), ParamError> {
        match self {
            Renderer::Kron { env, .. } => {
                let touched = KronEnvironment::touching(material, object_c);
                touched.validate(&format!("material `{}`", material.name))?;
                *env = touched;
            }
            Renderer::Fv {
                model,
                env,
                config,
                material: held,
                ..
            } => {
                if held.as_ref() != Some(material) {
                    model.replace_object(Some(material), config)?;
                    *held = Some(material.clone());
                }
                model.touch(object_c)?;
                *env = FvEnvironment::Object;
            }
        }
        Ok(())
    }

    /// Puts the fv renderer on the modal fast path with `stepping` (where the grid allows it; the default is
    /// [`ModalStepping::Exact`]) or, with `None`, off it (the full model steps every tick). No effect on the kron
    /// renderer.
    pub fn set_fv_fast_path(&mut self, stepping: Option<ModalStepping>) {
        if let Renderer::Fv { model, .. } = self {
            model.set_stepping(stepping.unwrap_or_default());
            model.set_fast_path(stepping.is_some());
        }
    }

    /// Advances the finger by `dt_s` \[s\] (finite and positive; the caller checks). Never allocates once a
    /// configuration (air, or contact with the touched object) and the step length are cached (see [`ModalFv`]).
    pub fn step(&mut self, dt_s: f64) {
        match self {
            Renderer::Kron { model, env, .. } => model.step(dt_s, env),
            Renderer::Fv { model, env, .. } => model.step(dt_s, *env),
        }
    }

    /// The receptor temperature now \[°C\]: the target skin temperature.
    pub fn receptor_c(&self) -> f64 {
        match self {
            Renderer::Kron { model, .. } => model.temperatures_c()[0],
            Renderer::Fv { model, .. } => model.surface_c(),
        }
    }

    /// The skin temperature at `depth_m` \[m\] below the surface \[°C\]: for the fv renderer
    /// [`FvModel::skin_temperature_at_depth_c`] (the surface at depth 0, [`Self::receptor_c`]); the three-layer
    /// model has one node per layer, so the kron renderer reads its receptor T1 whatever the depth.
    pub fn skin_temperature_at_depth_c(&self, depth_m: f64) -> f64 {
        match self {
            Renderer::Kron { .. } => self.receptor_c(),
            Renderer::Fv { model, .. } => model.skin_temperature_at_depth_c(depth_m),
        }
    }

    /// Whether the finger touches an object.
    pub fn in_contact(&self) -> bool {
        match self {
            Renderer::Kron { env, .. } => matches!(env, KronEnvironment::Object { .. }),
            Renderer::Fv { env, .. } => *env == FvEnvironment::Object,
        }
    }

    /// Which model renders.
    pub fn kind(&self) -> RendererKind {
        match self {
            Renderer::Kron { .. } => RendererKind::Kron,
            Renderer::Fv { .. } => RendererKind::Fv,
        }
    }
}

#[cfg(test)]
mod tests {
    //! The fv renderer on its fast path against the full model it replaces, over a touch, a release and a touch of
    //! another material.

    use super::*;

    /// The receptor trace of an fv renderer with `stepping` at a `dt_s` tick over touch aluminium (0.3 s), release
    /// (0.2 s), touch wood (0.3 s).
    fn trace(stepping: Option<ModalStepping>, dt_s: f64) -> Vec<f64> {
        let config = fv_config(LIGHT_TOUCH_RESISTANCE_M2K_W);
        let mut renderer = Renderer::new(RendererKind::Fv, &Skin::fingertip(), 23.0, &config).unwrap();
        renderer.set_fv_fast_path(stepping);
        let material = |name: &str| thermode_model::materials::find(name).unwrap();
        let mut out = Vec::new();
        let ticks = |s: f64| (s / dt_s).round() as usize;
        let mut run = |renderer: &mut Renderer, n: usize| {
            for _ in 0..n {
                renderer.step(dt_s);
                out.push(renderer.receptor_c());
            }
        };
        renderer.touch(&material("aluminium"), 23.0).unwrap();
        run(&mut renderer, ticks(0.3));
        renderer.release();
        run(&mut renderer, ticks(0.2));
        renderer.touch(&material("wood"), 30.0).unwrap();
        run(&mut renderer, ticks(0.3));
        out
    }

    fn largest_difference(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
    }

    #[test]
    fn scheme_stepping_keeps_the_full_models_targets() {
        let (full, scheme) = (trace(None, 0.01), trace(Some(ModalStepping::Scheme), 0.01));
        let difference = largest_difference(&full, &scheme);
        assert!(
            difference < 1e-9,
            "scheme-matched fast path vs full model: {difference} °C"
        );
    }

    #[test]
    fn exact_stepping_is_within_the_bound_of_the_full_model_at_a_1_ms_tick() {
        // At 1 ms the full model's own time error (TR-BDF2, one step per tick) is about 1.3e-3 °C just after a touch.
        let (full, exact) = (trace(None, 0.001), trace(Some(ModalStepping::Exact), 0.001));
        let difference = largest_difference(&full, &exact);
        assert!(
            difference <= 0.005,
            "exact fast path vs full model at 1 ms: {difference} °C (bound 0.005)"
        );
    }
}
