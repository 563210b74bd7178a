//! The analytic response of the receptor (skin) temperature to a prescribed plate temperature: the closed form of
//! the three-layer skin model (`thermode_model::kron`) resting on the plate, used to state what a procedure must
//! measure.
//!
//! Around its steady state on the plate at the baseline, the model is linear: with x the layer temperatures'
//! deviations, `C ẋ = A x + G_d e₁ u(t)`, u the plate's deviation from the baseline, C the layer capacities, A the
//! conductance and perfusion matrix of `thermode_model::kron` and G_d the finger–plate contact conductance. With
//! `S = C^{-1/2} A C^{-1/2} = Q Λ Qᵀ` (symmetric, eigenvalues λᵢ < 0), a plate ramp `u(t) = r t` from t = 0 moves
//! the receptor (the epidermis, T1) by
//!
//! `y(t) = r · (G_d / C₁) · Σᵢ Q₁ᵢ² · (e^{λᵢ t} − 1 − λᵢ t) / λᵢ²`.
//!
//! **The method of limits' analytic line.** A participant who detects a receptor change of `θ` (threshold_c) and
//! presses `t_rt` (reaction_time_s) later stops a ramp of rate r at the plate change
//!
//! `r · (t_d + t_rt) = θ + r · (t_rt + lag(r))`, with `y(t_d) = θ` and `lag(r) = t_d − θ / r`,
//!
//! the skin's lag behind the plate under that ramp: `lag = ∫₀^{t_d} (1 − h(s)) ds` with h the receptor's response
//! to a unit plate step. Perfusion keeps h below 1 for ever, so the lag grows with the ramp's duration and differs
//! from rate to rate ([`SkinResponse::limits_estimate_c`]).
//!
//! **Yes/no procedures.** A trapezoid (ramp at r to the amplitude a, plateau, return ramp, then an answer window)
//! moves the receptor by the superposition of four shifted ramp responses; the participant detects it when the peak
//! receptor change reaches θ, so the 50 % point of its psychometric function, in plate units, is the amplitude whose
//! peak receptor change is θ ([`SkinResponse::trapezoid_threshold_c`]).

use thermode_model::params::Rule;
use thermode_model::{KronModel, Skin};

use crate::ProcedureError;

/// How long after a trapezoid's return ramp the participant may still feel it before answering \[s\]. The skin lags
/// the plate, so its peak can come after the return has begun.
pub const ANSWER_WINDOW_S: f64 = 3.0;

/// The receptor's linear response to the plate, in modal form.
#[derive(Debug, Clone, PartialEq)]
pub struct SkinResponse {
    /// G_d / C₁ \[1/s\].
    contact_rate_per_s: f64,
    /// Q₁ᵢ², the receptor's share of each mode (they sum to 1).
    weights: [f64; 3],
    /// λᵢ \[1/s\], negative.
    eigenvalues_per_s: [f64; 3],
}

/// A symmetric 3×3 matrix's eigenvalues and the squares of its eigenvectors' first components, by cyclic Jacobi
/// rotations.
fn jacobi_first_row(mut m: [[f64; 3]; 3]) -> ([f64; 3], [f64; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = m[0][1].powi(2) + m[0][2].powi(2) + m[1][2].powi(2);
        let scale = m[0][0].powi(2) + m[1][1].powi(2) + m[2][2].powi(2);
        if off <= 1e-32 * scale {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            rotate(&mut m, &mut v, p, q);
        }
    }
    let values = [m[0][0], m[1][1], m[2][2]];
    let weights = [v[0][0].powi(2), v[0][1].powi(2), v[0][2].powi(2)];
    (values, weights)
}

/// One Jacobi rotation zeroing `m[p][q]`; `v` accumulates the eigenvectors (as columns).
fn rotate(m: &mut [[f64; 3]; 3], v: &mut [[f64; 3]; 3], p: usize, q: usize) {
    if m[p][q] == 0.0 {
        return;
    }
    let theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
    let t = if theta == 0.0 { 1.0 } else { t };
    let c = 1.0 / (t * t + 1.0).sqrt();
    let s = t * c;
    for row in m.iter_mut() {
        let (mkp, mkq) = (row[p], row[q]);
        row[p] = c * mkp - s * mkq;
        row[q] = s * mkp + c * mkq;
    }
    let (row_p, row_q) = (m[p], m[q]);
    m[p] = std::array::from_fn(|k| c * row_p[k] - s * row_q[k]);
    m[q] = std::array::from_fn(|k| s * row_p[k] + c * row_q[k]);
    for row in v.iter_mut() {
        let (vp, vq) = (row[p], row[q]);
        row[p] = c * vp - s * vq;
        row[q] = s * vp + c * vq;
    }
}

impl SkinResponse {
    /// The response of `skin` (three layers) on a plate through `contact_conductance_w_m2k` [W/(m²·K)].
    pub fn new(skin: &Skin, contact_conductance_w_m2k: f64) -> Result<Self, ProcedureError> {
        let model = KronModel::new(skin).map_err(|e| ProcedureError::Skin(e.to_string()))?;
        Rule::PositiveUpTo { max: 1e6 }.check("contact_conductance_w_m2k", contact_conductance_w_m2k)?;
        let c = model.capacities_j_m2k();
        let (g12, g23) = model.conductances_w_m2k();
        let blood = &skin.blood;
        let p = [0, 1, 2].map(|n| {
            let layer = &skin.layers[n];
            layer.perfusion_per_s * blood.density_kg_m3 * blood.specific_heat_j_kgk * layer.thickness_m
        });
        let a_diag = [
            -(contact_conductance_w_m2k + g12) - p[0],
            -(g12 + g23) - p[1],
            -g23 - p[2],
        ];
        let s01 = g12 / (c[0] * c[1]).sqrt();
        let s12 = g23 / (c[1] * c[2]).sqrt();
        let s = [
            [a_diag[0] / c[0], s01, 0.0],
            [s01, a_diag[1] / c[1], s12],
            [0.0, s12, a_diag[2] / c[2]],
        ];
        let (eigenvalues_per_s, weights) = jacobi_first_row(s);
        Ok(SkinResponse {
            contact_rate_per_s: contact_conductance_w_m2k / c[0],
            weights,
            eigenvalues_per_s,
        })
    }

    /// The receptor's change \[°C\] `t_s` \[s\] after the plate starts a ramp of 1 °C/s from the steady state (0 before).
    pub fn unit_ramp_c(&self, t_s: f64) -> f64 {
        if t_s <= 0.0 {
            return 0.0;
        }
        let modes = self.weights.iter().zip(&self.eigenvalues_per_s);
        self.contact_rate_per_s
            * modes
                .map(|(w, l)| w * (libm::expm1(l * t_s) - l * t_s) / (l * l))
                .sum::<f64>()
    }

    /// The receptor's steady change per degree of plate change (below 1: perfusion pulls it to the blood).
    pub fn steady_gain(&self) -> f64 {
        let modes = self.weights.iter().zip(&self.eigenvalues_per_s);
        -self.contact_rate_per_s * modes.map(|(w, l)| w / l).sum::<f64>()
    }

    /// The time \[s\] after a ramp of `rate_c_s` starts at which the receptor has changed by `threshold_c` (bisection
    /// to 1e-12 s; the response grows monotonically). `None` if it never does within 10⁴ s.
    pub fn detection_time_s(&self, threshold_c: f64, rate_c_per_s: f64) -> Option<f64> {
        let reached = |t: f64| rate_c_per_s * self.unit_ramp_c(t) >= threshold_c;
        let mut high = 1e-3;
        while !reached(high) {
            high *= 2.0;
            if high > 1e4 {
                return None;
            }
        }
        let mut low = 0.0;
        while high - low > 1e-12 {
            let mid = 0.5 * (low + high);
            if reached(mid) {
                high = mid;
            } else {
                low = mid;
            }
        }
        Some(high)
    }

    /// The skin's lag behind the plate under a ramp of `rate_c_s` at the moment the receptor has changed by
    /// `threshold_c` \[s\]: `t_d − θ/r`.
    pub fn lag_s(&self, threshold_c: f64, rate_c_per_s: f64) -> Option<f64> {
        Some(self.detection_time_s(threshold_c, rate_c_per_s)? - threshold_c / rate_c_per_s)
    }

    /// The method of limits' expected estimate \[°C of plate change, a magnitude\]: `θ + r·(t_rt + lag)`.
    pub fn limits_estimate_c(&self, threshold_c: f64, rate_c_per_s: f64, reaction_time_s: f64) -> Option<f64> {
        Some(threshold_c + rate_c_per_s * (reaction_time_s + self.lag_s(threshold_c, rate_c_per_s)?))
    }

    /// The receptor's change \[°C\] at `t_s` for a trapezoid of amplitude `amplitude_c` (ramp at `rate_c_s`, plateau
    /// `plateau_s`, return at `return_rate_c_s`), as a sum of shifted ramp responses.
    pub fn trapezoid_c(&self, t_s: f64, amplitude_c: f64, timing: Trapezoid) -> f64 {
        let t1 = amplitude_c / timing.rate_c_per_s;
        let t2 = t1 + timing.plateau_s;
        let t3 = t2 + amplitude_c / timing.return_rate_c_per_s;
        let up = timing.rate_c_per_s * (self.unit_ramp_c(t_s) - self.unit_ramp_c(t_s - t1));
        let down = timing.return_rate_c_per_s * (self.unit_ramp_c(t_s - t2) - self.unit_ramp_c(t_s - t3));
        up - down
    }

    /// The trapezoid's peak receptor change \[°C\] from its start to [`ANSWER_WINDOW_S`] after its return, on a 1 ms
    /// grid refined by golden-section search.
    pub fn trapezoid_peak_c(&self, amplitude_c: f64, timing: Trapezoid) -> f64 {
        let end = timing.duration_s(amplitude_c) + ANSWER_WINDOW_S;
        let f = |t: f64| self.trapezoid_c(t, amplitude_c, timing);
        let steps = (end / 1e-3).ceil() as usize;
        let best = (0..=steps)
            .map(|k| k as f64 * 1e-3)
            .max_by(|a, b| f(*a).total_cmp(&f(*b)))
            .unwrap_or(0.0);
        let (mut a, mut b) = ((best - 1e-3).max(0.0), (best + 1e-3).min(end));
        let g = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..60 {
            let (c, d) = (b - g * (b - a), a + g * (b - a));
            if f(c) > f(d) {
                b = d;
            } else {
                a = c;
            }
        }
        f(best).max(f(0.5 * (a + b)))
    }

    /// The trapezoid amplitude \[°C of plate change\] whose peak receptor change is `threshold_c`: the 50 % point of a
    /// noise-free yes/no participant, in plate units (bisection to 1e-9 °C). `None` beyond 100 °C.
    pub fn trapezoid_threshold_c(&self, threshold_c: f64, timing: Trapezoid) -> Option<f64> {
        let (mut low, mut high) = (0.0, 100.0);
        if self.trapezoid_peak_c(high, timing) < threshold_c {
            return None;
        }
        while high - low > 1e-9 {
            let mid = 0.5 * (low + high);
            if self.trapezoid_peak_c(mid, timing) >= threshold_c {
                high = mid;
            } else {
                low = mid;
            }
        }
        Some(high)
    }
}

/// A trapezoid's timing: ramp rate, plateau and return rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trapezoid {
    /// The ramp's rate \[°C/s\].
    pub rate_c_per_s: f64,
    /// The plateau \[s\].
    pub plateau_s: f64,
    /// The return ramp's rate \[°C/s\].
    pub return_rate_c_per_s: f64,
}

impl Trapezoid {
    /// From the ramp to the end of the return for an amplitude of `amplitude_c` \[°C\] \[s\].
    pub fn duration_s(&self, amplitude_c: f64) -> f64 {
        amplitude_c / self.rate_c_per_s + self.plateau_s + amplitude_c / self.return_rate_c_per_s
    }
}
