//! Criterion bench: channel-steps per second of the simulated plant (Peltier, plate, hot side, PT-100, finger),
//! with the paper's Kron finger and with the default finite-volume finger, at a 1 ms step.
#![allow(missing_docs)] // criterion_main! generates an undocumented `main`

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use thermode_device::{DeviceConfig, PlateFinger, SimulatedChannel};
use thermode_model::fv::FvModel;
use thermode_model::kron::KronModel;

const STEPS: u64 = 1000;

fn bench_finger<F: PlateFinger>(c: &mut Criterion, name: &str) {
    let finger = F::fingertip().unwrap_or_else(|e| panic!("{name} finger: {e}"));
    let mut channel = SimulatedChannel::seeded(&DeviceConfig::default(), finger, 1).unwrap_or_else(|e| panic!("{e}"));
    let mut group = c.benchmark_group("plant");
    group.throughput(Throughput::Elements(STEPS));
    group.bench_function(format!("{name}_finger_1ms_steps"), |b| {
        let mut n = 0u64;
        b.iter(|| {
            for _ in 0..STEPS {
                n += 1;
                // A current that changes every step, as under closed-loop control.
                let current = if n % 2000 < 1000 { -2.0 } else { 1.5 };
                black_box(channel.step(black_box(1e-3), current).plate_c);
            }
        });
    });
    group.finish();
}

fn plant(c: &mut Criterion) {
    bench_finger::<KronModel>(c, "kron");
    bench_finger::<FvModel>(c, "fv");
}

criterion_group!(benches, plant);
criterion_main!(benches);
