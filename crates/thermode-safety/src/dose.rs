//! Thermal dose of one channel: cumulative time at or above 43 °C (the IEC 60601-1 long-contact limit for applied
//! parts), the CEM43 accumulator, and the **dose cap** — the ceiling that keeps the total dose within
//! [`DOSE_CAP_ALLOWANCE`] (5 %) of the budget over any continuation, however long.
//!
//! # CEM43
//! CEM43 ("cumulative equivalent minutes at 43 °C", Sapareto & Dewey 1984) is `Σ R^(43 − T) Δt` in minutes, with
//! `R = 0.5` for `T ≥ 43 °C` and `R = 0.25` below. Each interval between consecutive valid samples is counted at the
//! *hotter* of its two end temperatures, which bounds the dose from above for any temperature path between them
//! that stays within those two ends (the CEM43 rate is increasing in T); the same rule decides whether an interval
//! counts as time at or above 43 °C.
//!
//! # The plate, not the sensor
//! The display sensor lags the plate (a PT-100 glued into the plate: a first-order lag of time constant τ_s, 0.3 s
//! on the default display). While the plate heats, the reading is low and its dose smaller than the plate's: on the
//! default display at 48 °C the plate is ahead of the reading by about 0.34 CEM43-min (measured with
//! `thermode render --material copper --object-temp 70`: 1.34 on the plate when the reading had counted 1.00).
//! While the plate cools the reading is high, and the reading's dose of the way down is several times the plate's
//! (counted at the reading, the fall from 48 °C after the lockout spent the whole allowance and sent the ceiling to
//! the display minimum for the rest of the hour). A [`DoseTracker`] built with [`DoseTracker::with_sensor_lag`]
//! therefore counts at the plate temperature reconstructed by inverting the lag, `T̂ = T_s + τ_s · dT_s/dt` (exact
//! for a first-order sensor), in both directions. The slope is taken over at least the slope window (the envelope's
//! `rate_window_s`, 50 ms) so that sensor noise is not amplified much (σ ≈ 0.17 °C with the default 0.02 °C noise;
//! the CEM43 rate being convex, unbiased noise over-counts by about 3 %), and limited to the fastest plausible rate
//! (the envelope's `max_measured_rate_c_per_s`, 50 °C/s: a jump of the reading beyond it is a sensor fault, not a
//! plate 60 °C hotter). The window's delay errs on the safe side where the dose is large: at the top of a rise
//! the slope is that of 25–50 ms earlier, so `T̂` overshoots the plate (the estimate counted 1.02 CEM43-min when
//! the plate had 0.87 in the copper run), and at the start of a fall it is still small. The reconstruction is as
//! good as τ_s: a τ_s longer than the real one over-counts rises and under-counts falls, a shorter one the reverse
//! (the device file gives it; a rendering pipeline refuses an envelope τ_s shorter than its device's).
//!
//! # Unseen time
//! Only fresh samples are measurements. Time without one (a link fault, a frozen or held reading) is counted by
//! [`DoseTracker::count_unseen`] at a temperature the caller bounds the plate by — the envelope's bound
//! (`SafetyEnvelope::unseen_plate_bound_c`, "Unseen time" in the envelope's documentation) — and the sample that ends
//! it adds only the rest, at the hotter of that bound and itself: never the whole gap at the held reading (which
//! counted 3.7–4.2 CEM43-min per 14 s of outage at 47 °C).
//!
//! # The cap
//! With `B` = `cem43_budget_min`, `D` = the accumulated (estimated) CEM43, `rate(T)` the CEM43 rate above and
//! `c` = [`DOSE_COOLDOWN_RATE_C_PER_S`], the channel's ceiling (the envelope's effective maximum, before the display
//! limits are applied) is the lowest of:
//!
//! 1. **After the lockout** (`D ≥ B`, or the time at ≥ 43 °C used up, or a restored lockout): the temperature whose
//!    CEM43 rate spends what is left of the estimate's allowance exponentially, `rate(T_c) = R / τ` with
//!    `R = B·(1 + a) − D`, `a` = [`DOSE_ESTIMATE_ALLOWANCE`] and `τ` = [`DOSE_CAP_TIME_CONSTANT_S`]; and never above
//!    `43 − dose_lockout_margin_c`. *Why this caps the dose:* while the plate stays at or below the ceiling,
//!    `dD/dt = rate(T) ≤ rate(T_c) = R/τ`, so `dR/dt ≥ −R/τ` and `R(t) ≥ R(t₀)·e^{−(t − t₀)/τ} > 0`: whatever
//!    follows — an hour or a year at any requested temperature — `D` never exceeds `B·(1 + a)`. The ceiling falls
//!    only as dose is spent: held at the ceiling it falls by `1/(τ·ln 4)` °C per unit time below 43 °C (0.072 °C per
//!    minute with τ = 10 min), continuously, towards the display minimum (which it never goes below: the envelope
//!    clamps; at 15 °C the CEM43 rate is 0.25^28 ≈ 1.4·10⁻¹⁷, nothing in any session).
//! 2. **Before the lockout, anticipating it** ([`DoseCap::anticipating_c`]): the temperature from which a fall at
//!    `c` down to `T_b` (ceiling 1 at `D = B`, where the plate must be when the budget is used) spends exactly what
//!    is left of the budget, `∫_{T_b}^{T_a} rate(x) dx / (60·c) = B − D`. A plate that rides this ceiling spends
//!    `rate(T_a)` while the ceiling falls by `dT_a/dt = −rate(T_a) / (rate(T_a)/c) = −c`: the ceiling comes down at
//!    exactly `c` and reaches `T_b` when the budget is used, where ceiling 1 takes over without a step. Without
//!    it the lockout would find the plate at up to 48 °C, and the way down (0.25–0.35 s at 16–20 °C/s) alone costs
//!    about 0.05 CEM43-min, the whole 5 % of the default budget. Likewise for the time budget:
//!    `T_a = 43 − dose_lockout_margin_c + c·(max_time_at_or_above_43_s − time at ≥ 43 °C)`.
//!    A sampled loop holds its plate for a whole interval, and an interval is counted at the hotter of its two
//!    samples, so a plate set now is counted over the coming interval and, when it is the hotter, over the next one
//!    too: the ceiling given now is where the continuous one will be two intervals ahead, `T_a − 2c·Δt` (`Δt` the
//!    last interval, at most the longest the caller allows — the envelope's stale-sensor timeout, 0.2 s by default
//!    — and that longest interval before the second sample; 0.1 °C at 100 Hz). The CEM43 rate grows with temperature, so a plate held there spends no more than the
//!    continuous descent. With one interval (`T_a − c·Δt`, the last interval only) a coarse loop still overspent a
//!    0.05 CEM43-min budget — by up to 20 % on the interval before the lockout and several times over on the very
//!    first interval, which no last interval covered; with two, and the longest interval from the start, any loop
//!    period from 10 ms to 1 s stays within the allowance (property test, 9000 cases).
//!
//! With the defaults (B = 1 CEM43-min, c = 5 °C/s, τ = 600 s, a = 0.025): `T_b = 43 + ln(0.0025)/ln 4 = 38.68 °C`;
//! the anticipating ceiling leaves 48 °C at D = 1 − 0.151 = 0.849 and reaches 38.68 °C at D = 1; an hour at the
//! ceiling after the lockout spends 0.025·(1 − e⁻⁶) = 0.0249 CEM43-min more and ends at 38.68 − 60/(10·ln 4) =
//! 34.35 °C.
//!
//! # Margins, and what they do not cover
//! The cap acts on the envelope's *estimate* of the dose, which aims at `B·(1 + 2.5 %)`; the other 2.5 % of the
//! 5 % allowance is the margin for the true plate's dose beyond the estimate: the reconstruction's error (its slope
//! window lags; the sensor is not exactly first order), the plate between samples, and a plate that cools slower
//! than `c` at the anticipated lockout. Not covered: a sensor that reads low in steady state (a calibration error:
//! 0.5 °C low under-counts the dose by 41 % above 43 °C and by half below; only calibration helps), a sensor time
//! constant set shorter than the real one, and a plate driven beyond the ceiling (the drive gate's business:
//! heating is refused at the ceiling, but a controller may overshoot it).

use thermode_model::{BadValue, Rule};

/// Reference temperature of CEM43 and the IEC 60601-1 long-contact (≥ 10 min) limit for applied parts, °C.
pub const CEM43_REFERENCE_C: f64 = 43.0;
/// How far above the budget the total dose of the true plate may go over any continuation, as a fraction of the
/// budget: 0.05 (5 %). Split between the estimate ([`DOSE_ESTIMATE_ALLOWANCE`]) and the margin for the estimate's
/// errors (the rest).
pub const DOSE_CAP_ALLOWANCE: f64 = 0.05;
/// How far above the budget the envelope's own dose estimate may go, as a fraction of the budget: 0.025 (half of
/// [`DOSE_CAP_ALLOWANCE`]; see the module documentation, "Margins").
pub const DOSE_ESTIMATE_ALLOWANCE: f64 = 0.025;
/// Time constant τ of the exponential spend of the remaining allowance after the lockout, s: 600 (10 min, the
/// IEC 60601-1 long-contact time scale). Larger: a lower ceiling right after the lockout that falls more slowly
/// (the ceiling is `43 + ln(R·60/τ)/ln 4` below 43 °C and falls by `1/(τ·ln 4)` per unit time when held at).
pub const DOSE_CAP_TIME_CONSTANT_S: f64 = 600.0;
/// Cooling rate of the plate that the anticipating ceiling assumes, °C/s: 5. The default display cools the plate
/// at 16–20 °C/s at full current (the model controller falls from 48 to 42.5 °C in 0.35 s); 5 leaves a factor of
/// three for a weaker module or a warmer hot side. The ceiling descends at this rate near the end of the budget.
pub const DOSE_COOLDOWN_RATE_C_PER_S: f64 = 5.0;

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

/// The temperature whose CEM43 rate is `rate` (CEM43-min per minute), °C: the inverse of [`cem43_rate`]
/// (`43 + log₂ rate` for rate ≥ 1, `43 + ln(rate)/ln 4` below). −∞ for a rate that is not positive (or NaN).
pub fn cem43_temperature_for_rate_c(rate: f64) -> f64 {
    if rate.is_nan() || rate <= 0.0 {
        f64::NEG_INFINITY
    } else if rate >= 1.0 {
        CEM43_REFERENCE_C + rate.log2()
    } else {
        CEM43_REFERENCE_C + rate.ln() / 4f64.ln()
    }
}

/// `∫_{−∞}^{T} rate(x) dx` in °C·(CEM43-min per minute): `4^(T−43)/ln 4` below 43 °C,
/// `1/ln 4 + (2^(T−43) − 1)/ln 2` at and above (continuous at 43 °C).
fn rate_integral(temp_c: f64) -> f64 {
    let x = temp_c - CEM43_REFERENCE_C;
    if x < 0.0 {
        4f64.powf(x) / 4f64.ln()
    } else {
        1.0 / 4f64.ln() + (2f64.powf(x) - 1.0) / 2f64.ln()
    }
}

/// Inverse of [`rate_integral`]: −∞ for a value that is not positive.
fn rate_integral_inverse_c(value: f64) -> f64 {
    let at_reference = 1.0 / 4f64.ln();
    if value.is_nan() || value <= 0.0 {
        f64::NEG_INFINITY
    } else if value < at_reference {
        CEM43_REFERENCE_C + (value * 4f64.ln()).ln() / 4f64.ln()
    } else {
        CEM43_REFERENCE_C + (1.0 + (value - at_reference) * 2f64.ln()).log2()
    }
}

/// CEM43 (minutes) of a plate falling linearly from `from_c` to `to_c` at `rate_c_per_s` (°C/s, > 0); 0 if
/// `from_c ≤ to_c`.
pub fn cem43_cooling_min(from_c: f64, to_c: f64, rate_c_per_s: f64) -> f64 {
    if from_c <= to_c {
        return 0.0;
    }
    (rate_integral(from_c) - rate_integral(to_c)) / (60.0 * rate_c_per_s)
}

/// The temperature from which a plate falling at `rate_c_per_s` (°C/s, > 0) to `to_c` spends `dose_min` CEM43
/// minutes, °C (the inverse of [`cem43_cooling_min`] in its first argument); `to_c` for a dose that is not positive.
pub fn cem43_cooling_start_c(to_c: f64, dose_min: f64, rate_c_per_s: f64) -> f64 {
    if dose_min.is_nan() || dose_min <= 0.0 {
        return to_c;
    }
    rate_integral_inverse_c(rate_integral(to_c) + dose_min * 60.0 * rate_c_per_s)
}

/// A channel's dose as it is saved and restored: the totals and whether the lockout has engaged.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DoseLedger {
    /// Accumulated thermal dose, CEM43-minutes (finite, ≥ 0).
    pub cem43_min: f64,
    /// Accumulated time with the (reconstructed) display at or above 43 °C, s (finite, ≥ 0).
    pub time_at_or_above_43_s: f64,
    /// The dose lockout has engaged (it stays engaged until the ledger is reset).
    pub lockout: bool,
}

impl DoseLedger {
    /// Both totals finite and not negative.
    pub fn validate(&self) -> Result<(), BadValue> {
        Rule::NonNegative.check("cem43_min", self.cem43_min)?;
        Rule::NonNegative.check("time_at_or_above_43_s", self.time_at_or_above_43_s)?;
        Ok(())
    }
}

/// Accumulates CEM43 (minutes) and the time at or above 43 °C (s) from a sequence of timed samples, optionally at
/// the plate temperature reconstructed from a lagging sensor (see the module documentation), and holds the
/// lockout once engaged.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DoseTracker {
    cem43_min: f64,
    time_at_or_above_43_s: f64,
    locked: bool,
    /// Sensor time constant τ_s of the reconstruction, s (0: the reading is used as it is).
    sensor_lag_s: f64,
    /// Shortest span of the slope, s.
    slope_window_s: f64,
    /// Largest slope the reconstruction believes, °C/s.
    max_slope_c_per_s: f64,
    /// Previous sample: time (s) and reconstructed temperature (°C).
    prev: Option<(f64, f64)>,
    /// Length of the last interval between samples, s (0 before the second sample).
    last_interval_s: f64,
    /// The longest interval between samples the caller allows, s (0: not known): the envelope's stale-sensor
    /// timeout, beyond which the drive is cut. The ceiling looks ahead at least this far, also before the first
    /// interval (see [`DoseCap::anticipating_c`]).
    longest_interval_s: f64,
    /// The time up to which the dose is counted, s: the newest sample's time, or later when unseen time after it
    /// was counted ([`DoseTracker::count_unseen`]).
    counted_to_s: f64,
    /// The temperature the unseen time since the newest sample was counted at, °C (`None` while none was).
    unseen_c: Option<f64>,
    /// Reference sample of the slope (time, reading), at least the window older than the newest sample.
    slope_older: Option<(f64, f64)>,
    /// The candidate that becomes the reference once the window has passed.
    slope_newer: Option<(f64, f64)>,
}

impl DoseTracker {
    /// An empty tracker (no dose) that accumulates at the readings as they are.
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty tracker that accumulates at the plate temperature reconstructed from a first-order sensor of time
    /// constant `sensor_lag_s` (s, ≥ 0; 0 = none), the slope taken over at least `slope_window_s` (s, > 0) and
    /// limited to `max_slope_c_per_s` (°C/s, > 0). The caller validates them (the envelope configuration does).
    pub fn with_sensor_lag(sensor_lag_s: f64, slope_window_s: f64, max_slope_c_per_s: f64) -> Self {
        DoseTracker {
            sensor_lag_s,
            slope_window_s,
            max_slope_c_per_s,
            ..Self::default()
        }
    }

    /// The reconstructed plate temperature of a reading `temp_c` at `time_s`, °C.
    fn reconstruct(&mut self, time_s: f64, temp_c: f64) -> f64 {
        if self.sensor_lag_s <= 0.0 {
            return temp_c;
        }
        let sample = (time_s, temp_c);
        let newer = *self.slope_newer.get_or_insert(sample);
        let mut older = self.slope_older.unwrap_or(newer);
        if time_s - newer.0 >= self.slope_window_s {
            older = newer;
            self.slope_newer = Some(sample);
        }
        self.slope_older = Some(older);
        let span_s = (time_s - older.0).max(self.slope_window_s);
        let limit = self.max_slope_c_per_s;
        let slope_c_per_s = ((temp_c - older.1) / span_s).clamp(-limit, limit);
        temp_c + self.sensor_lag_s * slope_c_per_s
    }

    /// Adds the interval from the previous sample to this one (`time_s` in s, `temp_c` the reading in °C, both
    /// finite; the caller validates). A sample not later than the previous one adds nothing but becomes the new
    /// reference.
    ///
    /// After unseen time was counted ([`DoseTracker::count_unseen`]), only the rest of the interval is added, at the
    /// hotter of the unseen temperature and this sample: the held reading of the previous sample is not counted
    /// again.
    pub fn add_sample(&mut self, time_s: f64, temp_c: f64) {
        let plate_c = self.reconstruct(time_s, temp_c);
        if let Some((t_prev, plate_prev_c)) = self.prev {
            if time_s - t_prev > 0.0 {
                self.last_interval_s = time_s - t_prev;
                let hot_c = self.unseen_c.unwrap_or(plate_prev_c).max(plate_c);
                self.count(time_s - self.counted_to_s.max(t_prev), hot_c);
            }
        }
        // A sample stamped before the unseen time already counted (its age) does not count that time again.
        self.counted_to_s = if self.prev.is_some() {
            self.counted_to_s.max(time_s)
        } else {
            time_s
        };
        self.prev = Some((time_s, plate_c));
        self.unseen_c = None;
    }

    /// Adds `dt_s` seconds (nothing if not positive) at `temp_c` to both totals.
    fn count(&mut self, dt_s: f64, temp_c: f64) {
        if dt_s > 0.0 {
            self.cem43_min += cem43_increment_min(temp_c, dt_s);
            if temp_c >= CEM43_REFERENCE_C {
                self.time_at_or_above_43_s += dt_s;
            }
        }
    }

    /// Counts the time from the last counted instant up to `now_s` (s), during which no fresh sample arrived, at
    /// `worst_c` (°C): the caller's bound on the plate it could not see (see `SafetyEnvelope`, "Unseen time"; −∞
    /// counts nothing but still marks the time as counted). The next sample adds only the time after `now_s`, at the
    /// hotter of the last `worst_c` and itself. Nothing happens before the first sample or for a `now_s` not later
    /// than the last counted instant.
    pub fn count_unseen(&mut self, now_s: f64, worst_c: f64) {
        if self.prev.is_none() || now_s <= self.counted_to_s {
            return;
        }
        self.count(now_s - self.counted_to_s, worst_c);
        self.counted_to_s = now_s;
        self.unseen_c = Some(worst_c);
    }

    /// Counts `dt_s` seconds (nothing if not positive) at `temp_c` (°C) once more, over time already counted: a
    /// stretch whose readings turned out not to measure the plate (a frozen sensor), counted again at the hottest
    /// the plate may have been. The counted instant does not move. Conservative: the stretch's first count stays.
    pub fn count_again(&mut self, dt_s: f64, temp_c: f64) {
        self.count(dt_s, temp_c);
    }

    /// The time up to which the dose is counted, s (the newest sample's time, or later after unseen time; 0 before
    /// the first sample).
    pub fn counted_to_s(&self) -> f64 {
        self.counted_to_s
    }

    /// Accumulated thermal dose, CEM43 minutes.
    pub fn cem43_min(&self) -> f64 {
        self.cem43_min
    }

    /// Accumulated time with the (reconstructed) display at or above 43 °C, s.
    pub fn time_at_or_above_43_s(&self) -> f64 {
        self.time_at_or_above_43_s
    }

    /// Length of the last interval between samples, s (0 before the second sample).
    pub fn last_interval_s(&self) -> f64 {
        self.last_interval_s
    }

    /// This tracker with the longest interval between samples its caller allows, s (finite, ≥ 0; see
    /// [`DoseTracker::lookahead_s`]).
    pub fn with_longest_interval_s(mut self, longest_interval_s: f64) -> Self {
        self.longest_interval_s = longest_interval_s;
        self
    }

    /// How long the coming interval between samples is taken to last, s: the last interval, at most the longest the
    /// caller allows (a longer gap faults the sensor and cuts the drive, so a gap already past — a link outage —
    /// says nothing about the coming interval); before the second sample, that longest interval.
    pub fn lookahead_s(&self) -> f64 {
        match (self.last_interval_s > 0.0, self.longest_interval_s > 0.0) {
            (true, true) => self.last_interval_s.min(self.longest_interval_s),
            (true, false) => self.last_interval_s,
            (false, _) => self.longest_interval_s,
        }
    }

    /// The time of the newest sample, s; `None` before the first sample.
    pub fn last_sample_s(&self) -> Option<f64> {
        self.prev.map(|(t, _)| t)
    }

    /// The plate temperature the last sample was counted at (reconstructed), °C; `None` before the first sample.
    pub fn last_plate_c(&self) -> Option<f64> {
        self.prev.map(|(_, c)| c)
    }

    /// Engages the lockout for good (only a reset ledger clears it).
    pub fn lock(&mut self) {
        self.locked = true;
    }

    /// Whether [`DoseTracker::lock`] was called (or a locked ledger restored).
    pub fn is_locked(&self) -> bool {
        self.locked
    }

    /// The totals and the lockout, for saving.
    pub fn ledger(&self) -> DoseLedger {
        DoseLedger {
            cem43_min: self.cem43_min,
            time_at_or_above_43_s: self.time_at_or_above_43_s,
            lockout: self.locked,
        }
    }

    /// Restores a saved dose: each total becomes the larger of the present and the saved one, and a saved lockout
    /// stays engaged, so a restore never lowers a dose (restoring twice changes nothing). Refused (nothing changes)
    /// when a total is negative or not finite. The next sample starts a new interval: the time between the save and
    /// the restore is not counted (the drive was off).
    pub fn restore(&mut self, saved: &DoseLedger) -> Result<(), BadValue> {
        saved.validate()?;
        self.cem43_min = self.cem43_min.max(saved.cem43_min);
        self.time_at_or_above_43_s = self.time_at_or_above_43_s.max(saved.time_at_or_above_43_s);
        self.locked |= saved.lockout;
        Ok(())
    }
}

/// A channel's dose budget and the ceilings it implies (see the module documentation, "The cap").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DoseCap {
    /// CEM43 budget `B`, CEM43-minutes (≥ 0).
    pub cem43_budget_min: f64,
    /// Budget of time at or above 43 °C, s (≥ 0).
    pub max_time_at_or_above_43_s: f64,
    /// Highest ceiling after the lockout, °C (`43 − dose_lockout_margin_c`, 42.5 by default).
    pub lockout_max_c: f64,
}

impl DoseCap {
    /// Whether the lockout has engaged: engaged before (a locked tracker), the CEM43 budget used, or the time at
    /// or above 43 °C used.
    pub fn lockout_reached(&self, dose: &DoseTracker) -> bool {
        dose.is_locked()
            || dose.cem43_min() >= self.cem43_budget_min
            || dose.time_at_or_above_43_s() >= self.max_time_at_or_above_43_s
    }

    /// Ceiling 1 for an accumulated dose `cem43_min`, °C: `rate(T) = (B·(1 + a) − D)/τ`, at most
    /// `lockout_max_c`; −∞ once the estimate's allowance is used.
    pub fn after_lockout_c(&self, cem43_min: f64) -> f64 {
        let remaining_min = self.cem43_budget_min * (1.0 + DOSE_ESTIMATE_ALLOWANCE) - cem43_min;
        let rate = remaining_min / (DOSE_CAP_TIME_CONSTANT_S / 60.0);
        cem43_temperature_for_rate_c(rate).min(self.lockout_max_c)
    }

    /// Ceiling 2, °C: the lower of the CEM43 and the time anticipation (+∞ far from either budget), taken where the
    /// continuous anticipating ceiling will be two intervals between samples ahead (each [`DoseTracker::lookahead_s`]
    /// long). Two, because an interval is counted at the hotter of its two samples: a plate set now is counted over
    /// the coming interval and, as the start of the next one, once more when it is the hotter. A plate held there
    /// then spends at most what a plate riding the continuous ceiling down would (the CEM43 rate grows with
    /// temperature), so sampling cannot carry the dose past the continuous path, however coarse the loop — also on
    /// the first interval, when the caller gave its longest interval.
    pub fn anticipating_c(&self, dose: &DoseTracker) -> f64 {
        let look_c = 2.0 * DOSE_COOLDOWN_RATE_C_PER_S * dose.lookahead_s();
        let (cem43_c, time_c) = self.continuous_anticipations_c(dose);
        // A plate at or below the lockout maximum (under 43 °C) adds no time at or above 43 °C: the time
        // anticipation needs no look ahead below it.
        (cem43_c - look_c).min((time_c - look_c).max(self.lockout_max_c))
    }

    /// The continuous anticipating ceilings `T_a` of the CEM43 and of the time budget, °C (no look ahead).
    fn continuous_anticipations_c(&self, dose: &DoseTracker) -> (f64, f64) {
        let landing_c = self.after_lockout_c(self.cem43_budget_min);
        let left_min = self.cem43_budget_min - dose.cem43_min();
        let cem43_c = cem43_cooling_start_c(landing_c, left_min, DOSE_COOLDOWN_RATE_C_PER_S);
        let left_s = (self.max_time_at_or_above_43_s - dose.time_at_or_above_43_s()).max(0.0);
        (cem43_c, self.lockout_max_c + DOSE_COOLDOWN_RATE_C_PER_S * left_s)
    }

    /// The continuous anticipating ceiling, °C: the lower of the two.
    fn continuous_anticipation_c(&self, dose: &DoseTracker) -> f64 {
        let (cem43_c, time_c) = self.continuous_anticipations_c(dose);
        cem43_c.min(time_c)
    }

    /// The dose ceiling, °C: before the lockout the anticipating ceiling; after it ceiling 1 and the continuous
    /// anticipation (at or below the landing temperature; the look ahead is for reaching the lockout at the landing
    /// temperature, and ceiling 1 falls with a 600 s time constant, which sampling cannot outrun). May lie outside
    /// the display range (+∞ far from the budget, −∞ once everything is spent): the envelope clamps it into
    /// `[min_display_c, max_display_c]`.
    pub fn ceiling_c(&self, dose: &DoseTracker) -> f64 {
        if self.lockout_reached(dose) {
            self.continuous_anticipation_c(dose)
                .min(self.after_lockout_c(dose.cem43_min()))
        } else {
            self.anticipating_c(dose)
        }
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

    fn close(got: f64, want: f64, tol: f64, what: &str) {
        assert!(
            (got - want).abs() <= tol,
            "{what}: got {got}, hand {want} (tolerance {tol})"
        );
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

    /// Hand values: rate 1 ↔ 43 °C, 2 ↔ 44 °C, 0.25 ↔ 42 °C, 1/16 ↔ 41 °C; nothing ↔ −∞.
    #[test]
    fn rate_inverse_matches_hand_values_and_round_trips() {
        for (rate, want_c) in [(1.0, 43.0), (2.0, 44.0), (32.0, 48.0), (0.25, 42.0), (0.0625, 41.0)] {
            close(
                cem43_temperature_for_rate_c(rate),
                want_c,
                1e-12,
                &format!("T(rate {rate})"),
            );
        }
        for t in [15.0, 30.0, 38.68, 42.5, 43.0, 45.5, 48.0] {
            close(cem43_temperature_for_rate_c(cem43_rate(t)), t, 1e-9, "round trip");
        }
        assert_eq!(cem43_temperature_for_rate_c(0.0), f64::NEG_INFINITY);
        assert_eq!(cem43_temperature_for_rate_c(-1.0), f64::NEG_INFINITY);
        assert_eq!(cem43_temperature_for_rate_c(f64::NAN), f64::NEG_INFINITY);
    }

    /// Hand values of a fall at 5 °C/s: 48 → 43 °C is ∫ 2^x dx over [0, 5] / (60·5) = 31/ln 2/300 = 0.149 078
    /// CEM43-min; 43 → 41 °C is (1 − 4^−2)/ln 4/300 = 0.002 254; 44 → 42 °C is (1/ln 2 + 0.75/ln 4)/300 = 0.006 613.
    /// The same falls integrated numerically (1 µs steps) agree, and the inverse returns the start.
    #[test]
    fn cooling_dose_matches_hand_values_and_its_inverse() {
        let c = 5.0;
        let cases = [
            (48.0, 43.0, 31.0 / 2f64.ln() / 300.0),
            (43.0, 41.0, (1.0 - 1.0 / 16.0) / 4f64.ln() / 300.0),
            (44.0, 42.0, (1.0 / 2f64.ln() + 0.75 / 4f64.ln()) / 300.0),
        ];
        for (from_c, to_c, want) in cases {
            let got = cem43_cooling_min(from_c, to_c, c);
            close(got, want, 1e-12, &format!("{from_c} → {to_c} °C at {c} °C/s"));
            let steps = 1_000_000;
            let dt_s = (from_c - to_c) / c / steps as f64;
            let numeric: f64 = (0..steps)
                .map(|k| cem43_increment_min(from_c - c * (k as f64 + 0.5) * dt_s, dt_s))
                .sum();
            close(got, numeric, 1e-9, "numerical integral");
            close(cem43_cooling_start_c(to_c, got, c), from_c, 1e-9, "inverse");
        }
        assert_eq!(cem43_cooling_min(40.0, 41.0, c), 0.0);
        assert_eq!(cem43_cooling_start_c(41.0, 0.0, c), 41.0);
        assert_eq!(cem43_cooling_start_c(41.0, -1.0, c), 41.0);
    }

    fn default_cap() -> DoseCap {
        DoseCap {
            cem43_budget_min: 1.0,
            max_time_at_or_above_43_s: 600.0,
            lockout_max_c: 42.5,
        }
    }

    fn tracker(cem43_min: f64, time_at_or_above_43_s: f64) -> DoseTracker {
        let mut d = DoseTracker::new();
        d.restore(&DoseLedger {
            cem43_min,
            time_at_or_above_43_s,
            lockout: false,
        })
        .unwrap();
        d
    }

    /// The documented figures of the defaults: landing at 43 + ln(0.0025)/ln 4 = 38.6781 °C; the anticipating
    /// ceiling at 48 °C once 1 − 0.1515 CEM43-min are spent; at D = 0.5 CEM43-min and 300 s at ≥ 43 °C nothing
    /// binds (ceiling above 48 °C); at the budget the ceiling is the landing temperature; 0.0125 CEM43-min past
    /// it (half the estimate's allowance) the rate is halved: 38.6781 − 0.5 = 38.1781 °C.
    #[test]
    fn ceilings_of_the_default_budget_match_hand_values() {
        let cap = default_cap();
        let landing_c = 43.0 + 0.0025f64.ln() / 4f64.ln();
        close(landing_c, 38.678_071_905, 1e-8, "landing");
        close(cap.after_lockout_c(1.0), landing_c, 1e-12, "ceiling at the budget");
        let start_min = 1.0 - cem43_cooling_min(48.0, landing_c, 5.0);
        // 48 → 43 °C: 31/ln 2/300 = 0.149 078; 43 → 38.678 °C: (1 − 0.0025)/ln 4/300 = 0.002 398.
        close(1.0 - start_min, 0.151_477, 1e-6, "anticipation reserve at 48 °C");
        close(
            cap.ceiling_c(&tracker(start_min, 0.0)),
            48.0,
            1e-9,
            "ceiling leaves 48 °C",
        );
        assert!(cap.ceiling_c(&tracker(0.5, 300.0)) > 48.0);
        assert!(!cap.lockout_reached(&tracker(0.999, 0.0)));
        assert!(cap.lockout_reached(&tracker(1.0, 0.0)));
        close(cap.ceiling_c(&tracker(1.0, 0.0)), landing_c, 1e-9, "at the budget");
        close(
            cap.ceiling_c(&tracker(1.0125, 0.0)),
            landing_c - 0.5,
            1e-9,
            "half the allowance left",
        );
        assert_eq!(cap.ceiling_c(&tracker(1.025, 0.0)), f64::NEG_INFINITY);
        // The time budget: 1 s left anticipates 42.5 + 5 = 47.5 °C; used up, the lockout ceiling with 0.3 CEM43-min
        // spent is 43 + ln(0.0725)/ln 4 = 41.1069 °C.
        close(cap.ceiling_c(&tracker(0.0, 599.0)), 47.5, 1e-9, "time anticipation");
        let want_c = 43.0 + 0.0725f64.ln() / 4f64.ln();
        close(cap.ceiling_c(&tracker(0.3, 600.0)), want_c, 1e-9, "time lockout");
        // A large budget: the lockout ceiling is capped at 43 − margin.
        let big = DoseCap {
            cem43_budget_min: 10.0,
            max_time_at_or_above_43_s: 2.0,
            lockout_max_c: 42.5,
        };
        close(big.ceiling_c(&tracker(0.1, 2.0)), 42.5, 1e-12, "capped at 42.5");
    }

    /// A link outage (a 5 s gap between samples, which faulted the sensor) says nothing about the coming interval:
    /// with the caller's longest interval given, the ceiling looks that far ahead, not as far as the gap.
    #[test]
    fn a_gap_between_samples_does_not_lower_the_ceiling_afterwards() {
        let cap = default_cap();
        let mut d = DoseTracker::new().with_longest_interval_s(0.2);
        for (t, temp_c) in [(0.0, 44.0), (0.01, 44.0), (5.01, 33.0)] {
            d.add_sample(t, temp_c);
        }
        let continuous_c = cap.continuous_anticipation_c(&d);
        assert_eq!(d.last_interval_s(), 5.0);
        assert!(
            (cap.anticipating_c(&d) - (continuous_c - 2.0)).abs() < 1e-9,
            "ceiling {} °C after a 5 s gap: want the continuous {continuous_c} °C less 2 · 5 °C/s · 0.2 s",
            cap.anticipating_c(&d)
        );
    }

    /// Unseen time counts at the caller's bound; the sample that ends it adds only the rest (at the hotter of the
    /// bound and itself), never the whole gap at the held reading, and a sample stamped before the counted time
    /// counts nothing twice.
    #[test]
    fn unseen_time_counts_at_the_bound_and_the_next_sample_adds_only_the_rest() {
        let mut d = DoseTracker::new();
        d.add_sample(0.0, 44.0);
        d.count_unseen(2.0, 46.0);
        let after_unseen = cem43_increment_min(46.0, 2.0);
        assert!(
            (d.cem43_min() - after_unseen).abs() < 1e-12,
            "{} vs {after_unseen}",
            d.cem43_min()
        );
        assert_eq!((d.counted_to_s(), d.time_at_or_above_43_s()), (2.0, 2.0));
        d.add_sample(2.5, 35.0);
        let want = after_unseen + cem43_increment_min(46.0, 0.5);
        assert!((d.cem43_min() - want).abs() < 1e-12, "{} vs {want}", d.cem43_min());
        // Counted up to 3.2 s at −∞ (nothing); a sample stamped 3.1 s then adds nothing, the next one from 3.2 s.
        d.count_unseen(3.2, f64::NEG_INFINITY);
        d.add_sample(3.1, 35.0);
        assert!((d.cem43_min() - want).abs() < 1e-12, "{} vs {want}", d.cem43_min());
        d.add_sample(3.3, 35.0);
        let want = want + cem43_increment_min(35.0, 0.1);
        assert!((d.cem43_min() - want).abs() < 1e-15, "{} vs {want}", d.cem43_min());
        // Nothing before the first sample.
        let mut empty = DoseTracker::new();
        empty.count_unseen(5.0, 48.0);
        assert_eq!(empty.cem43_min(), 0.0);
    }

    #[test]
    fn the_ceiling_never_rises_as_the_dose_grows() {
        let cap = default_cap();
        let mut last = f64::INFINITY;
        for k in 0..=2000 {
            let d = tracker(k as f64 * 0.001, k as f64 * 0.3);
            let c = cap.ceiling_c(&d);
            assert!(c <= last, "ceiling rose from {last} to {c} at D = {}", d.cem43_min());
            last = c;
        }
    }

    /// The plate at `request_c(t)` clamped to the ceiling of the previous sample (the most a plate that obeys the
    /// ceiling can spend), sampled every `dt_s` for `duration_s`, from a tracker `d`.
    fn obey(cap: &DoseCap, d: &mut DoseTracker, t0_s: f64, duration_s: f64, dt_s: f64, request_c: impl Fn(f64) -> f64) {
        let mut plate_c = d.last_plate_c().unwrap_or(33.0);
        let steps = (duration_s / dt_s).round() as u64;
        for k in 0..steps {
            let t = t0_s + k as f64 * dt_s;
            d.add_sample(t, plate_c);
            if cap.lockout_reached(d) {
                d.lock();
            }
            plate_c = request_c(t).min(cap.ceiling_c(d)).max(15.0);
        }
    }

    /// A plate held at whatever the ceiling allows (any request above it is clamped to it) for a long time: the
    /// estimate's dose converges to B·(1 + 2.5 %) and never exceeds it, and the time at or above 43 °C stays within
    /// its budget (plus one sample), for several budgets and any constant request (a request below the ceiling
    /// spends less). Analytic: D(t) = B(1 + a) − R₀·e^{−t/τ} after the lockout.
    #[test]
    fn any_continuation_stays_within_the_estimate_allowance() {
        for (budget, time_budget_s) in [(0.1, 600.0), (1.0, 600.0), (10.0, 600.0), (10.0, 20.0)] {
            let cap = DoseCap {
                cem43_budget_min: budget,
                max_time_at_or_above_43_s: time_budget_s,
                lockout_max_c: 42.5,
            };
            let limit = budget * (1.0 + DOSE_ESTIMATE_ALLOWANCE);
            for request_c in [38.0f64, 42.0, 44.0, 45.0, 48.0] {
                let mut d = DoseTracker::new();
                let dt_s = 0.05;
                obey(&cap, &mut d, 0.0, 36_000.0, dt_s, |_| request_c);
                let (got, t43) = (d.cem43_min(), d.time_at_or_above_43_s());
                assert!(
                    got <= limit * (1.0 + 1e-9),
                    "budget {budget}, request {request_c} °C: {got} CEM43-min > {limit}"
                );
                assert!(
                    t43 <= time_budget_s + dt_s,
                    "time budget {time_budget_s} s, request {request_c} °C: {t43} s at ≥ 43 °C"
                );
                if request_c >= 45.0 && time_budget_s >= 600.0 {
                    assert!(
                        got >= budget,
                        "budget {budget}, request {request_c}: {got} never reached the budget"
                    );
                }
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 32, failure_persistence: None,
            ..proptest::prelude::ProptestConfig::default() })]

        /// Any budgets, any sequence of requests (up to 20 segments of up to 10 min each at 15–48 °C), then two
        /// hours (12 τ) asking for 48 °C, sampled at loop periods from 10 ms to 1 s (the plate jumping to the ceiling
        /// at each sample): the total stays within the estimate's allowance and the time budget.
        #[test]
        fn any_request_sequence_stays_within_the_allowance(
            budget in 0.05..10.0f64,
            time_budget_s in 1.0..600.0f64,
            segments in proptest::collection::vec((1.0..600.0f64, 15.0..48.0f64), 1..20),
            dt_s in proptest::sample::select(vec![0.01, 0.1, 0.5, 1.0]),
        ) {
            let cap = DoseCap { cem43_budget_min: budget, max_time_at_or_above_43_s: time_budget_s, lockout_max_c: 42.5 };
            let mut d = DoseTracker::new().with_longest_interval_s(dt_s);
            let mut t0_s = 0.0;
            for (duration_s, request_c) in segments {
                obey(&cap, &mut d, t0_s, duration_s, dt_s, |_| request_c);
                t0_s += (duration_s / dt_s).round() * dt_s;
            }
            obey(&cap, &mut d, t0_s, 7_200.0, dt_s, |_| 48.0);
            let limit = budget * (1.0 + DOSE_ESTIMATE_ALLOWANCE);
            proptest::prop_assert!(d.cem43_min() <= limit * (1.0 + 1e-9), "{} > {limit}", d.cem43_min());
            proptest::prop_assert!(d.time_at_or_above_43_s() <= time_budget_s + dt_s,
                "{} s at ≥ 43 °C, budget {time_budget_s} s", d.time_at_or_above_43_s());
        }
    }

    /// A first-order sensor (τ = 0.3 s) behind a plate ramping 33 → 48 °C at 20 °C/s and holding: the reading
    /// under-counts the plate's dose, the reconstruction does not (it over-counts a little, by its window's lag).
    /// Then the plate falls to 38 °C at 20 °C/s: the reading over-counts the way down, the reconstruction stays
    /// close to the plate.
    #[test]
    fn the_reconstruction_recovers_the_plate_behind_a_lagging_sensor() {
        let (tau_s, dt_s) = (0.3, 0.01);
        let plate_at = |t: f64| {
            if t < 3.0 {
                (33.0 + 20.0 * t).min(48.0)
            } else {
                (48.0 - 20.0 * (t - 3.0)).max(38.0)
            }
        };
        let mut plain = DoseTracker::new();
        let mut recon = DoseTracker::with_sensor_lag(tau_s, 0.05, 50.0);
        let mut plate = DoseTracker::new();
        let mut sensor_c: f64 = 33.0;
        let sub = 100;
        let mut at_3_s = None;
        for k in 0..=500 {
            let t = k as f64 * dt_s;
            plain.add_sample(t, sensor_c);
            recon.add_sample(t, sensor_c);
            plate.add_sample(t, plate_at(t));
            if k == 300 {
                at_3_s = Some((plate.cem43_min(), plain.cem43_min(), recon.cem43_min()));
            }
            // The sensor to the next sample in small Euler steps of its first-order lag.
            for j in 0..sub {
                let tj = t + j as f64 * dt_s / sub as f64;
                sensor_c += (plate_at(tj) - sensor_c) * (dt_s / sub as f64) / tau_s;
            }
        }
        let (p, s, r) = at_3_s.unwrap();
        assert!(s < 0.8 * p, "rise: plain reading {s} vs plate {p}");
        assert!(r >= p && r <= 1.15 * p, "rise: reconstructed {r} vs plate {p}");
        let (p, s, r) = (plate.cem43_min() - p, plain.cem43_min() - s, recon.cem43_min() - r);
        assert!(s > 2.0 * p, "fall: plain reading {s} vs plate {p}");
        assert!(r >= p && r <= 1.5 * p, "fall: reconstructed {r} vs plate {p}");
    }

    #[test]
    fn restore_never_lowers_and_refuses_bad_totals() {
        let mut d = hold(44.0, 60.0, 0.01);
        let before = d.ledger();
        d.restore(&DoseLedger::default()).unwrap();
        assert_eq!(d.ledger(), before, "restoring a smaller dose changes nothing");
        let saved = DoseLedger {
            cem43_min: 5.0,
            time_at_or_above_43_s: 1.0,
            lockout: true,
        };
        d.restore(&saved).unwrap();
        let want = DoseLedger {
            cem43_min: 5.0,
            time_at_or_above_43_s: 60.0,
            lockout: true,
        };
        assert_eq!(d.ledger(), want);
        d.restore(&saved).unwrap();
        assert_eq!(d.ledger(), want, "restoring twice changes nothing");
        for bad in [f64::NAN, -1.0, f64::INFINITY] {
            let e = d.restore(&DoseLedger {
                cem43_min: bad,
                ..DoseLedger::default()
            });
            assert!(e.is_err(), "{bad} accepted");
            assert_eq!(d.ledger(), want);
        }
    }
}
