//! thermode-control: the controllers between the renderer's display set-point and the drive request of one thermal
//! display channel — filters, the paper's PID, observers and the model-based controller. Every request they make
//! passes the safety envelope of `thermode-safety` before it reaches a drive.
//!
//! Pure library: no I/O, no clock (time comes in as `now_s`/`dt_s`), no allocation on the per-tick path,
//! deterministic. Temperatures in °C, currents in A, times in s. **A positive current heats the display.**
//!
//! - [`filter`]: [`LowPass`], the first-order sensor filter with exact discretisation.
//! - [`pid`]: [`Pid`] and [`PidGains`] (gains files: [`PidGains::from_toml_str`]), the paper's controller
//!   structure: derivative on measurement, output limits, conditional-integration anti-windup, bumpless reset,
//!   P/I/D terms for logging.
//! - [`controller`]: the object-safe [`Controller`] trait with [`ControlInput`], and [`PidController`] (low-pass
//!   + PID, the paper's Figure 2). The model-based controller implements the same trait.
//! - [`model_controller`]: [`ModelController`] (`model`), thermode's own controller: a Kalman observer of the true
//!   plate ([`observer`]: [`PlateObserver`] on a [`PlantModel`] filled from the device file) and the plate's heat
//!   balance inverted through the Peltier equations, driving the most useful current when a set-point is
//!   infeasible, with nothing to wind up.
//! - [`module_fit`]: [`ModuleFit`], the live fit of the Peltier module to its terminal voltage that the model-based
//!   controller uses when the device reports one.
//! - [`linear`]: the small dense solves of the least-squares fits.
//! - [`error`]: [`ControlError`], refused parameters and inputs.
//!
//! One tick of a channel:
//! ```
//! use thermode_control::{ControlInput, Controller, PidController, PidGains};
//! use thermode_safety::{EnvelopeConfig, Measurement, MeasuredOnly, SafetyEnvelope};
//! let gains = PidGains { kp_a_per_c: 0.5, ki_a_per_c_s: 0.2, kd_a_s_per_c: 0.0, filter_cutoff_hz: 5.0,
//!     derivative_filter_s: None };
//! let mut controller = PidController::new(gains, 2.8)?;
//! let mut envelope = SafetyEnvelope::new(EnvelopeConfig::default(), 2.8)?;
//! let m = Measurement { time_s: 0.0, sensor_c: 32.0, hot_side_c: 24.0, sample_seq: 1 };
//! envelope.observe(&m);
//! let sp = envelope.shape_setpoint(0.0, 30.0);
//! let input = ControlInput { time_s: 0.0, dt_s: 1e-3, setpoint_c: sp.setpoint_c,
//!     setpoint_rate_c_per_s: sp.rate_c_per_s, sensor_c: m.sensor_c, hot_side_c: m.hot_side_c,
//!     applied_current_a: 0.0, finger_receptor_c: None, finger_conductance_w_k: 0.0,
//!     measured_current_a: f64::NAN, voltage_v: f64::NAN, fresh_sample: true };
//! let request_a = controller.update(&input).unwrap_or(f64::NAN);
//! let drive = envelope.gate_drive(0.0, request_a, &MeasuredOnly);
//! assert!(drive.current_a().abs() <= 2.8);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod controller;
pub mod error;
pub mod filter;
pub mod identify;
pub mod linear;
pub mod model_controller;
pub mod module_fit;
pub mod observer;
pub mod pid;

pub use controller::{ControlInput, Controller, PidController};
pub use error::ControlError;
pub use filter::LowPass;
pub use model_controller::{ModelController, ModelDesign, ModelTerms};
pub use module_fit::{ConductanceRule, ModuleFit};
pub use observer::{Finger, ObserverDesign, ObserverTick, PlantModel, PlateEstimate, PlateObserver};
pub use pid::{AntiWindup, Pid, PidGains, PidTerms};
