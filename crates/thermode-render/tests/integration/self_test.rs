//! The display checked against its file before a finger can be on it (issue 23, item 1): rendering copper at the
//! hottest and the coldest object temperature with both controllers on displays whose sensor lags 0.1 to 10 times,
//! whose plate and hot side hold 0.3 to 3 times the heat, and whose module and water conductance are 0.5 to 2 times
//! what the believed device file says, the true plate stays within 14.5–48.5 °C, or the self-test refused the
//! display before the touch (fault 106 from the first tick, the drive at 0 A throughout).

use crate::common::{pid, plant_off_file, spec};

use thermode_pipeline::stimulus::OBJECT_TEMPERATURE;
use thermode_pipeline::{ControllerKind, ShippedDisplay};
use thermode_render::run::render_all;
use thermode_safety::FaultCode;

/// The range the true plate must stay in when the display is not refused \[°C\] (the goal).
const PLATE_RANGE_C: (f64, f64) = (14.5, 48.5);

#[test]
fn off_file_displays_are_refused_before_the_touch_or_their_plate_stays_in_range() {
    type Edit = fn(&mut thermode_device::DeviceConfig);
    let plants: [(&str, Edit, bool); 12] = [
        ("sensor τ × 0.1", |p| p.sensor.time_constant_s *= 0.1, false),
        ("sensor τ × 2", |p| p.sensor.time_constant_s *= 2.0, true),
        ("sensor τ × 10", |p| p.sensor.time_constant_s *= 10.0, true),
        ("C_plate × 0.3", |p| p.plate.heat_capacity_j_k *= 0.3, true),
        ("C_plate × 0.5", |p| p.plate.heat_capacity_j_k *= 0.5, false),
        ("C_plate × 3", |p| p.plate.heat_capacity_j_k *= 3.0, false),
        ("C_hot × 0.3", |p| p.hot_side.heat_capacity_j_k *= 0.3, false),
        ("C_hot × 3", |p| p.hot_side.heat_capacity_j_k *= 3.0, false),
        ("G_water × 0.5", |p| p.hot_side.water_conductance_w_k *= 0.5, false),
        ("G_water × 2", |p| p.hot_side.water_conductance_w_k *= 2.0, false),
        ("module × 0.5", |p| p.peltier.imax_a *= 0.5, false),
        ("module × 2", |p| p.peltier.vmax_v *= 2.0, false),
    ];
    let mut specs = Vec::new();
    for (name, edit, refused) in plants {
        for controller in [pid(ShippedDisplay::Default), ControllerKind::Model] {
            for object_c in [OBJECT_TEMPERATURE.max, OBJECT_TEMPERATURE.min] {
                let mut s = spec(ShippedDisplay::Default, controller, "copper");
                s.hardware = Some(plant_off_file(edit));
                s.object_c = Some(object_c);
                s.duration_s = 4.0;
                specs.push((name, refused, s));
            }
        }
    }
    let runs =
        render_all(&specs.iter().map(|(_, _, s)| s.clone()).collect::<Vec<_>>()).unwrap_or_else(|e| panic!("{e}"));
    let mut failures = Vec::new();
    for ((name, want_refused, s), run) in specs.iter().zip(&runs) {
        let t = &run.trajectory;
        let report = run.self_test.expect("a plant off its file is self-tested");
        let refused = report.off_file().is_some();
        let what = format!(
            "{name} {} at {} °C ({report})",
            run.summary.controller,
            s.object_c.unwrap_or(f64::NAN)
        );
        if refused != *want_refused {
            failures.push(format!("{what}: refused {refused}, expected {want_refused}"));
        } else if refused {
            let first = t.fault.first().copied().flatten();
            let drive_a = t.current_a.iter().fold(0.0_f64, |m, a| m.max(a.abs()));
            if first != Some(FaultCode::DisplayNotAsFiled) || drive_a != 0.0 {
                failures.push(format!("{what}: first fault {first:?}, largest drive {drive_a} A"));
            }
        } else {
            let (lo, hi) = t
                .display_c
                .iter()
                .fold((f64::MAX, f64::MIN), |(lo, hi), &c| (lo.min(c), hi.max(c)));
            if lo < PLATE_RANGE_C.0 || hi > PLATE_RANGE_C.1 {
                failures.push(format!(
                    "{what}: true plate {lo:.2}..{hi:.2} °C outside {PLATE_RANGE_C:?}"
                ));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} runs:\n{}",
        failures.len(),
        specs.len(),
        failures.join("\n")
    );
}
