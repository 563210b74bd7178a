//! The innovation check: does the plate sensor still measure the plate? A reading can lie with every counter
//! fresh — an ADC stuck at one value while its reports keep their sample numbers advancing, a firmware that repeats
//! its last conversion, a sensor that reads another plate. Nothing in such a reading is wrong by itself (finite, in
//! range, a plausible rate), and a Kalman observer corrected by it follows it: the plate guard's estimate stayed
//! near a reading frozen at 34 °C while a full drive took the true plate to 194–266 °C. Only a model run *open loop*
//! can tell: under a drive it predicts the plate moving at tens of °C per second.
//!
//! **What is compared.** The plate, not the sensor: the PT-100 lags the plate by its time constant τ, and the
//! sensor's path over the next tenths of a second depends mostly on how far the plate already leads it, which a
//! model off its file gets wrong after every reversal (a sensor 30 % slower than its file kept rising 0.3 s into a
//! full cooling drive that the model expected it to follow at once). The reading's plate is its lag inverted,
//! `P = r + τ ṙ` (exact for a first-order sensor; ṙ against a reading τ/6 or more before, [`SLOPE_WINDOW_S`], so
//! its noise stays near 0.2 °C), and it is compared with the model's plate. A frozen reading loses its slope at once:
//! its plate falls back by τ·ṙ (6 °C under a 20 °C/s ramp) while the model's rises.
//!
//! **The shadow.** At a fresh sample whose plate agrees with it, the check restarts a *shadow*: a copy of the
//! guard's observer ([`PlateObserver`]) as it stands after that sample's correction, coasted from then on with the
//! current the device reports delivering (its own measurement, so a command still in transit on a slow link does
//! not count) and the finger model, never corrected. While the reading's plate change agrees with the shadow's to
//! within [`RESTART_TOLERANCE_C`] plus a tenth of it, the shadow restarts; otherwise it ages and the gap builds up.
//!
//! **The verdict.** On a fresh sample, a shadow whose plate moved at least [`MIN_PREDICTED_CHANGE_C`] since its
//! start, under a drive of at least [`MIN_DRIVE_FRACTION`] of the limit that keeps its direction
//! ([`MIN_DRIVE_DIRECTION_SHARE`]), disagrees when the
//! reading's plate moved less than [`MIN_FOLLOWED_FRACTION`] of that change in its direction (less
//! [`READING_NOISE_C`]). [`DISAGREEING_SAMPLES`] disagreeing samples in a row are a verdict ([`Disagreement`]): the
//! channel faults, and from the shadow's start on the dose is counted at the shadow's plate instead of the readings.
//! Both drive directions are checked. Displays 25–30 % off their file in every parameter at once follow at 50 % or
//! more of the file's prediction; a frozen reading's plate moves the wrong way.
//!
//! **Blind spots, by design.** No verdict without a drive (a frozen reading at rest is harmless and
//! indistinguishable from a resting plate), in the first [`SETTLING_S`] after the observer started (its estimate
//! is still the first reading's), nor on a first sample after a gap of more than [`MAX_SAMPLE_GAP`] sample periods
//! (the shadow restarts: during a gap the device may not have applied what the loop sent).

use thermode_control::{Finger, PlateObserver};

/// A reading's plate within this of the shadow's (plus a tenth of the shadow's change) agrees with it \[°C\]: 0.3,
/// about one and a half standard deviations of the lag-inverted reading's noise on the default display.
pub const RESTART_TOLERANCE_C: f64 = 0.3;
/// The least change of the plate the shadow must predict before it judges \[°C\]: 1.5 (under the default module's
/// full drive about 60 ms of travel; seven times the lag-inverted reading's noise).
pub const MIN_PREDICTED_CHANGE_C: f64 = 1.5;
/// The least share of the predicted change a reading that still measures the plate makes in its direction \[-\]:
/// 0.35. A display 25–30 % off its file in every parameter at once still makes half of it.
pub const MIN_FOLLOWED_FRACTION: f64 = 0.35;
/// The reading's noise allowed on top of [`MIN_FOLLOWED_FRACTION`] \[°C\]: 0.4 (twice the lag-inverted reading's
/// noise on the default display).
pub const READING_NOISE_C: f64 = 0.4;
/// The least mean drive, as a fraction of the current limit, under which the check judges \[-\]: 0.3. Below it a
/// model off its file drifts from its display by as much as the drive moves the plate (a plate held at the
/// display's limit by pulses of a few tenths of an ampere: 1.7 °C in 0.4 s on a plate 30 % lighter than its file);
/// a reading that freezes leaves any controller pushing ever harder, to its limit.
pub const MIN_DRIVE_FRACTION: f64 = 0.3;
/// The least share of the drive that keeps one direction over the shadow's life \[-\]: 0.8 (the signed mean over
/// the mean magnitude). A drive that reverses leaves the sensor running the old way for a while, with the lag
/// inversion's slope behind the plate by half its window (up to 1 °C at a full reversal).
pub const MIN_DRIVE_DIRECTION_SHARE: f64 = 0.8;
/// Disagreeing fresh samples in a row that make a verdict: 3 (30 ms at the default 100 Hz sensor).
pub const DISAGREEING_SAMPLES: usize = 3;
/// A shadow restarts no sooner than this after its start \[s\]: 0.2. Restarted at every agreeing sample, a shadow
/// would follow a reading that lies by less than the tolerance per sample (one frozen under a drive that is only
/// starting); over 0.2 s the gap of a lie exceeds the tolerance.
pub const MIN_SHADOW_AGE_S: f64 = 0.2;
/// A shadow older than this restarts at the next sample that does not disagree \[s\]: 0.5 (a display off its file
/// drifts from its shadow; the verdict's share allows for it over this long).
pub const MAX_SHADOW_AGE_S: f64 = 0.5;
/// A gap between fresh samples longer than this many sample periods restarts the shadow instead of judging: 3.
pub const MAX_SAMPLE_GAP: f64 = 3.0;
/// No verdict within this long of the first sample the check took (the observer's start or restart) \[s\]: 2. An
/// observer that has just started takes its plate from the first reading (behind a plate already moving) and knows
/// no unknown heat yet; coasted open loop from there it drifted 2 °C in half a second after a cleared fault.
pub const SETTLING_S: f64 = 2.0;
/// The reading's slope is taken against the newest kept reading at least a sixth of the sensor's time constant
/// old, within these bounds \[s\]: 0.05 to 0.3. The lag inversion multiplies the slope's noise by τ, so the window
/// grows with τ: the lag-inverted reading's noise stays near 0.2 °C (the default 0.3 s sensor: 50 ms; a 1.5 s one:
/// 0.25 s).
pub const SLOPE_WINDOW_S: (f64, f64) = (0.05, 0.3);
/// What the dose counts at beyond the shadow's plate while the reading is not believed \[°C\]: 1.0 (the model's
/// error over the seconds after a verdict, the drive off).
pub const DISTRUST_MARGIN_C: f64 = 1.0;

/// Readings the slope keeps, at least [`KEPT_SPACING_S`] apart (0.32 s of them, the longest slope window).
const KEPT_READINGS: usize = 32;
/// Smallest spacing of the kept readings \[s\]: 10 ms.
const KEPT_SPACING_S: f64 = 0.01;

/// What the check found: the reading stopped following the plate model under a drive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disagreement {
    /// When the shadow that disagrees started: the last sample the reading agreed with \[s\].
    pub since_s: f64,
    /// When the verdict fell \[s\].
    pub at_s: f64,
    /// The hottest plate the shadow went through since it started \[°C\].
    pub hottest_plate_c: f64,
    /// How far the shadow's plate moved since its start \[°C\].
    pub predicted_change_c: f64,
    /// How far the reading's plate (its lag inverted) moved since then \[°C\].
    pub reading_change_c: f64,
}

/// The reading's plate: its lag inverted, from the kept readings.
#[derive(Debug, Clone, Copy)]
struct ReadingPlate {
    /// (time \[s\], reading \[°C\]), oldest overwritten first.
    kept: [(f64, f64); KEPT_READINGS],
    next: usize,
}

impl Default for ReadingPlate {
    fn default() -> Self {
        ReadingPlate {
            kept: [(f64::NAN, f64::NAN); KEPT_READINGS],
            next: 0,
        }
    }
}

impl ReadingPlate {
    /// The plate a first-order sensor of time constant `lag_s` \[s\] reading `reading_c` at `now_s` stands for
    /// \[°C\]: `r + τ ṙ`, ṙ against the newest kept reading at least the slope window old ([`SLOPE_WINDOW_S`];
    /// none: the reading). The reading is kept when it is [`KEPT_SPACING_S`] or more after the last kept one.
    fn take(&mut self, now_s: f64, reading_c: f64, lag_s: f64) -> f64 {
        let window_s = slope_window_s(lag_s);
        let reference = self
            .kept
            .iter()
            .filter(|(t, _)| now_s - t >= window_s)
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .copied();
        let last_s = self.kept[(self.next + KEPT_READINGS - 1) % KEPT_READINGS].0;
        if last_s.is_nan() || now_s - last_s >= KEPT_SPACING_S {
            self.kept[self.next] = (now_s, reading_c);
            self.next = (self.next + 1) % KEPT_READINGS;
        }
        match reference {
            Some((t, c)) => reading_c + lag_s * (reading_c - c) / (now_s - t),
            None => reading_c,
        }
    }
}

/// The slope window of a sensor of time constant `lag_s` \[s\] ([`SLOPE_WINDOW_S`]) \[s\].
fn slope_window_s(lag_s: f64) -> f64 {
    (lag_s / 6.0).clamp(SLOPE_WINDOW_S.0, SLOPE_WINDOW_S.1)
}

/// The guard's observer coasted open loop since the last sample the reading agreed with.
#[derive(Debug, Clone)]
struct Shadow {
    model: PlateObserver,
    start_s: f64,
    /// The reading's plate at the start \[°C\].
    start_reading_plate_c: f64,
    start_plate_c: f64,
    /// ∫|I| dt since the start \[A·s\].
    drive_a_s: f64,
    /// ∫I dt since the start \[A·s\].
    signed_drive_a_s: f64,
    duration_s: f64,
    hottest_plate_c: f64,
}

impl Shadow {
    fn plate_c(&self) -> f64 {
        self.model.estimate().map_or(f64::NAN, |e| e.plate_c)
    }
}

/// What a judgement needs besides the sample: whether the check has settled, the drive's limit \[A\] and the
/// slope window \[s\].
#[derive(Debug, Clone, Copy)]
struct Judging {
    settled: bool,
    current_limit_a: f64,
    window_s: f64,
}

/// The innovation check of one channel (see the module documentation).
#[derive(Debug, Clone, Default)]
pub struct ReadingCheck {
    shadow: Option<Shadow>,
    reading_plate: ReadingPlate,
    /// Time of the first fresh sample since the start or a restart \[s\].
    first_sample_s: Option<f64>,
    /// Time of the last fresh sample \[s\].
    last_sample_s: Option<f64>,
    disagreeing: usize,
    verdict: Option<Disagreement>,
}

impl ReadingCheck {
    /// A check with no shadow yet.
    pub fn new() -> Self {
        ReadingCheck::default()
    }

    /// Coasts the shadow over `dt_s` \[s\] at the delivered `current_a` \[A\] with `finger` (every tick, before the
    /// guard's observer takes the tick). A current that is not finite counts as none.
    pub fn coast(&mut self, dt_s: f64, current_a: f64, finger: Finger) {
        let Some(shadow) = &mut self.shadow else {
            return;
        };
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        let current_a = if current_a.is_finite() { current_a } else { 0.0 };
        shadow.model.coast(dt_s, current_a, finger);
        shadow.drive_a_s += current_a.abs() * dt_s;
        shadow.signed_drive_a_s += current_a * dt_s;
        shadow.duration_s += dt_s;
        shadow.hottest_plate_c = shadow.hottest_plate_c.max(shadow.plate_c());
    }

    /// Judges the fresh sample `reading_c` \[°C\] at `now_s` \[s\] against the shadow, then restarts the shadow from
    /// `corrected` (the guard's observer after it took the sample) where the reading agrees with it, the shadow is
    /// old, or samples came after a gap. The sensor's lag and sample period and the drive's limit are `corrected`'s.
    pub fn judge(&mut self, now_s: f64, reading_c: f64, corrected: &PlateObserver) {
        let plant = corrected.plant();
        let reading_plate_c = self.reading_plate.take(now_s, reading_c, plant.sensor_time_constant_s);
        let first_s = *self.first_sample_s.get_or_insert(now_s);
        let gap = self
            .last_sample_s
            .is_some_and(|last_s| now_s - last_s > MAX_SAMPLE_GAP * plant.sample_period_s());
        self.last_sample_s = Some(now_s);
        if self.verdict.is_some() {
            return;
        }
        let restart = match (self.shadow.take(), gap) {
            (Some(shadow), false) => {
                let settled = now_s - first_s >= SETTLING_S;
                let judging = Judging {
                    settled,
                    current_limit_a: plant.current_limit_a,
                    window_s: slope_window_s(plant.sensor_time_constant_s),
                };
                let restart = self.judge_against(now_s, reading_plate_c, judging, &shadow);
                self.shadow = Some(shadow);
                restart
            }
            _ => true,
        };
        if restart && self.verdict.is_none() {
            self.restart(now_s, reading_plate_c, corrected);
        }
    }

    /// One sample against `shadow` (the reading's plate `reading_plate_c` \[°C\]): counts a disagreement (a verdict
    /// after [`DISAGREEING_SAMPLES`]); returns whether the shadow restarts. The lag inversion's slope is that of half
    /// its window ago, so under a drive that started with the shadow the reading's plate trails by that much: the
    /// share asked is lowered by it, and a shadow younger than the window is not judged.
    fn judge_against(&mut self, now_s: f64, reading_plate_c: f64, judging: Judging, shadow: &Shadow) -> bool {
        let Judging {
            settled,
            current_limit_a,
            window_s,
        } = judging;
        let predicted_c = shadow.plate_c() - shadow.start_plate_c;
        let reading_change_c = reading_plate_c - shadow.start_reading_plate_c;
        let duration_s = shadow.duration_s.max(f64::MIN_POSITIVE);
        let (mean_drive_a, signed_drive_a) = (shadow.drive_a_s / duration_s, shadow.signed_drive_a_s / duration_s);
        let judged = settled
            && shadow.duration_s >= window_s
            && predicted_c.abs() >= MIN_PREDICTED_CHANGE_C
            && signed_drive_a.abs() >= MIN_DRIVE_FRACTION * current_limit_a
            && signed_drive_a.abs() >= MIN_DRIVE_DIRECTION_SHARE * mean_drive_a;
        let followed_c = reading_change_c * predicted_c.signum();
        let trailing_share = 0.5 * window_s / duration_s;
        let asked_c = MIN_FOLLOWED_FRACTION * (1.0 - trailing_share) * predicted_c.abs() - READING_NOISE_C;
        if judged && followed_c < asked_c {
            self.disagreeing += 1;
            if self.disagreeing >= DISAGREEING_SAMPLES {
                self.verdict = Some(Disagreement {
                    since_s: shadow.start_s,
                    at_s: now_s,
                    hottest_plate_c: shadow.hottest_plate_c,
                    predicted_change_c: predicted_c,
                    reading_change_c,
                });
            }
            return false;
        }
        self.disagreeing = 0;
        let agrees = (reading_change_c - predicted_c).abs() <= RESTART_TOLERANCE_C + 0.1 * predicted_c.abs();
        (agrees && shadow.duration_s >= MIN_SHADOW_AGE_S) || shadow.duration_s >= MAX_SHADOW_AGE_S
    }

    fn restart(&mut self, now_s: f64, reading_plate_c: f64, corrected: &PlateObserver) {
        let Some(estimate) = corrected.estimate() else {
            return;
        };
        self.shadow = Some(Shadow {
            model: corrected.clone(),
            start_s: now_s,
            start_reading_plate_c: reading_plate_c,
            start_plate_c: estimate.plate_c,
            drive_a_s: 0.0,
            signed_drive_a_s: 0.0,
            duration_s: 0.0,
            hottest_plate_c: estimate.plate_c,
        });
    }

    /// Drops the shadow and the kept readings (the next fresh sample starts afresh, settling again); a verdict
    /// stays.
    pub fn restart_shadow(&mut self) {
        *self = ReadingCheck {
            verdict: self.verdict,
            ..ReadingCheck::default()
        };
    }

    /// The verdict, once the reading disagreed ([`Disagreement`]); it stays.
    pub fn verdict(&self) -> Option<Disagreement> {
        self.verdict
    }

    /// The shadow's plate now \[°C\]: where the model puts the plate since the reading last agreed (NaN without a
    /// shadow). After a verdict it is what the plate may be while the reading is not believed.
    pub fn shadow_plate_c(&self) -> f64 {
        self.shadow.as_ref().map_or(f64::NAN, |s| s.plate_c())
    }
}
