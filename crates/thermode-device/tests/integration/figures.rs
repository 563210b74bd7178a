//! The display's measured figures with a finger on the plate (printed with `--nocapture`) and the physics they must
//! obey: the initial cooling and heating rates against the node equation, time to reach 20 °C from 32 °C at full
//! current, and the hot side's rise during 90 s of full cooling (the paper saw it), more with weak cooling.

use thermode_device::{DeviceConfig, PlateFinger, SimulatedChannel, WEAK_COOLING_DEVICE_TOML};
use thermode_model::kron::KronModel;

/// A channel whose plate has been held at 32 °C for 60 s (PI control on the true plate temperature), so finger and
/// hot side have settled around it.
fn settled_at_32<F: PlateFinger>(config: &DeviceConfig, finger: F) -> SimulatedChannel<F> {
    let mut ch = SimulatedChannel::seeded(config, finger, 5).unwrap_or_else(|e| panic!("{e}"));
    ch.set_temperatures(32.0, config.ambient.water_c)
        .unwrap_or_else(|e| panic!("{e}"));
    let (dt, mut integral) = (0.01, 0.0);
    for _ in 0..6000 {
        let error = 32.0 - ch.state().plate_c;
        integral += error * dt;
        ch.step(dt, 2.0 * error + 2.0 * integral);
    }
    let plate = ch.state().plate_c;
    assert!((plate - 32.0).abs() < 1e-3, "settling failed: plate at {plate}");
    ch
}

/// The initial rate of the plate at `current_a` [°C/s] measured over 1 ms, and the node equation's prediction.
fn initial_rate<F: PlateFinger + Clone>(ch: &SimulatedChannel<F>, current_a: f64) -> (f64, f64) {
    let mut ch = ch.clone();
    let s0 = *ch.state();
    let c = ch.config();
    let finger_w = c.plate.area_m2 * ch.finger_conductance_w_m2k() * (s0.receptor_c - s0.plate_c);
    let predicted =
        (ch.module().heat_into_display_w(current_a, s0.plate_c, s0.hot_side_c) + finger_w) / c.plate.heat_capacity_j_k;
    let measured = (ch.step(1e-3, current_a).plate_c - s0.plate_c) / 1e-3;
    (measured, predicted)
}

/// Time \[s\] until the plate reaches `target_c` at `current_a` (None within 20 s).
fn time_to<F: PlateFinger>(mut ch: SimulatedChannel<F>, current_a: f64, target_c: f64) -> Option<f64> {
    let start = ch.state().time_s;
    for _ in 0..20_000 {
        let s = ch.step(1e-3, current_a);
        if (s.plate_c - target_c) * current_a.signum() >= 0.0 {
            return Some(s.time_s - start);
        }
    }
    None
}

/// Hot-side rise \[K\] over 90 s of full cooling, and the final hot-side temperature minus the water temperature
/// against q_h/G_w (the hot side's steady state).
fn hot_side_after_90_s<F: PlateFinger>(mut ch: SimulatedChannel<F>) -> (f64, f64, f64, f64) {
    let start = ch.state().hot_side_c;
    for _ in 0..9000 {
        ch.step(0.01, -2.8);
    }
    let s = *ch.state();
    let steady = s.flows.peltier_into_hot_side_w / ch.water_conductance_w_k();
    (
        s.hot_side_c - start,
        s.hot_side_c - ch.config().ambient.water_c,
        steady,
        s.plate_c,
    )
}

fn report_for<F: PlateFinger + Clone>(name: &str, finger: F) {
    let config = DeviceConfig::default();
    let ch = settled_at_32(&config, finger.clone());
    let (cool, cool_want) = initial_rate(&ch, -2.8);
    let (heat, heat_want) = initial_rate(&ch, 2.8);
    for (got, want, what) in [(cool, cool_want, "cooling"), (heat, heat_want, "heating")] {
        assert!(
            (got / want - 1.0).abs() < 0.01,
            "{name}: initial {what} rate {got} °C/s vs node equation {want}"
        );
    }
    // Heating is the stronger direction (Joule heat helps it), and both are several °C/s on a 0.28 J/K plate.
    assert!(
        heat > -cool && cool < -5.0,
        "{name}: cooling {cool} °C/s, heating {heat} °C/s"
    );
    let to_20 = time_to(ch.clone(), -2.8, 20.0);
    let Some(to_20) = to_20 else {
        panic!("{name}: 20 °C not reached at full cooling")
    };
    // It cannot be faster than the initial (largest) rate allows.
    assert!(
        to_20 > 12.0 / -cool,
        "{name}: 12 K in {to_20} s faster than the initial rate {cool} °C/s allows"
    );
    let to_44 = time_to(ch.clone(), 2.8, 44.0).unwrap_or(f64::NAN);
    println!(
        "{name}: from 32 °C at ±2.8 A: initial cooling {cool:.2} °C/s, heating {heat:.2} °C/s; \
         32→20 °C in {to_20:.3} s, 32→44 °C in {to_44:.3} s"
    );

    let weak_config =
        DeviceConfig::from_toml_str(WEAK_COOLING_DEVICE_TOML, "weak-cooling.toml").unwrap_or_else(|e| panic!("{e}"));
    let (rise, above, steady, plate) = hot_side_after_90_s(ch);
    let (weak_rise, weak_above, weak_steady, weak_plate) = hot_side_after_90_s(settled_at_32(&weak_config, finger));
    println!(
        "{name}: hot side after 90 s of full cooling: +{rise:.2} K (plate {plate:.2} °C) default, \
         +{weak_rise:.2} K (plate {weak_plate:.2} °C) weak cooling"
    );
    assert!(rise > 1.0, "{name}: the hot side rose only {rise} K");
    assert!(
        weak_rise > 1.5 * rise,
        "{name}: weak cooling rise {weak_rise} K vs default {rise} K"
    );
    // After 90 s the hot side is in its steady state: its excess over the water is q_h / G_w.
    for (got, want, what) in [(above, steady, "default"), (weak_above, weak_steady, "weak")] {
        assert!(
            (got / want - 1.0).abs() < 0.02,
            "{name} {what}: T_h − T_w = {got} K vs q_h/G_w = {want} K"
        );
    }
    // Weak cooling costs cooling: the plate ends warmer.
    assert!(
        weak_plate > plate,
        "{name}: plate {weak_plate} °C with weak cooling vs {plate} °C"
    );
}

#[test]
fn figures_with_the_default_finite_volume_finger() {
    report_for(
        "fv finger",
        thermode_device::default_finger().unwrap_or_else(|e| panic!("{e}")),
    );
}

#[test]
fn figures_with_the_kron_finger() {
    report_for(
        "kron finger",
        <KronModel as PlateFinger>::fingertip().unwrap_or_else(|e| panic!("{e}")),
    );
}
