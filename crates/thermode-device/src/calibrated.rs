//! [`CalibratedDevice`]: a real display whose plate sensor reads through its calibration
//! ([`crate::config::CalibrationConfig`], written by `thermode calibrate`): every reading's plate temperature is the
//! calibrated one, so the envelope, the controller and every record act on it. Only for current-commanded devices:
//! a device that regulates its plate itself does so on its own, uncalibrated reading.

use std::sync::Arc;

use thermode_safety::DriveCommand;

use crate::config::CalibrationConfig;
use crate::device::{Device, DevicePart, Measures, Reading};
use crate::error::DeviceError;
use crate::link::LinkHealth;

/// See the module documentation.
pub struct CalibratedDevice {
    inner: Box<dyn Device + Send>,
    calibration: CalibrationConfig,
}

impl CalibratedDevice {
    /// `inner` read through `calibration`.
    pub fn new(inner: Box<dyn Device + Send>, calibration: CalibrationConfig) -> Self {
        CalibratedDevice { inner, calibration }
    }
}

impl Device for CalibratedDevice {
    fn channel_count(&self) -> usize {
        self.inner.channel_count()
    }

    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        self.inner.apply(channel, command)
    }

    /// The inner reading with its plate temperature calibrated (a reading that is not finite stays as it is).
    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        let mut reading = self.inner.read(channel)?;
        if reading.sensor_c.is_finite() {
            reading.sensor_c = self.calibration.plate_c(reading.sensor_c);
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

    fn parts(&self) -> Vec<DevicePart> {
        self.inner.parts()
    }
}
