//! The hardware boundary: the small [`Device`] trait every display (simulated or real) implements, the
//! [`SimulatedDisplay`] of up to [`MAX_CHANNELS`] independent channels, and the [`RecordingDevice`] wrapper that
//! records every command (the fake of tests).
//!
//! A drive current reaches a device only as a [`DriveCommand`], which only the safety envelope
//! (`thermode_safety::SafetyEnvelope::gate_drive`, or `DriveCommand::off`) can make.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use thermode_model::Rule;
use thermode_safety::fault::FaultCode;
use thermode_safety::{DriveCommand, DriveLimits};

use crate::channel::SimulatedChannel;
use crate::config::DeviceConfig;
use crate::error::DeviceError;
use crate::finger::PlateFinger;
pub use crate::reading::Reading;
use crate::sensor::standard_normal;

/// Most channels of one display: the paper found at most about ten independently resolvable sites per hand.
pub const MAX_CHANNELS: usize = 10;

/// What a device measures or drives itself, so that the numbers it cannot give are reported as unknown (`null`),
/// never as the controller's or the model's guess.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Measures {
    /// The device drives the Peltier current thermode asks for and reports what it delivers. False for a
    /// temperature-commanded device (a TCS II, a MeCom controller in temperature mode), whose own controller sets
    /// the current: thermode's current and its model's finger estimate built on it do not reach the plate.
    pub drive_current: bool,
    /// The device reports its hot side (a TCS II reports none).
    pub hot_side: bool,
}

impl Measures {
    /// A current-driven display that reports its current and hot side (the simulated display, thermode's own
    /// protocol, MeCom in current mode).
    pub const ALL: Measures = Measures {
        drive_current: true,
        hot_side: true,
    };
}

/// One device of a display: its name, the display's channels it holds, and its link.
#[derive(Debug, Clone)]
pub struct DevicePart {
    /// The device's spelling (e.g. `mecom:/dev/ttyUSB0`); empty when the display has one device and no name for
    /// it (whoever reports it names it by the display's label).
    pub label: String,
    /// The display's first channel on this device.
    pub first_channel: usize,
    /// How many of the display's channels are on this device.
    pub channel_count: usize,
    /// The device's link (None: a device without one, the simulated display).
    pub health: Option<std::sync::Arc<crate::LinkHealth>>,
    /// What tells this very device apart from others of its kind, as it reports it (a MeCom controller's serial
    /// number, e.g. `SN4242`, else its `?IF` identity text); `None` when it reports nothing that does (the
    /// simulated display, a TCS II, whose identity answer names only its type). See [`Device::identity`].
    pub identity: Option<String>,
}

impl DevicePart {
    /// The display's channels on this device.
    pub fn channels(&self) -> std::ops::Range<usize> {
        self.first_channel..self.first_channel + self.channel_count
    }
}

/// A thermal display: channels that take gated drive commands and give sensor readings.
pub trait Device {
    /// Number of channels.
    fn channel_count(&self) -> usize;

    /// Applies a gated drive command to `channel`; it holds until the next command.
    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError>;

    /// The newest reading of `channel`.
    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError>;

    /// The start of a control tick at loop time `now_s` \[s\]: the device does the work it owes each tick. A
    /// simulated display advances its physics to `now_s`; a polled link sends its per-tick requests; a device with a
    /// link thread of its own has nothing to do. A time that is not finite or not later than the previous one
    /// changes nothing.
    fn poll(&mut self, now_s: f64);
    /// Switches every drive off at once (a stop). By default [`DriveCommand::off`] on every channel, each error
    /// counted but not stopping the others (the first is returned); a device with an all-off command of its own (a
    /// serial display's `AllOff`) uses it.
    fn all_off(&mut self) -> Result<(), DeviceError> {
        let mut first = Ok(());
        for channel in 0..self.channel_count() {
            if let Err(e) = self.apply(channel, &DriveCommand::off()) {
                if first.is_ok() {
                    first = Err(e);
                }
            }
        }
        first
    }

    /// The health of the link to a real display (up or down, reconnections), shared with whoever reports it;
    /// `None` for a device without a link (the default).
    fn link_health(&self) -> Option<std::sync::Arc<crate::LinkHealth>> {
        None
    }

    /// What the device measures or drives itself (default: everything, [`Measures::ALL`]).
    fn measures(&self) -> Measures {
        Measures::ALL
    }

    /// What tells this very device apart from others of its kind (a MeCom controller's serial number), for
    /// finding its identified device file; `None` (the default) for a device that reports nothing that does.
    fn identity(&self) -> Option<String> {
        None
    }

    /// The devices the display is made of, each with its channels and link (default: one unnamed part holding
    /// every channel, with [`Device::link_health`] and [`Device::identity`]; a [`crate::CompositeDevice`] lists its
    /// members).
    fn parts(&self) -> Vec<DevicePart> {
        vec![DevicePart {
            label: String::new(),
            first_channel: 0,
            channel_count: self.channel_count(),
            health: self.link_health(),
            identity: self.identity(),
        }]
    }
}

/// A boxed device is a device (the daemon's loop holds whichever display it was given as one).
impl<D: Device + ?Sized> Device for Box<D> {
    fn channel_count(&self) -> usize {
        (**self).channel_count()
    }
    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        (**self).apply(channel, command)
    }
    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        (**self).read(channel)
    }
    fn poll(&mut self, now_s: f64) {
        (**self).poll(now_s);
    }
    fn all_off(&mut self) -> Result<(), DeviceError> {
        (**self).all_off()
    }
    fn link_health(&self) -> Option<std::sync::Arc<crate::LinkHealth>> {
        (**self).link_health()
    }
    fn measures(&self) -> Measures {
        (**self).measures()
    }
    fn identity(&self) -> Option<String> {
        (**self).identity()
    }
    fn parts(&self) -> Vec<DevicePart> {
        (**self).parts()
    }
}

/// The simulated display: up to [`MAX_CHANNELS`] identical, independent channels, each with its own finger and its
/// own noise stream (ChaCha8 seeded from one seed, stream = channel index).
#[derive(Debug, Clone)]
pub struct SimulatedDisplay<F> {
    channels: Vec<SimulatedChannel<F>>,
    commanded_a: Vec<f64>,
    time_s: f64,
    /// The noise of each channel's voltage reading (ChaCha8 from the display's seed, stream
    /// [`VOLTAGE_NOISE_STREAM`] + channel, apart from the sensors').
    voltage_rngs: Vec<ChaCha8Rng>,
}

/// Standard deviation of the simulated Peltier voltage reading \[V\]: 1 mV (a TEC controller's measurement).
pub const VOLTAGE_NOISE_V: f64 = 1e-3;
/// First ChaCha8 stream of the voltage noise (channel k uses this + k).
pub const VOLTAGE_NOISE_STREAM: u64 = 1 << 32;

impl<F: PlateFinger> SimulatedDisplay<F> {
    /// A display with one channel per finger (1 to [`MAX_CHANNELS`]), all described by `config`.
    pub fn new(config: &DeviceConfig, fingers: Vec<F>, seed: u64) -> Result<Self, DeviceError> {
        if fingers.is_empty() || fingers.len() > MAX_CHANNELS {
            return Err(DeviceError::ChannelCount {
                count: fingers.len(),
                max: MAX_CHANNELS,
            });
        }
        let mut channels = Vec::with_capacity(fingers.len());
        for (index, finger) in fingers.into_iter().enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(index as u64);
            channels.push(SimulatedChannel::new(config, finger, rng)?);
        }
        let commanded_a = vec![0.0; channels.len()];
        let voltage_rngs = (0..channels.len())
            .map(|index| {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                rng.set_stream(VOLTAGE_NOISE_STREAM + index as u64);
                rng
            })
            .collect();
        Ok(SimulatedDisplay {
            channels,
            commanded_a,
            time_s: 0.0,
            voltage_rngs,
        })
    }

    /// A display of `count` channels, each with the default fingertip of model `F` ([`PlateFinger::fingertip`]).
    pub fn fingertips(config: &DeviceConfig, count: usize, seed: u64) -> Result<Self, DeviceError> {
        if count == 0 || count > MAX_CHANNELS {
            return Err(DeviceError::ChannelCount {
                count,
                max: MAX_CHANNELS,
            });
        }
        let fingers = (0..count).map(|_| F::fingertip()).collect::<Result<Vec<F>, _>>()?;
        SimulatedDisplay::new(config, fingers, seed)
    }

    /// Channel `index`.
    pub fn channel(&self, index: usize) -> Result<&SimulatedChannel<F>, DeviceError> {
        let count = self.channels.len();
        self.channels
            .get(index)
            .ok_or(DeviceError::NoSuchChannel { channel: index, count })
    }

    /// Channel `index`, mutable (fault injection, initial temperatures, the finger).
    pub fn channel_mut(&mut self, index: usize) -> Result<&mut SimulatedChannel<F>, DeviceError> {
        let count = self.channels.len();
        self.channels
            .get_mut(index)
            .ok_or(DeviceError::NoSuchChannel { channel: index, count })
    }

    /// Device time \[s\]: the sum of the steps taken.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Advances every channel's physics by `dt_s` \[s\] with the currents last applied (offline runs step the
    /// display this way; a control loop calls [`Device::poll`]). A step that is not finite and positive changes
    /// nothing.
    pub fn advance(&mut self, dt_s: f64) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        for (channel, &current_a) in self.channels.iter_mut().zip(&self.commanded_a) {
            channel.step(dt_s, current_a);
        }
        self.time_s += dt_s;
    }
}

impl<F: PlateFinger> Device for SimulatedDisplay<F> {
    fn channel_count(&self) -> usize {
        self.channels.len()
    }

    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        let count = self.channels.len();
        let slot = self
            .commanded_a
            .get_mut(channel)
            .ok_or(DeviceError::NoSuchChannel { channel, count })?;
        let current_a = command.current_a();
        Rule::Finite.check("drive current [A]", current_a)?;
        *slot = current_a;
        Ok(())
    }

    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        self.channel(channel)?;
        let voltage_noise_v = VOLTAGE_NOISE_V * standard_normal(&mut self.voltage_rngs[channel]);
        let ch = self.channel(channel)?;
        let state = ch.state();
        Ok(Reading {
            sensor_c: state.sensor.value_c,
            hot_side_c: ch.hot_side_reading_c(),
            time_s: state.sensor.time_s,
            sample_seq: state.sensor.seq,
            current_a: state.applied_current_a,
            voltage_v: ch
                .module()
                .voltage_v(state.applied_current_a, state.plate_c, state.hot_side_c)
                + voltage_noise_v,
            heating_limit_a: f64::INFINITY,
        })
    }

    fn poll(&mut self, now_s: f64) {
        self.advance(now_s - self.time_s);
    }
}

/// What a [`RecordingDevice`] saw of one command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordedCommand {
    /// Loop time of the last [`Device::poll`] before the command \[s\].
    pub time_s: f64,
    /// The channel it was for.
    pub channel: usize,
    /// The gated current \[A\].
    pub current_a: f64,
    /// The envelope's latched fault at that moment, if any.
    pub fault: Option<FaultCode>,
    /// Which envelope limits acted on it.
    pub limited_by: DriveLimits,
    /// Whether the inner device accepted it.
    pub accepted: bool,
}

/// Wraps a device and records every command applied to it (and the time it was applied).
#[derive(Debug, Clone)]
pub struct RecordingDevice<D> {
    inner: D,
    time_s: f64,
    commands: Vec<RecordedCommand>,
}

impl<D: Device> RecordingDevice<D> {
    /// Starts recording in front of `inner`.
    pub fn new(inner: D) -> Self {
        RecordingDevice {
            inner,
            time_s: 0.0,
            commands: Vec::new(),
        }
    }

    /// Every command so far, in order.
    pub fn commands(&self) -> &[RecordedCommand] {
        &self.commands
    }

    /// The wrapped device.
    pub fn inner(&self) -> &D {
        &self.inner
    }

    /// The wrapped device, mutable.
    pub fn inner_mut(&mut self) -> &mut D {
        &mut self.inner
    }

    /// Stops recording; returns the device and the record.
    pub fn into_parts(self) -> (D, Vec<RecordedCommand>) {
        (self.inner, self.commands)
    }
}

impl<D: Device> Device for RecordingDevice<D> {
    fn channel_count(&self) -> usize {
        self.inner.channel_count()
    }

    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        let result = self.inner.apply(channel, command);
        self.commands.push(RecordedCommand {
            time_s: self.time_s,
            channel,
            current_a: command.current_a(),
            fault: command.fault(),
            limited_by: command.limited_by(),
            accepted: result.is_ok(),
        });
        result
    }

    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        self.inner.read(channel)
    }

    fn poll(&mut self, now_s: f64) {
        self.inner.poll(now_s);
        if now_s.is_finite() && now_s > self.time_s {
            self.time_s = now_s;
        }
    }

    fn link_health(&self) -> Option<std::sync::Arc<crate::LinkHealth>> {
        self.inner.link_health()
    }

    fn measures(&self) -> Measures {
        self.inner.measures()
    }

    fn parts(&self) -> Vec<DevicePart> {
        self.inner.parts()
    }
}
