//! Typed errors of the safety crate: bad envelope configurations and refused fault clearing ([`EnvelopeError`]).
//! Every name is a `&'static str`, so no variant allocates and errors may be returned on the per-tick path.

use thermode_model::BadValue;
use thiserror::Error;

use crate::fault::FaultCode;

/// Why an envelope configuration was refused, or why a latched fault may not be cleared yet.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EnvelopeError {
    /// A configuration value (or a time passed to the envelope) is not finite or lies outside the range the
    /// envelope accepts (wider than the compiled-in absolute limits, or physically meaningless). It is an error,
    /// never clamped.
    #[error(transparent)]
    BadValue(#[from] BadValue),
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
