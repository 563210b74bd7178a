//! Offline rendering against the simulated display, as `thermode render` runs it: one channel pipeline drives a
//! [`SimulatedDisplay`] with a simulated finger resting on it, next to the ground truth (that finger touching the
//! real material), and every tick is recorded.
//!
//! # The run
//! - The simulated finger ([`RenderSpec::finger_skin`], default the fingertip) is the finite-volume finger — the
//!   reference physics — resting on the plate; its contact conductance is the device file's unless
//!   [`RenderSpec::finger_contact_w_m2k`] overrides it (real fingers press differently than the model assumes).
//! - Before the run the finger is at its steady state in still air and the plate at the temperature that draws
//!   exactly the heat still air would (`receptor − q_air/G`): the display has been rendering air when the finger is
//!   put on it. The hot side starts at the water temperature. The plant is then stepped one sensor sample period at
//!   0 A so that the first reading is a fresh sample of that state (otherwise the envelope would see the plate jump
//!   from the water temperature, an implausible rate).
//! - The display renders air for [`RenderSpec::pre_contact_s`], the finger touches the object at t = 0 and lets go
//!   at [`RenderSpec::release_at_s`] if given. One tick every 1/[`RenderSpec::rate_hz`] s.
//! - After each tick the plant is advanced by the tick in equal substeps of at most [`RenderSpec::plant_substep_s`]
//!   (default [`PLANT_SUBSTEP_S`]), the gated drive held. The plant's backward Euler is first order; 2 ms keeps its
//!   error below half the sensor's 0.01 °C resolution (test `plant_substep_convergence` in
//!   `tests/integration/run.rs`; figures in `docs/design-choices.md`).
//! - Truth: the simulated finger touching the real material under the reference fv physics, converged in grid and
//!   time to 0.005 °C at every row, its contact resistance 1/G with G the simulated finger's contact conductance
//!   (see [`crate::truth`]). The renderer's target is the same physics on the renderer's coarse grid, one step per
//!   tick, with the light-touch resistance [`LIGHT_TOUCH_RESISTANCE_M2K_W`]: with the default finger and display
//!   they differ only by the renderer's discretisation (a few hundredths of a °C at the first rows after a touch;
//!   the pipeline's calibration at the touch, [`PipelineConfig::calibrate_finger_at_touch`](thermode_pipeline::pipeline::PipelineConfig::calibrate_finger_at_touch), leaves a finger that
//!   matches the model as it is; a different finger gets a target computed for it, while the truth is that
//!   finger's own contact).
//! - Receptor depth: the target is the renderer's receptor — the skin surface for the fv renderer, the epidermis
//!   centre T1 (depth Δx₁/2) for the kron renderer — so the simulated finger on the display (`skin_c`) and the
//!   truth (`truth_skin_c`) are read at that same depth ([`RenderSpec::receptor_depth_m`]): at the surface for fv
//!   (the finger's receptor, bit for bit as before), and for kron at half the first layer of the *simulated
//!   finger's* skin ([`RenderSpec::finger_skin`]), interpolated between its finite-volume cells
//!   ([`FvModel::skin_temperature_at_depth_c`]). It is that skin's because the receptor is a place in the real
//!   finger (its own epidermis centre), and the truth is the same finger; with the default finger it is the
//!   renderer's own Δx₁/2. Comparing Kron's T1 with a surface temperature would count the gradient across half
//!   the epidermis as error (on aluminium several °C at the touch). The kron target remains Kron's model: what is
//!   left of truth − target is its known limit (an object held at its temperature, without heat capacity).
//! - Rows are recorded after each tick and plant step: `time_s` is the end of the tick's interval relative to the
//!   contact (0 at contact, negative before); temperatures are those at that time; current and set-point are those
//!   held over the interval.
//!
//! Deterministic: the only randomness is the sensor noise, seeded by [`RenderSpec::seed`] and the material's name
//! ([`noise_seed`]).

use std::io::Write;

use thermode_device::SimulatedDisplay;
use thermode_model::fv::{FvConfig, FvModel};
use thermode_pipeline::pipeline::ChannelPipeline;
use thermode_pipeline::renderer::{fv_config, Renderer, RendererKind, LIGHT_TOUCH_RESISTANCE_M2K_W};
use thermode_pipeline::stimulus::Stimulus;
pub use thermode_platform::csv_text::Precision;
use thermode_platform::csv_text::{self, CsvText};
use thermode_runtime::{Command, CommandError, ControlLoop, LoopConfig, Owner, VirtualLoop};

use crate::error::RenderError;
pub use crate::spec::noise_seed;
pub use crate::spec::{
    check_result_bytes, RenderSpec, BYTES_PER_ROW, DEFAULT_DURATION_S, DEFAULT_PRE_CONTACT_S, DEFAULT_RATE_HZ,
    DEFAULT_SEED, MAX_RUN_S, PLANT_SUBSTEP_S,
};
use crate::summary::{actuator_limit, summarise, RenderSummary};
pub use crate::trajectory::{finger_at_depth_c, ContactState, Plant, Trajectory};
use crate::truth::truth_skin_c;
use thermode_pipeline::self_test::SelfTestReport;

/// One offline render: its spec, its trajectory and its summary.
#[derive(Debug, Clone)]
pub struct RenderRun {
    /// What was run.
    pub spec: RenderSpec,
    /// Every tick.
    pub trajectory: Trajectory,
    /// The metrics of the paper's Figure 3.
    pub summary: RenderSummary,
    /// The display's start-up self-test against the pipeline's device file (`None`: the plant is that file).
    pub self_test: Option<SelfTestReport>,
}

/// The simulated display of `spec` at rest: the finger steady in air, the plate at the air-rendering temperature,
/// the hot side at the water temperature, one sample period stepped at 0 A (see the module documentation).
pub fn resting_plant(spec: &RenderSpec) -> Result<Plant, RenderError> {
    let device = spec.plant_device();
    let mut finger = FvModel::new(&spec.finger_skin, None, &FvConfig::default())?;
    finger.set_steady_in_air(spec.pipeline.ambient_c)?;
    let contact = device.plate.contact_conductance_w_m2k;
    let plate_c = finger.surface_c() - finger.surface_heat_flux_w_m2() / contact;
    let mut plant = SimulatedDisplay::new(&device, vec![finger], noise_seed(spec.seed, &spec.material.name))?;
    plant
        .channel_mut(0)?
        .set_temperatures(plate_c, device.ambient.water_c)?;
    plant.advance(1.0 / device.sensor.sample_rate_hz);
    Ok(plant)
}

/// A live fv renderer of the simulated finger's skin with the light-touch contact resistance on the default grid,
/// at rest in air: the ground truth before it was converged (stepped once per tick on the coarse grid, 0.02–0.09 °C
/// off at the first rows after a touch). Runs now use [`truth_skin_c`].
pub fn truth_renderer(spec: &RenderSpec) -> Result<Renderer, RenderError> {
    let grid = fv_config(LIGHT_TOUCH_RESISTANCE_M2K_W);
    Ok(Renderer::new(
        RendererKind::Fv,
        &spec.finger_skin,
        spec.pipeline.ambient_c,
        &grid,
    )?)
}

/// Runs `spec` with the controller its pipeline names.
pub fn render(spec: &RenderSpec) -> Result<RenderRun, RenderError> {
    spec.validate()?;
    let pipeline = ChannelPipeline::new(&spec.believed_pipeline())?;
    render_with(spec, pipeline)
}

/// Runs every spec, in parallel threads (one per spec); results in the order of `specs`. The first error is
/// returned. Work whose results would not fit in memory together ([`check_result_bytes`]) is refused before any
/// run starts.
pub fn render_all(specs: &[RenderSpec]) -> Result<Vec<RenderRun>, RenderError> {
    render_all_with_progress(specs, &|| {})
}

/// As [`render_all`], calling `run_done` as each run ends (a progress bar: runs done of `specs.len()`).
pub fn render_all_with_progress(
    specs: &[RenderSpec],
    run_done: &(dyn Fn() + Sync),
) -> Result<Vec<RenderRun>, RenderError> {
    check_result_bytes(specs)?;
    std::thread::scope(|scope| {
        let handles: Vec<_> = specs
            .iter()
            .map(|spec| {
                scope.spawn(move || {
                    let run = render(spec);
                    run_done();
                    run
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(RenderError::Invalid("a render thread panicked".into())))
            })
            .collect()
    })
}

/// Runs `spec` with a pipeline of the caller's (e.g. with a custom controller), on the daemon's loop core in
/// virtual time ([`VirtualLoop`]): the touch and the release are the loop's commands, each tick the loop's tick,
/// and the plant advanced after it in substeps of at most [`RenderSpec::plant_substep_s`]. A run that records a number that is not
/// finite is refused ([`RenderError::NonFinite`], see [`Trajectory::first_non_finite`]). A display its self-test
/// refused (fault 106) is refused the touch as the daemon refuses it: it renders air at 0 A throughout.
pub fn render_with(spec: &RenderSpec, mut pipeline: ChannelPipeline) -> Result<RenderRun, RenderError> {
    spec.validate()?;
    let plant = resting_plant(spec)?;
    let self_test = crate::self_test::self_test(spec, &pipeline)?;
    if let Some(report) = &self_test {
        pipeline.take_self_test(report, plant.time_s());
    }
    let (truth, _) = truth_skin_c(spec)?;
    let (pre, contact_ticks, release) = spec.tick_counts();
    let depth_m = spec.receptor_depth_m();
    let start_s = plant.time_s();
    let config = LoopConfig {
        rate_hz: spec.rate_hz,
        ..LoopConfig::default()
    };
    let core = ControlLoop::new(&config, plant, vec![pipeline], Vec::new(), Default::default())
        .map_err(|e| RenderError::Invalid(e.to_string()))?;
    let mut display = VirtualLoop::new(core, start_s, spec.tick_s());
    let mut trajectory = Trajectory::with_capacity(pre + contact_ticks);
    let mut at_contact = None;
    let touch = Stimulus::Touch {
        material: spec.material.clone(),
        object_c: spec.object_temperature_c(),
    };
    for (k, &truth_c) in truth.iter().enumerate().take(pre + contact_ticks) {
        if k == pre {
            command(&mut display, Command::stimulate(0, touch.clone(), Owner::Nobody))?;
            let core = display.core();
            at_contact = Some(ContactState {
                target_c: core.engine(0).map_or(f64::NAN, |p| p.renderer().receptor_c()),
                skin_c: finger_at_depth_c(core.device().channel(0)?, depth_m),
                plant: core.device().clone(),
            });
        }
        if release.is_some_and(|r| k == pre + r) {
            command(&mut display, Command::Release { channel: 0 })?;
        }
        display.tick();
        display.advance(spec.substeps());
        let time_s = (k + 1) as f64 * spec.tick_s() - pre as f64 * spec.tick_s();
        let core = display.core();
        trajectory.record(time_s, truth_c, &core.status()[0].telemetry, core.device(), depth_m);
    }
    let contact = at_contact.ok_or_else(|| RenderError::Invalid("the run never reached the touch".into()))?;
    let controller = display
        .core()
        .engine(0)
        .map_or("", |p| p.controller().name())
        .to_string();
    if let Some((quantity, row)) = trajectory.first_non_finite() {
        let column = trajectory.numbers().find(|(name, _)| *name == quantity).map(|(_, c)| c);
        return Err(RenderError::NonFinite {
            material: spec.material.name.clone(),
            controller,
            quantity,
            value: column.map_or(f64::NAN, |c| c[row]),
            time_s: trajectory.time_s[row],
        });
    }
    let limit = actuator_limit(spec, &trajectory, &contact)?;
    let summary = summarise(spec, &controller, &trajectory, &contact, limit);
    Ok(RenderRun {
        spec: spec.clone(),
        trajectory,
        summary,
        self_test,
    })
}

/// Gives `command` to the render's loop at once; a channel its self-test refused is refused it, as on the daemon,
/// and renders on in air.
fn command(display: &mut VirtualLoop<Plant, ChannelPipeline>, command: Command) -> Result<(), RenderError> {
    match display.core_mut().command(command) {
        Ok(_) | Err(CommandError::Faulted { .. }) => Ok(()),
        Err(e) => Err(RenderError::Invalid(format!(
            "the display refused the run's stimulus: {e}"
        ))),
    }
}

/// The CSV columns, in order.
pub const CSV_HEADER: [&str; 18] = [
    "time_s",
    "truth_skin_c",
    "target_skin_c",
    "skin_c",
    "model_skin_c",
    "display_setpoint_c",
    "requested_setpoint_c",
    "display_c",
    "sensor_c",
    "plate_estimate_c",
    "current_a",
    "hot_side_c",
    "contact",
    "fault",
    "material",
    "controller",
    "renderer",
    "fault_description",
];

/// Writes the runs as one CSV (header first, then every run's rows in order). `time_s` in Rust's shortest
/// round-trip form, the other numbers as `precision` says; `fault` is the numeric fault code (empty without fault); `contact` is 0 or 1.
/// The columns are the [`Trajectory`] fields of the same names. `target_skin_c` is the renderer's receptor, and
/// `skin_c` (the simulated finger on the display) and `truth_skin_c` (that finger touching the real material) are
/// read at the same depth: the skin surface with `renderer` = `fv`, the centre of the finger's epidermis (Kron's
/// T1, depth Δx₁/2) with `renderer` = `kron` ([`RenderSpec::receptor_depth_m`]). `model_skin_c` is the
/// pipeline's own display-finger model at its receptor (the same node as the target).
pub fn write_csv(runs: &[RenderRun], precision: Precision, sink: &mut dyn Write) -> Result<(), csv::Error> {
    sink.write_all(format!("{}\n", CSV_HEADER.join(",")).as_bytes())?;
    for run in runs {
        let t = &run.trajectory;
        let mut run_fields = CsvText::new();
        for text in [
            run.spec.material.name.as_str(),
            run.summary.controller.as_str(),
            run.spec.pipeline.renderer.name(),
        ] {
            run_fields.push_byte(b',');
            run_fields.push_field(text);
        }
        run_fields.push_byte(b',');
        csv_text::write_rows(sink, t.len(), |rows, out| {
            for row in rows {
                out.push_f64(t.time_s[row]);
                out.push_byte(b',');
                for column in [
                    &t.truth_skin_c,
                    &t.target_skin_c,
                    &t.skin_c,
                    &t.model_skin_c,
                    &t.display_setpoint_c,
                    &t.requested_setpoint_c,
                    &t.display_c,
                    &t.sensor_c,
                    &t.plate_estimate_c,
                    &t.current_a,
                    &t.hot_side_c,
                ] {
                    out.push_number(column[row], precision);
                    out.push_byte(b',');
                }
                out.push_byte(if t.contact[row] { b'1' } else { b'0' });
                out.push_byte(b',');
                if let Some(fault) = t.fault[row] {
                    out.push_bytes(fault.code().to_string().as_bytes());
                }
                out.push_bytes(run_fields.as_bytes());
                if let Some(fault) = t.fault[row] {
                    out.push_field(fault.description());
                }
                out.push_byte(b'\n');
            }
        })?;
    }
    sink.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_non_finite_number_is_found_in_csv_order() {
        let mut t = Trajectory::with_capacity(3);
        for (k, time_s) in [-0.01, 0.0, 0.01].into_iter().enumerate() {
            t.time_s.push(time_s);
            for column in [
                &mut t.truth_skin_c,
                &mut t.target_skin_c,
                &mut t.skin_c,
                &mut t.model_skin_c,
                &mut t.requested_setpoint_c,
                &mut t.display_setpoint_c,
                &mut t.display_c,
                &mut t.sensor_c,
                &mut t.plate_estimate_c,
                &mut t.current_a,
                &mut t.hot_side_c,
            ] {
                column.push(30.0 + k as f64);
            }
            t.contact.push(k > 0);
            t.fault.push(None);
        }
        assert_eq!(t.first_non_finite(), None);
        t.hot_side_c[1] = f64::INFINITY;
        t.skin_c[2] = f64::NAN;
        assert_eq!(t.first_non_finite(), Some(("skin_c", 2)));
        let names: Vec<&str> = t.numbers().map(|(name, _)| name).collect();
        assert_eq!(names, CSV_HEADER[..12].to_vec(), "numeric columns in CSV order");
    }
}
