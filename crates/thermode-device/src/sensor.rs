//! The PT-100 in the display plate: first-order lag behind the plate temperature, Gaussian noise (seeded
//! ChaCha8, Box–Muller), quantisation to the resolution, sampling at a fixed rate with the reading held between
//! samples, and the sensor faults (open, short, frozen).
//!
//! The lag is integrated exactly for an input that varies linearly over each step (the plant reports the plate
//! temperature at the start and the end of the step), so it has no time-step error for constant or ramped input.
//! Samples fall at exact multiples of the sample period since the sensor started, wherever the caller's steps end;
//! the lag is evaluated at each sample instant. One noise value is drawn per sample instant whatever the faults, so
//! the noise sequence, and hence every reading after a fault is cleared, does not depend on faults.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::config::SensorConfig;

/// What an open PT-100 reads \[°C\]: the top of the IEC 60751 range (850 °C, ≈ 390 Ω), where a typical front end
/// saturates when the element's resistance goes to infinity.
pub const SENSOR_OPEN_READING_C: f64 = 850.0;

/// What a shorted PT-100 reads \[°C\]: the temperature at which the IEC 60751 (Callendar–Van Dusen) curve of a
/// PT-100 reaches 0 Ω, about −242 °C.
pub const SENSOR_SHORT_READING_C: f64 = -242.0;

/// The state of the sensor element and its wiring.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SensorCondition {
    /// Working.
    #[default]
    Healthy,
    /// Broken wire: reads [`SENSOR_OPEN_READING_C`].
    Open,
    /// Shorted element: reads [`SENSOR_SHORT_READING_C`].
    Short,
    /// Frozen (stale): no new samples; the last reading, its time and its sequence number stay.
    Frozen,
}

/// One sample of the sensor as the acquisition delivers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorSample {
    /// The reading \[°C\]: lagged, noisy and quantised, or a fault value.
    pub value_c: f64,
    /// Time of the sample since the sensor started \[s\].
    pub time_s: f64,
    /// Sequence number of the sample (0 for the first, at time 0); it stops advancing when the sensor is frozen.
    pub seq: u64,
}

/// The PT-100 model.
#[derive(Debug, Clone)]
pub struct Pt100 {
    config: SensorConfig,
    sample_period_s: f64,
    /// Temperature of the sensing element \[°C\] (the lagged plate temperature).
    element_c: f64,
    /// Time since start \[s\].
    time_s: f64,
    /// Index of the next sample instant (instant k is at k · period).
    next_sample: u64,
    latest: SensorSample,
    condition: SensorCondition,
    rng: ChaCha8Rng,
}

impl Pt100 {
    /// A sensor whose element starts at `initial_c` \[°C\], taking its first sample at time 0. `config` must be valid
    /// (see [`crate::DeviceConfig::validate`]); `rng` supplies the noise (seed it explicitly).
    pub fn new(config: &SensorConfig, initial_c: f64, rng: ChaCha8Rng) -> Self {
        let mut sensor = Pt100 {
            config: *config,
            sample_period_s: 1.0 / config.sample_rate_hz,
            element_c: initial_c,
            time_s: 0.0,
            next_sample: 0,
            latest: SensorSample {
                value_c: initial_c,
                time_s: 0.0,
                seq: 0,
            },
            condition: SensorCondition::Healthy,
            rng,
        };
        sensor.sample_now(0.0);
        sensor
    }

    /// A sensor seeded from `seed` (ChaCha8 stream 0).
    pub fn seeded(config: &SensorConfig, initial_c: f64, seed: u64) -> Self {
        Pt100::new(config, initial_c, ChaCha8Rng::seed_from_u64(seed))
    }

    /// Advances by `dt_s` \[s\] while the plate temperature goes linearly from `from_c` to `to_c` \[°C\], taking every
    /// sample whose instant falls in the step. A step that is not finite and positive does nothing.
    pub fn advance(&mut self, dt_s: f64, from_c: f64, to_c: f64) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        let start = self.time_s;
        let end = start + dt_s;
        let slope = (to_c - from_c) / dt_s;
        let mut cursor = start;
        // A sample instant within a millionth of a period after the end belongs to this step (rounding of `end`).
        let slack = 1e-6 * self.sample_period_s;
        loop {
            let instant = self.next_sample as f64 * self.sample_period_s;
            if instant > end + slack {
                break;
            }
            let at = instant.max(cursor);
            self.lag(at - cursor, from_c + slope * (cursor - start), slope);
            cursor = at;
            self.sample_now(instant);
        }
        self.lag((end - cursor).max(0.0), from_c + slope * (cursor - start), slope);
        self.time_s = end;
    }

    /// Exact first-order lag over `span_s` for an input starting at `input_c` and changing at `slope` [°C/s]:
    /// x(h) = u(h) − τ m + (x₀ − u₀ + τ m) e^(−h/τ).
    fn lag(&mut self, span_s: f64, input_c: f64, slope: f64) {
        let tau = self.config.time_constant_s;
        let end_input = input_c + slope * span_s;
        if tau <= 0.0 {
            self.element_c = end_input;
            return;
        }
        let decay = (-span_s / tau).exp();
        self.element_c = end_input - tau * slope + (self.element_c - input_c + tau * slope) * decay;
    }

    /// Takes sample number `next_sample` at `instant_s`.
    fn sample_now(&mut self, instant_s: f64) {
        let noise = self.config.noise_c * standard_normal(&mut self.rng);
        let seq = self.next_sample;
        self.next_sample += 1;
        let value_c = match self.condition {
            SensorCondition::Healthy => quantise(self.element_c + noise, self.config.resolution_c),
            SensorCondition::Open => SENSOR_OPEN_READING_C,
            SensorCondition::Short => SENSOR_SHORT_READING_C,
            SensorCondition::Frozen => return,
        };
        self.latest = SensorSample {
            value_c,
            time_s: instant_s,
            seq,
        };
    }

    /// The latest sample (held between sample instants).
    pub fn latest(&self) -> SensorSample {
        self.latest
    }

    /// Temperature of the sensing element \[°C\] (the noiseless lagged plate temperature).
    pub fn element_c(&self) -> f64 {
        self.element_c
    }

    /// Time since the sensor started \[s\].
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// The current condition.
    pub fn condition(&self) -> SensorCondition {
        self.condition
    }

    /// Sets the condition (fault injection); takes effect from the next sample instant.
    pub fn set_condition(&mut self, condition: SensorCondition) {
        self.condition = condition;
    }

    /// Sets the element temperature \[°C\] (e.g. when the plant is started at another state).
    pub fn set_element_c(&mut self, element_c: f64) {
        self.element_c = element_c;
    }
}

/// Rounds `value` to the nearest multiple of `step` (no rounding when `step` is 0). A step that divides one into a
/// whole number of parts (0.01 °C: a hundred) gives the reading as that count divided by them, the `f64` nearest
/// to the decimal (31.99, where the count times the step gives 31.990000000000002).
pub fn quantise(value: f64, step: f64) -> f64 {
    if step <= 0.0 || step.is_nan() {
        return value;
    }
    let steps = (value / step).round();
    let parts = (1.0 / step).round();
    if parts >= 1.0 && parts * step == 1.0 {
        steps / parts
    } else {
        steps * step
    }
}

/// A standard normal deviate from `rng` by the Box–Muller transform (one per call; the sine partner is discarded).
pub(crate) fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1 = 1.0 - rng.gen::<f64>(); // (0, 1]: the logarithm stays finite
    let u2 = rng.gen::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}
