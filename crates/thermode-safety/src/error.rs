//! Typed errors of the safety crate: bad envelope configurations and refused fault clearing ([`EnvelopeError`]).
//! No variant allocates, so errors may be returned on the per-tick path.

use thiserror::Error;

use crate::fault::FaultCode;

/// Why an envelope configuration was refused, or why a latched fault may not be cleared yet.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum EnvelopeError {
    /// A configuration value (or a time passed to the envelope) is NaN or infinite.
    #[error("`{field}` must be finite, got {value}")]
    NotFinite {
        /// Name of the field.
        field: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A configuration value lies outside the range the envelope accepts (wider than the compiled-in absolute
    /// limits, or physically meaningless). It is an error, never clamped.
    #[error("`{field}` = {value} is outside the allowed range [{min}, {max}]")]
    OutOfRange {
        /// Name of the field.
        field: &'static str,
        /// The offending value.
        value: f64,
        /// Smallest allowed value (inclusive).
        min: f64,
        /// Largest allowed value (inclusive).
        max: f64,
    },
    /// Two configuration values contradict each other.
    #[error("inconsistent envelope configuration: {requirement}")]
    Inconsistent {
        /// The relation that does not hold.
        requirement: &'static str,
    },
    /// `clear_fault` refused: the cause of the latched fault is still present in the newest measurement.
    #[error("cannot clear fault {0}: its cause persists")]
    FaultPersists(FaultCode),
    /// `clear_fault` refused: no fresh sensor sample has arrived since the fault latched, so the cause cannot be
    /// re-checked.
    #[error("cannot clear fault {0}: no fresh measurement since it latched")]
    NoFreshMeasurement(FaultCode),
}
