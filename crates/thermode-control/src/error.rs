//! Typed errors of the control crate: bad controller/filter parameters or inputs ([`ControlError`]). Every name is
//! a `&'static str`, so no error allocates and errors may be returned on the per-tick path.

use thermode_model::BadValue;
use thiserror::Error;

/// Why a filter or controller refused its parameters or one tick's input. A refused tick leaves the state untouched.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ControlError {
    /// A parameter or input that is not finite or outside its range (the one [`BadValue`] of
    /// [`thermode_model::params`]).
    #[error(transparent)]
    BadValue(#[from] BadValue),
}
