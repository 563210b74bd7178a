//! The start-up self-test of a rendered display ([`thermode_pipeline::self_test`]): run on the plant's hardware with
//! no finger on it, at rest at the water's temperature, as a display is tested at power-on before a finger rests on
//! it. The run's timeline then starts from its own resting plant with the finger (the display had long settled
//! again). A plant built from the pipeline's own device file is that file exactly and is not tested.

use thermode_device::{Device, NoFinger, SimulatedDisplay};
use thermode_pipeline::controllers::plant_model;
use thermode_pipeline::self_test::{assess, SelfTest, SelfTestReport, SelfTestSample};
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
    let test = SelfTest::default();
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
    let ticks = (test.record_s / dt_s).round() as usize;
    let mut record = Vec::with_capacity(ticks);
    for k in 0..ticks {
        let t_s = k as f64 * dt_s;
        envelope.observe(&plant.read(0)?.measurement());
        let drive = envelope.gate_drive(start_s + t_s, test.current_at_a(t_s), &MeasuredOnly);
        plant.apply(0, &drive)?;
        for _ in 0..substeps {
            plant.advance(dt_s / substeps as f64);
        }
        let reading = plant.read(0)?;
        record.push(SelfTestSample {
            dt_s,
            current_a: drive.current_a(),
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
        });
    }
    let model = plant_model(&believed)?;
    let uncertainty = believed.render.sensor_lag_uncertainty;
    Ok(Some(assess(&model, uncertainty, &record)))
}
