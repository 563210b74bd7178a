//! The ground truth of a render (`truth_skin_c`, [`thermode_render::truth`]): converged to 0.005 °C at every row
//! against a refined fv (two grid levels finer, and an independent contact simulation of the model crate), its
//! contact resistance following the simulated finger's contact setting, a release returning the finger to air,
//! and the render's column being exactly that truth.

use crate::common;

use common::{pid, spec};
use thermode_model::fv::{simulate_contact, ContactSpec, FvConfig};
use thermode_pipeline::{ControllerKind, RendererKind, ShippedDisplay};
use thermode_render::render;
use thermode_render::truth::{truth_at_level, truth_contact_resistance_m2k_w, truth_skin_c};
use thermode_render::RenderSpec;

fn short(material: &str, duration_s: f64) -> RenderSpec {
    let mut s = spec(ShippedDisplay::Default, ControllerKind::Model, material);
    s.duration_s = duration_s;
    s.pre_contact_s = 0.5;
    s
}

fn max_abs_difference(a: &[f64], b: &[f64]) -> (f64, usize) {
    assert_eq!(a.len(), b.len(), "row counts");
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .enumerate()
        .fold((0.0, 0), |(m, at), (i, d)| if d > m { (d, i) } else { (m, at) })
}

#[test]
fn truth_is_converged_within_five_millidegrees_of_a_refined_fv_at_every_row() {
    let mut cases = vec![short("aluminium", 90.0), short("wood", 30.0)];
    let mut released = short("steel", 20.0);
    released.release_at_s = Some(7.5);
    cases.push(released);
    let mut kron = short("stone", 10.0);
    kron.pipeline.renderer = RendererKind::Kron;
    cases.push(kron);
    let mut pressed = short("aluminium", 10.0);
    pressed.finger_contact_w_m2k = Some(5000.0);
    cases.push(pressed);
    for s in &cases {
        let (truth, level) = truth_skin_c(s).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(truth.len() as u64, s.rows());
        let refined = truth_at_level(s, level + 2).unwrap_or_else(|e| panic!("{e}"));
        let (worst, row) = max_abs_difference(&truth, &refined);
        println!(
            "{} ({:?}, release {:?}, G {:?}): level {level}, max |truth − level {}| = {worst:.2e} °C at row {row}",
            s.material.name,
            s.pipeline.renderer,
            s.release_at_s,
            s.finger_contact_w_m2k,
            level + 2
        );
        assert!(
            worst <= 0.005,
            "{}: truth {} vs refined {} at row {row}",
            s.material.name,
            truth[row],
            refined[row]
        );
    }
}

#[test]
fn truth_agrees_with_the_model_crates_converged_contact_simulation() {
    // Independent path: simulate_contact (its own row recording) on a grid four times finer than the truth's
    // usual level, with a tight time tolerance.
    let s = short("aluminium", 30.0);
    let (truth, _) = truth_skin_c(&s).unwrap_or_else(|e| panic!("{e}"));
    let config = FvConfig {
        contact_resistance_m2k_w: 1e-3,
        tolerance_c: Some(1e-7),
        ..FvConfig::default()
    }
    .refined(4);
    let contact = ContactSpec {
        ambient_c: s.pipeline.ambient_c,
        object_c: s.object_temperature_c(),
        duration_s: s.duration_s,
        output_dt_s: s.tick_s(),
        ..ContactSpec::default()
    };
    let reference = simulate_contact(&s.finger_skin, &s.material, &config, &contact).unwrap();
    let pre = (s.pre_contact_s * s.rate_hz).round() as usize;
    // Row pre − 1 is the touch (t = 0, the finger at rest), as the reference's first row.
    let (worst, row) = max_abs_difference(&truth[pre - 1..], &reference.surface_c);
    println!("aluminium 30 s: max |truth − simulate_contact level 4| = {worst:.2e} °C at row {row}");
    assert!(worst <= 0.005, "truth vs reference: {worst} °C at contact row {row}");
    // Before the touch every row is the finger at rest in air (bit for bit one value), the reference's first row.
    assert!(
        truth[..pre].iter().all(|c| c.to_bits() == truth[0].to_bits()),
        "pre-contact rows differ"
    );
    assert!(
        (truth[0] - reference.surface_c[0]).abs() <= 0.005,
        "resting finger: truth {} vs reference {}",
        truth[0],
        reference.surface_c[0]
    );
}

#[test]
fn truth_contact_resistance_follows_the_fingers_contact_setting() {
    let light = short("aluminium", 5.0);
    assert_eq!(
        truth_contact_resistance_m2k_w(&light),
        1e-3,
        "default display: 1000 W/(m²K)"
    );
    let mut firm = light.clone();
    firm.finger_contact_w_m2k = Some(5000.0);
    assert_eq!(truth_contact_resistance_m2k_w(&firm), 2e-4);
    let (light_truth, _) = truth_skin_c(&light).unwrap();
    let (firm_truth, _) = truth_skin_c(&firm).unwrap();
    // 23 °C aluminium: the firmer contact pulls the surface further down at once (analytic: the drop across the
    // contact resistance decays as exp(β²t)erfc(β√t), β ∝ 1/R_c).
    let first = (light.pre_contact_s * light.rate_hz).round() as usize;
    assert!(
        firm_truth[first] < light_truth[first] - 1.0,
        "first row after the touch: firm {} vs light {}",
        firm_truth[first],
        light_truth[first]
    );
    // And it is the fv contact with R_c = 2e-4 itself.
    let config = FvConfig {
        contact_resistance_m2k_w: 2e-4,
        ..FvConfig::default()
    }
    .refined(4);
    let contact = ContactSpec {
        duration_s: 5.0,
        output_dt_s: firm.tick_s(),
        ..ContactSpec::default()
    };
    let reference = simulate_contact(&firm.finger_skin, &firm.material, &config, &contact).unwrap();
    let (worst, row) = max_abs_difference(&firm_truth[first - 1..], &reference.surface_c);
    assert!(
        worst <= 0.005,
        "firm truth vs R_c 2e-4 reference: {worst} °C at row {row}"
    );
}

#[test]
fn render_records_the_converged_truth_and_a_release_returns_to_air() {
    let mut s = short("steel", 6.0);
    s.pipeline.controller = pid(ShippedDisplay::Default);
    s.release_at_s = Some(3.0);
    let run = render(&s).unwrap_or_else(|e| panic!("{e}"));
    let (truth, _) = truth_skin_c(&s).unwrap();
    assert_eq!(
        run.trajectory.truth_skin_c, truth,
        "the render's truth column is truth_skin_c"
    );
    let release_row = ((s.pre_contact_s + 3.0) * s.rate_hz).round() as usize;
    let (at_release, end) = (truth[release_row - 1], truth[truth.len() - 1]);
    assert!(
        end > at_release + 0.5,
        "after letting go of 23 °C steel the skin rewarms: {at_release} → {end} °C"
    );
}
