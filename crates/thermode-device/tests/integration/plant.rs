//! Physics tests of the simulated channel: energy balance in every step, the steady state against the closed-form
//! solution of the node equations, convergence of the implicit coupling as the step is halved, relaxation to the
//! water/finger equilibrium without current, and the drive's limits.

use thermode_device::{DeviceConfig, PlateFinger, SimulatedChannel};
use thermode_model::inverse::PlateCoupled;
use thermode_model::kron::{KronEnvironment, KronModel};
use thermode_model::ParamError;

/// A receptor held at a fixed temperature (an infinitely large finger): makes the node equations solvable in closed
/// form. `conductance_scale` multiplies the contact conductance (0 = no finger).
#[derive(Debug, Clone)]
struct HeldFinger {
    receptor_c: f64,
    conductance_scale: f64,
}

impl PlateCoupled for HeldFinger {
    fn receptor_affine(&self, _dt_s: f64, _conductance_w_m2k: f64) -> (f64, f64) {
        (self.receptor_c, 0.0)
    }
    fn step_on_plate(&mut self, _dt_s: f64, _conductance_w_m2k: f64, _plate_c: f64) {}
    fn receptor_c(&self) -> f64 {
        self.receptor_c
    }
}

impl PlateFinger for HeldFinger {
    fn receptor_conductance_w_m2k(&self, surface_contact_w_m2k: f64) -> f64 {
        self.conductance_scale * surface_contact_w_m2k
    }
    fn fingertip() -> Result<Self, ParamError> {
        Ok(HeldFinger {
            receptor_c: 32.0,
            conductance_scale: 1.0,
        })
    }
}

fn channel<F: PlateFinger>(config: &DeviceConfig, finger: F) -> SimulatedChannel<F> {
    SimulatedChannel::seeded(config, finger, 7).unwrap_or_else(|e| panic!("channel: {e}"))
}

fn kron() -> KronModel {
    <KronModel as PlateFinger>::fingertip().unwrap_or_else(|e| panic!("kron: {e}"))
}

/// Checks the energy balance of every step of a run with a varied current.
fn check_energy_balance<F: PlateFinger>(mut ch: SimulatedChannel<F>, dt_s: f64, steps: usize) -> f64 {
    let (cd, chs) = (
        ch.config().plate.heat_capacity_j_k,
        ch.config().hot_side.heat_capacity_j_k,
    );
    let mut worst = 0.0f64;
    for n in 0..steps {
        let t = n as f64 * dt_s;
        // Cooling, heating, beyond the limit, zero and NaN commands.
        let current = match (n / 50) % 6 {
            0 => -2.8,
            1 => 2.0 * (3.0 * t).sin(),
            2 => 5.0,
            3 => 0.0,
            4 => f64::NAN,
            _ => -1.0,
        };
        let (plate0, hot0) = (ch.state().plate_c, ch.state().hot_side_c);
        let s = *ch.step(dt_s, current);
        let stored = (cd * (s.plate_c - plate0) + chs * (s.hot_side_c - hot0)) / dt_s;
        let f = s.flows;
        let supplied = f.electrical_w - f.hot_side_to_water_w + f.finger_into_plate_w;
        let scale = f.electrical_w.abs() + f.hot_side_to_water_w.abs() + f.finger_into_plate_w.abs() + stored.abs();
        let rel = (stored - supplied).abs() / scale;
        worst = worst.max(rel);
        assert!(
            rel <= 1e-9,
            "step {n}: stored {stored} W vs electrical − water + finger {supplied} W"
        );
        let peltier = f.peltier_into_plate_w + f.peltier_into_hot_side_w;
        assert!(
            (peltier - f.electrical_w).abs() <= 1e-12 * scale,
            "step {n}: q_d + q_h {peltier} vs V·I {}",
            f.electrical_w
        );
    }
    worst
}

#[test]
fn energy_balance_holds_in_every_step() {
    let config = DeviceConfig::default();
    let mut ch = channel(&config, kron());
    ch.set_temperatures(32.0, 24.0).unwrap_or_else(|e| panic!("{e}"));
    let kron_1ms = check_energy_balance(ch.clone(), 1e-3, 600);
    // 0.05 s steps are split into 5 substeps; the balance holds over the whole step.
    let kron_50ms = check_energy_balance(ch, 0.05, 600);
    let fv = check_energy_balance(
        channel(
            &config,
            thermode_device::default_finger().unwrap_or_else(|e| panic!("{e}")),
        ),
        0.01,
        300,
    );
    println!("worst relative energy residual: kron 1 ms {kron_1ms:e}, kron 50 ms {kron_50ms:e}, fv 10 ms {fv:e}");
}

/// The steady state of the node equations with a held receptor, solved independently (Cramer's rule).
fn closed_form_steady(config: &DeviceConfig, current_a: f64, receptor_c: f64) -> (f64, f64) {
    let m = config.module().unwrap_or_else(|e| panic!("{e}"));
    let (s, r, k) = (m.seebeck_v_k, m.resistance_ohm, m.conductance_w_k);
    let (i, t0) = (current_a, 273.15);
    let ag = config.plate.area_m2 * config.plate.contact_conductance_w_m2k;
    let (gw, tw) = (config.hot_side.water_conductance_w_k, config.ambient.water_c);
    // Plate: S I (Td + T0) + ½ I² R + K (Th − Td) + A G (Tr − Td) = 0
    // Hot:  −S I (Th + T0) + ½ I² R − K (Th − Td) − Gw (Th − Tw) = 0
    let (a11, a12, b1) = (s * i - k - ag, k, -s * i * t0 - 0.5 * i * i * r - ag * receptor_c);
    let (a21, a22, b2) = (k, -s * i - k - gw, s * i * t0 - 0.5 * i * i * r - gw * tw);
    let det = a11 * a22 - a12 * a21;
    ((b1 * a22 - a12 * b2) / det, (a11 * b2 - a21 * b1) / det)
}

#[test]
fn steady_state_matches_the_closed_form() {
    let config = DeviceConfig::default();
    for current in [-2.8, -1.5, 0.0, 1.0, 2.8] {
        let mut ch = channel(
            &config,
            HeldFinger {
                receptor_c: 33.0,
                conductance_scale: 1.0,
            },
        );
        for _ in 0..12_000 {
            ch.step(0.05, current);
        }
        let (plate, hot) = closed_form_steady(&config, current, 33.0);
        let s = ch.state();
        assert!(
            (s.plate_c - plate).abs() < 1e-9,
            "I={current}: plate {} vs closed form {plate}",
            s.plate_c
        );
        assert!(
            (s.hot_side_c - hot).abs() < 1e-9,
            "I={current}: hot side {} vs closed form {hot}",
            s.hot_side_c
        );
        println!("I={current:+.1} A: plate {plate:.4} °C, hot side {hot:.4} °C");
    }
}

#[test]
fn zero_current_relaxes_to_the_water_and_finger_equilibrium() {
    let config = DeviceConfig::default();
    // Without a finger everything ends at the water temperature.
    let mut ch = channel(
        &config,
        HeldFinger {
            receptor_c: 33.0,
            conductance_scale: 0.0,
        },
    );
    ch.set_temperatures(40.0, 30.0).unwrap_or_else(|e| panic!("{e}"));
    for _ in 0..12_000 {
        ch.step(0.05, 0.0);
    }
    let s = ch.state();
    assert!(
        (s.plate_c - 23.0).abs() < 1e-9 && (s.hot_side_c - 23.0).abs() < 1e-9,
        "plate {} hot {}",
        s.plate_c,
        s.hot_side_c
    );

    // With the Kron finger: its steady receptor on a plate at Td is α + β Td (linear model); with
    // K (Th − Td) + A G (α + β Td − Td) = 0 and −K (Th − Td) − G_w (Th − T_w) = 0 the equilibrium is closed form.
    let finger = kron();
    let mut ch = channel(&config, finger.clone());
    let g = ch.finger_conductance_w_m2k();
    let steady_t1 = |td: f64| {
        finger.steady_state_c(&KronEnvironment::Plate {
            conductance_w_m2k: g,
            temperature_c: td,
        })[0]
    };
    let alpha = steady_t1(0.0);
    let beta = steady_t1(1.0) - alpha;
    let m = config.module().unwrap_or_else(|e| panic!("{e}"));
    let (k, gw, tw) = (
        m.conductance_w_k,
        config.hot_side.water_conductance_w_k,
        config.ambient.water_c,
    );
    let ag = config.plate.area_m2 * g;
    let series = k * gw / (k + gw);
    let plate = (series * tw + ag * alpha) / (series + ag * (1.0 - beta));
    let hot = (k * plate + gw * tw) / (k + gw);
    let receptor = alpha + beta * plate;
    for _ in 0..40_000 {
        ch.step(0.1, 0.0);
    }
    let s = ch.state();
    assert!(
        (s.plate_c - plate).abs() < 1e-6,
        "plate {} vs equilibrium {plate}",
        s.plate_c
    );
    assert!(
        (s.hot_side_c - hot).abs() < 1e-6,
        "hot side {} vs equilibrium {hot}",
        s.hot_side_c
    );
    assert!(
        (s.receptor_c - receptor).abs() < 1e-6,
        "receptor {} vs equilibrium {receptor}",
        s.receptor_c
    );
    println!(
        "zero-current equilibrium with the Kron finger: plate {plate:.4}, hot {hot:.4}, receptor {receptor:.4} °C"
    );
}

/// Plate, hot side and receptor after 3 s of −2 A from a 32 °C plate, with step `dt_s`.
fn trajectory_end(dt_s: f64) -> [f64; 3] {
    let mut ch = channel(&DeviceConfig::default(), kron());
    ch.set_temperatures(32.0, 23.0).unwrap_or_else(|e| panic!("{e}"));
    let steps = (3.0 / dt_s).round() as usize;
    for n in 0..steps {
        // A smooth current profile: ramps to −2 A within 0.5 s.
        let t = n as f64 * dt_s;
        ch.step(dt_s, -2.0 * (t / 0.5).min(1.0));
    }
    let s = ch.state();
    [s.plate_c, s.hot_side_c, s.receptor_c]
}

#[test]
fn the_implicit_coupling_converges_at_first_order() {
    let dts = [0.008, 0.004, 0.002, 0.001];
    let ends: Vec<[f64; 3]> = dts.iter().map(|&dt| trajectory_end(dt)).collect();
    for (var, name) in ["plate", "hot side", "receptor"].iter().enumerate() {
        let diffs: Vec<f64> = ends.windows(2).map(|w| (w[0][var] - w[1][var]).abs()).collect();
        for pair in diffs.windows(2) {
            let ratio = pair[0] / pair[1];
            assert!(
                (1.8..=2.2).contains(&ratio),
                "{name}: successive differences {diffs:?}, ratio {ratio}, want ≈ 2"
            );
        }
        // First order: e(dt) ≈ C·dt, so T(dt) − T(dt/2) ≈ e(dt)/2 (Richardson).
        let (e8, e1) = (2.0 * diffs[0], diffs[2]);
        println!("{name}: error at 8 ms ≈ {e8:.2e} K, at 1 ms ≈ {e1:.2e} K");
        assert!(e8 < 0.05, "{name}: error at 8 ms {e8} K");
    }
}

#[test]
fn long_steps_equal_the_same_substeps_taken_one_by_one() {
    let config = DeviceConfig::default();
    let mut once = channel(&config, kron());
    let mut by_one = channel(&config, kron());
    for _ in 0..40 {
        once.step(0.05, -2.0);
        for _ in 0..5 {
            by_one.step(0.01, -2.0);
        }
    }
    let (a, b) = (once.state(), by_one.state());
    assert!(
        (a.plate_c - b.plate_c).abs() < 1e-12,
        "plate {} vs {}",
        a.plate_c,
        b.plate_c
    );
    assert!(
        (a.hot_side_c - b.hot_side_c).abs() < 1e-12,
        "hot {} vs {}",
        a.hot_side_c,
        b.hot_side_c
    );
    assert!(
        (a.time_s - 2.0).abs() < 1e-12 && (b.time_s - 2.0).abs() < 1e-12,
        "time {} {}",
        a.time_s,
        b.time_s
    );
}

#[test]
fn the_drive_limits_the_current_and_bad_steps_change_nothing() {
    let config = DeviceConfig::default();
    let mut ch = channel(&config, kron());
    assert_eq!(ch.step(0.01, 10.0).applied_current_a, 2.8);
    assert_eq!(ch.step(0.01, -10.0).applied_current_a, -2.8);
    assert_eq!(ch.step(0.01, 1.25).applied_current_a, 1.25);
    assert_eq!(ch.step(0.01, f64::NAN).applied_current_a, 0.0);
    assert_eq!(ch.step(0.01, f64::INFINITY).applied_current_a, 2.8);
    let before = *ch.state();
    for dt in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let after = *ch.step(dt, 2.0);
        assert_eq!(
            (after.plate_c, after.hot_side_c, after.time_s),
            (before.plate_c, before.hot_side_c, before.time_s)
        );
    }
    assert!(ch.set_temperatures(f64::NAN, 20.0).is_err());
    assert!(SimulatedChannel::seeded(
        &DeviceConfig {
            drive: thermode_device::config::DriveConfig { current_limit_a: 9.0 },
            ..config
        },
        kron(),
        1
    )
    .is_err());
}
