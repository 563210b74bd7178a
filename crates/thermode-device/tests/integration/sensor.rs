//! Tests of the PT-100 model: the lag against 1 − exp(−t/τ) and against the ramp solution, sampling and holding,
//! quantisation, the noise's standard deviation, and determinism of the seeded noise.

use thermode_device::config::SensorConfig;
use thermode_device::{DeviceConfig, Pt100, SimulatedChannel};
use thermode_model::kron::KronModel;

fn quiet(time_constant_s: f64, sample_rate_hz: f64) -> SensorConfig {
    SensorConfig {
        time_constant_s,
        noise_c: 0.0,
        resolution_c: 0.0,
        sample_rate_hz,
    }
}

#[test]
fn lag_follows_one_minus_exp_for_a_step() {
    for (tau, dt) in [(0.3, 0.01), (0.3, 0.0037), (1.5, 0.025), (0.3, 0.05)] {
        let mut sensor = Pt100::seeded(&quiet(tau, 100.0), 20.0, 1);
        let mut worst = 0.0f64;
        let mut last_seq = 0;
        for _ in 0..(3.0 / dt) as usize {
            sensor.advance(dt, 30.0, 30.0);
            let s = sensor.latest();
            let want = 20.0 + 10.0 * (1.0 - (-s.time_s / tau).exp());
            worst = worst.max((s.value_c - want).abs());
            // The sample instants are k / rate exactly, the reading is held between them.
            assert!(
                (s.time_s - s.seq as f64 * 0.01).abs() < 1e-12,
                "sample {} at {} s",
                s.seq,
                s.time_s
            );
            assert!(s.time_s <= sensor.time_s() + 1e-9 && sensor.time_s() - s.time_s < 0.01 + 1e-9);
            assert!(s.seq >= last_seq);
            last_seq = s.seq;
        }
        assert!(
            worst < 1e-12,
            "τ={tau} dt={dt}: largest deviation from 1 − exp(−t/τ) {worst:e} K"
        );
        let due = (sensor.time_s() / 0.01 + 1e-6).floor() as u64;
        assert_eq!(
            last_seq,
            due,
            "τ={tau} dt={dt}: samples in {} s at 100 Hz",
            sensor.time_s()
        );
    }
}

#[test]
fn lag_of_a_ramp_is_tau_times_the_rate() {
    // Input u = 30 + r t; exact solution x = u − τ r (1 − e^(−t/τ)) from x(0) = 30.
    let (tau, rate) = (0.3, -4.0);
    let mut sensor = Pt100::seeded(&quiet(tau, 1000.0), 30.0, 1);
    let dt = 0.007;
    for n in 0..700 {
        let t0 = n as f64 * dt;
        sensor.advance(dt, 30.0 + rate * t0, 30.0 + rate * (t0 + dt));
        let t = sensor.time_s();
        let want = 30.0 + rate * t - tau * rate * (1.0 - (-t / tau).exp());
        assert!(
            (sensor.element_c() - want).abs() < 1e-10,
            "t={t}: element {} vs {want}",
            sensor.element_c()
        );
    }
}

#[test]
fn readings_are_quantised_to_the_resolution() {
    let config = SensorConfig {
        time_constant_s: 0.3,
        noise_c: 0.02,
        resolution_c: 0.01,
        sample_rate_hz: 100.0,
    };
    let mut sensor = Pt100::seeded(&config, 31.234_567, 3);
    for n in 0..2000 {
        let t = n as f64 * 0.01;
        sensor.advance(0.01, 31.0 + (t).sin(), 31.0 + (t + 0.01).sin());
        let v = sensor.latest().value_c;
        let steps = v / 0.01;
        assert!(
            (steps - steps.round()).abs() < 1e-6,
            "reading {v} is not a multiple of 0.01 °C"
        );
    }
}

/// Mean and standard deviation of `n` readings of a constant 25.003 °C.
fn reading_statistics(config: &SensorConfig, n: usize, seed: u64) -> (f64, f64) {
    let mut sensor = Pt100::seeded(config, 25.003, seed);
    let values: Vec<f64> = (0..n)
        .map(|_| {
            sensor.advance(1.0 / config.sample_rate_hz, 25.003, 25.003);
            sensor.latest().value_c
        })
        .collect();
    let mean = values.iter().sum::<f64>() / n as f64;
    let var = values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n as f64 - 1.0);
    (mean, var.sqrt())
}

#[test]
fn noise_has_the_configured_standard_deviation() {
    let n = 20_000;
    for noise in [0.005, 0.02, 0.1] {
        let config = SensorConfig {
            time_constant_s: 0.3,
            noise_c: noise,
            resolution_c: 0.0,
            sample_rate_hz: 100.0,
        };
        let (mean, sd) = reading_statistics(&config, n, 11);
        assert!((sd / noise - 1.0).abs() < 0.1, "noise {noise}: standard deviation {sd}");
        assert!(
            (mean - 25.003).abs() < 4.0 * noise / (n as f64).sqrt(),
            "noise {noise}: mean {mean}"
        );
        println!(
            "noise {noise} °C: measured sd {sd:.5} ({:+.2} %)",
            100.0 * (sd / noise - 1.0)
        );
    }
    // With the default 0.01 °C quantisation on top, the variance grows by q²/12 (Sheppard).
    let config = DeviceConfig::default().sensor;
    let (_, sd) = reading_statistics(&config, n, 12);
    let want = (config.noise_c.powi(2) + config.resolution_c.powi(2) / 12.0).sqrt();
    assert!(
        (sd / want - 1.0).abs() < 0.1,
        "default sensor: sd {sd} vs √(σ² + q²/12) = {want}"
    );
}

#[test]
fn the_same_seed_gives_bit_identical_readings() {
    let run = |seed: u64| -> Vec<u64> {
        let finger = <KronModel as thermode_device::PlateFinger>::fingertip().unwrap_or_else(|e| panic!("{e}"));
        let mut ch = SimulatedChannel::seeded(&DeviceConfig::default(), finger, seed).unwrap_or_else(|e| panic!("{e}"));
        (0..500)
            .map(|n| ch.step(0.003, -1.0 + (n as f64 * 0.01).cos()).sensor.value_c.to_bits())
            .collect()
    };
    assert_eq!(run(42), run(42));
    assert_ne!(run(42), run(43));
}
