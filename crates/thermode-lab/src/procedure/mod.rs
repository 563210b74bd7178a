//! Psychophysical procedures run by `thermode lab run` (issue 24): the method of limits (DFNS), levels,
//! staircases, QUEST+ and multi-zone programs of `thermode_procedures`, each trial a program on a display.
//!
//! - [`display`]: the port ([`ProgramDisplay`]) — programs, plate samples, segment events, responses;
//!   [`simulated`]: the simulated display in virtual time; [`ws`]: a running daemon over its WebSocket.
//! - [`answers`]: who answers ([`ProcedureResponder`]): the simulated participant, a script, the CLI's keyboard.
//! - [`plan`]: `lab plan` of a procedure file; [`run`]: the session runner; [`session`]: its durable files (CSV, events, traces, sidecar).
//! - [`analysis`]: thresholds, z-scores and trace figures of procedure sessions (`lab analyze`).

pub mod analysis;
pub mod answers;
pub mod display;
pub mod plan;
pub mod run;
pub mod session;
pub mod simulated;
pub mod ws;

use thermode_procedures::ProcedureError;
use thiserror::Error;

pub use answers::{ProcedureResponder, ScriptedAnswers, SimulatedResponder};
pub use display::ProgramDisplay;
pub use run::{ProcedureRunner, ProcedureSummary};
pub use session::{ProcedureSession, ProcedureSessionSpec};
pub use simulated::SimulatedProgramDisplay;

use crate::runner::StimulusError;
use crate::session::SessionError;

/// Why a procedure session stopped.
#[derive(Debug, Error)]
pub enum ProcedureRunError {
    /// The procedure refused its file or a response.
    #[error(transparent)]
    Procedure(#[from] ProcedureError),
    /// The display failed.
    #[error(transparent)]
    Display(#[from] StimulusError),
    /// The session files could not be written or resumed.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// A resumed session's rows are not the procedure's trials.
    #[error("trial {trial} of the session file: {message}")]
    Resume {
        /// 1-based trial.
        trial: usize,
        /// What differs.
        message: String,
    },
    /// A multi-zone program file without its `[program]` table or stimuli.
    #[error("the experiment file has no multi-zone program to run")]
    NoProgram,
    /// The display has fewer channels than the program names.
    #[error("the program needs {needed} channels; the display has {display}")]
    Channels {
        /// Channels the program needs.
        needed: usize,
        /// Channels the display has.
        display: usize,
    },
    /// The progress output could not be written.
    #[error("terminal: {0}")]
    Console(std::io::Error),
}

/// The seed of participant `id`'s simulated participant in an experiment seeded `seed`: the seed mixed with the
/// identifier's FNV-1a hash, so participants differ and a participant's draws do not depend on who ran before.
pub fn participant_seed(seed: u64, id: &str) -> u64 {
    let hash = id.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    seed ^ hash
}
