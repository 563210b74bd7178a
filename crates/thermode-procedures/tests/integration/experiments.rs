//! Every procedure file shipped in `crates/thermode-lab/experiments` parses and validates, and the multi-zone
//! programs are what their comments say (checked against the segments' nominal timing).

use thermode_procedures::program::{segment_times_s, ZoneTrial};
use thermode_procedures::{ProcedureFile, ProcedureKind, Segment};

fn experiments_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../thermode-lab/experiments")
}

fn load(name: &str) -> ProcedureFile {
    let path = experiments_dir().join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    ProcedureFile::from_toml_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

const SHIPPED: [(&str, ProcedureKind); 7] = [
    ("dfns-thermal.toml", ProcedureKind::Limits),
    ("levels.toml", ProcedureKind::Levels),
    ("staircase.toml", ProcedureKind::Staircase),
    ("questplus.toml", ProcedureKind::Questplus),
    ("thermal-grill.toml", ProcedureKind::Program),
    ("temporal-summation.toml", ProcedureKind::Program),
    ("thermal-icons.toml", ProcedureKind::Program),
];

#[test]
fn every_shipped_procedure_file_parses_and_validates() {
    for (name, kind) in SHIPPED {
        let file = load(name);
        assert_eq!(file.procedure, kind, "{name}: procedure");
        assert_eq!(
            file.procedure().expect("buildable").is_some(),
            kind != ProcedureKind::Program,
            "{name}"
        );
    }
    // Every other file of the folder is an identification design (thermode-lab's), not a procedure file.
    for entry in std::fs::read_dir(experiments_dir()).expect("experiments folder") {
        let name = entry.expect("entry").file_name().to_string_lossy().into_owned();
        let known = SHIPPED.iter().any(|(n, _)| *n == name) || name == "paper.toml";
        assert!(known, "{name}: a file in experiments/ that this test does not parse");
        let text = std::fs::read_to_string(experiments_dir().join(&name)).expect("readable");
        assert_eq!(
            ProcedureFile::declares_procedure(&text),
            name != "paper.toml",
            "{name}: procedure key"
        );
    }
}

#[test]
fn the_dfns_file_is_the_protocol() {
    let limits = load("dfns-thermal.toml").limits.expect("[limits]");
    let got = (
        limits.baseline_c,
        limits.rate_c_per_s,
        limits.detection_return_rate_c_per_s,
        limits.pain_return_rate_c_per_s,
    );
    assert_eq!(got, (32.0, 1.0, 1.0, 5.0), "baseline, rate, return rates");
    assert_eq!(
        (limits.cold_cutoff_c, limits.heat_cutoff_c, limits.runs),
        (0.0, 50.0, 3),
        "cut-offs and runs"
    );
}

fn trials(name: &str) -> Vec<ZoneTrial> {
    load(name).program.expect("[program]").trials().expect("valid program")
}

#[test]
fn the_grill_interlaces_20_and_40_c_bars_for_30_s_on_five_zones() {
    let grill = &trials("thermal-grill.toml")[0];
    assert_eq!(grill.name, "grill");
    let mut plateau_c = Vec::new();
    for (channel, segments) in &grill.channels {
        let times = segment_times_s(grill.baseline_c, segments);
        assert!(
            (times[1] - 1.0).abs() < 1e-12,
            "zone {channel} reaches its bar at {} s, not with the others",
            times[1]
        );
        assert!(
            (times[2] - times[1] - 30.0).abs() < 1e-12,
            "zone {channel} holds {} s",
            times[2] - times[1]
        );
        let Segment::Ramp { to_c, .. } = segments[0] else {
            panic!("zone {channel} starts with {:?}", segments[0])
        };
        plateau_c.push(to_c);
    }
    assert_eq!(plateau_c, [20.0, 40.0, 20.0, 40.0, 20.0], "interlaced bars");
}

#[test]
fn temporal_summation_is_10_pulses_at_half_a_hertz_on_five_zones() {
    let train = &trials("temporal-summation.toml")[0];
    assert_eq!(train.channels.len(), 5, "zones");
    for (channel, segments) in &train.channels {
        let times = segment_times_s(train.baseline_c, segments);
        let peaks: Vec<f64> = segments
            .iter()
            .zip(&times)
            .filter(|(s, _)| matches!(s, Segment::Ramp { to_c, .. } if *to_c > train.baseline_c))
            .map(|(_, t)| *t)
            .collect();
        assert_eq!(peaks.len(), 10, "zone {channel}: pulses");
        for pair in peaks.windows(2) {
            assert!(
                (pair[1] - pair[0] - 2.0).abs() < 1e-9,
                "zone {channel}: pulses {} s apart",
                pair[1] - pair[0]
            );
        }
    }
}

#[test]
fn thermal_icons_vary_direction_magnitude_and_rate_across_five_zones() {
    let icons = trials("thermal-icons.toml");
    let names: Vec<&str> = icons
        .iter()
        .filter(|t| t.repetition == 1)
        .map(|t| t.name.as_str())
        .collect();
    assert_eq!(names, ["direction", "magnitude", "rate"]);
    let first = |icon: &ZoneTrial| -> Vec<(f64, f64)> {
        icon.channels
            .values()
            .map(|s| match s[0] {
                Segment::Ramp { to_c, rate_c_per_s, .. } => (to_c - icon.baseline_c, rate_c_per_s),
                other => panic!("{}: first segment {other:?}", icon.name),
            })
            .collect()
    };
    let by_name = |name: &str| icons.iter().find(|t| t.name == name).expect(name);
    let signs: Vec<f64> = first(by_name("direction")).iter().map(|(d, _)| d.signum()).collect();
    assert_eq!(signs, [-1.0, 1.0, -1.0, 1.0, -1.0], "direction pattern");
    let magnitudes: Vec<f64> = first(by_name("magnitude")).iter().map(|(d, _)| -d).collect();
    assert_eq!(magnitudes, [1.0, 2.0, 3.0, 4.0, 5.0], "magnitude pattern");
    let rates: Vec<f64> = first(by_name("rate")).iter().map(|(_, r)| *r).collect();
    assert_eq!(rates, [1.0, 2.0, 4.0, 8.0, 16.0], "rate pattern");
}

#[test]
fn bad_files_are_refused_with_the_key_named() {
    let cases = [
        ("name = \"x\"\nprocedure = \"levels\"\n", "needs a [levels] table"),
        (
            "name = \"x\"\nprocedure = \"limits\"\n[limits]\nrate_c_s = -1.0\n",
            "limits.rate_c_s",
        ),
        (
            "name = \"x\"\nprocedure = \"limits\"\n[limits]\nspeed = 1.0\n",
            "unknown field `speed`",
        ),
        (
            "name = \"x\"\nprocedure = \"questplus\"\n[questplus]\nfunc = \"norm_cdf\"\nstim_scale = \"log10\"\n\
             stim_domain = { intensity = [1.0] }\nparam_domain = { mean = [1.0], sd = [1.0] }\n",
            "questplus.stim_scale",
        ),
        (
            "name = \"x\"\nprocedure = \"program\"\n[program]\n[[program.stimuli]]\nname = \"a\"\n\
             [program.stimuli.channels]\n\"5\" = [{ to_c = 20.0, rate_c_s = 1.0 }]\n",
            "`program.stimuli.a.channels` = 5 is invalid: must be a finite number below program.channels = 5",
        ),
        (
            "name = \"x\"\nprocedure = \"program\"\n[program]\n[[program.stimuli]]\nname = \"a\"\n\
             [program.stimuli.channels]\n\"0\" = [{ hold_s = 1.0 }]\n",
            "a ramp or step away from the baseline",
        ),
        (
            "name = \"x\"\nprocedure = \"program\"\n[program]\n[[program.stimuli]]\nname = \"a\"\n\
             [program.stimuli.channels]\n\"0\" = [{ to_c = 20.0, rate_c_s = 1.0 }, { hold_s = 1.0, to_c = 3.0 }]\n",
            "did not match any variant",
        ),
        (
            "name = \"x\"\nprocedure = \"program\"\n[program]\n[[program.stimuli]]\nname = \"a\"\n\
             [program.stimuli.channels]\n\"0\" = [{ to_c = 20.0, rate_c_s = 1.0, until = \"button\" }]\n",
            "did not match any variant",
        ),
    ];
    for (text, expected) in cases {
        let error = ProcedureFile::from_toml_str(text).expect_err(text).to_string();
        assert!(error.contains(expected), "error `{error}` should mention `{expected}`");
    }
}

#[test]
fn a_program_of_1000_segments_is_refused() {
    let segments = "{ to_c = 33.0, rate_c_s = 1.0 }, ".to_string() + &"{ hold_s = 1.0 }, ".repeat(999);
    let text = format!(
        "name = \"x\"\nprocedure = \"program\"\n[program]\n[[program.stimuli]]\nname = \"a\"\n\
         [program.stimuli.channels]\n\"0\" = [{segments}]\n"
    );
    let error = ProcedureFile::from_toml_str(&text)
        .expect_err("1000 segments")
        .to_string();
    assert!(
        error.contains("(segments)` = 1000 is invalid: must be a finite number from 1 to 999"),
        "{error}"
    );
    let accepted = text.replacen("{ hold_s = 1.0 }, ", "", 1);
    ProcedureFile::from_toml_str(&accepted).expect("999 segments");
}
