//! `--record DIR`: the session CSV has the documented header, one row per tick per channel in order, loop times on
//! the tick grid, the contact names, and it is flushed while the daemon runs (a crash loses at most the last
//! second).

use crate::common;

use std::sync::Arc;

use common::{trackers, SpyDevice};
use thermode_model::materials;
use thermode_platform::{Clock, ManualClock};
use thermode_runtime::recorder::{Recorder, CSV_HEADER};
use thermode_runtime::{Command, LoopConfig, LoopHandle, Owner};

const PERIOD_S: f64 = 0.01;

#[test]
fn every_tick_of_every_channel_is_recorded_in_order() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (recorder, feed) = Recorder::start(dir.path()).expect("recorder");
    let clock = Arc::new(ManualClock::new());
    let mut handle = LoopHandle::spawn(
        LoopConfig::default(),
        Box::new(SpyDevice::new(3)),
        trackers(),
        clock.clone(),
        vec![feed],
    )
    .expect("loop");
    // Tick 0 runs at clock time 0; moving the clock before it ran would skip it as a missed deadline.
    assert!(
        common::wait_until(10.0, || handle.snapshot().stats.ticks >= 1),
        "first tick"
    );
    let wood = materials::find("wood").expect("wood");
    let ticks = 200u64;
    for k in 1..ticks {
        if k == 100 {
            let command = Command::touch(1, wood.clone(), 23.0, Owner::Script);
            handle.commands().send(command).expect("queued");
        }
        clock.set(k as f64 * PERIOD_S);
        let want = clock.now_s();
        assert!(
            common::wait_until(10.0, || handle.snapshot().time_s >= want),
            "tick {k}"
        );
    }
    handle.stop();
    drop(handle);
    let path = recorder.path().to_path_buf();
    let rows_written = recorder.finish().expect("recorder finishes");
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default()
        .to_string();
    assert!(
        name.starts_with("session_") && name.ends_with(".csv"),
        "file name {name}"
    );
    let text = std::fs::read_to_string(&path).expect("read CSV");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(CSV_HEADER));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len() as u64, 3 * ticks, "rows: 3 channels × {ticks} ticks");
    assert_eq!(rows_written, 3 * ticks);
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), 12, "row {i}: {row:?}");
        let tick = (i / 3) as f64;
        let time_s: f64 = row[0].parse().expect("time_s");
        assert!(
            (time_s - tick * PERIOD_S).abs() < 1e-6,
            "row {i}: time {time_s} vs {}",
            tick * PERIOD_S
        );
        assert_eq!(row[1], (i % 3).to_string(), "row {i}: channel");
        for (col, value) in row.iter().enumerate().skip(5).take(6) {
            assert!(value.parse::<f64>().is_ok(), "row {i} column {col}: {value:?}");
        }
        let touched = i % 3 == 1 && tick >= 100.0;
        let want = if touched {
            ["1", "wood", "touch"]
        } else {
            ["0", "", "air"]
        };
        assert_eq!([row[2], row[3], row[4]], want, "row {i}: contact, material, mode");
        assert_eq!(row[11], "", "row {i}: fault (empty: none)");
    }
}

#[test]
fn the_file_is_flushed_while_the_daemon_runs() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = common::test_config();
    config.record_dir = Some(dir.path().to_path_buf());
    let daemon = common::start(config, SpyDevice::new(2), trackers());
    let path = daemon.recording_path().expect("recording");
    let flushed = common::wait_until(5.0, || {
        std::fs::read_to_string(&path).is_ok_and(|t| t.lines().count() > 20)
    });
    assert!(flushed, "no rows on disk within 5 s of running at 100 Hz");
    let status = common::get_json(daemon.http_addr(), "/api/status");
    assert_eq!(status["recording"]["path"], path.display().to_string());
    assert!(
        status["recording"]["rows"].as_u64().unwrap_or(0) > 0,
        "{}",
        status["recording"]
    );
    let rows = daemon.shutdown().expect("shutdown").expect("recording");
    let lines = std::fs::read_to_string(&path).expect("CSV").lines().count() as u64;
    assert_eq!(
        lines,
        rows + 1,
        "every row the recorder counted is on disk after shutdown"
    );
}

#[test]
fn a_second_session_in_the_same_second_gets_its_own_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (a, feed_a) = Recorder::start(dir.path()).expect("first");
    let (b, feed_b) = Recorder::start(dir.path()).expect("second");
    assert_ne!(a.path(), b.path());
    drop((feed_a, feed_b));
    a.finish().expect("finish a");
    b.finish().expect("finish b");
}
