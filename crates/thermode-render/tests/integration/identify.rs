//! `thermode identify` on the simulated display (issue: identify a display): on plants whose hidden thermal
//! parameters are each up to 30 % off the device file the controller believes, every identified parameter is within
//! 10 % of the hidden one, and the model controller with the identified file renders the paper's materials with an
//! RMS skin error within 1.05 × the one it reaches with the true file.

use thermode_device::config::SELF_TEST_LAG_ERROR;
use thermode_device::DeviceConfig;
use thermode_model::materials::paper_materials;
use thermode_model::peltier::PeltierDatasheet;
use thermode_pipeline::{ControllerKind, PipelineConfig};
use thermode_render::identify::identify_simulated;
use thermode_render::run::render_all;
use thermode_render::RenderSpec;

/// The mean RMS skin error (0–90 s) of the model controller believing `believed` on the hardware `hardware`, over
/// the paper's five materials.
fn mean_rms_c(believed: &DeviceConfig, hardware: &DeviceConfig) -> f64 {
    let specs: Vec<RenderSpec> = paper_materials()
        .into_iter()
        .map(|material| {
            let mut spec = RenderSpec::new(PipelineConfig::new(*believed, ControllerKind::Model), material);
            spec.hardware = Some(*hardware);
            spec
        })
        .collect();
    let runs = render_all(&specs).unwrap_or_else(|e| panic!("{e}"));
    runs.iter()
        .map(|r| r.summary.rms_skin_0_90_c.unwrap_or(f64::NAN))
        .sum::<f64>()
        / runs.len() as f64
}

/// A plant with every identified parameter scaled by its factor (Peltier datasheet I_max, V_max, ΔT_max; plate and
/// hot-side capacities; water conductance; sensor time constant), Q_max kept consistent.
fn plant(factors: [f64; 7]) -> DeviceConfig {
    let base = DeviceConfig::default();
    let mut d = base;
    let mut p = PeltierDatasheet {
        imax_a: base.peltier.imax_a * factors[0],
        vmax_v: base.peltier.vmax_v * factors[1],
        dtmax_k: base.peltier.dtmax_k * factors[2],
        ..base.peltier
    };
    p.qmax_w = p.predicted_qmax_w();
    d.peltier = p;
    d.plate.heat_capacity_j_k *= factors[3];
    d.hot_side.heat_capacity_j_k *= factors[4];
    d.hot_side.water_conductance_w_k *= factors[5];
    d.sensor.time_constant_s *= factors[6];
    d.drive.current_limit_a = d.drive.current_limit_a.min(d.peltier.imax_a);
    d
}

fn named(d: &DeviceConfig) -> [(&'static str, f64); 8] {
    [
        ("peltier.imax_a", d.peltier.imax_a),
        ("peltier.vmax_v", d.peltier.vmax_v),
        ("peltier.dtmax_k", d.peltier.dtmax_k),
        ("plate.heat_capacity_j_k", d.plate.heat_capacity_j_k),
        ("hot_side.heat_capacity_j_k", d.hot_side.heat_capacity_j_k),
        ("hot_side.water_conductance_w_k", d.hot_side.water_conductance_w_k),
        ("ambient.water_c", d.ambient.water_c),
        ("sensor.time_constant_s", d.sensor.time_constant_s),
    ]
}

#[test]
fn identify_recovers_every_hidden_parameter_within_ten_percent() {
    let believed = DeviceConfig::default();
    for factors in [
        [1.3, 0.7, 1.2, 0.75, 1.3, 0.7, 1.3],
        [0.75, 1.3, 0.8, 1.3, 0.7, 1.3, 0.7],
    ] {
        let hidden = plant(factors);
        let (fit, identified) = identify_simulated(&believed, &hidden, 3).unwrap_or_else(|e| panic!("{e}"));
        for ((name, got), (_, want)) in named(&identified).into_iter().zip(named(&hidden)) {
            let error = got / want - 1.0;
            eprintln!(
                "{name}: identified {got:.5}, hidden {want:.5} ({:+.2} %)",
                100.0 * error
            );
            assert!(
                error.abs() < 0.10,
                "{name}: identified {got} vs hidden {want} (factors {factors:?}; fit {:?})",
                fit.relative_sd
            );
        }
        // The plate and sensor-lag uncertainties the identified file states cover the real errors of its capacity
        // and time constant, and are far below a datasheet file's 0.2 and 0.5; the sensor lag's is at least the
        // start-up self-test's own error (SELF_TEST_LAG_ERROR), never above it by the fit alone.
        for (what, got, want, stated, stated_at_most) in [
            (
                "plate capacity",
                identified.plate.heat_capacity_j_k,
                hidden.plate.heat_capacity_j_k,
                identified.render.plate_uncertainty,
                0.1,
            ),
            (
                "sensor time constant",
                identified.sensor.time_constant_s,
                hidden.sensor.time_constant_s,
                identified.render.sensor_lag_uncertainty,
                SELF_TEST_LAG_ERROR,
            ),
        ] {
            let error = got / want - 1.0;
            eprintln!(
                "{what} off by {:+.2} %, stated uncertainty {:.2} %",
                100.0 * error,
                100.0 * stated
            );
            assert!(
                error.abs() <= stated && stated <= stated_at_most,
                "{what} off by {error}, stated uncertainty {stated} (at most {stated_at_most})"
            );
        }
        let (with_identified, with_true) = (mean_rms_c(&identified, &hidden), mean_rms_c(&hidden, &hidden));
        eprintln!("mean RMS with the identified file {with_identified:.5} °C, with the true file {with_true:.5} °C");
        assert!(
            with_identified <= 1.05 * with_true,
            "the identified file's RMS {with_identified} °C vs the true file's {with_true} °C (factors {factors:?})"
        );
    }
}

/// Issue 26 (item 6): with only the sensor's lag 30 % off the file (slower and faster), the file `thermode identify`
/// makes of the simulated plant (the default file believed) brings the model controller within 1.05 × the mean RMS
/// it reaches with the true file. With the datasheet file the slower sensor costs 0.146 °C against 0.142 and a
/// 0.65 °C overshoot (`scripts/plant-sweep --identified`).
#[test]
fn an_identified_file_renders_as_well_as_the_true_one_on_a_sensor_lag_off_its_file() {
    let believed = DeviceConfig::default();
    for factor in [1.3, 0.7] {
        let hidden = plant([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, factor]);
        let (_, identified) = identify_simulated(&believed, &hidden, 1).unwrap_or_else(|e| panic!("{e}"));
        let (with_identified, with_true) = (mean_rms_c(&identified, &hidden), mean_rms_c(&hidden, &hidden));
        eprintln!(
            "τ × {factor}: identified τ {:.4} s (true {:.4}); mean RMS with the identified file {with_identified:.5} °C, \
             with the true file {with_true:.5} °C",
            identified.sensor.time_constant_s, hidden.sensor.time_constant_s
        );
        assert!(
            with_identified <= 1.05 * with_true,
            "τ × {factor}: the identified file's RMS {with_identified} °C vs the true file's {with_true} °C"
        );
    }
}
