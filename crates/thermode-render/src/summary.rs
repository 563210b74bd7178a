//! The metrics of one offline render, after the paper's Figure 3 and its two flaws (section 4.1): how far the
//! displayed contact is from the target and from the real contact, how well the plate follows its set-point, how
//! far the finger is driven past the target (the colder end, controller inertia), and how late the finger gets
//! half-way (the slow initial drop) next to what the actuator allows at all.
//!
//! # Definitions (t = time since the touch; rows after the touch are those with t > 0)
//! - Skin and truth are read where the renderer's target lives ([`RenderSpec::receptor_depth_m`]): at the skin
//!   surface for the fv renderer, at the centre of the simulated finger's epidermis (Kron's T1) for the kron
//!   renderer, in the simulated finger on the display, in the truth and in the actuator-limit run alike.
//! - RMS skin error: √(mean of (skin − target)²) over the rows with 0 < t ≤ 5 s, 5 < t ≤ 90 s, and 0 < t ≤ 90 s (90 s
//!   or the run's duration if shorter, [`RenderSummary::window_end_s`]; the labels follow it).
//! - RMS against the truth: the same for skin − truth over 0 < t ≤ 90 s.
//! - RMS display tracking: true plate minus the shaped set-point held over the tick, over 0 < t ≤ 90 s.
//! - Direction: T0 is the target at the touch; the target drops (cooling) if T0 − min target ≥ max target − T0,
//!   otherwise it rises (heating). The drop (or rise) Δ is that larger difference.
//! - Overshoot: the largest excursion of the skin beyond the target in that direction during the contact,
//!   max(target − skin) for cooling (max(skin − target) for heating) over the rows after the touch whose tick
//!   rendered the contact (`Trajectory::contact`), and at least 0. After a release (`RenderSpec::release_at_s`)
//!   the target warms back towards the resting skin faster than any display can warm the finger (the plate warms
//!   slower than it cools at the drive limit), so the skin trails below the target: that warming lag is the
//!   displayed finger being *late*, not driven past its target, and is not counted (it shows in the RMS errors).
//! - Lag at half of the target's drop: the half level is T0 − Δ/2 (T0 + Δ/2 rising); the lag is the time the skin
//!   first reaches it minus the time the target first reaches it, both interpolated linearly between rows (the
//!   skin's curve starts at its own value at the touch). Undefined (None) if Δ < [`MIN_DROP_C`] or a curve never
//!   reaches the level.
//! - Limit of that lag (`limit`): the plant as it was at the touch (same finger, same plate and hot-side state) is
//!   driven by an ideal controller that knows the true plate temperature and applies, in every plant substep, the
//!   most useful current: for cooling the module's optimum cooling current −S·T_d/R at the present plate
//!   temperature, capped by the drive limit (beyond the optimum more current warms the plate); for heating the full
//!   drive limit (the heat into the plate grows with the current) — unless that would take the plate past the
//!   fastest set-point the run's safety envelope can produce, and then the current that puts the plate exactly on
//!   it. That set-point starts where the envelope's set-point was at the touch (or the plate, if that is further
//!   in the direction of the change), moves at the envelope's set-point rate limit (`max_setpoint_rate_c_per_s`,
//!   one step per tick, as the envelope shapes it) and stops at the display limits (`min_display_c`,
//!   `max_display_c`). It runs from the touch until the skin meets the target (from then on an ideal controller
//!   follows the target); the limit lag is the time its skin reaches the half level minus the target's time, at
//!   least 0 (0 if it meets the target before the half level). It is the best any controller can do inside the
//!   envelope on this plant: no sensor, no controller delay, but the actuator and the envelope's rate and range.
//!   With the default display at its 20 °C/s the plate cools slower than the rate limit (about 13 °C/s), so the
//!   actuator binds; a display with a stronger module, or a lower `--max-rate`, is held by the envelope.
//! - RMS floor: the same ideal run's RMS skin error over 0 < t ≤ 90 s, counting its error until it meets the target
//!   and none afterwards. The heat equation is monotone in the plate temperature and no admissible current moves
//!   the plate towards the target faster within the envelope, so before that meeting no controller's skin whose
//!   plate stays on the envelope's side of its fastest set-point gets nearer a target below it: the floor bounds
//!   every such controller's RMS from below, up to the plant's substep and the slow hot-side coupling (cooling
//!   less now leaves the hot side a little cooler for later; over the ~1 s to the meeting that is a few mK).

use serde::Serialize;

use crate::error::RenderError;
use crate::spec::RenderSpec;
use crate::trajectory::{finger_at_depth_c, ContactState, Trajectory};

/// Smallest drop (or rise) of the target for which a lag is defined \[°C\]: 0.05.
pub const MIN_DROP_C: f64 = 0.05;

/// End of the early window of the RMS skin error \[s\]: 5.
pub const EARLY_WINDOW_S: f64 = 5.0;
/// End of the windows of the RMS errors \[s\]: 90 (the paper's recordings).
pub const FULL_WINDOW_S: f64 = 90.0;

/// Slack on window ends against rounding of row times \[s\].
const TIME_SLACK_S: f64 = 1e-9;

/// The metrics of one render. Temperatures and errors in °C, times in s; `None` where undefined (empty window, no
/// crossing).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RenderSummary {
    /// The touched material.
    pub material: String,
    /// The controller (`pid`, `model`).
    pub controller: String,
    /// The renderer (`fv`, `kron`).
    pub renderer: String,
    /// End of the windows the run covers \[s\]: its duration after the touch, at most [`FULL_WINDOW_S`] (90). The
    /// fields named `…_90_…` cover 0 (or 5) to this time, and the table and the JSON name them after it
    /// ([`RenderSummary::window_label`]).
    pub window_end_s: f64,
    /// RMS of skin − target over 0 < t ≤ 5 s.
    pub rms_skin_0_5_c: Option<f64>,
    /// RMS of skin − target over 5 < t ≤ 90 s.
    pub rms_skin_5_90_c: Option<f64>,
    /// RMS of skin − target over 0 < t ≤ 90 s (the tuner's objective per material).
    pub rms_skin_0_90_c: Option<f64>,
    /// RMS of skin − truth over 0 < t ≤ 90 s.
    pub rms_truth_0_90_c: Option<f64>,
    /// RMS of true plate − shaped set-point over 0 < t ≤ 90 s.
    pub rms_display_tracking_c: Option<f64>,
    /// Largest excursion of the skin beyond the target during the contact (below it for cooling), ≥ 0; rows after a
    /// release do not count (see the module documentation).
    pub overshoot_c: f64,
    /// Whether the target drops (true) or rises.
    pub cooling: bool,
    /// The target at the touch, T0.
    pub contact_target_c: f64,
    /// The target's drop (or rise) Δ, ≥ 0.
    pub target_drop_c: f64,
    /// The half level T0 ∓ Δ/2.
    pub half_level_c: f64,
    /// When the target first reaches the half level.
    pub target_half_time_s: Option<f64>,
    /// When the skin first reaches the half level.
    pub skin_half_time_s: Option<f64>,
    /// Skin half time minus target half time.
    pub lag_s: Option<f64>,
    /// The same lag for the ideal controller at the actuator and envelope limits (see the module documentation).
    pub actuator_limit_lag_s: Option<f64>,
    /// The RMS skin error floor over 0 < t ≤ 90 s of that ideal controller ([`ActuatorLimit::rms_floor_c`]).
    pub actuator_limit_rms_c: Option<f64>,
    /// The first fault latched during the run, as `E<code> <description>`.
    pub first_fault: Option<String>,
    /// When it latched (time since the touch).
    pub first_fault_time_s: Option<f64>,
}

/// Root mean square of `a − b` over the rows whose time lies in (`from_s`, `to_s`]; `None` for an empty window.
pub fn rms_between(time_s: &[f64], a: &[f64], b: &[f64], from_s: f64, to_s: f64) -> Option<f64> {
    let (sum, count) = time_s
        .iter()
        .zip(a.iter().zip(b))
        .filter(|(t, _)| **t > from_s + TIME_SLACK_S && **t <= to_s + TIME_SLACK_S)
        .fold((0.0, 0usize), |(s, n), (_, (x, y))| (s + (x - y) * (x - y), n + 1));
    (count > 0).then(|| (sum / count as f64).sqrt())
}

/// Direction and size of the target's change after the touch: (cooling, Δ).
fn direction(trajectory: &Trajectory, contact_target_c: f64) -> (bool, f64) {
    let after = trajectory
        .time_s
        .iter()
        .zip(&trajectory.target_skin_c)
        .filter(|(t, v)| **t > TIME_SLACK_S && v.is_finite())
        .map(|(_, v)| *v);
    let (lo, hi) = after.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let drop = contact_target_c - lo;
    let rise = hi - contact_target_c;
    if drop >= rise {
        (true, drop.max(0.0))
    } else {
        (false, rise.max(0.0))
    }
}

/// The level crossing of a curve that starts at `start_c` at t = 0 and continues with the rows after the touch:
/// the first time it reaches `level_c` (from above when `cooling`), interpolated linearly.
pub fn crossing_time(time_s: &[f64], values: &[f64], start_c: f64, level_c: f64, cooling: bool) -> Option<f64> {
    let reached = |v: f64| if cooling { v <= level_c } else { v >= level_c };
    if reached(start_c) {
        return Some(0.0);
    }
    let mut previous = (0.0, start_c);
    for (&t, &v) in time_s.iter().zip(values).filter(|(t, _)| **t > TIME_SLACK_S) {
        if reached(v) {
            return Some(interpolate(previous, (t, v), level_c));
        }
        previous = (t, v);
    }
    None
}

/// The time at which the straight line through `a` and `b` (time, value) passes `level`.
fn interpolate(a: (f64, f64), b: (f64, f64), level: f64) -> f64 {
    let span = b.1 - a.1;
    if span == 0.0 {
        return b.0;
    }
    a.0 + (b.0 - a.0) * ((level - a.1) / span).clamp(0.0, 1.0)
}

/// The half level, its target crossing and the direction, if the target changes enough.
struct HalfDrop {
    cooling: bool,
    drop_c: f64,
    level_c: f64,
    target_time_s: Option<f64>,
}

fn half_drop(trajectory: &Trajectory, contact_target_c: f64) -> HalfDrop {
    let (cooling, drop_c) = direction(trajectory, contact_target_c);
    let level_c = if cooling {
        contact_target_c - drop_c / 2.0
    } else {
        contact_target_c + drop_c / 2.0
    };
    let target_time_s = (drop_c >= MIN_DROP_C)
        .then(|| {
            crossing_time(
                &trajectory.time_s,
                &trajectory.target_skin_c,
                contact_target_c,
                level_c,
                cooling,
            )
        })
        .flatten();
    HalfDrop {
        cooling,
        drop_c,
        level_c,
        target_time_s,
    }
}

/// What the ideal controller at the actuator and envelope limits achieves (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ActuatorLimit {
    /// Its lag at half of the target's drop \[s\] (`None` if the target does not change enough or it never gets
    /// there within the recorded rows).
    pub lag_s: Option<f64>,
    /// Its RMS skin error over 0 < t ≤ 90 s \[°C\], counting the error until the skin meets the target and none
    /// after (perfect tracking from then on): a floor no controller on this plant inside this envelope can go
    /// below, since no admissible current brings the skin towards the target faster (`None` if the skin never
    /// meets the target within the rows).
    pub rms_floor_c: Option<f64>,
}

/// The fastest set-point the envelope of a run can produce after the touch, which the ideal controller's plate
/// may not pass (see the module documentation).
#[derive(Debug, Clone, Copy)]
struct FastestSetpoint {
    /// Where it starts \[°C\].
    origin_c: f64,
    /// Signed step per tick \[°C\]: −rate·dt when cooling, +rate·dt when heating.
    step_c: f64,
    /// The display limit it stops at \[°C\] (`min_display_c` cooling, `max_display_c` heating).
    stop_c: f64,
    cooling: bool,
}

impl FastestSetpoint {
    fn new(spec: &RenderSpec, trajectory: &Trajectory, plate_at_touch_c: f64, cooling: bool) -> Self {
        let envelope = &spec.pipeline.envelope;
        // The set-point the envelope held over the tick before the touch (the last row at or before t = 0).
        let before = trajectory
            .time_s
            .iter()
            .zip(&trajectory.display_setpoint_c)
            .take_while(|(t, _)| **t <= TIME_SLACK_S)
            .last()
            .map_or(plate_at_touch_c, |(_, s)| *s);
        let step_c = envelope.max_setpoint_rate_c_per_s * spec.tick_s();
        if cooling {
            FastestSetpoint {
                origin_c: before.min(plate_at_touch_c),
                step_c: -step_c,
                stop_c: envelope.min_display_c,
                cooling,
            }
        } else {
            FastestSetpoint {
                origin_c: before.max(plate_at_touch_c),
                step_c,
                stop_c: envelope.max_display_c,
                cooling,
            }
        }
    }

    /// The set-point held over tick `k` after the touch (k = 0 is the first) \[°C\].
    fn at_tick(&self, k: usize) -> f64 {
        let ramp_c = self.origin_c + self.step_c * (k + 1) as f64;
        if self.cooling {
            ramp_c.max(self.stop_c)
        } else {
            ramp_c.min(self.stop_c)
        }
    }

    /// Whether a plate at `plate_c` is past `bound_c` in the direction of the change.
    fn passes(&self, plate_c: f64, bound_c: f64) -> bool {
        if self.cooling {
            plate_c < bound_c
        } else {
            plate_c > bound_c
        }
    }
}

/// One plant substep of `h` \[s\] of the ideal controller: the most useful current (see the module documentation),
/// or, if that takes the plate past `bound_c`, the current that puts it on `bound_c` (the plate temperature after
/// a substep grows with the current from the optimum cooling current up; found by the Illinois variant of regula
/// falsi to 1e-9 °C).
fn ideal_substep(channel: &mut Channel, h: f64, limit_a: f64, bound: &FastestSetpoint, bound_c: f64) {
    let module = *channel.module();
    let lo_a = module.optimum_cooling_current_a(channel.state().plate_c).max(-limit_a);
    let hi_a = limit_a;
    let trial = |current_a: f64| {
        let mut next = channel.clone();
        next.step(h, current_a);
        next
    };
    let ideal = trial(if bound.cooling { lo_a } else { hi_a });
    if !bound.passes(ideal.state().plate_c, bound_c) {
        *channel = ideal;
        return;
    }
    let other = trial(if bound.cooling { hi_a } else { lo_a });
    if bound.passes(other.state().plate_c, bound_c) {
        // Even the opposite extreme passes the bound (the plate started beyond it): as near as the drive allows.
        *channel = other;
        return;
    }
    let miss = |next: &Channel| next.state().plate_c - bound_c;
    let (mut a, mut fa) = (lo_a, miss(if bound.cooling { &ideal } else { &other }));
    let (mut b, mut fb) = (hi_a, miss(if bound.cooling { &other } else { &ideal }));
    let mut best = if fa.abs() < fb.abs() { (a, fa) } else { (b, fb) };
    let mut side = 0;
    for _ in 0..60 {
        if best.1.abs() <= 1e-9 || fa == fb {
            break;
        }
        let c = (a * fb - b * fa) / (fb - fa);
        let fc = miss(&trial(c));
        if fc.abs() < best.1.abs() {
            best = (c, fc);
        }
        if (fc > 0.0) == (fb > 0.0) {
            (b, fb) = (c, fc);
            if side == -1 {
                fa /= 2.0;
            }
            side = -1;
        } else {
            (a, fa) = (c, fc);
            if side == 1 {
                fb /= 2.0;
            }
            side = 1;
        }
    }
    *channel = trial(best.0);
}

/// The simulated channel of a run's plant.
type Channel = thermode_device::SimulatedChannel<thermode_model::fv::FvModel>;

/// Runs the ideal controller at the actuator and envelope limits from the plant at the touch until the skin meets
/// the target (see the module documentation).
pub fn actuator_limit(
    spec: &RenderSpec,
    trajectory: &Trajectory,
    contact: &ContactState,
) -> Result<ActuatorLimit, RenderError> {
    let half = half_drop(trajectory, contact.target_c);
    if half.drop_c < MIN_DROP_C {
        return Ok(ActuatorLimit::default());
    }
    let mut plant = contact.plant.clone();
    let channel = plant.channel_mut(0)?;
    let limit_a = channel.config().drive.current_limit_a;
    let bound = FastestSetpoint::new(spec, trajectory, channel.state().plate_c, half.cooling);
    let substeps = spec.substeps();
    let depth_m = spec.receptor_depth_m();
    let h = spec.tick_s() / substeps as f64;
    let sign = if half.cooling { 1.0 } else { -1.0 };
    let window = trajectory
        .time_s
        .iter()
        .filter(|t| **t > TIME_SLACK_S && **t <= FULL_WINDOW_S + TIME_SLACK_S)
        .count();
    let mut result = ActuatorLimit::default();
    let (mut previous, mut squares) = ((0.0, contact.skin_c), 0.0);
    let rows = trajectory.time_s.iter().zip(&trajectory.target_skin_c);
    for (tick, (&t, &target_c)) in rows.filter(|(t, _)| **t > TIME_SLACK_S).enumerate() {
        let bound_c = bound.at_tick(tick);
        for _ in 0..substeps {
            ideal_substep(channel, h, limit_a, &bound, bound_c);
        }
        let skin_c = finger_at_depth_c(channel, depth_m);
        if result.lag_s.is_none() && sign * (half.level_c - skin_c) >= 0.0 {
            let skin_time_s = interpolate(previous, (t, skin_c), half.level_c);
            result.lag_s = half.target_time_s.map(|target_s| (skin_time_s - target_s).max(0.0));
        }
        if sign * (target_c - skin_c) >= 0.0 {
            // Met: from here on an ideal controller follows the target.
            result.lag_s = result.lag_s.or(half.target_time_s.map(|_| 0.0));
            result.rms_floor_c = (window > 0).then(|| (squares / window as f64).sqrt());
            return Ok(result);
        }
        if t <= FULL_WINDOW_S + TIME_SLACK_S {
            squares += (skin_c - target_c) * (skin_c - target_c);
        }
        previous = (t, skin_c);
    }
    Ok(result)
}

/// The overshoot of `t` (see the module documentation) in the direction `sign` (+1 cooling, −1 heating) \[°C\]:
/// the largest `sign · (target − skin)` over the contact rows after the touch, at least 0.
pub fn overshoot_c(t: &Trajectory, sign: f64) -> f64 {
    t.time_s
        .iter()
        .zip(&t.contact)
        .zip(t.target_skin_c.iter().zip(&t.skin_c))
        .filter(|((time, contact), _)| **time > TIME_SLACK_S && **contact)
        .map(|(_, (target, skin))| sign * (target - skin))
        .filter(|d| d.is_finite())
        .fold(0.0, f64::max)
}

/// The summary of a run (see the module documentation); `limit` from [`actuator_limit`].
pub fn summarise(
    spec: &RenderSpec,
    controller: &str,
    t: &Trajectory,
    contact: &ContactState,
    limit: ActuatorLimit,
) -> RenderSummary {
    let rms = |a: &[f64], b: &[f64], from: f64, to: f64| rms_between(&t.time_s, a, b, from, to);
    let half = half_drop(t, contact.target_c);
    let skin_half_time_s = (half.drop_c >= MIN_DROP_C)
        .then(|| crossing_time(&t.time_s, &t.skin_c, contact.skin_c, half.level_c, half.cooling))
        .flatten();
    let sign = if half.cooling { 1.0 } else { -1.0 };
    let overshoot_c = overshoot_c(t, sign);
    let first_fault = t.fault.iter().position(Option::is_some);
    RenderSummary {
        material: spec.material.name.clone(),
        controller: controller.to_string(),
        renderer: spec.pipeline.renderer.name().to_string(),
        window_end_s: spec.duration_s.min(FULL_WINDOW_S),
        rms_skin_0_5_c: rms(&t.skin_c, &t.target_skin_c, 0.0, EARLY_WINDOW_S),
        rms_skin_5_90_c: rms(&t.skin_c, &t.target_skin_c, EARLY_WINDOW_S, FULL_WINDOW_S),
        rms_skin_0_90_c: rms(&t.skin_c, &t.target_skin_c, 0.0, FULL_WINDOW_S),
        rms_truth_0_90_c: rms(&t.skin_c, &t.truth_skin_c, 0.0, FULL_WINDOW_S),
        rms_display_tracking_c: rms(&t.display_c, &t.display_setpoint_c, 0.0, FULL_WINDOW_S),
        overshoot_c,
        cooling: half.cooling,
        contact_target_c: contact.target_c,
        target_drop_c: half.drop_c,
        half_level_c: half.level_c,
        target_half_time_s: half.target_time_s,
        skin_half_time_s,
        lag_s: half.target_time_s.zip(skin_half_time_s).map(|(a, b)| b - a),
        actuator_limit_lag_s: limit.lag_s,
        actuator_limit_rms_c: limit.rms_floor_c,
        first_fault: first_fault.and_then(|i| t.fault[i]).map(|f| f.to_string()),
        first_fault_time_s: first_fault.map(|i| t.time_s[i]),
    }
}

impl RenderSummary {
    /// The end of the windows as the labels spell it: `90` for a full run, `10` for `--duration 10`, `7.5` for
    /// 7.5 s (the shortest decimal that reads back as the number).
    pub fn window_label(&self) -> String {
        format!("{}", self.window_end_s)
    }

    /// The JSON key of a field, following the windows actually used: `rms_skin_5_90_c` becomes `rms_skin_5_10_c`
    /// for a 10 s run (and likewise `rms_skin_0_90_c`, `rms_truth_0_90_c`); other keys are unchanged.
    pub fn json_key(&self, field: &str) -> String {
        match field.strip_suffix("_90_c") {
            Some(stem) if field.starts_with("rms_") => format!("{stem}_{}_c", self.window_label().replace('.', "p")),
            _ => field.to_string(),
        }
    }
}

/// A fixed-width text table of summaries, one row per run. The window labels follow the first summary's windows
/// (`rms5-10` for 10 s runs); runs of different lengths get one table each.
pub fn summary_table(summaries: &[RenderSummary]) -> String {
    let mut out = String::new();
    let mut rest = summaries;
    while let Some(first) = rest.first() {
        let same = rest.iter().take_while(|s| s.window_end_s == first.window_end_s).count();
        out.push_str(&table_of(&rest[..same]));
        rest = &rest[same..];
    }
    out
}

fn table_of(summaries: &[RenderSummary]) -> String {
    let end = summaries
        .first()
        .map_or_else(|| format!("{FULL_WINDOW_S}"), RenderSummary::window_label);
    let mut out = format!(
        "{:<10} {:<6} {:<4} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>7} {:>7} {:>7}  {}\n",
        "material",
        "ctrl",
        "rend",
        "rms0-5",
        format!("rms5-{end}"),
        format!("rms0-{end}"),
        "floor",
        "rmsTruth",
        "rmsDisp",
        "overshoot",
        "lag",
        "limit",
        "ratio",
        "fault"
    );
    let num = |v: Option<f64>, digits: usize| v.map_or("-".to_string(), |v| format!("{v:.digits$}"));
    for s in summaries {
        let ratio = s.lag_s.zip(s.actuator_limit_lag_s).map(|(lag, limit)| lag / limit);
        out.push_str(&format!(
            "{:<10} {:<6} {:<4} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9.4} {:>7} {:>7} {:>7}  {}\n",
            s.material,
            s.controller,
            s.renderer,
            num(s.rms_skin_0_5_c, 4),
            num(s.rms_skin_5_90_c, 4),
            num(s.rms_skin_0_90_c, 4),
            num(s.actuator_limit_rms_c, 4),
            num(s.rms_truth_0_90_c, 4),
            num(s.rms_display_tracking_c, 4),
            s.overshoot_c,
            num(s.lag_s, 3),
            num(s.actuator_limit_lag_s, 3),
            num(ratio.filter(|r| r.is_finite()), 2),
            s.first_fault.as_deref().unwrap_or("-"),
        ));
    }
    out.push_str(&format!(
        "(°C and s; rms = root mean square of skin − target over 0–5, 5–{end}, 0–{end} s after contact; floor = \
         rms0-{end} of an ideal controller at the actuator and safety-envelope limits (drive, set-point rate, display \
         range); rmsTruth, rmsDisp = of skin − truth and of plate − set-point over 0–{end} s; overshoot = largest skin \
         excursion beyond the target during contact; lag = skin minus target time at half of the target's drop; \
         limit = the same for the ideal controller; ratio = lag/limit)\n",
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_and_json_keys_follow_the_windows_actually_used() {
        let summary = |end: f64| RenderSummary {
            material: "wood".into(),
            controller: "model".into(),
            renderer: "fv".into(),
            window_end_s: end,
            rms_skin_0_5_c: Some(0.1),
            rms_skin_5_90_c: Some(0.2),
            rms_skin_0_90_c: Some(0.3),
            rms_truth_0_90_c: None,
            rms_display_tracking_c: None,
            overshoot_c: 0.0,
            cooling: true,
            contact_target_c: 30.0,
            target_drop_c: 2.0,
            half_level_c: 29.0,
            target_half_time_s: None,
            skin_half_time_s: None,
            lag_s: None,
            actuator_limit_lag_s: None,
            actuator_limit_rms_c: None,
            first_fault: None,
            first_fault_time_s: None,
        };
        let (short, full, odd) = (summary(10.0), summary(90.0), summary(7.5));
        assert_eq!(short.json_key("rms_skin_5_90_c"), "rms_skin_5_10_c");
        assert_eq!(short.json_key("rms_truth_0_90_c"), "rms_truth_0_10_c");
        assert_eq!(short.json_key("overshoot_c"), "overshoot_c");
        assert_eq!(full.json_key("rms_skin_0_90_c"), "rms_skin_0_90_c");
        assert_eq!(odd.json_key("rms_skin_0_90_c"), "rms_skin_0_7p5_c");
        let table = summary_table(&[short, full]);
        assert!(
            table.contains("rms5-10") && table.contains("over 0–5, 5–10, 0–10 s"),
            "{table}"
        );
        assert!(
            table.contains("rms5-90") && table.contains("over 0–5, 5–90, 0–90 s"),
            "{table}"
        );
    }

    #[test]
    fn rms_of_a_known_difference() {
        let t = [-1.0, 1.0, 2.0, 3.0, 6.0];
        let a = [9.0, 1.0, 2.0, 3.0, 4.0];
        let b = [0.0, 0.0, 0.0, 0.0, 0.0];
        let got = rms_between(&t, &a, &b, 0.0, 5.0).unwrap_or(f64::NAN);
        let want = ((1.0 + 4.0 + 9.0) / 3.0f64).sqrt();
        assert!((got - want).abs() < 1e-15, "rms {got} vs hand {want}");
        assert_eq!(rms_between(&t, &a, &b, 10.0, 20.0), None);
    }

    #[test]
    fn crossing_is_interpolated_between_rows() {
        // A straight line 30 − 2t sampled every 0.5 s crosses 27 at exactly 1.5 s; a line with its start between
        // rows crosses where the segment from the start does.
        let t: Vec<f64> = (1..=8).map(|k| 0.5 * k as f64).collect();
        let v: Vec<f64> = t.iter().map(|t| 30.0 - 2.0 * t).collect();
        let got = crossing_time(&t, &v, 30.0, 27.2, true).unwrap_or(f64::NAN);
        assert!((got - 1.4).abs() < 1e-12, "crossing {got} vs 1.4");
        assert_eq!(crossing_time(&t, &v, 30.0, 10.0, true), None);
        let rising: Vec<f64> = t.iter().map(|t| 20.0 + t).collect();
        let got = crossing_time(&t, &rising, 20.0, 21.25, false).unwrap_or(f64::NAN);
        assert!((got - 1.25).abs() < 1e-12, "rising crossing {got} vs 1.25");
        assert_eq!(crossing_time(&t, &v, 26.0, 27.0, true), Some(0.0));
    }
}
