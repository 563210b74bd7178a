//! Physics tests of `thermode_model::peltier`: energy conservation, the datasheet points, the miniature module's
//! parameters, heating versus cooling capacity, the optimum current and the feedforward inverse.

use thermode_model::peltier::{PeltierDatasheet, PeltierModule, DEFAULT_HOT_SIDE_K, KELVIN_OFFSET};
use thermode_model::ParamError;

fn mini() -> PeltierModule {
    PeltierModule::from_datasheet(&PeltierDatasheet::default()).unwrap_or_else(|e| panic!("default datasheet: {e}"))
}

/// The hot-side temperature of the datasheet in °C.
fn th_c() -> f64 {
    DEFAULT_HOT_SIDE_K - KELVIN_OFFSET
}

fn assert_close(got: f64, want: f64, rel: f64, what: &str) {
    let tol = rel * want.abs().max(1e-300);
    assert!(
        (got - want).abs() <= tol,
        "{what}: got {got} vs want {want} (tolerance {tol})"
    );
}

#[test]
fn energy_is_conserved_at_every_operating_point() {
    let m = mini();
    let mut worst = 0.0f64;
    for i in -30..=30 {
        let current = f64::from(i) * 0.15;
        for (display_c, hot_c) in [(32.0, 23.0), (15.0, 45.0), (48.0, 20.0), (25.0, 25.0), (-10.0, 60.0)] {
            let qd = m.heat_into_display_w(current, display_c, hot_c);
            let qh = m.heat_into_hot_side_w(current, display_c, hot_c);
            let p = m.electrical_power_w(current, display_c, hot_c);
            // The scale is at least the size of one term S·I·T or K·ΔT; at I = 0 and ΔT = 0 all flows vanish.
            let scale = (qd.abs() + qh.abs() + p.abs()).max(1e-3);
            let rel = (qd + qh - p).abs() / scale;
            worst = worst.max(rel);
            assert!(
                rel <= 1e-12,
                "I={current} Td={display_c} Th={hot_c}: qd+qh={} vs V·I={p}",
                qd + qh
            );
        }
    }
    println!("worst relative energy imbalance {worst:e}");
}

/// `display_heat_terms_w` bounds what a relative error u of S, R and K can do to the heat into the display: scaling
/// all three by 1 ± u moves `heat_into_display_w` by at most u times the terms' sum (equality when every term has
/// the sign of the change), and at zero current the sum is the conduction |K ΔT|.
#[test]
fn the_heat_terms_bound_the_effect_of_parameter_errors() {
    let m = mini();
    for current in [-2.8, -0.7, 0.0, 0.4, 2.8] {
        for (display_c, hot_c) in [(32.0, 23.0), (15.0, 45.0), (25.0, 25.0)] {
            let terms_w = m.display_heat_terms_w(current, display_c, hot_c);
            let q_w = m.heat_into_display_w(current, display_c, hot_c);
            for u in [-0.3, 0.3] {
                let scaled = PeltierModule::new(
                    m.seebeck_v_k * (1.0 + u),
                    m.resistance_ohm * (1.0 + u),
                    m.conductance_w_k * (1.0 + u),
                )
                .unwrap_or_else(|e| panic!("{e}"));
                let moved_w = (scaled.heat_into_display_w(current, display_c, hot_c) - q_w).abs();
                assert!(
                    moved_w <= 0.3 * terms_w * (1.0 + 1e-12),
                    "I={current} Td={display_c} Th={hot_c} u={u}: moved {moved_w} W, bound {} W",
                    0.3 * terms_w
                );
            }
        }
    }
    assert_close(
        m.display_heat_terms_w(0.0, 32.0, 23.0),
        m.conductance_w_k * 9.0,
        1e-12,
        "conduction at rest",
    );
}

#[test]
fn mini_module_parameters_match_the_expected_values() {
    let m = mini();
    // Independent evaluation of the formulas at T_h = 298.15 K.
    let (imax, vmax, dt, th) = (2.8, 1.9, 72.0, 298.15);
    assert_close(m.seebeck_v_k, vmax / th, 1e-14, "S exact");
    assert_close(m.resistance_ohm, (th - dt) * vmax / (th * imax), 1e-14, "R exact");
    assert_close(
        m.conductance_w_k,
        (th - dt) * vmax * imax / (2.0 * th * dt),
        1e-14,
        "K exact",
    );
    // model.md §5: S ≈ 6.4 mV/K (got 6.373), R ≈ 0.5 Ω (got 0.515), K ≈ 28 mW/K (got 28.02).
    assert_close(m.seebeck_v_k, 6.4e-3, 0.01, "S ≈ 6.4 mV/K");
    assert_close(m.resistance_ohm, 0.5, 0.05, "R ≈ 0.5 Ω");
    assert_close(m.conductance_w_k, 0.028, 0.01, "K ≈ 28 mW/K");
}

#[test]
fn datasheet_point_reproduces_qmax_at_imax_and_zero_delta_t() {
    let m = mini();
    let ds = PeltierDatasheet::default();
    // Cooling the display with I_max at ΔT = 0, both faces at the datasheet's hot-side temperature.
    let cooling = -m.heat_into_display_w(-ds.imax_a, th_c(), th_c());
    // The standard approximations give V_max I_max (T_h + ΔT_max)/(2 T_h) = 3.3024 W, 3.2 % above the quoted 3.2 W.
    let predicted = 1.9 * 2.8 * (298.15 + 72.0) / (2.0 * 298.15);
    assert_close(cooling, predicted, 1e-12, "Q(I_max, ΔT=0) vs closed form");
    assert_close(cooling, ds.qmax_w, 0.035, "Q(I_max, ΔT=0) vs datasheet Q_max");
    assert_close(ds.predicted_qmax_w(), predicted, 1e-14, "predicted_qmax_w");
    println!(
        "Q_max model {cooling:.4} W vs datasheet {} W ({:+.2} %)",
        ds.qmax_w,
        100.0 * (cooling / ds.qmax_w - 1.0)
    );
}

#[test]
fn datasheet_point_gives_zero_heat_and_vmax_at_delta_t_max() {
    let m = mini();
    let ds = PeltierDatasheet::default();
    let cold_c = th_c() - ds.dtmax_k;
    let q = m.heat_into_display_w(-ds.imax_a, cold_c, th_c());
    // The terms are of order S·I·T ≈ 4 W; exact zero up to rounding.
    assert!(q.abs() < 1e-12, "heat at (I_max, ΔT_max) = {q} W, want 0");
    let v = m.voltage_v(-ds.imax_a, cold_c, th_c());
    assert_close(-v, ds.vmax_v, 1e-12, "|V| at (I_max, ΔT_max)");
    // ΔT_max is the largest difference: I_max is the optimum current there, and no current cools at all.
    assert_close(
        m.optimum_cooling_current_a(cold_c),
        -ds.imax_a,
        1e-12,
        "optimum current at ΔT_max",
    );
    for i in 0..=60 {
        let current = -f64::from(i) * 0.1;
        let q = m.heat_into_display_w(current, cold_c, th_c());
        assert!(q >= -1e-12, "I={current}: heat into display {q} W < 0 at ΔT_max");
    }
}

#[test]
fn heating_capacity_is_about_twice_cooling_capacity() {
    let m = mini();
    let limit = 2.8;
    let heat = m.max_heating_w(limit, th_c(), th_c());
    let cool = m.max_cooling_w(limit, th_c(), th_c());
    // At ΔT = 0 and T = T_h: S I T = V_max I_max = 5.32 W, ½ I² R = 2.0176 W.
    let peltier = 1.9 * 2.8;
    let joule = 0.5 * 2.8 * 2.8 * (298.15 - 72.0) * 1.9 / (298.15 * 2.8);
    assert_close(heat, peltier + joule, 1e-12, "max heating");
    assert_close(cool, peltier - joule, 1e-12, "max cooling");
    let ratio = heat / cool;
    assert!(
        (1.8..=2.6).contains(&ratio),
        "heating/cooling = {ratio} ({heat} W / {cool} W), want ≈ 2"
    );
    println!("heating {heat:.3} W, cooling {cool:.3} W, ratio {ratio:.3}");
}

#[test]
fn above_the_optimum_current_more_current_warms_the_cold_side() {
    let m = mini();
    for (display_c, hot_c) in [(25.0, 25.0), (20.0, 30.0), (32.0, 23.0)] {
        let opt = m.optimum_cooling_current_a(display_c);
        assert_close(
            opt,
            -m.seebeck_v_k * (display_c + 273.15) / m.resistance_ohm,
            1e-14,
            "I_opt = −S T_d / R",
        );
        let at = |i: f64| m.heat_into_display_w(i, display_c, hot_c);
        // The heat into the display is smallest (the cooling largest) at the optimum …
        for factor in [0.5, 0.9, 0.99, 1.01, 1.1, 1.5, 2.0] {
            assert!(
                at(opt * factor) > at(opt),
                "Td={display_c}: q({factor}·I_opt)={} ≤ q(I_opt)={}",
                at(opt * factor),
                at(opt)
            );
        }
        // … and beyond it each further ampere of cooling current adds heat to the display.
        let mut previous = at(opt);
        for step in 1..=20 {
            let current = opt * (1.0 + 0.05 * f64::from(step));
            let q = at(current);
            assert!(
                q > previous,
                "Td={display_c}: q({current})={q} not above q at smaller current {previous}"
            );
            previous = q;
        }
        // max_cooling_w with a generous limit stops at the optimum.
        assert_close(
            m.max_cooling_w(10.0, display_c, hot_c),
            -at(opt),
            1e-12,
            "max cooling at generous limit",
        );
    }
}

#[test]
fn inverse_round_trips_on_the_efficient_branch() {
    let m = mini();
    let mut worst = 0.0f64;
    for (display_c, hot_c) in [(32.0, 23.0), (20.0, 35.0), (40.0, 25.0)] {
        let opt = m.optimum_cooling_current_a(display_c);
        let most_cooling = -m.heat_into_display_w(opt, display_c, hot_c);
        let most_heating = m.max_heating_w(2.8, display_c, hot_c);
        for k in 0..=100 {
            let q = -0.999 * most_cooling + (most_heating + 0.999 * most_cooling) * f64::from(k) / 100.0;
            let current = m.current_for_heat_into_display(q, display_c, hot_c);
            let Some(current) = current else {
                panic!("Td={display_c} Th={hot_c}: no current for q={q}")
            };
            assert!(
                current >= opt,
                "I={current} below the optimum {opt} (inefficient branch) for q={q}"
            );
            let back = m.heat_into_display_w(current, display_c, hot_c);
            let err = (back - q).abs() / (q.abs() + most_cooling);
            worst = worst.max(err);
            assert!(err < 1e-12, "q={q}: current {current} gives {back}");
        }
        // Unreachable cooling and non-finite inputs give None.
        assert_eq!(
            m.current_for_heat_into_display(-(most_cooling + 1e-3), display_c, hot_c),
            None
        );
        assert_eq!(m.current_for_heat_into_display(f64::NAN, display_c, hot_c), None);
        assert_eq!(m.current_for_heat_into_display(0.0, display_c, f64::INFINITY), None);
    }
    println!("worst relative round-trip error {worst:e}");
}

#[test]
fn affine_forms_match_direct_evaluation() {
    let m = mini();
    for current in [-2.8, -1.0, 0.0, 0.7, 2.8] {
        let (d, h) = (m.display_heat_affine(current), m.hot_heat_affine(current));
        for (td, th) in [(32.0, 23.0), (15.0, 45.0)] {
            assert_close(
                d.at(td, th),
                m.heat_into_display_w(current, td, th),
                1e-12,
                "display affine",
            );
            assert_close(
                h.at(td, th),
                m.heat_into_hot_side_w(current, td, th),
                1e-12,
                "hot affine",
            );
        }
    }
}

fn bad_key(ds: PeltierDatasheet) -> String {
    match PeltierModule::from_datasheet(&ds) {
        Err(ParamError::BadValue { source, origin }) => {
            assert_eq!(origin, "peltier datasheet");
            source.name.into_owned()
        }
        other => panic!("expected BadValue, got {other:?}"),
    }
}

#[test]
fn bad_datasheets_are_refused_with_the_key() {
    let ok = PeltierDatasheet::default();
    assert_eq!(bad_key(PeltierDatasheet { imax_a: f64::NAN, ..ok }), "imax_a");
    assert_eq!(bad_key(PeltierDatasheet { vmax_v: -1.9, ..ok }), "vmax_v");
    assert_eq!(bad_key(PeltierDatasheet { qmax_w: 0.0, ..ok }), "qmax_w");
    assert_eq!(
        bad_key(PeltierDatasheet {
            dtmax_k: f64::INFINITY,
            ..ok
        }),
        "dtmax_k"
    );
    assert_eq!(bad_key(PeltierDatasheet { hot_side_k: -3.0, ..ok }), "hot_side_k");
    assert_eq!(bad_key(PeltierDatasheet { dtmax_k: 400.0, ..ok }), "dtmax_k");
    // Q_max 10 W cannot come from a 2.8 A / 1.9 V module (3.3 W predicted): a typing error.
    assert_eq!(bad_key(PeltierDatasheet { qmax_w: 10.0, ..ok }), "qmax_w");
    let err = PeltierModule::from_datasheet_at(&PeltierDatasheet { qmax_w: 10.0, ..ok }, "lab.toml", "peltier.");
    let message = err.map(|_| String::new()).unwrap_or_else(|e| e.to_string());
    assert!(
        message.contains("lab.toml") && message.contains("peltier.qmax_w") && message.contains("3.302"),
        "{message}"
    );
    assert!(PeltierModule::new(0.0064, 0.5, f64::NAN).is_err());
    assert!(PeltierModule::new(0.0064, 0.5, 0.028).is_ok());
}

/// The datasheet of a module (`PeltierDatasheet::from_module`) is the one it was made from: I_max, V_max and
/// ΔT_max come back to 1e-9 relative for datasheets 30 % off the default each way, and Q_max is the predicted one.
#[test]
fn a_modules_datasheet_is_the_one_it_was_made_from() {
    for (fi, fv, fd) in [(1.0, 1.0, 1.0), (1.3, 0.7, 1.3), (0.7, 1.3, 0.7), (1.3, 1.3, 0.8)] {
        let base = PeltierDatasheet::default();
        let mut ds = PeltierDatasheet {
            imax_a: base.imax_a * fi,
            vmax_v: base.vmax_v * fv,
            dtmax_k: base.dtmax_k * fd,
            ..base
        };
        ds.qmax_w = ds.predicted_qmax_w();
        let module = PeltierModule::from_datasheet(&ds).unwrap_or_else(|e| panic!("{e}"));
        let back = PeltierDatasheet::from_module(&module, ds.hot_side_k).expect("a datasheet");
        for (name, got, want) in [
            ("imax", back.imax_a, ds.imax_a),
            ("vmax", back.vmax_v, ds.vmax_v),
            ("dtmax", back.dtmax_k, ds.dtmax_k),
            ("qmax", back.qmax_w, ds.qmax_w),
        ] {
            assert!(
                (got / want - 1.0).abs() < 1e-9,
                "{name}: {got} vs {want} (factors {fi} {fv} {fd})"
            );
        }
    }
}
