//! The method of limits with the simulated participant (the Kron skin stepped at 1 kHz under a prescribed plate)
//! against the analytic line `θ + r·(t_rt + lag(r))` of `thermode_procedures::skin_response`.

use thermode_model::inverse::DEFAULT_DISPLAY_CONDUCTANCE_W_M2K;
use thermode_model::{KronEnvironment, KronModel, Skin};
use thermode_procedures::analysis;
use thermode_procedures::limits::{LimitsConfig, LimitsProcedure, LimitsTest};
use thermode_procedures::participant::{run_simulated, ParticipantConfig, SimulatedParticipant};
use thermode_procedures::skin_response::SkinResponse;

fn participant() -> ParticipantConfig {
    ParticipantConfig {
        threshold_c: 0.5,
        reaction_time_s: 0.4,
        noise_c: 0.0,
        lapse: 0.0,
        ..ParticipantConfig::default()
    }
}

/// Runs CDT and WDT (3 runs each) at `rate_c_s` and returns their thresholds' magnitudes.
fn limits_session(rate_c_per_s: f64) -> (f64, f64) {
    let config = LimitsConfig {
        tests: vec![LimitsTest::Cdt, LimitsTest::Wdt],
        rate_c_per_s,
        ..LimitsConfig::default()
    };
    let mut procedure = LimitsProcedure::new(config).expect("valid limits");
    let mut someone = SimulatedParticipant::new(participant(), 1).expect("valid participant");
    run_simulated(&mut procedure, &mut someone, 1e-3).expect("a session");
    let thresholds = analysis::thresholds(procedure.runs());
    (thresholds[0].value_c.abs(), thresholds[1].value_c.abs())
}

#[test]
fn the_method_of_limits_follows_the_analytic_line_at_1_2_and_4_c_per_s() {
    let p = participant();
    let skin = SkinResponse::new(&Skin::fingertip(), p.contact_conductance_w_m2k).expect("skin");
    let mut worst: f64 = 0.0;
    for rate in [1.0, 2.0, 4.0] {
        let expected = skin
            .limits_estimate_c(p.threshold_c, rate, p.reaction_time_s)
            .expect("detected");
        let lag = skin.lag_s(p.threshold_c, rate).expect("detected");
        let (cdt, wdt) = limits_session(rate);
        println!("rate {rate} °C/s: lag {lag:.4} s, analytic {expected:.4} °C, CDT {cdt:.4}, WDT {wdt:.4}");
        for (name, got) in [("CDT", cdt), ("WDT", wdt)] {
            worst = worst.max((got - expected).abs());
            assert!(
                (got - expected).abs() <= 0.05,
                "{name} at {rate} °C/s: simulated {got} °C against the analytic {expected} °C"
            );
        }
    }
    println!("worst |simulated − analytic| = {worst:.5} °C");
}

#[test]
fn the_skin_lag_grows_with_the_ramp_duration() {
    let skin = SkinResponse::new(&Skin::fingertip(), DEFAULT_DISPLAY_CONDUCTANCE_W_M2K).expect("skin");
    let lags: Vec<f64> = [4.0, 2.0, 1.0]
        .iter()
        .map(|r| skin.lag_s(0.5, *r).expect("detected"))
        .collect();
    assert!(
        lags[0] < lags[1] && lags[1] < lags[2],
        "slower ramps (longer to the threshold) should lag more: {lags:?} s at 4, 2, 1 °C/s"
    );
}

#[test]
fn the_analytic_response_has_the_skin_models_steady_gain_and_initial_slope() {
    // Independent of the modal solution: the Kron model's own steady states on plates 1 °C apart.
    let g = DEFAULT_DISPLAY_CONDUCTANCE_W_M2K;
    let skin = Skin::fingertip();
    let model = KronModel::new(&skin).expect("kron");
    let plate = |t: f64| KronEnvironment::Plate {
        conductance_w_m2k: g,
        temperature_c: t,
    };
    let kron_gain = model.steady_state_c(&plate(33.0))[0] - model.steady_state_c(&plate(32.0))[0];
    let response = SkinResponse::new(&skin, g).expect("skin");
    let gain = response.steady_gain();
    println!("steady gain of the receptor: {gain:.4} (Kron steady states: {kron_gain:.4})");
    assert!(
        (gain - kron_gain).abs() < 1e-9,
        "steady gain: modal {gain}, Kron {kron_gain}"
    );
    // A ramp's first instants: y ≈ r (G_d / C₁) t² / 2.
    let c1 = model.capacities_j_m2k()[0];
    let t = 1e-4;
    let (got, expected) = (response.unit_ramp_c(t), g / c1 * t * t / 2.0);
    assert!(
        (got / expected - 1.0).abs() < 1e-3,
        "initial ramp response {got} against {expected}"
    );
}

#[test]
fn a_simulated_dfns_session_runs_every_test() {
    let file_text = std::fs::read_to_string(format!(
        "{}/../thermode-lab/experiments/dfns-thermal.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .expect("dfns-thermal.toml");
    let file = thermode_procedures::ProcedureFile::from_toml_str(&file_text).expect("valid");
    let mut procedure = LimitsProcedure::new(file.limits.clone().expect("[limits]")).expect("valid");
    let mut someone = SimulatedParticipant::new(file.participant(), file.seed).expect("valid");
    run_simulated(&mut procedure, &mut someone, 1e-2).expect("a session");
    let p = file.participant();
    let skin = SkinResponse::new(&Skin::fingertip(), p.contact_conductance_w_m2k).expect("skin");
    let line = skin
        .limits_estimate_c(p.threshold_c, 1.0, p.reaction_time_s)
        .expect("detected");
    for t in analysis::thresholds(procedure.runs()) {
        println!("{:?}", t);
        assert_eq!(t.cutoffs, 0, "{}: no ramp should reach its cut-off", t.test.name());
        match t.test {
            LimitsTest::Cdt | LimitsTest::Wdt => assert!(
                (t.value_c.abs() - line).abs() < 0.2,
                "{}: {} °C, the analytic line {line} °C (noise 0.05 °C)",
                t.test.name(),
                t.value_c
            ),
            LimitsTest::Tsl => assert!(
                t.value_c > line,
                "TSL {} °C should exceed one detection ({line} °C)",
                t.value_c
            ),
            LimitsTest::Cpt => assert!(t.value_c > 0.0 && t.value_c < 32.0 - line, "CPT {} °C", t.value_c),
            LimitsTest::Hpt => assert!(t.value_c < 50.0 && t.value_c > 32.0 + line, "HPT {} °C", t.value_c),
        }
    }
}
