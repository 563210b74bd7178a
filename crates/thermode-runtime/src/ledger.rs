//! The dose ledger: each channel's thermal dose (CEM43-minutes, time at or above 43 °C, lockout, when last
//! updated) kept in a state directory, so that the dose survives a restart of the daemon — a restart no longer
//! resets the dose budget (before it did: a channel locked out at 42.5 °C reached 48 °C again after a restart).
//!
//! Files in the state directory (`thermode serve --state-dir DIR`; the default is chosen by the CLI):
//! - [`LEDGER_FILE`] (`dose-ledger.json`): the ledger, always replaced whole by
//!   `thermode_platform::fs::write_atomically` (temporary file, fsync, rename, fsync of the directory), so it is
//!   either the old or the new ledger, never half of one:
//!   `{"format": "thermode-dose-ledger", "version": 1, "channels": [{"channel": 0, "cem43_min": 1.02,
//!   "time_at_or_above_43_s": 3.1, "lockout": true, "updated_utc": "2025-01-31T12:00:00Z"}]}`.
//! - [`RESET_LOG_FILE`] (`dose-reset.log`): append-only, one line per reset (UTC time, channel, the dose that was
//!   cleared, the reason), synced before the ledger is changed.
//! - [`LOCK_FILE`] (`dose.lock`): an advisory exclusive lock (`flock`, Unix) held by whoever may change the ledger
//!   — the daemon for its whole life, `thermode dose reset` while it resets — so two daemons cannot share a state
//!   directory and a reset cannot be silently overwritten by a running daemon. The kernel releases it when the
//!   holder dies, even by SIGKILL. (Elsewhere than Unix there is no lock.)
//!
//! Reading refuses anything but a well-formed ledger: unreadable, empty, malformed, unknown format or version,
//! unknown keys, duplicate channels, negative or non-finite totals are [`LedgerError`]s, never a silent reset. A
//! missing ledger file is an empty ledger (the first start).
//!
//! The daemon restores every channel's dose into its engine before the loop's first tick, writes the ledger once
//! at start (so an unwritable state directory is refused before anything is driven), and then a [`DoseWriter`]
//! thread takes the loop's published dose every [`WRITE_PERIOD_S`] and writes it when it grew noticeably
//! ([`SIGNIFICANT_CEM43_MIN`] or any time at ≥ 43 °C or a lockout), and at least every [`IDLE_WRITE_S`] when it
//! grew at all: a SIGKILL loses at most a quarter of a second (plus one tick) of dose. Every value written is the
//! larger of what the file holds and what the loop reports ([`Ledger::merge`]), so the ledger on disk never goes
//! down: only [`StateDir::reset_channel`] and [`StateDir::reset_all`] lower it, and they log first.

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use thermode_platform::{utc_iso8601, write_bytes_atomically};
use thermode_safety::DoseLedger;
use thiserror::Error;

use crate::snapshot::Shared;

/// The ledger's file name in the state directory.
pub const LEDGER_FILE: &str = "dose-ledger.json";
/// The reset log's file name in the state directory.
pub const RESET_LOG_FILE: &str = "dose-reset.log";
/// The lock file's name in the state directory.
pub const LOCK_FILE: &str = "dose.lock";
/// The `format` field of a ledger file.
pub const FORMAT: &str = "thermode-dose-ledger";
/// The `version` field of a ledger file this build writes and reads.
pub const VERSION: u32 = 1;
/// Period of the writer, s (real time): 0.25.
pub const WRITE_PERIOD_S: f64 = 0.25;
/// Growth of a channel's CEM43 that is written at the next period, CEM43-minutes: 1e-6 (10⁻⁷ of the largest
/// budget; 0.1 ms at 43 °C). Smaller growth — a resting finger at 32 °C adds 2.4·10⁻⁷ per minute — waits for
/// [`IDLE_WRITE_S`], so an idle daemon does not sync the disk four times a second.
pub const SIGNIFICANT_CEM43_MIN: f64 = 1e-6;
/// Longest time a growth below [`SIGNIFICANT_CEM43_MIN`] waits before it is written, s: 60.
pub const IDLE_WRITE_S: f64 = 60.0;
/// Most characters of a reset reason.
pub const MAX_REASON_CHARS: usize = 1000;

/// Why the ledger could not be read, written or reset.
#[derive(Debug, Error)]
pub enum LedgerError {
    /// The state directory could not be created or the lock file opened.
    #[error("cannot use the state directory {}: {source}", dir.display())]
    StateDir {
        /// The directory.
        dir: PathBuf,
        /// The operating system's reason.
        source: io::Error,
    },
    /// Another process (a running `thermode serve`?) holds the state directory.
    #[error(
        "the state directory {} is in use by another thermode process{holder}: stop it first (a running daemon \
         keeps each channel's dose and writes it back)",
        dir.display()
    )]
    InUse {
        /// The directory.
        dir: PathBuf,
        /// ` (pid N)` when the lock file names the holder, else empty.
        holder: String,
    },
    /// The ledger exists but cannot be read.
    #[error("cannot read the dose ledger {}: {source}; it is left as it is (nothing was reset)", path.display())]
    Unreadable {
        /// The ledger file.
        path: PathBuf,
        /// The operating system's reason.
        source: io::Error,
    },
    /// The ledger is not a well-formed ledger.
    #[error(
        "the dose ledger {} is corrupt: {reason}. It is left as it is and nothing was reset: repair it, or run \
         `thermode dose reset --all --reason TEXT` to set it aside (kept beside it) and start from no dose",
        path.display()
    )]
    Corrupt {
        /// The ledger file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The ledger or the reset log could not be written.
    #[error("cannot write {}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        source: io::Error,
    },
    /// A reset needs a reason (it is logged).
    #[error("a dose reset needs a reason (1 to {MAX_REASON_CHARS} characters, not only spaces); it is logged")]
    NoReason,
}

/// One channel's entry.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelEntry {
    /// The dose.
    pub dose: DoseLedger,
    /// When the dose last changed, UTC (`YYYY-MM-DDTHH:MM:SSZ`).
    pub updated_utc: String,
}

/// Every channel's dose, by channel number.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Ledger {
    channels: BTreeMap<usize, ChannelEntry>,
}

/// How much a merge changed a ledger.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Change {
    /// Nothing.
    None,
    /// Some CEM43, less than [`SIGNIFICANT_CEM43_MIN`].
    Small,
    /// At least [`SIGNIFICANT_CEM43_MIN`], any time at ≥ 43 °C, a lockout, or a new channel with a dose.
    Significant,
}

/// The file's layout (version 1).
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileV1 {
    format: String,
    version: u32,
    channels: Vec<EntryV1>,
}

/// One channel in the file.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct EntryV1 {
    channel: usize,
    cem43_min: f64,
    time_at_or_above_43_s: f64,
    lockout: bool,
    updated_utc: String,
}

impl Ledger {
    /// The entry of `channel`, if any.
    pub fn channel(&self, channel: usize) -> Option<&ChannelEntry> {
        self.channels.get(&channel)
    }

    /// The dose of `channel` (none recorded: zero).
    pub fn dose(&self, channel: usize) -> DoseLedger {
        self.channels.get(&channel).map_or_else(DoseLedger::default, |e| e.dose)
    }

    /// Every entry, by channel.
    pub fn entries(&self) -> impl Iterator<Item = (usize, &ChannelEntry)> {
        self.channels.iter().map(|(c, e)| (*c, e))
    }

    /// Whether no channel has an entry.
    pub fn is_empty(&self) -> bool {
        self.channels.is_empty()
    }

    /// Merges `dose` into `channel`'s entry: each total becomes the larger of the two and a lockout stays, so a
    /// merge never lowers the ledger; `now_utc` becomes the entry's time if anything changed. A dose that is not
    /// valid (negative or non-finite) changes nothing.
    pub fn merge(&mut self, channel: usize, dose: &DoseLedger, now_utc: &str) -> Change {
        if dose.validate().is_err() {
            return Change::None;
        }
        let old = self.dose(channel);
        let new = DoseLedger {
            cem43_min: old.cem43_min.max(dose.cem43_min),
            time_at_or_above_43_s: old.time_at_or_above_43_s.max(dose.time_at_or_above_43_s),
            lockout: old.lockout || dose.lockout,
        };
        let change = if new.time_at_or_above_43_s > old.time_at_or_above_43_s
            || new.lockout != old.lockout
            || new.cem43_min - old.cem43_min >= SIGNIFICANT_CEM43_MIN
        {
            Change::Significant
        } else if new.cem43_min > old.cem43_min {
            Change::Small
        } else {
            Change::None
        };
        if change != Change::None {
            self.channels.insert(
                channel,
                ChannelEntry {
                    dose: new,
                    updated_utc: now_utc.to_string(),
                },
            );
        }
        change
    }

    /// Removes `channel`'s entry (a reset); returns it.
    fn remove(&mut self, channel: usize) -> Option<ChannelEntry> {
        self.channels.remove(&channel)
    }

    /// The ledger as the file's JSON (pretty, ending in a newline).
    pub fn to_json(&self) -> String {
        let file = FileV1 {
            format: FORMAT.to_string(),
            version: VERSION,
            channels: self
                .channels
                .iter()
                .map(|(&channel, e)| EntryV1 {
                    channel,
                    cem43_min: e.dose.cem43_min,
                    time_at_or_above_43_s: e.dose.time_at_or_above_43_s,
                    lockout: e.dose.lockout,
                    updated_utc: e.updated_utc.clone(),
                })
                .collect(),
        };
        // Serialising plain numbers, booleans and strings cannot fail.
        serde_json::to_string_pretty(&file).unwrap_or_default() + "\n"
    }

    /// Reads a ledger's JSON; anything but a well-formed ledger is [`LedgerError::Corrupt`] naming `path`.
    pub fn from_json(text: &str, path: &Path) -> Result<Ledger, LedgerError> {
        let corrupt = |reason: String| LedgerError::Corrupt {
            path: path.to_path_buf(),
            reason,
        };
        let file: FileV1 = serde_json::from_str(text).map_err(|e| corrupt(e.to_string()))?;
        if file.format != FORMAT {
            return Err(corrupt(format!("format {:?}, not {FORMAT:?}", file.format)));
        }
        if file.version != VERSION {
            return Err(corrupt(format!(
                "version {} (this thermode reads version {VERSION})",
                file.version
            )));
        }
        let mut ledger = Ledger::default();
        for e in file.channels {
            let dose = DoseLedger {
                cem43_min: e.cem43_min,
                time_at_or_above_43_s: e.time_at_or_above_43_s,
                lockout: e.lockout,
            };
            dose.validate()
                .map_err(|bad| corrupt(format!("channel {}: {bad}", e.channel)))?;
            let entry = ChannelEntry {
                dose,
                updated_utc: e.updated_utc,
            };
            if ledger.channels.insert(e.channel, entry).is_some() {
                return Err(corrupt(format!("channel {} appears twice", e.channel)));
            }
        }
        Ok(ledger)
    }
}

/// A state directory, locked for changes while this value lives (see the module documentation).
#[derive(Debug)]
pub struct StateDir {
    dir: PathBuf,
    /// Holds the advisory lock; released when dropped (or when the process dies).
    _lock: File,
}

impl StateDir {
    /// Creates `dir` if needed and takes its lock; [`LedgerError::InUse`] if another process holds it.
    pub fn open(dir: &Path) -> Result<StateDir, LedgerError> {
        let state_error = |source| LedgerError::StateDir {
            dir: dir.to_path_buf(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(state_error)?;
        let path = dir.join(LOCK_FILE);
        let mut lock = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(state_error)?;
        match try_lock(&lock) {
            Ok(true) => {}
            Ok(false) => {
                let mut text = String::new();
                let _ = lock.read_to_string(&mut text);
                let holder = text
                    .trim()
                    .parse::<u32>()
                    .map_or(String::new(), |pid| format!(" (pid {pid})"));
                return Err(LedgerError::InUse {
                    dir: dir.to_path_buf(),
                    holder,
                });
            }
            Err(source) => return Err(state_error(source)),
        }
        // Who holds it, for the message of the next one who tries (best effort).
        let _ = lock
            .set_len(0)
            .and_then(|()| lock.write_all(format!("{}\n", std::process::id()).as_bytes()));
        Ok(StateDir {
            dir: dir.to_path_buf(),
            _lock: lock,
        })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The ledger file.
    pub fn ledger_path(&self) -> PathBuf {
        self.dir.join(LEDGER_FILE)
    }

    /// The reset log.
    pub fn log_path(&self) -> PathBuf {
        self.dir.join(RESET_LOG_FILE)
    }

    /// Reads the ledger (an empty one if the file does not exist).
    pub fn load(&self) -> Result<Ledger, LedgerError> {
        read_ledger(&self.dir)
    }

    /// Writes `ledger` atomically.
    pub fn store(&self, ledger: &Ledger) -> Result<(), LedgerError> {
        let path = self.ledger_path();
        write_bytes_atomically(&path, ledger.to_json().as_bytes()).map_err(|source| LedgerError::Write { path, source })
    }

    /// Appends one line to the reset log and syncs it.
    fn log(&self, line: &str) -> Result<(), LedgerError> {
        let path = self.log_path();
        let write = || -> io::Result<()> {
            let mut file = OpenOptions::new().create(true).append(true).open(&path)?;
            file.write_all(line.as_bytes())?;
            file.write_all(b"\n")?;
            file.sync_all()
        };
        write().map_err(|source| LedgerError::Write { path, source })
    }

    /// Clears `channel`'s dose, logging first (UTC time, the cleared dose, `reason`). Returns the logged line.
    /// A corrupt ledger is refused (see [`StateDir::reset_all`]).
    pub fn reset_channel(&self, channel: usize, reason: &str) -> Result<String, LedgerError> {
        let reason = checked_reason(reason)?;
        let mut ledger = self.load()?;
        let cleared = ledger.remove(channel);
        let what = match &cleared {
            Some(e) => describe(&e.dose, &e.updated_utc),
            None => "no dose recorded".to_string(),
        };
        let line = format!("{} dose reset channel {channel}: {what}; reason: {reason:?}", utc_now());
        self.log(&line)?;
        if let Err(e) = self.store(&ledger) {
            let _ = self.log(&format!("{} dose reset channel {channel} FAILED: {e}", utc_now()));
            return Err(e);
        }
        Ok(line)
    }

    /// Clears every channel's dose, logging first; a ledger that cannot be read (corrupt) is renamed aside (to
    /// `dose-ledger.json.set-aside-<UTC>`) and logged as such, never deleted. Returns the logged lines.
    pub fn reset_all(&self, reason: &str) -> Result<Vec<String>, LedgerError> {
        let reason = checked_reason(reason)?;
        let now = utc_now();
        let mut lines = Vec::new();
        let mut set_aside = None;
        match self.load() {
            Ok(ledger) if ledger.is_empty() => {
                lines.push(format!(
                    "{now} dose reset all channels: no dose recorded; reason: {reason:?}"
                ));
            }
            Ok(ledger) => {
                for (channel, e) in ledger.entries() {
                    let what = describe(&e.dose, &e.updated_utc);
                    lines.push(format!(
                        "{now} dose reset channel {channel}: {what}; reason: {reason:?}"
                    ));
                }
            }
            Err(error @ (LedgerError::Corrupt { .. } | LedgerError::Unreadable { .. })) => {
                let why = match error {
                    LedgerError::Corrupt { reason, .. } => format!("the ledger was corrupt ({reason})"),
                    other => format!("the ledger was unreadable ({other})"),
                };
                let aside = self
                    .dir
                    .join(format!("{LEDGER_FILE}.set-aside-{}", now.replace(':', "")));
                lines.push(format!(
                    "{now} dose reset all channels: {why}; set aside as {}; reason: {reason:?}",
                    aside.display()
                ));
                set_aside = Some(aside);
            }
            Err(other) => return Err(other),
        }
        for line in &lines {
            self.log(line)?;
        }
        if let Some(aside) = set_aside {
            std::fs::rename(self.ledger_path(), &aside).map_err(|source| LedgerError::Write { path: aside, source })?;
        }
        if let Err(e) = self.store(&Ledger::default()) {
            let _ = self.log(&format!("{} dose reset all channels FAILED: {e}", utc_now()));
            return Err(e);
        }
        Ok(lines)
    }
}

/// Reads the ledger of `dir` without taking the lock (the file is replaced atomically, so a reader sees a whole
/// ledger); an empty ledger if the file does not exist.
pub fn read_ledger(dir: &Path) -> Result<Ledger, LedgerError> {
    let path = dir.join(LEDGER_FILE);
    match std::fs::read_to_string(&path) {
        Ok(text) => Ledger::from_json(&text, &path),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Ledger::default()),
        Err(source) => Err(LedgerError::Unreadable { path, source }),
    }
}

/// The reason, trimmed, if it is acceptable.
fn checked_reason(reason: &str) -> Result<&str, LedgerError> {
    let reason = reason.trim();
    if reason.is_empty() || reason.chars().count() > MAX_REASON_CHARS {
        Err(LedgerError::NoReason)
    } else {
        Ok(reason)
    }
}

/// A dose in words, for the log.
fn describe(dose: &DoseLedger, updated_utc: &str) -> String {
    format!(
        "cem43_min {} time_at_or_above_43_s {} lockout {} (updated {updated_utc})",
        dose.cem43_min, dose.time_at_or_above_43_s, dose.lockout
    )
}

/// Now, UTC, as `YYYY-MM-DDTHH:MM:SSZ`.
pub fn utc_now() -> String {
    let unix_s = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    utc_iso8601(unix_s as i64)
}

/// Takes the exclusive advisory lock without waiting: `Ok(false)` if another holds it.
#[cfg(unix)]
fn try_lock(file: &File) -> io::Result<bool> {
    match rustix::fs::flock(file, rustix::fs::FlockOperation::NonBlockingLockExclusive) {
        Ok(()) => Ok(true),
        Err(e) if e == rustix::io::Errno::WOULDBLOCK => Ok(false),
        Err(e) => Err(e.into()),
    }
}

/// No advisory lock off Unix.
#[cfg(not(unix))]
fn try_lock(_file: &File) -> io::Result<bool> {
    Ok(true)
}

/// What the writer has done, for `/api/status`.
#[derive(Debug, Default)]
pub struct WriterStatus {
    /// The ledger file.
    pub path: PathBuf,
    /// Ledger writes since the start.
    pub writes: AtomicU64,
    /// Failed ledger writes since the start.
    pub errors: AtomicU64,
    /// The last write error, if any.
    pub last_error: Mutex<Option<String>>,
}

/// The thread that keeps the ledger up to date with the loop's dose (see the module documentation).
#[derive(Debug)]
pub struct DoseWriter {
    stop: Arc<AtomicBool>,
    status: Arc<WriterStatus>,
    thread: Option<JoinHandle<Result<(), LedgerError>>>,
}

impl DoseWriter {
    /// Starts the writer of `state`, whose file holds `ledger`, following `shared`'s snapshots.
    pub fn start(state: StateDir, ledger: Ledger, shared: Arc<Shared>) -> io::Result<DoseWriter> {
        let stop = Arc::new(AtomicBool::new(false));
        let status = Arc::new(WriterStatus {
            path: state.ledger_path(),
            ..WriterStatus::default()
        });
        let thread = {
            let (stop, status) = (stop.clone(), status.clone());
            std::thread::Builder::new()
                .name("thermode-dose".into())
                .spawn(move || keep_written(&state, ledger, &shared, &stop, &status))?
        };
        Ok(DoseWriter {
            stop,
            status,
            thread: Some(thread),
        })
    }

    /// The writer's counters.
    pub fn status(&self) -> Arc<WriterStatus> {
        self.status.clone()
    }

    /// Takes the newest snapshot once more (call it after the loop stopped: its final one), writes it, and ends
    /// the thread; the final write's error, if any.
    pub fn finish(mut self) -> Result<(), LedgerError> {
        self.stop_thread()
    }

    fn stop_thread(&mut self) -> Result<(), LedgerError> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(LedgerError::Write {
                path: self.status.path.clone(),
                source: io::Error::other("the dose ledger thread panicked"),
            }),
            None => Ok(()),
        }
    }
}

impl Drop for DoseWriter {
    fn drop(&mut self) {
        let _ = self.stop_thread();
    }
}

/// The writer's loop: merge the published dose every period, write when due; once more when stopped.
fn keep_written(
    state: &StateDir,
    mut written: Ledger,
    shared: &Shared,
    stop: &AtomicBool,
    status: &WriterStatus,
) -> Result<(), LedgerError> {
    let mut last_write = Instant::now();
    loop {
        let stopping = stop.load(Ordering::Relaxed);
        let snapshot = shared.snapshot();
        let mut next = written.clone();
        let now = utc_now();
        let change = snapshot
            .channels
            .iter()
            .map(|c| next.merge(c.channel, &c.dose, &now))
            .max()
            .unwrap_or(Change::None);
        let idle_due = change == Change::Small && last_write.elapsed().as_secs_f64() >= IDLE_WRITE_S;
        let due = change == Change::Significant || idle_due || (stopping && change != Change::None);
        let mut result = Ok(());
        if due {
            result = state.store(&next);
            match &result {
                Ok(()) => {
                    written = next;
                    last_write = Instant::now();
                    status.writes.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => {
                    status.errors.fetch_add(1, Ordering::Relaxed);
                    if let Ok(mut last) = status.last_error.lock() {
                        *last = Some(e.to_string());
                    }
                }
            }
        }
        if stopping {
            return result;
        }
        let until = Instant::now() + Duration::from_secs_f64(WRITE_PERIOD_S);
        while !stop.load(Ordering::Relaxed) && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dose(cem43_min: f64, time_at_or_above_43_s: f64, lockout: bool) -> DoseLedger {
        DoseLedger {
            cem43_min,
            time_at_or_above_43_s,
            lockout,
        }
    }

    #[test]
    fn utc_stamps_match_known_dates() {
        assert_eq!(utc_iso8601(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc_iso8601(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc_iso8601(1_700_000_000), "2023-11-14T22:13:20Z");
    }

    /// A dose read back is the dose written, to the bit (1.0023176924538377 came back an ulp lower, below the loop's
    /// dose, before JSON numbers were parsed with `float_roundtrip`).
    #[test]
    fn a_written_ledger_reads_back_to_the_bit() {
        let mut l = Ledger::default();
        let values: Vec<f64> = std::iter::once(1.002_317_692_453_837_7)
            .chain((0..2000u64).map(|i| f64::from_bits(0x3ff0_0000_0000_0000 + i * 1_037_353)))
            .collect();
        for (channel, &value) in values.iter().enumerate() {
            l.merge(channel, &dose(value, value * 60.0, false), "t");
        }
        let back = Ledger::from_json(&l.to_json(), Path::new("ledger.json")).unwrap_or_else(|e| panic!("{e}"));
        for (channel, &value) in values.iter().enumerate() {
            let d = back.dose(channel);
            assert_eq!(
                (d.cem43_min.to_bits(), d.time_at_or_above_43_s.to_bits()),
                (value.to_bits(), (value * 60.0).to_bits()),
                "channel {channel}: {value} read back as {d:?}"
            );
        }
    }

    #[test]
    fn a_merge_never_lowers_and_grades_the_change() {
        let mut l = Ledger::default();
        assert_eq!(l.merge(0, &dose(0.5, 1.0, false), "t1"), Change::Significant);
        assert_eq!(l.merge(0, &dose(0.4, 0.5, false), "t2"), Change::None);
        assert_eq!(l.dose(0), dose(0.5, 1.0, false));
        assert_eq!(l.channel(0).map(|e| e.updated_utc.as_str()), Some("t1"));
        assert_eq!(l.merge(0, &dose(0.5 + 1e-7, 1.0, false), "t3"), Change::Small);
        assert_eq!(l.merge(0, &dose(0.5, 1.0, true), "t4"), Change::Significant);
        assert_eq!(l.merge(0, &dose(0.0, 0.0, false), "t5"), Change::None);
        assert_eq!(l.dose(0), dose(0.5 + 1e-7, 1.0, true));
        assert_eq!(l.merge(1, &dose(f64::NAN, 0.0, false), "t6"), Change::None);
        assert_eq!(l.merge(1, &dose(0.0, 0.0, false), "t6"), Change::None);
        assert!(l.channel(1).is_none());
    }

    #[test]
    fn json_round_trips_and_anything_malformed_is_corrupt() {
        let mut l = Ledger::default();
        l.merge(0, &dose(1.0316, 3.25, true), "2025-01-31T12:00:00Z");
        l.merge(3, &dose(0.25, 0.0, false), "2025-01-31T12:00:01Z");
        let path = Path::new("dose-ledger.json");
        assert_eq!(Ledger::from_json(&l.to_json(), path).unwrap(), l);
        let good = l.to_json();
        let bad = [
            String::new(),
            "{".to_string(),
            good.replace("thermode-dose-ledger", "something-else"),
            good.replace("\"version\": 1", "\"version\": 2"),
            good.replace("\"lockout\": true", "\"lockout\": true, \"extra\": 1"),
            good.replace("1.0316", "-1.0"),
            good.replace("\"channel\": 3", "\"channel\": 0"),
            good.replace("1.0316", "\"a lot\""),
        ];
        for text in bad {
            match Ledger::from_json(&text, path) {
                Err(LedgerError::Corrupt { reason, .. }) => assert!(!reason.is_empty()),
                other => panic!("{text:?} read as {other:?}"),
            }
        }
    }

    #[test]
    fn the_lock_is_exclusive_and_released_on_drop() {
        let tmp = tempfile::tempdir().unwrap();
        let first = StateDir::open(tmp.path()).unwrap();
        match StateDir::open(tmp.path()) {
            Err(LedgerError::InUse { holder, .. }) if cfg!(unix) => {
                assert_eq!(holder, format!(" (pid {})", std::process::id()));
            }
            Ok(_) if !cfg!(unix) => {}
            other => panic!("second open: {other:?}"),
        }
        drop(first);
        StateDir::open(tmp.path()).unwrap();
    }

    #[test]
    fn resets_log_first_and_corrupt_ledgers_are_refused_or_set_aside() {
        let tmp = tempfile::tempdir().unwrap();
        let state = StateDir::open(tmp.path()).unwrap();
        assert!(state.load().unwrap().is_empty(), "no file: empty ledger");
        let mut l = Ledger::default();
        l.merge(0, &dose(1.5, 2.0, true), "2025-01-31T12:00:00Z");
        l.merge(1, &dose(0.1, 0.0, false), "2025-01-31T12:00:00Z");
        state.store(&l).unwrap();
        assert!(matches!(state.reset_channel(0, "  "), Err(LedgerError::NoReason)));
        let line = state.reset_channel(0, "new participant\n(P07)").unwrap();
        assert!(line.contains("dose reset channel 0: cem43_min 1.5"), "{line}");
        assert!(line.contains(r#"reason: "new participant\n(P07)""#), "{line}");
        let after = state.load().unwrap();
        assert!(after.channel(0).is_none());
        assert_eq!(after.dose(1), dose(0.1, 0.0, false));
        let log = std::fs::read_to_string(state.log_path()).unwrap();
        assert_eq!(log, format!("{line}\n"), "one line per reset, newlines escaped");
        // Corrupt: a channel reset is refused and changes nothing; reset --all sets the file aside.
        std::fs::write(state.ledger_path(), "{ not json").unwrap();
        assert!(matches!(state.reset_channel(1, "x"), Err(LedgerError::Corrupt { .. })));
        assert_eq!(std::fs::read_to_string(state.ledger_path()).unwrap(), "{ not json");
        let lines = state.reset_all("ledger damaged by a disk error").unwrap();
        assert_eq!(lines.len(), 1);
        assert!(lines[0].contains("set aside as"), "{}", lines[0]);
        assert!(state.load().unwrap().is_empty());
        let aside: Vec<_> = std::fs::read_dir(tmp.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains("set-aside"))
            .collect();
        assert_eq!(aside.len(), 1);
        assert_eq!(std::fs::read_to_string(aside[0].path()).unwrap(), "{ not json");
        let log = std::fs::read_to_string(state.log_path()).unwrap();
        assert_eq!(log.lines().count(), 2, "{log}");
    }
}
