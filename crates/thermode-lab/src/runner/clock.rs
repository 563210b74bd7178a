//! The runner's clock, injectable: [`SystemClock`] for sessions (real time, waits scaled by `--time-scale`) and
//! [`FakeClock`] for tests (time advances only when waited).

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Time as the runner sees it.
pub trait Clock {
    /// Seconds since an arbitrary origin (monotonic).
    fn now_s(&self) -> f64;
    /// Waits `duration_s` seconds of presentation time (an implementation may scale it).
    fn wait_s(&mut self, duration_s: f64);
    /// Today's date, ISO `YYYY-MM-DD`.
    fn today(&self) -> String;
}

/// Real time. `wait_s(d)` sleeps `d × time_scale` seconds (0 skips waiting, for demos and tests); `today` is the
/// UTC date.
#[derive(Debug, Clone)]
pub struct SystemClock {
    time_scale: f64,
    origin: Instant,
}

impl SystemClock {
    /// A system clock; `time_scale` must be finite and not negative (1 = real time). `None` for a bad scale.
    pub fn new(time_scale: f64) -> Option<SystemClock> {
        (time_scale.is_finite() && time_scale >= 0.0).then(|| SystemClock {
            time_scale,
            origin: Instant::now(),
        })
    }
}

impl Clock for SystemClock {
    fn now_s(&self) -> f64 {
        self.origin.elapsed().as_secs_f64()
    }

    fn wait_s(&mut self, duration_s: f64) {
        let real_s = duration_s * self.time_scale;
        if real_s.is_finite() && real_s > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(real_s.min(1e6)));
        }
    }

    fn today(&self) -> String {
        let days = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_secs() / 86_400);
        civil_date(days as i64)
    }
}

/// A clock for tests: starts at 0 s on a fixed date; only [`Clock::wait_s`] (and [`FakeClock::advance_s`]) move it.
#[derive(Debug, Clone, PartialEq)]
pub struct FakeClock {
    now_s: f64,
    date: String,
}

impl FakeClock {
    /// A fake clock at 0 s on `date` (`YYYY-MM-DD`).
    pub fn new(date: &str) -> FakeClock {
        FakeClock {
            now_s: 0.0,
            date: date.to_string(),
        }
    }

    /// Moves the clock forward by `seconds`.
    pub fn advance_s(&mut self, seconds: f64) {
        self.now_s += seconds;
    }
}

impl Clock for FakeClock {
    fn now_s(&self) -> f64 {
        self.now_s
    }

    fn wait_s(&mut self, duration_s: f64) {
        if duration_s.is_finite() && duration_s > 0.0 {
            self.now_s += duration_s;
        }
    }

    fn today(&self) -> String {
        self.date.clone()
    }
}

/// The proleptic Gregorian date `days` after 1970-01-01 (H. Hinnant's `civil_from_days`).
pub fn civil_date(days: i64) -> String {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}

/// Whether `text` has the shape `YYYY-MM-DD` (digits and dashes; not a calendar check).
pub fn is_iso_date(text: &str) -> bool {
    let b = text.as_bytes();
    b.len() == 10
        && b.iter().enumerate().all(|(i, &c)| {
            if i == 4 || i == 7 {
                c == b'-'
            } else {
                c.is_ascii_digit()
            }
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates_match_known_days() {
        assert_eq!(civil_date(0), "1970-01-01");
        assert_eq!(civil_date(59), "1970-03-01");
        assert_eq!(civil_date(11_016), "2000-02-29"); // leap day of a year divisible by 400
        assert_eq!(civil_date(11_017), "2000-03-01");
        assert_eq!(civil_date(19_723), "2024-01-01");
        assert_eq!(civil_date(-1), "1969-12-31");
    }

    #[test]
    fn fake_clock_moves_only_when_waited() {
        let mut clock = FakeClock::new("2024-05-01");
        assert_eq!(clock.now_s(), 0.0);
        clock.wait_s(30.0);
        clock.wait_s(-1.0);
        clock.advance_s(0.5);
        assert_eq!(clock.now_s(), 30.5);
        assert_eq!(clock.today(), "2024-05-01");
    }

    #[test]
    fn system_clock_refuses_bad_scales_and_skips_zero() {
        assert!(SystemClock::new(-1.0).is_none());
        assert!(SystemClock::new(f64::NAN).is_none());
        let mut clock = SystemClock::new(0.0).expect("valid");
        let before = clock.now_s();
        clock.wait_s(3600.0);
        assert!(clock.now_s() - before < 60.0, "a zero time scale must not wait an hour");
        assert!(is_iso_date(&clock.today()), "{}", clock.today());
        assert!(!is_iso_date("2024-5-01"));
    }
}
