//! thermode-model: the science of a finger touching a material.
//!
//! Pure library: no I/O, no clock. Everything is SI inside (metres, kilograms, seconds, kelvin-sized degrees,
//! temperatures in °C); the paper's cgs-calorie units are converted once at the edges by [`units`].
//!
//! - [`materials`]: the built-in material library (the paper's Table 1 and common VR materials) and material files.
//! - [`skin`]: skin layer parameters (a default fingertip) and skin files.
//! - [`kron`]: the paper's three-layer skin model (Kron), backward Euler.
//! - [`inverse`]: the display inverse (paper eq. 7): the display set-point that makes a finger on the display follow
//!   a target skin temperature.
//! - [`fv`]: the finite-volume reference model of finger and object (beyond the paper).
//! - [`semi_infinite`]: the analytic model of two semi-infinite bodies (the paper's model (a)), with and without
//!   contact resistance.
//! - [`peltier`]: Peltier module physics (from datasheet values) and its inverse, for the plant and for feedforward.
//! - [`limits`]: the one physical range of every quantity a user, a file or a client can give (temperatures,
//!   material and skin properties, contact, durations, rates), each with the reason for its bounds.
//! - [`params`]: the one parameter vocabulary: [`params::Rule`], [`params::Range`] and [`params::BadValue`], and
//!   the one TOML table reader of parameter files, [`params::Table`].
//! - [`simulate`]: one complete contact simulation with any of the three models, as `thermode simulate` runs it.

pub mod error;
pub mod fv;
pub mod inverse;
pub mod kron;
pub mod limits;
pub mod materials;
pub mod numbers;
pub mod params;
pub mod peltier;
pub mod semi_infinite;
pub mod simulate;
pub mod skin;
pub mod units;

pub use error::ParamError;
pub use inverse::{DisplayInverse, PlateCoupled};
pub use kron::{KronEnvironment, KronModel};
pub use materials::Material;
pub use params::{BadValue, Range, Rule};
pub use skin::{Blood, Skin, SkinLayer};
