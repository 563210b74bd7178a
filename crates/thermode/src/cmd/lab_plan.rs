//! `thermode lab plan`: the counterbalanced trial list of an experiment file, as CSV (one row per participant and
//! trial, the seed on every row). Same file → bit-identical plan. See `thermode_lab::plan` for the construction
//! (alternating condition order, Williams designs for the material order, seeded labels and row order).

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use thermode_lab::design::ExperimentFile;
use thermode_lab::plan::make_plan;
use thermode_pipeline::pipeline::render_envelope;
use thermode_runtime::StimulusLimits;

use crate::output::{print_stdout, write_atomically};

/// Arguments of `thermode lab plan`.
#[derive(Args, Debug)]
pub struct LabPlanArgs {
    /// Experiment file (TOML: name, materials, conditions, participants, repetitions, presentation_s,
    /// response_options, exclusion_max_drift_c, seed).
    #[arg(long)]
    experiment: PathBuf,
    /// Write the plan CSV to this file (atomically) and print a summary, instead of printing the CSV.
    #[arg(long)]
    out: Option<PathBuf>,
    /// The display's device file (TOML) whose stimulus limits a procedure's trials are checked against, as `lab
    /// run --device-file` would check them; default: the built-in default display.
    #[arg(long, value_name = "FILE")]
    device_file: Option<PathBuf>,
}

/// Runs `thermode lab plan`.
pub fn run(args: &LabPlanArgs) -> Result<()> {
    if let Some(text) = super::lab_procedure::is_procedure(&args.experiment)? {
        return procedure(args, &text);
    }
    let file = ExperimentFile::load(&args.experiment)?;
    let plan = make_plan(&file.experiment);
    let csv = plan.to_csv_string();
    let Some(out) = &args.out else {
        return print_stdout(&csv);
    };
    write_atomically(out, |w: &mut dyn Write| Ok(w.write_all(csv.as_bytes())?))?;
    let orders: Vec<String> = plan
        .first_condition_counts()
        .iter()
        .map(|(c, n)| format!("{n} {}-first", c.name()))
        .collect();
    print_stdout(&format!(
        "{}: {} participants × {} trials, seed {}; {}\n",
        out.display(),
        plan.participants.len(),
        file.experiment.trials_per_participant(),
        plan.seed,
        orders.join(", ")
    ))
}

/// `lab plan` of a procedure file: its trials as far as they are known before anyone answers.
fn procedure(args: &LabPlanArgs, text: &str) -> Result<()> {
    let file = thermode_procedures::ProcedureFile::from_toml_str(text)?;
    let device = crate::resolve::device_config(args.device_file.as_deref())?;
    let limits = StimulusLimits::of_envelope(&render_envelope(&device));
    let plan = thermode_lab::procedure::plan::procedure_plan(&file, 0, &limits)?;
    let Some(out) = &args.out else {
        return print_stdout(&plan.csv);
    };
    write_atomically(out, |w: &mut dyn Write| Ok(w.write_all(plan.csv.as_bytes())?))?;
    let what = match plan.adaptive {
        true => "the first trial (later intensities depend on the answers)".to_string(),
        false => format!(
            "{} trials, about {:.0} s with every ramp to its cut-off",
            plan.listed, plan.duration_s
        ),
    };
    print_stdout(&format!(
        "{}: {} ({}): {what}\n",
        out.display(),
        file.name,
        file.procedure.name()
    ))
}
