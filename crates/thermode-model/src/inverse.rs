//! The display inverse (paper eq. 7, `model.md` §2).
//!
//! The finger does not touch the virtual object but the display plate. A second skin model rests on the plate at
//! temperature T_d through the finger–display contact conductance G_d. Over one implicit step its receptor
//! temperature is an affine function of T_d; the inverse solves for the set-point T_d^s that makes it equal the
//! target. When the set-point is then limited (safety envelope, actuator), the second model is advanced with the
//! limited value so it keeps tracking what the finger really receives.

use crate::error::{At, ParamError};
use crate::params::Rule;

/// Default finger–display contact conductance G_d [W/(m²·K)].
///
/// ≈ eq. 3 of the paper for an aluminium display plate, `2/(Δx_1/k_1 + Δx_plate/k_al)`: with a 0.5 mm epidermis of
/// k = 0.21 W/(m·K) and a 1 mm aluminium plate (k ≈ 220 W/(m·K)) that is 2/(0.00238 + 0.0000045) ≈ 838 W/(m²·K),
/// rounded down to 800. The simulated display uses the same default.
pub const DEFAULT_DISPLAY_CONDUCTANCE_W_M2K: f64 = 800.0;

/// A linear skin model resting on a plate whose temperature is held constant over one step.
///
/// Implemented by the Kron three-layer model and by the finite-volume finger, so the inverse works for both.
pub trait PlateCoupled {
    /// The receptor temperature after one step of `dt_s` \[s\] with the plate held at T_d, as `(offset_c, slope)` such
    /// that T_receptor = offset_c + slope · T_d. `conductance_w_m2k` is G_d [W/(m²·K)]. Does not change the state.
    fn receptor_affine(&self, dt_s: f64, conductance_w_m2k: f64) -> (f64, f64);

    /// Advances the state by one step of `dt_s` \[s\] with the plate at `plate_c` \[°C\] through `conductance_w_m2k`.
    fn step_on_plate(&mut self, dt_s: f64, conductance_w_m2k: f64, plate_c: f64);

    /// The current receptor temperature \[°C\].
    fn receptor_c(&self) -> f64;
}

/// The finger-on-display model and its contact conductance: computes display set-points (paper eq. 7).
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayInverse<M: PlateCoupled> {
    model: M,
    conductance_w_m2k: f64,
}

impl<M: PlateCoupled> DisplayInverse<M> {
    /// Wraps `model` (the finger resting on the display, in its current state) with the finger–display contact
    /// conductance G_d [W/(m²·K)] (default [`DEFAULT_DISPLAY_CONDUCTANCE_W_M2K`]), which must be finite and positive.
    pub fn new(model: M, conductance_w_m2k: f64) -> Result<Self, ParamError> {
        Rule::Positive
            .check("conductance_w_m2k", conductance_w_m2k)
            .at("display inverse")?;
        Ok(DisplayInverse {
            model,
            conductance_w_m2k,
        })
    }

    /// The display temperature T_d^s \[°C\] that, held for the next step of `dt_s` \[s\], brings the finger-on-display
    /// receptor temperature to `target_c` \[°C\]: the solution of offset + slope · T_d = target. Unlimited: the
    /// caller limits it (safety envelope) and reports the value really applied to [`DisplayInverse::advance`].
    /// Does not change the state. `dt_s` must be a positive finite number; otherwise the result is NaN (no plate
    /// temperature acts in zero time).
    pub fn setpoint_c(&self, target_c: f64, dt_s: f64) -> f64 {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return f64::NAN;
        }
        let (offset_c, slope) = self.model.receptor_affine(dt_s, self.conductance_w_m2k);
        (target_c - offset_c) / slope
    }

    /// Continues the finger-on-display model by one step of `dt_s` \[s\] with the plate at `applied_plate_c` \[°C\], the
    /// value really applied (after limiting).
    pub fn advance(&mut self, dt_s: f64, applied_plate_c: f64) {
        self.model.step_on_plate(dt_s, self.conductance_w_m2k, applied_plate_c);
    }

    /// The finger-on-display model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The finger-on-display receptor temperature now \[°C\].
    pub fn receptor_c(&self) -> f64 {
        self.model.receptor_c()
    }

    /// The finger–display contact conductance G_d [W/(m²·K)].
    pub fn conductance_w_m2k(&self) -> f64 {
        self.conductance_w_m2k
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-node finger (C dT/dt = G_d (T_d − T)), backward Euler, solvable by hand.
    struct Node {
        capacity_j_m2k: f64,
        temperature_c: f64,
    }

    impl PlateCoupled for Node {
        fn receptor_affine(&self, dt_s: f64, g: f64) -> (f64, f64) {
            let m = self.capacity_j_m2k + dt_s * g;
            (self.capacity_j_m2k * self.temperature_c / m, dt_s * g / m)
        }
        fn step_on_plate(&mut self, dt_s: f64, g: f64, plate_c: f64) {
            let (offset, slope) = self.receptor_affine(dt_s, g);
            self.temperature_c = offset + slope * plate_c;
        }
        fn receptor_c(&self) -> f64 {
            self.temperature_c
        }
    }

    #[test]
    fn setpoint_of_a_single_node_is_the_hand_solution() {
        // C (T − T0)/h = G (T_d − T)  ⇒  T_d = T + C (T − T0)/(h G).
        let inverse = DisplayInverse::new(
            Node {
                capacity_j_m2k: 2000.0,
                temperature_c: 32.0,
            },
            800.0,
        );
        let inverse = inverse.unwrap_or_else(|e| panic!("{e}"));
        let got = inverse.setpoint_c(31.0, 0.01);
        let want = 31.0 + 2000.0 * (31.0 - 32.0) / (0.01 * 800.0);
        assert!((got - want).abs() < 1e-9, "set-point {got} vs hand {want}");
        assert!(inverse.setpoint_c(31.0, 0.0).is_nan());
    }

    #[test]
    fn rejects_bad_conductance() {
        for g in [0.0, -1.0, f64::NAN] {
            assert!(
                DisplayInverse::new(
                    Node {
                        capacity_j_m2k: 1.0,
                        temperature_c: 0.0
                    },
                    g
                )
                .is_err(),
                "G = {g}"
            );
        }
    }
}
