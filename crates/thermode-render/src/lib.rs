//! thermode-render: the display pipeline of one thermal display channel and everything around it that runs without
//! hardware.
//!
//! - [`pipeline`]: [`ChannelPipeline`], one allocation-free tick that cannot panic: the renderer's target skin
//!   temperature → display inverse (paper eq. 7) → safety envelope → controller → safety envelope → drive. The
//!   runtime reuses it per channel.
//! - [`renderer`]: the controller's finger model touching the virtual world, stepped live ([`RendererKind::Fv`],
//!   default, physics-true; [`RendererKind::Kron`], the paper's way).
//! - [`display`]: the display inverse over the finger model that matches the renderer.
//! - [`stimulus`]: [`Stimulus`] — air, a touch, or a direct display temperature — and its validation.
//! - [`controllers`]: `pid` (gains files; the tuned files of the shipped displays are embedded) and `model` (plant
//!   model from the device file).
//! - [`run`]: offline rendering against the simulated display with the ground truth, as `thermode render` runs it.
//! - [`summary`]: the metrics of the paper's Figure 3 and its two flaws (RMS errors, overshoot, lag at half drop next
//!   to the actuator limit).
//! - [`tune`]: the PID tuner behind `thermode tune` (Nelder–Mead in log-gain space, materials in parallel).
//! - [`figure`]: the paper's Figure 3 for the simulated system.
//!
//! Temperatures in °C, currents in A (positive heats the display), times in s. Deterministic: the only randomness
//! is the simulated sensor noise, seeded explicitly.

pub mod controllers;
pub mod display;
pub mod error;
pub mod figure;
pub mod nelder_mead;
pub mod pipeline;
pub mod renderer;
pub mod run;
pub mod stimulus;
pub mod summary;
pub mod tune;

pub use controllers::{build_controller, gains_for_device, ControllerKind, GainsSource, ShippedDisplay};
pub use error::RenderError;
pub use pipeline::{ChannelPipeline, PipelineConfig, Telemetry};
pub use renderer::{RendererKind, LIGHT_TOUCH_RESISTANCE_M2K_W};
pub use run::{render, RenderRun, RenderSpec, Trajectory};
pub use stimulus::Stimulus;
pub use summary::Summary;
