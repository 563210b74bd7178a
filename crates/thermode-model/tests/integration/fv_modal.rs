//! The modal fast path ([`ModalFv`]) against the full finite-volume model: the stated error bound (0.005 °C)
//! against the full model time-converged on the same grid over touch/release sequences and plate step inputs, for
//! several materials and contact resistances; second-order convergence of the full model's TR-BDF2 towards it;
//! steady states; conservation of energy in a closed system; determinism; the forced-off path equal to the full
//! model; the scheme-matched stepping equal to the full model stepped once per tick.

use thermode_model::fv::{DeepBoundary, FarSide, FvConfig, FvEnvironment, FvModel, ModalFv, ModalStepping, TimeScheme};
use thermode_model::inverse::PlateCoupled;
use thermode_model::materials::{self, Material};
use thermode_model::{Skin, SkinLayer};

/// The error bound of the fast path against the full model, stated in `docs/performance.md` \[°C\].
const BOUND_C: f64 = 0.005;
/// Tick of the comparisons \[s\] (the default sensor period).
const TICK_S: f64 = 0.01;
const AIR_C: f64 = 23.0;

fn material(name: &str) -> Material {
    materials::find(name).unwrap_or_else(|e| panic!("{e}"))
}

fn finger_touching(material: &Material, contact_resistance_m2k_w: f64) -> FvModel {
    let config = FvConfig {
        contact_resistance_m2k_w,
        ..FvConfig::default()
    };
    let mut model = FvModel::new(&Skin::fingertip(), Some(material), &config).unwrap_or_else(|e| panic!("{e}"));
    model.set_steady_in_air(AIR_C).unwrap_or_else(|e| panic!("{e}"));
    model
}

/// One event of a sequence: before the tick with this index, touch the object at this temperature (`Some`) or let go
/// (`None`).
type Event = (usize, Option<f64>);

/// Touch at 23 °C, let go, touch again at 40 °C, let go, touch at 10 °C: 2.5 s at [`TICK_S`].
const SEQUENCE: [Event; 5] = [
    (0, Some(23.0)),
    (60, None),
    (90, Some(40.0)),
    (150, None),
    (170, Some(10.0)),
];
const TICKS: usize = 250;

/// The full model stepped with `substeps` equal steps per tick.
fn full_tick(model: &mut FvModel, env: FvEnvironment, substeps: usize) {
    let h = TICK_S / substeps as f64;
    for _ in 0..substeps {
        model.step(h, env);
    }
}

fn environment(event_c: Option<f64>) -> FvEnvironment {
    match event_c {
        Some(_) => FvEnvironment::Object,
        None => FvEnvironment::Air { ambient_c: AIR_C },
    }
}

/// Runs [`SEQUENCE`] on the fast path and on the full model with `substeps` per tick; returns the largest difference
/// of the surface temperature over all ticks \[°C\] and the tick where it occurred.
fn sequence_difference(material: &Material, contact_resistance_m2k_w: f64, substeps: usize) -> (f64, usize) {
    let mut full = finger_touching(material, contact_resistance_m2k_w);
    let mut fast = ModalFv::new(full.clone());
    assert!(fast.fast_path(), "the default grid takes the fast path");
    let mut env = FvEnvironment::Air { ambient_c: AIR_C };
    let mut worst = (0.0f64, 0);
    for tick in 0..TICKS {
        if let Some(&(_, event_c)) = SEQUENCE.iter().find(|(at, _)| *at == tick) {
            if let Some(object_c) = event_c {
                full.touch(object_c).unwrap_or_else(|e| panic!("{e}"));
                fast.touch(object_c).unwrap_or_else(|e| panic!("{e}"));
            }
            env = environment(event_c);
        }
        full_tick(&mut full, env, substeps);
        fast.step(TICK_S, env);
        let difference = (fast.surface_c() - full.surface_c()).abs();
        if difference > worst.0 {
            worst = (difference, tick);
        }
    }
    worst
}

#[test]
fn fast_path_is_within_the_bound_of_the_time_converged_full_model_over_contact_sequences() {
    for name in ["aluminium", "steel", "stone", "wood", "rubber"] {
        let object = material(name);
        for contact_resistance in [0.0, 1e-3, 1e-2] {
            let (difference, tick) = sequence_difference(&object, contact_resistance, 64);
            println!(
                "{name}, R_c {contact_resistance:e}: fast vs full (64 substeps) {difference:.2e} °C at tick {tick}"
            );
            assert!(
                difference <= BOUND_C,
                "{name}, R_c {contact_resistance:e}: fast path differs by {difference} °C (bound {BOUND_C} °C) at \
                 tick {tick}"
            );
        }
    }
}

#[test]
fn full_model_converges_to_the_fast_path_at_second_order() {
    // TR-BDF2 is second order: halving its step twice divides its time error by about 16; the fast path, exact in
    // time, is the limit. A wrong decomposition would leave a floor that does not fall.
    let object = material("aluminium");
    let (coarse, _) = sequence_difference(&object, 1e-3, 8);
    let (fine, _) = sequence_difference(&object, 1e-3, 32);
    println!(
        "fast vs full: {coarse:.3e} °C at 8 substeps, {fine:.3e} °C at 32 (ratio {:.1})",
        coarse / fine
    );
    assert!(
        fine < coarse / 8.0,
        "the difference fell from {coarse} to only {fine} °C when the full model's step was divided by 4"
    );
}

#[test]
fn plate_steps_match_the_full_model_and_its_affine_prediction() {
    // A finger on the display: the plate temperature steps between 18 and 42 °C, two conductances, and the display
    // inverse asks over a horizon longer than its step (as the pipeline does at a 1 ms tick).
    for conductance in [800.0, 2500.0] {
        let mut full = finger_touching(&material("wood"), 1e-3);
        let mut fast = ModalFv::new(full.clone());
        let (mut worst_state, mut worst_prediction) = (0.0f64, 0.0f64);
        for tick in 0..400 {
            let plate_c = if (tick / 50) % 2 == 0 { 42.0 } else { 18.0 };
            let (offset, slope) = fast.receptor_affine(4.0 * TICK_S, conductance);
            let mut ahead = full.clone();
            full_tick(&mut ahead, plate(conductance, plate_c), 256);
            full_tick(&mut ahead, plate(conductance, plate_c), 256);
            full_tick(&mut ahead, plate(conductance, plate_c), 256);
            full_tick(&mut ahead, plate(conductance, plate_c), 256);
            worst_prediction = worst_prediction.max((offset + slope * plate_c - ahead.surface_c()).abs());
            full_tick(&mut full, plate(conductance, plate_c), 64);
            fast.step_on_plate(TICK_S, conductance, plate_c);
            worst_state = worst_state.max((fast.receptor_c() - full.surface_c()).abs());
        }
        println!("G {conductance}: receptor {worst_state:.2e} °C, 40 ms prediction {worst_prediction:.2e} °C");
        assert!(
            worst_state <= BOUND_C && worst_prediction <= BOUND_C,
            "G {conductance}: fast vs full receptor {worst_state} °C, prediction {worst_prediction} °C (bound \
             {BOUND_C} °C)"
        );
    }
}

fn plate(conductance_w_m2k: f64, temperature_c: f64) -> FvEnvironment {
    FvEnvironment::Plate {
        conductance_w_m2k,
        temperature_c,
    }
}

/// Largest difference over the skin and object cells of two models \[°C\].
fn cell_difference(a: &FvModel, b: &FvModel) -> f64 {
    let skin = a.skin_temperatures_c().iter().zip(b.skin_temperatures_c());
    let object = a.object_temperatures_c().iter().zip(b.object_temperatures_c());
    skin.chain(object).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn long_steps_reach_the_steady_states_and_steady_states_stay() {
    // Held core below and held far side: both air and contact have a unique steady state.
    let config = FvConfig {
        deep_boundary: DeepBoundary::Core { temperature_c: 36.0 },
        far_side: FarSide::Held { temperature_c: 20.0 },
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    };
    let object = material("stone");
    let mut model = FvModel::new(&Skin::fingertip(), Some(&object), &config).unwrap_or_else(|e| panic!("{e}"));
    model.set_steady_in_air(AIR_C).unwrap_or_else(|e| panic!("{e}"));
    for env in [
        FvEnvironment::Object,
        FvEnvironment::Air { ambient_c: 30.0 },
        plate(1000.0, 35.0),
    ] {
        let mut want = model.clone();
        want.set_steady(env).unwrap_or_else(|e| panic!("{e}"));
        let mut fast = ModalFv::new(model.clone());
        fast.step(1e4, env);
        let reached = cell_difference(&fast.model(), &want);
        let mut still = ModalFv::new(want.clone());
        still.step(0.01, env);
        still.step(0.37, env);
        let moved = cell_difference(&still.model(), &want);
        println!("{env:?}: long step off the steady state by {reached:.1e} °C, steady state moved {moved:.1e} °C");
        assert!(
            reached < 1e-9,
            "{env:?}: a 1e4 s step ends {reached} °C from the steady state"
        );
        assert!(
            moved < 1e-9,
            "{env:?}: steps from the steady state moved it by {moved} °C"
        );
        let surface = (fast.surface_c() - want.surface_c()).abs();
        assert!(
            surface < 1e-9,
            "{env:?}: surface {} vs steady {}",
            fast.surface_c(),
            want.surface_c()
        );
    }
}

/// A skin without perfusion or metabolic heat: with an insulated core and far side, skin and object in contact
/// exchange heat only with each other.
fn closed_skin() -> Skin {
    let mut skin = Skin::fingertip();
    skin.layers.iter_mut().for_each(|layer: &mut SkinLayer| {
        layer.perfusion_per_s = 0.0;
        layer.metabolic_w_m3 = 0.0;
    });
    skin
}

#[test]
fn closed_contact_conserves_energy_and_settles_at_the_mixing_temperature() {
    let object = material("aluminium");
    let config = FvConfig {
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    };
    let mut model = FvModel::new(&closed_skin(), Some(&object), &config).unwrap_or_else(|e| panic!("{e}"));
    model.set_skin_uniform(33.0).unwrap_or_else(|e| panic!("{e}"));
    model.touch(20.0).unwrap_or_else(|e| panic!("{e}"));
    let energy = |m: &FvModel| m.skin_energy_j_m2() + m.object_energy_j_m2();
    let before = energy(&model);
    let heat_capacity = energy(&{
        let mut unit = model.clone();
        unit.set_skin_uniform(1.0).unwrap_or_else(|e| panic!("{e}"));
        unit.touch(1.0).unwrap_or_else(|e| panic!("{e}"));
        unit
    });
    let mut fast = ModalFv::new(model);
    let mut worst = 0.0f64;
    for _ in 0..500 {
        fast.step(TICK_S, FvEnvironment::Object);
        worst = worst.max((energy(&fast.model()) - before).abs() / before);
    }
    println!("closed contact: relative energy drift {worst:.1e}");
    // Rounding only: about 1e-15 per step and cell projection, 500 steps.
    assert!(worst < 1e-10, "energy drifted by {worst} (relative) in a closed system");
    // Much later (1e4 s: the slowest decaying mode has a time constant of about 100 s) every cell is at the
    // capacity-weighted mean. The mode that should not decay at all gets a rate of rounding size (ε times the
    // fastest rate: about 3e-13/s here), which moves the mean by about 3e-9 of itself (1e-7 °C) over this time.
    fast.step(1e4, FvEnvironment::Object);
    let mixing_c = before / heat_capacity;
    let spread = fast
        .model()
        .skin_temperatures_c()
        .iter()
        .chain(fast.model().object_temperatures_c())
        .fold(0.0f64, |m, t| m.max((t - mixing_c).abs()));
    assert!(
        spread < 1e-6,
        "cells off the mixing temperature {mixing_c} °C by {spread} °C"
    );
}

/// The schedule of the bit-identity test at `tick`: whether the object is touched now, and the environment.
fn touch_schedule(tick: usize) -> (bool, FvEnvironment) {
    let env = if (10..80).contains(&tick) {
        FvEnvironment::Object
    } else {
        FvEnvironment::Air { ambient_c: AIR_C }
    };
    (tick == 10, env)
}

#[test]
fn runs_are_bit_identical_and_the_forced_off_path_is_the_full_model() {
    let object = material("steel");
    let run = |enabled: bool| {
        let mut fast = ModalFv::with_fast_path(finger_touching(&object, 1e-3), enabled);
        let mut trace = Vec::new();
        for tick in 0..120 {
            let (touch, env) = touch_schedule(tick);
            if touch {
                fast.touch(25.0).unwrap_or_else(|e| panic!("{e}"));
            }
            fast.step(TICK_S, env);
            trace.push(fast.surface_c().to_bits());
        }
        trace
    };
    assert_eq!(run(true), run(true), "two fast runs differ");
    let mut full = finger_touching(&object, 1e-3);
    let mut want = Vec::new();
    for tick in 0..120 {
        let (touch, env) = touch_schedule(tick);
        if touch {
            full.touch(25.0).unwrap_or_else(|e| panic!("{e}"));
        }
        full.step(TICK_S, env);
        want.push(full.surface_c().to_bits());
    }
    assert_eq!(run(false), want, "the forced-off path is not the full model");
}

#[test]
fn replacing_the_object_and_recalibrating_rebuild_the_configuration() {
    // After a change of object or perfusion the fast path must follow the new matrices, not a cached basis.
    let mut full = finger_touching(&material("aluminium"), 1e-3);
    let mut fast = ModalFv::new(full.clone());
    let wood = material("wood");
    let config = FvConfig {
        contact_resistance_m2k_w: 2e-3,
        ..FvConfig::default()
    };
    full.touch(30.0).unwrap_or_else(|e| panic!("{e}"));
    fast.touch(30.0).unwrap_or_else(|e| panic!("{e}"));
    let mut worst = 0.0f64;
    for round in 0..3 {
        if round == 1 {
            full.replace_object(Some(&wood), &config)
                .unwrap_or_else(|e| panic!("{e}"));
            fast.replace_object(Some(&wood), &config)
                .unwrap_or_else(|e| panic!("{e}"));
            full.touch(30.0).unwrap_or_else(|e| panic!("{e}"));
            fast.touch(30.0).unwrap_or_else(|e| panic!("{e}"));
        }
        if round == 2 {
            full.set_perfusion_scale(2.5).unwrap_or_else(|e| panic!("{e}"));
            fast.set_perfusion_scale(2.5).unwrap_or_else(|e| panic!("{e}"));
        }
        for _ in 0..40 {
            full_tick(&mut full, FvEnvironment::Object, 64);
            fast.step(TICK_S, FvEnvironment::Object);
            worst = worst.max((fast.surface_c() - full.surface_c()).abs());
        }
    }
    println!("object and perfusion changes: fast vs full {worst:.2e} °C");
    assert!(
        worst <= BOUND_C,
        "fast vs full {worst} °C after replacing the object or perfusion"
    );
}

#[test]
fn scheme_stepping_reproduces_the_full_model_step_by_step() {
    // The full model's own scheme applied to each mode is the full model's step, to rounding: a sharp check of the
    // decomposition (eigenvalues, eigenvectors, forcing and read-out), for both schemes, in contact and in air.
    for scheme in [TimeScheme::TrBdf2, TimeScheme::BackwardEuler] {
        for name in ["aluminium", "wood"] {
            let config = FvConfig {
                contact_resistance_m2k_w: 1e-3,
                scheme,
                ..FvConfig::default()
            };
            let object = material(name);
            let mut full = FvModel::new(&Skin::fingertip(), Some(&object), &config).unwrap_or_else(|e| panic!("{e}"));
            full.set_steady_in_air(AIR_C).unwrap_or_else(|e| panic!("{e}"));
            let mut fast = ModalFv::new(full.clone());
            fast.set_stepping(ModalStepping::Scheme);
            let mut env = FvEnvironment::Air { ambient_c: AIR_C };
            let mut worst = 0.0f64;
            for tick in 0..TICKS {
                if let Some(&(_, event_c)) = SEQUENCE.iter().find(|(at, _)| *at == tick) {
                    if let Some(object_c) = event_c {
                        full.touch(object_c).unwrap_or_else(|e| panic!("{e}"));
                        fast.touch(object_c).unwrap_or_else(|e| panic!("{e}"));
                    }
                    env = environment(event_c);
                }
                full.step(TICK_S, env);
                fast.step(TICK_S, env);
                worst = worst.max((fast.surface_c() - full.surface_c()).abs());
            }
            let cells = cell_difference(&fast.model(), &full);
            println!("{scheme:?}, {name}: scheme-matched fast vs full per tick: surface {worst:.1e} °C, cells {cells:.1e} °C");
            assert!(
                worst < 1e-9 && cells < 1e-9,
                "{scheme:?}, {name}: scheme-matched fast path vs full model: surface {worst} °C, cells {cells} °C"
            );
        }
    }
}
