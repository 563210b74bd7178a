//! The `thermode` command: a thin layer that parses arguments and wires the library crates together.
//!
//! Every error is printed as one clear message on standard error and ends the program with exit code 2.

// Doc comments here double as `--help` text, where units are written in brackets (`[s]`), not as links.
#![allow(rustdoc::broken_intra_doc_links)]

mod cmd;
mod output;

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
    /// List the built-in material library (the paper's Table 1 and common materials).
    Materials(cmd::materials::MaterialsArgs),
    /// Simulate a finger touching a material with one of the skin models and write the curve (CSV) and a plot.
    Simulate(cmd::simulate::SimulateArgs),
    /// Experiments: plan, run and analyse material-identification studies.
    #[command(subcommand)]
    Lab(LabCommand),
}

#[derive(Subcommand, Debug)]
enum LabCommand {
    /// Analyse session CSVs the way the paper did (rates, ratio table, χ², confusion correlation, figures).
    Analyze(cmd::lab_analyze::LabAnalyzeArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Materials(args) => cmd::materials::run(args),
        Command::Simulate(args) => cmd::simulate::run(args),
        Command::Lab(LabCommand::Analyze(args)) => cmd::lab_analyze::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("thermode: error: {error:#}");
            ExitCode::from(2)
        }
    }
}
