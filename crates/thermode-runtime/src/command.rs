//! Commands from the network side to the control loop, and the loop's answers. Commands travel through a bounded
//! queue ([`CommandSender`]); every command has been validated before it enters the queue, and the loop checks it
//! again. A reply (if asked for) comes back on a one-shot channel.

use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::sync::Arc;

use serde::Serialize;
use thermode_model::materials::Material;
use thermode_safety::FaultCode;
use thiserror::Error;
use tokio::sync::oneshot;

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

/// A command for the control loop.
#[derive(Debug, Clone)]
pub enum Command {
    /// Touch `material` at `object_c` \[°C\] on `channel`.
    Touch {
        /// Channel (from 0).
        channel: usize,
        /// The material (validated).
        material: Material,
        /// Object temperature \[°C\].
        object_c: f64,
        /// The name shown as the channel's `contact` (the material name, or "custom").
        label: Arc<str>,
        /// Who asked.
        owner: Owner,
    },
    /// Direct mode: move the display set-point of `channel` to `temp_c` \[°C\] at `rate_c_s` \[°C/s\].
    Setpoint {
        /// Channel (from 0).
        channel: usize,
        /// Target display temperature \[°C\].
        temp_c: f64,
        /// Ramp rate \[°C/s\].
        rate_c_s: f64,
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
    /// The fault could not be cleared: its cause persists (or no fresh measurement arrived yet).
    #[error("channel {channel}: the fault cannot be cleared yet: {message}")]
    FaultPersists {
        /// The channel.
        channel: usize,
        /// The envelope's reason.
        message: String,
    },
    /// The channel's engine refused the stimulus.
    #[error("channel {channel} refused the stimulus: {message}")]
    Rejected {
        /// The channel.
        channel: usize,
        /// The engine's reason.
        message: String,
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
pub struct Request {
    /// The command.
    pub command: Command,
    /// Where the answer goes (`None`: nobody waits).
    pub reply: Option<oneshot::Sender<Reply>>,
}

/// The sending end of the loop's bounded command queue. Cheap to clone; never blocks.
#[derive(Debug, Clone)]
pub struct CommandSender {
    queue: SyncSender<Request>,
}

impl CommandSender {
    pub(crate) fn new(queue: SyncSender<Request>) -> Self {
        CommandSender { queue }
    }

    /// Queues `command` without waiting for the loop; refused when the queue is full or the loop has stopped.
    pub fn send(&self, command: Command) -> Result<(), CommandError> {
        self.push(Request { command, reply: None })
    }

    /// Queues `command` and returns the receiver of the loop's answer.
    pub fn request(&self, command: Command) -> Result<oneshot::Receiver<Reply>, CommandError> {
        let (reply, answer) = oneshot::channel();
        self.push(Request {
            command,
            reply: Some(reply),
        })?;
        Ok(answer)
    }

    fn push(&self, request: Request) -> Result<(), CommandError> {
        self.queue.try_send(request).map_err(|e| match e {
            TrySendError::Full(_) => CommandError::Busy,
            TrySendError::Disconnected(_) => CommandError::Stopped,
        })
    }
}

/// The receiving end, owned by the loop.
pub(crate) type CommandReceiver = Receiver<Request>;
