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

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use thermode_safety::{EnvelopeConfig, MeasuredOnly, Measurement, SafetyEnvelope};

    use super::*;

    /// A temperature-commanded device of two channels whose plates read 30 °C; it keeps the set-points it is sent.
    struct Regulating(Arc<Mutex<Vec<Option<f64>>>>);

    impl Device for Regulating {
        fn channel_count(&self) -> usize {
            2
        }
        fn apply(&mut self, _channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
            self.0
                .lock()
                .map_err(|_| BadValue::custom("lock", 0.0, "poisoned"))?
                .push(command.setpoint_c());
            Ok(())
        }
        fn read(&mut self, _channel: usize) -> Result<Reading, DeviceError> {
            Ok(Reading {
                sensor_c: 30.0,
                hot_side_c: 25.0,
                time_s: 0.0,
                sample_seq: 1,
                current_a: f64::NAN,
                voltage_v: f64::NAN,
                heating_limit_a: f64::INFINITY,
            })
        }
        fn poll(&mut self, _now_s: f64) {}
        fn measures(&self) -> Measures {
            Measures {
                drive_current: false,
                hot_side: true,
            }
        }
    }

    /// The envelope's set-point goes out on each channel's sensor scale (`gain · T + offset`), and each channel's
    /// reading comes back through its own calibration.
    #[test]
    fn a_temperature_commanded_device_gets_its_set_points_on_the_sensors_scale() {
        let sent = Arc::new(Mutex::new(Vec::new()));
        let calibrations = vec![
            CalibrationConfig {
                sensor_gain: 1.01,
                sensor_offset_c: 0.3,
                ..CalibrationConfig::default()
            },
            CalibrationConfig::default(),
        ];
        let mut device = CalibratedDevice::per_channel(Box::new(Regulating(Arc::clone(&sent))), calibrations);
        let mut envelope = SafetyEnvelope::new(EnvelopeConfig::default(), 2.8).expect("envelope");
        let reading = device.read(0).expect("reading");
        envelope.observe(&Measurement {
            time_s: 0.01,
            ..reading.measurement()
        });
        envelope.shape_setpoint(0.02, 35.0);
        let command = envelope.gate_drive(0.02, 0.0, &MeasuredOnly);
        let setpoint_c = command.setpoint_c().expect("a shaped set-point");
        device.apply(0, &command).expect("apply 0");
        device.apply(1, &command).expect("apply 1");
        let sent = sent.lock().expect("lock").clone();
        let want_c = 1.01 * setpoint_c + 0.3;
        assert!(
            (sent[0].unwrap_or(f64::NAN) - want_c).abs() < 1e-12,
            "channel 0 sent {:?}, want {want_c} (set-point {setpoint_c})",
            sent[0]
        );
        assert_eq!(sent[1], Some(setpoint_c), "channel 1 is uncalibrated");
        let read_c = device.read(0).expect("read").sensor_c;
        assert!((read_c - (30.0 - 0.3) / 1.01).abs() < 1e-12, "channel 0 reads {read_c}");
        assert_eq!(device.read(1).expect("read").sensor_c, 30.0);
        assert!(
            command.on_sensor_scale(2.5, 0.0).is_none(),
            "a gain beyond 2 is refused"
        );
    }
}
