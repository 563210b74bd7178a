//! The limits a channel enforces on a stimulus, from one source: the object-temperature range of the pipeline's
//! [`Stimulus`] ([`OBJECT_TEMPERATURE`]) and the display range and set-point rate limit of the safety
//! envelope the channel really runs ([`StimulusLimits::of_envelope`]). Every engine reports its limits
//! ([`crate::ChannelEngine::limits`]); the control loop checks every stimulus against its channel's limits before the
//! engine sees it, the API checks it against the limits of all channels together before it is queued (so a refusal
//! has a reply), and `/api/status` publishes those same limits. [`StimulusLimits::check`] is the one validation, and
//! [`EngineError`] what an engine (or the loop on its behalf) refuses.

use thermode_model::params::{BadValue, Range, Rule};
use thermode_pipeline::stimulus::{DIRECT_RATE, DIRECT_TEMPERATURE, OBJECT_TEMPERATURE};
use thermode_pipeline::PipelineError;
use thermode_pipeline::Stimulus;
use thermode_safety::{EnvelopeConfig, EnvelopeError};
use thiserror::Error;

/// Why an engine (or the loop on its behalf) refused a stimulus, a fault clearing or its own construction.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EngineError {
    /// A number outside the channel's limits ([`StimulusLimits`]) or an engine parameter out of range.
    #[error(transparent)]
    BadValue(#[from] BadValue),
    /// The render pipeline refused (a stimulus's material, its configuration, or clearing a fault).
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// The safety envelope refused (clearing a fault whose cause persists, or its configuration).
    #[error(transparent)]
    Envelope(#[from] EnvelopeError),
    /// The engine failed (panicked) earlier or while handling this request; the channel is off for the session.
    #[error("the channel's engine failed; restart the daemon")]
    Failed,
}

/// What a channel accepts as a stimulus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StimulusLimits {
    /// Object temperatures a touch may name \[°C\] ([`OBJECT_TEMPERATURE`]).
    pub object_c: Range,
    /// Display temperatures a direct set-point may name \[°C\]: the envelope's `min_display_c..=max_display_c`.
    pub display_c: Range,
    /// Fastest direct-mode ramp \[°C/s\]: the envelope's `max_setpoint_rate_c_per_s`, the rate the channel really
    /// enforces (for a rendering pipeline the device file's `render.max_setpoint_rate_c_per_s`). Every rate must
    /// also be at least the smallest set-point rate ([`DIRECT_RATE`]).
    pub max_rate_c_per_s: f64,
}

impl StimulusLimits {
    /// The limits of a channel whose safety envelope runs `envelope`.
    pub fn of_envelope(envelope: &EnvelopeConfig) -> Self {
        StimulusLimits {
            object_c: OBJECT_TEMPERATURE,
            display_c: Range {
                name: DIRECT_TEMPERATURE.name,
                min: envelope.min_display_c,
                max: envelope.max_display_c,
            },
            max_rate_c_per_s: envelope.max_setpoint_rate_c_per_s,
        }
    }

    /// The widest limits any envelope may have (the compiled-in absolute limits of `thermode_safety`).
    pub fn absolute() -> Self {
        StimulusLimits {
            object_c: OBJECT_TEMPERATURE,
            display_c: DIRECT_TEMPERATURE,
            max_rate_c_per_s: DIRECT_RATE.max,
        }
    }

    /// What both `self` and `other` accept (the limits of several channels together).
    pub fn intersection(&self, other: &StimulusLimits) -> StimulusLimits {
        let both = |a: Range, b: Range| Range {
            name: a.name,
            min: a.min.max(b.min),
            max: a.max.min(b.max),
        };
        StimulusLimits {
            object_c: both(self.object_c, other.object_c),
            display_c: both(self.display_c, other.display_c),
            max_rate_c_per_s: self.max_rate_c_per_s.min(other.max_rate_c_per_s),
        }
    }

    /// Checks `stimulus` against these limits, then the pipeline's own checks ([`Stimulus::validate`]: the
    /// material). A refused number is an [`EngineError::BadValue`]; a refused material an [`EngineError::Pipeline`].
    pub fn check(&self, stimulus: &Stimulus) -> Result<(), EngineError> {
        match stimulus {
            Stimulus::Air => {}
            Stimulus::Touch { object_c, .. } => {
                self.object_c.check(*object_c)?;
            }
            Stimulus::Direct { temp_c, rate_c_per_s } => {
                self.display_c.check(*temp_c)?;
                self.rate_c_per_s(*rate_c_per_s)?;
            }
        }
        stimulus.validate()?;
        Ok(())
    }

    /// A direct-mode rate: in the physical range of set-point rates ([`DIRECT_RATE`]), at most
    /// [`StimulusLimits::max_rate_c_s`].
    fn rate_c_per_s(&self, rate_c_per_s: f64) -> Result<f64, BadValue> {
        Rule::Within {
            min: DIRECT_RATE.min,
            max: self.max_rate_c_per_s,
        }
        .check(DIRECT_RATE.name, rate_c_per_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_follow_the_envelope_and_refuse_with_a_typed_bad_value() {
        let envelope = EnvelopeConfig {
            min_display_c: 18.0,
            max_display_c: 44.0,
            max_setpoint_rate_c_per_s: 7.0,
            ..EnvelopeConfig::default()
        };
        let limits = StimulusLimits::of_envelope(&envelope);
        let direct = |temp_c, rate_c_per_s| Stimulus::Direct { temp_c, rate_c_per_s };
        assert_eq!(limits.check(&direct(18.0, 7.0)), Ok(()));
        for (t, r) in [(17.9, 1.0), (44.1, 1.0), (30.0, 7.1), (30.0, 0.0), (f64::NAN, 1.0)] {
            assert!(
                matches!(limits.check(&direct(t, r)), Err(EngineError::BadValue(_))),
                "{t} °C at {r} °C/s"
            );
        }
        let both = limits.intersection(&StimulusLimits::absolute());
        assert_eq!(both, limits);
        let wood = thermode_model::materials::find("wood").unwrap_or_else(|e| panic!("{e}"));
        let touch = |object_c| Stimulus::Touch {
            material: wood.clone(),
            object_c,
        };
        assert_eq!(limits.check(&touch(OBJECT_TEMPERATURE.min)), Ok(()));
        assert!(limits.check(&touch(OBJECT_TEMPERATURE.max + 1.0)).is_err());
    }
}
