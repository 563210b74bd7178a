//! What the lab records of a trial on a running display: the channel's telemetry samples ([`DisplaySample`]) and
//! the trial's curve ([`TrialTrace`], written beside the session as CSV with [`TRACE_COLUMNS`]). Filled by the live
//! runner ([`super::live`]), carried by the stimulus's measurement ([`super::stimulus::TrialMeasurement`]).

use std::fmt::Write as _;

use crate::design::Condition;

/// One telemetry sample of the lab's channel, as the daemon publishes it (`docs/api.md`, `subscribe`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisplaySample {
    /// The daemon's loop time \[s\] (the clock of its recordings and markers).
    pub loop_time_s: f64,
    /// The renderer's target receptor temperature \[°C\] (NaN in air or direct mode when not published).
    pub target_skin_c: f64,
    /// The skin model's receptor on the display \[°C\].
    pub skin_c: f64,
    /// The finger's receptor as the plate's heat balance measures it \[°C\] (NaN without an observer).
    pub finger_c: f64,
    /// The display sensor \[°C\].
    pub sensor_c: f64,
    /// The set-point after the safety envelope \[°C\].
    pub display_setpoint_c: f64,
    /// The drive current \[A\].
    pub current_a: f64,
    /// The latched fault code (0: none).
    pub fault: u16,
    /// Whether the channel renders a touch (the daemon's `contact`).
    pub contact: bool,
}

/// The columns of a trial's curve file, in order.
pub const TRACE_COLUMNS: [&str; 13] = [
    "trial",
    "condition",
    "material",
    "time_s",
    "loop_time_s",
    "lsl_time_s",
    "target_skin_c",
    "skin_c",
    "finger_c",
    "sensor_c",
    "display_setpoint_c",
    "current_a",
    "contact",
];

/// A trial's curve on the display: every sample of the channel from the touch (or, for a real trial, from the
/// start of the presentation) to its end. `lab analyze --curves` reads it (`finger_c` is its temperature; a real
/// trial has none, since the finger is on the sample, not on the plate).
#[derive(Debug, Clone, PartialEq)]
pub struct TrialTrace {
    /// The trial (1-based).
    pub trial: usize,
    /// Its condition.
    pub condition: Condition,
    /// The presented material's name.
    pub material: String,
    /// Seconds since the touch \[s\].
    pub time_s: Vec<f64>,
    /// The samples.
    pub samples: Vec<DisplaySample>,
    /// Whether the finger touched the rendered material (a simulated trial) or the display rendered air.
    pub contact: bool,
    /// The LSL clock minus the loop clock at the trial's start marker \[s\] (`None` without LSL): the curve's
    /// `lsl_time_s` is `loop_time_s` plus it.
    pub lsl_minus_loop_s: Option<f64>,
}

impl TrialTrace {
    /// The curve as CSV ([`TRACE_COLUMNS`]; a value that is not finite is an empty cell).
    pub fn to_csv(&self) -> String {
        let mut text = TRACE_COLUMNS.join(",");
        text.push('\n');
        let cell = |v: f64| if v.is_finite() { format!("{v}") } else { String::new() };
        // The plate measures the finger only while it rests on it: not during a real trial.
        let finger = |c: f64| if self.contact { c } else { f64::NAN };
        for (t, s) in self.time_s.iter().zip(&self.samples) {
            let values = [
                (t * 1e6).round() / 1e6,
                s.loop_time_s,
                self.lsl_minus_loop_s
                    .map_or(f64::NAN, |offset_s| s.loop_time_s + offset_s),
                s.target_skin_c,
                s.skin_c,
                finger(s.finger_c),
                s.sensor_c,
                s.display_setpoint_c,
                s.current_a,
            ];
            let row: Vec<String> = values.iter().map(|&v| cell(v)).collect();
            let head = format!("{},{},{}", self.trial, self.condition.name(), self.material);
            let _ = writeln!(text, "{head},{},{}", row.join(","), self.contact);
        }
        text
    }
}
