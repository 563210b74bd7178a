//! The loop core as one service: the dose ledger of a state directory, the recorder, the control loop and the
//! ledger's writer, started in the order that keeps every dose and every row ([`LoopCore::prepare`], then
//! [`PreparedCore::start`]) and stopped in the order that loses none ([`LoopCore::stop_loop`], then
//! [`LoopCore::finish`]). The network adapters (`thermode-serve`) attach to its two ports: [`LoopCore::commands`]
//! in, [`LoopCore::shared`] and the recording's events ([`crate::recorder::RecordStatus::listen`]) out, plus the
//! per-tick records of the taps given at the start.
//!
//! With a state directory ([`CoreConfig::state_dir`]) the thermal dose survives restarts ([`crate::ledger`]): the
//! directory is locked, its ledger read (a corrupt or unreadable one refuses the start: [`RuntimeError::Ledger`])
//! and written back once (an unwritable directory refuses the start), every channel's dose is restored into its
//! engine before the loop's first tick, and a writer thread keeps the ledger up to date until the stop, whose final
//! write follows the loop's last tick.

use std::path::{Path, PathBuf};
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex};

use thermode_device::{Device, DeviceError};
use thermode_platform::Clock;

use crate::command::CommandSender;
use crate::control_loop::{LoopConfig, LoopHandle};
use crate::engine::{with_restored_doses, EngineFactory};
use crate::error::RuntimeError;
use crate::interlock::Interlock;
use crate::ledger::{DoseWriter, Ledger, StateDir, WRITE_PERIOD_S};
use crate::recorder::{RecordErrorPolicy, RecordState, RecordStatus, Recorder, RESUME_FAILED};
use crate::snapshot::{Shared, Snapshot, TickRecord};

/// What the loop core needs besides the device, the engines and the clock.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CoreConfig {
    /// The control loop.
    pub loop_config: LoopConfig,
    /// Directory for the session CSV, if recording. Default none.
    pub record_dir: Option<PathBuf>,
    /// What a failed recording does. Default [`RecordErrorPolicy::Stop`].
    pub record_policy: RecordErrorPolicy,
    /// Largest session file \[bytes\]; a recording that reaches it fails as on a full disk. Default none.
    pub record_max_bytes: Option<u64>,
    /// The state directory of the dose ledger ([`crate::ledger`]), or `None`: then each channel's dose lives only
    /// as long as the loop (tests, the bench). Default `None`; `thermode serve` always gives one.
    pub state_dir: Option<PathBuf>,
}

/// The ledger read and the recorder started, the loop not yet: the adapters can still add taps (and write sidecars
/// beside the recording) before [`PreparedCore::start`].
#[derive(Debug)]
pub struct PreparedCore {
    config: CoreConfig,
    ledger: Option<(StateDir, Ledger)>,
    recorder: Option<Recorder>,
    feed: Option<SyncSender<TickRecord>>,
    interlock: Arc<Interlock>,
    notices: Vec<String>,
}

/// A running loop core.
#[derive(Debug)]
pub struct LoopCore {
    control: Option<LoopHandle>,
    /// What stopping the loop gave: the device's answer to all-off and the last tick's loop time \[s\].
    loop_stop: Option<(Option<Result<(), DeviceError>>, f64)>,
    recorder: Option<Recorder>,
    dose_writer: Option<DoseWriter>,
    ledger_path: Option<PathBuf>,
    recording: Option<Arc<RecordStatus>>,
    interlock: Arc<Interlock>,
    notices: Mutex<Notices>,
}

/// What [`LoopCore::take_notices`] has told already.
#[derive(Debug, Default)]
struct Notices {
    /// Lines from the start, not told yet.
    pending: Vec<String>,
    /// The recording's failures and resumptions already told.
    recording_failures: u64,
    recording_resumptions: u64,
    /// Per device part ([`LoopHandle::device_parts`]): its link's failures and reconnections already told.
    links: Vec<(u64, u64)>,
    /// The dose hold (an unwritable ledger) was told as on.
    dose_hold_told: bool,
}

/// What stopping the core did.
#[derive(Debug)]
pub struct CoreStop {
    /// The device's answer to switching every drive off at once: `Ok` when it took the command (on a serial display:
    /// the `AllOff` frame was written); `None` if the loop had already stopped.
    pub all_off: Option<Result<(), DeviceError>>,
    /// Loop time of the last tick \[s\].
    pub last_tick_s: f64,
    /// Rows recorded (written, whole, flushed and synced), if recording.
    pub rows: Option<u64>,
    /// Why the recording failed, if it did (the file then holds `rows` whole rows).
    pub recording_error: Option<String>,
}

impl LoopCore {
    /// Checks the loop's configuration, reads the dose ledger (refusing a corrupt, unreadable or unwritable one
    /// before anything drives) and starts the recorder, with its clock sidecar, if recording.
    pub fn prepare(config: CoreConfig, clock: &dyn Clock) -> Result<PreparedCore, RuntimeError> {
        config.loop_config.validate()?;
        let ledger = match &config.state_dir {
            Some(dir) => {
                let state = StateDir::open(dir)?;
                let ledger = state.load()?;
                state.store(&ledger)?;
                Some((state, ledger))
            }
            None => None,
        };
        let interlock = Arc::new(Interlock::new());
        let mut notices = Vec::new();
        let (recorder, feed) = match &config.record_dir {
            Some(dir) => {
                let trips = (config.record_policy == RecordErrorPolicy::Stop).then(|| interlock.clone());
                let (recorder, feed) = Recorder::start_with(dir, config.record_max_bytes, trips)?;
                for (path, bytes) in recorder.repaired() {
                    notices.push(format!(
                        "thermode: {} ended in a torn row (a daemon killed mid-write): cut back to its last whole row \
                         ({bytes} bytes removed)",
                        path.display()
                    ));
                }
                write_clock_sidecar(&recorder.path(), clock)?;
                (Some(recorder), Some(feed))
            }
            None => (None, None),
        };
        Ok(PreparedCore {
            config,
            ledger,
            recorder,
            feed,
            interlock,
            notices,
        })
    }

    /// The loop's command queue (the command port).
    pub fn commands(&self) -> Option<CommandSender> {
        self.control.as_ref().map(LoopHandle::commands)
    }

    /// The loop's published state (the snapshot port), while it runs.
    pub fn shared(&self) -> Option<Arc<Shared>> {
        self.control.as_ref().map(LoopHandle::shared)
    }

    /// The running loop, until [`LoopCore::stop_loop`].
    pub fn control(&self) -> Option<&LoopHandle> {
        self.control.as_ref()
    }

    /// A copy of the loop's newest snapshot.
    pub fn snapshot(&self) -> Option<Snapshot> {
        self.control.as_ref().map(LoopHandle::snapshot)
    }

    /// The dose ledger file, when the core has a state directory.
    pub fn ledger_path(&self) -> Option<&Path> {
        self.ledger_path.as_deref()
    }

    /// The dose ledger writer's state, when the core has a state directory.
    pub fn dose_ledger(&self) -> Option<Arc<crate::ledger::WriterStatus>> {
        self.dose_writer.as_ref().map(DoseWriter::status)
    }

    /// The session CSV, when recording.
    pub fn recording_path(&self) -> Option<PathBuf> {
        self.recorder.as_ref().map(Recorder::path)
    }

    /// The recording's shared state (and its event port), when recording.
    pub fn recording(&self) -> Option<Arc<RecordStatus>> {
        self.recording.clone()
    }

    /// The interlock the loop obeys.
    pub fn interlock(&self) -> Arc<Interlock> {
        self.interlock.clone()
    }

    /// What the operator must be told since the last call, one line each (a repaired recording at the start, a
    /// failed recording, the device link going down and coming back).
    pub fn take_notices(&self) -> Vec<String> {
        let Ok(mut seen) = self.notices.lock() else {
            return Vec::new();
        };
        let mut lines = std::mem::take(&mut seen.pending);
        if let Some(r) = &self.recording {
            recording_notices(r, &self.interlock, &mut seen, &mut lines);
        }
        match (self.interlock.dose_hold(), seen.dose_hold_told) {
            (Some(reason), false) => {
                seen.dose_hold_told = true;
                lines.push(format!(
                    "thermode: the dose ledger cannot be written ({reason}): every stimulus stopped; new ones are \
                     refused until a write succeeds again (retried every {WRITE_PERIOD_S} s)"
                ));
            }
            (None, true) => {
                seen.dose_hold_told = false;
                lines.push("thermode: the dose ledger is written again: stimuli are accepted".to_string());
            }
            _ => {}
        }
        if let Some(control) = &self.control {
            link_notices(control.device_parts(), &mut seen.links, &mut lines);
        }
        lines
    }

    /// Stops the loop (its last act: every drive to 0 A at once, within one loop period); what it gave goes into
    /// [`LoopCore::finish`]'s report. Later calls do nothing.
    pub fn stop_loop(&mut self) {
        if let Some(mut control) = self.control.take() {
            let all_off = control.stop();
            self.loop_stop = Some((all_off, control.snapshot().time_s));
        }
    }

    /// Stops the loop if it still runs, then the dose ledger's writer (its final write holds the loop's last tick)
    /// and the recorder (every queued row written, flushed and synced). Later calls do nothing.
    pub fn finish(&mut self) -> Result<CoreStop, RuntimeError> {
        self.stop_loop();
        let (all_off, last_tick_s) = self.loop_stop.take().unwrap_or((None, f64::NAN));
        let mut report = CoreStop {
            all_off,
            last_tick_s,
            rows: None,
            recording_error: None,
        };
        let ledger = self.dose_writer.take().map(DoseWriter::finish).transpose();
        if let Some(recorder) = self.recorder.take() {
            let status = recorder.status();
            match recorder.finish() {
                Ok(rows) => report.rows = Some(rows),
                Err(e) => {
                    report.rows = Some(status.rows_written());
                    report.recording_error = Some(e.to_string());
                }
            }
        }
        ledger?;
        Ok(report)
    }
}

impl PreparedCore {
    /// The session CSV, when recording (adapters write their sidecars beside it).
    pub fn recording_path(&self) -> Option<PathBuf> {
        self.recorder.as_ref().map(Recorder::path)
    }

    /// Starts the loop on `device` with `engines` (each channel's saved dose restored first) and the ledger's
    /// writer; `taps` receive every tick's record besides the recorder.
    pub fn start(
        self,
        device: Box<dyn Device + Send>,
        engines: EngineFactory,
        clock: Arc<dyn Clock>,
        mut taps: Vec<SyncSender<TickRecord>>,
    ) -> Result<LoopCore, RuntimeError> {
        taps.extend(self.feed);
        if let Some((state, saved)) = &self.ledger {
            saved.check_channels(device.channel_count(), &state.ledger_path())?;
        }
        let engines = match &self.ledger {
            Some((_, saved)) => {
                let saved = saved.clone();
                with_restored_doses(engines, move |channel| saved.dose(channel))
            }
            None => engines,
        };
        let control = LoopHandle::spawn(
            self.config.loop_config.clone(),
            device,
            engines,
            clock,
            taps,
            self.interlock.clone(),
        )?;
        let ledger_path = self.ledger.as_ref().map(|(state, _)| state.ledger_path());
        let dose_writer = match self.ledger {
            Some((state, saved)) => Some(
                DoseWriter::start(state, saved, control.shared(), self.interlock.clone()).map_err(|source| {
                    RuntimeError::Io {
                        context: "cannot start the dose ledger thread".into(),
                        source,
                    }
                })?,
            ),
            None => None,
        };
        Ok(LoopCore {
            recording: self.recorder.as_ref().map(Recorder::status),
            control: Some(control),
            loop_stop: None,
            recorder: self.recorder,
            dose_writer,
            ledger_path,
            interlock: self.interlock,
            notices: Mutex::new(Notices {
                pending: self.notices,
                ..Notices::default()
            }),
        })
    }
}

impl Drop for LoopCore {
    fn drop(&mut self) {
        let _ = self.finish();
    }
}

/// The lines the device links' new failures and reconnections owe the operator: one display device as before
/// (every channel faulted), several named with their channels (only those faulted). `seen` holds, per part, the
/// failures and reconnections told already.
fn link_notices(parts: &[thermode_device::DevicePart], seen: &mut Vec<(u64, u64)>, lines: &mut Vec<String>) {
    seen.resize(parts.len(), (0, 0));
    let several = parts.len() > 1;
    for (part, (told_failures, told_reconnects)) in parts.iter().zip(seen.iter_mut()) {
        let Some(link) = &part.health else { continue };
        let (failures, reconnects) = (link.failures(), link.reconnects());
        let channels = part.channels().map(|c| c.to_string()).collect::<Vec<_>>().join(", ");
        if failures > *told_failures {
            *told_failures = failures;
            let which = if several {
                format!("channels {channels} of {} faulted, 0 A; the others go on", part.label)
            } else {
                "every channel faulted, 0 A".to_string()
            };
            lines.push(format!(
                "thermode: device link DOWN: {}; reconnecting with back-off ({which})",
                link.error().unwrap_or_default()
            ));
        }
        if reconnects > *told_reconnects {
            *told_reconnects = reconnects;
            let what = if several {
                format!("{} (channels {channels})", part.label)
            } else {
                "channels".to_string()
            };
            lines.push(format!(
                "thermode: device link back up (reconnection {reconnects}); {what} resume once their faults are \
                 cleared (clear_fault)"
            ));
        }
    }
}

/// The lines a recording's new failures and resumptions owe the operator.
fn recording_notices(r: &RecordStatus, interlock: &Interlock, seen: &mut Notices, lines: &mut Vec<String>) {
    let events = r.events();
    if events.failures > seen.recording_failures && r.state() == RecordState::Failed {
        seen.recording_failures = events.failures;
        let error = r.error().unwrap_or_default();
        let what = if error.starts_with(RESUME_FAILED) {
            "the acknowledgement stands (stimuli allowed, unrecorded); acknowledge again to retry"
        } else if interlock.engaged() {
            "every stimulus released; new ones are refused until an operator acknowledges \
             (ack_recording, or the dashboard's button), which also goes on in a new file"
        } else {
            "stimuli go on unrecorded (--on-record-error continue); an acknowledgement (ack_recording) \
             goes on in a new file"
        };
        lines.push(format!(
            "thermode: recording to {} FAILED: {}; {} rows written, the file ends with a whole row; {what}",
            r.path().display(),
            error,
            r.rows_written(),
        ));
    }
    if events.resumptions > seen.recording_resumptions {
        seen.recording_resumptions = events.resumptions;
        lines.push(format!(
            "thermode: recording goes on in {} (segment {}); rows produced meanwhile are lost ({} so far)",
            r.path().display(),
            r.segment(),
            r.rows_lost(),
        ));
    }
}

/// Writes `<recording stem>.clock.json` beside the session CSV: what its `time_s` column is (the loop clock,
/// monotonic seconds) and the wall-clock time (UTC, ISO 8601 and Unix seconds) of its zero, so that a lab can align
/// the recording with EEG or other streams (`unix_time_s = loop_time_zero_unix_s + time_s`). The session's later
/// segment files (`_seg2`, …) share the same clock.
fn write_clock_sidecar(csv: &Path, clock: &dyn Clock) -> Result<(), RuntimeError> {
    let (now_s, unix_s) = (clock.now_s(), clock.unix_time_s());
    let zero_unix_s = unix_s - now_s;
    let text = serde_json::json!({
        "recording": csv.file_name().map(|n| n.to_string_lossy().into_owned()),
        "time_s": "loop time: monotonic seconds of the daemon's clock (CLOCK_MONOTONIC), about 0 at the start",
        "loop_time_zero_utc": thermode_platform::utc_iso8601_ms(zero_unix_s),
        "loop_time_zero_unix_s": zero_unix_s,
        "measured_at_loop_time_s": now_s,
        "alignment": "unix_time_s = loop_time_zero_unix_s + time_s; with --lsl see the .lsl.json beside it",
    });
    let path = csv.with_extension("clock.json");
    std::fs::write(&path, format!("{text:#}\n")).map_err(|source| RuntimeError::Io {
        context: format!("cannot write {}", path.display()),
        source,
    })
}
