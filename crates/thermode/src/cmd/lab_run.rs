//! `thermode lab run` of an identification design (a procedure file goes to `lab_procedure`): walks one participant
//! through the planned trials (experimenter-facing, line-based prompts on
//! standard input and output), writes the session CSV and its sidecar in the data folder, and resumes an interrupted
//! session where it stopped. Answers come from the keyboard, from `--responses FILE` or from the
//! simulated participant (`--simulated-participant`).
//!
//! Where the materials are presented (one is required; docs/lab.md):
//! - `--display ws://HOST:PORT [--token T]`: a running `thermode serve`; `--device DEVICE`: a display of this
//!   machine, run for the session as `serve` runs it (loopback, its own token; Ctrl-C stops it with every drive at
//!   0 A). Each trial is presented on `--channel N` and the finger is measured on the plate at rest before and after
//!   it ([`LiveStimulus`]); each trial's curve is kept beside the session CSV. One participant, in real time.
//! - `--simulate`: no display. `--stimulus display` (default) renders every material offline on the simulated
//!   display (`thermode_render`) with `--controller model|pid`, `--renderer fv|kron` and `--device-file FILE` — a
//!   real trial is the simulated finger touching the real material, a simulated trial the same finger on the
//!   display (the paper's own display: `--renderer kron --controller pid` on the default device file,
//!   docs/lab.md); `--stimulus model` has both conditions as real contact under the fv model. The finger
//!   temperatures are the simulation's (`model_finger_*` columns). `--time-scale` scales the waits (0 skips them,
//!   for demos).
//!
//! The simulated participant (`--participant-model`): by default `perceptual`, the model of
//! `thermode_lab::perception` with the fitted parameters shipped in `crates/thermode-lab/data/participant_fit.toml`
//! (docs/lab.md, with its validation table); `calibrated` is the nearest-reference participant whose one noise term
//! is calibrated to the paper's 66 % real identification rate. The
//! references of either are real contact under the same stimulus (its `real` curves), so that its calibration or
//! fit to the paper's real-condition rates holds for the real trials it will see.
//!
//! Seeds: the design's `seed` decides the plan (which material stands for which symbol of the Williams squares, the
//! order of the rows) and the simulated display's sensor noise; `--seed N` decides only the participants' noise
//! (the simulated participant's perceptual noise and the finger drift), so that the same design can be run with
//! other participants. Without `--seed` the participants' noise is seeded by the design's seed, as before.
//!
//! With the simulated participant, several participants (`--participant` repeated, or `--all-participants`) run as
//! one batch on `--jobs` threads: each participant's files are exactly those of a run of its own, and the printed
//! output is each participant's in design order, whatever the thread count.

use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use serde_json::json;
use thermode_device::DeviceConfig;
use thermode_lab::design::{Experiment, ExperimentFile};
use thermode_lab::participant::{CurveFeatures, SimulatedParticipant, PAPER_REAL_IDENTIFICATION_RATE};
use thermode_lab::perception::{PerceptionParams, PerceptualParticipant};
use thermode_lab::runner::live::{LiveSettings, LiveStimulus};
use thermode_lab::runner::stimulus::{DisplaySetup, DisplayStimulus};
use thermode_lab::runner::ws_link::WsLink;
use thermode_lab::runner::{
    participant_plan, FvContact, InteractiveResponder, ModelStimulus, Responder, Runner, ScriptedResponses, Stimulus,
    TerminalConsole,
};
use thermode_model::materials::{find, Material};
use thermode_pipeline::controllers::GainsSource;
use thermode_pipeline::{gains_for_device, ControllerKind, PipelineConfig};
use thermode_platform::MonotonicClock;
use thermode_serve::Daemon;

use super::render::RendererArg;
use super::serve;
use crate::controller::{ControllerArg, LAB_CONTROLLERS};
use crate::display::DisplayArgs;
use crate::progress::Progress;
use crate::resolve;
use crate::signals::{StopSignals, SECOND_SIGNAL_EXIT_CODE};

/// What presents the materials.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StimulusArg {
    /// The simulated display: real trials are the finger on the real material, simulated trials the finger on the
    /// display rendering it.
    Display,
    /// Real contact under the fv model for both conditions (no display in the loop).
    Model,
}

/// Which simulated participant answers an identification design.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ParticipantModel {
    /// The perceptual participant of `thermode_lab::perception`, fitted to the paper's real rates per material
    /// (the default).
    Perceptual,
    /// The nearest-reference participant, one noise term calibrated to the paper's 66 % real identification rate.
    Calibrated,
}

/// A simulated participant of either model, copied for each session.
#[derive(Debug, Clone)]
enum Simulated {
    Calibrated(SimulatedParticipant),
    Perceptual(PerceptualParticipant),
}

impl Simulated {
    /// A copy that answers one session.
    fn responder(&self) -> Box<dyn Responder> {
        match self {
            Simulated::Calibrated(p) => Box::new(p.clone()),
            Simulated::Perceptual(p) => Box::new(p.clone()),
        }
    }
}

/// Noise draws per option when calibrating the simulated participant.
const CALIBRATION_SAMPLES: usize = 4000;
/// Seed of the simulated participant calibration (fixed, so that the calibrated noise is the documented one).
const CALIBRATION_SEED: u64 = 1;

/// Arguments of `thermode lab run`.
#[derive(Args, Debug)]
pub struct LabRunArgs {
    /// Experiment file (TOML), as for `thermode lab plan`: an identification design, or a procedure file
    /// (`procedure = "limits" | "levels" | "staircase" | "questplus" | "program"`, docs/procedures.md).
    #[arg(long)]
    pub(crate) experiment: PathBuf,
    /// Participant identifier from the design (a design names them P01, P02, … unless it lists its own); letters,
    /// digits, `_` and `-` only. Required unless `--all-participants`. Repeat it (with `--simulated-participant`) to
    /// run several as one batch.
    #[arg(long, required_unless_present = "all_participants")]
    pub(crate) participant: Vec<String>,
    /// Every participant of the design, as one batch (needs `--simulated-participant`).
    #[arg(long, conflicts_with = "participant")]
    pub(crate) all_participants: bool,
    /// Threads of a batch of participants (default: the available parallelism); the output does not depend on it.
    #[arg(long, value_name = "N")]
    pub(crate) jobs: Option<usize>,
    /// Folder of the session files `<participant>_<experiment>_<date>.csv` and `.json` (created if missing).
    #[arg(long, default_value = "data")]
    pub(crate) data_dir: PathBuf,
    /// Scripted answers: one per trial in order (an option number or name per line, or a CSV with an `identified`
    /// column; for a procedure file `press SECONDS [phs]`, `none`, `yes`, `no` or `rating VALUE` per line).
    #[arg(long, conflicts_with = "simulated_participant")]
    pub(crate) responses: Option<PathBuf>,
    /// Let the simulated participant answer (`--participant-model`; for a procedure file, the file's
    /// `[simulated_participant]`).
    #[arg(long, alias = "observer")]
    pub(crate) simulated_participant: bool,
    /// Which simulated participant answers an identification design: `perceptual` (default: Weber-fraction noise,
    /// memory noise, per-person contact, a non-thermal recognition channel in real trials; fitted to the paper's
    /// real rates per material and checked against published human data, docs/lab.md's validation table) or
    /// `calibrated` (one noise term calibrated to the paper's 66 % real identification rate).
    #[arg(long, value_enum, default_value = "perceptual", requires = "simulated_participant")]
    pub(crate) participant_model: ParticipantModel,
    /// Multiplies every wait of a simulated session (1 = real time, e.g. to pace a demo; default 0: a simulation
    /// does not wait). A display presents in real time (1).
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) time_scale: Option<f64>,
    /// Standard deviation of the model finger's start temperature from trial to trial [°C] (0 = always at rest).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub(crate) finger_drift_sd_c: f64,
    /// What presents the materials.
    #[arg(long, value_enum, default_value = "display")]
    pub(crate) stimulus: StimulusArg,
    /// The display's controller (with `--stimulus display`; default model).
    #[arg(long, value_parser = ControllerArg::parser(&LAB_CONTROLLERS))]
    pub(crate) controller: Option<ControllerArg>,
    /// The simulated display's renderer (with `--simulate --stimulus display`; default fv): `kron` is the paper's
    /// three-layer model, as on the paper's own display.
    #[arg(long, value_enum, value_name = "RENDERER")]
    pub(crate) renderer: Option<RendererArg>,
    /// Seed of the simulated participants' noise (perceptual noise and finger drift) [-]; default: the design's
    /// seed. The plan (order of the materials) stays the design's whatever this seed.
    #[arg(long, value_name = "N")]
    pub(crate) seed: Option<u64>,
    /// The display's device file (TOML; with `--device` or `--stimulus display`); default: the built-in default
    /// display.
    #[arg(long, value_name = "FILE")]
    pub(crate) device_file: Option<PathBuf>,
    /// Present on a running display: the `ws://HOST:PORT` of a `thermode serve` (with `--token` if it has one).
    /// The finger is measured on it (docs/lab.md).
    #[arg(long, value_name = "ws://HOST:PORT", conflicts_with_all = ["device", "simulate"])]
    pub(crate) display: Option<String>,
    /// The token of the daemon of `--display`.
    #[arg(long, value_name = "T", requires = "display")]
    pub(crate) token: Option<String>,
    /// Present on a display connected to this machine: the values `thermode serve --device` takes (`sim` is the
    /// simulated display in real time, `serial:PATH`, `mecom:PATH`, …; given several times, one display of their
    /// channels in that order); thermode runs it as `serve` would, on loopback only, for this session.
    #[arg(long, value_name = "DEVICE", conflicts_with = "simulate")]
    pub(crate) device: Vec<String>,
    /// The display channel (finger) the trials are presented on, with `--display` or `--device`.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub(crate) channel: usize,
    /// Directory of the dose ledger of `--device` (as `serve --state-dir`).
    #[arg(long = "state-dir", value_name = "DIR", requires = "device")]
    pub(crate) state_dir: Option<PathBuf>,
    /// Simulate instead: no display; the materials are rendered offline (`--stimulus`) and every finger
    /// temperature is the simulation's (kept in the `model_finger_*` columns).
    #[arg(long)]
    pub(crate) simulate: bool,
}

/// Runs `thermode lab run`.
pub fn run(args: &LabRunArgs) -> Result<()> {
    let experiment = ExperimentFile::load(&args.experiment)?;
    if let Some(scale) = args.time_scale {
        thermode_model::params::Rule::NonNegative.check("--time-scale", scale)?;
    }
    let participants = if args.all_participants {
        experiment.experiment.participant_ids.clone()
    } else {
        args.participant.clone()
    };
    for participant in &participants {
        participant_plan(&experiment, participant)?;
    }
    let live = args.display.is_some() || !args.device.is_empty();
    if !live && !args.simulate {
        bail!(
            "choose where the materials are presented: --display ws://HOST:PORT (a running `thermode serve`), \
             --device DEVICE (a display on this machine) or --simulate (the offline simulation)"
        );
    }
    let mut stdout = std::io::stdout();
    if live {
        let [participant] = participants.as_slice() else {
            bail!("a display presents to one participant at a time: give one --participant");
        };
        if let Some(scale) = args.time_scale.filter(|&s| s != 1.0) {
            bail!("--time-scale {scale}: a display presents in real time (1)");
        }
        if args.renderer.is_some() {
            bail!(
                "--renderer chooses the simulated display's renderer (with --simulate); a display renders with its own"
            );
        }
        return run_live(args, &experiment, participant, &mut stdout);
    }
    match participants.as_slice() {
        [one] => {
            let prepared = prepare(args, &experiment.experiment, &mut stdout)?;
            let mut boxed = prepared.stimulus.fresh();
            let stimulus: (&mut dyn Stimulus, _) = (&mut *boxed, &prepared.description);
            session(
                args,
                &experiment,
                one,
                stimulus,
                &prepared.who,
                std::io::stdin().lock(),
                &mut stdout,
            )
        }
        _ => run_batch(args, &experiment, &participants),
    }
}

/// What every participant's session starts from: the prepared stimulus, the responder and their descriptions.
struct Prepared {
    stimulus: PreparedStimulus,
    who: Answers,
    description: serde_json::Value,
}

/// Who answers, and its description for the sidecar.
struct Answers {
    /// The simulated participant (`None`: keyboard or responses file).
    simulated: Option<Simulated>,
    answers: String,
}

/// A stimulus ready to present, copied for each session.
enum PreparedStimulus {
    Model(Box<ModelStimulus>),
    Display(Box<DisplayStimulus>),
}

impl PreparedStimulus {
    /// A copy for one session.
    fn fresh(&self) -> Box<dyn Stimulus> {
        match self {
            PreparedStimulus::Model(s) => Box::new(s.as_ref().clone()),
            PreparedStimulus::Display(s) => Box::new(s.as_ref().clone()),
        }
    }
}

/// The simulated display's stimulus of `--simulate`, prepared once (batches copy it).
fn prepare(args: &LabRunArgs, design: &Experiment, out: &mut dyn Write) -> Result<Prepared> {
    let (stimulus, references, description) = stimulus(args, design, out)?;
    let (simulated, answers) = answers(args, design, references, out)?;
    Ok(Prepared {
        stimulus,
        who: Answers { simulated, answers },
        description,
    })
}

/// Who answers: the simulated participant of `--participant-model` with references `references` (with
/// `--simulated-participant`), a responses file or the keyboard; and its description for the sidecar.
fn answers(
    args: &LabRunArgs,
    design: &Experiment,
    references: Vec<CurveFeatures>,
    out: &mut dyn Write,
) -> Result<(Option<Simulated>, String)> {
    if !args.simulated_participant {
        return Ok(match &args.responses {
            Some(path) => (None, format!("responses file {}", path.display())),
            None => (None, "keyboard".to_string()),
        });
    }
    let seed = participant_seed(args, design);
    let (simulated, mut answers) = match args.participant_model {
        ParticipantModel::Calibrated => {
            let mut simulated = SimulatedParticipant::new(design.response_options.clone(), references, seed);
            let calibration =
                simulated.calibrate(PAPER_REAL_IDENTIFICATION_RATE, CALIBRATION_SAMPLES, CALIBRATION_SEED)?;
            writeln!(
                out,
                "simulated participant: perceptual noise {:.4} (real contact identified {:.1} % on the calibration sample)",
                calibration.noise_sd,
                100.0 * calibration.rate
            )?;
            let answers = format!("simulated participant, noise {:.4}", calibration.noise_sd);
            (Simulated::Calibrated(simulated), answers)
        }
        ParticipantModel::Perceptual => {
            let params = PerceptionParams::fitted();
            let simulated =
                PerceptualParticipant::new(design.response_options.clone(), &references, params.clone(), seed)?;
            let answers = format!(
                "simulated participant (perceptual model fitted {}: Weber fraction {}, non-thermal recognition {})",
                params.fitted_on,
                params.weber_fraction,
                params.recognition_summary()
            );
            writeln!(out, "{answers}")?;
            (Simulated::Perceptual(simulated), answers)
        }
    };
    if let Some(seed) = args.seed {
        answers.push_str(&format!(", seed {seed}"));
    }
    Ok((Some(simulated), answers))
}

/// Runs one participant on a real display: a running daemon (`--display`) or one started for the session
/// (`--device`), the finger measured on it.
fn run_live(args: &LabRunArgs, experiment: &ExperimentFile, participant: &str, out: &mut dyn Write) -> Result<()> {
    let design = &experiment.experiment;
    on_display(args, |url, token| {
        let link = WsLink::connect(url, token, args.channel)?;
        let device = link.status().map(|s| s.device.clone()).unwrap_or_default();
        if device.contains("tcs2:") || device.contains("mode=temperature") {
            bail!(
                "{device} regulates its plate itself, so the plate's heat balance cannot measure the finger on it \
                 (docs/lab.md): run the lab on a current-commanded display"
            );
        }
        let settings = LiveSettings::default();
        let mut resting: Option<Progress> = None;
        let mut stimulus = LiveStimulus::new(link, settings)?.with_rest_progress(move |rest_s| match rest_s {
            // A bar per rest: the finger can take up to max_rest_s to settle, twice per trial.
            Some(rest_s) => resting
                .get_or_insert_with(|| Progress::seconds(settings.max_rest_s, "finger at rest"))
                .at_s(rest_s),
            None => drop(resting.take()),
        });
        if args.simulated_participant {
            stimulus = stimulus.with_modelled_real_contact(FvContact::default());
        }
        writeln!(
            out,
            "presenting on {} channel {}",
            if args.device.is_empty() {
                url.to_string()
            } else {
                args.device.join(" + ")
            },
            args.channel
        )?;
        // The simulated participant compares what it feels with real contact under the fv model.
        let references = match args.simulated_participant {
            true => {
                let options: Vec<Material> = design
                    .response_options
                    .iter()
                    .map(|n| find(n))
                    .collect::<Result<_, _>>()?;
                contact_references(&FvContact::default(), &options, design.presentation_s)?
            }
            false => Vec::new(),
        };
        let (simulated, answers) = answers(args, design, references, out)?;
        let who = Answers { simulated, answers };
        let description = stimulus.describe();
        let input = std::io::stdin().lock();
        session(
            args,
            experiment,
            participant,
            (&mut stimulus, &description),
            &who,
            input,
            out,
        )
    })
}

/// Runs `body` with the `ws://` address and token of the display of `--display` or `--device`: with `--device`
/// this process runs the display for the session (loopback, its own token), stops it at the end (every drive at
/// 0 A, the dose ledger written) and on SIGINT or SIGTERM.
pub(crate) fn on_display(args: &LabRunArgs, body: impl FnOnce(&str, Option<&str>) -> Result<()>) -> Result<()> {
    // With --device this process runs the display: a stop signal must stop it cleanly (every drive to 0 A, the
    // dose ledger written) before the process ends. Installed before the daemon starts.
    let signals = (!args.device.is_empty()).then(StopSignals::install).transpose()?;
    let (daemon, url, token) = match (&args.display, args.device.is_empty()) {
        (Some(url), _) => (None, url.clone(), args.token.clone()),
        (None, false) => {
            let display = DisplayArgs {
                device: args.device.clone(),
                device_file: args.device_file.clone(),
                channels: None,
                controller: args.controller.unwrap_or(ControllerArg::Model),
                seed: 1, // the simulated display's sensor noise, as `serve`'s default
            };
            let (daemon, token) = serve::start_private(&display, args.state_dir.clone())?;
            let url = format!("ws://{}", daemon.http_addr());
            (Some(daemon), url, Some(token))
        }
        (None, true) => bail!("--display or --device"),
    };
    let daemon = Arc::new(Mutex::new(daemon));
    let (done, interrupted) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
    if let Some(signals) = signals {
        let (daemon, done, interrupted) = (daemon.clone(), done.clone(), interrupted.clone());
        std::thread::spawn(move || stop_on_signal(&signals, &daemon, &done, &interrupted));
    }
    let result = body(&url, token.as_deref());
    if interrupted.load(Ordering::SeqCst) {
        // The session ended because the signal thread is stopping the display; it ends the process when done.
        loop {
            std::thread::park();
        }
    }
    done.store(true, Ordering::SeqCst);
    stop_display(&daemon)?;
    result
}

/// Stops the display this process runs, if it still runs: every drive to 0 A, the dose ledger written.
fn stop_display(daemon: &Mutex<Option<Daemon>>) -> Result<()> {
    let taken = daemon.lock().ok().and_then(|mut d| d.take());
    if let Some(daemon) = taken {
        if let Some(Err(e)) = daemon.stop()?.all_off {
            return Err(e).context("switching every drive off at the end of the session");
        }
    }
    Ok(())
}

/// Waits for SIGINT or SIGTERM until the session is `done`; on one, stops the display and ends the process (exit
/// 130): the completed trials are already on disk.
fn stop_on_signal(signals: &StopSignals, daemon: &Mutex<Option<Daemon>>, done: &AtomicBool, interrupted: &AtomicBool) {
    while !done.load(Ordering::SeqCst) {
        if let Some(signal) = signals.wait(Duration::from_millis(100)) {
            interrupted.store(true, Ordering::SeqCst);
            let stopped = match stop_display(daemon) {
                Ok(()) => "the display is stopped (every drive at 0 A)".to_string(),
                Err(e) => format!("stopping the display failed: {e:#}"),
            };
            eprintln!(
                "thermode: {}: {stopped}; the completed trials are saved; run the same command to resume",
                signal.as_str()
            );
            std::process::exit(SECOND_SIGNAL_EXIT_CODE);
        }
    }
}

/// What a session of a batch printed, and how it ended.
type SessionOutput = (Vec<u8>, Result<()>);

/// Runs several participants on `--jobs` threads, each into its own output, printed in design order.
fn run_batch(args: &LabRunArgs, experiment: &ExperimentFile, participants: &[String]) -> Result<()> {
    if !args.simulated_participant {
        bail!("several participants run only with --simulated-participant (keyboard and --responses answer for one)");
    }
    let jobs = match args.jobs {
        Some(0) => bail!("--jobs 0: at least one thread"),
        Some(n) => n,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    }
    .min(participants.len().max(1));
    let prepared = prepare(args, &experiment.experiment, &mut std::io::stdout())?;
    let next = AtomicUsize::new(0);
    let results: Vec<Mutex<Option<SessionOutput>>> = participants.iter().map(|_| Mutex::new(None)).collect();
    let progress = Progress::bar(participants.len() as u64, "sessions", "lab run");
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| loop {
                let index = next.fetch_add(1, Ordering::SeqCst);
                let Some(participant) = participants.get(index) else {
                    break;
                };
                let mut out = Vec::new();
                let mut boxed = prepared.stimulus.fresh();
                let stimulus: (&mut dyn Stimulus, _) = (&mut *boxed, &prepared.description);
                let input = std::io::empty();
                let result = session(args, experiment, participant, stimulus, &prepared.who, input, &mut out);
                if let Ok(mut slot) = results[index].lock() {
                    *slot = Some((out, result));
                }
                progress.step();
            });
        }
    });
    progress.finish();
    let mut stdout = std::io::stdout().lock();
    let mut failed = Vec::new();
    for (participant, slot) in participants.iter().zip(results) {
        let (out, result) = slot
            .into_inner()
            .ok()
            .flatten()
            .unwrap_or_else(|| (Vec::new(), Err(anyhow::anyhow!("its thread stopped"))));
        writeln!(stdout, "== {participant}")?;
        stdout.write_all(&out)?;
        if let Err(e) = result {
            writeln!(stdout, "{participant}: FAILED: {e:#}")?;
            failed.push(format!("{participant}: {e:#}"));
        }
    }
    stdout.flush()?;
    if !failed.is_empty() {
        bail!(
            "{} of {} participants failed: {}",
            failed.len(),
            participants.len(),
            failed.join("; ")
        );
    }
    Ok(())
}

/// Runs one participant's session from `prepared`, prompts and messages to `out`, answers (keyboard) from `input`.
fn session(
    args: &LabRunArgs,
    experiment: &ExperimentFile,
    participant: &str,
    (stimulus, description): (&mut dyn Stimulus, &serde_json::Value),
    who: &Answers,
    input: impl BufRead,
    out: &mut dyn Write,
) -> Result<()> {
    let clock = MonotonicClock::new();
    let design = &experiment.experiment;
    let mut responder: Box<dyn Responder> = match (&who.simulated, &args.responses) {
        (Some(simulated), _) => simulated.responder(),
        (None, Some(path)) => Box::new(ScriptedResponses::load(
            path,
            &design.response_options,
            design.trials_per_participant(),
        )?),
        (None, None) => Box::new(InteractiveResponder),
    };
    let device = json!({
        "stimulus": description,
        "answers": who.answers,
        "time_scale": simulated_time_scale(args),
    });
    let interactive = !args.simulated_participant && args.responses.is_none();
    let mut console = TerminalConsole::new(input, out);
    Runner {
        experiment,
        participant,
        data_dir: &args.data_dir,
        device,
        stimulus,
        responder: responder.as_mut(),
        clock: &clock,
        time_scale: simulated_time_scale(args),
        console: &mut console,
        interactive,
    }
    .run()?;
    Ok(())
}

/// The stimulus of `args`, the simulated participant's references (features of real contact with each response option under
/// it) and its description for the sidecar.
fn stimulus(
    args: &LabRunArgs,
    design: &Experiment,
    out: &mut dyn Write,
) -> Result<(PreparedStimulus, Vec<CurveFeatures>, serde_json::Value)> {
    let options: Vec<Material> = design
        .response_options
        .iter()
        .map(|name| find(name))
        .collect::<Result<_, _>>()?;
    match args.stimulus {
        StimulusArg::Model => {
            if args.controller.is_some() || args.device_file.is_some() || args.renderer.is_some() {
                bail!("--controller, --renderer and --device-file choose the display; they need --stimulus display");
            }
            let contact = FvContact::default();
            // The model stimulus has no display: its only randomness is the finger drift, the participants'.
            let stimulus = ModelStimulus::new(contact.clone(), args.finger_drift_sd_c, participant_seed(args, design))?;
            let references = contact_references(&contact, &options, design.presentation_s)?;
            let description = stimulus.describe();
            Ok((PreparedStimulus::Model(Box::new(stimulus)), references, description))
        }
        StimulusArg::Display => {
            let device = resolve::device_config(args.device_file.as_deref())?;
            let mut pipeline = PipelineConfig::new(device, controller(args, &device)?);
            if let Some(renderer) = args.renderer {
                pipeline.renderer = renderer.into();
            }
            let mut stimulus = DisplayStimulus::new(DisplaySetup::new(pipeline), args.finger_drift_sd_c, design.seed)?
                .with_drift_seed(participant_seed(args, design));
            let mut materials: Vec<Material> = design.materials.iter().map(|n| find(n)).collect::<Result<_, _>>()?;
            materials.extend(options.iter().cloned());
            let renderer = match args.renderer {
                Some(_) => format!(", {} renderer", stimulus.setup().pipeline.renderer.name()),
                None => String::new(),
            };
            writeln!(
                out,
                "rendering {} material(s) on the simulated display ({} controller{renderer})…",
                design.materials.len(),
                stimulus.setup().pipeline.controller.name()
            )?;
            stimulus.prepare(&materials, design.presentation_s)?;
            let mut references = Vec::with_capacity(options.len());
            for material in &options {
                references.push(CurveFeatures::of(
                    &stimulus.curves(material, design.presentation_s)?.real,
                )?);
            }
            let mut description = stimulus.describe();
            description["device_file"] = match &args.device_file {
                Some(path) => json!(path.display().to_string()),
                None => json!("built-in default display"),
            };
            Ok((PreparedStimulus::Display(Box::new(stimulus)), references, description))
        }
    }
}

/// The simulated participant's references: real contact with each option under `contact` for `duration_s`.
fn contact_references(contact: &FvContact, options: &[Material], duration_s: f64) -> Result<Vec<CurveFeatures>> {
    options
        .iter()
        .map(|material| Ok(CurveFeatures::of(&contact.curve(material, None, duration_s)?)?))
        .collect()
}

/// The display's controller: `model` (default), or `pid` with the tuned gains of the shipped display that matches
/// `device`.
fn controller(args: &LabRunArgs, device: &DeviceConfig) -> Result<ControllerKind> {
    match args.controller.unwrap_or(ControllerArg::Model) {
        ControllerArg::Model => Ok(ControllerKind::Model),
        ControllerArg::Both => bail!("a display runs one controller: --controller model or pid"),
        ControllerArg::Pid => {
            let (gains, source) = gains_for_device(device)?;
            if source == GainsSource::DefaultFallback {
                eprintln!(
                    "note: the device matches no shipped display; pid uses the default display's tuned gains \
                     (run `thermode tune --device-file FILE --out GAINS.toml` for its own)"
                );
            }
            Ok(ControllerKind::Pid(gains))
        }
    }
}

/// The seed of the simulated participants' noise: `--seed`, else the design's seed (the behaviour before `--seed`).
fn participant_seed(args: &LabRunArgs, design: &Experiment) -> u64 {
    args.seed.unwrap_or(design.seed)
}

/// How a simulated session paces its waits: `--time-scale`, else 0 (a simulation does not wait).
fn simulated_time_scale(args: &LabRunArgs) -> f64 {
    args.time_scale.unwrap_or(0.0)
}
