//! The durable trial runner (`thermode lab run`): walks one participant through the planned trials, presents each
//! material through a [`Stimulus`], times the presentation with a `thermode_platform::Clock`, takes the answer from a
//! [`Responder`], applies the exclusion rule and appends each trial to the session file before the next begins.
//!
//! Per trial: show the progress (`trial 7/20, simulated, present: aluminium`); for a real trial ask the experimenter
//! to place the sample and press Enter (interactive mode only); present the stimulus and wait until the
//! presentation time has passed; ask for the answer; apply the exclusion rule; append and sync the row.
//!
//! **Exclusion rule** (the paper: data were discarded when the finger temperature differed by more than 1 °C from
//! the subject's start): the session's baseline is the finger start temperature of its first trial; a trial whose
//! start temperature differs from it by more than `exclusion_max_drift_c` is recorded with `excluded = true` and the
//! reason. Excluded trials are not repeated.
//!
//! **Resume**: the same call after a crash or Ctrl-C continues at the first missing trial (see [`crate::session`]);
//! nothing needs to be caught, since every completed trial is already on disk. On a display, a resumed session
//! first measures the finger at rest against the session's baseline (its first trial's) and waits, measurement
//! after measurement, until it is back within the exclusion limit — at most [`RECOVERY_WAIT_S`] — or says plainly
//! that it is not (its next trials would then be excluded) before any trial is run.

pub mod console;
pub mod live;
pub mod responses;
pub mod stimulus;
pub mod trace;
pub mod ws_link;

use std::path::{Path, PathBuf};

use thermode_model::materials::{find, Material};
use thermode_platform::{civil_date, Clock};
use thiserror::Error;

pub use console::{Console, QuietConsole, TerminalConsole};
pub use responses::{parse_answer, InteractiveResponder, Responder, ResponseQuery, ScriptedResponses};
pub use stimulus::{FvContact, ModelStimulus, SkinCurve, Stimulus, StimulusError, StimulusRequest, TrialMeasurement};

use crate::design::Condition;
use crate::design::{is_valid_identifier, DesignError, ExperimentFile};
use crate::participant::ParticipantError;
use crate::plan::{make_plan, ParticipantPlan, PlannedTrial};
use crate::session::{SessionError, SessionFile, SessionSpec, TrialRecord, SOFTWARE_VERSION};

/// Why a session could not be run. The CLI turns any of them into exit code 2.
#[derive(Debug, Error)]
pub enum RunError {
    /// The experiment file was refused.
    #[error(transparent)]
    Design(#[from] DesignError),
    /// The session file could not be created, resumed or written.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The stimulus failed.
    #[error(transparent)]
    Stimulus(#[from] StimulusError),
    /// The simulated participant failed.
    #[error(transparent)]
    Participant(#[from] ParticipantError),
    /// A participant identifier outside `[A-Za-z0-9_-]`.
    #[error("participant `{0}`: identifiers are 1 to 64 characters from A-Z, a-z, 0-9, `_` and `-`")]
    BadParticipant(String),
    /// A participant identifier that the design does not list.
    #[error("participant `{id}` is not in the plan of {}: {known}", file.display())]
    NotInPlan {
        /// The identifier given.
        id: String,
        /// The experiment file.
        file: PathBuf,
        /// The planned identifiers (abbreviated).
        known: String,
    },
    /// A responses file is unreadable, malformed or has the wrong number of answers.
    #[error("{}{}: {message}", file.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Responses {
        /// The responses file.
        file: PathBuf,
        /// 1-based line, where known.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// The experimenter's input ended before the session did (the completed trials are saved).
    #[error("the input ended; the completed trials are saved; run the same command again to resume")]
    InputClosed,
    /// The terminal could not be read or written.
    #[error("terminal: {0}")]
    Console(std::io::Error),
    /// A presented material is not in the library (cannot happen with a validated design).
    #[error("material: {0}")]
    Material(#[from] thermode_model::ParamError),
}

/// Everything one session needs.
pub struct Runner<'a> {
    /// The experiment file.
    pub experiment: &'a ExperimentFile,
    /// Participant identifier (one of the design's).
    pub participant: &'a str,
    /// Folder of the session files (created if missing).
    pub data_dir: &'a Path,
    /// Device configuration, recorded in the sidecar.
    pub device: serde_json::Value,
    /// Presents the materials.
    pub stimulus: &'a mut dyn Stimulus,
    /// Gives the answers.
    pub responder: &'a mut dyn Responder,
    /// Times the presentations and dates the session (UTC date of its wall clock).
    pub clock: &'a dyn Clock,
    /// Multiplies every wait: 1 = real time, 0 = no waiting (finite, not negative).
    pub time_scale: f64,
    /// Talks to the experimenter.
    pub console: &'a mut dyn Console,
    /// Whether to wait for the experimenter (Enter) before each real trial; false in scripted mode.
    pub interactive: bool,
}

/// What a run did.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionSummary {
    /// The session CSV.
    pub csv_path: PathBuf,
    /// The sidecar JSON.
    pub sidecar_path: PathBuf,
    /// Number of planned trials.
    pub planned_trials: usize,
    /// Trials already recorded when this run started.
    pub recorded_before: usize,
    /// Trials recorded by this run.
    pub recorded_now: usize,
    /// Excluded trials in the whole session.
    pub excluded: usize,
    /// Whether an existing session was resumed.
    pub resumed: bool,
    /// Whether a torn last row was cut off.
    pub removed_torn_row: bool,
}

/// Checks a participant identifier and finds its plan.
pub fn participant_plan(experiment: &ExperimentFile, participant: &str) -> Result<ParticipantPlan, RunError> {
    if !is_valid_identifier(participant) {
        return Err(RunError::BadParticipant(participant.to_string()));
    }
    let plan = make_plan(&experiment.experiment);
    plan.participant(participant).cloned().ok_or_else(|| {
        let ids = &experiment.experiment.participant_ids;
        let known = match ids.as_slice() {
            [] => "none".to_string(),
            [one] => one.clone(),
            [first, .., last] => format!("{first} … {last} ({} participants)", ids.len()),
        };
        RunError::NotInPlan {
            id: participant.to_string(),
            file: experiment.path.clone(),
            known,
        }
    })
}

impl Runner<'_> {
    /// Waits `duration_s` \[s\] of presentation time: `duration_s × time_scale` on the clock.
    fn wait_s(&self, duration_s: f64) {
        let scaled_s = duration_s * self.time_scale;
        if !(scaled_s.is_finite() && scaled_s > 0.0) {
            return;
        }
        let deadline_s = self.clock.now_s() + scaled_s;
        while self.clock.now_s() < deadline_s {
            self.clock.sleep_until(deadline_s);
        }
    }

    /// Experiment seconds since the clock read `start_s`: the clock's seconds divided by the time scale (0 at time
    /// scale 0, where no experiment time passes but the waits).
    fn experiment_s_since(&self, start_s: f64) -> f64 {
        match self.time_scale > 0.0 {
            true => (self.clock.now_s() - start_s) / self.time_scale,
            false => 0.0,
        }
    }

    /// Runs (or resumes) the session to its end.
    pub fn run(mut self) -> Result<SessionSummary, RunError> {
        let plan = participant_plan(self.experiment, self.participant)?;
        let today = civil_date(self.clock.unix_time_s());
        let mut session = SessionFile::open(&SessionSpec {
            experiment: self.experiment,
            plan: &plan,
            data_dir: self.data_dir,
            today: &today,
            now_unix_s: self.clock.unix_time_s(),
            device: &self.device,
        })?;
        let recorded_before = session.records().len();
        self.announce(&session, &plan)?;
        if let (true, Some(baseline_c)) = (session.resumed() && !session.is_complete(), session.baseline_c()) {
            self.wait_for_baseline(baseline_c)?;
        }
        let materials: Vec<Material> = self
            .experiment
            .experiment
            .materials
            .iter()
            .map(|n| find(n))
            .collect::<Result<_, _>>()?;
        for planned in &plan.trials[recorded_before.min(plan.trials.len())..] {
            let material = materials.iter().find(|m| m.name == planned.presented).ok_or_else(|| {
                thermode_model::ParamError::UnknownMaterial {
                    name: planned.presented.clone(),
                    close: Vec::new(),
                }
            })?;
            let (mut record, trace) = self.run_trial(&plan, planned, material, session.baseline_c())?;
            if let Some(first) = session
                .records()
                .first()
                .filter(|f| f.finger_measured != record.finger_measured)
            {
                let kind = |measured: bool| if measured { "measured on a display" } else { "simulated" };
                return Err(SessionError::Mismatch {
                    file: session.csv_path().to_path_buf(),
                    message: format!(
                        "its finger temperatures are {}; this run's are {}: continue it as it was started",
                        kind(first.finger_measured),
                        kind(record.finger_measured)
                    ),
                }
                .into());
            }
            if let Some(trace) = trace {
                record.curve_file = session.write_curve(planned.trial, &trace.to_csv())?;
            }
            session.append(&record)?;
            self.report(&record)?;
        }
        let summary = SessionSummary {
            csv_path: session.csv_path().to_path_buf(),
            sidecar_path: session.sidecar_path().to_path_buf(),
            planned_trials: session.planned_trials(),
            recorded_before,
            recorded_now: session.records().len() - recorded_before,
            excluded: session.records().iter().filter(|r| r.excluded).count(),
            resumed: session.resumed(),
            removed_torn_row: session.removed_torn_row(),
        };
        self.say(&format!(
            "session complete: {} trials ({} excluded) in {}",
            summary.planned_trials,
            summary.excluded,
            summary.csv_path.display()
        ))?;
        Ok(summary)
    }

    /// Measures the finger at rest until it is within the exclusion limit of `baseline_c` \[°C\] or
    /// [`RECOVERY_WAIT_S`] of measuring have passed, saying each measurement; a stimulus without a finger returns at
    /// once.
    fn wait_for_baseline(&mut self, baseline_c: f64) -> Result<(), RunError> {
        let limit_c = self.experiment.experiment.exclusion_max_drift_c;
        let mut waited_s = 0.0;
        loop {
            let Some(measured) = self.stimulus.finger_at_rest() else {
                return Ok(());
            };
            let (finger_c, rest_s) = measured?;
            waited_s += rest_s;
            let drift_c = (finger_c - baseline_c).abs();
            let state = format!(
                "finger at rest {finger_c:.2} °C, {drift_c:.2} °C from the session's baseline {baseline_c:.2} °C \
                 (limit {limit_c} °C)"
            );
            if drift_c <= limit_c {
                return self.say(&format!("resume: {state}: the trials go on"));
            }
            if waited_s >= RECOVERY_WAIT_S {
                return self.say(&format!(
                    "resume: WARNING: {state} after {waited_s:.0} s of rest: the finger has not recovered; trials \
                     that start this far from the baseline will be excluded"
                ));
            }
            self.say(&format!(
                "resume: {state}: waiting for the finger to recover ({waited_s:.0} s so far)"
            ))?;
        }
    }

    fn say(&mut self, line: &str) -> Result<(), RunError> {
        self.console.say(line).map_err(RunError::Console)
    }

    fn announce(&mut self, session: &SessionFile, plan: &ParticipantPlan) -> Result<(), RunError> {
        let order: Vec<&str> = plan.condition_order.iter().map(|c| c.name()).collect();
        let done = session.records().len();
        let what = if !session.resumed() {
            "new session".to_string()
        } else if session.is_complete() {
            "session already complete".to_string()
        } else {
            format!("resuming at trial {}", done + 1)
        };
        self.say(&format!(
            "{what}: participant {}, experiment {}, {} of {} trials recorded, conditions {}; file {}",
            plan.id,
            self.experiment.experiment.name,
            done,
            plan.trials.len(),
            order.join(" then "),
            session.csv_path().display()
        ))?;
        if session.removed_torn_row() {
            self.say("removed an incomplete last row (the previous run was stopped while writing it)")?;
        }
        Ok(())
    }

    fn run_trial(
        &mut self,
        plan: &ParticipantPlan,
        planned: &PlannedTrial,
        material: &Material,
        baseline_c: Option<f64>,
    ) -> Result<(TrialRecord, Option<live::TrialTrace>), RunError> {
        let experiment: &ExperimentFile = self.experiment;
        let design = &experiment.experiment;
        self.say(&format!(
            "trial {}/{}, {}, present: {}",
            planned.trial,
            plan.trials.len(),
            planned.condition.name(),
            planned.presented
        ))?;
        self.prepare(planned)?;
        self.say(&format!("  presenting for {} s", design.presentation_s))?;
        let start_s = self.clock.now_s();
        let measurement = self.stimulus.present(&StimulusRequest {
            material,
            condition: planned.condition,
            duration_s: design.presentation_s,
            participant_index: plan.index,
            trial: planned.trial,
        })?;
        measurement.validate()?;
        for note in self.stimulus.take_notes() {
            self.say(&format!("  note: {note}"))?;
        }
        let elapsed_s = self.experiment_s_since(start_s);
        if elapsed_s < design.presentation_s {
            self.wait_s(design.presentation_s - elapsed_s);
        }
        // A display times the presentation itself (its trace, from the touch); the rests around it are not part
        // of it.
        let traced_s = measurement.trace.as_ref().and_then(|t| t.time_s.last().copied());
        let presentation_s = match (traced_s, self.time_scale > 0.0) {
            (Some(traced_s), _) => traced_s,
            (None, true) => self.experiment_s_since(start_s),
            (None, false) => design.presentation_s,
        };
        let options = &design.response_options;
        let query = ResponseQuery {
            participant_index: plan.index,
            trial: planned,
            options,
            measurement: &measurement,
        };
        let asked_s = self.clock.now_s();
        let choice = self.responder.respond(&query, &mut *self.console)?;
        let response_time_s = self.responder.is_a_person().then(|| self.clock.now_s() - asked_s);
        let baseline_c = baseline_c.unwrap_or(measurement.finger_start_c);
        let reason = exclusion_reason(measurement.finger_start_c, baseline_c, design.exclusion_max_drift_c);
        let record = TrialRecord {
            trial: planned.clone(),
            identified: options[choice].clone(),
            response_key: choice + 1,
            response_time_s,
            presentation_s,
            finger_measured: measurement.measured,
            finger_baseline_c: baseline_c,
            finger_start_c: measurement.finger_start_c,
            finger_end_c: measurement.finger_end_c,
            excluded: reason.is_some(),
            exclusion_reason: reason.unwrap_or_default(),
            software_version: SOFTWARE_VERSION.to_string(),
            curve_file: String::new(),
        };
        Ok((record, measurement.trace))
    }

    /// Real trial: the experimenter places the sample (and confirms, interactively). Simulated: say so.
    fn prepare(&mut self, planned: &PlannedTrial) -> Result<(), RunError> {
        match planned.condition {
            Condition::Real if self.interactive => {
                let prompt = format!(
                    "  place the {} sample under the finger, then press Enter ",
                    planned.presented
                );
                match self.console.ask(&prompt).map_err(RunError::Console)? {
                    Some(_) => Ok(()),
                    None => Err(RunError::InputClosed),
                }
            }
            Condition::Real => self.say(&format!("  (scripted) the {} sample is placed", planned.presented)),
            Condition::Simulated => self.say(&format!("  rendering {} on the display", planned.presented)),
        }
    }

    fn report(&mut self, record: &TrialRecord) -> Result<(), RunError> {
        let excluded = if record.excluded {
            format!("; EXCLUDED: {}", record.exclusion_reason)
        } else {
            String::new()
        };
        self.say(&format!(
            "  answer: {} ({}); finger {:.2} -> {:.2} °C{excluded}",
            record.identified, record.response_key, record.finger_start_c, record.finger_end_c
        ))
    }
}

/// Longest a resumed session waits, measuring the finger at rest, for it to come back within the exclusion limit of
/// the session's baseline \[s\]: 300 (a finger recovers from a cold touch within minutes).
pub const RECOVERY_WAIT_S: f64 = 300.0;

/// The exclusion rule: `Some(reason)` when the start temperature differs from the baseline by more than the limit.
pub fn exclusion_reason(start_c: f64, baseline_c: f64, max_drift_c: f64) -> Option<String> {
    let drift_c = (start_c - baseline_c).abs();
    (drift_c > max_drift_c).then(|| {
        format!(
            "finger start {start_c:.2} °C is {drift_c:.2} °C from the session start {baseline_c:.2} °C (limit \
             {max_drift_c} °C)"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exclusion_is_strictly_beyond_the_limit() {
        assert_eq!(exclusion_reason(33.0, 32.0, 1.0), None);
        assert_eq!(exclusion_reason(31.0, 32.0, 1.0), None);
        let reason = exclusion_reason(30.9, 32.0, 1.0).expect("excluded");
        assert!(reason.contains("1.10 °C"), "{reason}");
    }
}
