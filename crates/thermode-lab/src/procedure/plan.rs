//! `lab plan` of a procedure file: its trials as CSV, as far as they are known before anyone answers.
//!
//! A method-of-limits session's ramps are listed as they run when nobody presses (each to its cut-off; a thermal
//! sensory limen's later ramps start where the previous one stops, marked `continues_previous`); an adaptive
//! procedure (levels, staircase, QUEST+) lists its first trial, its later intensities depending on the answers; a
//! multi-zone program lists every presentation with its channels and duration. Every listed trial is checked against
//! the display's stimulus limits as `lab run` checks it ([`PlanError::Refused`]): a plan says what a run would refuse.

use thermode_procedures::program::segment_times_s;
use thermode_procedures::{ProcedureFile, ProcedureKind, Response, Segment, TrialPlan};
use thermode_runtime::program::Program;
use thermode_runtime::StimulusLimits;

use super::session::number;
use super::simulated::loop_segment;
use thermode_procedures::ProcedureError;

/// Why a procedure file has no plan.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The file is not a procedure.
    #[error(transparent)]
    Procedure(#[from] ProcedureError),
    /// A trial the display would refuse (as `lab run` would, before presenting it).
    #[error("trial {trial}: the display refuses its program ({message}); `lab run` would stop there")]
    Refused {
        /// The 1-based trial.
        trial: usize,
        /// What the display's limits say.
        message: String,
    },
}

/// Checks trial `trial`'s `segments` on `channel` against `limits` as the display does.
fn check_trial(trial: usize, channel: usize, segments: &[Segment], limits: &StimulusLimits) -> Result<(), PlanError> {
    Program::new(channel, segments.iter().map(loop_segment).collect(), limits)
        .map(|_| ())
        .map_err(|e| PlanError::Refused {
            trial,
            message: e.to_string(),
        })
}

/// Columns of a procedure plan.
pub const PLAN_COLUMNS: [&str; 13] = [
    "trial",
    "label",
    "run",
    "channels",
    "baseline_c",
    "intensity_c",
    "target_c",
    "rate_c_s",
    "until_response",
    "plateau_s",
    "return_c",
    "continues_previous",
    "duration_s",
];

/// A procedure plan: the CSV and what it says in one line.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcedurePlan {
    /// The plan as CSV ([`PLAN_COLUMNS`]).
    pub csv: String,
    /// Trials listed.
    pub listed: usize,
    /// Whether later trials depend on the answers (only the first is listed).
    pub adaptive: bool,
    /// The listed trials' nominal duration, pauses included \[s\] (ramps to their cut-offs).
    pub duration_s: f64,
}

fn plan_duration_s(plan: &TrialPlan) -> f64 {
    let ramp = plan.intensity_c.abs() / plan.rate_c_per_s;
    let back = plan
        .return_c
        .map_or(0.0, |r| (plan.target_c() - r).abs() / plan.return_rate_c_per_s);
    ramp + plan.plateau_s + back + plan.isi_s
}

fn plan_row(plan: &TrialPlan, channel: usize) -> Vec<String> {
    vec![
        (plan.index + 1).to_string(),
        plan.label.clone(),
        plan.run.to_string(),
        channel.to_string(),
        if plan.continues_previous {
            String::new()
        } else {
            number(plan.baseline_c)
        },
        number(plan.intensity_c),
        number(plan.target_c()),
        number(plan.rate_c_per_s),
        plan.until_response.to_string(),
        number(plan.plateau_s),
        plan.return_c.map_or(String::new(), number),
        plan.continues_previous.to_string(),
        number(plan_duration_s(plan)),
    ]
}

/// The plan of `file` for a single-channel procedure on `channel` of a display with stimulus `limits`.
pub fn procedure_plan(
    file: &ProcedureFile,
    channel: usize,
    limits: &StimulusLimits,
) -> Result<ProcedurePlan, PlanError> {
    let mut rows: Vec<Vec<String>> = Vec::new();
    let mut duration_s = file.adaptation_s;
    let adaptive = !matches!(file.procedure, ProcedureKind::Limits | ProcedureKind::Program);
    match file.procedure()? {
        Some(mut procedure) => {
            while let Some(plan) = procedure.next_trial() {
                check_trial(plan.index + 1, channel, &plan.segments(), limits)?;
                duration_s += plan_duration_s(&plan);
                rows.push(plan_row(&plan, channel));
                if adaptive {
                    break;
                }
                procedure.record(Response::yes_no(false, f64::NAN))?;
            }
        }
        None => {
            let config = file
                .program
                .as_ref()
                .ok_or_else(|| ProcedureError::invalid("program", "none", "a [program] table"))?;
            for trial in config.trials()? {
                for (&zone, segments) in &trial.channels {
                    check_trial(trial.index + 1, zone, segments, limits)?;
                }
                let length_s = trial
                    .channels
                    .values()
                    .map(|s| segment_times_s(trial.baseline_c, s).last().copied().unwrap_or(0.0))
                    .fold(0.0, f64::max);
                duration_s += length_s + trial.isi_s + file.adaptation_s;
                let channels: Vec<String> = trial.channels.keys().map(usize::to_string).collect();
                rows.push(vec![
                    (trial.index + 1).to_string(),
                    trial.name.clone(),
                    trial.repetition.to_string(),
                    channels.join(" "),
                    number(trial.baseline_c),
                    String::new(),
                    String::new(),
                    String::new(),
                    "false".into(),
                    String::new(),
                    number(trial.baseline_c),
                    "false".into(),
                    number(length_s + trial.isi_s),
                ]);
            }
        }
    }
    let mut writer = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    // Writing to memory cannot fail.
    let _ = writer.write_record(PLAN_COLUMNS);
    for row in &rows {
        let _ = writer.write_record(row);
    }
    Ok(ProcedurePlan {
        csv: String::from_utf8(writer.into_inner().unwrap_or_default()).unwrap_or_default(),
        listed: rows.len(),
        adaptive,
        duration_s,
    })
}
