//! Physics tests of the finite-volume contact model against analytic solutions (`model.md` §4): the interface
//! temperature of two semi-infinite bodies with and without contact resistance, the erf profile in the skin and the
//! object, conservation of energy, steady conduction through slabs in series (and a perfused slab), grid
//! convergence with its observed order, the display-inverse interface, and ordering by effusivity.

use thermode_model::fv::{
    simulate_contact, simulate_contact_converged, ContactSpec, DeepBoundary, FarSide, FvConfig, FvEnvironment, FvModel,
    Refinement, TimeScheme,
};
use thermode_model::inverse::PlateCoupled;
use thermode_model::materials::{self, Material};
use thermode_model::semi_infinite::{interface_temperature_c, skin_temperature_at_depth_c, surface_temperature_c};
use thermode_model::{Blood, Skin, SkinLayer};

const SKIN_C: f64 = 33.0;
const TIMES_S: [f64; 5] = [0.5, 1.0, 2.0, 5.0, 10.0];
const STEP_S: f64 = 0.01;

/// A homogeneous skin 30 mm thick without perfusion: semi-infinite over 10 s (heat penetrates about 1 mm).
pub(crate) fn homogeneous_skin() -> Skin {
    Skin {
        layers: vec![SkinLayer {
            name: "skin".into(),
            thickness_m: 0.03,
            conductivity_w_mk: 0.37,
            density_kg_m3: 1100.0,
            specific_heat_j_kgk: 3500.0,
            perfusion_per_s: 0.0,
            metabolic_w_m3: 0.0,
        }],
        blood: Blood {
            arterial_c: 36.8,
            density_kg_m3: 1060.0,
            specific_heat_j_kgk: 3800.0,
        },
        air_convection_w_m2k: 10.0,
    }
}

fn skin_effusivity() -> f64 {
    (0.37f64 * 1100.0 * 3500.0).sqrt()
}

fn skin_diffusivity() -> f64 {
    0.37 / (1100.0 * 3500.0)
}

/// An object thick enough to be semi-infinite over 10 s: 8 diffusion lengths √(a·10 s), at least 1 cm.
fn thick(name: &str, k: f64, rho: f64, c: f64) -> Material {
    let diffusion_length_m = (k / (rho * c) * 10.0).sqrt();
    Material {
        name: name.into(),
        conductivity_w_mk: k,
        density_kg_m3: rho,
        specific_heat_j_kgk: c,
        thickness_m: (8.0 * diffusion_length_m).max(0.01),
        source: "test".into(),
    }
}

/// Cork to copper, including the paper's five (Table 1 in SI).
fn materials_cork_to_copper() -> Vec<Material> {
    vec![
        thick("cork", 0.04, 120.0, 1800.0),
        thick("rubber", 0.1340, 990.0, 1620.3),
        thick("wood", 0.1382, 600.0, 2503.7),
        thick("stone", 2.763, 2700.0, 812.2),
        thick("steel", 46.05, 7850.0, 502.4),
        thick("aluminium", 220.2, 2700.0, 900.2),
        thick("copper", 400.0, 8960.0, 385.0),
    ]
}

/// Homogeneous skin at 33 °C touching `material` at `object_c` through `contact_resistance`.
fn touching(material: &Material, object_c: f64, contact_resistance: f64, config: &FvConfig) -> FvModel {
    let config = FvConfig {
        contact_resistance_m2k_w: contact_resistance,
        ..config.clone()
    };
    let mut model = FvModel::new(&homogeneous_skin(), Some(material), &config).unwrap();
    model.set_skin_uniform(SKIN_C).unwrap();
    model.touch(object_c).unwrap();
    model
}

fn steps_until(model: &mut FvModel, done_s: &mut f64, until_s: f64, dt_s: f64) {
    let steps = ((until_s - *done_s) / dt_s).round() as usize;
    for _ in 0..steps {
        model.step(dt_s, FvEnvironment::Object);
    }
    *done_s += steps as f64 * dt_s;
}

/// Largest |fv − analytic| surface temperature over `TIMES_S`.
fn worst_surface_error(material: &Material, object_c: f64, contact_resistance: f64, config: &FvConfig) -> f64 {
    let mut model = touching(material, object_c, contact_resistance, config);
    let mut done_s = 0.0;
    let mut worst: f64 = 0.0;
    for time_s in TIMES_S {
        steps_until(&mut model, &mut done_s, time_s, config.max_step_s);
        let e_o = material.effusivity();
        let want = surface_temperature_c(skin_effusivity(), SKIN_C, e_o, object_c, contact_resistance, done_s);
        let got = model.surface_c();
        assert!(
            (got - want).abs() < 0.05,
            "{} at {object_c} °C, R_c = {contact_resistance}, t = {done_s} s: fv {got} vs analytic {want}",
            material.name
        );
        worst = worst.max((got - want).abs());
    }
    worst
}

fn sci(values: &[f64]) -> String {
    values.iter().map(|v| format!("{v:.2e}")).collect::<Vec<_>>().join(", ")
}

#[test]
fn perfect_contact_gives_the_analytic_interface_temperature_from_cork_to_copper() {
    for material in materials_cork_to_copper() {
        for object_c in [23.0, 43.0] {
            let worst = worst_surface_error(&material, object_c, 0.0, &FvConfig::default());
            println!(
                "perfect contact, {:10} at {object_c} °C: max |fv − T_c| = {worst:.2e} °C",
                material.name
            );
        }
    }
}

#[test]
fn contact_resistance_matches_the_analytic_surface_temperature() {
    for contact_resistance in [1e-3, 5e-4] {
        for material in materials_cork_to_copper() {
            let worst = worst_surface_error(&material, 23.0, contact_resistance, &FvConfig::default());
            println!(
                "R_c = {contact_resistance:e}, {:10}: max |fv − analytic| = {worst:.2e} °C",
                material.name
            );
        }
    }
}

#[test]
fn profiles_in_skin_and_object_match_erf_solutions() {
    for material in materials_cork_to_copper() {
        let mut model = touching(&material, 23.0, 0.0, &FvConfig::default());
        let e_o = material.effusivity();
        let contact_c = interface_temperature_c(skin_effusivity(), SKIN_C, e_o, 23.0);
        let mut done_s = 0.0;
        let mut worst: f64 = 0.0;
        for time_s in [1.0, 5.0] {
            steps_until(&mut model, &mut done_s, time_s, STEP_S);
            let skin = model.skin_temperatures_c().iter().zip(model.skin_cell_centres_m());
            for (got, depth_m) in skin {
                let want = skin_temperature_at_depth_c(contact_c, SKIN_C, skin_diffusivity(), *depth_m, done_s);
                assert!(
                    (got - want).abs() < 0.05,
                    "{} skin x = {depth_m} m: fv {got} vs erf {want}",
                    material.name
                );
                worst = worst.max((got - want).abs());
            }
            // Object: T = T_o + (T_c − T_o) erfc(x / 2√(a_o t)), the same formula with the roles exchanged.
            let object = model.object_temperatures_c().iter().zip(model.object_cell_centres_m());
            for (got, x_m) in object {
                let want = skin_temperature_at_depth_c(contact_c, 23.0, material.diffusivity_m2_s(), *x_m, done_s);
                assert!(
                    (got - want).abs() < 0.05,
                    "{} object x = {x_m} m: fv {got} vs erf {want}",
                    material.name
                );
                worst = worst.max((got - want).abs());
            }
        }
        println!(
            "profiles, {:10}: max |fv − erf| over skin and object cells = {worst:.2e} °C",
            material.name
        );
    }
}

/// A three-layer skin with perfusion and metabolic heat in every layer (to exercise every term).
fn busy_skin() -> Skin {
    let mut skin = Skin::fingertip();
    for (i, layer) in skin.layers.iter_mut().enumerate() {
        layer.perfusion_per_s = 0.001 * (i + 1) as f64;
        layer.metabolic_w_m3 = 400.0 * (i + 1) as f64;
    }
    skin
}

fn assert_ledger_balances(model: &FvModel, skin_before: f64, object_before: f64, label: &str) {
    let ledger = model.energy_ledger();
    let skin_change = model.skin_energy_j_m2() - skin_before;
    let skin_flows = ledger.perfusion_j_m2 + ledger.metabolic_j_m2 + ledger.deep_in_j_m2 - ledger.skin_surface_out_j_m2;
    let object_change = model.object_energy_j_m2() - object_before;
    let object_flows = ledger.object_contact_in_j_m2 + ledger.object_far_side_in_j_m2;
    let scale = [
        ledger.perfusion_j_m2,
        ledger.metabolic_j_m2,
        ledger.deep_in_j_m2,
        ledger.skin_surface_out_j_m2,
    ]
    .iter()
    .chain(&[ledger.object_contact_in_j_m2, ledger.object_far_side_in_j_m2])
    .fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 1.0, "{label}: nothing flowed ({scale} J/m²)");
    assert!(
        (skin_change - skin_flows).abs() <= 1e-9 * scale,
        "{label}: skin energy change {skin_change} J/m² vs boundary and source flows {skin_flows} J/m²"
    );
    assert!(
        (object_change - object_flows).abs() <= 1e-9 * scale,
        "{label}: object energy change {object_change} J/m² vs flows {object_flows} J/m²"
    );
    println!(
        "{label}: skin Δ{skin_change:.6} vs {skin_flows:.6}, object Δ{object_change:.6} vs {object_flows:.6} J/m² \
         (relative {:.1e}, {:.1e})",
        (skin_change - skin_flows).abs() / scale,
        (object_change - object_flows).abs() / scale
    );
}

#[test]
fn energy_is_conserved_through_air_contact_and_plate() {
    for scheme in [TimeScheme::TrBdf2, TimeScheme::BackwardEuler] {
        let config = FvConfig {
            deep_boundary: DeepBoundary::Core { temperature_c: 36.0 },
            far_side: FarSide::Held { temperature_c: 20.0 },
            contact_resistance_m2k_w: 1e-3,
            scheme,
            ..FvConfig::default()
        };
        let stone = Material {
            thickness_m: 0.005,
            ..thick("stone", 2.763, 2700.0, 812.2)
        };
        let mut model = FvModel::new(&busy_skin(), Some(&stone), &config).unwrap();
        model.set_steady_in_air(23.0).unwrap();
        model.set_skin_uniform(31.0).unwrap();
        model.touch(25.0).unwrap();
        let (skin_before, object_before) = (model.skin_energy_j_m2(), model.object_energy_j_m2());
        for _ in 0..200 {
            model.step(0.01, FvEnvironment::Air { ambient_c: 23.0 });
        }
        for _ in 0..1000 {
            model.step(0.01, FvEnvironment::Object);
        }
        for _ in 0..100 {
            model.step(
                0.02,
                FvEnvironment::Plate {
                    conductance_w_m2k: 2000.0,
                    temperature_c: 40.0,
                },
            );
        }
        assert_ledger_balances(&model, skin_before, object_before, &format!("{scheme:?}"));
    }
}

#[test]
fn insulated_system_keeps_its_energy_and_skin_loss_is_object_gain_every_step() {
    let skin = homogeneous_skin();
    let config = FvConfig {
        contact_resistance_m2k_w: 5e-4,
        ..FvConfig::default()
    };
    let steel = Material {
        thickness_m: 0.004,
        ..thick("steel", 46.05, 7850.0, 502.4)
    };
    let mut model = FvModel::new(&skin, Some(&steel), &config).unwrap();
    model.set_skin_uniform(34.0).unwrap();
    model.touch(15.0).unwrap();
    let total_before = model.skin_energy_j_m2() + model.object_energy_j_m2();
    let mut moved = 0.0;
    for _ in 0..2000 {
        let (skin_before, object_before) = (model.skin_energy_j_m2(), model.object_energy_j_m2());
        let out_before = model.energy_ledger().skin_surface_out_j_m2;
        model.step(0.01, FvEnvironment::Object);
        let skin_loss = skin_before - model.skin_energy_j_m2();
        let object_gain = model.object_energy_j_m2() - object_before;
        let through_surface = model.energy_ledger().skin_surface_out_j_m2 - out_before;
        let tolerance = 1e-9 * through_surface.abs().max(1.0);
        assert!(
            (skin_loss - object_gain).abs() <= tolerance,
            "skin lost {skin_loss}, object gained {object_gain}"
        );
        assert!(
            (through_surface - object_gain).abs() <= tolerance,
            "out of skin {through_surface}, in {object_gain}"
        );
        moved += object_gain;
    }
    let total_after = model.skin_energy_j_m2() + model.object_energy_j_m2();
    assert!(moved > 1e4, "the test must move heat: {moved} J/m²");
    assert!(
        (total_after - total_before).abs() <= 1e-12 * total_before,
        "total energy {total_after} J/m² vs {total_before} J/m² before ({moved} J/m² moved)"
    );
    println!("insulated: total {total_before} → {total_after} J/m² after moving {moved:.1} J/m²");
}

/// Skin layers without perfusion, for slab-in-series tests.
fn unperfused_fingertip() -> Skin {
    Skin::fingertip().with_perfusion_scaled(0.0)
}

/// Resistance [m²K/W] from the skin surface down to depth `depth_m`.
fn resistance_to_depth(skin: &Skin, depth_m: f64) -> f64 {
    let mut top = 0.0;
    let mut r = 0.0;
    for layer in &skin.layers {
        let inside = (depth_m - top).clamp(0.0, layer.thickness_m);
        r += inside / layer.conductivity_w_mk;
        top += layer.thickness_m;
    }
    r
}

#[test]
fn steady_state_in_contact_is_the_slab_series_solution() {
    let skin = unperfused_fingertip();
    let stone = Material {
        thickness_m: 0.01,
        ..thick("stone", 2.763, 2700.0, 812.2)
    };
    let (core_c, far_c, r_c) = (36.0, 20.0, 1e-3);
    let config = FvConfig {
        deep_boundary: DeepBoundary::Core { temperature_c: core_c },
        far_side: FarSide::Held { temperature_c: far_c },
        contact_resistance_m2k_w: r_c,
        ..FvConfig::default()
    };
    let mut model = FvModel::new(&skin, Some(&stone), &config).unwrap();
    model.set_steady(FvEnvironment::Object).unwrap();
    let skin_r = resistance_to_depth(&skin, f64::INFINITY);
    let object_r = stone.thickness_m / stone.conductivity_w_mk;
    let flux = (core_c - far_c) / (skin_r + r_c + object_r);
    let got_flux = model.surface_heat_flux_w_m2();
    assert!(
        (got_flux - flux).abs() <= 1e-9 * flux,
        "flux fv {got_flux} vs series {flux} W/m²"
    );
    let surface = far_c + flux * (object_r + r_c);
    assert!(
        (model.surface_c() - surface).abs() < 1e-6,
        "surface fv {} vs {surface}",
        model.surface_c()
    );
    let mut worst: f64 = 0.0;
    for (got, depth_m) in model.skin_temperatures_c().iter().zip(model.skin_cell_centres_m()) {
        let want = surface + flux * resistance_to_depth(&skin, *depth_m);
        assert!(
            (got - want).abs() < 1e-6,
            "skin at {depth_m} m: fv {got} vs linear {want}"
        );
        worst = worst.max((got - want).abs());
    }
    let object_face = far_c + flux * object_r;
    for (got, x_m) in model.object_temperatures_c().iter().zip(model.object_cell_centres_m()) {
        let want = object_face - flux * x_m / stone.conductivity_w_mk;
        assert!(
            (got - want).abs() < 1e-6,
            "object at {x_m} m: fv {got} vs linear {want}"
        );
        worst = worst.max((got - want).abs());
    }
    println!("steady contact: flux {got_flux} vs {flux} W/m², max cell error {worst:.1e} °C");
}

#[test]
fn steady_state_in_air_is_the_slab_series_solution() {
    let skin = unperfused_fingertip();
    let (core_c, ambient_c) = (36.0, 23.0);
    let config = FvConfig {
        deep_boundary: DeepBoundary::Core { temperature_c: core_c },
        ..FvConfig::default()
    };
    let mut model = FvModel::new(&skin, None, &config).unwrap();
    model.set_steady_in_air(ambient_c).unwrap();
    let alpha = skin.air_convection_w_m2k;
    let flux = (core_c - ambient_c) / (resistance_to_depth(&skin, f64::INFINITY) + 1.0 / alpha);
    let surface = ambient_c + flux / alpha;
    let got_flux = model.surface_heat_flux_w_m2();
    assert!(
        (got_flux - flux).abs() <= 1e-9 * flux,
        "flux fv {got_flux} vs series {flux} W/m²"
    );
    assert!(
        (model.surface_c() - surface).abs() < 1e-6,
        "surface fv {} vs {surface}",
        model.surface_c()
    );
    for (got, depth_m) in model.skin_temperatures_c().iter().zip(model.skin_cell_centres_m()) {
        let want = surface + flux * resistance_to_depth(&skin, *depth_m);
        assert!(
            (got - want).abs() < 1e-6,
            "skin at {depth_m} m: fv {got} vs linear {want}"
        );
    }
    // The steady state is steady: stepping in the same air changes nothing.
    let before = model.skin_temperatures_c().to_vec();
    for _ in 0..100 {
        model.step(0.1, FvEnvironment::Air { ambient_c });
    }
    for (a, b) in before.iter().zip(model.skin_temperatures_c()) {
        assert!((a - b).abs() < 1e-9, "steady state drifted: {a} → {b}");
    }
}

#[test]
fn steady_perfused_slab_matches_the_pennes_solution() {
    // One layer, perfusion P = ω ρ_b c_b, insulated below, air above: T − T_art = A cosh(m (L − x)), m = √(P/k),
    // A = −α (T_art − T_air) / (k m sinh(mL) + α cosh(mL)).
    let mut skin = homogeneous_skin();
    skin.layers[0].thickness_m = 0.005;
    skin.layers[0].perfusion_per_s = 0.003;
    let (k, length) = (skin.layers[0].conductivity_w_mk, skin.layers[0].thickness_m);
    let perfusion = 0.003 * skin.blood.density_kg_m3 * skin.blood.specific_heat_j_kgk;
    let (arterial, ambient, alpha) = (skin.blood.arterial_c, 23.0, skin.air_convection_w_m2k);
    let m = (perfusion / k).sqrt();
    let a = -alpha * (arterial - ambient) / (k * m * (m * length).sinh() + alpha * (m * length).cosh());
    let exact = |x: f64| arterial + a * (m * (length - x)).cosh();
    let mut errors = Vec::new();
    for level in 0..3 {
        let mut model = FvModel::new(&skin, None, &FvConfig::default().refined(level)).unwrap();
        model.set_steady_in_air(ambient).unwrap();
        let got = model.surface_c();
        assert!(
            (got - exact(0.0)).abs() < 5e-3,
            "level {level}: surface fv {got} vs Pennes {}",
            exact(0.0)
        );
        for (t, x) in model.skin_temperatures_c().iter().zip(model.skin_cell_centres_m()) {
            assert!(
                (t - exact(*x)).abs() < 5e-3,
                "level {level}, x = {x} m: fv {t} vs Pennes {}",
                exact(*x)
            );
        }
        errors.push((got - exact(0.0)).abs());
    }
    println!("perfused slab, surface error by refinement: {}", sci(&errors));
    assert!(
        errors[2] < errors[0] / 8.0,
        "surface error does not fall with the grid: {errors:?}"
    );
}

#[test]
fn error_falls_with_grid_at_second_order_and_refinement_meets_its_tolerance() {
    let coarse = FvConfig {
        surface_cell_m: 4e-5,
        growth: 1.3,
        max_cell_m: 2e-3,
        max_step_s: 0.05,
        ..FvConfig::default()
    };
    for material in [
        thick("stone", 2.763, 2700.0, 812.2),
        thick("copper", 400.0, 8960.0, 385.0),
    ] {
        let errors: Vec<f64> = (0..4)
            .map(|level| worst_surface_error(&material, 23.0, 1e-3, &coarse.refined(level)))
            .collect();
        let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        println!(
            "{}: max error by refinement {}, observed order {orders:.2?}",
            material.name,
            sci(&errors)
        );
        for (level, order) in orders.iter().enumerate() {
            assert!(
                *order > 1.5,
                "{}: order {order} from refinement {level} to {}",
                material.name,
                level + 1
            );
        }
    }
    // The automatic refinement: its answer is within its tolerance of a run refined twice more.
    let skin = Skin::fingertip();
    let stone = materials::find("stone").unwrap();
    let config = FvConfig {
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    };
    let spec = ContactSpec {
        duration_s: 5.0,
        ..ContactSpec::default()
    };
    let refinement = Refinement::default();
    let (run, resolution) = simulate_contact_converged(&skin, &stone, &config, &spec, &refinement).unwrap();
    assert!(resolution.converged, "not converged: {resolution:?}");
    let finer = simulate_contact(&skin, &stone, &config.refined(resolution.refinements + 2), &spec).unwrap();
    let worst = run
        .surface_c
        .iter()
        .zip(&finer.surface_c)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    println!("auto refinement {resolution:?}; max difference to a run refined twice more: {worst:.2e} °C");
    assert!(
        worst < refinement.tolerance_c,
        "converged run differs by {worst} from the finer run"
    );
}

#[test]
fn receptor_affine_predicts_the_plate_step_exactly() {
    for scheme in [TimeScheme::TrBdf2, TimeScheme::BackwardEuler] {
        let config = FvConfig {
            scheme,
            ..FvConfig::default()
        };
        let mut model = FvModel::new(&Skin::fingertip(), None, &config).unwrap();
        model.set_steady_in_air(23.0).unwrap();
        let (dt_s, conductance) = (0.05, 3000.0);
        for step in 0..40 {
            let (offset, slope) = model.receptor_affine(dt_s, conductance);
            for plate_c in [18.0, 41.0] {
                let mut trial = model.clone();
                trial.step_on_plate(dt_s, conductance, plate_c);
                let want = offset + slope * plate_c;
                let got = trial.receptor_c();
                assert!(
                    (got - want).abs() < 1e-9,
                    "{scheme:?} step {step}: stepped {got} vs affine {want}"
                );
            }
            // Drive the finger with a varying plate so the state moves.
            model.step_on_plate(dt_s, conductance, 25.0 + 10.0 * (step as f64 * 0.3).sin());
        }
    }
}

#[test]
fn copper_leaves_the_fingertip_colder_than_wood_at_10_s() {
    let skin = Skin::fingertip();
    let spec = ContactSpec {
        duration_s: 10.0,
        output_dt_s: 0.1,
        ..ContactSpec::default()
    };
    for contact_resistance in [0.0, 1e-3] {
        let config = FvConfig {
            contact_resistance_m2k_w: contact_resistance,
            ..FvConfig::default()
        };
        let at_10_s = |name: &str| {
            let material = materials::find(name).unwrap();
            let run = simulate_contact(&skin, &material, &config, &spec).unwrap();
            *run.surface_c.last().unwrap()
        };
        let (copper, wood) = (at_10_s("copper"), at_10_s("wood"));
        println!("R_c = {contact_resistance}: at 10 s copper {copper:.3} °C, wood {wood:.3} °C");
        assert!(
            copper + 1.0 < wood,
            "copper {copper} °C should be well below wood {wood} °C"
        );
    }
}
