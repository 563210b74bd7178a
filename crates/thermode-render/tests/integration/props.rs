//! Property test: random and hostile stimulus sequences — touches of random materials (extreme properties
//! included) at random and extreme temperatures, releases, direct temperatures and rates (NaN, infinite, far out of
//! range included), material switches during contact — through the whole pipeline and the simulated display, with
//! either renderer and either controller. Whatever happens, no drive ever leaves the envelope: the current is
//! finite and within the drive limit, there is no heating while the measured display is at or above the effective
//! maximum and no cooling at or below the minimum, the shaped set-point stays within the limits, and a refused
//! stimulus is an error, never a panic.

use crate::common;

use common::{material, Loop};
use proptest::prelude::*;
use thermode_model::Material;
use thermode_pipeline::{ControllerKind, RendererKind, ShippedDisplay, Stimulus};

/// A number from a hostile mix: ordinary values, extremes, and non-finite values.
fn hostile(ordinary: std::ops::Range<f64>) -> impl Strategy<Value = f64> {
    prop_oneof![
        6 => ordinary,
        1 => prop::sample::select(vec![
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -1e300,
            1e300,
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            -273.15,
            1e6,
        ]),
    ]
}

fn random_material() -> impl Strategy<Value = Material> {
    let paper = prop::sample::select(vec!["aluminium", "steel", "stone", "wood", "rubber", "copper", "cork"])
        .prop_map(material);
    let wild = (
        hostile(1e-3..1e3),
        hostile(10.0..1e4),
        hostile(100.0..5e3),
        prop_oneof![1e-4..0.05, Just(1e-9), Just(0.5)],
    )
        .prop_map(|(k, rho, c, thickness)| Material {
            name: "random".into(),
            conductivity_w_mk: k,
            density_kg_m3: rho,
            specific_heat_j_kgk: c,
            thickness_m: thickness,
            source: "proptest".into(),
        });
    prop_oneof![3 => paper, 1 => wild]
}

fn stimulus() -> impl Strategy<Value = Stimulus> {
    prop_oneof![
        1 => Just(Stimulus::Air),
        3 => (random_material(), hostile(-60.0..160.0))
            .prop_map(|(material, object_c)| Stimulus::Touch { material, object_c }),
        2 => (hostile(0.0..60.0), hostile(-5.0..30.0)).prop_map(|(temp_c, rate_c_per_s)| Stimulus::Direct { temp_c, rate_c_per_s }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn no_drive_ever_leaves_the_envelope(
        kron in any::<bool>(),
        model in any::<bool>(),
        events in prop::collection::vec((1usize..150, stimulus()), 1..10),
    ) {
        let display = ShippedDisplay::Default;
        let controller = if model { ControllerKind::Model } else { common::pid(display) };
        let mut spec = common::spec(display, controller, "aluminium");
        spec.pipeline.renderer = if kron { RendererKind::Kron } else { RendererKind::Fv };
        let limit_a = spec.pipeline.device.drive.current_limit_a;
        let config = spec.pipeline.envelope;
        let mut lp = Loop::new(&spec);
        for (ticks, stimulus) in events {
            let valid = stimulus.validate().is_ok();
            let accepted = lp.pipeline.set_stimulus(stimulus.clone());
            prop_assert!(valid || accepted.is_err(), "invalid stimulus accepted: {:?}", stimulus);
            for _ in 0..ticks {
                let t = lp.tick();
                prop_assert!(t.current_a.is_finite() && t.current_a.abs() <= limit_a,
                    "current {} A beyond ±{} A", t.current_a, limit_a);
                prop_assert!(!(t.current_a > 0.0 && t.sensor_c >= t.max_c),
                    "heating {} A with the display measured at {} °C ≥ max {}", t.current_a, t.sensor_c, t.max_c);
                prop_assert!(!(t.current_a < 0.0 && t.sensor_c <= t.min_c),
                    "cooling {} A with the display measured at {} °C ≤ min {}", t.current_a, t.sensor_c, t.min_c);
                let sp = t.telemetry.display_setpoint_c;
                prop_assert!(sp >= config.min_display_c && sp <= config.max_display_c,
                    "set-point {} °C outside [{}, {}]", sp, config.min_display_c, config.max_display_c);
                prop_assert!(t.fault.is_none() || t.current_a == 0.0, "drive {} A under fault {:?}", t.current_a, t.fault);
            }
        }
    }
}
