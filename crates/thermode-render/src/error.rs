//! Typed errors of the render crate: everything the pipeline refuses (a parameter, a controller or envelope setting,
//! the simulated display, a stimulus), and what only offline runs, summaries and the tuner can refuse.

use thermode_control::ControlError;
use thermode_device::DeviceError;
use thermode_model::{BadValue, ParamError};
use thermode_pipeline::PipelineError;
use thermode_safety::EnvelopeError;
use thiserror::Error;

/// Why the render crate refused something.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RenderError {
    /// A parameter, a controller or envelope setting, the simulated display or a stimulus was refused, or a run
    /// setting is out of range.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// Something that is not a single number was refused (an empty material list, …).
    #[error("{0}")]
    Invalid(String),
}

/// The pipeline's sources of errors convert through [`PipelineError`], so `?` works on each of them.
macro_rules! through_pipeline {
    ($($source:ty),*) => {$(
        impl From<$source> for RenderError {
            fn from(error: $source) -> Self {
                RenderError::Pipeline(PipelineError::from(error))
            }
        }
    )*};
}

through_pipeline!(BadValue, ParamError, ControlError, EnvelopeError, DeviceError);
