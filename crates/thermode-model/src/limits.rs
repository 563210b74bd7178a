//! The one physical range of every quantity a user, a file or a client can give thermode: object and ambient
//! temperatures, material and skin properties, contact, durations and rates. Each range is a named [`Range`]
//! constant whose documentation says why its bounds are where they are; `thermode simulate`, `thermode render`,
//! the contact API, the lab, the parameter files and the safety envelope check their numbers against these
//! constants and nowhere else, so one quantity has one range everywhere.
//!
//! The bounds are physical, not numerical: a value outside describes no finger, no material or no touch that
//! exists, and the models (constant properties, no freezing, no burns, no phase change) say nothing meaningful
//! about it. Inside them every model gives finite results (tested at the corners).
//!
//! [`ALL`] lists every range with its reason and its users; `docs/ranges.md` holds [`markdown_table`]'s table,
//! and a test keeps the two equal (regenerate with `THERMODE_WRITE_DOCS=1 cargo test -p thermode-model --test
//! integration ranges`).
//!
//! Besides the ranges, [`MAX_RESULT_BYTES`] caps the memory one command's results may take.

use crate::error::{At, ParamError};
use crate::params::Range;

/// One documented range: the constant's name, the range, why its bounds are where they are, and who checks it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Documented {
    /// The constant's name in this module (`OBJECT_TEMPERATURE`).
    pub constant: &'static str,
    /// The range.
    pub range: Range,
    /// Why the bounds are where they are (the constant's documentation).
    pub reason: &'static str,
    /// What checks it (commands, files, API fields).
    pub used_by: &'static str,
}

/// Defines each range as a documented `pub const` and lists them all, with the same documentation as the reason,
/// in [`ALL`]: the reason is written once.
macro_rules! ranges {
    ($(
        $(#[doc = $doc:literal])+
        $constant:ident = $name:literal, $min:expr, $max:expr; used by $used:literal;
    )+) => {
        $(
            $(#[doc = $doc])+
            ///
            #[doc = concat!("Used by: ", $used, ".")]
            pub const $constant: Range = Range {
                name: $name,
                min: $min,
                max: $max,
            };
        )+

        /// Every range of this module with its reason and its users, in the order of `docs/ranges.md`.
        pub const ALL: &[Documented] = &[$(
            Documented {
                constant: stringify!($constant),
                range: $constant,
                reason: concat!($($doc),+),
                used_by: $used,
            },
        )+];
    };
}

ranges! {
    /// The air around the finger, −30 to 50 °C: the rooms, vehicles and outdoor air in which a bare hand touches
    /// things (a closed car in the summer sun at the top). Colder air freezes a bare finger within minutes and
    /// hotter air heat-stresses the body; the skin models (no freezing, no sweating) have no resting finger to
    /// start from there.
    AMBIENT_TEMPERATURE = "ambient temperature [°C]", -30.0, 50.0;
    used by "`simulate --ambient`, the pipeline's ambient (`render`, `serve`, lab display), the lab's fv contact, the \
             kron and fv models' air";

    /// The touched object at the moment of touch, −50 to 150 °C: below any freezer (−18 °C) and winter day, above
    /// boiling water and a hot pan handle. Beyond it a touch injures within a second (frostbite on metal, burns)
    /// and the materials' room-temperature properties no longer hold. The safety envelope, not this range, limits
    /// what a display shows.
    OBJECT_TEMPERATURE = "object temperature [°C]", -50.0, 150.0;
    used by "`simulate --object-temp`, `render --object-temp`, API `touch.object_temp_c`, the lab's fv contact, the \
             kron and fv models' touch";

    /// A living finger's skin, 0 to 50 °C: tissue freezes just below 0 °C (frostbite) and burns within minutes at
    /// 50 °C (Moritz & Henriques 1947), so no finger starts a touch outside.
    SKIN_TEMPERATURE = "skin temperature [°C]", 0.0, 50.0;
    used by "`simulate --initial uniform:C` and `surface:C`, the fv model's initial states, the kron and fv \
             resting-surface calibrations";

    /// Arterial blood, 30 to 42 °C: from severe hypothermia to the highest fever survived.
    ARTERIAL_TEMPERATURE = "arterial blood temperature [°C]", 30.0, 42.0;
    used by "skin files (`blood.arterial_c`)";

    /// Thermal conductivity, 0.01 to 2500 W/(m·K): below still air (0.026) and silica aerogel (≈ 0.015), the
    /// best solid insulators; above diamond (≈ 2200), the best conductor at room temperature.
    CONDUCTIVITY = "thermal conductivity [W/(m·K)]", 0.01, 2500.0;
    used by "material files, API `touch.properties`, skin files (layers)";

    /// Density, 1 to 25 000 kg/m³: from the lightest aerogels to above osmium (22 590), the densest element.
    DENSITY = "density [kg/m³]", 1.0, 25_000.0;
    used by "material files, API `touch.properties`, skin files (layers, blood)";

    /// Specific heat, 100 to 15 000 J/(kg·K): below the Dulong–Petit value 3R/M of the heaviest atoms (≈ 105 for
    /// uranium), the least any solid holds at room temperature; above hydrogen (14 300), the most of any
    /// substance.
    SPECIFIC_HEAT = "specific heat [J/(kg·K)]", 100.0, 15_000.0;
    used by "material files, API `touch.properties`, skin files (layers, blood)";

    /// Thickness of the touched object, 0.1 mm to 1 m: from a sheet of paper (a thinner layer is a coating, and
    /// its substrate decides what the finger feels) to far beyond the depth heat reaches in an hour's touch
    /// (√(a·t) ≈ 0.6 m for copper), so a thicker object feels the same.
    OBJECT_THICKNESS = "object thickness [m]", 1e-4, 1.0;
    used by "material files, API `touch.properties`";

    /// Thickness of one skin layer, 10 µm to 5 cm: from the stratum corneum, the thinnest layer a skin model
    /// resolves, to several times a fingertip's whole depth.
    SKIN_LAYER_THICKNESS = "skin layer thickness [m]", 1e-5, 0.05;
    used by "skin files (`layer[n].thickness_m`)";

    /// Blood perfusion of a tissue layer, 0 to 0.1 1/s: from unperfused tissue (the epidermis) to above the
    /// kidney's ≈ 0.07 1/s (4 ml/g/min), the most perfused tissue. The resting-surface calibration
    /// (`--initial surface:C`, the pipeline's calibration at the touch) scales the perfusion by design and may
    /// go beyond it.
    PERFUSION = "blood perfusion [1/s]", 0.0, 0.1;
    used by "skin files (`layer[n].perfusion_per_s`)";

    /// Metabolic heat of a tissue layer, 0 to 100 000 W/m³: resting tissue produces a few hundred, exercising
    /// muscle about 10 000.
    METABOLIC_HEAT = "metabolic heat [W/m³]", 0.0, 100_000.0;
    used by "skin files (`layer[n].metabolic_w_m3`)";

    /// Heat transfer coefficient from the skin to the air, 1 to 1000 W/(m²·K): still air gives about 10
    /// (convection plus radiation), wind up to about 100, still water several hundred.
    AIR_CONVECTION = "skin–air heat transfer coefficient [W/(m²·K)]", 1.0, 1000.0;
    used by "skin files (`air.convection_w_m2k`)";

    /// Contact resistance between skin and object, 0 to 0.01 m²K/W: from perfect contact through a light touch
    /// (≈ 1e-3) to the resistance of a 0.26 mm air gap, a finger that no longer touches.
    CONTACT_RESISTANCE = "contact resistance [m²K/W]", 0.0, 0.01;
    used by "`simulate --contact-resistance`, the pipeline's contact resistance";

    /// Contact conductance between skin and plate, 100 to 100 000 W/(m²·K): the inverse of the largest contact
    /// resistance above, up to a thermal-paste joint (≈ 1e-5 m²K/W), better than any skin contact.
    CONTACT_CONDUCTANCE = "contact conductance [W/(m²·K)]", 100.0, 100_000.0;
    used by "`simulate --display-conductance`, `render --finger-contact`, device files \
             (`plate.contact_conductance_w_m2k`)";

    /// How long a touch (or a simulated or rendered run) lasts, up to one hour: beyond the longest contact of any
    /// thermal-display experiment (IEC 60601-1 limits warm contact to 10 min) and beyond what the resting-finger
    /// models (no sweating, no vasomotor change) describe. Must also be above zero.
    DURATION = "duration [s]", 0.0, 3600.0;
    used by "`simulate --duration`, `render --duration` plus `--pre-contact`, lab `presentation_s`";

    /// Output interval and time step of `thermode simulate`, 10 µs to 10 s: finer than any receptor or sensor
    /// resolves (sensors sample at 1 kHz at most), and coarse enough to show the first seconds of a touch.
    TIME_STEP = "time step [s]", 1e-5, 10.0;
    used by "`simulate --dt`";

    /// Tick rate of an offline render, 1 Hz to 100 kHz: the slowest loop that still acts within the plate's
    /// time constant of about a second, up to a hundred times the fastest real-time loop; a faster tick sees the
    /// same held sensor sample again.
    TICK_RATE = "tick rate [Hz]", 1.0, 100_000.0;
    used by "`render --rate`, the lab's display stimulus";

    /// Rate of the daemon's real-time control loop, 1 Hz to 1 kHz: 1 ms is the finest period a desktop
    /// operating system's scheduler keeps with sub-millisecond jitter.
    LOOP_RATE = "loop rate [Hz]", 1.0, 1000.0;
    used by "`serve --rate`, `demo`, `bench`";

    /// Set-point rate of a display, 0.01 to 300 °C/s: from 36 °C per hour, slower than any stimulus, to the
    /// fastest ramps of commercial thermal stimulators (e.g. QST.Lab TCS II, up to 300 °C/s) inside the same
    /// temperature bounds. The rate is not what protects the skin (the temperature bounds and the thermal dose
    /// are); it caps how fast a display may follow. A display's own rendering rate is its device file's
    /// `render.max_setpoint_rate_c_per_s` (default 20).
    SETPOINT_RATE = "set-point rate [°C/s]", 0.01, 300.0;
    used by "the safety envelope (`max_setpoint_rate_c_per_s`), device files \
             (`render.max_setpoint_rate_c_per_s`), `render --max-rate`, API `setpoint.rate_c_s`";

    /// A Peltier module's datasheet maximum current I_max, 0.01 to 100 A: from the smallest micro-modules (tens of
    /// mA) to the largest single modules (about 30 A) with room; beyond it there is no thermoelectric module.
    PELTIER_CURRENT = "Peltier maximum current [A]", 0.01, 100.0;
    used by "device files (`peltier.imax_a`)";

    /// A Peltier module's datasheet voltage V_max, 0.01 to 100 V: from one couple (about 0.05 V at 25 °C) to a
    /// 254-couple module (about 30 V) with room.
    PELTIER_VOLTAGE = "Peltier maximum voltage [V]", 0.01, 100.0;
    used by "device files (`peltier.vmax_v`)";

    /// A Peltier module's datasheet cooling power Q_max, 1 mW to 1 kW: from a micro-module to the largest single
    /// modules (about 300 W) with room.
    PELTIER_POWER = "Peltier maximum cooling power [W]", 0.001, 1000.0;
    used by "device files (`peltier.qmax_w`)";

    /// A Peltier module's datasheet ΔT_max, 1 to 150 K: single-stage Bi₂Te₃ modules reach about 70 K, the best
    /// multi-stage stacks about 130 K.
    PELTIER_DELTA_T = "Peltier largest temperature difference [K]", 1.0, 150.0;
    used by "device files (`peltier.dtmax_k`)";

    /// The hot-side temperature at which a datasheet quotes its values, 250 to 400 K: datasheets quote 25 to 85 °C,
    /// and Bi₂Te₃ modules are soldered for at most about 200 °C.
    DATASHEET_HOT_SIDE = "datasheet hot-side temperature [K]", 250.0, 400.0;
    used by "device files (`peltier.hot_side_k`)";

    /// Heat capacity of a display's plate node, 0.1 mJ/K to 1 kJ/K: from a 1 mm² foil to a 0.4 kg aluminium block,
    /// far beyond a plate a Peltier element can move at a finger's pace (the default is 0.28 J/K).
    PLATE_HEAT_CAPACITY = "plate heat capacity [J/K]", 1e-4, 1000.0;
    used by "device files (`plate.heat_capacity_j_k`)";

    /// Contact area of the finger on the plate, 1 mm² to 0.1 m²: from a pin-point stimulator to a palm-sized plate
    /// and beyond (a whole hand is about 0.02 m²).
    CONTACT_AREA = "contact area [m²]", 1e-6, 0.1;
    used by "device files (`plate.area_m2`)";

    /// Heat capacity of a display's hot side (ceramic, heat sink, its water), 1 mJ/K to 100 kJ/K: up to a 20 l
    /// water bath.
    HOT_SIDE_HEAT_CAPACITY = "hot-side heat capacity [J/K]", 1e-3, 1e5;
    used by "device files (`hot_side.heat_capacity_j_k`)";

    /// Conductance from the hot side to the cooling water or air, 0 to 1 kW/K: from no flow at all to far more
    /// than any liquid cold plate under a module (a few W/K).
    WATER_CONDUCTANCE = "water conductance [W/K]", 0.0, 1000.0;
    used by "device files (`hot_side.water_conductance_w_k`)";

    /// First-order lag of a display's temperature sensor behind its plate, 0 to 10 s: from none to a sensor so
    /// slow that the safety envelope, which bounds the plate by it, allows no more.
    SENSOR_LAG = "sensor time constant [s]", 0.0, 10.0;
    used by "device files (`sensor.time_constant_s`), the safety envelope (`sensor_time_constant_s`)";

    /// Noise or quantisation step of a display's temperature reading, 0 to 10 °C: a reading worse than that tells
    /// nothing about a plate a finger can bear.
    SENSOR_ERROR = "sensor noise or resolution [°C]", 0.0, 10.0;
    used by "device files (`sensor.noise_c`, `sensor.resolution_c`)";

    /// Sampling rate of a display's temperature sensor, 1 Hz to 100 kHz: the tick rates thermode runs at.
    SENSOR_SAMPLE_RATE = "sensor sample rate [Hz]", 1.0, 100_000.0;
    used by "device files (`sensor.sample_rate_hz`)";
}

/// Largest memory one command's results may take \[bytes\]: 1 GiB. The estimate (rows × bytes per row, summed over
/// the runs of the command) is checked before anything is allocated, and larger work is refused with a message
/// saying how to make it smaller. 1 GiB is a quarter of a small single-board computer's memory and about 100 times
/// the largest default workload (`render --material all-paper --controller both`: about 9 MB).
pub const MAX_RESULT_BYTES: u64 = 1 << 30;

/// `Ok` if results estimated at `estimate_bytes` fit in [`MAX_RESULT_BYTES`], else the message to refuse them with
/// (the estimate and the limit in MB; the caller adds what to make smaller).
pub fn check_result_bytes(estimate_bytes: u64) -> Result<(), String> {
    if estimate_bytes <= MAX_RESULT_BYTES {
        return Ok(());
    }
    let mb = |bytes: u64| bytes as f64 / 1e6;
    Err(format!(
        "the results would take about {:.0} MB of memory, more than the {:.0} MB one command may use \
         (MAX_RESULT_BYTES, docs/ranges.md)",
        mb(estimate_bytes),
        mb(MAX_RESULT_BYTES)
    ))
}

/// Checks the two temperatures of a touch, in this order: the ambient `ambient_c` \[°C\] against
/// [`AMBIENT_TEMPERATURE`] and the object's `object_c` \[°C\] against [`OBJECT_TEMPERATURE`]; a refused one is a
/// [`ParamError::BadValue`] from `origin` naming `ambient_c` or `object_c`.
pub fn check_touch_temperatures(origin: &str, ambient_c: f64, object_c: f64) -> Result<(), ParamError> {
    AMBIENT_TEMPERATURE.rule().check("ambient_c", ambient_c).at(origin)?;
    OBJECT_TEMPERATURE.rule().check("object_c", object_c).at(origin)?;
    Ok(())
}

/// Checks the two temperatures of a resting-surface calibration, in this order: the ambient `ambient_c` \[°C\]
/// against [`AMBIENT_TEMPERATURE`] and the skin surface `surface_c` \[°C\] against [`SKIN_TEMPERATURE`]; a refused
/// one is a [`ParamError::BadValue`] from `origin` naming `ambient_c` or `surface_c`.
pub fn check_resting_temperatures(origin: &str, ambient_c: f64, surface_c: f64) -> Result<(), ParamError> {
    AMBIENT_TEMPERATURE.rule().check("ambient_c", ambient_c).at(origin)?;
    SKIN_TEMPERATURE.rule().check("surface_c", surface_c).at(origin)?;
    Ok(())
}

/// The table of `docs/ranges.md`: one row per entry of [`ALL`] (constant, quantity with unit, minimum, maximum,
/// why, used by), then the result-memory cap.
pub fn markdown_table() -> String {
    let mut out = String::from("| constant | quantity | min | max | why | used by |\n|---|---|---|---|---|---|\n");
    for entry in ALL {
        let reason = entry.reason.split_whitespace().collect::<Vec<_>>().join(" ");
        out.push_str(&format!(
            "| `{}` | {} | {} | {} | {} | {} |\n",
            entry.constant,
            entry.range.name,
            entry.range.min,
            entry.range.max,
            reason,
            entry.used_by.split_whitespace().collect::<Vec<_>>().join(" ")
        ));
    }
    out.push_str(&format!(
        "\nMemory: the results of one command may take at most `MAX_RESULT_BYTES` = {MAX_RESULT_BYTES} bytes \
         ({} GiB), estimated before anything is allocated.\n",
        MAX_RESULT_BYTES >> 30
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_range_is_ordered_finite_and_documented() {
        for entry in ALL {
            let r = entry.range;
            assert!(
                r.min.is_finite() && r.max.is_finite() && r.min < r.max,
                "{}: [{}, {}]",
                entry.constant,
                r.min,
                r.max
            );
            assert!(
                r.name.contains('[') && r.name.ends_with(']'),
                "{}: no unit in {:?}",
                entry.constant,
                r.name
            );
            assert!(entry.reason.len() > 40, "{}: reason {:?}", entry.constant, entry.reason);
            assert!(!entry.used_by.is_empty(), "{}: no users", entry.constant);
        }
        let mut names: Vec<&str> = ALL.iter().map(|e| e.constant).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), ALL.len(), "duplicate constants");
    }

    #[test]
    fn ranges_admit_their_bounds_and_refuse_beyond() {
        for entry in ALL {
            let r = entry.range;
            for inside in [r.min, r.max, 0.5 * (r.min + r.max)] {
                assert_eq!(r.check(inside), Ok(inside), "{} refused {inside}", entry.constant);
            }
            let below = r.min - r.min.abs().max(1.0) * 1e-3;
            let above = r.max + r.max.abs().max(1.0) * 1e-3;
            for outside in [below, above, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                assert!(r.check(outside).is_err(), "{} admitted {outside}", entry.constant);
            }
        }
        // The measured problems: an oven for air, colder than absolute zero, a conductivity of 1e300.
        assert!(AMBIENT_TEMPERATURE.check(1000.0).is_err());
        assert!(OBJECT_TEMPERATURE.check(-300.0).is_err());
        assert!(CONDUCTIVITY.check(1e300).is_err());
        let message = CONDUCTIVITY.check(1e300).map(drop).unwrap_err().to_string();
        assert_eq!(
            message,
            "`thermal conductivity [W/(m·K)]` = 1e300 is invalid: must be a finite number from 0.01 to 2500"
        );
    }

    #[test]
    fn results_above_the_cap_are_refused_with_the_estimate() {
        assert_eq!(check_result_bytes(MAX_RESULT_BYTES), Ok(()));
        let message = check_result_bytes(36_000_000_000).expect_err("36 GB");
        assert!(message.contains("36000 MB") && message.contains("1074 MB"), "{message}");
    }

    #[test]
    fn the_table_has_one_row_per_range() {
        let table = markdown_table();
        assert_eq!(
            table.lines().filter(|l| l.starts_with("| `")).count(),
            ALL.len(),
            "{table}"
        );
        assert!(
            table.contains("| `OBJECT_TEMPERATURE` | object temperature [°C] | -50 | 150 |"),
            "{table}"
        );
    }
}
