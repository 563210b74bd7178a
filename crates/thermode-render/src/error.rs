//! Typed errors of the render crate: everything the pipeline refuses, and what only offline runs, summaries and the
//! tuner can refuse.

use thermode_control::ControlError;
use thermode_device::DeviceError;
use thermode_model::{BadValue, ParamError};
use thermode_pipeline::PipelineError;
use thermode_safety::EnvelopeError;
use thiserror::Error;

/// Why the render crate refused something.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RenderError {
    /// The pipeline refused its configuration or a stimulus, or a run setting is out of range.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
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
    /// Something that is not a single number was refused (an empty material list, …).
    #[error("{0}")]
    Invalid(String),
}

impl From<BadValue> for RenderError {
    /// A refused run setting: the pipeline's [`PipelineError::BadValue`].
    fn from(error: BadValue) -> Self {
        RenderError::Pipeline(PipelineError::BadValue(error))
    }
}
