//! The finger on the plate: the mapping from the physical skin-to-plate contact conductance to each model's
//! receptor-node conductance, and its purpose — the Kron and the finite-volume finger draw about the same heat from
//! the same plate.

use thermode_device::{default_finger, DeviceConfig, PlateFinger};
use thermode_model::fv::FvModel;
use thermode_model::kron::KronModel;
use thermode_model::Skin;

#[test]
fn receptor_conductances_follow_the_receptor_depth() {
    let h = DeviceConfig::default().plate.contact_conductance_w_m2k;
    let epidermis = &Skin::fingertip().layers[0];
    // Kron's receptor is the epidermis centre: half the epidermis lies in series with the contact.
    let want = 1.0 / (epidermis.thickness_m / (2.0 * epidermis.conductivity_w_mk) + 1.0 / h);
    let kron = <KronModel as PlateFinger>::fingertip().unwrap_or_else(|e| panic!("{e}"));
    let got = kron.receptor_conductance_w_m2k(h);
    assert!((got - want).abs() < 1e-9 * want, "kron {got} vs {want} W/m²K");
    // The finite-volume receptor is the surface itself.
    let fv = default_finger().unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(fv.receptor_conductance_w_m2k(h), h);
    println!("contact {h} W/m²K: Kron receptor conductance {got:.1} W/m²K");
}

/// Heat flux [W/m²] from a finger into a plate held at 25 °C, at 1, 5, 20 and 60 s.
fn fluxes<F: PlateFinger>(mut finger: F, contact_w_m2k: f64) -> Vec<f64> {
    let g = finger.receptor_conductance_w_m2k(contact_w_m2k);
    let mut out = Vec::new();
    for n in 1..=60_000 {
        finger.step_on_plate(1e-3, g, 25.0);
        if [1000, 5000, 20_000, 60_000].contains(&n) {
            out.push(g * (finger.receptor_c() - 25.0));
        }
    }
    out
}

#[test]
fn both_fingers_draw_about_the_same_heat_from_the_same_plate() {
    let h = DeviceConfig::default().plate.contact_conductance_w_m2k;
    let kron = fluxes(
        <KronModel as PlateFinger>::fingertip().unwrap_or_else(|e| panic!("{e}")),
        h,
    );
    let fv = fluxes(
        <FvModel as PlateFinger>::fingertip().unwrap_or_else(|e| panic!("{e}")),
        h,
    );
    for (i, t) in [1, 5, 20, 60].iter().enumerate() {
        let rel = kron[i] / fv[i] - 1.0;
        println!(
            "t = {t} s: Kron {:.0} W/m², fv {:.0} W/m² ({:+.1} %)",
            kron[i],
            fv[i],
            100.0 * rel
        );
        // Kron lumps the epidermis into one node, so its first second differs most; 15 % covers it. Handing Kron
        // the surface contact conductance directly would put it 50 % above fv at 1 s.
        assert!(rel.abs() < 0.15, "t = {t} s: Kron {} vs fv {} W/m²", kron[i], fv[i]);
    }
}
