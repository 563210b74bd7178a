//! The thermal dose survives a restart of the daemon: held at 48 °C until the dose lockout, stopped, started again
//! with the same state directory and asked for 48 °C again, the true plate of the simulated display stays below
//! 43 °C. Also: `/api/status` and telemetry report each channel's dose, the ledger on disk never holds less than
//! the loop counted, and a corrupt ledger or a state directory in use refuses the start; so does a ledger holding a
//! channel the display does not have; a ledger that cannot be written stops every stimulus until it can.
//!
//! The daemons run the pipelines `thermode serve` runs (default display, default render envelope, 1 CEM43-min
//! budget) on a *jumping* manual clock: the loop runs its ticks at once, with the times they would have had, so a
//! minute of display time takes a few seconds of test time and no wall-clock timing is asserted.

use crate::common;

use std::sync::Arc;

use common::{get_json, pid_pipelines, pipelines, test_config, wait_until, SpyDevice};
use thermode_platform::{Clock, ManualClock};
use thermode_runtime::command::CommandError;
use thermode_runtime::ledger::{read_ledger, LedgerError, LEDGER_FILE};
use thermode_runtime::snapshot::Mode;
use thermode_runtime::{Command, EngineFactory, Owner, RuntimeError};
use thermode_serve::{Daemon, ServeError};

/// A daemon with the state directory `dir` on a jumping clock, one channel, and its spy's shared log.
fn start(dir: &std::path::Path, engines: EngineFactory) -> (Daemon, Arc<std::sync::Mutex<common::SpyLog>>) {
    let device = SpyDevice::new(1);
    let log = device.log.clone();
    let mut config = test_config();
    config.core.state_dir = Some(dir.to_path_buf());
    let clock: Arc<dyn Clock> = Arc::new(ManualClock::jumping());
    let daemon = Daemon::start(config, Box::new(device), engines, clock).expect("daemon starts");
    (daemon, log)
}

/// Asks channel 0 for 48 °C (direct, 20 °C/s) and returns the loop time at which it took effect.
fn ask_48(daemon: &Daemon) -> f64 {
    let answer = daemon
        .commands()
        .expect("commands")
        .request(Command::direct(0, 48.0, 20.0, Owner::Script))
        .expect("queued");
    let applied = answer.blocking_recv().expect("answered").expect("applied");
    applied.time_s
}

/// Waits (at most 60 s of real time) until the loop's time reaches `time_s`.
fn run_until(daemon: &Daemon, time_s: f64) {
    let reached = wait_until(60.0, || daemon.snapshot().is_some_and(|s| s.time_s >= time_s));
    assert!(reached, "the loop did not reach {time_s} s");
}

fn restart_case(engines: fn() -> EngineFactory, controller: &str) {
    let tmp = tempfile::tempdir().expect("temp dir");
    // First session: 48 °C until the lockout, then 20 s more at the request.
    let (daemon, log) = start(tmp.path(), engines());
    let t0 = ask_48(&daemon);
    let locked = wait_until(60.0, || daemon.snapshot().is_some_and(|s| s.channels[0].dose.lockout));
    assert!(locked, "{controller}: no lockout");
    let locked_at_s = daemon.snapshot().expect("snapshot").time_s;
    run_until(&daemon, locked_at_s + 20.0);
    let first_max_c = log.lock().expect("log").max_plate_c;
    let status = get_json(daemon.http_addr(), "/api/status");
    let ch = &status["channels"][0];
    assert_eq!(ch["dose_lockout"], true, "{ch}");
    assert!(ch["cem43_min"].as_f64().is_some_and(|d| d >= 1.0), "{ch}");
    assert!(ch["time_at_or_above_43_s"].as_f64().is_some(), "{ch}");
    assert_eq!(
        status["dose_ledger"]["path"],
        tmp.path().join(LEDGER_FILE).display().to_string()
    );
    let path = daemon.ledger_path().expect("ledger path").to_path_buf();
    daemon.shutdown().expect("clean shutdown");
    let saved = read_ledger(tmp.path()).expect("ledger").dose(0);
    println!(
        "{controller}: first session 48 °C asked at {t0} s, lockout at {locked_at_s} s, hottest plate \
         {first_max_c:.2} °C, saved {saved:?} in {}",
        path.display()
    );
    assert!(saved.lockout && saved.cem43_min >= 1.0, "{saved:?}");

    // Second session, same state directory: the restored dose is reported before anything is asked, and 48 °C is
    // refused for good.
    let (daemon, log) = start(tmp.path(), engines());
    let restored = daemon.snapshot().expect("snapshot").channels[0].dose;
    assert!(
        restored.lockout && restored.cem43_min >= saved.cem43_min,
        "restored {restored:?}, saved {saved:?}"
    );
    let t1 = ask_48(&daemon);
    run_until(&daemon, t1 + 60.0);
    let snapshot = daemon.snapshot().expect("snapshot");
    let max_plate_c = log.lock().expect("log").max_plate_c;
    let setpoint_c = snapshot.channels[0].telemetry.display_setpoint_c;
    println!(
        "{controller}: second session 48 °C asked at {t1} s; after 60 s the set-point is {setpoint_c:.2} °C, the \
         hottest true plate {max_plate_c:.2} °C, dose {:?}",
        snapshot.channels[0].dose
    );
    assert!(
        max_plate_c < 43.0,
        "{controller}: the true plate reached {max_plate_c} °C after the restart"
    );
    assert!(setpoint_c < 42.5, "{controller}: set-point {setpoint_c}");
    daemon.shutdown().expect("clean shutdown");
    let after = read_ledger(tmp.path()).expect("ledger").dose(0);
    assert!(
        after.cem43_min >= snapshot.channels[0].dose.cem43_min && after.lockout,
        "ledger {after:?} below the loop's {:?}",
        snapshot.channels[0].dose
    );
}

#[test]
fn a_restarted_daemon_keeps_the_dose_lockout_model() {
    restart_case(pipelines, "model");
}

#[test]
fn a_restarted_daemon_keeps_the_dose_lockout_pid() {
    restart_case(pid_pipelines, "pid");
}

#[test]
fn a_corrupt_ledger_or_a_state_directory_in_use_refuses_the_start() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join(LEDGER_FILE);
    std::fs::write(
        &path,
        "{\"format\": \"thermode-dose-ledger\", \"version\": 1, \"channels\": [",
    )
    .expect("write");
    let mut config = test_config();
    config.core.state_dir = Some(tmp.path().to_path_buf());
    let clock: Arc<dyn Clock> = Arc::new(ManualClock::new());
    let refused = Daemon::start(config.clone(), Box::new(SpyDevice::new(1)), pipelines(), clock.clone());
    match refused {
        Err(ServeError::Runtime(RuntimeError::Ledger(LedgerError::Corrupt { .. }))) => {}
        other => panic!("a corrupt ledger: {other:?}"),
    }
    assert_eq!(
        std::fs::read_to_string(&path).expect("read"),
        "{\"format\": \"thermode-dose-ledger\", \"version\": 1, \"channels\": [",
        "the corrupt ledger is left as it is"
    );
    std::fs::remove_file(&path).expect("remove");
    let first =
        Daemon::start(config.clone(), Box::new(SpyDevice::new(1)), pipelines(), clock.clone()).expect("first daemon");
    let second = Daemon::start(config, Box::new(SpyDevice::new(1)), pipelines(), clock);
    assert!(
        matches!(
            second,
            Err(ServeError::Runtime(RuntimeError::Ledger(LedgerError::InUse { .. })))
        ),
        "a second daemon on the same state directory: {second:?}"
    );
    first.shutdown().expect("shutdown");
}

/// Asks channel 0 for `temp_c` (direct, 5 °C/s): the loop's refusal, or `None` when it applied it.
fn ask(daemon: &Daemon, temp_c: f64) -> Option<CommandError> {
    let answer = daemon
        .commands()
        .expect("commands")
        .request(Command::direct(0, temp_c, 5.0, Owner::Script))
        .expect("queued");
    answer.blocking_recv().expect("answered").err()
}

/// A ledger that cannot be written (the state directory moved away and a regular file put in its place: the
/// tests run as root, whom permission bits do not stop, and the writer fails the same way on a full disk) stops
/// every stimulus and refuses new ones, says so in the status and in the notices, and a successful write lifts it;
/// the dose counted meanwhile is on disk at the end.
#[test]
fn an_unwritable_ledger_stops_every_stimulus_until_it_is_written_again() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("state");
    let (daemon, _log) = start(&dir, pipelines());
    assert!(ask(&daemon, 44.0).is_none(), "44 °C applied");
    let status = || get_json(daemon.http_addr(), "/api/status");
    assert!(
        wait_until(60.0, || status()["dose_ledger"]["writes"].as_u64() >= Some(2)),
        "the writer does not write: {}",
        status()["dose_ledger"]
    );
    let away = tmp.path().join("state-away");
    std::fs::rename(&dir, &away).expect("move the state directory away");
    std::fs::write(&dir, "not a directory").expect("a file in its place");
    assert!(
        wait_until(60.0, || status()["dose_ledger"]["stimuli_refused"] == true),
        "no refusal: {}",
        status()["dose_ledger"]
    );
    let s = status();
    assert!(s["dose_ledger"]["errors"].as_u64() >= Some(1), "{}", s["dose_ledger"]);
    assert!(s["dose_ledger"]["last_error"].is_string(), "{}", s["dose_ledger"]);
    assert!(
        wait_until(60.0, || daemon
            .snapshot()
            .is_some_and(|s| s.channels[0].mode == Mode::Air)),
        "the stimulus was not stopped: {:?}",
        daemon.snapshot().map(|s| s.channels[0].mode)
    );
    match ask(&daemon, 30.0) {
        Some(CommandError::DoseNotRecorded) => {}
        other => panic!("a stimulus while the ledger cannot be written: {other:?}"),
    }
    let notices = daemon.take_notices().join("\n");
    assert!(
        notices.contains("the dose ledger cannot be written"),
        "notices: {notices}"
    );
    let held = daemon.snapshot().expect("snapshot").channels[0].dose;

    std::fs::remove_file(&dir).expect("remove the file");
    std::fs::rename(&away, &dir).expect("the state directory back");
    assert!(
        wait_until(60.0, || status()["dose_ledger"]["stimuli_refused"] == false),
        "still refused: {}",
        status()["dose_ledger"]
    );
    let refused = ask(&daemon, 30.0);
    assert!(
        refused.is_none(),
        "a stimulus once the ledger is written again: {refused:?}"
    );
    let notices = daemon.take_notices().join("\n");
    assert!(
        notices.contains("the dose ledger is written again"),
        "notices: {notices}"
    );
    daemon.shutdown().expect("clean shutdown");
    let saved = read_ledger(&dir).expect("ledger").dose(0);
    assert!(
        saved.cem43_min >= held.cem43_min && saved.cem43_min > 0.0,
        "ledger {saved:?} below the dose counted while it could not be written {held:?}"
    );
}

/// A ledger holding a channel the display does not have (channel 3 on a one-channel display) refuses the start,
/// naming the key.
#[test]
fn a_ledger_of_another_display_refuses_the_start() {
    let tmp = tempfile::tempdir().expect("temp dir");
    std::fs::write(
        tmp.path().join(LEDGER_FILE),
        "{\"format\": \"thermode-dose-ledger\", \"version\": 1, \"channels\": [{\"channel\": 3, \"cem43_min\": 0.5, \
         \"time_at_or_above_43_s\": 0, \"lockout\": false, \"updated_utc\": \"2025-01-31T12:00:00Z\"}]}",
    )
    .expect("write");
    let mut config = test_config();
    config.core.state_dir = Some(tmp.path().to_path_buf());
    let clock: Arc<dyn Clock> = Arc::new(ManualClock::new());
    match Daemon::start(config, Box::new(SpyDevice::new(1)), pipelines(), clock) {
        Err(ServeError::Runtime(RuntimeError::Ledger(LedgerError::Corrupt { reason, .. }))) => {
            assert!(
                reason.contains("`channel` = 3") && reason.contains("1 channels"),
                "{reason}"
            );
        }
        other => panic!("a ledger with channel 3 on a one-channel display: {other:?}"),
    }
}
