//! thermode-render: offline rendering of a thermal display, against the simulated hardware and the ground truth.
//!
//! - [`run`]: offline rendering of `thermode-pipeline`'s channel pipeline against the simulated display with the
//!   ground truth (the finger touching the real material), as `thermode render` runs it.
//! - [`spec`]: what one render is ([`RenderSpec`]: settings, defaults, ranges, result memory).
//! - [`trajectory`]: what one render records ([`Trajectory`]) and the simulated display it runs on.
//! - [`summary`]: the metrics of the paper's Figure 3 and its two flaws (RMS errors, overshoot, lag at half drop next
//!   to the actuator limit).
//! - [`tune`]: the PID tuner behind `thermode tune` (Nelder–Mead in log-gain space, materials in parallel), composed
//!   of the pipeline's stages.
//! - [`truth`]: the ground truth of a render, converged in grid and time.
//! - [`figure`]: the paper's Figure 3 for the simulated system.
//! - [`identify`]: `thermode identify` on the simulated display (excitation, record, fit, device file).
//! - [`error`]: [`RenderError`], refused runs and settings.
//!
//! Temperatures in °C, currents in A (positive heats the display), times in s. Deterministic: the only randomness
//! is the simulated sensor noise, seeded explicitly.

pub mod error;
pub mod figure;
pub mod identify;
pub mod identify_steps;
pub mod nelder_mead;
pub mod run;
pub mod self_test;
pub mod spec;
pub mod summary;
pub mod trajectory;
pub mod truth;
pub mod tune;

pub use error::RenderError;
pub use run::{render, RenderRun, RenderSpec, Trajectory};
pub use summary::RenderSummary;
