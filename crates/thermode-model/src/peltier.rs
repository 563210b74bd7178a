//! Peltier (thermoelectric) module physics (`model.md` §5): heat flows, voltage and electrical power of a module
//! from its three lumped parameters, the parameters from datasheet values, and the inverse (the current that
//! delivers a wanted heat flow) for feedforward control.
//!
//! Pure physics, shared by the simulated display (the plant) and by model-based controllers.
//!
//! # Conventions
//! - Temperatures are given in °C at the interface and converted to kelvin inside (T = t + 273.15).
//! - **Display-side convention**: the module sits between the display plate and the hot side (the water-cooled
//!   box). A **positive current heats the display**, a negative one cools it. In the textbook form, with the display
//!   as the cold side and the module current i = −I flowing in the cooling direction,
//!   Q_c = S i T_c − ½ i² R − K (T_h − T_c) is the heat pumped *out of* the cold side and
//!   Q_h = S i T_h + ½ i² R − K (T_h − T_c) the heat released *into* the hot side. Hence, with T_d the display and
//!   T_h the hot-side temperature \[K\]:
//!   - heat into the display: `q_d = S I T_d + ½ I² R + K (T_h − T_d)`;
//!   - heat into the hot side: `q_h = −S I T_h + ½ I² R − K (T_h − T_d)`;
//!   - terminal voltage in the direction of I: `V = I R + S (T_d − T_h)`;
//!   - electrical power `P = V I = q_d + q_h` (energy conservation holds exactly in these equations).
//!
//! # Datasheet parameters
//! From (I_max, V_max, Q_max, ΔT_max) quoted at a hot-side temperature T_h, the standard approximations
//! (Thomson effect neglected, temperature-independent material properties) give
//! `S = V_max/T_h`, `R = (T_h − ΔT_max) V_max / (T_h I_max)`, `K = (T_h − ΔT_max) V_max I_max / (2 T_h ΔT_max)`.
//! These reproduce V_max at (I_max, ΔT_max) and zero cooling at (I_max, ΔT_max) exactly; Q_max is not used by them,
//! and the cooling they predict at (I_max, ΔT = 0) is `V_max I_max (T_h + ΔT_max) / (2 T_h)`. For the default
//! miniature module that is 3.30 W against the quoted 3.2 W (+3 %); [`PeltierModule::from_datasheet`] refuses
//! datasheets where the two differ by more than [`QMAX_CONSISTENCY_TOLERANCE`], which catches typing errors.

use crate::error::{At, ParamError};
use crate::params::Rule;

/// Offset between °C and K.
pub const KELVIN_OFFSET: f64 = 273.15;

/// Default hot-side temperature at which datasheet values are quoted \[K\]: 298.15 K (25 °C).
///
/// Why 25 °C and not 50 °C: (1) the quoted miniature-module values are a 25–27 °C set — S = V_max/T_h =
/// 1.9 V/298.15 K = 6.37 mV/K matches the expected ≈ 6.4 mV/K, whereas 323 K would give 5.9 mV/K, and a ΔT_max of
/// 72 K is typical of Bi₂Te₃ at a 25–27 °C hot side (it rises to ≈ 80 K at 50 °C); (2) in the display the hot side
/// sits on a box cooled by water at ambient (23 °C), so 25 °C is close to the operating point and the linearised
/// parameters are evaluated where they are used.
pub const DEFAULT_HOT_SIDE_K: f64 = 298.15;

/// Largest accepted relative difference between the datasheet's Q_max and the Q_max the standard approximations
/// predict from (I_max, V_max, ΔT_max, T_h): 0.3 (30 %). Real datasheets agree to about 3–15 %.
pub const QMAX_CONSISTENCY_TOLERANCE: f64 = 0.3;

/// Datasheet values of a Peltier module. Defaults: the miniature 8×8 mm module of `model.md` §5 (the paper's
/// 8×8×3 mm element): I_max 2.8 A, V_max 1.9 V, Q_max 3.2 W, ΔT_max 72 K at a 25 °C hot side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeltierDatasheet {
    /// Maximum current I_max \[A\] (the current that gives ΔT_max). Default 2.8 A.
    pub imax_a: f64,
    /// Voltage at I_max and ΔT_max, V_max \[V\]. Default 1.9 V.
    pub vmax_v: f64,
    /// Maximum cooling power at I_max and ΔT = 0, Q_max \[W\]. Default 3.2 W. Only checked for consistency.
    pub qmax_w: f64,
    /// Maximum temperature difference at I_max and zero load, ΔT_max \[K\]. Default 72 K.
    pub dtmax_k: f64,
    /// Hot-side temperature at which the values are quoted, T_h \[K\]. Default [`DEFAULT_HOT_SIDE_K`] (298.15 K).
    pub hot_side_k: f64,
}

impl Default for PeltierDatasheet {
    fn default() -> Self {
        PeltierDatasheet {
            imax_a: 2.8,
            vmax_v: 1.9,
            qmax_w: 3.2,
            dtmax_k: 72.0,
            hot_side_k: DEFAULT_HOT_SIDE_K,
        }
    }
}

impl PeltierDatasheet {
    /// The datasheet values (quoted at `hot_side_k` \[K\]) of a module with `module`'s S, R and K — the inverse of
    /// [`PeltierModule::from_datasheet`]: V_max = S T_h; ΔT_max the smaller root of S² (T_h − ΔT)² = 2 R K ΔT;
    /// I_max = S (T_h − ΔT_max)/R; Q_max the predicted value ([`PeltierDatasheet::predicted_qmax_w`]). `None` when
    /// the values give no ΔT_max between 0 and T_h.
    pub fn from_module(module: &PeltierModule, hot_side_k: f64) -> Option<PeltierDatasheet> {
        let (s, r, k, th) = (
            module.seebeck_v_k,
            module.resistance_ohm,
            module.conductance_w_k,
            hot_side_k,
        );
        // S² x² − (2 S² T_h + 2 R K) x + S² T_h² = 0.
        let (a, b, c) = (s * s, -(2.0 * s * s * th + 2.0 * r * k), s * s * th * th);
        let disc = b * b - 4.0 * a * c;
        let dtmax_k = (-b - disc.max(0.0).sqrt()) / (2.0 * a);
        if !(dtmax_k.is_finite() && dtmax_k > 0.0 && dtmax_k < th) {
            return None;
        }
        let mut sheet = PeltierDatasheet {
            imax_a: s * (th - dtmax_k) / r,
            vmax_v: s * th,
            qmax_w: 0.0,
            dtmax_k,
            hot_side_k: th,
        };
        sheet.qmax_w = sheet.predicted_qmax_w();
        Some(sheet)
    }

    /// The Q_max \[W\] that the standard approximations predict: V_max I_max (T_h + ΔT_max) / (2 T_h).
    pub fn predicted_qmax_w(&self) -> f64 {
        self.vmax_v * self.imax_a * (self.hot_side_k + self.dtmax_k) / (2.0 * self.hot_side_k)
    }

    /// Checks every value (finite, positive, ΔT_max below T_h, Q_max consistent with the others to within
    /// [`QMAX_CONSISTENCY_TOLERANCE`]). `origin` names where the values came from; `prefix` is put before the key
    /// names in errors (e.g. `"peltier."` for a device file, `""` otherwise).
    pub fn validate(&self, origin: &str, prefix: &str) -> Result<(), ParamError> {
        let key = |k: &str| format!("{prefix}{k}");
        Rule::Positive.check(key("imax_a"), self.imax_a).at(origin)?;
        Rule::Positive.check(key("vmax_v"), self.vmax_v).at(origin)?;
        Rule::Positive.check(key("qmax_w"), self.qmax_w).at(origin)?;
        Rule::Positive.check(key("dtmax_k"), self.dtmax_k).at(origin)?;
        Rule::Positive.check(key("hot_side_k"), self.hot_side_k).at(origin)?;
        let below_hot_side = Rule::Below {
            max: self.hot_side_k,
            what: "the hot-side temperature hot_side_k [K]",
        };
        if !below_hot_side.admits(self.dtmax_k) {
            return below_hot_side.check(key("dtmax_k"), self.dtmax_k).at(origin).map(drop);
        }
        let predicted = self.predicted_qmax_w();
        let consistent = Rule::Near {
            target: predicted,
            relative: QMAX_CONSISTENCY_TOLERANCE,
            what: "the Q_max [W] that I_max, V_max and ΔT_max imply",
        };
        if !consistent.admits(self.qmax_w) {
            return consistent.check(key("qmax_w"), self.qmax_w).at(origin).map(drop);
        }
        Ok(())
    }
}

/// A Peltier module as three lumped parameters (valid near the temperature they were derived at).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeltierModule {
    /// Module Seebeck coefficient S [V/K] (all couples in series). Default module: 6.37 mV/K.
    pub seebeck_v_k: f64,
    /// Electrical resistance R \[Ω\]. Default module: 0.515 Ω.
    pub resistance_ohm: f64,
    /// Thermal conductance between the two faces K [W/K]. Default module: 28.0 mW/K.
    pub conductance_w_k: f64,
}

/// The heat flows of a module at a fixed current as affine functions of the two face temperatures in °C:
/// `q = constant_w + display_w_k · t_d + hot_w_k · t_h`. Exact (the Peltier equations are linear in temperature at
/// fixed current); used by implicit plant integrators.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AffineHeat {
    /// Constant part \[W\].
    pub constant_w: f64,
    /// Coefficient of the display temperature [W/K].
    pub display_w_k: f64,
    /// Coefficient of the hot-side temperature [W/K].
    pub hot_w_k: f64,
}

impl AffineHeat {
    /// Evaluates the flow \[W\] at display and hot-side temperatures \[°C\].
    pub fn at(&self, display_c: f64, hot_c: f64) -> f64 {
        self.constant_w + self.display_w_k * display_c + self.hot_w_k * hot_c
    }
}

fn kelvin(celsius: f64) -> f64 {
    celsius + KELVIN_OFFSET
}

impl PeltierModule {
    /// A module from its lumped parameters; each must be finite and positive.
    pub fn new(seebeck_v_k: f64, resistance_ohm: f64, conductance_w_k: f64) -> Result<Self, ParamError> {
        let origin = "peltier module";
        Ok(PeltierModule {
            seebeck_v_k: Rule::Positive.check("seebeck_v_k", seebeck_v_k).at(origin)?,
            resistance_ohm: Rule::Positive.check("resistance_ohm", resistance_ohm).at(origin)?,
            conductance_w_k: Rule::Positive.check("conductance_w_k", conductance_w_k).at(origin)?,
        })
    }

    /// The module from datasheet values (see the module documentation for the formulas); errors name the origin
    /// `"peltier datasheet"`.
    pub fn from_datasheet(ds: &PeltierDatasheet) -> Result<Self, ParamError> {
        Self::from_datasheet_at(ds, "peltier datasheet", "")
    }

    /// As [`PeltierModule::from_datasheet`], with the origin and key prefix used in errors (see
    /// [`PeltierDatasheet::validate`]).
    pub fn from_datasheet_at(ds: &PeltierDatasheet, origin: &str, prefix: &str) -> Result<Self, ParamError> {
        ds.validate(origin, prefix)?;
        let th = ds.hot_side_k;
        let cold = th - ds.dtmax_k;
        Ok(PeltierModule {
            seebeck_v_k: ds.vmax_v / th,
            resistance_ohm: cold * ds.vmax_v / (th * ds.imax_a),
            conductance_w_k: cold * ds.vmax_v * ds.imax_a / (2.0 * th * ds.dtmax_k),
        })
    }

    /// Heat flowing into the display face \[W\] at `current_a` \[A\] (positive heats the display), with the display at
    /// `display_c` and the hot side at `hot_c` \[°C\]: S I T_d + ½ I² R + K (T_h − T_d).
    pub fn heat_into_display_w(&self, current_a: f64, display_c: f64, hot_c: f64) -> f64 {
        let i = current_a;
        self.seebeck_v_k * i * kelvin(display_c)
            + 0.5 * i * i * self.resistance_ohm
            + self.conductance_w_k * (hot_c - display_c)
    }

    /// The sum of the magnitudes of the three terms of [`PeltierModule::heat_into_display_w`] \[W\]:
    /// |S I T_d| + ½ I² R + |K (T_h − T_d)|. A relative error u of every parameter moves the heat into the display by
    /// at most u times this.
    pub fn display_heat_terms_w(&self, current_a: f64, display_c: f64, hot_c: f64) -> f64 {
        let i = current_a;
        (self.seebeck_v_k * i * kelvin(display_c)).abs()
            + 0.5 * i * i * self.resistance_ohm
            + (self.conductance_w_k * (hot_c - display_c)).abs()
    }

    /// Heat flowing into the hot side \[W\]: −S I T_h + ½ I² R − K (T_h − T_d).
    pub fn heat_into_hot_side_w(&self, current_a: f64, display_c: f64, hot_c: f64) -> f64 {
        let i = current_a;
        -self.seebeck_v_k * i * kelvin(hot_c) + 0.5 * i * i * self.resistance_ohm
            - self.conductance_w_k * (hot_c - display_c)
    }

    /// Terminal voltage in the direction of the current \[V\]: I R + S (T_d − T_h).
    pub fn voltage_v(&self, current_a: f64, display_c: f64, hot_c: f64) -> f64 {
        current_a * self.resistance_ohm + self.seebeck_v_k * (display_c - hot_c)
    }

    /// Electrical power delivered to the module \[W\]: V·I (equals the sum of the two heat flows).
    pub fn electrical_power_w(&self, current_a: f64, display_c: f64, hot_c: f64) -> f64 {
        self.voltage_v(current_a, display_c, hot_c) * current_a
    }

    /// [`PeltierModule::heat_into_display_w`] at `current_a` as an affine function of the face temperatures \[°C\].
    pub fn display_heat_affine(&self, current_a: f64) -> AffineHeat {
        let (s, i, k) = (self.seebeck_v_k, current_a, self.conductance_w_k);
        AffineHeat {
            constant_w: s * i * KELVIN_OFFSET + 0.5 * i * i * self.resistance_ohm,
            display_w_k: s * i - k,
            hot_w_k: k,
        }
    }

    /// [`PeltierModule::heat_into_hot_side_w`] at `current_a` as an affine function of the face temperatures \[°C\].
    pub fn hot_heat_affine(&self, current_a: f64) -> AffineHeat {
        let (s, i, k) = (self.seebeck_v_k, current_a, self.conductance_w_k);
        AffineHeat {
            constant_w: -s * i * KELVIN_OFFSET + 0.5 * i * i * self.resistance_ohm,
            display_w_k: k,
            hot_w_k: -s * i - k,
        }
    }

    /// The cooling current that extracts the most heat from the display \[A\] (negative): −S T_d / R. Beyond it
    /// (larger magnitude) Joule heating wins and more current warms the display.
    pub fn optimum_cooling_current_a(&self, display_c: f64) -> f64 {
        -self.seebeck_v_k * kelvin(display_c) / self.resistance_ohm
    }

    /// The current \[A\] that makes the heat into the display equal `q_w` \[W\] (negative `q_w` = cooling), on the
    /// efficient branch (the root at or above [`PeltierModule::optimum_cooling_current_a`], where more cooling needs
    /// more cooling current). `None` if more cooling is asked than the module can deliver at any current, or if an
    /// input is not finite. No current limit is applied; compare the result with the drive's limit.
    pub fn current_for_heat_into_display(&self, q_w: f64, display_c: f64, hot_c: f64) -> Option<f64> {
        if !(q_w.is_finite() && display_c.is_finite() && hot_c.is_finite()) {
            return None;
        }
        // ½ R I² + S T_d I + K (T_h − T_d) − q = 0, written a I² + b I + c = 0 with b > 0 for T_d > 0 K.
        let a = 0.5 * self.resistance_ohm;
        let b = self.seebeck_v_k * kelvin(display_c);
        let c = self.conductance_w_k * (hot_c - display_c) - q_w;
        let discriminant = b * b - 4.0 * a * c;
        if discriminant < 0.0 || b <= 0.0 {
            return None;
        }
        // The larger root, (−b + √D)/(2a), in the cancellation-free form −2c/(b + √D).
        Some(-2.0 * c / (b + discriminant.sqrt()))
    }

    /// The most heat the module can pull out of the display \[W\] with the current limited to `current_limit_a` \[A\]
    /// (magnitude), at the given face temperatures \[°C\]: at the optimum cooling current, or at the limit if that is
    /// smaller. Negative when the temperature difference is too large to cool at all.
    pub fn max_cooling_w(&self, current_limit_a: f64, display_c: f64, hot_c: f64) -> f64 {
        let best = self.optimum_cooling_current_a(display_c).max(-current_limit_a.abs());
        -self.heat_into_display_w(best, display_c, hot_c)
    }

    /// The most heat the module can push into the display \[W\] with the current limited to `current_limit_a` \[A\]:
    /// the heat at the full positive limit (the heat into the display grows with positive current).
    pub fn max_heating_w(&self, current_limit_a: f64, display_c: f64, hot_c: f64) -> f64 {
        self.heat_into_display_w(current_limit_a.abs(), display_c, hot_c)
    }
}
