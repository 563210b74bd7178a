//! thermode-pipeline: one thermal display channel's hard-real-time tick, as the daemon runs it per channel and
//! offline rendering reuses it.
//!
//! - [`pipeline`]: [`ChannelPipeline`], one allocation-free tick that cannot panic: the renderer's target skin
//!   temperature → display inverse (paper eq. 7) → safety envelope → controller → safety envelope → drive, built
//!   from composable stages.
//! - [`renderer`]: the controller's finger model touching the virtual world, stepped live ([`RendererKind::Fv`],
//!   default, physics-true; [`RendererKind::Kron`], the paper's way).
//! - [`display`]: the display inverse over the finger model that matches the renderer.
//! - [`stimulus`]: [`Stimulus`] — air, a touch, or a direct display temperature — and its validation.
//! - [`controllers`]: `pid` (gains files; the tuned files of the shipped displays are embedded) and `model` (plant
//!   model from the device file).
//! - [`guard`]: [`guard::PlateGuard`], the safety envelope's own model of the plate on every channel: the estimate
//!   and one-tick forecast of the true plate that the envelope bounds.
//! - [`reading_check`]: the innovation check, whether the plate sensor still measures the plate under a drive.
//! - [`error`]: [`PipelineError`], refused parameters and stimuli.
//!
//! Temperatures in °C, currents in A (positive heats the display), times in s. Deterministic: nothing here draws a
//! random number.

pub mod controllers;
pub mod display;
pub mod error;
pub mod guard;
pub mod pipeline;
pub mod reading_check;
pub mod renderer;
pub mod self_test;
pub mod stimulus;

pub use controllers::{build_controller, gains_for_device, ControllerKind, GainsSource, ShippedDisplay};
pub use error::PipelineError;
pub use pipeline::{ChannelPipeline, PipelineConfig, SelfTestState, Telemetry};
pub use renderer::{RendererKind, LIGHT_TOUCH_RESISTANCE_M2K_W};
pub use stimulus::Stimulus;
