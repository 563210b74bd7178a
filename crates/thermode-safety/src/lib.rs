//! thermode-safety: the one safety envelope every drive command of a thermal display channel passes.
//!
//! Pure library: no I/O, no clock (time comes in as `now_s`), no allocation on the per-tick path, deterministic.
//! Temperatures in °C, currents in A, times in s. **A positive current heats the display.**
//!
//! - [`envelope`]: [`SafetyEnvelope`]: set-point clamp and rate limit, thermal dose (IEC 60601-1 contact-time
//!   limits, CEM43), fault detection with latching. [`Measurement`] goes in, a [`DriveCommand`] comes out: the only
//!   ways to one are [`SafetyEnvelope::gate_drive`] and [`DriveCommand::off`].
//! - [`config`]: [`EnvelopeConfig`] (documented defaults and sources, read with `thermode_model::params::Table`) and the compiled-in absolute limits.
//! - [`fault`]: [`FaultCode`], stable numeric fault codes.
//! - [`dose`]: CEM43 and time-at-43 °C bookkeeping at the reconstructed plate temperature, the dose cap (the
//!   ceiling that keeps the total within 5 % of the budget over any continuation) and the [`DoseLedger`] that is
//!   saved and restored across restarts.
//! - [`plate`]: [`PlateForecast`], what a model of the plate tells the envelope so that it bounds the true plate.
//! - [`error`]: [`EnvelopeError`], refused configurations and refused fault clearing.
//!
//! One tick of a channel (the controller in the middle is any of `thermode-control`'s):
//! ```
//! use thermode_safety::{EnvelopeConfig, MeasuredOnly, Measurement, SafetyEnvelope};
//! let mut envelope = SafetyEnvelope::new(EnvelopeConfig::default(), 2.8)?;
//! let m = Measurement { time_s: 0.0, sensor_c: 32.0, hot_side_c: 24.0, sample_seq: 1 };
//! envelope.observe(&m);
//! envelope.shape_setpoint(0.0, 30.0); // the first call starts at the measured 32 °C
//! let shaped = envelope.shape_setpoint(0.1, 30.0); // then falls at the rate limit
//! let request_a = 0.5 * (shaped.setpoint_c - m.sensor_c); // a proportional controller
//! let drive = envelope.gate_drive(0.1, request_a, &MeasuredOnly); // no plate model in this example
//! assert!(drive.current_a() < 0.0 && drive.current_a().abs() <= 2.8);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod config;
pub mod dose;
pub mod envelope;
pub mod error;
pub mod fault;
pub mod plate;

pub use config::{EnvelopeConfig, ABSOLUTE_MAX_C, ABSOLUTE_MAX_RATE_C_PER_S, ABSOLUTE_MIN_C};
pub use dose::{DoseCap, DoseLedger, DoseTracker};
pub use envelope::{
    DriveCommand, DriveLimits, Measurement, SafetyEnvelope, SetpointDecision, SetpointLimits, FINGER_MAX_C,
    UNSEEN_DRIVE_HOLD_S,
};
pub use error::EnvelopeError;
pub use fault::FaultCode;
pub use plate::{MeasuredOnly, PlateForecast, PlateNow};
