//! thermode-procedures: the psychophysical procedures thermal labs run (issue 24), as pure state machines.
//!
//! Each procedure hands out one trial at a time as a small [`TrialPlan`] (baseline, target, rate, plateau, return,
//! pause; [`TrialPlan::segments`] turns it into a channel's program) and records the [`Response`] to it
//! ([`Procedure`]). Nothing here reads files, clocks or devices: the lab runner drives them.
//!
//! - [`limits`]: the method of limits, the DFNS thermal tests (CDT, WDT, TSL with PHS, CPT, HPT).
//! - [`levels`]: the method of levels (yes/no trapezoids, bisection).
//! - [`staircase`]: n-up/m-down staircases with PsychoPy's `StairHandler` rules.
//! - [`questplus`]: QUEST+ with the keys and arithmetic of the `questplus` Python package 2023.1.
//! - [`stimulus`]: the yes/no procedures' trapezoid.
//! - [`program`]: multi-zone programs (thermal grill, temporal summation, thermal icons).
//! - [`participant`]: the simulated participant on the skin model; [`skin_response`]: its analytic response to the
//!   plate, and the method of limits' analytic line.
//! - [`analysis`]: per-test thresholds, the DFNS log transform, z-scores against a reference table.
//! - [`experiment`]: the experiment files; [`error`]: the typed error.

pub mod analysis;
pub mod error;
pub mod experiment;
pub mod levels;
pub mod limits;
pub mod participant;
pub mod plan;
pub mod program;
pub mod questplus;
pub mod skin_response;
pub mod staircase;
pub mod stimulus;

pub use error::ProcedureError;
pub use experiment::{ProcedureFile, ProcedureKind};
pub use plan::{Direction, Procedure, Response, Segment, TrialPlan, Until};
