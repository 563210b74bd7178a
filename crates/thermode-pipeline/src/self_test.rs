//! The display checked against its device file before a finger can be on it: a short current pulse from rest
//! ([`SelfTest::current_a`]), the plate sensor's answer recorded, and the two numbers that decide whether the safety
//! envelope can trust its model of the plate measured against the file ([`assess`]): how slow the sensor is, and how
//! fast the plate answers heat. The verdict is one of three ([`Verdict`]): the display matches its file, it does not
//! (refused, fault E106), or the test cannot tell ([`Inconclusive`]: held off, fault E108, until `clear_fault` tests
//! it again).
//!
//! **Why.** The envelope bounds the true plate by a model of the display and by its sensor; it allows for a sensor
//! up to `render.sensor_lag_uncertainty` slower than the file and a plate that answers heat up to twice as fast (its
//! observer's response range). Rendered on displays off their file (copper at 150 and −50 °C, both controllers), a
//! sensor twice as slow as the file let the true plate reach 50.5 °C and 14.1 °C, five times as slow 61.7 °C, and a
//! plate of 0.3 times the file's heat capacity 48.6 °C; inside those allowances the plate stayed within 14.5–48.5 °C
//! (docs/security.md).
//!
//! **Rest.** Before its pulse the test waits for the display to rest: the least-squares slope of the readings over
//! the last [`REST_WINDOW_S`] below [`REST_DRIFT_C_PER_S`] ([`RestWatch`]), at most [`REST_LIMIT_S`]. A display that
//! still drifts then (a plate warming back after a cold touch before a restart) is pulsed if the drift is at most
//! [`MAX_DRIFT_C_PER_S`], the drift measured over the rest window subtracted from the answer; beyond it the test is
//! inconclusive.
//!
//! **Fit.** The response to the pulse, taken as the readings' departure from the first reading less the rest's
//! drift, is compared with the model's: the file's plant model stepped open loop with the current the device
//! delivered (its own measurement where it reports one, else the loop's) minus the same model at 0 A (so that an
//! unknown finger's heat cancels), its plate's heat capacity scaled by 1/`response`, then lagged by a first-order
//! sensor of time constant `lag`. The squared differences are minimised over a logarithmic grid of `lag` (from
//! 5 ms to twenty times the file's or 6 s) and `response` (0.2–5 times), then over a finer grid around the best point;
//! the fit's own standard deviations come from the curvature of the squared error there (the residual variance over
//! the degrees of freedom). The display has no finger on it (at power-on): a finger is a heat sink no lumped model
//! describes (its early absorption looks like a slower sensor: a fit with one on the plate measured the default
//! display's 0.3 s sensor as 0.47 s).
//!
//! **Verdict.** Inconclusive first, when the record cannot carry a verdict: fresh samples missing (a gap of more
//! than [`MAX_SAMPLE_GAP_S`], or fewer than [`MIN_SAMPLES`]) or readings not finite; readings that arrived late or a
//! loop that fell behind (a reading older than [`MAX_READING_AGE_S`] when taken, a tick longer than
//! [`MAX_TICK_S`]: an overloaded host); the pulse not delivered (the device's measured charge off the pulse's by more
//! than [`PULSE_CHARGE_TOLERANCE`]); the display not at rest; or a fit whose own three standard deviations exceed
//! half the allowance. Otherwise the display is refused when its sensor is slower than the allowance, or its plate
//! faster than [`MAX_RESPONSE_SCALE`], by more than three of the fit's standard deviations; else it matches, and the
//! plate guard allows for the measured lag ([`LAG_MARGIN`]).

use std::collections::VecDeque;
use std::fmt;

use thermode_control::{Finger, PlantModel};
use thermode_device::config::verified_lag_uncertainty;
use thermode_device::Reading;

/// The pulse of the self-test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelfTest {
    /// Heating current of the pulse \[A\]. Default 0.8 (the default plate rises about 2 °C).
    pub current_a: f64,
    /// Length of the pulse \[s\]. Default 0.4.
    pub pulse_s: f64,
    /// Length of the whole record, pulse included \[s\]. Default 2.5.
    pub record_s: f64,
}

impl Default for SelfTest {
    fn default() -> Self {
        SelfTest {
            current_a: 0.8,
            pulse_s: 0.4,
            record_s: 2.5,
        }
    }
}

impl SelfTest {
    /// The default pulse, recorded for at least five of the file's sensor time constants `sensor_lag_s` \[s\] after
    /// it (2.5 s for the default display's 0.3 s sensor; 7.9 s for a 1.5 s one, whose answer a 2.5 s record cuts off
    /// before it peaks).
    pub fn for_sensor(sensor_lag_s: f64) -> Self {
        let test = SelfTest::default();
        SelfTest {
            record_s: test.record_s.max(test.pulse_s + 5.0 * sensor_lag_s),
            ..test
        }
    }

    /// The current to request `t_s` \[s\] after the test's start (0 after the pulse).
    pub fn current_at_a(&self, t_s: f64) -> f64 {
        if (0.0..self.pulse_s).contains(&t_s) {
            self.current_a
        } else {
            0.0
        }
    }
}

/// One tick of the record: the current applied over the interval that ends here and the readings at its end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelfTestSample {
    /// Length of the interval \[s\].
    pub dt_s: f64,
    /// Current applied over it \[A\].
    pub current_a: f64,
    /// The plate sensor's reading at its end \[°C\].
    pub sensor_c: f64,
    /// The hot-side reading at its end \[°C\].
    pub hot_side_c: f64,
}

/// The display rests when its reading's slope over [`REST_WINDOW_S`] is below this \[°C/s\]: 0.02 (a display just
/// switched on, a plate warming back after a cold touch, or a finger just laid on it drift faster; a drift taken for
/// the pulse's answer read the emulator's 1.5 s sensor as 6 s).
pub const REST_DRIFT_C_PER_S: f64 = 0.02;
/// The window over which the rest is judged, by the least-squares slope of its readings \[s\]: 2 (at 100 Hz and
/// 0.02 °C of noise the slope is known to 0.003 °C/s, at 20 Hz to 0.007 °C/s).
pub const REST_WINDOW_S: f64 = 2.0;
/// The longest a self-test waits for rest \[s\]: 60 (a bare plate relaxes with about 9 s, so a plate 10 °C off its
/// rest comes within the drift in about 40 s).
pub const REST_LIMIT_S: f64 = 60.0;
/// A display that has not come to rest within [`REST_LIMIT_S`] is still pulsed while its drift is at most this
/// \[°C/s\] (subtracted from the answer, about 0.12 °C over the 2.5 s record against a 2 °C answer): 0.05.
pub const MAX_DRIFT_C_PER_S: f64 = 0.05;
/// Fewer fresh samples than this in the record carry no verdict: 10.
pub const MIN_SAMPLES: usize = 10;
/// A gap between two fresh samples longer than this leaves the answer unseen \[s\]: 0.15 (the envelope's stale
/// timeout is 0.2 s; a MeCom controller at 57600 baud samples a channel every 50 ms).
pub const MAX_SAMPLE_GAP_S: f64 = 0.15;
/// A reading older than this when the loop takes it came late \[s\]: 0.15.
pub const MAX_READING_AGE_S: f64 = 0.15;
/// A loop tick longer than this shows a host that fell behind \[s\]: 0.1 (ten of the default 10 ms).
pub const MAX_TICK_S: f64 = 0.1;
/// The device's measured charge may differ from the pulse's by this fraction \[-\]: 0.25.
pub const PULSE_CHARGE_TOLERANCE: f64 = 0.25;

/// The slope of a display's readings over a window of fresh samples (the plate sensor's and the hot side's), to
/// judge its rest: a least-squares line, so the sensor's noise averages out. Its memory is taken when it is made.
#[derive(Debug, Clone)]
pub struct RestWatch {
    window_s: f64,
    /// (time \[s\], sensor \[°C\], hot side \[°C\]) of the fresh samples in the window.
    samples: VecDeque<(f64, f64, f64)>,
    last_seq: Option<u64>,
}

impl RestWatch {
    /// A watch over `window_s` \[s\] holding up to `capacity` samples (the oldest dropped beyond).
    pub fn new(window_s: f64, capacity: usize) -> Self {
        RestWatch {
            window_s,
            samples: VecDeque::with_capacity(capacity.max(2)),
            last_seq: None,
        }
    }

    /// Takes `reading` if it is a fresh sample with finite numbers (a reading that is not restarts the window).
    pub fn push(&mut self, reading: &Reading) {
        if self.last_seq == Some(reading.sample_seq) {
            return;
        }
        self.last_seq = Some(reading.sample_seq);
        let sample = (reading.time_s, reading.sensor_c, reading.hot_side_c);
        if !(sample.0.is_finite() && sample.1.is_finite() && sample.2.is_finite()) {
            self.samples.clear();
            return;
        }
        while let Some(&(t_s, _, _)) = self.samples.front() {
            if sample.0 - t_s > self.window_s || self.samples.len() == self.samples.capacity() {
                self.samples.pop_front();
            } else {
                break;
            }
        }
        self.samples.push_back(sample);
    }

    /// The slopes of the sensor and the hot side \[°C/s\] once the window is nine tenths full with five samples or
    /// more; `None` before.
    pub fn drift_c_per_s(&self) -> Option<(f64, f64)> {
        let (first, last) = (self.samples.front()?, self.samples.back()?);
        if self.samples.len() < 5 || last.0 - first.0 < 0.9 * self.window_s {
            return None;
        }
        let n = self.samples.len() as f64;
        let mean = |f: fn(&(f64, f64, f64)) -> f64| self.samples.iter().map(f).sum::<f64>() / n;
        let (t, s, h) = (mean(|x| x.0), mean(|x| x.1), mean(|x| x.2));
        let (mut tt, mut ts, mut th) = (0.0, 0.0, 0.0);
        for &(ti, si, hi) in &self.samples {
            tt += (ti - t) * (ti - t);
            ts += (ti - t) * (si - s);
            th += (ti - t) * (hi - h);
        }
        (tt > 0.0).then(|| (ts / tt, th / tt))
    }
}

/// What keeps a self-test from a verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Inconclusive {
    /// Too few fresh samples, or a gap between two.
    SamplesMissing {
        /// The longest time between two fresh samples in the record \[s\].
        largest_gap_s: f64,
        /// The fresh samples recorded.
        samples: usize,
    },
    /// A reading was not finite.
    NotFinite,
    /// The readings arrived late or the loop fell behind.
    HostBehind {
        /// The oldest a reading was when the loop took it \[s\].
        reading_age_s: f64,
        /// The longest loop tick \[s\].
        tick_s: f64,
    },
    /// The device did not deliver the pulse.
    PulseNotDelivered {
        /// The charge the device measured over the record \[A·s\].
        measured_a_s: f64,
        /// The pulse's charge \[A·s\].
        asked_a_s: f64,
    },
    /// The display did not come to rest within [`REST_LIMIT_S`].
    NotAtRest {
        /// Its reading's drift at the end of the wait \[°C/s\] (NaN: too few samples to tell).
        drift_c_per_s: f64,
    },
    /// The fit's band of ±[`VERDICT_SDS`] standard deviations (of the lag or the response) holds the allowance and
    /// is wider than [`UNCERTAIN_FRACTION`] of it.
    TooUncertain {
        /// The sensor lag measured \[s\].
        sensor_lag_s: f64,
        /// The fit's standard deviation of it \[s\].
        sd_s: f64,
        /// The plate's response measured, relative to the file's \[-\].
        response_scale: f64,
        /// The fit's standard deviation of it \[-\].
        response_sd: f64,
    },
}

impl fmt::Display for Inconclusive {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Inconclusive::SamplesMissing { largest_gap_s, samples } => write!(
                f,
                "plate samples were missing ({samples} fresh samples, the longest gap {largest_gap_s:.2} s; at most \
                 {MAX_SAMPLE_GAP_S} s allowed)"
            ),
            Inconclusive::NotFinite => write!(f, "a reading was not a number"),
            Inconclusive::HostBehind { reading_age_s, tick_s } => write!(
                f,
                "the host fell behind (a reading {reading_age_s:.2} s old when taken, a tick of {tick_s:.2} s; at \
                 most {MAX_READING_AGE_S} s and {MAX_TICK_S} s allowed): is the computer overloaded?"
            ),
            Inconclusive::PulseNotDelivered {
                measured_a_s,
                asked_a_s,
            } => write!(
                f,
                "the pulse was not delivered (the device measured {measured_a_s:.3} A·s against the pulse's \
                 {asked_a_s:.3} A·s)"
            ),
            Inconclusive::NotAtRest { drift_c_per_s } if drift_c_per_s.is_nan() => write!(
                f,
                "the display's rest could not be judged within {REST_LIMIT_S} s (too few fresh plate samples)"
            ),
            Inconclusive::NotAtRest { drift_c_per_s } => write!(
                f,
                "the display did not come to rest within {REST_LIMIT_S} s (its reading drifts {drift_c_per_s:+.3} \
                 °C/s; at most {MAX_DRIFT_C_PER_S} allowed): is something on the plate?"
            ),
            Inconclusive::TooUncertain {
                sensor_lag_s,
                sd_s,
                response_scale,
                response_sd,
            } => write!(
                f,
                "the answer was too noisy to tell the display from its allowance (sensor time constant \
                 {sensor_lag_s:.3} ± {sd_s:.3} s, the plate answering heat {response_scale:.2} ± {response_sd:.2} \
                 times as fast as the file says)"
            ),
        }
    }
}

/// A self-test run in a channel's own loop (a daemon's display at start, [`crate::ChannelPipeline`]): it waits
/// for the display to rest at 0 A, then drives the pulse tick by tick and keeps the record once per fresh PT-100
/// sample (the fit's steps), whatever the loop's rate. Its memory is taken when it is made: a tick never allocates.
#[derive(Debug, Clone)]
pub struct SelfTestRun {
    test: SelfTest,
    /// The file's model of the display, and its sensor's stated uncertainty (`render.sensor_lag_uncertainty`).
    plant: PlantModel,
    sensor_lag_uncertainty: f64,
    /// Loop time of the first tick \[s\] (`None` before it).
    began_s: Option<f64>,
    /// The rest's readings.
    rest: RestWatch,
    /// The drift subtracted from the answer \[°C/s\] (the rest window's slope at the pulse's start).
    drift_c_per_s: f64,
    /// The display never came to rest: its drift \[°C/s\] (the test ends without a pulse).
    not_at_rest: Option<f64>,
    /// Loop time of the pulse's start \[s\] (`None` while waiting for rest).
    start_s: Option<f64>,
    /// The sample number and time \[s\] of the last reading recorded.
    last_sample: (u64, f64),
    /// Loop time \[s\] and charge \[A·s\] since the last recorded reading.
    pending: (f64, f64),
    record: Vec<SelfTestSample>,
    /// The plate's reading above its hot side's when the pulse began \[°C\].
    rest_excess_c: f64,
    /// Since the pulse began: the charge asked \[A·s\], the charge the device measured and the time it measured
    /// over \[A·s, s\], the time recorded \[s\], the largest gap between fresh samples, the oldest reading taken
    /// and the longest tick \[s\], and whether a reading was not finite.
    asked_a_s: f64,
    measured: (f64, f64),
    recorded_s: f64,
    largest_gap_s: f64,
    oldest_reading_s: f64,
    longest_tick_s: f64,
    not_finite: bool,
}

impl SelfTestRun {
    /// A run of `test` on a display described by `plant` whose sensor may lag `1 + sensor_lag_uncertainty` times
    /// its time constant. The record holds up to twice the samples the file's sample rate gives over the test.
    pub fn new(test: SelfTest, plant: PlantModel, sensor_lag_uncertainty: f64) -> Self {
        let samples = (2.0 * test.record_s * plant.sensor_sample_rate_hz)
            .ceil()
            .clamp(16.0, 100_000.0) as usize;
        let window = (2.0 * REST_WINDOW_S * plant.sensor_sample_rate_hz)
            .ceil()
            .clamp(16.0, 100_000.0) as usize;
        SelfTestRun {
            test,
            plant,
            sensor_lag_uncertainty,
            began_s: None,
            rest: RestWatch::new(REST_WINDOW_S, window),
            drift_c_per_s: 0.0,
            not_at_rest: None,
            start_s: None,
            last_sample: (0, f64::NAN),
            pending: (0.0, 0.0),
            record: Vec::with_capacity(samples),
            rest_excess_c: f64::NAN,
            asked_a_s: 0.0,
            measured: (0.0, 0.0),
            recorded_s: 0.0,
            largest_gap_s: 0.0,
            oldest_reading_s: 0.0,
            longest_tick_s: 0.0,
            not_finite: false,
        }
    }

    /// One tick at loop time `now_s` \[s\] with the tick's `reading`, which ends an interval of `dt_s` \[s\] over
    /// which `applied_a` \[A\] was applied: the current to request now \[A\] (0 while the display settles, then the
    /// pulse). Once the pulse has begun, a fresh PT-100 sample closes a step of the record: as long as the time
    /// between the samples' own stamps (a loaded host's ticks come late, its samples do not), at the current the
    /// device measured over it where it reports one, else the mean current the loop applied since the last one.
    pub fn tick(&mut self, now_s: f64, dt_s: f64, applied_a: f64, reading: &Reading) -> f64 {
        let Some(start_s) = self.start_s else {
            if self.at_rest(now_s, reading) {
                // The pulse starts from this reading: the record's rest.
                self.start_s = Some(now_s);
                self.last_sample = (reading.sample_seq, reading.time_s);
                self.rest_excess_c = reading.sensor_c - reading.hot_side_c;
                return self.test.current_at_a(0.0);
            }
            return 0.0;
        };
        self.watch(now_s, dt_s, reading);
        self.take(dt_s, applied_a, reading);
        self.test.current_at_a(now_s - start_s)
    }

    /// Whether the pulse may start at `now_s` \[s\]: the display rests ([`RestWatch`] below
    /// [`REST_DRIFT_C_PER_S`]), or [`REST_LIMIT_S`] has passed with a drift of at most [`MAX_DRIFT_C_PER_S`] (else
    /// the test ends, not at rest).
    fn at_rest(&mut self, now_s: f64, reading: &Reading) -> bool {
        let began_s = *self.began_s.get_or_insert(now_s);
        self.rest.push(reading);
        let drift = self.rest.drift_c_per_s();
        if let Some((sensor, hot)) = drift {
            if sensor.abs() < REST_DRIFT_C_PER_S && hot.abs() < MAX_DRIFT_C_PER_S {
                self.drift_c_per_s = sensor;
                return true;
            }
        }
        if now_s - began_s < REST_LIMIT_S {
            return false;
        }
        let sensor = drift.map_or(f64::NAN, |(sensor, _)| sensor);
        if sensor.abs() <= MAX_DRIFT_C_PER_S {
            self.drift_c_per_s = sensor;
            true
        } else {
            self.not_at_rest = Some(sensor);
            false
        }
    }

    /// Notes how the loop and the readings keep time during the record.
    fn watch(&mut self, now_s: f64, dt_s: f64, reading: &Reading) {
        if dt_s.is_finite() {
            self.longest_tick_s = self.longest_tick_s.max(dt_s);
        }
        let age_s = now_s - reading.time_s;
        if age_s.is_finite() {
            self.oldest_reading_s = self.oldest_reading_s.max(age_s);
        }
        if !(reading.sensor_c.is_finite() && reading.hot_side_c.is_finite()) {
            self.not_finite = true;
        }
    }

    fn take(&mut self, dt_s: f64, applied_a: f64, reading: &Reading) {
        let (last_seq, last_s) = self.last_sample;
        if dt_s.is_finite() && dt_s > 0.0 {
            self.pending = (self.pending.0 + dt_s, self.pending.1 + applied_a * dt_s);
        }
        if last_seq == reading.sample_seq || self.pending.0 <= 0.0 || self.record.len() == self.record.capacity() {
            return;
        }
        let stamped_s = reading.time_s - last_s;
        let step_s = if stamped_s.is_finite() && stamped_s > 0.0 {
            stamped_s
        } else {
            self.pending.0
        };
        let asked_a = self.pending.1 / self.pending.0;
        let current_a = if reading.current_a.is_finite() {
            self.measured = (self.measured.0 + reading.current_a * step_s, self.measured.1 + step_s);
            reading.current_a
        } else {
            asked_a
        };
        self.asked_a_s += self.pending.1;
        self.recorded_s += step_s;
        self.largest_gap_s = self.largest_gap_s.max(step_s);
        self.record.push(SelfTestSample {
            dt_s: step_s,
            current_a,
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
        });
        self.pending = (0.0, 0.0);
        self.last_sample = (reading.sample_seq, reading.time_s);
    }

    /// Whether the record is complete at loop time `now_s` \[s\] (or the display never came to rest).
    pub fn finished(&self, now_s: f64) -> bool {
        self.not_at_rest.is_some()
            || self
                .start_s
                .is_some_and(|start_s| now_s - start_s >= self.test.record_s)
    }

    /// What keeps the record from a verdict, if anything (before the fit's own uncertainty).
    fn record_fault(&self) -> Option<Inconclusive> {
        if let Some(drift_c_per_s) = self.not_at_rest {
            return Some(Inconclusive::NotAtRest { drift_c_per_s });
        }
        if self.not_finite {
            return Some(Inconclusive::NotFinite);
        }
        if self.record.len() < MIN_SAMPLES || self.largest_gap_s > MAX_SAMPLE_GAP_S {
            return Some(Inconclusive::SamplesMissing {
                largest_gap_s: self.largest_gap_s,
                samples: self.record.len(),
            });
        }
        if self.oldest_reading_s > MAX_READING_AGE_S || self.longest_tick_s > MAX_TICK_S {
            return Some(Inconclusive::HostBehind {
                reading_age_s: self.oldest_reading_s,
                tick_s: self.longest_tick_s,
            });
        }
        // The device's measurement over the time it measured, against the pulse asked (where it measures most of
        // the record).
        let (measured_a_s, measured_s) = self.measured;
        if measured_s >= 0.8 * self.recorded_s {
            let asked_a_s = self.test.current_a * self.test.pulse_s;
            if ((measured_a_s - asked_a_s) / asked_a_s).abs() > PULSE_CHARGE_TOLERANCE {
                return Some(Inconclusive::PulseNotDelivered {
                    measured_a_s,
                    asked_a_s: self.asked_a_s.max(asked_a_s),
                });
            }
        }
        None
    }

    /// The record measured against the file ([`assess`]), or why it carries no verdict; with heat resting on the
    /// display, the lag taken [`FINGER_LAG_FACTOR`] times the fit's.
    pub fn report(&self) -> SelfTestReport {
        let fault = self.record_fault();
        let record = match fault {
            Some(_) => &[][..],
            None => &self.record[..],
        };
        let mut report = assess(
            &self.plant,
            self.sensor_lag_uncertainty,
            record,
            Some(self.drift_c_per_s),
        );
        if fault.is_some() {
            report.inconclusive = fault;
        }
        if self.rest_excess_c > HEAT_AT_REST_C && report.sensor_lag_s.is_finite() {
            report.sensor_lag_s *= FINGER_LAG_FACTOR;
            report.sensor_lag_sd_s *= FINGER_LAG_FACTOR;
            report.heat_at_rest_c = Some(self.rest_excess_c);
        }
        report
    }
}

/// What the self-test measured, against the file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelfTestReport {
    /// The sensor's time constant as measured \[s\] (NaN when nothing was).
    pub sensor_lag_s: f64,
    /// The fit's standard deviation of it \[s\].
    pub sensor_lag_sd_s: f64,
    /// The file's \[s\].
    pub filed_sensor_lag_s: f64,
    /// The longest the envelope allows for: the file's times `1 + render.sensor_lag_uncertainty` (at least
    /// [`thermode_device::config::SELF_TEST_LAG_ERROR`], the test's own error) \[s\]. A sensor measured within it
    /// (within three of the fit's standard deviations) gives the plate guard's bound its measured lag with
    /// [`LAG_MARGIN`] (where that is longer than the file's allowance), so the bound holds the plate whatever the
    /// measurement's own error.
    pub allowed_sensor_lag_s: f64,
    /// How fast the plate answers heat relative to the file (2: twice as fast, a heat capacity half the file's).
    pub response_scale: f64,
    /// The fit's standard deviation of it \[-\].
    pub response_sd: f64,
    /// The fastest the envelope allows for \[-\]: [`MAX_RESPONSE_SCALE`].
    pub allowed_response_scale: f64,
    /// How much warmer than its hot side the plate rested before the pulse \[°C\], when more than
    /// [`HEAT_AT_REST_C`]: heat resting on the display (a finger), for which `sensor_lag_s` is the fit's times
    /// [`FINGER_LAG_FACTOR`]. `None`: a bare display, or not known.
    pub heat_at_rest_c: Option<f64>,
    /// Why the test carries no verdict, if it does not.
    pub inconclusive: Option<Inconclusive>,
}

/// A plate resting more than this above its hot side at 0 A has heat on it \[°C\]: 0.5 (a bare plate at rest sits at
/// its hot side's temperature, the module being its only path; the own-protocol emulator's finger held its plate
/// 1.7 °C above).
pub const HEAT_AT_REST_C: f64 = 0.5;

/// A finger resting on the display makes its sensor seem faster (its sink takes the end of the pulse's answer): the
/// own-protocol emulator's finger read the default 0.30 s sensor as 0.25–0.29 s and a 1.5 s one as 1.21 s (0.81 times
/// at worst). With heat at rest the measured lag is taken this many times longer \[-\]: 1.3, so a finger cannot pass
/// a sensor the envelope does not allow for (the safe side: a refusal the banner explains).
pub const FINGER_LAG_FACTOR: f64 = 1.3;

/// The plate's answer to heat may be up to this many times the file's: the guard's observer estimates a response
/// up to twice the file's, and a display half the file's heat capacity kept the plate within 14.5–48.5 °C (0.45
/// times did not); a twentieth is allowed for the measurement's error (2–3 % on the sweep's plants).
pub const MAX_RESPONSE_SCALE: f64 = 2.1;

/// The plate guard bounds the plate with a sensor this much slower than the measured one \[-\]: 1.15 (the
/// measurement is within 5 % near the verdict's thresholds, the unit tests below; a sensor 1.6 times the file's,
/// measured and not refused, let the plate reach 48.7 °C behind a bound of 1.5 times).
pub const LAG_MARGIN: f64 = 1.15;

/// A measurement beyond its allowance by more than this many of its standard deviations refuses the display \[-\]: 3.
pub const VERDICT_SDS: f64 = 3.0;

/// A measurement whose band of ±[`VERDICT_SDS`] standard deviations holds its allowance and is wider than this
/// fraction of it leaves the verdict open \[-\]: 0.1 (a narrower band is judged by its benefit of the doubt: the plate
/// guard then allows for the measured lag with [`LAG_MARGIN`]).
pub const UNCERTAIN_FRACTION: f64 = 0.1;

/// Where a measurement stands against its allowance.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Judged {
    Within,
    Beyond,
    Undecided,
}

/// Judges (measured, standard deviation, allowed): beyond when even its low end ([`VERDICT_SDS`] below) passes the
/// allowance (a NaN measurement too: nothing measured is not within), undecided when its band holds the allowance
/// and is wider than [`UNCERTAIN_FRACTION`] of it (an infinite or NaN deviation too), else within.
fn judge((measured, sd, allowed): (f64, f64, f64)) -> Judged {
    let spread = if sd.is_nan() {
        f64::INFINITY
    } else {
        VERDICT_SDS * sd.max(0.0)
    };
    // NaN compares as neither: beyond, and undecided.
    let at_most = |a: f64, b: f64| {
        matches!(
            a.partial_cmp(&b),
            Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
        )
    };
    if !at_most(measured - spread, allowed) {
        Judged::Beyond
    } else if measured + spread > allowed && !at_most(spread, UNCERTAIN_FRACTION * allowed) {
        Judged::Undecided
    } else {
        Judged::Within
    }
}

/// What is off when the display is not its file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OffFile {
    /// The plate sensor is slower than the envelope allows for.
    SensorSlower,
    /// The plate answers heat faster than the envelope allows for.
    PlateFaster,
}

/// The self-test's verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// The display is its file within what the envelope allows for.
    Matches,
    /// It is not: refused (fault E106).
    NotAsFiled(OffFile),
    /// The test cannot tell: held off (fault E108) until `clear_fault` tests it again.
    Inconclusive(Inconclusive),
}

impl SelfTestReport {
    /// The verdict: inconclusive first (the record could not carry one); then refused when a measurement passes
    /// its allowance by more than [`VERDICT_SDS`] of its standard deviations; inconclusive when its band of
    /// ±[`VERDICT_SDS`] standard deviations holds its allowance and is wider than [`UNCERTAIN_FRACTION`] of it
    /// (the test cannot tell which side the display is on); else matches.
    pub fn verdict(&self) -> Verdict {
        if let Some(why) = self.inconclusive {
            return Verdict::Inconclusive(why);
        }
        let lag = (self.sensor_lag_s, self.sensor_lag_sd_s, self.allowed_sensor_lag_s);
        let response = (self.response_scale, self.response_sd, self.allowed_response_scale);
        match (judge(lag), judge(response)) {
            (Judged::Beyond, _) => Verdict::NotAsFiled(OffFile::SensorSlower),
            (_, Judged::Beyond) => Verdict::NotAsFiled(OffFile::PlateFaster),
            (Judged::Undecided, _) | (_, Judged::Undecided) => Verdict::Inconclusive(Inconclusive::TooUncertain {
                sensor_lag_s: self.sensor_lag_s,
                sd_s: self.sensor_lag_sd_s,
                response_scale: self.response_scale,
                response_sd: self.response_sd,
            }),
            (Judged::Within, Judged::Within) => Verdict::Matches,
        }
    }

    /// What is off, if the display is refused ([`Verdict::NotAsFiled`]).
    pub fn off_file(&self) -> Option<OffFile> {
        match self.verdict() {
            Verdict::NotAsFiled(off) => Some(off),
            _ => None,
        }
    }

    /// The sensor lag the plate guard's bound should allow for after this test \[s\]: the measured lag with
    /// [`LAG_MARGIN`] (NaN when nothing was measured).
    pub fn guard_lag_s(&self) -> f64 {
        LAG_MARGIN * self.sensor_lag_s
    }
}

impl fmt::Display for SelfTestReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lag = format!(
            "plate sensor time constant {:.2} ± {:.2} s measured, {:.2} s in the device file (at most {:.2} s \
             allowed)",
            self.sensor_lag_s, self.sensor_lag_sd_s, self.filed_sensor_lag_s, self.allowed_sensor_lag_s
        );
        let response = format!(
            "the plate answers heat {:.2} ± {:.2} times as fast as the file says (at most {:.2} allowed)",
            self.response_scale, self.response_sd, self.allowed_response_scale
        );
        match self.verdict() {
            Verdict::Inconclusive(why) => {
                return write!(
                    f,
                    "the self-test was inconclusive: {why} (the device file's plate sensor time constant {:.2} s)",
                    self.filed_sensor_lag_s
                )
            }
            Verdict::NotAsFiled(OffFile::SensorSlower) => {
                write!(f, "the display is not its device file: {lag}; {response}")
            }
            Verdict::NotAsFiled(OffFile::PlateFaster) => {
                write!(f, "the display is not its device file: {response}; {lag}")
            }
            Verdict::Matches => write!(f, "the display matches its device file: {lag}; {response}"),
        }?;
        match self.heat_at_rest_c {
            Some(excess_c) => write!(
                f,
                " (the plate rested {excess_c:.1} °C above its hot side: heat on the display, a finger?, the lag taken \
                 {FINGER_LAG_FACTOR} times the fit's)"
            ),
            None => Ok(()),
        }
    }
}

/// Grid of the coarse search: points per decade of each factor.
const POINTS_PER_DECADE: f64 = 12.0;
/// The coarse search's range of the sensor lag \[s\]: from 5 ms to twenty times the file's, at least 6 s (a file
/// claiming a far faster sensor than the display's is measured, not cut off at its own scale).
fn lag_range_s(filed_s: f64) -> (f64, f64) {
    (0.005, (20.0 * filed_s).max(6.0))
}
/// The coarse search's range of the plate's response relative to the file's.
const RESPONSE_RANGE: (f64, f64) = (0.2, 5.0);
/// The fine search moves on at most this many times \[-\]: 20.
const MAX_REFINEMENTS: usize = 20;

/// Measures the sensor's lag and the plate's response from `record` (the display at rest with no finger before its
/// first sample, then the pulse) against `plant` (the file's model) and the file's `sensor_lag_uncertainty` (at
/// least [`thermode_device::config::SELF_TEST_LAG_ERROR`]), with the display's drift at rest `drift_c_per_s`
/// \[°C/s\] subtracted (`None`: the straight drift within ±[`REST_DRIFT_C_PER_S`] that fits best). A record of
/// fewer than [`MIN_SAMPLES`] samples measures nothing: the report is inconclusive (samples missing).
pub fn assess(
    plant: &PlantModel,
    sensor_lag_uncertainty: f64,
    record: &[SelfTestSample],
    drift_c_per_s: Option<f64>,
) -> SelfTestReport {
    let filed_s = plant.sensor_time_constant_s;
    let mut report = SelfTestReport {
        sensor_lag_s: f64::NAN,
        sensor_lag_sd_s: f64::NAN,
        filed_sensor_lag_s: filed_s,
        allowed_sensor_lag_s: (1.0 + verified_lag_uncertainty(sensor_lag_uncertainty)) * filed_s.max(MIN_LAG_S),
        response_scale: f64::NAN,
        response_sd: f64::NAN,
        allowed_response_scale: MAX_RESPONSE_SCALE,
        heat_at_rest_c: None,
        inconclusive: None,
    };
    if record.len() < MIN_SAMPLES {
        report.inconclusive = Some(Inconclusive::SamplesMissing {
            largest_gap_s: record.iter().map(|s| s.dt_s).fold(0.0, f64::max),
            samples: record.len(),
        });
        return report;
    }
    let fit = Fit::new(plant, record, drift_c_per_s);
    let (lag_s, response) = fit.best();
    let (lag_sd, response_sd) = fit.relative_sds(lag_s, response);
    report.sensor_lag_s = lag_s;
    report.sensor_lag_sd_s = lag_s * lag_sd;
    report.response_scale = response;
    report.response_sd = response * response_sd;
    report
}

/// A file without sensor lag is judged against this one \[s\]: 10 ms, the sensor's sample period.
const MIN_LAG_S: f64 = 0.01;

/// The fit's data and model.
struct Fit<'a> {
    plant: &'a PlantModel,
    record: &'a [SelfTestSample],
    /// The readings' departure from the first \[°C\].
    response_c: Vec<f64>,
    /// The rest's drift, if measured \[°C/s\].
    drift_c_per_s: Option<f64>,
}

impl<'a> Fit<'a> {
    fn new(plant: &'a PlantModel, record: &'a [SelfTestSample], drift_c_per_s: Option<f64>) -> Self {
        let first_c = record[0].sensor_c;
        Fit {
            plant,
            record,
            response_c: record.iter().map(|s| s.sensor_c - first_c).collect(),
            drift_c_per_s: drift_c_per_s.filter(|d| d.is_finite()),
        }
    }

    /// The best (lag \[s\], response): a coarse logarithmic grid, then a grid ten times finer around its best,
    /// moved on while its best lies on its edge (the lag and the response trade off: the coarse grid's nearest point
    /// can sit a whole coarse step off the minimum along that valley), at most [`MAX_REFINEMENTS`] times.
    fn best(&self) -> (f64, f64) {
        let coarse = 1.0 / POINTS_PER_DECADE;
        let (mut lag, mut response) =
            self.search(lag_range_s(self.plant.sensor_time_constant_s), RESPONSE_RANGE, coarse);
        let around = |x: f64| (x * 10f64.powf(-coarse), x * 10f64.powf(coarse));
        let inside = |x: f64, centre: f64| (x / centre).log10().abs() < 0.95 * coarse;
        for _ in 0..MAX_REFINEMENTS {
            let (next_lag, next_response) = self.search(around(lag), around(response), coarse / 10.0);
            let settled = inside(next_lag, lag) && inside(next_response, response);
            (lag, response) = (next_lag, next_response);
            if settled {
                break;
            }
        }
        (lag, response)
    }

    /// The grid point of least squared error over `lags` \[s\] × `responses` spaced `step` decades apart.
    fn search(&self, lags: (f64, f64), responses: (f64, f64), step: f64) -> (f64, f64) {
        let grid = |(lo, hi): (f64, f64)| {
            let n = ((hi / lo).log10() / step).round().max(1.0) as usize;
            (0..=n).map(move |i| lo * 10f64.powf(i as f64 * step))
        };
        let mut best = (f64::INFINITY, 1.0, 1.0);
        for response in grid(responses) {
            let plate = self.plate_response_c(response);
            for lag in grid(lags) {
                let error = self.squared_error(&plate, lag);
                if error < best.0 {
                    best = (error, lag, response);
                }
            }
        }
        (best.1, best.2)
    }

    /// The relative standard deviations of the lag and the response at (`lag_s`, `response`): from the curvature of
    /// the squared error in their logarithms (a 2 × 2 Hessian by central differences), scaled by the residual
    /// variance over the degrees of freedom. Infinite where the curvature does not show a minimum.
    fn relative_sds(&self, lag_s: f64, response: f64) -> (f64, f64) {
        let h = 0.01_f64;
        let at = |dl: f64, dr: f64| {
            let plate = self.plate_response_c(response * (dr * h).exp());
            self.squared_error(&plate, lag_s * (dl * h).exp())
        };
        let e0 = at(0.0, 0.0);
        let ll = (at(1.0, 0.0) + at(-1.0, 0.0) - 2.0 * e0) / (h * h);
        let rr = (at(0.0, 1.0) + at(0.0, -1.0) - 2.0 * e0) / (h * h);
        let lr = (at(1.0, 1.0) - at(1.0, -1.0) - at(-1.0, 1.0) + at(-1.0, -1.0)) / (4.0 * h * h);
        let variance = e0 / (self.record.len() as f64 - 2.0).max(1.0);
        let det = ll * rr - lr * lr;
        if !(det > 0.0 && ll > 0.0) {
            return (f64::INFINITY, f64::INFINITY);
        }
        // cov = 2 σ² H⁻¹ for the squared error's Hessian H.
        let sd = |diagonal: f64| (2.0 * variance * diagonal / det).max(0.0).sqrt();
        (sd(rr), sd(ll))
    }

    /// The model's plate departure from rest at each sample with its heat capacity divided by `response` \[°C\].
    fn plate_response_c(&self, response: f64) -> Vec<f64> {
        let plant = PlantModel {
            plate_heat_capacity_j_k: self.plant.plate_heat_capacity_j_k / response,
            ..*self.plant
        };
        let first = self.record[0];
        let (mut pulsed, mut rest) = ([first.sensor_c, first.hot_side_c], [first.sensor_c, first.hot_side_c]);
        self.record
            .iter()
            .map(|s| {
                pulsed = plant.nodes_after(s.dt_s, s.current_a, pulsed, Finger::NONE);
                rest = plant.nodes_after(s.dt_s, 0.0, rest, Finger::NONE);
                pulsed[0] - rest[0]
            })
            .collect()
    }

    /// Squared difference of the readings' departure and `plate` seen through a sensor of `lag_s` \[s\] (exact for a
    /// plate linear over each interval), after the rest's level and drift: the level that fits best (the first
    /// reading, the departure's zero, carries the sensor's noise), and the drift measured at rest, or else the
    /// straight drift within ±[`REST_DRIFT_C_PER_S`] that fits best.
    fn squared_error(&self, plate: &[f64], lag_s: f64) -> f64 {
        let tau_s = lag_s;
        let (mut sensor, mut previous_plate, mut time_s) = (0.0, 0.0, 0.0);
        // Sums of 1, r, t, r², r t, t² over the samples.
        let (mut n, mut sum_r, mut sum_t) = (0.0, 0.0, 0.0);
        let (mut sum_rr, mut sum_rt, mut sum_tt) = (0.0, 0.0, 0.0);
        for ((sample, &plate_c), &measured) in self.record.iter().zip(plate).zip(&self.response_c) {
            let decay = (-sample.dt_s / tau_s).exp();
            let beta = tau_s / sample.dt_s * (1.0 - decay);
            sensor = decay * sensor + (1.0 - beta) * plate_c + (beta - decay) * previous_plate;
            previous_plate = plate_c;
            time_s += sample.dt_s;
            let residual = measured - sensor;
            n += 1.0;
            sum_r += residual;
            sum_t += time_s;
            sum_rr += residual * residual;
            sum_rt += residual * time_s;
            sum_tt += time_s * time_s;
        }
        // The line `a + b t` of least squares (b measured at rest, or the best within the rest's
        // ±REST_DRIFT_C_PER_S: a free drift takes the slow rise of a sensor eight times the file's for a drift).
        let free_drift = (n * sum_rt - sum_t * sum_r) / (n * sum_tt - sum_t * sum_t);
        let drift = self
            .drift_c_per_s
            .unwrap_or_else(|| free_drift.clamp(-REST_DRIFT_C_PER_S, REST_DRIFT_C_PER_S));
        let level = (sum_r - drift * sum_t) / n;
        sum_rr - 2.0 * level * sum_r - 2.0 * drift * sum_rt
            + n * level * level
            + 2.0 * level * drift * sum_t
            + drift * drift * sum_tt
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controllers::plant_model;
    use crate::ChannelPipeline;
    use thermode_device::config::SELF_TEST_LAG_ERROR;
    use thermode_device::DeviceConfig;

    /// The record of the pulse on a model display whose sensor lags `lag` times and whose plate answers heat
    /// `response` times as the default file says, sampled at 100 Hz with ±0.02 °C of alternating noise.
    fn record(lag: f64, response: f64) -> Vec<SelfTestSample> {
        let file = plant_model(&DeviceConfig::default()).expect("plant");
        let plant = PlantModel {
            plate_heat_capacity_j_k: file.plate_heat_capacity_j_k / response,
            sensor_time_constant_s: file.sensor_time_constant_s * lag,
            ..file
        };
        let (test, dt_s) = (SelfTest::default(), 0.01);
        let (mut nodes, mut sensor_c) = ([23.0, 23.0], 23.0);
        let tau_s = plant.sensor_time_constant_s;
        let decay = (-dt_s / tau_s).exp();
        let beta = tau_s / dt_s * (1.0 - decay);
        (0..(test.record_s / dt_s) as usize)
            .map(|k| {
                let current_a = test.current_at_a(k as f64 * dt_s);
                let plate_before_c = nodes[0];
                nodes = plant.nodes_after(dt_s, current_a, nodes, Finger::NONE);
                // A first-order sensor behind a plate moving linearly over the step.
                sensor_c = decay * sensor_c + (1.0 - beta) * nodes[0] + (beta - decay) * plate_before_c;
                let noise_c = if k % 2 == 0 { 0.02 } else { -0.02 };
                SelfTestSample {
                    dt_s,
                    current_a,
                    sensor_c: sensor_c + noise_c,
                    hot_side_c: nodes[1],
                }
            })
            .collect()
    }

    /// A pipeline built to test its display at start, on a simulated display (no finger) whose sensor lags `lag`
    /// times the file's, ticked at 1 ms for 5 s (a 1 s rest, then the 2.5 s test): the pipeline and the largest drive
    /// current during the test.
    fn start_up(lag: f64) -> (ChannelPipeline, f64) {
        use thermode_device::{Device, NoFinger, SimulatedDisplay};
        let file = DeviceConfig::default();
        let mut hardware = file;
        hardware.sensor.time_constant_s *= lag;
        let mut plant = SimulatedDisplay::new(&hardware, vec![NoFinger], 3).expect("plant");
        plant
            .channel_mut(0)
            .and_then(|c| c.set_temperatures(23.0, 23.0))
            .expect("rest");
        let mut config = crate::PipelineConfig::new(file, crate::ControllerKind::Model);
        config.self_test_at_start = true;
        let mut pipeline = ChannelPipeline::new(&config).expect("pipeline");
        let touch = crate::Stimulus::Touch {
            material: thermode_model::materials::find("aluminium").expect("aluminium"),
            object_c: 23.0,
        };
        assert!(
            matches!(pipeline.set_stimulus(touch), Err(crate::PipelineError::SelfTestRunning)),
            "a touch during the self-test must be refused"
        );
        let (dt_s, mut largest_a) = (0.001, 0.0_f64);
        for _ in 0..5000 {
            let reading = plant.read(0).expect("reading");
            let testing = pipeline.self_test_state() == crate::SelfTestState::Running;
            let (drive, _) = pipeline.tick(plant.time_s(), dt_s, &reading);
            if testing {
                largest_a = largest_a.max(drive.current_a().abs());
            }
            plant.apply(0, &drive).expect("apply");
            plant.advance(dt_s);
        }
        (pipeline, largest_a)
    }

    /// The daemon's start-up self-test inside the pipeline: at a 1 ms tick (ten ticks per PT-100 sample) it measures
    /// the sensor as the render's does at 10 ms, drives only its pulse meanwhile, and refuses a display whose sensor
    /// lags five times its file (0 A, fault E106) while one as filed takes touches afterwards.
    #[test]
    fn a_pipeline_tests_its_display_at_start_and_refuses_one_off_its_file() {
        for (lag, refused) in [(1.0, false), (5.0, true)] {
            let (mut pipeline, largest_a) = start_up(lag);
            let crate::SelfTestState::Done(report) = pipeline.self_test_state() else {
                panic!(
                    "lag × {lag}: the self-test did not end: {:?}",
                    pipeline.self_test_state()
                );
            };
            let measured = report.sensor_lag_s / report.filed_sensor_lag_s;
            println!("lag × {lag}: {report}");
            assert!(
                (measured / lag - 1.0).abs() < 0.05,
                "lag × {lag}: measured × {measured}"
            );
            assert!(
                largest_a <= SelfTest::default().current_a + 1e-9,
                "lag × {lag}: {largest_a} A"
            );
            assert_eq!(report.off_file().is_some(), refused, "lag × {lag}: {report}");
            let fault = pipeline.envelope().fault();
            assert_eq!(
                fault == Some(thermode_safety::FaultCode::DisplayNotAsFiled),
                refused,
                "lag × {lag}: {fault:?}"
            );
            let touch = crate::Stimulus::Touch {
                material: thermode_model::materials::find("aluminium").expect("aluminium"),
                object_c: 23.0,
            };
            assert!(
                pipeline.set_stimulus(touch).is_ok(),
                "lag × {lag}: a touch after the test"
            );
        }
    }

    #[test]
    fn the_fit_recovers_the_sensor_lag_and_the_plates_response_it_was_given() {
        let file = plant_model(&DeviceConfig::default()).expect("plant");
        // Within 5 % near the verdict's thresholds; 10 % for a fast sensor (τ 60 ms, six samples) and a heavy
        // plate (a 0.6 °C answer).
        let cases = [
            (1.0, 1.0, 0.05),
            (2.0, 1.0, 0.05),
            (1.5, 1.5, 0.05),
            (1.0, 3.0, 0.05),
            (0.2, 1.0, 0.1),
        ];
        for (lag, response, tolerance) in cases.into_iter().chain([(1.0, 0.4, 0.1)]) {
            let report = assess(&file, 0.5, &record(lag, response), None);
            let measured_lag = report.sensor_lag_s / file.sensor_time_constant_s;
            let off = |measured: f64, given: f64| (measured / given - 1.0).abs();
            assert!(
                off(measured_lag, lag) < tolerance && off(report.response_scale, response) < tolerance,
                "given lag × {lag}, response × {response}: measured lag × {measured_lag:.3}, response × {:.3}",
                report.response_scale
            );
        }
        // A sensor 8 times the file's (2.4 s) does not settle within the file's 2.5 s record: its rise is partly
        // taken for the drift a display at rest may have, and it reads slower still (10.6 times): refused either way.
        let slow = assess(&file, 0.5, &record(8.0, 1.0), None).sensor_lag_s / file.sensor_time_constant_s;
        assert!((8.0..13.0).contains(&slow), "given lag × 8: measured × {slow:.3}");
    }

    #[test]
    fn a_display_within_the_files_allowance_passes_and_one_beyond_is_named() {
        let file = plant_model(&DeviceConfig::default()).expect("plant");
        let verdict = |lag, response| assess(&file, 0.5, &record(lag, response), None).off_file();
        assert_eq!(verdict(1.0, 1.0), None);
        assert_eq!(verdict(1.3, 1.0), None, "a sensor 30 % slower: within the file's 50 %");
        assert_eq!(verdict(0.1, 0.33), None, "a faster sensor and a heavier plate are safe");
        assert_eq!(verdict(2.0, 1.0), Some(OffFile::SensorSlower));
        assert_eq!(verdict(1.0, 3.0), Some(OffFile::PlateFaster));
        let report = assess(&file, 0.5, &record(2.0, 1.0), None);
        let text = report.to_string();
        assert!(
            text.contains("not its device file") && text.contains("0.30 s in the device file"),
            "{text}"
        );
        // A file that states less than the test's own error is judged with the test's error: a sensor 10 % slower
        // than a file stating 2 % passes (the red team's 0.34 s against 0.31 s), one 30 % slower does not.
        let narrow = |lag| assess(&file, 0.02, &record(lag, 1.0), None);
        let allowed_s = narrow(1.0).allowed_sensor_lag_s;
        let expected_s = (1.0 + SELF_TEST_LAG_ERROR) * file.sensor_time_constant_s;
        assert!(
            (allowed_s - expected_s).abs() < 1e-12,
            "allowed {allowed_s} s, expected {expected_s} s"
        );
        assert_eq!(narrow(1.1).off_file(), None, "{}", narrow(1.1));
        assert_eq!(narrow(1.3).off_file(), Some(OffFile::SensorSlower), "{}", narrow(1.3));
        let nothing = assess(&file, 0.5, &[], None);
        assert!(
            matches!(
                nothing.verdict(),
                Verdict::Inconclusive(Inconclusive::SamplesMissing { samples: 0, .. })
            ),
            "nothing measured: {nothing}"
        );
    }
    /// A self-test run on a simulated display built from `hardware` (no finger, at rest at `start_c` with its hot
    /// side at 23 °C) judged against `file`, ticked every `tick_s` \[s\] for at most 80 s: the device delivers
    /// `delivered` times the current asked, every reading reaches the loop `late_s` \[s\] after its sample, and its
    /// plate and hot-side readings drift `drift_c_per_s` \[°C/s\] on top of the plate's own (the water warming).
    fn run_on(
        hardware: DeviceConfig,
        file: &DeviceConfig,
        start_c: f64,
        tick_s: f64,
        delivered: f64,
        late_s: f64,
        drift_c_per_s: f64,
    ) -> SelfTestReport {
        use thermode_device::{Device, NoFinger, SimulatedDisplay};
        let model = plant_model(file).expect("plant");
        let mut run = SelfTestRun::new(
            SelfTest::for_sensor(model.sensor_time_constant_s),
            model,
            file.render.sensor_lag_uncertainty,
        );
        let mut plant = SimulatedDisplay::new(&hardware, vec![NoFinger], 7).expect("plant");
        plant
            .channel_mut(0)
            .and_then(|c| c.set_temperatures(start_c, 23.0))
            .expect("rest");
        // A fresh sample of the plate set.
        plant.advance(0.05);
        let (mut applied_a, substeps) = (0.0, (tick_s / 1e-3).round().max(1.0) as usize);
        let mut envelope =
            thermode_safety::SafetyEnvelope::new(thermode_safety::EnvelopeConfig::default(), 2.8).expect("envelope");
        for _ in 0..(80.0 / tick_s) as usize {
            let now_s = plant.time_s();
            if run.finished(now_s) {
                break;
            }
            let mut reading = plant.read(0).expect("reading");
            reading.sensor_c += drift_c_per_s * reading.time_s;
            reading.hot_side_c += drift_c_per_s * reading.time_s;
            reading.time_s -= late_s;
            let asked_a = run.tick(now_s, tick_s, applied_a, &reading);
            applied_a = asked_a;
            envelope.observe(&reading.measurement());
            let command = envelope.gate_drive(now_s, asked_a * delivered, &thermode_safety::MeasuredOnly);
            plant.apply(0, &command).expect("apply");
            for _ in 0..substeps {
                plant.advance(tick_s / substeps as f64);
            }
        }
        run.report()
    }

    /// Issue 35 item 6: a file claiming a sensor of 10 ms where the display's is 0.3 s is refused, with the sensor
    /// sampled at 100 Hz and at the 20 Hz of a MeCom controller (the search is not cut off at the file's own scale);
    /// the default file on the same display matches at both rates, its lag within 5 % and its own standard
    /// deviation under 10 ms.
    #[test]
    fn a_file_claiming_a_far_faster_sensor_is_refused_at_any_sample_rate() {
        for rate_hz in [100.0, 20.0] {
            let mut hardware = DeviceConfig::default();
            hardware.sensor.sample_rate_hz = rate_hz;
            let mut tampered = hardware;
            tampered.sensor.time_constant_s = 0.01;
            let report = run_on(hardware, &tampered, 23.0, 0.01, 1.0, 0.0, 0.0);
            println!("{rate_hz} Hz, tampered file: {report}");
            assert_eq!(
                report.verdict(),
                Verdict::NotAsFiled(OffFile::SensorSlower),
                "{rate_hz} Hz: {report}"
            );
            let report = run_on(hardware, &hardware, 23.0, 0.01, 1.0, 0.0, 0.0);
            println!("{rate_hz} Hz, its own file: {report}");
            assert_eq!(report.verdict(), Verdict::Matches, "{rate_hz} Hz: {report}");
            assert!((report.sensor_lag_s / 0.3 - 1.0).abs() < 0.05, "{rate_hz} Hz: {report}");
            assert!(report.sensor_lag_sd_s < 0.01, "{rate_hz} Hz: {report}");
        }
    }

    /// Issue 35 item 6: what the test cannot judge it says so, naming why, and never as a measurement: a device
    /// that delivers a tenth of the pulse (pulse not delivered), samples 0.3 s apart (samples missing), readings
    /// 0.3 s old (the host behind), a loop ticking every 0.2 s (the host behind). The text holds no "NaN" and
    /// blames no finger.
    #[test]
    fn a_record_that_cannot_carry_a_verdict_is_inconclusive_and_says_why() {
        let file = DeviceConfig::default();
        let mut sparse = file;
        sparse.sensor.sample_rate_hz = 3.0;
        type Case<'a> = (&'a str, SelfTestReport, fn(&Inconclusive) -> bool);
        let cases: [Case; 4] = [
            (
                "a tenth delivered",
                run_on(file, &file, 23.0, 0.01, 0.1, 0.0, 0.0),
                |w| matches!(w, Inconclusive::PulseNotDelivered { .. }),
            ),
            (
                "samples 0.33 s apart",
                run_on(sparse, &file, 23.0, 0.01, 1.0, 0.0, 0.0),
                |w| matches!(w, Inconclusive::SamplesMissing { .. }),
            ),
            (
                "readings 0.3 s late",
                run_on(file, &file, 23.0, 0.01, 1.0, 0.3, 0.0),
                |w| matches!(w, Inconclusive::HostBehind { .. }),
            ),
            (
                "ticks 0.2 s apart",
                run_on(file, &file, 23.0, 0.2, 1.0, 0.0, 0.0),
                |w| matches!(w, Inconclusive::HostBehind { .. }) || matches!(w, Inconclusive::SamplesMissing { .. }),
            ),
        ];
        for (name, report, expected) in cases {
            let text = report.to_string();
            println!("{name}: {text}");
            match report.verdict() {
                Verdict::Inconclusive(why) => assert!(expected(&why), "{name}: {why:?}"),
                other => panic!("{name}: {other:?}: {text}"),
            }
            assert!(!text.contains("NaN") && !text.contains("finger"), "{name}: {text}");
            assert!(text.contains("inconclusive"), "{name}: {text}");
        }
    }

    /// Issue 35 item 6, after a restart following a cold touch: a plate 6 °C below its rest, warming back, is waited
    /// for (the pulse comes once its drift is below 0.02 °C/s) and matches its file, the lag within 5 %; readings
    /// that drift 0.03 °C/s for ever (between the rest's 0.02 and the most allowed, 0.05) are pulsed at the end of
    /// the wait with its drift subtracted and matches too; one drifting 0.1 °C/s is inconclusive (not at rest),
    /// never refused.
    #[test]
    fn a_plate_warming_back_is_waited_for_and_one_that_never_rests_is_inconclusive() {
        let file = DeviceConfig::default();
        let run = |start_c, drift_c_per_s| run_on(file, &file, start_c, 0.01, 1.0, 0.0, drift_c_per_s);
        for (name, report) in [("from 17 °C", run(17.0, 0.0)), ("drifting 0.03 °C/s", run(23.0, 0.03))] {
            println!("{name}: {report}");
            assert_eq!(report.verdict(), Verdict::Matches, "{name}: {report}");
            assert!((report.sensor_lag_s / 0.3 - 1.0).abs() < 0.05, "{name}: {report}");
        }
        let report = run(23.0, 0.1);
        println!("drifting 0.1 °C/s: {report}");
        assert!(
            matches!(report.verdict(), Verdict::Inconclusive(Inconclusive::NotAtRest { drift_c_per_s })
                if (drift_c_per_s - 0.1).abs() < 0.01),
            "{report}"
        );
        let text = report.to_string();
        assert!(!text.contains("NaN") && !text.contains("finger"), "{text}");
    }

    /// The rest watch measures a straight drift through the sensor's noise and waits for its window.
    #[test]
    fn the_rest_watch_measures_the_slope_over_its_window() {
        let mut watch = RestWatch::new(2.0, 400);
        for k in 0..300u64 {
            let t = k as f64 * 0.01;
            let noise = if k % 2 == 0 { 0.02 } else { -0.02 };
            let reading = Reading {
                sensor_c: 30.0 + 0.03 * t + noise,
                hot_side_c: 23.0,
                time_s: t,
                sample_seq: k,
                current_a: 0.0,
                voltage_v: f64::NAN,
                heating_limit_a: f64::INFINITY,
            };
            watch.push(&reading);
            if t < 1.7 {
                assert!(watch.drift_c_per_s().is_none(), "at {t} s");
            }
        }
        let (sensor, hot) = watch.drift_c_per_s().expect("a window");
        assert!((sensor - 0.03).abs() < 0.002 && hot.abs() < 1e-12, "{sensor} / {hot}");
    }
}
