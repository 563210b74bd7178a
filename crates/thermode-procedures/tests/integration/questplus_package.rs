//! QUEST+ sessions replayed through the `questplus` Python package 2023.1: for the same grid and responses, every
//! trial's next intensity must be the package's and the final posterior must agree cell by cell to 1e-9 relative
//! (as must the parameter estimate). Needs `python3` with `questplus==2023.1`; CI installs it and sets
//! `THERMODE_REQUIRE_PYTHON_TESTS=1`, so there a missing package fails the test; elsewhere it is skipped with a
//! message saying how to run it.

use std::io::Write;
use std::process::{Command, Stdio};

use serde_json::{json, Value};
use thermode_procedures::participant::{ParticipantConfig, SimulatedParticipant};
use thermode_procedures::questplus::{Func, QuestPlusConfig, QuestPlusProcedure};
use thermode_procedures::stimulus::StimulusConfig;
use thermode_procedures::{Procedure, ProcedureFile};

/// Replays `{config, trials: [[stim, outcome]]}` through the package; prints the next intensity before each trial,
/// the final posterior (C order over the parameters as listed) and the parameter estimate.
const REPLAY: &str = r#"
import json, sys
import questplus
assert questplus.__version__ == "2023.1", questplus.__version__
from questplus import QuestPlus
spec = json.load(sys.stdin)
params = spec["param_names"]
qp = QuestPlus(
    stim_domain={"intensity": spec["stim"]},
    param_domain={name: spec["params"][name] for name in params},
    outcome_domain={"response": spec["outcomes"]},
    func=spec["func"],
    stim_scale=spec["stim_scale"],
    stim_selection_method="min_entropy",
    param_estimation_method=spec["estimation"],
)
nexts = []
for stim, outcome in spec["trials"]:
    nexts.append(qp.next_stim["intensity"])
    qp.update(stim={"intensity": stim}, outcome={"response": outcome})
posterior = qp.posterior.transpose(*params).values.ravel().tolist()
estimate = [qp.param_estimate[name] for name in params]
print(json.dumps({"next": nexts, "posterior": posterior, "estimate": estimate}))
"#;

fn python_ready() -> bool {
    let required = std::env::var("THERMODE_REQUIRE_PYTHON_TESTS").is_ok_and(|v| v == "1");
    let ready = Command::new("python3")
        .args(["-c", "import questplus; assert questplus.__version__ == '2023.1'"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ready {
        assert!(
            !required,
            "THERMODE_REQUIRE_PYTHON_TESTS=1 but python3 lacks questplus 2023.1"
        );
        println!("skipped: `python3 -m pip install questplus==2023.1` to compare QUEST+ with the package");
    }
    ready
}

fn replay(spec: &Value) -> Value {
    let mut child = Command::new("python3")
        .args(["-c", REPLAY])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("run python3: {e}"));
    let mut stdin = child.stdin.take().expect("stdin");
    stdin.write_all(spec.to_string().as_bytes()).expect("write the session");
    drop(stdin);
    let out = child.wait_with_output().expect("python3 output");
    assert!(
        out.status.success(),
        "the replay failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("replay output {e}: {}", String::from_utf8_lossy(&out.stdout)))
}

fn values(config: &QuestPlusConfig) -> (Vec<&'static str>, Value) {
    let d = &config.param_domain;
    let grid = |g: &Option<thermode_procedures::questplus::Grid>, key: &str| match g {
        Some(g) => g.values(key).expect("grid"),
        None => vec![0.01],
    };
    let (names, first, second) = match config.func {
        Func::NormCdf => (vec!["mean", "sd", "lower_asymptote", "lapse_rate"], &d.mean, &d.sd),
        Func::Weibull => (
            vec!["threshold", "slope", "lower_asymptote", "lapse_rate"],
            &d.threshold,
            &d.slope,
        ),
    };
    let params = json!({
        names[0]: grid(first, names[0]),
        names[1]: grid(second, names[1]),
        "lower_asymptote": grid(&d.lower_asymptote, "lower_asymptote"),
        "lapse_rate": grid(&d.lapse_rate, "lapse_rate"),
    });
    (names, params)
}

/// Runs a 30-trial session of `config` with a simulated participant, replays it through the package and compares.
fn compare_with_the_package(config: &QuestPlusConfig, stimulus: StimulusConfig, seed: u64) {
    let mut procedure = QuestPlusProcedure::new(config, stimulus).expect("valid QUEST+");
    let participant = ParticipantConfig {
        noise_c: 0.1,
        lapse: 0.02,
        ..ParticipantConfig::default()
    };
    let mut someone = SimulatedParticipant::new(participant, seed).expect("participant");
    let mut ours = Vec::new();
    let mut trials = Vec::new();
    while let Some(plan) = procedure.next_trial() {
        let index = procedure.engine().next_index();
        let stim = procedure.engine().stim_domain()[index];
        let response = someone.run_trial(&plan, 5e-3);
        procedure.record(response).expect("pending");
        ours.push(stim);
        let outcome = &config.outcome_domain.response[usize::from(!response.detected)];
        trials.push(json!([stim, outcome]));
    }
    let (names, params) = values(config);
    let spec = json!({
        "stim": config.stim_domain.intensity.values("stim").expect("grid"),
        "param_names": names,
        "params": params,
        "outcomes": config.outcome_domain.response,
        "func": match config.func { Func::NormCdf => "norm_cdf", Func::Weibull => "weibull" },
        "stim_scale": serde_json::to_value(config.stim_scale).expect("scale"),
        "estimation": serde_json::to_value(config.param_estimation_method).expect("method"),
        "trials": trials,
    });
    let theirs = replay(&spec);
    let next: Vec<f64> = serde_json::from_value(theirs["next"].clone()).expect("next");
    for (trial, (a, b)) in ours.iter().zip(&next).enumerate() {
        assert!(a == b, "trial {trial}: thermode presents {a}, the package {b}");
    }
    assert_eq!(ours.len(), next.len(), "trials");
    let posterior: Vec<f64> = serde_json::from_value(theirs["posterior"].clone()).expect("posterior");
    let mine = procedure.engine().posterior();
    assert_eq!(mine.len(), posterior.len(), "posterior cells");
    let mut worst: f64 = 0.0;
    for (cell, (a, b)) in mine.iter().zip(&posterior).enumerate() {
        if a.abs().max(b.abs()) < 1e-290 {
            continue; // underflowing tails: both below the normal range
        }
        let relative = (a - b).abs() / a.abs().max(b.abs());
        worst = worst.max(relative);
        assert!(
            relative <= 1e-9,
            "posterior cell {cell}: thermode {a:e}, the package {b:e} (relative {relative:e})"
        );
    }
    let estimate: Vec<f64> = serde_json::from_value(theirs["estimate"].clone()).expect("estimate");
    let my_estimate = procedure.engine().param_estimate();
    for (k, (a, b)) in my_estimate.iter().zip(&estimate).enumerate() {
        let relative = (a - b).abs() / a.abs().max(b.abs()).max(1e-300);
        assert!(
            relative <= 1e-9,
            "estimate of {}: thermode {a}, the package {b}",
            names[k]
        );
    }
    println!(
        "{} trials: same intensities; posterior worst relative difference {worst:e}; estimate {estimate:?}",
        ours.len()
    );
}

#[test]
fn the_shipped_questplus_session_replays_through_the_package() {
    if !python_ready() {
        return;
    }
    let path = format!(
        "{}/../thermode-lab/experiments/questplus.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let file = ProcedureFile::from_toml_str(&std::fs::read_to_string(&path).expect("questplus.toml")).expect("valid");
    let config = file.questplus.clone().expect("a [questplus] table");
    for seed in [1, 2, 3] {
        compare_with_the_package(&config, file.stimulus(), seed);
    }
}

#[test]
fn a_weibull_session_on_a_log10_scale_with_the_mode_replays_through_the_package() {
    if !python_ready() {
        return;
    }
    let text = r#"
        func = "weibull"
        stim_scale = "log10"
        param_estimation_method = "mode"
        trials = 25
        stim_domain = { intensity = { start = -1.3, stop = 0.55, step = 0.1 } }
        param_domain = { threshold = { start = -1.3, stop = 0.55, step = 0.1 }, slope = [2.0, 3.5, 5.0], lower_asymptote = [0.01, 0.05], lapse_rate = [0.01] }
    "#;
    let config: QuestPlusConfig = toml::from_str(text).expect("a QUEST+ table");
    compare_with_the_package(&config, StimulusConfig::default(), 7);
}
