//! A live fit of the Peltier module from its terminal voltage ([`ModuleFit`]), for the model-based controller on
//! a display whose module is not its datasheet.
//!
//! The voltage across the module is `V = I R + S (T_p − T_h)` (`PeltierModule::voltage_v`): linear in the Seebeck
//! coefficient S and the resistance R, with regressors the plate-to-hot-side difference and the current, both known
//! every tick. A Kalman filter on θ = [S, R] (a slow random walk, so a module that warms up is followed) starts at
//! the device file's values with the file's relative uncertainty and updates on every reading that carries a
//! voltage. The resting plate (about 9 K above the hot side, a small current) and every change of current separate
//! the two. The conductance K is not in the voltage; [`ConductanceRule`] says what the fitted S and R tell of it:
//! - [`ConductanceRule::FigureOfMerit`] ([`ModuleFit::new`]): the module's figure of merit `Z = S² / (R K)`, a
//!   property of the thermoelectric material, is the file's, so `K = S² / (R Z)`: a module whose every parameter is
//!   scaled (a different V_max) or whose R and K trade (a different I_max) is then right in all three, but a module
//!   whose S alone is 30 % off gets a K 69 % too high (Z ∝ S²).
//! - [`ConductanceRule::ErrorSources`] (the model controller's): the module differs from its file through three
//!   independent sources of equal relative spread — the number of couples (S, R and K alike), the legs' aspect
//!   ratio (R and K opposite) and each parameter's own error (material, contacts) — so the logarithmic errors of
//!   (S, R, K) have the covariance σ² [[2, 1, 1], [1, 3, 0], [1, 0, 3]], and the expected K given the fitted S and
//!   R is `K = K_file (S/S_file)^0.6 (R/R_file)^−0.2` ([`ERROR_SOURCES_EXPONENTS`]). Its error stays within
//!   25 % on modules whose S or R alone, or all three, are 30 % off (the Z rule: up to 69 %), and a K off on its
//!   own (not in the voltage) stays as far off as the file: errors of the size the touch calibration's gate allows
//!   for (`render.peltier_uncertainty`); figures in `docs/design-choices.md`.
//!
//! Each estimate is kept within a factor of two of the file's value; a reading that is not finite, or further than
//! [`GATE_SD`] standard deviations from what the fit expects, changes nothing. No allocation; deterministic.

use thermode_model::peltier::PeltierModule;

/// Standard deviation of a voltage reading the fit assumes \[V\]: 2 mV (twice the simulated display's noise; a
/// Meerstetter controller reports the output voltage to the millivolt).
pub const VOLTAGE_SD_V: f64 = 2e-3;

/// Relative random walk of S and R per √s \[1/√s\]: 1e-3 (a module's parameters change with its temperature, a few
/// tenths of a percent per kelvin, over seconds).
pub const DRIFT_PER_SQRT_S: f64 = 1e-3;

/// Largest factor between an estimate and the device file's value: 2.
pub const MAX_FACTOR: f64 = 2.0;

/// A reading further than this many of its expected standard deviations from the prediction is not used: 5 (a
/// spike, a voltage in another sign convention or unit, a module the model cannot describe).
pub const GATE_SD: f64 = 5.0;

/// The exponents (a, b) of [`ConductanceRule::ErrorSources`], `K = K_file (S/S_file)^a (R/R_file)^b`: (0.6, −0.2),
/// the regression of ln K on (ln S, ln R), `[1, 0] · [[2, 1], [1, 3]]⁻¹`, under three independent error sources of
/// equal spread (see the module documentation).
pub const ERROR_SOURCES_EXPONENTS: (f64, f64) = (0.6, -0.2);

/// What the fitted S and R say of the module's conductance K, which the voltage does not carry; see the module
/// documentation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ConductanceRule {
    /// The file's figure of merit Z = S²/(R K) holds: `K = S²/(R Z)` (right for a module scaled in V_max or I_max).
    FigureOfMerit,
    /// Three independent error sources (couples, leg aspect, each parameter's own): `K = K_file (S/S_file)^0.6
    /// (R/R_file)^−0.2` ([`ERROR_SOURCES_EXPONENTS`]). The default.
    #[default]
    ErrorSources,
}

/// The live fit of S and R; see the module documentation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModuleFit {
    /// The device file's module.
    file: PeltierModule,
    /// Current estimate [S in V/K, R in Ω].
    theta: [f64; 2],
    /// Its covariance.
    p: [[f64; 2]; 2],
    /// How K follows from S and R.
    conductance: ConductanceRule,
}

impl ModuleFit {
    /// A fit starting at `file` with relative standard deviation `relative_sd` (> 0) of S and R, K from the file's
    /// figure of merit ([`ConductanceRule::FigureOfMerit`]).
    pub fn new(file: PeltierModule, relative_sd: f64) -> Self {
        Self::with_conductance(file, relative_sd, ConductanceRule::FigureOfMerit)
    }

    /// A fit starting at `file` with relative standard deviation `relative_sd` (> 0) of S and R, K by `conductance`.
    pub fn with_conductance(file: PeltierModule, relative_sd: f64, conductance: ConductanceRule) -> Self {
        let theta = [file.seebeck_v_k, file.resistance_ohm];
        let var = |x: f64| (relative_sd * x).powi(2);
        Self {
            file,
            theta,
            p: [[var(theta[0]), 0.0], [0.0, var(theta[1])]],
            conductance,
        }
    }

    /// Updates with one reading: the module's terminal `voltage_v` \[V\] while `current_a` \[A\] flows with the plate
    /// at `plate_c` and the hot side at `hot_c` \[°C\], `dt_s` \[s\] after the previous one. Returns the module as now
    /// estimated, or `None` (and nothing changes) when the reading is not usable (not finite, or beyond the gate).
    pub fn update(
        &mut self,
        voltage_v: f64,
        current_a: f64,
        plate_c: f64,
        hot_c: f64,
        dt_s: f64,
    ) -> Option<PeltierModule> {
        let phi = [plate_c - hot_c, current_a];
        if !([voltage_v, phi[0], phi[1], dt_s].iter().all(|x| x.is_finite()) && dt_s > 0.0) {
            return None;
        }
        let mut p = self.p;
        for (k, theta) in self.theta.iter().enumerate() {
            p[k][k] += (DRIFT_PER_SQRT_S * theta).powi(2) * dt_s;
        }
        let p_phi = [p[0][0] * phi[0] + p[0][1] * phi[1], p[1][0] * phi[0] + p[1][1] * phi[1]];
        let innovation_var = phi[0] * p_phi[0] + phi[1] * p_phi[1] + VOLTAGE_SD_V * VOLTAGE_SD_V;
        let innovation = voltage_v - (phi[0] * self.theta[0] + phi[1] * self.theta[1]);
        if innovation * innovation > GATE_SD * GATE_SD * innovation_var {
            return None;
        }
        self.p = p;
        let file = [self.file.seebeck_v_k, self.file.resistance_ohm];
        for k in 0..2 {
            let gain = p_phi[k] / innovation_var;
            self.theta[k] = (self.theta[k] + gain * innovation).clamp(file[k] / MAX_FACTOR, file[k] * MAX_FACTOR);
            for (p, p_phi_j) in self.p[k].iter_mut().zip(p_phi) {
                *p -= gain * p_phi_j;
            }
        }
        Some(self.module())
    }

    /// The device file's module, where the fit started.
    pub fn file_module(&self) -> PeltierModule {
        self.file
    }

    /// The module as now estimated: S and R fitted, K by the fit's [`ConductanceRule`].
    pub fn module(&self) -> PeltierModule {
        let [s, r] = self.theta;
        let (s_ratio, r_ratio) = (s / self.file.seebeck_v_k, r / self.file.resistance_ohm);
        let k_ratio = match self.conductance {
            ConductanceRule::FigureOfMerit => s_ratio * s_ratio / r_ratio,
            ConductanceRule::ErrorSources => {
                let (a, b) = ERROR_SOURCES_EXPONENTS;
                s_ratio.powf(a) * r_ratio.powf(b)
            }
        };
        PeltierModule {
            seebeck_v_k: s,
            resistance_ohm: r,
            conductance_w_k: self.file.conductance_w_k * k_ratio,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thermode_model::peltier::PeltierDatasheet;

    fn module_of(datasheet: &PeltierDatasheet) -> PeltierModule {
        PeltierModule::from_datasheet(datasheet).unwrap_or_else(|e| panic!("{e}"))
    }

    /// Feeds `fit` 20 s at 100 Hz of noise-free voltages of `truth`: a resting plate 9 K above the hot side at a
    /// small current, then a cooling drop at -2.8 A and a recovery, as a touch gives them.
    fn feed(fit: &mut ModuleFit, truth: &PeltierModule) -> PeltierModule {
        let mut module = fit.module();
        for k in 0..2000 {
            let t = f64::from(k) * 0.01;
            let (current_a, plate_c): (f64, f64) = match t {
                t if t < 10.0 => (0.12, 32.0),
                t if t < 11.0 => (-2.8, 32.0 - 10.0 * (t - 10.0)),
                t => (0.4, 22.0 + (t - 11.0)),
            };
            let hot_c = 23.0 + 0.3 * current_a.abs();
            let voltage_v = truth.voltage_v(current_a, plate_c, hot_c);
            module = fit.update(voltage_v, current_a, plate_c, hot_c, 0.01).unwrap_or(module);
        }
        module
    }

    fn assert_within(got: f64, want: f64, relative: f64, what: &str) {
        assert!(
            (got / want - 1.0).abs() <= relative,
            "{what}: fitted {got} vs true {want}"
        );
    }

    /// Datasheets 30 % off in V_max (S, R and K scaled together) and I_max (R and K trading): S and R from the
    /// voltage, and K from the file's figure of merit, each within 0.5 % of the true module.
    #[test]
    fn the_fit_finds_a_module_scaled_from_its_file() {
        let file = PeltierDatasheet::default();
        for (vmax, imax) in [(1.3, 1.0), (0.7, 1.0), (1.0, 1.3), (1.0, 0.7)] {
            let mut hidden = PeltierDatasheet {
                vmax_v: file.vmax_v * vmax,
                imax_a: file.imax_a * imax,
                ..file
            };
            hidden.qmax_w = hidden.predicted_qmax_w();
            let truth = module_of(&hidden);
            let mut fit = ModuleFit::new(module_of(&file), 0.3);
            let fitted = feed(&mut fit, &truth);
            let what = format!("V_max × {vmax}, I_max × {imax}");
            assert_within(fitted.seebeck_v_k, truth.seebeck_v_k, 0.005, &format!("{what}: S"));
            assert_within(
                fitted.resistance_ohm,
                truth.resistance_ohm,
                0.005,
                &format!("{what}: R"),
            );
            assert_within(
                fitted.conductance_w_k,
                truth.conductance_w_k,
                0.005,
                &format!("{what}: K"),
            );
        }
    }

    /// The error-sources rule's exponents are the regression of ln K on (ln S, ln R) under the covariance of three
    /// equal, independent error sources (couples: (1, 1, 1); leg aspect: (0, −1, 1); each parameter's own: the
    /// identity), computed here from those vectors; and on modules 30 % off in S or R alone or in all three the
    /// fitted K is within 25 % of the true one (the figure-of-merit rule: 69 % off for S × 1.3; a K off on its own
    /// is not in the voltage and stays as far off as it is).
    #[test]
    fn the_error_sources_rule_regresses_k_on_s_and_r_and_stays_near_every_module() {
        let sources = [[1.0, 1.0, 1.0], [0.0, -1.0, 1.0]];
        let cov =
            |i: usize, j: usize| sources.iter().map(|v| v[i] * v[j]).sum::<f64>() + if i == j { 1.0 } else { 0.0 };
        let (a, b, c) = (cov(0, 0), cov(0, 1), cov(1, 1));
        let det = a * c - b * b;
        let exponents = (
            (cov(2, 0) * c - cov(2, 1) * b) / det,
            (cov(2, 1) * a - cov(2, 0) * b) / det,
        );
        let want = ERROR_SOURCES_EXPONENTS;
        assert!(
            (exponents.0 - want.0).abs() < 1e-12 && (exponents.1 - want.1).abs() < 1e-12,
            "regression {exponents:?} vs {want:?}"
        );
        let file = module_of(&PeltierDatasheet::default());
        let scaled = |s: f64, r: f64, k: f64| PeltierModule {
            seebeck_v_k: file.seebeck_v_k * s,
            resistance_ohm: file.resistance_ohm * r,
            conductance_w_k: file.conductance_w_k * k,
        };
        let mut worst: f64 = 0.0;
        for f in [1.3, 0.7] {
            for truth in [scaled(f, 1.0, 1.0), scaled(1.0, f, 1.0), scaled(f, f, f)] {
                let mut fit = ModuleFit::with_conductance(file, 0.3, ConductanceRule::ErrorSources);
                let fitted = feed(&mut fit, &truth);
                assert_within(fitted.seebeck_v_k, truth.seebeck_v_k, 0.005, &format!("{truth:?}: S"));
                worst = worst.max((fitted.conductance_w_k / truth.conductance_w_k).ln().abs());
            }
        }
        assert!(worst.exp() - 1.0 < 0.25, "largest K error {:.3}", worst.exp() - 1.0);
        let mut z_fit = ModuleFit::new(file, 0.3);
        let z_k = feed(&mut z_fit, &scaled(1.3, 1.0, 1.0)).conductance_w_k / file.conductance_w_k;
        assert!((z_k - 1.69).abs() < 0.02, "figure-of-merit K for S × 1.3: × {z_k}");
    }

    #[test]
    fn an_unusable_or_implausible_reading_changes_nothing_and_estimates_stay_within_a_factor_of_two() {
        let file = module_of(&PeltierDatasheet::default());
        let mut fit = ModuleFit::new(file, 0.3);
        let before = fit;
        for (voltage_v, current_a, dt_s) in [(f64::NAN, 1.0, 0.01), (0.5, f64::INFINITY, 0.01), (0.5, 1.0, 0.0)] {
            assert_eq!(fit.update(voltage_v, current_a, 32.0, 23.0, dt_s), None);
            assert_eq!(fit, before);
        }
        // A voltage in the opposite sign convention is refused outright; nothing moves.
        for _ in 0..1000 {
            assert_eq!(
                fit.update(-file.voltage_v(2.0, 32.0, 23.0), 2.0, 32.0, 23.0, 0.01),
                None
            );
        }
        assert_eq!(fit, before);
        // A module twice as resistive as the file's hardest case: the estimates stop at twice the file's values.
        let mut strong = file;
        strong.resistance_ohm *= 2.5;
        let mut fit = ModuleFit::new(file, 1.0);
        for k in 0..3000 {
            let current_a = 0.5 + f64::from(k % 7) * 0.3;
            fit.update(strong.voltage_v(current_a, 32.0, 23.0), current_a, 32.0, 23.0, 0.01);
        }
        let module = fit.module();
        assert!(module.resistance_ohm <= 2.0 * file.resistance_ohm, "{module:?}");
        assert!(module.resistance_ohm >= 1.9 * file.resistance_ohm, "{module:?}");
        assert_eq!(fit.file_module(), file);
    }
}
