//! `thermode identify` on the simulated display: an excitation inside the safety envelope with no finger on the
//! plate, recorded, and the device file's thermal parameters fitted to it ([`thermode_control::identify`]).
//!
//! **Excitation** ([`excitation`]): the pipeline in direct mode (every current through the controller and the
//! safety envelope) is taken from rest to 32 °C, through steps between 20 and 40 °C (below 43 °C, so no thermal dose
//! accrues) and a pseudo-random binary sequence of ±5 °C around 30 °C (one-second bits from a 16-bit LFSR), 160 s in
//! all. The plate is bare ([`NoFinger`]).
//!
//! **Result**: the fitted S, R, K become a datasheet quoted at the believed file's hot-side temperature
//! ([`PeltierDatasheet::from_module`]); the capacities, the water conductance and temperature and the sensor's time
//! constant replace the believed file's; the module's uncertainty (`render.peltier_uncertainty`) becomes the fit's
//! (three of the largest standard deviation of S, R, K, at least [`MIN_IDENTIFIED_UNCERTAINTY`]), and so does the
//! plate's (`render.plate_uncertainty`, from the plate capacity's standard deviation), the hot side's
//! (`render.hot_side_uncertainty`, from its capacity's and water conductance's) and the sensor's
//! (`render.sensor_lag_uncertainty`, from the time constant's, at least the self-test's own error
//! [`thermode_device::config::SELF_TEST_LAG_ERROR`]); everything else (sensor noise and rate, contact, the render
//! rate limit) is kept, and the drive limit too unless it exceeds the identified I_max (a device file bounds it by
//! I_max).

use thermode_control::identify::{identify, IdSample, Identification, IdentifyError};
use thermode_device::config::verified_lag_uncertainty;
use thermode_device::{Device, DeviceConfig, NoFinger, Reading, SimulatedDisplay};
use thermode_model::peltier::PeltierDatasheet;
use thermode_pipeline::{controllers::plant_model, ChannelPipeline, ControllerKind, PipelineConfig, Stimulus};
use thermode_safety::DriveCommand;

use crate::error::RenderError;

/// Tick rate of the excitation \[Hz\]: 100 (the PT-100's rate).
pub const RATE_HZ: f64 = 100.0;
/// Plant substeps per tick: 10.
const SUBSTEPS: usize = 10;
/// Length of the excitation \[s\]: 160.
pub const DURATION_S: f64 = 160.0;
/// Rate of the direct set-point steps \[°C/s\]: 10.
const STEP_RATE_C_PER_S: f64 = 10.0;

/// The direct set-points of the excitation: `(from time [s], temperature [°C])`, in order.
pub fn excitation() -> Vec<(f64, f64)> {
    let mut steps = vec![
        (0.0, 32.0),
        (15.0, 20.0),
        (30.0, 40.0),
        (45.0, 28.0),
        (60.0, 38.0),
        (75.0, 24.0),
        (90.0, 34.0),
    ];
    let mut lfsr: u16 = 0xACE1;
    for bit in 0..60 {
        // x¹⁶ + x¹⁴ + x¹³ + x¹¹ + 1, maximal length.
        let feedback = (lfsr ^ (lfsr >> 2) ^ (lfsr >> 3) ^ (lfsr >> 5)) & 1;
        lfsr = (lfsr >> 1) | (feedback << 15);
        let level = if lfsr & 1 == 1 { 35.0 } else { 25.0 };
        steps.push((100.0 + bit as f64, level));
    }
    steps
}

/// The excitation tick by tick on the pipeline of `believed` (the device file the controller knows): for a
/// simulated display ([`record`]) or a real one in real time (`thermode identify --device`).
pub struct Excitation {
    pipeline: ChannelPipeline,
    schedule: Vec<(f64, f64)>,
    next_step: usize,
    /// The clock time of the first tick \[s\]: the schedule's zero.
    start_s: Option<f64>,
}

impl Excitation {
    /// The excitation of [`excitation`] on a fresh pipeline with the model controller.
    pub fn new(believed: &DeviceConfig) -> Result<Excitation, RenderError> {
        Ok(Excitation {
            pipeline: ChannelPipeline::new(&PipelineConfig::new(*believed, ControllerKind::Model))?,
            schedule: excitation(),
            next_step: 0,
            start_s: None,
        })
    }

    /// The gated drive for the tick at `now_s` \[s\] (the clock of the readings' `time_s`; the first tick is the
    /// schedule's zero) of `dt_s` \[s\] with `reading`; a fault is an error (the drive is then off).
    pub fn tick(&mut self, now_s: f64, dt_s: f64, reading: &Reading) -> Result<DriveCommand, RenderError> {
        let since_s = now_s - *self.start_s.get_or_insert(now_s);
        while let Some(&(_, temp_c)) = self.schedule.get(self.next_step).filter(|s| s.0 <= since_s) {
            self.pipeline.set_stimulus(Stimulus::Direct {
                temp_c,
                rate_c_per_s: STEP_RATE_C_PER_S,
            })?;
            self.next_step += 1;
        }
        let (drive, _) = self.pipeline.tick(now_s, dt_s, reading);
        match drive.fault() {
            Some(fault) => Err(RenderError::Invalid(format!(
                "identification: the display faulted at {now_s:.2} s: {fault}"
            ))),
            None => Ok(drive),
        }
    }
}

/// The record sample of a reading.
pub fn sample_of(reading: &Reading) -> IdSample {
    IdSample {
        current_a: reading.current_a,
        sensor_c: reading.sensor_c,
        hot_side_c: reading.hot_side_c,
        voltage_v: reading.voltage_v,
    }
}

/// Runs the excitation for `duration_s` \[s\] on a simulated display built from `plant` (the hidden hardware)
/// with the pipeline of `believed`, sensor noise seeded by `seed`; returns the record.
pub fn record(
    believed: &DeviceConfig,
    plant: &DeviceConfig,
    seed: u64,
    duration_s: f64,
) -> Result<Vec<IdSample>, RenderError> {
    let invalid = |e: &dyn std::fmt::Display| RenderError::Invalid(format!("identification: {e}"));
    let mut display = SimulatedDisplay::<NoFinger>::fingertips(plant, 1, seed).map_err(|e| invalid(&e))?;
    let mut excitation = Excitation::new(believed)?;
    let dt_s = 1.0 / RATE_HZ;
    let ticks = (duration_s * RATE_HZ).round() as usize;
    let mut samples = Vec::with_capacity(ticks + 1);
    let first = display.read(0).map_err(|e| invalid(&e))?;
    samples.push(IdSample {
        current_a: 0.0,
        ..sample_of(&first)
    });
    for tick in 0..ticks {
        let reading = display.read(0).map_err(|e| invalid(&e))?;
        let drive = excitation.tick(tick as f64 * dt_s, dt_s, &reading)?;
        display.apply(0, &drive).map_err(|e| invalid(&e))?;
        for _ in 0..SUBSTEPS {
            display.advance(dt_s / SUBSTEPS as f64);
        }
        samples.push(sample_of(&display.read(0).map_err(|e| invalid(&e))?));
    }
    Ok(samples)
}

/// The device file of an identification: `believed` with the fitted values (see the module documentation).
pub fn identified_device(believed: &DeviceConfig, fit: &Identification) -> Result<DeviceConfig, IdentifyError> {
    let p = &fit.plant;
    let peltier = PeltierDatasheet::from_module(&p.module, believed.peltier.hot_side_k).ok_or_else(|| {
        IdentifyError::Record("the fitted module gives no datasheet (no ΔT_max between 0 and T_h)".into())
    })?;
    let mut device = *believed;
    device.peltier = peltier;
    device.plate.heat_capacity_j_k = p.plate_heat_capacity_j_k;
    device.hot_side.heat_capacity_j_k = p.hot_heat_capacity_j_k;
    device.hot_side.water_conductance_w_k = p.water_conductance_w_k;
    device.ambient.water_c = p.water_c;
    device.sensor.time_constant_s = p.sensor_time_constant_s;
    device.render.peltier_uncertainty = identified_uncertainty(&fit.relative_sd[..3]);
    device.render.plate_uncertainty = identified_uncertainty(&fit.relative_sd[3..4]);
    device.render.hot_side_uncertainty = identified_uncertainty(&fit.relative_sd[4..6]);
    // The lag's uncertainty at least the self-test's own error, which judges the file at every start.
    device.render.sensor_lag_uncertainty = verified_lag_uncertainty(identified_uncertainty(&fit.relative_sd[7..8]));
    // The drive's limit is the drive's, not fitted; a device file bounds it by the module's I_max.
    device.drive.current_limit_a = device.drive.current_limit_a.min(device.peltier.imax_a);
    Ok(device)
}

/// The smallest relative uncertainty an identified module is given \[-\]: 0.02 (the fit's standard deviations
/// say how well the record fixes the model's parameters, not how well the model describes the display; over the
/// MeCom emulator in real time the parameters came out within 2–3 %).
pub const MIN_IDENTIFIED_UNCERTAINTY: f64 = 0.02;

/// The relative uncertainty of identified parameters (the module's S, R and K; the plate's capacity) from their
/// relative standard deviations: three of the largest, at least [`MIN_IDENTIFIED_UNCERTAINTY`], at most 1.
fn identified_uncertainty(relative_sd: &[f64]) -> f64 {
    let largest_sd = relative_sd.iter().copied().fold(0.0, f64::max);
    if largest_sd.is_finite() {
        (3.0 * largest_sd).clamp(MIN_IDENTIFIED_UNCERTAINTY, 1.0)
    } else {
        1.0
    }
}

/// Fits `believed` to `samples` (one every 1/[`RATE_HZ`] s) and makes the identified device file.
pub fn fit(believed: &DeviceConfig, samples: &[IdSample]) -> Result<(Identification, DeviceConfig), RenderError> {
    let initial = plant_model(believed)?;
    let fit = identify(samples, &initial, 1.0 / RATE_HZ).map_err(|e| RenderError::Invalid(e.to_string()))?;
    let device = identified_device(believed, &fit).map_err(|e| RenderError::Invalid(e.to_string()))?;
    Ok((fit, device))
}

/// Records the whole excitation on the simulated display of `plant` and fits `believed` to it.
pub fn identify_simulated(
    believed: &DeviceConfig,
    plant: &DeviceConfig,
    seed: u64,
) -> Result<(Identification, DeviceConfig), RenderError> {
    fit(believed, &record(believed, plant, seed, DURATION_S)?)
}
