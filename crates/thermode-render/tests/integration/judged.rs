//! The judged properties of thermode's `model` controller against the paper's `pid` (tuned by `thermode tune` for
//! each display), on the paper's five materials over 90 s with the default fv renderer, as `thermode render` runs
//! them (seed 1):
//!
//! 1. the slow initial drop (the Peltier's limit): on the default display the model's lag at half of the target's
//!    drop is within 20 % of the actuator limit for every material;
//! 2. the colder end (controller inertia): the model's overshoot below the target is under 0.1 °C on the default,
//!    weakly cooled and lagging-sensor displays;
//! 3. RMS skin error over 0–90 s: model no worse than pid on the default and the weakly cooled display;
//! 4. on the lagging sensor: both controllers are bounded below by the RMS floor of an ideal controller at the
//!    actuator limit (`Summary::actuator_limit_rms_c`), which the model reaches; the part of the error above that
//!    floor, √(rms² − floor²), is for the model at most half of pid's (the issue asks for the whole RMS to be at
//!    most half; the floor alone is about 0.98 of pid's RMS there, so that is out of reach for any controller —
//!    see the report);
//! 5. with a simulated finger whose skin parameters (every layer's thickness, conductivity, density, specific heat
//!    and perfusion) are all 20 % below or above the controller's model, the model is no worse than pid against the
//!    ground truth (mean over the materials), thanks to the calibration of the finger model at the touch, which is
//!    checked on its own;
//! 6. the overshoot holds at the runtime's tick rates (200 and 1000 Hz), and counts only the contact, not the
//!    warming lag after a release.
//!
//! Each test renders 2–30 contacts of up to 95 s (a few seconds for all in the test profile).

use crate::common;

use std::sync::OnceLock;

use common::{pid, plant_off_file, spec, Loop};
use thermode_model::Skin;
use thermode_pipeline::{ControllerKind, ShippedDisplay, Stimulus};
use thermode_render::run::{render_all, Trajectory};
use thermode_render::{RenderRun, RenderSpec, RenderSummary as Summary};

const PAPER: [&str; 5] = ["aluminium", "steel", "stone", "wood", "rubber"];

/// pid then model, the five materials each, on `display` with `finger` (None = the controller's own model).
fn runs(display: ShippedDisplay, finger: Option<&Skin>) -> Vec<RenderRun> {
    runs_edited(display, |s| {
        if let Some(skin) = finger {
            s.finger_skin = skin.clone();
        }
    })
}

/// pid then model, the five materials each, on `display`, each spec changed by `edit`.
fn runs_edited(display: ShippedDisplay, edit: impl Fn(&mut RenderSpec)) -> Vec<RenderRun> {
    let specs: Vec<_> = [pid(display), ControllerKind::Model]
        .into_iter()
        .flat_map(|c| PAPER.map(|m| spec(display, c, m)))
        .map(|mut s| {
            edit(&mut s);
            s
        })
        .collect();
    render_all(&specs).unwrap_or_else(|e| panic!("{e}"))
}

fn cached(display: ShippedDisplay) -> &'static [RenderRun] {
    static DEFAULT: OnceLock<Vec<RenderRun>> = OnceLock::new();
    static WEAK: OnceLock<Vec<RenderRun>> = OnceLock::new();
    static LAGGING: OnceLock<Vec<RenderRun>> = OnceLock::new();
    let cell = match display {
        ShippedDisplay::Default => &DEFAULT,
        ShippedDisplay::WeakCooling => &WEAK,
        ShippedDisplay::LaggingSensor => &LAGGING,
    };
    cell.get_or_init(|| runs(display, None))
}

fn of<'a>(runs: &'a [RenderRun], controller: &str) -> Vec<&'a Summary> {
    runs.iter()
        .map(|r| &r.summary)
        .filter(|s| s.controller == controller)
        .collect()
}

fn value(v: Option<f64>, what: &str, s: &Summary) -> f64 {
    v.unwrap_or_else(|| panic!("{} {}: no {what}", s.material, s.controller))
}

fn mean(summaries: &[&Summary], f: impl Fn(&Summary) -> f64) -> f64 {
    summaries.iter().map(|s| f(s)).sum::<f64>() / summaries.len() as f64
}

#[test]
fn model_lag_is_within_20_percent_of_the_actuator_limit_on_the_default_display() {
    for s in of(cached(ShippedDisplay::Default), "model") {
        let lag = value(s.lag_s, "lag", s);
        let limit = value(s.actuator_limit_lag_s, "actuator limit", s);
        eprintln!("{}: lag {lag:.3} s, actuator limit {limit:.3} s", s.material);
        assert!(
            lag <= 1.2 * limit,
            "{}: lag {lag} s vs actuator limit {limit} s",
            s.material
        );
    }
}

#[test]
fn model_overshoot_stays_below_a_tenth_of_a_degree_on_every_display() {
    for display in ShippedDisplay::ALL {
        for s in of(cached(display), "model") {
            eprintln!("{} {}: overshoot {:.4} °C", display.name(), s.material, s.overshoot_c);
            assert!(
                s.overshoot_c < 0.1,
                "{} {}: overshoot {} °C",
                display.name(),
                s.material,
                s.overshoot_c
            );
        }
    }
}

#[test]
fn model_rms_is_no_worse_than_the_tuned_pid_on_the_default_and_the_weakly_cooled_display() {
    for display in [ShippedDisplay::Default, ShippedDisplay::WeakCooling] {
        let runs = cached(display);
        let (p, m) = (of(runs, "pid"), of(runs, "model"));
        for (p, m) in p.iter().zip(&m) {
            let (rp, rm) = (value(p.rms_skin_0_90_c, "rms", p), value(m.rms_skin_0_90_c, "rms", m));
            eprintln!("{} {}: rms pid {rp:.4} model {rm:.4} °C", display.name(), p.material);
            assert!(rm <= rp, "{} {}: model {rm} vs pid {rp} °C", display.name(), p.material);
        }
    }
}

#[test]
fn on_the_lagging_sensor_the_model_sits_on_the_floor_and_halves_pids_excess_over_it() {
    let runs = cached(ShippedDisplay::LaggingSensor);
    let excess = |s: &Summary| {
        let rms = value(s.rms_skin_0_90_c, "rms", s);
        let floor = value(s.actuator_limit_rms_c, "floor", s);
        assert!(
            rms >= floor * (1.0 - 1e-3),
            "{} {}: rms {rms} below the floor {floor}",
            s.material,
            s.controller
        );
        (rms * rms - floor * floor).max(0.0).sqrt()
    };
    let (p, m) = (of(runs, "pid"), of(runs, "model"));
    for (p, m) in p.iter().zip(&m) {
        let (ep, em) = (excess(p), excess(m));
        eprintln!(
            "{}: rms pid {:.4} (floor {:.4}, excess {ep:.4}), model {:.4} (floor {:.4}, excess {em:.4}) °C",
            p.material,
            value(p.rms_skin_0_90_c, "rms", p),
            value(p.actuator_limit_rms_c, "floor", p),
            value(m.rms_skin_0_90_c, "rms", m),
            value(m.actuator_limit_rms_c, "floor", m)
        );
        assert!(
            em <= 0.5 * ep,
            "{}: model excess {em} vs pid excess {ep} °C",
            p.material
        );
        assert!(
            value(m.rms_skin_0_90_c, "rms", m) <= value(p.rms_skin_0_90_c, "rms", p),
            "{}: model worse than pid",
            p.material
        );
    }
}

/// The default fingertip with every layer's thickness, conductivity, density, specific heat and perfusion times
/// `factor`.
fn finger(factor: f64) -> Skin {
    let mut skin = Skin::fingertip();
    for layer in &mut skin.layers {
        layer.thickness_m *= factor;
        layer.conductivity_w_mk *= factor;
        layer.density_kg_m3 *= factor;
        layer.specific_heat_j_kgk *= factor;
        layer.perfusion_per_s *= factor;
    }
    skin
}

fn finger_check(factor: f64) {
    let runs = runs(ShippedDisplay::Default, Some(&finger(factor)));
    let truth = |s: &Summary| value(s.rms_truth_0_90_c, "rms against the truth", s);
    let (p, m) = (mean(&of(&runs, "pid"), truth), mean(&of(&runs, "model"), truth));
    eprintln!("finger ×{factor}: mean rms against the truth pid {p:.4}, model {m:.4} °C");
    for (p, m) in of(&runs, "pid").iter().zip(of(&runs, "model")) {
        eprintln!("  {}: pid {:.4} model {:.4} °C", p.material, truth(p), truth(m));
    }
    assert!(m <= p, "finger ×{factor}: model {m} vs pid {p} °C against the truth");
}

#[test]
fn with_a_finger_20_percent_below_the_model_model_is_no_worse_than_pid_against_the_truth() {
    finger_check(0.8);
}

/// With a finger that delivers more heat than the model (×1.2), the paper's PID lets the plate warm with that heat
/// (its finite loop gain acts like the real material's surface, which warms under the extra heat), while the model
/// controller's observer learns the heat and holds the plate on the set-point. Without the calibration at the touch
/// the model lost by 0.5 % (0.7014 °C against pid's 0.6982, seeds 1–4 alike); with it (the rest's learned heat
/// tells how much warmer this finger is, and the target is computed for it) it wins, 0.6044 against 0.6982
/// (×0.8: 0.8578 against 0.9559, before 0.9512).
#[test]
fn with_a_finger_20_percent_above_the_model_model_is_no_worse_than_pid_against_the_truth() {
    finger_check(1.2);
}

/// The runtime ticks the pipeline at up to 1 kHz. The display inverse then requests over one sensor sample period
/// rather than one tick (`ChannelPipeline::request_horizon_s`); with a one-tick request the overshoot was 0.13–0.14
/// °C at 1000 Hz and 0.06–0.07 °C at 200 Hz, with it 0.008–0.016 and 0.009–0.020 (measured, seed 1).
#[test]
fn model_overshoot_stays_below_a_tenth_of_a_degree_at_200_and_1000_hz_on_the_default_display() {
    let specs: Vec<_> = [200.0, 1000.0]
        .into_iter()
        .flat_map(|rate_hz| {
            PAPER.map(|m| {
                let mut s = spec(ShippedDisplay::Default, ControllerKind::Model, m);
                s.rate_hz = rate_hz;
                s
            })
        })
        .collect();
    for run in render_all(&specs).unwrap_or_else(|e| panic!("{e}")) {
        let (s, rate_hz) = (&run.summary, run.spec.rate_hz);
        eprintln!("{rate_hz} Hz {}: overshoot {:.4} °C", s.material, s.overshoot_c);
        assert!(
            s.overshoot_c < 0.1,
            "{rate_hz} Hz {}: overshoot {} °C",
            s.material,
            s.overshoot_c
        );
        assert_eq!(s.first_fault, None, "{rate_hz} Hz {}: fault", s.material);
    }
}

/// After a release the target warms back faster than the display can warm the finger; that lag is not driven past
/// the target and must not count as overshoot. With a release at 10 s the overshoot is exactly that of the same
/// run (same seed, identical rows until the release) over its first 10 s, while the skin trails the warming target
/// after the release by far more than the 0.1 °C bound (so counting it would break the judged property).
#[test]
fn overshoot_counts_the_contact_only_not_the_warming_after_a_release() {
    let release_at_s = 10.0;
    let held = {
        let mut s = spec(ShippedDisplay::Default, ControllerKind::Model, "aluminium");
        s.duration_s = 30.0;
        s
    };
    let released = RenderSpec {
        release_at_s: Some(release_at_s),
        ..held.clone()
    };
    let runs = render_all(&[held, released]).unwrap_or_else(|e| panic!("{e}"));
    let (held, released) = (&runs[0].trajectory, &runs[1].trajectory);
    let below = |t: &Trajectory, after_release: bool| {
        (0..t.len())
            .filter(|&i| t.time_s[i] > 0.0 && (t.time_s[i] > release_at_s + 1e-9) == after_release)
            .map(|i| t.target_skin_c[i] - t.skin_c[i])
            .fold(0.0, f64::max)
    };
    let want = below(held, false);
    let trailing = below(released, true);
    let got = runs[1].summary.overshoot_c;
    eprintln!(
        "overshoot with release {got:.4} °C, contact part of the held run {want:.4} °C, trailing {trailing:.4} °C"
    );
    assert_eq!(
        got, want,
        "overshoot with release {got} vs the held run's first {release_at_s} s {want}"
    );
    assert!(trailing > 0.1, "skin trails the warming target by {trailing} °C only");
    assert!(got < 0.1, "overshoot {got} °C");
}

/// The calibration at the touch (`PipelineConfig::calibrate_finger_at_touch`): after the 5 s rest, the model
/// controller's learned unknown heat shifts the finger model's receptor to the real finger's receptor on the
/// display at the touch (the plant's true state), for the ×0.8 and ×1.2 fingers to within 0.05 °C and a quarter of
/// the gap the uncalibrated model leaves (the learned heat fluctuates by about ±3 mW, ±0.05 °C, from tick to tick;
/// its average over the last second trails the real finger, which still settles on the display), and
/// leaves the model exactly as it is for the default finger (its learned heat is noise, which the gate refuses).
/// pid learns no heat: never calibrated. The telemetry's `finger_c` (the same measure per tick), averaged over
/// the last second of rest, is the real finger's receptor within 0.1 °C (NaN for pid). The real finger's own resting temperature in air differs from the model's
/// by more (−1.15 °C at ×0.8): while the display renders air for the model finger, its plate holds the real finger
/// near the model's resting surface (800 W/(m²·K) to the plate against 10 to air), and the display can only
/// render a touch from where the finger really is.
#[test]
fn the_touch_calibrates_the_finger_model_to_the_real_finger_and_only_to_a_different_one() {
    for factor in [1.0, 0.8, 1.2] {
        for controller in [pid(ShippedDisplay::Default), ControllerKind::Model] {
            let mut s = spec(ShippedDisplay::Default, controller, "wood");
            s.finger_skin = finger(factor);
            let mut lp = Loop::new(&s);
            let rest = lp.run((s.pre_contact_s * s.rate_hz).round() as usize);
            let model_c = lp.pipeline.display_finger().receptor_c();
            let real_c = lp.plant.channel(0).unwrap_or_else(|e| panic!("{e}")).state().receptor_c;
            let last_second = &rest[rest.len() - s.rate_hz as usize..];
            let measured_c = last_second.iter().map(|t| t.telemetry.finger_c).sum::<f64>() / s.rate_hz;
            if lp.pipeline.controller().name() == "pid" {
                assert!(
                    measured_c.is_nan(),
                    "pid has no observer to measure the finger: {measured_c}"
                );
            } else {
                assert!(
                    (measured_c - real_c).abs() < 0.1,
                    "×{factor}: finger_c over the last second of rest {measured_c} vs the real receptor {real_c} °C"
                );
            }
            let touch = Stimulus::Touch {
                material: s.material.clone(),
                object_c: s.object_temperature_c(),
            };
            lp.pipeline.set_stimulus(touch).unwrap_or_else(|e| panic!("{e}"));
            let (shift_c, want_c) = (lp.pipeline.calibration_shift_c(), real_c - model_c);
            let name = lp.pipeline.controller().name();
            eprintln!("finger ×{factor} {name}: calibration shift {shift_c:.4} °C, real minus model {want_c:.4}");
            if factor == 1.0 || name == "pid" {
                assert_eq!(shift_c, 0.0, "×{factor} {name}: shift {shift_c} °C");
            } else {
                assert!(
                    (shift_c - want_c).abs() < 0.05 && (shift_c - want_c).abs() < 0.25 * want_c.abs(),
                    "×{factor}: calibration shift {shift_c} vs real minus model receptor {want_c} °C"
                );
            }
        }
    }
}

/// The calibration's gate on the device file's uncertainty (`render.peltier_uncertainty`): on a display whose
/// module conducts 30 % less than its datasheet file says (ΔT_max × 0.7 in the plant), the resting plate exchanges
/// less heat with the hot side than the model expects, and the controller learns that as heat from the finger.
/// Believing the file exact, the touch would move the finger model by that heat over G — a finger that is not
/// there; the datasheet file's 30 % explains it, so a finger that matches the model is left as it is, and the model
/// controller then renders the paper's materials with an RMS no worse than pid's on that plant.
#[test]
fn a_datasheet_file_does_not_take_its_own_peltier_error_for_the_finger() {
    let believed = thermode_device::DeviceConfig::default();
    let mut plant = believed;
    plant.peltier.dtmax_k *= 0.7;
    plant.peltier.qmax_w = plant.peltier.predicted_qmax_w();
    let shift_c = |uncertainty: f64| {
        let mut s = spec(ShippedDisplay::Default, ControllerKind::Model, "wood");
        s.pipeline.device.render.peltier_uncertainty = uncertainty;
        s.hardware = Some(plant);
        let mut lp = Loop::new(&s);
        lp.run((s.pre_contact_s * s.rate_hz).round() as usize);
        let touch = Stimulus::Touch {
            material: s.material.clone(),
            object_c: s.object_temperature_c(),
        };
        lp.pipeline.set_stimulus(touch).unwrap_or_else(|e| panic!("{e}"));
        lp.pipeline.calibration_shift_c()
    };
    let (believed_exact_c, datasheet_c) = (shift_c(0.0), shift_c(believed.render.peltier_uncertainty));
    eprintln!("calibration shift of a model finger: file taken as exact {believed_exact_c:.3} °C, as a datasheet {datasheet_c:.3} °C");
    assert!(
        believed_exact_c.abs() > 0.5,
        "the module's error read as a finger: {believed_exact_c} °C"
    );
    assert_eq!(datasheet_c, 0.0, "a datasheet file's own error taken for the finger");
    let (p, m, _) = on_hardware(plant);
    eprintln!("ΔT_max × 0.7 plant: mean RMS pid {p:.4}, model {m:.4} °C");
    assert!(
        m <= p,
        "model {m} vs pid {p} °C on a plant whose K is 30 % below its file"
    );
}

/// Mean RMS skin error (0-90 s) of pid and of the model controller, and the model's largest overshoot, over the
/// paper's materials on the default display's file with `hardware` as the plant.
fn on_hardware(hardware: thermode_device::DeviceConfig) -> (f64, f64, f64) {
    let runs = runs_edited(ShippedDisplay::Default, |s| s.hardware = Some(hardware));
    let rms = |s: &Summary| value(s.rms_skin_0_90_c, "rms", s);
    let overshoot_c = of(&runs, "model").iter().map(|s| s.overshoot_c).fold(0.0, f64::max);
    (
        mean(&of(&runs, "pid"), rms),
        mean(&of(&runs, "model"), rms),
        overshoot_c,
    )
}

/// The observer's estimate of the plate's response (device file `render.plate_uncertainty`): on displays whose
/// plate has 30 % more or less heat capacity than the default file says, the model controller believing that file
/// overshoots the target by at most 0.2 °C and its mean RMS stays at or below pid's. With the file's capacity taken
/// as exact it overshot by 0.29 and 0.50 °C.
#[test]
fn the_plate_response_estimate_keeps_the_model_controller_on_target_with_a_plate_off_its_file() {
    for factor in [1.3, 0.7] {
        let mut plant = thermode_device::DeviceConfig::default();
        plant.plate.heat_capacity_j_k *= factor;
        let (p, m, overshoot_c) = on_hardware(plant);
        eprintln!("C_p × {factor}: mean RMS pid {p:.4}, model {m:.4} °C; overshoot {overshoot_c:.3} °C");
        assert!(
            overshoot_c <= 0.2 && m <= p,
            "C_p × {factor}: overshoot {overshoot_c} °C, RMS model {m} vs pid {p} °C"
        );
    }
}

/// The live fit of the module to its voltage (`thermode_control::ModuleFit`): on displays whose module is 30 % off
/// the datasheet file in V_max (S, R and K together) or has 30 % less I_max (R up, K down, and a drive that stops
/// at the module's I_max), the model controller believing the default file overshoots the target by at most
/// 0.2 °C and its mean RMS stays at or below pid's. Without the fit it overshot by 0.45, 0.29 and 0.31 °C.
#[test]
fn the_voltage_fit_keeps_the_model_controller_on_target_with_a_module_off_its_datasheet() {
    for (vmax, imax) in [(1.3, 1.0), (0.7, 1.0), (1.0, 0.7)] {
        let plant = plant_off_file(|p| {
            p.peltier.vmax_v *= vmax;
            p.peltier.imax_a *= imax;
        });
        let (p, m, overshoot_c) = on_hardware(plant);
        eprintln!(
            "V_max × {vmax}, I_max × {imax}: mean RMS pid {p:.4}, model {m:.4} °C; overshoot {overshoot_c:.3} °C"
        );
        assert!(
            overshoot_c <= 0.2 && m <= p,
            "V_max × {vmax}, I_max × {imax}: overshoot {overshoot_c} °C, RMS model {m} vs pid {p} °C"
        );
    }
}

/// Issue 26's robustness bar (item 6), its whole plant set: the module's Seebeck coefficient S, resistance R and
/// conductance K (each on its own; the plant's datasheet is the one that gives that module,
/// `PeltierDatasheet::from_module`, the drive limit within its I_max), the plate's and the hot side's heat capacities
/// and the water conductance, each 30 % up and down, then all six together up and down; the sensor lag and the
/// finger's contact as filed. The model controller believing the default datasheet file overshoots the target by at
/// most 0.2 °C and its mean RMS over the paper's materials stays at or below pid's. Before: S × 1.3 overshot by
/// 0.43 °C (K from the file's figure of merit came out 69 % high and was read as finger heat at the touch), S × 0.7
/// had an RMS above pid's, the lighter hot side overshot by 0.19 °C. The same sweep with the release binary:
/// `scripts/plant-sweep --module` (docs/design-choices.md).
#[test]
fn the_model_controller_meets_the_bar_on_plants_whose_module_capacities_or_water_are_off_its_file() {
    type Edit = Box<dyn Fn(&mut thermode_device::DeviceConfig)>;
    let module = |s: f64, r: f64, k: f64| -> Edit {
        Box::new(move |p: &mut thermode_device::DeviceConfig| {
            let file = p.module().unwrap_or_else(|e| panic!("{e}"));
            let scaled = thermode_model::peltier::PeltierModule {
                seebeck_v_k: file.seebeck_v_k * s,
                resistance_ohm: file.resistance_ohm * r,
                conductance_w_k: file.conductance_w_k * k,
            };
            p.peltier = thermode_model::peltier::PeltierDatasheet::from_module(&scaled, p.peltier.hot_side_k)
                .unwrap_or_else(|| panic!("no datasheet for {scaled:?}"));
        })
    };
    let capacities_and_water = |f: f64| -> Edit {
        Box::new(move |p: &mut thermode_device::DeviceConfig| {
            p.plate.heat_capacity_j_k *= f;
            p.hot_side.heat_capacity_j_k *= f;
            p.hot_side.water_conductance_w_k *= f;
        })
    };
    let mut failures = Vec::new();
    for f in [1.3, 0.7] {
        let plants: [(&str, Edit); 7] = [
            ("S", module(f, 1.0, 1.0)),
            ("R", module(1.0, f, 1.0)),
            ("K", module(1.0, 1.0, f)),
            ("C_p", Box::new(move |p| p.plate.heat_capacity_j_k *= f)),
            ("C_h", Box::new(move |p| p.hot_side.heat_capacity_j_k *= f)),
            ("G_w", Box::new(move |p| p.hot_side.water_conductance_w_k *= f)),
            ("all six", {
                let (m, c) = (module(f, f, f), capacities_and_water(f));
                Box::new(move |p| {
                    m(p);
                    c(p);
                })
            }),
        ];
        for (name, edit) in plants {
            let (p, m, overshoot_c) = on_hardware(plant_off_file(edit));
            eprintln!("{name} × {f}: mean RMS pid {p:.4}, model {m:.4} °C; model overshoot {overshoot_c:.3} °C");
            if !(overshoot_c <= 0.2 && m <= p) {
                failures.push(format!(
                    "{name} × {f}: model overshoot {overshoot_c} °C (bar 0.2), mean RMS model {m} vs pid {p} °C"
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
