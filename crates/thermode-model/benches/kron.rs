//! Criterion benchmarks of the three-layer (Kron) model: backward-Euler steps per second in air and in contact, and
//! display-inverse set-point + advance pairs per second.
#![allow(missing_docs)] // criterion_main! generates an undocumented `main`

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use thermode_model::inverse::{DisplayInverse, DEFAULT_DISPLAY_CONDUCTANCE_W_M2K};
use thermode_model::kron::{KronEnvironment, KronModel};
use thermode_model::materials;
use thermode_model::Skin;

const STEPS: u64 = 1000;
const DT_S: f64 = 0.01;

fn fingertip() -> KronModel {
    match KronModel::new(&Skin::fingertip()) {
        Ok(model) => model,
        Err(e) => panic!("default fingertip refused: {e}"),
    }
}

fn steps(c: &mut Criterion) {
    let aluminium = match materials::find("aluminium") {
        Ok(m) => m,
        Err(e) => panic!("{e}"),
    };
    let cases = [
        ("air", KronEnvironment::Air { ambient_c: 23.0 }),
        ("contact", KronEnvironment::touching(&aluminium, 23.0)),
    ];
    let mut group = c.benchmark_group("kron_step");
    group.throughput(Throughput::Elements(STEPS));
    for (name, env) in cases {
        group.bench_function(name, |b| {
            let mut model = fingertip();
            b.iter(|| {
                for _ in 0..STEPS {
                    model.step(black_box(DT_S), black_box(&env));
                }
                black_box(model.temperatures_c())
            })
        });
    }
    group.finish();
}

fn inverse(c: &mut Criterion) {
    let mut group = c.benchmark_group("kron_inverse");
    group.throughput(Throughput::Elements(STEPS));
    group.bench_function("setpoint_and_advance", |b| {
        let mut inverse = match DisplayInverse::new(fingertip(), DEFAULT_DISPLAY_CONDUCTANCE_W_M2K) {
            Ok(inverse) => inverse,
            Err(e) => panic!("{e}"),
        };
        b.iter(|| {
            for i in 0..STEPS {
                let target = 31.0 + 0.001 * i as f64;
                let setpoint = inverse.setpoint_c(black_box(target), DT_S);
                inverse.advance(DT_S, setpoint.clamp(10.0, 45.0));
            }
            black_box(inverse.receptor_c())
        })
    });
    group.finish();
}

criterion_group!(benches, steps, inverse);
criterion_main!(benches);
