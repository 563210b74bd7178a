//! The `thermode` command: a thin layer that parses arguments and wires the library crates together.
//!
//! Every error is printed as one clear message on standard error and ends the program with exit code 2.

// Doc comments here double as `--help` text, where units are written in brackets (`[s]`), not as links.
#![allow(rustdoc::broken_intra_doc_links)]

mod cmd;
mod controller;
mod display;
mod identified;
mod output;
mod progress;
mod record_columnar;
mod resolve;
mod signals;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// thermode — an open thermal display engine: makes a finger on a Peltier element feel virtual materials.
#[derive(Parser, Debug)]
#[command(name = "thermode", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run the daemon: the display rendered in real time, the contact API (WebSocket, HTTP, OSC) and the dashboard.
    Serve(cmd::serve::ServeArgs),
    /// Like `serve`, plus a short scripted sequence of touches so a newcomer sees it work.
    Demo(cmd::demo::DemoArgs),
    /// List the built-in material library (the paper's Table 1 and common materials).
    Materials(cmd::materials::MaterialsArgs),
    /// Simulate a finger touching a material with one of the skin models and write the curve (CSV) and a plot.
    Simulate(cmd::simulate::SimulateArgs),
    /// Render touches on the simulated display (renderer, inverse, controller, safety envelope) next to the truth.
    Render(cmd::render::RenderArgs),
    /// Tune the paper's PID (gains and sensor filter) for a display; writes a gains file.
    Tune(cmd::tune::TuneArgs),
    /// Identify a display (no finger on it): fit its device file's thermal parameters to an excitation.
    Identify(cmd::identify::IdentifyArgs),
    /// Calibrate a display's plate sensor against a reference thermometer (no finger on it); writes a device file.
    Calibrate(cmd::calibrate::CalibrateArgs),
    /// Experiments: plan, run and analyse material-identification studies.
    #[command(subcommand)]
    Lab(LabCommand),
    /// Run the device side of the serial protocol on a pseudo-terminal (prints its path) with the simulated display.
    Emulate(cmd::emulate::EmulateArgs),
    /// Measure control-loop jitter and touch-to-drive latency (figures only; build with --release).
    Bench(cmd::bench::BenchArgs),
    /// Show or reset the thermal-dose ledger that `serve` keeps per channel across restarts.
    #[command(subcommand)]
    Dose(DoseCommand),
}

#[derive(Subcommand, Debug)]
enum DoseCommand {
    /// Print each channel's dose (CEM43, time at or above 43 °C, lockout, last update).
    Show(cmd::dose::ShowArgs),
    /// Clear one channel's dose (or every channel's); the reset is logged with its reason and UTC time.
    Reset(cmd::dose::ResetArgs),
}

#[derive(Subcommand, Debug)]
enum LabCommand {
    /// Write the counterbalanced trial plan of an experiment file (CSV, one row per participant and trial).
    Plan(cmd::lab_plan::LabPlanArgs),
    /// Run or resume one participant's session (terminal prompts; durable session CSV and JSON sidecar).
    Run(cmd::lab_run::LabRunArgs),
    /// Analyse session CSVs the way the paper did (rates, ratio table, χ², confusion correlation, figures).
    Analyze(cmd::lab_analyze::LabAnalyzeArgs),
    /// Export the lab's sessions and recordings as a BIDS data set (events, continuous signals, sidecars).
    Export(cmd::lab_export::LabExportArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Serve(args) => cmd::serve::run(args),
        Command::Demo(args) => cmd::demo::run(args),
        Command::Bench(args) => cmd::bench::run(args),
        Command::Emulate(args) => cmd::emulate::run(args),
        Command::Materials(args) => cmd::materials::run(args),
        Command::Simulate(args) => cmd::simulate::run(args),
        Command::Lab(LabCommand::Analyze(args)) => cmd::lab_analyze::run(args),
        Command::Lab(LabCommand::Export(args)) => cmd::lab_export::run(args),
        Command::Lab(LabCommand::Plan(args)) => cmd::lab_plan::run(args),
        Command::Lab(LabCommand::Run(args)) => cmd::lab_procedure::dispatch(args),
        Command::Render(args) => cmd::render::run(args),
        Command::Tune(args) => cmd::tune::run(args),
        Command::Identify(args) => cmd::identify::run(args),
        Command::Calibrate(args) => cmd::calibrate::run(args),
        Command::Dose(DoseCommand::Show(args)) => cmd::dose::show(args),
        Command::Dose(DoseCommand::Reset(args)) => cmd::dose::reset(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("thermode: error: {}", message(&error));
            ExitCode::from(2)
        }
    }
}

/// The error and its causes as one line, `: `-separated (as `{:#}` writes it), leaving out a cause whose text the
/// line already ends with (an error that shows its source in its own message, such as a refused value with the
/// file it came from, would otherwise say it twice).
fn message(error: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in error.chain() {
        let text = cause.to_string();
        if out.ends_with(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}
