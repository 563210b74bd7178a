//! The yes/no procedures (levels, staircase, QUEST+) of the shipped experiment files recover the simulated
//! participant's threshold within 0.1 °C after 30 trials in at least 95 % of 1000 seeded sessions.
//!
//! The participant detects a change of its receptor (skin) temperature of `threshold_c`; in the stimulus' units
//! (the plate's change) that is the trapezoid amplitude whose peak receptor change is `threshold_c`, computed from
//! the skin's analytic response (`SkinResponse::trapezoid_threshold_c`), not from the simulation.

use thermode_model::Skin;
use thermode_procedures::participant::{run_simulated, SimulatedParticipant};
use thermode_procedures::skin_response::{SkinResponse, Trapezoid};
use thermode_procedures::ProcedureFile;

/// The participant's skin is stepped at 200 Hz in these sessions.
const DT_S: f64 = 5e-3;
const SESSIONS: u64 = 1000;

fn experiment(name: &str) -> ProcedureFile {
    let path = format!("{}/../thermode-lab/experiments/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    ProcedureFile::from_toml_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// The threshold in plate units for `file`'s stimulus and participant.
fn plate_threshold_c(file: &ProcedureFile) -> f64 {
    let (s, p) = (file.stimulus(), file.participant());
    let skin = SkinResponse::new(&Skin::fingertip(), p.contact_conductance_w_m2k).expect("skin");
    let timing = Trapezoid {
        rate_c_per_s: s.rate_c_per_s,
        plateau_s: s.plateau_s,
        return_rate_c_per_s: s.return_rate_c_per_s,
    };
    skin.trapezoid_threshold_c(p.threshold_c, timing).expect("reachable")
}

/// Runs `SESSIONS` sessions of `name` and returns (sessions within 0.1 °C, worst error, mean signed error,
/// expected threshold).
fn recovery(name: &str) -> (u64, f64, f64, f64) {
    let file = experiment(name);
    let expected = plate_threshold_c(&file);
    let mut within = 0;
    let mut worst: f64 = 0.0;
    let mut bias = 0.0;
    for session in 0..SESSIONS {
        let mut procedure = file.procedure().expect("valid").expect("single-channel");
        let mut someone = SimulatedParticipant::new(file.participant(), file.seed + session).expect("valid");
        let trials = run_simulated(procedure.as_mut(), &mut someone, DT_S).expect("a session");
        assert_eq!(trials.len(), 30, "{name}: a session has 30 trials");
        let signed = procedure.estimate_c().expect("an estimate") - expected;
        bias += signed / SESSIONS as f64;
        let error = signed.abs();
        worst = worst.max(error);
        within += u64::from(error <= 0.1);
    }
    (within, worst, bias, expected)
}

fn assert_recovers(name: &str) {
    let (within, worst, bias, expected) = recovery(name);
    println!(
        "{name}: {within}/{SESSIONS} sessions within 0.1 °C of {expected:.4} °C (worst error {worst:.3} °C, mean error {bias:+.4} °C)"
    );
    assert!(
        within * 100 >= 95 * SESSIONS,
        "{name}: {within} of {SESSIONS} sessions within 0.1 °C of {expected} °C, at least 95 % expected (worst {worst})"
    );
}

#[test]
fn the_method_of_levels_recovers_the_threshold() {
    assert_recovers("levels.toml");
}

#[test]
fn the_staircase_recovers_the_threshold() {
    assert_recovers("staircase.toml");
}

#[test]
fn questplus_recovers_the_threshold() {
    assert_recovers("questplus.toml");
}
