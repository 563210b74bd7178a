//! With the kron renderer the target is Kron's T1, the centre of the epidermis, so the simulated finger and the
//! truth are read at that depth: these tests check the depth itself, that the truth at that depth does not move
//! in the first tick after touching aluminium (heat has not got there yet, while the surface jumps by degrees),
//! and that the summary's lag and overshoot of a kron render are physical (lag ≥ 0, near the actuator limit).

use crate::common;

use common::{pid, spec};
use thermode_pipeline::{ControllerKind, RendererKind, ShippedDisplay};
use thermode_render::run::render;
use thermode_render::RenderSpec;

/// A 10 s kron render of aluminium on the default display with `controller`.
fn kron_aluminium(controller: ControllerKind) -> RenderSpec {
    let mut s = spec(ShippedDisplay::Default, controller, "aluminium");
    s.pipeline.renderer = RendererKind::Kron;
    s.duration_s = 10.0;
    s
}

#[test]
fn the_receptor_depth_is_half_the_simulated_fingers_epidermis_for_kron_and_the_surface_for_fv() {
    let mut s = kron_aluminium(ControllerKind::Model);
    let epidermis_m = s.finger_skin.layers[0].thickness_m;
    assert_eq!(
        s.receptor_depth_m(),
        0.5 * epidermis_m,
        "kron depth vs Δx₁/2 of the fingertip"
    );
    s.finger_skin.layers[0].thickness_m = 7e-4;
    assert_eq!(
        s.receptor_depth_m(),
        3.5e-4,
        "kron depth vs Δx₁/2 of a 0.7 mm epidermis"
    );
    s.pipeline.renderer = RendererKind::Fv;
    assert_eq!(s.receptor_depth_m(), 0.0, "fv depth vs the surface");
}

#[test]
fn kron_truth_at_the_epidermis_centre_does_not_jump_at_the_touch() {
    // Aluminium pulls the surface down by several °C at once, but in one 10 ms tick heat diffuses only
    // √(a·t) ≈ 20 µm into the epidermis (a ≈ 5e-8 m²/s): at 0.25 mm the truth must still be at rest (and the
    // simulated finger, whose plate cannot move that fast, too). A surface read-out fails this by degrees.
    let run = render(&kron_aluminium(ControllerKind::Model)).unwrap_or_else(|e| panic!("{e}"));
    let t = &run.trajectory;
    let first = t
        .time_s
        .iter()
        .position(|time| *time > 0.0)
        .expect("rows after the touch");
    for (name, column) in [("truth", &t.truth_skin_c), ("skin", &t.skin_c)] {
        let (before, after) = (column[first - 1], column[first]);
        assert!(
            (after - before).abs() < 0.01,
            "{name} at 0.25 mm: {after} °C one tick after the touch vs {before} °C at rest"
        );
    }
}

#[test]
fn kron_lag_is_non_negative_and_near_the_actuator_limit_and_overshoot_is_small() {
    // Before the depth fix (surface vs T1) aluminium gave lags of −1.1 s and overshoots of 6.2–6.3 °C.
    for controller in [ControllerKind::Model, pid(ShippedDisplay::Default)] {
        let run = render(&kron_aluminium(controller)).unwrap_or_else(|e| panic!("{e}"));
        let s = &run.summary;
        let (lag, limit) = (
            s.lag_s.expect("lag defined"),
            s.actuator_limit_lag_s.expect("limit defined"),
        );
        println!(
            "{}: lag {lag:.3} s, limit {limit:.3} s, overshoot {:.3} °C",
            s.controller, s.overshoot_c
        );
        assert!(lag >= 0.0, "{}: lag {lag} s must be ≥ 0", s.controller);
        assert!(
            lag <= 1.5 * limit + 0.05,
            "{}: lag {lag} s vs actuator limit {limit} s",
            s.controller
        );
        assert!(s.overshoot_c < 1.0, "{}: overshoot {} °C", s.controller, s.overshoot_c);
    }
}
