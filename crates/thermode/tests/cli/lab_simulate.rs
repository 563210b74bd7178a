//! `lab run --simulate` with `--seed` (the simulated participants' noise apart from the design's seed, which keeps
//! deciding the plan) and `--renderer kron|fv` (the paper's own display), and the new `lab analyze` outputs on such
//! sessions (the confusion comparison and the just-noticeable differences).

use std::collections::BTreeMap;
use std::path::Path;

use super::{expect_error, expect_success};

const EXPERIMENT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../thermode-lab/experiments/paper.toml");

/// Runs P01–P04 of the paper's design into `dir` with `extra` options; returns the session CSVs by file name.
fn run_sessions(dir: &Path, extra: &[&str]) -> BTreeMap<String, String> {
    let dir_text = dir.display().to_string();
    let mut args = vec![
        "lab",
        "run",
        "--simulate",
        "--experiment",
        EXPERIMENT,
        "--simulated-participant",
        "--data-dir",
        &dir_text,
    ];
    for p in ["P01", "P02", "P03", "P04"] {
        args.extend(["--participant", p]);
    }
    args.extend(extra);
    expect_success(&args);
    std::fs::read_dir(dir)
        .expect("read data dir")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .map(|p| {
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default();
            (name, std::fs::read_to_string(&p).expect("read session"))
        })
        .collect()
}

/// The values of `columns` of every row of a session CSV (no field of these sessions holds a comma).
fn columns(csv: &str, columns: &[&str]) -> Vec<Vec<String>> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let index: Vec<usize> = columns
        .iter()
        .map(|c| {
            header
                .iter()
                .position(|h| h == c)
                .unwrap_or_else(|| panic!("no column {c} in {header:?}"))
        })
        .collect();
    lines
        .map(|l| {
            let fields: Vec<&str> = l.split(',').collect();
            index.iter().map(|&i| fields[i].to_string()).collect()
        })
        .collect()
}

/// The name of the first sidecar (JSON) in `dir`.
fn first_sidecar_name(dir: &Path) -> String {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".json"))
        .collect();
    names.sort();
    names.into_iter().next().expect("a sidecar")
}

/// The plan's columns of a session: what was presented when.
const PLAN: [&str; 8] = [
    "participant",
    "seed",
    "trial",
    "block",
    "repetition",
    "condition",
    "position",
    "presented",
];

#[test]
fn the_participant_seed_changes_the_answers_only() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let default = run_sessions(&tmp.path().join("default"), &[]);
    let design_seed = run_sessions(&tmp.path().join("2008"), &["--seed", "2008"]);
    let seven = run_sessions(&tmp.path().join("7"), &["--seed", "7"]);
    let sidecar = tmp.path().join("7").join(first_sidecar_name(&tmp.path().join("7")));
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sidecar).expect("read sidecar")).expect("JSON sidecar");
    let answers = sidecar["device"]["answers"].as_str().unwrap_or_default();
    assert!(
        answers.ends_with(", seed 7"),
        "the sidecar names the participants' seed: {answers}"
    );
    let eight = run_sessions(&tmp.path().join("8"), &["--seed", "8"]);
    assert_eq!(
        default.len(),
        4,
        "one session CSV per participant: {:?}",
        default.keys()
    );
    assert_eq!(
        default, design_seed,
        "--seed equal to the design's seed (2008) gives the sessions of a run without --seed"
    );
    let plan_csv = expect_success(&["lab", "plan", "--experiment", EXPERIMENT]);
    let mut answers_differ = 0;
    for (name, text) in &default {
        let planned = columns(text, &PLAN);
        for other in [&seven, &eight] {
            assert_eq!(
                planned,
                columns(&other[name], &PLAN),
                "{name}: the plan does not depend on --seed"
            );
        }
        let answers = |csv: &str| columns(csv, &["identified"]);
        answers_differ += answers(&seven[name])
            .iter()
            .zip(answers(&eight[name]))
            .filter(|(a, b)| **a != *b)
            .count();
        // The plan CSV of `lab plan` lists the same trials in the same order.
        let participant = &planned[0][0];
        let from_plan: Vec<Vec<String>> = columns(&plan_csv, &["participant", "trial", "condition", "presented"])
            .into_iter()
            .filter(|row| &row[0] == participant)
            .collect();
        let from_session = columns(text, &["participant", "trial", "condition", "presented"]);
        assert_eq!(from_plan, from_session, "{name}: the session follows the plan CSV");
    }
    // 80 answers at about 60 % correct: two independent noise seeds give the same answer to every trial with a
    // probability far below 1e-6.
    assert!(answers_differ > 0, "seeds 7 and 8 gave the same 80 answers");
}

#[test]
fn the_kron_renderer_with_pid_presents_the_papers_display() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let fv = run_sessions(&tmp.path().join("fv"), &["--renderer", "fv"]);
    let default = run_sessions(&tmp.path().join("default"), &[]);
    assert_eq!(fv, default, "--renderer fv is the default");
    let kron_dir = tmp.path().join("kron");
    let kron = run_sessions(&kron_dir, &["--renderer", "kron", "--controller", "pid"]);
    // The finger rests on the display before each touch, so every trial (real ones too) depends on the display;
    // the simulated trials are the display's rendering.
    let finger = ["condition", "model_finger_end_c"];
    let mut simulated_differ = 0;
    for (name, text) in &default {
        for (a, b) in columns(text, &finger).iter().zip(columns(&kron[name], &finger)) {
            simulated_differ += usize::from(a[0] == "simulated" && a[1] != b[1]);
        }
    }
    assert!(
        simulated_differ > 20,
        "the kron renderer with PID rendered {simulated_differ} of 40 simulated trials differently from fv with the model"
    );
    let sidecar = kron_dir.join(first_sidecar_name(&kron_dir));
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sidecar).expect("read sidecar")).expect("JSON sidecar");
    let stimulus = &sidecar["device"]["stimulus"];
    assert_eq!(stimulus["renderer"], "kron", "{sidecar}");
    assert_eq!(stimulus["controller"], "pid", "{sidecar}");
    let model = [
        "lab",
        "run",
        "--simulate",
        "--experiment",
        EXPERIMENT,
        "--participant",
        "P01",
        "--simulated-participant",
        "--stimulus",
        "model",
        "--renderer",
        "kron",
    ];
    expect_error(&model, "--stimulus display");
    let display = [
        "lab",
        "run",
        "--experiment",
        EXPERIMENT,
        "--participant",
        "P01",
        "--display",
        "ws://127.0.0.1:9",
        "--renderer",
        "kron",
    ];
    expect_error(&display, "renders with its own");
}

#[test]
fn lab_analyze_reports_the_confusion_comparison_and_the_jnds() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let sessions = run_sessions(&tmp.path().join("data"), &[]);
    let mut args: Vec<String> = ["lab", "analyze"].map(String::from).to_vec();
    args.extend(
        sessions
            .keys()
            .map(|n| tmp.path().join("data").join(n).display().to_string()),
    );
    let out = tmp.path().join("report");
    args.extend([
        "--out".to_string(),
        out.display().to_string(),
        "--format".into(),
        "md".into(),
    ]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    expect_success(&args);
    let analysis: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("analysis.json")).expect("read")).expect("JSON");
    let comparison = &analysis["confusion_comparison"];
    let pairs = comparison["pairs"].as_u64().expect("pairs");
    let zero = comparison["zero_in_both"].as_u64().expect("zero_in_both");
    assert_eq!(
        pairs + zero,
        20,
        "the 20 off-diagonal cells are used or left out: {comparison}"
    );
    assert!(
        comparison["p_value"].as_f64().is_some_and(|p| p > 0.0 && p <= 1.0),
        "a p-value in (0, 1]: {comparison}"
    );
    for group in ["real", "simulated", "overall"] {
        for quantity in ["k", "c"] {
            let fit = &analysis["jnd"][group][quantity];
            let (mu, jnd) = (&fit["mu"], &fit["jnd_75"]);
            let value = |e: &serde_json::Value, key: &str| e[key].as_f64().unwrap_or(f64::NAN);
            assert!(
                value(mu, "ci_low") <= value(mu, "value") && value(mu, "value") <= value(mu, "ci_high"),
                "{group} {quantity}: the estimate inside its interval: {fit}"
            );
            assert!(
                value(jnd, "value") > value(mu, "value"),
                "{group} {quantity}: 75 % above 50 %: {fit}"
            );
        }
    }
    let report = std::fs::read_to_string(out.join("report.md")).expect("read report");
    assert!(
        report.contains("not zero in both conditions") && report.contains("Just-noticeable differences"),
        "{report}"
    );
}

#[test]
fn the_perceptual_participant_answers_by_default_and_the_calibrated_one_when_asked() {
    let (calibrated, perceptual) = (tempfile::tempdir().expect("dir"), tempfile::tempdir().expect("dir"));
    let default = run_sessions(perceptual.path(), &[]);
    let chosen = run_sessions(calibrated.path(), &["--participant-model", "calibrated"]);
    assert_eq!(default.len(), chosen.len());
    let sidecar = |dir: &Path| std::fs::read_to_string(dir.join(first_sidecar_name(dir))).expect("sidecar");
    assert!(
        sidecar(calibrated.path()).contains("simulated participant, noise"),
        "the calibrated participant when asked"
    );
    assert!(
        sidecar(perceptual.path()).contains("perceptual model fitted"),
        "the perceptual model by default"
    );
    let presented = |sessions: &BTreeMap<String, String>| -> Vec<Vec<Vec<String>>> {
        sessions
            .values()
            .map(|csv| columns(csv, &["presented", "condition"]))
            .collect()
    };
    assert_eq!(
        presented(&default),
        presented(&chosen),
        "the same trials, other answers"
    );
}
