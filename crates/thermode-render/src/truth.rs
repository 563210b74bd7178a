//! The ground truth of a render (`truth_skin_c`): the simulated finger touching the real material under the
//! reference finite-volume physics, converged in grid and time, at every row of the run.
//!
//! - The finger ([`RenderSpec::finger_skin`]) rests at its steady state in still air at the pipeline's ambient
//!   temperature until the touch, touches a fresh slab of the material (uniform at the object temperature) at
//!   t = 0 and returns to still air at the release, if any.
//! - Its contact resistance follows the finger's contact with the plate: R_c = 1/G with G the simulated finger's
//!   contact conductance ([`RenderSpec::plant_device`]: `--finger-contact`, else the hardware's device file; the
//!   default display's 1000 W/(m²·K) is the light touch R_c = 1e-3 m²K/W) — a finger that presses harder on the
//!   display presses harder on the material too.
//! - Time: adaptive TR-BDF2 ([`FvModel::advance_adaptive`]) with local error tolerance [`TRUTH_TOLERANCE_C`], the
//!   rows read from the steps' interpolant (time error about 1e-4 °C).
//! - Grid: the fv default grid refined [`FIRST_LEVEL`] times and once more, then further until the largest change
//!   between two successive levels over all rows is below [`TRUTH_CHANGE_C`]; the finer run is the truth. The grid
//!   converges at second order, so the finer run's own error is about a third of that change (aluminium, R_c
//!   1e-3, 90 s: change 3.3e-3 °C from level 1 to 2, level 2 within 1.3e-3 °C of level 6), within the 0.005 °C the
//!   truth is held to (test `truth_is_converged` in `tests/integration/truth.rs`).
//! - Read at [`RenderSpec::receptor_depth_m`]: the surface for the fv renderer, the epidermis centre for kron.

use thermode_model::fv::{FvConfig, FvEnvironment, FvModel};
use thermode_model::ParamError;

use crate::error::RenderError;
use crate::spec::RenderSpec;

/// Local error tolerance of the truth's adaptive time steps \[K\].
pub const TRUTH_TOLERANCE_C: f64 = 2e-5;
/// Largest change of the truth between two successive grid levels (over every row) that counts as converged \[°C\].
pub const TRUTH_CHANGE_C: f64 = 0.005;
/// The coarsest grid level the truth is computed on (refinements of [`FvConfig::default`]).
pub const FIRST_LEVEL: u32 = 1;
/// The finest grid level tried; a truth not converged by then is an error.
pub const LAST_LEVEL: u32 = 6;

/// The contact resistance of the truth [m²K/W]: 1 over the simulated finger's contact conductance with the plate.
pub fn truth_contact_resistance_m2k_w(spec: &RenderSpec) -> f64 {
    1.0 / spec.plant_device().plate.contact_conductance_w_m2k
}

/// The truth of `spec` at every row of its run (as many as [`RenderSpec::rows`]; row k ends at
/// (k + 1 − pre-contact ticks) ticks after the touch), converged as the [module documentation](self) says, with the
/// grid level used.
pub fn truth_skin_c(spec: &RenderSpec) -> Result<(Vec<f64>, u32), RenderError> {
    let mut previous = truth_at_level(spec, FIRST_LEVEL)?;
    for level in FIRST_LEVEL + 1..=LAST_LEVEL {
        let finer = truth_at_level(spec, level)?;
        let change = previous
            .iter()
            .zip(&finer)
            .map(|(a, b)| (a - b).abs())
            .fold(
                0.0,
                |m: f64, d| if d.is_nan() || m.is_nan() { f64::NAN } else { m.max(d) },
            );
        if change < TRUTH_CHANGE_C {
            return Ok((finer, level));
        }
        previous = finer;
    }
    Err(RenderError::Invalid(format!(
        "the ground truth of {} did not converge to {TRUTH_CHANGE_C} °C by grid level {LAST_LEVEL}",
        spec.material.name
    )))
}

/// The truth of `spec` on the default grid refined `level` times, at every row.
pub fn truth_at_level(spec: &RenderSpec, level: u32) -> Result<Vec<f64>, RenderError> {
    let config = FvConfig {
        contact_resistance_m2k_w: truth_contact_resistance_m2k_w(spec),
        tolerance_c: Some(TRUTH_TOLERANCE_C),
        ..FvConfig::default()
    }
    .refined(level);
    let (pre, contact_ticks, release) = spec.tick_counts();
    let depth_m = spec.receptor_depth_m();
    let dt = spec.tick_s();
    let ambient_c = spec.pipeline.ambient_c;
    let mut finger = FvModel::new(&spec.finger_skin, Some(&spec.material), &config)?;
    finger.set_steady_in_air(ambient_c)?;
    let mut rows = vec![read(&finger, depth_m); pre];
    rows.reserve(contact_ticks);
    finger.touch(spec.object_temperature_c())?;
    let contact_end = release.unwrap_or(contact_ticks).min(contact_ticks);
    phase(
        &mut finger,
        FvEnvironment::Object,
        (0, contact_end),
        dt,
        depth_m,
        &mut rows,
    )?;
    if contact_end < contact_ticks {
        let air = FvEnvironment::Air { ambient_c };
        phase(&mut finger, air, (contact_end, contact_ticks), dt, depth_m, &mut rows)?;
    }
    Ok(rows)
}

/// The finger's temperature at `depth_m` \[m\] (the surface value itself at depth 0).
fn read(finger: &FvModel, depth_m: f64) -> f64 {
    if depth_m == 0.0 {
        finger.surface_c()
    } else {
        finger.skin_temperature_at_depth_c(depth_m)
    }
}

/// Advances `finger` in `env` from tick `from` to tick `to` after the touch (`dt` \[s\] each), pushing the reading at
/// the end of every tick onto `rows`.
fn phase(
    finger: &mut FvModel,
    env: FvEnvironment,
    (from, to): (usize, usize),
    dt: f64,
    depth_m: f64,
    rows: &mut Vec<f64>,
) -> Result<(), ParamError> {
    if to <= from {
        return Ok(());
    }
    let duration_s = (to - from) as f64 * dt;
    let times = (1..=to - from).map(|j| if j == to - from { duration_s } else { j as f64 * dt });
    let before = rows.len();
    finger.advance_adaptive(env, duration_s, TRUTH_TOLERANCE_C, times, |state, _| {
        rows.push(read(state, depth_m))
    })?;
    // A state that became non-finite stops the stepping: its rows are NaN, which the run refuses.
    rows.resize(before + (to - from), f64::NAN);
    Ok(())
}
