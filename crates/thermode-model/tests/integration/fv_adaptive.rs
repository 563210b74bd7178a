//! Physics tests of the adaptive time stepping of the finite-volume contact model ([`FvConfig::tolerance_c`]):
//! against the analytic semi-infinite contact with contact resistance, convergence as the tolerance falls, energy
//! conservation step by step (accepted steps balance the ledger, rejected ones change nothing) and bit-identical
//! reruns.

use thermode_model::fv::{simulate_contact, ContactSpec, FvConfig, FvEnvironment, FvModel, InitialState};
use thermode_model::materials::{self, Material};
use thermode_model::semi_infinite::surface_temperature_c;
use thermode_model::Skin;

use super::fv_physics::homogeneous_skin;

const SKIN_C: f64 = 33.0;

/// A slab of `material` 8 diffusion lengths over 10 s thick (at least 1 cm): semi-infinite over the run.
fn thick(material: &str) -> Material {
    let m = materials::find(material).unwrap();
    let diffusion_length_m = (m.conductivity_w_mk / (m.density_kg_m3 * m.specific_heat_j_kgk) * 10.0).sqrt();
    Material {
        thickness_m: (8.0 * diffusion_length_m).max(0.01),
        ..m
    }
}

fn contact_spec(duration_s: f64, output_dt_s: f64) -> ContactSpec {
    ContactSpec {
        object_c: 23.0,
        initial: InitialState::Uniform { temperature_c: SKIN_C },
        duration_s,
        output_dt_s,
        ..ContactSpec::default()
    }
}

fn max_abs_difference(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn adaptive_run_matches_the_analytic_semi_infinite_contact() {
    let skin = homogeneous_skin();
    let skin_e = (0.37f64 * 1100.0 * 3500.0).sqrt();
    for material in ["aluminium", "stone", "wood"] {
        let object = thick(material);
        for contact_resistance in [1e-3, 2e-4] {
            let config = FvConfig {
                contact_resistance_m2k_w: contact_resistance,
                ..FvConfig::default()
            }
            .refined(2);
            let spec = contact_spec(10.0, 0.01);
            let run = simulate_contact(&skin, &object, &config, &spec).unwrap();
            let mut worst = 0.0f64;
            for (t, got) in run.time_s.iter().zip(&run.surface_c).skip(1) {
                let want = surface_temperature_c(skin_e, SKIN_C, object.effusivity(), 23.0, contact_resistance, *t);
                worst = worst.max((got - want).abs());
                // Tolerance: the grid's spatial error at refinement 2 (about 2e-3 °C at the first rows) plus the
                // time error of the default tolerance (about 1e-4 °C), with margin.
                assert!(
                    (got - want).abs() < 5e-3,
                    "{material}, R_c {contact_resistance}, t = {t} s: adaptive fv {got} vs analytic {want}"
                );
            }
            println!(
                "{material}, R_c {contact_resistance:e}: {} steps ({} rejected), max |fv − analytic| {worst:.2e} °C",
                run.steps.accepted, run.steps.rejected
            );
            assert!(
                run.steps.accepted < 1000,
                "{material}: {} steps for 1000 output rows: the step does not adapt",
                run.steps.accepted
            );
        }
    }
}

#[test]
fn error_falls_as_the_tolerance_falls() {
    let skin = Skin::fingertip();
    let aluminium = materials::find("aluminium").unwrap();
    let spec = ContactSpec {
        duration_s: 20.0,
        output_dt_s: 0.01,
        ..ContactSpec::default()
    };
    let base = FvConfig {
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    };
    let run_with = |tolerance_c: Option<f64>, max_step_s: f64| {
        let config = FvConfig {
            tolerance_c,
            max_step_s,
            ..base.clone()
        };
        simulate_contact(&skin, &aluminium, &config, &spec).unwrap()
    };
    // Reference: fixed TR-BDF2 steps of 0.1 ms (time error about 1e-7 °C on this grid).
    let reference = run_with(None, 1e-4);
    let tolerances = [1e-3, 1e-4, 1e-5, 1e-6];
    let errors: Vec<f64> = tolerances
        .iter()
        .map(|tol| max_abs_difference(&run_with(Some(*tol), 0.01).surface_c, &reference.surface_c))
        .collect();
    println!("tolerance {tolerances:?} → max error vs 0.1 ms fixed steps {errors:?} °C",);
    for (pair, tol) in errors.windows(2).zip(&tolerances[1..]) {
        assert!(pair[1] < pair[0], "error does not fall at tolerance {tol}: {errors:?}");
    }
    // A second-order method under local error control: the global error scales about as tolerance^(2/3), so
    // three decades of tolerance give at least a factor 50 (100 expected).
    assert!(
        errors[3] < errors[0] / 50.0,
        "error falls too slowly with the tolerance: {errors:?}"
    );
    // The default tolerance keeps the time error well below the 0.005 °C of a converged trajectory.
    let default_error = max_abs_difference(&run_with(base.tolerance_c, 0.01).surface_c, &reference.surface_c);
    assert!(default_error < 5e-4, "default tolerance: error {default_error} °C");
}

/// Runs adaptive steps by hand on `model` for `duration_s`, checking after every attempt that a rejected step
/// changed nothing and an accepted one balances the ledger; returns (accepted, rejected).
fn stepped_with_checks(model: &mut FvModel, duration_s: f64, tolerance_c: f64) -> (usize, usize) {
    let start_skin = model.skin_energy_j_m2();
    let start_object = model.object_energy_j_m2();
    let (mut done_s, mut h, mut accepted, mut rejected) = (0.0, 1e-6f64, 0, 0);
    while done_s < duration_s {
        let before = (model.skin_temperatures_c().to_vec(), model.energy_ledger());
        let step_s = h.min(duration_s - done_s);
        let error_c = model.step_with_error(step_s, FvEnvironment::Object, tolerance_c);
        if error_c > tolerance_c {
            rejected += 1;
            assert_eq!(
                model.skin_temperatures_c(),
                before.0.as_slice(),
                "rejected step changed the state"
            );
            assert_eq!(model.energy_ledger(), before.1, "rejected step changed the ledger");
            h *= 0.5;
            continue;
        }
        accepted += 1;
        done_s += step_s;
        h *= 1.5;
        let ledger = model.energy_ledger();
        let skin_in =
            ledger.perfusion_j_m2 + ledger.metabolic_j_m2 + ledger.deep_in_j_m2 - ledger.skin_surface_out_j_m2;
        let object_in = ledger.object_contact_in_j_m2 + ledger.object_far_side_in_j_m2;
        let skin_gain = model.skin_energy_j_m2() - start_skin;
        let object_gain = model.object_energy_j_m2() - start_object;
        // Rounding of Σ C·T (about 1e6 J/m² in the skin) at 1e-16 relative per operation over the cells.
        assert!(
            (skin_gain - skin_in).abs() < 1e-6,
            "t = {done_s} s: skin gained {skin_gain} J/m², ledger says {skin_in}"
        );
        assert!(
            (object_gain - object_in).abs() < 1e-6 * object_gain.abs().max(1.0),
            "t = {done_s} s: object gained {object_gain} J/m², ledger says {object_in}"
        );
        assert!(
            (ledger.skin_surface_out_j_m2 - ledger.object_contact_in_j_m2).abs() < 1e-9,
            "heat left the skin ({}) but did not enter the object ({})",
            ledger.skin_surface_out_j_m2,
            ledger.object_contact_in_j_m2
        );
    }
    (accepted, rejected)
}

#[test]
fn adaptive_steps_conserve_energy_and_rejected_steps_change_nothing() {
    let mut skin = Skin::fingertip();
    skin.layers[2].perfusion_per_s = 0.002;
    let config = FvConfig {
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    };
    let mut model = FvModel::new(&skin, Some(&materials::find("stone").unwrap()), &config).unwrap();
    model.set_steady_in_air(23.0).unwrap();
    model.touch(15.0).unwrap();
    model.reset_energy_ledger();
    let (accepted, rejected) = stepped_with_checks(&mut model, 10.0, 1e-5);
    println!("{accepted} steps accepted, {rejected} rejected");
    assert!(
        rejected > 0,
        "the growing step was never rejected: the test checked no rejection"
    );
    assert!(
        model.energy_ledger().skin_surface_out_j_m2 > 100.0,
        "hardly any heat flowed"
    );
}

#[test]
fn reruns_are_bit_identical_and_equal_steps_share_their_bits() {
    let skin = Skin::fingertip();
    let aluminium = materials::find("aluminium").unwrap();
    let config = FvConfig {
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    };
    let spec = ContactSpec {
        duration_s: 30.0,
        ..ContactSpec::default()
    };
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let first = simulate_contact(&skin, &aluminium, &config, &spec).unwrap();
    let second = simulate_contact(&skin, &aluminium, &config, &spec).unwrap();
    assert_eq!(bits(&first.surface_c), bits(&second.surface_c));
    assert_eq!(bits(&first.heat_flux_w_m2), bits(&second.heat_flux_w_m2));
    assert_eq!(first.steps, second.steps);
    println!(
        "adaptive, 30 s: {} steps, {} rejected, {} eliminations",
        first.steps.accepted, first.steps.rejected, first.factorisations
    );
    // Each attempt is one elimination at most (the error estimate reuses the step's), and steps that stay on a
    // ladder rung share one: measured 65 for 200 steps; without the ladder every step would refactorise.
    assert!(
        2 * first.factorisations <= first.steps.accepted + first.steps.rejected,
        "{} eliminations for {} attempts",
        first.factorisations,
        first.steps.accepted + first.steps.rejected
    );
    // Fixed steps: 0.01 s rows split into 0.0025 s steps. Every full interval is stepped with the same bits, so
    // a run over k intervals equals k repetitions of one interval's steps from the same state.
    let fixed = FvConfig {
        tolerance_c: None,
        max_step_s: 0.0025,
        ..config.clone()
    };
    let spec = ContactSpec {
        duration_s: 0.5,
        ..ContactSpec::default()
    };
    let run = simulate_contact(&skin, &aluminium, &fixed, &spec).unwrap();
    // One elimination for the whole run: every step has the same bits.
    assert_eq!(run.factorisations, 1, "fixed steps of equal intent refactorised");
    let mut model = FvModel::new(&skin, Some(&aluminium), &fixed).unwrap();
    model.set_steady_in_air(23.0).unwrap();
    model.touch(23.0).unwrap();
    for _ in 0..200 {
        model.step(0.01 / 4.0, FvEnvironment::Object);
    }
    assert_eq!(
        run.surface_c.last().unwrap().to_bits(),
        model.surface_c().to_bits(),
        "fixed-step run {} vs 200 steps of 0.0025 s {}",
        run.surface_c.last().unwrap(),
        model.surface_c()
    );
}

#[test]
fn contact_rows_equal_the_interpolated_state_of_advance_adaptive() {
    // simulate_contact interpolates the recorded quantities directly; advance_adaptive interpolates the whole
    // state and reads it. Same steps, same interpolant: equal to rounding.
    let skin = Skin::fingertip();
    let stone = materials::find("stone").unwrap();
    let config = FvConfig {
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    };
    let spec = ContactSpec {
        duration_s: 12.0,
        output_dt_s: 0.05,
        object_c: 40.0,
        ..ContactSpec::default()
    };
    let run = simulate_contact(&skin, &stone, &config, &spec).unwrap();
    let mut model = FvModel::new(&skin, Some(&stone), &config).unwrap();
    model.set_steady_in_air(spec.ambient_c).unwrap();
    model.touch(spec.object_c).unwrap();
    let times: Vec<f64> = run.time_s[1..].to_vec();
    let mut rows = Vec::new();
    let counts = model
        .advance_adaptive(
            FvEnvironment::Object,
            spec.duration_s,
            config.tolerance_c.unwrap(),
            times,
            |m, t| {
                rows.push((
                    t,
                    m.surface_c(),
                    m.object_face_c().unwrap(),
                    m.surface_heat_flux_w_m2(),
                    m.layer_means_c(),
                ))
            },
        )
        .unwrap();
    assert_eq!(counts, run.steps);
    assert_eq!(rows.len(), run.time_s.len() - 1);
    for (k, (t, surface, face, flux, means)) in rows.iter().enumerate() {
        let row = k + 1;
        assert_eq!(*t, run.time_s[row]);
        let pairs = [
            (*surface, run.surface_c[row], 1e-10),
            (*face, run.object_face_c[row], 1e-10),
            (*flux, run.heat_flux_w_m2[row], 1e-6),
        ];
        for (a, b, tol) in pairs {
            assert!((a - b).abs() <= tol, "t = {t} s: state interpolant {a} vs recorded {b}");
        }
        for (a, b) in means.iter().zip(&run.layer_mean_c[row]) {
            assert!((a - b).abs() <= 1e-10, "t = {t} s: layer mean {a} vs {b}");
        }
    }
    // The model ends exactly at the duration, as the run's last row.
    assert!((model.surface_c() - run.surface_c[run.surface_c.len() - 1]).abs() <= 1e-10);
}

#[test]
fn an_unreachable_tolerance_is_an_error_not_a_hang() {
    let config = FvConfig {
        tolerance_c: Some(1e-300),
        ..FvConfig::default()
    };
    let spec = ContactSpec {
        duration_s: 1.0,
        ..ContactSpec::default()
    };
    let stone = materials::find("stone").unwrap();
    let err = simulate_contact(&Skin::fingertip(), &stone, &config, &spec).unwrap_err();
    assert!(err.to_string().contains("stalled"), "{err}");
    let mut model = FvModel::new(&Skin::fingertip(), Some(&stone), &FvConfig::default()).unwrap();
    model.touch(23.0).unwrap();
    let err = model
        .advance_adaptive(FvEnvironment::Object, 1.0, 1e-300, [0.5], |_, _| {})
        .unwrap_err();
    assert!(err.to_string().contains("stalled"), "{err}");
    let bad = model.advance_adaptive(FvEnvironment::Object, f64::NAN, 1e-5, [0.5], |_, _| {});
    assert!(bad.is_err(), "NaN duration accepted");
    let bad = model.advance_adaptive(FvEnvironment::Object, 1.0, -1.0, [0.5], |_, _| {});
    assert!(bad.is_err(), "negative tolerance accepted");
}
