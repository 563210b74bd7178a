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
//! missing ledger file is an empty ledger (the first start). The file is read like every input, through
//! `thermode_platform::fs::AtMost` (at most [`MAX_LEDGER_BYTES`]), and only from a regular file: its type is checked
//! before it is opened and again on the open file, which is opened non-blocking, so a device (`/dev/zero`) or a FIFO
//! put in its place is refused at once instead of eating memory or blocking the start for ever. Every value is
//! range-checked with a `Rule` naming its key: `channel` below `MAX_CHANNELS` (and, at the loop core's start,
//! below the display's channel count), `cem43_min` in \[0, [`MAX_CEM43_MIN`]\], `time_at_or_above_43_s` in
//! \[0, [`MAX_TIME_AT_OR_ABOVE_43_S`]\]; a merge saturates at those bounds, so what is written is always read back.
//!
//! The daemon restores every channel's dose into its engine before the loop's first tick, writes the ledger once
//! at start (so an unwritable state directory is refused before anything is driven), and then a [`DoseWriter`]
//! thread takes the loop's published dose every [`WRITE_PERIOD_S`] and writes it when it grew noticeably
//! ([`SIGNIFICANT_CEM43_MIN`] or any time at ≥ 43 °C or a lockout), and at least every [`IDLE_WRITE_S`] when it
//! grew at all: a SIGKILL loses at most a quarter of a second (plus one tick) of dose. Every value written is the
//! larger of what the file holds and what the loop reports ([`Ledger::merge`]), so the ledger on disk never goes
//! down: only [`StateDir::reset_channel`] and [`StateDir::reset_all`] lower it, and they log first.
//!
//! A ledger that cannot be written (a full disk, a read-only directory) must not let the dose be forgotten: the
//! writer's failure puts the [`Interlock`]'s dose hold on — the loop stops every stimulus and refuses new ones
//! (`CommandError::DoseNotRecorded`), `/api/status` and standard error say why — and the writer keeps trying every
//! period; the first write that succeeds again lifts the hold (no acknowledgement needed: the dose is safe on disk
//! again).

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use thermode_device::MAX_CHANNELS;
use thermode_model::params::{BadValue, Rule};
use thermode_platform::fs::{file_kind, AtMost};
use thermode_platform::{utc_iso8601, write_bytes_atomically};
use thermode_safety::DoseLedger;
use thiserror::Error;

use crate::interlock::Interlock;
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
/// Largest ledger file read \[bytes\]: 1 MiB (a ledger of every channel of the largest display is about 2 KiB).
pub const MAX_LEDGER_BYTES: u64 = 1 << 20;
/// Largest CEM43 a ledger holds \[CEM43-min\]: 10⁹, a billion times the default budget of 1 (48 °C held for about
/// 60 years). Finite, so it survives JSON; a merge saturates at it (a channel there is far over any budget) and a
/// file holding more is corrupt.
pub const MAX_CEM43_MIN: f64 = 1e9;
/// Largest time at or above 43 °C a ledger holds \[s\]: 3.2·10⁹ (about a century); a merge saturates at it and a
/// file holding more is corrupt.
pub const MAX_TIME_AT_OR_ABOVE_43_S: f64 = 3.2e9;

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
    /// merge never lowers the ledger; `now_utc` becomes the entry's time if anything changed. Totals saturate at
    /// [`MAX_CEM43_MIN`] and [`MAX_TIME_AT_OR_ABOVE_43_S`] (so +∞ is written as the bound, never lost); a dose that
    /// is NaN or negative changes nothing.
    pub fn merge(&mut self, channel: usize, dose: &DoseLedger, now_utc: &str) -> Change {
        let valid = |v: f64| v >= 0.0; // false for NaN
        if !valid(dose.cem43_min) || !valid(dose.time_at_or_above_43_s) {
            return Change::None;
        }
        let old = self.dose(channel);
        let new = DoseLedger {
            cem43_min: old.cem43_min.max(dose.cem43_min.min(MAX_CEM43_MIN)),
            time_at_or_above_43_s: old
                .time_at_or_above_43_s
                .max(dose.time_at_or_above_43_s.min(MAX_TIME_AT_OR_ABOVE_43_S)),
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
            check_entry(e.channel, &dose).map_err(|bad| corrupt(format!("channel {}: {bad}", e.channel)))?;
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

    /// Refuses an entry for a channel the display does not have (`channel_count` channels): a ledger of another
    /// display, or a damaged one; [`LedgerError::Corrupt`] naming the key `channel` and `path`.
    pub fn check_channels(&self, channel_count: usize, path: &Path) -> Result<(), LedgerError> {
        let last = Rule::Within {
            min: 0.0,
            max: channel_count.saturating_sub(1) as f64,
        };
        for &channel in self.channels.keys() {
            last.check("channel", channel as f64)
                .map_err(|bad| LedgerError::Corrupt {
                    path: path.to_path_buf(),
                    reason: format!(
                        "{bad} (the display has {channel_count} channels: is this another display's state directory? \
                         use that display's own --state-dir, or clear the channel with `thermode dose reset --channel \
                         {channel} --reason TEXT`)"
                    ),
                })?;
        }
        Ok(())
    }
}

/// One entry's values in their physical ranges: a channel any display can have, each total finite, not negative
/// and within its bound; the error names the key.
fn check_entry(channel: usize, dose: &DoseLedger) -> Result<(), BadValue> {
    let channels = Rule::Within {
        min: 0.0,
        max: (MAX_CHANNELS - 1) as f64,
    };
    channels.check("channel", channel as f64)?;
    let cem43 = Rule::Within {
        min: 0.0,
        max: MAX_CEM43_MIN,
    };
    cem43.check("cem43_min", dose.cem43_min)?;
    let time = Rule::Within {
        min: 0.0,
        max: MAX_TIME_AT_OR_ABOVE_43_S,
    };
    time.check("time_at_or_above_43_s", dose.time_at_or_above_43_s)?;
    Ok(())
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
                let _ = AtMost::new(&lock, 64).read_to_string(&mut text);
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

    /// Writes `ledger` atomically. A ledger file that is not a regular file (a FIFO or a device put in its place,
    /// which the atomic writer would write in place, and a FIFO without a reader would block for ever) is refused.
    pub fn store(&self, ledger: &Ledger) -> Result<(), LedgerError> {
        let path = self.ledger_path();
        let write = || match std::fs::metadata(&path) {
            Ok(meta) if !meta.is_file() => Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "it is {}, not a regular file (a dose ledger is written only as a regular file)",
                    file_kind(&meta.file_type())
                ),
            )),
            _ => write_bytes_atomically(&path, ledger.to_json().as_bytes()),
        };
        write().map_err(|source| LedgerError::Write {
            path: path.clone(),
            source,
        })
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
    match read_regular_text(&path, MAX_LEDGER_BYTES) {
        Ok(text) => Ledger::from_json(&text, &path),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Ledger::default()),
        Err(source) => Err(LedgerError::Unreadable { path, source }),
    }
}

/// The text of `path`, at most `limit` bytes, only if it is a regular file: the type is checked before the open
/// (following links) and again on the opened file, which is opened non-blocking so that a FIFO swapped in between
/// cannot block; anything else is `InvalidInput` naming what it is.
fn read_regular_text(path: &Path, limit: u64) -> io::Result<String> {
    let regular = |meta: std::fs::Metadata| {
        if meta.is_file() {
            Ok(())
        } else {
            Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "it is {}, not a regular file (a dose ledger is read only from a regular file)",
                    file_kind(&meta.file_type())
                ),
            ))
        }
    };
    regular(std::fs::metadata(path)?)?;
    let mut options = OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(rustix::fs::OFlags::NONBLOCK.bits() as i32);
    }
    let file = options.open(path)?;
    regular(file.metadata()?)?;
    let mut text = String::new();
    AtMost::new(file, limit).read_to_string(&mut text)?;
    Ok(text)
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
    /// Starts the writer of `state`, whose file holds `ledger`, following `shared`'s snapshots; a failed write puts
    /// `interlock`'s dose hold on, the next successful one lifts it.
    pub fn start(
        state: StateDir,
        ledger: Ledger,
        shared: Arc<Shared>,
        interlock: Arc<Interlock>,
    ) -> io::Result<DoseWriter> {
        let stop = Arc::new(AtomicBool::new(false));
        let status = Arc::new(WriterStatus {
            path: state.ledger_path(),
            ..WriterStatus::default()
        });
        let thread = {
            let (stop, status) = (stop.clone(), status.clone());
            std::thread::Builder::new()
                .name("thermode-dose".into())
                .spawn(move || keep_written(&state, ledger, &shared, &stop, &status, &interlock))?
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
    interlock: &Interlock,
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
                    interlock.lift_dose_hold();
                }
                Err(e) => {
                    status.errors.fetch_add(1, Ordering::Relaxed);
                    if let Ok(mut last) = status.last_error.lock() {
                        *last = Some(e.to_string());
                    }
                    interlock.hold_dose(e.to_string());
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
        let values: Vec<f64> = std::iter::once(1.002_317_692_453_837_7)
            .chain((0..2000u64).map(|i| f64::from_bits(0x3ff0_0000_0000_0000 + i * 1_037_353)))
            .collect();
        // Ten channels per ledger (MAX_CHANNELS): a channel beyond is refused since issue 23.
        for chunk in values.chunks(MAX_CHANNELS) {
            let mut l = Ledger::default();
            for (channel, &value) in chunk.iter().enumerate() {
                l.merge(channel, &dose(value, value * 60.0, false), "t");
            }
            let back = Ledger::from_json(&l.to_json(), Path::new("ledger.json")).unwrap_or_else(|e| panic!("{e}"));
            for (channel, &value) in chunk.iter().enumerate() {
                let d = back.dose(channel);
                assert_eq!(
                    (d.cem43_min.to_bits(), d.time_at_or_above_43_s.to_bits()),
                    (value.to_bits(), (value * 60.0).to_bits()),
                    "channel {channel}: {value} read back as {d:?}"
                );
            }
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

    /// A ledger holding `entry` (one channel's JSON object, as the file writes it).
    fn ledger_with(entry: &str) -> String {
        format!("{{\"format\": \"thermode-dose-ledger\", \"version\": 1, \"channels\": [{entry}]}}")
    }

    /// Reads the ledger of `dir` on another thread: the answer, or a panic if it blocks for 10 s (a FIFO
    /// blocked the start for ever).
    fn read_within_10_s(dir: &Path) -> Result<Ledger, LedgerError> {
        let (tx, rx) = std::sync::mpsc::channel();
        let dir = dir.to_path_buf();
        std::thread::spawn(move || {
            let _ = tx.send(read_ledger(&dir));
        });
        rx.recv_timeout(Duration::from_secs(10))
            .unwrap_or_else(|_| panic!("reading the ledger blocked for 10 s"))
    }

    fn unreadable_reason(result: Result<Ledger, LedgerError>) -> String {
        match result {
            Err(LedgerError::Unreadable { source, .. }) => source.to_string(),
            other => panic!("expected an unreadable ledger, got {other:?}"),
        }
    }

    fn corrupt_reason(result: Result<Ledger, LedgerError>) -> String {
        match result {
            Err(LedgerError::Corrupt { reason, .. }) => reason,
            other => panic!("expected a corrupt ledger, got {other:?}"),
        }
    }

    /// A link to `/dev/zero` grew `serve` to 3.3 GB in 6 s before; now it is refused before it is opened.
    #[cfg(unix)]
    #[test]
    fn a_ledger_linked_to_dev_zero_is_refused_as_a_device() {
        let tmp = tempfile::tempdir().unwrap();
        std::os::unix::fs::symlink("/dev/zero", tmp.path().join(LEDGER_FILE)).unwrap();
        let reason = unreadable_reason(read_within_10_s(tmp.path()));
        assert!(reason.contains("a device, not a regular file"), "{reason}");
    }

    /// A FIFO blocked the start for ever (deaf to SIGTERM); now it is refused at once.
    #[cfg(unix)]
    #[test]
    fn a_fifo_ledger_is_refused_without_blocking() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join(LEDGER_FILE);
        rustix::fs::mknodat(
            rustix::fs::CWD,
            &path,
            rustix::fs::FileType::Fifo,
            rustix::fs::Mode::from_raw_mode(0o600),
            0,
        )
        .unwrap();
        let reason = unreadable_reason(read_within_10_s(tmp.path()));
        assert!(reason.contains("a FIFO, not a regular file"), "{reason}");
        // Written: refused too (the atomic writer writes special files in place; a FIFO without a reader blocks).
        let state = StateDir::open(tmp.path()).unwrap();
        match state.store(&Ledger::default()) {
            Err(LedgerError::Write { source, .. }) => assert!(source.to_string().contains("a FIFO"), "{source}"),
            other => panic!("a FIFO written as the ledger: {other:?}"),
        }
        // Opened as the reader does (non-blocking), a FIFO does not block either: the second check refuses it.
        let mut options = OpenOptions::new();
        std::os::unix::fs::OpenOptionsExt::custom_flags(options.read(true), rustix::fs::OFlags::NONBLOCK.bits() as i32);
        let file = options.open(&path).unwrap();
        assert!(!file.metadata().unwrap().is_file());
    }

    /// A ledger larger than [`MAX_LEDGER_BYTES`] (a regular file full of spaces) is refused, not read whole.
    #[test]
    fn an_oversized_ledger_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let mut text = " ".repeat(MAX_LEDGER_BYTES as usize);
        text.push_str(&ledger_with(""));
        std::fs::write(tmp.path().join(LEDGER_FILE), text).unwrap();
        let reason = unreadable_reason(read_within_10_s(tmp.path()));
        assert!(reason.contains("larger than 1 MiB"), "{reason}");
    }

    /// 1e308, NaN, ∞-like and channel 99 were accepted; each is now refused naming its key.
    #[test]
    fn out_of_range_ledger_values_are_refused_naming_the_key() {
        let entry = |channel: &str, cem43: &str, time: &str| {
            ledger_with(&format!(
                "{{\"channel\": {channel}, \"cem43_min\": {cem43}, \"time_at_or_above_43_s\": {time}, \
                 \"lockout\": false, \"updated_utc\": \"2025-01-31T12:00:00Z\"}}"
            ))
        };
        let path = Path::new("dose-ledger.json");
        let cases = [
            (entry("0", "1e308", "0"), "cem43_min"),
            (entry("0", "1000000001", "0"), "cem43_min"),
            (entry("0", "0.5", "1e300"), "time_at_or_above_43_s"),
            (entry("0", "0.5", "-0.1"), "time_at_or_above_43_s"),
            (entry("99", "0.5", "0"), "`channel` = 99"),
            (entry("10", "0.5", "0"), "`channel` = 10"),
        ];
        for (text, key) in cases {
            let reason = corrupt_reason(Ledger::from_json(&text, path));
            assert!(reason.contains(key), "{text}: {reason} does not name {key}");
        }
        for nan in ["NaN", "\"NaN\"", "1e999"] {
            let text = entry("0", nan, "0");
            let reason = corrupt_reason(Ledger::from_json(&text, path));
            assert!(!reason.is_empty(), "{text}");
        }
        let good = entry("9", "1000000000", "0");
        assert!(
            Ledger::from_json(&good, path).is_ok(),
            "the bounds themselves are accepted"
        );
    }

    #[test]
    fn a_channel_the_display_does_not_have_is_refused_at_the_start() {
        let mut l = Ledger::default();
        l.merge(4, &dose(0.1, 0.0, false), "t");
        let path = Path::new("dose-ledger.json");
        assert!(l.check_channels(5, path).is_ok());
        match l.check_channels(2, path) {
            Err(LedgerError::Corrupt { reason, .. }) => {
                assert!(
                    reason.contains("`channel` = 4") && reason.contains("2 channels"),
                    "{reason}"
                );
            }
            other => panic!("channel 4 on a 2-channel display: {other:?}"),
        }
    }

    /// A dose beyond the bounds (an infinite one included) is written as the bound, never dropped, and reads back.
    #[test]
    fn a_merge_saturates_at_the_bounds_and_reads_back() {
        let mut l = Ledger::default();
        assert_eq!(l.merge(0, &dose(f64::INFINITY, 1e30, true), "t"), Change::Significant);
        assert_eq!(l.dose(0), dose(MAX_CEM43_MIN, MAX_TIME_AT_OR_ABOVE_43_S, true));
        let back = Ledger::from_json(&l.to_json(), Path::new("x")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, l);
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
