//! [`Reading`]: one reading of a channel's sensors, as every device gives it (and as a device's own cut carries it,
//! `crate::DeviceError::Cut`).

use thermode_safety::Measurement;

/// One reading of a channel's sensors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// Display (plate) temperature from the PT-100 \[°C\]: lagged, noisy, quantised, held between samples; fault
    /// values when the sensor is open or shorted.
    pub sensor_c: f64,
    /// Hot-side temperature from the box sensor \[°C\].
    pub hot_side_c: f64,
    /// When the PT-100 sample was taken \[s\] (device clock: the loop time of the last [`crate::Device::poll`], or the sum of the steps of `SimulatedDisplay::advance`).
    pub time_s: f64,
    /// Sequence number of the PT-100 sample; it stops advancing when the sensor is stale.
    pub sample_seq: u64,
    /// The current the drive delivered over the interval that ends at this reading's sample \[A\] (its own
    /// measurement).
    pub current_a: f64,
    /// The voltage across the Peltier module \[V\] (its own measurement; NaN when the device does not report it).
    /// `thermode identify` needs it: it fixes the absolute scale of the module's parameters.
    pub voltage_v: f64,
    /// The largest heating current the device delivers now \[A\], whatever it is sent: its own second line where the
    /// host keeps one on it (a MeCom controller's current limitation, which shrinks as the plate warms,
    /// `thermode_link::mecom::line`); infinite for a device without one. The pipeline asks no more, so that its
    /// models integrate the current the plate receives.
    pub heating_limit_a: f64,
}

impl Reading {
    /// The reading as the safety envelope takes it.
    pub fn measurement(&self) -> Measurement {
        Measurement {
            time_s: self.time_s,
            sensor_c: self.sensor_c,
            hot_side_c: self.hot_side_c,
            sample_seq: self.sample_seq,
        }
    }
}
