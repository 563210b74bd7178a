//! thermode-device: the hardware boundary and the simulated thermal display (the embedded default device).
//!
//! - [`Device`]: the small trait every display implements (apply a gated `DriveCommand`, read the sensors, do its
//!   per-tick work at the loop's time); [`SimulatedDisplay`] (up to [`MAX_CHANNELS`] channels) and [`RecordingDevice`] (records
//!   every command); [`CompositeDevice`]: one display made of several devices ([`DevicePart`] each).
//! - [`SimulatedChannel`]: one channel's physics (`model.md` §5): a Peltier module from datasheet values
//!   ([`thermode_model::peltier`]), the display plate, the hot side on the water-cooled aluminium box, the PT-100
//!   ([`Pt100`]: lag, noise, 0.01 °C resolution, sampling), a bipolar current drive with a limit, and a finger resting
//!   on the plate (any [`PlateFinger`]: the finite-volume finger by default, or the paper's Kron model), plus fault
//!   injection ([`Fault`]).
//! - [`DeviceConfig`]: the device file (TOML); every key optional, documented with unit, default and source. The
//!   files in `devices/` are the default display, a weakly cooled one and one with a lagging sensor.
//!
//! Real displays connect through `thermode-link` (wire protocols, serial hosts, emulators), which implements
//! [`Device`] for each; their failures are typed here ([`LinkError`], carried by [`DeviceError::Link`]) and their
//! reconnections counted in [`LinkHealth`].
//!
//! Temperatures in °C at the interfaces, currents in A (**positive current heats the display**), times in s.
//! Deterministic: the only randomness is the sensor noise, from ChaCha8 with an explicit seed.
//!
//! One second of one channel, every drive through the safety envelope:
//! ```
//! use thermode_safety::{EnvelopeConfig, MeasuredOnly, SafetyEnvelope};
//! use thermode_device::{Device, DeviceConfig, SimulatedDisplay};
//! use thermode_model::kron::KronModel;
//!
//! let config = DeviceConfig::from_toml_str("[sensor]\ntime_constant_s = 1.5", "lagging.toml")?;
//! let mut display = SimulatedDisplay::<KronModel>::fingertips(&config, 1, 42)?;
//! let mut envelope = SafetyEnvelope::new(EnvelopeConfig::default(), config.drive.current_limit_a)?;
//! for n in 0..1000 {
//!     let reading = display.read(0)?;
//!     envelope.observe(&reading.measurement());
//!     let command = envelope.gate_drive(n as f64 * 1e-3, 1.0, &MeasuredOnly); // ask for 1 A of heating
//!     display.apply(0, &command)?;
//!     display.poll((n + 1) as f64 * 1e-3);
//! }
//! let state = display.channel(0)?.state();
//! assert!(state.plate_c > 23.0 && state.applied_current_a == 1.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod calibrated;
pub mod channel;
pub mod composite;
pub mod config;
pub mod device;
pub mod error;
pub mod finger;
pub mod link;
pub mod link_error;
pub mod reading;
pub mod sensor;

pub use calibrated::CalibratedDevice;
pub use channel::{ChannelState, Fault, HeatFlows, Polarity, SimulatedChannel, MAX_SUBSTEP_S};
pub use composite::CompositeDevice;
pub use config::DeviceConfig;
pub use device::{
    Device, DevicePart, Measures, Reading, RecordedCommand, RecordingDevice, SimulatedDisplay, MAX_CHANNELS,
};
pub use error::{CalibrationRefusal, DeviceCut, DeviceError};
pub use finger::{default_finger, DefaultFinger, NoFinger, PlateFinger};
pub use link::LinkHealth;
pub use link_error::{
    Awaited, DownReason, LinkError, LinkFault, MecomSetup, OpenStep, OsError, RequestFault, Silence, SpecFault,
};
pub use sensor::{Pt100, SensorCondition, SensorSample, SENSOR_OPEN_READING_C, SENSOR_SHORT_READING_C};

/// The default device file (`devices/default.toml`): equal to [`DeviceConfig::default`].
pub const DEFAULT_DEVICE_TOML: &str = include_str!("../devices/default.toml");
/// A display with weak water cooling (`devices/weak-cooling.toml`): a third of the default water conductance.
pub const WEAK_COOLING_DEVICE_TOML: &str = include_str!("../devices/weak-cooling.toml");
/// A display whose sensor lags (`devices/lagging-sensor.toml`): time constant 1.5 s.
pub const LAGGING_SENSOR_DEVICE_TOML: &str = include_str!("../devices/lagging-sensor.toml");
