//! Typed errors of the control crate: bad controller/filter parameters or inputs ([`ControlError`]). No variant
//! allocates, so errors may be returned on the per-tick path.

use thiserror::Error;

/// Why a filter or controller refused its parameters or one tick's input. A refused tick leaves the state untouched.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum ControlError {
    /// A parameter or input that must be a finite number is NaN or infinite.
    #[error("`{name}` must be finite, got {value}")]
    NotFinite {
        /// Name of the parameter or input.
        name: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A parameter or input is outside its allowed range.
    #[error("`{name}` = {value} is invalid: {requirement}")]
    OutOfRange {
        /// Name of the parameter or input.
        name: &'static str,
        /// The offending value.
        value: f64,
        /// What the value must satisfy.
        requirement: &'static str,
    },
}
