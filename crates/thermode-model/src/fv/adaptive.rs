//! Error-controlled adaptive time stepping of a contact run: TR-BDF2 with the Hosea & Shampine (1996) embedded
//! error estimate ([`FvModel::step_with_error`]), steps taken across the output times and the rows read from the
//! step's cubic Hermite interpolant, so the number of steps follows the physics (tiny at the touch, seconds late
//! in the contact) rather than the output interval.
//!
//! Step lengths are quantised down to a ladder of exactly representable values, `q·2ᵉ` with q ∈ {1, 1.25, 1.5,
//! 1.75}: a step that is equal in intent to the previous one is equal in bits, so it reuses the cached elimination
//! of the matrix (the cache is keyed on the step's bits).

use super::FvModel;
use super::{bad, FvEnvironment, ORIGIN};
use crate::error::{At, ParamError};
use crate::params::Rule;

/// The first step after the touch \[s\] (the controller grows it from there; the jump at the touch needs it small).
const FIRST_STEP_S: f64 = 1.0 / 1_048_576.0;
/// The longest step \[s\]: keeps the interpolated rows between steps within the error the steps are held to.
pub(super) const MAX_STEP_S: f64 = 2.0;
/// The shortest step the controller may propose after a rejection \[s\]: a tolerance that needs shorter steps is
/// refused as unreachable (stepping stops with an error). Far below any physical time scale of skin and objects
/// (the most diffusive object in range, 0.1 mm cells at 25 m²/s, needs about 1e-12 s at the touch).
const MIN_STEP_S: f64 = 1e-16;
/// Safety factor of the step-size controller.
const SAFETY: f64 = 0.9;
/// Largest growth and shrink of the step from one attempt to the next.
const MAX_GROWTH: f64 = 4.0;
const MIN_SHRINK: f64 = 0.2;

/// The largest ladder value `q·2ᵉ` (q ∈ {1, 1.25, 1.5, 1.75}) not above `h` (> 0, finite, normal): exact in
/// binary, so equal intents give equal bits.
pub(super) fn ladder_floor(h: f64) -> f64 {
    let power = f64::from_bits(h.to_bits() & 0x7FF0_0000_0000_0000);
    let mantissa = h / power;
    (mantissa * 4.0).floor() / 4.0 * power
}

/// The next step after an attempt of `h_s` \[s\] whose error estimate was `error_c` against `tolerance_c` \[K\]
/// (third-order local error: the step scales with the cube root of the ratio), on the ladder, at most
/// `max_step_s`.
pub(super) fn next_step(h_s: f64, error_c: f64, tolerance_c: f64, max_step_s: f64) -> f64 {
    let factor = if error_c > 0.0 {
        SAFETY * (tolerance_c / error_c).cbrt()
    } else {
        MAX_GROWTH
    };
    let factor = if error_c > tolerance_c {
        factor.clamp(MIN_SHRINK, 0.9)
    } else {
        factor.clamp(1.0, MAX_GROWTH)
    };
    ladder_floor((h_s * factor).min(max_step_s))
}

/// Where an output row lies in the adaptive steps.
#[derive(Debug, Clone, Copy)]
pub(super) struct RowAt {
    /// Fraction of the last step at which the row lies, in \[0, 1\].
    pub theta: f64,
    /// Length of the last step \[s\].
    pub step_s: f64,
    /// Time of the row \[s\].
    pub time_s: f64,
    /// Number of the last step (1 for the first accepted step).
    pub step: usize,
}

/// Counts of an adaptive run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StepCounts {
    /// Steps taken.
    pub accepted: usize,
    /// Steps attempted and rejected (error above the tolerance), then retried shorter.
    pub rejected: usize,
}

/// Advances `model` in `env` from `start_s` to `end_s` \[s\] with steps of local error at most `tolerance_c` \[K\],
/// starting with a step of [`FIRST_STEP_S`]; calls `row(model, at)` at every time of `row_times_s` (increasing,
/// in (`start_s`, `end_s`]) as the steps pass it, `at` saying where in the step just taken it lies (read the state
/// there with [`FvModel::interpolate_last_step`] or [`FvModel::last_step_ends`]). Returns the counts and the
/// longest step taken \[s\].
pub(super) fn integrate(
    model: &mut FvModel,
    env: FvEnvironment,
    (start_s, end_s): (f64, f64),
    tolerance_c: f64,
    row_times_s: &mut dyn Iterator<Item = f64>,
    row: &mut dyn FnMut(&FvModel, RowAt),
) -> Result<(StepCounts, f64), ParamError> {
    let mut largest_step_s = 0.0f64;
    let mut counts = StepCounts::default();
    let mut time_s = start_s;
    let mut h = FIRST_STEP_S;
    let mut pending = row_times_s.next();
    while time_s < end_s {
        // The last step ends exactly at the end (and so leaves the ladder once).
        let step_s = if time_s + h >= end_s { end_s - time_s } else { h };
        let error_c = model.step_with_error(step_s, env, tolerance_c);
        if !error_c.is_finite() {
            // A non-finite state cannot become finite by shortening the step: stop with an error.
            return Err(stalled(time_s, step_s, error_c, tolerance_c));
        }
        if error_c > tolerance_c {
            counts.rejected += 1;
            h = next_step(step_s, error_c, tolerance_c, MAX_STEP_S);
            if h < MIN_STEP_S {
                // A tolerance that needs steps below the floor cannot be met: stop rather than loop on.
                return Err(stalled(time_s, step_s, error_c, tolerance_c));
            }
            continue;
        }
        counts.accepted += 1;
        largest_step_s = largest_step_s.max(step_s);
        let done_s = if step_s == end_s - time_s {
            end_s
        } else {
            time_s + step_s
        };
        while let Some(t) = pending.filter(|t| *t <= done_s) {
            let theta = ((t - time_s) / step_s).clamp(0.0, 1.0);
            let at = RowAt {
                theta,
                step_s,
                time_s: t,
                step: counts.accepted,
            };
            row(model, at);
            pending = row_times_s.next();
        }
        time_s = done_s;
        h = next_step(step_s, error_c, tolerance_c, MAX_STEP_S);
    }
    Ok((counts, largest_step_s))
}

/// The error of an adaptive run that cannot go on at `time_s` \[s\].
fn stalled(time_s: f64, step_s: f64, error_c: f64, tolerance_c: f64) -> ParamError {
    ParamError::Invalid {
        origin: ORIGIN.to_string(),
        message: format!(
            "adaptive stepping stalled at t = {time_s} s: a step of {step_s} s has a local error estimate of \
             {error_c} K against the tolerance {tolerance_c} K (non-finite state, or a tolerance too tight)"
        ),
    }
}

impl FvModel {
    /// Advances the model by `duration_s` \[s\] in `env` with error-controlled adaptive TR-BDF2 steps (local error
    /// estimate at most `tolerance_c` \[K\] per step, see [`FvModel::step_with_error`]) and calls `row(state, t)` at
    /// every time `t` of `row_times_s` (seconds from now, increasing, in (0, `duration_s`\]; others are skipped) with
    /// the state interpolated there (cubic Hermite within the step, one order above its local error): read any
    /// observable of `state` ([`FvModel::surface_c`], [`FvModel::skin_temperature_at_depth_c`], …). The model
    /// ends exactly `duration_s` later, its energy ledger advanced by every step. Allocates one copy of the model
    /// (the interpolation probe); stepping itself does not allocate. Errors if `env`, `duration_s` (positive,
    /// finite, at most [`crate::limits::DURATION`]) or `tolerance_c` (positive, finite) are invalid, or if stepping
    /// stalls (a non-finite state, or a tolerance that needs steps below 1e-16 s): the model is then left where
    /// it stopped.
    pub fn advance_adaptive(
        &mut self,
        env: FvEnvironment,
        duration_s: f64,
        tolerance_c: f64,
        row_times_s: impl IntoIterator<Item = f64>,
        mut row: impl FnMut(&FvModel, f64),
    ) -> Result<StepCounts, ParamError> {
        env.validate()?;
        Rule::Positive.check("duration_s", duration_s).at(ORIGIN)?;
        crate::limits::DURATION
            .rule()
            .check("duration_s", duration_s)
            .at(ORIGIN)?;
        Rule::Positive.check("tolerance_c", tolerance_c).at(ORIGIN)?;
        if env == FvEnvironment::Object && self.object_cells() == 0 {
            return Err(bad(
                "duration_s",
                duration_s,
                "cannot advance in contact: the model has no object",
            ));
        }
        let mut probe = self.clone();
        let mut times = row_times_s.into_iter().filter(|t| *t > 0.0 && *t <= duration_s);
        let mut at_row = |model: &FvModel, at: RowAt| {
            model.interpolate_last_step(at.theta, at.step_s, &mut probe);
            row(&probe, at.time_s);
        };
        let (counts, _) = integrate(self, env, (0.0, duration_s), tolerance_c, &mut times, &mut at_row)?;
        Ok(counts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ladder_values_are_exact_and_at_most_a_quarter_below() {
        for h in [1e-7, 3e-4, 0.01, 0.0123, 0.7, 1.0, 1.9999, 2.0, 5.5] {
            let q = ladder_floor(h);
            assert!(q <= h && q > 0.75 * h, "ladder_floor({h}) = {q}");
            // q·2⁻ᵉ is one of the four mantissas exactly.
            let power = f64::from_bits(q.to_bits() & 0x7FF0_0000_0000_0000);
            let m = q / power;
            assert!([1.0, 1.25, 1.5, 1.75].contains(&m), "mantissa {m} of {q}");
            assert_eq!(
                ladder_floor(q).to_bits(),
                q.to_bits(),
                "ladder value {q} is its own floor"
            );
        }
        // Two intents that differ in the last bit land on the same rung.
        let a: f64 = 0.1 * 3.0;
        let b: f64 = 0.3;
        assert_ne!(a.to_bits(), b.to_bits());
        assert_eq!(ladder_floor(a).to_bits(), ladder_floor(b).to_bits());
    }

    #[test]
    fn controller_shrinks_on_rejection_and_grows_on_small_errors() {
        let h = 0.01;
        assert!(next_step(h, 8e-4, 1e-4, 10.0) < h, "rejected step must shrink");
        assert!(next_step(h, 1e-7, 1e-4, 10.0) > h, "small error must grow the step");
        assert!(next_step(h, 0.0, 1e-4, 10.0) <= 4.0 * h);
        assert_eq!(next_step(1.0, 0.0, 1e-4, 2.0), 2.0, "capped at the largest step");
    }
}
