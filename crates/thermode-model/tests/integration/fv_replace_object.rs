//! Tests of `FvModel::replace_object`: a finger that changes the touched material keeps its own skin state, and the
//! model with the new object behaves exactly as one built with it; errors leave the model unchanged; removing the
//! object leaves an insulated surface in the object environment; energy is conserved across the replacement.

use thermode_model::fv::{FvConfig, FvEnvironment, FvModel};
use thermode_model::materials::{self, Material};
use thermode_model::Skin;

const STEP_S: f64 = 0.01;

fn paper(name: &str) -> Material {
    materials::find(name).unwrap_or_else(|e| panic!("{e}"))
}

fn light_touch() -> FvConfig {
    FvConfig {
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    }
}

fn resting(object: &Material) -> FvModel {
    let mut model = FvModel::new(&Skin::fingertip(), Some(object), &light_touch()).unwrap_or_else(|e| panic!("{e}"));
    model.set_steady_in_air(23.0).unwrap_or_else(|e| panic!("{e}"));
    model
}

#[test]
fn a_replaced_object_behaves_bit_for_bit_as_one_built_with_it() {
    // The resting state in air does not depend on the object, so both fingers start identical.
    let mut replaced = resting(&paper("aluminium"));
    replaced
        .replace_object(Some(&paper("wood")), &light_touch())
        .unwrap_or_else(|e| panic!("{e}"));
    let mut built = resting(&paper("wood"));
    assert_eq!(replaced.object_cells(), built.object_cells());
    replaced.touch(23.0).unwrap_or_else(|e| panic!("{e}"));
    built.touch(23.0).unwrap_or_else(|e| panic!("{e}"));
    for n in 0..500 {
        replaced.step(STEP_S, FvEnvironment::Object);
        built.step(STEP_S, FvEnvironment::Object);
        assert_eq!(
            replaced.surface_c(),
            built.surface_c(),
            "step {n}: replaced {} vs built {}",
            replaced.surface_c(),
            built.surface_c()
        );
    }
}

#[test]
fn the_skin_state_survives_the_replacement_and_energy_is_conserved_after_it() {
    let mut model = resting(&paper("aluminium"));
    model.touch(23.0).unwrap_or_else(|e| panic!("{e}"));
    for _ in 0..100 {
        model.step(STEP_S, FvEnvironment::Object);
    }
    let skin_before = model.skin_temperatures_c().to_vec();
    model
        .replace_object(Some(&paper("rubber")), &light_touch())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(model.skin_temperatures_c(), &skin_before[..], "skin state changed");
    assert_eq!(model.environment(), FvEnvironment::Object);
    model.touch(23.0).unwrap_or_else(|e| panic!("{e}"));
    model.reset_energy_ledger();
    let (skin0, object0) = (model.skin_energy_j_m2(), model.object_energy_j_m2());
    for _ in 0..300 {
        model.step(STEP_S, FvEnvironment::Object);
    }
    let ledger = model.energy_ledger();
    let skin_change = model.skin_energy_j_m2() - skin0;
    let skin_budget =
        ledger.perfusion_j_m2 + ledger.metabolic_j_m2 + ledger.deep_in_j_m2 - ledger.skin_surface_out_j_m2;
    assert!(
        (skin_change - skin_budget).abs() < 1e-6 * skin_change.abs().max(1.0),
        "skin energy change {skin_change} vs ledger {skin_budget}"
    );
    let object_change = model.object_energy_j_m2() - object0;
    let object_budget = ledger.object_contact_in_j_m2 + ledger.object_far_side_in_j_m2;
    assert!(
        (object_change - object_budget).abs() < 1e-6 * object_change.abs().max(1.0),
        "object energy change {object_change} vs ledger {object_budget}"
    );
    assert!(
        (ledger.skin_surface_out_j_m2 - ledger.object_contact_in_j_m2).abs() < 1e-9 * ledger.skin_surface_out_j_m2,
        "heat out of the skin {} vs into the rubber {}",
        ledger.skin_surface_out_j_m2,
        ledger.object_contact_in_j_m2
    );
}

#[test]
fn errors_leave_the_model_unchanged() {
    let mut model = resting(&paper("steel"));
    let cells = model.object_cells();
    let mut bad = paper("wood");
    bad.conductivity_w_mk = f64::NAN;
    assert!(model.replace_object(Some(&bad), &light_touch()).is_err());
    let bad_config = FvConfig {
        contact_resistance_m2k_w: -1.0,
        ..FvConfig::default()
    };
    assert!(model.replace_object(Some(&paper("wood")), &bad_config).is_err());
    let mut huge = paper("wood");
    huge.thickness_m = 1e6; // more cells than the grid allows
    assert!(model.replace_object(Some(&huge), &light_touch()).is_err());
    assert_eq!(
        model.object_cells(),
        cells,
        "object grid changed by a refused replacement"
    );
    let mut reference = resting(&paper("steel"));
    model.touch(23.0).unwrap_or_else(|e| panic!("{e}"));
    reference.touch(23.0).unwrap_or_else(|e| panic!("{e}"));
    for _ in 0..50 {
        model.step(STEP_S, FvEnvironment::Object);
        reference.step(STEP_S, FvEnvironment::Object);
    }
    assert_eq!(model.surface_c(), reference.surface_c());
}

#[test]
fn removing_the_object_leaves_an_insulated_surface_in_contact() {
    let mut model = resting(&paper("aluminium"));
    model
        .replace_object(None, &light_touch())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(model.object_cells(), 0);
    assert!(model.touch(23.0).is_err(), "touching without an object must be refused");
    model
        .set_environment(FvEnvironment::Object)
        .unwrap_or_else(|e| panic!("{e}"));
    let before = model.skin_energy_j_m2();
    model.reset_energy_ledger();
    for _ in 0..100 {
        model.step(STEP_S, FvEnvironment::Object);
    }
    assert_eq!(model.surface_heat_flux_w_m2(), 0.0);
    let ledger = model.energy_ledger();
    assert_eq!(
        ledger.skin_surface_out_j_m2, 0.0,
        "heat left through an insulated surface"
    );
    // Perfusion alone warms the finger: its energy grows by exactly the perfusion heat.
    let change = model.skin_energy_j_m2() - before;
    assert!(
        change > 0.0 && (change - ledger.perfusion_j_m2).abs() < 1e-6 * change,
        "energy change {change} vs perfusion {}",
        ledger.perfusion_j_m2
    );
}
