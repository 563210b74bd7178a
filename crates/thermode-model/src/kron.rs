//! The paper's three-layer skin model (after Kron, paper eq. 1–6; `model.md` §1), stepped by backward Euler.
//!
//! State: T1, T2, T3 \[°C\], the centre temperatures of epidermis, dermis and subcutis. Per unit area:
//!
//! - capacity `C_n = ρ_n c_n Δx_n` [J/(m²·K)];
//! - conductance between layer centres `G_ab = 2 / (Δx_a/k_a + Δx_b/k_b)` [W/(m²·K)] (the paper's K, eq. 1);
//! - heat to the environment `q_env = G_env (T1 − T_env)` [W/m²], where G_env is
//!   - touching an object: `2 / (Δx_1/k_1 + Δx_env/k_env)` with the object's thickness Δx_env and conductivity
//!     k_env (the object is held at T_env: it has no heat capacity in this model, see below),
//!   - in air: the convection coefficient α of the skin (convection plus radiation),
//!   - on a display plate: the finger–display contact conductance G_d, given directly;
//! - balances
//!   `C1 dT1/dt = −q_env + G12 (T2 − T1)`,
//!   `C2 dT2/dt = −G12 (T2 − T1) + G23 (T3 − T2)`,
//!   `C3 dT3/dt = −G23 (T3 − T2) + q_m3 Δx3 + ω_3 ρ_b c_b Δx3 (T_art − T3)`.
//!
//! Each layer's own perfusion and metabolic terms `q_mn Δx_n + ω_n ρ_b c_b Δx_n (T_art − T_n)` are added to its
//! balance, so a skin file may put them anywhere; the default fingertip has them in layer 3 only, which gives
//! exactly the equations above. Written as `dT/dt = C⁻¹(A T + b)`, backward Euler is
//! `(C − hA) T_p = C T_{p−1} + h b_p` (paper eq. 6), solved by the Thomas algorithm on the 3×3 tridiagonal matrix.
//! It is unconditionally stable and first-order accurate in h.
//!
//! **Deviation from the paper, on purpose.** The paper's eq. 2–5 write the inter-layer and contact fluxes as
//! `K (T_b − T_a) / Δx`, dividing by a thickness once more. With K as eq. 1 defines it,
//! `K = 2/(Δx_a/k_a + Δx_b/k_b)` already is a conductance per area [W/(m²·K)], so the extra division gives W/m³
//! where the balance needs W/m²: dimensionally wrong. thermode implements the consistent form above (`model.md` §1).
//!
//! **Known limit.** The touched object has no heat capacity here: only its conductivity and thickness enter, so
//! its density and specific heat (and hence its effusivity) do not matter. The finite-volume model in
//! [`crate::fv`] remedies this.

use crate::error::{At, ParamError};
use crate::inverse::PlateCoupled;
use crate::limits;
use crate::materials::Material;
use crate::params::{BadValue, Rule};
use crate::skin::Skin;

/// Ambient temperature \[°C\] of the paper's experiments (mean 23 °C); the initial state of [`KronModel::new`] is
/// the steady state in air at this temperature.
pub const DEFAULT_AMBIENT_C: f64 = 23.0;

/// What the epidermis exchanges heat with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum KronEnvironment {
    /// Still air at `ambient_c` \[°C\]; the conductance is the skin's `air_convection_w_m2k`.
    Air {
        /// Air temperature \[°C\].
        ambient_c: f64,
    },
    /// An object held at `temperature_c`, conductance `2/(Δx_1/k_1 + thickness_m/conductivity_w_mk)`.
    Object {
        /// Object conductivity k_env [W/(m·K)].
        conductivity_w_mk: f64,
        /// Object thickness Δx_env \[m\].
        thickness_m: f64,
        /// Object temperature T_env \[°C\].
        temperature_c: f64,
    },
    /// A display plate at `temperature_c` through the finger–display contact conductance.
    Plate {
        /// Finger–display contact conductance G_d [W/(m²·K)].
        conductance_w_m2k: f64,
        /// Plate temperature T_d \[°C\].
        temperature_c: f64,
    },
}

impl KronEnvironment {
    /// Touching `material` (its conductivity and thickness) held at `temperature_c` \[°C\].
    pub fn touching(material: &Material, temperature_c: f64) -> Self {
        KronEnvironment::Object {
            conductivity_w_mk: material.conductivity_w_mk,
            thickness_m: material.thickness_m,
            temperature_c,
        }
    }

    /// The environment's temperature T_env \[°C\].
    pub fn temperature_c(&self) -> f64 {
        match *self {
            KronEnvironment::Air { ambient_c } => ambient_c,
            KronEnvironment::Object { temperature_c, .. } | KronEnvironment::Plate { temperature_c, .. } => {
                temperature_c
            }
        }
    }

    /// Checks that the air and the object lie in their physical ranges ([`limits::AMBIENT_TEMPERATURE`],
    /// [`limits::OBJECT_TEMPERATURE`]), a plate temperature is finite, and conductivities, thicknesses and
    /// conductances finite and positive. The model's methods assume a valid environment (an invalid one gives
    /// non-finite temperatures, no panic).
    pub fn validate(&self, origin: &str) -> Result<(), ParamError> {
        match *self {
            KronEnvironment::Air { ambient_c } => limits::AMBIENT_TEMPERATURE
                .rule()
                .check("ambient_c", ambient_c)
                .at(origin)
                .map(drop),
            KronEnvironment::Object {
                conductivity_w_mk,
                thickness_m,
                temperature_c,
            } => {
                Rule::Positive
                    .check("conductivity_w_mk", conductivity_w_mk)
                    .at(origin)?;
                Rule::Positive.check("thickness_m", thickness_m).at(origin)?;
                limits::OBJECT_TEMPERATURE
                    .rule()
                    .check("temperature_c", temperature_c)
                    .at(origin)
                    .map(drop)
            }
            KronEnvironment::Plate {
                conductance_w_m2k,
                temperature_c,
            } => {
                Rule::Positive
                    .check("conductance_w_m2k", conductance_w_m2k)
                    .at(origin)?;
                Rule::Finite.check("temperature_c", temperature_c).at(origin).map(drop)
            }
        }
    }
}

/// A symmetric tridiagonal 3×3 matrix: `diag` on the diagonal, `off[0]` at (1,2) and (2,1), `off[1]` at (2,3) and
/// (3,2).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Tridiagonal3 {
    diag: [f64; 3],
    off: [f64; 2],
}

impl Tridiagonal3 {
    /// Solves `self · x = rhs` by the Thomas algorithm (no pivoting; the matrices here are diagonally dominant).
    fn solve(&self, rhs: [f64; 3]) -> [f64; 3] {
        let [d0, d1, d2] = self.diag;
        let [o0, o1] = self.off;
        let c0 = o0 / d0;
        let r0 = rhs[0] / d0;
        let m1 = d1 - o0 * c0;
        let c1 = o1 / m1;
        let r1 = (rhs[1] - o0 * r0) / m1;
        let m2 = d2 - o1 * c1;
        let x2 = (rhs[2] - o1 * r1) / m2;
        let x1 = r1 - c1 * x2;
        let x0 = r0 - c0 * x1;
        [x0, x1, x2]
    }

    /// `C − h·self` for the diagonal capacity matrix C.
    fn implicit(&self, capacity: [f64; 3], h: f64) -> Tridiagonal3 {
        Tridiagonal3 {
            diag: [0, 1, 2].map(|n| capacity[n] - h * self.diag[n]),
            off: [-h * self.off[0], -h * self.off[1]],
        }
    }

    /// `−self`.
    fn negated(&self) -> Tridiagonal3 {
        Tridiagonal3 {
            diag: self.diag.map(|d| -d),
            off: self.off.map(|o| -o),
        }
    }
}

/// The three-layer skin model with its parameters precomputed and its state [T1, T2, T3] in °C.
#[derive(Debug, Clone, PartialEq)]
pub struct KronModel {
    skin: Skin,
    capacity_j_m2k: [f64; 3],
    g12_w_m2k: f64,
    g23_w_m2k: f64,
    /// Δx_1/k_1 [m²K/W], the epidermis term of the contact conductance.
    epidermis_resistance_m2k_w: f64,
    /// P_n = ω_n ρ_b c_b Δx_n [W/(m²·K)].
    perfusion_w_m2k: [f64; 3],
    /// q_mn Δx_n [W/m²].
    metabolic_w_m2: [f64; 3],
    arterial_c: f64,
    temperatures_c: [f64; 3],
}

impl KronModel {
    /// Builds the model for `skin`, which must be valid and have exactly three layers (outermost first). The state
    /// starts at the steady state in still air at [`DEFAULT_AMBIENT_C`].
    pub fn new(skin: &Skin) -> Result<Self, ParamError> {
        skin.validate("skin")?;
        if skin.layers.len() != 3 {
            return Err(ParamError::Invalid {
                origin: "skin".to_string(),
                message: format!(
                    "the three-layer (Kron) model needs exactly 3 layers, the skin has {}",
                    skin.layers.len()
                ),
            });
        }
        let l = &skin.layers;
        let resistance = |n: usize| l[n].thickness_m / l[n].conductivity_w_mk;
        let blood = skin.blood.density_kg_m3 * skin.blood.specific_heat_j_kgk;
        let mut model = KronModel {
            skin: skin.clone(),
            capacity_j_m2k: [0, 1, 2].map(|n| l[n].density_kg_m3 * l[n].specific_heat_j_kgk * l[n].thickness_m),
            g12_w_m2k: 2.0 / (resistance(0) + resistance(1)),
            g23_w_m2k: 2.0 / (resistance(1) + resistance(2)),
            epidermis_resistance_m2k_w: resistance(0),
            perfusion_w_m2k: [0, 1, 2].map(|n| l[n].perfusion_per_s * blood * l[n].thickness_m),
            metabolic_w_m2: [0, 1, 2].map(|n| l[n].metabolic_w_m3 * l[n].thickness_m),
            arterial_c: skin.blood.arterial_c,
            temperatures_c: [skin.blood.arterial_c; 3],
        };
        model.temperatures_c = model.steady_state_c(&KronEnvironment::Air {
            ambient_c: DEFAULT_AMBIENT_C,
        });
        Ok(model)
    }

    /// The skin the model was built from.
    pub fn skin(&self) -> &Skin {
        &self.skin
    }

    /// Current temperatures [T1, T2, T3] \[°C\].
    pub fn temperatures_c(&self) -> [f64; 3] {
        self.temperatures_c
    }

    /// Sets the state [T1, T2, T3] \[°C\] (e.g. `uniform:C` initial conditions).
    pub fn set_temperatures_c(&mut self, temperatures_c: [f64; 3]) {
        self.temperatures_c = temperatures_c;
    }

    /// Sets the state to the steady state in `env`.
    pub fn settle(&mut self, env: &KronEnvironment) {
        self.temperatures_c = self.steady_state_c(env);
    }

    /// Layer capacities C_n = ρ_n c_n Δx_n [J/(m²·K)].
    pub fn capacities_j_m2k(&self) -> [f64; 3] {
        self.capacity_j_m2k
    }

    /// Inter-layer conductances (G12, G23) [W/(m²·K)].
    pub fn conductances_w_m2k(&self) -> (f64, f64) {
        (self.g12_w_m2k, self.g23_w_m2k)
    }

    /// G_env [W/(m²·K)] for `env`: α in air, `2/(Δx_1/k_1 + Δx_env/k_env)` touching an object, G_d on a plate.
    pub fn env_conductance_w_m2k(&self, env: &KronEnvironment) -> f64 {
        match *env {
            KronEnvironment::Air { .. } => self.skin.air_convection_w_m2k,
            KronEnvironment::Object {
                conductivity_w_mk,
                thickness_m,
                ..
            } => 2.0 / (self.epidermis_resistance_m2k_w + thickness_m / conductivity_w_mk),
            KronEnvironment::Plate { conductance_w_m2k, .. } => conductance_w_m2k,
        }
    }

    /// The linear system `dT/dt = C⁻¹(A T + b)` in `env`, with all perfusion multiplied by `perfusion_factor`.
    fn system(&self, env: &KronEnvironment, perfusion_factor: f64) -> (Tridiagonal3, [f64; 3]) {
        let g_env = self.env_conductance_w_m2k(env);
        let (g12, g23) = (self.g12_w_m2k, self.g23_w_m2k);
        let p = self.perfusion_w_m2k.map(|p| p * perfusion_factor);
        let a = Tridiagonal3 {
            diag: [-(g_env + g12) - p[0], -(g12 + g23) - p[1], -g23 - p[2]],
            off: [g12, g23],
        };
        let source = [0, 1, 2].map(|n| self.metabolic_w_m2[n] + p[n] * self.arterial_c);
        let b = [source[0] + g_env * env.temperature_c(), source[1], source[2]];
        (a, b)
    }

    /// Advances the state by one backward-Euler step of `dt_s` \[s\] in `env`: `(C − hA) T_p = C T_{p−1} + h b`.
    /// Cannot fail; a step that is not a positive finite number leaves the state unchanged.
    pub fn step(&mut self, dt_s: f64, env: &KronEnvironment) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        let (a, b) = self.system(env, 1.0);
        let rhs = [0, 1, 2].map(|n| self.capacity_j_m2k[n] * self.temperatures_c[n] + dt_s * b[n]);
        self.temperatures_c = a.implicit(self.capacity_j_m2k, dt_s).solve(rhs);
    }

    /// The steady state [T1, T2, T3] \[°C\] in `env`: the direct solution of `A T + b = 0`. Does not change the state.
    pub fn steady_state_c(&self, env: &KronEnvironment) -> [f64; 3] {
        self.steady_state_scaled_c(env, 1.0)
    }

    fn steady_state_scaled_c(&self, env: &KronEnvironment, perfusion_factor: f64) -> [f64; 3] {
        let (a, b) = self.system(env, perfusion_factor);
        a.negated().solve(b)
    }

    /// Heat flowing from the skin to the environment now, q_env = G_env (T1 − T_env) [W/m²] (positive = the finger
    /// loses heat).
    pub fn heat_flux_to_env_w_m2(&self, env: &KronEnvironment) -> f64 {
        self.env_conductance_w_m2k(env) * (self.temperatures_c[0] - env.temperature_c())
    }

    /// Heat supplied now by perfusion and metabolism, Σ_n [q_mn Δx_n + ω_n ρ_b c_b Δx_n (T_art − T_n)] [W/m²].
    pub fn body_heat_w_m2(&self) -> f64 {
        (0..3)
            .map(|n| self.metabolic_w_m2[n] + self.perfusion_w_m2k[n] * (self.arterial_c - self.temperatures_c[n]))
            .sum()
    }

    /// Stored heat Σ C_n T_n [J/m²] (relative to 0 °C), for energy balances.
    pub fn stored_energy_j_m2(&self) -> f64 {
        (0..3).map(|n| self.capacity_j_m2k[n] * self.temperatures_c[n]).sum()
    }
}

impl PlateCoupled for KronModel {
    fn receptor_affine(&self, dt_s: f64, conductance_w_m2k: f64) -> (f64, f64) {
        // T_p = M⁻¹(C T_{p−1} + h b₀) + T_d · M⁻¹(h G_d e₁), b₀ the source vector with the plate at 0 °C.
        let env = KronEnvironment::Plate {
            conductance_w_m2k,
            temperature_c: 0.0,
        };
        let (a, b) = self.system(&env, 1.0);
        let m = a.implicit(self.capacity_j_m2k, dt_s);
        let rhs = [0, 1, 2].map(|n| self.capacity_j_m2k[n] * self.temperatures_c[n] + dt_s * b[n]);
        let offset = m.solve(rhs)[0];
        let slope = m.solve([dt_s * conductance_w_m2k, 0.0, 0.0])[0];
        (offset, slope)
    }

    fn step_on_plate(&mut self, dt_s: f64, conductance_w_m2k: f64, plate_c: f64) {
        self.step(
            dt_s,
            &KronEnvironment::Plate {
                conductance_w_m2k,
                temperature_c: plate_c,
            },
        );
    }

    fn receptor_c(&self) -> f64 {
        self.temperatures_c[0]
    }
}

/// Calibrates `skin` to a measured resting surface temperature (the `surface:C` initial condition; the paper
/// measured each subject's initial finger temperature).
///
/// Returns the skin with every layer's perfusion scaled by one factor f such that the steady state of the
/// three-layer model in still air at `ambient_c` \[°C\] has T1 = `surface_c` \[°C\]. T1 rises monotonically with f
/// (more arterial heat), from its value without perfusion (f = 0) towards a limit below T_art (f → ∞, perfused
/// layers at T_art); f is found by bisection on g = f/(1+f) ∈ [0, 1) to machine precision. Errors: non-finite
/// inputs, a skin the model refuses, no perfused layer, ambient not below T_art, or `surface_c` outside the
/// reachable open interval (the message states the interval).
pub fn calibrate_to_surface(skin: &Skin, ambient_c: f64, surface_c: f64) -> Result<Skin, ParamError> {
    const ORIGIN: &str = "surface calibration";
    limits::check_resting_temperatures(ORIGIN, ambient_c, surface_c)?;
    let model = KronModel::new(skin)?;
    if model.perfusion_w_m2k.iter().all(|&p| p == 0.0) {
        return Err(ParamError::Invalid {
            origin: ORIGIN.to_string(),
            message: "the skin has no perfused layer, so its surface temperature cannot be calibrated".to_string(),
        });
    }
    let below_arterial = Rule::Below {
        max: model.arterial_c,
        what: "the arterial temperature [°C]",
    };
    below_arterial.check("ambient_c", ambient_c).at(ORIGIN)?;
    let env = KronEnvironment::Air { ambient_c };
    let t1 = |g: f64| model.steady_state_scaled_c(&env, g / (1.0 - g))[0];
    const G_MAX: f64 = 1.0 - 1e-12;
    let (t_lo, t_hi) = (t1(0.0), t1(G_MAX));
    // Between the surface temperature without perfusion and with unlimited perfusion, for this skin in this air.
    Rule::Between { min: t_lo, max: t_hi }
        .check("surface_c", surface_c)
        .at(ORIGIN)?;
    let (mut lo, mut hi) = (0.0, G_MAX);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if t1(mid) < surface_c {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let g = 0.5 * (lo + hi);
    let reached = t1(g);
    if (reached - surface_c).abs() > 1e-7 {
        return Err(ParamError::bad_value(
            ORIGIN,
            BadValue::custom(
                "surface_c",
                surface_c,
                "could not be reached by the calibration's bisection",
            ),
        ));
    }
    Ok(skin.with_perfusion_scaled(g / (1.0 - g)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fingertip() -> KronModel {
        KronModel::new(&Skin::fingertip()).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn thomas_solve_matches_multiplication() {
        let m = Tridiagonal3 {
            diag: [4.0, -5.0, 3.0],
            off: [1.5, -2.0],
        };
        let x = [0.3, -1.7, 2.9];
        let rhs = [
            m.diag[0] * x[0] + m.off[0] * x[1],
            m.off[0] * x[0] + m.diag[1] * x[1] + m.off[1] * x[2],
            m.off[1] * x[1] + m.diag[2] * x[2],
        ];
        let got = m.solve(rhs);
        for n in 0..3 {
            assert!((got[n] - x[n]).abs() < 1e-14, "x[{n}]: {} vs {}", got[n], x[n]);
        }
    }

    #[test]
    fn default_fingertip_rests_at_32_c_in_room_air() {
        // Independent: series chain α, G12, G23 from the fingertip's numbers, Pennes term in layer 3.
        let skin = Skin::fingertip();
        let l = &skin.layers;
        let r = |n: usize| l[n].thickness_m / l[n].conductivity_w_mk;
        let (g12, g23) = (2.0 / (r(0) + r(1)), 2.0 / (r(1) + r(2)));
        let g_tot = 1.0 / (1.0 / 10.0 + 1.0 / g12 + 1.0 / g23);
        let p = l[2].perfusion_per_s * 1060.0 * 3800.0 * l[2].thickness_m;
        let t3 = (p * 36.8 + g_tot * 23.0) / (p + g_tot);
        let t1 = 23.0 + g_tot * (t3 - 23.0) / 10.0;
        let got = fingertip().temperatures_c();
        assert!((got[0] - t1).abs() < 1e-9, "model T1 {} vs closed form {t1}", got[0]);
        assert!(
            (got[0] - 32.0).abs() < 0.05,
            "fingertip surface {} °C, want about 32 °C",
            got[0]
        );
    }

    #[test]
    fn refuses_skins_without_three_layers() {
        let mut skin = Skin::fingertip();
        skin.layers.pop();
        match KronModel::new(&skin) {
            Err(ParamError::Invalid { message, .. }) => assert!(message.contains("exactly 3"), "{message}"),
            other => panic!("expected Invalid, got {other:?}"),
        }
        let mut skin = Skin::fingertip();
        skin.layers[1].conductivity_w_mk = f64::NAN;
        assert!(matches!(KronModel::new(&skin), Err(ParamError::BadValue { .. })));
    }

    #[test]
    fn non_positive_steps_leave_the_state_alone() {
        let mut model = fingertip();
        let before = model.temperatures_c();
        let env = KronEnvironment::Air { ambient_c: 0.0 };
        for dt in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            model.step(dt, &env);
            assert_eq!(model.temperatures_c(), before, "dt = {dt}");
        }
    }

    #[test]
    fn environment_validation() {
        assert!(KronEnvironment::Air { ambient_c: 23.0 }.validate("t").is_ok());
        let bad = KronEnvironment::Object {
            conductivity_w_mk: 0.0,
            thickness_m: 0.01,
            temperature_c: 23.0,
        };
        assert!(
            matches!(bad.validate("t"), Err(ParamError::BadValue { source, .. }) if source.name == "conductivity_w_mk")
        );
        let bad = KronEnvironment::Plate {
            conductance_w_m2k: 800.0,
            temperature_c: f64::NAN,
        };
        assert!(
            matches!(bad.validate("t"), Err(ParamError::BadValue { source, .. }) if source.name == "temperature_c")
        );
    }
}
