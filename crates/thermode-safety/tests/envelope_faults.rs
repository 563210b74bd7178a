//! Every fault of the safety envelope injected at the unit level. Each test asserts the detection time, the safe
//! state (0 A, fault latched), that the drive stays at 0 A after the cause disappears until the fault is cleared,
//! that clearing is refused while the cause persists, and that the drive returns after a successful clear.
//! Also: gating (limit, heating/cooling refused at the limits), set-point shaping, and the thermal dose measured
//! through the envelope against hand-computed CEM43 values.

use thermode_safety::dose::DOSE_COOLDOWN_RATE_C_PER_S;
use thermode_safety::{
    DoseLedger, DriveCommand, EnvelopeConfig, EnvelopeError, FaultCode, MeasuredOnly, Measurement, PlateForecast,
    PlateNow, SafetyEnvelope,
};

const LIMIT_A: f64 = 2.8;
const DT_S: f64 = 1e-3;
const REQUEST_A: f64 = 0.5;

/// One channel driven at 1 kHz: every tick takes a sample (unless skipped), shapes a set-point and gates a request.
struct Rig {
    env: SafetyEnvelope,
    tick: u64,
    seq: u64,
}

impl Rig {
    fn new(config: EnvelopeConfig) -> Self {
        Self {
            env: SafetyEnvelope::new(config, LIMIT_A).unwrap(),
            tick: 0,
            seq: 0,
        }
    }

    fn default() -> Self {
        Self::new(EnvelopeConfig::default())
    }

    /// The default envelope with the largest CEM43 budget (10 CEM43-min), for tests of other faults whose readings
    /// near 48 °C spend about one CEM43-minute — enough to lock the default budget out (the dose is tested below).
    fn generous() -> Self {
        Self::new(EnvelopeConfig {
            cem43_budget_min: 10.0,
            ..Default::default()
        })
    }

    fn now_s(&self) -> f64 {
        self.tick as f64 * DT_S
    }

    fn sample(&mut self, sensor_c: f64, hot_side_c: f64) {
        self.seq += 1;
        let m = Measurement {
            time_s: self.now_s(),
            sensor_c,
            hot_side_c,
            sample_seq: self.seq,
        };
        self.env.observe(&m);
    }

    /// One tick without a sample.
    fn blind(&mut self, request_a: f64) -> DriveCommand {
        let now_s = self.now_s();
        let _ = self.env.shape_setpoint(now_s, 33.0);
        let drive = self.env.gate_drive(now_s, request_a, &MeasuredOnly);
        self.tick += 1;
        drive
    }

    /// One tick with a sample.
    fn step(&mut self, sensor_c: f64, hot_side_c: f64, request_a: f64) -> DriveCommand {
        self.sample(sensor_c, hot_side_c);
        self.blind(request_a)
    }

    /// Healthy ticks for `duration_s` at 33 °C, asserting the request passes unchanged.
    fn healthy(&mut self, duration_s: f64) {
        for _ in 0..(duration_s / DT_S).round() as usize {
            let d = self.step(33.0, 25.0, REQUEST_A);
            assert_eq!(
                (d.current_a(), d.fault()),
                (REQUEST_A, None),
                "healthy tick at {}",
                self.now_s()
            );
        }
    }

    /// Runs `f` tick by tick until a fault latches (at most `max_s`); returns the detection time and the command.
    /// Before detection every command must carry `expect_a` (if given).
    fn until_fault(
        &mut self,
        max_s: f64,
        expect_a: Option<f64>,
        mut f: impl FnMut(&mut Rig) -> DriveCommand,
    ) -> (f64, DriveCommand) {
        for _ in 0..(max_s / DT_S).round() as usize {
            let t = self.now_s();
            let d = f(self);
            if d.fault().is_some() {
                return (t, d);
            }
            if let Some(want) = expect_a {
                assert_eq!(d.current_a(), want, "drive before detection at {t}");
            }
        }
        panic!("no fault within {max_s} s");
    }

    /// The cause is gone: 0 A and latched for 0.1 s of healthy samples, then the clear succeeds and drive returns.
    fn stays_off_until_cleared(&mut self, code: FaultCode) {
        for _ in 0..100 {
            let d = self.step(33.0, 25.0, REQUEST_A);
            assert_eq!(
                (d.current_a(), d.fault()),
                (0.0, Some(code)),
                "latched at {}",
                self.now_s()
            );
        }
        assert_eq!(self.env.clear_fault(self.now_s()), Ok(Some(code)));
        let d = self.step(33.0, 25.0, REQUEST_A);
        assert_eq!(
            (d.current_a(), d.fault()),
            (REQUEST_A, None),
            "drive returns after clear"
        );
    }
}

fn assert_off(d: &DriveCommand, code: FaultCode) {
    assert_eq!(d.current_a(), 0.0, "drive must be off on {code}");
    assert_eq!(d.fault(), Some(code));
    assert!(d.limited_by().faulted);
}

/// Instantaneous sensor faults: detected on the very sample that shows them.
#[test]
fn sensor_open_short_and_out_of_range_are_detected_on_the_sample() {
    let cases = [
        (200.0, FaultCode::SensorOpen),
        (150.0, FaultCode::SensorOpen),
        (-242.0, FaultCode::SensorShort),
        (80.0, FaultCode::SensorOutOfRange),
        (-10.0, FaultCode::SensorOutOfRange),
    ];
    for (reading_c, code) in cases {
        let mut rig = Rig::default();
        rig.healthy(0.5);
        let t_inject = rig.now_s();
        let (t, d) = rig.until_fault(1.0, Some(REQUEST_A), |r| r.step(reading_c, 25.0, REQUEST_A));
        assert_eq!(t, t_inject, "{code} detected at {t} s, injected at {t_inject} s");
        assert_off(&d, code);
        assert_eq!(
            rig.env.clear_fault(rig.now_s()),
            Err(EnvelopeError::NoFreshMeasurement(code))
        );
        let _ = rig.step(reading_c, 25.0, REQUEST_A);
        assert_eq!(
            rig.env.clear_fault(rig.now_s()),
            Err(EnvelopeError::FaultPersists(code)),
            "{reading_c} °C"
        );
        rig.stays_off_until_cleared(code);
    }
}

#[test]
fn stale_sensor_is_detected_after_the_timeout() {
    let mut rig = Rig::default();
    rig.healthy(0.5);
    let last_sample_s = rig.now_s() - DT_S;
    let (t, d) = rig.until_fault(1.0, Some(REQUEST_A), |r| r.blind(REQUEST_A));
    let timeout_s = EnvelopeConfig::default().stale_timeout_s;
    let late_s = t - last_sample_s - timeout_s;
    assert!(
        late_s > 0.0 && late_s <= DT_S + 1e-12,
        "stale detected {late_s} s after the timeout"
    );
    assert_off(&d, FaultCode::SensorStale);
    rig.stays_off_until_cleared(FaultCode::SensorStale);
}

#[test]
fn a_sensor_that_never_delivers_is_stale_and_drive_is_off_meanwhile() {
    let mut rig = Rig::default();
    let d = rig.blind(REQUEST_A);
    assert_eq!(d.current_a(), 0.0);
    assert!(d.limited_by().no_measurement && d.fault().is_none());
    let (t, d) = rig.until_fault(1.0, Some(0.0), |r| r.blind(REQUEST_A));
    assert!(
        t > 0.2 && t <= 0.2 + DT_S + 1e-12,
        "stale without any sample detected at {t} s"
    );
    assert_off(&d, FaultCode::SensorStale);
    assert_eq!(
        rig.env.clear_fault(rig.now_s()),
        Err(EnvelopeError::NoFreshMeasurement(FaultCode::SensorStale))
    );
    rig.stays_off_until_cleared(FaultCode::SensorStale);
}

#[test]
fn implausible_rate_of_change_is_detected_within_one_window() {
    let window_s = EnvelopeConfig::default().rate_window_s;
    // A sustained 60 °C/s ramp (threshold 50 °C/s) from 20 °C.
    let mut rig = Rig::default();
    for _ in 0..500 {
        let _ = rig.step(20.0, 25.0, REQUEST_A);
    }
    let t0 = rig.now_s();
    let (t, d) = rig.until_fault(1.0, Some(REQUEST_A), |r| {
        let sensor_c = 20.0 + 60.0 * (r.now_s() - t0);
        r.step(sensor_c, 25.0, REQUEST_A)
    });
    assert!(
        t - t0 <= window_s + 2.0 * DT_S,
        "60 °C/s ramp detected after {} s",
        t - t0
    );
    assert_off(&d, FaultCode::SensorRateImplausible);
    rig.stays_off_until_cleared(FaultCode::SensorRateImplausible);
    // A jump of 3 °C between two samples (> 50 °C/s × 0.05 s) is detected on that sample.
    let mut rig = Rig::default();
    rig.healthy(0.5);
    let t_jump = rig.now_s();
    let (t, d) = rig.until_fault(1.0, Some(REQUEST_A), |r| r.step(36.0, 25.0, REQUEST_A));
    assert_eq!(t, t_jump);
    assert_off(&d, FaultCode::SensorRateImplausible);
}

#[test]
fn fast_but_plausible_changes_and_sensor_noise_are_not_faults() {
    let mut rig = Rig::default();
    // 40 °C/s for 0.3 s (below the 50 °C/s threshold).
    for k in 0..300 {
        let d = rig.step(20.0 + 40.0 * k as f64 * DT_S, 25.0, REQUEST_A);
        assert_eq!(d.fault(), None, "40 °C/s ramp at step {k}");
    }
    // ±0.01 °C quantisation noise at 1 kHz for 5 s around the ramp's end (32 °C).
    for k in 0..5000u64 {
        let noise_c = 0.01 * ((k * 7 % 3) as f64 - 1.0);
        let d = rig.step(32.0 + noise_c, 25.0, REQUEST_A);
        assert_eq!(d.fault(), None, "noise at step {k}");
    }
}

#[test]
fn hot_side_over_temperature_and_implausible_hot_side_sensor() {
    for (hot_c, code) in [
        (45.5, FaultCode::HotSideOverTemperature),
        (-242.0, FaultCode::HotSideSensorImplausible),
    ] {
        let mut rig = Rig::default();
        rig.healthy(0.5);
        let t_inject = rig.now_s();
        let (t, d) = rig.until_fault(1.0, Some(REQUEST_A), |r| r.step(33.0, hot_c, REQUEST_A));
        assert_eq!(t, t_inject, "{code}");
        assert_off(&d, code);
        let _ = rig.step(33.0, hot_c, REQUEST_A);
        assert_eq!(
            rig.env.clear_fault(rig.now_s()),
            Err(EnvelopeError::FaultPersists(code))
        );
        rig.stays_off_until_cleared(code);
    }
}

/// Ramps the reading at 10 °C/s from 33 °C towards `end_c`; the fault comes on the first sample beyond
/// the limit ± margin.
#[test]
fn display_beyond_its_limits_by_the_margin() {
    // The request points back into range (cooling when hot, heating when cold), so the gate passes it.
    for (end_c, bound_c, code, request_a) in [
        (50.0f64, 49.0, FaultCode::DisplayOverTemperature, -REQUEST_A),
        (10.0, 14.0, FaultCode::DisplayUnderTemperature, REQUEST_A),
    ] {
        let mut rig = Rig::generous();
        rig.healthy(0.2);
        let t0 = rig.now_s();
        let reading = |t: f64| {
            let r: f64 = 33.0 + (end_c - 33.0).signum() * 10.0 * (t - t0);
            if end_c > 33.0 {
                r.min(end_c)
            } else {
                r.max(end_c)
            }
        };
        let (t, d) = rig.until_fault(5.0, Some(request_a), |r| {
            let now = r.now_s();
            r.step(reading(now), 25.0, request_a)
        });
        let beyond = |c: f64| if end_c > 33.0 { c > bound_c } else { c < bound_c };
        assert!(
            beyond(reading(t)) && !beyond(reading(t - DT_S)),
            "{code} at {} °C",
            reading(t)
        );
        assert_off(&d, code);
        rig.stays_off_until_cleared(code);
    }
}

#[test]
fn display_sustained_at_48_is_a_fault_after_one_second() {
    let mut rig = Rig::generous();
    rig.healthy(0.2);
    for k in 0..1500 {
        // approach 48 °C at 10 °C/s
        let c = (33.0 + 10.0 * k as f64 * DT_S).min(47.99);
        let _ = rig.step(c, 25.0, -REQUEST_A);
    }
    let t48 = rig.now_s();
    let (t, d) = rig.until_fault(3.0, Some(-REQUEST_A), |r| r.step(48.0, 25.0, -REQUEST_A));
    let late_s = t - t48 - 1.0;
    assert!(
        late_s > 0.0 && late_s <= DT_S + 1e-9,
        "48 °C sustained detected {late_s} s after 1 s"
    );
    assert_off(&d, FaultCode::SustainedAtAbsoluteMax);
    let _ = rig.step(48.0, 25.0, REQUEST_A);
    let refused = rig.env.clear_fault(rig.now_s());
    assert_eq!(
        refused,
        Err(EnvelopeError::FaultPersists(FaultCode::SustainedAtAbsoluteMax))
    );
    rig.stays_off_until_cleared(FaultCode::SustainedAtAbsoluteMax);
}

#[test]
fn dose_time_limit_lowers_the_maximum_and_a_hot_display_after_the_grace_is_a_fault() {
    let config = EnvelopeConfig {
        max_time_at_or_above_43_s: 2.0,
        cem43_budget_min: 10.0,
        ..Default::default()
    };
    let mut rig = Rig::new(config);
    let _ = rig.step(44.0, 25.0, REQUEST_A);
    let t0 = rig.now_s() - DT_S;
    // Long before the lockout: heating allowed at 44 °C, maximum 48 °C.
    assert_eq!(rig.env.effective_max_c(), 48.0);
    let (mut t_lock, mut t_block) = (None, None);
    let (t, d) = rig.until_fault(10.0, None, |r| {
        let d = r.step(44.0, 25.0, REQUEST_A);
        let now = r.now_s() - DT_S;
        if r.env.dose_lockout_active() && t_lock.is_none() {
            t_lock = Some(now);
        }
        if d.fault().is_none() {
            // The anticipating ceiling 42.5 + 5 °C/s · (2 s − time at ≥ 43 °C), looked two 1 ms ticks ahead
            // (− 0.01 °C), falls to 44 °C after 1.698 s: from then on heating at 44 °C is refused; before, it passes.
            let blocked = r.env.effective_max_c() <= 44.0;
            if blocked && t_block.is_none() {
                t_block = Some(now);
            }
            assert_eq!(d.current_a(), if blocked { 0.0 } else { REQUEST_A });
            assert_eq!(d.limited_by().heating_blocked_at_max, blocked);
        }
        d
    });
    let (t_lock, t_block) = (t_lock.expect("lockout engaged"), t_block.expect("heating blocked"));
    assert!(
        (t_block - t0 - (1.7 - 2.0 * DT_S)).abs() <= DT_S + 1e-9,
        "heating refused {} s after reaching 44 °C, hand 1.698 s",
        t_block - t0
    );
    assert!(
        (t_lock - t0 - 2.0).abs() <= DT_S + 1e-9,
        "lockout {} s after reaching 44 °C",
        t_lock - t0
    );
    // Locked with little CEM43 spent (7 s at 44 °C = 0.23 of 10 CEM43-min): the maximum is 43 − 0.5 °C (after the
    // lockout the ceiling does not look ahead).
    let locked_max_c = 42.5;
    assert!(
        (rig.env.effective_max_c() - locked_max_c).abs() < 1e-9,
        "{} vs {locked_max_c}",
        rig.env.effective_max_c()
    );
    let late_s = t - t_lock - config.dose_lockout_grace_s;
    assert!(
        late_s > 0.0 && late_s <= DT_S + 1e-9,
        "lockout violation detected {late_s} s after the grace"
    );
    assert_off(&d, FaultCode::DoseLockoutViolated);
    let _ = rig.step(43.0, 25.0, 0.0);
    let refused = rig.env.clear_fault(rig.now_s());
    assert_eq!(
        refused,
        Err(EnvelopeError::FaultPersists(FaultCode::DoseLockoutViolated))
    );
    rig.stays_off_until_cleared(FaultCode::DoseLockoutViolated);
    assert!(
        rig.env.dose_lockout_active(),
        "clearing a fault does not reset the dose"
    );
    let mut last = None;
    for _ in 0..2000 {
        rig.sample(33.0, 25.0);
        last = Some(rig.env.shape_setpoint(rig.now_s(), 46.0));
        rig.tick += 1;
    }
    let sp = last.unwrap();
    assert!(
        (sp.setpoint_c - locked_max_c).abs() < 1e-9,
        "set-point {} capped below 43 °C under the lockout ({locked_max_c})",
        sp.setpoint_c
    );
    assert!(sp.limited_by.dose_lockout && sp.limited_by.clamped_high);
}

#[test]
fn cem43_budget_lowers_the_maximum_at_the_analytic_times() {
    // 45 °C accrues 0.5^(−2) = 4 CEM43-min per minute: the 1 CEM43-min budget is used after 15 s. The anticipating
    // ceiling is the temperature T_a from which a fall at c = 5 °C/s to the landing temperature T_b = 43 +
    // ln(0.0025)/ln 4 = 38.678 °C spends what is left, looked two 1 ms ticks ahead: T_a − 2c·Δt = T_a − 0.01 °C. It
    // falls below 45 °C when what is left equals the dose of the fall from 45.01 °C:
    // ((1 − 0.0025)/ln 4 + (2^2.01 − 1)/ln 2)/300 = 0.016 93 CEM43-min, i.e. at 15 s · (1 − 0.016 93) = 14.746 s.
    let landing_c = 43.0 + 0.0025f64.ln() / 4f64.ln();
    let margin_c = 2.0 * DOSE_COOLDOWN_RATE_C_PER_S * DT_S;
    let from_c: f64 = 45.0 + margin_c;
    let left_min = ((1.0 - 0.0025) / 4f64.ln() + (2f64.powf(from_c - 43.0) - 1.0) / 2f64.ln()) / 300.0;
    let t_below_45_hand = 15.0 * (1.0 - left_min);
    let mut rig = Rig::default();
    let (mut t_lock, mut t_below_45) = (None, None);
    while t_lock.is_none() {
        let d = rig.step(45.0, 25.0, -REQUEST_A);
        assert_eq!(d.fault(), None);
        let now = rig.now_s() - DT_S;
        if rig.env.effective_max_c() < 45.0 && t_below_45.is_none() {
            t_below_45 = Some(now);
        }
        if rig.env.dose_lockout_active() {
            t_lock = Some(now);
        }
        assert!(now < 16.0, "no lockout after {now} s");
    }
    let (t_lock, t_below_45) = (t_lock.unwrap(), t_below_45.expect("ceiling fell below 45 °C"));
    assert!(
        (t_below_45 - t_below_45_hand).abs() <= DT_S + 1e-9,
        "ceiling below 45 °C at {t_below_45} s, hand {t_below_45_hand} s"
    );
    assert!(
        (t_lock - 15.0).abs() <= DT_S + 1e-9,
        "CEM43 budget used at {t_lock} s, analytic 15 s"
    );
    // At the lockout the ceiling is the landing temperature (after the lockout it does not look ahead; one tick of
    // dose past the budget moves it by 2 mK).
    let max_c = rig.env.effective_max_c();
    let hand_c = landing_c;
    assert!(
        (max_c - hand_c).abs() < 0.003,
        "ceiling {max_c} at the lockout, hand {hand_c}"
    );
    // Cool to 38 °C at 10 °C/s; the ceiling is then 43 + ln((1.025 − D)/10)/ln 4 for the dose D spent: heating
    // 0.1 °C below it is allowed, at it refused.
    for k in 1..=700 {
        let _ = rig.step((45.0 - 10.0 * k as f64 * DT_S).max(38.0), 25.0, -REQUEST_A);
    }
    let d_min = rig.env.cem43_min();
    let want_c = 43.0 + ((1.025 - d_min) / 10.0).ln() / 4f64.ln();
    let max_c = rig.env.effective_max_c();
    assert!(
        (max_c - want_c).abs() < 1e-6,
        "ceiling {max_c} °C after {d_min} CEM43-min, hand {want_c} °C"
    );
    assert!(want_c > 38.0 && want_c < landing_c, "ceiling {want_c}");
    let d = rig.step(want_c - 0.1, 25.0, 1.0);
    assert_eq!(d.current_a(), 1.0, "heating below the lowered maximum is allowed");
    let d = rig.step(want_c, 25.0, 1.0);
    assert_eq!(d.current_a(), 0.0);
    assert!(d.limited_by().heating_blocked_at_max);
    // The estimate's allowance spent: the ceiling is the display minimum, never below.
    for _ in 0..20_000 {
        let _ = rig.step(43.0, 25.0, -REQUEST_A);
    }
    assert!(rig.env.cem43_min() > 1.025, "{}", rig.env.cem43_min());
    assert_eq!(rig.env.effective_max_c(), rig.env.min_c());
}

/// The dose survives a restart: a fresh envelope restored from the ledger of a locked one is locked, has the same
/// totals and the same ceiling, and a restore never lowers a dose; bad ledgers are refused and change nothing.
#[test]
fn a_restored_dose_keeps_the_lockout_and_the_ceiling() {
    let mut rig = Rig::default();
    for _ in 0..15_500 {
        let _ = rig.step(45.0, 25.0, -REQUEST_A);
    }
    assert!(rig.env.dose_lockout_active());
    let saved = rig.env.dose_ledger();
    assert!(saved.lockout && saved.cem43_min >= 1.0, "{saved:?}");
    let mut fresh = SafetyEnvelope::new(EnvelopeConfig::default(), LIMIT_A).unwrap();
    assert_eq!(fresh.effective_max_c(), 48.0);
    fresh.restore_dose(&saved).unwrap();
    assert_eq!(fresh.dose_ledger(), saved);
    assert!(fresh.dose_lockout_active());
    assert_eq!(fresh.effective_max_c(), rig.env.effective_max_c());
    assert!(fresh.effective_max_c() < 42.5);
    // A larger budget in the new configuration does not unlock a restored lockout.
    let mut roomy = SafetyEnvelope::new(
        EnvelopeConfig {
            cem43_budget_min: 10.0,
            ..Default::default()
        },
        LIMIT_A,
    )
    .unwrap();
    roomy.restore_dose(&saved).unwrap();
    assert!(roomy.dose_lockout_active() && roomy.effective_max_c() <= 42.5);
    // Never lower; bad numbers refused.
    fresh.restore_dose(&DoseLedger::default()).unwrap();
    assert_eq!(fresh.dose_ledger(), saved);
    let bad = DoseLedger {
        cem43_min: f64::NAN,
        ..saved
    };
    assert!(matches!(fresh.restore_dose(&bad), Err(EnvelopeError::BadValue(_))));
    assert_eq!(fresh.dose_ledger(), saved);
}

#[test]
fn drive_stuck_at_its_limit_is_a_fault_after_the_configured_time() {
    let mut rig = Rig::default();
    rig.healthy(0.1);
    let t0 = rig.now_s();
    let mut saw_limit = false;
    let (t, d) = rig.until_fault(20.0, Some(LIMIT_A), |r| {
        let d = r.step(33.0, 25.0, 5.0);
        if d.fault().is_none() {
            assert!(d.limited_by().clamped_to_limit, "request clamped to the limit");
            saw_limit = true;
        }
        d
    });
    assert!(saw_limit);
    let late_s = t - t0 - 10.0;
    assert!(
        late_s > 0.0 && late_s <= DT_S + 1e-9,
        "stuck drive detected {late_s} s after 10 s"
    );
    assert_off(&d, FaultCode::DriveStuckAtLimit);
    rig.stays_off_until_cleared(FaultCode::DriveStuckAtLimit);
    // Just below 98 % of the limit for 20 s is not "stuck".
    let mut rig = Rig::default();
    for _ in 0..20_000 {
        let d = rig.step(33.0, 25.0, 0.97 * LIMIT_A);
        assert_eq!(d.fault(), None);
    }
}

#[test]
fn a_drive_at_its_limit_that_moves_the_plate_or_changes_sign_is_not_stuck() {
    // Heating at the limit for 30 s while the plate warms 0.6 °C every 5 s: the plate answers, no fault.
    let mut rig = Rig::default();
    rig.healthy(0.1);
    for k in 0..30_000 {
        let sensor_c = 33.0 + 0.6 * (k / 5_000) as f64;
        let d = rig.step(sensor_c, 25.0, 5.0);
        assert_eq!(d.fault(), None, "tick {k}: plate at {sensor_c} °C answers the drive");
    }
    // Alternating heating and cooling at the limit every 6 s, the plate never moving: each change of sign restarts
    // the count, so 10 s is never reached.
    let mut rig = Rig::default();
    rig.healthy(0.1);
    for k in 0..30_000 {
        let request_a = if (k / 6_000) % 2 == 0 { 5.0 } else { -5.0 };
        let d = rig.step(33.0, 25.0, request_a);
        assert_eq!(d.fault(), None, "tick {k}: {request_a} A");
    }
    // The plate moving against the drive is not an answer: stuck after 10 s.
    let mut rig = Rig::default();
    rig.healthy(0.1);
    let t0 = rig.now_s();
    let (t, d) = rig.until_fault(20.0, Some(LIMIT_A), |r| {
        let sensor_c = 33.0 - 0.1 * (r.now_s() - t0);
        r.step(sensor_c, 25.0, 5.0)
    });
    assert_off(&d, FaultCode::DriveStuckAtLimit);
    assert!((t - t0 - 10.0).abs() <= 2.0 * DT_S, "stuck after {} s, want 10", t - t0);
}

#[test]
fn a_hold_switches_the_drive_off_without_counting_towards_a_stuck_drive() {
    let mut rig = Rig::default();
    rig.healthy(0.1);
    // 8 s at the limit, a 60 s hold, 8 s at the limit again: never 10 s in a row.
    for _ in 0..8_000 {
        assert_eq!(rig.step(33.0, 25.0, 5.0).fault(), None);
    }
    for _ in 0..60_000 {
        rig.sample(33.0, 25.0);
        let now_s = rig.now_s();
        let d = rig.env.hold(now_s);
        rig.tick += 1;
        assert_eq!((d.current_a(), d.fault()), (0.0, None), "held at {now_s} s");
    }
    for _ in 0..8_000 {
        assert_eq!(rig.step(33.0, 25.0, 5.0).fault(), None);
    }
    // A hold still sees a dead sensor.
    let stale_after_s = EnvelopeConfig::default().stale_timeout_s;
    let mut latched = None;
    for _ in 0..((stale_after_s / DT_S) as usize + 2) {
        let now_s = rig.now_s();
        latched = latched.or(rig.env.hold(now_s).fault());
        rig.tick += 1;
    }
    assert_eq!(latched, Some(FaultCode::SensorStale));
}

/// A plate that follows the current at `slope` °C per A over one tick from `plate_c`, with no uncertainty.
struct LinearPlate {
    plate_c: f64,
    slope_c_per_a: f64,
}

impl PlateForecast for LinearPlate {
    fn now(&self) -> Option<PlateNow> {
        Some(PlateNow {
            plate_c: self.plate_c,
            sd_c: 0.0,
        })
    }
    fn plate_after_c(&self, current_a: f64) -> f64 {
        self.plate_c + self.slope_c_per_a * current_a
    }
    fn strongest_cooling_a(&self) -> f64 {
        -LIMIT_A
    }
}

#[test]
fn the_predicted_plate_limits_heating_and_cooling_even_when_the_reading_lags() {
    let config = EnvelopeConfig::default();
    let margin_c = thermode_safety::plate::MIN_PLATE_MARGIN_C;
    let mut rig = Rig::default();
    rig.healthy(0.1);
    let gate = |rig: &mut Rig, sensor_c: f64, plate: &LinearPlate, request_a: f64| {
        rig.sample(sensor_c, 25.0);
        let now_s = rig.now_s();
        let d = rig.env.gate_drive(now_s, request_a, plate);
        rig.tick += 1;
        d
    };
    // The reading says 33 °C, the model 47.6 °C; 2 A would take the plate to 47.6 + 0.4 = 48 > 48 − margin.
    let hot = LinearPlate {
        plate_c: 47.6,
        slope_c_per_a: 0.2,
    };
    let d = gate(&mut rig, 33.0, &hot, 2.0);
    let want_a = (config.max_display_c - margin_c - hot.plate_c) / hot.slope_c_per_a;
    assert!(d.limited_by().heating_limited_by_plate);
    assert!(
        (d.current_a() - want_a).abs() < 1e-6,
        "heating limited to {} A, want {want_a} A",
        d.current_a()
    );
    // A plate that would pass the maximum even at 0 A is cooled.
    let hotter = LinearPlate {
        plate_c: 48.2,
        slope_c_per_a: 0.2,
    };
    let d = gate(&mut rig, 33.0, &hotter, 0.0);
    assert!(d.current_a() < 0.0, "{} A: the plate must be cooled", d.current_a());
    // Cooling towards the minimum is limited the same way; a request inside the band passes unchanged.
    let cold = LinearPlate {
        plate_c: 15.5,
        slope_c_per_a: 0.2,
    };
    let d = gate(&mut rig, 33.0, &cold, -2.8);
    let want_a = (config.min_display_c + margin_c - cold.plate_c) / cold.slope_c_per_a;
    assert!(d.limited_by().cooling_limited_by_plate);
    assert!(
        (d.current_a() - want_a).abs() < 1e-6,
        "cooling limited to {} A, want {want_a} A",
        d.current_a()
    );
    let d = gate(&mut rig, 33.0, &cold, 0.5);
    assert_eq!(d.current_a(), 0.5);
    assert_eq!(d.fault(), None);
}

/// A [`LinearPlate`] whose forecast is widened by `upper_c` for heating currents (a sensor bound on a rising plate).
struct WidenedPlate {
    plate: LinearPlate,
    upper_c: f64,
}

impl PlateForecast for WidenedPlate {
    fn now(&self) -> Option<PlateNow> {
        self.plate.now()
    }
    fn plate_after_c(&self, current_a: f64) -> f64 {
        self.plate.plate_after_c(current_a)
    }
    fn plate_after_range_c(&self, current_a: f64) -> (f64, f64) {
        let plate_c = self.plate_after_c(current_a);
        (plate_c, plate_c + if current_a > 0.0 { self.upper_c } else { 0.0 })
    }
    fn strongest_cooling_a(&self) -> f64 {
        self.plate.strongest_cooling_a()
    }
}

/// The forecast's range: its upper end limits heating, where the plate itself would pass; a range widened for
/// heating only stops heating (at most 0 A, not a cooling drive), and leaves cooling as it was.
#[test]
fn the_forecast_range_limits_heating_by_its_upper_end_without_driving_the_other_way() {
    let config = EnvelopeConfig::default();
    let margin_c = thermode_safety::plate::MIN_PLATE_MARGIN_C;
    let mut rig = Rig::default();
    rig.healthy(0.1);
    let mut gate = |plate: &WidenedPlate, request_a: f64| {
        rig.sample(33.0, 25.0);
        let now_s = rig.now_s();
        let d = rig.env.gate_drive(now_s, request_a, plate);
        rig.tick += 1;
        d
    };
    let widened_by = |upper_c: f64| WidenedPlate {
        plate: LinearPlate {
            plate_c: 46.0,
            slope_c_per_a: 0.2,
        },
        upper_c,
    };
    // The model says 46 °C; the bound says the plate may be 3 °C further: heating would pass 48 − margin.
    let widened = widened_by(3.0);
    let d = gate(&widened, 2.8);
    assert!(d.limited_by().heating_limited_by_plate, "{d:?}");
    assert!(
        (-1e-6..=1e-6).contains(&d.current_a()),
        "heating stopped at {} A, want 0 A (no cooling drive on the bound alone)",
        d.current_a()
    );
    // A smaller widening leaves the heating the range allows: 46 + 0.2 I + 1.5 ≤ 48 − margin.
    let slight = widened_by(1.5);
    let d = gate(&slight, 2.8);
    let want_a = (config.max_display_c - margin_c - 1.5 - slight.plate.plate_c) / slight.plate.slope_c_per_a;
    assert!(
        (d.current_a() - want_a).abs() < 1e-6,
        "heating limited to {} A, want {want_a} A",
        d.current_a()
    );
    // Cooling is not touched by a bound on heating.
    let d = gate(&widened, -2.0);
    assert_eq!(d.current_a(), -2.0);
    assert_eq!(d.fault(), None);
}

#[test]
fn non_finite_set_point_request_measurement_and_time_latch() {
    type Inject = fn(&mut Rig) -> DriveCommand;
    let cases: [(Inject, FaultCode); 9] = [
        (|r| inject_setpoint(r, f64::NAN), FaultCode::NonFiniteSetpoint),
        (|r| inject_setpoint(r, f64::INFINITY), FaultCode::NonFiniteSetpoint),
        (|r| inject_setpoint(r, f64::NEG_INFINITY), FaultCode::NonFiniteSetpoint),
        (|r| r.step(f64::NAN, 25.0, REQUEST_A), FaultCode::NonFiniteMeasurement),
        (
            |r| r.step(33.0, f64::INFINITY, REQUEST_A),
            FaultCode::NonFiniteMeasurement,
        ),
        (|r| r.step(33.0, 25.0, f64::NAN), FaultCode::NonFiniteCommand),
        (|r| r.step(33.0, 25.0, f64::NEG_INFINITY), FaultCode::NonFiniteCommand),
        (
            |r| {
                r.sample(33.0, 25.0);
                r.env.gate_drive(f64::NAN, REQUEST_A, &MeasuredOnly)
            },
            FaultCode::NonFiniteTime,
        ),
        (
            |r| {
                r.sample(33.0, 25.0);
                r.env.gate_drive(r.now_s() - 0.5, REQUEST_A, &MeasuredOnly)
            },
            FaultCode::TimeNotMonotonic,
        ),
    ];
    for (inject, code) in cases {
        let mut rig = Rig::default();
        rig.healthy(0.2);
        let d = inject(&mut rig);
        assert_off(&d, code);
        rig.tick += 1;
        rig.stays_off_until_cleared(code);
    }
}

fn inject_setpoint(r: &mut Rig, requested_c: f64) -> DriveCommand {
    r.sample(33.0, 25.0);
    let before = r.env.shape_setpoint(r.now_s(), 33.0).setpoint_c;
    let sp = r.env.shape_setpoint(r.now_s(), requested_c);
    assert!(sp.limited_by.rejected);
    assert_eq!(sp.setpoint_c, before, "a rejected set-point holds the previous one");
    r.env.gate_drive(r.now_s(), REQUEST_A, &MeasuredOnly)
}

#[test]
fn gating_limits_the_current_and_refuses_heating_at_max_and_cooling_at_min() {
    let mut rig = Rig::default();
    let d = rig.step(33.0, 25.0, 9.0);
    assert_eq!(d.current_a(), LIMIT_A);
    let d = rig.step(33.0, 25.0, -9.0);
    assert_eq!(d.current_a(), -LIMIT_A);
    let mut rig = Rig::default();
    let _ = rig.step(47.0, 25.0, 0.0);
    let d = rig.step(47.9, 25.0, 1.0);
    assert_eq!(d.current_a(), 1.0, "heating below the maximum");
    let d = rig.step(48.0, 25.0, 1.0);
    assert_eq!(d.current_a(), 0.0, "no heating at the maximum");
    assert!(d.limited_by().heating_blocked_at_max);
    let d = rig.step(48.0, 25.0, -1.0);
    assert_eq!(d.current_a(), -1.0, "cooling at the maximum is allowed");
    let mut rig = Rig::default();
    let _ = rig.step(16.0, 25.0, 0.0);
    let d = rig.step(15.0, 25.0, -1.0);
    assert_eq!(d.current_a(), 0.0, "no cooling at the minimum");
    assert!(d.limited_by().cooling_blocked_at_min);
    assert_eq!(rig.step(15.0, 25.0, 1.0).current_a(), 1.0);
}

#[test]
fn set_point_starts_at_the_display_is_clamped_and_rate_limited() {
    let mut env = SafetyEnvelope::new(EnvelopeConfig::default(), LIMIT_A).unwrap();
    env.observe(&Measurement {
        time_s: 0.0,
        sensor_c: 30.0,
        hot_side_c: 25.0,
        sample_seq: 1,
    });
    let sp = env.shape_setpoint(0.0, 45.0);
    assert_eq!(sp.setpoint_c, 30.0, "first set-point starts at the measured display");
    assert!(sp.limited_by.rate_limited);
    let sp = env.shape_setpoint(0.5, 45.0);
    assert!(
        (sp.setpoint_c - 35.0).abs() < 1e-12,
        "10 °C/s for 0.5 s: {}",
        sp.setpoint_c
    );
    assert!((sp.rate_c_per_s - 10.0).abs() < 1e-9);
    let sp = env.shape_setpoint(10.0, 1e308);
    assert_eq!(sp.setpoint_c, 48.0);
    assert!(sp.limited_by.clamped_high);
    let sp = env.shape_setpoint(20.0, -1e308);
    assert_eq!(sp.setpoint_c, 15.0);
    assert!(sp.limited_by.clamped_low);
    assert_eq!(env.fault(), None, "huge finite requests are clamped, not faults");
}

#[test]
fn cem43_through_the_envelope_matches_hand_computed_values() {
    for (temp_c, want_min, want_43_s) in [(44.0, 2.0, 60.0), (42.0, 0.25, 0.0)] {
        let config = EnvelopeConfig {
            cem43_budget_min: 10.0,
            ..Default::default()
        };
        let mut env = SafetyEnvelope::new(config, LIMIT_A).unwrap();
        for k in 0..=60_000u64 {
            let m = Measurement {
                time_s: k as f64 * DT_S,
                sensor_c: temp_c,
                hot_side_c: 25.0,
                sample_seq: k + 1,
            };
            env.observe(&m);
            // repeated samples add nothing
            env.observe(&m);
        }
        let got = env.cem43_min();
        assert!(
            (got - want_min).abs() < 1e-9,
            "60 s at {temp_c} °C: CEM43 {got} vs hand {want_min} min"
        );
        let t43 = env.time_at_or_above_43_s();
        assert!((t43 - want_43_s).abs() < 1e-9, "time at ≥ 43 °C {t43} vs {want_43_s} s");
        assert_eq!(env.fault(), None);
    }
}

#[test]
fn bad_configuration_and_current_limit_are_errors() {
    let too_hot = EnvelopeConfig {
        max_display_c: 50.0,
        ..Default::default()
    };
    assert!(matches!(
        SafetyEnvelope::new(too_hot, LIMIT_A),
        Err(EnvelopeError::BadValue(_))
    ));
    for limit in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(
            SafetyEnvelope::new(EnvelopeConfig::default(), limit).is_err(),
            "limit {limit}"
        );
    }
    let mut env = SafetyEnvelope::new(EnvelopeConfig::default(), LIMIT_A).unwrap();
    assert_eq!(env.clear_fault(0.0), Ok(None), "nothing to clear");
}

/// The gated command carries the envelope's shaped set-point (for temperature-commanded devices) only when it passed
/// the gate in the same tick as the shaping: never before a measurement, under a fault, in a hold, or for `off`.
#[test]
fn the_gated_command_carries_the_shaped_setpoint_only_when_it_passed() {
    let mut env = SafetyEnvelope::new(EnvelopeConfig::default(), LIMIT_A).unwrap();
    let sample = |t: f64, seq: u64, c: f64| Measurement {
        time_s: t,
        sensor_c: c,
        hot_side_c: 25.0,
        sample_seq: seq,
    };
    // Before any measurement: off, no set-point.
    env.shape_setpoint(0.0, 40.0);
    let before = env.gate_drive(0.0, REQUEST_A, &MeasuredOnly);
    assert_eq!(before.setpoint_c(), None, "{before:?}");
    env.observe(&sample(0.01, 1, 30.0));
    let shaped = env.shape_setpoint(0.02, 40.0).setpoint_c;
    let passed = env.gate_drive(0.02, REQUEST_A, &MeasuredOnly);
    assert_eq!(passed.setpoint_c(), Some(shaped), "shaped {shaped}, command {passed:?}");
    assert!((30.0..=40.0).contains(&shaped), "shaped {shaped}");
    // A gate without a shaping at its time carries none.
    let unshaped = env.gate_drive(0.03, REQUEST_A, &MeasuredOnly);
    assert_eq!(unshaped.setpoint_c(), None, "{unshaped:?}");
    assert_eq!(DriveCommand::off().setpoint_c(), None);
    assert_eq!(env.hold(0.04).setpoint_c(), None);
    // A fault (a NaN request) switches it off.
    env.shape_setpoint(0.05, 40.0);
    let faulted = env.gate_drive(0.05, f64::NAN, &MeasuredOnly);
    assert_eq!((faulted.current_a(), faulted.setpoint_c()), (0.0, None), "{faulted:?}");
}

/// From the lockout on the maximum never rises (the dose only grows): a plate held at 45 °C until the default
/// budget is nearly used (about 15 s), then at 38.6 °C, just under the landing temperature, where the last
/// thousandth of the budget takes seconds, sampled at 1 kHz through the lockout and on. Where the lockout engages
/// the ceiling's formula drops its look ahead, a step up of two ticks' cool-down (0.01 °C) that let a PID heat at
/// 38.6 °C above the maximum of the tick before (found by the render property test). Before the lockout the
/// maximum may rise a little as the interval between samples becomes known.
#[test]
fn the_dose_maximum_never_rises_from_the_lockout_on() {
    let mut rig = Rig::default();
    let mut previous_c = f64::INFINITY;
    let mut locked_at_s = None;
    while locked_at_s.is_none_or(|t| rig.now_s() < t + 1.0) {
        assert!(
            rig.now_s() < 600.0,
            "no lockout within 600 s: {} CEM43-min",
            rig.env.cem43_min()
        );
        rig.sample(if rig.env.cem43_min() < 0.999 { 45.0 } else { 38.6 }, 25.0);
        rig.tick += 1;
        let max_c = rig.env.effective_max_c();
        if rig.env.dose_lockout_active() {
            locked_at_s.get_or_insert(rig.now_s());
            assert!(
                max_c <= previous_c,
                "at {} s the maximum rose from {previous_c} to {max_c} °C",
                rig.now_s()
            );
        }
        previous_c = max_c;
    }
    assert!(previous_c < 43.0, "maximum {previous_c} °C after the lockout");
}
