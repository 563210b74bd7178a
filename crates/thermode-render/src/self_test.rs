//! The start-up self-test of a rendered display ([`thermode_pipeline::self_test`]), the daemon's own
//! ([`SelfTestRun`]): run on the plant's hardware with no finger on it, at rest at the water's temperature, as a
//! display is tested at power-on before a finger rests on it. The run's timeline then starts from its own resting
//! plant with the finger (the display had long settled again). A plant built from the pipeline's own device file is
//! that file exactly and is not tested.

use thermode_device::{Device, NoFinger, SimulatedDisplay};
use thermode_pipeline::controllers::plant_model;
use thermode_pipeline::self_test::{SelfTest, SelfTestReport, SelfTestRun, REST_LIMIT_S};
use thermode_pipeline::ChannelPipeline;
use thermode_safety::{MeasuredOnly, SafetyEnvelope};

use crate::error::RenderError;
use crate::spec::RenderSpec;

/// The self-test of `spec`'s plant hardware (no finger on it) against the device file `pipeline` was built for, or
/// `None` when the plant is built from that file. Every pulse passes a safety envelope of the pipeline's limits.
pub fn self_test(spec: &RenderSpec, pipeline: &ChannelPipeline) -> Result<Option<SelfTestReport>, RenderError> {
    if spec.hardware.is_none() {
        return Ok(None);
    }
    let believed = spec.believed_pipeline().device;
    let model = plant_model(&believed)?;
    let test = SelfTest::for_sensor(model.sensor_time_constant_s);
    let longest_s = REST_LIMIT_S + test.record_s;
    let mut run = SelfTestRun::new(test, model, believed.render.sensor_lag_uncertainty);
    let hardware = spec.plant_device();
    let mut plant = SimulatedDisplay::new(
        &hardware,
        vec![NoFinger],
        crate::spec::noise_seed(spec.seed, "self-test"),
    )?;
    let water_c = hardware.ambient.water_c;
    plant.channel_mut(0)?.set_temperatures(water_c, water_c)?;
    let envelope = pipeline.envelope();
    let mut envelope = SafetyEnvelope::new(*envelope.config(), envelope.current_limit_a())?;
    let (dt_s, substeps) = (spec.tick_s(), spec.substeps());
    let start_s = plant.time_s();
    let mut applied_a = 0.0;
    for k in 0..(longest_s / dt_s).ceil() as usize {
        let now_s = start_s + k as f64 * dt_s;
        if run.finished(now_s) {
            break;
        }
        let reading = plant.read(0)?;
        envelope.observe(&reading.measurement());
        let requested_a = run.tick(now_s, dt_s, applied_a, &reading);
        let drive = envelope.gate_drive(now_s, requested_a, &MeasuredOnly);
        applied_a = drive.current_a();
        plant.apply(0, &drive)?;
        for _ in 0..substeps {
            plant.advance(dt_s / substeps as f64);
        }
    }
    Ok(Some(run.report()))
}
