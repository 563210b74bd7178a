//! What the control loop publishes for the network side: a [`Snapshot`] of every channel and the loop statistics,
//! written by the loop each tick with `try_lock` (the loop never waits for a reader) and copied by readers, and the
//! per-tick [`TickRecord`] sent to the recorder (and to the bench) through a bounded queue.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use serde::Serialize;
use thermode_device::{DeviceCut, MAX_CHANNELS};
use thermode_safety::DoseLedger;

use crate::command::{Owner, ResponseKind};
use crate::engine::Telemetry;
use crate::stats::Summary;

/// Telemetry before a channel's first tick: every number NaN (shown as null), no contact, no fault.
pub const EMPTY_TELEMETRY: Telemetry = Telemetry {
    time_s: 0.0,
    contact: false,
    target_skin_c: f64::NAN,
    skin_c: f64::NAN,
    requested_setpoint_c: f64::NAN,
    display_setpoint_c: f64::NAN,
    sensor_c: f64::NAN,
    hot_side_c: f64::NAN,
    requested_current_a: f64::NAN,
    current_a: 0.0,
    plate_estimate_c: f64::NAN,
    finger_c: f64::NAN,
    fault: None,
};

/// What a channel renders. (The wire spells it `thermode_protocol::Mode`; the daemon converts at its edge.)
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Air: no contact.
    Air,
    /// A material contact.
    Touch,
    /// Direct set-point mode (a set-point or a program).
    Direct,
}

/// The properties of a touched material, as the recording names them (so that a custom material, which no library
/// knows, can be read back).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaterialProperties {
    /// Thermal conductivity k \[W/(m·K)\].
    pub conductivity_w_mk: f64,
    /// Density ρ \[kg/m³\].
    pub density_kg_m3: f64,
    /// Specific heat capacity c \[J/(kg·K)\].
    pub specific_heat_j_kgk: f64,
    /// Thickness of the touched object \[m\].
    pub thickness_m: f64,
}

impl MaterialProperties {
    /// The properties of `material`.
    pub fn of(material: &thermode_model::Material) -> Self {
        MaterialProperties {
            conductivity_w_mk: material.conductivity_w_mk,
            density_kg_m3: material.density_kg_m3,
            specific_heat_j_kgk: material.specific_heat_j_kgk,
            thickness_m: material.thickness_m,
        }
    }
}

/// A channel's program as the loop last saw it, and what happened to it on the newest tick (the per-tick fields are
/// cleared at the start of every tick).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ProgramMark {
    /// The running segment (`None`: no program runs, or it has ended).
    pub segment: Option<usize>,
    /// The segment that started on this tick: (segment, target \[°C\] of a ramp or step, cut-off \[°C\] if its
    /// target was clipped).
    pub started: Option<(usize, Option<f64>, Option<f64>)>,
    /// The program's last segment ended on this tick.
    pub ended: bool,
    /// The program was stopped on this tick before its end: the channel faulted or its device cut it (the channel
    /// then renders air; nothing of the program resumes).
    pub stopped: Option<ProgramStop>,
    /// The (last) response applied on this tick: its kind, its rating, and the `until: response` segment it
    /// ended (if it ended one).
    pub response: Option<(ResponseKind, Option<f64>, Option<usize>)>,
}

impl ProgramMark {
    /// Whether something happened on this tick (a segment's start, the end, a stop, a response).
    pub fn has_event(&self) -> bool {
        self.started.is_some() || self.ended || self.stopped.is_some() || self.response.is_some()
    }

    /// This tick's events cleared (the running segment kept).
    pub fn next_tick(&mut self) {
        (self.started, self.ended, self.stopped, self.response) = (None, false, None, None);
    }
}

/// Why a program stopped before its end.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProgramStop {
    /// The channel's safety envelope latched a fault.
    Fault(thermode_safety::FaultCode),
    /// The device's own protection cut the channel.
    DeviceCut(DeviceCut),
}

impl std::fmt::Display for ProgramStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ProgramStop::Fault(code) => write!(f, "the channel faulted: {code}"),
            ProgramStop::DeviceCut(cut) => write!(f, "the device cut the channel: {cut}"),
        }
    }
}

/// One channel as the loop last saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelStatus {
    /// Channel number (from 0).
    pub channel: usize,
    /// What the channel shows: `"air"`, the touched material's name (`"custom"` for properties without a name) or
    /// `"direct"`.
    pub label: Arc<str>,
    /// What the channel renders.
    pub mode: Mode,
    /// Object temperature of the contact \[°C\] (touch only).
    pub object_c: Option<f64>,
    /// The touched material's properties (touch only).
    pub material: Option<MaterialProperties>,
    /// Direct-mode target \[°C\] and rate \[°C/s\] (direct only).
    pub direct: Option<(f64, f64)>,
    /// After stop-all: the drive is held at 0 A until the channel's next command.
    pub held_off: bool,
    /// Who set the stimulus.
    pub owner: Owner,
    /// Loop time at which the contact of a disconnected client will be released \[s\].
    pub release_at_s: Option<f64>,
    /// The device answered the last read.
    pub link_ok: bool,
    /// The device's own protection has cut this channel (its over- or under-temperature cut): set while its reads
    /// say so, cleared by the next good read.
    pub device_cut: Option<DeviceCut>,
    /// The channel's engine failed (panicked): its drive is off for the rest of the session.
    pub engine_failed: bool,
    /// This tick's numbers.
    pub telemetry: Telemetry,
    /// The channel's thermal dose after this tick (CEM43, time at or above 43 °C, lockout), as its envelope counts
    /// it; restored from the dose ledger at the start.
    pub dose: DoseLedger,
    /// The channel's dose budget is spent (`SafetyEnvelope::dose_budget_spent`): its drive is off (0 A) and every
    /// stimulus but air is refused ([`crate::CommandError::DoseBudgetSpent`]) until the ledger is reset.
    pub dose_budget_spent: bool,
    /// The channel's program, and its events of this tick.
    pub program: ProgramMark,
}

/// Loop timing: the measured periods (wake to wake) and tick durations over the window, and missed deadlines.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct LoopStats {
    /// Configured rate \[Hz\].
    pub rate_hz: f64,
    /// Configured period \[s\].
    pub period_s: f64,
    /// Measured periods over the window.
    pub period: Summary,
    /// Measured work per tick (wake to done) over the window.
    pub work: Summary,
    /// Deadlines that got no tick of their own since the start (see `thermode_platform::Ticker`).
    pub missed_deadlines: u64,
    /// Ticks since the start.
    pub ticks: u64,
}

/// Everything the loop publishes.
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    /// Index of the newest tick.
    pub tick: u64,
    /// Loop time of the newest tick \[s\] (the loop clock's time at the tick's deadline).
    pub time_s: f64,
    /// Every channel.
    pub channels: Vec<ChannelStatus>,
    /// Loop timing (refreshed once a second).
    pub stats: LoopStats,
    /// Commands applied since the start.
    pub commands_applied: u64,
    /// Commands refused by the loop since the start.
    pub commands_refused: u64,
    /// Commands withdrawn by their requester before the loop took them (answered `busy`, never applied).
    pub commands_withdrawn: u64,
    /// Failed device reads or writes since the start.
    pub device_errors: u64,
    /// The loop is running (false once it stopped).
    pub running: bool,
}

/// One channel's row of a [`TickRecord`].
#[derive(Debug, Clone, PartialEq)]
pub struct RecordRow {
    /// The channel's label (`air`, the material's name, `direct`).
    pub label: Arc<str>,
    /// What the channel renders.
    pub mode: Mode,
    /// Object temperature of the contact \[°C\] (touch only).
    pub object_c: Option<f64>,
    /// The touched material's properties (touch only).
    pub material: Option<MaterialProperties>,
    /// Direct-mode target \[°C\] and rate \[°C/s\] (direct only).
    pub direct: Option<(f64, f64)>,
    /// After stop-all: the drive is held at 0 A until the channel's next command.
    pub held_off: bool,
    /// The numbers.
    pub telemetry: Telemetry,
    /// The channel's program and its events of this tick.
    pub program: ProgramMark,
}

/// One tick of every channel, for the recorder.
#[derive(Debug, Clone)]
pub struct TickRecord {
    /// Tick index.
    pub tick: u64,
    /// Loop time \[s\] (the tick's deadline).
    pub time_s: f64,
    /// When the loop woke for this tick \[s, loop clock\].
    pub woke_s: f64,
    /// Number of valid rows.
    pub len: usize,
    /// Rows `0..len` are the channels in order.
    pub rows: [RecordRow; MAX_CHANNELS],
}

impl TickRecord {
    /// The valid rows.
    pub fn channels(&self) -> &[RecordRow] {
        &self.rows[..self.len.min(MAX_CHANNELS)]
    }
}

/// State shared between the loop and its readers.
#[derive(Debug)]
pub struct Shared {
    snapshot: Mutex<Snapshot>,
    /// Ticks whose snapshot was not published because a reader held the lock.
    pub(crate) skipped_publishes: AtomicU64,
    /// Tick records the recorder queue could not take (it was full).
    pub(crate) dropped_records: AtomicU64,
}

impl Shared {
    pub(crate) fn new(initial: Snapshot) -> Self {
        Shared {
            snapshot: Mutex::new(initial),
            skipped_publishes: AtomicU64::new(0),
            dropped_records: AtomicU64::new(0),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Snapshot> {
        self.snapshot.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// A copy of the newest snapshot.
    pub fn snapshot(&self) -> Snapshot {
        self.lock().clone()
    }

    /// Runs `write` on the snapshot unless a reader holds it; false (nothing written) if one does.
    pub(crate) fn try_publish(&self, write: impl FnOnce(&mut Snapshot)) -> bool {
        match self.snapshot.try_lock() {
            Ok(mut guard) => write(&mut guard),
            Err(std::sync::TryLockError::Poisoned(poisoned)) => write(&mut poisoned.into_inner()),
            Err(std::sync::TryLockError::WouldBlock) => return false,
        }
        true
    }

    /// Publishes unconditionally (waits for readers); used once when the loop stops.
    pub(crate) fn publish(&self, write: impl FnOnce(&mut Snapshot)) {
        write(&mut self.lock());
    }

    /// Tick records dropped because the recorder queue was full.
    pub fn dropped_records(&self) -> u64 {
        self.dropped_records.load(Ordering::Relaxed)
    }

    /// Snapshot publishes skipped because a reader held the lock.
    pub fn skipped_publishes(&self) -> u64 {
        self.skipped_publishes.load(Ordering::Relaxed)
    }
}
