//! `--record DIR`: one CSV per session, one row per tick per channel, written by its own thread.
//!
//! The loop hands each tick's [`TickRecord`] to a bounded queue ([`RECORD_QUEUE_TICKS`] ticks, 8 s at 1 kHz) and
//! never waits; a full queue drops the record and counts it. The writer flushes at least every
//! [`FLUSH_INTERVAL_S`] of real time, so a crash loses at most the last half second. Each tick's rows are formatted
//! first and handed to the file's buffer in one piece, so what reaches the file is whole rows (a kill tears none
//! unless it lands inside a write). When the loop stops, the writer drains the queue, flushes, and syncs the file
//! and its directory ([`Recorder::finish`]).
//!
//! Columns (the `render` CSV names and conventions): `time_s, channel, contact, material, mode, target_skin_c,
//! skin_c, display_setpoint_c, sensor_c, current_a, hot_side_c, fault` — `time_s` is loop time (the daemon clock's
//! seconds, about 0 at the start), `contact` 1 while a material is touched and 0 otherwise, `material` its name
//! (empty otherwise), `mode` `air`, `touch` or `direct`, `fault` the numeric fault code (empty without fault).

use std::borrow::Cow;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use thermode_platform::utc_stamp;

use crate::error::RuntimeError;
use crate::snapshot::{Mode, TickRecord};

/// Capacity of the recorder queue \[ticks\].
pub const RECORD_QUEUE_TICKS: usize = 8192;
/// Longest time between flushes \[s\].
pub const FLUSH_INTERVAL_S: f64 = 0.5;
/// The CSV header.
pub const CSV_HEADER: &str =
    "time_s,channel,contact,material,mode,target_skin_c,skin_c,display_setpoint_c,sensor_c,current_a,hot_side_c,fault";

/// A running recorder.
#[derive(Debug)]
pub struct Recorder {
    path: PathBuf,
    rows: Arc<AtomicU64>,
    thread: Option<JoinHandle<Result<(), std::io::Error>>>,
}

impl Recorder {
    /// Creates `dir` if needed and a new session file in it (`session_<UTC date-time>.csv`, or with `_2`, `_3`…
    /// if that exists). Returns the recorder and the queue the loop feeds.
    pub fn start(dir: &Path) -> Result<(Recorder, SyncSender<TickRecord>), RuntimeError> {
        std::fs::create_dir_all(dir).map_err(|source| RuntimeError::Io {
            context: format!("cannot create the recording directory {}", dir.display()),
            source,
        })?;
        let (path, file) = create_session_file(dir, &session_stem())?;
        // The new file's name is durable once its directory is synced.
        sync_dir(dir);
        let (feed, queue) = sync_channel(RECORD_QUEUE_TICKS);
        let rows = Arc::new(AtomicU64::new(0));
        let thread = {
            let rows = rows.clone();
            std::thread::Builder::new()
                .name("thermode-recorder".into())
                .spawn(move || write_session(file, queue, &rows))
                .map_err(|source| RuntimeError::Io {
                    context: "cannot start the recorder thread".into(),
                    source,
                })?
        };
        let recorder = Recorder {
            path,
            rows,
            thread: Some(thread),
        };
        Ok((recorder, feed))
    }

    /// The session file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The shared counter of rows written (for the status page).
    pub fn rows_counter(&self) -> Arc<AtomicU64> {
        self.rows.clone()
    }

    /// Rows written so far.
    pub fn rows_written(&self) -> u64 {
        self.rows.load(Ordering::Relaxed)
    }

    /// Waits until the writer has drained the queue and closed the file (the feed must be dropped first, i.e. the
    /// loop stopped). Returns the writer's I/O error, if any.
    pub fn finish(mut self) -> Result<u64, RuntimeError> {
        let result = match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(std::io::Error::other("recorder thread panicked")),
            None => Ok(()),
        };
        result.map_err(|source| RuntimeError::Io {
            context: format!("recording to {}", self.path.display()),
            source,
        })?;
        if let Some(dir) = self.path.parent() {
            sync_dir(dir);
        }
        Ok(self.rows_written())
    }
}

fn create_session_file(dir: &Path, stem: &str) -> Result<(PathBuf, File), RuntimeError> {
    for attempt in 1..=1000 {
        let name = if attempt == 1 {
            format!("{stem}.csv")
        } else {
            format!("{stem}_{attempt}.csv")
        };
        let path = dir.join(name);
        match OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(file) => return Ok((path, file)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(source) => {
                return Err(RuntimeError::Io {
                    context: format!("cannot create {}", path.display()),
                    source,
                })
            }
        }
    }
    Err(RuntimeError::Config(format!(
        "{} already holds 1000 session files named {stem}",
        dir.display()
    )))
}

/// Syncs a directory (best effort: not every platform or file system can).
fn sync_dir(dir: &Path) {
    if let Ok(handle) = File::open(dir) {
        let _ = handle.sync_all();
    }
}

/// The writer thread: rows until the feed closes, flushing at least every [`FLUSH_INTERVAL_S`].
fn write_session(file: File, queue: Receiver<TickRecord>, rows: &AtomicU64) -> Result<(), std::io::Error> {
    let mut out = BufWriter::with_capacity(1 << 16, file);
    writeln!(out, "{CSV_HEADER}")?;
    out.flush()?;
    let interval = Duration::from_secs_f64(FLUSH_INTERVAL_S);
    let mut last_flush = Instant::now();
    let mut tick_rows = Vec::with_capacity(1024);
    loop {
        match queue.recv_timeout(interval) {
            Ok(record) => {
                tick_rows.clear();
                write_record(&mut tick_rows, &record)?;
                out.write_all(&tick_rows)?;
                rows.fetch_add(record.channels().len() as u64, Ordering::Relaxed);
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if last_flush.elapsed() >= interval {
            out.flush()?;
            last_flush = Instant::now();
        }
    }
    out.flush()?;
    out.into_inner().map_err(|e| e.into_error())?.sync_all()
}

fn write_record(out: &mut impl Write, record: &TickRecord) -> std::io::Result<()> {
    for (channel, row) in record.channels().iter().enumerate() {
        let t = &row.telemetry;
        let fault = t.fault.map_or(String::new(), |f| f.code().to_string());
        let touching = row.mode == Mode::Touch;
        let material = if touching {
            csv_field(&row.label)
        } else {
            Cow::Borrowed("")
        };
        writeln!(
            out,
            "{:.6},{channel},{},{material},{},{:.4},{:.4},{:.4},{:.4},{:.5},{:.4},{fault}",
            record.time_s,
            u8::from(touching),
            mode_name(row.mode),
            t.target_skin_c,
            t.skin_c,
            t.display_setpoint_c,
            t.sensor_c,
            t.current_a,
            t.hot_side_c,
        )?;
    }
    Ok(())
}

/// The mode as written in the CSV and the API.
pub fn mode_name(mode: Mode) -> &'static str {
    match mode {
        Mode::Air => "air",
        Mode::Touch => "touch",
        Mode::Direct => "direct",
    }
}

/// A label as a CSV field (quoted when it holds a comma, quote or line break; labels are validated names, so this
/// is a second line of defence).
fn csv_field(label: &str) -> Cow<'_, str> {
    if label.contains([',', '"', '\n', '\r']) {
        Cow::Owned(format!("\"{}\"", label.replace('"', "\"\"")))
    } else {
        Cow::Borrowed(label)
    }
}

/// `session_YYYYMMDD-HHMMSS` in UTC (the file name only; nothing else reads the wall clock).
fn session_stem() -> String {
    let unix_s = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64());
    format!("session_{}", utc_stamp(unix_s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_quoted_only_when_needed() {
        assert_eq!(csv_field("aluminium"), "aluminium");
        assert_eq!(csv_field("a,b\"c"), "\"a,b\"\"c\"");
    }
}
