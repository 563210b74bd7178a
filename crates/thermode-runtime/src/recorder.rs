//! `--record DIR`: one CSV per session, one row per tick per channel, written by its own thread.
//!
//! The loop hands each tick's [`TickRecord`] to a bounded queue ([`RECORD_QUEUE_TICKS`] ticks, 8 s at 1 kHz) and
//! never waits; a full queue drops the record and counts it. The writer formats whole ticks into its buffer and
//! writes the buffer at least every [`FLUSH_INTERVAL_S`] of real time (or once it holds [`WRITE_CHUNK_BYTES`]), so a
//! crash loses at most the last half second. Every write holds whole rows only, and rows are counted once they are
//! written ([`RecordStatus::rows_written`]).
//!
//! A write that fails (a full disk, a quota, an I/O error) or writes only part of its rows leaves the file cut back
//! to its last whole row (the whole rows that made it are kept and counted): the file always ends with a newline
//! and holds exactly [`RecordStatus::rows_written`] rows. The recording then stops for the session ([`RecordState::Failed`], with the error): the status says so at
//! once, the writer trips the [`Interlock`] it was given (the daemon's policy `stop`: every stimulus released, new ones
//! refused until an operator acknowledges), and it keeps taking the loop's records (counted as lost,
//! [`RecordStatus::rows_lost`]) so the loop never sees a full queue. When the loop stops, the writer syncs the file
//! and its directory ([`Recorder::finish`]).
//!
//! Columns (the `render` CSV names and conventions): `time_s, channel, contact, material, mode, target_skin_c,
//! skin_c, display_setpoint_c, sensor_c, current_a, hot_side_c, fault` — `time_s` is loop time (the daemon clock's
//! seconds, about 0 at the start), `contact` 1 while a material is touched and 0 otherwise, `material` its name
//! (empty otherwise), `mode` `air`, `touch` or `direct`, `fault` the numeric fault code (empty without fault).

use std::borrow::Cow;
use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use thermode_platform::utc_stamp;
use tokio::sync::watch;

use crate::error::RuntimeError;
use crate::interlock::Interlock;
use crate::snapshot::{Mode, TickRecord};

/// Capacity of the recorder queue \[ticks\].
pub const RECORD_QUEUE_TICKS: usize = 8192;
/// Longest time between writes \[s\].
pub const FLUSH_INTERVAL_S: f64 = 0.5;
/// The buffer is written once it holds this much \[bytes\] (64 KiB), even before [`FLUSH_INTERVAL_S`].
pub const WRITE_CHUNK_BYTES: usize = 64 * 1024;
/// The CSV header.
pub const CSV_HEADER: &str =
    "time_s,channel,contact,material,mode,target_skin_c,skin_c,display_setpoint_c,sensor_c,current_a,hot_side_c,fault";

/// What the daemon does when the recording fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RecordErrorPolicy {
    /// Release every stimulus and refuse new ones until an operator acknowledges the failure (default).
    #[default]
    Stop,
    /// Report the failure everywhere and go on without recording.
    Continue,
}

impl RecordErrorPolicy {
    /// `stop` or `continue`.
    pub fn name(self) -> &'static str {
        match self {
            RecordErrorPolicy::Stop => "stop",
            RecordErrorPolicy::Continue => "continue",
        }
    }
}

/// Whether the recording is still being written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordState {
    /// Every row so far is in the file.
    Ok,
    /// A write failed: the file holds [`RecordStatus::rows_written`] whole rows and no more will be written.
    Failed,
}

/// The recording's state, shared by the writer, the status page and the WebSocket events.
#[derive(Debug)]
pub struct RecordStatus {
    path: PathBuf,
    rows_written: AtomicU64,
    bytes_written: AtomicU64,
    rows_lost: AtomicU64,
    error: Mutex<Option<String>>,
    /// (failures, acknowledgements), bumped at each; WebSocket connections watch it to send their events.
    changed: watch::Sender<(u64, u64)>,
}

impl RecordStatus {
    fn new(path: PathBuf) -> Self {
        RecordStatus {
            path,
            rows_written: AtomicU64::new(0),
            bytes_written: AtomicU64::new(0),
            rows_lost: AtomicU64::new(0),
            error: Mutex::new(None),
            changed: watch::Sender::new((0, 0)),
        }
    }

    /// The session file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Rows in the file (written, whole; the header not counted).
    pub fn rows_written(&self) -> u64 {
        self.rows_written.load(Ordering::SeqCst)
    }

    /// Bytes in the file, the header included.
    pub fn bytes_written(&self) -> u64 {
        self.bytes_written.load(Ordering::SeqCst)
    }

    /// Rows the loop produced after the recording failed (or that a failed write could not hold).
    pub fn rows_lost(&self) -> u64 {
        self.rows_lost.load(Ordering::SeqCst)
    }

    /// `Ok` or `Failed`.
    pub fn state(&self) -> RecordState {
        if self.error().is_some() {
            RecordState::Failed
        } else {
            RecordState::Ok
        }
    }

    /// The write error, once the recording failed.
    pub fn error(&self) -> Option<String> {
        self.error.lock().ok().and_then(|e| e.clone())
    }

    /// A receiver of the (failures, acknowledgements) counts: it sees every failure and every acknowledgement.
    pub fn subscribe(&self) -> watch::Receiver<(u64, u64)> {
        self.changed.subscribe()
    }

    /// An operator acknowledged the failure (for the events; the interlock itself is acknowledged separately).
    pub fn acknowledged(&self) {
        self.changed.send_modify(|(_, acks)| *acks += 1);
    }

    fn fail(&self, error: String) {
        if let Ok(mut slot) = self.error.lock() {
            slot.get_or_insert(error);
        }
        self.changed.send_modify(|(failures, _)| *failures += 1);
    }
}

/// The session file as the writer uses it: writes, cutting back to a length, syncing. [`File`] is one;
/// [`QuotaFile`] another (a quota that fails like a full disk).
pub trait SessionFile: Send {
    /// Writes some of `bytes` at the end (as `Write::write`): the count written, or the error.
    fn write_some(&mut self, bytes: &[u8]) -> std::io::Result<usize>;
    /// Cuts the file to `len` bytes and continues writing there.
    fn cut_to(&mut self, len: u64) -> std::io::Result<()>;
    /// Syncs data and metadata to the disk.
    fn sync(&mut self) -> std::io::Result<()>;
}

impl SessionFile for File {
    fn write_some(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        Write::write(self, bytes)
    }

    fn cut_to(&mut self, len: u64) -> std::io::Result<()> {
        self.set_len(len)?;
        self.seek(SeekFrom::Start(len)).map(|_| ())
    }

    fn sync(&mut self) -> std::io::Result<()> {
        self.sync_all()
    }
}

/// A file that takes at most `max_bytes` and then fails as a full disk does: the write that crosses the quota
/// writes what fits, the next one fails with `StorageFull` (`--record-max-bytes`).
#[derive(Debug)]
pub struct QuotaFile<F> {
    inner: F,
    max_bytes: u64,
    len: u64,
}

impl<F: SessionFile> QuotaFile<F> {
    /// `inner`, empty, limited to `max_bytes` \[bytes\].
    pub fn new(inner: F, max_bytes: u64) -> Self {
        QuotaFile {
            inner,
            max_bytes,
            len: 0,
        }
    }
}

impl<F: SessionFile> SessionFile for QuotaFile<F> {
    fn write_some(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        let room = usize::try_from(self.max_bytes.saturating_sub(self.len)).unwrap_or(usize::MAX);
        if room == 0 && !bytes.is_empty() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::StorageFull,
                format!("the recording's quota of {} bytes is used up", self.max_bytes),
            ));
        }
        let n = self.inner.write_some(&bytes[..bytes.len().min(room)])?;
        self.len += n as u64;
        Ok(n)
    }

    fn cut_to(&mut self, len: u64) -> std::io::Result<()> {
        self.inner.cut_to(len)?;
        self.len = len;
        Ok(())
    }

    fn sync(&mut self) -> std::io::Result<()> {
        self.inner.sync()
    }
}

/// A running recorder.
#[derive(Debug)]
pub struct Recorder {
    status: Arc<RecordStatus>,
    thread: Option<JoinHandle<Result<(), std::io::Error>>>,
}

impl Recorder {
    /// Creates `dir` if needed and a new session file in it (`session_<UTC date-time>.csv`, or with `_2`, `_3`…
    /// if that exists). Returns the recorder and the queue the loop feeds.
    pub fn start(dir: &Path) -> Result<(Recorder, SyncSender<TickRecord>), RuntimeError> {
        Recorder::start_with(dir, None, None)
    }

    /// As [`Recorder::start`]; the file takes at most `max_bytes` (then fails as a full disk would), and a failure
    /// trips `interlock` (the policy `stop`).
    pub fn start_with(
        dir: &Path,
        max_bytes: Option<u64>,
        interlock: Option<Arc<Interlock>>,
    ) -> Result<(Recorder, SyncSender<TickRecord>), RuntimeError> {
        std::fs::create_dir_all(dir).map_err(|source| RuntimeError::Io {
            context: format!("cannot create the recording directory {}", dir.display()),
            source,
        })?;
        let (path, file) = create_session_file(dir, &session_stem())?;
        // The new file's name is durable once its directory is synced.
        sync_dir(dir);
        let file: Box<dyn SessionFile> = match max_bytes {
            Some(max) => Box::new(QuotaFile::new(file, max)),
            None => Box::new(file),
        };
        Recorder::start_on(path, file, interlock)
    }

    /// A recorder writing to `file`, shown as `path` (tests and drills: a file that fails on purpose).
    pub fn start_on(
        path: PathBuf,
        file: Box<dyn SessionFile>,
        interlock: Option<Arc<Interlock>>,
    ) -> Result<(Recorder, SyncSender<TickRecord>), RuntimeError> {
        let (feed, queue) = sync_channel(RECORD_QUEUE_TICKS);
        let status = Arc::new(RecordStatus::new(path));
        let thread = {
            let status = status.clone();
            std::thread::Builder::new()
                .name("thermode-recorder".into())
                .spawn(move || write_session(file, queue, &status, interlock.as_deref()))
                .map_err(|source| RuntimeError::Io {
                    context: "cannot start the recorder thread".into(),
                    source,
                })?
        };
        let recorder = Recorder {
            status,
            thread: Some(thread),
        };
        Ok((recorder, feed))
    }

    /// The session file.
    pub fn path(&self) -> &Path {
        self.status.path()
    }

    /// The shared state of the recording (for the status page).
    pub fn status(&self) -> Arc<RecordStatus> {
        self.status.clone()
    }

    /// Rows written so far.
    pub fn rows_written(&self) -> u64 {
        self.status.rows_written()
    }

    /// Waits until the writer has drained the queue and closed the file (the feed must be dropped first, i.e. the
    /// loop stopped). Returns the rows in the file, or the writer's I/O error (the file then holds
    /// [`RecordStatus::rows_written`] whole rows).
    pub fn finish(mut self) -> Result<u64, RuntimeError> {
        let result = match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(std::io::Error::other("recorder thread panicked")),
            None => Ok(()),
        };
        if let Some(dir) = self.path().parent() {
            sync_dir(dir);
        }
        result.map_err(|source| RuntimeError::Io {
            context: format!(
                "recording to {} ({} rows written)",
                self.path().display(),
                self.rows_written()
            ),
            source,
        })?;
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

/// Whole rows on their way to the file: the buffer, its row count, and the file's length so far.
struct Rows {
    file: Box<dyn SessionFile>,
    buffer: Vec<u8>,
    buffered_rows: u64,
    len: u64,
    /// The buffer begins with the header line (not a row).
    header_buffered: bool,
}

impl Rows {
    /// Writes the buffer. On any failure (a short write included) the file is cut back to its last whole row and
    /// the buffered rows are lost.
    fn write_out(&mut self, status: &RecordStatus) -> std::io::Result<()> {
        if self.buffer.is_empty() {
            return Ok(());
        }
        let mut done = 0;
        let result = loop {
            if done == self.buffer.len() {
                break Ok(());
            }
            match self.file.write_some(&self.buffer[done..]) {
                Ok(0) => break Err(std::io::Error::from(std::io::ErrorKind::WriteZero)),
                Ok(n) => done += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => break Err(e),
            }
        };
        match result {
            Ok(()) => {
                self.len += self.buffer.len() as u64;
                status.rows_written.fetch_add(self.buffered_rows, Ordering::SeqCst);
                status.bytes_written.store(self.len, Ordering::SeqCst);
            }
            Err(e) => {
                // What reached the file: keep its whole rows, cut off the partial one.
                let keep = self.buffer[..done]
                    .iter()
                    .rposition(|&b| b == b'\n')
                    .map_or(0, |i| i + 1);
                let lines = self.buffer[..keep].iter().filter(|&&b| b == b'\n').count() as u64;
                let kept_rows = lines.saturating_sub(u64::from(self.header_buffered && keep > 0));
                let mut result = Err(e);
                if done > keep {
                    if let Err(cut) = self.file.cut_to(self.len + keep as u64) {
                        let e = result.err().unwrap_or_else(|| std::io::Error::other("write failed"));
                        result = Err(std::io::Error::new(
                            e.kind(),
                            format!("{e}; cutting the file back to its last whole row failed too: {cut}"),
                        ));
                    }
                }
                self.len += keep as u64;
                status.rows_written.fetch_add(kept_rows, Ordering::SeqCst);
                status.bytes_written.store(self.len, Ordering::SeqCst);
                status
                    .rows_lost
                    .fetch_add(self.buffered_rows.saturating_sub(kept_rows), Ordering::SeqCst);
                self.clear();
                return result;
            }
        }
        self.clear();
        Ok(())
    }

    fn clear(&mut self) {
        self.buffer.clear();
        self.buffered_rows = 0;
        self.header_buffered = false;
    }
}

/// The writer thread: rows until the feed closes, written at least every [`FLUSH_INTERVAL_S`]. On a failure it
/// reports (status, interlock) and goes on draining the feed without writing.
fn write_session(
    file: Box<dyn SessionFile>,
    queue: Receiver<TickRecord>,
    status: &RecordStatus,
    interlock: Option<&Interlock>,
) -> Result<(), std::io::Error> {
    let mut rows = Rows {
        file,
        buffer: Vec::with_capacity(WRITE_CHUNK_BYTES + 4096),
        buffered_rows: 0,
        len: 0,
        header_buffered: true,
    };
    rows.buffer.extend_from_slice(CSV_HEADER.as_bytes());
    rows.buffer.push(b'\n');
    let mut failure: Option<std::io::Error> = None;
    let write_out = |rows: &mut Rows, failure: &mut Option<std::io::Error>| {
        if let Err(e) = rows.write_out(status) {
            let message = e.to_string();
            // The interlock first: whoever learns of the failure from the status sees stimuli refused already.
            if let Some(interlock) = interlock {
                interlock.trip(format!("recording to {} failed: {message}", status.path().display()));
            }
            status.fail(message);
            *failure = Some(e);
        }
    };
    write_out(&mut rows, &mut failure);
    let interval = Duration::from_secs_f64(FLUSH_INTERVAL_S);
    let mut last_write = Instant::now();
    loop {
        let open = match queue.recv_timeout(interval) {
            Ok(record) if failure.is_some() => {
                status
                    .rows_lost
                    .fetch_add(record.channels().len() as u64, Ordering::SeqCst);
                true
            }
            Ok(record) => {
                write_record(&mut rows.buffer, &record)?;
                rows.buffered_rows += record.channels().len() as u64;
                true
            }
            Err(RecvTimeoutError::Timeout) => true,
            Err(RecvTimeoutError::Disconnected) => false,
        };
        let due = last_write.elapsed() >= interval || rows.buffer.len() >= WRITE_CHUNK_BYTES || !open;
        if failure.is_none() && due {
            write_out(&mut rows, &mut failure);
            last_write = Instant::now();
        }
        if !open {
            break;
        }
    }
    match failure {
        Some(e) => Err(e),
        None => rows.file.sync(),
    }
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
