//! Judged: the thermal dose is a cap. `thermode render --material copper --object-temp 70 --duration 3600` — a
//! finger on a 70 °C copper object for an hour, which asks the display for far more than 48 °C all along — and the
//! CEM43 computed here from the CSV's `display_c` column (the *true* simulated plate, not the sensor the envelope
//! sees) is at most 1.05 × the envelope's budget (`cem43_budget_min`, 1 CEM43-min by default).
//!
//! The spec is the one the CLI builds for those arguments (default display, fv renderer, render envelope,
//! 5 s of pre-contact, 100 Hz — the CLI's rate: an hour takes a few seconds in the test profile, so no coarser rate
//! is needed). The CEM43 is computed independently of `thermode_safety::dose`: `Σ R^(43 − T) Δt / 60` with
//! R = 0.5 at and above 43 °C and 0.25 below, each interval counted at the hotter of its two rows (an upper bound
//! of the dose of the plate path between them).
//!
//! Both controllers are asserted: the model controller (the CLI's default) and the paper's PID, which heats hardest
//! (without the envelope's plate guard its plate overshot to 52 °C on the first rise, before any dose was counted).

use thermode_device::DeviceConfig;
use thermode_model::materials;
use thermode_pipeline::{gains_for_device, ControllerKind, PipelineConfig};
use thermode_render::run::{render, write_csv, Precision};
use thermode_render::RenderSpec;

/// The spec of `thermode render --material copper --object-temp 70 --duration 3600 --controller <controller>`.
fn cli_spec(controller: ControllerKind) -> RenderSpec {
    let pipeline = PipelineConfig::new(DeviceConfig::default(), controller);
    let mut spec = RenderSpec::new(pipeline, materials::find("copper").unwrap_or_else(|e| panic!("{e}")));
    spec.object_c = Some(70.0);
    spec.duration_s = 3600.0;
    spec
}

/// CEM43 rate at `temp_c`, CEM43-minutes per minute.
fn rate(temp_c: f64) -> f64 {
    let r: f64 = if temp_c >= 43.0 { 0.5 } else { 0.25 };
    r.powf(43.0 - temp_c)
}

/// The CEM43 (minutes) of the CSV's `display_c` over `time_s`, each interval at its hotter end; also the hottest
/// `display_c` and the last `display_setpoint_c`.
fn cem43_of_csv(csv_text: &[u8]) -> (f64, f64, f64) {
    let mut reader = csv::Reader::from_reader(csv_text);
    let header = reader.headers().unwrap_or_else(|e| panic!("{e}")).clone();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no {name} column"))
    };
    let (t_col, plate_col, sp_col) = (col("time_s"), col("display_c"), col("display_setpoint_c"));
    let (mut cem43_min, mut hottest_c, mut last_setpoint_c) = (0.0, f64::NEG_INFINITY, f64::NAN);
    let mut prev: Option<(f64, f64)> = None;
    for record in reader.records() {
        let record = record.unwrap_or_else(|e| panic!("{e}"));
        let number = |i: usize| -> f64 { record[i].parse().unwrap_or_else(|e| panic!("{e}: {:?}", &record[i])) };
        let (t, plate_c) = (number(t_col), number(plate_col));
        if let Some((t_prev, plate_prev_c)) = prev {
            cem43_min += rate(plate_c.max(plate_prev_c)) * (t - t_prev) / 60.0;
        }
        prev = Some((t, plate_c));
        hottest_c = hottest_c.max(plate_c);
        last_setpoint_c = number(sp_col);
    }
    (cem43_min, hottest_c, last_setpoint_c)
}

/// Renders the hour with `controller`, writes the CSV and returns (CEM43 of `display_c`, budget, hottest plate,
/// final set-point), printing them.
fn hour_on_hot_copper(controller: ControllerKind) -> (f64, f64, f64, f64) {
    let spec = cli_spec(controller);
    let budget_min = spec.pipeline.envelope.cem43_budget_min;
    let run = render(&spec).unwrap_or_else(|e| panic!("{e}"));
    let mut csv_text = Vec::new();
    write_csv(std::slice::from_ref(&run), Precision::Exact, &mut csv_text).unwrap_or_else(|e| panic!("{e}"));
    let (cem43_min, hottest_c, last_setpoint_c) = cem43_of_csv(&csv_text);
    println!(
        "{}: CEM43 of display_c over {} s = {cem43_min:.4} CEM43-min (budget {budget_min}, cap {:.4}); hottest \
         plate {hottest_c:.2} °C; set-point at the end {last_setpoint_c:.2} °C",
        run.summary.controller,
        spec.duration_s,
        1.05 * budget_min
    );
    (cem43_min, budget_min, hottest_c, last_setpoint_c)
}

#[test]
fn an_hour_on_70_c_copper_stays_within_5_percent_of_the_dose_budget_model() {
    let (cem43_min, budget_min, hottest_c, last_setpoint_c) = hour_on_hot_copper(ControllerKind::Model);
    assert!(
        cem43_min <= 1.05 * budget_min,
        "true plate CEM43 {cem43_min} CEM43-min > 1.05 × budget {budget_min}"
    );
    // The budget was really spent (the display went to the top of its range, which the envelope's plate guard keeps
    // 0.3 °C below 48 °C), and the ceiling came down below 43 °C and stayed.
    assert!(hottest_c >= 47.5, "hottest plate {hottest_c} °C");
    assert!(
        cem43_min >= 0.5 * budget_min,
        "CEM43 {cem43_min}: the budget was never approached"
    );
    assert!(last_setpoint_c < 42.5, "set-point at the end {last_setpoint_c} °C");
}

#[test]
fn an_hour_on_70_c_copper_stays_within_5_percent_of_the_dose_budget_pid() {
    let (gains, _) = gains_for_device(&DeviceConfig::default()).unwrap_or_else(|e| panic!("{e}"));
    let (cem43_min, budget_min, _, _) = hour_on_hot_copper(ControllerKind::Pid(gains));
    assert!(
        cem43_min <= 1.05 * budget_min,
        "true plate CEM43 {cem43_min} CEM43-min > 1.05 × budget {budget_min}"
    );
}
