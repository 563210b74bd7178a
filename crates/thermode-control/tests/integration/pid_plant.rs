//! The paper's controller (low-pass + PID) against a first-order thermal plant simulated exactly in the test:
//! `C dT/dt = b I − G (T − T_amb)`, advanced with the exact zero-order-hold solution over each step.
//! Checks: zero steady-state error and the analytic holding current; the analytic P-only offset; anti-windup
//! bounds the integral under saturation and shortens recovery; derivative on measurement (no kick, analytic
//! ramp response, analytic derivative filter); bumpless reset; gains files; refused inputs.

use thermode_control::{AntiWindup, ControlError, ControlInput, Controller, Pid, PidController, PidGains};

/// First-order plant: heat capacity `c_j_k` (J/K), actuator gain `b_w_a` (W/A, positive current heats),
/// conductance `g_w_k` (W/K) to `ambient_c`.
struct Plant {
    c_j_k: f64,
    b_w_a: f64,
    g_w_k: f64,
    ambient_c: f64,
    temp_c: f64,
}

impl Plant {
    fn new() -> Self {
        Self {
            c_j_k: 0.3,
            b_w_a: 0.5,
            g_w_k: 0.05,
            ambient_c: 23.0,
            temp_c: 23.0,
        }
    }

    /// Steady state under a constant current.
    fn steady_c(&self, current_a: f64) -> f64 {
        self.ambient_c + self.b_w_a * current_a / self.g_w_k
    }

    /// Current that holds `temp_c` in steady state.
    fn holding_current_a(&self, temp_c: f64) -> f64 {
        self.g_w_k * (temp_c - self.ambient_c) / self.b_w_a
    }

    /// Exact step with the current held for `dt_s`.
    fn step(&mut self, current_a: f64, dt_s: f64) {
        let ss = self.steady_c(current_a);
        self.temp_c = ss + (self.temp_c - ss) * (-self.g_w_k * dt_s / self.c_j_k).exp();
    }
}

const LIMIT_A: f64 = 2.8;
const DT_S: f64 = 1e-3;

fn pi_gains() -> PidGains {
    PidGains {
        kp_a_per_c: 1.0,
        ki_a_per_c_s: 0.5,
        kd_a_s_per_c: 0.0,
        filter_cutoff_hz: 5.0,
        derivative_filter_s: None,
    }
}

fn input(setpoint_c: f64, sensor_c: f64) -> ControlInput {
    ControlInput {
        time_s: 0.0,
        dt_s: DT_S,
        setpoint_c,
        setpoint_rate_c_per_s: 0.0,
        sensor_c,
        hot_side_c: 25.0,
        applied_current_a: 0.0,
        finger_receptor_c: None,
        finger_conductance_w_k: 0.0,
        measured_current_a: f64::NAN,
        voltage_v: f64::NAN,
        fresh_sample: true,
    }
}

/// Closed loop for `duration_s` at a constant set-point; returns the last current.
fn run(controller: &mut dyn Controller, plant: &mut Plant, setpoint_c: f64, duration_s: f64) -> f64 {
    let mut current_a = 0.0;
    for _ in 0..(duration_s / DT_S).round() as usize {
        current_a = controller.update(&input(setpoint_c, plant.temp_c)).unwrap();
        plant.step(current_a, DT_S);
    }
    current_a
}

#[test]
fn step_response_settles_with_zero_steady_state_error() {
    let mut plant = Plant::new();
    let mut controller = PidController::new(pi_gains(), LIMIT_A).unwrap();
    let setpoint_c = 33.0;
    let current_a = run(&mut controller, &mut plant, setpoint_c, 60.0);
    let err = plant.temp_c - setpoint_c;
    eprintln!("PI on first-order plant after 60 s: error {err:e} °C, current {current_a} A");
    assert!(
        err.abs() < 1e-9,
        "steady-state error {err} °C (plant {} vs set-point {setpoint_c})",
        plant.temp_c
    );
    let want_a = plant.holding_current_a(setpoint_c);
    assert!(
        (current_a - want_a).abs() < 1e-9,
        "holding current {current_a} A vs analytic {want_a} A"
    );
    let terms = controller.terms();
    assert!(
        (terms.i_a - want_a).abs() < 1e-9,
        "integral {} A carries the holding current {want_a} A",
        terms.i_a
    );
    assert!(terms.p_a.abs() < 1e-8 && !terms.saturated, "P {} at rest", terms.p_a);
}

/// Without the integral, the loop settles with the analytic offset `G (sp − T_amb) / (b K_p + G)`.
#[test]
fn p_only_leaves_the_analytic_offset() {
    let mut plant = Plant::new();
    let gains = PidGains {
        ki_a_per_c_s: 0.0,
        ..pi_gains()
    };
    let mut controller = PidController::new(gains, LIMIT_A).unwrap();
    let setpoint_c = 33.0;
    run(&mut controller, &mut plant, setpoint_c, 60.0);
    let kp = gains.kp_a_per_c;
    let want = plant.g_w_k * (setpoint_c - plant.ambient_c) / (plant.b_w_a * kp + plant.g_w_k);
    let got = setpoint_c - plant.temp_c;
    eprintln!("P-only offset {got} °C vs analytic {want} °C");
    assert!(
        (got - want).abs() < 1e-9,
        "P-only offset {got} °C vs analytic {want} °C"
    );
}

/// Set-point 60 °C is unreachable (the limit holds at most 51 °C) for 60 s, then 40 °C for 180 s. Measures the
/// largest integral term and the time to come within 0.5 °C of 40 °C after the drop.
fn windup_scenario(anti_windup: AntiWindup) -> (f64, f64) {
    let mut plant = Plant::new();
    let mut pid = Pid::new(pi_gains(), LIMIT_A).unwrap().with_anti_windup(anti_windup);
    let mut max_integral_a: f64 = 0.0;
    let steps = (60.0 / DT_S) as usize;
    for _ in 0..steps {
        let current_a = pid.update(60.0, plant.temp_c, DT_S).unwrap();
        max_integral_a = max_integral_a.max(pid.terms().i_a.abs());
        plant.step(current_a, DT_S);
    }
    assert!(
        (plant.temp_c - plant.steady_c(LIMIT_A)).abs() < 0.05,
        "saturated plant at {}",
        plant.temp_c
    );
    let mut recovery_s = f64::INFINITY;
    for k in 0..3 * steps {
        let current_a = pid.update(40.0, plant.temp_c, DT_S).unwrap();
        max_integral_a = max_integral_a.max(pid.terms().i_a.abs());
        plant.step(current_a, DT_S);
        if (plant.temp_c - 40.0).abs() < 0.5 && recovery_s.is_infinite() {
            recovery_s = (k + 1) as f64 * DT_S;
        }
    }
    (max_integral_a, recovery_s)
}

#[test]
fn anti_windup_bounds_the_integral_and_speeds_recovery() {
    let (with_i, with_s) = windup_scenario(AntiWindup::ConditionalIntegration);
    let (without_i, without_s) = windup_scenario(AntiWindup::Off);
    eprintln!("max |I|: with {with_i} A, without {without_i} A; recovery: with {with_s} s, without {without_s} s");
    assert!(
        with_i <= LIMIT_A,
        "with anti-windup the integral stays within the limit: {with_i} A"
    );
    // Without: the integral grows by about K_i·(60 − 51)·60 s ≈ 270 A.
    assert!(
        without_i > 100.0,
        "without anti-windup the integral winds up: {without_i} A"
    );
    assert!(with_s < 10.0, "recovery with anti-windup {with_s} s");
    assert!(
        without_s > 3.0 * with_s,
        "recovery without {without_s} s vs with {with_s} s"
    );
}

#[test]
fn positive_error_heats_and_output_is_limited() {
    let mut pid = Pid::new(pi_gains(), LIMIT_A).unwrap();
    assert_eq!(pid.update(40.0, 20.0, DT_S).unwrap(), LIMIT_A);
    assert!(pid.terms().saturated);
    pid.reset();
    assert_eq!(pid.update(10.0, 40.0, DT_S).unwrap(), -LIMIT_A);
    pid.reset();
    let small = pid.update(33.1, 33.0, DT_S).unwrap();
    assert!(
        small > 0.0 && small < 0.2,
        "0.1 °C too cold → small heating current, got {small}"
    );
}

#[test]
fn derivative_acts_on_measurement_only() {
    let gains = PidGains {
        kp_a_per_c: 0.0,
        ki_a_per_c_s: 0.0,
        kd_a_s_per_c: 0.2,
        ..pi_gains()
    };
    let mut pid = Pid::new(gains, LIMIT_A).unwrap();
    pid.update(30.0, 30.0, DT_S).unwrap();
    // A set-point step with a constant measurement: no derivative kick.
    assert_eq!(pid.update(40.0, 30.0, DT_S).unwrap(), 0.0);
    assert_eq!(pid.terms().d_a, 0.0);
    // A measurement ramp of slope s: D = −K_d s.
    let slope_c_per_s = 0.5;
    let mut y = 30.0;
    for _ in 0..10 {
        y += slope_c_per_s * DT_S;
        pid.update(40.0, y, DT_S).unwrap();
        let want = -0.2 * slope_c_per_s;
        assert!(
            (pid.terms().d_a - want).abs() < 1e-9,
            "D {} vs analytic {want}",
            pid.terms().d_a
        );
    }
}

/// With a first-order derivative filter of time constant T_f, a ramp gives D(t) = −K_d s (1 − exp(−t/T_f)),
/// t counted from the first sample that has a predecessor.
#[test]
fn derivative_filter_matches_analytic_first_order_response() {
    let tf_s = 0.05;
    let gains = PidGains {
        kp_a_per_c: 0.0,
        ki_a_per_c_s: 0.0,
        kd_a_s_per_c: 0.3,
        derivative_filter_s: Some(tf_s),
        ..pi_gains()
    };
    let mut pid = Pid::new(gains, LIMIT_A).unwrap();
    let slope_c_per_s = 2.0;
    let dt_s = 1.0 / 1024.0; // exact in binary, so the ramp differences are exact
    pid.update(30.0, 30.0, dt_s).unwrap();
    for k in 1..=400 {
        pid.update(30.0, 30.0 + slope_c_per_s * k as f64 * dt_s, dt_s).unwrap();
        let want = -0.3 * slope_c_per_s * (1.0 - (-(k as f64) * dt_s / tf_s).exp());
        let got = pid.terms().d_a;
        assert!((got - want).abs() < 1e-12, "step {k}: D {got} vs analytic {want}");
    }
}

#[test]
fn bumpless_reset_continues_from_the_given_output() {
    let mut pid = Pid::new(pi_gains(), LIMIT_A).unwrap();
    pid.update(45.0, 20.0, DT_S).unwrap();
    let (sp, y, u0) = (34.0, 33.0, 1.3);
    pid.reset_bumpless(sp, y, u0).unwrap();
    let got = pid.update(sp, y, DT_S).unwrap();
    let want = u0 + pi_gains().ki_a_per_c_s * (sp - y) * DT_S;
    assert!(
        (got - want).abs() < 1e-12,
        "first output after bumpless reset {got} vs {want}"
    );
    assert!(pid.reset_bumpless(f64::NAN, y, u0).is_err());
}

#[test]
fn gains_round_trip_through_toml_and_bad_gains_are_refused() {
    let g = PidGains {
        derivative_filter_s: Some(0.02),
        ..pi_gains()
    };
    let text = toml::to_string(&g).unwrap();
    assert_eq!(PidGains::from_toml_str(&text, "g.toml").unwrap(), g);
    let plain = toml::to_string(&pi_gains()).unwrap();
    assert!(!plain.contains("derivative_filter_s"), "{plain}");
    assert_eq!(PidGains::from_toml_str(&plain, "g.toml").unwrap(), pi_gains());
    assert!(
        PidGains::from_toml_str("kp_a_per_c = 1.0\n", "g.toml").is_err(),
        "missing gains must be an error"
    );
    assert!(
        PidGains::from_toml_str(&format!("{plain}kq = 1.0\n"), "g.toml").is_err(),
        "unknown key refused"
    );
    let negative = PidGains {
        kp_a_per_c: -1.0,
        ..pi_gains()
    };
    assert!(matches!(
        Pid::new(negative, LIMIT_A),
        Err(ControlError::BadValue(ref e)) if e.name == "kp_a_per_c"
    ));
    let nan = PidGains {
        ki_a_per_c_s: f64::NAN,
        ..pi_gains()
    };
    assert!(matches!(
        PidController::new(nan, LIMIT_A),
        Err(ControlError::BadValue(ref e)) if e.name == "ki_a_per_c_s"
    ));
    assert!(Pid::new(pi_gains(), 0.0).is_err());
    assert!(Pid::new(pi_gains(), f64::INFINITY).is_err());
    let no_filter = PidGains {
        filter_cutoff_hz: f64::INFINITY,
        ..pi_gains()
    };
    PidController::new(no_filter, LIMIT_A).unwrap();
}

#[test]
fn refused_ticks_leave_the_controller_untouched() {
    let mut boxed: Box<dyn Controller> = Box::new(PidController::new(pi_gains(), LIMIT_A).unwrap());
    assert_eq!(boxed.name(), "pid");
    boxed.update(&input(34.0, 33.0)).unwrap();
    let mut c = PidController::new(pi_gains(), LIMIT_A).unwrap();
    c.update(&input(34.0, 33.0)).unwrap();
    let before = c.clone();
    for bad in [
        ControlInput {
            sensor_c: f64::NAN,
            ..input(34.0, 33.0)
        },
        ControlInput {
            setpoint_c: f64::INFINITY,
            ..input(34.0, 33.0)
        },
        ControlInput {
            dt_s: 0.0,
            ..input(34.0, 33.0)
        },
        ControlInput {
            dt_s: -1e-3,
            ..input(34.0, 33.0)
        },
        ControlInput {
            dt_s: f64::NAN,
            ..input(34.0, 33.0)
        },
    ] {
        assert!(c.update(&bad).is_err(), "{bad:?} must be refused");
        assert_eq!(c, before, "state changed by refused input {bad:?}");
    }
    c.reset();
    assert_eq!(c.filtered_c(), None);
    assert_eq!(c.terms().output_a, 0.0);
}
