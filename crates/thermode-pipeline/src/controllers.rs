//! Choosing and building a channel's controller: the paper's `pid` with gains from a gains file (the tuned files for
//! the three shipped displays are embedded), or thermode's `model` controller with its plant model filled from the
//! device file.
//!
//! A gains file is the TOML form of [`PidGains`] (`kp_a_per_c`, `ki_a_per_c_s`, `kd_a_s_per_c`, `filter_cutoff_hz`,
//! optional `derivative_filter_s`); comments are allowed, unknown keys are refused. `thermode tune` writes them.

use thermode_control::{Controller, ModelController, ModelDesign, ObserverDesign, PidController, PidGains, PlantModel};
use thermode_device::{DeviceConfig, DEFAULT_DEVICE_TOML, LAGGING_SENSOR_DEVICE_TOML, WEAK_COOLING_DEVICE_TOML};

use crate::error::PipelineError;

/// Tuned PID gains of the default display (`gains/default.toml`, written by `thermode tune`).
pub const DEFAULT_GAINS_TOML: &str = include_str!("../gains/default.toml");
/// Tuned PID gains of the weakly cooled display (`gains/weak-cooling.toml`).
pub const WEAK_COOLING_GAINS_TOML: &str = include_str!("../gains/weak-cooling.toml");
/// Tuned PID gains of the display with the lagging sensor (`gains/lagging-sensor.toml`).
pub const LAGGING_SENSOR_GAINS_TOML: &str = include_str!("../gains/lagging-sensor.toml");

/// The displays whose device files ship with thermode (`thermode-device/devices/`), each with tuned PID gains.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShippedDisplay {
    /// `default.toml`: the paper's hardware as closely as the paper allows.
    Default,
    /// `weak-cooling.toml`: a third of the default water conductance.
    WeakCooling,
    /// `lagging-sensor.toml`: the PT-100 lags by 1.5 s.
    LaggingSensor,
}

impl ShippedDisplay {
    /// All shipped displays.
    pub const ALL: [ShippedDisplay; 3] = [
        ShippedDisplay::Default,
        ShippedDisplay::WeakCooling,
        ShippedDisplay::LaggingSensor,
    ];

    /// The file stem: `default`, `weak-cooling`, `lagging-sensor`.
    pub fn name(self) -> &'static str {
        match self {
            ShippedDisplay::Default => "default",
            ShippedDisplay::WeakCooling => "weak-cooling",
            ShippedDisplay::LaggingSensor => "lagging-sensor",
        }
    }

    /// The device file's text.
    pub fn device_toml(self) -> &'static str {
        match self {
            ShippedDisplay::Default => DEFAULT_DEVICE_TOML,
            ShippedDisplay::WeakCooling => WEAK_COOLING_DEVICE_TOML,
            ShippedDisplay::LaggingSensor => LAGGING_SENSOR_DEVICE_TOML,
        }
    }

    /// The device configuration.
    pub fn device(self) -> Result<DeviceConfig, PipelineError> {
        Ok(DeviceConfig::from_toml_str(
            self.device_toml(),
            &format!("devices/{}.toml", self.name()),
        )?)
    }

    /// The tuned gains file's text.
    pub fn gains_toml(self) -> &'static str {
        match self {
            ShippedDisplay::Default => DEFAULT_GAINS_TOML,
            ShippedDisplay::WeakCooling => WEAK_COOLING_GAINS_TOML,
            ShippedDisplay::LaggingSensor => LAGGING_SENSOR_GAINS_TOML,
        }
    }

    /// The tuned gains.
    pub fn gains(self) -> Result<PidGains, PipelineError> {
        gains_from_toml_str(self.gains_toml(), &format!("gains/{}.toml (built-in)", self.name()))
    }

    /// The shipped display whose device file describes exactly `device`, if any.
    pub fn matching(device: &DeviceConfig) -> Option<ShippedDisplay> {
        ShippedDisplay::ALL
            .into_iter()
            .find(|shipped| shipped.device().is_ok_and(|d| d == *device))
    }
}

/// Reads a gains file ([`PidGains::from_toml_str`]); `origin` names the file in errors ([`PipelineError::Param`]).
pub fn gains_from_toml_str(text: &str, origin: &str) -> Result<PidGains, PipelineError> {
    Ok(PidGains::from_toml_str(text, origin)?)
}

/// Writes `gains` as a gains file, with `comment` (any number of lines) as `#` comments on top. Numbers are
/// written in Rust's shortest round-trip form, so [`gains_from_toml_str`] reads back identical gains.
pub fn gains_to_toml_string(gains: &PidGains, comment: &str) -> String {
    let mut out = String::new();
    for line in comment.lines() {
        out.push_str(&format!("# {line}\n").replace("# \n", "#\n"));
    }
    out.push_str(&format!("kp_a_per_c = {:?}\n", gains.kp_a_per_c));
    out.push_str(&format!("ki_a_per_c_s = {:?}\n", gains.ki_a_per_c_s));
    out.push_str(&format!("kd_a_s_per_c = {:?}\n", gains.kd_a_s_per_c));
    if gains.filter_cutoff_hz.is_finite() {
        out.push_str(&format!("filter_cutoff_hz = {:?}\n", gains.filter_cutoff_hz));
    } else {
        out.push_str("filter_cutoff_hz = inf\n");
    }
    if let Some(tf) = gains.derivative_filter_s {
        out.push_str(&format!("derivative_filter_s = {tf:?}\n"));
    }
    out
}

/// Where the PID gains of a run came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GainsSource {
    /// The tuned file of a shipped display that matches the device exactly.
    Shipped(ShippedDisplay),
    /// The device matches no shipped display: the default display's gains are used (tune this display with
    /// `thermode tune` for its own).
    DefaultFallback,
}

/// The tuned gains for `device`: those of the shipped display it matches, else the default display's.
pub fn gains_for_device(device: &DeviceConfig) -> Result<(PidGains, GainsSource), PipelineError> {
    match ShippedDisplay::matching(device) {
        Some(shipped) => Ok((shipped.gains()?, GainsSource::Shipped(shipped))),
        None => Ok((ShippedDisplay::Default.gains()?, GainsSource::DefaultFallback)),
    }
}

/// Which controller runs, with what it needs beyond the device file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControllerKind {
    /// The paper's structure: low-pass filtered sensor, PID (gains and filter cut-off given).
    Pid(PidGains),
    /// thermode's model-based controller (observer, Peltier feedforward); every number from the device file.
    Model,
}

impl ControllerKind {
    /// The controller's name: `pid` or `model`.
    pub fn name(&self) -> &'static str {
        match self {
            ControllerKind::Pid(_) => "pid",
            ControllerKind::Model => "model",
        }
    }
}

/// The model controller's plant model from a device file: the module's S, R, K from the datasheet, the plate and
/// hot-side capacities, the water, the sensor and the drive limit.
pub fn plant_model(device: &DeviceConfig) -> Result<PlantModel, PipelineError> {
    let plant = PlantModel {
        module: device.module()?,
        plate_heat_capacity_j_k: device.plate.heat_capacity_j_k,
        hot_heat_capacity_j_k: device.hot_side.heat_capacity_j_k,
        water_conductance_w_k: device.hot_side.water_conductance_w_k,
        water_c: device.ambient.water_c,
        sensor_time_constant_s: device.sensor.time_constant_s,
        sensor_noise_c: device.sensor.noise_c,
        sensor_resolution_c: device.sensor.resolution_c,
        sensor_sample_rate_hz: device.sensor.sample_rate_hz,
        current_limit_a: device.drive.current_limit_a,
    };
    plant.validate()?;
    Ok(plant)
}

/// Builds the controller `kind` for `device` (output limited to the device's drive limit). The model controller
/// fits its module to the device's voltage starting from the file's `render.peltier_uncertainty`, and its observer
/// estimates the plate's response to heat starting from `render.plate_uncertainty` and follows the hot-side reading
/// as far as `render.hot_side_uncertainty` says; none of these when its uncertainty is 0 (a file exact for its
/// display).
pub fn build_controller(kind: &ControllerKind, device: &DeviceConfig) -> Result<Box<dyn Controller>, PipelineError> {
    match kind {
        ControllerKind::Pid(gains) => Ok(Box::new(PidController::new(*gains, device.drive.current_limit_a)?)),
        ControllerKind::Model => {
            let design = ModelDesign {
                module_fit_relative_sd: Some(device.render.peltier_uncertainty).filter(|&u| u > 0.0),
                observer: ObserverDesign {
                    plate_response_uncertainty: device.render.plate_uncertainty,
                    hot_side_response_uncertainty: device.render.hot_side_uncertainty,
                    ..ObserverDesign::default()
                },
                ..ModelDesign::default()
            };
            Ok(Box::new(ModelController::with_design(plant_model(device)?, design)?))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_gains_parse_and_match_their_devices() {
        for shipped in ShippedDisplay::ALL {
            let gains = shipped.gains().unwrap_or_else(|e| panic!("{}: {e}", shipped.name()));
            let device = shipped.device().unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(ShippedDisplay::matching(&device), Some(shipped));
            assert_eq!(
                gains_for_device(&device).ok(),
                Some((gains, GainsSource::Shipped(shipped)))
            );
        }
        let mut other = DeviceConfig::default();
        other.plate.heat_capacity_j_k = 0.2;
        assert_eq!(ShippedDisplay::matching(&other), None);
        assert!(matches!(
            gains_for_device(&other),
            Ok((_, GainsSource::DefaultFallback))
        ));
    }

    #[test]
    fn gains_files_round_trip_and_refuse_bad_values() {
        let gains = PidGains {
            kp_a_per_c: 0.123456789012345,
            ki_a_per_c_s: 1e-7,
            kd_a_s_per_c: 0.0,
            filter_cutoff_hz: f64::INFINITY,
            derivative_filter_s: Some(0.05),
        };
        let text = gains_to_toml_string(&gains, "tuned for a test\n\nsecond paragraph");
        assert!(
            text.starts_with("# tuned for a test\n#\n# second paragraph\n"),
            "{text}"
        );
        assert_eq!(gains_from_toml_str(&text, "t").ok(), Some(gains));
        for bad in [
            "kp_a_per_c = -1.0\nki_a_per_c_s = 0.0\nkd_a_s_per_c = 0.0\nfilter_cutoff_hz = 5.0\n",
            "kp_a_per_c = nan\nki_a_per_c_s = 0.0\nkd_a_s_per_c = 0.0\nfilter_cutoff_hz = 5.0\n",
            "kp_a_per_c = 1.0\nki_a_per_c_s = 0.0\nkd_a_s_per_c = 0.0\n",
            "kp_a_per_c = 1.0\nki_a_per_c_s = 0.0\nkd_a_s_per_c = 0.0\nfilter_cutoff_hz = 5.0\nextra = 1\n",
        ] {
            assert!(
                matches!(gains_from_toml_str(bad, "bad.toml"), Err(PipelineError::Param(_))),
                "accepted {bad}"
            );
        }
    }

    #[test]
    fn the_plant_model_takes_every_number_from_the_device() {
        let device = ShippedDisplay::LaggingSensor.device().unwrap_or_else(|e| panic!("{e}"));
        let plant = plant_model(&device).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(plant.sensor_time_constant_s, 1.5);
        assert_eq!(plant.module, device.module().unwrap_or_else(|e| panic!("{e}")));
        assert_eq!(plant.current_limit_a, device.drive.current_limit_a);
        assert_eq!(plant.water_conductance_w_k, device.hot_side.water_conductance_w_k);
    }
}
