//! The plate guard: a Kalman observer of the device's thermal model ([`PlateObserver`]) that runs on every channel,
//! whatever its controller, and gives the safety envelope the estimate and one-tick forecast of the true plate
//! ([`PlateForecast`]). It is the envelope's own model, separate from any controller's, so a controller that
//! misjudges the plate (the paper's PID on a lagging sensor) cannot take the envelope's view with it.
//!
//! Per tick, before the drive is gated: the observer is advanced over the interval since the previous tick with the
//! current the envelope let through then and the display's finger model, and corrected with both readings when the
//! PT-100 gave a fresh sample (between samples it coasts: [`PlateObserver::coast`], [`PlateObserver::update_fresh`]);
//! the forecast then predicts the plate at the end of the coming tick for any current
//! ([`PlateObserver::predict_plate_c`]).
//!
//! **A model that is not its display.** The observer is only as good as the device file: on a display whose sensor
//! lags 30 % more, or whose module heats 30 % harder, than its file says, the estimate ran up to 2.4 °C behind a
//! plate heating at full current, and the plate reached 50.1 °C under a 48 °C maximum. So the forecast is also held
//! to what the PT-100 alone says: a first-order sensor trails the plate by its time constant times its own rate, so
//! while the reading moves the plate is at least `reading + (1 + u) τ ṙ` along in that direction, with τ the file's
//! time constant, u its stated uncertainty (device file `render.sensor_lag_uncertainty`: a sensor up to that much
//! slower than its file) and ṙ the reading's steepest rate against its readings of 40–200 ms ago (beyond the noise's
//! 2 °C/s). Where that bound lies beyond the model's forecast, the forecast's range is widened to it on that side
//! only ([`PlateForecast::plate_after_range_c`]: a bound on a rising plate must not let it cool past the minimum).
//! That trend cannot see a plate swung by pulses shorter than its window (a controller chattering at full current at
//! the display's limit: 48.21 °C under a 48 °C maximum on a sensor 30 % slower than its file), so a second observer
//! runs beside the first with the slowest sensor the file allows, `(1 + u) τ`, and its forecast widens the range the
//! same way: where the plate is if the sensor is that slow. A file exact for its display (u = 0: a simulated display
//! built from it) has neither bound: its model is the display (figures in `docs/security.md`).

use thermode_control::{Finger, ObserverDesign, ObserverTick, PlantModel, PlateObserver};
use thermode_device::Reading;
use thermode_safety::{PlateForecast, PlateNow};

use crate::error::PipelineError;
use crate::reading_check::{Disagreement, ReadingCheck, DISTRUST_MARGIN_C};

/// How much faster the unknown heat of a temperature-commanded device's guard may drift than the default's: 10
/// (the device's own regulation is heat the model is not told of).
pub const REGULATED_DRIFT_RATIO: f64 = 10.0;

/// Readings the trend keeps (at least [`TREND_SPACING_S`] apart, so 240 ms or more of them).
const TREND_READINGS: usize = 24;
/// Smallest spacing of the readings the trend keeps \[s\]: 10 ms (the PT-100's sample period; at a faster tick the
/// same sample is held).
const TREND_SPACING_S: f64 = 0.01;
/// The trend's rates are taken against readings 40 to 200 ms old \[s\]: long enough that the sensor's noise
/// (0.02 °C, 0.01 °C steps) gives rates under [`TREND_NOISE_RATE_C_PER_S`], short enough to follow a plate at full
/// current.
const TREND_WINDOW_S: (f64, f64) = (0.04, 0.2);
/// A steepest rate of at most this is the sensor's noise, not a moving plate \[°C/s\]: 2 (a difference of 0.08 °C
/// over 40 ms; taken as the plate's motion, it made the guard hold a plate at the display's minimum with the drive
/// swinging between ±2.8 A).
const TREND_NOISE_RATE_C_PER_S: f64 = 2.0;

/// The PT-100's recent trend: its newest reading and its steepest rate over the last 40–200 ms.
#[derive(Debug, Clone)]
struct SensorTrend {
    /// (time \[s\], reading \[°C\]) at least [`TREND_SPACING_S`] apart, oldest overwritten first.
    readings: [(f64, f64); TREND_READINGS],
    next: usize,
    newest_c: f64,
    /// The steepest rate against the kept readings within [`TREND_WINDOW_S`] \[°C/s\], 0 when it is within the
    /// noise ([`TREND_NOISE_RATE_C_PER_S`]) or there is none.
    rate_c_per_s: f64,
}

impl SensorTrend {
    fn new() -> Self {
        SensorTrend {
            readings: [(f64::NAN, f64::NAN); TREND_READINGS],
            next: 0,
            newest_c: f64::NAN,
            rate_c_per_s: 0.0,
        }
    }

    /// Takes the finite reading `sensor_c` at `now_s`. The rate is renewed when the reading is kept (every
    /// [`TREND_SPACING_S`] or more: a faster tick sees the same held sample in between).
    fn record(&mut self, now_s: f64, sensor_c: f64) {
        let last_s = self.readings[(self.next + TREND_READINGS - 1) % TREND_READINGS].0;
        // The first reading (no last one: NaN) is kept too.
        if !(last_s.is_nan() || now_s - last_s >= TREND_SPACING_S) {
            return;
        }
        self.newest_c = sensor_c;
        let rate = self.steepest_rate_c_per_s(now_s, sensor_c);
        self.rate_c_per_s = if rate.abs() > TREND_NOISE_RATE_C_PER_S {
            rate
        } else {
            0.0
        };
        self.readings[self.next] = (now_s, sensor_c);
        self.next = (self.next + 1) % TREND_READINGS;
    }

    /// The steepest rate of `sensor_c` at `now_s` against the kept readings 40–200 ms old ([`TREND_WINDOW_S`])
    /// \[°C/s\]: of largest magnitude, with its sign (0 without one). Rates are compared cross-multiplied, with one
    /// division at the end.
    fn steepest_rate_c_per_s(&self, now_s: f64, sensor_c: f64) -> f64 {
        let (mut change_c, mut span_s) = (0.0_f64, 1.0_f64);
        for &(t, c) in &self.readings {
            let age_s = now_s - t;
            if (TREND_WINDOW_S.0..=TREND_WINDOW_S.1).contains(&age_s) {
                let candidate_c = sensor_c - c;
                if candidate_c.abs() * span_s > change_c.abs() * age_s {
                    (change_c, span_s) = (candidate_c, age_s);
                }
            }
        }
        change_c / span_s
    }

    /// Where a first-order sensor of time constant `lag_s` \[s\] puts the plate at least, in the direction the
    /// reading moves \[°C\] (NaN before the first reading).
    fn plate_bound_c(&self, lag_s: f64) -> f64 {
        self.newest_c + lag_s * self.rate_c_per_s
    }
}

/// The envelope's model of one channel's plate.
#[derive(Debug, Clone)]
pub struct PlateGuard {
    observer: PlateObserver,
    /// The same observer with the sensor as slow as the file allows, `(1 + u) τ`: where the plate is if the
    /// sensor lags that much (`None` for a file exact for its display, u = 0).
    slow_observer: Option<PlateObserver>,
    /// Time of the previous update \[s\] (`None` before the first).
    last_time_s: Option<f64>,
    /// The sample number of the last PT-100 sample the observer corrected with (`None` before the first).
    last_sample_seq: Option<u64>,
    trend: SensorTrend,
    /// The sensor lag of the bound, `(1 + u) τ` \[s\]; `None` for a file exact for its display (u = 0).
    bound_lag_s: Option<f64>,
    /// Whether the reading still measures the plate ([`crate::reading_check`]); `None` where the plate is not
    /// driven by the current the model is given (a temperature-commanded device).
    reading_check: Option<ReadingCheck>,
}

/// The plate guard's forecast over one tick.
#[derive(Debug, Clone, Copy)]
pub struct TickForecast<'a> {
    observer: &'a PlateObserver,
    /// The observer with the slowest sensor the file allows, if any.
    slow_observer: Option<&'a PlateObserver>,
    /// How far the sensor's bound lies beyond the model's estimate in the direction the reading moves \[°C\]
    /// (positive rising, negative falling, 0 when the estimate is already beyond it or there is no bound).
    beyond_c: f64,
    /// Length of the tick \[s\].
    dt_s: f64,
    /// The finger model on the plate.
    finger: Finger,
}

impl PlateGuard {
    /// A guard of the display described by `plant` (validated), whose sensor may lag by up to `1 +
    /// sensor_lag_uncertainty` times the plant's time constant (0: exactly it, no sensor bound), with no estimate
    /// yet.
    pub fn new(plant: PlantModel, sensor_lag_uncertainty: f64) -> Result<Self, PipelineError> {
        let bound_lag_s =
            (sensor_lag_uncertainty > 0.0).then_some((1.0 + sensor_lag_uncertainty) * plant.sensor_time_constant_s);
        Ok(PlateGuard {
            slow_observer: bound_lag_s
                .map(|lag_s| slow_sensor_observer(&plant, lag_s))
                .transpose()?,
            observer: PlateObserver::new(plant)?,
            last_time_s: None,
            last_sample_seq: None,
            trend: SensorTrend::new(),
            bound_lag_s,
            reading_check: Some(ReadingCheck::new()),
        })
    }

    /// This guard for a device that regulates its plate itself (temperature-commanded): no innovation check
    /// ([`crate::reading_check`]: the current the model is given is not what drives the plate), and an observer whose
    /// unknown heat follows the plate [`REGULATED_DRIFT_RATIO`] times faster, so that without a reported current
    /// (a TCS II) the estimate follows the reading's lag-corrected plate instead of trailing the device's own
    /// regulation by up to 15 °C (a 24 → 32 °C approach).
    pub fn for_regulating_device(mut self) -> Result<Self, PipelineError> {
        self.reading_check = None;
        let plant = *self.observer.plant();
        let design = ObserverDesign {
            disturbance_drift_per_sqrt_s: REGULATED_DRIFT_RATIO
                * ObserverDesign::default().disturbance_drift_per_sqrt_s,
            ..ObserverDesign::default()
        };
        self.observer = PlateObserver::with_design(plant, design)?;
        if let Some(slow) = &mut self.slow_observer {
            let mut slow_plant = plant;
            slow_plant.sensor_time_constant_s = slow.plant().sensor_time_constant_s;
            *slow = PlateObserver::with_design(slow_plant, design)?;
        }
        Ok(self)
    }

    /// Updates the estimate at `now_s` \[s\] with `reading`, after the device delivered the current it reports
    /// (`reading.current_a`; the envelope's `gated_current_a` \[A\] where it reports none) since the previous update,
    /// with `finger` on the plate. The observer corrects on a fresh PT-100 sample only and
    /// coasts through the ticks that see a held one ([`PlateObserver::update_fresh`]: the filter's covariance costs a
    /// few hundred flops, once per sample instead of once per tick). A reading the observer refuses (non-finite
    /// numbers, time not moving forward) leaves the estimate as it was: the envelope latches its own fault on such a
    /// reading. Returns whether `reading` is a fresh PT-100 sample (the controller's observer corrects on the same).
    pub fn update(&mut self, now_s: f64, reading: &Reading, gated_current_a: f64, finger: Finger) -> bool {
        let dt_s = self.last_time_s.map_or(1.0, |t| now_s - t);
        let applied_current_a = delivered_current_a(reading, gated_current_a);
        if let Some(check) = &mut self.reading_check {
            check.coast(dt_s, applied_current_a, finger);
        }
        if self.last_sample_seq == Some(reading.sample_seq) {
            self.observer.coast(dt_s, applied_current_a, finger);
            if let Some(slow) = &mut self.slow_observer {
                slow.coast(dt_s, applied_current_a, finger);
            }
            if dt_s > 0.0 {
                self.last_time_s = Some(now_s);
            }
            return false;
        }
        let tick = ObserverTick {
            // The first update only initialises the estimate from the readings; its dt is not used.
            dt_s,
            applied_current_a,
            finger,
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
        };
        if let Some(slow) = &mut self.slow_observer {
            // Refused exactly when the main observer refuses (the same tick): its state is left as it was too.
            let _ = slow.update_fresh(&tick);
        }
        if self.observer.update_fresh(&tick).is_ok() {
            self.last_time_s = Some(now_s);
            self.last_sample_seq = Some(reading.sample_seq);
            self.trend.record(now_s, reading.sensor_c);
            if let Some(check) = &mut self.reading_check {
                check.judge(now_s, reading.sensor_c, &self.observer);
            }
        }
        true
    }

    /// The innovation check's verdict: the reading stopped following the plate model under a drive
    /// ([`crate::reading_check`]); it stays once given.
    pub fn reading_disagreement(&self) -> Option<Disagreement> {
        self.reading_check.as_ref().and_then(ReadingCheck::verdict)
    }

    /// Where the dose counts the plate while the reading is not believed \[°C\]: the innovation check's shadow
    /// (the model run open loop since the reading last agreed) plus [`DISTRUST_MARGIN_C`] (NaN without one).
    pub fn distrusted_plate_c(&self) -> f64 {
        self.reading_check
            .as_ref()
            .map_or(f64::NAN, |check| check.shadow_plate_c() + DISTRUST_MARGIN_C)
    }

    /// Forgets the estimate (the next reading starts it afresh) and the innovation check's shadow; a verdict
    /// stays. For a channel whose fault was cleared: the readings that faulted it (an open sensor's 850 °C) are no
    /// plate the model should start from.
    pub fn restart(&mut self) {
        self.observer.reset();
        if let Some(slow) = &mut self.slow_observer {
            slow.reset();
        }
        self.last_time_s = None;
        self.last_sample_seq = None;
        self.trend = SensorTrend::new();
        if let Some(check) = &mut self.reading_check {
            check.restart_shadow();
        }
    }

    /// Bounds the plate from here on with a sensor lag of at least `lag_s` \[s\] (a self-test measured the sensor
    /// slower than the file; a shorter or NaN `lag_s` changes nothing).
    pub fn allow_sensor_lag(&mut self, lag_s: f64) {
        let current_s = self.bound_lag_s.unwrap_or(0.0);
        if lag_s > current_s {
            self.bound_lag_s = Some(lag_s);
            // A model the observer refuses (a lag beyond its range) keeps the slower sensor's bound from the trend.
            if let Ok(slow) = slow_sensor_observer(self.observer.plant(), lag_s) {
                self.slow_observer = Some(slow);
            }
        }
    }

    /// The estimated true plate \[°C\] (NaN before the first reading).
    pub fn plate_estimate_c(&self) -> f64 {
        self.observer.estimate().map_or(f64::NAN, |e| e.plate_c)
    }

    /// How far the sensor's bound lies beyond the model's estimate, in the direction the reading moves \[°C\]
    /// (see the module documentation; 0 before the first reading).
    fn beyond_estimate_c(&self) -> f64 {
        let Some(lag_s) = self.bound_lag_s else {
            return 0.0;
        };
        let gap_c = self.trend.plate_bound_c(lag_s) - self.plate_estimate_c();
        let rate = self.trend.rate_c_per_s;
        if !gap_c.is_finite() {
            0.0
        } else if rate > 0.0 {
            gap_c.max(0.0)
        } else if rate < 0.0 {
            gap_c.min(0.0)
        } else {
            0.0
        }
    }

    /// The forecast over a tick of `dt_s` \[s\] with `finger` on the plate.
    pub fn forecast(&self, dt_s: f64, finger: Finger) -> TickForecast<'_> {
        TickForecast {
            observer: &self.observer,
            slow_observer: self.slow_observer.as_ref(),
            beyond_c: self.beyond_estimate_c(),
            dt_s,
            finger,
        }
    }
}

impl PlateForecast for TickForecast<'_> {
    fn now(&self) -> Option<PlateNow> {
        self.observer.estimate().map(|e| PlateNow {
            plate_c: e.plate_c,
            sd_c: e.plate_sd_c,
        })
    }

    fn plate_after_c(&self, current_a: f64) -> f64 {
        self.observer
            .predict_plate_c(self.dt_s, current_a, self.finger)
            .unwrap_or(f64::NAN)
    }

    /// The model's forecast, widened on the side a current drives the plate to where the slowest sensor the file
    /// allows puts it (the slow-sensor observer's forecast, and the sensor's trend bound on the side the reading
    /// moves): the bounds stop heating (or cooling) a plate the model may lag, but never make the envelope drive
    /// the other way on a worst case alone.
    fn plate_after_range_c(&self, current_a: f64) -> (f64, f64) {
        let plate_c = self.plate_after_c(current_a);
        let slow_c = self
            .slow_observer
            .and_then(|slow| slow.predict_plate_c(self.dt_s, current_a, self.finger))
            .unwrap_or(plate_c);
        let (lower_c, upper_c) = (self.beyond_c.min(0.0), self.beyond_c.max(0.0));
        if current_a < 0.0 {
            ((plate_c + lower_c).min(slow_c), plate_c)
        } else if current_a > 0.0 {
            (plate_c, (plate_c + upper_c).max(slow_c))
        } else {
            (plate_c, plate_c)
        }
    }

    fn strongest_cooling_a(&self) -> f64 {
        let plate_c = self.observer.estimate().map_or(f64::NAN, |e| e.plate_c);
        self.observer.plant().most_useful_cooling_a(plate_c)
    }
}

/// The current that drove the plate over the interval the reading ends \[A\]: the one the device reports delivering
/// (its own measurement: a drive stuck at its limit, a command still in transit on a slow link, a channel switched
/// off by the loop), else the one the envelope gated, `gated_current_a` \[A\].
fn delivered_current_a(reading: &Reading, gated_current_a: f64) -> f64 {
    if reading.current_a.is_finite() {
        reading.current_a
    } else {
        gated_current_a
    }
}

/// An observer of `plant` with its sensor's time constant `lag_s` \[s\].
fn slow_sensor_observer(plant: &PlantModel, lag_s: f64) -> Result<PlateObserver, PipelineError> {
    let mut slow = *plant;
    slow.sensor_time_constant_s = lag_s;
    Ok(PlateObserver::new(slow)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reading of `plate_c(t)` sampled at 100 Hz with ±0.02 °C of alternating noise and 0.01 °C steps, recorded
    /// every 10 ms for `duration_s`: the trend's rate at the end.
    fn trend_rate(plate_c: impl Fn(f64) -> f64, duration_s: f64) -> f64 {
        let mut trend = SensorTrend::new();
        for k in 0..=(duration_s / 0.01).round() as usize {
            let t = k as f64 * 0.01;
            let noise_c = if k % 2 == 0 { 0.02 } else { -0.02 };
            trend.record(t, ((plate_c(t) + noise_c) / 0.01).round() * 0.01);
        }
        trend.rate_c_per_s
    }

    #[test]
    fn the_trend_follows_a_ramp_and_ignores_noise() {
        for rate in [20.0, -15.0, 5.0] {
            let got = trend_rate(|t| 30.0 + rate * t, 0.5);
            assert!((got - rate).abs() < 1.5, "ramp of {rate} °C/s: trend {got} °C/s");
        }
        let still = trend_rate(|_| 30.0, 0.5);
        assert_eq!(still, 0.0, "a still plate: trend {still} °C/s");
        let slow = trend_rate(|t| 30.0 + t, 0.5);
        assert_eq!(slow, 0.0, "1 °C/s is within the noise: trend {slow} °C/s");
        assert_eq!(trend_rate(|t| 30.0 + 20.0 * t, 0.02), 0.0, "no reading 40 ms old yet");
    }
}
