//! Property tests: random and hostile set-point trajectories, measurements and drive requests thrown at the
//! envelope (NaN, ±inf, ±1e308, huge jumps, random configurations, occasional fault clearing), asserting on every
//! tick that no limit is crossed: the shaped set-point stays finite and inside [min, effective max] and never moves
//! faster than the rate limit (except the downward step when the dose lockout lowers the maximum); the gated
//! current is finite, within the limit, zero while faulted, never heating at/above the effective maximum and never
//! cooling at/below the minimum (measured); under a dose lockout the maximum and set-point stay below 43 °C; the
//! dose never decreases. A closed-loop property drives a first-order plant through envelope + PID with hostile
//! targets and bounds the plant temperature by the one-tick overshoot the gate allows.

use proptest::prelude::*;
use thermode_control::{ControlInput, Controller, PidController, PidGains};
use thermode_safety::{EnvelopeConfig, MeasuredOnly, Measurement, SafetyEnvelope};

const LIMIT_A: f64 = 2.8;

/// Any f64 with the hostile values over-represented.
fn hostile() -> impl Strategy<Value = f64> {
    prop_oneof![
        6 => -100.0..200.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(1e308),
        1 => Just(-1e308),
        1 => any::<f64>(),
    ]
}

#[derive(Debug, Clone)]
struct Tick {
    dt_s: f64,
    request_c: f64,
    sensor_c: f64,
    hot_side_c: f64,
    fresh: bool,
    request_a: f64,
    try_clear: bool,
}

fn tick() -> impl Strategy<Value = Tick> {
    (
        prop_oneof![4 => 1e-4..0.05f64, 1 => Just(0.0), 1 => 0.05..2.0f64],
        prop_oneof![3 => 0.0..60.0f64, 1 => hostile()],
        prop_oneof![8 => 10.0..50.0f64, 1 => hostile()],
        prop_oneof![8 => 15.0..44.0f64, 1 => hostile()],
        prop::bool::weighted(0.9),
        prop_oneof![3 => -5.0..5.0f64, 1 => hostile()],
        prop::bool::weighted(0.2),
    )
        .prop_map(
            |(dt_s, request_c, sensor_c, hot_side_c, fresh, request_a, try_clear)| Tick {
                dt_s,
                request_c,
                sensor_c,
                hot_side_c,
                fresh,
                request_a,
                try_clear,
            },
        )
}

/// Valid configurations: a random display range inside the absolute one, random rate and dose limits.
fn config() -> impl Strategy<Value = EnvelopeConfig> {
    (10.0..30.0f64, 5.0..38.0f64, 0.5..20.0f64, 0.0..5.0f64, 0.0..2.0f64).prop_map(
        |(min_c, span_c, rate, time43_s, budget)| EnvelopeConfig {
            min_display_c: min_c,
            max_display_c: (min_c + span_c).min(48.0),
            max_setpoint_rate_c_per_s: rate,
            max_time_at_or_above_43_s: time43_s,
            cem43_budget_min: budget,
            ..Default::default()
        },
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn no_limit_is_ever_crossed(config in config(), ticks in prop::collection::vec(tick(), 1..300)) {
        let mut env = SafetyEnvelope::new(config, LIMIT_A).unwrap();
        let (mut now_s, mut seq) = (0.0f64, 0u64);
        let mut prev: Option<(f64, f64, f64)> = None; // (time, set-point, effective max)
        let (mut cem, mut t43) = (0.0, 0.0);
        for t in &ticks {
            now_s += t.dt_s;
            if t.fresh {
                seq += 1;
                env.observe(&Measurement { time_s: now_s, sensor_c: t.sensor_c, hot_side_c: t.hot_side_c, sample_seq: seq });
            }
            if t.try_clear {
                let _ = env.clear_fault(now_s);
            }
            let (min_c, max_c) = (env.min_c(), env.effective_max_c());
            prop_assert!(min_c >= config.min_display_c && max_c <= config.max_display_c);
            let sp = env.shape_setpoint(now_s, t.request_c);
            prop_assert!(sp.setpoint_c.is_finite(), "set-point {}", sp.setpoint_c);
            prop_assert!(sp.setpoint_c >= min_c && sp.setpoint_c <= max_c,
                "set-point {} outside [{min_c}, {max_c}]", sp.setpoint_c);
            if let Some((t_prev, sp_prev, max_prev)) = prev {
                let allowed = config.max_setpoint_rate_c_per_s * (now_s - t_prev) * (1.0 + 1e-12) + 1e-12;
                let lowered = max_c < max_prev;
                prop_assert!(lowered || (sp.setpoint_c - sp_prev).abs() <= allowed,
                    "set-point moved {} in {} s (allowed {allowed})", sp.setpoint_c - sp_prev, now_s - t_prev);
                if lowered {
                    prop_assert!(sp.setpoint_c <= sp_prev.max(max_c), "a lowered maximum only steps down");
                }
            }
            prev = Some((now_s, sp.setpoint_c, max_c));
            if env.dose_lockout_active() {
                prop_assert!(max_c <= 42.5 && sp.setpoint_c <= 42.5, "dose lockout: max {max_c}, sp {}", sp.setpoint_c);
            }
            let d = env.gate_drive(now_s, t.request_a, &MeasuredOnly);
            let i = d.current_a();
            prop_assert!(i.is_finite() && i.abs() <= LIMIT_A, "current {i}");
            prop_assert_eq!(d.fault(), env.fault());
            if env.fault().is_some() {
                prop_assert_eq!(i, 0.0);
            } else if let Some(m) = env.last_measurement() {
                prop_assert!(!(i > 0.0 && m.sensor_c >= env.effective_max_c()), "heating {i} A at {} °C", m.sensor_c);
                prop_assert!(!(i < 0.0 && m.sensor_c <= env.min_c()), "cooling {i} A at {} °C", m.sensor_c);
            } else {
                prop_assert_eq!(i, 0.0, "no measurement yet");
            }
            prop_assert!(env.cem43_min() >= cem && env.time_at_or_above_43_s() >= t43, "dose decreased");
            prop_assert!(env.time_at_or_above_43_s() <= now_s + 1e-9);
            cem = env.cem43_min();
            t43 = env.time_at_or_above_43_s();
        }
    }

}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    /// Envelope + PID + first-order plant at 1 kHz with hostile targets: the plate (measured exactly) never
    /// exceeds the configured maximum (or the ambient, towards which it drifts passively) by more than one tick of
    /// full heating, nor falls below the minimum (or the ambient) by more than one tick of full cooling.
    #[test]
    fn closed_loop_plate_stays_in_the_envelope(
        config in config(),
        targets in prop::collection::vec((0.05..1.5f64, hostile()), 1..10),
    ) {
        // Plate: 0.2 J/K; 1.9 W/A (≈ S·T of the 8×8 mm module); 0.05 W/K to 23 °C.
        let (c_j_k, b_w_a, g_w_k, ambient_c, dt_s) = (0.2, 1.9, 0.05, 23.0f64, 1e-3);
        let one_tick_c = b_w_a * LIMIT_A * dt_s / c_j_k;
        let gains = PidGains { kp_a_per_c: 2.0, ki_a_per_c_s: 1.0, kd_a_s_per_c: 0.0, filter_cutoff_hz: 20.0,
            derivative_filter_s: None };
        let mut controller = PidController::new(gains, LIMIT_A).unwrap();
        let mut env = SafetyEnvelope::new(config, LIMIT_A).unwrap();
        let mut temp_c = ambient_c.clamp(config.min_display_c, config.max_display_c);
        let (mut applied_a, mut k) = (0.0, 0u64);
        let upper_c = config.max_display_c.max(ambient_c) + one_tick_c;
        let lower_c = config.min_display_c.min(ambient_c) - one_tick_c;
        for (duration_s, target_c) in targets {
            for _ in 0..(duration_s / dt_s) as usize {
                k += 1;
                let now_s = k as f64 * dt_s;
                env.observe(&Measurement { time_s: now_s, sensor_c: temp_c, hot_side_c: 25.0, sample_seq: k });
                if env.fault().is_some() {
                    let _ = env.clear_fault(now_s);
                }
                let sp = env.shape_setpoint(now_s, target_c);
                let input = ControlInput { time_s: now_s, dt_s, setpoint_c: sp.setpoint_c,
                    setpoint_rate_c_per_s: sp.rate_c_per_s, sensor_c: temp_c, hot_side_c: 25.0,
                    applied_current_a: applied_a, finger_receptor_c: None, finger_conductance_w_k: 0.0,
                    measured_current_a: f64::NAN, voltage_v: f64::NAN, fresh_sample: true };
                let request_a = controller.update(&input).unwrap_or(f64::NAN);
                let d = env.gate_drive(now_s, request_a, &MeasuredOnly);
                applied_a = d.current_a();
                prop_assert!(applied_a.abs() <= LIMIT_A);
                let ss = ambient_c + b_w_a * applied_a / g_w_k;
                temp_c = ss + (temp_c - ss) * (-g_w_k * dt_s / c_j_k).exp();
                prop_assert!(temp_c <= upper_c, "plate {temp_c} °C above {upper_c}");
                prop_assert!(temp_c >= lower_c, "plate {temp_c} °C below {lower_c}");
            }
        }
    }
}
