//! The MeCom controller's dynamic second line on heating: a current limitation (2030) and an upper object
//! temperature error threshold (4011) that the host keeps rewriting as the plate warms, so that the controller's own
//! coast after a host death stays below [`LINE_PLATE_MAX_C`] while the plate can reach the display's 48 °C in normal
//! use (issue 35 item 8).
//!
//! **Why not a fixed threshold.** The controller compares only its *reading* with 4011, and the sensor lags the plate:
//! heating at a rate r, the plate runs up to r·τ ahead of its reading. With the output left on after a host death (a
//! second client keeping the communication watchdog fed, or the watchdog's own 0.25 s), a threshold on the reading
//! lets the plate pass it by the gap. A fixed threshold must therefore allow for the fastest heating at full current
//! (48 °C − τ·r_max, 39.7 °C on the default display: `upper_error_threshold_c`), and no reading above it is possible.
//!
//! **The pair.** With the current limitation `I` in force, the plate's worst rate after a host death is `r(I)` (the
//! Peltier heat at `I` with the plate anywhere from the reading up to [`LINE_PLATE_MAX_C`], the hot side at its
//! reading, a finger at most at the body core: [`PlateRates`]), so the gap between plate and reading can grow to
//! `τ·r(I)` and no further; and it can start from the gap `G` the drive has built already. `G` is bounded the way the
//! own firmware bounds it (`crate::own::guard`): `dG/dt = r(I_delivered) − G/τ`, from the largest of the current
//! delivered and commanded between two cycles. A threshold
//!
//! `U = P − max(G, τ·r(I))`, `P` = [`LINE_PLATE_MAX_C`],
//!
//! therefore cuts the output before the true plate passes `P`, whoever keeps the watchdog fed. (The watchdog alone
//! would leave the plate at most where it is plus 0.25 s at the delivered current; the threshold bounds both cases.)
//!
//! **The limit that shrinks.** In normal use the reading must stay below `U` until the host writes the next pair, one
//! cycle later (`Δw`, [`LineState::limit_a`]): with the reading's error `δ` (4 σ of its noise and a quantisation
//! step), the reading `s` rising at most `max(G, τ·r)/τ`, the largest current the line allows is the one with
//! `s + δ + r(I)·(τ + Δw) ≤ P` (a share of it near the line, [`approach_share`], so the last kelvins are approached
//! smoothly), and none (the line *brakes*) while the gap already built, `G·(1 + Δw/τ)`, leaves no room above the
//! reading. So the limitation is the file's drive limit while the plate
//! is cool, shrinks as it warms (FIGURES), and a ramp at full current is slowed where its gap would carry the plate
//! past `P`.
//!
//! **The lag.** τ is the longest lag the envelope allows the sensor: the file's times `1 + render.sensor_lag_uncertainty`
//! (the uncertainty at least the self-test's own error, `SELF_TEST_LAG_ERROR`: a sensor that slow passes the
//! start-up self-test), and never less than the datasheet's (the built-in default file's 0.3 s): a file that claims
//! a faster sensor does not lift the line ([`line_lag_s`]).

use thermode_device::config::verified_lag_uncertainty;
use thermode_device::DeviceConfig;
use thermode_safety::ABSOLUTE_MAX_C;

use crate::own::guard::{PlateRates, NOISE_SIGMAS};

/// The hottest the true plate may become after a host death with the line in force \[°C\]: 48.3, the envelope's
/// absolute maximum (48) plus 0.3 K (issue 35 allows a dead host 48.5 °C; 0.2 K is left for the controller comparing
/// a noisy reading and the emulator's 1 ms tick).
pub const LINE_PLATE_MAX_C: f64 = ABSOLUTE_MAX_C + 0.3;

/// The shortest time the line assumes between two of a channel's writes \[s\]: 0.05 (one request and its answer take
/// about 7 ms at 57600 baud, a cycle of one channel about 50 ms, a loaded host later); the line uses twice the last measured interval
/// when that is longer.
pub const MIN_WRITE_INTERVAL_S: f64 = 0.1;

/// The share of the widest gap `g*` the limit lets the gap settle at, with `room_c` \[K\] between the reading (and
/// its error) and the line's maximum \[-\]: 1 with 12 K of room or more, falling linearly to 0.45 at the line. A
/// plate approaching the line exponentially at the rate its room allows builds a gap that reaches `g*` (and brakes
/// the drive, cycle after cycle) once the share passes `(τ + Δw)/(2τ + Δw)`, 0.55 on the default display; below it
/// the last kelvins are approached smoothly, while a cool plate keeps the drive's full current.
pub fn approach_share(room_c: f64) -> f64 {
    0.45 + 0.55 * (room_c / 12.0).clamp(0.0, 1.0)
}

/// The lag \[s\] every device-side line of a display of `device` allows for: the file's sensor time constant times
/// `1 + render.sensor_lag_uncertainty` (at least the self-test's own error), and never less than the datasheet's
/// (the built-in default file's).
pub fn line_lag_s(device: &DeviceConfig) -> f64 {
    let filed_s =
        device.sensor.time_constant_s * (1.0 + verified_lag_uncertainty(device.render.sensor_lag_uncertainty));
    filed_s.max(DeviceConfig::default().sensor.time_constant_s)
}

/// What a display's device file tells the line: the plate's rate bounds, the lag, the reading's error and the
/// drive's limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeatingLine {
    rates: PlateRates,
    /// The lag allowed for \[s\] ([`line_lag_s`]).
    lag_s: f64,
    /// The reading's error bound δ \[K\]: 4 σ of the sensor noise and one quantisation step.
    reading_error_c: f64,
    /// The file's drive limit \[A\]: the largest limitation written.
    current_limit_a: f64,
}

impl HeatingLine {
    /// The line of a display of `device`. Fails if its module is invalid.
    pub fn new(device: &DeviceConfig) -> Result<Self, thermode_model::ParamError> {
        Ok(HeatingLine {
            rates: PlateRates::new(device)?,
            lag_s: line_lag_s(device),
            reading_error_c: NOISE_SIGMAS * device.sensor.noise_c + device.sensor.resolution_c,
            current_limit_a: device.drive.current_limit_a.max(0.0),
        })
    }

    /// The lag the line allows for \[s\].
    pub fn lag_s(&self) -> f64 {
        self.lag_s
    }

    /// The largest limitation it writes \[A\] (the file's drive limit).
    pub fn current_limit_a(&self) -> f64 {
        self.current_limit_a
    }

    /// The plate's fastest heating \[K/s\] at a heating current `current_a` \[A\], with the plate anywhere from the
    /// reading `reading_c` \[°C\] less its error up to [`LINE_PLATE_MAX_C`] and the hot side reading `hot_side_c`
    /// \[°C\]; at least 0, infinite when a number is not finite.
    pub fn rate_c_per_s(&self, current_a: f64, reading_c: f64, hot_side_c: f64) -> f64 {
        let lo_c = reading_c - self.reading_error_c;
        let (_, hi_c_per_s) =
            self.rates
                .bounds_c_per_s(current_a.max(0.0), lo_c, LINE_PLATE_MAX_C.max(lo_c), hot_side_c);
        if hi_c_per_s.is_nan() {
            f64::INFINITY
        } else {
            hi_c_per_s.max(0.0)
        }
    }

    /// The largest current up to the drive's limit whose [`HeatingLine::rate_c_per_s`] is at most `rate_c_per_s`
    /// \[A\] (bisection to 1 mA; 0 when even no current exceeds it).
    fn current_for_rate_a(&self, rate_c_per_s: f64, reading_c: f64, hot_side_c: f64) -> f64 {
        let rate = |a: f64| self.rate_c_per_s(a, reading_c, hot_side_c);
        if rate(self.current_limit_a) <= rate_c_per_s {
            return self.current_limit_a;
        }
        let idle_rate = rate(0.0);
        if idle_rate > rate_c_per_s || idle_rate.is_nan() || rate_c_per_s.is_nan() {
            return 0.0;
        }
        let (mut lo_a, mut hi_a) = (0.0, self.current_limit_a);
        while hi_a - lo_a > 1e-3 {
            let mid_a = 0.5 * (lo_a + hi_a);
            if rate(mid_a) <= rate_c_per_s {
                lo_a = mid_a;
            } else {
                hi_a = mid_a;
            }
        }
        lo_a
    }
}

/// One channel's line as the host tracks it: the gap bound and the interval between its writes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LineState {
    /// Bound on plate − reading \[K\] (G).
    gap_c: f64,
    /// Host time of the last account \[s\].
    time_s: Option<f64>,
    /// The interval between the last two accounts \[s\].
    interval_s: f64,
}

impl LineState {
    /// Accounts the time up to `now_s` \[s\] since the last account, over which the drive delivered at most the
    /// heating current `heating_a` \[A\], with the reading `reading_c` and the hot side `hot_side_c` \[°C\] of now.
    pub fn account(&mut self, line: &HeatingLine, now_s: f64, heating_a: f64, reading_c: f64, hot_side_c: f64) {
        if let Some(last_s) = self.time_s {
            let dt_s = now_s - last_s;
            if dt_s <= 0.0 || dt_s.is_nan() {
                return;
            }
            let settled_c = line.lag_s * line.rate_c_per_s(heating_a, reading_c, hot_side_c);
            self.gap_c = if settled_c.is_finite() {
                settled_c + (self.gap_c - settled_c) * (-dt_s / line.lag_s).exp()
            } else {
                f64::INFINITY
            };
            self.interval_s = dt_s;
        }
        self.time_s = Some(now_s);
    }

    /// The bound on plate − reading now \[K\].
    pub fn gap_c(&self) -> f64 {
        self.gap_c
    }

    /// The time the line allows until the channel's next write \[s\]: twice the last interval, at least
    /// [`MIN_WRITE_INTERVAL_S`].
    pub fn write_interval_s(&self) -> f64 {
        (2.0 * self.interval_s).max(MIN_WRITE_INTERVAL_S)
    }

    /// The largest heating current the line allows now \[A\] with the reading `reading_c` and the hot side
    /// `hot_side_c` \[°C\]. The reading must stay below the threshold until the next write: with the gap `g` the
    /// plate may have, the threshold is `P − g` and the reading rises at most `g/τ` meanwhile, so the largest gap
    /// that allows it is `g* = room/(1 + Δw/τ)` (`room` = `P − s − δ`). While the gap already built is below `g*` the
    /// limit is the current whose gap settles at a share of `g*` ([`approach_share`]); once it reaches `g*` the line
    /// brakes (0 A: the gap then shrinks faster than the room). 0 when a number is not finite.
    pub fn limit_a(&self, line: &HeatingLine, reading_c: f64, hot_side_c: f64) -> f64 {
        let write_s = self.write_interval_s();
        let room_c = LINE_PLATE_MAX_C - reading_c - line.reading_error_c;
        let widest_c = room_c / (1.0 + write_s / line.lag_s);
        if !(widest_c > 0.0 && self.gap_c < widest_c) {
            return 0.0;
        }
        let settled_c = approach_share(room_c) * widest_c;
        line.current_for_rate_a(settled_c / line.lag_s, reading_c, hot_side_c)
    }

    /// The upper threshold \[°C\] that keeps the plate below [`LINE_PLATE_MAX_C`] after a host death with the
    /// limitation `limit_a` \[A\] in force (NaN when a number is not finite: nothing is written then).
    pub fn upper_c(&self, line: &HeatingLine, limit_a: f64, reading_c: f64, hot_side_c: f64) -> f64 {
        let coast_c = line.lag_s * line.rate_c_per_s(limit_a, reading_c, hot_side_c);
        let upper_c = LINE_PLATE_MAX_C - self.gap_c.max(coast_c);
        if upper_c.is_finite() {
            upper_c
        } else {
            f64::NAN
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn default_line() -> HeatingLine {
        HeatingLine::new(&DeviceConfig::default()).unwrap_or_else(|e| panic!("{e}"))
    }

    /// The datasheet file's lag is 0.3 s with an uncertainty of 0.5: the line allows 0.45 s; a file claiming a
    /// faster sensor is held at the datasheet's 0.3 s; an identified 0.31 s with 0.065 is allowed the self-test's
    /// own error instead: 0.31 · 1.15 = 0.3565 s (0.33015 s would be below what the self-test can tell apart).
    #[test]
    fn the_line_allows_the_files_slowest_sensor_and_never_less_than_the_datasheets() {
        assert!((line_lag_s(&DeviceConfig::default()) - 0.45).abs() < 1e-12);
        let mut tampered = DeviceConfig::default();
        tampered.sensor.time_constant_s = 0.01;
        assert!((line_lag_s(&tampered) - 0.3).abs() < 1e-12, "{}", line_lag_s(&tampered));
        let mut identified = DeviceConfig::default();
        identified.sensor.time_constant_s = 0.31;
        identified.render.sensor_lag_uncertainty = 0.065;
        assert!(
            (line_lag_s(&identified) - 0.3565).abs() < 1e-9,
            "{} s, expected 0.3565 s",
            line_lag_s(&identified)
        );
        identified.render.sensor_lag_uncertainty = 0.2;
        assert!(
            (line_lag_s(&identified) - 0.372).abs() < 1e-9,
            "{} s, expected 0.372 s",
            line_lag_s(&identified)
        );
    }

    /// At rest the limit is the drive's at a cool plate and shrinks as the plate warms; every pair it gives keeps
    /// the coast (threshold plus the lag times the rate at the limit) at the line's maximum, and at 48 °C the limit
    /// still holds a bare plate there (0.31 A against a hot side at 25 °C, by hand: K·23 K = S·I·T + ½I²R).
    #[test]
    fn the_limit_shrinks_as_the_plate_warms_and_each_pair_keeps_the_coast_below_the_line() {
        let line = default_line();
        let state = LineState::default();
        let mut previous_a = f64::INFINITY;
        for reading_c in [30.0, 36.0, 40.0, 44.0, 46.0, 47.0, 48.0] {
            let limit_a = state.limit_a(&line, reading_c, 25.0);
            let upper_c = state.upper_c(&line, limit_a, reading_c, 25.0);
            let coast_c = upper_c + line.lag_s() * line.rate_c_per_s(limit_a, reading_c, 25.0);
            println!("reading {reading_c} °C: limit {limit_a:.3} A, threshold {upper_c:.2} °C, coast {coast_c:.2} °C");
            assert!(
                limit_a <= previous_a,
                "{reading_c} °C: {limit_a} A after {previous_a} A"
            );
            assert!(coast_c <= LINE_PLATE_MAX_C + 1e-9, "{reading_c} °C: {coast_c} °C");
            assert!(upper_c > reading_c, "{reading_c} °C: threshold {upper_c} °C");
            previous_a = limit_a;
        }
        assert!((state.limit_a(&line, 30.0, 25.0) - 2.8).abs() < 1e-12);
        let at_48_a = state.limit_a(&line, 48.0, 25.0);
        assert!((0.31..0.4).contains(&at_48_a), "at 48 °C: {at_48_a} A");
    }

    /// A ramp at full current builds a gap of τ·r(2.8 A), about 12 K: the line brakes (limit 0) where that gap would
    /// carry the plate past its maximum, and releases once the gap has decayed.
    #[test]
    fn a_gap_built_at_full_current_brakes_the_drive_until_it_decays() {
        let line = default_line();
        let mut state = LineState::default();
        let mut time_s = 0.0;
        for _ in 0..80 {
            state.account(&line, time_s, 2.8, 30.0, 25.0);
            time_s += 0.05;
        }
        let settled_c = line.lag_s() * line.rate_c_per_s(2.8, 30.0, 25.0);
        assert!(
            (state.gap_c() - settled_c).abs() < 0.01 * settled_c,
            "gap {} K",
            state.gap_c()
        );
        assert_eq!(state.limit_a(&line, 36.0, 25.0), 0.0, "gap {} K", state.gap_c());
        for _ in 0..40 {
            state.account(&line, time_s, 0.0, 36.0, 25.0);
            time_s += 0.05;
        }
        assert!(state.limit_a(&line, 36.0, 25.0) > 2.0, "gap {} K", state.gap_c());
    }

    #[test]
    fn numbers_that_are_not_finite_brake_and_write_nothing() {
        let line = default_line();
        let state = LineState::default();
        assert_eq!(state.limit_a(&line, f64::NAN, 25.0), 0.0);
        assert!(state.upper_c(&line, 0.0, f64::NAN, 25.0).is_nan());
        assert!(state.upper_c(&line, 1.0, 40.0, f64::INFINITY).is_nan());
    }
}
