//! The device's own over- and under-temperature cut: the firmware's second line of protection, which does not
//! depend on the host. Before every plant step the firmware bounds its true plate temperature from its **own**
//! sensor reading and its **own** drive current, and cuts heating before the plate can pass [`PLATE_MAX_C`]
//! (cooling before it can pass [`PLATE_MIN_C`]). A cut latches; `ClearFault` releases it only once the plate is back
//! inside by [`RELEASE_HYSTERESIS_C`] (`docs/protocol.md` §6).
//!
//! # The bound
//! The sensor element `x` follows the plate `u` with the sensor's first-order lag τ: `dx/dt = (u − x)/τ`. The gap
//! `g = u − x` therefore obeys `dg/dt = du/dt − g/τ`: it is the plate's rate filtered by the sensor's lag. If `r⁺(t)`
//! bounds the plate's rate from above at every instant, the comparison principle gives `g(t) ≤ G(t)` with
//! `dG/dt = r⁺ − G/τ`, `G(0) = g(0) = 0` (plate and sensor start together). At a constant rate `r`, `G` settles at
//! `r·τ`: the "plate rate at the present current times the sensor lag"; the filter also remembers a faster rate of
//! the last few τ (a current that was just lowered). The same holds from below with a lower rate bound `r⁻` and `H`.
//!
//! The upper bound on the plate at the next step's end, for a reading `x̃` taken at `t_s`, is
//!
//! `U = x̃ + δ + G(t_s) + ∫_{t_s}^{now} r⁺ dt + r⁺(I_next)·Δt`,
//!
//! (the reading's error `δ`, the gap at the sample, the plate's possible rise since the sample — the sample age, up
//! to a sample period and more when the sensor freezes — and the rise over the step the current is about to drive,
//! one tick). Heating is cut when `U ≥ PLATE_MAX_C`; the lower bound `L` (with `−δ`, `H`, `r⁻`) cuts cooling when
//! `L ≤ PLATE_MIN_C`. The plate cannot rise further once heating is off: it has no thermal mass beyond its own node
//! (`thermode_device::channel`), so the bound's peak is the plate's peak.
//!
//! # The rate bounds
//! From the device's own configuration (what the firmware of that display is built for), at the drive's current `I`
//! and the hot side's reading `T_h` (the box sensor, rounded to its resolution):
//!
//! `C_d du/dt = q_d(I, u, T_h) + q_f`, with the Peltier heat `q_d = S I T_u + ½ I² R + K (T_h − u)`
//! ([`PeltierModule::heat_into_display_w`]) and the finger's heat `q_f = A h_c (T_skin − u)`.
//!
//! The firmware cannot know whether a finger rests on the plate, nor its temperature; it assumes only that the skin
//! surface lies between the plate and the body core ([`BODY_CORE_C`]), so
//! `A h_c · min(0, 37 − u) ≤ q_f ≤ A h_c · max(0, 37 − u)` (0 for a lifted finger, which is inside). `A h_c` is the
//! plate's contact conductance (area × `contact_conductance_w_m2k`): a finger's tissue only adds resistance. The
//! plate temperature in these terms is only known to lie in `[L, U]` (at the sample); the upper rate bound is the
//! largest of the (convex, piecewise affine) right-hand side at the two ends, the lower bound the smallest. The check
//! before a step uses the current about to be delivered; the bound's history uses the drive's own measurement of the
//! current it delivered (so a stuck drive is accounted for, though it cannot be cut).
//!
//! The reading's error `δ = 4σ + q` ([`NOISE_SIGMAS`] standard deviations of the sensor noise plus one quantisation
//! step): a reading that errs by more is rare (6·10⁻⁵ of the samples) and then only by hundredths of a degree.
//!
//! Numbers for the default display (S 6.37 mV/K, R 0.515 Ω, K 28 mW/K, C_d 0.28 J/K, τ 0.3 s), hot side at
//! 25 °C: at 2.5 A and 46 °C the plate can rise at 22 K/s, so `G` approaches 6.5 K and a host ramping at full
//! current is cut when the reading passes about 42 °C, the true plate near 47.4 °C; holding a finger at 48 °C takes
//! about 0.5 A, at which a lifted finger would let the plate rise at 1.6 K/s: heating is cut when the reading reaches
//! about 47.4 °C (45.5 °C with a 1.5 s sensor). The device's line therefore sits below 48 °C by the plate's possible
//! rise during the sensor's lag; a host that keeps its plate within that margin of 48 °C trips it
//! (`docs/protocol.md` §6.1).
//!
//! A reading outside the sensor's valid range (open: ≥ [`SENSOR_OPEN_THRESHOLD_C`], shorted: ≤
//! [`SENSOR_SHORT_THRESHOLD_C`], or not a number) leaves the plate unbounded: both directions are cut. A frozen
//! sensor stops the sample clock; the rise since the last sample grows until the bound cuts.

use thermode_device::config::CalibrationConfig;
use thermode_device::{CalibrationRefusal, DeviceConfig, SensorSample};
use thermode_model::peltier::PeltierModule;
use thermode_safety::{ABSOLUTE_MAX_C, ABSOLUTE_MIN_C};

use super::codec::{SENSOR_OPEN_THRESHOLD_C, SENSOR_SHORT_THRESHOLD_C};

/// The device cuts heating before its plate can pass this temperature \[°C\]: 48, the absolute maximum of the host's
/// safety envelope ([`ABSOLUTE_MAX_C`], IEC 60601-1's limit for 1–10 min contact).
pub const PLATE_MAX_C: f64 = ABSOLUTE_MAX_C;

/// The device cuts cooling before its plate can pass this temperature \[°C\]: 10, the host envelope's absolute
/// minimum ([`ABSOLUTE_MIN_C`], 3 K above the ISO 13732-3 numbness criterion).
pub const PLATE_MIN_C: f64 = ABSOLUTE_MIN_C;

/// A cut is released (by `ClearFault`) only once the plate's bound is this far back inside \[K\]: 1 (below 47 °C,
/// above 11 °C), so a plate at the line does not trip and release over and over.
pub const RELEASE_HYSTERESIS_C: f64 = 1.0;

/// The warmest a skin surface on the plate can be unless the plate made it so \[°C\]: 37, the body core.
pub const BODY_CORE_C: f64 = 37.0;

/// Standard deviations of the sensor noise in the reading's error bound \[-\]: 4.
pub const NOISE_SIGMAS: f64 = 4.0;

/// The sensor lag \[s\] a static line on the reading allows for: the file's sensor time constant, and never less
/// than the datasheet's (the built-in default file's 0.3 s), so that a file claiming a faster sensor (an identified
/// file tampered with, a fit gone wrong) cannot lift a device's threshold towards 48 °C (issue 35: a file claiming a
/// too-short lag lifted a MeCom threshold to 47.7 °C and the true plate reached 52 °C).
pub fn static_line_lag_s(config: &DeviceConfig) -> f64 {
    config
        .sensor
        .time_constant_s
        .max(DeviceConfig::default().sensor.time_constant_s)
}

/// What a sensor that lags its plate can hide at the display's fastest heating \[K\]: the plate's fastest heating
/// rate at full current times the sensor's time constant,
///
/// `M = τ · r_max`, `r_max = (S·I_max·T + ½·I_max²·R) / C_d` at `T` = [`PLATE_MAX_C`] (in kelvin), τ the
/// [`static_line_lag_s`],
///
/// with the hot side at the plate's temperature (no conduction back to the sink, the fastest case with a hot side
/// below 48 °C) and no finger (a finger below 48 °C only takes heat away). Under a constant rate `r` the gap
/// between plate and sensor settles at `r·τ` and never exceeds it while the rate is at most `r`, so a line on the
/// *reading* at `PLATE_MAX_C − M` keeps the true plate below `PLATE_MAX_C` for any current the drive can deliver,
/// with no host: the static line of a device that only compares its reading with a threshold (a MeCom controller's
/// upper object temperature threshold, `docs/hardware.md`). The own firmware's [`PlateGuard`] bounds the gap by the
/// same filter at the present current, so its cut never comes later than that static line would. Default display
/// (S 6.37 mV/K, R 0.515 Ω, C_d 0.28 J/K, I_max 2.8 A, τ 0.3 s): `r_max` 27.7 K/s, `M` 8.3 K, a line at 39.7 °C.
/// Fails if the configuration's module is invalid.
pub fn sensor_lag_margin_c(config: &DeviceConfig) -> Result<f64, thermode_model::ParamError> {
    let module = config.module()?;
    let heating_w = module.max_heating_w(config.drive.current_limit_a, PLATE_MAX_C, PLATE_MAX_C);
    let rate_c_per_s = heating_w.max(0.0) / config.plate.heat_capacity_j_k;
    Ok(static_line_lag_s(config) * rate_c_per_s)
}

/// What a sensor that lags its plate can hide at the display's fastest cooling \[K\]: the plate's fastest cooling rate
/// times the sensor's time constant,
///
/// `M⁻ = τ · r_cool`, `r_cool = (S·I·T − ½·I²·R) / C_d` at `T` = [`PLATE_MIN_C`] (in kelvin) and the cooling current
/// that draws the most heat, `I = min(I_max, S·T/R)`,
///
/// with the hot side at the plate's temperature and no finger (both only warm a plate below 37 °C). The mirror of
/// [`sensor_lag_margin_c`] for a line on the reading at `PLATE_MIN_C + M⁻`. Default display: `r_cool` 10.8 K/s,
/// `M⁻` 3.2 K, a line at 13.2 °C. Fails if the configuration's module is invalid.
pub fn sensor_lag_cooling_margin_c(config: &DeviceConfig) -> Result<f64, thermode_model::ParamError> {
    let module = config.module()?;
    let plate_k = PLATE_MIN_C + 273.15;
    let current_a = config
        .drive
        .current_limit_a
        .min(module.seebeck_v_k * plate_k / module.resistance_ohm);
    let cooling_w = -module.heat_into_display_w(-current_a, PLATE_MIN_C, PLATE_MIN_C);
    let rate_c_per_s = cooling_w.max(0.0) / config.plate.heat_capacity_j_k;
    Ok(static_line_lag_s(config) * rate_c_per_s)
}

/// How far beyond its lines ([`PLATE_MAX_C`], [`PLATE_MIN_C`]) the firmware's cut may come on the true scale under
/// a device file's calibration \[K\]: 0.5, so a sensor that reads low, honestly calibrated, still has its cut
/// stop the true plate by 48.5 °C (the line every host-kill test judges by; the cut itself peaks at 47.64 °C with an
/// honest sensor). The cut compares only the firmware's own reading and the protocol has no message to move it.
pub const CALIBRATION_MARGIN_C: f64 = 0.5;

/// `Ok` if the firmware's fixed cut, compared with its own reading, still holds the true plate within
/// [`CALIBRATION_MARGIN_C`] of its lines under `calibration` (the reading `gain · T + offset` at a true T: the cut
/// at a reading of 48 °C comes at a true `(48 − offset) / gain`); else the refusal that says by how much. A sensor
/// that reads high at 48 °C (or low at 10 °C) only makes the cut come earlier, and is allowed.
pub fn own_cut_allows(calibration: &CalibrationConfig) -> Result<(), CalibrationRefusal> {
    for (line_c, outward) in [(PLATE_MAX_C, 1.0), (PLATE_MIN_C, -1.0)] {
        let true_c = calibration.plate_c(line_c);
        if (true_c - line_c) * outward > CALIBRATION_MARGIN_C {
            return Err(CalibrationRefusal::BeyondFixedCut {
                gain: calibration.sensor_gain,
                offset_c: calibration.sensor_offset_c,
                line_c,
                error_c: calibration.reading_c(line_c) - line_c,
                true_c,
                margin_c: CALIBRATION_MARGIN_C,
            });
        }
    }
    Ok(())
}

/// What a channel's guard has cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Cuts {
    /// Heating is latched off: the plate could pass [`PLATE_MAX_C`].
    pub heating: bool,
    /// Cooling is latched off: the plate could pass [`PLATE_MIN_C`].
    pub cooling: bool,
}

/// A cut that tripped, with the numbers behind it (for tests and diagnostics).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardTrip {
    /// Which direction was cut (true: heating).
    pub heating: bool,
    /// The bound that tripped \[°C\]: the plate's upper bound for a heating cut, its lower bound for a cooling cut.
    pub bound_c: f64,
    /// The sensor reading at the time \[°C\].
    pub sensor_c: f64,
    /// The current the host had asked for \[A\].
    pub requested_a: f64,
}

/// The last sample the guard took and the bounds at its instant.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    seq: u64,
    value_c: f64,
    gap_hi_c: f64,
    gap_lo_c: f64,
}

/// Bounds on a plate's rate from its device file (the "rate bounds" of the module documentation): the Peltier heat
/// at a current, with the plate anywhere in a range and the hot side within its reading's error, and a finger whose
/// skin lies between the plate and the body core. The own firmware's [`PlateGuard`] and the MeCom host's dynamic
/// second line (`crate::mecom::line`) bound the gap between plate and sensor with it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateRates {
    module: PeltierModule,
    /// Heat capacity of the plate node \[J/K\].
    capacity_j_k: f64,
    /// Contact conductance of a finger on the plate, A h_c \[W/K\].
    contact_w_k: f64,
    /// Error bound of the hot-side reading \[K\] (its resolution).
    hot_error_c: f64,
}

impl PlateRates {
    /// The bounds of a display of `config`. Fails if the configuration's module is invalid.
    pub fn new(config: &DeviceConfig) -> Result<Self, thermode_model::ParamError> {
        Ok(PlateRates {
            module: config.module()?,
            capacity_j_k: config.plate.heat_capacity_j_k,
            contact_w_k: config.plate.area_m2 * config.plate.contact_conductance_w_m2k,
            hot_error_c: config.sensor.resolution_c,
        })
    }

    /// Lower and upper bounds on the plate's rate \[K/s\] at `current_a` \[A\] with the plate in `[lo, hi]` \[°C\] and
    /// the hot side reading `hot_side_c` \[°C\]; unbounded when a number is not finite.
    pub fn bounds_c_per_s(&self, current_a: f64, lo: f64, hi: f64, hot_side_c: f64) -> (f64, f64) {
        if !(lo.is_finite() && hi.is_finite() && current_a.is_finite() && hot_side_c.is_finite()) {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        let peltier = |plate_c: f64, hot_c: f64| self.module.heat_into_display_w(current_a, plate_c, hot_c);
        let finger = |plate_c: f64| self.contact_w_k * (BODY_CORE_C - plate_c);
        let upper = |plate_c: f64| peltier(plate_c, hot_side_c + self.hot_error_c) + finger(plate_c).max(0.0);
        let lower = |plate_c: f64| peltier(plate_c, hot_side_c - self.hot_error_c) + finger(plate_c).min(0.0);
        (
            lower(lo).min(lower(hi)) / self.capacity_j_k,
            upper(lo).max(upper(hi)) / self.capacity_j_k,
        )
    }
}

/// One channel's over- and under-temperature cut. See the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct PlateGuard {
    rates: PlateRates,
    /// Sensor time constant τ \[s\] (0: no lag).
    tau_s: f64,
    /// Error bound of a reading, δ \[K\].
    reading_error_c: f64,
    /// Bounds on plate − sensor element now \[K\].
    gap_hi_c: f64,
    gap_lo_c: f64,
    sample: Sample,
    /// Bounds on the plate's change since the sample \[K\].
    rise_hi_c: f64,
    rise_lo_c: f64,
    cuts: Cuts,
}

impl PlateGuard {
    /// A guard for a channel built from `config`, whose sensor's latest sample is `sample` and whose plate equals
    /// the sensor element (as at power-up). Fails if the configuration's module is invalid.
    pub fn new(config: &DeviceConfig, sample: SensorSample) -> Result<Self, thermode_model::ParamError> {
        let sensor = &config.sensor;
        Ok(PlateGuard {
            rates: PlateRates::new(config)?,
            tau_s: sensor.time_constant_s.max(0.0),
            reading_error_c: NOISE_SIGMAS * sensor.noise_c + sensor.resolution_c,
            gap_hi_c: 0.0,
            gap_lo_c: 0.0,
            sample: Sample {
                seq: sample.seq,
                value_c: sample.value_c,
                gap_hi_c: 0.0,
                gap_lo_c: 0.0,
            },
            rise_hi_c: 0.0,
            rise_lo_c: 0.0,
            cuts: Cuts::default(),
        })
    }

    /// What is cut.
    pub fn cuts(&self) -> Cuts {
        self.cuts
    }

    /// The bounds on the true plate now \[°C\]: (lower, upper); both infinite while the reading is invalid.
    pub fn plate_bounds_c(&self) -> (f64, f64) {
        let x = self.sample.value_c;
        if !reading_valid(x) {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        (
            x - self.reading_error_c + self.sample.gap_lo_c + self.rise_lo_c,
            x + self.reading_error_c + self.sample.gap_hi_c + self.rise_hi_c,
        )
    }

    /// Before a plant step of `dt_s` \[s\]: the current \[A\] the drive may deliver instead of `requested_a`
    /// (heating removed if heating is cut or would be, cooling likewise), and the trip if this call latched a cut.
    /// `hot_side_c` is the hot side's reading \[°C\].
    pub fn gate(&mut self, requested_a: f64, dt_s: f64, hot_side_c: f64) -> (f64, Option<GuardTrip>) {
        let (lo, hi) = self.plate_bounds_c();
        let mut trip = None;
        let both = Cuts {
            heating: true,
            cooling: true,
        };
        if !reading_valid(self.sample.value_c) && self.cuts != both {
            self.cuts = both;
            trip = Some(GuardTrip {
                heating: requested_a >= 0.0,
                bound_c: if requested_a >= 0.0 { hi } else { lo },
                sensor_c: self.sample.value_c,
                requested_a,
            });
        }
        let dt_s = if dt_s.is_finite() { dt_s.max(0.0) } else { 0.0 };
        if requested_a > 0.0 && !self.cuts.heating {
            let (_, rate_hi) = self.rates(requested_a, lo, hi, hot_side_c);
            let bound_c = hi.max(hi + rate_hi * dt_s);
            if bound_c >= PLATE_MAX_C {
                self.cuts.heating = true;
                trip = Some(GuardTrip {
                    heating: true,
                    bound_c,
                    sensor_c: self.sample.value_c,
                    requested_a,
                });
            }
        }
        if requested_a < 0.0 && !self.cuts.cooling {
            let (rate_lo, _) = self.rates(requested_a, lo, hi, hot_side_c);
            let bound_c = lo.min(lo + rate_lo * dt_s);
            if bound_c <= PLATE_MIN_C {
                self.cuts.cooling = true;
                trip = Some(GuardTrip {
                    heating: false,
                    bound_c,
                    sensor_c: self.sample.value_c,
                    requested_a,
                });
            }
        }
        let allowed_a = match requested_a {
            i if i > 0.0 && self.cuts.heating => 0.0,
            i if i < 0.0 && self.cuts.cooling => 0.0,
            i if i.is_nan() => 0.0,
            i => i,
        };
        (allowed_a, trip)
    }

    /// After a plant step of `dt_s` \[s\] that ended at `end_s` \[s\] with the drive delivering `applied_a` \[A\] (its own
    /// measurement) and the hot side reading `hot_side_c` \[°C\]: moves the bounds on and takes the sensor's latest
    /// `sample`.
    pub fn account(&mut self, dt_s: f64, end_s: f64, applied_a: f64, hot_side_c: f64, sample: SensorSample) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        let (lo, hi) = self.plate_bounds_c();
        let (rate_lo, rate_hi) = self.rates(applied_a, lo, hi, hot_side_c);
        self.gap_hi_c = self.filtered(self.gap_hi_c, rate_hi, dt_s);
        self.gap_lo_c = self.filtered(self.gap_lo_c, rate_lo, dt_s);
        if sample.seq != self.sample.seq {
            // The sample was taken within this step; the plate moved on for the rest of it.
            let since_s = (end_s - sample.time_s).clamp(0.0, dt_s);
            self.sample = Sample {
                seq: sample.seq,
                value_c: sample.value_c,
                gap_hi_c: self.gap_hi_c,
                gap_lo_c: self.gap_lo_c,
            };
            self.rise_hi_c = rate_hi * since_s;
            self.rise_lo_c = rate_lo * since_s;
        } else {
            self.rise_hi_c += rate_hi * dt_s;
            self.rise_lo_c += rate_lo * dt_s;
        }
    }

    /// `ClearFault`: releases each cut whose bound is back inside by [`RELEASE_HYSTERESIS_C`]; the others stay.
    pub fn release(&mut self) {
        let (lo, hi) = self.plate_bounds_c();
        if self.cuts.heating && hi <= PLATE_MAX_C - RELEASE_HYSTERESIS_C {
            self.cuts.heating = false;
        }
        if self.cuts.cooling && lo >= PLATE_MIN_C + RELEASE_HYSTERESIS_C {
            self.cuts.cooling = false;
        }
    }

    /// The gap bound after `dt_s` at a constant rate bound: the exact solution of `dG/dt = r − G/τ`.
    fn filtered(&self, gap_c: f64, rate_c_per_s: f64, dt_s: f64) -> f64 {
        if self.tau_s <= 0.0 {
            return 0.0;
        }
        let settled = rate_c_per_s * self.tau_s;
        settled + (gap_c - settled) * (-dt_s / self.tau_s).exp()
    }

    /// Lower and upper bounds on the plate's rate \[K/s\] at `current_a` with the plate in `[lo, hi]`.
    fn rates(&self, current_a: f64, lo: f64, hi: f64, hot_side_c: f64) -> (f64, f64) {
        self.rates.bounds_c_per_s(current_a, lo, hi, hot_side_c)
    }
}

/// Whether a reading is a temperature the plate can have (not open, not shorted, a number).
fn reading_valid(value_c: f64) -> bool {
    value_c.is_finite() && value_c < SENSOR_OPEN_THRESHOLD_C && value_c > SENSOR_SHORT_THRESHOLD_C
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lag_margin_of_the_default_display_is_its_fastest_rise_over_one_sensor_lag() {
        let margin_c = sensor_lag_margin_c(&DeviceConfig::default()).unwrap_or_else(|e| panic!("{e}"));
        // By hand: (6.37e-3 · 2.8 · 321.15 + ½ · 2.8² · 0.515) / 0.28 · 0.3 = 8.3 K.
        assert!(
            (margin_c - 8.3).abs() < 0.15,
            "lag margin {margin_c:.3} K, expected about 8.3 K"
        );
        let cooling_c = sensor_lag_cooling_margin_c(&DeviceConfig::default()).unwrap_or_else(|e| panic!("{e}"));
        // By hand: (6.37e-3 · 2.8 · 283.15 − ½ · 2.8² · 0.515) / 0.28 · 0.3 = 3.25 K.
        assert!(
            (cooling_c - 3.25).abs() < 0.1,
            "cooling lag margin {cooling_c:.3} K, expected about 3.25 K"
        );
        let mut slower = DeviceConfig::default();
        slower.sensor.time_constant_s *= 2.0;
        let doubled_c = sensor_lag_margin_c(&slower).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            (doubled_c - 2.0 * margin_c).abs() < 1e-9,
            "a sensor twice as slow hides twice as much: {doubled_c:.3} K against {margin_c:.3} K"
        );
        // A file claiming a sensor thirty times faster (0.01 s) keeps the datasheet's margin.
        let mut tampered = DeviceConfig::default();
        tampered.sensor.time_constant_s = 0.01;
        let tampered_c = sensor_lag_margin_c(&tampered).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            (tampered_c - margin_c).abs() < 1e-9,
            "a file claiming a faster sensor: {tampered_c:.3} K against the datasheet's {margin_c:.3} K"
        );
    }
}
