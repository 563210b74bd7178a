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

/// A recorded session on a manual clock: `channels` tracking channels ticked `ticks` times, 10 ms apart, with
/// `command` sent at tick `at`. The session file and the rows the recorder wrote.
fn record_session(
    dir: &std::path::Path,
    channels: usize,
    ticks: u64,
    (at, command): (u64, Command),
) -> (std::path::PathBuf, u64) {
    let (recorder, feed) = Recorder::start(dir).expect("recorder");
    let clock = Arc::new(ManualClock::new());
    let mut handle = LoopHandle::spawn(
        LoopConfig::default(),
        Box::new(SpyDevice::new(channels)),
        trackers(),
        clock.clone(),
        vec![feed],
        Arc::default(),
    )
    .expect("loop");
    // Tick 0 runs at clock time 0; moving the clock before it ran would skip it as a missed deadline.
    assert!(
        common::wait_until(10.0, || handle.snapshot().stats.ticks >= 1),
        "first tick"
    );
    let mut command = Some(command);
    for k in 1..ticks {
        if k == at {
            let command = command.take().expect("sent once");
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
    let rows = recorder.finish().expect("recorder finishes");
    (path, rows)
}

#[test]
fn every_tick_of_every_channel_is_recorded_in_order() {
    let dir = tempfile::tempdir().expect("temp dir");
    let wood = materials::find("wood").expect("wood");
    let ticks = 200u64;
    let touch = Command::touch(1, wood, 23.0, Owner::Script);
    let (path, rows_written) = record_session(dir.path(), 3, ticks, (100, touch));
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
        // 12 columns, then the touched material's properties (issue 25: the recording names them).
        assert_eq!(row.len(), 16, "row {i}: {row:?}");
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
fn a_custom_material_is_recorded_with_its_properties() {
    let dir = tempfile::tempdir().expect("temp dir");
    // A material no library knows, as a client's `properties` make it.
    let glass = materials::Material {
        name: "ice-cold-glass".into(),
        conductivity_w_mk: 1.05,
        density_kg_m3: 2500.0,
        specific_heat_j_kgk: 840.0,
        thickness_m: 0.004,
        source: "client".into(),
    };
    let touch = Command::touch(0, glass, 5.0, Owner::Script);
    let (path, _) = record_session(dir.path(), 2, 40, (10, touch));
    let text = std::fs::read_to_string(&path).expect("read CSV");
    let header: Vec<&str> = text.lines().next().unwrap_or_default().split(',').collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no {name}: {header:?}"))
    };
    let properties = [
        "conductivity_w_mk",
        "density_kg_m3",
        "specific_heat_j_kgk",
        "thickness_m",
    ]
    .map(column);
    let rows: Vec<Vec<&str>> = text.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let touched: Vec<&Vec<&str>> = rows.iter().filter(|r| r[3] == "ice-cold-glass").collect();
    assert!(touched.len() >= 20, "{} rows of the touch", touched.len());
    for row in &touched {
        let values = properties.map(|i| row[i].parse::<f64>().unwrap_or(f64::NAN));
        assert_eq!(values, [1.05, 2500.0, 840.0, 0.004], "{row:?}");
    }
    let air = rows.iter().filter(|r| r[4] == "air");
    assert!(air.clone().count() > 0 && air.into_iter().all(|r| properties.iter().all(|&i| r[i].is_empty())));
}

#[test]
fn the_file_is_flushed_while_the_daemon_runs() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = common::test_config();
    config.core.record_dir = Some(dir.path().to_path_buf());
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

/// The rows of a session file (the header excluded), and whether it ends with a newline.
fn rows_on_disk(path: &std::path::Path) -> (u64, bool) {
    let bytes = std::fs::read(path).expect("read CSV");
    let lines = bytes.iter().filter(|&&b| b == b'\n').count() as u64;
    (lines.saturating_sub(1), bytes.last() == Some(&b'\n'))
}

#[test]
fn a_file_that_fills_up_keeps_whole_rows_counts_only_them_and_trips_the_interlock() {
    use thermode_runtime::recorder::{QuotaFile, RecordState};
    use thermode_runtime::Interlock;
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("full.csv");
    let file = std::fs::File::create(&path).expect("file");
    // 3000 bytes: the header and a few ticks fit, then a write is cut short as on a full disk.
    let interlock = Arc::new(Interlock::new());
    let (recorder, feed) = Recorder::start_on(
        path.clone(),
        Box::new(QuotaFile::new(file, 3000)),
        Some(interlock.clone()),
        None,
    )
    .expect("recorder");
    let status = recorder.status();
    let clock = Arc::new(ManualClock::new());
    let mut handle = LoopHandle::spawn(
        LoopConfig::default(),
        Box::new(SpyDevice::new(3)),
        trackers(),
        clock.clone(),
        vec![feed],
        interlock.clone(),
    )
    .expect("loop");
    assert!(
        common::wait_until(10.0, || handle.snapshot().stats.ticks >= 1),
        "first tick"
    );
    for k in 1..400u64 {
        clock.set(k as f64 * PERIOD_S);
        let want = clock.now_s();
        assert!(
            common::wait_until(10.0, || handle.snapshot().time_s >= want),
            "tick {k}"
        );
    }
    // The writer writes at least every 0.5 s of real time.
    assert!(
        common::wait_until(10.0, || status.state() == RecordState::Failed),
        "the recording never failed: {} rows, {} bytes",
        status.rows_written(),
        status.bytes_written()
    );
    let error = status.error().unwrap_or_default();
    assert!(error.contains("3000 bytes"), "error names the quota: {error}");
    assert!(interlock.engaged(), "the failure trips the interlock");
    clock.set(400.0 * PERIOD_S);
    assert!(
        common::wait_until(10.0, || handle.snapshot().channels.iter().all(|c| c.held_off)),
        "the next tick stops all"
    );
    let (rows, newline) = rows_on_disk(&path);
    assert!(newline, "the file ends with a whole row");
    assert_eq!(rows, status.rows_written(), "rows counted = rows in the file");
    assert!(status.bytes_written() <= 3000, "{} bytes", status.bytes_written());
    handle.stop();
    drop(handle);
    let finished = recorder.finish();
    assert!(finished.is_err(), "finish reports the error: {finished:?}");
    assert_eq!(rows_on_disk(&path), (rows, true), "nothing written after the failure");
    assert!(status.rows_lost() > 0, "rows after the failure are counted as lost");
}

#[test]
fn a_disk_that_is_full_from_the_start_fails_at_the_header() {
    use thermode_runtime::recorder::RecordState;
    let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
        eprintln!("SKIPPED: no /dev/full on this system");
        return;
    };
    let (recorder, feed) = Recorder::start_on("/dev/full".into(), Box::new(full), None, None).expect("recorder");
    let status = recorder.status();
    assert!(common::wait_until(10.0, || status.state() == RecordState::Failed));
    assert_eq!(status.rows_written(), 0);
    let error = status.error().unwrap_or_default();
    assert!(error.to_lowercase().contains("space"), "ENOSPC: {error}");
    drop(feed);
    assert!(recorder.finish().is_err());
}

#[test]
fn a_failed_recording_stops_every_stimulus_until_acknowledged_and_says_so_everywhere() {
    use thermode_runtime::recorder::RecordErrorPolicy;
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = common::test_config();
    config.core.record_dir = Some(dir.path().to_path_buf());
    config.core.record_max_bytes = Some(16 * 1024);
    assert_eq!(config.core.record_policy, RecordErrorPolicy::Stop, "the default policy");
    let daemon = common::start(config, SpyDevice::new(2), trackers());
    let addr = daemon.http_addr();
    let path = daemon.recording_path().expect("recording");
    common::client_runtime().block_on(async {
        let mut ws = common::ws_connect(addr, "").await;
        let r = common::ask(
            &mut ws,
            r#"{"type":"setpoint","id":1,"channel":0,"temp_c":36,"rate_c_s":2}"#,
        )
        .await;
        assert_eq!(r["type"], "ok", "{r}");
        // 2 channels at 100 Hz fill 16 KiB in under a second; the event reaches every client.
        let event = loop {
            let m = common::next_json(&mut ws).await;
            if m["type"] == "event" {
                break m;
            }
        };
        assert_eq!(event["event"], "recording_failed", "{event}");
        let notices = daemon.take_notices();
        assert!(
            notices.len() == 1 && notices[0].contains("FAILED") && notices[0].contains(&path.display().to_string()),
            "{notices:?}"
        );
        assert_eq!(event["recording"]["state"], "failed", "{event}");
        assert_eq!(event["recording"]["stimuli_refused"], true, "{event}");
        let status = common::get_json(addr, "/api/status");
        let recording = &status["recording"];
        assert_eq!(recording["state"], "failed", "{recording}");
        assert!(
            recording["error"].as_str().is_some_and(|e| e.contains("16384 bytes")),
            "{recording}"
        );
        let (rows, newline) = rows_on_disk(&path);
        assert!(newline, "the file ends with a whole row");
        assert_eq!(
            recording["rows_written"].as_u64(),
            Some(rows),
            "{recording} vs {rows} rows in the file"
        );
        assert!(
            common::wait_until(5.0, || {
                let s = common::get_json(addr, "/api/status");
                s["contacts"] == serde_json::json!([]) && s["channels"][0]["held_off"] == true
            }),
            "every stimulus released and held off"
        );
        let refused = common::ask(&mut ws, r#"{"type":"touch","id":2,"channel":1,"material":"wood"}"#).await;
        assert_eq!(
            (refused["type"].as_str(), refused["code"].as_str()),
            (Some("error"), Some("recording_failed")),
            "{refused}"
        );
        let released = common::ask(&mut ws, r#"{"type":"release","id":3,"channel":1}"#).await;
        assert_eq!(released["type"], "ok", "a release is never refused: {released}");
        let ack = common::ask(&mut ws, r#"{"type":"ack_recording","id":4}"#).await;
        assert_eq!(
            (ack["type"].as_str(), ack["acknowledged"].as_bool()),
            (Some("ok"), Some(true)),
            "{ack}"
        );
        let again = common::ask(&mut ws, r#"{"type":"touch","id":5,"channel":1,"material":"wood"}"#).await;
        assert_eq!(again["type"], "ok", "accepted after the acknowledgement: {again}");
        // The acknowledgement asks for a new file; the quota (a full disk) is still used up, so it stays failed,
        // says why, removes the empty new file, and does not trip the interlock again.
        assert!(
            common::wait_until(5.0, || common::get_json(addr, "/api/status")["recording"]["error"]
                .as_str()
                .is_some_and(|e| e.contains("cannot go on in a new file"))),
            "the failed resumption shows"
        );
        let status = common::get_json(addr, "/api/status");
        assert_eq!(status["recording"]["state"], "failed", "the recording stays failed");
        assert_eq!(status["recording"]["segment"], 1, "{}", status["recording"]);
        assert_eq!(status["interlock"]["engaged"], false, "{}", status["interlock"]);
    });
    let csv_files = std::fs::read_dir(dir.path())
        .expect("dir")
        .filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "csv"))
        })
        .count();
    assert_eq!(csv_files, 1, "the empty second file is removed");
    // The clock sidecar: the wall-clock time of the loop's zero.
    let sidecar = std::fs::read_to_string(path.with_extension("clock.json")).expect("clock sidecar");
    let sidecar: serde_json::Value = serde_json::from_str(&sidecar).expect("JSON");
    assert!(sidecar["loop_time_zero_unix_s"].as_f64().is_some(), "{sidecar}");
    let utc = sidecar["loop_time_zero_utc"].as_str().unwrap_or_default();
    assert!(
        utc.len() == 24 && utc.ends_with('Z') && utc.as_bytes()[10] == b'T',
        "ISO 8601: {utc}"
    );
    let notices = daemon.take_notices();
    assert!(
        notices.len() == 1 && notices[0].contains("cannot go on in a new file") && notices[0].contains("stands"),
        "{notices:?}"
    );
    assert!(daemon.take_notices().is_empty(), "told once");
    let report = daemon.stop().expect("stop");
    assert!(report.recording_error.is_some(), "the stop reports the error");
    assert_eq!(report.rows, Some(rows_on_disk(&path).0));
}

#[test]
fn with_the_policy_continue_a_failed_recording_is_reported_and_stimuli_go_on() {
    use thermode_runtime::recorder::RecordErrorPolicy;
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = common::test_config();
    config.core.record_dir = Some(dir.path().to_path_buf());
    config.core.record_max_bytes = Some(4 * 1024);
    config.core.record_policy = RecordErrorPolicy::Continue;
    let daemon = common::start(config, SpyDevice::new(2), trackers());
    let addr = daemon.http_addr();
    assert!(
        common::wait_until(10.0, || common::get_json(addr, "/api/status")["recording"]["state"]
            == "failed"),
        "the failure shows"
    );
    let status = common::get_json(addr, "/api/status");
    assert_eq!(status["recording"]["on_error"], "continue");
    assert_eq!(status["recording"]["stimuli_refused"], false);
    common::client_runtime().block_on(async {
        let mut ws = common::ws_connect(addr, "").await;
        let r = common::ask(&mut ws, r#"{"type":"touch","id":1,"channel":1,"material":"wood"}"#).await;
        assert_eq!(r["type"], "ok", "{r}");
    });
    assert!(daemon.take_notices()[0].contains("--on-record-error continue"));
}

#[test]
fn after_an_acknowledgement_a_failed_recording_goes_on_in_a_new_file() {
    use thermode_runtime::recorder::{QuotaFile, RecordState, SegmentOpener, SessionFile};
    let dir = tempfile::tempdir().expect("temp dir");
    let first_path = dir.path().join("session.csv");
    let file = std::fs::File::create(&first_path).expect("file");
    let next_dir = dir.path().to_path_buf();
    let opener: SegmentOpener = Box::new(move |segment| {
        let path = next_dir.join(format!("session_seg{segment}.csv"));
        let file: Box<dyn SessionFile> = Box::new(std::fs::File::create(&path)?);
        Ok((path, file))
    });
    let quota = Box::new(QuotaFile::new(file, 3000));
    let (recorder, feed) = Recorder::start_on(first_path.clone(), quota, None, Some(opener)).expect("recorder");
    let status = recorder.status();
    let clock = Arc::new(ManualClock::new());
    let mut handle = LoopHandle::spawn(
        LoopConfig::default(),
        Box::new(SpyDevice::new(2)),
        trackers(),
        clock.clone(),
        vec![feed],
        Arc::default(),
    )
    .expect("loop");
    let mut tick = 0u64;
    let mut run_until = |done: &dyn Fn() -> bool, what: &str| {
        while !done() {
            tick += 1;
            assert!(tick < 20_000, "{what}: never happened");
            clock.set(tick as f64 * PERIOD_S);
            let want = clock.now_s();
            assert!(
                common::wait_until(10.0, || handle.snapshot().time_s >= want),
                "tick {tick}"
            );
            if tick.is_multiple_of(50) {
                // The writer writes at least every 0.5 s of real time.
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
        }
    };
    assert!(
        common::wait_until(10.0, || handle.snapshot().stats.ticks >= 1),
        "first tick"
    );
    run_until(&|| status.state() == RecordState::Failed, "the first file failing");
    let failed_rows = status.rows_written();
    status.request_resume();
    run_until(&|| status.state() == RecordState::Ok, "going on in a new file");
    run_until(&|| status.rows_written() >= 100, "rows in the new file");
    handle.stop();
    drop(handle);
    let rows = recorder.finish().expect("the second file is whole");
    let second_path = dir.path().join("session_seg2.csv");
    assert_eq!(status.path(), second_path);
    assert_eq!(status.segment(), 2);
    assert_eq!(status.earlier_files(), vec![(first_path.clone(), failed_rows)]);
    assert_eq!(
        rows_on_disk(&first_path),
        (failed_rows, true),
        "the first file as it failed"
    );
    assert_eq!(
        rows_on_disk(&second_path),
        (rows, true),
        "rows counted = rows in the new file"
    );
    let text = std::fs::read_to_string(&second_path).expect("read");
    assert_eq!(text.lines().next(), Some(CSV_HEADER), "the new file has its header");
    assert!(
        status.rows_lost() > 0,
        "rows between the failure and the acknowledgement are lost"
    );
}

#[test]
fn a_torn_row_left_by_a_killed_daemon_is_cut_back_at_the_next_start_but_a_live_file_is_left_alone() {
    let dir = tempfile::tempdir().expect("temp dir");
    let torn = dir.path().join("session_20260101-000000.csv");
    let whole = dir.path().join("session_20260101-000001.csv");
    let live = dir.path().join("session_20260101-000002.csv");
    let other = dir.path().join("notes.csv");
    let rows = format!("{CSV_HEADER}\n0.000000,0,0,,air,32.0000\n");
    for path in [&torn, &live, &other] {
        std::fs::write(path, format!("{rows}0.010000,0,0,,ai")).expect("write");
    }
    std::fs::write(&whole, &rows).expect("write");
    // Another daemon still writing holds its file's lock.
    let writer = std::fs::OpenOptions::new().write(true).open(&live).expect("open");
    writer.try_lock().expect("lock");
    let (recorder, feed) = Recorder::start(dir.path()).expect("recorder");
    assert_eq!(
        recorder.repaired(),
        &[(torn.clone(), "0.010000,0,0,,ai".len() as u64)],
        "only the torn, unlocked session file is repaired"
    );
    assert_eq!(
        std::fs::read_to_string(&torn).expect("read"),
        rows,
        "cut to its last whole row"
    );
    assert_eq!(
        std::fs::read_to_string(&whole).expect("read"),
        rows,
        "a whole file untouched"
    );
    assert!(
        std::fs::read_to_string(&live).expect("read").ends_with(",ai"),
        "a live file untouched"
    );
    assert!(
        std::fs::read_to_string(&other).expect("read").ends_with(",ai"),
        "not a session file"
    );
    drop(feed);
    recorder.finish().expect("finish");
    // The daemon tells the operator.
    std::fs::write(&torn, format!("{rows}0.0")).expect("write");
    let mut config = common::test_config();
    config.core.record_dir = Some(dir.path().to_path_buf());
    let daemon = common::start(config, SpyDevice::new(1), trackers());
    let notices = daemon.take_notices();
    assert!(
        notices.len() == 1 && notices[0].contains("torn row") && notices[0].contains(&torn.display().to_string()),
        "{notices:?}"
    );
    daemon.stop().expect("stop");
}
