//! Fault codes of the safety envelope. Every fault switches its channel's drive off (0 A) and latches until
//! [`crate::SafetyEnvelope::clear_fault`] succeeds. Codes are stable: they appear in CSV logs and reports, so a
//! code is never reused for another meaning. Hundreds group the source: 1xx display sensor, 2xx temperatures and
//! thermal dose, 3xx drive, 4xx invalid numbers and time.

use std::fmt;

/// A latched safety fault. See [`crate::EnvelopeConfig`] for every threshold and its default.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FaultCode {
    /// Display sensor reads at or above `sensor_open_c` (an open PT-100 reads as a very high resistance).
    SensorOpen,
    /// Display sensor reads at or below `sensor_short_c` (a shorted PT-100 reads as ~0 Ω, about −242 °C).
    SensorShort,
    /// Display sensor reading outside the plausible band `[plausible_min_c, plausible_max_c]` but not open/short.
    SensorOutOfRange,
    /// No fresh display sample for longer than `stale_timeout_s`.
    SensorStale,
    /// The measured display temperature changes faster than `max_measured_rate_c_per_s`.
    SensorRateImplausible,
    /// The display's self-test found it unlike its device file beyond what the envelope allows for (a plate sensor
    /// slower, or a plate answering heat faster, than the file says): the channel is refused before any touch,
    /// and stays refused (only a device file that describes the display lifts it).
    DisplayNotAsFiled,
    /// The display reading disagrees with the plate guard's model of the plate under a drive (a reading frozen while
    /// its sample counter advances, a sensor that reads another plate): the reading is no measurement of the plate
    /// from the disagreement's start on, the dose is counted at the model's plate, and the channel stays off for
    /// the session (a sensor that lied once is not trusted again).
    ReadingDisagreesWithModel,
    /// The display's self-test could not judge it (samples missing or stale, the pulse not delivered, the host
    /// behind, the display not at rest, or a measurement too uncertain): the channel is held off, unverified, until
    /// the fault is cleared, which tests the display again.
    SelfTestInconclusive,
    /// Hot (reference) side above `hot_side_max_c`: the water cooling has failed.
    HotSideOverTemperature,
    /// Hot-side sensor below `hot_side_min_c` (shorted or implausible), so cooling failure could go unseen.
    HotSideSensorImplausible,
    /// Measured display above `max_display_c + limit_margin_c`.
    DisplayOverTemperature,
    /// Measured display below `min_display_c − limit_margin_c`.
    DisplayUnderTemperature,
    /// Measured display at or above the absolute maximum (48 °C) continuously for longer than
    /// `max_time_at_or_above_48_s`.
    SustainedAtAbsoluteMax,
    /// After the thermal-dose lockout (10 min at ≥ 43 °C, or the CEM43 budget), the measured display stayed at or
    /// above 43 °C for longer than `dose_lockout_grace_s`.
    DoseLockoutViolated,
    /// Drive current at or beyond `stuck_current_fraction` of its limit continuously for longer than
    /// `stuck_at_limit_s`.
    DriveStuckAtLimit,
    /// A requested display set-point is NaN or infinite.
    NonFiniteSetpoint,
    /// A measurement (time, display or hot-side temperature) is NaN or infinite.
    NonFiniteMeasurement,
    /// A requested drive current (controller output) is NaN or infinite, or the controller reported an error.
    NonFiniteCommand,
    /// A time passed to the envelope is NaN or infinite.
    NonFiniteTime,
    /// Time went backwards (a `now_s` or a sample time earlier than a previous one).
    TimeNotMonotonic,
    /// A model's estimate (the plate guard's plate, the finger model on the display) left the plausible band of the
    /// readings (`[plausible_min_c, plausible_max_c]`): the model no longer describes the display (a current it
    /// integrates never reaching the plate, a device file far off its display), so nothing built on it is driven.
    EstimateImplausible,
}

impl FaultCode {
    /// Every fault code, in code order.
    pub const ALL: [FaultCode; 21] = [
        FaultCode::SensorOpen,
        FaultCode::SensorShort,
        FaultCode::SensorOutOfRange,
        FaultCode::SensorStale,
        FaultCode::SensorRateImplausible,
        FaultCode::DisplayNotAsFiled,
        FaultCode::ReadingDisagreesWithModel,
        FaultCode::SelfTestInconclusive,
        FaultCode::HotSideOverTemperature,
        FaultCode::HotSideSensorImplausible,
        FaultCode::DisplayOverTemperature,
        FaultCode::DisplayUnderTemperature,
        FaultCode::SustainedAtAbsoluteMax,
        FaultCode::DoseLockoutViolated,
        FaultCode::DriveStuckAtLimit,
        FaultCode::NonFiniteSetpoint,
        FaultCode::NonFiniteMeasurement,
        FaultCode::NonFiniteCommand,
        FaultCode::NonFiniteTime,
        FaultCode::TimeNotMonotonic,
        FaultCode::EstimateImplausible,
    ];

    /// The stable numeric code.
    pub fn code(self) -> u16 {
        match self {
            FaultCode::SensorOpen => 101,
            FaultCode::SensorShort => 102,
            FaultCode::SensorOutOfRange => 103,
            FaultCode::SensorStale => 104,
            FaultCode::SensorRateImplausible => 105,
            FaultCode::DisplayNotAsFiled => 106,
            FaultCode::ReadingDisagreesWithModel => 107,
            FaultCode::SelfTestInconclusive => 108,
            FaultCode::HotSideOverTemperature => 201,
            FaultCode::HotSideSensorImplausible => 202,
            FaultCode::DisplayOverTemperature => 203,
            FaultCode::DisplayUnderTemperature => 204,
            FaultCode::SustainedAtAbsoluteMax => 205,
            FaultCode::DoseLockoutViolated => 206,
            FaultCode::DriveStuckAtLimit => 301,
            FaultCode::NonFiniteSetpoint => 401,
            FaultCode::NonFiniteMeasurement => 402,
            FaultCode::NonFiniteCommand => 403,
            FaultCode::NonFiniteTime => 404,
            FaultCode::TimeNotMonotonic => 405,
            FaultCode::EstimateImplausible => 406,
        }
    }

    /// The fault with numeric code `code`, if any.
    pub fn from_code(code: u16) -> Option<FaultCode> {
        FaultCode::ALL.into_iter().find(|f| f.code() == code)
    }

    /// A short lower-case description.
    pub fn description(self) -> &'static str {
        match self {
            FaultCode::SensorOpen => "display sensor open",
            FaultCode::SensorShort => "display sensor short",
            FaultCode::SensorOutOfRange => "display sensor out of plausible range",
            FaultCode::SensorStale => "display sensor stale",
            FaultCode::SensorRateImplausible => "display temperature changes implausibly fast",
            FaultCode::DisplayNotAsFiled => "display unlike its device file (self-test): refused",
            FaultCode::ReadingDisagreesWithModel => {
                "display reading disagrees with the plate model under a drive (frozen or lying sensor)"
            }
            FaultCode::SelfTestInconclusive => {
                "display self-test inconclusive: held off until clear_fault tests it again"
            }
            FaultCode::HotSideOverTemperature => "hot side over temperature (cooling failure)",
            FaultCode::HotSideSensorImplausible => "hot-side sensor implausible",
            FaultCode::DisplayOverTemperature => "display above its maximum",
            FaultCode::DisplayUnderTemperature => "display below its minimum",
            FaultCode::SustainedAtAbsoluteMax => "display sustained at or above 48 °C",
            FaultCode::DoseLockoutViolated => "display above 43 °C after the thermal-dose lockout",
            FaultCode::DriveStuckAtLimit => "drive stuck at its current limit",
            FaultCode::NonFiniteSetpoint => "set-point not finite",
            FaultCode::NonFiniteMeasurement => "measurement not finite",
            FaultCode::NonFiniteCommand => "drive request not finite",
            FaultCode::NonFiniteTime => "time not finite",
            FaultCode::TimeNotMonotonic => "time went backwards",
            FaultCode::EstimateImplausible => "a model's estimate of the plate or finger left the plausible band",
        }
    }
}

impl fmt::Display for FaultCode {
    /// `E<code> <description>`, e.g. `E101 display sensor open`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "E{} {}", self.code(), self.description())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_unique_and_round_trip() {
        for (i, a) in FaultCode::ALL.iter().enumerate() {
            assert_eq!(FaultCode::from_code(a.code()), Some(*a), "{a}");
            for b in &FaultCode::ALL[i + 1..] {
                assert_ne!(a.code(), b.code(), "{a} and {b} share a code");
            }
        }
        assert_eq!(FaultCode::from_code(0), None);
        assert_eq!(FaultCode::SensorOpen.to_string(), "E101 display sensor open");
    }
}
