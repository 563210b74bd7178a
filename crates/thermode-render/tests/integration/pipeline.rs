//! The channel pipeline on the simulated display: at rest it holds the plate at the temperature that draws exactly
//! the heat still air would (receptor − q_air/G); direct mode ramps at the requested rate and settles on the
//! requested temperature; a change of material during contact continues from the finger's own state; a release
//! lets the finger warm back towards its resting temperature; the controller gets the finger model's receptor and
//! its conductance over the contact area.

use crate::common;

use common::{material, spec, Loop};
use thermode_device::PlateFinger;
use thermode_model::fv::{FvConfig, FvModel};
use thermode_model::kron::{KronEnvironment, KronModel};
use thermode_model::Skin;
use thermode_pipeline::{ControllerKind, RendererKind, ShippedDisplay, Stimulus};

fn controllers() -> [ControllerKind; 2] {
    [common::pid(ShippedDisplay::Default), ControllerKind::Model]
}

#[test]
fn at_rest_the_plate_draws_the_heat_still_air_would() {
    // Independent of the pipeline: the fv fingertip at steady state in air at 23 °C loses q = h (T_s − T_air)
    // through its surface; on the plate that heat must flow through the contact conductance G.
    let mut finger = FvModel::new(&Skin::fingertip(), None, &FvConfig::default()).unwrap_or_else(|e| panic!("{e}"));
    finger.set_steady_in_air(23.0).unwrap_or_else(|e| panic!("{e}"));
    let q_w_m2 = 10.0 * (finger.surface_c() - 23.0);
    let want_c = finger.surface_c() - q_w_m2 / 1000.0;
    for controller in controllers() {
        let mut lp = Loop::new(&spec(ShippedDisplay::Default, controller, "wood"));
        let ticks = lp.run(1000);
        let late: Vec<f64> = ticks[500..].iter().map(|t| t.plate_c).collect();
        let mean_c = late.iter().sum::<f64>() / late.len() as f64;
        assert!(
            (mean_c - want_c).abs() < 0.05,
            "{}: plate {mean_c} °C at rest vs air rendering {want_c} °C",
            controller.name()
        );
        let setpoint_c = ticks[999].telemetry.display_setpoint_c;
        assert!(
            (setpoint_c - want_c).abs() < 0.01,
            "set-point {setpoint_c} vs {want_c} °C"
        );
    }
}

#[test]
fn direct_mode_ramps_at_the_requested_rate_and_settles() {
    for controller in controllers() {
        let mut lp = Loop::new(&spec(ShippedDisplay::Default, controller, "wood"));
        let rest = lp.run(50);
        let start_c = rest[49].telemetry.display_setpoint_c;
        lp.pipeline
            .set_stimulus(Stimulus::Direct {
                temp_c: 40.0,
                rate_c_per_s: 2.0,
            })
            .unwrap_or_else(|e| panic!("{e}"));
        let ticks = lp.run(1200);
        for (k, t) in ticks.iter().enumerate() {
            let want_c = (start_c + 2.0 * 0.01 * (k + 1) as f64).min(40.0);
            let got_c = t.telemetry.display_setpoint_c;
            assert!(
                (got_c - want_c).abs() < 1e-9,
                "tick {k}: set-point {got_c} vs ramp {want_c}"
            );
            assert!(!t.telemetry.contact && t.telemetry.target_skin_c.is_nan());
        }
        let end = &ticks[1199];
        assert!(
            (end.plate_c - 40.0).abs() < 0.1,
            "{}: plate {} °C after the ramp to 40 °C",
            controller.name(),
            end.plate_c
        );
    }
}

#[test]
fn a_change_of_material_during_contact_continues_from_the_fingers_state() {
    for renderer in [RendererKind::Fv, RendererKind::Kron] {
        let mut s = spec(ShippedDisplay::Default, ControllerKind::Model, "aluminium");
        s.pipeline.renderer = renderer;
        let mut lp = Loop::new(&s);
        lp.run(20);
        let touch = |name: &str| Stimulus::Touch {
            material: material(name),
            object_c: 23.0,
        };
        lp.pipeline
            .set_stimulus(touch("aluminium"))
            .unwrap_or_else(|e| panic!("{e}"));
        let on_aluminium = lp.run(300);
        let before_c = on_aluminium[299].telemetry.target_skin_c;
        lp.pipeline
            .set_stimulus(touch("wood"))
            .unwrap_or_else(|e| panic!("{e}"));
        let on_wood = lp.run(300);
        // Wood insulates: the cooled finger warms again, but from where it was, not from a resting finger.
        assert!(
            on_wood[299].telemetry.target_skin_c > before_c + 0.5,
            "{renderer:?}: target {} after 3 s on wood vs {before_c} when leaving aluminium",
            on_wood[299].telemetry.target_skin_c
        );
        let mut fresh = Loop::new(&s);
        fresh.run(20);
        fresh
            .pipeline
            .set_stimulus(touch("wood"))
            .unwrap_or_else(|e| panic!("{e}"));
        let only_wood = fresh.run(300);
        assert!(
            on_wood[299].telemetry.target_skin_c < only_wood[299].telemetry.target_skin_c - 0.3,
            "{renderer:?}: the finger forgot the aluminium: {} vs {} after 3 s of wood alone",
            on_wood[299].telemetry.target_skin_c,
            only_wood[299].telemetry.target_skin_c
        );
        assert!(on_wood.iter().all(|t| t.fault.is_none() && t.telemetry.contact));
    }
}

#[test]
fn a_release_lets_the_finger_warm_back_towards_rest() {
    let mut lp = Loop::new(&spec(ShippedDisplay::Default, ControllerKind::Model, "steel"));
    let rest = lp.run(20);
    let resting_c = rest[19].telemetry.target_skin_c;
    lp.pipeline
        .set_stimulus(Stimulus::Touch {
            material: material("steel"),
            object_c: 23.0,
        })
        .unwrap_or_else(|e| panic!("{e}"));
    let touched = lp.run(500);
    lp.pipeline
        .set_stimulus(Stimulus::Air)
        .unwrap_or_else(|e| panic!("{e}"));
    let released = lp.run(3000);
    let cold_c = touched[499].telemetry.target_skin_c;
    let later_c = released[2999].telemetry.target_skin_c;
    assert!(
        later_c > cold_c + 2.0 && later_c < resting_c,
        "after release {later_c} °C, at release {cold_c} °C, at rest {resting_c} °C"
    );
    assert!(released.iter().all(|t| !t.telemetry.contact));
    // The finger on the display follows the warming target.
    let last = released[2999];
    assert!(
        (last.telemetry.skin_c - later_c).abs() < 0.05,
        "finger model {} vs target {later_c}",
        last.telemetry.skin_c
    );
}

#[test]
fn the_controller_gets_the_finger_models_receptor_conductance_over_the_area() {
    let s = spec(ShippedDisplay::Default, ControllerKind::Model, "wood");
    let area = s.pipeline.device.plate.area_m2;
    let contact = s.pipeline.device.plate.contact_conductance_w_m2k;
    let lp = Loop::new(&s);
    let got = lp.pipeline.finger_conductance_w_k();
    assert!(
        (got - contact * area).abs() < 1e-15,
        "fv finger: {got} vs {} W/K",
        contact * area
    );
    let mut kron = s.clone();
    kron.pipeline.renderer = RendererKind::Kron;
    let lp = Loop::new(&kron);
    // The Kron receptor (epidermis centre) sees half the epidermis in series with the contact.
    let epidermis = &Skin::fingertip().layers[0];
    let want = area / (epidermis.thickness_m / (2.0 * epidermis.conductivity_w_mk) + 1.0 / contact);
    let got = lp.pipeline.finger_conductance_w_k();
    assert!((got - want).abs() < 1e-15, "kron finger: {got} vs {want} W/K");
    let mut model = KronModel::new(&Skin::fingertip()).unwrap_or_else(|e| panic!("{e}"));
    model.settle(&KronEnvironment::Air { ambient_c: 23.0 });
    assert_eq!(model.receptor_conductance_w_m2k(contact) * area, got);
}
