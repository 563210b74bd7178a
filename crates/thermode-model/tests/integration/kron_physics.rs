//! Physics checks of the three-layer (Kron) model and the display inverse against independent calculations:
//! a direct Gaussian-elimination solve of the backward-Euler step built from the equations of `model.md` §1,
//! the closed-form steady state of a series resistor chain, first-order step convergence, energy conservation,
//! ordering by conductivity, the exactness of the display inverse, and the surface calibration.

use thermode_model::inverse::{DisplayInverse, PlateCoupled, DEFAULT_DISPLAY_CONDUCTANCE_W_M2K};
use thermode_model::kron::{calibrate_to_surface, KronEnvironment, KronModel};
use thermode_model::materials::{self, Material};
use thermode_model::{ParamError, Skin};

/// Environments the tests use, described independently of the model: (G_env, T_env) for the given skin.
fn env_conductance(skin: &Skin, env: &KronEnvironment) -> (f64, f64) {
    let l1 = &skin.layers[0];
    match *env {
        KronEnvironment::Air { ambient_c } => (skin.air_convection_w_m2k, ambient_c),
        KronEnvironment::Object {
            conductivity_w_mk,
            thickness_m,
            temperature_c,
        } => (
            2.0 / (l1.thickness_m / l1.conductivity_w_mk + thickness_m / conductivity_w_mk),
            temperature_c,
        ),
        KronEnvironment::Plate {
            conductance_w_m2k,
            temperature_c,
        } => (conductance_w_m2k, temperature_c),
    }
}

/// The equations of `model.md` §1 written out: C (capacities), A (3×3), b (3) with dT/dt = C⁻¹ (A T + b).
fn equations(skin: &Skin, env: &KronEnvironment) -> ([f64; 3], [[f64; 3]; 3], [f64; 3]) {
    let l = &skin.layers;
    let c: Vec<f64> = l
        .iter()
        .map(|x| x.density_kg_m3 * x.specific_heat_j_kgk * x.thickness_m)
        .collect();
    let g12 = 2.0 / (l[0].thickness_m / l[0].conductivity_w_mk + l[1].thickness_m / l[1].conductivity_w_mk);
    let g23 = 2.0 / (l[1].thickness_m / l[1].conductivity_w_mk + l[2].thickness_m / l[2].conductivity_w_mk);
    let (g_env, t_env) = env_conductance(skin, env);
    let rho_c_b = skin.blood.density_kg_m3 * skin.blood.specific_heat_j_kgk;
    let p: Vec<f64> = l.iter().map(|x| x.perfusion_per_s * rho_c_b * x.thickness_m).collect();
    let q: Vec<f64> = l.iter().map(|x| x.metabolic_w_m3 * x.thickness_m).collect();
    let t_art = skin.blood.arterial_c;
    let a = [
        [-g_env - g12 - p[0], g12, 0.0],
        [g12, -g12 - g23 - p[1], g23],
        [0.0, g23, -g23 - p[2]],
    ];
    let b = [
        g_env * t_env + q[0] + p[0] * t_art,
        q[1] + p[1] * t_art,
        q[2] + p[2] * t_art,
    ];
    ([c[0], c[1], c[2]], a, b)
}

/// Gaussian elimination with partial pivoting.
fn gauss_solve(mut m: [[f64; 3]; 3], mut r: [f64; 3]) -> [f64; 3] {
    for col in 0..3 {
        let pivot = (col..3)
            .max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))
            .unwrap_or(col);
        m.swap(col, pivot);
        r.swap(col, pivot);
        for row in col + 1..3 {
            let f = m[row][col] / m[col][col];
            let pivot_row = m[col];
            for (entry, pivot_entry) in m[row].iter_mut().zip(pivot_row).skip(col) {
                *entry -= f * pivot_entry;
            }
            r[row] -= f * r[col];
        }
    }
    let mut x = [0.0; 3];
    for row in (0..3).rev() {
        let s: f64 = (row + 1..3).map(|k| m[row][k] * x[k]).sum();
        x[row] = (r[row] - s) / m[row][row];
    }
    x
}

/// One backward-Euler step solved directly: (C − hA) T = C T_old + h b.
fn direct_step(skin: &Skin, env: &KronEnvironment, t_old: [f64; 3], h: f64) -> [f64; 3] {
    let (c, a, b) = equations(skin, env);
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = if i == j { c[i] } else { 0.0 } - h * a[i][j];
        }
    }
    let r = [0, 1, 2].map(|i| c[i] * t_old[i] + h * b[i]);
    gauss_solve(m, r)
}

fn model(skin: &Skin) -> KronModel {
    KronModel::new(skin).unwrap_or_else(|e| panic!("KronModel::new: {e}"))
}

fn material(name: &str) -> Material {
    materials::find(name).unwrap_or_else(|e| panic!("{e}"))
}

/// A skin with perfusion and metabolic heat in every layer, to exercise the per-layer terms.
fn skin_with_sources_everywhere() -> Skin {
    let mut skin = Skin::fingertip();
    for (n, layer) in skin.layers.iter_mut().enumerate() {
        layer.perfusion_per_s = 0.0005 * (n as f64 + 1.0);
        layer.metabolic_w_m3 = 300.0 + 100.0 * n as f64;
    }
    skin
}

fn test_environments() -> Vec<KronEnvironment> {
    vec![
        KronEnvironment::Air { ambient_c: 23.0 },
        KronEnvironment::touching(&material("aluminium"), 23.0),
        KronEnvironment::touching(&material("wood"), 15.0),
        KronEnvironment::Plate {
            conductance_w_m2k: DEFAULT_DISPLAY_CONDUCTANCE_W_M2K,
            temperature_c: 40.0,
        },
    ]
}

#[test]
fn backward_euler_step_equals_direct_solve() {
    for skin in [Skin::fingertip(), skin_with_sources_everywhere()] {
        for env in test_environments() {
            for h in [1e-3, 0.01, 0.5, 30.0] {
                let mut m = model(&skin);
                m.set_temperatures_c([31.0, 33.5, 35.0]);
                let mut want = m.temperatures_c();
                for step in 0..20 {
                    want = direct_step(&skin, &env, want, h);
                    m.step(h, &env);
                    let got = m.temperatures_c();
                    for n in 0..3 {
                        assert!(
                            (got[n] - want[n]).abs() < 1e-10,
                            "{env:?}, h {h}, step {step}, T{}: model {} vs direct solve {}",
                            n + 1,
                            got[n],
                            want[n]
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn steady_state_equals_series_chain_closed_form() {
    let mut skin = Skin::fingertip();
    skin.layers[2].metabolic_w_m3 = 400.0;
    let l = &skin.layers;
    let g12 = 2.0 / (l[0].thickness_m / l[0].conductivity_w_mk + l[1].thickness_m / l[1].conductivity_w_mk);
    let g23 = 2.0 / (l[1].thickness_m / l[1].conductivity_w_mk + l[2].thickness_m / l[2].conductivity_w_mk);
    let p = l[2].perfusion_per_s * skin.blood.density_kg_m3 * skin.blood.specific_heat_j_kgk * l[2].thickness_m;
    let qm = l[2].metabolic_w_m3 * l[2].thickness_m;
    for env in test_environments() {
        let (g_env, t_env) = env_conductance(&skin, &env);
        let g_tot = 1.0 / (1.0 / g_env + 1.0 / g12 + 1.0 / g23);
        let t3 = (p * skin.blood.arterial_c + qm + g_tot * t_env) / (p + g_tot);
        let q = g_tot * (t3 - t_env);
        let t2 = t3 - q / g23;
        let t1 = t2 - q / g12;
        let want = [t1, t2, t3];
        let mut m = model(&skin);
        let steady = m.steady_state_c(&env);
        for n in 0..3 {
            assert!(
                (steady[n] - want[n]).abs() < 1e-10,
                "{env:?} T{}: {} vs closed form {}",
                n + 1,
                steady[n],
                want[n]
            );
        }
        // Heat out of the skin equals the heat through the chain.
        m.settle(&env);
        let flux = m.heat_flux_to_env_w_m2(&env);
        assert!(
            (flux - q).abs() < 1e-9 * q.abs().max(1.0),
            "{env:?}: flux {flux} vs chain {q}"
        );
        // Long stepping from elsewhere converges to it.
        m.set_temperatures_c([20.0, 25.0, 30.0]);
        for _ in 0..20_000 {
            m.step(0.5, &env);
        }
        let got = m.temperatures_c();
        for n in 0..3 {
            assert!(
                (got[n] - want[n]).abs() < 1e-8,
                "{env:?} stepped T{}: {} vs steady {}",
                n + 1,
                got[n],
                want[n]
            );
        }
    }
}

/// T1 after `duration_s` touching `env`, from the steady state in air at 23 °C, with `steps` equal steps.
fn t1_after(skin: &Skin, env: &KronEnvironment, duration_s: f64, steps: usize) -> f64 {
    let mut m = model(skin);
    m.settle(&KronEnvironment::Air { ambient_c: 23.0 });
    let h = duration_s / steps as f64;
    for _ in 0..steps {
        m.step(h, env);
    }
    m.temperatures_c()[0]
}

#[test]
fn halving_the_step_halves_the_error() {
    let skin = Skin::fingertip();
    for name in ["aluminium", "stone", "wood"] {
        let env = KronEnvironment::touching(&material(name), 23.0);
        let duration = 3.0;
        let reference = t1_after(&skin, &env, duration, 300_000);
        let errors: Vec<f64> = [30, 60, 120, 240]
            .iter()
            .map(|&n| (t1_after(&skin, &env, duration, n) - reference).abs())
            .collect();
        for pair in errors.windows(2) {
            let ratio = pair[0] / pair[1];
            assert!(
                (1.8..=2.2).contains(&ratio),
                "{name}: error {} at h, {} at h/2, ratio {ratio} (first order wants 2)",
                pair[0],
                pair[1]
            );
        }
        println!("{name}: T1(3 s) errors for h = 0.1, 0.05, 0.025, 0.0125 s: {errors:?}");
    }
}

#[test]
fn energy_is_conserved_step_by_step() {
    for skin in [Skin::fingertip(), skin_with_sources_everywhere()] {
        for env in test_environments() {
            let (g_env, t_env) = env_conductance(&skin, &env);
            let rho_c_b = skin.blood.density_kg_m3 * skin.blood.specific_heat_j_kgk;
            let mut m = model(&skin);
            m.set_temperatures_c([30.0, 32.0, 34.0]);
            for &h in &[0.01, 0.2, 2.0] {
                for step in 0..50 {
                    let before = m.stored_energy_j_m2();
                    m.step(h, &env);
                    let t = m.temperatures_c();
                    let body: f64 = (0..3)
                        .map(|n| {
                            let l = &skin.layers[n];
                            l.metabolic_w_m3 * l.thickness_m
                                + l.perfusion_per_s * rho_c_b * l.thickness_m * (skin.blood.arterial_c - t[n])
                        })
                        .sum();
                    let want = h * (-g_env * (t[0] - t_env) + body);
                    let got = m.stored_energy_j_m2() - before;
                    // 1e-9 relative, plus the floor set by storing temperatures in f64: ΔE is a difference of
                    // two sums of size E = Σ C_n T_n, each known to a few ulps of E.
                    let floor = 8.0 * f64::EPSILON * before.abs();
                    let tolerance = 1e-9 * want.abs() + floor;
                    assert!(
                        (got - want).abs() <= tolerance,
                        "{env:?}, h {h}, step {step}: ΔE {got} vs h·(−q_env + body) {want}"
                    );
                    // The model's own bookkeeping agrees.
                    let own = h * (-m.heat_flux_to_env_w_m2(&env) + m.body_heat_w_m2());
                    assert!((own - want).abs() <= tolerance, "model bookkeeping {own} vs {want}");
                }
            }
        }
    }
}

#[test]
fn colder_for_more_conductive_objects() {
    let skin = Skin::fingertip();
    let names = ["copper", "aluminium", "steel", "stone", "rubber", "wood"];
    let t10: Vec<f64> = names
        .iter()
        .map(|n| t1_after(&skin, &KronEnvironment::touching(&material(n), 23.0), 10.0, 1000))
        .collect();
    for (n, t) in names.iter().zip(&t10) {
        println!("T1 after 10 s on {n} at 23 °C: {t:.3} °C");
    }
    let at = |name: &str| t10[names.iter().position(|n| *n == name).unwrap_or(0)];
    assert!(
        at("copper") < at("aluminium"),
        "copper {} vs aluminium {}",
        at("copper"),
        at("aluminium")
    );
    assert!(
        at("aluminium") < at("steel"),
        "aluminium {} vs steel {}",
        at("aluminium"),
        at("steel")
    );
    assert!(
        at("steel") < at("stone"),
        "steel {} vs stone {}",
        at("steel"),
        at("stone")
    );
    assert!(at("stone") < at("wood"), "stone {} vs wood {}", at("stone"), at("wood"));
    assert!(
        at("rubber") > at("stone"),
        "rubber {} vs stone {}",
        at("rubber"),
        at("stone")
    );
    let rest = model(&skin).temperatures_c()[0];
    assert!(
        t10.iter().all(|&t| t < rest && t > 23.0),
        "every contact cools, none below the object: {t10:?}"
    );
}

#[test]
fn paper_materials_cool_monotonically_towards_the_contact_steady_state() {
    let skin = Skin::fingertip();
    let times = [1.0, 5.0, 10.0, 30.0, 90.0];
    println!("T1 [°C] (Kron, object at 23 °C, from the steady state in air at 23 °C), at {times:?} s:");
    for m in materials::paper_materials() {
        let env = KronEnvironment::touching(&m, 23.0);
        let mut k = model(&skin);
        let rest = k.temperatures_c()[0];
        let steady = k.steady_state_c(&env)[0];
        let mut row = Vec::new();
        let h = 0.01;
        for step in 1..=9000 {
            k.step(h, &env);
            let t = step as f64 * h;
            if times.iter().any(|&x| (x - t).abs() < 1e-9) {
                row.push(k.temperatures_c()[0]);
            }
        }
        println!(
            "  {:<10} {:?}  (rest {rest:.3}, contact steady state {steady:.3})",
            m.name, row
        );
        assert_eq!(row.len(), times.len());
        let mut previous = rest;
        for (&t, &v) in times.iter().zip(&row) {
            assert!(
                v < previous && v > steady,
                "{} at {t} s: {v}, before {previous}, steady {steady}",
                m.name
            );
            previous = v;
        }
    }
}

/// Target skin temperatures: the Kron model touching `env`, `steps` steps of `h`.
fn target_trajectory(skin: &Skin, env: &KronEnvironment, h: f64, steps: usize) -> Vec<f64> {
    let mut renderer = model(skin);
    (0..steps)
        .map(|_| {
            renderer.step(h, env);
            renderer.temperatures_c()[0]
        })
        .collect()
}

#[test]
fn unlimited_inverse_makes_the_finger_follow_the_target_exactly() {
    let skin = Skin::fingertip();
    let h = 0.01;
    for name in ["aluminium", "wood"] {
        let targets = target_trajectory(&skin, &KronEnvironment::touching(&material(name), 23.0), h, 3000);
        let mut inverse =
            DisplayInverse::new(model(&skin), DEFAULT_DISPLAY_CONDUCTANCE_W_M2K).unwrap_or_else(|e| panic!("{e}"));
        for (step, &target) in targets.iter().enumerate() {
            let setpoint = inverse.setpoint_c(target, h);
            inverse.advance(h, setpoint);
            let got = inverse.receptor_c();
            assert!(
                (got - target).abs() < 1e-9,
                "{name} step {step}: finger {got} vs target {target}"
            );
        }
    }
}

#[test]
fn inverse_recovers_a_known_display_trajectory() {
    let skin = Skin::fingertip();
    let g = 600.0;
    let h = 0.02;
    let plate = |p: usize| 30.0 + 6.0 * (0.3 * p as f64 * h).sin() - 0.002 * p as f64;
    let mut forward = model(&skin);
    let mut inverse = DisplayInverse::new(model(&skin), g).unwrap_or_else(|e| panic!("{e}"));
    for p in 0..2000 {
        forward.step_on_plate(h, g, plate(p));
        let recovered = inverse.setpoint_c(forward.receptor_c(), h);
        assert!(
            (recovered - plate(p)).abs() < 1e-7,
            "step {p}: recovered {recovered} vs applied {}",
            plate(p)
        );
        inverse.advance(h, recovered);
    }
}

#[test]
fn clamped_setpoint_continues_the_model_with_the_clamp() {
    let skin = Skin::fingertip();
    let h = 0.01;
    let (lo, hi) = (15.0, 45.0);
    let targets = target_trajectory(&skin, &KronEnvironment::touching(&material("copper"), 5.0), h, 500);
    let mut inverse =
        DisplayInverse::new(model(&skin), DEFAULT_DISPLAY_CONDUCTANCE_W_M2K).unwrap_or_else(|e| panic!("{e}"));
    let mut shadow = model(&skin);
    let mut clamped_steps = 0;
    for (step, &target) in targets.iter().enumerate() {
        let setpoint = inverse.setpoint_c(target, h);
        let applied = setpoint.clamp(lo, hi);
        inverse.advance(h, applied);
        shadow.step(
            h,
            &KronEnvironment::Plate {
                conductance_w_m2k: DEFAULT_DISPLAY_CONDUCTANCE_W_M2K,
                temperature_c: applied,
            },
        );
        assert_eq!(inverse.model().temperatures_c(), shadow.temperatures_c(), "step {step}");
        if applied != setpoint {
            clamped_steps += 1;
            // The finger receives less cold than asked: it stays warmer than the target.
            assert!(
                inverse.receptor_c() > target,
                "step {step}: finger {} vs target {target}",
                inverse.receptor_c()
            );
        }
    }
    assert!(clamped_steps > 10, "the clamp never acted ({clamped_steps} steps)");
}

#[test]
fn calibration_hits_the_requested_surface_temperature() {
    let skin = Skin::fingertip();
    for (ambient, surface) in [(23.0, 28.0), (23.0, 30.5), (23.0, 34.0), (18.0, 25.0), (28.0, 33.0)] {
        let calibrated = calibrate_to_surface(&skin, ambient, surface).unwrap_or_else(|e| panic!("{e}"));
        // Independent check: closed-form series chain with the calibrated perfusion.
        let l = &calibrated.layers;
        let r = |n: usize| l[n].thickness_m / l[n].conductivity_w_mk;
        let g_tot = 1.0 / (1.0 / calibrated.air_convection_w_m2k + (r(0) + r(1)) / 2.0 + (r(1) + r(2)) / 2.0);
        let p = l[2].perfusion_per_s * 1060.0 * 3800.0 * l[2].thickness_m;
        let t3 = (p * 36.8 + g_tot * ambient) / (p + g_tot);
        let t1 = ambient + g_tot * (t3 - ambient) / calibrated.air_convection_w_m2k;
        assert!(
            (t1 - surface).abs() < 1e-6,
            "ambient {ambient}: calibrated T1 {t1} vs requested {surface}"
        );
        let stepped = model(&calibrated).steady_state_c(&KronEnvironment::Air { ambient_c: ambient })[0];
        assert!(
            (stepped - surface).abs() < 1e-6,
            "model steady T1 {stepped} vs requested {surface}"
        );
        // Only perfusion changed.
        for (a, b) in skin.layers.iter().zip(&calibrated.layers) {
            assert_eq!(
                (a.thickness_m, a.conductivity_w_mk),
                (b.thickness_m, b.conductivity_w_mk)
            );
        }
    }
}

#[test]
fn calibration_rejects_unreachable_surfaces() {
    let skin = Skin::fingertip();
    for surface in [23.0, 22.0, 35.5, 36.8, 40.0, f64::NAN] {
        match calibrate_to_surface(&skin, 23.0, surface) {
            Err(ParamError::BadValue { source, .. }) => assert_eq!(source.name, "surface_c", "surface {surface}"),
            other => panic!("surface {surface}: expected BadValue, got {other:?}"),
        }
    }
    let message = calibrate_to_surface(&skin, 23.0, 36.0)
        .map(|_| ())
        .unwrap_err()
        .to_string();
    assert!(message.contains("between"), "{message}");
    match calibrate_to_surface(&skin, 37.0, 38.0) {
        Err(ParamError::BadValue { source, .. }) => assert_eq!(source.name, "ambient_c"),
        other => panic!("expected BadValue for ambient, got {other:?}"),
    }
    let unperfused = skin.with_perfusion_scaled(0.0);
    assert!(matches!(
        calibrate_to_surface(&unperfused, 23.0, 30.0),
        Err(ParamError::Invalid { .. })
    ));
    let mut two_layers = skin.clone();
    two_layers.layers.pop();
    assert!(matches!(
        calibrate_to_surface(&two_layers, 23.0, 30.0),
        Err(ParamError::Invalid { .. })
    ));
}
