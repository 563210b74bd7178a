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
//! and holds exactly [`RecordStatus::rows_written`] rows. The recording then stops ([`RecordState::Failed`], with the
//! error): the status says so at once, the writer trips the [`Interlock`] it was given (the daemon's policy `stop`:
//! every stimulus released, new ones refused until an operator acknowledges), and it keeps taking the loop's records
//! (counted as lost, [`RecordStatus::rows_lost`]) so the loop never sees a full queue.
//!
//! An operator's acknowledgement ([`RecordStatus::request_resume`]) asks the writer to go on in a new file, the next
//! *segment* (`<session>_seg2.csv`, `_seg3`…, each with its header): the failed file is left as it is (whole rows), the
//! status then shows the new file, its rows and the earlier files. If the new file cannot be written either (the disk
//! is still full), the recording stays failed with that error, an empty new file is removed, and the interlock is not
//! tripped again for it (the operator has just acknowledged this failure); the next acknowledgement tries again. When
//! the loop stops, the writer syncs the file and its directory ([`Recorder::finish`]).
//!
//! Columns (the `render` CSV names and conventions): `time_s, channel, contact, material, mode, target_skin_c,
//! skin_c, display_setpoint_c, sensor_c, current_a, hot_side_c, fault` — `time_s` is loop time (the daemon clock's
//! seconds, about 0 at the start), `contact` 1 while a material is touched and 0 otherwise, `material` its name
//! (empty otherwise), `mode` `air`, `touch` or `direct`, `fault` the numeric fault code (empty without fault), then
//! the touched material's properties, `conductivity_w_mk, density_kg_m3, specific_heat_j_kgk, thickness_m` (empty
//! outside a touch), so that a recording of a custom material, which no library knows, reads back.
//! A stimulus program's events (segment starts, responses, ends) go beside it, in `<session>.events.csv`, written
//! by the daemon (`thermode_serve::program_events`).

use std::borrow::Cow;
use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use thermode_platform::utc_stamp;

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
pub const CSV_HEADER: &str = "time_s,channel,contact,material,mode,target_skin_c,skin_c,display_setpoint_c,sensor_c,\
                              current_a,hot_side_c,fault,conductivity_w_mk,density_kg_m3,specific_heat_j_kgk,thickness_m";

/// How the error of a failed resumption (a new file that cannot be written either) begins.
pub const RESUME_FAILED: &str = "cannot go on in a new file";

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
    path: Mutex<PathBuf>,
    rows_written: AtomicU64,
    bytes_written: AtomicU64,
    rows_lost: AtomicU64,
    error: Mutex<Option<String>>,
    /// The files of earlier segments and the rows each holds.
    earlier: Mutex<Vec<(PathBuf, u64)>>,
    /// An acknowledgement asked the writer to go on in a new file.
    resume_requested: AtomicBool,
    /// Failures, acknowledgements and resumptions, bumped at each.
    events: Mutex<RecordEvents>,
    /// Who is told of every change (the network side's event feeds).
    listeners: Listeners,
}

/// Told the new counts at every failure, acknowledgement and resumption (called on the thread that made the change:
/// it must only hand them on, never block).
pub type RecordListener = Box<dyn Fn(RecordEvents) + Send + Sync>;

#[derive(Default)]
struct Listeners(Mutex<Vec<RecordListener>>);

impl std::fmt::Debug for Listeners {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let count = self.0.lock().map_or(0, |l| l.len());
        write!(f, "{count} listener(s)")
    }
}

/// Counts of what happened to a recording, for those who report it as events.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RecordEvents {
    /// Writes that failed (and resumptions that could not start).
    pub failures: u64,
    /// Operator acknowledgements.
    pub acknowledgements: u64,
    /// Segments begun after a failure.
    pub resumptions: u64,
}

impl RecordStatus {
    fn new(path: PathBuf) -> Self {
        RecordStatus {
            path: Mutex::new(path),
            rows_written: AtomicU64::new(0),
            bytes_written: AtomicU64::new(0),
            rows_lost: AtomicU64::new(0),
            error: Mutex::new(None),
            earlier: Mutex::new(Vec::new()),
            resume_requested: AtomicBool::new(false),
            events: Mutex::new(RecordEvents::default()),
            listeners: Listeners::default(),
        }
    }

    /// The file being written (the current segment's).
    pub fn path(&self) -> PathBuf {
        self.path.lock().map(|p| p.clone()).unwrap_or_default()
    }

    /// The segment being written: 1 for the session's first file, 2 after the first resumption, …
    pub fn segment(&self) -> usize {
        self.earlier_files().len() + 1
    }

    /// The files of earlier segments, each with the rows it holds.
    pub fn earlier_files(&self) -> Vec<(PathBuf, u64)> {
        self.earlier.lock().map(|e| e.clone()).unwrap_or_default()
    }

    /// Rows in the current file (written, whole; the header not counted).
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

    /// The counts of failures, acknowledgements and resumptions so far.
    pub fn events(&self) -> RecordEvents {
        *self.events.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// `listener` is told the counts at every later change (the adapter's event port).
    pub fn listen(&self, listener: RecordListener) {
        self.listeners
            .0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(listener);
    }

    /// Bumps one count and tells every listener.
    fn changed(&self, bump: impl FnOnce(&mut RecordEvents)) {
        let events = {
            let mut events = self.events.lock().unwrap_or_else(PoisonError::into_inner);
            bump(&mut events);
            *events
        };
        for listener in self.listeners.0.lock().unwrap_or_else(PoisonError::into_inner).iter() {
            listener(events);
        }
    }

    /// An operator acknowledged the failure: counted for the events, and, while the recording is failed, the writer
    /// is asked to go on in a new file (the interlock itself is acknowledged separately).
    pub fn request_resume(&self) {
        if self.state() == RecordState::Failed {
            self.resume_requested.store(true, Ordering::SeqCst);
        }
        self.changed(|e| e.acknowledgements += 1);
    }

    fn take_resume_request(&self) -> bool {
        self.resume_requested.swap(false, Ordering::SeqCst)
    }

    fn fail(&self, error: String) {
        if let Ok(mut slot) = self.error.lock() {
            *slot = Some(error);
        }
        self.changed(|e| e.failures += 1);
    }

    /// The writer goes on in `path`: the current file joins the earlier ones and the error is cleared.
    fn resumed(&self, path: PathBuf) {
        let previous = self.path.lock().map(|mut p| std::mem::replace(&mut *p, path));
        if let (Ok(previous), Ok(mut earlier)) = (previous, self.earlier.lock()) {
            earlier.push((previous, self.rows_written()));
        }
        self.rows_written.store(0, Ordering::SeqCst);
        self.bytes_written.store(0, Ordering::SeqCst);
        if let Ok(mut slot) = self.error.lock() {
            *slot = None;
        }
        self.changed(|e| e.resumptions += 1);
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

/// A disk's worth of bytes shared by a recording's files (`--record-max-bytes`).
#[derive(Debug, Clone)]
pub struct Quota {
    max_bytes: u64,
    /// Bytes held by the files under this quota.
    used: Arc<AtomicU64>,
}

impl Quota {
    /// `max_bytes` \[bytes\], none used.
    pub fn new(max_bytes: u64) -> Self {
        Quota {
            max_bytes,
            used: Arc::new(AtomicU64::new(0)),
        }
    }

    /// `inner`, empty, under this quota.
    pub fn file<F: SessionFile>(&self, inner: F) -> QuotaFile<F> {
        QuotaFile {
            inner,
            quota: self.clone(),
            len: 0,
        }
    }
}

/// A file under a [`Quota`] that fails as a full disk does once the quota is used up: the write that crosses it
/// writes what fits, the next one fails with `StorageFull`.
#[derive(Debug)]
pub struct QuotaFile<F> {
    inner: F,
    quota: Quota,
    len: u64,
}

impl<F: SessionFile> QuotaFile<F> {
    /// `inner`, empty, alone under a quota of `max_bytes` \[bytes\].
    pub fn new(inner: F, max_bytes: u64) -> Self {
        Quota::new(max_bytes).file(inner)
    }
}

impl<F: SessionFile> SessionFile for QuotaFile<F> {
    fn write_some(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        let used = self.quota.used.load(Ordering::SeqCst);
        let room = usize::try_from(self.quota.max_bytes.saturating_sub(used)).unwrap_or(usize::MAX);
        if room == 0 && !bytes.is_empty() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::StorageFull,
                format!("the recording's quota of {} bytes is used up", self.quota.max_bytes),
            ));
        }
        let n = self.inner.write_some(&bytes[..bytes.len().min(room)])?;
        self.len += n as u64;
        self.quota.used.fetch_add(n as u64, Ordering::SeqCst);
        Ok(n)
    }

    fn cut_to(&mut self, len: u64) -> std::io::Result<()> {
        self.inner.cut_to(len)?;
        self.quota
            .used
            .fetch_sub(self.len.saturating_sub(len), Ordering::SeqCst);
        self.len = len;
        Ok(())
    }

    fn sync(&mut self) -> std::io::Result<()> {
        self.inner.sync()
    }
}

/// Opens the file of the next segment (given its number: 2, 3, …): its path and the file, or why not.
pub type SegmentOpener = Box<dyn FnMut(usize) -> std::io::Result<(PathBuf, Box<dyn SessionFile>)> + Send>;

/// A running recorder.
#[derive(Debug)]
pub struct Recorder {
    status: Arc<RecordStatus>,
    thread: Option<JoinHandle<Result<(), std::io::Error>>>,
    /// Earlier session files in the directory that ended in a torn row, and the bytes cut from each.
    repaired: Vec<(PathBuf, u64)>,
}

impl Recorder {
    /// Creates `dir` if needed and a new session file in it (`session_<UTC date-time>.csv`, or with `_2`, `_3`…
    /// if that exists). Returns the recorder and the queue the loop feeds.
    pub fn start(dir: &Path) -> Result<(Recorder, SyncSender<TickRecord>), RuntimeError> {
        Recorder::start_with(dir, None, None)
    }

    /// As [`Recorder::start`]; the files take at most `max_bytes` together (then fail as a full disk would), and a
    /// failure trips `interlock` (the policy `stop`).
    pub fn start_with(
        dir: &Path,
        max_bytes: Option<u64>,
        interlock: Option<Arc<Interlock>>,
    ) -> Result<(Recorder, SyncSender<TickRecord>), RuntimeError> {
        std::fs::create_dir_all(dir).map_err(|source| RuntimeError::Io {
            context: format!("cannot create the recording directory {}", dir.display()),
            source,
        })?;
        let repaired = repair_torn_sessions(dir);
        let stem = session_stem();
        let (path, file) = create_session_file(dir, &stem)?;
        // The new file's name is durable once its directory is synced.
        sync_dir(dir);
        let quota = max_bytes.map(Quota::new);
        let wrap = move |file: File| -> Box<dyn SessionFile> {
            match &quota {
                Some(quota) => Box::new(quota.file(file)),
                None => Box::new(file),
            }
        };
        let first = wrap(file);
        let dir = dir.to_path_buf();
        let opener: SegmentOpener = Box::new(move |segment| {
            let (path, file) =
                create_session_file(&dir, &format!("{stem}_seg{segment}")).map_err(std::io::Error::other)?;
            sync_dir(&dir);
            Ok((path, wrap(file)))
        });
        let (mut recorder, feed) = Recorder::start_on(path, first, interlock, Some(opener))?;
        recorder.repaired = repaired;
        Ok((recorder, feed))
    }

    /// A recorder writing to `file`, shown as `path`, going on after an acknowledged failure in the files `opener`
    /// gives (tests and drills: a file that fails on purpose).
    pub fn start_on(
        path: PathBuf,
        file: Box<dyn SessionFile>,
        interlock: Option<Arc<Interlock>>,
        opener: Option<SegmentOpener>,
    ) -> Result<(Recorder, SyncSender<TickRecord>), RuntimeError> {
        let (feed, queue) = sync_channel(RECORD_QUEUE_TICKS);
        let status = Arc::new(RecordStatus::new(path));
        let thread = {
            let status = status.clone();
            let session = Session {
                status,
                interlock,
                opener,
            };
            std::thread::Builder::new()
                .name("thermode-recorder".into())
                .spawn(move || session.write(file, queue))
                .map_err(|source| RuntimeError::Io {
                    context: "cannot start the recorder thread".into(),
                    source,
                })?
        };
        let recorder = Recorder {
            status,
            thread: Some(thread),
            repaired: Vec::new(),
        };
        Ok((recorder, feed))
    }

    /// The file being written.
    pub fn path(&self) -> PathBuf {
        self.status.path()
    }

    /// Earlier session files of the directory that a killed daemon left ending in a torn row (a write cut short
    /// at a page boundary by SIGKILL), each cut back to its last whole row at this start, with the bytes cut.
    pub fn repaired(&self) -> &[(PathBuf, u64)] {
        &self.repaired
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
            Ok(file) => {
                // Held while the file is written (released when the process ends, however it ends): a daemon that
                // starts on the same directory leaves a live file alone (see `repair_torn_sessions`).
                let _ = file.try_lock();
                return Ok((path, file));
            }
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

/// Cuts every `session_*.csv` of `dir` that does not end with a newline back to its last whole row (a daemon
/// killed in the middle of a write can leave part of a row: the kernel may stop a write to a file at a page
/// boundary for a fatal signal). Returns the files cut and the bytes cut from each; files it cannot read or cut, and
/// files another daemon is writing (it holds their lock), are left alone.
fn repair_torn_sessions(dir: &Path) -> Vec<(PathBuf, u64)> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut repaired = Vec::new();
    for path in entries.filter_map(|e| e.ok().map(|e| e.path())) {
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if !(name.starts_with("session_") && name.ends_with(".csv")) {
            continue;
        }
        if let Some(cut) = cut_torn_tail(&path) {
            repaired.push((path, cut));
        }
    }
    repaired.sort();
    repaired
}

/// Cuts `path` back to just after its last newline when it does not end with one: the bytes cut.
fn cut_torn_tail(path: &Path) -> Option<u64> {
    let file = OpenOptions::new().read(true).write(true).open(path).ok()?;
    file.try_lock().ok()?;
    let bytes = std::fs::read(path).ok()?;
    if bytes.is_empty() || bytes.last() == Some(&b'\n') {
        return None;
    }
    let keep = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    file.set_len(keep as u64).ok()?;
    file.sync_all().ok()?;
    Some((bytes.len() - keep) as u64)
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
        let (done, result) = write_fully(self.file.as_mut(), &self.buffer);
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

/// Writes all of `bytes` (retrying short writes): how many were written, and the error that stopped it.
fn write_fully(file: &mut dyn SessionFile, bytes: &[u8]) -> (usize, std::io::Result<()>) {
    let mut done = 0;
    while done < bytes.len() {
        match file.write_some(&bytes[done..]) {
            Ok(0) => return (done, Err(std::io::Error::from(std::io::ErrorKind::WriteZero))),
            Ok(n) => done += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return (done, Err(e)),
        }
    }
    (done, Ok(()))
}

impl Rows {
    /// A file and a buffer holding the header, ready for rows.
    fn new(file: Box<dyn SessionFile>) -> Self {
        let mut buffer = Vec::with_capacity(WRITE_CHUNK_BYTES + 4096);
        buffer.extend_from_slice(CSV_HEADER.as_bytes());
        buffer.push(b'\n');
        Rows {
            file,
            buffer,
            buffered_rows: 0,
            len: 0,
            header_buffered: true,
        }
    }
}

/// What the writer thread reports to: the status, the interlock it trips, and where later segments go.
struct Session {
    status: Arc<RecordStatus>,
    interlock: Option<Arc<Interlock>>,
    opener: Option<SegmentOpener>,
}

impl Session {
    /// The writer thread: rows until the feed closes, written at least every [`FLUSH_INTERVAL_S`]. On a failure it
    /// reports (status, interlock) and goes on draining the feed without writing, until an acknowledgement lets it
    /// go on in a new file.
    fn write(mut self, file: Box<dyn SessionFile>, queue: Receiver<TickRecord>) -> Result<(), std::io::Error> {
        let mut rows = Rows::new(file);
        let mut failure = self.write_out(&mut rows);
        let interval = Duration::from_secs_f64(FLUSH_INTERVAL_S);
        let mut last_write = Instant::now();
        loop {
            if failure.is_some() && self.status.take_resume_request() {
                if let Some(next) = self.next_segment() {
                    // The failed file keeps its whole rows: make them durable before leaving it.
                    let _ = rows.file.sync();
                    (rows, failure) = (next, None);
                }
            }
            let open = match queue.recv_timeout(interval) {
                Ok(record) if failure.is_some() => {
                    let lost = record.channels().len() as u64;
                    self.status.rows_lost.fetch_add(lost, Ordering::SeqCst);
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
                failure = self.write_out(&mut rows);
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

    /// Writes the buffer; a failure is reported at once (the interlock first: whoever learns of it from the
    /// status sees stimuli refused already) and returned.
    fn write_out(&self, rows: &mut Rows) -> Option<std::io::Error> {
        let e = rows.write_out(&self.status).err()?;
        let message = e.to_string();
        if let Some(interlock) = &self.interlock {
            interlock.trip(format!(
                "recording to {} failed: {message}",
                self.status.path().display()
            ));
        }
        self.status.fail(message);
        Some(e)
    }

    /// Opens the next segment's file and writes its header: the rows to go on with, or `None` (the recording
    /// stays failed with the reason; the interlock is not tripped again, as the operator has just acknowledged).
    fn next_segment(&mut self) -> Option<Rows> {
        let segment = self.status.segment() + 1;
        let Some(opener) = self.opener.as_mut() else {
            self.status
                .fail(format!("{RESUME_FAILED}: this recording has nowhere to open one"));
            return None;
        };
        let (path, mut file) = match opener(segment) {
            Ok(opened) => opened,
            Err(e) => {
                self.status.fail(format!("{RESUME_FAILED}: {e}"));
                return None;
            }
        };
        let header = format!("{CSV_HEADER}\n");
        if let (_, Err(e)) = write_fully(file.as_mut(), header.as_bytes()) {
            drop(file);
            // Nothing of the new file is worth keeping.
            let _ = std::fs::remove_file(&path);
            let shown = path.display();
            self.status.fail(format!("{RESUME_FAILED} ({shown}): {e}"));
            return None;
        }
        self.status.resumed(path);
        self.status.bytes_written.store(header.len() as u64, Ordering::SeqCst);
        let mut rows = Rows::new(file);
        rows.len = header.len() as u64;
        rows.buffer.clear();
        rows.header_buffered = false;
        Some(rows)
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
        write!(
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
        match row.material.filter(|_| touching) {
            Some(m) => writeln!(
                out,
                ",{},{},{},{}",
                m.conductivity_w_mk, m.density_kg_m3, m.specific_heat_j_kgk, m.thickness_m
            )?,
            None => writeln!(out, ",,,,")?,
        }
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
