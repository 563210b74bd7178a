//! Criterion benchmarks of the finite-volume model: steps per second on the default grid with the fingertip in
//! contact with aluminium (1 cm, R_c = 1e-3), for both schemes and for the display-inverse pair
//! (`receptor_affine` + `step_on_plate`), the time of one grid-converged 90 s contact simulation, and one 90 s
//! contact (rows every 10 ms, adaptive steps at the default tolerance) on each grid level 0 to 4 — the workload
//! `scripts/peer/fv_scipy.py` times against SciPy's BDF.
#![allow(missing_docs)] // criterion_main! generates an undocumented `main`

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use thermode_model::fv::{
    simulate_contact, simulate_contact_converged, ContactSpec, FvConfig, FvEnvironment, FvModel, Refinement, TimeScheme,
};
use thermode_model::inverse::PlateCoupled;
use thermode_model::materials;
use thermode_model::Skin;

fn contact_model(scheme: TimeScheme) -> FvModel {
    let aluminium = materials::find("aluminium").expect("aluminium is in the library");
    let config = FvConfig {
        contact_resistance_m2k_w: 1e-3,
        scheme,
        ..FvConfig::default()
    };
    let mut model = FvModel::new(&Skin::fingertip(), Some(&aluminium), &config).expect("valid model");
    model.set_steady_in_air(23.0).expect("steady state");
    model.touch(23.0).expect("has an object");
    model
}

fn steps(c: &mut Criterion) {
    let mut group = c.benchmark_group("fv_step");
    group.throughput(Throughput::Elements(1));
    for (name, scheme) in [
        ("tr_bdf2_contact", TimeScheme::TrBdf2),
        ("backward_euler_contact", TimeScheme::BackwardEuler),
    ] {
        let mut model = contact_model(scheme);
        group.bench_function(name, |b| b.iter(|| model.step(black_box(0.01), FvEnvironment::Object)));
    }
    let mut finger = FvModel::new(&Skin::fingertip(), None, &FvConfig::default()).expect("valid model");
    finger.set_steady_in_air(23.0).expect("steady state");
    group.bench_function("display_inverse_step", |b| {
        b.iter(|| {
            let (offset, slope) = finger.receptor_affine(black_box(0.01), 2000.0);
            let plate_c = ((30.0 - offset) / slope).clamp(15.0, 45.0);
            finger.step_on_plate(0.01, 2000.0, plate_c);
        })
    });
    group.finish();
}

fn converged_run(c: &mut Criterion) {
    let skin = Skin::fingertip();
    let aluminium = materials::find("aluminium").expect("aluminium is in the library");
    let config = FvConfig {
        contact_resistance_m2k_w: 1e-3,
        ..FvConfig::default()
    };
    let spec = ContactSpec {
        duration_s: 90.0,
        output_dt_s: 0.01,
        ..ContactSpec::default()
    };
    let mut group = c.benchmark_group("fv_simulate_contact_converged");
    group.sample_size(10);
    group.bench_function("aluminium_90s", |b| {
        b.iter(|| simulate_contact_converged(&skin, &aluminium, &config, &spec, &Refinement::default()))
    });
    group.finish();
}

fn contact_by_level(c: &mut Criterion) {
    let skin = Skin::fingertip();
    let aluminium = materials::find("aluminium").expect("aluminium is in the library");
    let spec = ContactSpec {
        duration_s: 90.0,
        output_dt_s: 0.01,
        ..ContactSpec::default()
    };
    let mut group = c.benchmark_group("fv_contact_aluminium_90s");
    group.sample_size(10);
    for level in 0..=4 {
        let config = FvConfig {
            contact_resistance_m2k_w: 1e-3,
            ..FvConfig::default()
        }
        .refined(level);
        group.bench_function(format!("level_{level}"), |b| {
            b.iter(|| simulate_contact(&skin, &aluminium, black_box(&config), &spec))
        });
    }
    group.finish();
}

criterion_group!(benches, steps, converged_run, contact_by_level);
criterion_main!(benches);
