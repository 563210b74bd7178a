//! Commands from the network side to the control loop, and the loop's answers. Commands travel through a bounded
//! queue ([`CommandSender`]); every command has been validated before it enters the queue, and the loop checks it
//! again against the same limits ([`crate::limits::StimulusLimits`]). A reply (if asked for) comes back on a one-shot channel.
//!
//! Two lanes: [`Command::StopAll`] and [`Command::ClientGone`] travel on a small lane of their own
//! ([`URGENT_QUEUE_LEN`]) that the loop empties first at every tick, so neither ever waits behind a flood of other
//! commands. Every command carries a sequence number: a stop-all cancels every command sent before it that the loop
//! has not applied yet ([`CommandError::Cancelled`]), so nothing sent before a stop outlives it.
//!
//! Honest answers: a request ([`CommandSender::request`]) gives an [`Answer`]. [`Answer::wait_until`] waits a bounded
//! time; when the time is over it withdraws the command, unless the loop has already taken it (then it waits for
//! that tick's answer, which follows within the tick). So [`CommandError::Busy`] always means that nothing was
//! queued, or that what was queued was withdrawn and will never be applied.

use std::future::Future;
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::task::Poll;

use serde::Serialize;
use thermode_model::materials::Material;
use thermode_safety::FaultCode;
use thiserror::Error;

use crate::engine::{EngineError, Stimulus};
use crate::program::Program;
use crate::reply::{self, Closed, ReplyReceiver, ReplySender};

/// Who set a channel's stimulus. A client's contacts are released when it is gone (after a grace period); OSC and
/// script contacts have no connection and stay until released. (The wire spells it `thermode_protocol::Owner`; the
/// daemon converts at its edge.)
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Owner {
    /// Nobody (air, or released).
    Nobody,
    /// A client (a WebSocket connection, or the HTTP commands' lease), by its number.
    Client(u64),
    /// An OSC sender.
    Osc,
    /// The demo script or the daemon itself.
    Script,
}

/// The kind of a participant's response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResponseKind {
    /// A button press.
    Button,
    /// A rating on a visual analogue scale, 0 to 100.
    Rating,
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
    /// Run a stimulus program on each of `programs`' channels, all starting on the tick that applies it (each
    /// checked again against its channel's limits by the loop). A channel's program ends at its channel's next
    /// command (or a `ProgramStop`).
    Program {
        /// (channel, its program), channels distinct.
        programs: Vec<(usize, Program)>,
        /// Who asked.
        owner: Owner,
    },
    /// End `channel`'s program; its set-point holds where it is.
    ProgramStop {
        /// Channel (from 0).
        channel: usize,
    },
    /// A participant's response on `channel`: it ends a running `until: response` segment, and the answer carries
    /// the plate and set-point of the tick that applied it.
    Response {
        /// Channel (from 0).
        channel: usize,
        /// Button or rating.
        kind: ResponseKind,
        /// The rating, 0 to 100 (ratings only).
        value: Option<f64>,
    },
    /// A WebSocket client disconnected: release its contacts after the grace period unless retouched.
    ClientGone {
        /// The connection number.
        client: u64,
        /// Loop time at which it disconnected \[s\] (the grace period runs from here); `None`: the time of the tick
        /// that applies this command.
        at_s: Option<f64>,
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

    /// Direct mode: the display set-point of `channel` goes to `temp_c` \[°C\] at `rate_c_per_s` \[°C/s\].
    pub fn direct(channel: usize, temp_c: f64, rate_c_per_s: f64, owner: Owner) -> Command {
        Command::stimulate(channel, Stimulus::Direct { temp_c, rate_c_per_s }, owner)
    }
}

/// When the loop applied a command.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Applied {
    /// Index of the tick that applied it (its drive command is the first to see it).
    pub tick: u64,
    /// Loop time of that tick \[s\].
    pub time_s: f64,
    /// A response's channel as that tick left it (responses only).
    pub at_response: Option<AtResponse>,
}

/// A channel at the tick that applied a response: the temperature at the response, not after it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AtResponse {
    /// The channel.
    pub channel: usize,
    /// The plate sensor's reading of that tick \[°C\] (NaN where the device cannot measure it).
    pub sensor_c: f64,
    /// The engine's plate estimate of that tick \[°C\] (NaN where there is none).
    pub plate_estimate_c: f64,
    /// The display set-point of that tick \[°C\].
    pub setpoint_c: f64,
    /// The `until: response` segment the response ended, if it ended one.
    pub ended_segment: Option<usize>,
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
    /// The command queue is full (the loop is overloaded), or the loop did not take the command in time and it was
    /// withdrawn: nothing was applied and nothing will be; try again.
    #[error("the control loop is busy; nothing was applied; try again")]
    Busy,
    /// A stop-all sent after this command was applied first: this command was cancelled, nothing changed.
    #[error("cancelled by a stop_all sent after it; nothing was applied")]
    Cancelled,
    /// The recording failed and the daemon's policy is to stop: every stimulus was released and new ones are
    /// refused until an operator acknowledges the failure (`ack_recording`).
    #[error("the recording failed: stimuli are refused until an operator acknowledges it (ack_recording)")]
    RecordingFailed,
    /// The dose ledger cannot be written (a full disk, a read-only state directory): every stimulus was stopped and
    /// new ones are refused until a write succeeds again, so that no dose goes unrecorded.
    #[error(
        "the dose ledger cannot be written: stimuli are refused until it can (the dose must not be forgotten; free \
         space or fix the state directory)"
    )]
    DoseNotRecorded,
    /// The control loop has stopped.
    #[error("the control loop has stopped")]
    Stopped,
    /// A program's channel refused it (a segment out of the channel's limits).
    #[error(transparent)]
    Program(#[from] crate::program::ProgramError),
    /// The channel has no temperature to start a program from yet (no reading so far).
    #[error("channel {channel} has no temperature reading yet to start a program from; try again")]
    NoStartTemperature {
        /// The channel.
        channel: usize,
    },
    /// The channel's thermal-dose budget is spent: its drive is off (0 A) and it renders nothing but air until the
    /// dose ledger is reset (`thermode dose reset`, after checking the skin).
    #[error(
        "channel {channel} is off: its thermal-dose budget is spent ({cem43_min:.3} CEM43-min counted); it renders \
         nothing but air until the dose is reset (thermode dose reset, after checking the skin)"
    )]
    DoseBudgetSpent {
        /// The channel.
        channel: usize,
        /// The dose counted \[CEM43-minutes\].
        cem43_min: f64,
    },
}

/// The loop's answer to one command.
pub type Reply = Result<Applied, CommandError>;

/// Capacity of the urgent lane (stop-all, client gone) \[commands\]; the loop empties it at every tick.
pub const URGENT_QUEUE_LEN: usize = 256;

/// A request's claim: still waiting, taken by the loop, or withdrawn by the requester.
const CLAIM_PENDING: u8 = 0;
const CLAIM_TAKEN: u8 = 1;
const CLAIM_WITHDRAWN: u8 = 2;

/// Who gets to decide a request's fate: the loop (it takes it) or the requester (it withdraws it), whoever is first.
#[derive(Debug, Default)]
pub struct Claim(AtomicU8);

impl Claim {
    /// The loop takes the command; false if the requester withdrew it first (the loop must then skip it).
    pub(crate) fn take(&self) -> bool {
        self.0
            .compare_exchange(CLAIM_PENDING, CLAIM_TAKEN, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
    }

    /// The requester withdraws the command; false if the loop took it first.
    fn withdraw(&self) -> bool {
        self.0
            .compare_exchange(CLAIM_PENDING, CLAIM_WITHDRAWN, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
    }
}

/// A command and where to send the answer.
#[derive(Debug)]
pub struct Queued {
    /// The command.
    pub command: Command,
    /// Where the answer goes (`None`: nobody waits).
    pub reply: Option<ReplySender<Reply>>,
    /// The requester's claim (`None`: the command cannot be withdrawn).
    pub claim: Option<Arc<Claim>>,
    /// Sequence number, in the order commands were sent (both lanes).
    pub seq: u64,
}

/// The loop's answer to a request, to be awaited.
#[derive(Debug)]
pub struct Answer {
    receiver: ReplyReceiver<Reply>,
    claim: Arc<Claim>,
}

impl Answer {
    /// Waits for the answer without a time limit (threads outside an async executor, tests).
    pub fn blocking_recv(self) -> Result<Reply, Closed> {
        self.receiver.blocking_recv()
    }

    /// Waits for the answer until `timer` completes (the adapter's timer, e.g. a tokio sleep of the reply
    /// timeout). When the time is over the command is withdrawn, unless the loop has taken it already; then the
    /// answer of that tick is awaited (it follows within the tick). `Err(Busy)` means the loop never applied the
    /// command and never will; `Err(Stopped)` that the loop stopped.
    pub async fn wait_until(mut self, timer: impl Future<Output = ()>) -> Reply {
        let mut timer = std::pin::pin!(timer);
        let answered = std::future::poll_fn(|cx| {
            if let Poll::Ready(reply) = std::pin::Pin::new(&mut self.receiver).poll(cx) {
                return Poll::Ready(Some(reply));
            }
            timer.as_mut().poll(cx).map(|()| None)
        })
        .await;
        match answered {
            Some(reply) => reply.unwrap_or(Err(CommandError::Stopped)),
            None if self.claim.withdraw() => Err(CommandError::Busy),
            None => self.receiver.await.unwrap_or(Err(CommandError::Stopped)),
        }
    }
}

/// The sending end of the loop's bounded command queue. Cheap to clone; never blocks.
#[derive(Debug, Clone)]
pub struct CommandSender {
    queue: SyncSender<Queued>,
    urgent: SyncSender<Queued>,
    next_seq: Arc<AtomicU64>,
}

impl CommandSender {
    pub(crate) fn new(queue: SyncSender<Queued>, urgent: SyncSender<Queued>) -> Self {
        CommandSender {
            queue,
            urgent,
            next_seq: Arc::new(AtomicU64::new(1)),
        }
    }

    /// Queues `command` without waiting for the loop; refused when the queue is full or the loop has stopped.
    pub fn send(&self, command: Command) -> Result<(), CommandError> {
        self.push(command, None, None)
    }

    /// Queues `command` and returns the loop's [`Answer`].
    pub fn request(&self, command: Command) -> Result<Answer, CommandError> {
        let (reply, receiver) = reply::slot();
        let claim = Arc::new(Claim::default());
        self.push(command, Some(reply), Some(claim.clone()))?;
        Ok(Answer { receiver, claim })
    }

    fn push(
        &self,
        command: Command,
        reply: Option<ReplySender<Reply>>,
        claim: Option<Arc<Claim>>,
    ) -> Result<(), CommandError> {
        let lane = match command {
            Command::StopAll | Command::ClientGone { .. } => &self.urgent,
            _ => &self.queue,
        };
        let queued = Queued {
            command,
            reply,
            claim,
            seq: self.next_seq.fetch_add(1, Ordering::Relaxed),
        };
        lane.try_send(queued).map_err(|e| match e {
            TrySendError::Full(_) => CommandError::Busy,
            TrySendError::Disconnected(_) => CommandError::Stopped,
        })
    }
}

/// The receiving ends, owned by the loop: the urgent lane and the ordinary queue.
pub(crate) struct CommandReceiver {
    pub(crate) urgent: Receiver<Queued>,
    pub(crate) queue: Receiver<Queued>,
}
