//! The daemon's status: the `/api/status` body and the WebSocket `status` reply (with `type` and `id`). Each part is
//! a type of its own; the daemon fills them from the loop's snapshot and its adapters' counters.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::telemetry::{ChannelState, Mode, Owner};

/// The daemon's status.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Status {
    /// thermode's version.
    pub version: String,
    /// The device, e.g. `sim` or `serial:/dev/ttyACM0`.
    pub device: String,
    /// The control loop runs.
    pub running: bool,
    /// Loop time of the newest tick \[s\].
    pub time_s: f64,
    /// Index of the newest tick.
    pub tick: u64,
    /// Number of channels.
    pub channel_count: usize,
    /// Every channel.
    pub channels: Vec<ChannelState>,
    /// The channels that show something (a touch or direct mode).
    pub contacts: Vec<Contact>,
    /// The channels with a latched safety fault.
    pub faults: Vec<FaultEntry>,
    /// The channels the device's own protection has cut.
    pub device_cuts: Vec<DeviceCutEntry>,
    /// The control loop's timing.
    #[serde(rename = "loop")]
    pub loop_stats: LoopStatus,
    /// Commands the loop applied, refused, or saw withdrawn.
    pub commands: Commands,
    /// Failed device reads or writes since the start.
    pub device_errors: u64,
    /// WebSocket clients connected.
    pub clients: usize,
    /// The HTTP server.
    pub http: HttpStatus,
    /// Access control.
    pub auth: Auth,
    /// What every request is checked against.
    pub limits: Limits,
    /// The OSC listener.
    pub osc: OscStatus,
    /// The session recording, if any.
    pub recording: Option<Recording>,
    /// The Lab Streaming Layer streams, under `--lsl`.
    pub lsl: Option<LslStatus>,
    /// The device link, for a device behind one; for a display of several devices, all of their links together
    /// (`up` only when every one is up, the counts summed, the error of a link that is down).
    pub link: Option<LinkStatus>,
    /// The devices the display is made of, in channel order (one for a display of one device).
    pub devices: Vec<DeviceStatus>,
    /// Per channel: the index in `devices` of the device it is on.
    pub channel_devices: Vec<usize>,
    /// Per channel: what its device file is (`datasheet`, `identified` or `calibrated`).
    pub channel_device_files: Vec<DeviceFileKind>,
    /// The dose ledger of the state directory, if any.
    pub dose_ledger: Option<DoseLedgerStatus>,
    /// The interlock (tripped by a failed recording under the policy `stop`).
    pub interlock: InterlockStatus,
}

/// A channel that shows something.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Contact {
    /// The channel.
    pub channel: usize,
    /// The material's name, `custom`, or `direct`.
    pub material: String,
    /// What it renders.
    pub mode: Mode,
    /// Who set it.
    pub owner: Owner,
}

/// A latched safety fault.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct FaultEntry {
    /// The channel.
    pub channel: usize,
    /// The fault's stable code.
    pub fault: u16,
    /// The fault in words.
    pub description: String,
}

/// A channel the device's own protection has cut.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DeviceCutEntry {
    /// The channel.
    pub channel: usize,
    /// The cut's name.
    pub cut: String,
    /// The cut in words.
    pub description: String,
}

/// The control loop's timing over the statistics window (null until measured).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LoopStatus {
    /// Configured rate \[Hz\].
    pub rate_hz: f64,
    /// Configured period \[s\].
    pub period_s: f64,
    /// Median measured period \[s\].
    pub period_p50_s: Option<f64>,
    /// 99th percentile of the measured period \[s\].
    pub period_p99_s: Option<f64>,
    /// Longest measured period \[s\].
    pub period_max_s: Option<f64>,
    /// Median work per tick \[s\].
    pub work_p50_s: Option<f64>,
    /// 99th percentile of the work per tick \[s\].
    pub work_p99_s: Option<f64>,
    /// Longest work per tick \[s\].
    pub work_max_s: Option<f64>,
    /// Ticks in the window.
    pub window_ticks: usize,
    /// Deadlines that got no tick of their own since the start.
    pub missed_deadlines: u64,
    /// Ticks since the start.
    pub ticks: u64,
    /// Snapshots the loop could not publish (a reader held the lock).
    pub skipped_publishes: u64,
    /// The real-time treatment the loop obtained.
    pub realtime: RealtimeStatus,
}

/// The real-time treatment of the loop thread.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RealtimeStatus {
    /// `SCHED_FIFO` or `normal`.
    pub scheduling: String,
    /// The `SCHED_FIFO` priority, when granted.
    pub priority: Option<i32>,
    /// Why real-time scheduling was not granted.
    pub scheduling_error: Option<String>,
    /// The process's memory is locked.
    pub memory_locked: bool,
    /// Why memory could not be locked.
    pub memory_error: Option<String>,
    /// The CPU the loop has to itself, if any.
    pub cpu: Option<usize>,
}

/// Commands the loop saw.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Commands {
    /// Applied since the start.
    pub applied: u64,
    /// Refused by the loop since the start.
    pub refused: u64,
    /// Withdrawn by their requester before the loop took them.
    pub withdrawn: u64,
}

/// The HTTP server.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct HttpStatus {
    /// Connections open now.
    pub open: u64,
    /// The connection cap in force.
    pub max_connections: usize,
    /// A request head must be complete within this \[s\].
    pub header_timeout_s: f64,
    /// An idle kept-alive connection is closed after this \[s\].
    pub idle_timeout_s: f64,
    /// Connections accepted.
    pub accepted: u64,
    /// Idle connections closed to make room at the cap.
    pub evicted: u64,
    /// Connections closed by a timeout.
    pub timed_out: u64,
    /// Connections refused.
    pub refused: u64,
    /// Failed accepts.
    pub accept_errors: u64,
    /// `POST /api/command` requests read (answered, refused or rate-limited).
    pub commands: u64,
    /// The lease of `POST /api/command`'s virtual connection: its contacts are released after the grace period
    /// once no HTTP command arrived for this long \[s\].
    pub command_lease_s: f64,
    /// The client number (`owner`) of `POST /api/command`'s virtual connection while its lease runs.
    pub command_client: Option<u64>,
}

/// Access control.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Auth {
    /// Every request must present the token.
    pub token_required: bool,
}

/// What every request is checked against: the network's limits and the stimulus limits the channels enforce.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Limits {
    /// Largest message answered with a reply \[bytes\].
    pub max_message_bytes: usize,
    /// Sustained requests per second per WebSocket connection.
    pub requests_per_s: f64,
    /// Requests a connection may send at once.
    pub burst: f64,
    /// Fastest telemetry subscription \[Hz\].
    pub max_subscribe_hz: f64,
    /// Lowest display set-point \[°C\].
    pub display_min_c: f64,
    /// Highest display set-point \[°C\].
    pub display_max_c: f64,
    /// Fastest set-point rate \[°C/s\].
    #[serde(rename = "max_rate_c_s")]
    pub max_rate_c_per_s: f64,
    /// Coldest object of a touch \[°C\].
    pub object_temp_min_c: f64,
    /// Hottest object of a touch \[°C\].
    pub object_temp_max_c: f64,
}

/// The OSC listener.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct OscStatus {
    /// OSC listens.
    pub enabled: bool,
    /// Its port.
    pub port: Option<u16>,
    /// Datagrams received.
    pub packets: u64,
    /// Messages the loop applied.
    pub applied: u64,
    /// Datagrams that are not valid OSC.
    pub malformed: u64,
    /// Valid messages refused.
    pub refused: u64,
    /// Messages dropped by the rate limit.
    pub rate_limited: u64,
    /// Telemetry subscribers now.
    pub subscribers: usize,
    /// Datagrams sent to subscribers.
    pub sent: u64,
    /// Subscriptions refused (the daemon's own ports, a port another address subscribed, the cap, a bad rate).
    pub subscriptions_refused: u64,
    /// Datagrams not sent because a subscriber's byte budget was spent.
    pub throttled: u64,
    /// Most bytes sent to one subscriber per second \[B/s\].
    pub subscriber_bytes_per_s: f64,
    /// The last refusal.
    pub last_error: Option<String>,
}

/// The session recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Recording {
    /// The file being written.
    pub path: String,
    /// The segment: 1 for the session's first file, 2 after the first resumption, …
    pub segment: usize,
    /// The files of earlier segments.
    pub earlier_files: Vec<EarlierFile>,
    /// `ok` or `failed`.
    pub state: String,
    /// The write error, once failed.
    pub error: Option<String>,
    /// Rows in the current file.
    pub rows_written: u64,
    /// The same as `rows_written` (kept for older clients).
    pub rows: u64,
    /// Bytes in the file.
    pub bytes_written: u64,
    /// Rows produced while the recording had failed.
    pub rows_lost: u64,
    /// Tick records the recorder could not take.
    pub dropped_ticks: u64,
    /// The policy: `stop` or `continue`.
    pub on_error: String,
    /// Stimuli are refused until an operator acknowledges the failure.
    pub stimuli_refused: bool,
}

/// A finished segment of a recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct EarlierFile {
    /// The file.
    pub path: String,
    /// Rows it holds.
    pub rows_written: u64,
}

/// The Lab Streaming Layer streams.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LslStatus {
    /// Where liblsl was loaded from.
    pub library: String,
    /// LSL time minus loop time \[s\].
    pub lsl_offset_s: f64,
    /// The LSL clock at the start \[s\].
    pub lsl_clock_at_start_s: f64,
    /// Telemetry samples pushed.
    pub samples: u64,
    /// Markers pushed.
    pub markers: u64,
    /// Pushes that failed.
    pub failed: u64,
}

/// One device of the display.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DeviceStatus {
    /// The device as given to `--device`, e.g. `mecom:/dev/ttyUSB0` (the display's `device` for a display of one).
    pub device: String,
    /// The display's channels on this device.
    pub channels: Vec<usize>,
    /// Its link, for a device behind one (a device that is down has only its own channels faulted).
    pub link: Option<LinkStatus>,
    /// Which of its protocol's commands it is driven with, when the host records it (a MeCom controller: the full
    /// command set, or the commands every firmware has and how its instances were counted).
    pub command_set: Option<String>,
}

/// What a channel's device file is: how far it has been measured on this very display.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum DeviceFileKind {
    /// The datasheet's values (the built-in default display, or a file neither identified nor calibrated). The
    /// simulated display reports the kind of the file it is built from: `datasheet` by default.
    #[default]
    Datasheet,
    /// Fitted to this display by `thermode identify`.
    Identified,
    /// With a sensor calibration (`thermode calibrate`; a `[calibration]` section), identified or not.
    Calibrated,
}

/// The device link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LinkStatus {
    /// `up` or `down`.
    pub state: String,
    /// Reconnections since the start.
    pub reconnects: u64,
    /// Failures since the start.
    pub failures: u64,
    /// Connection attempts since the start.
    pub attempts: u64,
    /// The last error.
    pub error: Option<String>,
}

/// The dose ledger's writer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DoseLedgerStatus {
    /// The ledger file.
    pub path: String,
    /// Writes done.
    pub writes: u64,
    /// Writes that failed.
    pub errors: u64,
    /// The last write error.
    pub last_error: Option<String>,
    /// The ledger cannot be written: every stimulus was stopped and new ones are refused (`dose_not_recorded`)
    /// until a write succeeds again.
    pub stimuli_refused: bool,
}

/// The interlock.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct InterlockStatus {
    /// Stimuli are refused until an operator acknowledges.
    pub engaged: bool,
    /// Times it tripped.
    pub trips: u64,
    /// Why it is engaged.
    pub reason: Option<String>,
}
