//! Unit tests of the finite-volume model: the implicit steps equal dense solves of their defining equations
//! (assembled here independently from the grid), the time order of both schemes, calibration, and typed errors.

use super::*;
use crate::inverse::PlateCoupled;
use crate::materials::Material;
use crate::skin::Skin;

fn stone(thickness_m: f64) -> Material {
    Material {
        name: "stone".into(),
        conductivity_w_mk: 2.763,
        density_kg_m3: 2700.0,
        specific_heat_j_kgk: 812.2,
        thickness_m,
        source: "test".into(),
    }
}

/// A fingertip with perfusion and metabolic heat in every layer.
fn busy_skin() -> Skin {
    let mut skin = Skin::fingertip();
    for (i, layer) in skin.layers.iter_mut().enumerate() {
        layer.perfusion_per_s = 0.001 * (i + 1) as f64;
        layer.metabolic_w_m3 = 500.0 * (i + 1) as f64;
    }
    skin
}

/// A coarse grid so the dense systems stay small.
fn coarse() -> FvConfig {
    FvConfig {
        surface_cell_m: 2e-4,
        growth: 1.3,
        max_cell_m: 1e-3,
        deep_boundary: DeepBoundary::Core { temperature_c: 35.0 },
        far_side: FarSide::Held { temperature_c: 21.0 },
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    }
}

/// The semi-discrete system C dT/dt = J T + S of skin (+ object in contact), assembled from the grid widths and the
/// material numbers: unknowns are the skin cells, surface first, then the object cells, contact face first.
struct Dense {
    capacity: Vec<f64>,
    jacobian: Vec<Vec<f64>>,
    source: Vec<f64>,
}

fn dense(model: &FvModel, skin: &Skin, object: &Material, config: &FvConfig, env: FvEnvironment) -> Dense {
    let ws = model.skin_cell_widths_m();
    let wo = if env == FvEnvironment::Object {
        model.object_cell_widths_m()
    } else {
        &[]
    };
    let (ns, n) = (ws.len(), ws.len() + wo.len());
    let layer = |i: usize| &skin.layers[model.skin_cell_layers()[i]];
    let k = |i: usize| {
        if i < ns {
            layer(i).conductivity_w_mk
        } else {
            object.conductivity_w_mk
        }
    };
    let w = |i: usize| if i < ns { ws[i] } else { wo[i - ns] };
    let mut d = Dense {
        capacity: vec![0.0; n],
        jacobian: vec![vec![0.0; n]; n],
        source: vec![0.0; n],
    };
    let link = |d: &mut Dense, i: usize, j: usize, g: f64| {
        d.jacobian[i][i] -= g;
        d.jacobian[j][j] -= g;
        d.jacobian[i][j] += g;
        d.jacobian[j][i] += g;
    };
    for i in 0..n {
        if i < ns {
            let l = layer(i);
            d.capacity[i] = l.density_kg_m3 * l.specific_heat_j_kgk * w(i);
            let p = l.perfusion_per_s * skin.blood.density_kg_m3 * skin.blood.specific_heat_j_kgk * w(i);
            d.jacobian[i][i] -= p;
            d.source[i] += p * skin.blood.arterial_c + l.metabolic_w_m3 * w(i);
        } else {
            d.capacity[i] = object.density_kg_m3 * object.specific_heat_j_kgk * w(i);
        }
        if i + 1 < n && i + 1 != ns {
            link(
                &mut d,
                i,
                i + 1,
                1.0 / (w(i) / (2.0 * k(i)) + w(i + 1) / (2.0 * k(i + 1))),
            );
        }
    }
    let core = 2.0 * k(ns - 1) / w(ns - 1);
    d.jacobian[ns - 1][ns - 1] -= core;
    d.source[ns - 1] += core * 35.0;
    let surface = |h: f64| 1.0 / (ws[0] / (2.0 * k(0)) + 1.0 / h);
    match env {
        FvEnvironment::Object => {
            let g = 1.0 / (w(0) / (2.0 * k(0)) + config.contact_resistance_m2k_w + w(ns) / (2.0 * k(ns)));
            link(&mut d, 0, ns, g);
            let far = 2.0 * k(n - 1) / w(n - 1);
            d.jacobian[n - 1][n - 1] -= far;
            d.source[n - 1] += far * 21.0;
        }
        FvEnvironment::Air { ambient_c } => {
            let g = surface(skin.air_convection_w_m2k);
            d.jacobian[0][0] -= g;
            d.source[0] += g * ambient_c;
        }
        FvEnvironment::Plate {
            conductance_w_m2k,
            temperature_c,
        } => {
            let g = surface(conductance_w_m2k);
            d.jacobian[0][0] -= g;
            d.source[0] += g * temperature_c;
        }
    }
    d
}

/// Solves (diag(C)·κ − θh J) x = rhs by Gaussian elimination with partial pivoting.
fn dense_solve(d: &Dense, kappa: f64, theta_h: f64, rhs: &[f64]) -> Vec<f64> {
    let n = rhs.len();
    let mut a: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| if i == j { kappa * d.capacity[i] } else { 0.0 } - theta_h * d.jacobian[i][j])
                .collect()
        })
        .collect();
    let mut b = rhs.to_vec();
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|x, y| a[*x][col].abs().total_cmp(&a[*y][col].abs()))
            .unwrap();
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col].clone();
        for row in col + 1..n {
            let factor = a[row][col] / pivot_row[col];
            for (x, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= factor * p;
            }
            b[row] -= factor * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let tail: f64 = (row + 1..n).map(|j| a[row][j] * x[j]).sum();
        x[row] = (b[row] - tail) / a[row][row];
    }
    x
}

fn net_flux(d: &Dense, t: &[f64]) -> Vec<f64> {
    (0..t.len())
        .map(|i| d.source[i] + (0..t.len()).map(|j| d.jacobian[i][j] * t[j]).sum::<f64>())
        .collect()
}

/// A model in an uneven state: steady in air, then touched and stepped a little.
fn prepared(scheme: TimeScheme) -> (FvModel, Skin, Material, FvConfig) {
    let skin = busy_skin();
    let object = stone(0.006);
    let config = FvConfig { scheme, ..coarse() };
    let mut model = FvModel::new(&skin, Some(&object), &config).unwrap();
    model.set_steady_in_air(23.0).unwrap();
    model.touch(18.0).unwrap();
    model.step(0.05, FvEnvironment::Object);
    (model, skin, object, config)
}

fn state(model: &FvModel, env: FvEnvironment) -> Vec<f64> {
    let mut t = model.skin_temperatures_c().to_vec();
    if env == FvEnvironment::Object {
        t.extend_from_slice(model.object_temperatures_c());
    }
    t
}

fn assert_close(got: &[f64], want: &[f64], tolerance: f64, label: &str) {
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!((g - w).abs() <= tolerance, "{label}, cell {i}: fv {g} vs dense {w}");
    }
}

const ENVIRONMENTS: [FvEnvironment; 3] = [
    FvEnvironment::Object,
    FvEnvironment::Air { ambient_c: 23.0 },
    FvEnvironment::Plate {
        conductance_w_m2k: 1500.0,
        temperature_c: 40.0,
    },
];

#[test]
fn backward_euler_step_equals_a_dense_solve() {
    for env in ENVIRONMENTS {
        let (mut model, skin, object, config) = prepared(TimeScheme::BackwardEuler);
        let d = dense(&model, &skin, &object, &config, env);
        let h = 0.2;
        let before = state(&model, env);
        let rhs: Vec<f64> = (0..before.len())
            .map(|i| d.capacity[i] * before[i] + h * d.source[i])
            .collect();
        let want = dense_solve(&d, 1.0, h, &rhs);
        model.step(h, env);
        assert_close(&state(&model, env), &want, 1e-10, &format!("backward Euler in {env:?}"));
    }
}

#[test]
fn tr_bdf2_step_equals_dense_solves_of_its_two_stages() {
    let gamma = 2.0 - std::f64::consts::SQRT_2;
    for env in ENVIRONMENTS {
        let (mut model, skin, object, config) = prepared(TimeScheme::TrBdf2);
        let d = dense(&model, &skin, &object, &config, env);
        let h = 0.2;
        let t0 = state(&model, env);
        // Trapezoidal rule to t + γh: C (Tγ − T0) = γh/2 (F(T0) + F(Tγ)).
        let f0 = net_flux(&d, &t0);
        let half = gamma * h / 2.0;
        let rhs: Vec<f64> = (0..t0.len())
            .map(|i| d.capacity[i] * t0[i] + half * (f0[i] + d.source[i]))
            .collect();
        let stage = dense_solve(&d, 1.0, half, &rhs);
        // BDF2 through t, t + γh, t + h: T1 − Tγ/(γ(2−γ)) + (1−γ)²T0/(γ(2−γ)) = (1−γ)/(2−γ) h F(T1).
        let norm = gamma * (2.0 - gamma);
        let w = (1.0 - gamma) / (2.0 - gamma) * h;
        let rhs: Vec<f64> = (0..t0.len())
            .map(|i| d.capacity[i] * (stage[i] / norm - (1.0 - gamma).powi(2) * t0[i] / norm) + w * d.source[i])
            .collect();
        let want = dense_solve(&d, 1.0, w, &rhs);
        model.step(h, env);
        assert_close(&state(&model, env), &want, 1e-10, &format!("TR-BDF2 in {env:?}"));
    }
}

#[test]
fn steady_state_equals_a_dense_solve() {
    for env in ENVIRONMENTS {
        let (mut model, skin, object, config) = prepared(TimeScheme::TrBdf2);
        let d = dense(&model, &skin, &object, &config, env);
        model.set_steady(env).unwrap();
        let want = dense_solve(&d, 0.0, 1.0, &d.source);
        assert_close(&state(&model, env), &want, 1e-9, &format!("steady state in {env:?}"));
    }
}

/// Surface temperature at 1 s after touching stone with R_c = 1e-3, with step `dt_s`.
fn surface_after_one_second(scheme: TimeScheme, dt_s: f64) -> f64 {
    let config = FvConfig {
        scheme,
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    };
    let mut model = FvModel::new(&Skin::fingertip(), Some(&stone(0.01)), &config).unwrap();
    model.set_steady_in_air(23.0).unwrap();
    model.touch(23.0).unwrap();
    for _ in 0..(1.0 / dt_s).round() as usize {
        model.step(dt_s, FvEnvironment::Object);
    }
    model.surface_c()
}

#[test]
fn backward_euler_is_first_order_and_tr_bdf2_second_order_in_time() {
    for (scheme, order) in [(TimeScheme::BackwardEuler, 1.0), (TimeScheme::TrBdf2, 2.0)] {
        let reference = surface_after_one_second(scheme, 1.0 / 12800.0);
        let errors: Vec<f64> = [0.04, 0.02, 0.01]
            .iter()
            .map(|dt| (surface_after_one_second(scheme, *dt) - reference).abs())
            .collect();
        println!("{scheme:?}: |T(1 s) − T_ref| for dt 0.04, 0.02, 0.01 s: {errors:?}");
        for pair in errors.windows(2) {
            let observed = (pair[0] / pair[1]).log2();
            assert!(
                (observed - order).abs() < 0.3,
                "{scheme:?}: observed order {observed}, errors {errors:?}"
            );
        }
    }
}

#[test]
fn calibration_reaches_the_resting_surface_temperature() {
    let mut model = FvModel::new(&Skin::fingertip(), None, &FvConfig::default()).unwrap();
    for target in [30.0, 33.5] {
        let scale = model.calibrate_to_surface(23.0, target).unwrap();
        assert!(
            (model.surface_c() - target).abs() < 1e-8,
            "calibrated surface {} vs {target}",
            model.surface_c()
        );
        assert_eq!(model.perfusion_scale(), scale);
        // The same scale applied to the skin itself gives the same steady state.
        let scaled = Skin::fingertip().with_perfusion_scaled(scale);
        let mut check = FvModel::new(&scaled, None, &FvConfig::default()).unwrap();
        check.set_steady_in_air(23.0).unwrap();
        assert!(
            (check.surface_c() - target).abs() < 1e-8,
            "scaled skin {} vs {target}",
            check.surface_c()
        );
    }
}

#[test]
fn unreachable_calibration_is_an_error_and_changes_nothing() {
    let mut model = FvModel::new(&Skin::fingertip(), None, &FvConfig::default()).unwrap();
    model.set_steady_in_air(23.0).unwrap();
    let before = (model.skin_temperatures_c().to_vec(), model.perfusion_scale());
    // Above arterial blood or below the unperfused skin (which sits at ambient) cannot be reached.
    for target in [37.5, 22.0] {
        let err = model.calibrate_to_surface(23.0, target).unwrap_err();
        assert!(
            matches!(err, ParamError::BadValue { ref source, .. } if source.name == "surface_c"),
            "{err}"
        );
        assert_eq!((model.skin_temperatures_c().to_vec(), model.perfusion_scale()), before);
    }
    assert!(model.calibrate_to_surface(23.0, f64::NAN).is_err());
}

#[test]
fn bad_parameters_are_typed_errors() {
    let skin = Skin::fingertip();
    let bad_configs = [
        FvConfig {
            surface_cell_m: 0.0,
            ..FvConfig::default()
        },
        FvConfig {
            surface_cell_m: f64::NAN,
            ..FvConfig::default()
        },
        FvConfig {
            growth: 0.9,
            ..FvConfig::default()
        },
        FvConfig {
            max_cell_m: 1e-6,
            ..FvConfig::default()
        },
        FvConfig {
            max_step_s: -1.0,
            ..FvConfig::default()
        },
        FvConfig {
            contact_resistance_m2k_w: -1e-3,
            ..FvConfig::default()
        },
        FvConfig {
            deep_boundary: DeepBoundary::Core {
                temperature_c: f64::INFINITY,
            },
            ..FvConfig::default()
        },
        FvConfig {
            far_side: FarSide::Held {
                temperature_c: f64::NAN,
            },
            ..FvConfig::default()
        },
        FvConfig {
            surface_cell_m: 1e-9,
            growth: 1.0,
            max_cell_m: 1e-9,
            ..FvConfig::default()
        },
    ];
    for config in bad_configs {
        assert!(FvModel::new(&skin, None, &config).is_err(), "accepted {config:?}");
    }
    let mut thin = skin.clone();
    thin.layers[1].thickness_m = -1.0;
    assert!(FvModel::new(&thin, None, &FvConfig::default()).is_err());
    assert!(FvModel::new(&skin, Some(&stone(0.0)), &FvConfig::default()).is_err());
    let mut bare = FvModel::new(&skin, None, &FvConfig::default()).unwrap();
    assert!(bare.touch(20.0).is_err(), "touched without an object");
    assert!(
        bare.set_steady(FvEnvironment::Object).is_err(),
        "steady contact without an object"
    );
    assert!(bare.set_skin_uniform(f64::NAN).is_err());
    assert!(bare.set_perfusion_scale(-1.0).is_err());
    assert!(bare.set_steady(FvEnvironment::Air { ambient_c: f64::NAN }).is_err());
    let no_exchange = FvEnvironment::Plate {
        conductance_w_m2k: 0.0,
        temperature_c: 30.0,
    };
    let mut unperfused = FvModel::new(&skin.with_perfusion_scaled(0.0), None, &FvConfig::default()).unwrap();
    assert!(
        unperfused.set_steady(no_exchange).is_err(),
        "a singular steady state was accepted"
    );
    let mut with_object = FvModel::new(&skin, Some(&stone(0.01)), &FvConfig::default()).unwrap();
    assert!(with_object.touch(f64::NAN).is_err());
}

#[test]
fn receptor_affine_does_not_change_the_state() {
    let mut model = FvModel::new(&Skin::fingertip(), None, &FvConfig::default()).unwrap();
    model.set_steady_in_air(23.0).unwrap();
    let before = (
        model.skin_temperatures_c().to_vec(),
        model.energy_ledger(),
        model.environment(),
    );
    let (offset, slope) = model.receptor_affine(0.01, 2000.0);
    assert!(slope > 0.0 && slope < 1.0, "slope {slope}");
    assert!(offset.is_finite(), "offset {offset}");
    assert_eq!(
        (
            model.skin_temperatures_c().to_vec(),
            model.energy_ledger(),
            model.environment()
        ),
        before
    );
}

#[test]
fn refined_configuration_halves_the_width_rule_and_the_step() {
    let base = FvConfig::default();
    let fine = base.refined(2);
    assert_eq!(fine.surface_cell_m, base.surface_cell_m / 4.0);
    assert_eq!(fine.max_cell_m, base.max_cell_m / 4.0);
    assert_eq!(fine.max_step_s, base.max_step_s / 4.0);
    assert!((fine.growth - 1.0375).abs() < 1e-15, "growth {}", fine.growth);
    assert_eq!(base.refined(0), base);
}

#[test]
fn layer_means_and_energy_of_a_uniform_skin() {
    let skin = Skin::fingertip();
    let mut model = FvModel::new(&skin, Some(&stone(0.01)), &FvConfig::default()).unwrap();
    model.set_skin_uniform(30.0).unwrap();
    model.touch(20.0).unwrap();
    assert!(
        model.layer_means_c().iter().all(|t| (t - 30.0).abs() < 1e-12),
        "{:?}",
        model.layer_means_c()
    );
    let capacity: f64 = skin
        .layers
        .iter()
        .map(|l| l.density_kg_m3 * l.specific_heat_j_kgk * l.thickness_m)
        .sum();
    let energy = model.skin_energy_j_m2();
    assert!(
        (energy - 30.0 * capacity).abs() < 1e-9 * energy,
        "skin energy {energy} vs {}",
        30.0 * capacity
    );
    let object_energy = model.object_energy_j_m2();
    let want = 20.0 * 2700.0 * 812.2 * 0.01;
    assert!(
        (object_energy - want).abs() < 1e-9 * want,
        "object energy {object_energy} vs {want}"
    );
}
