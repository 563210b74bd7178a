//! `thermode lab run`: walks one participant through the planned trials (experimenter-facing, line-based prompts on
//! standard input and output), writes the session CSV and its sidecar in the data folder, and resumes an interrupted
//! session where it stopped. Answers come from the keyboard, from `--responses FILE` or from the simulated
//! observer (`--observer`).
//!
//! The stimulus is `ModelStimulus` (no display hardware yet): both conditions are real contact under the fv model,
//! and the finger temperatures are the model's. `--time-scale` scales the waits (0 skips them, for demos).

use std::path::PathBuf;

use anyhow::{anyhow, Result};
use clap::Args;
use serde_json::json;
use thermode_lab::design::ExperimentFile;
use thermode_lab::observer::{SimulatedObserver, PAPER_REAL_IDENTIFICATION_RATE};
use thermode_lab::runner::{
    participant_plan, FvContact, InteractiveResponder, ModelStimulus, Responder, Runner, ScriptedResponses,
    SystemClock, TerminalConsole,
};

/// Noise draws per option when calibrating the simulated observer.
const CALIBRATION_SAMPLES: usize = 4000;
/// Seed of the observer calibration (fixed, so that the calibrated noise is the documented one).
const CALIBRATION_SEED: u64 = 1;

/// Arguments of `thermode lab run`.
#[derive(Args, Debug)]
pub struct LabRunArgs {
    /// Experiment file (TOML), as for `thermode lab plan`.
    #[arg(long)]
    experiment: PathBuf,
    /// Participant identifier from the design (default P01, P02, …); letters, digits, `_` and `-` only.
    #[arg(long)]
    participant: String,
    /// Folder of the session files `<participant>_<experiment>_<date>.csv` and `.json` (created if missing).
    #[arg(long, default_value = "data")]
    data_dir: PathBuf,
    /// Scripted answers: one per trial in order (an option number or name per line, or a CSV with an `identified`
    /// column).
    #[arg(long, conflicts_with = "observer")]
    responses: Option<PathBuf>,
    /// Let the simulated observer answer (calibrated to the paper's 66 % real identification rate).
    #[arg(long)]
    observer: bool,
    /// Multiplies every wait (1 = real time, 0 = no waiting).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    time_scale: f64,
    /// Standard deviation of the model finger's start temperature from trial to trial [°C] (0 = always at rest).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    finger_drift_sd_c: f64,
}

/// Runs `thermode lab run`.
pub fn run(args: &LabRunArgs) -> Result<()> {
    let experiment = ExperimentFile::load(&args.experiment)?;
    participant_plan(&experiment, &args.participant)?;
    let mut clock = SystemClock::new(args.time_scale).ok_or_else(|| {
        anyhow!(
            "--time-scale {}: must be a finite number of at least 0",
            args.time_scale
        )
    })?;
    let design = &experiment.experiment;
    let contact = FvContact::default();
    let mut stimulus = ModelStimulus::new(contact.clone(), args.finger_drift_sd_c, design.seed)?;
    let (mut responder, answers): (Box<dyn Responder>, String) = if args.observer {
        let mut observer =
            SimulatedObserver::from_model(&design.response_options, &contact, design.presentation_s, design.seed)?;
        let calibration = observer.calibrate(PAPER_REAL_IDENTIFICATION_RATE, CALIBRATION_SAMPLES, CALIBRATION_SEED)?;
        println!(
            "simulated observer: perceptual noise {:.4} (real contact identified {:.1} % on the calibration sample)",
            calibration.noise_sd,
            100.0 * calibration.rate
        );
        (
            Box::new(observer),
            format!("simulated observer, noise {:.4}", calibration.noise_sd),
        )
    } else if let Some(path) = &args.responses {
        let scripted = ScriptedResponses::load(path, &design.response_options, design.trials_per_participant())?;
        (Box::new(scripted), format!("responses file {}", path.display()))
    } else {
        (Box::new(InteractiveResponder), "keyboard".to_string())
    };
    let device = json!({
        "stimulus": stimulus.describe(),
        "answers": answers,
        "time_scale": args.time_scale,
    });
    let interactive = !args.observer && args.responses.is_none();
    let mut console = TerminalConsole::new(std::io::stdin().lock(), std::io::stdout());
    Runner {
        experiment: &experiment,
        participant: &args.participant,
        data_dir: &args.data_dir,
        device,
        stimulus: &mut stimulus,
        responder: responder.as_mut(),
        clock: &mut clock,
        console: &mut console,
        interactive,
    }
    .run()?;
    Ok(())
}
