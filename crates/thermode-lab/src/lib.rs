//! thermode-lab: material-identification experiments with a thermal display, and the paper's analysis of them.
//!
//! The founding paper (section 4) validates the display objectively, by comparing finger temperature curves for real
//! and simulated contact (Figure 3), and subjectively, by asking blindfolded participants to identify materials that
//! are either touched or rendered (Tables 2 and 3, a χ² test, the confusion correlation r = 0.90, Figure 4).
//!
//! - [`analysis`]: reads session CSVs (one row per trial, PsychoPy-like) and curve CSVs, computes every number of the
//!   paper's section 4 ([`analysis::analyze`], [`analysis::analyze_curves`]) and writes JSON, Markdown and HTML
//!   reports with figures ([`analysis::write_outputs`]).
//! - [`export`]: `lab export --bids`, the sessions and recordings as a BIDS data set.
//! - [`error`]: the typed error [`LabError`] shared by the lab's modules.
//! - [`design`]: experiment files (TOML); [`plan`]: the counterbalanced trial plan (Williams designs);
//!   [`session`]: durable session CSVs and sidecars; [`runner`]: the trial runner and its stimulus, clock, console
//!   and responder seams; [`participant`]: the nearest-reference simulated participant;
//!   [`perception`]: the perceptual simulated participant `lab run` uses (issue 28); [`random`]: the per-trial random streams.
//! - [`procedure`]: psychophysical procedures (method of limits, levels, staircases, QUEST+, multi-zone programs)
//!   run as programs on a display, their session files and their analysis.

pub mod analysis;
pub mod design;
pub mod error;
pub mod export;
pub mod participant;
pub mod perception;
pub mod plan;
pub mod procedure;
pub mod random;
pub mod runner;
pub mod session;
pub mod validation;

pub use error::LabError;
