//! What the daemon says of each channel: its telemetry ([`ChannelTelemetry`], the columns of `render`'s CSV), its
//! status ([`ChannelState`]: telemetry plus mode, fault text, owner, link), what it renders ([`Mode`]) and who set
//! it ([`Owner`]), and the telemetry message a subscription sends ([`Telemetry`]).
//!
//! A number the device cannot measure, or that is not known yet, is `null` (`None`), never a plausible guess.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// What a channel renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Air: no contact.
    Air,
    /// A material contact.
    Touch,
    /// Direct set-point mode.
    Direct,
}

/// Who set a channel's stimulus. Contacts of a WebSocket client are released when it disconnects (after a grace
/// period); OSC and script contacts have no connection and stay until released.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case", tag = "kind", content = "id")]
pub enum Owner {
    /// Nobody (air, or released).
    Nobody,
    /// A WebSocket connection, by its connection number.
    Client(u64),
    /// An OSC sender.
    Osc,
    /// The demo script or the daemon itself.
    Script,
}

/// `value` when it is finite, else `None` (JSON has no NaN: an unknown number is `null`).
pub fn finite(value: f64) -> Option<f64> {
    value.is_finite().then_some(value)
}

/// One channel's numbers at a tick (the names of `render`'s CSV columns).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ChannelTelemetry {
    /// The channel (from 0).
    pub channel: usize,
    /// A material contact is rendered.
    pub contact: bool,
    /// The touched material's name, during a contact.
    pub material: Option<String>,
    /// What the channel renders.
    pub mode: Mode,
    /// The skin temperature the contact would give \[°C\].
    pub target_skin_c: Option<f64>,
    /// The rendered skin temperature (the display's finger model) \[°C\].
    pub skin_c: Option<f64>,
    /// The display set-point after the safety envelope \[°C\].
    pub display_setpoint_c: Option<f64>,
    /// The plate sensor's reading \[°C\].
    pub sensor_c: Option<f64>,
    /// The envelope's estimate of the true plate \[°C\].
    pub plate_estimate_c: Option<f64>,
    /// The finger's surface as the controller's observer estimates it \[°C\]; null where nothing measures it.
    pub finger_c: Option<f64>,
    /// The drive current \[A\] (positive heats the display); null where the device does not report it.
    pub current_a: Option<f64>,
    /// The module's hot side \[°C\]; null where the device does not report it.
    pub hot_side_c: Option<f64>,
    /// The latched safety fault's stable code, 0 for none.
    pub fault: u16,
    /// The channel's thermal dose \[CEM43-minutes\].
    pub cem43_min: Option<f64>,
    /// Time at or above 43 °C \[s\].
    pub time_at_or_above_43_s: Option<f64>,
    /// The dose lockout has engaged (the budget is used): the channel's maximum is below 43 °C and only falls;
    /// once nothing is left above the display minimum the channel is off (`dose_budget_spent` in its status).
    pub dose_lockout: bool,
}

/// Why a channel's drive is off (0 A) whatever is asked; the first that applies, in this order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum OffReason {
    /// The channel's engine failed: off for the rest of the session (restart the daemon).
    EngineFailed,
    /// A safety fault is latched (see `fault_description`); clear it once its cause is gone.
    Fault,
    /// The device's own protection cut the channel (see `device_cut_description`).
    DeviceCut,
    /// The device did not answer the last read.
    LinkDown,
    /// The thermal-dose budget is spent: off, and nothing but a release is accepted, until the dose ledger is reset
    /// (`thermode dose reset`, after checking the skin).
    DoseBudgetSpent,
    /// Held at 0 A after a stop-all, until the channel's next command.
    HeldOff,
}

/// One channel's status (`/api/status` `channels`): its telemetry and what drives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ChannelState {
    /// The numbers.
    #[serde(flatten)]
    pub telemetry: ChannelTelemetry,
    /// The channel's name (e.g. the finger), if the display names its channels.
    pub name: Option<String>,
    /// The running segment of the channel's stimulus program (from 0); null without a running program.
    pub program_segment: Option<usize>,
    /// The latched fault, in words.
    pub fault_description: Option<String>,
    /// The contact's object temperature \[°C\] (touch only).
    pub object_temp_c: Option<f64>,
    /// The direct-mode target \[°C\] (direct only).
    pub direct_temp_c: Option<f64>,
    /// The direct-mode rate \[°C/s\] (direct only).
    #[serde(rename = "direct_rate_c_s")]
    pub direct_rate_c_per_s: Option<f64>,
    /// After stop-all: the drive is held at 0 A until the channel's next command.
    pub held_off: bool,
    /// Who set the stimulus.
    pub owner: Owner,
    /// Loop time at which the contact of a disconnected client will be released \[s\].
    pub release_at_s: Option<f64>,
    /// The device answered the last read.
    pub link_ok: bool,
    /// The device's own protection has cut this channel: its name.
    pub device_cut: Option<String>,
    /// The device's cut, in words.
    pub device_cut_description: Option<String>,
    /// The channel's engine failed: its drive is off for the rest of the session.
    pub engine_failed: bool,
    /// The channel's thermal-dose budget is spent: its drive is off (0 A) until the dose ledger is reset.
    pub dose_budget_spent: bool,
    /// Why the drive is off whatever is asked; null while the channel may drive.
    pub off_reason: Option<OffReason>,
}

/// A telemetry message (`type` `telemetry`), sent at a subscription's rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Telemetry {
    /// Loop time of the tick \[s\].
    pub time_s: f64,
    /// The tick's index.
    pub tick: u64,
    /// Every channel.
    pub channels: Vec<ChannelTelemetry>,
}
