//! `thermode lab run` of a procedure file (`procedure = "limits" | "levels" | "staircase" | "questplus" |
//! "program"`; docs/procedures.md): each trial a program on the display, answered by the space bar (a USB button
//! is a keyboard), a script (`--responses`) or the file's simulated participant (`--simulated-participant`).
//!
//! Displays: `--simulate` runs the simulated display in virtual time (the loop's program executor, the pipeline
//! and envelope, the Peltier plant; no waiting); `--display ws://…` and `--device DEVICE` run on a daemon, any
//! backend (programs need no finger observer, so TCS II and MeCom in temperature mode are welcome).

use std::io::Write;
use std::path::Path;
use std::sync::mpsc::{self, Receiver, TryRecvError};

use anyhow::{bail, Context, Result};
use thermode_lab::design::is_valid_identifier;
use thermode_lab::procedure::answers::ProcedureResponder;
use thermode_lab::procedure::{
    participant_seed, ProcedureRunner, ProcedureSession, ProcedureSessionSpec, ProgramDisplay, ScriptedAnswers,
    SimulatedProgramDisplay, SimulatedResponder,
};
use thermode_lab::runner::ws_link::WsLink;
use thermode_lab::runner::StimulusError;
use thermode_pipeline::{ControllerKind, PipelineConfig};
use thermode_platform::{civil_date, utc_iso8601_ms, Clock};
use thermode_procedures::participant::SimulatedParticipant;
use thermode_procedures::{ProcedureFile, TrialPlan};

use super::lab_run::{on_display, LabRunArgs};
use crate::controller::ControllerArg;
use crate::resolve;

/// How long the simulated display settles in air before a session \[s\].
const SIMULATED_SETTLE_S: f64 = 2.0;

/// Runs `thermode lab run`: a procedure file here, an identification design by `lab_run`.
pub fn dispatch(args: &LabRunArgs) -> Result<()> {
    match is_procedure(&args.experiment)? {
        Some(text) => run(args, &text),
        None => super::lab_run::run(args),
    }
}

/// Runs `thermode lab run` for the procedure file `text` (read from `args.experiment`).
fn run(args: &LabRunArgs, text: &str) -> Result<()> {
    let file = ProcedureFile::from_toml_str(text).with_context(|| args.experiment.display().to_string())?;
    if args.time_scale.is_some() && args.simulate {
        bail!(
            "--time-scale: a procedure on the simulated display runs in virtual time (in real time when a person \
             answers at the keyboard)"
        );
    }
    if args.renderer.is_some() {
        bail!("--renderer: a procedure drives the plate's set-point directly; nothing is rendered");
    }
    let participants: Vec<String> = match args.all_participants {
        true => (1..=file.participants).map(|i| format!("P{i:02}")).collect(),
        false => args.participant.clone(),
    };
    if let Some(bad) = participants.iter().find(|p| !is_valid_identifier(p)) {
        bail!("participant `{bad}`: identifiers are 1 to 64 characters from A-Z, a-z, 0-9, `_` and `-`");
    }
    if participants.len() > 1 && !args.simulated_participant {
        bail!("several participants run only with --simulated-participant (keyboard and --responses answer for one)");
    }
    let mut out = std::io::stdout();
    if args.simulate {
        for participant in &participants {
            if participants.len() > 1 {
                writeln!(out, "== {participant}")?;
            }
            let mut display = simulated_display(args, &file)?;
            if !args.simulated_participant && args.responses.is_none() {
                // A person at the keyboard answers in real time.
                display = display.paced(std::sync::Arc::new(thermode_platform::MonotonicClock::new()));
            }
            session(args, &file, text, participant, &mut display, &mut out)?;
        }
        return Ok(());
    }
    let [participant] = participants.as_slice() else {
        bail!("a display presents to one participant at a time: give one --participant");
    };
    on_display(args, |url, token| {
        let mut link = WsLink::connect(url, token, args.channel)?;
        session(args, &file, text, participant, &mut link, &mut std::io::stdout())
    })
}

/// The simulated display of `--simulate`, with the channels the procedure needs.
fn simulated_display(args: &LabRunArgs, file: &ProcedureFile) -> Result<SimulatedProgramDisplay> {
    let device = resolve::device_config(args.device_file.as_deref())?;
    let controller = match args.controller.unwrap_or(ControllerArg::Model) {
        ControllerArg::Model => ControllerKind::Model,
        ControllerArg::Pid => ControllerKind::Pid(thermode_pipeline::gains_for_device(&device)?.0),
        ControllerArg::Both => bail!("a display runs one controller: --controller model or pid"),
    };
    let channels = file
        .program
        .as_ref()
        .map_or(args.channel + 1, |p| p.channels.max(args.channel + 1));
    let config = PipelineConfig::new(device, controller);
    Ok(SimulatedProgramDisplay::new(
        &config,
        channels,
        file.seed,
        SIMULATED_SETTLE_S,
    )?)
}

/// Runs one participant's session on `display`.
fn session(
    args: &LabRunArgs,
    file: &ProcedureFile,
    text: &str,
    participant: &str,
    display: &mut dyn ProgramDisplay,
    out: &mut dyn Write,
) -> Result<()> {
    let mut responder: Box<dyn ProcedureResponder> = if args.simulated_participant {
        // --seed sets the simulated participants' noise only (the file's seed by default).
        let seed = args.seed.unwrap_or(file.seed);
        let simulated = SimulatedParticipant::new(file.participant(), participant_seed(seed, participant))?;
        Box::new(SimulatedResponder::new(simulated))
    } else if let Some(path) = &args.responses {
        Box::new(ScriptedAnswers::load(path)?)
    } else {
        Box::new(Keyboard::start())
    };
    let now_unix_s = thermode_platform::MonotonicClock::new().unix_time_s();
    let mut session = ProcedureSession::open(&ProcedureSessionSpec {
        participant,
        experiment: &file.name,
        procedure: file.procedure.name(),
        seed: file.seed,
        experiment_file: (&args.experiment, text),
        data_dir: &args.data_dir,
        today: &civil_date(now_unix_s),
        now_utc: &utc_iso8601_ms(now_unix_s),
        device: display.describe(),
        answers: responder.describe(),
    })?;
    let recorded = session.rows().len();
    if let (Some(path), true) = (&args.responses, recorded > 0) {
        let mut script = ScriptedAnswers::load(path)?;
        script.skip(recorded);
        responder = Box::new(script);
    }
    writeln!(
        out,
        "{} ({}) for {participant}: {}{}",
        file.name,
        file.procedure.name(),
        session.csv_path().display(),
        if recorded > 0 {
            format!(", resuming after trial {recorded}")
        } else {
            String::new()
        }
    )?;
    let summary = ProcedureRunner {
        file,
        display,
        responder: responder.as_mut(),
        session: &mut session,
        channel: args.channel,
        out,
    }
    .run()?;
    let estimate = summary
        .estimate_c
        .map_or(String::new(), |e| format!("; estimate {e:.3} °C"));
    writeln!(
        out,
        "{} trial(s) in {}{estimate}",
        summary.trials,
        session.csv_path().display()
    )?;
    Ok(())
}

/// Whether a file's text is a procedure file (a top-level `procedure` key).
pub fn is_procedure(path: &Path) -> Result<Option<String>> {
    let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
    Ok(ProcedureFile::declares_procedure(&text).then_some(text))
}

/// The person at the keyboard: the space bar (or Enter) presses the button, `y`/`n` answer, digits and Enter rate.
/// Keys are read on a thread of their own (a terminal in raw mode, or standard input's bytes when it is not a
/// terminal), so a press reaches the runner at its next plate sample.
struct Keyboard {
    keys: Receiver<char>,
}

impl Keyboard {
    fn start() -> Keyboard {
        let (send, keys) = mpsc::channel();
        std::thread::spawn(move || {
            let term = console::Term::stdout();
            if term.is_term() {
                while let Ok(key) = term.read_key() {
                    let c = match key {
                        console::Key::Char(c) => c,
                        console::Key::Enter => '\n',
                        _ => continue,
                    };
                    if send.send(c).is_err() {
                        break;
                    }
                }
            } else {
                use std::io::Read;
                for byte in std::io::stdin().lock().bytes() {
                    let Ok(byte) = byte else { break };
                    if send.send(char::from(byte)).is_err() {
                        break;
                    }
                }
            }
        });
        Keyboard { keys }
    }

    fn key(&self) -> Result<char, StimulusError> {
        self.keys
            .recv()
            .map_err(|_| StimulusError::Device("the keyboard input ended; the completed trials are saved".into()))
    }

    fn ask_yes_no(&self, question: &str) -> Result<bool, StimulusError> {
        println!("{question} [y/n]");
        loop {
            match self.key()?.to_ascii_lowercase() {
                'y' => return Ok(true),
                'n' => return Ok(false),
                _ => continue,
            }
        }
    }
}

impl ProcedureResponder for Keyboard {
    fn begin(&mut self, plan: &TrialPlan) -> Result<(), StimulusError> {
        while self.keys.try_recv().is_ok() {}
        let what = if plan.until_response {
            "press SPACE when you feel it"
        } else {
            "feel"
        };
        println!("{} run {}: {what}", plan.label, plan.run);
        Ok(())
    }

    fn watch(&mut self, _dt_s: f64, _plate_c: f64) -> Result<bool, StimulusError> {
        loop {
            match self.keys.try_recv() {
                Ok(' ' | '\n') => return Ok(true),
                Ok(_) => continue,
                Err(TryRecvError::Empty) => return Ok(false),
                Err(TryRecvError::Disconnected) => {
                    return Err(StimulusError::Device("the keyboard input ended".into()))
                }
            }
        }
    }

    fn yes_no(&mut self, _plan: &TrialPlan) -> Result<bool, StimulusError> {
        self.ask_yes_no("did you feel a change?")
    }

    fn paradoxical_heat(&mut self, _plan: &TrialPlan) -> Result<bool, StimulusError> {
        self.ask_yes_no("did it feel warm or hot?")
    }

    fn rating(&mut self, name: &str) -> Result<Option<f64>, StimulusError> {
        println!("rate `{name}` from 0 to 100, then Enter (Enter alone: no rating)");
        let mut typed = String::new();
        loop {
            match self.key()? {
                '\n' | '\r' if typed.is_empty() => return Ok(None),
                '\n' | '\r' => match typed.parse::<f64>() {
                    Ok(value) if (0.0..=100.0).contains(&value) => return Ok(Some(value)),
                    _ => {
                        println!("`{typed}` is not a number from 0 to 100; again:");
                        typed.clear();
                    }
                },
                c if c.is_ascii_digit() || c == '.' => typed.push(c),
                _ => continue,
            }
        }
    }

    fn describe(&self) -> String {
        "keyboard (space bar)".into()
    }
}
