//! The safety envelope of one display channel. Every drive command passes through it: it is the only way to a
//! [`DriveCommand`] other than [`DriveCommand::off`] (its fields are private, and it has no other public
//! constructor, no `Clone`, no `Deserialize`).
//!
//! Per tick the runtime calls, in this order:
//! 1. [`SafetyEnvelope::observe`] with the newest [`Measurement`] (fault checks, thermal-dose accumulation);
//! 2. [`SafetyEnvelope::shape_setpoint`] with the requested display set-point (NaN → fault; clamp into
//!    `[min, effective max]`; rate limit);
//! 3. the controller, on the shaped set-point;
//! 4. [`SafetyEnvelope::gate_drive`] with the controller's request (use `f64::NAN` if the controller returned an
//!    error) and a [`PlateForecast`]: 0 A while a fault is latched or before the first measurement; never heating
//!    while the measured display is at/above the effective maximum, never cooling at/below the minimum; within
//!    `±current_limit_a`; and, with a model of the plate, never a current whose predicted plate at the end of the
//!    tick passes `[min + margin, effective max − margin]` (the margin follows the estimate's uncertainty,
//!    [`crate::plate::plate_margin_c`]): heating and cooling are limited, and the drive is turned round when the
//!    plate would pass a limit even at 0 A.
//!
//! While a channel is held off (stop all), [`SafetyEnvelope::hold`] replaces steps 2–4: fault checks go on, the
//! drive is off, and the stuck-drive detection is reset.
//!
//! Sign convention: **positive current heats the display**.
//!
//! Faults ([`FaultCode`]) switch the drive off and latch. [`SafetyEnvelope::clear_fault`] refuses while no fresh
//! measurement has arrived since the fault latched, or while the newest measurement still shows a cause
//! (sensor fault, temperatures beyond limits, stale sensor, display at/above 48 °C, display at/above 43 °C under a
//! dose lockout). Causes outside the measurement (NaN set-point or request, stuck drive, time going backwards) are
//! cleared; they latch again at once if they recur. Clearing never resets the thermal dose: the dose belongs to the
//! session, and a new session is a new envelope.
//!
//! Thermal dose: the measured display temperature feeds a [`DoseTracker`], which counts the dose at the plate
//! temperature reconstructed from the lagging sensor (`sensor_time_constant_s`). The dose is a **cap**, not a
//! slope ([`crate::dose`], "The cap"): near the end of the budget the effective maximum comes down at
//! [`crate::dose::DOSE_COOLDOWN_RATE_C_PER_S`]; once the time at/above 43 °C reaches `max_time_at_or_above_43_s` or
//! CEM43 reaches `cem43_budget_min` the lockout engages for good, and the effective maximum, at most
//! `43 − dose_lockout_margin_c`, keeps falling as dose is spent so that the total stays within 5 % of the budget
//! over any continuation; it never goes below the display minimum. A lowered maximum may make the shaped
//! set-point step down (the only case in which the set-point moves faster than the rate limit: the safe direction
//! wins). The dose can be saved and restored ([`SafetyEnvelope::dose_ledger`], [`SafetyEnvelope::restore_dose`]),
//! so that it survives a restart. Fault checks act on the **measured** display temperature; the drive limits act
//! on the measured display and, where a forecast is given, on the estimated true plate, which a lagging sensor
//! would otherwise hide.
//!
//! **Unseen time.** A reading that is not fresh (a link fault, a frozen or held reading with an old sample counter,
//! a non-finite or implausible one) is no measurement of the plate: it adds no dose itself. Once the newest counted
//! sample is older than `stale_timeout_s` (the envelope has then latched [`FaultCode::SensorStale`] and gates 0 A),
//! every tick ([`SafetyEnvelope::gate_drive`], [`SafetyEnvelope::hold`]) counts the time since the last counted
//! instant — from that sample on — at the hottest the plate may have been ([`SafetyEnvelope::unseen_plate_bound_c`]):
//! the last counted plate, raised by what the strongest heating current `I` gated since that sample could add
//! while it may still have been applied — the stale timeout, then up to [`UNSEEN_DRIVE_HOLD_S`] (0.25 s) of the
//! device's watchdog, as a device holds its last command — at `max_measured_rate_c_per_s` (50 °C/s, twice the
//! default display's full-current rate) times `I / current_limit_a` (a Peltier module's heating, `αIT + I²R/2`, is
//! at most that fraction of its full-current heating); at most [`ABSOLUTE_MAX_C`] + `limit_margin_c` (49 °C by
//! default: the over-temperature fault; the device's own cut keeps a plate thermode cannot see below it); and never
//! below the warmer of a finger ([`FINGER_MAX_C`], 37 °C) and the last hot-side reading, where a plate whose drive
//! does not heat tends to. On a hot touch (47 °C, 1 A) that is 49 °C; at rest (32 °C, 0.1 A) 37 °C. No cooling is
//! credited while nothing is seen. When samples come back, the rest of the interval counts at the hotter of that
//! bound and the new sample (never again at the held reading). So the count is never less than the plate's could
//! have been — until the budget is spent: from then on the channel is off for good (see "Over budget") and unseen
//! time adds nothing, so an outage of any length leaves the dose at most at the larger of what it was and the end
//! of the estimate's allowance, `B·(1 + 2.5 %)`, plus the stale timeout and one tick at the bound (the first count
//! takes the whole stale timeout at once: 0.21 s at 49 °C and 100 Hz, 0.224 CEM43-min). An outage during a
//! hot touch therefore usually spends the budget (14 s at 47 °C held used to count 3.7 CEM43-min and grow for as long
//! as the outage lasted).
//!
//! **Over budget.** Once the dose cap leaves no temperature above the display minimum (the estimate's allowance is
//! used up: [`SafetyEnvelope::dose_budget_spent`]), every drive is 0 A ([`DriveLimits::dose_budget_spent`]) whatever
//! is asked — not the display minimum at full cooling current, which chills a resting finger — until the ledger is
//! reset; the runtime refuses every stimulus but air (air is what an off channel does).
//!
//! Stuck drive: the time at the current limit counts only while the drive really is at its limit in one
//! direction and the plate does not answer (the measured display has not moved [`STUCK_PROGRESS_C`] in the
//! drive's direction since the count started); a change of sign, a drive below the limit, a hold or a fault
//! restarts it.

use crate::config::{EnvelopeConfig, ABSOLUTE_MAX_C, NEUTRAL_SETPOINT_C};
use crate::dose::{DoseCap, DoseLedger, DoseTracker, CEM43_REFERENCE_C};
use thermode_model::Rule;

use crate::error::EnvelopeError;
use crate::fault::FaultCode;
use crate::plate::{plate_margin_c, search_current_a, PlateForecast};

/// The warmest a finger on the plate is taken to be, °C: 37 (body core temperature). A plate whose drive does not
/// heat tends to no more than the warmer of its finger and its hot side; the bound on unseen time uses it
/// ([`SafetyEnvelope::unseen_plate_bound_c`]).
pub const FINGER_MAX_C: f64 = 37.0;

/// How long a device may go on applying the last current it was sent after thermode stops sending, s: 0.25 (the
/// longest watchdog the own protocol accepts, `thermode_link::own::MAX_DEVICE_WATCHDOG_MS`; MeCom and TCS II are
/// configured by thermode to no more). Added to the stale timeout for the heating a plate may have had unseen.
pub const UNSEEN_DRIVE_HOLD_S: f64 = 0.25;

/// Movement of the measured display in the drive's direction that shows the plate answers a drive at its limit,
/// °C: 0.5 (50 steps of the PT-100's resolution, well above its noise; a working module at full current moves
/// the plate several °C per second).
pub const STUCK_PROGRESS_C: f64 = 0.5;

/// One sample of a channel's sensors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// When the sample was taken, s (same clock as `now_s`).
    pub time_s: f64,
    /// Display (plate) sensor reading, °C.
    pub sensor_c: f64,
    /// Hot (reference) side reading, °C.
    pub hot_side_c: f64,
    /// Sample counter of the sensor; a sample is fresh when its counter exceeds the last one seen. Repeated
    /// samples are ignored (they neither refresh the stale timer nor add dose).
    pub sample_seq: u64,
}

/// Why a shaped set-point differs from the request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SetpointLimits {
    /// The request was above the effective maximum.
    pub clamped_high: bool,
    /// The request was below the minimum.
    pub clamped_low: bool,
    /// The rate limit held the set-point back.
    pub rate_limited: bool,
    /// The thermal-dose lockout lowers the maximum.
    pub dose_lockout: bool,
    /// The request (or the time) was not finite: the previous set-point is held and a fault latched.
    pub rejected: bool,
}

/// The set-point the controller shall follow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetpointDecision {
    /// Shaped display set-point, °C (always finite, within `[min, effective max]`).
    pub setpoint_c: f64,
    /// Rate of change of the shaped set-point since the previous call, °C/s (0 on the first call).
    pub rate_c_per_s: f64,
    /// Which limits acted.
    pub limited_by: SetpointLimits,
}

/// Why a gated current differs from the request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriveLimits {
    /// A fault is latched: the drive is off.
    pub faulted: bool,
    /// No measurement has been observed yet: the drive is off.
    pub no_measurement: bool,
    /// The request exceeded the current limit.
    pub clamped_to_limit: bool,
    /// Heating refused: the measured display is at/above the effective maximum.
    pub heating_blocked_at_max: bool,
    /// Cooling refused: the measured display is at/below the minimum.
    pub cooling_blocked_at_min: bool,
    /// Heating limited (or cooling imposed): the plate predicted at the end of the tick would pass the effective
    /// maximum less the estimate's margin.
    pub heating_limited_by_plate: bool,
    /// Cooling limited (or heating imposed): the plate predicted at the end of the tick would pass the minimum
    /// plus the estimate's margin.
    pub cooling_limited_by_plate: bool,
    /// The thermal-dose budget is spent ([`SafetyEnvelope::dose_budget_spent`]): the drive is off, whatever is
    /// asked.
    pub dose_budget_spent: bool,
}

/// A drive current that has passed the safety envelope. Obtainable only from [`SafetyEnvelope::gate_drive`].
#[must_use = "a gated drive command must be applied to the drive"]
#[derive(Debug, PartialEq)]
pub struct DriveCommand {
    current_a: f64,
    fault: Option<FaultCode>,
    limited_by: DriveLimits,
    setpoint_c: Option<f64>,
}

impl DriveCommand {
    /// 0 A: the one command that needs no envelope, because switching a drive off is always safe (a stop, a failed
    /// read, a shutdown). It carries no fault and no limits.
    pub fn off() -> Self {
        DriveCommand {
            current_a: 0.0,
            fault: None,
            limited_by: DriveLimits::default(),
            setpoint_c: None,
        }
    }

    /// The current to apply, A (positive heats the display; 0 when faulted).
    pub fn current_a(&self) -> f64 {
        self.current_a
    }

    /// The latched fault, if any (then `current_a() == 0`).
    pub fn fault(&self) -> Option<FaultCode> {
        self.fault
    }

    /// Which limits acted on this command.
    pub fn limited_by(&self) -> DriveLimits {
        self.limited_by
    }

    /// The envelope's shaped display set-point \[°C\] that this command serves, for a device that regulates its
    /// plate itself (a temperature-commanded display follows this instead of the current). `Some` only when the
    /// command passed the gate (no fault latched, a measurement observed) and the envelope shaped a set-point at the
    /// same time as the gate (`shape_setpoint` and `gate_drive` with one `now_s`); it then lies in `[min, effective
    /// max]` and moves no faster than the set-point rate limit. `None` for [`DriveCommand::off`], a hold, a fault or
    /// a gate without a set-point of that tick: such a command switches a temperature-commanded output off.
    pub fn setpoint_c(&self) -> Option<f64> {
        self.setpoint_c
    }

    /// This command for a device that regulates its plate on a sensor reading `gain · T + offset_c` \[°C\] at a
    /// true plate temperature T (a calibrated sensor: `thermode calibrate`), so that its own regulation brings the
    /// true plate to the envelope's set-point: the set-point on the reading's scale, the current, the fault and the
    /// limits unchanged. `None` when `gain` is not within 0.5 to 2 or `offset_c` not within ±10 °C (what a plate
    /// sensor can be off, the bounds of a device file's calibration).
    pub fn on_sensor_scale(&self, gain: f64, offset_c: f64) -> Option<DriveCommand> {
        if !((0.5..=2.0).contains(&gain) && (-10.0..=10.0).contains(&offset_c)) {
            return None;
        }
        Some(DriveCommand {
            current_a: self.current_a,
            fault: self.fault,
            limited_by: self.limited_by,
            setpoint_c: self.setpoint_c.map(|c| gain * c + offset_c),
        })
    }
}

/// A fault and when it latched.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Latch {
    code: FaultCode,
    time_s: f64,
    /// `sample_seq` of the newest valid sample when the fault latched (None: no sample yet).
    seq: Option<u64>,
}

/// The shaped set-point and when it was shaped.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Shaped {
    value_c: f64,
    time_s: f64,
}

/// The drive at its limit in one direction since `since_s`, with the measured display at `from_c` then.
#[derive(Debug, Clone, Copy, PartialEq)]
struct AtLimit {
    since_s: f64,
    heating: bool,
    from_c: f64,
}

/// The safety envelope of one channel. See the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct SafetyEnvelope {
    config: EnvelopeConfig,
    current_limit_a: f64,
    latch: Option<Latch>,
    /// Latest `now_s` seen by `shape_setpoint`/`gate_drive`.
    clock_s: Option<f64>,
    /// First `gate_drive` time: the stale timer runs from here until the first sample.
    armed_at_s: Option<f64>,
    shaped: Option<Shaped>,
    /// Newest fresh sample with finite values (may be implausible: then a fault is latched).
    sample: Option<Measurement>,
    /// Highest `sample_seq` seen (also of samples refused as non-finite).
    last_seq: Option<u64>,
    /// Reference sample (time, °C) of the measured-rate check.
    rate_ref: Option<(f64, f64)>,
    dose: DoseTracker,
    /// The dose ceiling of the last sample, and after the lockout the lowest since the last sample before it, °C
    /// (+∞ before the first sample): the ceiling's formula steps up by its look ahead as the lockout engages, and
    /// the maximum must not.
    lowest_dose_ceiling_c: f64,
    /// The dose cap's formula ceiling for the dose as it stands, °C ([`DoseCap::ceiling_c`]): renewed whenever the
    /// dose changes (a sample, unseen time, the lockout, a restore), read several times a tick.
    dose_formula_ceiling_c: f64,
    lockout_at_s: Option<f64>,
    at_48_since_s: Option<f64>,
    at_limit: Option<AtLimit>,
    /// The last gated drive, A: a device holds it until the next command or its watchdog.
    drive_a: f64,
    /// The strongest heating current gated (or held by the device) since the newest sample the dose counted, A
    /// (≥ 0).
    heating_since_sample_a: f64,
    /// While the reading is distrusted ([`SafetyEnvelope::distrust_reading`]): the plate the dose counts at, °C,
    /// renewed every tick by whoever models the plate ([`SafetyEnvelope::set_distrusted_plate_c`]).
    distrusted_plate_c: Option<f64>,
}

impl SafetyEnvelope {
    /// An envelope for one channel whose drive is limited to `±current_limit_a` (A, finite, > 0). The
    /// configuration is validated; anything outside the absolute limits is an error.
    pub fn new(config: EnvelopeConfig, current_limit_a: f64) -> Result<Self, EnvelopeError> {
        config.validate()?;
        Rule::Positive.check("current_limit_a", current_limit_a)?;
        let mut envelope = Self {
            config,
            current_limit_a,
            latch: None,
            clock_s: None,
            armed_at_s: None,
            shaped: None,
            sample: None,
            last_seq: None,
            rate_ref: None,
            dose: DoseTracker::with_sensor_lag(
                config.sensor_time_constant_s,
                config.rate_window_s,
                config.max_measured_rate_c_per_s,
            )
            .with_longest_interval_s(config.stale_timeout_s),
            lowest_dose_ceiling_c: f64::INFINITY,
            dose_formula_ceiling_c: f64::NAN,
            lockout_at_s: None,
            at_48_since_s: None,
            at_limit: None,
            drive_a: 0.0,
            heating_since_sample_a: 0.0,
            distrusted_plate_c: None,
        };
        envelope.dose_changed();
        Ok(envelope)
    }

    /// Renews the dose cap's formula ceiling after the dose changed.
    fn dose_changed(&mut self) {
        self.dose_formula_ceiling_c = self.dose_cap().ceiling_c(&self.dose);
    }

    /// The configuration in force.
    pub fn config(&self) -> &EnvelopeConfig {
        &self.config
    }

    /// The drive current limit, A.
    pub fn current_limit_a(&self) -> f64 {
        self.current_limit_a
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<FaultCode> {
        self.latch.map(|l| l.code)
    }

    /// When the latched fault latched, s.
    pub fn fault_time_s(&self) -> Option<f64> {
        self.latch.map(|l| l.time_s)
    }

    /// Accumulated thermal dose of this channel, CEM43-minutes.
    pub fn cem43_min(&self) -> f64 {
        self.dose.cem43_min()
    }

    /// Accumulated time with the display (reconstructed from the measurement) at or above 43 °C, s.
    pub fn time_at_or_above_43_s(&self) -> f64 {
        self.dose.time_at_or_above_43_s()
    }

    /// Whether the thermal-dose lockout is active (time at ≥ 43 °C or CEM43 budget used up, now or in a restored
    /// ledger). Once active it stays active for the envelope's life.
    pub fn dose_lockout_active(&self) -> bool {
        self.dose_cap().lockout_reached(&self.dose)
    }

    /// The channel's dose budget and its ceilings.
    fn dose_cap(&self) -> DoseCap {
        DoseCap {
            cem43_budget_min: self.config.cem43_budget_min,
            max_time_at_or_above_43_s: self.config.max_time_at_or_above_43_s,
            lockout_max_c: self.config.dose_lockout_max_c(),
        }
    }

    /// The dose to save: accumulated CEM43, time at or above 43 °C, and whether the lockout has engaged.
    pub fn dose_ledger(&self) -> DoseLedger {
        DoseLedger {
            lockout: self.dose_lockout_active(),
            ..self.dose.ledger()
        }
    }

    /// Restores a saved dose (call it before the first measurement): each total becomes the larger of the present
    /// and the saved one and a saved lockout stays engaged, so a restore never lowers the dose. A negative or
    /// non-finite total is refused ([`EnvelopeError::BadValue`]) and changes nothing.
    pub fn restore_dose(&mut self, saved: &DoseLedger) -> Result<(), EnvelopeError> {
        self.dose.restore(saved)?;
        if self.dose_lockout_active() {
            self.dose.lock();
        }
        self.dose_changed();
        Ok(())
    }

    /// The lowest display set-point, °C.
    pub fn min_c(&self) -> f64 {
        self.config.min_display_c
    }

    /// The highest display set-point now, °C: `max_display_c`, lowered by the dose cap near and after the end of the
    /// budget ([`crate::dose`], "The cap"; from the lockout on never raised again), never below `min_display_c`.
    pub fn effective_max_c(&self) -> f64 {
        let ceiling_c = self.dose_ceiling_c();
        let (min_c, max_c) = (self.config.min_display_c, self.config.max_display_c);
        // Written so that a NaN ceiling (none is expected) gives the minimum.
        if ceiling_c >= max_c {
            max_c
        } else if ceiling_c > min_c {
            ceiling_c
        } else {
            min_c
        }
    }

    /// The dose cap's ceiling, °C: the formula's, from the lockout on never raised again (NaN passes through).
    fn dose_ceiling_c(&self) -> f64 {
        let formula_c = self.dose_formula_ceiling_c;
        if formula_c.is_nan() {
            formula_c
        } else {
            formula_c.min(self.lowest_dose_ceiling_c)
        }
    }

    /// Whether the thermal-dose budget is spent: the dose cap leaves no temperature above the display minimum (the
    /// estimate's allowance is used up; module documentation, "Over budget"). The channel is then off: every drive
    /// is 0 A and the runtime refuses every stimulus but air, until the ledger is reset.
    pub fn dose_budget_spent(&self) -> bool {
        let ceiling_c = self.dose_ceiling_c();
        // A NaN ceiling (none is expected) counts as spent.
        ceiling_c.is_nan() || ceiling_c <= self.config.min_display_c
    }

    /// The hottest the plate may have been while no sample was counted (module documentation, "Unseen time"), °C:
    /// the last counted plate raised by the strongest heating current gated since, held for
    /// [`UNSEEN_DRIVE_HOLD_S`] beyond the stale timeout at the fastest rate a reading may move
    /// (`max_measured_rate_c_per_s`) in proportion to the current limit, at most [`ABSOLUTE_MAX_C`] +
    /// `limit_margin_c` (the over-temperature fault); and never below the warmer of a finger ([`FINGER_MAX_C`]) and
    /// the last hot-side reading (a plate whose drive does not heat tends to no more than they).
    pub fn unseen_plate_bound_c(&self) -> f64 {
        let c = &self.config;
        let last_c = self.dose.last_plate_c().unwrap_or(f64::NEG_INFINITY);
        let heating_s = c.stale_timeout_s + UNSEEN_DRIVE_HOLD_S;
        let rise_c = self.heating_since_sample_a / self.current_limit_a * c.max_measured_rate_c_per_s * heating_s;
        let heated_c = (last_c + rise_c).min(ABSOLUTE_MAX_C + c.limit_margin_c).max(last_c);
        let hot_side_c = self.sample.map_or(f64::NEG_INFINITY, |s| s.hot_side_c);
        heated_c.max(FINGER_MAX_C).max(hot_side_c)
    }

    /// Counts the dose of the time without a sample at time `now_s` (s), once the newest counted sample is older
    /// than the stale-sensor timeout: at [`SafetyEnvelope::unseen_plate_bound_c`] until the budget is spent, then
    /// nothing (the channel is off for good). While the reading is distrusted, every tick counts the time since the
    /// last counted instant at the distrusted plate instead ([`SafetyEnvelope::distrust_reading`]). The lockout
    /// engages as on a sample.
    fn count_unseen_dose(&mut self, now_s: f64) {
        let Some(last_s) = self.dose.last_sample_s() else {
            return;
        };
        if self.distrusted_plate_c.is_none() && now_s - last_s <= self.config.stale_timeout_s {
            return;
        }
        let worst_c = if self.dose_budget_spent() {
            f64::NEG_INFINITY
        } else {
            self.distrusted_plate_c.unwrap_or_else(|| self.unseen_plate_bound_c())
        };
        self.dose.count_unseen(now_s, worst_c);
        if self.dose_lockout_active() {
            self.dose.lock();
            self.lockout_at_s.get_or_insert(now_s);
        }
        self.dose_changed();
        self.lower_dose_ceiling();
    }

    /// The newest fresh measurement with finite values, if any.
    pub fn last_measurement(&self) -> Option<&Measurement> {
        self.sample.as_ref()
    }

    /// Latches `code` unless a fault is already latched (the first cause is kept).
    fn latch(&mut self, code: FaultCode, time_s: f64) {
        if self.latch.is_none() {
            let time_s = if time_s.is_finite() {
                time_s
            } else {
                self.clock_s.unwrap_or(0.0)
            };
            self.latch = Some(Latch {
                code,
                time_s,
                seq: self.sample.map(|s| s.sample_seq),
            });
        }
    }

    /// Advances the envelope clock to `now_s`; a non-finite or earlier time latches a fault and returns false.
    fn advance_clock(&mut self, now_s: f64) -> bool {
        if !now_s.is_finite() {
            self.latch(FaultCode::NonFiniteTime, now_s);
            return false;
        }
        if self.clock_s.is_some_and(|c| now_s < c) {
            self.latch(FaultCode::TimeNotMonotonic, now_s);
            return false;
        }
        self.clock_s = Some(now_s);
        true
    }

    /// Shapes a requested display set-point (°C) at time `now_s` (s): a non-finite request latches
    /// [`FaultCode::NonFiniteSetpoint`] and holds the previous set-point; a finite one is clamped into
    /// `[min, effective max]` and then rate limited to `max_setpoint_rate_c_per_s`. The first call starts from the
    /// measured display temperature (clamped into range) if one is known, so the set-point never jumps away from
    /// the plate.
    pub fn shape_setpoint(&mut self, now_s: f64, requested_c: f64) -> SetpointDecision {
        let mut limits = SetpointLimits {
            dose_lockout: self.dose_lockout_active(),
            ..Default::default()
        };
        let time_ok = self.advance_clock(now_s);
        let target_c = if time_ok {
            self.clamp_request(now_s, requested_c, &mut limits)
        } else {
            None
        };
        limits.rejected = target_c.is_none();
        let (min_c, max_c) = (self.min_c(), self.effective_max_c());
        let (shaped, rate_c_per_s) = match self.shaped {
            None => (self.anchor(now_s, time_ok, target_c, &mut limits), 0.0),
            Some(prev) if time_ok => self.rate_limit(prev, now_s, target_c.unwrap_or(prev.value_c), &mut limits),
            Some(prev) => (
                Shaped {
                    value_c: prev.value_c.clamp(min_c, max_c),
                    ..prev
                },
                0.0,
            ),
        };
        self.shaped = Some(shaped);
        SetpointDecision {
            setpoint_c: shaped.value_c,
            rate_c_per_s,
            limited_by: limits,
        }
    }

    /// A finite request clamped into `[min, effective max]` (flagged); a non-finite one latches a fault → `None`.
    fn clamp_request(&mut self, now_s: f64, requested_c: f64, limits: &mut SetpointLimits) -> Option<f64> {
        if !requested_c.is_finite() {
            self.latch(FaultCode::NonFiniteSetpoint, now_s);
            return None;
        }
        let (min_c, max_c) = (self.min_c(), self.effective_max_c());
        limits.clamped_high = requested_c > max_c;
        limits.clamped_low = requested_c < min_c;
        Some(requested_c.clamp(min_c, max_c))
    }

    /// The first set-point: the measured display (if a plausible sample exists), else the request, else the
    /// neutral 33 °C — clamped into range.
    fn anchor(&self, now_s: f64, time_ok: bool, target_c: Option<f64>, limits: &mut SetpointLimits) -> Shaped {
        let measured_c = self
            .sample
            .filter(|s| self.sensor_fault(s).is_none())
            .map(|s| s.sensor_c);
        let anchor_c = measured_c.or(target_c).unwrap_or(NEUTRAL_SETPOINT_C);
        let value_c = anchor_c.clamp(self.min_c(), self.effective_max_c());
        limits.rate_limited = target_c.is_some_and(|t| t != value_c);
        let time_s = if time_ok { now_s } else { self.clock_s.unwrap_or(0.0) };
        Shaped { value_c, time_s }
    }

    /// Moves from `prev` towards `target_c` by at most the rate limit, then clamps into `[min, effective max]`
    /// (a lowered maximum wins over the rate limit). Returns the new set-point and its rate, °C/s.
    fn rate_limit(&self, prev: Shaped, now_s: f64, target_c: f64, limits: &mut SetpointLimits) -> (Shaped, f64) {
        let dt_s = (now_s - prev.time_s).max(0.0);
        let max_step_c = self.config.max_setpoint_rate_c_per_s * dt_s;
        let step_c = (target_c - prev.value_c).clamp(-max_step_c, max_step_c);
        limits.rate_limited = step_c != target_c - prev.value_c;
        let value_c = (prev.value_c + step_c).clamp(self.min_c(), self.effective_max_c());
        let rate_c_per_s = if dt_s > 0.0 {
            (value_c - prev.value_c) / dt_s
        } else {
            0.0
        };
        (Shaped { value_c, time_s: now_s }, rate_c_per_s)
    }

    /// Checks a measurement: a repeated sample (counter not above the last) is ignored; a fresh one is checked for
    /// non-finite values, sensor open/short/out of range, hot-side faults, an implausible rate of change, the
    /// display beyond its limits, 48 °C sustained and the dose lockout, and its interval since the previous valid
    /// sample is added to the thermal dose. Any fault latches.
    pub fn observe(&mut self, m: &Measurement) {
        if self.last_seq.is_some_and(|seq| m.sample_seq <= seq) {
            return;
        }
        self.last_seq = Some(m.sample_seq);
        if !(m.time_s.is_finite() && m.sensor_c.is_finite() && m.hot_side_c.is_finite()) {
            self.latch(FaultCode::NonFiniteMeasurement, m.time_s);
            return;
        }
        if self.sample.is_some_and(|s| m.time_s < s.time_s) {
            self.latch(FaultCode::TimeNotMonotonic, m.time_s);
            return;
        }
        self.sample = Some(*m);
        if let Some(code) = self.sensor_fault(m) {
            self.latch(code, m.time_s);
            return;
        }
        if let Some(code) = self.hot_side_fault(m) {
            self.latch(code, m.time_s);
        }
        self.check_rate(m);
        if self.distrusted_plate_c.is_some() {
            // No measurement of the plate: the dose counts at the distrusted plate (count_unseen_dose).
            return;
        }
        self.dose.add_sample(m.time_s, m.sensor_c);
        self.dose_changed();
        self.heating_since_sample_a = self.drive_a.max(0.0);
        if let Some(code) = self.display_limit_fault(m) {
            self.latch(code, m.time_s);
        }
        self.check_sustained_48(m);
        self.check_dose_lockout(m);
        self.lower_dose_ceiling();
    }

    /// Keeps the dose ceiling of this sample, and after the lockout the lowest one since the last sample before it
    /// ([`SafetyEnvelope::effective_max_c`]). Before the lockout the ceiling may rise (its look ahead shrinks once
    /// the interval between samples is known); from the lockout on it only falls.
    fn lower_dose_ceiling(&mut self) {
        let ceiling_c = self.dose_formula_ceiling_c;
        if !self.dose_lockout_active() || ceiling_c < self.lowest_dose_ceiling_c {
            self.lowest_dose_ceiling_c = ceiling_c;
        }
    }

    /// Open, short or implausible display sensor reading.
    fn sensor_fault(&self, m: &Measurement) -> Option<FaultCode> {
        let c = &self.config;
        if m.sensor_c >= c.sensor_open_c {
            Some(FaultCode::SensorOpen)
        } else if m.sensor_c <= c.sensor_short_c {
            Some(FaultCode::SensorShort)
        } else if m.sensor_c < c.plausible_min_c || m.sensor_c > c.plausible_max_c {
            Some(FaultCode::SensorOutOfRange)
        } else {
            None
        }
    }

    /// Hot side over temperature (cooling failure) or implausibly low (sensor shorted).
    fn hot_side_fault(&self, m: &Measurement) -> Option<FaultCode> {
        if m.hot_side_c > self.config.hot_side_max_c {
            Some(FaultCode::HotSideOverTemperature)
        } else if m.hot_side_c < self.config.hot_side_min_c {
            Some(FaultCode::HotSideSensorImplausible)
        } else {
            None
        }
    }

    /// Measured display beyond the configured limits by more than the margin.
    fn display_limit_fault(&self, m: &Measurement) -> Option<FaultCode> {
        let c = &self.config;
        if m.sensor_c > c.max_display_c + c.limit_margin_c {
            Some(FaultCode::DisplayOverTemperature)
        } else if m.sensor_c < c.min_display_c - c.limit_margin_c {
            Some(FaultCode::DisplayUnderTemperature)
        } else {
            None
        }
    }

    /// Rate of change against a reference sample at least `rate_window_s` old (denominator at least the window).
    fn check_rate(&mut self, m: &Measurement) {
        let Some((t_ref, c_ref)) = self.rate_ref else {
            self.rate_ref = Some((m.time_s, m.sensor_c));
            return;
        };
        let span_s = m.time_s - t_ref;
        let rate = (m.sensor_c - c_ref).abs() / span_s.max(self.config.rate_window_s);
        if rate > self.config.max_measured_rate_c_per_s {
            self.latch(FaultCode::SensorRateImplausible, m.time_s);
        }
        if span_s >= self.config.rate_window_s {
            self.rate_ref = Some((m.time_s, m.sensor_c));
        }
    }

    /// Measured display at or above 48 °C continuously for longer than allowed.
    fn check_sustained_48(&mut self, m: &Measurement) {
        if m.sensor_c >= ABSOLUTE_MAX_C {
            let since = *self.at_48_since_s.get_or_insert(m.time_s);
            if m.time_s - since > self.config.max_time_at_or_above_48_s {
                self.latch(FaultCode::SustainedAtAbsoluteMax, m.time_s);
            }
        } else {
            self.at_48_since_s = None;
        }
    }

    /// After the dose lockout engaged (it is then held for good), readings at/above 43 °C past the grace period are
    /// a fault.
    fn check_dose_lockout(&mut self, m: &Measurement) {
        if !self.dose_lockout_active() {
            return;
        }
        self.dose.lock();
        self.dose_changed();
        let since = *self.lockout_at_s.get_or_insert(m.time_s);
        if m.sensor_c >= CEM43_REFERENCE_C && m.time_s - since > self.config.dose_lockout_grace_s {
            self.latch(FaultCode::DoseLockoutViolated, m.time_s);
        }
    }

    /// Stale sensor: no fresh sample for longer than the timeout (timed from the first `gate_drive` call until
    /// the first sample arrives).
    fn check_stale(&mut self, now_s: f64) {
        let since_s = match self.sample {
            Some(s) => Some(s.time_s),
            None => self.armed_at_s,
        };
        if since_s.is_some_and(|t| now_s - t > self.config.stale_timeout_s) {
            self.latch(FaultCode::SensorStale, now_s);
        }
    }

    /// Gates the controller's requested current (A, positive heats) at time `now_s` (s) into the current allowed,
    /// with `plate` the model of the plate over the tick ([`crate::plate::MeasuredOnly`] if there is none).
    /// Returns 0 A while a fault is latched (a non-finite request, a non-finite or backward time, a stale sensor
    /// or a drive stuck at its limit latch here) and before the first measurement. Otherwise the request is
    /// limited to `±current_limit_a`, heating is refused while the measured display is at/above the effective
    /// maximum and cooling while it is at/below the minimum, and the predicted plate is kept inside the limits less
    /// its margin (see the module documentation).
    pub fn gate_drive(&mut self, now_s: f64, requested_current_a: f64, plate: &dyn PlateForecast) -> DriveCommand {
        let mut limits = DriveLimits::default();
        if self.advance_clock(now_s) {
            self.armed_at_s.get_or_insert(now_s);
            if !requested_current_a.is_finite() {
                self.latch(FaultCode::NonFiniteCommand, now_s);
            }
            self.check_stale(now_s);
            self.count_unseen_dose(now_s);
        }
        if self.latch.is_some() {
            limits.faulted = true;
            return self.off(limits);
        }
        let Some(sample) = self.sample else {
            limits.no_measurement = true;
            return self.off(limits);
        };
        if self.dose_budget_spent() {
            limits.dose_budget_spent = true;
            return self.off(limits);
        }
        let limit_a = self.current_limit_a;
        let mut current_a = requested_current_a.clamp(-limit_a, limit_a);
        limits.clamped_to_limit = current_a != requested_current_a;
        if current_a > 0.0 && sample.sensor_c >= self.effective_max_c() {
            current_a = 0.0;
            limits.heating_blocked_at_max = true;
        }
        if current_a < 0.0 && sample.sensor_c <= self.min_c() {
            current_a = 0.0;
            limits.cooling_blocked_at_min = true;
        }
        current_a = self.bound_by_plate(current_a, plate, &mut limits);
        if self.stuck_at_limit(now_s, current_a, sample.sensor_c) {
            self.latch(FaultCode::DriveStuckAtLimit, now_s);
            limits.faulted = true;
            return self.off(limits);
        }
        let setpoint_c = self.shaped.filter(|s| s.time_s == now_s).map(|s| s.value_c);
        self.note_drive(current_a);
        DriveCommand {
            current_a,
            fault: None,
            limited_by: limits,
            setpoint_c,
        }
    }

    /// The current nearest to `current_a` \[A\] whose predicted plate stays within `[min + margin, effective max −
    /// margin]` (unchanged without an estimate, or when no current within the drive's range can keep it there).
    fn bound_by_plate(&self, current_a: f64, plate: &dyn PlateForecast, limits: &mut DriveLimits) -> f64 {
        let Some(now) = plate.now().filter(|p| p.plate_c.is_finite()) else {
            return current_a;
        };
        let margin_c = plate_margin_c(now.sd_c);
        let (floor_c, ceiling_c) = (self.min_c() + margin_c, self.effective_max_c() - margin_c);
        let strongest_cooling_a = plate.strongest_cooling_a().clamp(-self.current_limit_a, 0.0);
        let (lowest_c, highest_c) = plate.plate_after_range_c(current_a);
        if highest_c > ceiling_c && current_a > strongest_cooling_a {
            limits.heating_limited_by_plate = true;
            search_current_a(plate, strongest_cooling_a, current_a, ceiling_c, true)
        } else if lowest_c < floor_c && current_a < self.current_limit_a {
            limits.cooling_limited_by_plate = true;
            search_current_a(
                plate,
                current_a.max(strongest_cooling_a),
                self.current_limit_a,
                floor_c,
                false,
            )
        } else {
            current_a
        }
    }

    /// Tracks how long the drive has been at its limit in one direction without the plate answering; true once
    /// that exceeds `stuck_at_limit_s` (see the module documentation). `sensor_c` is the newest measured display.
    fn stuck_at_limit(&mut self, now_s: f64, current_a: f64, sensor_c: f64) -> bool {
        if current_a.abs() < self.config.stuck_current_fraction * self.current_limit_a {
            self.at_limit = None;
            return false;
        }
        let heating = current_a > 0.0;
        let restart = match self.at_limit {
            None => true,
            Some(at) if at.heating != heating => true,
            Some(at) => {
                let moved_c = if heating {
                    sensor_c - at.from_c
                } else {
                    at.from_c - sensor_c
                };
                moved_c >= STUCK_PROGRESS_C
            }
        };
        if restart {
            self.at_limit = Some(AtLimit {
                since_s: now_s,
                heating,
                from_c: sensor_c,
            });
        }
        self.at_limit
            .is_some_and(|at| now_s - at.since_s > self.config.stuck_at_limit_s)
    }

    /// A tick in which the channel is held off (stop all) at `now_s` \[s\]: the clock and the stale-sensor check
    /// advance, the stuck-drive count restarts, the shaped set-point is forgotten (the next one starts again from
    /// the measured display, as on a fresh channel), and the command is 0 A (carrying any latched fault).
    pub fn hold(&mut self, now_s: f64) -> DriveCommand {
        self.shaped = None;
        if self.advance_clock(now_s) {
            self.armed_at_s.get_or_insert(now_s);
            self.check_stale(now_s);
            self.count_unseen_dose(now_s);
        }
        self.off(DriveLimits {
            faulted: self.latch.is_some(),
            ..DriveLimits::default()
        })
    }

    /// A zero-current command carrying the latched fault (if any).
    fn off(&mut self, limits: DriveLimits) -> DriveCommand {
        self.at_limit = None;
        self.note_drive(0.0);
        DriveCommand {
            current_a: 0.0,
            fault: self.fault(),
            limited_by: limits,
            setpoint_c: None,
        }
    }

    /// Refuses the display at `now_s` \[s\]: its self-test found it unlike its device file
    /// ([`FaultCode::DisplayNotAsFiled`], latched unless a fault already is, and never cleared: only an envelope
    /// built for a file that describes the display drives it).
    pub fn refuse_display(&mut self, now_s: f64) {
        self.latch(FaultCode::DisplayNotAsFiled, now_s);
    }

    /// The reading no longer measures the plate: a model of the plate (the plate guard's innovation check) found
    /// it disagreeing under a drive since `since_s` \[s\], while the plate may have been as hot as `hottest_c`
    /// \[°C\] (the model's hottest over that stretch). Latches [`FaultCode::ReadingDisagreesWithModel`] at `now_s`
    /// \[s\] (never cleared: a sensor that lied once is not trusted again this session), counts the stretch from
    /// `since_s` once more at `hottest_c` (its readings were counted; the count errs high), and from now on counts
    /// the dose at the plate [`SafetyEnvelope::set_distrusted_plate_c`] gives each tick (starting at `hottest_c`),
    /// not at the readings. Non-finite arguments count the stretch at the over-temperature limit.
    pub fn distrust_reading(&mut self, now_s: f64, since_s: f64, hottest_c: f64) {
        self.latch(FaultCode::ReadingDisagreesWithModel, now_s);
        let over_c = ABSOLUTE_MAX_C + self.config.limit_margin_c;
        let hottest_c = if hottest_c.is_finite() { hottest_c } else { over_c };
        let counted_to_s = self.dose.counted_to_s();
        let stretch_s = counted_to_s - since_s;
        if stretch_s.is_finite() && stretch_s > 0.0 {
            self.dose.count_again(stretch_s, hottest_c);
        }
        self.distrusted_plate_c = Some(hottest_c);
        self.dose_changed();
        self.lower_dose_ceiling();
    }

    /// Latches [`FaultCode::EstimateImplausible`] at `now_s` \[s\] if `estimate_c` \[°C\] (a model's plate or finger
    /// temperature) is finite and outside the plausible band of readings (`[plausible_min_c, plausible_max_c]`).
    /// NaN (no estimate yet) passes. Cleared like the causes outside the measurement: it latches again at once if
    /// the estimate is still out.
    pub fn check_estimate(&mut self, now_s: f64, estimate_c: f64) {
        let c = &self.config;
        if estimate_c.is_finite() && !(c.plausible_min_c..=c.plausible_max_c).contains(&estimate_c) {
            self.latch(FaultCode::EstimateImplausible, now_s);
        }
    }

    /// The plate the dose counts at while the reading is distrusted, \[°C\] (renewed every tick; a non-finite
    /// value counts at the over-temperature limit). Does nothing while the reading is trusted.
    pub fn set_distrusted_plate_c(&mut self, plate_c: f64) {
        if let Some(distrusted_c) = &mut self.distrusted_plate_c {
            *distrusted_c = if plate_c.is_finite() {
                plate_c
            } else {
                ABSOLUTE_MAX_C + self.config.limit_margin_c
            };
        }
    }

    /// Whether the reading is distrusted ([`SafetyEnvelope::distrust_reading`]).
    pub fn reading_distrusted(&self) -> bool {
        self.distrusted_plate_c.is_some()
    }

    /// Holds the display off, unverified, at `now_s` \[s\]: its self-test could not judge it
    /// ([`FaultCode::SelfTestInconclusive`], latched unless a fault already is; [`SafetyEnvelope::clear_fault`]
    /// clears it like any fault, and the pipeline then tests the display again).
    pub fn hold_untested(&mut self, now_s: f64) {
        self.latch(FaultCode::SelfTestInconclusive, now_s);
    }

    /// Remembers the drive just gated (`current_a`, A), for the bound on unseen time.
    fn note_drive(&mut self, current_a: f64) {
        self.drive_a = current_a;
        self.heating_since_sample_a = self.heating_since_sample_a.max(current_a);
    }

    /// Clears the latched fault at time `now_s` (s). Returns the cleared fault (`None` if none was latched).
    /// Refused while no fresh measurement has arrived since the fault latched
    /// ([`EnvelopeError::NoFreshMeasurement`]) or while the newest measurement still shows a cause
    /// ([`EnvelopeError::FaultPersists`]). On success the timers of the time-based checks restart.
    pub fn clear_fault(&mut self, now_s: f64) -> Result<Option<FaultCode>, EnvelopeError> {
        let Some(latch) = self.latch else {
            return Ok(None);
        };
        if matches!(
            latch.code,
            FaultCode::DisplayNotAsFiled | FaultCode::ReadingDisagreesWithModel
        ) {
            return Err(EnvelopeError::FaultPersists(latch.code));
        }
        Rule::Finite.check("now_s", now_s)?;
        let fresh = self.sample.filter(|s| match latch.seq {
            None => true,
            Some(seq) => s.sample_seq > seq,
        });
        let Some(sample) = fresh else {
            return Err(EnvelopeError::NoFreshMeasurement(latch.code));
        };
        if let Some(cause) = self.persisting_cause(&sample, now_s) {
            return Err(EnvelopeError::FaultPersists(cause));
        }
        self.latch = None;
        self.rate_ref = Some((sample.time_s, sample.sensor_c));
        self.at_48_since_s = None;
        self.at_limit = None;
        self.clock_s = Some(self.clock_s.map_or(now_s, |c| c.max(now_s)));
        Ok(Some(latch.code))
    }

    /// A fault cause still visible in the newest measurement at time `now_s`.
    fn persisting_cause(&self, s: &Measurement, now_s: f64) -> Option<FaultCode> {
        let stale = now_s - s.time_s > self.config.stale_timeout_s;
        self.sensor_fault(s)
            .or_else(|| self.hot_side_fault(s))
            .or_else(|| self.display_limit_fault(s))
            .or_else(|| stale.then_some(FaultCode::SensorStale))
            .or_else(|| (s.sensor_c >= ABSOLUTE_MAX_C).then_some(FaultCode::SustainedAtAbsoluteMax))
            .or_else(|| {
                let hot_under_lockout = self.dose_lockout_active() && s.sensor_c >= CEM43_REFERENCE_C;
                hot_under_lockout.then_some(FaultCode::DoseLockoutViolated)
            })
    }
}
