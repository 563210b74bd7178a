//! Fault injection through the pipeline into the simulated display: every fault the device can inject is detected
//! by the safety envelope within a stated bound, and from then on the commanded drive is 0 A with the fault latched
//! on every tick. Broken numbers (NaN readings, NaN time steps, NaN stimuli) are refused or latched likewise.
//!
//! Bounds (100 Hz sensor, 100 Hz ticks, default envelope):
//! - sensor open / short: the next sample instant reads the fault value, the next tick sees it: ≤ 1 sample period
//!   + 1 tick after the injection;
//! - sensor frozen: the envelope's stale timeout after the last fresh sample, + 1 tick;
//! - pump failure: the hot-side reading (quantised to 0.01 °C) is checked every tick: ≤ 2 ticks after the true hot
//!   side first exceeds the 45 °C limit by half a quantisation step;
//! - drive stuck at its limit: the plate runs away; the lagging PT-100 follows a ramp τ behind, so the measured
//!   display passes its limit (48 + 1 °C, or 15 − 1 °C) at most 2τ + 1 sample + 1 tick after the true plate does.

use crate::common;

use common::{material, spec, Loop, Tick};
use thermode_device::{Fault, Polarity};
use thermode_pipeline::{ControllerKind, ShippedDisplay, Stimulus};
use thermode_render::RenderSpec;
use thermode_safety::FaultCode;

const TICK_S: f64 = 0.01;

fn base(controller: ControllerKind) -> RenderSpec {
    spec(ShippedDisplay::Default, controller, "aluminium")
}

fn controllers() -> [ControllerKind; 2] {
    [common::pid(ShippedDisplay::Default), ControllerKind::Model]
}

/// Runs `before` ticks, injects `fault`, runs `after` ticks; returns the ticks after the injection and the time of
/// the injection (device clock).
fn inject(lp: &mut Loop, before: usize, fault: Fault, after: usize) -> (Vec<Tick>, f64) {
    let quiet = lp.run(before);
    assert!(quiet.iter().all(|t| t.fault.is_none()), "a fault before the injection");
    lp.plant
        .channel_mut(0)
        .unwrap_or_else(|e| panic!("{e}"))
        .inject(fault)
        .unwrap_or_else(|e| panic!("{e}"));
    let at_s = lp.now_s();
    (lp.run(after), at_s)
}

/// The first tick with a fault, checking that it is `code` and that every later tick commands 0 A with it latched.
fn detected(ticks: &[Tick], code: FaultCode, what: &str) -> f64 {
    let first = ticks
        .iter()
        .position(|t| t.fault.is_some())
        .unwrap_or_else(|| panic!("{what}: never detected"));
    assert_eq!(ticks[first].fault, Some(code), "{what}: wrong fault");
    for t in &ticks[first..] {
        assert_eq!(
            t.current_a, 0.0,
            "{what}: drive {} A at {} s after detection",
            t.current_a, t.now_s
        );
        assert_eq!(t.fault, Some(code), "{what}: fault not latched at {} s", t.now_s);
    }
    ticks[first].now_s
}

#[test]
fn open_and_shorted_sensors_are_detected_at_the_next_sample() {
    for controller in controllers() {
        for (fault, code) in [
            (Fault::SensorOpen, FaultCode::SensorOpen),
            (Fault::SensorShort, FaultCode::SensorShort),
        ] {
            let mut lp = Loop::new(&base(controller));
            let (ticks, at_s) = inject(&mut lp, 150, fault, 100);
            let when = detected(&ticks, code, &format!("{fault:?} ({})", controller.name()));
            let bound = 0.01 + TICK_S + 1e-9;
            eprintln!(
                "{fault:?} ({}): detected {:.3} s after the injection",
                controller.name(),
                when - at_s
            );
            assert!(
                when - at_s <= bound,
                "{fault:?}: detected {} s after, bound {bound}",
                when - at_s
            );
        }
    }
}

#[test]
fn a_frozen_sensor_is_detected_after_the_stale_timeout() {
    for controller in controllers() {
        let mut lp = Loop::new(&base(controller));
        let timeout_s = lp.pipeline.envelope().config().stale_timeout_s;
        let (ticks, at_s) = inject(&mut lp, 150, Fault::SensorFrozen, 100);
        let when = detected(&ticks, FaultCode::SensorStale, "frozen sensor");
        // The last fresh sample is at most one sample period before the injection.
        let bound = timeout_s + 0.01 + TICK_S + 1e-9;
        eprintln!(
            "frozen ({}): detected {:.3} s after the injection",
            controller.name(),
            when - at_s
        );
        assert!(
            when - at_s <= bound && when - at_s >= timeout_s - 0.01,
            "frozen sensor detected {} s after the injection, want within [{}, {bound}]",
            when - at_s,
            timeout_s - 0.01
        );
    }
}

#[test]
fn a_pump_failure_is_detected_when_the_hot_side_passes_its_limit() {
    for controller in controllers() {
        let mut lp = Loop::new(&base(controller));
        lp.pipeline
            .set_stimulus(Stimulus::Direct {
                temp_c: 15.0,
                rate_c_per_s: 10.0,
            })
            .unwrap_or_else(|e| panic!("{e}"));
        let limit_c = lp.pipeline.envelope().config().hot_side_max_c;
        let (ticks, _) = inject(
            &mut lp,
            100,
            Fault::PumpFailure {
                remaining_fraction: 0.0,
            },
            15_000,
        );
        let when = detected(&ticks, FaultCode::HotSideOverTemperature, "pump failure");
        let crossed = ticks
            .iter()
            .find(|t| t.hot_side_c > limit_c + 0.005)
            .map_or(f64::NAN, |t| t.now_s);
        eprintln!(
            "pump failure ({}): hot side over {limit_c} °C at {crossed:.2} s, detected at {when:.2} s",
            controller.name()
        );
        assert!(
            when - crossed <= 2.0 * TICK_S + 1e-9,
            "{}: hot side passed {limit_c} °C at {crossed} s, detected at {when} s",
            controller.name()
        );
    }
}

#[test]
fn a_drive_stuck_at_its_limit_is_detected_when_the_display_runs_away() {
    for controller in controllers() {
        for (polarity, code) in [
            (Polarity::Heating, FaultCode::DisplayOverTemperature),
            (Polarity::Cooling, FaultCode::DisplayUnderTemperature),
        ] {
            let spec = base(controller);
            let tau_s = spec.pipeline.device.sensor.time_constant_s;
            let mut lp = Loop::new(&spec);
            let config = *lp.pipeline.envelope().config();
            let (ticks, _) = inject(&mut lp, 150, Fault::DriveStuck { polarity }, 1500);
            let what = format!("stuck {polarity:?} ({})", controller.name());
            let when = detected(&ticks, code, &what);
            let crossed = ticks
                .iter()
                .find(|t| match polarity {
                    Polarity::Heating => t.plate_c > config.max_display_c + config.limit_margin_c,
                    Polarity::Cooling => t.plate_c < config.min_display_c - config.limit_margin_c,
                })
                .map_or(f64::NAN, |t| t.now_s);
            let bound = 2.0 * tau_s + 0.01 + TICK_S;
            eprintln!(
                "{what}: plate past its limit at {crossed:.2} s, detected {:.3} s later",
                when - crossed
            );
            assert!(
                when - crossed <= bound,
                "{what}: plate passed its limit at {crossed} s, detected at {when} s (bound {bound} s later)"
            );
        }
    }
}

#[test]
fn broken_numbers_latch_at_once_and_nan_stimuli_are_refused() {
    // A NaN reading.
    let mut lp = Loop::new(&base(ControllerKind::Model));
    lp.run(50);
    let t = lp.tick_with(TICK_S, |mut r| {
        r.sensor_c = f64::NAN;
        r.sample_seq += 1_000;
        r
    });
    assert_eq!(t.fault, Some(FaultCode::NonFiniteMeasurement));
    assert_eq!(t.current_a, 0.0);
    assert!(lp.run(20).iter().all(|t| t.current_a == 0.0 && t.fault.is_some()));
    // A NaN or non-positive time step.
    for dt in [f64::NAN, 0.0, -0.01, f64::INFINITY] {
        let mut lp = Loop::new(&base(common::pid(ShippedDisplay::Default)));
        lp.run(50);
        let t = lp.tick_with(dt, |r| r);
        assert_eq!(t.fault, Some(FaultCode::NonFiniteCommand), "dt = {dt}");
        assert_eq!(t.current_a, 0.0, "dt = {dt}");
        assert!(
            t.telemetry.target_skin_c.is_nan(),
            "dt = {dt}: no target on a refused tick"
        );
    }
    // NaN and out-of-range stimuli are refused and leave the pipeline as it was.
    let mut lp = Loop::new(&base(ControllerKind::Model));
    lp.run(20);
    let before = lp.pipeline.renderer().receptor_c();
    let mut broken = material("steel");
    broken.conductivity_w_mk = f64::NAN;
    for stimulus in [
        Stimulus::Touch {
            material: material("steel"),
            object_c: f64::NAN,
        },
        Stimulus::Touch {
            material: broken,
            object_c: 23.0,
        },
        Stimulus::Direct {
            temp_c: f64::NAN,
            rate_c_per_s: 1.0,
        },
        Stimulus::Direct {
            temp_c: 30.0,
            rate_c_per_s: f64::INFINITY,
        },
        Stimulus::Direct {
            temp_c: 60.0,
            rate_c_per_s: 1.0,
        },
    ] {
        assert!(
            lp.pipeline.set_stimulus(stimulus.clone()).is_err(),
            "{stimulus:?} accepted"
        );
    }
    assert!(!lp.pipeline.renderer().in_contact() && !lp.pipeline.is_direct());
    assert_eq!(lp.pipeline.renderer().receptor_c(), before);
    assert!(
        lp.run(50).iter().all(|t| t.fault.is_none()),
        "a refused stimulus caused a fault"
    );
}

#[test]
fn a_cleared_fault_restarts_the_controller_and_the_drive() {
    let mut lp = Loop::new(&base(ControllerKind::Model));
    let (ticks, _) = inject(&mut lp, 100, Fault::SensorOpen, 20);
    detected(&ticks, FaultCode::SensorOpen, "open sensor");
    lp.plant.channel_mut(0).unwrap_or_else(|e| panic!("{e}")).clear_faults();
    lp.run(3);
    let now = lp.now_s();
    assert_eq!(lp.pipeline.clear_fault(now).ok(), Some(Some(FaultCode::SensorOpen)));
    let after = lp.run(100);
    let back = after.iter().find_map(|t| t.fault.map(|f| (t.now_s, f)));
    assert!(back.is_none(), "the fault came back: {back:?}");
    assert!(after.iter().any(|t| t.current_a != 0.0), "the drive stayed off");
}
