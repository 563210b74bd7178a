//! The kill test: the runner, in a child process (this test binary re-run on its ignored `child_session` test),
//! runs a scripted session — model stimulus with a drifting finger, the calibrated simulated participant, a small
//! nonzero time scale — and is killed with SIGKILL at seeded random moments, then resumed, several times. In the
//! end every planned trial must be in the session file exactly once, in order, identical to an uninterrupted run's
//! rows except the timing columns; after every kill the file's complete rows must be a prefix of those rows and never
//! fewer than before.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use thermode_lab::design::ExperimentFile;
use thermode_lab::participant::{SimulatedParticipant, PAPER_REAL_IDENTIFICATION_RATE};
use thermode_lab::runner::{FvContact, ModelStimulus, QuietConsole, Runner};
use thermode_lab::session::TIMING_COLUMNS;
use thermode_platform::{parse_iso_date, Clock, ManualClock, MonotonicClock};

const CHILD_ENV: &str = "THERMODE_LAB_KILL_CHILD_DIR";
const DATE: &str = "2024-05-01";
/// 30 s presentations at this scale take 0.12 s.
const TIME_SCALE: f64 = 0.004;
const DESIGN: &str = "name = \"kill\"\nmaterials = [\"aluminium\", \"steel\", \"stone\", \"wood\", \"rubber\"]\n\
                      participants = 1\nrepetitions = 2\nseed = 77\nexclusion_max_drift_c = 0.5\n";

/// The machine's clock on a fixed date, so that the child's session file has a known name.
#[derive(Debug)]
struct FixedDateClock(MonotonicClock);

impl Clock for FixedDateClock {
    fn now_s(&self) -> f64 {
        self.0.now_s()
    }
    fn sleep_until(&self, deadline_s: f64) {
        self.0.sleep_until(deadline_s);
    }
    fn unix_time_s(&self) -> f64 {
        parse_iso_date(DATE).expect("a valid date") + self.0.now_s()
    }
}

/// Runs the whole session of participant P01 in `dir` with `clock`, waits scaled by `time_scale`.
fn run_session(dir: &Path, clock: &dyn Clock, time_scale: f64) {
    let experiment = ExperimentFile::load(&dir.join("kill.toml")).expect("valid design");
    let seed = experiment.experiment.seed;
    let contact = FvContact::default();
    let mut stimulus = ModelStimulus::new(contact.clone(), 0.3, seed).expect("model");
    let options = &experiment.experiment.response_options;
    let mut simulated = SimulatedParticipant::from_model(options, &contact, 30.0, seed).expect("references");
    simulated
        .calibrate(PAPER_REAL_IDENTIFICATION_RATE, 1000, 1)
        .expect("reachable");
    Runner {
        experiment: &experiment,
        participant: "P01",
        data_dir: &dir.join("data"),
        device: stimulus.describe(),
        stimulus: &mut stimulus,
        responder: &mut simulated,
        clock,
        time_scale,
        console: &mut QuietConsole,
        interactive: false,
    }
    .run()
    .expect("session runs");
}

#[test]
#[ignore = "child process of runner_survives_random_kills"]
fn child_session() {
    let dir = PathBuf::from(std::env::var(CHILD_ENV).expect("run by runner_survives_random_kills"));
    run_session(&dir, &FixedDateClock(MonotonicClock::new()), TIME_SCALE);
}

fn spawn_child(dir: &Path) -> Child {
    Command::new(std::env::current_exe().expect("test binary"))
        .args(["kill::child_session", "--exact", "--ignored", "--test-threads=1"])
        .env(CHILD_ENV, dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("child starts")
}

/// The complete rows of a session CSV (a torn last line ignored), without the timing columns.
fn complete_rows(csv: &Path) -> Vec<Vec<String>> {
    let Ok(bytes) = std::fs::read(csv) else {
        return Vec::new();
    };
    let complete = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    let mut reader = csv::Reader::from_reader(&bytes[..complete]);
    let header: Vec<String> = match reader.headers() {
        Ok(h) => h.iter().map(str::to_string).collect(),
        Err(_) => return Vec::new(),
    };
    reader
        .records()
        .map(|r| {
            let r = r.expect("complete rows parse");
            header
                .iter()
                .zip(r.iter())
                .filter(|(h, _)| !TIMING_COLUMNS.contains(&h.as_str()))
                .map(|(_, v)| v.to_string())
                .collect()
        })
        .collect()
}

/// If the child has ended: `true` when it succeeded; a failure fails the test.
fn has_finished(child: &mut Child) -> bool {
    let Some(status) = child.try_wait().expect("child status") else {
        return false;
    };
    if !status.success() {
        let mut err = String::new();
        if let Some(mut stderr) = child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut stderr, &mut err);
        }
        panic!("child failed ({status}): {err}");
    }
    true
}

/// Waits until `until` says so or the child ends (`true`), at most `limit`.
fn wait_for(child: &mut Child, limit: Duration, mut until: impl FnMut() -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if has_finished(child) {
            return true;
        }
        if until() {
            return false;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    panic!("the child made no progress within {limit:?}");
}

#[test]
fn runner_survives_random_kills() {
    let dir = tempfile::tempdir().expect("temp dir");
    let reference_dir = tempfile::tempdir().expect("temp dir");
    for d in [dir.path(), reference_dir.path()] {
        std::fs::write(d.join("kill.toml"), DESIGN).expect("write design");
    }
    let reference_clock = ManualClock::jumping().with_unix_origin_s(parse_iso_date(DATE).expect("a valid date"));
    run_session(reference_dir.path(), &reference_clock, 1.0);
    let csv_name = format!("P01_kill_{DATE}.csv");
    let reference = complete_rows(&reference_dir.path().join("data").join(&csv_name));
    assert_eq!(reference.len(), 20);
    let csv = dir.path().join("data").join(&csv_name);
    let mut rng = ChaCha8Rng::seed_from_u64(20_240_501);
    let (mut kills, mut recorded) = (0, 0);
    let limit = Duration::from_secs(60);
    loop {
        // Kill moment: once 0-3 more trials are on disk, a further 0-150 ms (a trial takes about 120 ms), seeded.
        let target = recorded + rng.gen_range(0..=3);
        let extra = Duration::from_millis(rng.gen_range(0..150));
        let mut child = spawn_child(dir.path());
        let mut done = wait_for(&mut child, limit, || complete_rows(&csv).len() >= target);
        if !done {
            let moment = Instant::now() + extra;
            done = wait_for(&mut child, limit, || Instant::now() >= moment);
        }
        if !done {
            child.kill().expect("SIGKILL");
            child.wait().expect("reaped");
            kills += 1;
        }
        let rows = complete_rows(&csv);
        eprintln!(
            "run {}: {}, {} rows",
            kills + usize::from(done),
            if done { "finished" } else { "killed" },
            rows.len()
        );
        assert!(
            rows.len() >= recorded,
            "kill {kills}: {} rows after, {recorded} before",
            rows.len()
        );
        assert_eq!(
            rows[..],
            reference[..rows.len()],
            "kill {kills}: rows are not a prefix of the reference"
        );
        recorded = rows.len();
        if done {
            break;
        }
    }
    assert!(kills >= 5, "only {kills} kills happened before the session ended");
    let sidecar_path = csv.with_extension("json");
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&sidecar_path).expect("sidecar")).expect("JSON");
    let resumes = sidecar["resumes"].as_array().map_or(0, Vec::len);
    let torn = sidecar["resumes"]
        .as_array()
        .map_or(0, |r| r.iter().filter(|n| n["removed_torn_row"] == true).count());
    eprintln!("{kills} kills, {resumes} resumes noted in the sidecar, {torn} of them cut a torn row");
    assert_eq!(complete_rows(&csv), reference, "after {kills} kills");
    let text = std::fs::read_to_string(&csv).expect("read");
    assert!(
        text.ends_with('\n') && text.lines().count() == 21,
        "header + 20 rows, nothing torn"
    );
}
