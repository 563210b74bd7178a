//! Thermal dose bookkeeping for one channel: cumulative time at or above 43 °C (the IEC 60601-1 long-contact
//! limit for applied parts) and the CEM43 accumulator.
//!
//! CEM43 ("cumulative equivalent minutes at 43 °C", Sapareto & Dewey 1984) is `Σ R^(43 − T) Δt` in minutes, with
//! `R = 0.5` for `T ≥ 43 °C` and `R = 0.25` below. It is accumulated from the **measured** display temperature
//! between consecutive valid samples. Each interval is counted at the *hotter* of its two end samples, which bounds
//! the true dose from above for any temperature path between them that stays within those two ends (the CEM43
//! rate is increasing in T), and the same rule decides whether an interval counts as time at or above 43 °C.

/// Reference temperature of CEM43 and the IEC 60601-1 long-contact (≥ 10 min) limit for applied parts, °C.
pub const CEM43_REFERENCE_C: f64 = 43.0;

/// CEM43 rate at display temperature `temp_c`: equivalent minutes at 43 °C per minute at `temp_c`
/// (`0.5^(43 − T)` for T ≥ 43 °C, `0.25^(43 − T)` below).
pub fn cem43_rate(temp_c: f64) -> f64 {
    let r: f64 = if temp_c >= CEM43_REFERENCE_C { 0.5 } else { 0.25 };
    r.powf(CEM43_REFERENCE_C - temp_c)
}

/// CEM43 increment in minutes for `dt_s` seconds at `temp_c`.
pub fn cem43_increment_min(temp_c: f64, dt_s: f64) -> f64 {
    cem43_rate(temp_c) * dt_s / 60.0
}

/// Accumulates CEM43 (minutes) and the time at or above 43 °C (s) from a sequence of timed samples.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DoseTracker {
    cem43_min: f64,
    time_at_or_above_43_s: f64,
    prev: Option<(f64, f64)>,
}

impl DoseTracker {
    /// An empty tracker (no dose).
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the interval from the previous sample to this one (`time_s` in s, `temp_c` in °C, both finite; the
    /// caller validates). A sample not later than the previous one adds nothing but becomes the new reference.
    pub fn add_sample(&mut self, time_s: f64, temp_c: f64) {
        if let Some((t_prev, temp_prev)) = self.prev {
            let dt_s = time_s - t_prev;
            if dt_s > 0.0 {
                let hot_c = temp_prev.max(temp_c);
                self.cem43_min += cem43_increment_min(hot_c, dt_s);
                if hot_c >= CEM43_REFERENCE_C {
                    self.time_at_or_above_43_s += dt_s;
                }
            }
        }
        self.prev = Some((time_s, temp_c));
    }

    /// Accumulated thermal dose, CEM43 minutes.
    pub fn cem43_min(&self) -> f64 {
        self.cem43_min
    }

    /// Accumulated time with the measured display at or above 43 °C, s.
    pub fn time_at_or_above_43_s(&self) -> f64 {
        self.time_at_or_above_43_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hold(temp_c: f64, duration_s: f64, dt_s: f64) -> DoseTracker {
        let mut d = DoseTracker::new();
        let n = (duration_s / dt_s).round() as usize;
        for k in 0..=n {
            d.add_sample(k as f64 * dt_s, temp_c);
        }
        d
    }

    /// Hand-computed: 60 s at 44 °C = 1 min · 0.5^(−1) = 2 CEM43-min; 60 s at 42 °C = 1 min · 0.25^1 = 0.25;
    /// 60 s at 43 °C = 1; 120 s at 45 °C = 2 min · 4 = 8; 60 s at 37 °C = 0.25^6 = 1/4096.
    #[test]
    fn cem43_matches_hand_computed_values() {
        let cases = [
            (44.0, 60.0, 2.0),
            (42.0, 60.0, 0.25),
            (43.0, 60.0, 1.0),
            (45.0, 120.0, 8.0),
            (37.0, 60.0, 1.0 / 4096.0),
        ];
        for (temp_c, duration_s, want) in cases {
            let got = hold(temp_c, duration_s, 0.01).cem43_min();
            assert!(
                (got - want).abs() < 1e-9 * want.max(1.0),
                "{duration_s} s at {temp_c} °C: {got} vs hand {want}"
            );
        }
    }

    #[test]
    fn time_at_or_above_43_counts_only_hot_intervals() {
        let d = hold(43.0, 30.0, 0.5);
        assert!(
            (d.time_at_or_above_43_s() - 30.0).abs() < 1e-9,
            "{}",
            d.time_at_or_above_43_s()
        );
        assert_eq!(hold(42.99, 30.0, 0.5).time_at_or_above_43_s(), 0.0);
        // 10 s at 40, one sample at 44 (two intervals touch it), 10 s at 40: 2 s counted at 44 °C.
        let mut d = DoseTracker::new();
        for k in 0..=10 {
            d.add_sample(k as f64, 40.0);
        }
        d.add_sample(11.0, 44.0);
        for k in 12..=22 {
            d.add_sample(k as f64, 40.0);
        }
        assert!(
            (d.time_at_or_above_43_s() - 2.0).abs() < 1e-12,
            "{}",
            d.time_at_or_above_43_s()
        );
        let want = 2.0 / 60.0 * 2.0 + 20.0 / 60.0 * 0.25f64.powi(3);
        assert!((d.cem43_min() - want).abs() < 1e-12, "{} vs {want}", d.cem43_min());
    }

    #[test]
    fn non_increasing_time_adds_nothing() {
        let mut d = DoseTracker::new();
        d.add_sample(10.0, 45.0);
        d.add_sample(10.0, 45.0);
        d.add_sample(5.0, 45.0);
        assert_eq!(d.cem43_min(), 0.0);
        assert_eq!(d.time_at_or_above_43_s(), 0.0);
    }
}
