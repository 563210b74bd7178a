//! The thermal dose of time the envelope cannot see (a link fault, a frozen or held reading), and a channel over its
//! dose budget: the unseen time counts at the envelope's bound on the plate, never at the held reading, stops adding
//! once the budget is spent, and a spent channel's drive is 0 A whatever is asked (not the display minimum at full
//! cooling current). Hand-computed CEM43 values from `thermode_safety::dose`.

use thermode_safety::dose::{cem43_increment_min, DOSE_ESTIMATE_ALLOWANCE};
use thermode_safety::{
    DoseLedger, DriveCommand, EnvelopeConfig, FaultCode, MeasuredOnly, Measurement, SafetyEnvelope, FINGER_MAX_C,
    UNSEEN_DRIVE_HOLD_S,
};

const LIMIT_A: f64 = 2.8;
/// The loop's period, s (100 Hz, as `thermode serve`).
const DT_S: f64 = 0.01;

/// One channel at 100 Hz: a tick takes a sample (or none: the reading is held), shapes a set-point and gates a
/// request.
struct Rig {
    env: SafetyEnvelope,
    tick: u64,
    seq: u64,
}

impl Rig {
    fn new() -> Self {
        Rig {
            env: SafetyEnvelope::new(EnvelopeConfig::default(), LIMIT_A).expect("envelope"),
            tick: 0,
            seq: 0,
        }
    }

    fn now_s(&self) -> f64 {
        self.tick as f64 * DT_S
    }

    /// One tick; `sensor_c` `None` is a tick whose reading is not fresh (held: same counter, not observed anew).
    fn tick(&mut self, sensor_c: Option<f64>, setpoint_c: f64, request_a: f64) -> DriveCommand {
        let now_s = self.now_s();
        if let Some(sensor_c) = sensor_c {
            self.seq += 1;
            self.env.observe(&Measurement {
                time_s: now_s,
                sensor_c,
                hot_side_c: 25.0,
                sample_seq: self.seq,
            });
        }
        let _ = self.env.shape_setpoint(now_s, setpoint_c);
        let drive = self.env.gate_drive(now_s, request_a, &MeasuredOnly);
        self.tick += 1;
        drive
    }

    fn run(&mut self, duration_s: f64, sensor_c: Option<f64>, setpoint_c: f64, request_a: f64) {
        for _ in 0..(duration_s / DT_S).round() as usize {
            let _ = self.tick(sensor_c, setpoint_c, request_a);
        }
    }
}

/// A hot touch (47 °C, heating at 1 A) during which the link fails for 14 s and then for 60 s: the unseen time
/// counts at the bound (47 °C + 1/2.8 · 50 °C/s · 0.45 s, capped at 49 °C), not at the held 47 °C, until the budget is spent; from then on
/// nothing more, however long the outage. The old count — the whole gap at the held reading — was 3.73 CEM43-min for
/// 14 s and grew with the outage.
#[test]
fn a_link_fault_during_a_hot_touch_counts_the_bound_until_the_budget_is_spent_then_nothing() {
    let mut rig = Rig::new();
    rig.run(1.0, Some(47.0), 47.0, 1.0);
    let before = rig.env.cem43_min();
    assert!(!rig.env.dose_budget_spent(), "spent before the outage: {before}");
    let bound_c = rig.env.unseen_plate_bound_c();
    assert_eq!(
        bound_c, 49.0,
        "bound with a heating drive: {bound_c} °C, want 48 + 1 °C margin"
    );
    // A short outage (0.5 s): every unseen second counts at 49 °C, more than the plate could have spent (≤ 49 °C).
    rig.run(0.5, None, 47.0, 1.0);
    let short = rig.env.cem43_min() - before;
    let hand = cem43_increment_min(49.0, 0.5);
    println!("0.5 s unseen after 1 s at 47 °C: counted {short:.5} CEM43-min, 49 °C over the outage {hand:.5}");
    assert!(
        (short - hand).abs() < 1e-9,
        "0.5 s unseen: counted {short}, want 49 °C for 0.5 s = {hand}"
    );
    // The outage goes on: the budget is spent within it and the count stops.
    rig.run(13.5, None, 47.0, 1.0);
    let at_14_s = rig.env.cem43_min();
    rig.run(46.0, None, 47.0, 1.0);
    let at_60_s = rig.env.cem43_min();
    let budget = rig.env.config().cem43_budget_min;
    let limit = budget * (1.0 + DOSE_ESTIMATE_ALLOWANCE) + cem43_increment_min(49.0, DT_S);
    let frozen_14_s = before + cem43_increment_min(47.0, 14.0);
    println!(
        "outage during a 47 °C touch: {before:.4} CEM43-min before, {at_14_s:.4} after 14 s, {at_60_s:.4} after 60 s \
         (bound {limit:.4}); the held reading would have counted {frozen_14_s:.4} after 14 s"
    );
    assert!(
        rig.env.dose_budget_spent(),
        "not spent after 14 s unseen at 49 °C: {at_14_s}"
    );
    assert!(
        at_14_s <= limit && at_14_s >= budget * (1.0 + DOSE_ESTIMATE_ALLOWANCE) - 1e-9,
        "after 14 s: {at_14_s} CEM43-min, want within [{}, {limit}]",
        budget * (1.0 + DOSE_ESTIMATE_ALLOWANCE)
    );
    assert_eq!(at_60_s, at_14_s, "the count grew after the budget was spent");
    assert!(at_14_s < frozen_14_s, "{at_14_s} vs held {frozen_14_s}");
    // Readings come back (the plate has cooled to 35 °C): the gap is not counted again at the held 47 °C.
    rig.run(1.0, Some(35.0), 35.0, 0.0);
    let back = rig.env.cem43_min() - at_60_s;
    assert!(back < 1e-3, "the return counted {back} CEM43-min");
    let fault = rig.env.fault();
    assert_eq!(fault, Some(FaultCode::SensorStale), "the outage faulted: {fault:?}");
}

/// Unseen time while the drive does not heat (a touch at rest, the drive cooling or off) counts at the warmer of a
/// finger (37 °C) and the hot side: a 30 s outage at rest adds what 37 °C adds, nowhere near the budget.
#[test]
fn unseen_time_without_a_heating_drive_counts_at_the_finger_bound() {
    let mut rig = Rig::new();
    rig.run(1.0, Some(33.0), 33.0, -0.2);
    let before = rig.env.cem43_min();
    let bound_c = rig.env.unseen_plate_bound_c();
    assert_eq!(bound_c, FINGER_MAX_C, "bound at rest: {bound_c} °C");
    rig.run(30.0, None, 33.0, -0.2);
    let added = rig.env.cem43_min() - before;
    let hand = cem43_increment_min(FINGER_MAX_C, 30.0);
    println!("30 s unseen at rest: counted {added:.3e} CEM43-min, 37 °C for 30 s {hand:.3e}");
    assert!((added - hand).abs() < 1e-12, "30 s at rest: {added}, want {hand}");
    assert!(!rig.env.dose_budget_spent());
}

/// The bound follows the strongest heating current gated since the last sample: the rise a first-order heating
/// rate proportional to the current (50 °C/s at the 2.8 A limit) gives over the stale timeout and the device's
/// watchdog (0.2 + 0.25 s), capped at 49 °C and never below 37 °C.
#[test]
fn the_unseen_bound_follows_the_heating_current() {
    let heating_s = EnvelopeConfig::default().stale_timeout_s + UNSEEN_DRIVE_HOLD_S;
    for (plate_c, current_a) in [(35.0, 0.5), (38.0, 1.0), (35.0, 2.8), (32.0, 0.1), (40.0, -2.0)] {
        let mut rig = Rig::new();
        rig.run(0.5, Some(plate_c), plate_c, current_a);
        let got_c = rig.env.unseen_plate_bound_c();
        let rise_c = current_a.max(0.0) / LIMIT_A * 50.0 * heating_s;
        let want_c = (plate_c + rise_c).clamp(FINGER_MAX_C, 49.0); // the hot side reads 25 °C
        println!("{plate_c} °C at {current_a} A: bound {got_c:.3} °C, hand {want_c:.3} °C");
        assert!(
            (got_c - want_c).abs() < 1e-9,
            "{plate_c} °C at {current_a} A: bound {got_c} °C, want {want_c} °C"
        );
    }
}

/// A channel over its budget (a restored ledger past the estimate's allowance) asked for 48 °C, and asked to cool:
/// the drive is 0 A with `dose_budget_spent`, where it was the display minimum at −2.8 A.
#[test]
fn a_channel_over_its_budget_is_driven_at_0_a_whatever_is_asked() {
    let mut rig = Rig::new();
    let saved = DoseLedger {
        cem43_min: 1.03,
        time_at_or_above_43_s: 20.0,
        lockout: true,
    };
    rig.env.restore_dose(&saved).expect("restore");
    assert!(rig.env.dose_budget_spent());
    assert_eq!(rig.env.effective_max_c(), rig.env.min_c());
    for (setpoint_c, request_a) in [(48.0, LIMIT_A), (15.0, -LIMIT_A), (33.0, -1.0)] {
        let d = rig.tick(Some(33.0), setpoint_c, request_a);
        println!(
            "over budget, {setpoint_c} °C asked, {request_a} A requested: drive {} A, {:?}",
            d.current_a(),
            d.limited_by()
        );
        assert_eq!(
            d.current_a(),
            0.0,
            "{setpoint_c} °C asked: drive {} A, want 0 A",
            d.current_a()
        );
        assert!(
            d.limited_by().dose_budget_spent && d.fault().is_none(),
            "{:?}",
            d.limited_by()
        );
    }
}
