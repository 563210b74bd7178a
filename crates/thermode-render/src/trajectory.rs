//! What one offline render records ([`Trajectory`]: one column per quantity, one row per tick), the state at the
//! touch ([`ContactState`]) and the simulated display it runs on ([`Plant`]), read at the receptor depth
//! ([`finger_at_depth_c`]). Written by [`crate::run`], read by [`crate::summary`].

use thermode_device::{PlateFinger, SimulatedChannel, SimulatedDisplay};
use thermode_model::fv::FvModel;
use thermode_pipeline::pipeline::Telemetry;
use thermode_safety::FaultCode;

#[cfg(doc)]
use crate::spec::RenderSpec;

/// The simulated display of a run: one channel with the finite-volume finger.
pub type Plant = SimulatedDisplay<FvModel>;

/// One column per recorded quantity, one row per tick.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trajectory {
    /// Time since the touch at the end of the tick \[s\] (0 at contact, negative before).
    pub time_s: Vec<f64>,
    /// Ground truth: the simulated finger touching the real material, at the receptor depth
    /// ([`RenderSpec::receptor_depth_m`]: surface for fv, epidermis centre for kron) \[°C\].
    pub truth_skin_c: Vec<f64>,
    /// The renderer's target: its receptor (fv: the skin surface; kron: T1, the epidermis centre) \[°C\].
    pub target_skin_c: Vec<f64>,
    /// The simulated finger on the display at the receptor depth ([`RenderSpec::receptor_depth_m`]: surface for
    /// fv, epidermis centre for kron) \[°C\].
    pub skin_c: Vec<f64>,
    /// The pipeline's finger model on the display (what it believes the finger feels) \[°C\].
    pub model_skin_c: Vec<f64>,
    /// The set-point the inverse asked for, before the envelope \[°C\].
    pub requested_setpoint_c: Vec<f64>,
    /// The set-point after the envelope \[°C\].
    pub display_setpoint_c: Vec<f64>,
    /// The true plate temperature \[°C\].
    pub display_c: Vec<f64>,
    /// The PT-100 reading \[°C\].
    pub sensor_c: Vec<f64>,
    /// The safety envelope's estimate of the true plate (`display_c`) from the reading \[°C\].
    pub plate_estimate_c: Vec<f64>,
    /// The gated drive current \[A\].
    pub current_a: Vec<f64>,
    /// The true hot-side temperature \[°C\].
    pub hot_side_c: Vec<f64>,
    /// Whether the rendered finger touched the object.
    pub contact: Vec<bool>,
    /// The latched fault, if any.
    pub fault: Vec<Option<FaultCode>>,
}

impl Trajectory {
    pub(crate) fn with_capacity(rows: usize) -> Self {
        let v = || Vec::with_capacity(rows);
        Trajectory {
            time_s: v(),
            truth_skin_c: v(),
            target_skin_c: v(),
            skin_c: v(),
            model_skin_c: v(),
            requested_setpoint_c: v(),
            display_setpoint_c: v(),
            display_c: v(),
            sensor_c: v(),
            plate_estimate_c: v(),
            current_a: v(),
            hot_side_c: v(),
            contact: Vec::with_capacity(rows),
            fault: Vec::with_capacity(rows),
        }
    }

    /// The numeric columns with their CSV names, in CSV order.
    pub fn numbers(&self) -> impl Iterator<Item = (&'static str, &[f64])> {
        [
            ("time_s", &self.time_s),
            ("truth_skin_c", &self.truth_skin_c),
            ("target_skin_c", &self.target_skin_c),
            ("skin_c", &self.skin_c),
            ("model_skin_c", &self.model_skin_c),
            ("display_setpoint_c", &self.display_setpoint_c),
            ("requested_setpoint_c", &self.requested_setpoint_c),
            ("display_c", &self.display_c),
            ("sensor_c", &self.sensor_c),
            ("plate_estimate_c", &self.plate_estimate_c),
            ("current_a", &self.current_a),
            ("hot_side_c", &self.hot_side_c),
        ]
        .into_iter()
        .map(|(name, column)| (name, column.as_slice()))
    }

    /// The first numeric column (in CSV order) holding a number that is not finite, with the row of its first
    /// such number; `None` if every number is finite.
    pub fn first_non_finite(&self) -> Option<(&'static str, usize)> {
        self.numbers()
            .find_map(|(name, column)| column.iter().position(|v| !v.is_finite()).map(|row| (name, row)))
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    pub(crate) fn record(&mut self, time_s: f64, truth_c: f64, telemetry: &Telemetry, plant: &Plant, depth_m: f64) {
        let Ok(channel) = plant.channel(0) else {
            return;
        };
        let state = channel.state();
        self.time_s.push(time_s);
        self.truth_skin_c.push(truth_c);
        self.target_skin_c.push(telemetry.target_skin_c);
        self.skin_c.push(finger_at_depth_c(channel, depth_m));
        self.model_skin_c.push(telemetry.skin_c);
        self.requested_setpoint_c.push(telemetry.requested_setpoint_c);
        self.display_setpoint_c.push(telemetry.display_setpoint_c);
        self.display_c.push(state.plate_c);
        self.sensor_c.push(state.sensor.value_c);
        self.plate_estimate_c.push(telemetry.plate_estimate_c);
        self.current_a.push(state.applied_current_a);
        self.hot_side_c.push(state.hot_side_c);
        self.contact.push(telemetry.contact);
        self.fault.push(telemetry.fault);
    }
}

/// The state at the moment of touch.
#[derive(Debug, Clone)]
pub struct ContactState {
    /// The renderer's target at the touch \[°C\] (T0 of the lag).
    pub target_c: f64,
    /// The simulated finger at the receptor depth at the touch \[°C\] ([`RenderSpec::receptor_depth_m`]).
    pub skin_c: f64,
    /// The plant at the touch (for the actuator-limit run).
    pub plant: Plant,
}

/// The simulated finger's skin at `depth_m` \[m\] below its surface \[°C\]: its receptor (the surface) at depth 0
/// — exactly the channel state's `receptor_c` — otherwise [`PlateFinger::temperature_at_depth_c`].
pub fn finger_at_depth_c(channel: &SimulatedChannel<FvModel>, depth_m: f64) -> f64 {
    if depth_m == 0.0 {
        channel.state().receptor_c
    } else {
        channel.finger().temperature_at_depth_c(depth_m)
    }
}
