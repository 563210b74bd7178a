//! Who answers a procedure's trials ([`ProcedureResponder`]): the simulated participant of the experiment file
//! ([`SimulatedResponder`]), a script of answers ([`ScriptedAnswers`]), or a person at the keyboard (the CLI's).
//!
//! The runner shows a responder every plate sample of the trial's channel; during an `until: response` ramp a
//! responder that says "press" makes the runner send a response, which stops the ramp on the display's next tick.

use std::path::Path;

use thermode_platform::fs::{read_text_at_most, MAX_SETTINGS_BYTES};
use thermode_procedures::participant::{Criterion, SimulatedParticipant};
use thermode_procedures::{ProcedureError, TrialPlan};

use crate::runner::StimulusError;

/// What answers a procedure's trials.
pub trait ProcedureResponder {
    /// A trial starts: `plan` is what it presents (for a multi-zone program, a plan of its first channel). An error
    /// when the responder has no answer for it (a script that ended).
    fn begin(&mut self, plan: &TrialPlan) -> Result<(), StimulusError>;
    /// A plate sample of the trial's channel, `dt_s` \[s\] after the previous one, the plate at `plate_c` \[°C\];
    /// `true` asks the runner to send a button press now (it sends one only while an `until: response` ramp runs).
    fn watch(&mut self, dt_s: f64, plate_c: f64) -> Result<bool, StimulusError>;
    /// The yes/no answer after a trapezoid: was a change felt?
    fn yes_no(&mut self, plan: &TrialPlan) -> Result<bool, StimulusError>;
    /// After a cold ramp of the thermal sensory limen stopped by a press: was it felt as warm or hot (a paradoxical
    /// heat sensation)?
    fn paradoxical_heat(&mut self, plan: &TrialPlan) -> Result<bool, StimulusError>;
    /// A rating 0–100 of a multi-zone stimulus named `name`, or `None` for no rating.
    fn rating(&mut self, name: &str) -> Result<Option<f64>, StimulusError>;
    /// Who answers, for the session sidecar.
    fn describe(&self) -> String;
}

/// The simulated participant of the experiment file, feeling the plate sample by sample.
#[derive(Debug, Clone)]
pub struct SimulatedResponder {
    participant: SimulatedParticipant,
    /// The largest change of its receptor from the trial's start \[°C\] (its ratings).
    largest_change_c: f64,
    start_receptor_c: f64,
}

/// The change of receptor temperature the simulated participant rates 100 \[°C\].
pub const FULL_SCALE_CHANGE_C: f64 = 10.0;

impl SimulatedResponder {
    /// Answers as `participant`.
    pub fn new(participant: SimulatedParticipant) -> Self {
        SimulatedResponder {
            participant,
            largest_change_c: 0.0,
            start_receptor_c: f64::NAN,
        }
    }
}

impl ProcedureResponder for SimulatedResponder {
    fn begin(&mut self, plan: &TrialPlan) -> Result<(), StimulusError> {
        if !plan.continues_previous {
            self.participant.adapt(plan.baseline_c);
        }
        let sign = plan.intensity_c.signum();
        let criterion = if plan.pain {
            Criterion::Pain { sign }
        } else {
            Criterion::Change { sign }
        };
        self.participant.begin_trial(criterion);
        self.start_receptor_c = self.participant.receptor_c();
        self.largest_change_c = 0.0;
        Ok(())
    }

    fn watch(&mut self, dt_s: f64, plate_c: f64) -> Result<bool, StimulusError> {
        if !plate_c.is_finite() {
            return Err(StimulusError::BadMeasurement(format!(
                "the simulated participant cannot feel a plate of {plate_c} °C"
            )));
        }
        let press = self.participant.observe(dt_s, plate_c);
        let change = (self.participant.receptor_c() - self.start_receptor_c).abs();
        self.largest_change_c = self.largest_change_c.max(change);
        Ok(press)
    }

    fn yes_no(&mut self, _plan: &TrialPlan) -> Result<bool, StimulusError> {
        Ok(self.participant.answer())
    }

    fn paradoxical_heat(&mut self, _plan: &TrialPlan) -> Result<bool, StimulusError> {
        Ok(false)
    }

    fn rating(&mut self, _name: &str) -> Result<Option<f64>, StimulusError> {
        Ok(Some((100.0 * self.largest_change_c / FULL_SCALE_CHANGE_C).min(100.0)))
    }

    fn describe(&self) -> String {
        let c = self.participant.config();
        format!(
            "simulated participant (threshold {} °C, reaction time {} s, noise {} °C, lapse {})",
            c.threshold_c, c.reaction_time_s, c.noise_c, c.lapse
        )
    }
}

/// One scripted answer.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Scripted {
    /// Press this long after the trial's start \[s\] (`press 3.2`); `phs` adds a paradoxical heat sensation.
    PressAfter { after_s: f64, phs: bool },
    /// No press (`none`).
    None,
    /// A yes/no answer (`yes`, `no`).
    YesNo(bool),
    /// A rating 0–100 (`rating 40`).
    Rating(f64),
}

/// Answers from a text file, one line per trial in order: `press SECONDS` (after the trial's start; `press
/// SECONDS phs` for a paradoxical heat sensation), `none`, `yes`, `no` or `rating VALUE`; `#` starts a comment.
#[derive(Debug, Clone)]
pub struct ScriptedAnswers {
    answers: Vec<Scripted>,
    next: usize,
    current: Option<Scripted>,
    elapsed_s: f64,
    source: String,
}

fn parse_line(line: &str) -> Result<Scripted, String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    let number = |text: &str, what: &str, max: f64| {
        text.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && (0.0..=max).contains(v))
            .ok_or_else(|| format!("`{text}` is not {what}"))
    };
    match words.as_slice() {
        ["none"] => Ok(Scripted::None),
        ["yes"] => Ok(Scripted::YesNo(true)),
        ["no"] => Ok(Scripted::YesNo(false)),
        ["press", t] => Ok(Scripted::PressAfter {
            after_s: number(t, "a time from 0 to 3600 s", 3600.0)?,
            phs: false,
        }),
        ["press", t, "phs"] => Ok(Scripted::PressAfter {
            after_s: number(t, "a time from 0 to 3600 s", 3600.0)?,
            phs: true,
        }),
        ["rating", v] => Ok(Scripted::Rating(number(v, "a rating from 0 to 100", 100.0)?)),
        _ => Err(format!(
            "`{line}`: expected `press SECONDS [phs]`, `none`, `yes`, `no` or `rating VALUE`"
        )),
    }
}

impl ScriptedAnswers {
    /// Reads the answers of `path`.
    pub fn load(path: &Path) -> Result<ScriptedAnswers, ProcedureError> {
        let text = read_text_at_most(path, MAX_SETTINGS_BYTES)
            .map_err(|e| ProcedureError::Parse(format!("{}: {e}", path.display())))?;
        Self::from_text(&text, &path.display().to_string())
    }

    /// Parses answers from `text` (`source` names it in errors).
    pub fn from_text(text: &str, source: &str) -> Result<ScriptedAnswers, ProcedureError> {
        let mut answers = Vec::new();
        for (index, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let answer =
                parse_line(line).map_err(|e| ProcedureError::Parse(format!("{source} line {}: {e}", index + 1)))?;
            answers.push(answer);
        }
        Ok(ScriptedAnswers {
            answers,
            next: 0,
            current: None,
            elapsed_s: 0.0,
            source: source.to_string(),
        })
    }

    /// Skips the answers of `trials` trials already recorded (a resumed session).
    pub fn skip(&mut self, trials: usize) {
        self.next = self.next.max(trials);
    }

    fn answer_of(&self, plan_label: &str) -> Result<Scripted, StimulusError> {
        self.current.ok_or_else(|| {
            StimulusError::BadMeasurement(format!(
                "{}: no answer for trial {} ({plan_label}): it has {} line(s)",
                self.source,
                self.next + 1,
                self.answers.len()
            ))
        })
    }

    fn mismatch(&self, wanted: &str, got: Scripted) -> StimulusError {
        StimulusError::BadMeasurement(format!(
            "{}: trial {} asks for {wanted}, the script says {got:?}",
            self.source,
            self.next + 1
        ))
    }
}

impl ProcedureResponder for ScriptedAnswers {
    fn begin(&mut self, plan: &TrialPlan) -> Result<(), StimulusError> {
        self.current = self.answers.get(self.next).copied();
        let answer = self.answer_of(&plan.label)?;
        if plan.until_response && matches!(answer, Scripted::YesNo(_) | Scripted::Rating(_)) {
            return Err(self.mismatch("`press SECONDS` or `none`", answer));
        }
        self.next += 1;
        self.elapsed_s = 0.0;
        Ok(())
    }

    fn watch(&mut self, dt_s: f64, _plate_c: f64) -> Result<bool, StimulusError> {
        self.elapsed_s += dt_s;
        Ok(matches!(self.current, Some(Scripted::PressAfter { after_s, .. }) if self.elapsed_s >= after_s))
    }

    fn yes_no(&mut self, plan: &TrialPlan) -> Result<bool, StimulusError> {
        match self.answer_of(&plan.label)? {
            Scripted::YesNo(yes) => Ok(yes),
            other => Err(self.mismatch("`yes` or `no`", other)),
        }
    }

    fn paradoxical_heat(&mut self, plan: &TrialPlan) -> Result<bool, StimulusError> {
        Ok(matches!(
            self.answer_of(&plan.label)?,
            Scripted::PressAfter { phs: true, .. }
        ))
    }

    fn rating(&mut self, name: &str) -> Result<Option<f64>, StimulusError> {
        match self.answer_of(name)? {
            Scripted::Rating(value) => Ok(Some(value)),
            Scripted::None => Ok(None),
            other => Err(self.mismatch("`rating VALUE` or `none`", other)),
        }
    }

    fn describe(&self) -> String {
        format!("answers file {}", self.source)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_script_reads_every_kind_of_answer_and_names_a_bad_line() {
        let script = ScriptedAnswers::from_text("press 2.5 # CDT\npress 1 phs\nnone\nyes\nno\nrating 40\n", "s.txt")
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            script.answers,
            vec![
                Scripted::PressAfter {
                    after_s: 2.5,
                    phs: false
                },
                Scripted::PressAfter {
                    after_s: 1.0,
                    phs: true
                },
                Scripted::None,
                Scripted::YesNo(true),
                Scripted::YesNo(false),
                Scripted::Rating(40.0),
            ]
        );
        let error = ScriptedAnswers::from_text("yes\nrating 140\n", "s.txt")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(error.contains("s.txt line 2") && error.contains("0 to 100"), "{error}");
    }

    #[test]
    fn a_scripted_press_comes_at_its_time_after_the_trial_start() {
        let mut script = ScriptedAnswers::from_text("press 0.045\n", "s").unwrap_or_else(|e| panic!("{e}"));
        let plan = thermode_procedures::stimulus::StimulusConfig::default().trial(0, "x", 1.0);
        script.begin(&plan).unwrap_or_else(|e| panic!("{e}"));
        let presses: Vec<bool> = (0..10).map(|_| script.watch(0.01, 32.0).unwrap_or(false)).collect();
        assert_eq!(presses.iter().position(|&p| p), Some(4), "{presses:?}");
        assert!(script.begin(&plan).is_err(), "the script has one line");
    }
}
