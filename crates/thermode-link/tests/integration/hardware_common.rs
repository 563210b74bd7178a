//! Shared by the MeCom and TCS II end-to-end tests: a control loop through safety envelopes (read → observe →
//! shape the set-point → a proportional request → gate → apply, as the runtime does) and waiting helpers.

use std::sync::Arc;
use std::time::{Duration, Instant};

use thermode_device::{Device, DeviceError, Reading};
use thermode_platform::Clock;
use thermode_safety::{EnvelopeConfig, MeasuredOnly, SafetyEnvelope};

/// Waits (polling every millisecond, at most `limit_s`) until `done` holds; returns the time waited.
pub fn wait_for(limit_s: f64, mut done: impl FnMut() -> bool) -> Option<f64> {
    let start = Instant::now();
    while start.elapsed().as_secs_f64() < limit_s {
        if done() {
            return Some(start.elapsed().as_secs_f64());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    None
}

/// A host control loop over any device.
pub struct Loop<D> {
    pub device: D,
    pub envelopes: Vec<SafetyEnvelope>,
    pub clock: Arc<dyn Clock>,
    /// The proportional request's gain \[A/K\]: 1 unless a test sets it.
    pub gain_a_per_c: f64,
}

impl<D: Device> Loop<D> {
    /// Envelopes with the default limits and a 1 s stale-sensor timeout (the tests are not about the runtime's
    /// timing), the current limit `limit_a`.
    pub fn new(device: D, clock: Arc<dyn Clock>, limit_a: f64) -> Self {
        let config = EnvelopeConfig {
            stale_timeout_s: 1.0,
            ..EnvelopeConfig::default()
        };
        Loop::with_envelope(device, clock, limit_a, config)
    }

    /// As [`Loop::new`] with the envelopes' settings `config`.
    pub fn with_envelope(device: D, clock: Arc<dyn Clock>, limit_a: f64, config: EnvelopeConfig) -> Self {
        let envelopes = (0..device.channel_count())
            .map(|_| SafetyEnvelope::new(config, limit_a).unwrap_or_else(|e| panic!("{e}")))
            .collect();
        Loop {
            device,
            envelopes,
            clock,
            gain_a_per_c: 1.0,
        }
    }

    /// One tick towards `targets_c`: the readings (or errors) per channel.
    pub fn tick(&mut self, targets_c: &[f64]) -> Vec<Result<Reading, DeviceError>> {
        let now = self.clock.now_s();
        let mut out = Vec::new();
        for (ch, envelope) in self.envelopes.iter_mut().enumerate() {
            let reading = self.device.read(ch);
            if let Ok(r) = &reading {
                envelope.observe(&r.measurement());
            }
            let shaped = envelope.shape_setpoint(now, targets_c[ch]);
            let sensor_c = reading.as_ref().map_or(shaped.setpoint_c, |r| r.sensor_c);
            let request_a = self.gain_a_per_c * (shaped.setpoint_c - sensor_c);
            let command = envelope.gate_drive(now, request_a, &MeasuredOnly);
            if let Err(e) = self.device.apply(ch, &command) {
                out.push(Err(e));
                continue;
            }
            out.push(reading);
        }
        out
    }

    /// Ticks at about 100 Hz for `duration_s`; the last tick's results.
    pub fn run(&mut self, duration_s: f64, targets_c: &[f64]) -> Vec<Result<Reading, DeviceError>> {
        let start = Instant::now();
        let mut last = Vec::new();
        while start.elapsed().as_secs_f64() < duration_s {
            last = self.tick(targets_c);
            std::thread::sleep(Duration::from_millis(10));
        }
        last
    }
}

/// The reading, or a panic naming the error.
pub fn ok(reading: &Result<Reading, DeviceError>) -> Reading {
    match reading {
        Ok(r) => *r,
        Err(e) => panic!("reading failed: {e}"),
    }
}
