//! Helpers shared by the integration tests: materials, shipped displays, render specs, and a closed loop of one
//! pipeline on the simulated display that records every tick with the plant's true state.

#![allow(dead_code)]

use thermode_device::{Device, DeviceConfig, Reading};
use thermode_model::materials;
use thermode_model::Material;
use thermode_pipeline::{ChannelPipeline, ControllerKind, PipelineConfig, ShippedDisplay, Telemetry};
use thermode_render::run::{resting_plant, Plant};
use thermode_render::RenderSpec;
use thermode_safety::FaultCode;

/// A material of the library.
pub fn material(name: &str) -> Material {
    materials::find(name).unwrap_or_else(|e| panic!("{e}"))
}

/// The device of a shipped display.
pub fn device(display: ShippedDisplay) -> DeviceConfig {
    display.device().unwrap_or_else(|e| panic!("{e}"))
}

/// The default device file with `edit` applied, Q_max and the drive limit kept consistent with the module (a
/// simulated display that is not its file, for `RenderSpec::hardware`).
pub fn plant_off_file(edit: impl Fn(&mut DeviceConfig)) -> DeviceConfig {
    let mut plant = DeviceConfig::default();
    edit(&mut plant);
    plant.peltier.qmax_w = plant.peltier.predicted_qmax_w();
    plant.drive.current_limit_a = plant.drive.current_limit_a.min(plant.peltier.imax_a);
    plant
}

/// The paper's PID with the tuned gains of `display`.
pub fn pid(display: ShippedDisplay) -> ControllerKind {
    ControllerKind::Pid(display.gains().unwrap_or_else(|e| panic!("{e}")))
}

/// The render spec of `material` on `display` with `controller`, defaults otherwise.
pub fn spec(display: ShippedDisplay, controller: ControllerKind, material_name: &str) -> RenderSpec {
    RenderSpec::new(
        PipelineConfig::new(device(display), controller),
        material(material_name),
    )
}

/// One tick of a closed loop with the plant's true state after it.
#[derive(Debug, Clone, Copy)]
pub struct Tick {
    /// The tick's time (device clock) [s].
    pub now_s: f64,
    /// The reading the tick used.
    pub sensor_c: f64,
    /// What the pipeline reported.
    pub telemetry: Telemetry,
    /// The gated drive [A].
    pub current_a: f64,
    /// The latched fault.
    pub fault: Option<FaultCode>,
    /// True plate after the tick [°C].
    pub plate_c: f64,
    /// True hot side after the tick [°C].
    pub hot_side_c: f64,
    /// The envelope's effective maximum and minimum at the tick [°C].
    pub max_c: f64,
    /// Minimum [°C].
    pub min_c: f64,
}

/// A pipeline and the resting plant of `spec`, ticking at the spec's rate with its substeps.
pub struct Loop {
    pub pipeline: ChannelPipeline,
    pub plant: Plant,
    pub dt_s: f64,
    pub substeps: usize,
    pub ticks: usize,
    start_s: f64,
}

impl Loop {
    pub fn new(spec: &RenderSpec) -> Self {
        let pipeline = ChannelPipeline::new(&spec.believed_pipeline()).unwrap_or_else(|e| panic!("{e}"));
        let plant = resting_plant(spec).unwrap_or_else(|e| panic!("{e}"));
        let start_s = plant.time_s();
        let substeps = ((spec.tick_s() / spec.plant_substep_s) - 1e-9).ceil().max(1.0) as usize;
        Loop {
            pipeline,
            plant,
            dt_s: spec.tick_s(),
            substeps,
            ticks: 0,
            start_s,
        }
    }

    /// Time of the next tick (device clock) [s].
    pub fn now_s(&self) -> f64 {
        self.start_s + self.ticks as f64 * self.dt_s
    }

    /// One tick with the plant's reading, then the plant advanced.
    pub fn tick(&mut self) -> Tick {
        self.tick_with(self.dt_s, |r| r)
    }

    /// One tick with the reading changed by `edit` and the time step `dt_s`, then the plant advanced by the
    /// loop's tick.
    pub fn tick_with(&mut self, dt_s: f64, edit: impl FnOnce(Reading) -> Reading) -> Tick {
        let now_s = self.now_s();
        let reading = edit(self.plant.read(0).unwrap_or_else(|e| panic!("{e}")));
        let (max_c, min_c) = (
            self.pipeline.envelope().effective_max_c(),
            self.pipeline.envelope().min_c(),
        );
        let (drive, telemetry) = self.pipeline.tick(now_s, dt_s, &reading);
        let current_a = drive.current_a();
        let fault = drive.fault();
        self.plant.apply(0, &drive).unwrap_or_else(|e| panic!("{e}"));
        let h = self.dt_s / self.substeps as f64;
        for _ in 0..self.substeps {
            self.plant.advance(h);
        }
        self.ticks += 1;
        let state = *self.plant.channel(0).unwrap_or_else(|e| panic!("{e}")).state();
        Tick {
            now_s,
            sensor_c: reading.sensor_c,
            telemetry,
            current_a,
            fault,
            plate_c: state.plate_c,
            hot_side_c: state.hot_side_c,
            max_c,
            min_c,
        }
    }

    /// `n` ticks.
    pub fn run(&mut self, n: usize) -> Vec<Tick> {
        (0..n).map(|_| self.tick()).collect()
    }
}
