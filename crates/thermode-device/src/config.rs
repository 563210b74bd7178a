//! The device file: every parameter of one simulated display channel (Peltier datasheet, plate, hot side, sensor,
//! drive, water), its defaults with units and sources, reading from TOML and writing a documented TOML file.
//!
//! Every key is optional; a file may give only some, the rest keep their defaults. Unknown sections and keys are
//! errors naming the key and the file; every number is validated (finite, in range), and cross-checks are made (the
//! current limit may not exceed the module's I_max; the datasheet must be self-consistent, see
//! [`thermode_model::peltier`]). The defaults describe the paper's hardware (section 3.1: an 8×8×3 mm miniature
//! Peltier element on a thin water-cooled aluminium box, a PT-100 sensor, water at ambient) as closely as the paper
//! allows; where the paper is silent the number is an engineering estimate, derived in its source text.

use thermode_model::error::At;
use thermode_model::limits;
use thermode_model::params::{self, Rule, Table};
use thermode_model::peltier::{PeltierDatasheet, PeltierModule};
use thermode_model::ParamError;

/// The Peltier module's datasheet values: [`PeltierDatasheet`] (section `\[peltier\]`).
pub type PeltierConfig = PeltierDatasheet;

/// The display plate (section `\[plate\]`): what the finger touches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateConfig {
    /// Heat capacity of the display node (plate, cold ceramic, half the thermoelectric legs) [J/K]. Default 0.28.
    pub heat_capacity_j_k: f64,
    /// Contact conductance between the skin surface and the plate, 1/R_c [W/(m²·K)]. Default 1000.
    pub contact_conductance_w_m2k: f64,
    /// Contact area of the finger on the plate \[m²\]. Default 6.4e-5 (8 × 8 mm).
    pub area_m2: f64,
}

/// The hot side (section `[hot_side]`): hot ceramic and the water-cooled aluminium box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HotSideConfig {
    /// Heat capacity of the hot node [J/K]. Default 1.7.
    pub heat_capacity_j_k: f64,
    /// Conductance from the hot node to the cooling water [W/K]. Default 0.3.
    pub water_conductance_w_k: f64,
}

/// The PT-100 sensor in the plate (section `\[sensor\]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorConfig {
    /// First-order lag of the sensor behind the plate temperature \[s\]; 0 = no lag. Default 0.3.
    pub time_constant_s: f64,
    /// Standard deviation of the Gaussian measurement noise \[°C\]; 0 = none. Default 0.02.
    pub noise_c: f64,
    /// Quantisation step of the reading \[°C\]; 0 = none. Default 0.01.
    pub resolution_c: f64,
    /// Sampling rate \[Hz\]; the reading is held between samples. Default 100.
    pub sample_rate_hz: f64,
}

/// The plate sensor's calibration against a reference thermometer (section `\[calibration\]`, written by `thermode
/// calibrate`, present in a file only when set): the sensor reads `sensor_gain · T + sensor_offset_c` at a true
/// plate temperature T, so thermode takes `(reading − sensor_offset_c) / sensor_gain` for the plate on real
/// hardware (every reading, the envelope's included).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationConfig {
    /// The sensor's gain \[-\], 0.5 to 2. Default 1 (uncalibrated).
    pub sensor_gain: f64,
    /// The sensor's offset \[°C\], −10 to 10. Default 0 (uncalibrated).
    pub sensor_offset_c: f64,
    /// Standard uncertainty of the gain \[-\], 0 to 1. Default 0.
    pub gain_uncertainty: f64,
    /// Standard uncertainty of the offset \[°C\], 0 to 10. Default 0.
    pub offset_uncertainty_c: f64,
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        CalibrationConfig {
            sensor_gain: 1.0,
            sensor_offset_c: 0.0,
            gain_uncertainty: 0.0,
            offset_uncertainty_c: 0.0,
        }
    }
}

/// The keys of `[calibration]`: (key, rule).
const CALIBRATION_KEYS: [(&str, Rule); 4] = [
    ("sensor_gain", Rule::Within { min: 0.5, max: 2.0 }),
    ("sensor_offset_c", Rule::Within { min: -10.0, max: 10.0 }),
    ("gain_uncertainty", Rule::Within { min: 0.0, max: 1.0 }),
    ("offset_uncertainty_c", Rule::Within { min: 0.0, max: 10.0 }),
];

impl CalibrationConfig {
    /// Whether anything is set (not the uncalibrated default).
    pub fn is_set(&self) -> bool {
        *self != CalibrationConfig::default()
    }

    /// The plate temperature \[°C\] the reading `reading_c` \[°C\] stands for.
    pub fn plate_c(&self, reading_c: f64) -> f64 {
        (reading_c - self.sensor_offset_c) / self.sensor_gain
    }

    /// The reading \[°C\] the sensor gives at a true plate temperature `plate_c` \[°C\]: `gain · T + offset`.
    pub fn reading_c(&self, plate_c: f64) -> f64 {
        self.sensor_gain * plate_c + self.sensor_offset_c
    }

    /// A device-side upper line `line_c` \[°C\] (a plate temperature the device itself keeps its plate below: a
    /// controller's object threshold, a stimulator's warmest set-point) on the scale of the sensor's own reading,
    /// which is all the device compares: the more cautious (lower) of the line as calibrated (`gain · line +
    /// offset`: right if the calibration is honest and the sensor errs) and the line as it stands (right if the
    /// sensor is honest and the calibration lies). Neither an honest calibration of a sensor that reads low nor a
    /// lying calibration of an honest sensor moves the line outward.
    pub fn upper_line_on_reading_c(&self, line_c: f64) -> f64 {
        line_c.min(self.reading_c(line_c))
    }

    /// The mirror of [`CalibrationConfig::upper_line_on_reading_c`] for a lower line `line_c` \[°C\]: the more
    /// cautious (higher) of `gain · line + offset` and `line`.
    pub fn lower_line_on_reading_c(&self, line_c: f64) -> f64 {
        line_c.max(self.reading_c(line_c))
    }

    /// A device-side limit on how fast the plate may change, `rate_c_per_s` \[°C/s\], on the reading's scale (a
    /// reading changes `gain` times as fast as the plate): the more cautious (lower) of `gain · rate` and `rate`.
    pub fn rate_on_reading_c_per_s(&self, rate_c_per_s: f64) -> f64 {
        rate_c_per_s * self.sensor_gain.min(1.0)
    }

    fn values(&mut self) -> [&mut f64; 4] {
        [
            &mut self.sensor_gain,
            &mut self.sensor_offset_c,
            &mut self.gain_uncertainty,
            &mut self.offset_uncertainty_c,
        ]
    }

    /// Reads the section from `file`, if it has one.
    fn read(file: &Table<'_>) -> Result<CalibrationConfig, ParamError> {
        let mut calibration = CalibrationConfig::default();
        if let Some(section) = file.section("calibration")? {
            for ((key, rule), value) in CALIBRATION_KEYS.iter().zip(calibration.values()) {
                if let Some(number) = section.number(key, *rule)? {
                    *value = number;
                }
            }
            section.finish()?;
        }
        Ok(calibration)
    }

    /// The section as device-file text (empty when nothing is set).
    fn to_toml_string(mut self) -> String {
        if !self.is_set() {
            return String::new();
        }
        let mut out = String::from(
            "\n[calibration]\n# The plate sensor's calibration (thermode calibrate): it reads sensor_gain · T + \
             sensor_offset_c at a true\n# plate temperature T; the uncertainties are the fit's standard errors.\n",
        );
        for ((key, _), value) in CALIBRATION_KEYS.iter().zip(self.values()) {
            out.push_str(&format!("{key} = {:?}\n", *value));
        }
        out
    }
}

/// The bipolar current drive (section `\[drive\]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveConfig {
    /// Largest current magnitude the drive delivers \[A\], at most the module's I_max. Default 2.8.
    pub current_limit_a: f64,
}

/// The surroundings (section `\[ambient\]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmbientConfig {
    /// Temperature of the cooling water \[°C\] (held at ambient by the radiator). Default 23.
    pub water_c: f64,
}

/// How the display renders contacts (section `\[render\]`): what the rendering pipeline's safety envelope allows on
/// this display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderConfig {
    /// Set-point rate limit of the safety envelope when this display renders contacts \[°C/s\], in
    /// [`limits::SETPOINT_RATE`] (at most the compiled-in 300). Default 20.
    pub max_setpoint_rate_c_per_s: f64,
    /// Relative uncertainty of the Peltier module's S, R and K as this file gives them \[-\], 0 to 1. Default 0.3
    /// (datasheet values); `thermode identify` writes its fit's. The heat at rest that errors this large could
    /// explain is not taken for the finger's when the finger models are calibrated at a touch, and the model
    /// controller's live fit of the module to its voltage starts with this uncertainty (none when 0).
    pub peltier_uncertainty: f64,
    /// Relative uncertainty of the plate's heat capacity (`plate.heat_capacity_j_k`) as this file gives it \[-\], 0
    /// to 1. Default 0.2; `thermode identify` writes its fit's. The model controller's observer estimates how fast
    /// the plate really responds to heat, starting with this uncertainty (the file's capacity taken as exact when
    /// 0).
    pub plate_uncertainty: f64,
    /// Relative uncertainty of the hot side's response (its heat capacity `hot_side.heat_capacity_j_k` and water
    /// conductance `hot_side.water_conductance_w_k` as this file gives them) \[-\], 0 to 1. Default 0.3;
    /// `thermode identify` writes its fit's. While the hot-side reading runs off the model's prediction, the model
    /// controller's observer takes the hot side's modelled change over a step as uncertain by this fraction of
    /// itself and follows the reading instead (the file's hot side taken as exact when 0).
    pub hot_side_uncertainty: f64,
    /// Relative uncertainty of the sensor's time constant (`sensor.time_constant_s`) as this file gives it \[-\], 0
    /// to 1. Default 0.5; `thermode identify` writes its fit's. The safety envelope's plate guard holds its estimate
    /// of the true plate to where a sensor that much slower puts it (none when 0). The start-up self-test and the
    /// device-side lines allow for at least [`SELF_TEST_LAG_ERROR`] ([`verified_lag_uncertainty`]).
    pub sensor_lag_uncertainty: f64,
}

/// The start-up self-test measures the sensor's time constant within this fraction of it \[-\]: 0.15. On the
/// MeCom emulator's 0.30 s sensor it measured 0.30–0.31 s bare and 0.27–0.28 s with the emulated finger (ten
/// starts each), and a red team measured 0.34 s at load 1–13 (13 % above); an allowance narrower than this refused
/// a display that was its file. So the self-test allows at least this much, `identify` writes at least this much, and every
/// device-side line allows for a sensor this much slower than the file.
pub const SELF_TEST_LAG_ERROR: f64 = 0.15;

/// The sensor-lag uncertainty \[-\] the self-test, `identify` and the device-side lines work with for a stated
/// `sensor_lag_uncertainty` \[-\]: that, at least [`SELF_TEST_LAG_ERROR`].
pub fn verified_lag_uncertainty(sensor_lag_uncertainty: f64) -> f64 {
    sensor_lag_uncertainty.max(SELF_TEST_LAG_ERROR)
}

/// Everything that describes one simulated display channel (all channels of a display are identical).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DeviceConfig {
    /// Peltier module datasheet.
    pub peltier: PeltierConfig,
    /// Display plate and finger contact.
    pub plate: PlateConfig,
    /// Hot side and water cooling.
    pub hot_side: HotSideConfig,
    /// Temperature sensor.
    pub sensor: SensorConfig,
    /// Current drive.
    pub drive: DriveConfig,
    /// Surroundings.
    pub ambient: AmbientConfig,
    /// Rendering settings of this display.
    pub render: RenderConfig,
    /// The plate sensor's calibration (section `[calibration]`, not among [`DeviceConfig::keys`]).
    pub calibration: CalibrationConfig,
}

impl Default for PlateConfig {
    fn default() -> Self {
        PlateConfig {
            heat_capacity_j_k: 0.28,
            contact_conductance_w_m2k: 1000.0,
            area_m2: 6.4e-5,
        }
    }
}

impl Default for HotSideConfig {
    fn default() -> Self {
        HotSideConfig {
            heat_capacity_j_k: 1.7,
            water_conductance_w_k: 0.3,
        }
    }
}

impl Default for SensorConfig {
    fn default() -> Self {
        SensorConfig {
            time_constant_s: 0.3,
            noise_c: 0.02,
            resolution_c: 0.01,
            sample_rate_hz: 100.0,
        }
    }
}

impl Default for DriveConfig {
    fn default() -> Self {
        DriveConfig { current_limit_a: 2.8 }
    }
}

impl Default for AmbientConfig {
    fn default() -> Self {
        AmbientConfig { water_c: 23.0 }
    }
}

impl Default for RenderConfig {
    fn default() -> Self {
        RenderConfig {
            max_setpoint_rate_c_per_s: 20.0,
            peltier_uncertainty: 0.3,
            plate_uncertainty: 0.2,
            hot_side_uncertainty: 0.3,
            sensor_lag_uncertainty: 0.5,
        }
    }
}

/// One key of the device file: where it lives, what it must satisfy, its documentation, and the value it reads and
/// writes (a field of one [`DeviceConfig`]; the default is the field of [`DeviceConfig::default`], written nowhere
/// else).
struct Field<'a> {
    section: &'static str,
    key: &'static str,
    rule: Rule,
    /// Meaning and unit (first line of the comment).
    doc: &'static str,
    /// Where the default comes from.
    source: &'static str,
    value: &'a mut f64,
}

impl Field<'_> {
    /// `section.key`, as errors and [`DeviceConfig::keys`] name it.
    fn name(&self) -> String {
        format!("{}.{}", self.section, self.key)
    }
}

/// Sections in file order.
const SECTIONS: [&str; 7] = ["peltier", "plate", "hot_side", "sensor", "drive", "ambient", "render"];

const MODULE_SOURCE: &str = "model.md §5: a typical single-stage Bi₂Te₃ miniature module of 8 × 8 mm, the size of the \
     paper's 8 × 8 × 3 mm element (section 3.1; the paper names no part).";

impl DeviceConfig {
    /// Every key of the device file, in file order, each with the field of `self` it reads and writes.
    fn fields(&mut self) -> [Field<'_>; 21] {
        [
            Field {
                section: "peltier",
                key: "imax_a",
                rule: limits::PELTIER_CURRENT.rule(),
                value: &mut self.peltier.imax_a,
                doc: "Datasheet maximum current I_max [A] (the current of the largest temperature difference).",
                source: MODULE_SOURCE,
            },
            Field {
                section: "peltier",
                key: "vmax_v",
                rule: limits::PELTIER_VOLTAGE.rule(),
                value: &mut self.peltier.vmax_v,
                doc: "Datasheet voltage at I_max and ΔT_max, V_max [V].",
                source: MODULE_SOURCE,
            },
            Field {
                section: "peltier",
                key: "qmax_w",
                rule: limits::PELTIER_POWER.rule(),
                value: &mut self.peltier.qmax_w,
                doc: "Datasheet cooling power at I_max and ΔT = 0, Q_max [W]; checked against the other values (±30 \
                      %).",
                source: MODULE_SOURCE,
            },
            Field {
                section: "peltier",
                key: "dtmax_k",
                rule: limits::PELTIER_DELTA_T.rule(),
                value: &mut self.peltier.dtmax_k,
                doc: "Datasheet largest temperature difference at I_max and zero load, ΔT_max [K].",
                source: MODULE_SOURCE,
            },
            Field {
                section: "peltier",
                key: "hot_side_k",
                rule: limits::DATASHEET_HOT_SIDE.rule(),
                value: &mut self.peltier.hot_side_k,
                doc: "Hot-side temperature at which the datasheet values are quoted, T_h [K].",
                source: "25 °C: these values are a 25–27 °C datasheet set (S = V_max/T_h = 6.37 mV/K matches \
                         model.md's 6.4 mV/K; 323 K would give 5.9), and the hot side runs near the 23 °C water, where \
                         the derived S, R, K are then evaluated.",
            },
            Field {
                section: "plate",
                key: "heat_capacity_j_k",
                rule: limits::PLATE_HEAT_CAPACITY.rule(),
                value: &mut self.plate.heat_capacity_j_k,
                doc: "Heat capacity of the display node: plate, cold ceramic, half the thermoelectric legs [J/K].",
                source: "Estimate (model.md §5: 0.1–0.3): aluminium plate 8 × 8 × 1 mm (ρc = 2702 × 903 J/(m³·K), \
                         Incropera Table A.1) 0.156 J/K + alumina ceramic 8 × 8 × 0.5 mm (96 % Al₂O₃, 3720 kg/m³, 880 \
                         J/(kg·K)) 0.105 J/K + half of 2 mm Bi₂Te₃ legs at 30 % fill (7740 kg/m³, 154 J/(kg·K)) 0.023 \
                         J/K = 0.284 J/K.",
            },
            Field {
                section: "plate",
                key: "contact_conductance_w_m2k",
                rule: limits::CONTACT_CONDUCTANCE.rule(),
                value: &mut self.plate.contact_conductance_w_m2k,
                doc: "Contact conductance between the skin surface and the plate, 1/R_c [W/(m²·K)]; a finger model \
                      whose receptor node lies below the surface adds its own tissue in series (see \
                      thermode_device::finger).",
                source: "model.md §3: R_c is about 1e-3 m²·K/W for a light touch (the paper's static touch without \
                         pressure, section 4.2).",
            },
            Field {
                section: "plate",
                key: "area_m2",
                rule: limits::CONTACT_AREA.rule(),
                value: &mut self.plate.area_m2,
                doc: "Contact area of the finger on the plate [m²].",
                source: "The 8 × 8 mm face of the paper's element (section 3.1), fully covered by the phalanx pad.",
            },
            Field {
                section: "hot_side",
                key: "heat_capacity_j_k",
                rule: limits::HOT_SIDE_HEAT_CAPACITY.rule(),
                value: &mut self.hot_side.heat_capacity_j_k,
                doc:
                    "Heat capacity of the hot node: hot ceramic, half the legs, the aluminium box and the water in it \
                      [J/K].",
                source: "Estimate (the paper: 'a thin aluminium box', no size): hot ceramic 0.105 + half legs 0.023 + \
                         box 12 × 12 × 5 mm with 0.5 mm walls (236 mm³ aluminium) 0.576 + half of the 484 mm³ of water \
                         it holds (4.17 MJ/(m³·K); its temperature lies between inlet and wall) 1.009 = 1.71 J/K.",
            },
            Field {
                section: "hot_side",
                key: "water_conductance_w_k",
                rule: limits::WATER_CONDUCTANCE.rule(),
                value: &mut self.hot_side.water_conductance_w_k,
                doc: "Conductance from the hot node to the cooling water [W/K]; a pump failure lowers it.",
                source: "model.md §5 (about 0.3 W/K); check: laminar flow through the box (11 × 4 mm channel, \
                         hydraulic diameter 5.9 mm, Nu 5–8, so h = 500–800 W/(m²·K)) over about 4 cm² of wetted wall \
                         at partial fin efficiency gives 0.2–0.3 W/K.",
            },
            Field {
                section: "sensor",
                key: "time_constant_s",
                rule: limits::SENSOR_LAG.rule(),
                value: &mut self.sensor.time_constant_s,
                doc: "First-order lag of the PT-100 behind the plate temperature [s]; 0 = none.",
                source: "model.md §5 (0.2–0.6 s): a thin-film PT-100 chip glued into the 1 mm plate.",
            },
            Field {
                section: "sensor",
                key: "noise_c",
                rule: limits::SENSOR_ERROR.rule(),
                value: &mut self.sensor.noise_c,
                doc: "Standard deviation of the Gaussian measurement noise [°C]; 0 = none.",
                source: "Estimate: two steps of the 0.01 °C resolution (1 mA through a PT-100 gives 3.85 µV per 0.01 \
                         °C, comparable to amplifier and 16-bit converter noise); the paper needed a low-pass filter \
                         against sensor noise (section 3.2), so the noise exceeds one step.",
            },
            Field {
                section: "sensor",
                key: "resolution_c",
                rule: limits::SENSOR_ERROR.rule(),
                value: &mut self.sensor.resolution_c,
                doc: "Quantisation step of the reading [°C]; 0 = none.",
                source: "The paper, section 3: 'a resolution of 0.01 °C'.",
            },
            Field {
                section: "sensor",
                key: "sample_rate_hz",
                rule: limits::SENSOR_SAMPLE_RATE.rule(),
                value: &mut self.sensor.sample_rate_hz,
                doc: "Sampling rate of the sensor [Hz]; the reading is held between samples.",
                source: "Estimate: the paper gives none; 100 Hz is a usual rate of a Simulink real-time loop on a \
                         thermal plant whose fastest time constant is about 0.1 s.",
            },
            Field {
                section: "drive",
                key: "current_limit_a",
                rule: Rule::Positive,
                value: &mut self.drive.current_limit_a,
                doc: "Largest current magnitude of the bipolar drive [A]; at most the module's I_max.",
                source: "The module's I_max: beyond it a module is outside its rating and cools no better.",
            },
            Field {
                section: "ambient",
                key: "water_c",
                rule: Rule::Between { min: 0.0, max: 100.0 },
                value: &mut self.ambient.water_c,
                doc: "Temperature of the cooling water [°C], held at ambient by the radiator and fans.",
                source: "The paper, section 4.1: mean ambient temperature 23 °C; section 3.1: the water circuit keeps \
                         the reference side at ambient level.",
            },
            Field {
                section: "render",
                key: "max_setpoint_rate_c_per_s",
                rule: limits::SETPOINT_RATE.rule(),
                value: &mut self.render.max_setpoint_rate_c_per_s,
                doc: "Set-point rate limit of the safety envelope when this display renders contacts [°C/s], at most \
                      the compiled-in 300 (see docs/ranges.md). A display with a stronger module may raise it so that \
                      its actuator, not the limiter, sets how fast a touch is rendered.",
                source: "The default module cools the resting plate at about 13 °C/s at full current, so 20 °C/s \
                         leaves the actuator in charge of the initial drop (docs/design-choices.md, rendering rate \
                         limit); commercial stimulators ramp at 70-300 °C/s within the same temperature bounds.",
            },
            Field {
                section: "render",
                key: "peltier_uncertainty",
                rule: Rule::Within { min: 0.0, max: 1.0 },
                value: &mut self.render.peltier_uncertainty,
                doc: "Relative uncertainty of the Peltier module's S, R and K as this file gives them [-], 0 to 1. \
                      At a touch the finger models are calibrated to the heat the resting finger gives the plate \
                      beyond the model's (docs/design-choices.md, touch calibration); the part of that heat which \
                      errors this large in the module could explain is not taken for the finger's. Where the \
                      display reports the module's voltage, the model controller fits S and R to it live, starting \
                      with this uncertainty (no fit when 0). `thermode identify` writes its fit's uncertainty.",
                source: "Datasheet values describe a module type, not the one on the display: ±30 % in the derived \
                         conductance K moves the heat a resting plate exchanges with the hot side by about 75 mW, a \
                         1.2 °C error of the finger's temperature (docs/design-choices.md).",
            },
            Field {
                section: "render",
                key: "plate_uncertainty",
                rule: Rule::Within { min: 0.0, max: 1.0 },
                value: &mut self.render.plate_uncertainty,
                doc: "Relative uncertainty of the plate's heat capacity (plate.heat_capacity_j_k) as this file \
                      gives it [-], 0 to 1. The model controller's observer estimates how fast the plate really \
                      responds to heat (the response of a saturated drop decides when it ends), starting with this \
                      uncertainty; 0 takes the file's capacity as exact. `thermode identify` writes its fit's \
                      uncertainty.",
                source: "An estimate from handbook values and part sizes (plate.heat_capacity_j_k) misses the glue and \
                         grease layers and how much of the legs moves with the plate: about 20 % (docs/design-choices.md, \
                         the plate's response).",
            },
            Field {
                section: "render",
                key: "hot_side_uncertainty",
                rule: Rule::Within { min: 0.0, max: 1.0 },
                value: &mut self.render.hot_side_uncertainty,
                doc: "Relative uncertainty of the hot side's response (hot_side.heat_capacity_j_k and \
                      hot_side.water_conductance_w_k as this file gives them) [-], 0 to 1. While the hot-side \
                      reading runs off the model's prediction (beyond 3 standard deviations), the model \
                      controller's observer takes the hot side's modelled change over a step as uncertain by this \
                      fraction of itself and follows the reading instead; 0 takes the file's hot side as exact. \
                      `thermode identify` writes its fit's uncertainty.",
                source: "The hot side's capacity is an estimate of a box the paper does not size and its water \
                         conductance one of a laminar flow (hot_side.*): about 30 %. Believed exact, a hot side 30 % \
                         lighter ran ahead of the observer's during a drop, and its reading pulled the plate \
                         estimate 0.3 °C warm (docs/design-choices.md, the hot side's response).",
            },
            Field {
                section: "render",
                key: "sensor_lag_uncertainty",
                rule: Rule::Within { min: 0.0, max: 1.0 },
                value: &mut self.render.sensor_lag_uncertainty,
                doc: "Relative uncertainty of the sensor's time constant (sensor.time_constant_s) as this file gives \
                      it [-], 0 to 1. The safety envelope's plate guard holds its estimate of the true plate to where \
                      a sensor this much slower than the file's would put it while the reading moves, so that a \
                      display off its file cannot heat past the envelope's maximum behind a model that lags it \
                      (docs/security.md); 0 takes the file's time constant as exact. `thermode identify` writes its \
                      fit's uncertainty.",
                source: "model.md §5 gives 0.2–0.6 s for a PT-100 chip glued into the plate: the file's 0.3 s may be \
                         50 % short.",
            },
        ]
    }

    /// This file as a controller may believe it when it drives a simulated display built from this very file: the
    /// module, the plate, the hot side and the sensor are then exactly what the file says
    /// (`render.peltier_uncertainty`, `render.plate_uncertainty`, `render.hot_side_uncertainty` and
    /// `render.sensor_lag_uncertainty` 0). Real hardware, or a simulated display
    /// built from another file, keeps the file's own uncertainties.
    pub fn exact_for_its_simulation(&self) -> DeviceConfig {
        let mut exact = *self;
        exact.render.peltier_uncertainty = 0.0;
        exact.render.plate_uncertainty = 0.0;
        exact.render.hot_side_uncertainty = 0.0;
        exact.render.sensor_lag_uncertainty = 0.0;
        exact
    }

    /// Reads a device file. Every key is optional (missing keys keep their defaults); unknown sections or keys,
    /// values of the wrong type, and invalid numbers are errors naming the key (`section.key`) and `origin` (usually
    /// the file name).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<DeviceConfig, ParamError> {
        let toml = params::parse(text, origin)?;
        let file = Table::new(&toml, origin);
        let mut config = DeviceConfig::default();
        for section_name in SECTIONS {
            let Some(section) = file.section(section_name)? else {
                continue;
            };
            for field in config.fields().into_iter().filter(|f| f.section == section_name) {
                if let Some(value) = section.number(field.key, field.rule)? {
                    *field.value = value;
                }
            }
            section.finish()?;
        }
        config.calibration = CalibrationConfig::read(&file)?;
        file.finish()?;
        config.validate(origin)?;
        Ok(config)
    }

    /// Checks every number and the cross-conditions; `origin` names where the values came from.
    pub fn validate(&self, origin: &str) -> Result<(), ParamError> {
        let mut copy = *self;
        for field in copy.fields() {
            if !field.rule.admits(*field.value) {
                return field.rule.check(field.name(), *field.value).at(origin).map(drop);
            }
        }
        PeltierModule::from_datasheet_at(&self.peltier, origin, "peltier.")?;
        let within_module = Rule::AtMost {
            max: self.peltier.imax_a,
            what: "the module's I_max (peltier.imax_a) [A]",
        };
        within_module
            .check("drive.current_limit_a", self.drive.current_limit_a)
            .at(origin)?;
        Ok(())
    }

    /// Every key of the device file as `section.key`, in file order.
    pub fn keys() -> Vec<String> {
        DeviceConfig::default().fields().iter().map(Field::name).collect()
    }

    /// The Peltier module's lumped parameters (S, R, K) from the datasheet values.
    pub fn module(&self) -> Result<PeltierModule, ParamError> {
        PeltierModule::from_datasheet_at(&self.peltier, "device config", "peltier.")
    }

    /// The whole configuration as a device file: every key, each preceded by a comment with its meaning, unit,
    /// default and source. [`DeviceConfig::from_toml_str`] reads it back to an equal configuration.
    pub fn to_toml_string(&self) -> String {
        let mut defaults = DeviceConfig::default();
        let mut values = *self;
        let mut out = String::from(HEADER);
        let mut section = "";
        for (default, field) in defaults.fields().into_iter().zip(values.fields()) {
            if field.section != section {
                section = field.section;
                out.push_str(&format!("\n[{section}]\n"));
            }
            let text = format!("{} Default {:?}. Source: {}", field.doc, *default.value, field.source);
            for line in wrap(&text, 116) {
                out.push_str(&format!("# {line}\n"));
            }
            out.push_str(&format!("{} = {:?}\n", field.key, *field.value));
        }
        out.push_str(&self.calibration.to_toml_string());
        out
    }
}

const HEADER: &str = "\
# thermode device file: the simulated thermal display, one channel (all channels of a display are identical).
# Every key is optional: keys left out keep the default named in their comment. Units are in the key names.
# Written by thermode_device::DeviceConfig::to_toml_string.
";

/// Splits `text` into lines of at most `width` characters at spaces.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}
