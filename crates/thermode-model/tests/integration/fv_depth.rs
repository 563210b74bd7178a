//! Tests of [`FvModel::skin_temperature_at_depth_c`], the temperature below the skin surface read from the
//! finite-volume state: against the analytic erf profile of two semi-infinite bodies in perfect contact
//! (`model.md` §4), against the exact piecewise-linear steady profile through two layers and a held core, and its
//! edge cases (surface, cell centres, clamping, NaN).

use thermode_model::fv::{DeepBoundary, FvConfig, FvEnvironment, FvModel};
use thermode_model::materials::Material;
use thermode_model::semi_infinite::{interface_temperature_c, skin_temperature_at_depth_c};
use thermode_model::{Blood, Skin, SkinLayer};

const SKIN_C: f64 = 33.0;
const OBJECT_C: f64 = 23.0;
const STEP_S: f64 = 0.001;
/// Largest accepted |fv − erf| inside the skin on the once-refined grid \[°C\] (of a 10 °C contrast).
const PROFILE_TOLERANCE_C: f64 = 5e-3;
/// Largest accepted |fv − erf| on the default grid \[°C\] (its own second-order discretisation error).
const DEFAULT_GRID_TOLERANCE_C: f64 = 2e-2;

fn layer(thickness_m: f64, conductivity_w_mk: f64) -> SkinLayer {
    SkinLayer {
        name: "skin".into(),
        thickness_m,
        conductivity_w_mk,
        density_kg_m3: 1100.0,
        specific_heat_j_kgk: 3500.0,
        perfusion_per_s: 0.0,
        metabolic_w_m3: 0.0,
    }
}

fn skin(layers: Vec<SkinLayer>) -> Skin {
    Skin {
        layers,
        blood: Blood {
            arterial_c: 36.8,
            density_kg_m3: 1060.0,
            specific_heat_j_kgk: 3800.0,
        },
        air_convection_w_m2k: 10.0,
    }
}

/// A homogeneous unperfused skin 30 mm thick: semi-infinite over 10 s (heat penetrates about 1 mm).
fn homogeneous_skin() -> Skin {
    skin(vec![layer(0.03, 0.37)])
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

/// The largest |fv − erf| over the depths and times, for the skin at `SKIN_C` touching `material` at `OBJECT_C`
/// in perfect contact, on the default grid refined `levels` times.
fn worst_profile_error(material: &Material, levels: u32, depths_m: &[f64], times_s: &[f64]) -> f64 {
    let config = FvConfig {
        contact_resistance_m2k_w: 0.0,
        ..FvConfig::default()
    }
    .refined(levels);
    let skin = homogeneous_skin();
    let mut model = FvModel::new(&skin, Some(material), &config).expect("valid model");
    model.set_skin_uniform(SKIN_C).expect("finite");
    model.touch(OBJECT_C).expect("has an object");
    let e_skin = (0.37f64 * 1100.0 * 3500.0).sqrt();
    let e_object = (material.conductivity_w_mk * material.density_kg_m3 * material.specific_heat_j_kgk).sqrt();
    let interface_c = interface_temperature_c(e_skin, SKIN_C, e_object, OBJECT_C);
    let diffusivity = 0.37 / (1100.0 * 3500.0);
    let (mut now_s, mut worst) = (0.0, 0.0f64);
    for &time_s in times_s {
        while now_s < time_s - 1e-9 {
            model.step(STEP_S, FvEnvironment::Object);
            now_s += STEP_S;
        }
        for &depth_m in depths_m {
            let got = model.skin_temperature_at_depth_c(depth_m);
            let want = skin_temperature_at_depth_c(interface_c, SKIN_C, diffusivity, depth_m, time_s);
            worst = worst.max((got - want).abs());
        }
    }
    worst
}

#[test]
fn depth_profile_matches_the_analytic_erf_profile() {
    // Depths between cell centres, including the Kron receptor depth of the fingertip (0.25 mm), down to 1.5 mm
    // (deeper the cells reach their 0.5 mm maximum and interpolation across them costs more than 5 mK).
    let depths_m = [0.0, 2.5e-5, 1e-4, 2.5e-4, 4e-4, 7e-4, 1e-3, 1.5e-3];
    let times_s = [0.5, 1.0, 2.0, 5.0, 10.0];
    for material in [
        thick("wood", 0.15, 700.0, 1700.0),
        thick("glass", 1.0, 2500.0, 800.0),
        thick("aluminium", 237.0, 2700.0, 900.0),
    ] {
        let coarse = worst_profile_error(&material, 0, &depths_m, &times_s);
        let fine = worst_profile_error(&material, 1, &depths_m, &times_s);
        println!(
            "{:10}: max |fv − erf| = {coarse:.2e} °C (default grid), {fine:.2e} °C (refined once)",
            material.name
        );
        assert!(
            fine < PROFILE_TOLERANCE_C && coarse < DEFAULT_GRID_TOLERANCE_C,
            "{}: max |fv − erf| {fine} (refined) vs {PROFILE_TOLERANCE_C}, {coarse} (default) vs \
             {DEFAULT_GRID_TOLERANCE_C}",
            material.name
        );
        assert!(
            fine < 0.5 * coarse,
            "{}: refining must shrink the error (second order: about 4×): {coarse} → {fine}",
            material.name
        );
    }
}

#[test]
fn depth_profile_is_exact_for_steady_conduction_through_two_layers() {
    // Unperfused layers 0.5 mm (k 0.21) and 1.5 mm (k 0.37), core held at 35 °C, plate at 20 °C through 2000
    // W/(m²K): the steady profile is linear in each layer with the same flux q = ΔT / ΣR, kinked at 0.5 mm.
    let (k1, l1, k2, l2) = (0.21, 5e-4, 0.37, 1.5e-3);
    let (core_c, plate_c, h) = (35.0, 20.0, 2000.0);
    let config = FvConfig {
        deep_boundary: DeepBoundary::Core { temperature_c: core_c },
        ..FvConfig::default()
    };
    let mut model = FvModel::new(&skin(vec![layer(l1, k1), layer(l2, k2)]), None, &config).expect("valid model");
    model
        .set_steady(FvEnvironment::Plate {
            conductance_w_m2k: h,
            temperature_c: plate_c,
        })
        .expect("grounded by the core");
    let q = (core_c - plate_c) / (1.0 / h + l1 / k1 + l2 / k2);
    let surface_c = plate_c + q / h;
    let exact = |x: f64| {
        if x <= l1 {
            surface_c + q * x / k1
        } else {
            surface_c + q * l1 / k1 + q * (x - l1) / k2
        }
    };
    for i in 0..=200 {
        let depth_m = (l1 + l2) * i as f64 / 200.0;
        let got = model.skin_temperature_at_depth_c(depth_m);
        let want = exact(depth_m);
        assert!(
            (got - want).abs() < 1e-9,
            "depth {:.4} mm: fv {got} vs exact {want}",
            depth_m * 1e3
        );
    }
}

#[test]
fn depth_zero_is_the_surface_centres_are_the_cells_and_out_of_range_depths_clamp() {
    let mut model = FvModel::new(&Skin::fingertip(), None, &FvConfig::default()).expect("valid model");
    model.set_steady_in_air(23.0).expect("perfused");
    model.step(
        0.05,
        FvEnvironment::Plate {
            conductance_w_m2k: 2000.0,
            temperature_c: 15.0,
        },
    );
    let surface_c = model.surface_c();
    assert_eq!(model.skin_temperature_at_depth_c(0.0), surface_c, "depth 0 vs surface");
    assert_eq!(
        model.skin_temperature_at_depth_c(-1.0),
        surface_c,
        "negative depth vs surface"
    );
    for (centre_m, cell_c) in model.skin_cell_centres_m().iter().zip(model.skin_temperatures_c()) {
        let got = model.skin_temperature_at_depth_c(*centre_m);
        assert!(
            (got - cell_c).abs() < 1e-12,
            "at the centre {centre_m} m: depth read-out {got} vs cell {cell_c}"
        );
    }
    let deepest_c = *model.skin_temperatures_c().last().expect("cells");
    let thickness_m: f64 = Skin::fingertip().layers.iter().map(|l| l.thickness_m).sum();
    for depth_m in [thickness_m, 2.0 * thickness_m, f64::INFINITY] {
        let got = model.skin_temperature_at_depth_c(depth_m);
        assert!(
            (got - deepest_c).abs() < 1e-12,
            "depth {depth_m} m (insulated bottom): {got} vs deepest cell {deepest_c}"
        );
    }
    assert!(
        model.skin_temperature_at_depth_c(f64::NAN).is_nan(),
        "NaN depth must read NaN"
    );
}
