//! The display checked against its device file before a finger can be on it: a short current pulse from rest
//! ([`SelfTest::current_a`]), the plate sensor's answer recorded, and the two numbers that decide whether the safety
//! envelope can trust its model of the plate measured against the file ([`assess`]): how slow the sensor is, and how
//! fast the plate answers heat.
//!
//! **Why.** The envelope bounds the true plate by a model of the display and by its sensor; it allows for a sensor
//! up to `render.sensor_lag_uncertainty` slower than the file and a plate that answers heat up to twice as fast (its
//! observer's response range). Rendered on displays off their file (copper at 150 and −50 °C, both controllers), a
//! sensor twice as slow as the file let the true plate reach 50.5 °C and 14.1 °C, five times as slow 61.7 °C, and a
//! plate of 0.3 times the file's heat capacity 48.6 °C; inside those allowances the plate stayed within 14.5–48.5 °C
//! (docs/security.md).
//!
//! **Fit.** The response to the pulse, taken as the readings' departure from the first reading (the display at rest),
//! is compared with the model's: the file's plant model stepped open loop with the pulse minus the same model at
//! 0 A (so that the rest state's own drift and an unknown finger's heat cancel), its plate's heat capacity scaled by
//! 1/`response`, then lagged by a first-order sensor of time constant `lag`. The squared differences are minimised
//! over a logarithmic grid of `lag` (0.05–20 times the file's) and `response` (0.2–5 times), then over a finer grid
//! around the best point. The display has no finger on it (at power-on): a finger is a heat sink no lumped model
//! describes (its early absorption looks like a slower sensor: a fit with one on the plate measured the default
//! display's 0.3 s sensor as 0.47 s).

use std::fmt;

use thermode_control::{Finger, PlantModel};
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

/// Before its pulse a self-test in a loop waits for the display to rest: the PT-100 moving less than this \[°C/s\]
/// over [`REST_WINDOW_S`]. 0.05 (a display just switched on, or a finger just laid on it, drifts faster; a drift
/// taken for the pulse's answer read the emulator's 1.5 s sensor as 6 s).
pub const REST_DRIFT_C_PER_S: f64 = 0.05;
/// The window over which the rest is judged \[s\]: 1.
pub const REST_WINDOW_S: f64 = 1.0;
/// The longest a self-test waits for rest before it pulses anyway \[s\]: 20.
pub const REST_LIMIT_S: f64 = 20.0;

/// A self-test under way in a channel's own loop (a daemon's display at start, [`crate::ChannelPipeline`]): it waits
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
    /// The reading at the start of the current rest window: (time \[s\], °C).
    window: Option<(f64, f64)>,
    /// Loop time of the pulse's start \[s\] (`None` while waiting for rest).
    start_s: Option<f64>,
    /// The sample number and time \[s\] of the last reading recorded.
    last_sample: (u64, f64),
    /// Loop time \[s\] and charge \[A·s\] since the last recorded reading.
    pending: (f64, f64),
    record: Vec<SelfTestSample>,
    /// The plate's reading above its hot side's when the pulse began \[°C\].
    rest_excess_c: f64,
}

impl SelfTestRun {
    /// A run of `test` on a display described by `plant` whose sensor may lag `1 + sensor_lag_uncertainty` times
    /// its time constant. The record holds up to twice the samples the file's sample rate gives over the test.
    pub fn new(test: SelfTest, plant: PlantModel, sensor_lag_uncertainty: f64) -> Self {
        let samples = (2.0 * test.record_s * plant.sensor_sample_rate_hz)
            .ceil()
            .clamp(16.0, 100_000.0) as usize;
        SelfTestRun {
            test,
            plant,
            sensor_lag_uncertainty,
            began_s: None,
            window: None,
            start_s: None,
            last_sample: (0, f64::NAN),
            pending: (0.0, 0.0),
            record: Vec::with_capacity(samples),
            rest_excess_c: f64::NAN,
        }
    }

    /// One tick at loop time `now_s` \[s\] with the tick's `reading`, which ends an interval of `dt_s` \[s\] over
    /// which `applied_a` \[A\] was applied: the current to request now \[A\] (0 while the display settles, then the
    /// pulse). Once the pulse has begun, a fresh PT-100 sample closes a step of the record: as long as the time
    /// between the samples' own stamps (a loaded host's ticks come late, its samples do not), at the mean current the
    /// loop applied since the last one.
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
        self.take(dt_s, applied_a, reading);
        self.test.current_at_a(now_s - start_s)
    }

    /// Whether the display rests at `now_s` \[s\]: its reading moved less than [`REST_DRIFT_C_PER_S`] over the last
    /// [`REST_WINDOW_S`], or [`REST_LIMIT_S`] has passed.
    fn at_rest(&mut self, now_s: f64, reading: &Reading) -> bool {
        let began_s = *self.began_s.get_or_insert(now_s);
        if now_s - began_s >= REST_LIMIT_S {
            return true;
        }
        let (window_s, window_c) = *self.window.get_or_insert((reading.time_s, reading.sensor_c));
        let span_s = reading.time_s - window_s;
        // A NaN span (a reading without a time) is no window.
        if span_s.is_nan() || span_s < REST_WINDOW_S {
            return false;
        }
        self.window = Some((reading.time_s, reading.sensor_c));
        ((reading.sensor_c - window_c) / span_s).abs() < REST_DRIFT_C_PER_S
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
        self.record.push(SelfTestSample {
            dt_s: if stamped_s.is_finite() && stamped_s > 0.0 {
                stamped_s
            } else {
                self.pending.0
            },
            current_a: self.pending.1 / self.pending.0,
            sensor_c: reading.sensor_c,
            hot_side_c: reading.hot_side_c,
        });
        self.pending = (0.0, 0.0);
        self.last_sample = (reading.sample_seq, reading.time_s);
    }

    /// Whether the record is complete at loop time `now_s` \[s\].
    pub fn finished(&self, now_s: f64) -> bool {
        self.start_s
            .is_some_and(|start_s| now_s - start_s >= self.test.record_s)
    }

    /// The record measured against the file ([`assess`]); with heat resting on the display, the lag taken
    /// [`FINGER_LAG_FACTOR`] times the fit's.
    pub fn report(&self) -> SelfTestReport {
        let report = assess(&self.plant, self.sensor_lag_uncertainty, &self.record);
        if self.rest_excess_c > HEAT_AT_REST_C {
            SelfTestReport {
                sensor_lag_s: report.sensor_lag_s * FINGER_LAG_FACTOR,
                heat_at_rest_c: Some(self.rest_excess_c),
                ..report
            }
        } else {
            report
        }
    }
}

/// What the self-test measured, against the file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelfTestReport {
    /// The sensor's time constant as measured \[s\].
    pub sensor_lag_s: f64,
    /// The file's \[s\].
    pub filed_sensor_lag_s: f64,
    /// The longest the envelope allows for: the file's times `1 + render.sensor_lag_uncertainty` \[s\]. A sensor
    /// measured within it gives the plate guard's bound its measured lag with [`LAG_MARGIN`] (where that is longer
    /// than the file's allowance), so the bound holds the plate whatever the measurement's own error.
    pub allowed_sensor_lag_s: f64,
    /// How fast the plate answers heat relative to the file (2: twice as fast, a heat capacity half the file's).
    pub response_scale: f64,
    /// The fastest the envelope allows for \[-\]: [`MAX_RESPONSE_SCALE`].
    pub allowed_response_scale: f64,
    /// How much warmer than its hot side the plate rested before the pulse \[°C\], when more than
    /// [`HEAT_AT_REST_C`]: heat resting on the display (a finger), for which `sensor_lag_s` is the fit's times
    /// [`FINGER_LAG_FACTOR`]. `None`: a bare display, or not known.
    pub heat_at_rest_c: Option<f64>,
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

/// What is off when the display is not its file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OffFile {
    /// The plate sensor is slower than the envelope allows for.
    SensorSlower,
    /// The plate answers heat faster than the envelope allows for.
    PlateFaster,
}

impl SelfTestReport {
    /// What is off, if the display is not its file within what the envelope allows for.
    pub fn off_file(&self) -> Option<OffFile> {
        // NaN (nothing measured) is not within: `within` is false for it.
        let within = |measured: f64, allowed: f64| measured <= allowed;
        if !within(self.sensor_lag_s, self.allowed_sensor_lag_s) {
            Some(OffFile::SensorSlower)
        } else if !within(self.response_scale, self.allowed_response_scale) {
            Some(OffFile::PlateFaster)
        } else {
            None
        }
    }
}

impl SelfTestReport {
    /// The sensor lag the plate guard's bound should allow for after this test \[s\]: the measured lag with
    /// [`LAG_MARGIN`] (NaN when nothing was measured).
    pub fn guard_lag_s(&self) -> f64 {
        LAG_MARGIN * self.sensor_lag_s
    }
}

impl fmt::Display for SelfTestReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lag = format!(
            "plate sensor time constant {:.2} s measured, {:.2} s in the device file (at most {:.2} s allowed)",
            self.sensor_lag_s, self.filed_sensor_lag_s, self.allowed_sensor_lag_s
        );
        let response = format!(
            "the plate answers heat {:.2} times as fast as the file says (at most {:.2} allowed)",
            self.response_scale, self.allowed_response_scale
        );
        match self.off_file() {
            Some(OffFile::SensorSlower) => write!(f, "the display is not its device file: {lag}; {response}"),
            Some(OffFile::PlateFaster) => write!(f, "the display is not its device file: {response}; {lag}"),
            None => write!(f, "the display matches its device file: {lag}; {response}"),
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
/// The coarse search's range of the sensor lag relative to the file's.
const LAG_RANGE: (f64, f64) = (0.05, 20.0);
/// The coarse search's range of the plate's response relative to the file's.
const RESPONSE_RANGE: (f64, f64) = (0.2, 5.0);

/// Measures the sensor's lag and the plate's response from `record` (the display at rest with no finger before its
/// first sample, then the pulse) against `plant` (the file's model) and the file's `sensor_lag_uncertainty`. A record
/// of fewer than ten samples measures nothing (NaN numbers: not within the file).
pub fn assess(plant: &PlantModel, sensor_lag_uncertainty: f64, record: &[SelfTestSample]) -> SelfTestReport {
    let filed_s = plant.sensor_time_constant_s;
    let (sensor_lag_s, response_scale) = if record.len() < 10 {
        (f64::NAN, f64::NAN)
    } else {
        let fit = Fit::new(plant, record);
        let (lag, response) = fit.best();
        (lag * filed_s.max(MIN_LAG_S), response)
    };
    SelfTestReport {
        sensor_lag_s,
        filed_sensor_lag_s: filed_s,
        allowed_sensor_lag_s: (1.0 + sensor_lag_uncertainty) * filed_s.max(MIN_LAG_S),
        response_scale,
        allowed_response_scale: MAX_RESPONSE_SCALE,
        heat_at_rest_c: None,
    }
}

/// A file without sensor lag is measured against this one \[s\]: 10 ms, the sensor's sample period.
const MIN_LAG_S: f64 = 0.01;

/// The fit's data and model.
struct Fit<'a> {
    plant: &'a PlantModel,
    record: &'a [SelfTestSample],
    /// The readings' departure from the first \[°C\].
    response_c: Vec<f64>,
}

impl<'a> Fit<'a> {
    fn new(plant: &'a PlantModel, record: &'a [SelfTestSample]) -> Self {
        let first_c = record[0].sensor_c;
        Fit {
            plant,
            record,
            response_c: record.iter().map(|s| s.sensor_c - first_c).collect(),
        }
    }

    /// The best (lag, response) factors: a coarse logarithmic grid, then a grid ten times finer around its best.
    fn best(&self) -> (f64, f64) {
        let coarse = 1.0 / POINTS_PER_DECADE;
        let (lag, response) = self.search(LAG_RANGE, RESPONSE_RANGE, coarse);
        let around = |x: f64| (x * 10f64.powf(-coarse), x * 10f64.powf(coarse));
        self.search(around(lag), around(response), coarse / 10.0)
    }

    /// The grid point of least squared error over `lags` × `responses` spaced `step` decades apart.
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

    /// Squared difference of the readings' departure and `plate` seen through a sensor of `lag` times the file's
    /// time constant (exact for a plate linear over each interval), after the straight drift within the rest's
    /// ([`REST_DRIFT_C_PER_S`]) that fits the difference best (a display that was not quite still, a finger's slow
    /// warming).
    fn squared_error(&self, plate: &[f64], lag: f64) -> f64 {
        let tau_s = lag * self.plant.sensor_time_constant_s.max(MIN_LAG_S);
        let (mut sensor, mut previous_plate, mut time_s) = (0.0, 0.0, 0.0);
        let (mut sum_rr, mut sum_rt, mut sum_tt) = (0.0, 0.0, 0.0);
        for ((sample, &plate_c), &measured) in self.record.iter().zip(plate).zip(&self.response_c) {
            let decay = (-sample.dt_s / tau_s).exp();
            let beta = tau_s / sample.dt_s * (1.0 - decay);
            sensor = decay * sensor + (1.0 - beta) * plate_c + (beta - decay) * previous_plate;
            previous_plate = plate_c;
            time_s += sample.dt_s;
            let residual = measured - sensor;
            sum_rr += residual * residual;
            sum_rt += residual * time_s;
            sum_tt += time_s * time_s;
        }
        // The drift `a t` nearest a = Σ r t / Σ t² within the rest's ±REST_DRIFT_C_PER_S (a free drift takes the slow
        // rise of a sensor eight times the file's for a drift: 12 times measured).
        let drift = (sum_rt / sum_tt).clamp(-REST_DRIFT_C_PER_S, REST_DRIFT_C_PER_S);
        sum_rr - 2.0 * drift * sum_rt + drift * drift * sum_tt
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controllers::plant_model;
    use crate::ChannelPipeline;
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
            let report = assess(&file, 0.5, &record(lag, response));
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
        let slow = assess(&file, 0.5, &record(8.0, 1.0)).sensor_lag_s / file.sensor_time_constant_s;
        assert!((8.0..13.0).contains(&slow), "given lag × 8: measured × {slow:.3}");
    }

    #[test]
    fn a_display_within_the_files_allowance_passes_and_one_beyond_is_named() {
        let file = plant_model(&DeviceConfig::default()).expect("plant");
        let verdict = |lag, response| assess(&file, 0.5, &record(lag, response)).off_file();
        assert_eq!(verdict(1.0, 1.0), None);
        assert_eq!(verdict(1.3, 1.0), None, "a sensor 30 % slower: within the file's 50 %");
        assert_eq!(verdict(0.1, 0.33), None, "a faster sensor and a heavier plate are safe");
        assert_eq!(verdict(2.0, 1.0), Some(OffFile::SensorSlower));
        assert_eq!(verdict(1.0, 3.0), Some(OffFile::PlateFaster));
        let report = assess(&file, 0.5, &record(2.0, 1.0));
        let text = report.to_string();
        assert!(
            text.contains("not its device file") && text.contains("0.30 s in the device file"),
            "{text}"
        );
        assert_eq!(
            assess(&file, 0.5, &[]).off_file(),
            Some(OffFile::SensorSlower),
            "nothing measured"
        );
    }
}
