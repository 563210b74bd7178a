//! Time: the one [`Clock`] trait (seconds on a monotonic axis, sleeping until a deadline, and the wall clock for
//! dates), its two implementations, the fixed-rate [`Ticker`] of control loops and the civil date.
//!
//! [`MonotonicClock`] reads `std::time::Instant` (and `SystemTime` once, at its creation, for the wall clock);
//! [`ManualClock`] stands still until [`ManualClock::advance`] or [`ManualClock::set`] moves it, or, made with
//! [`ManualClock::jumping`], moves to every deadline a caller sleeps until (a single-threaded runner under test).
//!
//! The [`Ticker`] hands out deadlines on the grid `start + k·period` (computed by multiplication, so they never
//! drift). A *missed deadline* is a deadline that got no tick of its own: when the loop wakes so late that one or
//! more later deadlines have passed too, it runs one tick for the newest passed deadline and counts the ones in
//! between as missed. A tick that starts late but before the next deadline is not missed.

use std::fmt::Debug;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use thiserror::Error;

/// Longest a [`ManualClock`] sleeper waits in real time before it returns, so a stopping caller is not stuck \[s\].
const MANUAL_POLL_S: f64 = 0.02;

/// Resolution of thermode's clocks \[s\]: 1 ns, that of `std::time::Instant`. [`MonotonicClock`] reads whole
/// nanoseconds, and times that leave thermode in replies and messages are rounded to them
/// ([`to_clock_resolution`]), so they print as the decimals they are (`16.686951061`, not `16.686951061000002`).
pub const CLOCK_RESOLUTION_S: f64 = 1e-9;

/// `time_s` rounded to the clock's resolution (whole nanoseconds; the nearest `f64` to that decimal); times beyond
/// 2^53 ns (104 days) pass unchanged.
pub fn to_clock_resolution(time_s: f64) -> f64 {
    let ns = time_s * 1e9;
    if ns.is_finite() && ns.abs() < 9.007_199_254_740_992e15 {
        // An exact integer divided by an exact power of ten: correctly rounded.
        ns.round() / 1e9
    } else {
        time_s
    }
}

/// A monotonic clock in seconds, with a wall clock for dates.
pub trait Clock: Send + Sync + Debug {
    /// Seconds since the clock's origin; never decreases.
    fn now_s(&self) -> f64;

    /// Sleeps until `now_s() >= deadline_s`, or returns earlier (spuriously, or so the caller can check for a stop);
    /// the caller re-checks the time.
    fn sleep_until(&self, deadline_s: f64);

    /// The wall-clock time at `now_s()`: seconds since 1970-01-01 00:00 UTC (for dates and file names only; never
    /// for timing).
    fn unix_time_s(&self) -> f64;
}

/// The machine's monotonic clock (`Instant`), in seconds since the clock was made; its wall clock is the system
/// time at creation plus the monotonic time since.
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    origin: Instant,
    origin_unix_s: f64,
}

impl MonotonicClock {
    /// A clock whose origin is now.
    pub fn new() -> Self {
        MonotonicClock {
            origin: Instant::now(),
            origin_unix_s: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64()),
        }
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        MonotonicClock::new()
    }
}

impl Clock for MonotonicClock {
    fn now_s(&self) -> f64 {
        to_clock_resolution(self.origin.elapsed().as_secs_f64())
    }

    fn sleep_until(&self, deadline_s: f64) {
        let remaining_s = deadline_s - self.now_s();
        if remaining_s > 0.0 && remaining_s.is_finite() {
            std::thread::sleep(Duration::try_from_secs_f64(remaining_s).unwrap_or(Duration::MAX));
        }
    }

    fn unix_time_s(&self) -> f64 {
        self.origin_unix_s + self.now_s()
    }
}

/// A clock that moves only when told to (tests). A sleeper wakes as soon as the time reaches its deadline (and at
/// least every 20 ms of real time). A *jumping* clock instead moves to every deadline it is asked to sleep until,
/// up to its jump limit ([`ManualClock::jump_until`]; none by default): a test lets the loop run at once to a time it
/// chooses, and no further.
#[derive(Debug, Default)]
pub struct ManualClock {
    now_s: Mutex<f64>,
    moved: Condvar,
    jumps: bool,
    /// How far a jumping clock jumps \[s\] (`None`: without limit).
    jump_limit_s: Mutex<Option<f64>>,
    origin_unix_s: f64,
}

impl ManualClock {
    /// A manual clock at time 0, whose wall clock starts at 1970-01-01 00:00 UTC.
    pub fn new() -> Self {
        ManualClock::default()
    }

    /// A manual clock at time 0 that jumps to every deadline a caller sleeps until (a runner that waits on its own
    /// thread then runs at once, with the times it would have had).
    pub fn jumping() -> Self {
        ManualClock {
            jumps: true,
            ..ManualClock::default()
        }
    }

    /// Lets a jumping clock jump no further than `limit_s` \[s\] (raised or lowered at any time; the clock never goes
    /// back); sleepers past it wait as on a manual clock until the limit is raised.
    pub fn jump_until(&self, limit_s: f64) {
        *self
            .jump_limit_s
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner()) = Some(limit_s);
        let _now = self.lock();
        self.moved.notify_all();
    }

    /// The same clock with its wall clock starting at `unix_s` \[s since 1970-01-01 UTC\] (dates under test).
    pub fn with_unix_origin_s(mut self, unix_s: f64) -> Self {
        self.origin_unix_s = unix_s;
        self
    }

    /// Moves the time forward by `dt_s` \[s\]; a step that is not finite and positive changes nothing.
    pub fn advance(&self, dt_s: f64) {
        if dt_s.is_finite() && dt_s > 0.0 {
            let mut now = self.lock();
            *now += dt_s;
            self.moved.notify_all();
        }
    }

    /// Sets the time to `time_s` \[s\] if that is later than now (the clock never goes back).
    pub fn set(&self, time_s: f64) {
        let mut now = self.lock();
        if time_s.is_finite() && time_s > *now {
            *now = time_s;
            self.moved.notify_all();
        }
    }

    fn lock(&self) -> MutexGuard<'_, f64> {
        // A poisoned lock only means a panicking test thread held it; the number inside is still valid.
        self.now_s.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl Clock for ManualClock {
    fn now_s(&self) -> f64 {
        *self.lock()
    }

    fn sleep_until(&self, deadline_s: f64) {
        if self.jumps {
            let limit_s = *self
                .jump_limit_s
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner());
            match limit_s {
                Some(limit_s) if deadline_s > limit_s => self.set(limit_s),
                _ => {
                    self.set(deadline_s);
                    return;
                }
            }
        }
        let now = self.lock();
        if *now >= deadline_s {
            return;
        }
        let _unused = self
            .moved
            .wait_timeout(now, Duration::from_secs_f64(MANUAL_POLL_S))
            .unwrap_or_else(|poisoned| poisoned.into_inner());
    }

    fn unix_time_s(&self) -> f64 {
        self.origin_unix_s + self.now_s()
    }
}

/// The UTC calendar date (year, month 1–12, day 1–31) `days` after 1970-01-01, proleptic Gregorian (H. Hinnant's
/// `civil_from_days`).
pub fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

/// Days since 1970-01-01 of the proleptic Gregorian date (`year`, `month` 1–12, `day` 1–31) (H. Hinnant's
/// `days_from_civil`, the inverse of [`civil_from_days`]).
pub fn days_from_civil(year: i64, month: u32, day: u32) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y.rem_euclid(400);
    let m = i64::from(month);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(day) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The start of an ISO `YYYY-MM-DD` date, 00:00 UTC, in s since 1970-01-01 UTC; `None` unless `text` is such a date
/// (month 1–12, day 1 to the month's length).
pub fn parse_iso_date(text: &str) -> Option<f64> {
    let b = text.as_bytes();
    let shaped = b.len() == 10
        && b.iter().enumerate().all(|(i, &c)| {
            if i == 4 || i == 7 {
                c == b'-'
            } else {
                c.is_ascii_digit()
            }
        });
    if !shaped {
        return None;
    }
    let (year, month, day) = (
        text[..4].parse().ok()?,
        text[5..7].parse().ok()?,
        text[8..].parse().ok()?,
    );
    let days = days_from_civil(year, month, day);
    (civil_from_days(days) == (year, month, day)).then_some(days as f64 * 86_400.0)
}

/// The UTC date of `unix_s` \[s since 1970-01-01 UTC\] as ISO `YYYY-MM-DD`.
pub fn civil_date(unix_s: f64) -> String {
    let (year, month, day) = civil_from_days((unix_s / 86_400.0).floor() as i64);
    format!("{year:04}-{month:02}-{day:02}")
}

/// The UTC date and time of day of `unix_s` (whole seconds since 1970): (year, month, day, hour, minute, second).
fn utc_parts(unix_s: i64) -> (i64, u32, u32, i64, i64, i64) {
    let (year, month, day) = civil_from_days(unix_s.div_euclid(86_400));
    let rem = unix_s.rem_euclid(86_400);
    (year, month, day, rem / 3600, (rem % 3600) / 60, rem % 60)
}

/// The UTC date and time of day of `unix_s` as `YYYYMMDD-HHMMSS` (for file names).
pub fn utc_stamp(unix_s: f64) -> String {
    let (year, month, day, hour, minute, second) = utc_parts(unix_s.floor() as i64);
    format!("{year:04}{month:02}{day:02}-{hour:02}{minute:02}{second:02}")
}

/// `unix_s` (s since 1970, UTC) as `YYYY-MM-DDTHH:MM:SSZ` (ISO 8601, for logs and ledgers).
pub fn utc_iso8601(unix_s: i64) -> String {
    let (year, month, day, hour, minute, second) = utc_parts(unix_s);
    format!("{year:04}-{month:02}-{day:02}T{hour:02}:{minute:02}:{second:02}Z")
}

/// `unix_s` (s since 1970, UTC) as `YYYY-MM-DDTHH:MM:SS.mmmZ` (ISO 8601 with milliseconds, truncated; for clock
/// alignment of recordings and lab sessions).
pub fn utc_iso8601_ms(unix_s: f64) -> String {
    let whole_s = unix_s.floor();
    let millis = (((unix_s - whole_s) * 1000.0).floor() as u32).min(999);
    let iso = utc_iso8601(whole_s as i64);
    format!("{}.{millis:03}Z", iso.trim_end_matches('Z'))
}

/// Why a [`Ticker`] was refused.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum TickerError {
    /// The period is not finite and positive.
    #[error("tick period {0} s must be finite and positive")]
    Period(f64),
    /// The start is not finite.
    #[error("first deadline {0} s must be finite")]
    Start(f64),
}

/// One tick handed out by [`Ticker::wait`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Index of the deadline this tick serves (`scheduled_s = start_s + index · period_s`).
    pub index: u64,
    /// The deadline \[s, clock time\]: the loop's time for this tick.
    pub scheduled_s: f64,
    /// Time since the previous tick's deadline \[s\] (one period unless deadlines were missed; one period for the
    /// first tick).
    pub dt_s: f64,
    /// When the loop actually woke \[s, clock time\] (at or after `scheduled_s`).
    pub woke_s: f64,
    /// Deadlines skipped just before this one (0 when on time).
    pub missed: u64,
}

/// Hands out ticks at a fixed rate on a [`Clock`].
#[derive(Debug, Clone)]
pub struct Ticker {
    period_s: f64,
    start_s: f64,
    next_index: u64,
    last_scheduled_s: Option<f64>,
    missed_total: u64,
}

impl Ticker {
    /// A ticker whose first deadline is `start_s` \[s\] and which then ticks every `period_s` \[s\] (finite, > 0).
    pub fn new(period_s: f64, start_s: f64) -> Result<Self, TickerError> {
        if !(period_s.is_finite() && period_s > 0.0) {
            return Err(TickerError::Period(period_s));
        }
        if !start_s.is_finite() {
            return Err(TickerError::Start(start_s));
        }
        Ok(Ticker {
            period_s,
            start_s,
            next_index: 0,
            last_scheduled_s: None,
            missed_total: 0,
        })
    }

    /// The period \[s\].
    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// The first deadline \[s, clock time\]: loop time 0.
    pub fn start_s(&self) -> f64 {
        self.start_s
    }

    /// Deadlines missed since the start.
    pub fn missed_total(&self) -> u64 {
        self.missed_total
    }

    /// The deadline the next [`Ticker::wait`] waits for \[s\].
    pub fn next_deadline_s(&self) -> f64 {
        self.deadline_s(self.next_index)
    }

    fn deadline_s(&self, index: u64) -> f64 {
        self.start_s + index as f64 * self.period_s
    }

    /// Sleeps until the next deadline and returns its tick, or `None` as soon as `stop` is set.
    pub fn wait(&mut self, clock: &dyn Clock, stop: &AtomicBool) -> Option<Tick> {
        let mut deadline_s = self.deadline_s(self.next_index);
        loop {
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            if clock.now_s() >= deadline_s {
                break;
            }
            clock.sleep_until(deadline_s);
        }
        let woke_s = clock.now_s();
        let behind = ((woke_s - deadline_s) / self.period_s).floor();
        // Saturating float-to-int conversion: a clock that jumped absurdly far only makes `missed` large.
        let missed = if behind >= 1.0 { behind as u64 } else { 0 };
        let index = self.next_index.saturating_add(missed);
        deadline_s = self.deadline_s(index);
        let dt_s = self.last_scheduled_s.map_or(self.period_s, |last| deadline_s - last);
        self.last_scheduled_s = Some(deadline_s);
        self.next_index = index.saturating_add(1);
        self.missed_total = self.missed_total.saturating_add(missed);
        Some(Tick {
            index,
            scheduled_s: deadline_s,
            dt_s,
            woke_s,
            missed,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn iso_timestamps_with_milliseconds_truncate_and_roll_over_correctly() {
        // 2023-11-14T22:13:20Z is 1 700 000 000 s (GNU `date -u -d @1700000000`).
        assert_eq!(utc_iso8601_ms(1_700_000_000.0), "2023-11-14T22:13:20.000Z");
        assert_eq!(utc_iso8601_ms(1_700_000_000.999_6), "2023-11-14T22:13:20.999Z");
        assert_eq!(utc_iso8601_ms(1_700_000_059.25), "2023-11-14T22:14:19.250Z");
        assert_eq!(utc_iso8601_ms(-0.5), "1969-12-31T23:59:59.500Z");
    }

    #[test]
    fn manual_clock_moves_only_forward() {
        let clock = ManualClock::new();
        assert_eq!(clock.now_s(), 0.0);
        clock.advance(0.5);
        clock.advance(f64::NAN);
        clock.advance(-1.0);
        assert_eq!(clock.now_s(), 0.5);
        clock.set(0.25);
        assert_eq!(clock.now_s(), 0.5, "set must not move the clock back");
        clock.set(2.0);
        assert_eq!(clock.now_s(), 2.0);
    }

    #[test]
    fn manual_sleeper_wakes_when_time_reaches_deadline() {
        let clock = Arc::new(ManualClock::new());
        let sleeper = {
            let clock = clock.clone();
            std::thread::spawn(move || {
                let mut wakes = 0;
                while clock.now_s() < 1.0 && wakes < 10_000 {
                    clock.sleep_until(1.0);
                    wakes += 1;
                }
                clock.now_s()
            })
        };
        clock.advance(1.0);
        let woke_at = sleeper.join().unwrap_or(f64::NAN);
        assert_eq!(woke_at, 1.0);
    }

    #[test]
    fn a_jumping_clock_moves_to_each_deadline_and_dates_from_its_origin() {
        let clock = ManualClock::jumping().with_unix_origin_s(19_723.0 * 86_400.0);
        clock.sleep_until(30.0);
        clock.sleep_until(10.0);
        assert_eq!(clock.now_s(), 30.0, "a jumping clock must not go back");
        assert_eq!(civil_date(clock.unix_time_s()), "2024-01-01");
    }

    #[test]
    fn a_jumping_clock_stops_at_its_jump_limit_until_the_limit_is_raised() {
        let clock = ManualClock::jumping();
        clock.jump_until(1.5);
        clock.sleep_until(1.0);
        assert_eq!(clock.now_s(), 1.0, "within the limit the clock jumps to the deadline");
        clock.sleep_until(2.0);
        assert_eq!(clock.now_s(), 1.5, "past the limit the clock stops at the limit");
        clock.jump_until(3.0);
        clock.sleep_until(2.0);
        assert_eq!(clock.now_s(), 2.0, "a raised limit lets the sleeper jump on");
    }

    #[test]
    fn monotonic_clock_does_not_go_back_and_knows_the_year() {
        let clock = MonotonicClock::new();
        let a = clock.now_s();
        clock.sleep_until(a + 0.001);
        let b = clock.now_s();
        assert!(b >= a + 0.001, "slept from {a} to {b}, wanted at least 1 ms");
        let year: i64 = civil_date(clock.unix_time_s())[..4].parse().unwrap_or(0);
        assert!(year >= 2024, "wall clock says year {year}");
    }

    #[test]
    fn civil_dates_match_known_days() {
        for (days, date) in [
            (0, "1970-01-01"),
            (59, "1970-03-01"),
            (11_016, "2000-02-29"), // leap day of a year divisible by 400
            (11_017, "2000-03-01"),
            (19_723, "2024-01-01"),
            (-1, "1969-12-31"),
        ] {
            assert_eq!(civil_date(days as f64 * 86_400.0 + 3600.0), date, "day {days}");
        }
        assert_eq!(utc_stamp(19_723.0 * 86_400.0 + 3661.5), "20240101-010101");
        for days in [-800_000, -1, 0, 59, 11_016, 19_723, 800_000] {
            let (y, m, d) = civil_from_days(days);
            assert_eq!(days_from_civil(y, m, d), days, "{y}-{m}-{d}");
        }
        assert_eq!(parse_iso_date("2000-02-29"), Some(11_016.0 * 86_400.0));
        for bad in ["2001-02-29", "2024-13-01", "2024-5-01", "2024-05-00", "not a date"] {
            assert_eq!(parse_iso_date(bad), None, "{bad}");
        }
    }

    #[test]
    fn times_rounded_to_the_clock_print_as_whole_nanoseconds() {
        // 0.686951061 + 30 · 0.001 = 0.7169510610000001 in f64 (a loop time on the ticker's grid).
        let (start, step) = (std::hint::black_box(0.686951061), std::hint::black_box(0.001));
        let on_grid = start + 30.0 * step;
        assert_eq!(on_grid.to_string(), "0.7169510610000001");
        assert_eq!(to_clock_resolution(on_grid).to_string(), "0.716951061");
        assert_eq!(to_clock_resolution(0.1 + 0.2).to_string(), "0.3");
        assert_eq!(to_clock_resolution(1e300), 1e300);
        let now = MonotonicClock::new().now_s();
        assert_eq!(
            to_clock_resolution(now),
            now,
            "the monotonic clock reads whole nanoseconds"
        );
    }

    #[test]
    fn deadlines_are_on_the_grid_and_late_wakes_count_missed_deadlines() {
        let clock = ManualClock::new();
        let stop = AtomicBool::new(false);
        let mut ticker = Ticker::new(0.01, 0.0).expect("valid period");
        let first = ticker.wait(&clock, &stop).expect("tick");
        assert_eq!((first.index, first.scheduled_s, first.missed), (0, 0.0, 0));
        clock.set(0.013); // 3 ms late for the deadline at 10 ms: jitter, not a miss
        let second = ticker.wait(&clock, &stop).expect("tick");
        assert_eq!((second.index, second.missed), (1, 0));
        assert!(
            (second.scheduled_s - 0.01).abs() < 1e-15,
            "deadline {}",
            second.scheduled_s
        );
        clock.set(0.045); // deadlines at 20, 30 and 40 ms passed: run 40 ms, miss 20 and 30
        let third = ticker.wait(&clock, &stop).expect("tick");
        assert_eq!((third.index, third.missed), (4, 2));
        assert!((third.dt_s - 0.03).abs() < 1e-12, "dt {} vs 0.03", third.dt_s);
        assert_eq!(ticker.missed_total(), 2);
    }

    #[test]
    fn a_million_periods_do_not_drift() {
        let ticker = Ticker::new(1e-3, 0.0).expect("valid period");
        let at = ticker.deadline_s(1_000_000);
        assert!((at - 1000.0).abs() < 1e-9, "deadline {at} vs 1000 s");
    }

    #[test]
    fn stop_ends_the_wait_and_bad_periods_are_refused() {
        let clock = ManualClock::new();
        let stop = AtomicBool::new(true);
        let mut ticker = Ticker::new(0.01, 1.0).expect("valid period");
        assert_eq!(ticker.wait(&clock, &stop), None);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(Ticker::new(bad, 0.0).is_err(), "period {bad} accepted");
        }
    }
}
