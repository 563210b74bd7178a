//! Loop timing statistics without allocation on the hot path: a ring of the most recent measured periods (or
//! tick durations) and nearest-rank percentiles computed in a pre-allocated scratch buffer.

use serde::Serialize;

/// Percentiles of a window of durations.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Summary {
    /// Number of samples in the window.
    pub count: usize,
    /// Median \[s\].
    pub p50_s: f64,
    /// 99th percentile (nearest rank) \[s\].
    pub p99_s: f64,
    /// Largest \[s\].
    pub max_s: f64,
}

/// A window of the last `capacity` durations.
#[derive(Debug, Clone)]
pub struct Window {
    ring: Vec<f64>,
    scratch: Vec<f64>,
    next: usize,
    len: usize,
}

impl Window {
    /// A window of the last `capacity` samples (at least 1).
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Window {
            ring: vec![0.0; capacity],
            scratch: vec![0.0; capacity],
            next: 0,
            len: 0,
        }
    }

    /// Adds a sample \[s\]; samples that are not finite are ignored.
    pub fn record(&mut self, value_s: f64) {
        if !value_s.is_finite() {
            return;
        }
        self.ring[self.next] = value_s;
        self.next = (self.next + 1) % self.ring.len();
        self.len = (self.len + 1).min(self.ring.len());
    }

    /// Percentiles of the samples in the window (all zero when empty).
    pub fn summary(&mut self) -> Summary {
        let n = self.len;
        if n == 0 {
            return Summary::default();
        }
        let scratch = &mut self.scratch[..n];
        scratch.copy_from_slice(&self.ring[..n]);
        let rank = |p: f64| ((p * n as f64).ceil() as usize).clamp(1, n) - 1;
        let (_, p50, _) = scratch.select_nth_unstable_by(rank(0.5), f64::total_cmp);
        let p50_s = *p50;
        let (_, p99, _) = scratch.select_nth_unstable_by(rank(0.99), f64::total_cmp);
        let p99_s = *p99;
        let max_s = scratch.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Summary {
            count: n,
            p50_s,
            p99_s,
            max_s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_one_to_a_hundred() {
        let mut w = Window::new(100);
        for v in (1..=100).rev() {
            w.record(v as f64);
        }
        let s = w.summary();
        assert_eq!((s.count, s.p50_s, s.p99_s, s.max_s), (100, 50.0, 99.0, 100.0));
    }

    #[test]
    fn the_window_forgets_old_samples_and_ignores_nan() {
        let mut w = Window::new(3);
        for v in [100.0, 1.0, f64::NAN, 2.0, 3.0] {
            w.record(v);
        }
        let s = w.summary();
        assert_eq!((s.count, s.max_s, s.p50_s), (3, 3.0, 2.0));
        assert_eq!(Window::new(0).summary(), Summary::default());
    }
}
