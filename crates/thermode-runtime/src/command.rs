//! Commands from the network side to the control loop, and the loop's answers. Commands travel through a bounded
//! queue ([`CommandSender`]); every command has been validated before it enters the queue, and the loop checks it
//! again against the same limits ([`crate::limits::StimulusLimits`]). A reply (if asked for) comes back on a one-shot channel.

use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::sync::Arc;

use serde::Serialize;
use thermode_model::materials::Material;
use thermode_safety::FaultCode;
use thiserror::Error;
use tokio::sync::oneshot;

use crate::engine::{EngineError, Stimulus};

/// Who set a channel's stimulus. Contacts of a WebSocket client are released when it disconnects (after a grace
/// period); OSC and script contacts have no connection and stay until released.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
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

/// A command for the control loop: the one vocabulary of the WebSocket API, OSC, the demo script and tests. What
/// a channel should show travels as the pipeline's [`Stimulus`], so nothing between the wire and the engine spells
/// a touch again.
#[derive(Debug, Clone)]
pub enum Command {
    /// Show `stimulus` on `channel`: a touch (`Stimulus::Touch`, wire `touch`) or direct mode (`Stimulus::Direct`,
    /// wire `setpoint`). `Stimulus::Air` is the same as [`Command::Release`]. Build it with
    /// [`Command::stimulate`], [`Command::touch`] or [`Command::direct`].
    Stimulate {
        /// Channel (from 0).
        channel: usize,
        /// What the channel shows from the next tick on (checked against the channel's limits by the loop).
        stimulus: Stimulus,
        /// The name shown as the channel's `contact`: the material's name, `direct` or `air` (allocated here, so
        /// the loop never allocates it).
        label: Arc<str>,
        /// Who asked.
        owner: Owner,
    },
    /// Release `channel`: the display renders air again.
    Release {
        /// Channel (from 0).
        channel: usize,
    },
    /// Clear `channel`'s latched safety fault (refused while its cause persists).
    ClearFault {
        /// Channel (from 0).
        channel: usize,
    },
    /// Release every channel and drive 0 A on each until its next command.
    StopAll,
    /// A WebSocket client disconnected: release its contacts after the grace period unless retouched.
    ClientGone {
        /// The connection number.
        client: u64,
    },
}

impl Command {
    /// Show `stimulus` on `channel` for `owner` (air is a release).
    pub fn stimulate(channel: usize, stimulus: Stimulus, owner: Owner) -> Command {
        let label: Arc<str> = match &stimulus {
            Stimulus::Air => return Command::Release { channel },
            Stimulus::Touch { material, .. } => Arc::from(material.name.as_str()),
            Stimulus::Direct { .. } => Arc::from("direct"),
        };
        Command::Stimulate {
            channel,
            stimulus,
            label,
            owner,
        }
    }

    /// Touch `material` at `object_c` \[°C\] on `channel`.
    pub fn touch(channel: usize, material: Material, object_c: f64, owner: Owner) -> Command {
        Command::stimulate(channel, Stimulus::Touch { material, object_c }, owner)
    }

    /// Direct mode: the display set-point of `channel` goes to `temp_c` \[°C\] at `rate_c_s` \[°C/s\].
    pub fn direct(channel: usize, temp_c: f64, rate_c_s: f64, owner: Owner) -> Command {
        Command::stimulate(channel, Stimulus::Direct { temp_c, rate_c_s }, owner)
    }

    /// The request's name on the wire: `touch`, `setpoint`, `release`, `clear_fault`, `stop_all` (and
    /// `client_gone`, which no client sends).
    pub fn name(&self) -> &'static str {
        match self {
            Command::Stimulate {
                stimulus: Stimulus::Touch { .. },
                ..
            } => "touch",
            Command::Stimulate {
                stimulus: Stimulus::Direct { .. },
                ..
            } => "setpoint",
            Command::Stimulate {
                stimulus: Stimulus::Air,
                ..
            }
            | Command::Release { .. } => "release",
            Command::ClearFault { .. } => "clear_fault",
            Command::StopAll => "stop_all",
            Command::ClientGone { .. } => "client_gone",
        }
    }
}

/// When the loop applied a command.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Applied {
    /// Index of the tick that applied it (its drive command is the first to see it).
    pub tick: u64,
    /// Loop time of that tick \[s\].
    pub time_s: f64,
}

/// Why the loop refused a command (nothing changed).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CommandError {
    /// The channel does not exist.
    #[error("channel {channel} does not exist (channels 0 to {last})", last = count.saturating_sub(1))]
    UnknownChannel {
        /// The channel asked for.
        channel: usize,
        /// Number of channels.
        count: usize,
    },
    /// The channel has a latched safety fault; its drive is off.
    #[error("channel {channel} has a latched safety fault ({fault}); its drive is off")]
    Faulted {
        /// The channel.
        channel: usize,
        /// The fault.
        fault: FaultCode,
    },
    /// The fault could not be cleared: its cause persists (or no fresh measurement arrived yet, or the engine
    /// failed).
    #[error("channel {channel}: the fault cannot be cleared yet: {cause}")]
    FaultPersists {
        /// The channel.
        channel: usize,
        /// The engine's (envelope's) reason.
        cause: EngineError,
    },
    /// The stimulus is outside the channel's limits, or its engine refused it.
    #[error("channel {channel} refused the stimulus: {cause}")]
    Rejected {
        /// The channel.
        channel: usize,
        /// The reason.
        cause: EngineError,
    },
    /// The command queue is full (the loop is overloaded); try again.
    #[error("the control loop's command queue is full; try again")]
    Busy,
    /// The control loop has stopped.
    #[error("the control loop has stopped")]
    Stopped,
}

/// The loop's answer to one command.
pub type Reply = Result<Applied, CommandError>;

/// A command and where to send the answer.
#[derive(Debug)]
pub struct Queued {
    /// The command.
    pub command: Command,
    /// Where the answer goes (`None`: nobody waits).
    pub reply: Option<oneshot::Sender<Reply>>,
}

/// The sending end of the loop's bounded command queue. Cheap to clone; never blocks.
#[derive(Debug, Clone)]
pub struct CommandSender {
    queue: SyncSender<Queued>,
}

impl CommandSender {
    pub(crate) fn new(queue: SyncSender<Queued>) -> Self {
        CommandSender { queue }
    }

    /// Queues `command` without waiting for the loop; refused when the queue is full or the loop has stopped.
    pub fn send(&self, command: Command) -> Result<(), CommandError> {
        self.push(Queued { command, reply: None })
    }

    /// Queues `command` and returns the receiver of the loop's answer.
    pub fn request(&self, command: Command) -> Result<oneshot::Receiver<Reply>, CommandError> {
        let (reply, answer) = oneshot::channel();
        self.push(Queued {
            command,
            reply: Some(reply),
        })?;
        Ok(answer)
    }

    fn push(&self, queued: Queued) -> Result<(), CommandError> {
        self.queue.try_send(queued).map_err(|e| match e {
            TrySendError::Full(_) => CommandError::Busy,
            TrySendError::Disconnected(_) => CommandError::Stopped,
        })
    }
}

/// The receiving end, owned by the loop.
pub(crate) type CommandReceiver = Receiver<Queued>;
