//! `thermode lab run`: walks one participant through the planned trials (experimenter-facing, line-based prompts on
//! standard input and output), writes the session CSV and its sidecar in the data folder, and resumes an interrupted
//! session where it stopped. Answers come from the keyboard, from `--responses FILE` or from the
//! simulated participant (`--simulated-participant`).
//!
//! The stimulus (no display hardware yet) is, by default, `display`: every material rendered offline on the
//! simulated display (`thermode_render`) with the controller (`--controller model|pid`) and device file
//! (`--device FILE`) given — a real trial is the simulated finger touching the real material, a simulated trial the
//! same finger on the display. `--stimulus model` is the older stand-in: both conditions are real contact under the
//! fv model. The finger temperatures are the simulation's. `--time-scale` scales the waits (0 skips them, for
//! demos).
//!
//! The simulated participant's references are real contact under the same stimulus (its `real` curves), so that its
//! calibration to the paper's 66 % holds for the real trials it will see.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::{Args, ValueEnum};
use serde_json::json;
use thermode_device::DeviceConfig;
use thermode_lab::design::{Experiment, ExperimentFile};
use thermode_lab::participant::{CurveFeatures, SimulatedParticipant, PAPER_REAL_IDENTIFICATION_RATE};
use thermode_lab::runner::stimulus::{DisplaySetup, DisplayStimulus};
use thermode_lab::runner::{
    participant_plan, FvContact, InteractiveResponder, ModelStimulus, Responder, Runner, ScriptedResponses, Stimulus,
    TerminalConsole,
};
use thermode_model::materials::{find, Material};
use thermode_pipeline::controllers::GainsSource;
use thermode_pipeline::{gains_for_device, ControllerKind, PipelineConfig};
use thermode_platform::MonotonicClock;

use crate::resolve;

/// What presents the materials.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StimulusArg {
    /// The simulated display: real trials are the finger on the real material, simulated trials the finger on the
    /// display rendering it.
    Display,
    /// Real contact under the fv model for both conditions (no display in the loop).
    Model,
}

/// The display's controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LabControllerArg {
    /// thermode's model-based controller (observer, Peltier feedforward).
    Model,
    /// The paper's PID (the tuned gains of the shipped display that matches the device).
    Pid,
}

/// Noise draws per option when calibrating the simulated participant.
const CALIBRATION_SAMPLES: usize = 4000;
/// Seed of the simulated participant calibration (fixed, so that the calibrated noise is the documented one).
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
    #[arg(long, conflicts_with = "simulated_participant")]
    responses: Option<PathBuf>,
    /// Let the simulated participant answer (calibrated to the paper's 66 % real identification rate).
    #[arg(long, alias = "observer")]
    simulated_participant: bool,
    /// Multiplies every wait (1 = real time, 0 = no waiting).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    time_scale: f64,
    /// Standard deviation of the model finger's start temperature from trial to trial [°C] (0 = always at rest).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    finger_drift_sd_c: f64,
    /// What presents the materials.
    #[arg(long, value_enum, default_value = "display")]
    stimulus: StimulusArg,
    /// The display's controller (with `--stimulus display`; default model).
    #[arg(long, value_enum)]
    controller: Option<LabControllerArg>,
    /// The display's device file (TOML; with `--stimulus display`); default: the built-in default display.
    #[arg(long, value_name = "FILE")]
    device_file: Option<PathBuf>,
}

/// Runs `thermode lab run`.
pub fn run(args: &LabRunArgs) -> Result<()> {
    let experiment = ExperimentFile::load(&args.experiment)?;
    participant_plan(&experiment, &args.participant)?;
    if !(args.time_scale.is_finite() && args.time_scale >= 0.0) {
        bail!(
            "--time-scale {}: must be a finite number of at least 0",
            args.time_scale
        );
    }
    let clock = MonotonicClock::new();
    let design = &experiment.experiment;
    let (mut stimulus, references, description) = stimulus(args, design)?;
    let (mut responder, answers): (Box<dyn Responder>, String) = if args.simulated_participant {
        let mut simulated = SimulatedParticipant::new(design.response_options.clone(), references, design.seed);
        let calibration = simulated.calibrate(PAPER_REAL_IDENTIFICATION_RATE, CALIBRATION_SAMPLES, CALIBRATION_SEED)?;
        println!(
            "simulated participant: perceptual noise {:.4} (real contact identified {:.1} % on the calibration sample)",
            calibration.noise_sd,
            100.0 * calibration.rate
        );
        (
            Box::new(simulated),
            format!("simulated participant, noise {:.4}", calibration.noise_sd),
        )
    } else if let Some(path) = &args.responses {
        let scripted = ScriptedResponses::load(path, &design.response_options, design.trials_per_participant())?;
        (Box::new(scripted), format!("responses file {}", path.display()))
    } else {
        (Box::new(InteractiveResponder), "keyboard".to_string())
    };
    let device = json!({
        "stimulus": description,
        "answers": answers,
        "time_scale": args.time_scale,
    });
    let interactive = !args.simulated_participant && args.responses.is_none();
    let mut console = TerminalConsole::new(std::io::stdin().lock(), std::io::stdout());
    Runner {
        experiment: &experiment,
        participant: &args.participant,
        data_dir: &args.data_dir,
        device,
        stimulus: stimulus.as_mut(),
        responder: responder.as_mut(),
        clock: &clock,
        time_scale: args.time_scale,
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
) -> Result<(Box<dyn Stimulus>, Vec<CurveFeatures>, serde_json::Value)> {
    let options: Vec<Material> = design
        .response_options
        .iter()
        .map(|name| find(name))
        .collect::<Result<_, _>>()?;
    match args.stimulus {
        StimulusArg::Model => {
            if args.controller.is_some() || args.device_file.is_some() {
                bail!("--controller and --device-file choose the display; they need --stimulus display");
            }
            let contact = FvContact::default();
            let stimulus = ModelStimulus::new(contact.clone(), args.finger_drift_sd_c, design.seed)?;
            let mut references = Vec::with_capacity(options.len());
            for material in &options {
                references.push(CurveFeatures::of(&contact.curve(
                    material,
                    None,
                    design.presentation_s,
                )?)?);
            }
            let description = stimulus.describe();
            Ok((Box::new(stimulus), references, description))
        }
        StimulusArg::Display => {
            let device = resolve::device_config(args.device_file.as_deref())?;
            let setup = DisplaySetup::new(PipelineConfig::new(device, controller(args, &device)?));
            let mut stimulus = DisplayStimulus::new(setup, args.finger_drift_sd_c, design.seed)?;
            let mut materials: Vec<Material> = design.materials.iter().map(|n| find(n)).collect::<Result<_, _>>()?;
            materials.extend(options.iter().cloned());
            println!(
                "rendering {} material(s) on the simulated display ({} controller)…",
                design.materials.len(),
                stimulus.setup().pipeline.controller.name()
            );
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
            Ok((Box::new(stimulus), references, description))
        }
    }
}

/// The display's controller: `model` (default), or `pid` with the tuned gains of the shipped display that matches
/// `device`.
fn controller(args: &LabRunArgs, device: &DeviceConfig) -> Result<ControllerKind> {
    match args.controller.unwrap_or(LabControllerArg::Model) {
        LabControllerArg::Model => Ok(ControllerKind::Model),
        LabControllerArg::Pid => {
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
