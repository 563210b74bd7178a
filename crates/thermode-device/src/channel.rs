//! One channel of the simulated display (`model.md` §5): Peltier module, display plate, hot side on the water-cooled
//! box, PT-100, bipolar current drive, and a finger resting on the plate — plus fault injection.
//!
//! # Node equations
//! With the plate at T_d, the hot side at T_h, the water at T_w, the current I (positive heats the plate) and the
//! finger's receptor at T_r:
//! - `C_d dT_d/dt = q_d(I, T_d, T_h) + A G (T_r − T_d)`
//! - `C_h dT_h/dt = q_h(I, T_d, T_h) − G_w (T_h − T_w)`
//!
//! where q_d, q_h are the Peltier heat flows into plate and hot side ([`PeltierModule`]), A the contact area, G the
//! conductance from the finger's receptor node to the plate ([`PlateFinger`]) and G_w the water conductance (times
//! the remaining fraction after a pump failure). The plate has no other losses (its free edges are ≈ 0.3 cm² of
//! 10 W/(m²·K) air contact, under 0.3 mW/K, two orders below K).
//!
//! # Integration: one monolithic implicit step
//! At a fixed current the Peltier flows are affine in T_d and T_h, and over one step the finger's receptor is an
//! affine function of the plate temperature ([`PlateCoupled::receptor_affine`](thermode_model::inverse::PlateCoupled::receptor_affine)). So plate, hot side and finger are
//! advanced together by backward Euler: one 2×2 linear solve gives T_d and T_h at the end of the step with the
//! finger's response already in it, then the finger is stepped with that plate temperature. There is no splitting
//! error between finger and plate and no stability limit from the small plate capacity (≈ 0.3 J/K); the scheme is
//! first order in the step. Steps longer than [`MAX_SUBSTEP_S`] are split into equal substeps for accuracy; a
//! substep whose 2×2 system is not positive definite (possible only for a large step with a strongly heating
//! current) is halved again.
//!
//! Energy: all flows of a step are evaluated at the end-of-step temperatures, exactly as the implicit equations use
//! them, so `C_d ΔT_d + C_h ΔT_h = (P_el − Q_water + Q_finger→plate)·Δt` holds to rounding in every step.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use thermode_model::peltier::PeltierModule;
use thermode_model::Rule;

use crate::config::DeviceConfig;
use crate::error::DeviceError;
use crate::finger::PlateFinger;
use crate::sensor::{quantise, Pt100, SensorCondition, SensorSample};

/// Longest internal step of the plant \[s\]; longer steps are split into equal substeps. The scheme is first order:
/// during a full-current transient the plate's error is about 0.04 K at 8–10 ms and 0.004 K at 1 ms
/// (`tests/integration/plant.rs`, Richardson estimate), below the sensor's 0.01 °C resolution from about 2 ms down.
pub const MAX_SUBSTEP_S: f64 = 0.01;

/// Most halvings of a substep whose system is not positive definite: 12 (4096 pieces; a display within the device
/// file's bounds needs none at [`MAX_SUBSTEP_S`]: the default plate's C/h of 28 W/K dwarfs the module's temperature
/// coefficients, hundredths of a W/K).
const MAX_HALVINGS: u32 = 12;

/// Fraction of the water conductance left by default after a pump failure: 0.1. Estimate: the box's water is still;
/// natural convection in it and conduction through the hoses carry about a tenth of the forced-flow heat.
pub const PUMP_FAILURE_REMAINING_FRACTION: f64 = 0.1;

/// Sign of a stuck drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Polarity {
    /// Positive current: heats the plate.
    Heating,
    /// Negative current: cools the plate.
    Cooling,
}

/// A fault injected into a channel (for tests of the safety envelope). Faults stay until cleared.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The sensor wire is broken: reads [`crate::SENSOR_OPEN_READING_C`].
    SensorOpen,
    /// The sensor is shorted: reads [`crate::SENSOR_SHORT_READING_C`].
    SensorShort,
    /// The sensor is frozen: the reading, its time and sequence number stop changing.
    SensorFrozen,
    /// The pump stops: the water conductance drops to `remaining_fraction` (in [0, 1]) of its value.
    PumpFailure {
        /// Fraction of the water conductance left, in [0, 1]; see [`PUMP_FAILURE_REMAINING_FRACTION`].
        remaining_fraction: f64,
    },
    /// The drive is stuck: it delivers its full current limit with this polarity whatever is commanded.
    DriveStuck {
        /// The sign of the stuck current.
        polarity: Polarity,
    },
}

/// Mean heat flows over the last step \[W\] (energy over the step divided by its length).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HeatFlows {
    /// Peltier heat into the plate, q_d.
    pub peltier_into_plate_w: f64,
    /// Peltier heat into the hot side, q_h.
    pub peltier_into_hot_side_w: f64,
    /// Electrical power into the module, V·I.
    pub electrical_w: f64,
    /// Heat from the finger into the plate, A G (T_r − T_d) (negative when the plate warms the finger).
    pub finger_into_plate_w: f64,
    /// Heat from the hot side into the water, G_w (T_h − T_w).
    pub hot_side_to_water_w: f64,
}

/// Everything a channel exposes after a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelState {
    /// Time since the channel started \[s\].
    pub time_s: f64,
    /// True plate (display) temperature \[°C\].
    pub plate_c: f64,
    /// True hot-side temperature \[°C\].
    pub hot_side_c: f64,
    /// The latest PT-100 sample.
    pub sensor: SensorSample,
    /// Current asked for in the last step \[A\] (NaN commands are recorded as given).
    pub commanded_current_a: f64,
    /// Current the drive delivered in the last step \[A\].
    pub applied_current_a: f64,
    /// The finger's receptor temperature \[°C\].
    pub receptor_c: f64,
    /// Mean heat flows over the last step.
    pub flows: HeatFlows,
}

/// One channel of the simulated display with a finger of type `F` resting on it.
#[derive(Debug, Clone)]
pub struct SimulatedChannel<F> {
    config: DeviceConfig,
    module: PeltierModule,
    finger: F,
    /// Conductance from the finger's receptor node to the plate [W/(m²·K)].
    finger_conductance_w_m2k: f64,
    sensor: Pt100,
    pump_fraction: f64,
    stuck: Option<Polarity>,
    state: ChannelState,
}

/// Energies of one step \[J\], accumulated over its substeps.
#[derive(Default)]
struct Ledger {
    peltier_plate_j: f64,
    peltier_hot_j: f64,
    electrical_j: f64,
    finger_j: f64,
    water_j: f64,
}

impl<F: PlateFinger> SimulatedChannel<F> {
    /// A channel described by `config` (validated here) with `finger` on it; plate and hot side start at the water
    /// temperature, the sensor reads the plate. `rng` supplies the sensor noise (seed it explicitly).
    pub fn new(config: &DeviceConfig, finger: F, rng: ChaCha8Rng) -> Result<Self, DeviceError> {
        config.validate("device config")?;
        let module = config.module()?;
        let water_c = config.ambient.water_c;
        let finger_conductance_w_m2k = finger.receptor_conductance_w_m2k(config.plate.contact_conductance_w_m2k);
        let sensor = Pt100::new(&config.sensor, water_c, rng);
        let state = ChannelState {
            time_s: 0.0,
            plate_c: water_c,
            hot_side_c: water_c,
            sensor: sensor.latest(),
            commanded_current_a: 0.0,
            applied_current_a: 0.0,
            receptor_c: finger.receptor_c(),
            flows: HeatFlows::default(),
        };
        Ok(SimulatedChannel {
            config: *config,
            module,
            finger,
            finger_conductance_w_m2k,
            sensor,
            pump_fraction: 1.0,
            stuck: None,
            state,
        })
    }

    /// As [`SimulatedChannel::new`] with the sensor noise seeded from `seed` (ChaCha8, stream 0).
    pub fn seeded(config: &DeviceConfig, finger: F, seed: u64) -> Result<Self, DeviceError> {
        SimulatedChannel::new(config, finger, ChaCha8Rng::seed_from_u64(seed))
    }

    /// Sets the plate and hot-side temperatures \[°C\]; the sensor element follows the plate. Both must be finite.
    pub fn set_temperatures(&mut self, plate_c: f64, hot_side_c: f64) -> Result<(), DeviceError> {
        for (what, value) in [
            ("plate temperature [°C]", plate_c),
            ("hot-side temperature [°C]", hot_side_c),
        ] {
            Rule::Finite.check(what, value)?;
        }
        self.state.plate_c = plate_c;
        self.state.hot_side_c = hot_side_c;
        self.sensor.set_element_c(plate_c);
        Ok(())
    }

    /// Advances the channel by `dt_s` \[s\] with `current_a` \[A\] commanded (positive heats the plate). Cannot fail:
    /// the drive limits the current to ± the current limit (that is its job), a NaN command makes it deliver 0 A,
    /// a stuck drive delivers its limit; a step that is not finite and positive changes nothing.
    pub fn step(&mut self, dt_s: f64, current_a: f64) -> &ChannelState {
        self.state.commanded_current_a = current_a;
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return &self.state;
        }
        let applied = self.drive_current(current_a);
        let substeps = (dt_s / MAX_SUBSTEP_S).ceil().max(1.0) as usize;
        let h = dt_s / substeps as f64;
        let mut ledger = Ledger::default();
        for _ in 0..substeps {
            self.advance(h, applied, &mut ledger, 0);
        }
        self.state.applied_current_a = applied;
        self.state.time_s += dt_s;
        self.state.receptor_c = self.finger.receptor_c();
        self.state.sensor = self.sensor.latest();
        self.state.flows = HeatFlows {
            peltier_into_plate_w: ledger.peltier_plate_j / dt_s,
            peltier_into_hot_side_w: ledger.peltier_hot_j / dt_s,
            electrical_w: ledger.electrical_j / dt_s,
            finger_into_plate_w: ledger.finger_j / dt_s,
            hot_side_to_water_w: ledger.water_j / dt_s,
        };
        &self.state
    }

    /// The current the drive delivers for a command.
    fn drive_current(&self, commanded_a: f64) -> f64 {
        let limit = self.config.drive.current_limit_a;
        match self.stuck {
            Some(Polarity::Heating) => limit,
            Some(Polarity::Cooling) => -limit,
            None if commanded_a.is_nan() => 0.0,
            None => commanded_a.clamp(-limit, limit),
        }
    }

    /// One implicit substep of `h` \[s\]; halves itself (at most [`MAX_HALVINGS`] times) while the 2×2 system's
    /// determinant is finite but not positive. A determinant that is not finite (NaN from a broken finger, numbers
    /// beyond any display) is not helped by halving: the step is taken as it is and the NaN shows in the readings.
    fn advance(&mut self, h: f64, current_a: f64, ledger: &mut Ledger, depth: u32) {
        let (offset, slope) = self.finger.receptor_affine(h, self.finger_conductance_w_m2k);
        let det = self.determinant(h, current_a, offset, slope);
        if det.is_finite() && det <= 0.0 && depth < MAX_HALVINGS {
            self.advance(h / 2.0, current_a, ledger, depth + 1);
            self.advance(h / 2.0, current_a, ledger, depth + 1);
            return;
        }
        let (plate_c, hot_c) = self.solve_unchecked(h, current_a, offset, slope);
        let area_g = self.config.plate.area_m2 * self.finger_conductance_w_m2k;
        ledger.peltier_plate_j += h * self.module.heat_into_display_w(current_a, plate_c, hot_c);
        ledger.peltier_hot_j += h * self.module.heat_into_hot_side_w(current_a, plate_c, hot_c);
        ledger.electrical_j += h * self.module.electrical_power_w(current_a, plate_c, hot_c);
        ledger.finger_j += h * area_g * (offset + slope * plate_c - plate_c);
        ledger.water_j += h * self.water_conductance_w_k() * (hot_c - self.config.ambient.water_c);
        self.finger.step_on_plate(h, self.finger_conductance_w_m2k, plate_c);
        self.sensor.advance(h, self.state.plate_c, plate_c);
        self.state.plate_c = plate_c;
        self.state.hot_side_c = hot_c;
    }

    /// The 2×2 backward-Euler system for (T_d, T_h) as ((a11, a12, r1), (a21, a22, r2)).
    fn system(&self, h: f64, current_a: f64, offset: f64, slope: f64) -> ([f64; 3], [f64; 3]) {
        let qd = self.module.display_heat_affine(current_a);
        let qh = self.module.hot_heat_affine(current_a);
        let cd = self.config.plate.heat_capacity_j_k / h;
        let ch = self.config.hot_side.heat_capacity_j_k / h;
        let area_g = self.config.plate.area_m2 * self.finger_conductance_w_m2k;
        let gw = self.water_conductance_w_k();
        let plate = [
            cd - qd.display_w_k + area_g * (1.0 - slope),
            -qd.hot_w_k,
            cd * self.state.plate_c + qd.constant_w + area_g * offset,
        ];
        let hot = [
            -qh.display_w_k,
            ch - qh.hot_w_k + gw,
            ch * self.state.hot_side_c + qh.constant_w + gw * self.config.ambient.water_c,
        ];
        (plate, hot)
    }

    /// The determinant of the step's system.
    fn determinant(&self, h: f64, current_a: f64, offset: f64, slope: f64) -> f64 {
        let ([a11, a12, _], [a21, a22, _]) = self.system(h, current_a, offset, slope);
        a11 * a22 - a12 * a21
    }

    fn solve_unchecked(&self, h: f64, current_a: f64, offset: f64, slope: f64) -> (f64, f64) {
        let ([a11, a12, r1], [a21, a22, r2]) = self.system(h, current_a, offset, slope);
        let det = a11 * a22 - a12 * a21;
        ((r1 * a22 - a12 * r2) / det, (a11 * r2 - a21 * r1) / det)
    }

    /// The water conductance in effect [W/K] (reduced by a pump failure).
    pub fn water_conductance_w_k(&self) -> f64 {
        self.config.hot_side.water_conductance_w_k * self.pump_fraction
    }

    /// Injects a fault; it stays until [`SimulatedChannel::clear_faults`]. A pump failure's fraction must lie in
    /// [0, 1]. A new sensor fault replaces an older one.
    pub fn inject(&mut self, fault: Fault) -> Result<(), DeviceError> {
        match fault {
            Fault::SensorOpen => self.sensor.set_condition(SensorCondition::Open),
            Fault::SensorShort => self.sensor.set_condition(SensorCondition::Short),
            Fault::SensorFrozen => self.sensor.set_condition(SensorCondition::Frozen),
            Fault::PumpFailure { remaining_fraction } => {
                Rule::Within { min: 0.0, max: 1.0 }.check("pump failure remaining_fraction [-]", remaining_fraction)?;
                self.pump_fraction = remaining_fraction;
            }
            Fault::DriveStuck { polarity } => self.stuck = Some(polarity),
        }
        Ok(())
    }

    /// Clears every fault: the sensor samples again, the pump runs, the drive follows its commands.
    pub fn clear_faults(&mut self) {
        self.sensor.set_condition(SensorCondition::Healthy);
        self.pump_fraction = 1.0;
        self.stuck = None;
    }

    /// The state after the last step.
    pub fn state(&self) -> &ChannelState {
        &self.state
    }

    /// The box sensor's reading of the hot side \[°C\]: the hot-side temperature quantised to the sensor resolution
    /// (a second sensor on the box; no lag, no noise, unaffected by PT-100 faults).
    pub fn hot_side_reading_c(&self) -> f64 {
        quantise(self.state.hot_side_c, self.config.sensor.resolution_c)
    }

    /// The configuration.
    pub fn config(&self) -> &DeviceConfig {
        &self.config
    }

    /// The Peltier module's lumped parameters.
    pub fn module(&self) -> &PeltierModule {
        &self.module
    }

    /// The finger.
    pub fn finger(&self) -> &F {
        &self.finger
    }

    /// The finger, mutable (e.g. to calibrate it to a measured temperature).
    pub fn finger_mut(&mut self) -> &mut F {
        &mut self.finger
    }

    /// Conductance from the finger's receptor node to the plate [W/(m²·K)] (see [`PlateFinger`]).
    pub fn finger_conductance_w_m2k(&self) -> f64 {
        self.finger_conductance_w_m2k
    }

    /// The PT-100 model.
    pub fn sensor(&self) -> &Pt100 {
        &self.sensor
    }
}
