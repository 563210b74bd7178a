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
    /// The runs' results would not fit in the memory one command may use
    /// ([`thermode_model::limits::MAX_RESULT_BYTES`]); refused before anything is allocated.
    #[error("{0}: use a lower tick rate, a shorter duration or fewer runs")]
    TooLarge(String),
    /// A run produced a number that is not finite (NaN or ±∞); its results are refused, never written.
    #[error("{material} ({controller}): the result is not finite: `{quantity}` = {value} at t = {time_s} s")]
    NonFinite {
        /// The rendered material.
        material: String,
        /// The controller.
        controller: String,
        /// The quantity (its CSV column).
        quantity: &'static str,
        /// The value.
        value: f64,
        /// When (time since the touch) \[s\].
        time_s: f64,
    },
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
