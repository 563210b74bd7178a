//! Typed errors of the pipeline crate: refused parameters (skin, material, device, controller, envelope), refused
//! stimuli and gains files. Nothing on the per-tick path returns an error: a tick cannot fail (a
//! broken input latches a fault in the safety envelope instead).

use thermode_control::ControlError;
use thermode_device::DeviceError;
use thermode_model::ParamError;
use thermode_safety::EnvelopeError;
use thiserror::Error;

/// Why the pipeline crate refused something.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PipelineError {
    /// A model parameter (skin, material, grid, contact) was refused.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// A controller parameter (gains, limits) was refused.
    #[error("controller: {0}")]
    Control(#[from] ControlError),
    /// The safety-envelope configuration was refused.
    #[error("safety envelope: {0}")]
    Envelope(#[from] EnvelopeError),
    /// The simulated display refused a parameter.
    #[error("simulated display: {0}")]
    Device(#[from] DeviceError),
    /// A number (stimulus, pipeline or run setting) that must be finite and in a range is not.
    #[error("{what} = {value} is invalid: {requirement}")]
    BadValue {
        /// What the number is, with its unit.
        what: String,
        /// The offending value.
        value: f64,
        /// What it must satisfy.
        requirement: String,
    },
    /// A gains file could not be read.
    #[error("{origin}: {message}")]
    GainsFile {
        /// Where the text came from (file name, or "built-in").
        origin: String,
        /// What was wrong.
        message: String,
    },
}

/// `Ok(value)` if `value` is finite and within `[min, max]`, else [`PipelineError::BadValue`] naming `what`.
pub fn require_in(what: &str, value: f64, min: f64, max: f64) -> Result<f64, PipelineError> {
    if value.is_finite() && value >= min && value <= max {
        Ok(value)
    } else {
        Err(PipelineError::BadValue {
            what: what.to_string(),
            value,
            requirement: format!("must be a finite number in [{min}, {max}]"),
        })
    }
}

/// `Ok(value)` if `value` is finite and strictly positive, else [`PipelineError::BadValue`] naming `what`.
pub fn require_positive(what: &str, value: f64) -> Result<f64, PipelineError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(PipelineError::BadValue {
            what: what.to_string(),
            value,
            requirement: "must be a finite number greater than zero".to_string(),
        })
    }
}
