//! System identification of a display with no finger on it: the thermal parameters of the device file fitted to a
//! record of the drive current and the plate sensor, hot-side sensor and Peltier voltage readings (`thermode
//! identify`).
//!
//! # Model (the observer's, [`crate::observer`], without the finger and the unknown heat)
//! - `C_p dT_p/dt = S I T_p + ½ I² R + K (T_h − T_p)` (T in kelvin in the Seebeck term)
//! - `C_h dT_h/dt = −S I T_h + ½ I² R − K (T_h − T_p) − G_w (T_h − T_w)`
//! - `τ dT_s/dt = T_p − T_s`
//! - `V = I R + S (T_p − T_h)`
//!
//! From temperatures and current alone, multiplying S, R, K, C_p, C_h and G_w by one factor changes nothing: the
//! heat balance fixes only their ratios. The voltage fixes the scale (R and S in volts), which is why a device
//! that does not report it cannot be identified absolutely. A record without any voltage (an older MeCom firmware,
//! which lacks parameter 1021) is fitted with the Seebeck coefficient held at the starting file's: the ratios —
//! what the plate's rates, the sensor's lag and therefore the safety envelope's bounds depend on — are identified,
//! the scale is the file's ([`Identification::scale_from_file`]).
//!
//! # Fit
//! Output error: the model is simulated from the first reading with the recorded currents (backward Euler for
//! plate and hot side with [`SUBSTEPS`] substeps per sample, the sensor lag exactly), and the weighted squared
//! differences to the three readings (weights: one over each reading's variance) are minimised by
//! Levenberg–Marquardt over the logarithms of the seven positive parameters and the water temperature, with a
//! forward-difference Jacobian. The confidence of each parameter is its standard deviation from the inverse of the
//! Gauss–Newton matrix scaled by the residual variance per degree of freedom (relative, since the positive
//! parameters are fitted as logarithms).

use thermode_model::peltier::PeltierModule;
use thiserror::Error;

use crate::error::ControlError;
use crate::linear::{inverse_diagonal, solve};
use crate::observer::PlantModel;

/// Why a record could not be identified.
#[derive(Debug, Error)]
pub enum IdentifyError {
    /// The starting plant is invalid.
    #[error(transparent)]
    Plant(#[from] ControlError),
    /// The record cannot be fitted (too short, a reading missing or not finite).
    #[error("identification: {0}")]
    Record(String),
}

/// Plant substeps per sample in the fit's simulation: 10 (1 ms at 100 Hz, the simulated display's own substep).
pub const SUBSTEPS: usize = 10;
/// Standard deviation given to a voltage reading \[V\]: 1 mV (a TEC controller's voltage measurement).
pub const VOLTAGE_SD_V: f64 = 1e-3;
/// Fitted parameters, in the order of [`Identification::relative_sd`].
pub const PARAMETERS: [&str; 8] = [
    "seebeck_v_k",
    "resistance_ohm",
    "conductance_w_k",
    "plate_heat_capacity_j_k",
    "hot_heat_capacity_j_k",
    "water_conductance_w_k",
    "water_c",
    "sensor_time_constant_s",
];
/// Largest number of Levenberg–Marquardt iterations: 60 (the fits measured take 5).
const MAX_ITERATIONS: usize = 60;

/// One reading of the record: the current applied over the interval that ends at it and the readings at its end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdSample {
    /// Current over the interval before this reading \[A\] (positive heats the plate).
    pub current_a: f64,
    /// Plate sensor \[°C\].
    pub sensor_c: f64,
    /// Hot-side sensor \[°C\].
    pub hot_side_c: f64,
    /// Peltier voltage \[V\].
    pub voltage_v: f64,
}

/// The result of [`identify`].
#[derive(Debug, Clone, PartialEq)]
pub struct Identification {
    /// The fitted plant: `initial` with the eight fitted values replaced.
    pub plant: PlantModel,
    /// Standard deviation of each fitted parameter ([`PARAMETERS`] order): relative for the positive ones, in °C for
    /// the water temperature.
    pub relative_sd: [f64; 8],
    /// RMS differences of the fitted model to the sensor \[°C\], hot-side \[°C\] and voltage \[V\] readings.
    pub rms_residuals: [f64; 3],
    /// Levenberg–Marquardt iterations taken.
    pub iterations: usize,
    /// The record had no voltage: the Seebeck coefficient was held at the starting file's (its standard deviation
    /// 0), the module's scale is the file's, and the voltage's RMS residual is NaN.
    pub scale_from_file: bool,
}

type Theta = [f64; 8];

fn theta_of(p: &PlantModel) -> Theta {
    [
        p.module.seebeck_v_k.ln(),
        p.module.resistance_ohm.ln(),
        p.module.conductance_w_k.ln(),
        p.plate_heat_capacity_j_k.ln(),
        p.hot_heat_capacity_j_k.ln(),
        p.water_conductance_w_k.max(1e-9).ln(),
        p.water_c,
        p.sensor_time_constant_s.max(1e-6).ln(),
    ]
}

fn plant_of(theta: &Theta, base: &PlantModel) -> Result<PlantModel, IdentifyError> {
    Ok(PlantModel {
        module: PeltierModule::new(theta[0].exp(), theta[1].exp(), theta[2].exp()).map_err(bad)?,
        plate_heat_capacity_j_k: theta[3].exp(),
        hot_heat_capacity_j_k: theta[4].exp(),
        water_conductance_w_k: theta[5].exp(),
        water_c: theta[6],
        sensor_time_constant_s: theta[7].exp(),
        ..*base
    })
}

fn bad(e: thermode_model::ParamError) -> IdentifyError {
    IdentifyError::Record(e.to_string())
}

/// The weighted residuals of `plant` on `record` (sample period `dt_s`): sensor, hot side and voltage per reading.
fn residuals(plant: &PlantModel, record: &[IdSample], dt_s: f64, out: &mut Vec<f64>) {
    out.clear();
    let with_voltage = record.iter().any(|s| s.voltage_v.is_finite());
    let (ws, wh, wv) = (
        plant.sensor_variance_c2().sqrt().recip(),
        plant.hot_side_variance_c2().sqrt().recip(),
        VOLTAGE_SD_V.recip(),
    );
    let h = dt_s / SUBSTEPS as f64;
    let lag = if plant.sensor_time_constant_s > 0.0 {
        1.0 - (-h / plant.sensor_time_constant_s).exp()
    } else {
        1.0
    };
    let (cp, ch) = (plant.plate_heat_capacity_j_k / h, plant.hot_heat_capacity_j_k / h);
    let (mut tp, mut th, mut ts) = (record[0].sensor_c, record[0].hot_side_c, record[0].sensor_c);
    for sample in &record[1..] {
        let i = sample.current_a;
        let qd = plant.module.display_heat_affine(i);
        let qh = plant.module.hot_heat_affine(i);
        for _ in 0..SUBSTEPS {
            // Backward Euler: (C/h − A) T₁ = C/h T₀ + b, a 2×2 system.
            let a11 = cp - qd.display_w_k;
            let a12 = -qd.hot_w_k;
            let r1 = cp * tp + qd.constant_w;
            let a21 = -qh.display_w_k;
            let a22 = ch - qh.hot_w_k + plant.water_conductance_w_k;
            let r2 = ch * th + qh.constant_w + plant.water_conductance_w_k * plant.water_c;
            let det = a11 * a22 - a12 * a21;
            let next_tp = (r1 * a22 - a12 * r2) / det;
            th = (a11 * r2 - a21 * r1) / det;
            ts += (0.5 * (tp + next_tp) - ts) * lag;
            tp = next_tp;
        }
        out.push(ws * (ts - sample.sensor_c));
        out.push(wh * (th - sample.hot_side_c));
        out.push(match with_voltage {
            true => wv * (plant.module.voltage_v(i, tp, th) - sample.voltage_v),
            false => 0.0,
        });
    }
}

fn sum_squares(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Fits the thermal parameters of `initial` (the device file's, the starting point) to `record`, readings every
/// `dt_s` seconds. The record must hold at least 100 readings, all finite — or, a device without a voltage
/// reading, with no voltage at all (NaN throughout: the scale is then the file's, see the module documentation).
pub fn identify(record: &[IdSample], initial: &PlantModel, dt_s: f64) -> Result<Identification, IdentifyError> {
    initial.validate()?;
    if !(dt_s.is_finite() && dt_s > 0.0) || record.len() < 100 {
        return Err(IdentifyError::Record(format!(
            "a record of at least 100 readings at a positive interval is needed ({} readings, interval {dt_s} s)",
            record.len()
        )));
    }
    let scale_from_file = record.iter().all(|s| s.voltage_v.is_nan());
    let finite = |s: &IdSample| {
        [s.current_a, s.sensor_c, s.hot_side_c]
            .iter()
            .chain((!scale_from_file).then_some(&s.voltage_v))
            .all(|v| v.is_finite())
    };
    if let Some(k) = record.iter().position(|s| !finite(s)) {
        return Err(IdentifyError::Record(format!(
            "reading {k} is not finite (a device that reports the Peltier voltage must report it in every reading)"
        )));
    }
    // Without a voltage the scale is the file's: the Seebeck coefficient (parameter 0) stays.
    let fixed = |k: usize| scale_from_file && k == 0;
    let mut theta = theta_of(initial);
    let mut r = Vec::new();
    residuals(&plant_of(&theta, initial)?, record, dt_s, &mut r);
    let mut cost = sum_squares(&r);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut jacobian = vec![Vec::new(); 8];
    for _ in 0..MAX_ITERATIONS {
        iterations += 1;
        jacobian_at(&theta, initial, record, dt_s, &r, &mut jacobian)?;
        let (jtj, jtr) = normal_equations(&jacobian, &r, fixed);
        let mut improved = false;
        while lambda < 1e12 {
            let mut a = jtj;
            for (k, row) in a.iter_mut().enumerate() {
                row[k] += lambda * jtj[k][k].max(1e-12);
            }
            let Some(step) = solve(a, jtr.map(|v| -v)) else {
                lambda *= 10.0;
                continue;
            };
            let trial: Theta = std::array::from_fn(|k| theta[k] + step[k]);
            let mut trial_r = Vec::new();
            let trial_cost = match plant_of(&trial, initial) {
                Ok(plant) => {
                    residuals(&plant, record, dt_s, &mut trial_r);
                    sum_squares(&trial_r)
                }
                Err(_) => f64::INFINITY,
            };
            if trial_cost.is_finite() && trial_cost < cost {
                let relative = (cost - trial_cost) / cost;
                (theta, r, cost) = (trial, trial_r, trial_cost);
                lambda = (lambda / 10.0).max(1e-9);
                improved = relative > 1e-10;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    jacobian_at(&theta, initial, record, dt_s, &r, &mut jacobian)?;
    let (jtj, _) = normal_equations(&jacobian, &r, fixed);
    let (readings, free) = match scale_from_file {
        true => (2.0, 7.0),
        false => (3.0, 8.0),
    };
    let dof = (readings * (r.len() / 3) as f64 - free).max(1.0);
    let scale = cost / dof;
    let mut relative_sd = [f64::NAN; 8];
    for (k, sd) in relative_sd.iter_mut().enumerate() {
        if fixed(k) {
            *sd = 0.0;
        } else if let Some(variance) = inverse_diagonal(jtj, k) {
            *sd = (variance * scale).max(0.0).sqrt();
        }
    }
    let n = (r.len() / 3) as f64;
    let rms = |offset: usize, weight: f64| {
        (r.iter()
            .skip(offset)
            .step_by(3)
            .map(|v| (v / weight).powi(2))
            .sum::<f64>()
            / n)
            .sqrt()
    };
    let plant = plant_of(&theta, initial)?;
    let rms_residuals = [
        rms(0, plant.sensor_variance_c2().sqrt().recip()),
        rms(1, plant.hot_side_variance_c2().sqrt().recip()),
        if scale_from_file {
            f64::NAN
        } else {
            rms(2, VOLTAGE_SD_V.recip())
        },
    ];
    Ok(Identification {
        plant,
        relative_sd,
        rms_residuals,
        iterations,
        scale_from_file,
    })
}

/// Forward-difference Jacobian of the residuals `r` (at `theta`) into `out[k]` (one column per parameter).
fn jacobian_at(
    theta: &Theta,
    base: &PlantModel,
    record: &[IdSample],
    dt_s: f64,
    r: &[f64],
    out: &mut [Vec<f64>],
) -> Result<(), IdentifyError> {
    for (k, column) in out.iter_mut().enumerate() {
        let step = if k == 6 { 1e-4 } else { 1e-6 };
        let mut shifted = *theta;
        shifted[k] += step;
        residuals(&plant_of(&shifted, base)?, record, dt_s, column);
        for (c, r0) in column.iter_mut().zip(r) {
            *c = (*c - r0) / step;
        }
    }
    Ok(())
}

/// JᵀJ and Jᵀr; a `fixed` parameter's row and column are the identity's (its step 0, its block apart).
fn normal_equations(jacobian: &[Vec<f64>], r: &[f64], fixed: impl Fn(usize) -> bool) -> ([[f64; 8]; 8], [f64; 8]) {
    let mut jtj = [[0.0; 8]; 8];
    let mut jtr = [0.0; 8];
    for a in 0..8 {
        if fixed(a) {
            jtj[a][a] = 1.0;
            continue;
        }
        jtr[a] = jacobian[a].iter().zip(r).map(|(x, y)| x * y).sum();
        for b in (a..8).filter(|&b| !fixed(b)) {
            let v: f64 = jacobian[a].iter().zip(&jacobian[b]).map(|(x, y)| x * y).sum();
            jtj[a][b] = v;
            jtj[b][a] = v;
        }
    }
    (jtj, jtr)
}

#[cfg(test)]
mod tests {
    use super::*;
    use thermode_model::peltier::PeltierDatasheet;

    fn plant() -> PlantModel {
        PlantModel {
            module: PeltierModule::from_datasheet(&PeltierDatasheet::default()).expect("module"),
            plate_heat_capacity_j_k: 0.28,
            hot_heat_capacity_j_k: 1.7,
            water_conductance_w_k: 0.3,
            water_c: 23.0,
            sensor_time_constant_s: 0.3,
            sensor_noise_c: 0.02,
            sensor_resolution_c: 0.01,
            sensor_sample_rate_hz: 100.0,
            current_limit_a: 2.8,
        }
    }

    /// A noiseless record of `truth` driven by square waves of current.
    fn record(truth: &PlantModel) -> Vec<IdSample> {
        let currents: Vec<f64> = (0..6000)
            .map(|k| {
                let t = k as f64 * 0.01;
                2.5 * ((t / 7.0).floor() % 2.0 * 2.0 - 1.0) * if (t / 3.0).floor() % 3.0 == 0.0 { 0.4 } else { 1.0 }
            })
            .collect();
        let mut out = vec![IdSample {
            current_a: 0.0,
            sensor_c: truth.water_c,
            hot_side_c: truth.water_c,
            voltage_v: 0.0,
        }];
        // Simulate with the fit's own residual function: the residuals against a zero record are the outputs.
        let zeros: Vec<IdSample> = std::iter::once(out[0])
            .chain(currents.iter().map(|&i| IdSample {
                current_a: i,
                sensor_c: 0.0,
                hot_side_c: 0.0,
                voltage_v: 0.0,
            }))
            .collect();
        let mut r = Vec::new();
        residuals(truth, &zeros, 0.01, &mut r);
        let (ws, wh) = (truth.sensor_variance_c2().sqrt(), truth.hot_side_variance_c2().sqrt());
        for (k, &i) in currents.iter().enumerate() {
            out.push(IdSample {
                current_a: i,
                sensor_c: r[3 * k] * ws,
                hot_side_c: r[3 * k + 1] * wh,
                voltage_v: r[3 * k + 2] * VOLTAGE_SD_V,
            });
        }
        out
    }

    #[test]
    fn a_noiseless_record_gives_back_the_parameters_it_was_made_with() {
        let base = plant();
        let truth = PlantModel {
            module: PeltierModule::new(
                base.module.seebeck_v_k * 1.2,
                base.module.resistance_ohm * 0.8,
                base.module.conductance_w_k * 1.25,
            )
            .expect("module"),
            plate_heat_capacity_j_k: 0.28 * 0.75,
            hot_heat_capacity_j_k: 1.7 * 1.3,
            water_conductance_w_k: 0.3 * 0.7,
            water_c: 23.0,
            sensor_time_constant_s: 0.3 * 1.3,
            ..base
        };
        let fit = identify(&record(&truth), &base, 0.01).expect("identified");
        let got = theta_of(&fit.plant);
        let want = theta_of(&truth);
        for k in 0..8 {
            assert!(
                (got[k] - want[k]).abs() < 1e-4,
                "{}: fitted {} vs true {} (log or °C), after {} iterations",
                PARAMETERS[k],
                got[k],
                want[k],
                fit.iterations
            );
        }
    }

    /// Issue 35 item 5 (an older MeCom firmware reports no voltage): with the Seebeck coefficient held at the file's,
    /// a record without any voltage gives back every ratio the heat balance fixes — each parameter over the
    /// Seebeck coefficient's scale — and the sensor's lag and the water temperature exactly.
    #[test]
    fn a_record_without_any_voltage_gives_the_ratios_on_the_files_scale() {
        let base = plant();
        let truth = PlantModel {
            module: PeltierModule::new(
                base.module.seebeck_v_k * 1.2,
                base.module.resistance_ohm * 0.8,
                base.module.conductance_w_k * 1.25,
            )
            .expect("module"),
            plate_heat_capacity_j_k: 0.28 * 0.75,
            hot_heat_capacity_j_k: 1.7 * 1.3,
            water_conductance_w_k: 0.3 * 0.7,
            sensor_time_constant_s: 0.3 * 1.3,
            ..base
        };
        let mut r = record(&truth);
        for s in &mut r {
            s.voltage_v = f64::NAN;
        }
        let fit = identify(&r, &base, 0.01).expect("identified");
        assert!(fit.scale_from_file && fit.rms_residuals[2].is_nan() && fit.relative_sd[0] == 0.0);
        let (got, want) = (theta_of(&fit.plant), theta_of(&truth));
        // The scale: the file's Seebeck coefficient over the true one (1/1.2), the same for every scaled parameter.
        let scale = got[0] - want[0];
        assert!((scale - (1.0f64 / 1.2).ln()).abs() < 1e-12, "scale {scale}");
        for k in [1, 2, 3, 4, 5] {
            assert!(
                (got[k] - want[k] - scale).abs() < 1e-4,
                "{}: fitted {} vs true {} on the file's scale {scale}",
                PARAMETERS[k],
                got[k],
                want[k]
            );
        }
        for k in [6, 7] {
            assert!(
                (got[k] - want[k]).abs() < 1e-4,
                "{}: {} vs {}",
                PARAMETERS[k],
                got[k],
                want[k]
            );
        }
    }

    #[test]
    fn a_record_without_voltage_or_too_short_is_refused() {
        let base = plant();
        let mut r = record(&base);
        r[50].voltage_v = f64::NAN;
        let e = identify(&r, &base, 0.01).expect_err("no voltage");
        assert!(e.to_string().contains("Peltier voltage"), "{e}");
        let e = identify(&r[..20], &base, 0.01).expect_err("too short");
        assert!(e.to_string().contains("at least 100"), "{e}");
    }
}
