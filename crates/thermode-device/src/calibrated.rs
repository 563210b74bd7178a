//! [`CalibratedDevice`]: a real display whose plate sensor reads through its calibration
//! ([`crate::config::CalibrationConfig`], written by `thermode calibrate`): every reading's plate temperature is the
//! calibrated one, so the envelope, the controller and every record act on it. A device that regulates its plate
//! itself (temperature-commanded) does so on its own, uncalibrated reading: the set-point it is sent is put on that
//! reading's scale ([`DriveCommand::on_sensor_scale`]), so its regulation brings the true plate to the envelope's
//! set-point.

use std::sync::Arc;

use thermode_model::BadValue;
use thermode_safety::DriveCommand;

use crate::config::CalibrationConfig;
use crate::device::{Device, DevicePart, Measures, Reading};
use crate::error::DeviceError;
use crate::link::LinkHealth;

/// See the module documentation.
pub struct CalibratedDevice {
    inner: Box<dyn Device + Send>,
    /// Per channel; channels past the list take its last entry.
    calibrations: Vec<CalibrationConfig>,
}

impl CalibratedDevice {
    /// `inner` read through `calibration` on every channel.
    pub fn new(inner: Box<dyn Device + Send>, calibration: CalibrationConfig) -> Self {
        CalibratedDevice {
            inner,
            calibrations: vec![calibration],
        }
    }

    /// `inner` with channel `i` read through `calibrations[i]` (a display of several devices, each with its own
    /// device file; channels past the list take its last entry, none: uncalibrated).
    pub fn per_channel(inner: Box<dyn Device + Send>, calibrations: Vec<CalibrationConfig>) -> Self {
        CalibratedDevice { inner, calibrations }
    }

    /// The calibration of `channel`.
    fn calibration(&self, channel: usize) -> CalibrationConfig {
        self.calibrations
            .get(channel)
            .or(self.calibrations.last())
            .copied()
            .unwrap_or_default()
    }
}

impl Device for CalibratedDevice {
    fn channel_count(&self) -> usize {
        self.inner.channel_count()
    }

    /// The command, with its set-point on the sensor's reading scale for a temperature-commanded device.
    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        if self.inner.measures().drive_current || command.setpoint_c().is_none() {
            return self.inner.apply(channel, command);
        }
        let calibration = self.calibration(channel);
        let (gain, offset_c) = (calibration.sensor_gain, calibration.sensor_offset_c);
        let scaled = command.on_sensor_scale(gain, offset_c).ok_or_else(|| {
            BadValue::custom(
                "calibration sensor_gain",
                gain,
                "must be from 0.5 to 2 (offset within ±10 °C)",
            )
        })?;
        self.inner.apply(channel, &scaled)
    }

    /// The inner reading with its plate temperature calibrated (a reading that is not finite stays as it is).
    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        let mut reading = self.inner.read(channel)?;
        if reading.sensor_c.is_finite() {
            reading.sensor_c = self.calibration(channel).plate_c(reading.sensor_c);
        }
        Ok(reading)
    }

    fn poll(&mut self, now_s: f64) {
        self.inner.poll(now_s);
    }

    fn all_off(&mut self) -> Result<(), DeviceError> {
        self.inner.all_off()
    }

    fn link_health(&self) -> Option<Arc<LinkHealth>> {
        self.inner.link_health()
    }

    fn measures(&self) -> Measures {
        self.inner.measures()
    }

    fn identity(&self) -> Option<String> {
        self.inner.identity()
    }

    fn parts(&self) -> Vec<DevicePart> {
        self.inner.parts()
    }
}
