//! Criterion bench: channel-steps per second of the full pipeline — renderer, display inverse, controller, safety
//! envelope and the simulated plant — for the kron and fv renderers and both controllers, at a 1 ms tick (the
//! plant advanced once per tick), the finger touching aluminium. The plant's finger is the finite-volume finger
//! (the reference physics, as `thermode render` uses it) and, for the cheapest configuration, the paper's Kron
//! finger. The pipeline alone (without the plant) is measured too, to show where the time goes.
//!
//! The group `physics_true` is the physics-true pipeline — fv renderer, fv display finger and the fv finger on the
//! plant — before and after the modal fast path: `*_full_fv` steps the full finite-volume model in all three
//! (`PipelineConfig::fv_fast_path = None`, the plant's finger an `FvModel`), `*_modal` uses the fast path in all three
//! (the plant's finger a `ModalFv`). The other groups use the pipeline's default (fast path on) with an `FvModel`
//! or Kron finger on the plant.
#![allow(missing_docs)] // criterion_main! generates an undocumented `main`

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use thermode_device::{default_finger, Device, DeviceConfig, PlateFinger, SimulatedDisplay};
use thermode_model::fv::{FvModel, ModalFv, ModalStepping};
use thermode_model::kron::KronModel;
use thermode_pipeline::{ChannelPipeline, ControllerKind, PipelineConfig, RendererKind, ShippedDisplay, Stimulus};

const STEPS: u64 = 1000;
const DT_S: f64 = 1e-3;

fn pipeline(renderer: RendererKind, controller: ControllerKind) -> ChannelPipeline {
    pipeline_with(renderer, controller, Some(ModalStepping::Exact))
}

/// The pipeline touching aluminium, with the fv fast path on or off.
fn pipeline_with(
    renderer: RendererKind,
    controller: ControllerKind,
    fv_fast_path: Option<ModalStepping>,
) -> ChannelPipeline {
    let mut config = PipelineConfig::new(DeviceConfig::default(), controller);
    config.renderer = renderer;
    config.fv_fast_path = fv_fast_path;
    let mut pipeline = ChannelPipeline::new(&config).unwrap_or_else(|e| panic!("{e}"));
    let aluminium = thermode_model::materials::find("aluminium").unwrap_or_else(|e| panic!("{e}"));
    pipeline
        .set_stimulus(Stimulus::Touch {
            material: aluminium,
            object_c: 23.0,
        })
        .unwrap_or_else(|e| panic!("{e}"));
    pipeline
}

fn plant<F: PlateFinger>(finger: F) -> SimulatedDisplay<F> {
    let mut plant = SimulatedDisplay::new(&DeviceConfig::default(), vec![finger], 1).unwrap_or_else(|e| panic!("{e}"));
    plant
        .channel_mut(0)
        .and_then(|c| c.set_temperatures(31.9, 23.0))
        .unwrap_or_else(|e| panic!("{e}"));
    plant.advance(0.01);
    plant
}

fn controllers() -> [(&'static str, ControllerKind); 2] {
    let gains = ShippedDisplay::Default.gains().unwrap_or_else(|e| panic!("{e}"));
    [("pid", ControllerKind::Pid(gains)), ("model", ControllerKind::Model)]
}

fn full_loop<F: PlateFinger>(
    c: &mut Criterion,
    name: &str,
    renderer: RendererKind,
    controller: ControllerKind,
    finger: F,
) {
    closed_loop(c, "pipeline_and_plant", name, pipeline(renderer, controller), finger);
}

/// `STEPS` ticks of `pipeline` closed over the simulated display with `finger` on it, in `group_name`.
fn closed_loop<F: PlateFinger>(
    c: &mut Criterion,
    group_name: &str,
    name: &str,
    mut pipeline: ChannelPipeline,
    finger: F,
) {
    let mut plant = plant(finger);
    let mut now_s = plant.time_s();
    let mut group = c.benchmark_group(group_name);
    group.throughput(Throughput::Elements(STEPS));
    group.bench_function(name, |b| {
        b.iter(|| {
            for _ in 0..STEPS {
                let Ok(reading) = plant.read(0) else { return };
                let (drive, telemetry) = pipeline.tick(now_s, DT_S, &reading);
                let _ = plant.apply(0, &drive);
                plant.advance(DT_S);
                now_s += DT_S;
                black_box(telemetry.skin_c);
            }
        });
    });
    group.finish();
}

/// The pipeline alone on readings of a plate that is not stepped: a fresh PT-100 sample every `sample_every`
/// ticks (10: the file's 100 Hz at the 1 ms tick, the sample held in between as a real PT-100 gives it; 1: a fresh
/// sample every tick, the costliest case for the plate guard, which corrects once per sample).
fn pipeline_only(c: &mut Criterion, name: &str, renderer: RendererKind, controller: ControllerKind, sample_every: u64) {
    let mut pipeline = pipeline(renderer, controller);
    let mut plant = plant(default_finger().unwrap_or_else(|e| panic!("{e}")));
    let mut now_s = plant.time_s();
    let mut reading = plant.read(0).unwrap_or_else(|e| panic!("{e}"));
    let mut tick = 0_u64;
    let mut group = c.benchmark_group("pipeline_only");
    group.throughput(Throughput::Elements(STEPS));
    group.bench_function(name, |b| {
        b.iter(|| {
            for _ in 0..STEPS {
                if tick.is_multiple_of(sample_every) {
                    reading.time_s = now_s;
                    reading.sample_seq += 1;
                }
                tick += 1;
                let (drive, telemetry) = pipeline.tick(now_s, DT_S, &reading);
                now_s += DT_S;
                black_box((drive.current_a(), telemetry.skin_c));
            }
        });
    });
    group.finish();
}

/// The physics-true pipeline before (full fv everywhere) and after (modal fast path everywhere).
fn physics_true(c: &mut Criterion) {
    for (controller_name, controller) in controllers() {
        let full = FvModel::fingertip().unwrap_or_else(|e| panic!("{e}"));
        let before = pipeline_with(RendererKind::Fv, controller, None);
        closed_loop(c, "physics_true", &format!("{controller_name}_full_fv"), before, full);
        let modal = ModalFv::fingertip().unwrap_or_else(|e| panic!("{e}"));
        let after = pipeline_with(RendererKind::Fv, controller, Some(ModalStepping::Exact));
        closed_loop(c, "physics_true", &format!("{controller_name}_modal"), after, modal);
    }
}

fn benches(c: &mut Criterion) {
    physics_true(c);
    for (controller_name, controller) in controllers() {
        for (renderer_name, renderer) in [("kron", RendererKind::Kron), ("fv", RendererKind::Fv)] {
            let name = format!("{renderer_name}_renderer_{controller_name}_fv_plant");
            let finger = default_finger().unwrap_or_else(|e| panic!("{e}"));
            full_loop(c, &name, renderer, controller, finger);
            let name = format!("{renderer_name}_renderer_{controller_name}");
            pipeline_only(c, &name, renderer, controller, 10);
            pipeline_only(c, &format!("{name}_fresh_every_tick"), renderer, controller, 1);
        }
        let finger = <KronModel as PlateFinger>::fingertip().unwrap_or_else(|e| panic!("{e}"));
        let name = format!("kron_renderer_{controller_name}_kron_plant");
        full_loop(c, &name, RendererKind::Kron, controller, finger);
    }
}

criterion_group!(pipeline_benches, benches);
criterion_main!(pipeline_benches);
