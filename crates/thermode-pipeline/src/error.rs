//! Typed errors of the pipeline crate: refused parameters (skin, material, device, controller, envelope), refused
//! stimuli and gains files. Nothing on the per-tick path returns an error: a tick cannot fail (a
//! broken input latches a fault in the safety envelope instead).

use thermode_control::ControlError;
use thermode_device::DeviceError;
use thermode_model::{BadValue, ParamError};
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
    #[error(transparent)]
    BadValue(#[from] BadValue),
    /// A stimulus other than air during the display's start-up self-test (see
    /// [`crate::PipelineConfig::self_test_at_start`]).
    #[error(
        "the display's start-up self-test is under way (seconds, with no finger on the display): only air until it ends"
    )]
    SelfTestRunning,
}
