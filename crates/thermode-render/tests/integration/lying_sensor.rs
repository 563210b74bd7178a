//! A reading that lies while its sample counter keeps advancing (a stuck ADC, a firmware bug): the PT-100's value
//! freezes during a full-current drive, with or without fresh noise on it, and every report still counts as a new
//! sample. Nothing about the reading itself is wrong (finite, in range, plausible rate); only the plate model can
//! tell, since it predicts the plate moving at tens of °C per second while the reading stays flat. The plate guard's
//! innovation check ([`thermode_pipeline::guard`]) must fault the channel within a fraction of a second, so the true
//! plate stays within 14.9–48.1 °C, and the dose must be counted at what the plate may have been, not at the frozen
//! reading. Before the check (issue 35) the true plate reached 266 °C heating and −25 °C cooling.

use crate::common;

use common::{spec, Loop, Tick};
use thermode_pipeline::{ControllerKind, ShippedDisplay, Stimulus};
use thermode_safety::FaultCode;

const TICK_S: f64 = 0.01;
/// The envelope's judgement of the true plate \[°C\]: the display range with 0.1 °C of tolerance.
const PLATE_RANGE_C: (f64, f64) = (14.9, 48.1);

/// How the reading lies once it has frozen.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Lie {
    /// The same value on every fresh sample.
    Frozen,
    /// The frozen value with fresh, quantised noise on each sample (±0.02 °C alternating, 0.01 °C steps).
    FrozenWithNoise,
}

/// A direct ramp to `setpoint_c` on the default display with `controller`; once the reading passes `freeze_at_c`
/// (in the ramp's direction) it lies as `lie` says, its counter still advancing. Runs 15 s; returns the ticks and
/// the dose the envelope counted \[CEM43-min\].
fn run(controller: ControllerKind, setpoint_c: f64, freeze_at_c: f64, lie: Lie) -> (Vec<Tick>, f64) {
    let mut lp = Loop::new(&spec(ShippedDisplay::Default, controller, "aluminium"));
    // Three seconds at rest first: the check settles for two (reading_check::SETTLING_S).
    lp.run(300);
    lp.pipeline
        .set_stimulus(Stimulus::Direct {
            temp_c: setpoint_c,
            rate_c_per_s: 20.0,
        })
        .unwrap_or_else(|e| panic!("{e}"));
    let heating = setpoint_c > freeze_at_c;
    let mut frozen_c: Option<f64> = None;
    let mut ticks = Vec::new();
    for k in 0..(15.0 / TICK_S) as usize {
        ticks.push(lp.tick_with(TICK_S, |mut reading| {
            let passed = if heating {
                reading.sensor_c >= freeze_at_c
            } else {
                reading.sensor_c <= freeze_at_c
            };
            if frozen_c.is_none() && passed {
                frozen_c = Some(reading.sensor_c);
            }
            if let Some(value_c) = frozen_c {
                let noise_c = match lie {
                    Lie::Frozen => 0.0,
                    Lie::FrozenWithNoise => [0.02, -0.02][k % 2],
                };
                reading.sensor_c = ((value_c + noise_c) / 0.01).round() * 0.01;
            }
            reading
        }));
    }
    assert!(frozen_c.is_some(), "the reading never reached {freeze_at_c} °C");
    (ticks, lp.pipeline.envelope().cem43_min())
}

/// The true plate's dose over `ticks` \[CEM43-min\]: Sapareto & Dewey's R^(43 − T) per minute, R = 0.5 at or above
/// 43 °C and 0.25 below, each tick at the plate after it.
fn true_cem43_min(ticks: &[Tick]) -> f64 {
    ticks
        .iter()
        .map(|t| {
            let r: f64 = if t.plate_c >= 43.0 { 0.5 } else { 0.25 };
            r.powf(43.0 - t.plate_c) * TICK_S / 60.0
        })
        .sum()
}

/// The true plate's range over `ticks` \[°C\].
fn plate_range_c(ticks: &[Tick]) -> (f64, f64) {
    ticks.iter().fold((f64::MAX, f64::MIN), |(lo, hi), t| {
        (lo.min(t.plate_c), hi.max(t.plate_c))
    })
}

#[test]
fn a_reading_that_freezes_under_a_full_drive_faults_the_channel_before_the_plate_leaves_the_range() {
    let mut failures = Vec::new();
    for controller in [common::pid(ShippedDisplay::Default), ControllerKind::Model] {
        // Frozen during a heating and a cooling ramp, and frozen at rest just before a full heating drive starts.
        for (setpoint_c, freeze_at_c) in [(45.0, 34.0), (15.0, 25.0), (47.0, 20.0)] {
            for lie in [Lie::Frozen, Lie::FrozenWithNoise] {
                let (ticks, counted_cem43_min) = run(controller, setpoint_c, freeze_at_c, lie);
                let true_cem43_min = true_cem43_min(&ticks);
                let (coldest_c, hottest_c) = plate_range_c(&ticks);
                let fault = ticks.iter().find_map(|t| t.fault.map(|f| (f, t.now_s)));
                let last = ticks.last().map(|t| t.telemetry.fault);
                let what = format!(
                    "{} to {setpoint_c} °C, reading {lie:?} at {freeze_at_c} °C: true plate {coldest_c:.2}..{hottest_c:.2} \
                     °C, first fault {fault:?}, last {last:?}; dose counted {counted_cem43_min:.5}, true \
                     {true_cem43_min:.5} CEM43-min",
                    controller.name()
                );
                eprintln!("{what}");
                let inside = coldest_c >= PLATE_RANGE_C.0 && hottest_c <= PLATE_RANGE_C.1;
                let faulted = fault.is_some_and(|(f, _)| f == FaultCode::ReadingDisagreesWithModel);
                // Never below the true dose; the distrusted stretch is counted at the model's plate (plus its 1 °C
                // margin), not at the dose budget.
                let dose_ok = counted_cem43_min >= true_cem43_min && counted_cem43_min <= true_cem43_min + 0.05;
                if !(inside && faulted && dose_ok) {
                    failures.push(what);
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
